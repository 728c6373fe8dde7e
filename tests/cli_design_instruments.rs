//! `cpm design --instruments`: poses for a mix of gauges, laser-tracker reflectors and an
//! inclinometer, with the bounds of the mix and of each instrument alone; the poses it writes
//! are then simulated (SIMULATED data), calibrated, and the fit's standard deviations match
//! the design's bounds. Bad lists are refused.
#[path = "common/cli.rs"]
mod cli;

use std::path::{Path, PathBuf};

use cli::{calibrate_json, cpm, example, ok, p, scratch};

/// The example hexapod with three reflectors and a two-axis inclinometer.
fn robot(dir: &Path) -> PathBuf {
    let mut text = std::fs::read_to_string(example("hexapod_66.toml")).unwrap();
    for (k, xyz) in [
        "90.0, 10.0, 30.0",
        "-50.0, 80.0, 30.0",
        "-40.0, -85.0, 30.0",
    ]
    .iter()
    .enumerate()
    {
        text.push_str(&format!(
            "\n[[target]]\nname = \"smr{}\"\nplatform_mm = [{xyz}]\n",
            k + 1
        ));
    }
    text.push_str(
        "\n[[inclinometer]]\nname = \"scl3300\"\naxes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\n",
    );
    let path = dir.join("robot.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_designed_mix_identifies_what_no_instrument_alone_does() {
    let dir = scratch("design-instruments", "mix");
    let r = robot(&dir);
    let out = dir.join("mix");
    ok(&[
        "design",
        "--robot",
        &p(&r),
        "--instruments",
        "gauges,points,tilts",
        "--readings",
        "300",
        "--candidates",
        "400",
        "--out",
        &p(&out),
    ]);
    let d = json(&out.join("design.json"));
    let b = &d["bounds"];
    let per_pose = 3 + 9 + 2;
    // The budget is a ceiling: as many whole poses as it holds.
    assert_eq!(b["poses"].as_u64().unwrap(), 300 / per_pose);
    assert!(b["observations"].as_u64().unwrap() <= 300);
    assert_eq!(b["joint_errors_determined"], 36);
    let alone: Vec<(&str, &serde_json::Value)> = d["alone"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| (a["instrument"].as_str().unwrap(), &a["bounds"]))
        .collect();
    assert_eq!(alone.len(), 3);
    let mix_rms = b["joint_crb_rms_um"].as_f64().unwrap();
    for (name, a) in &alone {
        // Each alone sees less: fewer joint errors determined, or a larger bound.
        let worse = a["joint_errors_determined"].as_u64().unwrap() < 36
            || a["joint_crb_rms_um"].as_f64().unwrap() > mix_rms;
        assert!(worse, "{name}: {a}");
    }
    let tilts = alone.iter().find(|(n, _)| *n == "tilts").unwrap().1;
    let blind = tilts["blind_directions"].to_string();
    assert!(blind.contains("translated together"), "{blind}");
    let poses = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    assert_eq!(
        poses.lines().count() as u64,
        1 + b["poses"].as_u64().unwrap()
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("tilts alone"), "{report}");
}

/// The design's bound is what the fit then states: gauges and reflectors at the designed
/// poses, simulated from the example's truth, calibrated with the design's noise.
#[test]
fn the_fit_of_a_designed_campaign_states_the_designed_bound() {
    let dir = scratch("design-instruments", "fit");
    let r = robot(&dir);
    let out = dir.join("design");
    ok(&[
        "design",
        "--robot",
        &p(&r),
        "--instruments",
        "gauges,points",
        "--readings",
        "360",
        "--candidates",
        "400",
        "--out",
        &p(&out),
    ]);
    let d = json(&out.join("design.json"));
    let plan = out.join("poses.csv");
    // The truth: the example's, with the same reflectors and inclinometer as the robot.
    let instruments = std::fs::read_to_string(&r).unwrap().split_off(
        std::fs::read_to_string(example("hexapod_66.toml"))
            .unwrap()
            .len(),
    );
    let truth = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap() + &instruments;
    let truth_path = dir.join("truth.toml");
    std::fs::write(&truth_path, truth).unwrap();
    let (gauge, points) = (dir.join("gauge.csv"), dir.join("points.csv"));
    for (file, measure, noise) in [(&gauge, "lengths", "1"), (&points, "points", "10")] {
        ok(&[
            "simulate",
            "--robot",
            &p(&r),
            "--truth",
            &p(&truth_path),
            "--plan",
            &p(&plan),
            "--measure",
            measure,
            "--noise",
            &format!("gaussian:{noise}"),
            "--seed",
            "4",
            "--out",
            &p(file),
        ]);
    }
    let cal = calibrate_json(
        &r,
        &[&gauge, &points],
        &[
            "--effects",
            "none",
            "--sigma-um",
            "1",
            "--pose-sigma-um",
            "10",
        ],
        &dir.join("cal"),
    );
    let sd: Vec<f64> = ["base", "platform"]
        .iter()
        .flat_map(|side| {
            cal["std_um"][side]
                .as_array()
                .unwrap()
                .iter()
                .flat_map(|v| v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        })
        .collect();
    assert_eq!(sd.len(), 36);
    let fit_rms = (sd.iter().map(|s| s * s).sum::<f64>() / 36.0).sqrt();
    let designed = d["bounds"]["joint_crb_rms_um"].as_f64().unwrap();
    println!(
        "gauges + points, designed: bound {designed:.2} um, fit's deviations {fit_rms:.2} um RMS"
    );
    assert_eq!(
        cal["identifiability"]["rank"], d["bounds"]["rank"],
        "design and fit see different ranks"
    );
    assert!(
        (fit_rms / designed - 1.0).abs() < 0.1,
        "{fit_rms} vs {designed}"
    );
}

#[test]
fn bad_instrument_lists_are_refused() {
    let dir = scratch("design-instruments", "bad");
    let r = robot(&dir);
    for (list, robot, says) in [
        (
            "gauges,lasers",
            p(&r),
            "none of gauges, tracker, points, tilts",
        ),
        ("points,points", p(&r), "given twice"),
        (
            "points",
            example("hexapod_66.toml"),
            "declares no [[target]]",
        ),
        (
            "tilts",
            example("hexapod_66.toml"),
            "declares no [[inclinometer]]",
        ),
    ] {
        let out = dir.join("out");
        let o = cpm(&[
            "design",
            "--robot",
            &robot,
            "--instruments",
            list,
            "--out",
            &p(&out),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(matches!(o.status.code(), Some(2 | 3)), "{list}: {err}");
        assert!(err.contains(says), "{list}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists());
    }
}
