//! Open instruments: a user instrument's analytic Jacobian against finite differences, the
//! built-in point targets and inclinometers plugged in as user instruments predicting exactly
//! what the built-in path predicts, and a user instrument through identify(),
//! identifiability() and refine()'s cross-validation.
use std::sync::Arc;

use cpm_calib::instruments::{simulate_instruments, Instrument, InstrumentInput};
use cpm_calib::model::{predict, Predictions, Prepared};
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::points::{PointTarget, PointTargets};
use cpm_calib::tilts::{Inclinometer, Inclinometers};
use cpm_calib::*;
use cpm_geometry::JointTable;
use nalgebra::{DMatrix, Rotation3, Vector3};

/// A laser distance sensor with beams from base points to platform points: per beam a zero
/// offset (um), per session the base points' common shift (x y z um: the stand was moved).
#[derive(Debug)]
struct Laser {
    beams: Vec<(Vector3<f64>, Vector3<f64>)>,
}

impl Laser {
    fn beam(
        &self,
        input: &InstrumentInput,
        k: usize,
        nuisance: &[f64],
    ) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.beams.len();
        let (base, platform) = self.beams[k];
        let shift = Vector3::new(nuisance[n], nuisance[n + 1], nuisance[n + 2]) * 1e-3;
        let rp = input.pose.rotation * platform;
        (rp, rp + input.pose.position_mm - base - shift)
    }
}

impl Instrument for Laser {
    fn name(&self) -> &str {
        "laser"
    }
    fn num_channels(&self) -> usize {
        self.beams.len()
    }
    fn num_values(&self) -> usize {
        1
    }
    fn unit(&self) -> &str {
        "mm"
    }
    fn num_instrument_params(&self) -> usize {
        self.beams.len()
    }
    fn num_session_params(&self) -> usize {
        3
    }
    fn predict(&self, input: &InstrumentInput, k: usize, nuisance: &[f64], values: &mut [f64]) {
        values[0] = self.beam(input, k, nuisance).1.norm() + nuisance[k] * 1e-3;
    }
    fn jacobian(
        &self,
        input: &InstrumentInput,
        k: usize,
        nuisance: &[f64],
        d_pose: &mut DMatrix<f64>,
        d_nuisance: &mut DMatrix<f64>,
    ) {
        let (rp, d) = self.beam(input, k, nuisance);
        let u = d.normalize();
        let w = rp.cross(&u);
        let n = self.beams.len();
        for a in 0..3 {
            d_pose[(0, a)] = u[a];
            d_pose[(0, 3 + a)] = w[a];
            d_nuisance[(0, n + a)] = -u[a] * 1e-3;
        }
        d_nuisance[(0, k)] = 1e-3;
    }
}

fn laser() -> Laser {
    let beams = [
        ([900.0, 50.0, 0.0], [100.0, 0.0, 20.0]),
        ([-30.0, 900.0, 40.0], [0.0, 100.0, -10.0]),
        ([20.0, -10.0, -600.0], [30.0, -20.0, 0.0]),
    ];
    Laser {
        beams: beams
            .iter()
            .map(|(b, p)| (Vector3::from(*b), Vector3::from(*p)))
            .collect(),
    }
}

/// The 6-6 hexapod with the laser, two sessions, and `effects`.
fn laser_model(effects: &[Effect]) -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::hexapod_66());
    m.effects = effects.to_vec();
    m.instruments = vec![Arc::new(laser())];
    m.instrument_sessions = 2;
    m
}

fn laser_skeleton(m: &MeasurementModel, poses: usize, seed: u64) -> Campaign {
    let mut c = Campaign {
        poses: random_workspace_poses(&m.nominal, poses, 60.0, 12.0, 4.0, seed),
        simulated: true,
        session_starts: vec![poses / 2],
        ..Campaign::default()
    };
    for j in 0..poses {
        for beam in 0..3 {
            c.instrument_measurements.push(InstrumentMeasurement {
                pose: j,
                instrument: 0,
                channel: beam,
                session: usize::from(j >= poses / 2),
                values: vec![0.0],
                sigma: 0.002,
            });
        }
    }
    c
}

fn truth(np: usize) -> Vec<f64> {
    (0..np).map(|k| 40.0 * ((k as f64) * 0.77).sin()).collect()
}

#[test]
fn a_user_instruments_jacobian_matches_finite_differences() {
    let m = laser_model(&[Effect::LinkOffset]);
    assert_eq!(m.num_params(), 36 + 6 + 3 + 2 * 3);
    let names = m.parameter_names();
    assert_eq!(names[42], "laser instrument 1 [um]");
    assert_eq!(names[45], "laser session 1 (session 1) [um]");
    assert_eq!(names[50], "laser session 3 (session 2) [um]");
    let c = laser_skeleton(&m, 10, 3);
    assert_eq!(c.len(), 30);
    assert_eq!(c.observation_kind(29), ObservationKind::Instrument(29, 0));
    let mut problem = Predictions::new(&m, &c).unwrap();
    // Central differences (cpm-lm's checker), relative step 0.025.
    let check = cpm_lm::check_jacobian(&mut problem, &truth(m.num_params()), 0.025).unwrap();
    assert!(check.is_consistent(1e-5), "{check}");
}

/// Predictions and Jacobians of two models at one parameter vector, equal to round-off.
fn same_predictions(a: (&MeasurementModel, &Campaign), b: (&MeasurementModel, &Campaign)) {
    assert_eq!(a.0.num_params(), b.0.num_params());
    assert_eq!(a.1.observations(), b.1.observations());
    assert_eq!(a.1.observation_weights(3.0), b.1.observation_weights(3.0));
    let x = truth(a.0.num_params());
    let run = |(m, c): (&MeasurementModel, &Campaign)| {
        let mut j = DMatrix::zeros(c.len(), m.num_params());
        let y = predict(m, &Prepared::new(m, c).unwrap(), c, &x, Some(&mut j)).unwrap();
        (y, j)
    };
    let ((ya, ja), (yb, jb)) = (run(a), run(b));
    for (p, q) in ya.iter().zip(&yb) {
        assert!((p - q).abs() < 1e-12, "{p} {q}");
    }
    assert!((&ja - &jb).amax() < 1e-12, "{}", (&ja - &jb).amax());
}

#[test]
fn built_in_point_targets_are_an_instrument_like_any_other() {
    let targets = vec![
        PointTarget {
            name: "smr1".into(),
            platform_mm: Vector3::new(90.0, 10.0, 30.0),
        },
        PointTarget {
            name: "smr2".into(),
            platform_mm: Vector3::new(-50.0, 80.0, 25.0),
        },
    ];
    let mut built_in = MeasurementModel::new(JointTable::hexapod_66());
    built_in.targets = targets.clone();
    built_in.point_sessions = 2;
    built_in.effects = vec![
        Effect::LinkScale,
        Effect::TargetPosition,
        Effect::PointFrame,
    ];
    let mut own = MeasurementModel::new(JointTable::hexapod_66());
    own.effects = vec![Effect::LinkScale];
    own.instruments = vec![Arc::new(PointTargets { targets })];
    own.instrument_sessions = 2;
    let poses = random_workspace_poses(&own.nominal, 8, 60.0, 12.0, 4.0, 9);
    let mut a = Campaign {
        poses,
        point_sigma_um: 5.0,
        ..Campaign::default()
    };
    let mut b = a.clone();
    for j in 0..8 {
        for t in 0..2 {
            let measured = Vector3::new(j as f64, t as f64, 1.0);
            let session = usize::from(j >= 4);
            a.point_measurements.push(PointMeasurement {
                pose: j,
                target: t,
                session,
                measured_mm: measured,
                time_s: None,
            });
            b.instrument_measurements.push(InstrumentMeasurement {
                pose: j,
                instrument: 0,
                channel: t,
                session,
                values: measured.iter().copied().collect(),
                sigma: 0.005,
            });
        }
    }
    same_predictions((&built_in, &a), (&own, &b));
    let names = own.parameter_names();
    assert_eq!(names[42], "point_target target `smr1` x [um]");
    assert_eq!(names[51], "point_target session rx (session 1) [urad]");
}

#[test]
fn built_in_inclinometers_are_an_instrument_like_any_other() {
    let inclinometers = vec![
        Inclinometer {
            name: "scl3300".into(),
            axes: vec![Vector3::y(), -Vector3::x()],
            mount: Rotation3::new(Vector3::new(0.002, -0.001, 0.003)),
        },
        Inclinometer {
            name: "one_axis".into(),
            axes: vec![Vector3::new(1.0, 1.0, 0.0).normalize()],
            mount: Rotation3::identity(),
        },
    ];
    let mut built_in = MeasurementModel::new(JointTable::hexapod_66());
    built_in.inclinometers = inclinometers.clone();
    built_in.tilt_sessions = 2;
    built_in.effects = vec![
        Effect::Compliance,
        Effect::InclinometerMount,
        Effect::BaseTilt,
    ];
    let mut own = MeasurementModel::new(JointTable::hexapod_66());
    own.effects = vec![Effect::Compliance];
    let instrument = Inclinometers { inclinometers };
    let channels = [(0, 0), (0, 1), (1, 0)].map(|(i, a)| (i, a, instrument.channel(i, a)));
    own.instruments = vec![Arc::new(instrument)];
    own.instrument_sessions = 2;
    let poses = random_workspace_poses(&own.nominal, 8, 40.0, 8.0, 4.0, 21);
    let mut a = Campaign {
        poses,
        tilt_sigma_urad: 20.0,
        ..Campaign::default()
    };
    let mut b = a.clone();
    for j in 0..8 {
        for &(i, axis, channel) in &channels {
            let session = usize::from(j >= 4);
            let angle = 0.1 * j as f64 - 0.3 * axis as f64;
            a.tilt_measurements.push(TiltMeasurement {
                pose: j,
                inclinometer: i,
                axis,
                session,
                angle_mrad: angle,
                time_s: None,
            });
            b.instrument_measurements.push(InstrumentMeasurement {
                pose: j,
                instrument: 0,
                channel,
                session,
                values: vec![angle],
                sigma: 0.02,
            });
        }
    }
    same_predictions((&built_in, &a), (&own, &b));
}

#[test]
fn a_user_instrument_is_fitted_analysed_and_cross_validated_through_the_one_path() {
    // Gauge readings of the designed sensors pin the joints; the laser brings its offsets and
    // a stand shift per session.
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = paper::designed_sensors();
    m.instruments = vec![Arc::new(laser())];
    m.instrument_sessions = 2;
    let mut skeleton = laser_skeleton(&m, 40, 11);
    skeleton.poses = random_workspace_poses(&m.nominal, 40, 100.0, 25.0, 3.0, 7);
    let gauges = Plan {
        poses: skeleton.poses.clone(),
        sensors: (0..16).collect(),
    }
    .skeleton();
    skeleton.readings = gauges.readings;
    let mut x = vec![0.0; m.num_params()];
    for (k, v) in x.iter_mut().enumerate().take(36) {
        *v = 30.0 * ((k as f64) * 0.9).cos();
    }
    let nuisance = [
        150.0, -80.0, 40.0, 300.0, -200.0, 100.0, -250.0, 120.0, 60.0,
    ];
    x[36..].copy_from_slice(&nuisance);
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: 2.0 },
        repeats: 1,
        seed: 5,
    };
    let data = simulate_instruments(&m, &x, &skeleton, &sim).unwrap();
    let options = IdentifyOptions {
        sigma_um: Some(2.0),
        ..IdentifyOptions::default()
    };
    // The plan sees the nuisance parameters: their Cramér-Rao bounds are finite.
    let id = identifiability(&m, &data, 2.0, &RankOptions::default()).unwrap();
    let cal = identify(&m, &data, &options).unwrap();
    assert!(
        (cal.residual_rms_um - 2.0).abs() < 0.4,
        "{}",
        cal.residual_rms_um
    );
    // Every identifiable combination holds the truth within its deviation.
    let mut worst: f64 = 0.0;
    for (k, comb) in cal.combinations.iter().enumerate() {
        let v = cal.identifiability.v.column(k);
        let est: f64 = v.iter().zip(&cal.minimum_norm_um).map(|(a, b)| a * b).sum();
        let t: f64 = v.iter().zip(&x).map(|(a, b)| a * b).sum();
        worst = worst.max(((est - t) / comb.std_um).abs());
    }
    assert!(
        worst < 4.5,
        "worst {worst} sd over {} combinations",
        id.rank
    );
    // Every nuisance parameter is determined on its own: the beam offsets, and the stand's
    // shift per session (the beams' directions change enough over the workspace).
    for (k, t) in nuisance.iter().enumerate() {
        let (e, s) = (
            cal.estimate_um[36 + k].unwrap(),
            cal.std_um[36 + k].unwrap(),
        );
        assert!(
            (e - t).abs() < 4.0 * s && s < 6.0,
            "{}: {e} +- {s}, truth {t}",
            m.parameter_names()[36 + k]
        );
    }
    // Cross-validation drops instrument observations with their measurement.
    let refined = refine(
        &m,
        &data,
        &RefineOptions {
            candidates: vec![Effect::LinkOffset],
            identify: options.clone(),
            ..RefineOptions::default()
        },
    )
    .unwrap();
    assert!(refined.steps.is_empty(), "{:?}", refined.steps.len());
    // A machine held fixed does not carry the instrument's nuisance values: refused.
    assert!(m.held_fixed(&x).is_err());
    // A measurement of a channel the instrument does not have is refused before any fit.
    let mut bad = data.clone();
    bad.instrument_measurements[0].channel = 3;
    let e = identify(&m, &bad, &options).unwrap_err().to_string();
    assert!(e.contains("channel"), "{e}");
}
