//! The round trip as the contract: what `cpm calibrate` writes (`calibrated.toml`) is read
//! back by `cpm validate` into exactly the model the fit ended with, for every built-in
//! effect, and the exact truth reproduces its own noise-free simulation.
//!
//! Data: simulated (labelled so) by `cpm simulate` from `examples/hexapod_66_truth.toml` plus
//! the effect's values, driven by the controller's inverse kinematics (no `reading_k`), and an
//! independent simulation written here from plain geometry (link lengths by inverse
//! kinematics of the true joints, readings through the reading model), and the real Jugglebot
//! session (`tests/data/jugglebot/`).
#[path = "common/cli.rs"]
mod cli;

use std::path::Path;

use cli::{cpm, example, ok, p, scratch};
use cpm::calib::Effect;

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text).unwrap()
}

fn read_json(path: &Path) -> serde_json::Value {
    json(&std::fs::read_to_string(path).unwrap())
}

/// Values of `effect` for the hexapod of the examples: alternating, of the size a real
/// machine shows in the effect's unit.
fn truth_values(effect: Effect, links: usize, sensors: usize) -> Vec<f64> {
    let n = effect.num_params(links, sensors);
    let size = match effect {
        Effect::LinkOffset => 20.0,
        Effect::LinkScale => 300.0,
        Effect::SensorOffset => 15.0,
        Effect::SensorScale => 200.0,
        Effect::SocketError => 40.0,
        Effect::Clearance => 5.0,
        Effect::Backlash => 6.0,
        Effect::Compliance => 0.2,
        Effect::ThermalDrift => 2.0,
        Effect::ScrewPeriodic => 3.0,
        Effect::LinkNonlinearity => 5.0,
        _ => 10.0,
    };
    (0..n)
        .map(|k| size * [1.0, -0.7, 0.4, 0.9, -1.1, 0.6][k % 6])
        .collect()
}

/// `cpm calibrate --robot robot --data data --effects effects --out cal` plus `extra`
/// options; its calibration.json.
fn calibrate(
    cal: &Path,
    robot: &str,
    data: &Path,
    effects: &str,
    extra: &[&str],
) -> serde_json::Value {
    let (data, out) = (p(data), p(cal));
    let mut args = vec![
        "calibrate",
        "--robot",
        robot,
        "--data",
        &data,
        "--effects",
        effects,
    ];
    args.extend_from_slice(extra);
    args.extend(["--out", &out]);
    ok(&args);
    read_json(&cal.join("calibration.json"))
}

/// `cpm validate --robot calibrated --data data --json` (reference from the file).
fn validate(calibrated: &Path, data: &Path) -> serde_json::Value {
    json(&ok(&[
        "validate",
        "--robot",
        &p(calibrated),
        "--data",
        &p(data),
        "--json",
    ]))
}

/// A validation's calibrated error weighted as the fit weighs tracker observations: positions
/// at 1, orientations at pose sigma / orientation sigma (10 um / 20 urad).
fn weighted_rms_um(v: &serde_json::Value) -> f64 {
    let pos = v["calibrated"]["rms_um"].as_f64().unwrap();
    let rot = v["calibrated"]["orientation_rms_urad"].as_f64().unwrap();
    ((pos * pos + (0.5 * rot).powi(2)) / 2.0).sqrt()
}

/// `calibrate` with `effects` on `data`, then `validate` of its calibrated.toml on the same
/// data (reference from the file): the file reproduces the fit. Returns (fit, file) RMS.
fn fit_and_read_back(dir: &Path, robot: &str, data: &Path, effects: &str) -> (f64, f64) {
    let cal = dir.join("cal");
    let fit = calibrate(&cal, robot, data, effects, &[])["residual_rms_um"]
        .as_f64()
        .unwrap();
    let v = validate(&cal.join("calibrated.toml"), data);
    (fit, v["calibrated"]["rms_um"].as_f64().unwrap())
}

/// Every built-in effect that a gauge campaign can carry: simulated from the truth with the
/// effect, fitted with it, written, read back; the file reproduces the fit to 1e-9 mm (the
/// RMS to a relative 1e-9), and the truth itself (the effect in its known values) reproduces
/// its own noise-free simulation.
#[test]
fn every_effect_round_trips_through_calibrated_toml() {
    let robot = example("hexapod_66.toml");
    let truth_text = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap();
    let mut table = Vec::new();
    for effect in [
        Effect::LinkOffset,
        Effect::LinkScale,
        Effect::SensorOffset,
        Effect::SensorScale,
        Effect::Backlash,
        Effect::Compliance,
        Effect::ScrewPeriodic,
        Effect::LinkNonlinearity,
        Effect::Clearance,
        Effect::SocketError,
    ] {
        let name = effect.name();
        let dir = scratch("roundtrip", name);
        let values = truth_values(effect, 6, 3);
        let list = values
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(", ");
        // The truth as a description: the example's truth plus the effect's known values.
        let truth = dir.join("truth.toml");
        std::fs::write(
            &truth,
            format!("{truth_text}\n[calibration.known_effects]\n{name} = [{list}]\n"),
        )
        .unwrap();
        for (noise, file) in [("gaussian:1", "data.csv"), ("none", "exact.csv")] {
            ok(&[
                "simulate",
                "--robot",
                &robot,
                "--random",
                "70",
                "--truth",
                &p(&truth),
                "--noise",
                noise,
                "--seed",
                "3",
                "--out",
                &p(&dir.join(file)),
            ]);
        }
        // The exact truth reproduces its own noise-free simulation at every pose.
        let v = json(&ok(&[
            "validate",
            "--robot",
            &p(&truth),
            "--reference",
            &robot,
            "--data",
            &p(&dir.join("exact.csv")),
            "--json",
        ]));
        let exact = v["calibrated"]["max_um"].as_f64().unwrap();
        assert!(
            exact < 1e-6,
            "{name}: the truth misses its own simulation by {exact} um"
        );
        let (fit, file) = fit_and_read_back(&dir, &robot, &dir.join("data.csv"), name);
        table.push(format!("{name}: fit {fit:.4} um, file {file:.4} um"));
        assert!(
            (fit - file).abs() <= 1e-9 * fit.max(1.0),
            "{name}: fit {fit} um, calibrated.toml {file} um"
        );
    }
    println!("{}", table.join("\n"));
}

/// A rank-deficient fit (socket errors beside the installation errors) writes its own point
/// of the solution set: the file reproduces the fit instead of the nominal machine.
#[test]
fn a_rank_deficient_fit_writes_a_point_that_reproduces_it() {
    let robot = example("hexapod_66.toml");
    let dir = scratch("roundtrip", "rank-deficient");
    let data = dir.join("data.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "60",
        "--truth",
        &example("hexapod_66_truth.toml"),
        "--noise",
        "gaussian:1",
        "--seed",
        "1",
        "--out",
        &p(&data),
    ]);
    let (fit, file) = fit_and_read_back(&dir, &robot, &data, "socket_error");
    let j = read_json(&dir.join("cal/calibration.json"));
    assert!(
        j["identifiability"]["rank"].as_u64().unwrap()
            < j["identifiability"]["parameters"].as_u64().unwrap()
    );
    assert!(
        (fit - file).abs() <= 1e-9 * fit.max(1.0),
        "fit {fit}, file {file}"
    );
    let toml = std::fs::read_to_string(dir.join("cal/calibrated.toml")).unwrap();
    assert!(toml.contains("# Not determined by the data on their own"));
}

/// An independent simulation: poses of the true machine (truth joints, by plain inverse
/// kinematics), readings `reading_k` through the robot's reading model, gauge lengths as
/// socket distances; no `cpm simulate`. Folded link offsets and scales (a reading model unlike
/// the nominal one) must survive the round trip.
#[test]
fn link_offsets_and_scales_survive_on_independently_simulated_readings() {
    use cpm::geometry::Pose;
    let robot_path = example("hexapod_66.toml");
    let robot = cpm::io::Robot::load(Path::new(&robot_path)).unwrap();
    let truth = cpm::io::Robot::load(Path::new(&example("hexapod_66_truth.toml"))).unwrap();
    let (offset_mm, scale) = (
        [0.02, -0.015, 0.01, 0.025, -0.02, 0.015],
        [3e-4, -2e-4, 1e-4, 0.0, 2e-4, -1e-4],
    );
    let home = robot.table.home;
    let mut csv = String::from("# independent simulation (tests/roundtrip.rs): simulated data\npose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm");
    for k in 1..=6 {
        csv.push_str(&format!(",reading_{k}"));
    }
    csv.push('\n');
    let mut state: u64 = 12345;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    for j in 0..50 {
        let [r, pi, y] = home.rpy_deg();
        let pose = Pose::from_xyz_rpy_deg(
            [
                home.position_mm.x + 30.0 * rnd(),
                home.position_mm.y + 30.0 * rnd(),
                home.position_mm.z + 20.0 * rnd(),
            ],
            [r + 5.0 * rnd(), pi + 5.0 * rnd(), y + 5.0 * rnd()],
        );
        // The true machine's link lengths at this (actual) pose, and the readings that give
        // them: true length = (nominal reading model)(1 + scale) + offset.
        let readings: Vec<f64> = truth
            .table
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let len = (pose.position_mm + pose.rotation * l.platform_mm - l.base_mm).norm();
                robot.reading(i, (len - offset_mm[i]) / (1.0 + scale[i]))
            })
            .collect();
        for (si, s) in truth.table.sensors.iter().enumerate() {
            let len = (pose.position_mm + pose.rotation * s.platform_mm - s.base_mm).norm();
            let a = pose.rpy_deg();
            csv.push_str(&format!(
                "{j},{},{},{},{},{},{},{},{}",
                robot.table.sensors[si].name,
                pose.position_mm.x,
                pose.position_mm.y,
                pose.position_mm.z,
                a[0],
                a[1],
                a[2],
                len
            ));
            for u in &readings {
                csv.push_str(&format!(",{u}"));
            }
            csv.push('\n');
        }
    }
    let dir = scratch("roundtrip", "independent");
    let data = dir.join("data.csv");
    std::fs::write(&data, csv).unwrap();
    // The robot description has joint clearance; the independent truth has none: calibrate a
    // copy without it.
    let text = std::fs::read_to_string(&robot_path).unwrap();
    let bare = dir.join("robot.toml");
    let cut = text.replace("[clearance]\nradius_um = 10.0\n", "");
    assert_ne!(cut, text);
    std::fs::write(&bare, cut).unwrap();
    let (fit, file) = fit_and_read_back(&dir, &p(&bare), &data, "link_offset,link_scale");
    assert!(
        fit < 1e-3,
        "noise-free independent data should fit exactly: {fit} um"
    );
    assert!((fit - file).abs() <= 1e-6, "fit {fit}, file {file}");
    let out = cpm(&[
        "validate",
        "--robot",
        &p(&dir.join("cal/calibrated.toml")),
        "--data",
        &p(&data),
    ]);
    assert!(out.status.success());
}

/// The real Jugglebot session (tests/data/jugglebot, measured, not simulated): calibrated on
/// its first two thirds in acquisition order with its motion-capture frame refined, the file
/// reproduces the fit on those poses, and on the last third (a held-out block, its frame
/// re-registered) the calibrated robot beats the nominal one on pose and link length.
#[test]
fn the_real_session_round_trips_and_improves_a_held_out_block() {
    let dir = scratch("roundtrip", "jugglebot");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/jugglebot");
    let text = std::fs::read_to_string(src.join("session_108.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let (header, rows) = (lines[0], &lines[1..]);
    assert_eq!(rows.len(), 108);
    let write = |name: &str, part: &[&str]| {
        let path = dir.join(name);
        std::fs::write(&path, format!("{header}\n{}\n", part.join("\n"))).unwrap();
        path
    };
    let (first, last) = (
        write("first.csv", &rows[..72]),
        write("last.csv", &rows[72..]),
    );
    let robot = p(&src.join("robot.toml"));
    let cal = dir.join("cal");
    let fit = calibrate(
        &cal,
        &robot,
        &first,
        "link_offset,link_scale,tracker_frame",
        &[],
    );
    assert_eq!(fit["simulated"], false);
    let fit_rms = fit["residual_rms_um"].as_f64().unwrap();
    let combined = weighted_rms_um(&validate(&cal.join("calibrated.toml"), &first));
    assert!(
        (combined - fit_rms).abs() <= 1e-9 * fit_rms,
        "fit {fit_rms} um, calibrated.toml {combined} um"
    );
    let held = validate(&cal.join("calibrated.toml"), &last);
    let get = |who: &str, key: &str| held[who][key].as_f64().unwrap();
    println!(
        "held-out last third: calibrated {:.1} um / link {:.3} mm, nominal {:.1} um / link {:.3} mm",
        get("calibrated", "rms_um"),
        get("calibrated", "link_rms_mm"),
        get("reference", "rms_um"),
        get("reference", "link_rms_mm")
    );
    assert!(get("calibrated", "rms_um") < 0.5 * get("reference", "rms_um"));
    assert!(get("calibrated", "link_rms_mm") < 0.5 * get("reference", "link_rms_mm"));
    assert_eq!(held["calibrated"]["sessions"].as_array().unwrap().len(), 1);
    // Link offsets and scales fitted with the frame held at its rough registration: the file
    // (offsets and scales as known effects) still registers the held-out session and beats the
    // nominal robot there.
    let cal3 = dir.join("cal3");
    calibrate(&cal3, &robot, &first, "link_offset,link_scale", &[]);
    let held3 = validate(&cal3.join("calibrated.toml"), &last);
    assert!(
        held3["calibrated"]["rms_um"].as_f64().unwrap()
            < 0.5 * held3["reference"]["rms_um"].as_f64().unwrap()
    );
    // Force- and pose-dependent effects too (compliance reads the link forces at the
    // commanded pose, a pose map the commanded pose itself): the file still reproduces the fit.
    let cal2 = dir.join("cal2");
    let effects = "link_offset,link_scale,tracker_frame,compliance,pose_map_z_roll";
    let fit2 = calibrate(&cal2, &robot, &first, effects, &[])["residual_rms_um"]
        .as_f64()
        .unwrap();
    let combined2 = weighted_rms_um(&validate(&cal2.join("calibrated.toml"), &first));
    assert!(
        (combined2 - fit2).abs() <= 1e-9 * fit2,
        "with compliance and a pose map: fit {fit2} um, calibrated.toml {combined2} um"
    );
}

/// Tracker poses in the tracker's own frame (100 mm and a few degrees away), simulated with
/// link offsets: the fit registers the frame and refines it (`tracker_frame`), the file
/// reproduces the fit once `validate` has re-registered the session, and the held-out session
/// in another frame is predicted to the noise.
#[test]
fn tracker_sessions_in_their_own_frames_round_trip() {
    let robot = example("hexapod_66.toml");
    let truth = example("hexapod_66_truth.toml");
    let dir = scratch("roundtrip", "tracker-frame");
    let sim = |file: &str, seed: &str, frame: &str| {
        let path = dir.join(file);
        ok(&[
            "simulate",
            "--robot",
            &robot,
            "--random",
            "40",
            "--truth",
            &truth,
            "--truth-effect",
            "link_offset=20,-15,10,25,-20,15",
            "--measure",
            "poses",
            "--tracker-frame",
            frame,
            "--noise",
            "gaussian:2",
            "--orientation-noise-urad",
            "20",
            "--seed",
            seed,
            "--out",
            &p(&path),
        ]);
        path
    };
    let data = sim("train.csv", "1", "100,-40,20,1,-2,3");
    let held = sim("held.csv", "2", "-60,30,10,-2,1,-4");
    let cal = dir.join("cal");
    let sigmas = ["--pose-sigma-um", "10", "--orientation-sigma-urad", "20"];
    let fit = calibrate(&cal, &robot, &data, "link_offset,tracker_frame", &sigmas)
        ["residual_rms_um"]
        .as_f64()
        .unwrap();
    let file = weighted_rms_um(&validate(&cal.join("calibrated.toml"), &data));
    assert!(
        (file - fit).abs() <= 1e-9 * fit,
        "fit {fit} um, calibrated.toml {file} um"
    );
    let v = validate(&cal.join("calibrated.toml"), &held);
    let (c, r) = (
        v["calibrated"]["rms_um"].as_f64().unwrap(),
        v["reference"]["rms_um"].as_f64().unwrap(),
    );
    println!("tracker: fit {fit:.3} um, file {file:.3} um; held-out session calibrated {c:.2} um, nominal {r:.2} um");
    assert!(c < 4.0, "held-out position error {c} um on 2 um noise");
    assert!(c < 0.2 * r);
    let s = &v["calibrated"]["sessions"][0];
    assert!(s["rms_after_um"].as_f64().unwrap() <= s["rms_before_um"].as_f64().unwrap());
}

/// `compensate --from-home` then `validate --commands --from-home` against the simulated
/// truth: a machine with backlash reaches its targets when the first target's approach from
/// home is known.
#[test]
fn compensation_with_backlash_from_home_reaches_the_targets() {
    let robot = example("hexapod_66.toml");
    let dir = scratch("roundtrip", "compensate-from-home");
    let truth_text = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap();
    let truth = dir.join("truth.toml");
    std::fs::write(
        &truth,
        format!("{truth_text}\n[calibration.known_effects]\nbacklash = [-8.0, 6.0, -10.0, 5.0, -7.0, 9.0]\n"),
    )
    .unwrap();
    let data = dir.join("data.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "80",
        "--truth",
        &p(&truth),
        "--noise",
        "gaussian:0.5",
        "--seed",
        "4",
        "--out",
        &p(&data),
    ]);
    let cal = dir.join("cal");
    calibrate(&cal, &robot, &data, "backlash", &[]);
    let commands = dir.join("commands.csv");
    ok(&[
        "compensate",
        "--robot",
        &p(&cal.join("calibrated.toml")),
        "--poses",
        &example("targets.csv"),
        "--from-home",
        "--out",
        &p(&commands),
    ]);
    assert!(std::fs::read_to_string(&commands)
        .unwrap()
        .contains("SIMULATED"));
    let check = |from_home: bool| {
        let mut args = vec![
            "validate".to_string(),
            "--reference".into(),
            robot.clone(),
            "--commands".into(),
            p(&commands),
            "--truth".into(),
            p(&truth),
            "--json".into(),
        ];
        if from_home {
            args.push("--from-home".into());
        }
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        json(&ok(&a))
    };
    let v = check(true);
    let (c, u) = (
        v["compensated"]["position_max_um"].as_f64().unwrap(),
        v["reference"]["position_rms_um"].as_f64().unwrap(),
    );
    println!("compensate --from-home: worst target {c:.2} um, uncompensated RMS {u:.1} um");
    assert!(c < 5.0, "a compensated target missed by {c} um");
    assert!(c < 0.1 * u);
    // Checked as if the machine did not come from home, the first target's backlash is off.
    let w = check(false);
    assert!(
        w["per_target"][0]["position_um"].as_f64().unwrap()
            > v["per_target"][0]["position_um"].as_f64().unwrap()
    );
}

/// `refine` too writes the model it ended with: an undeclared backlash is found, and its
/// calibrated.toml reproduces the final fit on the training data.
#[test]
fn refine_writes_the_model_it_fitted() {
    let robot = example("hexapod_66.toml");
    let dir = scratch("roundtrip", "refine");
    let data = dir.join("data.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "80",
        "--truth",
        &example("hexapod_66_truth.toml"),
        "--truth-effect",
        "backlash=-8,6,-10,5,-7,9",
        "--noise",
        "gaussian:1",
        "--seed",
        "5",
        "--out",
        &p(&data),
    ]);
    let out = dir.join("refined");
    ok(&[
        "refine",
        "--robot",
        &robot,
        "--data",
        &p(&data),
        "--effects",
        "none",
        "--sigma-um",
        "1",
        "--out",
        &p(&out),
    ]);
    let r = read_json(&out.join("refine.json"));
    let effects: Vec<&str> = r["final"]["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_str().unwrap())
        .collect();
    assert!(effects.contains(&"backlash"), "{effects:?}");
    assert!(
        !effects.iter().any(|e| e.starts_with("pose_map")),
        "{effects:?}"
    );
    let fit = r["final"]["rms_um"].as_f64().unwrap();
    let file = validate(&out.join("calibrated.toml"), &data)["calibrated"]["rms_um"]
        .as_f64()
        .unwrap();
    println!("refine: {effects:?}, fit {fit:.4} um, file {file:.4} um");
    assert!(
        (fit - file).abs() <= 1e-9 * fit,
        "refine fit {fit} um, calibrated.toml {file} um"
    );
}

/// `simulate --truth` measures with the truth's own sensor sockets (its `[[sensor]]` tables),
/// as `validate` predicts with them: the truth reproduces its noise-free simulation, and the
/// robot with the nominal sockets does not.
#[test]
fn the_truths_sensor_sockets_are_the_ones_simulated() {
    let robot = example("hexapod_66.toml");
    let dir = scratch("roundtrip", "truth-sockets");
    let text = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap();
    let moved = text.replace(
        "base_mm = [375.877048314, 136.80805733, 100.0]",
        "base_mm = [375.917048314, 136.77805733, 100.02]",
    );
    assert_ne!(moved, text);
    let truth = dir.join("truth.toml");
    std::fs::write(&truth, moved).unwrap();
    let data = dir.join("exact.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "30",
        "--truth",
        &p(&truth),
        "--noise",
        "none",
        "--seed",
        "2",
        "--out",
        &p(&data),
    ]);
    let v = json(&ok(&[
        "validate",
        "--robot",
        &p(&truth),
        "--reference",
        &robot,
        "--data",
        &p(&data),
        "--json",
    ]));
    let exact = v["calibrated"]["max_um"].as_f64().unwrap();
    assert!(
        exact < 1e-6,
        "the truth misses its own simulation by {exact} um"
    );
    let s1 = v["groups"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["name"] == "s1")
        .unwrap();
    assert!(s1["reference"]["rms_um"].as_f64().unwrap() > 5.0, "{s1}");
}

/// Each kind of observation has its own noise: a tracker whose orientations are noise-free
/// and positions carry 2 um of noise gives no "outliers" (pooled, the tiny orientation
/// residuals made 59 of them), and a real spike in a position is still flagged.
#[test]
fn outliers_are_judged_per_kind_of_observation() {
    let robot = example("hexapod_66.toml");
    let dir = scratch("roundtrip", "outliers-per-kind");
    let data = dir.join("t.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "80",
        "--truth",
        &example("hexapod_66_truth.toml"),
        "--measure",
        "poses",
        "--noise",
        "gaussian:2",
        "--orientation-noise-urad",
        "0",
        "--seed",
        "4",
        "--out",
        &p(&data),
    ]);
    let fit = |file: &Path, out: &str| {
        let cal = dir.join(out);
        ok(&[
            "calibrate",
            "--robot",
            &robot,
            "--data",
            &p(file),
            "--out",
            &p(&cal),
        ]);
        read_json(&cal.join("calibration.json"))
    };
    let clean = fit(&data, "clean");
    assert_eq!(
        clean["outliers"].as_array().unwrap().len(),
        0,
        "{}",
        clean["outliers"]
    );
    // A 0.2 mm slip of the tracker on one row's x.
    let text = std::fs::read_to_string(&data).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header = lines.iter().position(|l| l.starts_with("pose,")).unwrap();
    let cols: Vec<&str> = lines[header].split(',').collect();
    let x = cols.iter().position(|c| *c == "x_mm").unwrap();
    let row = header + 10;
    let mut f: Vec<String> = lines[row].split(',').map(String::from).collect();
    f[x] = (f[x].parse::<f64>().unwrap() + 0.2).to_string();
    lines[row] = f.join(",");
    let spiked = dir.join("spiked.csv");
    std::fs::write(&spiked, lines.join("\n") + "\n").unwrap();
    let j = fit(&spiked, "spiked");
    let o = j["outliers"].as_array().unwrap();
    // The slip is flagged, the largest by far (least squares smears a little of it onto a
    // few others, which a robust loss would not).
    assert!(!o.is_empty() && o.len() <= 3, "{o:?}");
    let worst = o
        .iter()
        .max_by(|a, b| {
            let r = |x: &serde_json::Value| x["residual_um"].as_f64().unwrap().abs();
            r(a).total_cmp(&r(b))
        })
        .unwrap();
    assert_eq!(worst["line"].as_u64(), Some(row as u64 + 1), "{o:?}");
}
