//! Closing the loop on data that carry an effect nobody declared.
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};

const SIGMA: f64 = 2.0;

fn base_model() -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m
}

/// A simulated campaign whose truth carries `effect` with parameters from `value(k)`.
fn campaign_with(effect: Option<Effect>, value: impl Fn(usize) -> f64, seed: u64) -> Campaign {
    campaign_sized(effect, value, seed, 50)
}

fn campaign_sized(
    effect: Option<Effect>,
    value: impl Fn(usize) -> f64,
    seed: u64,
    poses: usize,
) -> Campaign {
    let base = base_model();
    let mut truth_model = base.clone();
    truth_model.effects = effect.into_iter().collect();
    let plan = Plan {
        poses: random_workspace_poses(&base.nominal, poses, 100.0, 25.0, 3.0, 77),
        sensors: (0..base.nominal.sensors.len()).collect(),
    };
    let mut truth = InstallationErrors::paper_table2().to_vec_um();
    truth.extend((0..truth_model.num_params() - 36).map(&value));
    // Log time and temperature along the acquisition.
    let mut skeleton = plan.skeleton();
    for r in skeleton.readings.iter_mut() {
        r.time_s = Some(30.0 * r.pose as f64).into();
        r.temperature_c = Some(20.0 + 3.0 * (r.pose as f64 / poses as f64)).into();
    }
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: SIGMA },
        repeats: 1,
        seed,
    };
    simulate_campaign(&truth_model, &truth, &skeleton, &sim).unwrap()
}

fn options() -> RefineOptions {
    RefineOptions {
        identify: IdentifyOptions {
            sigma_um: Some(SIGMA),
            ..IdentifyOptions::default()
        },
        ..RefineOptions::default()
    }
}

#[test]
fn refine_names_the_undeclared_effect_and_reaches_the_noise() {
    type Values = fn(usize) -> f64;
    let cases: [(Effect, Values); 5] = [
        (Effect::LinkScale, |k| {
            [60.0, -40.0, 30.0, -50.0, 45.0, -35.0][k % 6]
        }),
        (Effect::SensorOffset, |k| 8.0 + (k as f64 * 1.7).sin() * 6.0),
        (Effect::Backlash, |k| [6.0, 5.0, -4.0, 7.0, 5.0, 6.0][k % 6]),
        (Effect::ThermalDrift, |k| {
            [4.0, 4.0, 4.0, 3.0, 3.0, 3.0][k % 6]
        }),
        (Effect::ScrewPeriodic, |k| {
            [5.0, -3.0, 4.0, 2.0, -4.0, 3.0][k % 6]
        }),
    ];
    for (effect, value) in cases {
        let data = campaign_with(Some(effect), value, 5);
        let r = refine(&base_model(), &data, &options()).unwrap();
        let names: Vec<Effect> = r.steps.iter().map(|s| s.effect).collect();
        assert_eq!(names.first(), Some(&effect), "{effect}: steps {names:?}");
        let first = &r.steps[0];
        assert!(
            first.cv_rms_after_um < first.cv_rms_before_um,
            "{effect}: {first:?}"
        );
        // Cross-validated RMS at the noise level (within 15 %).
        assert!(
            r.final_cv_rms_um < 1.15 * SIGMA,
            "{effect}: cv {}",
            r.final_cv_rms_um
        );
        eprintln!(
            "{effect}: steps {names:?}, cv RMS {:.3} -> {:.3} um (noise {SIGMA} um)",
            first.cv_rms_before_um, r.final_cv_rms_um
        );
        assert!(
            r.unexplained_structure.is_empty(),
            "{effect}: {:?}",
            r.unexplained_structure
        );
    }
}

#[test]
fn refine_adds_nothing_when_there_is_nothing() {
    let mut added = Vec::new();
    for seed in 0..100 {
        let data = campaign_sized(None, |_| 0.0, 1000 + seed, 20);
        let r = refine(&base_model(), &data, &options()).unwrap();
        if let Some(s) = r.steps.first() {
            added.push((seed, s.effect));
        }
    }
    eprintln!(
        "clean campaigns: refine added an effect in {} of 100 seeds {added:?}",
        added.len()
    );
    assert!(
        added.len() <= 5,
        "added an effect in {} of 100 clean campaigns: {added:?}",
        added.len()
    );
}

#[test]
fn structure_outside_the_library_is_reported_with_its_regressor() {
    // A reading error that grows with the square of the platform height: no library effect
    // has that shape (think of a gauge that sags with its own extension angle).
    let mut data = campaign_with(None, |_| 0.0, 9);
    let poses = data.poses.clone();
    for r in data.readings.iter_mut() {
        let dz = (poses[r.pose].position_mm.z - 410.0) / 100.0;
        r.length_mm += 25e-3 * dz * dz;
    }
    let r = refine(&base_model(), &data, &options()).unwrap();
    eprintln!(
        "outside the library: steps {:?}, unexplained structure {:?}",
        r.steps.iter().map(|s| s.effect).collect::<Vec<_>>(),
        r.unexplained_structure
    );
    assert!(
        r.unexplained_structure
            .iter()
            .any(|s| s == "pose z squared"),
        "steps {:?}, unexplained {:?}",
        r.steps.iter().map(|s| s.effect).collect::<Vec<_>>(),
        r.unexplained_structure
    );
}
