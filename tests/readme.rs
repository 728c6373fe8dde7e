//! The shell blocks of README.md and docs/cli.md run as written: each ```sh block is run by
//! bash in a scratch directory holding a copy of `examples/` (as the repository's root holds
//! it), with the `cpm` under test first on the PATH (the blocks' `cargo`, `pip` and `python`
//! lines are dropped: CI runs those). Synopses (`cpm calibrate --robot R.toml [--json]`) are
//! not commands and are skipped. Then the files each walk-through promises are checked, and
//! what they say: validation improves on the reference, the compensation reaches the targets,
//! the exported INI has a section per joint, the walk-through wrote only into its scratch
//! folder and left no lock behind.
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The first ```sh block after `heading` in `file`.
fn block_after(file: &str, heading: &str) -> String {
    let text = std::fs::read_to_string(root().join(file)).unwrap();
    let at = text
        .find(heading)
        .unwrap_or_else(|| panic!("{file}: no {heading:?}"));
    let rest = &text[at..];
    let start = rest.find("```sh\n").expect("a sh block") + 6;
    let end = rest[start..].find("\n```").expect("its end") + start;
    rest[start..end].to_string()
}

/// A scratch directory with a copy of examples/.
fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("readme-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(d.join("examples")).unwrap();
    for e in std::fs::read_dir(root().join("examples")).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), d.join("examples").join(e.file_name())).unwrap();
        }
    }
    d
}

/// Every ```sh block of `file`, with the heading above it.
fn blocks(file: &str) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(root().join(file)).unwrap();
    let mut out = Vec::new();
    let mut heading = String::new();
    let mut lines = text.lines();
    while let Some(l) = lines.next() {
        if l.starts_with('#') {
            heading = l.to_string();
        } else if l.trim_start() == "```sh" {
            let body: Vec<&str> = lines.by_ref().take_while(|l| l.trim() != "```").collect();
            out.push((heading.clone(), body.join("\n")));
        }
    }
    out
}

/// A synopsis, not a command: optional parts in brackets or alternatives in parentheses.
fn is_synopsis(block: &str) -> bool {
    block.contains(" [--") || block.contains("(--")
}

/// The block without its `cargo`, `pip` and `python` commands (and their continuation lines).
fn runnable(block: &str) -> String {
    let mut out = Vec::new();
    let mut skipping = false;
    for l in block.lines() {
        let first = l.split_whitespace().next().unwrap_or("");
        let starts = !skipping && matches!(first, "cargo" | "pip" | "python" | "python3");
        if !(skipping || starts) {
            out.push(l);
        }
        skipping = (skipping || starts) && l.trim_end().ends_with('\\');
    }
    out.join("\n")
}

/// The files and folders directly in `dir`.
fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Every `.cpm-lock` file under `dir`.
fn locks(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            out.extend(locks(&e.path()));
        } else if e.file_name().to_string_lossy().ends_with(".cpm-lock") {
            out.push(e.path());
        }
    }
    out
}

fn run_block(dir: &Path, block: &str) -> String {
    let script = runnable(block);
    let bin = Path::new(env!("CARGO_BIN_EXE_cpm")).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("bash")
        .args(["-euo", "pipefail", "-c", &script])
        .current_dir(dir)
        .env("PATH", path)
        .output()
        .expect("run bash");
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "the walk-through failed ({:?}):\n--- script\n{script}\n--- stdout\n{stdout}\n--- stderr\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn readme_walk_through_runs_as_written() {
    let top = scratch("readme");
    let block = block_after("README.md", "## The cpm command");
    assert!(block.contains("cpm validate") && block.contains("cpm export"));
    run_block(&top, &block);
    // Everything went into the scratch folder, which git ignores, and no lock is left.
    assert_eq!(
        entries(&top),
        ["examples", "scratch"],
        "written beside scratch/"
    );
    let ignore = std::fs::read_to_string(root().join(".gitignore")).unwrap();
    assert!(ignore.lines().any(|l| l == "/scratch/"), "{ignore}");
    assert_eq!(
        locks(&top),
        Vec::<PathBuf>::new(),
        "locks left after clean runs"
    );
    let dir = top.join("scratch/tour");
    for f in [
        "design/robot.toml",
        "design/poses.csv",
        "data.csv",
        "held_out.csv",
        "cal/calibration.json",
        "cal/report.md",
        "refined/calibrated.toml",
        "validation/validation.json",
        "validation/report.md",
        "validation/report.html",
        "compensation/report.md",
        "compensation/report.html",
        "validation/validation.svg",
        "commands.csv",
        "joints.ini",
    ] {
        assert!(dir.join(f).is_file(), "{f} was not written");
    }
    // Provenance: the simulated file names the effect it carries.
    let data = std::fs::read_to_string(dir.join("data.csv")).unwrap();
    let header = data.lines().next().unwrap();
    assert!(
        header.starts_with("# simulated by cpm")
            && header.contains("--truth-effect backlash=-8,6,-10,5,-7,9"),
        "{header}"
    );
    // The refined calibration predicts the held-out campaign better than the nominal robot.
    let v = json(&dir.join("validation/validation.json"));
    let (c, r) = (
        v["calibrated"]["rms_um"].as_f64().unwrap(),
        v["reference"]["rms_um"].as_f64().unwrap(),
    );
    println!("README walk-through, held-out RMS: calibrated {c:.3} um, nominal {r:.3} um");
    assert!(c < 0.2 * r, "calibrated {c} um vs reference {r} um");
    assert_eq!(v["simulated"], serde_json::json!(true));
    let ini = std::fs::read_to_string(dir.join("joints.ini")).unwrap();
    for j in 0..6 {
        assert!(ini.contains(&format!("[JOINT_{j}]")), "{ini}");
    }
    // The compensation, checked end to end by the block's last command: the simulated true
    // machine (the truth plus the backlash the data carried) executes commands.csv.
    let v = json(&dir.join("compensation/compensation.json"));
    let (c, u) = (
        v["compensated"]["position_rms_um"].as_f64().unwrap(),
        v["reference"]["position_rms_um"].as_f64().unwrap(),
    );
    println!(
        "README walk-through, pose error reached: compensated {c:.3} um, uncompensated {u:.3} um"
    );
    assert!(
        c < 1.0 && c < 0.05 * u,
        "compensated {c} um, uncompensated {u} um"
    );
    let commands = std::fs::read_to_string(dir.join("commands.csv")).unwrap();
    let targets = std::fs::read_to_string(dir.join("examples/targets.csv")).unwrap();
    let count = |t: &str| {
        t.lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .count()
    };
    assert_eq!(
        count(&commands),
        count(&targets),
        "one command row per target"
    );
}

#[test]
fn cli_md_walk_through_runs_as_written() {
    let top = scratch("cli-md");
    let block = block_after("docs/cli.md", "## Walk-through on the 6-6 hexapod");
    let stdout = run_block(&top, &block);
    assert_eq!(
        entries(&top),
        ["examples", "scratch"],
        "written beside scratch/"
    );
    assert_eq!(
        locks(&top),
        Vec::<PathBuf>::new(),
        "locks left after clean runs"
    );
    let dir = top.join("scratch/walk");
    assert!(dir.join("cal/calibrated.toml").is_file());
    assert!(dir.join("commands.csv").is_file());
    assert!(stdout.contains("setp genhexkins.base.0.x"), "{stdout}");
}

/// Every other shell block of README.md and docs/cli.md (the two walk-throughs above have
/// their own tests) runs as written, each in a scratch directory of its own.
#[test]
fn every_other_shell_block_runs_as_written() {
    let walk_throughs = ["## The cpm command", "## Walk-through on the 6-6 hexapod"];
    let (mut ran, mut synopses) = (0, 0);
    for file in ["README.md", "docs/cli.md"] {
        for (k, (heading, block)) in blocks(file).into_iter().enumerate() {
            if walk_throughs.iter().any(|w| heading.starts_with(w)) {
                continue;
            }
            if is_synopsis(&block) {
                synopses += 1;
                continue;
            }
            if runnable(&block).trim().is_empty() {
                continue;
            }
            let dir = scratch(&format!("block-{}-{k}", file.replace(['/', '.'], "-")));
            run_block(&dir, &block);
            ran += 1;
        }
    }
    println!("{ran} shell blocks ran, {synopses} synopses skipped");
    assert!(ran >= 1 && synopses >= 8, "{ran} ran, {synopses} synopses");
}
