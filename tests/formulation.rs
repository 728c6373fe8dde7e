//! The two formulations of `cpm calibrate` (nested, implicit) give the same estimates on a
//! campaign both can fit, and the outputs say which one was used. Simulated data.
use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
use cli::{example, ok, scratch};

use cpm::calib::paper::{designed_sensors, random_workspace_poses};
use cpm::calib::{simulate, IdentifyOptions, MeasurementModel, Plan, SimulationOptions};
use cpm::cli::formulation::{choose, identify_with, Formulation};
use cpm::geometry::{InstallationErrors, JointTable, RobotDescription};

#[test]
fn nested_and_implicit_agree_to_a_tenth_of_a_standard_deviation() {
    let mut model = MeasurementModel::new(JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, 60, 100.0, 25.0, 3.0, 7),
        sensors: (0..model.nominal.sensors.len()).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).unwrap();
    let options = IdentifyOptions::default();
    assert_eq!(choose(&model, &data, &options), Formulation::Nested);
    let nested = identify_with(Formulation::Nested, &model, &data, &options).unwrap();
    let implicit = identify_with(Formulation::Implicit, &model, &data, &options).unwrap();
    assert!(implicit.solver.was_successful(), "{}", implicit.solver);
    assert_eq!(nested.identifiability.rank, implicit.identifiability.rank);
    let mut compared = 0;
    for k in 0..model.num_params() {
        match (
            nested.estimate_um[k],
            implicit.estimate_um[k],
            nested.std_um[k],
        ) {
            (Some(a), Some(b), Some(s)) => {
                assert!(
                    (a - b).abs() < 0.1 * s,
                    "{k}: nested {a} implicit {b} (std {s})"
                );
                let si = implicit.std_um[k].unwrap();
                assert!(
                    (si - s).abs() < 0.05 * s,
                    "{k}: std nested {s} implicit {si}"
                );
                compared += 1;
            }
            (None, None, _) => {}
            other => panic!("{k}: determined by one formulation only: {other:?}"),
        }
    }
    assert_eq!(compared, nested.identifiability.num_determined());
    assert!(compared > 0);
    // The noise both estimate from the residuals, and the residuals themselves.
    assert!(
        (nested.sigma_um - implicit.sigma_um).abs() < 0.02 * nested.sigma_um,
        "{} vs {}",
        nested.sigma_um,
        implicit.sigma_um
    );
    assert!(
        (nested.residual_rms_um - implicit.residual_rms_um).abs() < 0.02 * nested.residual_rms_um
    );
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The 36 installation-error values of a `per_joint` JSON object, in parameter order.
fn per_joint(v: &serde_json::Value) -> Vec<Option<f64>> {
    let mut out = vec![None; 36];
    for (s, side) in ["base", "platform"].iter().enumerate() {
        for i in 0..6 {
            for a in 0..3 {
                out[6 * i + 3 * s + a] = v[side][i][a].as_f64();
            }
        }
    }
    out
}

#[test]
fn calibrate_says_which_formulation_and_both_agree() {
    let d = scratch("formulation", "cli");
    let robot = example("hexapod_66.toml");
    let mut truth = RobotDescription::load(&robot).unwrap();
    truth.installation_errors_um = Some(
        cpm::geometry::description::InstallationErrorsSpec::from_errors(
            &InstallationErrors::paper_table2(),
        ),
    );
    let truth_path = d.join("truth.toml");
    std::fs::write(&truth_path, truth.to_toml_string().unwrap()).unwrap();
    let data = d.join("data.csv");
    let (dp, tp) = (data.display().to_string(), truth_path.display().to_string());
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "60",
        "--truth",
        &tp,
        "--noise",
        "gaussian:0.5",
        "--seed",
        "3",
        "--effects",
        "none",
        "--out",
        &dp,
    ]);
    let mut results = Vec::new();
    for f in ["nested", "implicit", "auto"] {
        let out = d.join(f);
        let op = out.display().to_string();
        let summary = ok(&[
            "calibrate",
            "--robot",
            &robot,
            "--data",
            &dp,
            "--effects",
            "none",
            "--out",
            &op,
            "--formulation",
            f,
            "--json",
        ]);
        let summary: serde_json::Value = serde_json::from_str(&summary).unwrap();
        let expected = if f == "auto" { "nested" } else { f };
        assert_eq!(summary["formulation"], expected);
        let cal = read_json(&out.join("calibration.json"));
        assert_eq!(cal["formulation"], expected);
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert!(
            report.contains(&format!("Formulation: {expected} (")),
            "{report}"
        );
        results.push((
            per_joint(&cal["installation_errors_um"]),
            per_joint(&cal["std_um"]),
        ));
    }
    let (nested, nested_std) = &results[0];
    let (implicit, _) = &results[1];
    let mut compared = 0;
    for k in 0..36 {
        if let (Some(a), Some(b), Some(s)) = (nested[k], implicit[k], nested_std[k]) {
            assert!(
                (a - b).abs() < 0.1 * s,
                "{k}: nested {a} implicit {b} (std {s})"
            );
            compared += 1;
        }
    }
    assert!(compared > 0);
    assert_eq!(
        results[2].0, results[0].0,
        "auto picks nested for 360 readings"
    );
}
