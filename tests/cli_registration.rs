//! Tracker logs as a real instrument writes them: in the tracker's own frame (50-300 mm and
//! 1-10 deg from the base frame) with link readings whose zero is off by about 20 mm.
//! `cpm calibrate` and `cpm refine` take them with no hand registration, and the registration
//! they report matches the transform the test applied.
//!
//! The logs are SIMULATED: `cpm simulate --measure poses` writes a log in the base frame,
//! and this test moves it into another frame with nalgebra (independently of the code under
//! test) and shifts the readings.
#[path = "common/cli.rs"]
mod cli;
use std::path::{Path, PathBuf};
use std::process::Command;

use cpm::geometry::Pose;
use nalgebra::{Rotation3, Vector3};

/// Reading offsets, mm: a log's reading is the true length minus this.
const OFFSETS_MM: [f64; 6] = [20.0, -18.0, 15.0, -22.0, 19.0, -16.0];

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/hexapod_66.toml")
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-reg-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cpm(args: &[&str], paths: &[(&str, &Path)]) -> std::process::Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cpm"));
    c.args(args);
    for (flag, p) in paths {
        c.arg(flag).arg(p);
    }
    c.output().unwrap()
}

/// A simulated tracker log in the base frame: `poses` random poses, tracker noise 10 um and
/// 20 urad (the defaults cpm assumes), `table2` to give the machine the paper's installation
/// errors.
fn simulate(dir: &Path, name: &str, poses: usize, seed: u64, table2: bool) -> String {
    let out = dir.join(name);
    let n = poses.to_string();
    let s = seed.to_string();
    let mut args = vec![
        "simulate",
        "--random",
        &n,
        "--range-deg",
        "12",
        "--measure",
        "poses",
        "--noise",
        "gaussian:10",
        "--orientation-noise-urad",
        "20",
        "--seed",
        &s,
    ];
    if table2 {
        args.push("--paper-table2");
    }
    let o = cpm(&args, &[("--robot", &example()), ("--out", &out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read_to_string(out).unwrap()
}

/// The log seen by a tracker at `frame` (base to tracker: `p_t = R p + t`), readings shifted
/// by -OFFSETS_MM; orientation as roll/pitch/yaw or as a quaternion.
fn in_frame(text: &str, frame: &Pose, quaternion: bool) -> String {
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        if f[0] == "pose" {
            let mut h: Vec<&str> = f[..10].to_vec();
            if quaternion {
                h.extend(["qw", "qx", "qy", "qz"]);
            } else {
                h.extend(["roll_deg", "pitch_deg", "yaw_deg"]);
            }
            h.extend(&f[13..]);
            out.push_str(&h.join(","));
            out.push('\n');
            continue;
        }
        let v: Vec<f64> = f[1..13].iter().map(|x| x.parse().unwrap()).collect();
        let rpy = [v[9], v[10], v[11]].map(f64::to_radians);
        let r = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        let p = Vector3::new(v[6], v[7], v[8]);
        let p2 = frame.rotation * p + frame.position_mm;
        let r2 = frame.rotation * r;
        let mut row = vec![f[0].to_string()];
        row.extend((0..6).map(|i| format!("{}", v[i] - OFFSETS_MM[i])));
        row.extend((0..3).map(|a| format!("{}", p2[a])));
        if quaternion {
            let q = nalgebra::UnitQuaternion::from_rotation_matrix(&r2);
            row.extend([q.w, q.i, q.j, q.k].map(|x| format!("{x}")));
        } else {
            let (a, b, c) = r2.euler_angles();
            row.extend([a, b, c].map(|x| format!("{}", x.to_degrees())));
        }
        row.extend(f[13..].iter().map(|s| s.to_string()));
        out.push_str(&row.join(","));
        out.push('\n');
    }
    out
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn arr(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Checks one session of calibration.json's registration against the true frame: each
/// translation component and each component of the rotation error within `k` standard
/// deviations plus `slack_mm` / `slack_deg`. Returns the largest error in sigmas.
fn check_session(
    s: &serde_json::Value,
    truth: &Pose,
    k: f64,
    slack_mm: f64,
    slack_deg: f64,
) -> f64 {
    let t = arr(&s["translation_mm"]);
    let tsd = arr(&s["translation_sd_mm"]);
    let rpy = arr(&s["roll_pitch_yaw_deg"]);
    let rsd = arr(&s["rotation_sd_deg"]);
    let r = Rotation3::from_euler_angles(
        rpy[0].to_radians(),
        rpy[1].to_radians(),
        rpy[2].to_radians(),
    );
    let dw = cpm::geometry::rotation::log(&(r * truth.rotation.inverse()));
    let mut worst: f64 = 0.0;
    for a in 0..3 {
        let e = t[a] - truth.position_mm[a];
        eprintln!(
            "  translation {a}: truth {:.4} mm, recovered {:.4} +- {:.4} mm",
            truth.position_mm[a], t[a], tsd[a]
        );
        assert!(
            e.abs() <= k * tsd[a] + slack_mm,
            "translation {a}: {e} mm, sd {}",
            tsd[a]
        );
        worst = worst.max(e.abs() / tsd[a]);
        let e = dw[a].to_degrees();
        eprintln!("  rotation error {a}: {e:.6} deg, sd {:.6} deg", rsd[a]);
        assert!(
            e.abs() <= k * rsd[a] + slack_deg,
            "rotation {a}: {e} deg, sd {}",
            rsd[a]
        );
        worst = worst.max(e.abs() / rsd[a]);
    }
    worst
}

fn check_offsets(reg: &serde_json::Value, k: f64, slack_mm: f64) {
    let o = arr(&reg["link_reading_offset_mm"]);
    let sd = arr(&reg["link_reading_offset_sd_mm"]);
    for i in 0..6 {
        eprintln!(
            "  link {} reading offset: truth {} mm, recovered {:.4} +- {:.4} mm",
            i + 1,
            OFFSETS_MM[i],
            o[i],
            sd[i]
        );
        assert!(
            (o[i] - OFFSETS_MM[i]).abs() <= k * sd[i] + slack_mm,
            "offset {i}: {} +- {}",
            o[i],
            sd[i]
        );
    }
    assert_eq!(reg["offsets_applied"], true);
}

#[test]
fn tracker_logs_in_another_frame_calibrate_and_refine_without_hand_registration() {
    let d = scratch("one");
    // The frame is 219 mm and about 10 deg from the base; the machine is nominal, so the
    // registration has a truth (no installation error to share the gauge with).
    let frame = Pose::from_xyz_rpy_deg([180.0, -95.0, 60.0], [4.0, -3.0, 8.5]);
    let base = simulate(&d, "base.csv", 60, 21, false);
    for quaternion in [false, true] {
        let name = if quaternion { "quaternion" } else { "rpy" };
        let data = d.join(format!("{name}.csv"));
        std::fs::write(&data, in_frame(&base, &frame, quaternion)).unwrap();
        let out = d.join(format!("cal-{name}"));
        let o = cpm(
            &["calibrate", "--effects", "tracker_frame,link_offset"],
            &[("--robot", &example()), ("--data", &data), ("--out", &out)],
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = json(&out.join("calibration.json"));
        let reg = &v["registration"];
        let s = &reg["sessions"][0];
        assert_eq!(s["applied"], true);
        assert!(s["rms_before_mm"].as_f64().unwrap() > 50.0, "{s}");
        assert!(s["rms_after_mm"].as_f64().unwrap() < 0.05, "{s}");
        eprintln!("{name} columns (SIMULATED):");
        let worst = check_session(s, &frame, 3.0, 0.0, 0.0);
        eprintln!("  largest error {worst:.2} sigma");
        check_offsets(reg, 3.0, 0.0);
        // The fit refines both on top, to the tracker noise, and names the gauge freedoms.
        let rms = cli::length_rms_um(&v);
        assert!(rms < 15.0, "residual {rms} um");
        assert!(reg["refined_by_fit"]["tracker_frame"].is_array());
        assert!(!reg["refined_by_fit"]["gauge_freedoms"]
            .as_array()
            .unwrap()
            .is_empty());
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert!(report.contains("## Tracker registration"), "{report}");
        assert!(report.contains("Gauge freedoms"), "{report}");
        // calibrated.toml carries the reading offsets in the link reading models.
        let robot = cpm::io::Robot::load(&example()).unwrap();
        let cal = cpm::io::Robot::load(&out.join("calibrated.toml")).unwrap();
        for (i, off) in OFFSETS_MM.iter().enumerate() {
            let shift = cal.length_mm(i, 300.0) - robot.length_mm(i, 300.0);
            assert!((shift - off).abs() < 0.5, "link {i}: {shift} mm");
        }
    }
    // `cpm refine` takes the same log (one candidate, one step: fast).
    let out = d.join("refine");
    let o = cpm(
        &[
            "refine",
            "--effects",
            "tracker_frame,link_offset",
            "--candidates",
            "link_scale",
            "--max-steps",
            "1",
        ],
        &[
            ("--robot", &example()),
            ("--data", &d.join("rpy.csv")),
            ("--out", &out),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&out.join("calibration.json"));
    check_session(&v["registration"]["sessions"][0], &frame, 3.0, 0.0, 0.0);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("## Tracker registration"), "{report}");
}

#[test]
fn a_machine_with_installation_errors_is_registered_up_to_its_gauge() {
    // With the paper's installation errors the registration absorbs their rigid part (the
    // gauge freedom of base and tracker moving together): it matches the truth to a fraction
    // of a millimetre, and the fit then explains the data to the noise.
    let d = scratch("table2");
    let frame = Pose::from_xyz_rpy_deg([-60.0, 40.0, -25.0], [-1.5, 2.0, -4.0]);
    let base = simulate(&d, "base.csv", 60, 22, true);
    let data = d.join("q.csv");
    std::fs::write(&data, in_frame(&base, &frame, true)).unwrap();
    let out = d.join("cal");
    let o = cpm(
        &["calibrate", "--effects", "tracker_frame,link_offset"],
        &[("--robot", &example()), ("--data", &data), ("--out", &out)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&out.join("calibration.json"));
    eprintln!("Table 2 errors, quaternion columns (SIMULATED):");
    check_session(&v["registration"]["sessions"][0], &frame, 3.0, 0.5, 0.05);
    check_offsets(&v["registration"], 3.0, 0.5);
    let rms = cli::length_rms_um(&v);
    assert!(rms < 15.0, "residual {rms} um");
}

#[test]
fn two_sessions_get_their_own_frames() {
    let d = scratch("two");
    let frames = [
        Pose::from_xyz_rpy_deg([60.0, 250.0, -40.0], [-2.0, 1.5, -7.0]),
        Pose::from_xyz_rpy_deg([-120.0, 80.0, 210.0], [6.0, -1.0, 3.0]),
    ];
    let mut files = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        let base = simulate(&d, &format!("base{k}.csv"), 40, 30 + k as u64, false);
        let p = d.join(format!("session{k}.csv"));
        std::fs::write(&p, in_frame(&base, f, k == 1)).unwrap();
        files.push(p);
    }
    let out = d.join("cal");
    let o = cpm(
        &["calibrate", "--effects", "link_offset"],
        &[
            ("--robot", &example()),
            ("--data", &files[0]),
            ("--data", &files[1]),
            ("--out", &out),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&out.join("calibration.json"));
    let sessions = v["registration"]["sessions"].as_array().unwrap();
    assert_eq!(sessions.len(), 2);
    for (k, (s, f)) in sessions.iter().zip(&frames).enumerate() {
        assert!(s["file"]
            .as_str()
            .unwrap()
            .ends_with(&format!("session{k}.csv")));
        eprintln!("session {k} (SIMULATED):");
        check_session(s, f, 3.0, 0.0, 0.0);
    }
    check_offsets(&v["registration"], 3.0, 0.0);
    let rms = cli::length_rms_um(&v);
    assert!(rms < 15.0, "residual {rms} um");
}

#[test]
fn a_tracker_log_already_in_the_base_frame_is_left_as_it_is() {
    let d = scratch("base");
    let base = d.join("base.csv");
    std::fs::write(&base, simulate(&d, "sim.csv", 30, 23, true)).unwrap();
    let out = d.join("cal");
    let o = cpm(
        &["calibrate"],
        &[("--robot", &example()), ("--data", &base), ("--out", &out)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&out.join("calibration.json"));
    assert_eq!(v["registration"]["sessions"][0]["applied"], false);
    assert_eq!(v["registration"]["offsets_applied"], false);
}
