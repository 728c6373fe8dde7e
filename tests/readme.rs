//! The walk-throughs of README.md and docs/cli.md run as written: each `sh` block is run by
//! bash in a scratch directory holding a copy of `examples/`, with the `cpm` under test first
//! on the PATH (the block's own `cargo build` line is dropped). Then the files each step
//! promises are checked, and what they say: validation improves on the reference, the
//! exported INI has a section per joint.
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

fn run_block(dir: &Path, block: &str) -> String {
    let script: String = block
        .lines()
        .filter(|l| !l.trim_start().starts_with("cargo build"))
        .collect::<Vec<_>>()
        .join("\n");
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
    let dir = scratch("readme");
    let block = block_after("README.md", "## The cpm command");
    assert!(block.contains("cpm validate") && block.contains("cpm export"));
    run_block(&dir, &block);
    for f in [
        "design/robot.toml",
        "design/poses.csv",
        "data.csv",
        "held_out.csv",
        "cal/calibration.json",
        "cal/report.md",
        "refined/calibrated.toml",
        "validation/validation.json",
        "validation/validation.md",
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
    // The compensation, checked end to end: the simulated true machine (the truth plus the
    // backlash the data carried) executes commands.csv.
    let truth = std::fs::read_to_string(dir.join("examples/hexapod_66_truth.toml")).unwrap();
    std::fs::write(
        dir.join("truth_backlash.toml"),
        format!("{truth}\n[calibration.known_effects]\nbacklash = [-8, 6, -10, 5, -7, 9]\n"),
    )
    .unwrap();
    run_block(
        &dir,
        "cpm validate --reference design/robot.toml --commands commands.csv --truth truth_backlash.toml --out compensation/",
    );
    let v = json(&dir.join("compensation/compensation.json"));
    let (c, u) = (
        v["compensated"]["position_rms_um"].as_f64().unwrap(),
        v["reference"]["position_rms_um"].as_f64().unwrap(),
    );
    println!(
        "README walk-through, pose error reached: compensated {c:.3} um, uncompensated {u:.3} um"
    );
    assert!(
        c < 5.0 && c < 0.05 * u,
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
    let dir = scratch("cli-md");
    let block = block_after("docs/cli.md", "## Walk-through on the 6-6 hexapod");
    let stdout = run_block(&dir, &block);
    assert!(dir.join("cal/calibrated.toml").is_file());
    assert!(dir.join("commands.csv").is_file());
    assert!(stdout.contains("setp genhexkins.base.0.x"), "{stdout}");
}
