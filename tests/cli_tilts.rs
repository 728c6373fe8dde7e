//! Inclinometers end to end: `cpm simulate --measure tilts` from a truth whose instrument is
//! mounted off its drawing, two sessions each levelled differently, `cpm calibrate`, `cpm
//! validate` of its file on the training sessions (the fit reproduced) and on a held-out
//! session re-levelled, `cpm identifiability` naming what tilts cannot see, and bad tilt files
//! refused with the file, line and field named.
#[path = "common/cli.rs"]
mod cli;

use std::path::{Path, PathBuf};

use cli::{calibrate_json, calibrate_refused, example, ok, p, scratch, validate_json};

const NOISE_URAD: f64 = 20.0;

fn inclinometer(mount: Option<[f64; 3]>) -> String {
    let mut s = String::from(
        "\n[[inclinometer]]\nname = \"scl3300\"\naxes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\n",
    );
    if let Some(m) = mount {
        s.push_str(&format!("mount_rpy_deg = [{}, {}, {}]\n", m[0], m[1], m[2]));
    }
    s
}

/// The example hexapod with the inclinometer as drawn, and its truth with the instrument
/// mounted 0.1-0.3 deg off.
fn robots(dir: &Path) -> (PathBuf, PathBuf) {
    let robot = dir.join("robot.toml");
    let truth = dir.join("truth.toml");
    let r = std::fs::read_to_string(example("hexapod_66.toml")).unwrap();
    std::fs::write(&robot, r + &inclinometer(None)).unwrap();
    let t = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap();
    std::fs::write(&truth, t + &inclinometer(Some([0.15, -0.1, 0.3]))).unwrap();
    (robot, truth)
}

fn simulate(robot: &Path, truth: &Path, out: &Path, poses: usize, seed: u64, tilt: &str) {
    ok(&[
        "simulate",
        "--robot",
        &p(robot),
        "--truth",
        &p(truth),
        "--random",
        &poses.to_string(),
        "--range-deg",
        "10",
        "--measure",
        "tilts",
        "--noise",
        &format!("gaussian:{NOISE_URAD}"),
        "--seed",
        &seed.to_string(),
        "--base-tilt-deg",
        tilt,
        "--out",
        &p(out),
    ]);
}

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text).unwrap()
}

#[test]
fn tilts_round_trip_and_a_held_out_session_re_levelled() {
    let dir = scratch("tilts", "round-trip");
    let (robot, truth) = robots(&dir);
    let (a, b, held) = (dir.join("a.csv"), dir.join("b.csv"), dir.join("held.csv"));
    simulate(&robot, &truth, &a, 150, 1, "0.05,-0.08");
    simulate(&robot, &truth, &b, 150, 2, "-0.03,0.02");
    simulate(&robot, &truth, &held, 80, 3, "0.1,0.06");
    let cal = dir.join("cal");
    let noise = NOISE_URAD.to_string();
    // The reference noise of the weighting equal to the angle noise: residuals in urad.
    let report = calibrate_json(
        &robot,
        &[&a, &b],
        &["--sigma-um", &noise, "--orientation-sigma-urad", &noise],
        &cal,
    );
    // Angles alone: the residual's RMS is in urad, the inclinometer's kind (calibration.json's
    // residual_rms_um is null: no figure in um).
    assert!(
        report["residual_rms_um"].is_null(),
        "{}",
        report["residual_rms_um"]
    );
    let fit = cli::kind_rms(&report, "inclinometer angles");
    assert!((fit - NOISE_URAD).abs() < 0.1 * NOISE_URAD, "fit RMS {fit}");
    let calibrated = cal.join("calibrated.toml");
    // The file reproduces the fit on the training sessions (each re-levelled).
    let back = validate_json(&calibrated, &[&a, &b]);
    let file = back["calibrated"]["orientation_rms_urad"].as_f64().unwrap();
    eprintln!("tilts: fit RMS {fit} urad, file RMS {file} urad");
    assert!((file - fit).abs() <= 1e-9 * fit, "fit {fit}, file {file}");
    // A held-out session, levelled otherwise: the calibrated mount predicts it to the noise,
    // the drawing's does not.
    let v = validate_json(&calibrated, &[&held]);
    let (c, r) = (
        v["calibrated"]["orientation_rms_urad"].as_f64().unwrap(),
        v["reference"]["orientation_rms_urad"].as_f64().unwrap(),
    );
    eprintln!("tilts held-out: calibrated {c} urad, reference {r} urad");
    assert!((c - NOISE_URAD).abs() < 0.15 * NOISE_URAD, "held-out {c}");
    assert!(r > 10.0 * NOISE_URAD, "reference {r}");
    let s = &v["calibrated"]["sessions"][0];
    let sd = s["frame_sd"].as_array().unwrap();
    assert!(sd[..2]
        .iter()
        .all(|x| x.as_f64().is_some_and(|x| x > 0.0 && x < 50.0)));
    // The calibrated description carries the fitted mount.
    let text = std::fs::read_to_string(&calibrated).unwrap();
    assert!(text.contains("mount_rpy_deg"), "{text}");
}

#[test]
fn tilts_identify_orientation_only_and_say_so() {
    let dir = scratch("tilts", "identifiability");
    let (robot, truth) = robots(&dir);
    let data = dir.join("id.csv");
    simulate(&robot, &truth, &data, 150, 5, "0,0");
    let v = json(&ok(&[
        "identifiability",
        "--robot",
        &p(&robot),
        "--data",
        &p(&data),
        "--sigma-um",
        "20",
        "--json",
    ]));
    let rank = v["rank"].as_u64().unwrap();
    let n = v["parameters"].as_u64().unwrap();
    let words = v["blind_directions"].to_string();
    eprintln!("tilts: rank {rank} of {n}: {words}");
    // 36 joints + 3 mount + 2 levelling: positions are invisible to an inclinometer.
    assert_eq!(n, 41);
    assert!(rank < 36, "{rank}");
    assert!(
        words.contains("all base joints translated together"),
        "{words}"
    );
    assert!(
        words.contains("all platform joints translated together"),
        "{words}"
    );
}

#[test]
fn bad_tilt_files_name_file_line_and_field() {
    let dir = scratch("tilts", "bad");
    let (robot, _) = robots(&dir);
    let good = dir.join("good.csv");
    simulate(&robot, &robot, &good, 10, 7, "0,0");
    let text = std::fs::read_to_string(&good).unwrap();
    let run = |name: &str, text: String| -> String {
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        calibrate_refused(&robot, &f)
    };
    let e = run("unknown.csv", text.replacen(",scl3300,", ",imu9,", 1));
    assert!(
        e.contains("unknown.csv:3") && e.contains("inclinometer") && e.contains("imu9"),
        "{e}"
    );
    // Line 3, the first angle: not a number.
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let names: Vec<&str> = lines[1].split(',').collect();
    let i = names.iter().position(|h| *h == "angle_1_deg").unwrap();
    let mut cells: Vec<String> = lines[2].split(',').map(str::to_string).collect();
    cells[i] = "0.1x".into();
    lines[2] = cells.join(",");
    let e = run("nan.csv", lines.join("\n") + "\n");
    assert!(e.contains("nan.csv:3") && e.contains("angle_1_deg"), "{e}");
}

#[test]
fn a_mixed_campaign_gauges_points_and_tilts_in_one_fit() {
    let dir = scratch("tilts", "mixed");
    // One description with the example's gauges, three reflectors and the inclinometer.
    let targets: String = [
        ("smr1", [90.0, 10.0, 30.0]),
        ("smr2", [-50.0, 80.0, 25.0]),
        ("smr3", [-40.0, -85.0, 35.0]),
    ]
    .iter()
    .map(|(n, drawn)| {
        format!(
            "\n[[target]]\nname = \"{n}\"\nplatform_mm = [{}, {}, {}]\n",
            drawn[0], drawn[1], drawn[2]
        )
    })
    .collect();
    let (robot, truth) = robots(&dir);
    let r = std::fs::read_to_string(&robot).unwrap() + &targets;
    std::fs::write(&robot, r).unwrap();
    let gauges = dir.join("gauges.csv");
    let points = dir.join("points.csv");
    let tilts = dir.join("tilts.csv");
    let held = dir.join("held.csv");
    let sim = |out: &Path, extra: &[&str]| {
        let (r, t, o) = (p(&robot), p(&truth), p(out));
        let mut args = vec!["simulate", "--robot", &r, "--truth", &t, "--out", &o];
        args.extend_from_slice(extra);
        ok(&args);
    };
    sim(
        &gauges,
        &["--random", "30", "--noise", "gaussian:2", "--seed", "9"],
    );
    sim(
        &points,
        &[
            "--random",
            "40",
            "--measure",
            "points",
            "--noise",
            "gaussian:5",
            "--seed",
            "10",
            "--tracker-frame",
            "1500,200,-100,0,0,30",
        ],
    );
    simulate(&robot, &truth, &tilts, 100, 11, "0.04,-0.02");
    simulate(&robot, &truth, &held, 60, 12, "-0.05,0.03");
    let cal = dir.join("cal");
    let report = calibrate_json(
        &robot,
        &[&gauges, &points, &tilts],
        &[
            "--sigma-um",
            "2",
            "--pose-sigma-um",
            "5",
            "--orientation-sigma-urad",
            "20",
        ],
        &cal,
    );
    // Every kind is counted, in calibration.json and report.md alike (issue 61: a tilt
    // campaign was 'Data: 0 length readings and 0 tracker pose measurements at 285 poses').
    let (n_points, n_tilts) = (
        report["point_measurements"].as_u64().unwrap(),
        report["tilt_measurements"].as_u64().unwrap(),
    );
    // 40 poses of three reflectors; 100 poses of a two-axis inclinometer.
    assert_eq!((n_points, n_tilts), (120, 200));
    let md = std::fs::read_to_string(cal.join("report.md")).unwrap();
    let line = format!(
        "- Data: {} length readings, 0 tracker pose measurements, {n_points} reflector points ({} coordinates) and {n_tilts} inclinometer angles at",
        report["readings"], 3 * n_points
    );
    assert!(md.contains(&line), "{line}\n{md}");
    // Together the instruments determine every parameter: the gauges fix what the frames and
    // the levelling leave free.
    let id = &report["identifiability"];
    assert_eq!(id["rank"], id["parameters"], "{id}");
    // Every kind fits to its declared noise: the weighted RMS is about 1 sigma, and each kind's
    // RMS in its own unit near its noise (calibration.json has no figure in um for the mix).
    let fit = report["weighted_rms_in_sigma"].as_f64().unwrap();
    assert!((fit - 1.0).abs() < 0.2, "{fit}");
    assert!(report["residual_rms_um"].is_null());
    let points = cli::kind_rms(&report, "point targets");
    assert!((points - 5.0).abs() < 1.0, "{points} um");
    let angles = cli::kind_rms(&report, "inclinometer angles");
    assert!(
        (angles - NOISE_URAD).abs() < 0.2 * NOISE_URAD,
        "{angles} urad"
    );
    // The calibrated file predicts a held-out inclinometer session (re-levelled) to the noise.
    let v = validate_json(&cal.join("calibrated.toml"), &[&held]);
    let c = v["calibrated"]["orientation_rms_urad"].as_f64().unwrap();
    assert!((c - NOISE_URAD).abs() < 0.15 * NOISE_URAD, "{c}");
}

/// Exact angles (`--noise none`) flag no outlier (one was flagged at 0.0 urad: the robust
/// spread of exact residuals is rounding), as exact gauge readings flag none.
#[test]
fn exact_angles_flag_no_outlier() {
    let d = scratch("tilts", "exact");
    let (robot, truth) = robots(&d);
    let data = d.join("exact.csv");
    ok(&[
        "simulate",
        "--robot",
        &p(&robot),
        "--truth",
        &p(&truth),
        "--random",
        "40",
        "--range-deg",
        "10",
        "--measure",
        "tilts",
        "--noise",
        "none",
        "--seed",
        "5",
        "--out",
        &p(&data),
    ]);
    let j = calibrate_json(&robot, &[&data], &[], &d.join("cal"));
    assert_eq!(
        j["outliers"].as_array().unwrap().len(),
        0,
        "{}",
        j["outliers"]
    );
    // Nor a weighted RMS of 0.871 sigma for a zero residual: the ratio of two roundings.
    let md = std::fs::read_to_string(d.join("cal/report.md")).unwrap();
    assert!(md.contains("the data are fitted exactly"), "{md}");
}

/// Issue 60 item 10: a weighted figure is never written in um. Angles alone (SIMULATED, 40
/// poses, 20 urad noise): before, calibration.json's `residual_rms_um` held the weighted
/// figure (9.836 for residuals of 19.67 urad) and `sigma_um` a noise of no instrument. Now
/// every figure in um is null, the angles' RMS is in urad and equals the RMS of
/// residuals.csv, and refine.json writes its figures weighted, in sigma.
#[test]
fn weighted_figures_are_never_written_in_um() {
    let dir = scratch("tilts", "weighted");
    let (robot, truth) = robots(&dir);
    let data = dir.join("angles.csv");
    simulate(&robot, &truth, &data, 40, 8, "0.05,-0.08");
    let out = dir.join("cal");
    let summary = json(&ok(&[
        "calibrate",
        "--robot",
        &p(&robot),
        "--data",
        &p(&data),
        "--json",
        "--out",
        &p(&out),
    ]));
    assert_eq!(summary["residual_weighted"], true, "{summary}");
    assert!(summary["residual_rms_um"].is_null(), "{summary}");
    let cal = json(&std::fs::read_to_string(out.join("calibration.json")).unwrap());
    for key in ["residual_rms_um", "initial_rms_um", "sigma_um"] {
        assert!(cal[key].is_null(), "{key}: {}", cal[key]);
    }
    assert_eq!(cal["residual_weighted"], true);
    // The angles' RMS, in urad, is the RMS of the residuals the file lists.
    let csv = std::fs::read_to_string(out.join("residuals.csv")).unwrap();
    let values: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| {
            assert!(l.contains(",urad,"), "{l}");
            l.rsplit(',').next().unwrap().parse().unwrap()
        })
        .collect();
    assert_eq!(values.len(), 80);
    let rms = (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt();
    let angles = cli::kind_rms(&cal, "inclinometer angles");
    assert!(
        (angles - rms).abs() <= 1e-6 * rms,
        "{angles} urad vs residuals.csv {rms} urad"
    );
    assert!(
        (angles - NOISE_URAD).abs() < 0.3 * NOISE_URAD,
        "{angles} urad"
    );
    let w = cal["weighted_rms_in_sigma"].as_f64().unwrap();
    assert!(w.is_finite() && w > 0.0, "{w}");
    // refine: every RMS of refine.json in sigma, none in um.
    let refined = dir.join("refined");
    ok(&[
        "refine",
        "--robot",
        &p(&robot),
        "--data",
        &p(&data),
        "--out",
        &p(&refined),
    ]);
    let doc = json(&std::fs::read_to_string(refined.join("refine.json")).unwrap());
    assert_eq!(doc["residual_weighted"], true);
    fn walk(v: &serde_json::Value, found: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    if k.contains("rms") && k.ends_with("_um") {
                        assert!(x.is_null(), "{k}: {x}");
                        let stem = k.strip_suffix("_um").unwrap();
                        assert!(m.contains_key(&format!("{stem}_in_sigma")), "{k}");
                        found.push(k.clone());
                    }
                    walk(x, found);
                }
            }
            serde_json::Value::Array(a) => a.iter().for_each(|x| walk(x, found)),
            _ => {}
        }
    }
    let mut found = Vec::new();
    walk(&doc, &mut found);
    assert!(found.len() >= 4, "{found:?}");
    let (start, end) = (
        doc["initial"]["rms_in_sigma"].as_f64().unwrap(),
        doc["final"]["rms_in_sigma"].as_f64().unwrap(),
    );
    assert!(end <= start * (1.0 + 1e-9) && end > 0.0, "{start} -> {end}");
}
