//! A 6-6 hexapod measured by a tracker: simulated pose measurements with link offsets and
//! scales, read back, and calibrated with `link_offset` and `link_scale` unknowns.
#[path = "common/cli.rs"]
mod cli;
#[path = "common/ingest.rs"]
mod ingest;

use std::path::{Path, PathBuf};
use std::process::Command;

use cpm::geometry::{InstallationErrors, RobotDescription};
use cpm::io::{ReadOptions, Robot};
use ingest::read_data;

const OFFSETS_UM: [f64; 6] = [30.0, -20.0, 15.0, 0.0, -25.0, 10.0];
const SCALES_PPM: [f64; 6] = [200.0, -150.0, 0.0, 100.0, 50.0, -80.0];

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/hexapod_66.toml")
}

/// The example hexapod with Table 2 errors and link reading models off by the offsets and
/// scales above.
fn truth_file(dir: &Path) -> PathBuf {
    let mut d = RobotDescription::load(example()).unwrap();
    d.installation_errors_um = Some(
        cpm::geometry::description::InstallationErrorsSpec::from_errors(
            &InstallationErrors::paper_table2(),
        ),
    );
    for (i, l) in d.links.iter_mut().enumerate() {
        let f = 1.0 + SCALES_PPM[i] * 1e-6;
        l.length_at_zero_mm = l.length_at_zero_mm * f + OFFSETS_UM[i] * 1e-3;
        l.mm_per_unit *= f;
    }
    let path = dir.join("truth.toml");
    std::fs::write(&path, d.to_toml_string().unwrap()).unwrap();
    path
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn simulate_tracker(dir: &Path) -> PathBuf {
    let truth = truth_file(dir);
    let data = dir.join("tracker.csv");
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(["simulate", "--robot"])
        .arg(example())
        .args(["--random", "40", "--range-deg", "12", "--truth"])
        .arg(&truth)
        .args([
            "--measure",
            "poses",
            "--noise",
            "gaussian:1",
            "--orientation-noise-urad",
            "2",
        ])
        .args(["--seed", "11", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    data
}

/// `cpm calibrate` with link_offset and link_scale unknowns, noise 1 um (readings and tracker
/// positions) and 2 urad; its calibration.json.
fn calibrate_offsets_and_scales(robot: &Path, data: &[&Path], out: &Path) -> serde_json::Value {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cpm"));
    c.args(["calibrate", "--robot"]).arg(robot);
    for f in data {
        c.arg("--data").arg(f);
    }
    let o = c
        .args(["--effects", "link_offset,link_scale", "--sigma-um", "1"])
        .args([
            "--pose-sigma-um",
            "1",
            "--orientation-sigma-urad",
            "2",
            "--out",
        ])
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap()
}

#[test]
fn simulated_tracker_file_reads_back() {
    let d = scratch("tracker-read");
    let data = simulate_tracker(&d);
    let text = std::fs::read_to_string(&data).unwrap();
    assert!(text.starts_with("# simulated by cpm"));
    let robot = Robot::load(&example()).unwrap();
    let f = read_data(&text, "tracker.csv", &robot, &ReadOptions::default()).unwrap();
    let c = &f.campaign;
    assert!(c.simulated);
    assert_eq!(c.pose_measurements.len(), 40);
    assert!(c.readings.is_empty());
    // The measured poses differ from the commanded ones by the machine's errors: tens of um.
    let cmd = c.commanded_lengths_mm.as_ref().unwrap();
    let mut worst: f64 = 0.0;
    for (m, l) in c.pose_measurements.iter().zip(cmd) {
        let ik = cpm::kinematics::inverse_lengths(&robot.table, &m.measured);
        for (a, b) in ik.iter().zip(l) {
            worst = worst.max((a - b).abs());
        }
    }
    assert!(worst > 0.01 && worst < 1.0, "{worst} mm");
}

#[test]
fn hexapod_66_pose_measurements_with_offset_and_scale_unknowns() {
    let d = scratch("tracker-calibrate");
    let data = simulate_tracker(&d);
    let out = d.join("cal");
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(["calibrate", "--robot"])
        .arg(example())
        .arg("--data")
        .arg(&data)
        .args([
            "--effects",
            "link_offset,link_scale",
            "--pose-sigma-um",
            "1",
            "--orientation-sigma-urad",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["simulated"], true);
    let effects = json["effects"].as_array().unwrap();
    let offsets = &effects
        .iter()
        .find(|e| e["effect"] == "link_offset")
        .unwrap()["parameters"];
    let scales = &effects
        .iter()
        .find(|e| e["effect"] == "link_scale")
        .unwrap()["parameters"];
    for i in 0..6 {
        let (v, s) = (
            offsets[i]["value"].as_f64().unwrap(),
            offsets[i]["std"].as_f64().unwrap(),
        );
        assert!(
            (v - OFFSETS_UM[i]).abs() < 4.0 * s + 1.0,
            "offset {i}: {v} +- {s}"
        );
        let (v, s) = (
            scales[i]["value"].as_f64().unwrap(),
            scales[i]["std"].as_f64().unwrap(),
        );
        assert!(
            (v - SCALES_PPM[i]).abs() < 4.0 * s + 5.0,
            "scale {i}: {v} +- {s}"
        );
    }
    // The calibrated description carries the offsets and scales as known effects; folded into
    // a reading model (what a controller takes) they act exactly.
    let cal = Robot::load(&out.join("calibrated.toml")).unwrap();
    for i in 0..6 {
        let (o, s) = (
            offsets[i]["value"].as_f64().unwrap(),
            scales[i]["value"].as_f64().unwrap(),
        );
        let u = 300.0;
        let (l0, k) = cpm::io::robot::folded_reading_model(&cal, i);
        assert!((l0 + k * u - (u * (1.0 + s * 1e-6) + o * 1e-3)).abs() < 1e-9);
    }
}

#[test]
fn tracker_frame_gauge_freedoms_are_reported() {
    let d = scratch("tracker-frame");
    let data = simulate_tracker(&d);
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(["identifiability", "--robot"])
        .arg(example())
        .arg("--data")
        .arg(&data)
        .args(["--effects", "tracker_frame", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["parameters"], 42);
    assert_eq!(
        v["rank"], 36,
        "the tracker frame and the base move together: 6 gauge freedoms"
    );
    let words: Vec<String> = v["blind_directions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["description"].as_str().unwrap().to_string())
        .collect();
    assert!(
        words.iter().any(|w| w.contains("tracker frame")),
        "{words:?}"
    );
}

#[test]
fn length_readings_and_tracker_poses_calibrate_together() {
    let d = scratch("tracker-merged");
    let tracker = simulate_tracker(&d);
    let lengths = d.join("lengths.csv");
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(["simulate", "--robot"])
        .arg(example())
        .args(["--random", "20", "--truth"])
        .arg(d.join("truth.toml"))
        .args(["--noise", "gaussian:1", "--seed", "12", "--out"])
        .arg(&lengths)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = calibrate_offsets_and_scales(&example(), &[&lengths, &tracker], &d.join("cal"));
    assert_eq!(json["readings"], 60);
    assert_eq!(json["pose_measurements"], 40);
    assert_eq!(json["poses"], 60);
    assert_eq!(json["identifiability"]["rank"], 48);
    assert!(cli::length_rms_um(&json) < 2.0);
}

#[test]
fn known_tracker_registration_and_link_effects_are_applied_on_both_sides() {
    // A description that knows its tracker's registration (100 um, 500 urad) and a backlash:
    // data simulated with it and calibrated with it fit to the noise; calibrated without
    // them, the same data leave a residual far above the noise.
    let d = scratch("tracker-known");
    let mut r = RobotDescription::load(example()).unwrap();
    r.calibration
        .get_or_insert_with(Default::default)
        .known_effects = [
        (
            "tracker_frame".to_string(),
            vec![100.0, -50.0, 30.0, 0.0, 0.0, 500.0],
        ),
        ("backlash".to_string(), vec![8.0, -6.0, 5.0, 7.0, -8.0, 6.0]),
    ]
    .into_iter()
    .collect();
    let known = d.join("known.toml");
    std::fs::write(&known, r.to_toml_string().unwrap()).unwrap();
    // The true machine: Table 2, the link reading models' offsets and scales, and the same
    // registration and backlash.
    let truth = truth_file(&d);
    let mut t = RobotDescription::load(&truth).unwrap();
    t.calibration = r.calibration.clone();
    std::fs::write(&truth, t.to_toml_string().unwrap()).unwrap();
    let data = d.join("tracker.csv");
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(["simulate", "--robot"])
        .arg(&known)
        .args(["--random", "40", "--range-deg", "12", "--truth"])
        .arg(&truth)
        .args(["--measure", "poses", "--noise", "gaussian:1"])
        .args(["--orientation-noise-urad", "2", "--seed", "5", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rms = |robot: &Path, name: &str| {
        cli::length_rms_um(&calibrate_offsets_and_scales(
            robot,
            &[&data],
            &d.join(name),
        ))
    };
    let with_json = calibrate_offsets_and_scales(&known, &[&data], &d.join("with"));
    // calibration.json says which known values the fit applied.
    let applied: Vec<&str> = with_json["known_effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["effect"].as_str().unwrap())
        .collect();
    assert_eq!(applied, ["backlash", "tracker_frame"]);
    let report = std::fs::read_to_string(d.join("with").join("report.md")).unwrap();
    assert!(report.contains("known backlash, tracker_frame"), "{report}");
    let with = cli::length_rms_um(&with_json);
    let without = rms(&example(), "without");
    eprintln!("tracker data, residual RMS: {with:.3} um with the known registration and backlash, {without:.3} um without");
    assert!(with < 1.3, "with the known values: {with} um");
    assert!(
        without > 3.0 * with,
        "without: {without} um, with {with} um"
    );
}
