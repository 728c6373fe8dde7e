//! Atomic output: files are written to a temporary sibling and renamed, so a failed or
//! interrupted run never leaves a half-written file behind.
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `contents` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let tmp: PathBuf = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(contents)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// A set of files staged in memory and written together only when all were produced:
/// every file is written atomically, after all contents exist.
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

    /// Creates parent folders and writes every staged file atomically.
    pub fn commit(self) -> std::io::Result<Vec<PathBuf>> {
        let mut written = Vec::new();
        for (p, c) in self.files {
            if let Some(d) = p.parent() {
                std::fs::create_dir_all(d)?;
            }
            write_atomic(&p, &c)?;
            written.push(p);
        }
        Ok(written)
    }
}
