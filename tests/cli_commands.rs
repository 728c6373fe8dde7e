//! End-to-end tests of the `cpm` binary on the shipped examples: simulate -> calibrate ->
//! compensate, identifiability, refine, export, and what bad input and bad usage give.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use cpm::geometry::{InstallationErrors, Pose, RobotDescription};
use cpm::io::Robot;

fn example(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
        .display()
        .to_string()
}

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cpm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(args)
        .output()
        .expect("run cpm")
}

fn ok(args: &[&str]) -> String {
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

fn p(path: &Path) -> String {
    path.display().to_string()
}

/// The hexapod example with the paper's Table 2 as its installation errors: the true machine.
fn write_truth(dir: &Path) -> PathBuf {
    let mut d = RobotDescription::load(example("hexapod_66.toml")).unwrap();
    d.installation_errors_um = Some(
        cpm::geometry::description::InstallationErrorsSpec::from_errors(
            &InstallationErrors::paper_table2(),
        ),
    );
    let path = dir.join("truth.toml");
    std::fs::write(&path, d.to_toml_string().unwrap()).unwrap();
    path
}

/// A JSON file written by `cpm`.
fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The `reading_k` columns of a commands file.
fn read_commands(text: &str) -> Vec<Vec<f64>> {
    command_columns(text, |k| format!("reading_{k}"))
}

/// The `length_k_mm` columns of a commands file.
fn read_command_lengths(text: &str) -> Vec<Vec<f64>> {
    command_columns(text, |k| format!("length_{k}_mm"))
}

/// The six columns `name(1)..name(6)` of a commands file, row by row.
fn command_columns(text: &str, name: impl Fn(usize) -> String) -> Vec<Vec<f64>> {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let cols: Vec<usize> = (1..=6)
        .map(|k| header.iter().position(|h| *h == name(k)).unwrap())
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            cols.iter().map(|&c| f[c].parse().unwrap()).collect()
        })
        .collect()
}

/// `n` random targets about `robot_path`'s home (seed `seed`) written to `d/targets.csv`, and
/// `cpm compensate` of them with `calibrated` into `d/commands.csv` (`--json` when `json`):
/// the targets, both paths and what the command printed.
fn compensate_random_targets(
    d: &Path,
    robot_path: &str,
    calibrated: &Path,
    n: usize,
    seed: u64,
    json: bool,
) -> (Vec<Pose>, PathBuf, PathBuf, String) {
    let nominal = Robot::load(Path::new(robot_path)).unwrap();
    let targets =
        cpm::calib::paper::random_workspace_poses(&nominal.table, n, 40.0, 8.0, 3.0, seed);
    let targets_path = d.join("targets.csv");
    std::fs::write(&targets_path, cpm::io::write_pose_list(&targets)).unwrap();
    let commands = d.join("commands.csv");
    let mut args = vec![
        "compensate".to_string(),
        "--robot".into(),
        p(calibrated),
        "--poses".into(),
        p(&targets_path),
        "--out".into(),
        p(&commands),
    ];
    if json {
        args.push("--json".into());
    }
    let out = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    (targets, targets_path, commands, out)
}

/// `cpm simulate` (60 random poses of `robot_path`'s machine with the errors of
/// `truth_path`, `noise`, `seed`, no effects) into `data`, then `cpm calibrate` of them (no
/// effects) into `cal`: its `--json` summary.
fn simulate_and_calibrate(
    robot_path: &str,
    truth_path: &Path,
    noise: &str,
    seed: &str,
    data: &Path,
    cal: &Path,
) -> String {
    ok(&[
        "simulate",
        "--robot",
        robot_path,
        "--random",
        "60",
        "--truth",
        &p(truth_path),
        "--noise",
        noise,
        "--seed",
        seed,
        "--effects",
        "none",
        "--out",
        &p(data),
    ]);
    ok(&[
        "calibrate",
        "--robot",
        robot_path,
        "--data",
        &p(data),
        "--effects",
        "none",
        "--out",
        &p(cal),
        "--json",
    ])
}

#[test]
fn simulate_calibrate_compensate_reduces_the_pose_error() {
    let d = scratch("round-trip");
    let robot_path = example("hexapod_66.toml");
    let truth_path = write_truth(&d);
    let (data, cal) = (d.join("data.csv"), d.join("cal"));
    let out = simulate_and_calibrate(&robot_path, &truth_path, "gaussian:0.2", "5", &data, &cal);
    let text = std::fs::read_to_string(&data).unwrap();
    assert!(text.starts_with("# simulated by cpm"));
    let summary: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(summary["simulated"], true);
    assert_eq!(summary["rank"], 36);
    for f in [
        "calibration.json",
        "report.md",
        "calibrated.toml",
        "residuals_pose.svg",
        "estimates.svg",
    ] {
        assert!(cal.join(f).exists(), "{f} missing");
    }
    let json = read_json(&cal.join("calibration.json"));
    assert_eq!(json["simulated"], true);
    assert_eq!(
        json["installation_errors_um"]["base"]
            .as_array()
            .unwrap()
            .len(),
        6
    );
    assert_eq!(json["std_um"]["platform"][5].as_array().unwrap().len(), 3);
    assert!(json["residual_rms_um"].as_f64().unwrap() < 0.5);
    let report = std::fs::read_to_string(cal.join("report.md")).unwrap();
    assert!(report.contains("SIMULATED"));

    // Targets away from the calibration poses.
    let truth = Robot::load(&truth_path).unwrap();
    let (targets, targets_path, commands, _) =
        compensate_random_targets(&d, &robot_path, &cal.join("calibrated.toml"), 20, 99, false);
    let calibrated = read_commands(&std::fs::read_to_string(&commands).unwrap());
    assert_eq!(calibrated.len(), 20);
    // The nominal commands, through the same command for comparison.
    let nominal_commands = d.join("nominal.csv");
    ok(&[
        "compensate",
        "--robot",
        &robot_path,
        "--poses",
        &p(&targets_path),
        "--out",
        &p(&nominal_commands),
    ]);
    let nominal_readings = read_commands(&std::fs::read_to_string(&nominal_commands).unwrap());
    let before = reached_error_um(&truth, &[0.0; 6], &targets, &nominal_readings);
    let after = reached_error_um(&truth, &[0.0; 6], &targets, &calibrated);
    assert!(before > 30.0, "the truth should be visible: {before} um");
    assert!(
        after < 0.1 * before,
        "nominal {before:.2} um, calibrated {after:.2} um"
    );

    // Export of the calibrated joints.
    let hal = ok(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &p(&cal.join("calibrated.toml")),
    ]);
    let setp: Vec<&str> = hal.lines().filter(|l| l.starts_with("setp ")).collect();
    assert_eq!(setp.len(), 36);
    assert!(setp[0].starts_with("setp genhexkins.base.0.x "));
    assert!(setp[35].starts_with("setp genhexkins.platform.5.z "));
    let cal_robot = Robot::load(&cal.join("calibrated.toml")).unwrap();
    let x: f64 = setp[0].rsplit(' ').next().unwrap().parse().unwrap();
    assert!((x - cal_robot.table.links[0].base_mm.x).abs() < 1e-6);
}

#[test]
fn paper_design_reports_what_it_cannot_determine() {
    let d = scratch("paper");
    let robot = example("paper_cubic.toml");
    let data = d.join("paper.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--circle",
        "--paper-table2",
        "--noise",
        "uniform:10",
        "--seed",
        "2002",
        "--effects",
        "none",
        "--out",
        &p(&data),
    ]);
    let out = ok(&[
        "identifiability",
        "--robot",
        &robot,
        "--data",
        &p(&data),
        "--effects",
        "none",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rank = v["rank"].as_u64().unwrap();
    assert!(rank < 36, "rank {rank}");
    assert!(!v["blind_directions"].as_array().unwrap().is_empty());
    assert_eq!(v["simulated"], true);
    // The plan alone gives the same rank.
    let out = ok(&[
        "identifiability",
        "--robot",
        &robot,
        "--circle",
        "--effects",
        "none",
        "--json",
    ]);
    let w: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(w["rank"], v["rank"]);
    let text = ok(&[
        "identifiability",
        "--robot",
        &robot,
        "--circle",
        "--effects",
        "none",
    ]);
    assert!(text.contains("blind directions") && text.contains("link 1 base dx"));

    let cal = d.join("cal");
    ok(&[
        "calibrate",
        "--robot",
        &robot,
        "--data",
        &p(&data),
        "--effects",
        "none",
        "--out",
        &p(&cal),
    ]);
    let json = read_json(&cal.join("calibration.json"));
    assert!(json["installation_errors_um"]["base"][0][0].is_null());
    assert!(json["std_um"]["base"][0][0].is_null());
    assert!(!json["not_determined"].as_array().unwrap().is_empty());
    let toml = std::fs::read_to_string(cal.join("calibrated.toml")).unwrap();
    // What holds each parameter the data do not determine, in its word.
    assert!(
        toml.contains("# Held by tolerance (") || toml.contains("# Blind ("),
        "{toml}"
    );
    assert!(toml.contains("SIMULATED"));
    // Undetermined components are written at the fit's (minimum-norm) point, never at
    // nominal beside fitted ones: the file reproduces the fit on its own data, and validate
    // finds its reference from the file.
    let c = Robot::load(&cal.join("calibrated.toml")).unwrap();
    let n = Robot::load(Path::new(&robot)).unwrap();
    assert_ne!(c.table.links, n.table.links);
    let v: serde_json::Value = serde_json::from_str(&ok(&[
        "validate",
        "--robot",
        &p(&cal.join("calibrated.toml")),
        "--data",
        &p(&data),
        "--json",
    ]))
    .unwrap();
    let fit = json["residual_rms_um"].as_f64().unwrap();
    let file = v["calibrated"]["rms_um"].as_f64().unwrap();
    assert!(
        (fit - file).abs() <= 1e-9 * fit.max(1.0),
        "fit {fit} um, file {file} um"
    );
}

/// `cpm refine` from no effects with candidates sensor_offset, link_offset and backlash; its
/// JSON summary.
fn refine_no_effects(robot: &str, data: &Path, sigma_um: &str, out_dir: &Path) -> String {
    ok(&[
        "refine",
        "--robot",
        robot,
        "--data",
        &p(data),
        "--effects",
        "none",
        "--candidates",
        "sensor_offset,link_offset,backlash",
        "--sigma-um",
        sigma_um,
        "--out",
        &p(out_dir),
        "--json",
    ])
}

#[test]
fn refine_finds_backlash() {
    let d = scratch("refine");
    let robot = example("hexapod_66.toml");
    let truth = write_truth(&d);
    let data = d.join("data.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "40",
        "--truth",
        &p(&truth),
        "--truth-effect",
        "backlash=20,-15,25,10,-20,15",
        "--noise",
        "gaussian:0.5",
        "--seed",
        "3",
        "--out",
        &p(&data),
    ]);
    let out_dir = d.join("refined");
    let out = refine_no_effects(&robot, &data, "0.5", &out_dir);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["steps"][0]["effect"], "backlash", "{v:#}");
    let step = &v["steps"][0];
    for k in [
        "p_value",
        "delta_bic",
        "rms_before_um",
        "rms_after_um",
        "cv_rms_before_um",
        "cv_rms_after_um",
    ] {
        assert!(step[k].is_number(), "{k}");
    }
    assert!(step["rms_after_um"].as_f64().unwrap() < step["rms_before_um"].as_f64().unwrap());
    for k in [
        "rms_um",
        "cv_rms_um",
        "residual_white",
        "unexplained_structure",
    ] {
        assert!(!v["final"][k].is_null(), "{k}");
    }
    let value = step["parameters"][2]["value"].as_f64().unwrap();
    assert!((value - 25.0).abs() < 2.0, "backlash of link 3: {value}");
    for f in [
        "refine.json",
        "report.md",
        "calibrated.toml",
        "calibration.json",
        "residuals_before_after.svg",
    ] {
        assert!(out_dir.join(f).exists(), "{f}");
    }
    let json = read_json(&out_dir.join("calibration.json"));
    assert_eq!(json["known_effects"], serde_json::json!([]));
    let toml = std::fs::read_to_string(out_dir.join("calibrated.toml")).unwrap();
    assert!(toml.contains("effects = [\"backlash\"]"), "{toml}");
    assert!(toml.contains("[calibration.known_effects]"), "{toml}");
    // The calibrated description carries the backlash it found, and reading it back gives it.
    let cal = Robot::load(&out_dir.join("calibrated.toml")).unwrap();
    let known = cal.model(&[]).known_effects;
    assert_eq!(known.len(), 1);
    assert_eq!(known[0].effect, cpm::calib::Effect::Backlash);
    for (got, want) in known[0]
        .values
        .iter()
        .zip([20.0, -15.0, 25.0, 10.0, -20.0, 15.0])
    {
        assert!((got - want).abs() < 2.0, "{:?}", known[0].values);
    }
}

/// RMS position error (um) reached on the true machine of `truth_robot` plus a per-link
/// backlash `backlash_um` when commanding `readings` for `targets` in order, starting at home.
fn reached_error_um(
    truth_robot: &Robot,
    backlash_um: &[f64],
    targets: &[Pose],
    readings: &[Vec<f64>],
) -> f64 {
    let clearance = truth_robot.clearance();
    let load = truth_robot.platform_load();
    let mut previous =
        cpm::kinematics::inverse_lengths(&truth_robot.table, &truth_robot.table.home);
    let mut sign = [0.0; 6];
    let mut sq = 0.0;
    for (t, u) in targets.iter().zip(readings) {
        let commanded: Vec<f64> = (0..6).map(|i| truth_robot.length_mm(i, u[i])).collect();
        let shift = clearance
            .link_corrections_mm(&truth_robot.table, t, &load)
            .unwrap();
        for i in 0..6 {
            let d: f64 = commanded[i] - previous[i];
            if d.abs() > 1e-9 {
                sign[i] = d.signum();
            }
        }
        let lengths: Vec<f64> = (0..6)
            .map(|i| commanded[i] + shift[i] + backlash_um[i] * 1e-3 * sign[i])
            .collect();
        previous = commanded;
        let (reached, _) = cpm::kinematics::forward(
            &truth_robot.table,
            &lengths,
            t,
            &cpm::kinematics::ForwardOptions::default(),
        )
        .unwrap();
        let d = t.difference(&reached);
        sq += (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * 1e6;
    }
    (sq / targets.len() as f64).sqrt()
}

#[test]
fn calibrated_backlash_is_compensated() {
    // Truth: Table 2 installation errors and a backlash declared in the truth description's
    // [calibration.known_effects] (simulated). refine finds the backlash, calibrated.toml
    // carries it, and compensate applies it: the pose error with it is far below the error
    // of the same calibration without the backlash values.
    let d = scratch("backlash-loop");
    let robot = example("hexapod_66.toml");
    let backlash = [18.0, -12.0, 22.0, 9.0, -16.0, 14.0];
    let mut t = RobotDescription::load(write_truth(&d)).unwrap();
    t.calibration
        .get_or_insert_with(Default::default)
        .known_effects = [("backlash".to_string(), backlash.to_vec())]
        .into_iter()
        .collect();
    let truth_path = d.join("truth_backlash.toml");
    std::fs::write(&truth_path, t.to_toml_string().unwrap()).unwrap();
    let data = d.join("data.csv");
    let sim = ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "40",
        "--truth",
        &p(&truth_path),
        "--noise",
        "gaussian:0.3",
        "--seed",
        "8",
        "--out",
        &p(&data),
        "--json",
    ]);
    assert!(sim.contains("known backlash"), "{sim}");
    let out_dir = d.join("refined");
    refine_no_effects(&robot, &data, "0.3", &out_dir);
    let calibrated = out_dir.join("calibrated.toml");
    let text = std::fs::read_to_string(&calibrated).unwrap();
    assert!(text.contains("backlash = ["), "{text}");
    // The same calibration without its backlash values.
    let without = d.join("without_backlash.toml");
    let mut w = RobotDescription::load(&calibrated).unwrap();
    w.calibration.as_mut().unwrap().known_effects.clear();
    std::fs::write(&without, w.to_toml_string().unwrap()).unwrap();

    let truth = Robot::load(&write_truth(&d)).unwrap();
    let targets = cpm::calib::paper::random_workspace_poses(&truth.table, 20, 40.0, 8.0, 3.0, 77);
    let targets_path = d.join("targets.csv");
    std::fs::write(&targets_path, cpm::io::write_pose_list(&targets)).unwrap();
    let (mut reached, mut baseline) = (Vec::new(), Vec::new());
    for desc in [&calibrated, &without] {
        let out = d.join("commands.csv");
        ok(&[
            "compensate",
            "--robot",
            &p(desc),
            "--poses",
            &p(&targets_path),
            "--from-home",
            "--out",
            &p(&out),
        ]);
        let u = read_commands(&std::fs::read_to_string(&out).unwrap());
        reached.push(reached_error_um(&truth, &backlash, &targets, &u));
        // What the calibration reaches on a machine without backlash (its own accuracy).
        baseline.push(reached_error_um(&truth, &[0.0; 6], &targets, &u));
    }
    let (with, without) = (reached[0], reached[1]);
    let own = baseline[1];
    eprintln!("backlash loop: RMS position error {with:.3} um with the calibrated backlash, {without:.3} um without; {own:.3} um on the machine without backlash");
    assert!(without > 8.0, "the backlash should show: {without:.2} um");
    assert!(
        with < 0.2 * without,
        "with the calibrated backlash {with:.2} um, without {without:.2} um"
    );
    // Compensated backlash leaves the calibration's own accuracy.
    assert!(
        with < own + 1.0,
        "with {with:.2} um, own accuracy {own:.2} um"
    );
}

#[test]
fn design_writes_a_plan_that_identifies_everything() {
    let d = scratch("design");
    // A calibrated description: known backlash and sensor offsets of its three sensors.
    let mut r = RobotDescription::load(example("hexapod_66.toml")).unwrap();
    r.calibration
        .get_or_insert_with(Default::default)
        .known_effects = [
        ("backlash".to_string(), vec![2.0; 6]),
        ("sensor_offset".to_string(), vec![5.0, -3.0, 1.0]),
    ]
    .into_iter()
    .collect();
    let robot = p(&d.join("known.toml"));
    std::fs::write(&robot, r.to_toml_string().unwrap()).unwrap();
    let out = d.join("design");
    let text = ok(&[
        "design",
        "--robot",
        &robot,
        "--readings",
        "360",
        "--candidates",
        "150",
        "--out",
        &p(&out),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["rank"], 36);
    assert_eq!(v["readings"], 360);
    for f in [
        "poses.csv",
        "sockets.csv",
        "robot.toml",
        "design.json",
        "report.md",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    let text = ok(&[
        "identifiability",
        "--robot",
        &p(&out.join("robot.toml")),
        "--plan",
        &p(&out.join("poses.csv")),
        "--json",
    ]);
    let w: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(w["rank"], 36);
    assert_eq!(w["observations"], 360);
    // The designed description keeps the machine's backlash; the old sensors' offsets do
    // not carry over to the new sensors.
    let designed = Robot::load(&out.join("robot.toml")).unwrap();
    let known: Vec<_> = designed
        .model(&[])
        .known_effects
        .iter()
        .map(|k| k.effect)
        .collect();
    assert_eq!(known, vec![cpm::calib::Effect::Backlash]);
    // The chosen sockets (sockets.csv, socket pairs) read back through --sockets: the same
    // socket places, and a design from them keeps them all.
    let pairs = std::fs::read_to_string(out.join("sockets.csv")).unwrap();
    let back = cpm::cli::design::read_sockets(&pairs, "sockets.csv").unwrap();
    let count = |f: fn(&cpm::geometry::Sensor) -> cpm::geometry::Vector3<f64>| {
        let mut v: Vec<_> = designed.table.sensors.iter().map(f).collect();
        v.dedup_by(|a, b| (*a - *b).norm() < 1e-9);
        let mut distinct: Vec<cpm::geometry::Vector3<f64>> = Vec::new();
        for x in v {
            if !distinct.iter().any(|y| (x - y).norm() < 1e-9) {
                distinct.push(x);
            }
        }
        distinct
    };
    let (bases, platforms) = (count(|s| s.base_mm), count(|s| s.platform_mm));
    assert_eq!(back.base.len(), bases.len());
    assert_eq!(back.platform.len(), platforms.len());
    for (got, want) in back.base.iter().zip(&bases) {
        assert!((got.position_mm - want).norm() < 1e-9);
    }
    for (got, want) in back.platform.iter().zip(&platforms) {
        assert!((got.position_mm - want).norm() < 1e-9);
    }
    let again = d.join("again");
    let text = ok(&[
        "design",
        "--robot",
        &robot,
        "--sockets",
        &p(&out.join("sockets.csv")),
        "--base-sockets",
        &bases.len().to_string(),
        "--platform-sockets",
        &platforms.len().to_string(),
        "--readings",
        "360",
        "--candidates",
        "150",
        "--out",
        &p(&again),
        "--json",
    ]);
    let w: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(w["rank"], 36);
    assert_eq!(
        w["sensors"].as_array().unwrap().len(),
        bases.len() * platforms.len()
    );
    // A pair file with a bad number names its line and column.
    let bad = pairs.replacen(
        &pairs
            .lines()
            .nth(1)
            .unwrap()
            .split(',')
            .nth(1)
            .unwrap()
            .to_string(),
        "abc",
        1,
    );
    let e = cpm::cli::design::read_sockets(&bad, "sockets.csv").unwrap_err();
    assert_eq!(
        (e.line, e.field.as_deref()),
        (Some(2), Some("base_x_mm")),
        "{e}"
    );
    // Too few socket places in the description: a clear error, nothing written.
    let o = cpm(&[
        "design",
        "--robot",
        &example("paper_cubic.toml"),
        "--out",
        &p(&d.join("none")),
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--sockets FILE"));
    assert!(!d.join("none").exists());
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn bad_files_give_exit_3_a_located_message_and_no_output() {
    let d = scratch("bad");
    let robot = example("paper_cubic.toml");
    let out_dir = d.join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    std::fs::write(out_dir.join("keep.txt"), "x").unwrap();
    let header = "pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm";
    let row = "1,paper,0,0,410,0,0,0,309.9";
    let cases = [
        (
            "missing.csv",
            format!(
                "pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n{}\n",
                "1,paper,0,0,410,0,0,0"
            ),
            1,
            "field length_mm: missing column",
        ),
        (
            "nan.csv",
            format!("{header}\n{row}\n2,paper,0,0,410,0,0,0,NaN\n"),
            3,
            "field length_mm: \"NaN\" is not a finite number",
        ),
        (
            "sensor.csv",
            format!("{header}\n1,ballbar,0,0,410,0,0,0,309.9\n"),
            2,
            "field sensor: unknown sensor \"ballbar\"",
        ),
        (
            "unreachable.csv",
            format!("{header}\n{row}\n2,paper,0,0,41,0,0,0,309.9\n"),
            3,
            "pose \"2\"",
        ),
        (
            "metres.csv",
            format!("{header}\n1,paper,0,0,410,0,0,0,0.3099\n"),
            2,
            "field length_mm: 0.3099 mm is far from the nominal length",
        ),
        (
            "extra.csv",
            format!("{header},operator\n{row},me\n"),
            1,
            "field operator: unknown column",
        ),
    ];
    for (name, text, line, what) in cases {
        let f = d.join(name);
        std::fs::write(&f, text).unwrap();
        let o = cpm(&[
            "calibrate",
            "--robot",
            &robot,
            "--data",
            &p(&f),
            "--out",
            &p(&out_dir),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(3), "{name}: {err}");
        let want = format!("error: {}:{line}: {what}", p(&f));
        assert!(err.starts_with(&want), "\n got: {err}\nwant: {want}");
        assert_eq!(
            listing(&out_dir),
            vec!["keep.txt".to_string()],
            "{name} left output"
        );
    }
    // A bad robot description.
    let bad_robot = d.join("robot.toml");
    std::fs::write(
        &bad_robot,
        std::fs::read_to_string(&robot)
            .unwrap()
            .replace("radius_um = 10.0", "radius_um = -1.0"),
    )
    .unwrap();
    let o = cpm(&[
        "calibrate",
        "--robot",
        &p(&bad_robot),
        "--data",
        &p(&d.join("nan.csv")),
        "--out",
        &p(&out_dir),
    ]);
    assert_eq!(o.status.code(), Some(3));
    let err = String::from_utf8_lossy(&o.stderr);
    let located = err
        .strip_prefix(&format!("error: {}:", p(&bad_robot)))
        .and_then(|rest| rest.split_once(": field clearance.radius_um: must be finite and >= 0"))
        .is_some_and(|(line, _)| line.parse::<usize>().is_ok());
    assert!(located, "{err}");
    // A missing file is an I/O error.
    let o = cpm(&[
        "calibrate",
        "--robot",
        &robot,
        "--data",
        &p(&d.join("none.csv")),
        "--out",
        &p(&out_dir),
    ]);
    assert_eq!(
        o.status.code(),
        Some(4),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // Bad targets for compensate: nothing written.
    let targets = d.join("targets.csv");
    std::fs::write(
        &targets,
        "x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n0,0,410,0,0,0\n0,0,41,0,0,0\n",
    )
    .unwrap();
    let o = cpm(&[
        "compensate",
        "--robot",
        &robot,
        "--poses",
        &p(&targets),
        "--out",
        &p(&out_dir.join("c.csv")),
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&o.stderr)
        .starts_with(&format!("error: {}:3: pose \"2\"", p(&targets))));
    assert_eq!(listing(&out_dir), vec!["keep.txt".to_string()]);
}

#[test]
fn every_u64_seed_draws_random_poses() {
    // `--seed 18446744073709551615` found "only 0 of 5 well-conditioned poses": the batch
    // loop ended at `seed + 100`, which wrapped.
    let robot = example("hexapod_66.toml");
    let d = scratch("seed-max");
    let mut rows = Vec::new();
    for seed in ["18446744073709551615", "18446744073709551614", "0"] {
        let f = d.join(format!("{seed}.csv"));
        ok(&[
            "simulate",
            "--robot",
            &robot,
            "--random",
            "5",
            "--seed",
            seed,
            "--out",
            &p(&f),
        ]);
        let text = std::fs::read_to_string(&f).unwrap();
        let data: Vec<&str> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .skip(1)
            .collect();
        assert!(!data.is_empty(), "{text}");
        rows.push(data.join("\n"));
    }
    // Different seeds, different poses.
    assert_ne!(rows[0], rows[1]);
    assert_ne!(rows[0], rows[2]);
}

#[test]
fn usage_errors_exit_2_and_help_exits_0() {
    let robot = example("hexapod_66.toml");
    let d = scratch("usage");
    let out = p(&d.join("x.csv"));
    for args in [
        vec!["simulate", "--robot", &robot, "--out", &out],
        vec![
            "simulate", "--robot", &robot, "--circle", "--random", "3", "--out", &out,
        ],
        vec![
            "simulate",
            "--robot",
            &robot,
            "--random",
            "3",
            "--effects",
            "nosuch",
            "--out",
            &out,
        ],
        vec![
            "simulate", "--robot", &robot, "--random", "3", "--noise", "pink:3", "--out", &out,
        ],
        vec![
            "simulate",
            "--robot",
            &robot,
            "--random",
            "3",
            "--sensors",
            "s9",
            "--out",
            &out,
        ],
        vec!["calibrate", "--robot", &robot],
        vec!["identifiability", "--robot", &robot],
        vec!["export", "--format", "fanuc", "--robot", &robot],
        vec!["frobnicate"],
        vec![],
    ] {
        let o = cpm(&args);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    assert!(!d.join("x.csv").exists());
    for cmd in [
        "simulate",
        "identifiability",
        "calibrate",
        "compensate",
        "export",
        "refine",
    ] {
        let o = cpm(&[cmd, "--help"]);
        assert_eq!(o.status.code(), Some(0));
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("Examples:"),
            "{cmd}"
        );
    }
}

#[test]
fn refine_names_undeclared_effects_simulated_by_the_cli() {
    // `cpm simulate` puts an effect the description does not declare into the truth, a few
    // times the noise; `cpm refine` with the whole library as candidates must name it first
    // and bring the cross-validated RMS to the noise.
    let d = scratch("refine-library");
    let robot = example("hexapod_66.toml");
    let truth = write_truth(&d);
    let noise_um = 0.5;
    for (k, effect) in [
        "link_scale=300,-250,200,-300,250,-200",
        "link_nonlinearity=4,-2,-3,2,5,-1,-4,2,3,-2,-5,1",
        "backlash=3,-2.5,3,2,-3,2.5",
        // The example's link forces are tens of newtons: 0.3-0.4 um/N gives a few um.
        "compliance=400,-300,350,-400,300,-350",
        "screw_periodic=3,-2,2.5,1.5,-2,2,3,-1.5,2,2.5,-3,1.5",
    ]
    .iter()
    .enumerate()
    {
        let name = effect.split('=').next().unwrap();
        let data = d.join(format!("{name}.csv"));
        ok(&[
            "simulate",
            "--robot",
            &robot,
            "--random",
            "100",
            "--range-mm",
            "60",
            "--range-deg",
            "8",
            "--truth",
            &p(&truth),
            "--truth-effect",
            effect,
            "--noise",
            &format!("gaussian:{noise_um}"),
            "--seed",
            &format!("{}", 11 + k),
            "--out",
            &p(&data),
        ]);
        let out = ok(&[
            "refine",
            "--robot",
            &robot,
            "--data",
            &p(&data),
            "--effects",
            "none",
            "--sigma-um",
            &format!("{noise_um}"),
            "--out",
            &p(&d.join(name)),
            "--json",
        ]);
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        let steps: Vec<&str> = v["steps"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["effect"].as_str().unwrap())
            .collect();
        let cv = v["final"]["cv_rms_um"].as_f64().unwrap();
        let before = v["steps"][0]["cv_rms_before_um"]
            .as_f64()
            .unwrap_or(f64::NAN);
        eprintln!("{name}: steps {steps:?}, cv RMS {before:.3} -> {cv:.3} um");
        assert_eq!(steps.first(), Some(&name), "{name}: {steps:?}");
        assert!(cv < 1.2 * noise_um, "{name}: cv RMS {cv} um");
    }
}

#[test]
fn compensate_corrects_a_known_thermal_drift_at_the_given_temperature() {
    // A known drift of 12 ppm/K on every link (reference 20 deg C): at 30 deg C the links are
    // 120 ppm longer, so the commanded lengths L satisfy L (1 + 120e-6) = the IK length.
    let d = scratch("thermal");
    let mut r = RobotDescription::load(example("hexapod_66.toml")).unwrap();
    r.clearance = None;
    let c = r.calibration.get_or_insert_with(Default::default);
    c.reference_temperature_c = Some(20.0);
    c.known_effects = [("thermal_drift".to_string(), vec![12.0; 6])]
        .into_iter()
        .collect();
    let robot = d.join("thermal.toml");
    std::fs::write(&robot, r.to_toml_string().unwrap()).unwrap();
    let loaded = Robot::load(&robot).unwrap();
    let targets = cpm::calib::paper::random_workspace_poses(&loaded.table, 5, 30.0, 5.0, 3.0, 21);
    let targets_path = d.join("targets.csv");
    std::fs::write(&targets_path, cpm::io::write_pose_list(&targets)).unwrap();
    let out = d.join("commands.csv");
    let base = [
        "compensate",
        "--robot",
        robot.to_str().unwrap(),
        "--poses",
        targets_path.to_str().unwrap(),
    ];
    let lengths = |temperature: Option<&str>| {
        let mut args = base.to_vec();
        args.extend(["--out", out.to_str().unwrap()]);
        if let Some(t) = temperature {
            args.extend(["--temperature-c", t]);
        }
        ok(&args);
        read_command_lengths(&std::fs::read_to_string(&out).unwrap())
    };
    let warm = lengths(Some("30"));
    let reference = lengths(Some("20"));
    let unknown = lengths(None);
    for (k, t) in targets.iter().enumerate() {
        let ik = cpm::kinematics::inverse_lengths(&loaded.table, t);
        for i in 0..6 {
            assert!((reference[k][i] - ik[i]).abs() < 1e-9);
            assert!((unknown[k][i] - ik[i]).abs() < 1e-9);
            let want = ik[i] / (1.0 + 120e-6);
            assert!(
                (warm[k][i] - want).abs() < 1e-6,
                "target {k} link {i}: {} vs {want}",
                warm[k][i]
            );
        }
    }
    // A temperature that is not one is a usage error.
    let mut args = base.to_vec();
    args.extend(["--temperature-c", "-500"]);
    assert_eq!(cpm(&args).status.code(), Some(2));
}

/// A campaign under limits on the paper's cube (small), written with the files
/// `cargo xtask reproduce-paper` writes to `designed/`: `cpm calibrate` reads them back and
/// identifies all 36 errors.
#[test]
fn designed_files_under_limits_round_trip_through_calibrate() {
    use cpm::calib::design::{
        candidates, design_setups, Constraints, SetupOptions, SocketCandidates,
    };
    use cpm::calib::{simulate_campaign, MeasurementModel, Noise, SimulationOptions};
    let d = scratch("designed-limits");
    let model = MeasurementModel::new(cpm::geometry::JointTable::paper_cubic());
    let (cands, _) = candidates::default_candidates(
        &model.nominal,
        &candidates::Workspace::default(),
        300,
        100.0,
        25.0,
        4,
    );
    let opts = SetupOptions {
        max_readings: 300,
        max_setups: 8,
        windows_per_pair: 3,
        screening_projections: 6,
        projections: 40,
        minimax_rounds: 1,
        ..SetupOptions::default()
    };
    let design = design_setups(
        &model,
        &SocketCandidates::paper_cubic(),
        &cands,
        &Constraints::default(),
        &opts,
        &|_| {},
    )
    .unwrap();
    let dmodel = design.model(&model);
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let sim = SimulationOptions {
        noise: Noise::Uniform {
            half_width_um: 10.0,
        },
        repeats: 1,
        seed: 3,
    };
    let data = simulate_campaign(&dmodel, &truth, &design.campaign(), &sim).unwrap();
    let robot = d.join("robot.toml");
    for (name, text) in
        cpm::paper_report::designed_files(&design, &data, "test", &p(&robot)).unwrap()
    {
        std::fs::write(d.join(name), text).unwrap();
    }
    let readings = std::fs::read_to_string(d.join("readings.csv")).unwrap();
    assert!(readings.starts_with("# simulated by cpm"), "{readings:.80}");
    let text = ok(&[
        "calibrate",
        "--robot",
        &p(&robot),
        "--data",
        &p(&d.join("readings.csv")),
        "--out",
        &p(&d.join("cal")),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["simulated"], true);
    assert_eq!(v["rank"], 36, "{text:.2000}");
    let cal = read_json(&d.join("cal").join("calibration.json"));
    assert_eq!(cal["readings"], design.num_readings());
    // The file's sensors are the setups, in mounting order.
    let loaded = Robot::load(&robot).unwrap();
    let names: Vec<String> = loaded
        .table
        .sensors
        .iter()
        .map(|s| s.name.clone())
        .collect();
    let expected: Vec<String> = design.setups.iter().map(|s| s.name.clone()).collect();
    assert_eq!(names, expected);
    // It carries the candidate sockets, the gauge and the limits, so `cpm design` reads them
    // back: a design under the same limits from the same socket places.
    let desc = &loaded.description;
    assert_eq!(desc.sockets.len(), 16);
    assert_eq!(desc.gauges[0].stroke_mm, 200.0);
    assert!(desc.sensors.iter().all(|s| s.bar_mm.is_some()));
    let text = ok(&[
        "design",
        "--robot",
        &p(&robot),
        "--readings",
        "120",
        "--candidates",
        "100",
        "--range-mm",
        "100",
        "--range-deg",
        "20",
        "--setups",
        "6",
        "--out",
        &p(&d.join("again")),
        "--json",
    ]);
    let w: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(w["limited"], true);
    assert_eq!(w["constraints"]["stroke_mm"], 200.0);
    assert_eq!(w["constraints"]["clearance_mm"], 30.0);
    assert_eq!(w["constraints"]["cone_deg"], 40.0);
    assert!(w["max_travel_mm"].as_f64().unwrap() <= 200.0 + 1e-9);
    assert!(w["min_clearance_mm"].as_f64().unwrap() >= 30.0);
    for s in w["setups"].as_array().unwrap() {
        let b = s["base_socket"].as_str().unwrap();
        assert!(desc.sockets.iter().any(|x| x.name == b), "{b}");
    }
}

/// `cpm design --stroke-mm`: setup plans that `cpm simulate` and `cpm calibrate` read, every
/// plan within the stroke.
#[test]
fn design_under_limits_writes_setup_plans_simulate_and_calibrate_read() {
    let d = scratch("design-limits");
    let sockets = d.join("sockets.csv");
    let c = cpm::calib::design::SocketCandidates::paper_cubic();
    let mut text = String::from("name,side,x_mm,y_mm,z_mm\n");
    for (side, list) in [("base", &c.base), ("platform", &c.platform)] {
        for s in list.iter() {
            let v = s.position_mm;
            text.push_str(&format!("{},{side},{},{},{}\n", s.name, v.x, v.y, v.z));
        }
    }
    std::fs::write(&sockets, text).unwrap();
    let out = d.join("design");
    let text = ok(&[
        "design",
        "--robot",
        &example("paper_cubic.toml"),
        "--sockets",
        &p(&sockets),
        "--readings",
        "240",
        "--candidates",
        "200",
        "--range-mm",
        "100",
        "--range-deg",
        "20",
        "--stroke-mm",
        "80",
        "--setups",
        "8",
        "--out",
        &p(&out),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v["readings"].as_u64().unwrap() <= 240);
    assert!(v["max_travel_mm"].as_f64().unwrap() <= 80.0 + 1e-9);
    assert!(v["min_clearance_mm"].as_f64().unwrap() >= 30.0);
    assert!(v["max_base_cone_deg"].as_f64().unwrap() <= 40.0 + 1e-9);
    assert!(out.join("setup_sheet.md").exists() && out.join("setup_sheet.csv").exists());
    let robot = p(&out.join("robot.toml"));
    let mut data = Vec::new();
    for s in v["setups"].as_array().unwrap() {
        let name = s["sensor"].as_str().unwrap();
        let file = d.join(format!("{name}.csv"));
        ok(&[
            "simulate",
            "--robot",
            &robot,
            "--plan",
            &p(&out.join(s["plan"].as_str().unwrap())),
            "--sensors",
            name,
            "--paper-table2",
            "--noise",
            "uniform:10",
            "--out",
            &p(&file),
        ]);
        // Every simulated reading of the true machine lies in the setup's window (the design
        // keeps an edge margin for the machine's errors).
        let w = &s["window_mm"];
        let (lo, hi) = (w[0].as_f64().unwrap(), w[1].as_f64().unwrap());
        let csv = std::fs::read_to_string(&file).unwrap();
        let mut lines = csv.lines().filter(|l| !l.starts_with('#'));
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = header.iter().position(|h| *h == "length_mm").unwrap();
        for l in lines {
            let len: f64 = l.split(',').nth(col).unwrap().parse().unwrap();
            assert!(len >= lo && len <= hi, "{name}: {len} outside {lo}..{hi}");
        }
        data.push(p(&file));
    }
    let mut args = vec!["calibrate", "--robot", &robot];
    for f in &data {
        args.push("--data");
        args.push(f);
    }
    let cal = p(&d.join("cal"));
    args.extend(["--out", &cal, "--json"]);
    let text = ok(&args);
    let c: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(c["rank"], v["rank"]);
    let cal = read_json(&d.join("cal").join("calibration.json"));
    assert_eq!(cal["readings"], v["readings"]);

    // The written description carries the gauge, the limits and each setup's gauge and bar.
    let desc = Robot::load(&out.join("robot.toml")).unwrap().description;
    assert_eq!(desc.gauges.len(), 1);
    assert_eq!(desc.gauges[0].stroke_mm, 80.0);
    // The example declares no noise: none is written for the gauge.
    assert_eq!(desc.gauges[0].noise_um, None);
    let limits = desc.limits.unwrap();
    assert_eq!(
        (limits.base_cone_deg, limits.gauge_link_clearance_mm),
        (40.0, Some(30.0))
    );
    for (sensor, s) in desc.sensors.iter().zip(v["setups"].as_array().unwrap()) {
        assert_eq!(sensor.gauge.as_deref(), Some("gauge"));
        let (lo, hi) = desc.gauges[0].window_mm(sensor.bar_mm.unwrap());
        assert!((lo - s["window_mm"][0].as_f64().unwrap()).abs() < 1e-9);
        assert!((hi - s["window_mm"][1].as_f64().unwrap()).abs() < 1e-9);
    }

    // `cpm design` reads the limits back from that description (no --stroke-mm), and a flag
    // overrides one of them.
    let again = d.join("again");
    let text = ok(&[
        "design",
        "--robot",
        &robot,
        "--sockets",
        &p(&sockets),
        "--readings",
        "120",
        "--candidates",
        "100",
        "--range-mm",
        "100",
        "--range-deg",
        "20",
        "--setups",
        "6",
        "--cone-deg",
        "35",
        "--out",
        &p(&again),
        "--json",
    ]);
    let w: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(w["limited"], true);
    assert_eq!(w["constraints"]["stroke_mm"], 80.0);
    assert_eq!(w["constraints"]["clearance_mm"], 30.0);
    assert_eq!(w["constraints"]["base_cone_deg"], 35.0);
    assert!(w["max_travel_mm"].as_f64().unwrap() <= 80.0 + 1e-9);
    assert!(w["max_base_cone_deg"].as_f64().unwrap() <= 35.0 + 1e-9);
    assert!(w["max_platform_cone_deg"].as_f64().unwrap() <= 35.0 + 1e-9);

    // A reading outside its setup's window is refused, naming its file, line and field: the
    // same readings with the description's first setup given a bar one stroke longer.
    let mut shifted = desc.clone();
    *shifted.sensors[0].bar_mm.as_mut().unwrap() += 80.0;
    let shifted_path = d.join("shifted.toml");
    std::fs::write(&shifted_path, shifted.to_toml_string().unwrap()).unwrap();
    let csv = std::fs::read_to_string(&data[0]).unwrap();
    let header_line = csv.lines().position(|l| !l.starts_with('#')).unwrap() + 1;
    let o = cpm(&[
        "calibrate",
        "--robot",
        &p(&shifted_path),
        "--data",
        &data[0],
        "--out",
        &p(&d.join("cal_bad")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    let want = format!(
        "{}:{}: field length_mm: sensor `{}` read",
        data[0],
        header_line + 1,
        v["setups"][0]["sensor"].as_str().unwrap()
    );
    assert!(err.contains(&want), "{err}\nwant {want}");
    assert!(err.contains("outside") && err.contains("bar"), "{err}");
    assert!(!d.join("cal_bad").exists());
}

/// A sensor that names a gauge: its readings within one stroke, and a plan that leaves the
/// gauge's range is refused by `cpm simulate`.
#[test]
fn readings_beyond_a_gauges_stroke_are_refused() {
    let d = scratch("gauge-stroke");
    let mut r = RobotDescription::load(example("paper_cubic.toml")).unwrap();
    r.gauges.push(cpm::geometry::description::GaugeSpec {
        name: "lg".into(),
        kind: Default::default(),
        stroke_mm: 20.0,
        shortest_mm: Some(200.0),
        longest_mm: Some(500.0),
        bars_mm: Vec::new(),
        noise_um: None,
        radius_mm: None,
    });
    r.sensors[0].gauge = Some("lg".into());
    let robot = d.join("robot.toml");
    std::fs::write(&robot, r.to_toml_string().unwrap()).unwrap();
    // A 60 mm circle: the paper's sensor spans more than 20 mm.
    let o = cpm(&[
        "simulate",
        "--robot",
        &p(&robot),
        "--circle",
        "--radius-mm",
        "60",
        "--count",
        "12",
        "--out",
        &p(&d.join("sim.csv")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--circle:") && err.contains("20 mm stroke"),
        "{err}"
    );
    // The same readings simulated without the gauge, then calibrated with it: refused at the
    // first reading that takes the span beyond the stroke.
    let mut plain = r.clone();
    plain.sensors[0].gauge = None;
    let plain_path = d.join("plain.toml");
    std::fs::write(&plain_path, plain.to_toml_string().unwrap()).unwrap();
    ok(&[
        "simulate",
        "--robot",
        &p(&plain_path),
        "--circle",
        "--radius-mm",
        "60",
        "--count",
        "12",
        "--out",
        &p(&d.join("sim.csv")),
    ]);
    let o = cpm(&[
        "calibrate",
        "--robot",
        &p(&robot),
        "--data",
        &p(&d.join("sim.csv")),
        "--out",
        &p(&d.join("cal")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(
        err.contains("field length_mm") && err.contains("stroke"),
        "{err}"
    );
    // A plan file: home, then 30 mm along y (the sensor shortens by 28 mm): refused at the
    // second pose's line.
    let plan = d.join("plan.csv");
    std::fs::write(
        &plan,
        "pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\nhome,0,0,410,0,0,0\nshift,0,30,410,0,0,0\n",
    )
    .unwrap();
    let o = cpm(&[
        "simulate",
        "--robot",
        &p(&robot),
        "--plan",
        &p(&plan),
        "--out",
        &p(&d.join("sim2.csv")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(
        err.contains(&format!("{}:3: sensor `paper` would read", p(&plan))),
        "{err}"
    );
    assert!(!d.join("sim2.csv").exists());
    // Within the stroke: read.
    ok(&[
        "simulate",
        "--robot",
        &p(&robot),
        "--circle",
        "--radius-mm",
        "3",
        "--count",
        "12",
        "--out",
        &p(&d.join("small.csv")),
    ]);
}

#[test]
fn simulate_json_summary_counts_what_the_file_holds() {
    let d = scratch("simulate-json");
    let robot_path = example("hexapod_66.toml");
    let data = d.join("data.csv");
    let out = ok(&[
        "simulate",
        "--robot",
        &robot_path,
        "--random",
        "20",
        "--noise",
        "gaussian:0.5",
        "--seed",
        "7",
        "--out",
        &p(&data),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let robot = Robot::load(Path::new(&robot_path)).unwrap();
    let back = cpm::workflow::ingest::read_data_file(
        &data,
        &robot,
        &Default::default(),
        &Default::default(),
    )
    .unwrap();
    assert_eq!(v["simulated"], true);
    assert!(back.campaign.simulated);
    assert_eq!(v["out"], p(&data));
    assert_eq!(v["seed"], 7);
    assert_eq!(v["measure"], "lengths");
    assert_eq!(v["readings"], back.campaign.readings.len());
    assert_eq!(v["poses"], back.campaign.poses.len());
    assert!(back.campaign.readings.len() >= 20, "{v}");
    assert_eq!(v["pose_measurements"], 0);
}

/// Issue 63 item 4: what a compensation can promise. `calibrate` writes the covariance of the
/// machine's parameters into `calibrated.toml` (its standard deviations those of
/// calibration.json), and `compensate` turns it into the pose error it predicts at each
/// target, with the worst target's ISO 9283 bands; the true machine's error after
/// compensation (SIMULATED, reached by its own forward kinematics) lies within them. A
/// description without a calibration promises nothing (`null`).
#[test]
fn compensate_promises_a_band_from_the_calibrations_covariance() {
    let d = scratch("promise");
    let robot_path = example("hexapod_66.toml");
    let truth_path = write_truth(&d);
    let (data, cal) = (d.join("data.csv"), d.join("cal"));
    simulate_and_calibrate(&robot_path, &truth_path, "gaussian:1", "7", &data, &cal);
    // The covariance written is the fit's: its deviations are calibration.json's posterior
    // ones (the fit's prior is in it).
    let calibrated = Robot::load(&cal.join("calibrated.toml")).unwrap();
    let covariance = calibrated.covariance().unwrap().expect("a covariance");
    let json = read_json(&cal.join("calibration.json"));
    let params = json["prior"]["parameters"].as_array().unwrap();
    assert_eq!(covariance.covariance.nrows(), params.len());
    let mut compared = 0;
    for (k, q) in params.iter().enumerate() {
        let (ours, theirs) = (
            covariance.covariance[(k, k)].sqrt(),
            q["posterior_std"].as_f64().unwrap(),
        );
        assert!(
            (ours - theirs).abs() <= 1e-5 * theirs,
            "{}: {ours} vs {theirs}",
            q["name"]
        );
        compared += 1;
    }
    assert!(compared > 0);
    // The promise, per target and over the targets.
    let truth = Robot::load(&truth_path).unwrap();
    let (targets, targets_path, commands, out) =
        compensate_random_targets(&d, &robot_path, &cal.join("calibrated.toml"), 12, 31, true);
    let summary: serde_json::Value = serde_json::from_str(&out).unwrap();
    let promise = &summary["predicted_error"];
    assert_eq!(promise["level"], 0.95);
    let per_target = promise["targets"].as_array().unwrap();
    assert_eq!(per_target.len(), 12);
    let worst_p = promise["worst_target"]["ap_p_um"].as_f64().unwrap();
    for t in per_target {
        let band = t["position_95_um"].as_f64().unwrap();
        let std: Vec<f64> = t["position_std_um"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        // The ellipsoid's largest semi-axis is at least 2.8 times every axis' deviation.
        assert!(std.iter().all(|s| *s > 0.0 && band >= 2.79 * s), "{t}");
        assert!(band <= worst_p);
    }
    let text = std::fs::read_to_string(&commands).unwrap();
    assert!(text
        .lines()
        .next()
        .unwrap()
        .contains("predicted pose error, worst target, 95 %"));
    let after = reached_error_um(&truth, &[0.0; 6], &targets, &read_commands(&text));
    println!("SIMULATED: true position error after compensation {after:.3} um RMS; promised at most {worst_p:.3} um (95 %, worst target)");
    assert!(
        after > 0.0 && after <= worst_p,
        "error {after} um, band {worst_p} um"
    );
    assert!(
        worst_p < 20.0 * after,
        "an informative band: {worst_p} um for {after} um"
    );
    // Without a calibration: no promise.
    let out = ok(&[
        "compensate",
        "--robot",
        &robot_path,
        "--poses",
        &p(&targets_path),
        "--out",
        &p(&d.join("nominal.csv")),
        "--json",
    ]);
    let summary: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(summary["predicted_error"].is_null());
}
