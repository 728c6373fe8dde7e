//! What a newcomer's first hour runs into (issue 35): `calibrate` says when its residual has
//! structure the model lacks, `validate --commands` checks a compensation on the machine the
//! campaign was simulated on (`--truth-effect`), a calibrated file can move with its nominal
//! description, and a calibration result is not announced on every command. All data are
//! SIMULATED from the examples.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn examples(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
        .display()
        .to_string()
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("newcomer-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cpm(dir: &Path, args: &[&str]) -> Output {
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "cpm {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

const BACKLASH: &str = "backlash=-8,6,-10,5,-7,9";

/// A campaign of the example machine (its truth), with an undeclared backlash or without.
fn simulate(dir: &Path, out: &str, backlash: bool, seed: &str) {
    let (robot, truth) = (
        examples("hexapod_66.toml"),
        examples("hexapod_66_truth.toml"),
    );
    let mut args = vec![
        "simulate",
        "--robot",
        &robot,
        "--random",
        "80",
        "--truth",
        &truth,
        "--noise",
        "gaussian:1",
        "--seed",
        seed,
        "--out",
        out,
    ];
    if backlash {
        args.extend(["--truth-effect", BACKLASH]);
    }
    cpm(dir, &args);
}

/// The residual of a fit without the backlash the data carry is not white, and with the
/// noise left undeclared nothing else says so (the README's story: a designed campaign, 13 um
/// of residual for 1 um of noise): `calibrate` warns (stderr, report.md, calibration.json) and
/// points to `cpm refine`. The same campaign without the backlash raises no warning.
#[test]
fn calibrate_warns_when_the_residual_is_not_white() {
    let dir = scratch("white");
    let (robot, truth) = (
        examples("hexapod_66.toml"),
        examples("hexapod_66_truth.toml"),
    );
    cpm(
        &dir,
        &[
            "design",
            "--robot",
            &robot,
            "--readings",
            "360",
            "--out",
            "design",
        ],
    );
    for (out, backlash) in [("backlash.csv", true), ("clean.csv", false)] {
        let mut args = vec![
            "simulate",
            "--robot",
            "design/robot.toml",
            "--plan",
            "design/poses.csv",
            "--truth",
            &truth,
            "--noise",
            "gaussian:1",
            "--seed",
            "1",
            "--out",
            out,
        ];
        if backlash {
            args.extend(["--truth-effect", BACKLASH]);
        }
        cpm(&dir, &args);
    }
    let o = cpm(
        &dir,
        &[
            "calibrate",
            "--robot",
            "design/robot.toml",
            "--data",
            "backlash.csv",
            "--out",
            "cal",
        ],
    );
    let err = stderr(&o);
    assert!(
        err.contains("The residual is not white") && err.contains("cpm refine"),
        "{err}"
    );
    let j = json(&dir.join("cal/calibration.json"));
    assert!(
        j["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().starts_with("The residual is not white")),
        "{}",
        j["warnings"]
    );
    let md = std::fs::read_to_string(dir.join("cal/report.md")).unwrap();
    assert!(md.contains("**The residual is not white**"), "{md}");
    let o = cpm(
        &dir,
        &[
            "calibrate",
            "--robot",
            "design/robot.toml",
            "--data",
            "clean.csv",
            "--out",
            "clean",
        ],
    );
    assert!(!stderr(&o).contains("not white"), "{}", stderr(&o));
    let j = json(&dir.join("clean/calibration.json"));
    assert!(
        !j["warnings"].to_string().contains("not white"),
        "{}",
        j["warnings"]
    );
}

/// The compensation check runs on the machine the campaign was simulated on: `--truth T
/// --truth-effect E=V` is the truth with `[calibration.known_effects] E = V` written in, as
/// `cpm simulate` takes it.
#[test]
fn validate_commands_takes_the_truth_effects_of_simulate() {
    let dir = scratch("truth-effect");
    let (robot, truth) = (
        examples("hexapod_66.toml"),
        examples("hexapod_66_truth.toml"),
    );
    simulate(&dir, "data.csv", true, "3");
    cpm(
        &dir,
        &[
            "calibrate",
            "--robot",
            &robot,
            "--data",
            "data.csv",
            "--effects",
            "backlash",
            "--out",
            "cal",
        ],
    );
    let targets = examples("targets.csv");
    cpm(
        &dir,
        &[
            "compensate",
            "--robot",
            "cal/calibrated.toml",
            "--poses",
            &targets,
            "--from-home",
            "--out",
            "commands.csv",
        ],
    );
    let written = std::fs::read_to_string(&truth).unwrap();
    std::fs::write(
        dir.join("truth_backlash.toml"),
        format!("{written}\n[calibration.known_effects]\nbacklash = [-8, 6, -10, 5, -7, 9]\n"),
    )
    .unwrap();
    let check = |truth: &str, truth_effect: Option<&str>| -> serde_json::Value {
        let mut args = vec![
            "validate",
            "--reference",
            &robot,
            "--commands",
            "commands.csv",
            "--from-home",
            "--truth",
            truth,
            "--json",
        ];
        if let Some(t) = truth_effect {
            args.extend(["--truth-effect", t]);
        }
        let o = cpm(&dir, &args);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["compensated"].clone()
    };
    let flag = check(&truth, Some(BACKLASH));
    let file = check("truth_backlash.toml", None);
    let without = check(&truth, None);
    println!("compensated: {flag} with --truth-effect, {file} written in, {without} without");
    assert_eq!(flag, file);
    assert_ne!(flag, without);
    // A value count that does not fit the effect is a usage error naming the option.
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args([
            "validate",
            "--reference",
            &robot,
            "--commands",
            "commands.csv",
            "--truth",
            &truth,
            "--truth-effect",
            "backlash=1,2",
        ])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--truth-effect"), "{}", stderr(&o));
}

/// `calibrated.toml` records its nominal description relative to itself, with a content
/// fingerprint: the two move together and `validate` still finds the reference; a changed
/// reference is noted; a missing one is asked for by name. Reading a calibration result is
/// not announced on every command.
#[test]
fn calibrated_from_moves_with_the_files() {
    let dir = scratch("moves");
    let work = dir.join("work");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::copy(examples("hexapod_66.toml"), work.join("robot.toml")).unwrap();
    simulate(&work, "data.csv", false, "5");
    simulate(&work, "held_out.csv", false, "6");
    cpm(
        &work,
        &[
            "calibrate",
            "--robot",
            "robot.toml",
            "--data",
            "data.csv",
            "--out",
            "cal",
        ],
    );
    let toml = std::fs::read_to_string(work.join("cal/calibrated.toml")).unwrap();
    assert!(
        toml.contains("calibrated_from = \"../robot.toml\"")
            && toml.contains("calibrated_from_fnv1a64 = \""),
        "{toml}"
    );
    // Moved elsewhere, together.
    let moved = dir.join("moved");
    std::fs::rename(&work, &moved).unwrap();
    let o = cpm(
        &moved,
        &[
            "validate",
            "--robot",
            "cal/calibrated.toml",
            "--data",
            "held_out.csv",
        ],
    );
    let err = stderr(&o);
    assert!(!err.contains("installation_errors_um"), "{err}");
    assert!(!err.contains("changed since"), "{err}");
    // The reference edited since: a note.
    let robot = std::fs::read_to_string(moved.join("robot.toml")).unwrap();
    std::fs::write(moved.join("robot.toml"), format!("{robot}\n# edited\n")).unwrap();
    let o = cpm(
        &moved,
        &[
            "validate",
            "--robot",
            "cal/calibrated.toml",
            "--data",
            "held_out.csv",
        ],
    );
    assert!(stderr(&o).contains("changed since"), "{}", stderr(&o));
    // Other commands that read the calibration result say nothing about its errors.
    let targets = examples("targets.csv");
    for args in [
        vec![
            "compensate",
            "--robot",
            "cal/calibrated.toml",
            "--poses",
            &targets,
        ],
        vec![
            "export",
            "--format",
            "linuxcnc",
            "--robot",
            "cal/calibrated.toml",
        ],
    ] {
        let o = cpm(&moved, &args);
        assert!(
            !stderr(&o).contains("installation_errors_um"),
            "{args:?}: {}",
            stderr(&o)
        );
    }
    // Without it: usage error, naming what to give.
    std::fs::remove_file(moved.join("robot.toml")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args([
            "validate",
            "--robot",
            "cal/calibrated.toml",
            "--data",
            "held_out.csv",
        ])
        .current_dir(&moved)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--reference"), "{}", stderr(&o));
}

/// `refine` on gauge readings without temperatures does not offer a tracker frame or a
/// thermal drift (nor say a better design could see them): they do not apply, and it says so.
#[test]
fn refine_offers_only_candidates_that_apply() {
    let dir = scratch("refine");
    let robot = examples("hexapod_66.toml");
    simulate(&dir, "data.csv", true, "7");
    let o = cpm(
        &dir,
        &[
            "refine",
            "--robot",
            &robot,
            "--data",
            "data.csv",
            "--max-steps",
            "1",
            "--folds",
            "3",
            "--pose-map-degree",
            "0",
            "--out",
            "refined",
        ],
    );
    let j = json(&dir.join("refined/refine.json"));
    let not: Vec<&str> = j["not_applicable"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["effect"].as_str().unwrap())
        .collect();
    assert!(
        not.contains(&"tracker_frame") && not.contains(&"thermal_drift"),
        "{not:?}"
    );
    let tried = j.to_string();
    for e in ["tracker_frame", "thermal_drift"] {
        let in_rounds = j["last_round"]
            .as_array()
            .unwrap()
            .iter()
            .chain(j["steps"].as_array().unwrap())
            .any(|c| c.to_string().contains(e));
        assert!(!in_rounds, "{e} offered: {tried}");
    }
    let md = std::fs::read_to_string(dir.join("refined/report.md")).unwrap();
    assert!(md.contains("do not apply to these data"), "{md}");
    assert!(!stderr(&o).contains("tracker_frame"), "{}", stderr(&o));
}

/// The most significant digits of any numeric field of a CSV text (comments left out).
fn max_digits(csv: &str) -> (usize, String) {
    let mut worst = (0, String::new());
    for line in csv.lines().filter(|l| !l.starts_with('#')) {
        for f in line.split(',') {
            if f.parse::<f64>().is_err() || f.chars().any(|c| c.is_ascii_alphabetic() && c != 'e') {
                continue;
            }
            let d = f
                .split(['e', 'E'])
                .next()
                .unwrap()
                .trim_start_matches(['-', '+', '0', '.'])
                .bytes()
                .filter(u8::is_ascii_digit)
                .count();
            if d > worst.0 {
                worst = (d, f.to_string());
            }
        }
    }
    worst
}

/// Numbers as docs/cli.md promises: the CSV files of `design` and `compensate` carry at most
/// 12 significant digits; `simulate` writes a plan's angles as the plan gives them; the
/// export's comments carry no full-precision float.
#[test]
fn numbers_in_files_are_as_documented() {
    let dir = scratch("numbers");
    let robot = examples("hexapod_66.toml");
    std::fs::write(
        dir.join("plan.csv"),
        "pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n1,1.5,-2,300,3.30054776056,-1.25,0.1\n2,0,0,310,0,2.2,-3.30054776056\n",
    )
    .unwrap();
    let truth = examples("hexapod_66_truth.toml");
    cpm(
        &dir,
        &[
            "simulate", "--robot", &robot, "--plan", "plan.csv", "--truth", &truth, "--out",
            "data.csv",
        ],
    );
    let data = std::fs::read_to_string(dir.join("data.csv")).unwrap();
    assert!(
        data.contains(",3.30054776056,") && data.contains(",-3.30054776056,"),
        "{data}"
    );
    cpm(
        &dir,
        &[
            "design",
            "--robot",
            &robot,
            "--readings",
            "60",
            "--candidates",
            "100",
            "--out",
            "design",
        ],
    );
    simulate(&dir, "fit.csv", true, "9");
    cpm(
        &dir,
        &[
            "calibrate",
            "--robot",
            &robot,
            "--data",
            "fit.csv",
            "--effects",
            "backlash",
            "--out",
            "cal",
        ],
    );
    let targets = examples("targets.csv");
    cpm(
        &dir,
        &[
            "compensate",
            "--robot",
            "cal/calibrated.toml",
            "--poses",
            &targets,
            "--out",
            "commands.csv",
        ],
    );
    for f in ["design/poses.csv", "design/sockets.csv", "commands.csv"] {
        let (d, field) = max_digits(&std::fs::read_to_string(dir.join(f)).unwrap());
        assert!(d <= 12, "{f}: {field} has {d} significant digits");
    }
    let o = cpm(
        &dir,
        &[
            "export",
            "--format",
            "linuxcnc",
            "--robot",
            "cal/calibrated.toml",
        ],
    );
    let hal = String::from_utf8_lossy(&o.stdout);
    assert_eq!(cpm::report::format::find_artefact(&hal), None, "{hal}");
}
