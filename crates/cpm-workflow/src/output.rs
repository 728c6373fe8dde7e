//! Outputs that never destroy: single files are written to a temporary sibling and renamed
//! (never over a device, FIFO, socket or an input of the run), and a result directory is
//! committed as one step (staged in a sibling directory, then swapped in by one rename) under a
//! lock, so an interrupted run leaves either the previous complete result or the new one.
//!
//! Test hook (documented in docs/cli.md, meant for the test suite only): when the environment
//! variable `CPM_FAULT_AT` names a step of [`commit_dir`] ([`COMMIT_STEPS`]), the process aborts
//! there, as a `kill -9` would; `CPM_FAULT_NO_EXCHANGE=1` forces the two-rename fallback of
//! systems without an atomic exchange.
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

pub use cpm_io::write::{write_atomic, OutputSet};
use cpm_io::write::{write_contents_synced, write_synced, Contents};

/// Why an output was not written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output path was refused before anything was written (a usage error: not a regular
    /// file, or an input of the run).
    #[error("{0}")]
    Refused(String),
    /// Reading or writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
}

fn io_at(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Where a single-file output goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// Standard output (`-`).
    Stdout,
    /// A regular file (new, or replaced atomically); a symbolic link is followed to the
    /// regular file it names, which is replaced (the link stays).
    File(PathBuf),
}

/// True when `a` and `b` are the same file (device and inode), following links.
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        }
    }
}

/// Refuses `path` when it is one of `inputs` (the same file, by device and inode).
pub fn refuse_inputs(option: &str, path: &Path, inputs: &[&Path]) -> Result<(), OutputError> {
    if let Some(i) = inputs.iter().find(|i| same_file(path, i)) {
        return Err(OutputError::Refused(format!(
            "{option} {}: is the input {}; writing it would destroy the input (choose another output)",
            path.display(),
            i.display()
        )));
    }
    Ok(())
}

/// Checks a single-file output path: `-` is standard output; an existing path must be a
/// regular file (or a link to one) that is not one of `inputs`. Devices, FIFOs, sockets,
/// directories and dangling links are refused ([`OutputError::Refused`]), never replaced.
pub fn output_target(option: &str, path: &Path, inputs: &[&Path]) -> Result<Target, OutputError> {
    if path.as_os_str() == "-" {
        return Ok(Target::Stdout);
    }
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Target::File(path.into())),
        Err(e) => return Err(io_at(path)(e)),
    };
    let resolved = if meta.file_type().is_symlink() {
        std::fs::canonicalize(path).map_err(|_| {
            OutputError::Refused(format!(
                "{option} {}: is a symbolic link to nothing that exists; cpm does not write through it",
                path.display()
            ))
        })?
    } else {
        path.to_path_buf()
    };
    let ft = std::fs::metadata(&resolved)
        .map_err(io_at(path))?
        .file_type();
    if ft.is_dir() {
        return Err(OutputError::Refused(format!(
            "{option} {}: is a directory, not a file",
            path.display()
        )));
    }
    if !ft.is_file() {
        return Err(OutputError::Refused(format!(
            "{option} {}: is not a regular file (a device, FIFO or socket); cpm does not replace it (use `{option} -` for standard output)",
            path.display()
        )));
    }
    refuse_inputs(option, path, inputs)?;
    Ok(Target::File(resolved))
}

/// Writes one file to a checked [`Target::File`] atomically, creating its parent folders.
pub fn write_file(path: &Path, contents: &[u8]) -> Result<(), OutputError> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(io_at(d))?;
    }
    write_atomic(path, contents).map_err(io_at(path))
}

/// The steps of [`commit_dir`] at which the test hook `CPM_FAULT_AT` can abort the process.
pub const COMMIT_STEPS: &[&str] = &[
    "locked",
    "recovered",
    "staging-created",
    "carried-over",
    "file-written",
    "manifest-written",
    "staged",
    "moved-aside",
    "swapped",
    "cleaned",
];

/// The test hook: aborts the process at `step` when `CPM_FAULT_AT` names it.
fn fault_point(step: &str) {
    if std::env::var_os("CPM_FAULT_AT").is_some_and(|v| v == step) {
        std::process::abort();
    }
}

/// The name of the manifest a committed result directory holds.
pub const MANIFEST: &str = ".cpm-result.json";

/// FNV-1a, 64 bits: a content fingerprint for the manifest.
pub fn fingerprint(bytes: &[u8]) -> u64 {
    let mut h = Fingerprint::new();
    h.add(bytes);
    h.value()
}

/// [`fingerprint`] of bytes given piece by piece (as a file is written).
#[derive(Debug, Clone, Copy)]
pub struct Fingerprint(u64);

impl Default for Fingerprint {
    fn default() -> Self {
        Self::new()
    }
}

impl Fingerprint {
    /// Of no bytes yet.
    pub fn new() -> Self {
        Fingerprint(0xcbf2_9ce4_8422_2325)
    }

    /// Adds the next bytes.
    pub fn add(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    /// The fingerprint of the bytes so far.
    pub fn value(&self) -> u64 {
        self.0
    }
}

/// Bytes handed to the fingerprinting thread at a time ([`write_fingerprinted`]); contents
/// smaller than one chunk (and not streamed) are fingerprinted in line.
const HASH_CHUNK: usize = 1 << 20;

/// Writes `contents` to `path` (synced, [`write_contents_synced`]) and returns how many bytes
/// it wrote and their [`fingerprint`].
///
/// FNV-1a takes one byte after the other (about 0.1 s for the 70 MB of a million readings'
/// residuals.csv, the critical path of the write when done in line). So large contents are
/// fingerprinted on a second thread, fed copies of the bytes in chunks of [`HASH_CHUNK`],
/// while the writing thread goes on producing and writing: the same bytes in the same order,
/// so the same fingerprint. Without a thread (none can be started) it is done in line.
fn write_fingerprinted(path: &Path, contents: &Contents) -> std::io::Result<(usize, u64)> {
    let large = match contents {
        Contents::Bytes(b) => b.len() >= HASH_CHUNK,
        Contents::Streamed(_) => true,
    };
    let in_line = || -> std::io::Result<(usize, u64)> {
        let (mut bytes, mut hash) = (0usize, Fingerprint::new());
        write_contents_synced(path, contents, &mut |b| {
            bytes += b.len();
            hash.add(b);
        })?;
        Ok((bytes, hash.value()))
    };
    if !large {
        return in_line();
    }
    std::thread::scope(|scope| {
        // Full chunks go one way, emptied ones come back to be filled again: a few buffers
        // in all, whatever the size of the file.
        let (full, chunks) = std::sync::mpsc::sync_channel::<Vec<u8>>(2);
        let (spent, emptied) = std::sync::mpsc::channel::<Vec<u8>>();
        let hasher = std::thread::Builder::new()
            .name("cpm-fingerprint".to_string())
            .spawn_scoped(scope, move || {
                let mut hash = Fingerprint::new();
                for chunk in chunks {
                    hash.add(&chunk);
                    let _ = spent.send(chunk);
                }
                hash.value()
            });
        let Ok(hasher) = hasher else {
            return in_line();
        };
        let mut bytes = 0usize;
        let mut chunk = Vec::with_capacity(HASH_CHUNK);
        let hand_over = |chunk: &mut Vec<u8>| {
            let next = emptied
                .try_recv()
                .map(|mut c| {
                    c.clear();
                    c
                })
                .unwrap_or_else(|_| Vec::with_capacity(HASH_CHUNK));
            let _ = full.send(std::mem::replace(chunk, next));
        };
        let written = write_contents_synced(path, contents, &mut |mut b| {
            bytes += b.len();
            while !b.is_empty() {
                let n = b.len().min(HASH_CHUNK - chunk.len());
                chunk.extend_from_slice(&b[..n]);
                b = &b[n..];
                if chunk.len() == HASH_CHUNK {
                    hand_over(&mut chunk);
                }
            }
        });
        if !chunk.is_empty() {
            hand_over(&mut chunk);
        }
        drop(full);
        let hash = hasher
            .join()
            .map_err(|_| std::io::Error::other("the fingerprinting thread stopped"))?;
        written.map(|()| (bytes, hash))
    })
}

/// What [`commit_dir`] did.
#[derive(Debug, Default)]
pub struct Committed {
    /// The files written, under the result directory.
    pub written: Vec<PathBuf>,
    /// Leftovers of an interrupted earlier run that were cleaned up (or put back).
    pub recovered: Vec<String>,
    /// True when the run had to wait for another run writing the same directory.
    pub waited: bool,
}

/// The hidden siblings of `dir` that belong to cpm: `(lock, stage prefix, aside prefix)`.
fn dir_siblings(parent: &Path, name: &str) -> (PathBuf, String, String) {
    (
        parent.join(format!(".{name}.cpm-lock")),
        format!(".{name}.cpm-stage-"),
        format!(".{name}.cpm-old-"),
    )
}

/// Puts back or removes what an interrupted commit left beside `dir`.
fn recover(parent: &Path, name: &str, dir: &Path) -> Result<Vec<String>, OutputError> {
    let (_, stage_prefix, old_prefix) = dir_siblings(parent, name);
    let mut notes = Vec::new();
    let mut leftovers: Vec<PathBuf> = Vec::new();
    for e in std::fs::read_dir(parent).map_err(io_at(parent))? {
        let e = e.map_err(io_at(parent))?;
        let n = e.file_name().to_string_lossy().into_owned();
        if n.starts_with(&stage_prefix) || n.starts_with(&old_prefix) {
            leftovers.push(e.path());
        }
    }
    leftovers.sort();
    // An interrupted two-rename swap: the previous result was moved aside and the new one
    // not yet moved in. Put the previous one back.
    if std::fs::symlink_metadata(dir).is_err() {
        if let Some(old) = leftovers.iter().find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(&old_prefix))
        }) {
            std::fs::rename(old, dir).map_err(io_at(dir))?;
            notes.push(format!(
                "put back the previous result {} (an earlier run was interrupted while swapping)",
                dir.display()
            ));
        }
    }
    for p in leftovers.iter().filter(|p| p.exists()) {
        std::fs::remove_dir_all(p).map_err(io_at(p))?;
        notes.push(format!(
            "removed {} left by an interrupted run",
            p.display()
        ));
    }
    Ok(notes)
}

/// Swaps `stage` and `dir` in one step when the system can (Linux `RENAME_EXCHANGE`).
fn exchange(stage: &Path, dir: &Path) -> std::io::Result<bool> {
    if std::env::var_os("CPM_FAULT_NO_EXCHANGE").is_some_and(|v| v == "1") {
        return Ok(false);
    }
    #[cfg(target_os = "linux")]
    {
        use rustix::fs::{renameat_with, RenameFlags, CWD};
        match renameat_with(CWD, stage, CWD, dir, RenameFlags::EXCHANGE) {
            Ok(()) => Ok(true),
            Err(e)
                if e == rustix::io::Errno::INVAL
                    || e == rustix::io::Errno::NOSYS
                    || e == rustix::io::Errno::OPNOTSUPP =>
            {
                Ok(false)
            }
            Err(e) => Err(e.into()),
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (stage, dir);
        Ok(false)
    }
}

fn sync_dir(dir: &Path) {
    // Best effort: not every system lets a directory be opened and synced.
    if let Ok(f) = std::fs::File::open(dir) {
        let _ = f.sync_all();
    }
}

/// Hard-links (or copies) what is in `from` but is neither a new file nor an earlier cpm
/// output into `to`, so files of the user's in a result directory survive the swap.
fn carry_over(
    from: &Path,
    to: &Path,
    rel: &Path,
    skip: &BTreeSet<PathBuf>,
) -> Result<(), OutputError> {
    for e in std::fs::read_dir(from.join(rel)).map_err(io_at(from))? {
        let e = e.map_err(io_at(from))?;
        let r = rel.join(e.file_name());
        if skip.contains(&r) || r.as_os_str() == MANIFEST {
            continue;
        }
        let src = from.join(&r);
        let dst = to.join(&r);
        let ft = e.file_type().map_err(io_at(&src))?;
        if ft.is_dir() {
            std::fs::create_dir_all(&dst).map_err(io_at(&dst))?;
            carry_over(from, to, &r, skip)?;
        } else if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).map_err(io_at(&src))?;
        }
    }
    Ok(())
}

/// The files an earlier commit's manifest lists (empty without one).
fn manifest_files(dir: &Path) -> BTreeSet<PathBuf> {
    std::fs::read_to_string(dir.join(MANIFEST))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| {
            v["files"].as_array().map(|a| {
                a.iter()
                    .filter_map(|f| f["name"].as_str().map(PathBuf::from))
                    .collect()
            })
        })
        .unwrap_or_default()
}

/// Commits `set`, whose files all lie under `dir`, as one result directory, all or nothing.
///
/// Under a lock (`.NAME.cpm-lock` beside `dir`; a second run on the same directory waits for
/// the first), leftovers of an interrupted earlier commit are cleaned up, the new result is
/// staged in a sibling directory (with the files of the user's in `dir` that are not outputs
/// hard-linked over, and a manifest [`MANIFEST`] naming the run and every file with its
/// fingerprint), synced, and swapped in by one rename (Linux `RENAME_EXCHANGE`; elsewhere two
/// renames, undone if the second fails, and put back by the next run if interrupted). Output
/// names that are inputs of the run (`inputs`) or directories are refused before anything is
/// written.
pub fn commit_dir(
    set: OutputSet,
    dir: &Path,
    inputs: &[&Path],
    command: &str,
) -> Result<Committed, OutputError> {
    // Where: the directory's real parent and its name.
    match std::fs::symlink_metadata(dir) {
        Ok(m) if m.file_type().is_symlink() && !dir.is_dir() => {
            return Err(OutputError::Refused(format!(
                "--out {}: is a symbolic link to something that is not a directory",
                dir.display()
            )))
        }
        Ok(_) if !dir.is_dir() => {
            return Err(OutputError::Refused(format!(
                "--out {}: exists and is not a directory",
                dir.display()
            )))
        }
        _ => {}
    }
    let mut rels: Vec<(PathBuf, Contents)> = Vec::new();
    for (p, c) in set.into_files() {
        let rel = p.strip_prefix(dir).map_err(|_| {
            OutputError::Refused(format!(
                "{}: not inside the output directory {}",
                p.display(),
                dir.display()
            ))
        })?;
        rels.push((rel.to_path_buf(), c));
    }
    let absolute = if dir.is_dir() {
        std::fs::canonicalize(dir).map_err(io_at(dir))?
    } else {
        let parent = dir
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(io_at(parent))?;
        let name = dir.file_name().ok_or_else(|| {
            OutputError::Refused(format!("--out {}: not a directory name", dir.display()))
        })?;
        std::fs::canonicalize(parent)
            .map_err(io_at(parent))?
            .join(name)
    };
    let (Some(parent), Some(name)) = (absolute.parent(), absolute.file_name()) else {
        return Err(OutputError::Refused(format!(
            "--out {}: cannot be replaced (the root of the file system)",
            dir.display()
        )));
    };
    let name = name.to_string_lossy().into_owned();
    for (rel, _) in &rels {
        let p = dir.join(rel);
        if p.is_dir() {
            return Err(io_at(&p)(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                format!("{}: is a directory, not a file", p.display()),
            )));
        }
        refuse_inputs("--out", &p, inputs)?;
    }
    // The lock.
    let (lock_path, stage_prefix, old_prefix) = dir_siblings(parent, &name);
    let mut done = Committed::default();
    let lock = take_lock(&lock_path, &mut done.waited)?;
    fault_point("locked");
    done.recovered = recover(parent, &name, &absolute)?;
    fault_point("recovered");
    // The stage.
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let run_id = format!("{}-{nanos}", std::process::id());
    let stage = parent.join(format!("{stage_prefix}{run_id}"));
    let result = (|| {
        std::fs::create_dir(&stage).map_err(io_at(&stage))?;
        fault_point("staging-created");
        if absolute.is_dir() {
            let mut skip = manifest_files(&absolute);
            skip.extend(rels.iter().map(|(r, _)| r.clone()));
            carry_over(&absolute, &stage, Path::new(""), &skip)?;
        }
        fault_point("carried-over");
        let mut listed = Vec::new();
        for (rel, contents) in &rels {
            let p = stage.join(rel);
            if let Some(d) = p.parent() {
                std::fs::create_dir_all(d).map_err(io_at(d))?;
            }
            let _ = std::fs::remove_file(&p);
            let (bytes, hash) = write_fingerprinted(&p, contents).map_err(io_at(&dir.join(rel)))?;
            listed.push(serde_json::json!({
                "name": rel.to_string_lossy(),
                "bytes": bytes,
                "fnv1a64": format!("{hash:016x}"),
            }));
            fault_point("file-written");
        }
        let manifest = serde_json::json!({
            "written_by": format!("cpm {} {command}", env!("CARGO_PKG_VERSION")),
            "run_id": run_id,
            "files": listed,
        });
        let text = serde_json::to_string_pretty(&manifest).unwrap_or_default();
        write_synced(&stage.join(MANIFEST), text.as_bytes()).map_err(io_at(&dir.join(MANIFEST)))?;
        fault_point("manifest-written");
        sync_dir(&stage);
        fault_point("staged");
        // The swap.
        if absolute.exists() {
            if !exchange(&stage, &absolute).map_err(io_at(&absolute))? {
                let aside = parent.join(format!("{old_prefix}{run_id}"));
                std::fs::rename(&absolute, &aside).map_err(io_at(&absolute))?;
                fault_point("moved-aside");
                if let Err(e) = std::fs::rename(&stage, &absolute) {
                    let _ = std::fs::rename(&aside, &absolute);
                    return Err(io_at(&absolute)(e));
                }
                let _ = std::fs::rename(&aside, &stage);
            }
        } else {
            std::fs::rename(&stage, &absolute).map_err(io_at(&absolute))?;
        }
        sync_dir(parent);
        fault_point("swapped");
        Ok(())
    })();
    // The stage now holds the previous result (or, after a failure, the partial new one).
    let _ = std::fs::remove_dir_all(&stage);
    fault_point("cleaned");
    // The lock file goes while it is held: a run waiting on it finds it gone (or replaced)
    // once it has the lock, and takes the lock again on a new file (`take_lock`; where files
    // have no inode to compare, the lock file stays).
    if cfg!(unix) {
        let _ = std::fs::remove_file(&lock_path);
    }
    drop(lock);
    result?;
    done.written = rels.into_iter().map(|(r, _)| dir.join(r)).collect();
    Ok(done)
}

/// Takes the lock `lock_path` (creating the file), waiting for another run that holds it
/// (`waited` is then set). The lock counts only when the file locked is still the one at
/// `lock_path` (the run before may have removed it after its commit): otherwise it is taken
/// again.
fn take_lock(lock_path: &Path, waited: &mut bool) -> Result<std::fs::File, OutputError> {
    loop {
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(lock_path)
            .map_err(io_at(lock_path))?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                *waited = true;
                lock.lock().map_err(io_at(lock_path))?;
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io_at(lock_path)(e)),
        }
        if locked_file_is_at(&lock, lock_path) {
            return Ok(lock);
        }
    }
}

/// True when `path` names the open file `file` (same device and inode).
#[cfg(unix)]
fn locked_file_is_at(file: &std::fs::File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Without inodes to compare, the lock file is trusted as it is.
#[cfg(not(unix))]
fn locked_file_is_at(_file: &std::fs::File, _path: &Path) -> bool {
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What a file holds, fingerprinted once in line from its bytes on disk.
    fn on_disk(path: &Path) -> (usize, u64) {
        let bytes = std::fs::read(path).unwrap();
        (bytes.len(), fingerprint(&bytes))
    }

    #[test]
    fn fingerprints_made_aside_are_those_of_the_bytes_written() {
        let scratch = tempfile::Builder::new()
            .prefix("cpm-fingerprint-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        // Streamed across several hash chunks (aside; in the writer's pieces, 1 MiB by direct
        // I/O, row by row through the page cache), a large buffer not a whole number of
        // chunks (aside), a small one (in line), and nothing at all.
        let streamed = Contents::Streamed(Box::new(|out: &mut dyn std::io::Write| {
            for i in 0..200_000u32 {
                writeln!(out, "{i},{}", i.wrapping_mul(2_654_435_761))?;
            }
            Ok(())
        }));
        let large: Vec<u8> = (0..(3 * HASH_CHUNK + 17))
            .map(|i| (i % 251) as u8)
            .collect();
        let cases = [
            ("streamed.csv", streamed),
            ("large.bin", Contents::Bytes(large)),
            ("small.txt", Contents::Bytes(b"a,b\n1,2\n".to_vec())),
            ("empty.txt", Contents::Bytes(Vec::new())),
        ];
        for (name, contents) in &cases {
            let path = dir.join(name);
            let made = write_fingerprinted(&path, contents).unwrap();
            assert_eq!(made, on_disk(&path), "{name}");
        }
        assert!(on_disk(&dir.join("streamed.csv")).0 > 2 * HASH_CHUNK);
    }
}
