//! Golden test of the measurement model: predictions and Jacobians of every built-in effect
//! (estimated, and estimated on top of known values, with tracker and socket channels) on a
//! fixed campaign, against `tests/data/golden_model.json`.
//!
//! The vendored file was written by the implementation before effects became a trait (commit
//! "golden model test" on branch `effects`, the last commit with the closed `Effect` match in
//! `predict_exact`), with `CPM_WRITE_GOLDEN=1 cargo test -p cpm-calib --test golden`. Every
//! later implementation must reproduce it to 1e-12 mm (predictions) and 1e-12 mm per unit
//! (Jacobian entries).
use cpm_calib::campaign::PoseMeasurement;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};
use serde::{Deserialize, Serialize};

const PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/golden_model.json");

#[derive(Debug, Serialize, Deserialize, PartialEq)]
struct Case {
    name: String,
    params: Vec<f64>,
    predictions_mm: Vec<f64>,
    /// Nonzero Jacobian entries: (row, column, value).
    jacobian: Vec<(usize, usize, f64)>,
    rows: usize,
    cols: usize,
}

fn campaign(model: &MeasurementModel) -> Campaign {
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, 3, 100.0, 25.0, 3.0, 4242),
        sensors: (0..model.nominal.sensors.len()).collect(),
    };
    let mut c = plan.skeleton();
    for r in c.readings.iter_mut() {
        r.time_s = Some(45.0 * r.pose as f64 + 10.0).into();
        r.temperature_c = Some(21.0 + 0.4 * r.pose as f64).into();
    }
    for j in [0, 2] {
        let twist = nalgebra::Vector6::new(0.02, -0.01, 0.012, 2e-4, -1e-4, 7e-5);
        c.pose_measurements.push(PoseMeasurement {
            pose: j,
            measured: c.poses[j].perturbed(&twist),
            time_s: Some(45.0 * j as f64 + 10.0),
            temperature_c: None,
        });
    }
    c
}

fn model(known: bool) -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m.effects = Effect::ALL.to_vec();
    if known {
        let (n, s) = (m.nominal.num_links(), m.nominal.sensors.len());
        m.known_effects = Effect::ALL
            .iter()
            .map(|&e| KnownEffect {
                effect: e,
                values: (0..e.num_params(n, s))
                    .map(|k| 2.0 + (k as f64 * 0.9 + e.name().len() as f64).cos() * 3.0)
                    .collect(),
            })
            .collect();
    }
    m
}

fn compute(name: &str, model: &MeasurementModel) -> Case {
    let c = campaign(model);
    let mut params = InstallationErrors::paper_table2().to_vec_um();
    params.extend((0..model.num_params() - 36).map(|k| 4.0 + (k as f64 * 1.7).sin() * 5.0));
    let prepared = Prepared::new(model, &c).unwrap();
    let mut j = nalgebra::DMatrix::zeros(c.len(), model.num_params());
    let y = predict(model, &prepared, &c, &params, Some(&mut j)).unwrap();
    let mut jacobian = Vec::new();
    for r in 0..j.nrows() {
        for k in 0..j.ncols() {
            if j[(r, k)] != 0.0 {
                jacobian.push((r, k, j[(r, k)]));
            }
        }
    }
    Case {
        name: name.into(),
        params,
        predictions_mm: y,
        jacobian,
        rows: j.nrows(),
        cols: j.ncols(),
    }
}

#[test]
fn every_built_in_effect_predicts_as_before_the_redesign() {
    let cases = vec![
        compute("all effects estimated", &model(false)),
        compute("all effects estimated on top of known values", &model(true)),
    ];
    if std::env::var("CPM_WRITE_GOLDEN").is_ok() {
        std::fs::write(PATH, serde_json::to_string(&cases).unwrap()).unwrap();
        return;
    }
    let golden: Vec<Case> = serde_json::from_str(&std::fs::read_to_string(PATH).unwrap()).unwrap();
    assert_eq!(golden.len(), cases.len());
    for (g, c) in golden.iter().zip(&cases) {
        assert_eq!(g.name, c.name);
        assert_eq!((g.rows, g.cols), (c.rows, c.cols), "{}", g.name);
        // serde_json reads floats to within an ulp: the parameters agree to far below 1e-12.
        assert_eq!(g.params.len(), c.params.len(), "{}", g.name);
        for (a, b) in g.params.iter().zip(&c.params) {
            assert!((a - b).abs() < 1e-12, "{}: parameter {a} vs {b}", g.name);
        }
        for (k, (a, b)) in g.predictions_mm.iter().zip(&c.predictions_mm).enumerate() {
            assert!(
                (a - b).abs() < 1e-12,
                "{}: prediction {k}: {a} vs {b}",
                g.name
            );
        }
        let dense = |entries: &[(usize, usize, f64)]| {
            let mut m = nalgebra::DMatrix::zeros(g.rows, g.cols);
            for &(r, k, v) in entries {
                m[(r, k)] = v;
            }
            m
        };
        let (jg, jc) = (dense(&g.jacobian), dense(&c.jacobian));
        for r in 0..g.rows {
            for k in 0..g.cols {
                let (a, b) = (jg[(r, k)], jc[(r, k)]);
                assert!(
                    (a - b).abs() < 1e-12,
                    "{}: jacobian ({r}, {k}): {a} vs {b}",
                    g.name
                );
            }
        }
        // The campaign has readings, tracker measurements and every channel's columns.
        assert!(
            jg.column_iter().all(|col| col.iter().any(|v| *v != 0.0)),
            "{}",
            g.name
        );
    }
}

/// A campaign without logged commanded lengths predicts exactly what the same campaign with
/// its nominal inverse kinematics logged predicts: effects that read the commanded length
/// (link scale, non-linearity, screw error, backlash) see the same value either way, joint
/// clearance included. (Before, an unlogged campaign handed them the clearance-shifted
/// effective lengths; the golden record was renewed for that fix.)
#[test]
fn unlogged_commands_are_the_nominal_inverse_kinematics() {
    let m = model(true);
    let mut c = campaign(&m);
    c.pose_measurements.clear();
    let params: Vec<f64> = (0..m.num_params())
        .map(|k| 0.5 + (k as f64 * 0.37).sin())
        .collect();
    let predict = |c: &Campaign| {
        let prepared = cpm_calib::model::Prepared::new(&m, c).unwrap();
        cpm_calib::model::predict(&m, &prepared, c, &params, None).unwrap()
    };
    let unlogged = predict(&c);
    c.commanded_lengths_mm = Some(
        c.poses
            .iter()
            .map(|p| cpm_kinematics::inverse_lengths(&m.nominal, p))
            .collect(),
    );
    let logged = predict(&c);
    assert!(m.clearance.radius_um > 0.0);
    for (a, b) in unlogged.iter().zip(&logged) {
        assert!((a - b).abs() < 1e-12, "unlogged {a} vs logged {b}");
    }
}
