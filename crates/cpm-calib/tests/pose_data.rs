//! A general 6-6 hexapod measured by a tracker: pose measurements, tracker registration,
//! link offset/scale unknowns, the gauge freedoms the registration brings, and an actuator
//! mapping with a non-linearity nobody declared.
use cpm_calib::campaign::PoseMeasurement;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::*;
use cpm_geometry::JointTable;
use rand::{Rng, SeedableRng};

const POS_SIGMA: f64 = 5.0;
const ORI_SIGMA: f64 = 10.0;

/// A tracker campaign on `truth_model` with parameters `truth`: every pose measured, Gaussian
/// noise on position (um) and orientation (urad).
fn tracker_campaign(
    truth_model: &MeasurementModel,
    truth: &[f64],
    poses: usize,
    seed: u64,
) -> Campaign {
    let t = &truth_model.nominal;
    let mut c = Campaign {
        poses: random_workspace_poses(t, poses, 60.0, 12.0, 3.0, seed),
        pose_sigma_um: POS_SIGMA,
        orientation_sigma_urad: ORI_SIGMA,
        simulated: true,
        ..Campaign::default()
    };
    for j in 0..c.poses.len() {
        c.pose_measurements.push(PoseMeasurement {
            pose: j,
            measured: c.poses[j],
            time_s: Some(j as f64),
            temperature_c: None,
        });
    }
    let prepared = Prepared::new(truth_model, &c).unwrap();
    let y = predict(truth_model, &prepared, &c, truth, None).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut gauss = |s: f64| {
        // Box-Muller.
        let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
        s * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    for (q, pm) in c.pose_measurements.iter_mut().enumerate() {
        let o = 6 * q;
        let p = nalgebra::Vector3::new(y[o], y[o + 1], y[o + 2])
            + nalgebra::Vector3::new(gauss(POS_SIGMA), gauss(POS_SIGMA), gauss(POS_SIGMA)) * 1e-3;
        // y[o+3..] is the rotation from the commanded to the true orientation (mrad).
        let w = nalgebra::Vector3::new(y[o + 3], y[o + 4], y[o + 5]) * 1e-3
            + nalgebra::Vector3::new(gauss(ORI_SIGMA), gauss(ORI_SIGMA), gauss(ORI_SIGMA)) * 1e-6;
        pm.measured =
            cpm_geometry::Pose::new(p, nalgebra::Rotation3::new(w) * pm.measured.rotation);
    }
    c
}

fn hexapod_model(effects: &[Effect]) -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::hexapod_66());
    m.effects = effects.to_vec();
    m
}

fn truth_for(model: &MeasurementModel) -> Vec<f64> {
    (0..model.num_params())
        .map(|k| 40.0 * ((k as f64) * 0.77).sin())
        .collect()
}

#[test]
fn hexapod_with_tracker_offsets_and_scales_is_calibrated() {
    let model = hexapod_model(&[Effect::LinkOffset, Effect::LinkScale, Effect::TrackerFrame]);
    let truth = truth_for(&model);
    let data = tracker_campaign(&model, &truth, 60, 3);
    let opts = IdentifyOptions {
        sigma_um: Some(POS_SIGMA),
        ..IdentifyOptions::default()
    };
    let cal = identify(&model, &data, &opts).unwrap();
    let id = &cal.identifiability;
    // The registration brings six gauge freedoms (translation and rotation of base and tracker
    // together); with pose data, link offsets are confounded with joints moved along the link.
    assert!(id.rank < model.num_params());
    let text = id.summary();
    assert!(text.contains("tracker frame translated together"), "{text}");
    assert!(text.contains("tracker frame rotated together"), "{text}");
    // Everything the data determine agrees with the truth within 5 standard deviations,
    // and the residual is at the noise.
    let mut checked = 0;
    for k in 0..model.num_params() {
        if let (Some(e), Some(s)) = (cal.estimate_um[k], cal.std_um[k]) {
            assert!(
                (e - truth[k]).abs() < 5.0 * s + 1e-6,
                "{}: {e} vs {} (std {s})",
                model.parameter_names()[k],
                truth[k]
            );
            checked += 1;
        }
    }
    assert!(checked > 0, "nothing determined");
    assert!(
        cal.residual_rms_um < 1.3 * POS_SIGMA,
        "{}",
        cal.residual_rms_um
    );
}

#[test]
fn refine_finds_an_undeclared_actuator_nonlinearity_on_a_hexapod() {
    let truth_model = hexapod_model(&[Effect::TrackerFrame, Effect::LinkNonlinearity]);
    let mut truth = truth_for(&truth_model);
    // Non-linearity of 30 um at 100 mm from home, a few times the tracker noise.
    let nl = truth_model.blocks()[2];
    for k in 0..nl.len {
        truth[nl.offset + k] = if k % 2 == 0 { 30.0 } else { -15.0 };
    }
    let data = tracker_campaign(&truth_model, &truth, 80, 5);
    let declared = hexapod_model(&[Effect::TrackerFrame]);
    let opts = RefineOptions {
        identify: IdentifyOptions {
            sigma_um: Some(POS_SIGMA),
            ..IdentifyOptions::default()
        },
        ..RefineOptions::default()
    };
    let r = refine(&declared, &data, &opts).unwrap();
    let names: Vec<Effect> = r.steps.iter().map(|s| s.effect).collect();
    eprintln!(
        "hexapod, tracker: steps {names:?}, cv RMS {:.3} -> {:.3} um (noise {POS_SIGMA} um)",
        r.steps.first().map_or(f64::NAN, |s| s.cv_rms_before_um),
        r.final_cv_rms_um
    );
    assert_eq!(names.first(), Some(&Effect::LinkNonlinearity), "{names:?}");
    assert!(r.steps[0].cv_rms_after_um < r.steps[0].cv_rms_before_um);
    assert!(
        r.final_cv_rms_um < 1.2 * POS_SIGMA,
        "cv {}",
        r.final_cv_rms_um
    );
}

/// The marker frame (`marker_frame`: the body a tracker measures, placed on the platform):
/// its Jacobian against central differences at a large frame (15 mm, 10 mrad), with a
/// tracker frame and joint errors beside it.
#[test]
fn the_marker_frame_jacobian_matches_finite_differences() {
    let model = hexapod_model(&[
        Effect::TrackerFrame,
        Effect::MarkerFrame,
        Effect::LinkOffset,
    ]);
    let mut x = truth_for(&model);
    let b = model
        .blocks()
        .into_iter()
        .find(|b| b.effect == Some(Effect::MarkerFrame))
        .unwrap();
    x[b.offset..b.offset + 6].copy_from_slice(&[3000.0, -2000.0, 15000.0, 1000.0, -9500.0, 2000.0]);
    let data = tracker_campaign(&model, &x, 12, 5);
    let mut problem = cpm_calib::model::Predictions::new(&model, &data).unwrap();
    let check = cpm_lm::check_jacobian(&mut problem, &x, 0.025).unwrap();
    assert!(check.is_consistent(1e-5), "{check}");
}

/// SIMULATED, with an independent model of the body: the tracker reports a rigid body 15 mm
/// above the platform and turned by 10 mrad (composed here with nalgebra on the forward
/// kinematics of the nominal machine without joint clearance, not through `marker_frame`). A fit with `marker_frame`
/// puts that body into the marker frame, not into the platform joints, and the six gauge
/// freedoms it shares with them are named.
#[test]
fn a_body_offset_goes_into_the_marker_frame_not_the_joints() {
    let machine = hexapod_model(&[]);
    let mut data = tracker_campaign(&machine, &vec![0.0; 36], 40, 9);
    let body_t = nalgebra::Vector3::new(3.0, -2.0, 15.0);
    let body_r = nalgebra::Rotation3::new(nalgebra::Vector3::new(1e-3, -9.5e-3, 2e-3));
    for pm in &mut data.pose_measurements {
        let reached = cpm_kinematics::forward(
            &machine.nominal,
            &cpm_kinematics::inverse_lengths(&machine.nominal, &data.poses[pm.pose]),
            &data.poses[pm.pose],
            &Default::default(),
        )
        .unwrap()
        .0;
        pm.measured = cpm_geometry::Pose::new(
            reached.position_mm + reached.rotation * body_t,
            reached.rotation * body_r,
        );
    }
    let mut model = hexapod_model(&[Effect::TrackerFrame, Effect::MarkerFrame]);
    // The body's model above has no joint clearance: nor has this one.
    model.clearance = cpm_clearance::ClearanceModel::none();
    let opts = IdentifyOptions {
        sigma_um: Some(POS_SIGMA),
        ..IdentifyOptions::default()
    };
    let cal = identify(&model, &data, &opts).unwrap();
    let text = cal.identifiability.summary();
    assert!(
        text.contains("platform joints and the marker frame translated together"),
        "{text}"
    );
    assert!(
        text.contains("platform joints and the marker frame rotated together"),
        "{text}"
    );
    let e = &cal.minimum_norm_um;
    let b = model
        .blocks()
        .into_iter()
        .find(|b| b.effect == Some(Effect::MarkerFrame))
        .unwrap();
    let (t, r) = cpm_calib::effects::tracker_registration(&e[b.offset..b.offset + 6]);
    assert!(
        (t - body_t).norm() < 1e-3,
        "marker at {t} mm, body at {body_t}"
    );
    assert!(
        (r.inverse() * body_r).angle() < 5e-6,
        "marker turned {} rad off the body",
        (r.inverse() * body_r).angle()
    );
    let joints = e[..36].iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(joints < 1.0, "joints moved {joints} um");
}
