//! Helpers shared by the command-line tests: example paths, scratch directories, running the
//! `cpm` under test. Each test binary uses what it needs.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The path of a shipped example, `examples/<name>`.
pub fn example(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
        .display()
        .to_string()
}

/// A fresh scratch directory `<prefix>-<name>` for one test.
pub fn scratch(prefix: &str, name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{prefix}-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `cpm args`.
pub fn cpm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(args)
        .output()
        .expect("run cpm")
}

/// Runs `cpm args`, which must succeed; its standard output.
pub fn ok(args: &[&str]) -> String {
    let o = cpm(args);
    assert!(
        o.status.success(),
        "cpm {args:?} failed ({:?}):\n{}{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// A path as an argument.
pub fn p(path: &Path) -> String {
    path.display().to_string()
}
