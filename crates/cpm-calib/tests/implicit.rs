//! The implicit-loop formulation against the nested one, and its Jacobian.
use cpm_calib::implicit::{identify_implicit, ImplicitOptions};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};

fn setup(poses: usize, effects: &[Effect]) -> (MeasurementModel, Campaign, Vec<f64>) {
    let mut model = MeasurementModel::new(JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    model.effects = effects.to_vec();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, 8),
        sensors: (0..16).collect(),
    };
    let mut truth = InstallationErrors::paper_table2().to_vec_um();
    truth.extend((36..model.num_params()).map(|k| 5.0 + (k as f64).sin() * 3.0));
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: 3.0 },
        repeats: 1,
        seed: 4,
    };
    let data = simulate(&model, &truth, &plan, &sim).unwrap();
    (model, data, truth)
}

#[test]
fn implicit_agrees_with_nested_when_encoders_are_exact() {
    let (model, data, truth) = setup(40, &[Effect::LinkOffset, Effect::SensorOffset]);
    let nested = identify(
        &model,
        &data,
        &IdentifyOptions {
            sigma_um: Some(3.0),
            ..IdentifyOptions::default()
        },
    )
    .unwrap();
    let opts = ImplicitOptions {
        encoder_sigma_um: 1e-4,
        sensor_sigma_um: 3.0,
        ..ImplicitOptions::default()
    };
    let imp = identify_implicit(&model, &data, &opts).unwrap();
    assert!(
        imp.solver.termination.was_successful(),
        "{}",
        imp.solver.brief()
    );
    let mut compared = 0;
    for k in 0..model.num_params() {
        if let (Some(a), Some(b), Some(s)) =
            (nested.estimate_um[k], imp.estimate_um[k], nested.std_um[k])
        {
            assert!(
                (a - b).abs() < 0.05 * s + 1e-6,
                "{k}: nested {a} implicit {b} (std {s}), truth {}",
                truth[k]
            );
            compared += 1;
        }
    }
    assert_eq!(compared, nested.identifiability.num_determined());
    assert!(compared > 36, "{compared}");
    // The pose unknowns reproduce the closures.
    assert!(imp.closure_rms_um < 1e-3, "{}", imp.closure_rms_um);
    // And the marginal standard deviations agree with the nested ones.
    for k in 0..36 {
        let (a, b) = (nested.std_um[k].unwrap(), imp.std_um[k].unwrap());
        assert!((a - b).abs() < 0.02 * a, "{k}: {a} vs {b}");
    }
}

#[test]
fn encoder_noise_widens_the_bounds() {
    let (model, data, _) = setup(30, &[]);
    let tight = identify_implicit(
        &model,
        &data,
        &ImplicitOptions {
            encoder_sigma_um: 1e-3,
            sensor_sigma_um: 3.0,
            ..ImplicitOptions::default()
        },
    )
    .unwrap();
    let loose = identify_implicit(
        &model,
        &data,
        &ImplicitOptions {
            encoder_sigma_um: 5.0,
            sensor_sigma_um: 3.0,
            ..ImplicitOptions::default()
        },
    )
    .unwrap();
    let rms =
        |c: &cpm_calib::implicit::ImplicitCalibration| c.identifiability.crlb_rms_um().unwrap();
    assert!(
        rms(&loose) > 1.2 * rms(&tight),
        "{} vs {}",
        rms(&loose),
        rms(&tight)
    );
}

#[test]
fn implicit_jacobian_matches_finite_differences() {
    let (model, data, truth) = setup(
        5,
        &[Effect::LinkScale, Effect::SensorScale, Effect::Backlash],
    );
    let opts = ImplicitOptions {
        encoder_sigma_um: 2.0,
        ..ImplicitOptions::default()
    };
    // Pose corrections of tens of um / urad, globals near the truth.
    let mut x: Vec<f64> = (0..6 * data.poses.len())
        .map(|k| 30.0 * ((k as f64) * 0.37).sin() + 40.0)
        .collect();
    x.extend(truth.iter().map(|t| t * 0.9));
    let check =
        cpm_calib::implicit::check_implicit_jacobian(&model, &data, &opts, &x, 1e-4).unwrap();
    // Central differences with a relative step of 1e-4 carry ~1e-5 relative error here.
    assert!(check.is_consistent(1e-4), "{check}");
}

/// The streamed Schur accumulation (no stored Jacobian, parallel over the poses) against
/// `cpm-lm`'s general Schur solver on the stored sparse Jacobian: the same estimates, the
/// same Cramér-Rao bounds and residuals, with link and sensor effects and unequal numbers of
/// readings per pose (readings dropped), across more poses than one parallel chunk holds.
#[test]
fn streamed_schur_matches_the_stored_jacobian_solver() {
    let (model, mut data, _) = setup(300, &[Effect::LinkOffset, Effect::SensorScale]);
    // Unequal blocks: drop every seventh reading.
    let mut k = 0;
    data.readings.retain(|_| {
        k += 1;
        k % 7 != 0
    });
    let run = |streamed: bool| {
        identify_implicit(
            &model,
            &data,
            &ImplicitOptions {
                encoder_sigma_um: 0.5,
                sensor_sigma_um: 3.0,
                streamed,
                ..ImplicitOptions::default()
            },
        )
        .unwrap()
    };
    let (s, e) = (run(true), run(false));
    assert!(
        s.solver.termination.was_successful(),
        "{}",
        s.solver.brief()
    );
    assert!(
        e.solver.termination.was_successful(),
        "{}",
        e.solver.brief()
    );
    assert_eq!(s.solver.linear_solver, "Schur complement (streamed)");
    assert_eq!(
        s.identifiability.num_determined(),
        e.identifiability.num_determined()
    );
    assert!(s.identifiability.num_determined() > 36);
    for k in 0..model.num_params() {
        match (s.estimate_um[k], e.estimate_um[k]) {
            (Some(a), Some(b)) => {
                let sd = e.std_um[k].unwrap();
                let sa = s.std_um[k].unwrap();
                assert!(
                    (a - b).abs() < 1e-4 * sd,
                    "{k}: streamed {a} stored {b} (std {sd})"
                );
                assert!((sa - sd).abs() < 1e-6 * sd, "{k}: std {sa} vs {sd}");
            }
            (None, None) => {}
            other => panic!("{k}: determined differently: {other:?}"),
        }
    }
    assert!((s.reading_rms_um - e.reading_rms_um).abs() < 1e-6 * e.reading_rms_um);
    assert!((s.closure_rms_um - e.closure_rms_um).abs() < 1e-4 * e.closure_rms_um + 1e-9);
    assert_eq!(s.initial_reading_rms_um, e.initial_reading_rms_um);
    assert_eq!(s.reading_residuals_um.len(), data.readings.len());
    for (a, b) in s.reading_residuals_um.iter().zip(&e.reading_residuals_um) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b}");
    }
    // The residuals are in the campaign's order: the largest one is the same reading.
    let argmax = |r: &[f64]| {
        r.iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .unwrap()
            .0
    };
    assert_eq!(
        argmax(&s.reading_residuals_um),
        argmax(&e.reading_residuals_um)
    );
}
