//! The pose error map through the command line (simulated data): a truth whose platform sags
//! with y squared, `calibrate --effects pose_map_y2` writes the term and its fitted range to
//! calibrated.toml, `compensate` applies it and flags targets outside the range, `refine`
//! reports the pose structure and range.
#[path = "common/cli.rs"]
mod cli;

use cli::{example, ok, p, scratch};
use cpm::geometry::{InstallationErrors, Pose, RobotDescription};
use cpm::io::Robot;

const SAG_UM: [f64; 6] = [0.0, 0.0, 80.0, 0.0, 0.0, 0.0];

fn truth(dir: &std::path::Path) -> std::path::PathBuf {
    let mut d = RobotDescription::load(example("hexapod_66.toml")).unwrap();
    d.installation_errors_um = Some(
        cpm::geometry::description::InstallationErrorsSpec::from_errors(
            &InstallationErrors::paper_table2(),
        ),
    );
    d.calibration
        .get_or_insert_with(Default::default)
        .known_effects = [("pose_map_y2".to_string(), SAG_UM.to_vec())]
        .into_iter()
        .collect();
    let path = dir.join("truth.toml");
    std::fs::write(&path, d.to_toml_string().unwrap()).unwrap();
    path
}

/// RMS position error (um) the truth reaches with the commanded readings: the truth's own
/// lengths, clearance and sag (computed here by hand, not through the pose map effect).
fn reached_error_um(truth: &Robot, sag_um: f64, targets: &[Pose], readings: &[Vec<f64>]) -> f64 {
    let (clearance, load) = (truth.clearance(), truth.platform_load());
    let mut sq = 0.0;
    for (t, u) in targets.iter().zip(readings) {
        let shift = clearance
            .link_corrections_mm(&truth.table, t, &load)
            .unwrap();
        let lengths: Vec<f64> = (0..6)
            .map(|i| truth.length_mm(i, u[i]) + shift[i])
            .collect();
        let (fk, _) =
            cpm::kinematics::forward(&truth.table, &lengths, t, &Default::default()).unwrap();
        let y = (t.position_mm.y - truth.table.home.position_mm.y) / 100.0;
        let reached = fk.position_mm + nalgebra::Vector3::new(0.0, 0.0, sag_um * 1e-3 * y * y);
        sq += (reached - t.position_mm).norm_squared() * 1e6;
    }
    (sq / targets.len() as f64).sqrt()
}

fn readings(text: &str) -> Vec<Vec<f64>> {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let cols: Vec<usize> = (1..=6)
        .map(|k| {
            header
                .iter()
                .position(|h| *h == format!("reading_{k}"))
                .unwrap()
        })
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            cols.iter().map(|&c| f[c].parse().unwrap()).collect()
        })
        .collect()
}

#[test]
fn a_calibrated_pose_map_is_written_applied_and_bounded() {
    let d = scratch("cli", "pose-map");
    let robot = example("hexapod_66.toml");
    let truth_path = truth(&d);
    let data = d.join("data.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "80",
        "--truth",
        &p(&truth_path),
        "--noise",
        "gaussian:0.3",
        "--seed",
        "8",
        "--out",
        &p(&data),
    ]);
    let cal = d.join("cal");
    ok(&[
        "calibrate",
        "--robot",
        &robot,
        "--data",
        &p(&data),
        "--effects",
        "pose_map_y2",
        "--sigma-um",
        "0.3",
        "--out",
        &p(&cal),
    ]);
    let calibrated = cal.join("calibrated.toml");
    let desc = RobotDescription::load(&calibrated).unwrap();
    let known = &desc.calibration.as_ref().unwrap().known_effects;
    let sag = known
        .get("pose_map_y2")
        .expect("pose_map_y2 in calibrated.toml");
    assert!((sag[2] - SAG_UM[2]).abs() < 5.0, "{sag:?}");
    let range = desc.pose_map.expect("[pose_map] in calibrated.toml");
    let (lo, hi) = (range.fitted_min.unwrap(), range.fitted_max.unwrap());
    assert!(lo[1] < -10.0 && hi[1] > 10.0, "{lo:?} {hi:?}");

    // Compensation with the map and without it.
    let without = d.join("without.toml");
    let mut w = desc.clone();
    w.calibration
        .as_mut()
        .unwrap()
        .known_effects
        .remove("pose_map_y2");
    std::fs::write(&without, w.to_toml_string().unwrap()).unwrap();
    let truth = Robot::load(&truth_path).unwrap();
    let targets: Vec<Pose> =
        cpm::calib::paper::random_workspace_poses(&truth.table, 20, 40.0, 8.0, 3.0, 77)
            .into_iter()
            .filter(|t| cpm::calib::refine::PoseRange { min: lo, max: hi }.contains(t, 0.0))
            .collect();
    assert!(targets.len() >= 10);
    let targets_path = d.join("targets.csv");
    std::fs::write(&targets_path, cpm::io::write_pose_list(&targets)).unwrap();
    let (mut errors, mut own) = (Vec::new(), Vec::new());
    for desc in [&calibrated, &without] {
        let out = d.join("commands.csv");
        let json = ok(&[
            "compensate",
            "--robot",
            &p(desc),
            "--poses",
            &p(&targets_path),
            "--out",
            &p(&out),
            "--json",
        ]);
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(
            v["outside_pose_map_range"].as_array().unwrap().len(),
            0,
            "{v}"
        );
        let u = readings(&std::fs::read_to_string(&out).unwrap());
        errors.push(reached_error_um(&truth, SAG_UM[2], &targets, &u));
        // What the commands reach on a machine without the sag (the calibration's own
        // accuracy with three sensors).
        own.push(reached_error_um(&truth, 0.0, &targets, &u));
    }
    eprintln!(
        "pose map loop: RMS position error {:.3} um with the map, {:.3} um without; {:.3} um on a machine without the sag",
        errors[0], errors[1], own[1]
    );
    assert!(
        errors[1] > own[1] + 3.0,
        "the sag should show: {errors:?} {own:?}"
    );
    assert!(errors[0] < own[1] + 1.0, "{errors:?} {own:?}");

    // Targets outside the fitted range are flagged.
    let mut narrow = desc.clone();
    narrow
        .pose_map
        .as_mut()
        .unwrap()
        .fitted_max
        .as_mut()
        .unwrap()[1] = 0.0;
    let narrow_path = d.join("narrow.toml");
    std::fs::write(&narrow_path, narrow.to_toml_string().unwrap()).unwrap();
    let json = ok(&[
        "compensate",
        "--robot",
        &p(&narrow_path),
        "--poses",
        &p(&targets_path),
        "--out",
        &p(&d.join("c2.csv")),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let flagged = v["outside_pose_map_range"].as_array().unwrap().len();
    let expected = targets.iter().filter(|t| t.position_mm.y > 1e-6).count();
    assert_eq!(flagged, expected, "{v}");

    // refine reports the pose structure it scanned and the pose range.
    let refined = d.join("refined");
    ok(&[
        "refine",
        "--robot",
        &robot,
        "--data",
        &p(&data),
        "--effects",
        "none",
        "--candidates",
        "sensor_offset",
        "--pose-map-degree",
        "2",
        "--sigma-um",
        "0.3",
        "--out",
        &p(&refined),
    ]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(refined.join("refine.json")).unwrap())
            .unwrap();
    eprintln!(
        "refine: steps {:?}, pose structure {}",
        r["final"]["effects"], r["pose_structure"][0]
    );
    assert_eq!(
        r["pose_structure"][0]["effect"], "pose_map_y2",
        "{}",
        r["pose_structure"]
    );
    assert!(r["pose_range"]["min_xyz_mm_rpy_deg"][1].as_f64().unwrap() < -10.0);
    assert!(
        r["final"]["effects"]
            .as_array()
            .unwrap()
            .iter()
            .any(|e| e == "pose_map_y2"),
        "{}",
        r["final"]
    );
    let report = std::fs::read_to_string(refined.join("report.md")).unwrap();
    assert!(report.contains("does not extrapolate"), "{report}");
    assert!(
        report.contains(
            "Pose-correlated structure in the first residual (pose map scan): `pose_map_y2`"
        ),
        "{report}"
    );
}
