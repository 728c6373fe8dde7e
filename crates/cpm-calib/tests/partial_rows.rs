//! Tracker measurements with components not measured (`Campaign::unmeasured`): they are not
//! observations, whatever value the measured pose holds there; the Jacobian of the rest is
//! exact; restricting a campaign keeps the right components.
use cpm_calib::campaign::PoseMeasurement;
use cpm_calib::model::{predict, Predictions, Prepared};
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::*;
use cpm_geometry::{JointTable, Pose};
use nalgebra::{Rotation3, Vector3};

fn model() -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::hexapod_66());
    m.effects = vec![Effect::LinkOffset];
    m
}

fn truth(m: &MeasurementModel) -> Vec<f64> {
    (0..m.num_params())
        .map(|k| 30.0 * ((k as f64) * 0.61).sin())
        .collect()
}

/// 30 poses measured by a tracker (noise-free, then a deterministic 3 um / 6 urad wobble),
/// with `unmeasured` components.
fn campaign(m: &MeasurementModel, unmeasured: Vec<(usize, usize)>) -> Campaign {
    let mut c = Campaign {
        poses: random_workspace_poses(&m.nominal, 30, 60.0, 12.0, 3.0, 11),
        pose_sigma_um: 3.0,
        orientation_sigma_urad: 6.0,
        simulated: true,
        ..Campaign::default()
    };
    for j in 0..c.poses.len() {
        c.pose_measurements.push(PoseMeasurement {
            pose: j,
            measured: c.poses[j],
            time_s: None,
            temperature_c: None,
        });
    }
    let prepared = Prepared::new(m, &c).unwrap();
    let y = predict(m, &prepared, &c, &truth(m), None).unwrap();
    for (q, pm) in c.pose_measurements.iter_mut().enumerate() {
        let o = 6 * q;
        let wobble = |a: usize| ((q * 6 + a) as f64 * 1.7).sin();
        let p = Vector3::new(y[o], y[o + 1], y[o + 2])
            + Vector3::new(wobble(0), wobble(1), wobble(2)) * 3e-3;
        let w = Vector3::new(y[o + 3], y[o + 4], y[o + 5]) * 1e-3
            + Vector3::new(wobble(3), wobble(4), wobble(5)) * 6e-6;
        pm.measured = Pose::new(p, Rotation3::new(w) * pm.measured.rotation);
    }
    c.unmeasured = unmeasured;
    c
}

fn mask() -> Vec<(usize, usize)> {
    let mut v = Vec::new();
    for q in 0..30 {
        if q % 4 == 1 {
            v.extend([(q, 3), (q, 4), (q, 5)]);
        }
        if q % 5 == 2 {
            v.push((q, 1));
        }
    }
    v.sort_unstable();
    v
}

fn try_fit(m: &MeasurementModel, c: &Campaign) -> Result<Calibration, CalibError> {
    let options = IdentifyOptions {
        sigma_um: Some(3.0),
        ..IdentifyOptions::default()
    };
    identify(m, c, &options)
}

fn fit(m: &MeasurementModel, c: &Campaign) -> Calibration {
    try_fit(m, c).unwrap()
}

#[test]
fn unmeasured_components_are_not_observations() {
    let m = model();
    let c = campaign(&m, mask());
    assert_eq!(c.len(), 6 * 30 - mask().len());
    assert_eq!(c.observations().len(), c.len());
    assert_eq!(c.observation_weights(3.0).len(), c.len());
    // The values held where nothing was measured do not matter: moved by a metre and a
    // radian, the fit is the same to the last digits.
    let mut moved = c.clone();
    for &(q, a) in &mask() {
        let pm = &mut moved.pose_measurements[q];
        if a < 3 {
            pm.measured.position_mm[a] += 1000.0;
        } else {
            pm.measured.rotation =
                Rotation3::new(Vector3::new(1.0, -0.5, 0.3)) * pm.measured.rotation;
        }
    }
    let (a, b) = (fit(&m, &c), fit(&m, &moved));
    assert!((a.residual_rms_um - b.residual_rms_um).abs() < 1e-9);
    for (x, y) in a.minimum_norm_um.iter().zip(&b.minimum_norm_um) {
        assert!((x - y).abs() < 1e-6, "{x} {y}");
    }
    // Without the mask those moved values are observations and spoil the fit (or break it).
    let mut spoiled = moved.clone();
    spoiled.unmeasured.clear();
    if let Ok(s) = try_fit(&m, &spoiled) {
        assert!(s.residual_rms_um > 100.0 * a.residual_rms_um);
    }
    assert!(a.residual_rms_um < 10.0, "{}", a.residual_rms_um);
    // Every kind of observation is where the index map says.
    let kinds = c.observation_kinds();
    assert_eq!(kinds.len(), c.len());
    for (k, kind) in kinds.iter().enumerate() {
        assert_eq!(c.observation_kind(k), *kind);
    }
    assert_eq!(kinds[6 + 1], ObservationKind::TrackerPosition(1, 1));
    assert_eq!(kinds[6 + 3], ObservationKind::TrackerPosition(2, 0));
}

#[test]
fn the_jacobian_of_partial_rows_matches_finite_differences() {
    let m = model();
    let c = campaign(&m, mask());
    let mut problem = Predictions::new(&m, &c).unwrap();
    // Central differences (cpm-lm's checker), relative step 0.025 as in the effects' doc.
    let check = cpm_lm::check_jacobian(&mut problem, &truth(&m), 0.025).unwrap();
    assert!(check.is_consistent(1e-5), "{check}");
}

#[test]
fn restricting_a_campaign_keeps_the_right_components() {
    let m = model();
    let c = campaign(&m, mask());
    let even = c.filter_poses(|j| j % 2 == 0);
    assert_eq!(even.pose_measurements.len(), 15);
    // Pose 2 (now measurement 1) lost its y; pose 12 (now 6) lost y; 9 (odd) is gone.
    assert!(!even.is_measured(1, 1) && even.is_measured(1, 0));
    assert!(!even.is_measured(6, 1));
    let expected: usize = mask().iter().filter(|(q, _)| q % 2 == 0).count();
    assert_eq!(even.unmeasured.len(), expected);
    let prepared = Prepared::new(&m, &even).unwrap();
    let y = predict(&m, &prepared, &even, &truth(&m), None).unwrap();
    assert_eq!(y.len(), even.len());
}
