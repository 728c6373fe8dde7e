//! Writing files so that an interruption never leaves a half-written one: a single file goes
//! to a temporary sibling renamed into place ([`write_atomic`]), a set of files is written all
//! or none ([`OutputSet`]).
use std::io::Write;
use std::path::{Path, PathBuf};

/// The hidden sibling `.NAME.WHATPID` a file is staged in (`what` = `tmp`) or moved aside
/// to (`old`) around a rename.
fn sibling(path: &Path, what: &str) -> PathBuf {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    dir.join(format!(".{name}.{what}{}", std::process::id()))
}

/// Writes `contents` to `path` and syncs it to disk.
pub fn write_synced(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    let mut f = std::fs::File::create(path)?;
    f.write_all(contents)?;
    f.sync_all()
}

/// Writes `contents` to `path` atomically (temporary file in the same folder, then rename).
///
/// This low-level helper does not check what `path` is (the `cpm` command checks its outputs
/// against its inputs first).
pub fn write_atomic(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    refuse_directory(path)?;
    let tmp = sibling(path, "tmp");
    let result = write_synced(&tmp, contents).and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// An error when `path` is a directory (a file cannot replace it).
fn refuse_directory(path: &Path) -> std::io::Result<()> {
    if path.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!("{}: is a directory, not a file", path.display()),
        ));
    }
    Ok(())
}

/// A set of files staged in memory and written together only when all were produced.
///
/// [`OutputSet::commit`] writes every file to a temporary sibling first; only when all of
/// them are on disk are they renamed into place (earlier files of the same names are moved
/// aside first and put back if a rename fails). A failure before the renames leaves every
/// earlier file untouched and no temporary file behind; an interruption leaves at most hidden
/// `.NAME.tmpPID` files beside intact earlier results.
#[derive(Debug, Default)]
pub struct OutputSet {
    files: Vec<(PathBuf, Vec<u8>)>,
}

impl OutputSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Stages a file.
    pub fn add(&mut self, path: impl Into<PathBuf>, contents: impl Into<Vec<u8>>) {
        self.files.push((path.into(), contents.into()));
    }

    /// The staged contents of `path`, if it is staged.
    pub fn contents(&self, path: &Path) -> Option<&[u8]> {
        self.files
            .iter()
            .find(|(p, _)| p == path)
            .map(|(_, c)| c.as_slice())
    }

    /// The staged files, as (path, contents), for a writer of its own (the `cpm` command's
    /// result directories).
    pub fn into_files(self) -> Vec<(PathBuf, Vec<u8>)> {
        self.files
    }

    /// The staged paths.
    pub fn paths(&self) -> impl Iterator<Item = &Path> {
        self.files.iter().map(|(p, _)| p.as_path())
    }

    /// Creates parent folders and writes every staged file atomically, all or none.
    pub fn commit(self) -> std::io::Result<Vec<PathBuf>> {
        self.commit_failing_at(None)
    }

    /// [`OutputSet::commit`], failing on purpose at the `fail_at`-th rename (tests).
    fn commit_failing_at(self, fail_at: Option<usize>) -> std::io::Result<Vec<PathBuf>> {
        let mut created_dirs: Vec<PathBuf> = Vec::new();
        let mut staged: Vec<(PathBuf, PathBuf)> = Vec::new();
        let cleanup = |staged: &[(PathBuf, PathBuf)], dirs: &[PathBuf]| {
            for (_, tmp) in staged {
                let _ = std::fs::remove_file(tmp);
            }
            for d in dirs.iter().rev() {
                let _ = std::fs::remove_dir(d); // only when empty
            }
        };
        // 1. Every file on disk under a temporary name.
        for (path, contents) in &self.files {
            let result = (|| {
                refuse_directory(path)?;
                if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    let mut missing = Vec::new();
                    let mut a = Some(d);
                    while let Some(x) = a.filter(|x| !x.as_os_str().is_empty() && !x.exists()) {
                        missing.push(x.to_path_buf());
                        a = x.parent();
                    }
                    std::fs::create_dir_all(d)?;
                    created_dirs.extend(missing.into_iter().rev());
                }
                let tmp = sibling(path, "tmp");
                staged.push((path.clone(), tmp.clone()));
                write_synced(&tmp, contents)
            })();
            if let Err(e) = result {
                cleanup(&staged, &created_dirs);
                return Err(e);
            }
        }
        // 2. The renames; an earlier file is moved aside and restored if a rename fails.
        let mut done: Vec<(PathBuf, Option<PathBuf>)> = Vec::new();
        for (k, (path, tmp)) in staged.iter().enumerate() {
            let result = (|| {
                let backup = if path.exists() {
                    let b = sibling(path, "old");
                    std::fs::rename(path, &b)?;
                    Some(b)
                } else {
                    None
                };
                let renamed = if fail_at == Some(k) {
                    Err(std::io::Error::other("injected failure"))
                } else {
                    std::fs::rename(tmp, path)
                };
                if let Err(e) = renamed {
                    if let Some(b) = &backup {
                        let _ = std::fs::rename(b, path);
                    }
                    return Err(e);
                }
                done.push((path.clone(), backup));
                Ok(())
            })();
            if let Err(e) = result {
                for (p, backup) in done.iter().rev() {
                    match backup {
                        Some(b) => {
                            let _ = std::fs::rename(b, p);
                        }
                        None => {
                            let _ = std::fs::remove_file(p);
                        }
                    }
                }
                cleanup(&staged, &created_dirs);
                return Err(e);
            }
        }
        for (_, backup) in &done {
            if let Some(b) = backup {
                let _ = std::fs::remove_file(b);
            }
        }
        Ok(staged.into_iter().map(|(p, _)| p).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("cpm-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failed_rename_puts_every_earlier_file_back() {
        let d = scratch("rollback");
        std::fs::write(d.join("a.txt"), "old a").unwrap();
        std::fs::write(d.join("b.txt"), "old b").unwrap();
        for fail_at in 0..3 {
            let mut set = OutputSet::new();
            set.add(d.join("a.txt"), "new a");
            set.add(d.join("c.txt"), "new c");
            set.add(d.join("b.txt"), "new b");
            assert!(set.commit_failing_at(Some(fail_at)).is_err());
            assert_eq!(listing(&d), ["a.txt", "b.txt"], "fail at {fail_at}");
            assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "old a");
            assert_eq!(std::fs::read_to_string(d.join("b.txt")).unwrap(), "old b");
        }
        let mut set = OutputSet::new();
        set.add(d.join("a.txt"), "new a");
        set.add(d.join("sub/c.txt"), "new c");
        set.commit().unwrap();
        assert_eq!(listing(&d), ["a.txt", "b.txt", "sub"]);
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "new a");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_failure_while_staging_leaves_nothing() {
        let d = scratch("staging");
        std::fs::write(d.join("a.txt"), "old a").unwrap();
        std::fs::create_dir_all(d.join("b.txt")).unwrap(); // a directory in the way
        let mut set = OutputSet::new();
        set.add(d.join("new/deeper/x.txt"), "x");
        set.add(d.join("a.txt"), "new a");
        set.add(d.join("b.txt"), "new b");
        let e = set.commit().unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        assert_eq!(listing(&d), ["a.txt", "b.txt"]);
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "old a");
        let _ = std::fs::remove_dir_all(&d);
    }
}
