//! Every example of `cpm --help` and `cpm <command> --help` runs as written, copied into a
//! shell in a scratch directory holding a copy of `examples/`: the files an example names are
//! the repository's examples or the outputs of an example before it (the commands are run in
//! the order a newcomer would: simulate, look, design, fit, check, compensate, export).
use std::path::{Path, PathBuf};
use std::process::Command;

fn cpm() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_cpm"))
}

/// The lines under `Examples:` of `cpm [command] --help`.
fn examples(command: Option<&str>) -> Vec<String> {
    let mut c = Command::new(cpm());
    if let Some(command) = command {
        c.arg(command);
    }
    let out = c.arg("--help").output().expect("run cpm --help");
    assert!(out.status.success(), "cpm {command:?} --help failed");
    let help = String::from_utf8(out.stdout).unwrap();
    let at = help
        .find("Examples:\n")
        .unwrap_or_else(|| panic!("cpm {command:?} --help has no Examples:\n{help}"));
    help[at + "Examples:\n".len()..]
        .lines()
        .take_while(|l| l.starts_with("  "))
        .map(|l| l.trim().to_string())
        .filter(|l| !l.is_empty())
        .collect()
}

fn scratch() -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("help-examples");
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(d.join("examples")).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for e in std::fs::read_dir(root.join("examples")).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), d.join("examples").join(e.file_name())).unwrap();
        }
    }
    d
}

#[test]
fn every_help_example_runs_as_written() {
    let dir = scratch();
    let bin = cpm().parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let commands = [
        None,
        Some("simulate"),
        Some("identifiability"),
        Some("design"),
        Some("calibrate"),
        Some("refine"),
        Some("compensate"),
        Some("validate"),
        Some("export"),
    ];
    let mut ran = 0;
    for command in commands {
        let lines = examples(command);
        assert!(!lines.is_empty(), "cpm {command:?} --help: no examples");
        for line in lines {
            assert!(line.starts_with("cpm "), "not a cpm command: {line}");
            let out = Command::new("bash")
                .args(["-euo", "pipefail", "-c", &line])
                .current_dir(&dir)
                .env("PATH", &path)
                .output()
                .expect("run bash");
            assert!(
                out.status.success(),
                "an example of `cpm {} --help` failed ({:?}):\n{line}\n--- stdout\n{}\n--- stderr\n{}",
                command.unwrap_or(""),
                out.status.code(),
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            ran += 1;
        }
    }
    println!("{ran} help examples ran");
    // Nothing the examples write lands outside the scratch directory, and no lock is left.
    let locks: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".cpm-lock"))
        .collect();
    assert!(locks.is_empty(), "locks left after clean runs: {locks:?}");
}
