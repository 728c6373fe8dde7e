//! What a compensation can promise, checked on simulated truths (SIMULATED data): over many
//! seeds the true pose error a compensation leaves falls inside its stated 95 % band about
//! 95 % of the time.
//!
//! The machine's error after compensation is found without the measurement model: the
//! commands are the fitted joints' inverse kinematics, the pose the true joints reach is
//! their forward kinematics (cpm-kinematics), and the error is the twist from target to
//! reached pose. Only the band comes from the fit ([`parameter_covariance`] and
//! [`predicted_pose_error`]).
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::promise::{parameter_covariance, predicted_pose_error, PredictedPoseError};
use cpm_calib::*;
use cpm_geometry::JointTable;
use cpm_kinematics::{forward, inverse_lengths};
use rand::{Rng, SeedableRng};

const SIGMA_UM: f64 = 2.0;

/// The paper's cubic machine with the designed sensors; no clearance (the controller and the
/// machine then agree that a command is a length).
fn machine() -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m.clearance = cpm_clearance::ClearanceModel::none();
    m
}

/// One seed: a random machine (installation errors uniform in +-60 um), a random campaign of
/// 24 poses read by 4 sensors at 2 um, a fit, and 6 targets compensated. Returns, per target,
/// (position covered, orientation covered, true position error um, its band um, position
/// covered by a band of half the width).
fn one_seed(m: &MeasurementModel, seed: u64) -> Vec<(bool, bool, f64, f64, bool)> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1000 + seed);
    let truth: Vec<f64> = (0..36).map(|_| rng.random_range(-60.0..60.0)).collect();
    let plan = Plan {
        poses: random_workspace_poses(&m.nominal, 24, 80.0, 20.0, 3.0, seed + 1),
        sensors: vec![0, 5, 10, 15],
    };
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: SIGMA_UM },
        repeats: 1,
        seed,
    };
    let data = simulate(m, &truth, &plan, &sim).unwrap();
    let options = IdentifyOptions {
        sigma_um: Some(SIGMA_UM),
        ..IdentifyOptions::default()
    };
    let cal = identify(m, &data, &options).unwrap();
    assert_eq!(
        cal.identifiability.rank, 36,
        "seed {seed}: every error determined"
    );
    let c = parameter_covariance(m, &data, &cal).unwrap();
    let targets = random_workspace_poses(&m.nominal, 6, 60.0, 15.0, 3.0, 5000 + seed);
    let bands = predicted_pose_error(m, &cal.minimum_norm_um, &c, &targets).unwrap();
    let fitted = m.table_with(&cal.minimum_norm_um).unwrap();
    let true_table = m.table_with(&truth).unwrap();
    targets
        .iter()
        .zip(&bands)
        .map(|(t, band)| {
            let commands = inverse_lengths(&fitted, t);
            let (reached, _) = forward(&true_table, &commands, t, &m.fk).unwrap();
            let twist = t.difference(&reached);
            let half = PredictedPoseError {
                covariance: band.covariance / 4.0,
            };
            (
                band.position_covers(&twist),
                band.orientation_covers(&twist),
                twist.fixed_rows::<3>(0).norm() * 1e3,
                band.position_95_um(),
                half.position_covers(&twist),
            )
        })
        .collect()
}

#[test]
fn the_stated_95_percent_band_covers_the_true_error_95_percent_of_the_time() {
    let m = machine();
    let seeds = 200;
    let all: Vec<_> = (0..seeds).flat_map(|s| one_seed(&m, s)).collect();
    let n = all.len() as f64;
    let position = all.iter().filter(|r| r.0).count() as f64 / n;
    let orientation = all.iter().filter(|r| r.1).count() as f64 / n;
    let mean_error = all.iter().map(|r| r.2).sum::<f64>() / n;
    let mean_band = all.iter().map(|r| r.3).sum::<f64>() / n;
    // The check has teeth: a band of half the width covers far less.
    let half = all.iter().filter(|r| r.4).count() as f64 / n;
    println!(
        "SIMULATED, {seeds} seeds x 6 targets: coverage of the 95 % band: position {:.1} %, \
         orientation {:.1} %; mean true position error {mean_error:.2} um, mean band radius \
         {mean_band:.2} um; a band of half the width covers {:.1} %",
        100.0 * position,
        100.0 * orientation,
        100.0 * half
    );
    assert!(half < 0.80, "half-width coverage {half}");
    assert!(
        (0.90..=0.99).contains(&position),
        "position coverage {position}"
    );
    assert!(
        (0.90..=0.99).contains(&orientation),
        "orientation coverage {orientation}"
    );
    // The band is informative, not merely wide: of the size of the errors it covers.
    assert!(
        mean_band < 6.0 * mean_error,
        "band {mean_band} um, error {mean_error} um"
    );
}

/// The covariance is the fit's own: under the default prior its diagonal is the posterior
/// standard deviations the fit reports (every parameter it reports one for); without a prior
/// it is the fit's Cramér-Rao bounds, and zero along what the data cannot see (no number
/// there is measured). The paper's design: one sensor on a circle, rank below 36.
#[test]
fn the_covariance_is_the_fits_own_and_blind_directions_carry_none() {
    let m = machine();
    let plan = Plan {
        poses: cpm_calib::campaign::paper_circle(&m.nominal.home),
        sensors: vec![0],
    };
    let truth: Vec<f64> = (0..36).map(|k| 30.0 * (k as f64 * 0.7).cos()).collect();
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: SIGMA_UM },
        repeats: 1,
        seed: 3,
    };
    let data = simulate(&m, &truth, &plan, &sim).unwrap();
    // Under the default prior: the posterior the fit summarises.
    let options = IdentifyOptions {
        sigma_um: Some(SIGMA_UM),
        ..IdentifyOptions::default()
    };
    let cal = identify(&m, &data, &options).unwrap();
    let prior = cal.prior.as_ref().expect("the default fit has a prior");
    let c = parameter_covariance(&m, &data, &cal).unwrap();
    let close = |a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>| {
        (a - b).abs().max() <= 1e-9 * b.abs().max()
    };
    // The fit forms the same covariance itself (what calibrate writes).
    assert!(close(&cal.covariance, &c), "the fit's covariance differs");
    let mut compared = 0;
    for k in 0..36 {
        if let Some(std) = prior.posterior_std[k] {
            let ours = c[(k, k)].sqrt();
            assert!(
                (ours - std).abs() <= 1e-9 * std.max(1.0),
                "parameter {k}: {ours} vs {std}"
            );
            compared += 1;
        }
    }
    assert_eq!(
        compared, 36,
        "every parameter is bounded by the data or its tolerance"
    );
    // Without a prior: the Cramer-Rao bounds, and nothing along the blind directions.
    let options = IdentifyOptions {
        sigma_um: Some(SIGMA_UM),
        tolerances: cpm_calib::prior::Tolerances::none(),
        ..IdentifyOptions::default()
    };
    let cal = identify(&m, &data, &options).unwrap();
    let rank = cal.identifiability.rank;
    assert!(rank < 36, "rank {rank}");
    let c = parameter_covariance(&m, &data, &cal).unwrap();
    assert!(
        close(&cal.covariance, &c),
        "the fit's covariance differs (no prior)"
    );
    for k in 0..36 {
        if let Some(std) = cal.std_um[k] {
            let ours = c[(k, k)].sqrt();
            assert!(
                (ours - std).abs() <= 1e-6 * std,
                "parameter {k}: {ours} vs {std}"
            );
        }
    }
    let null = cal.identifiability.null_space();
    assert_eq!(null.ncols(), 36 - rank);
    for q in 0..null.ncols() {
        let v = null.column(q);
        let var = (v.transpose() * &c * v)[(0, 0)];
        assert!(
            var.abs() < 1e-9 * c.trace(),
            "blind direction {q}: variance {var}"
        );
    }
}
