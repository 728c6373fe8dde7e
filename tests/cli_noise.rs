//! Noise per kind of observation, end to end: a simulated tracker whose orientations are 250
//! times noisier than its positions (neither declared) makes `cpm calibrate` warn that the
//! kinds are weighed wrongly; `--noise-per-kind` estimates each kind's noise from its own
//! residual, writes it to calibrated.toml, and `validate` of that file reproduces the fit. A
//! gauge file beside the tracker file gets its own noise too. All data simulated.
#[path = "common/cli.rs"]
mod cli;

use std::path::{Path, PathBuf};

use cli::{calibrate_json, example, ok, p, scratch, validate_json};

fn simulate(out: &Path, measure: &str, noise_um: f64, extra: &[&str]) {
    let mut args = vec![
        "simulate".to_string(),
        "--robot".into(),
        example("hexapod_66.toml"),
        "--random".into(),
        "80".into(),
        "--truth".into(),
        example("hexapod_66_truth.toml"),
        "--measure".into(),
        measure.into(),
        "--noise".into(),
        format!("gaussian:{noise_um}"),
        "--seed".into(),
        "3".into(),
        "--out".into(),
        p(out),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(&args);
}

fn kind<'a>(cal: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    cal["noise_by_kind"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["kind"] == name)
        .unwrap_or_else(|| panic!("no {name} in {}", cal["noise_by_kind"]))
}

fn warned(cal: &serde_json::Value) -> bool {
    cal["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w.as_str().unwrap().starts_with("Noise not as weighed"))
}

#[test]
fn noise_per_kind_is_estimated_written_and_read_back() {
    let dir = scratch("noise", "tracker");
    let tracker = dir.join("tracker.csv");
    simulate(&tracker, "poses", 2.0, &["--orientation-noise-urad", "500"]);
    let robot = Path::new(&example("hexapod_66.toml")).to_path_buf();
    // Weighed by the defaults (10 um, 20 urad; `--noise-per-kind off`): said, and the
    // positions' residual is far above their noise.
    let plain = calibrate_json(
        &robot,
        &[&tracker],
        &["--noise-per-kind", "off"],
        &dir.join("plain"),
    );
    assert!(warned(&plain), "{}", plain["warnings"]);
    let pos_plain = kind(&plain, "tracker positions")["estimated"]
        .as_f64()
        .unwrap();
    // Estimated per kind: the default, since two kinds have no declared noise; the bare
    // flag asks for the same.
    let cal = calibrate_json(&robot, &[&tracker], &[], &dir.join("per-kind"));
    let flagged = calibrate_json(
        &robot,
        &[&tracker],
        &["--noise-per-kind"],
        &dir.join("flagged"),
    );
    assert_eq!(cal["noise_by_kind"], flagged["noise_by_kind"]);
    assert!(!warned(&cal), "{}", cal["warnings"]);
    let pos = kind(&cal, "tracker positions")["estimated"]
        .as_f64()
        .unwrap();
    let rot = kind(&cal, "tracker orientations")["estimated"]
        .as_f64()
        .unwrap();
    println!(
        "tracker 2 um / 500 urad simulated: positions {pos_plain:.2} um from the residual weighed by the defaults; per kind {pos:.3} um and {rot:.1} urad"
    );
    assert!((pos / 2.0 - 1.0).abs() < 0.15, "{pos}");
    assert!((rot / 500.0 - 1.0).abs() < 0.15, "{rot}");
    assert!(pos_plain > 5.0, "{pos_plain}");
    // The file carries the weights, and validate reproduces the fit with them.
    let desc = cpm::geometry::RobotDescription::load(dir.join("per-kind/calibrated.toml")).unwrap();
    let c = desc.calibration.unwrap();
    let (ws, wr) = (
        c.tracker_position_sigma_um.unwrap(),
        c.tracker_orientation_sigma_urad.unwrap(),
    );
    let same = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b;
    let assumed = |name: &str| kind(&cal, name)["assumed"].as_f64().unwrap();
    assert!(same(ws, assumed("tracker positions")), "{ws}");
    assert!(same(wr, assumed("tracker orientations")), "{wr}");
    let v = validate_json(&dir.join("per-kind/calibrated.toml"), &[&tracker]);
    let (vp, vr) = (
        v["calibrated"]["rms_um"].as_f64().unwrap(),
        v["calibrated"]["orientation_rms_urad"].as_f64().unwrap(),
    );
    // The file reproduces each kind's residual in its own unit; the weighted mix has no
    // figure in um (calibration.json's residual_rms_um and sigma_um are null).
    for (file, name) in [(vp, "tracker positions"), (vr, "tracker orientations")] {
        let fit = cli::kind_rms(&cal, name);
        assert!(same(file, fit), "{name}: fit {fit}, file {file}");
    }
    assert_eq!(cal["residual_weighted"], true);
    assert!(
        cal["residual_rms_um"].is_null() && cal["sigma_um"].is_null(),
        "{cal}"
    );
}

#[test]
fn a_gauge_beside_a_tracker_gets_its_own_noise() {
    let dir = scratch("noise", "mixed");
    let (tracker, gauge) = (dir.join("tracker.csv"), dir.join("gauge.csv"));
    simulate(&tracker, "poses", 20.0, &["--orientation-noise-urad", "40"]);
    simulate(&gauge, "lengths", 1.0, &[]);
    let robot = Path::new(&example("hexapod_66.toml")).to_path_buf();
    let cal = calibrate_json(
        &robot,
        &[&gauge, &tracker],
        &["--noise-per-kind"],
        &dir.join("cal"),
    );
    let kinds = cal["noise_by_kind"].as_array().unwrap();
    let gauges: Vec<f64> = kinds
        .iter()
        .filter(|k| k["kind"].as_str().unwrap().starts_with("gauge"))
        .map(|k| k["estimated"].as_f64().unwrap())
        .collect();
    let pos = kind(&cal, "tracker positions")["estimated"]
        .as_f64()
        .unwrap();
    println!("gauge 1 um beside a tracker at 20 um: gauges {gauges:.3?} um, tracker positions {pos:.2} um");
    assert_eq!(gauges.len(), 3);
    for g in &gauges {
        assert!((g - 1.0).abs() < 0.25, "{gauges:?}");
    }
    assert!((pos / 20.0 - 1.0).abs() < 0.15, "{pos}");
    assert!(!warned(&cal), "{}", cal["warnings"]);
}

/// The example hexapod with `instruments` (TOML tables) as robot and truth in `dir`, and
/// SIMULATED point (10 um) and tilt (50 urad) files of 60 poses: (robot, points, tilts).
fn points_and_tilts(dir: &Path, instruments: &str) -> (PathBuf, PathBuf, PathBuf) {
    let robot = std::fs::read_to_string(example("hexapod_66.toml")).unwrap() + instruments;
    let truth = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap() + instruments;
    let (r, t) = (dir.join("robot.toml"), dir.join("truth.toml"));
    std::fs::write(&r, robot).unwrap();
    std::fs::write(&t, truth).unwrap();
    let (points, tilts) = (dir.join("points.csv"), dir.join("tilts.csv"));
    for (file, measure, noise, seed) in [(&points, "points", 10, "1"), (&tilts, "tilts", 50, "2")] {
        ok(&[
            "simulate",
            "--robot",
            &p(&r),
            "--truth",
            &p(&t),
            "--random",
            "60",
            "--measure",
            measure,
            "--noise",
            &format!("gaussian:{noise}"),
            "--seed",
            seed,
            "--out",
            &p(file),
        ]);
    }
    (r, points, tilts)
}

/// Reflectors and an inclinometer (points at 10 um, angles at 50 urad, neither declared: the
/// defaults weigh the angles as 20 urad): each kind's noise is found, and the file written
/// with those weights passes calibrate's own read-back check (the angles weighed as angles,
/// not as tracker orientations).
#[test]
fn points_and_tilts_get_their_own_noise() {
    let dir = scratch("noise", "points-tilts");
    let instruments = "\n[[target]]\nname = \"smr1\"\nplatform_mm = [90.0, 10.0, 30.0]\n\n[[target]]\nname = \"smr2\"\nplatform_mm = [-50.0, 80.0, 30.0]\n\n[[inclinometer]]\nname = \"scl3300\"\naxes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\n";
    let (r, points, tilts) = points_and_tilts(&dir, instruments);
    let cal = calibrate_json(
        &r,
        &[&points, &tilts],
        &["--effects", "none", "--noise-per-kind"],
        &dir.join("cal"),
    );
    let (pt, an) = (
        kind(&cal, "point targets")["estimated"].as_f64().unwrap(),
        kind(&cal, "inclinometer angles")["estimated"]
            .as_f64()
            .unwrap(),
    );
    println!("points 10 um, angles 50 urad simulated: estimated {pt:.2} um, {an:.1} urad");
    assert!((pt / 10.0 - 1.0).abs() < 0.15, "{pt}");
    assert!((an / 50.0 - 1.0).abs() < 0.15, "{an}");
}

/// The noise each instrument table declares (`[[target]] sigma_um`, `[[inclinometer]]
/// sigma_urad`) weighs its measurements; `calibrated.toml` keeps it; two targets declaring
/// different noise are refused with the field named.
#[test]
fn noise_declared_per_instrument_table_weighs_its_measurements() {
    let dir = scratch("noise", "declared");
    let instruments = |second: &str| {
        format!("\n[[target]]\nname = \"smr1\"\nplatform_mm = [90.0, 10.0, 30.0]\nsigma_um = 10.0\n\n[[target]]\nname = \"smr2\"\nplatform_mm = [-50.0, 80.0, 30.0]\nsigma_um = {second}\n\n[[inclinometer]]\nname = \"scl3300\"\naxes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\nsigma_urad = 50.0\n")
    };
    let (r, points, tilts) = points_and_tilts(&dir, &instruments("10.0"));
    let cal = calibrate_json(
        &r,
        &[&points, &tilts],
        &["--effects", "none"],
        &dir.join("cal"),
    );
    assert_eq!(kind(&cal, "point targets")["assumed"].as_f64(), Some(10.0));
    assert_eq!(
        kind(&cal, "inclinometer angles")["assumed"].as_f64(),
        Some(50.0)
    );
    assert!(!warned(&cal), "{}", cal["warnings"]);
    let written = std::fs::read_to_string(dir.join("cal/calibrated.toml")).unwrap();
    assert!(written.contains("sigma_um = 10.0") && written.contains("sigma_urad = 50.0"));
    // Two targets, two noises: refused, naming the file and field.
    let bad = dir.join("bad.toml");
    let base = std::fs::read_to_string(example("hexapod_66.toml")).unwrap();
    std::fs::write(&bad, base + &instruments("12.0")).unwrap();
    let o = cli::cpm(&["identifiability", "--robot", &p(&bad), "--random", "10"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(
        err.contains("bad.toml") && err.contains("sigma_um") && err.contains("declare one noise"),
        "{err}"
    );
}
