//! The 6-D tracker pose as an [`Instrument`]: a laser tracker's 6-D probe or a motion-capture
//! rigid body reports the platform's position and orientation in its own frame.
//!
//! The values of one pose measurement are the platform position in the tracker frame (mm) and
//! the rotation vector from the measured to the predicted orientation (mrad), whose measured
//! value is zero: the prediction depends on the measured orientation, so the instrument holds
//! it ([`TrackerPoses::measured`]), one per measurement, as a factor of a factor graph holds
//! its measurement. The body measured sits on the platform in its marker frame
//! `(t_m, R_m)` (a known part, [`TrackerPoses::marker`], composed with the estimated
//! `marker_frame`: the instrument's own six parameters, tx ty tz um and rx ry rz urad), so the
//! measured pose is `(p + R t_m, R R_m)` for the platform pose `(p, R)`. The frame
//! `p_tracker = R_e (R_k p + t_k) + t_e` composes a known registration (`R_k`, `t_k`: a
//! previous calibration's `tracker_frame`) with the estimated one of the session (`R_e`, `t_e`:
//! the six nuisance parameters per session, tx ty tz um and rx ry rz urad, of `tracker_frame`).
use cpm_geometry::rotation::{left_jacobian, left_jacobian_inverse, log};
use nalgebra::{DMatrix, Rotation3, Vector3};

use crate::model::effects::EffectModel;
use crate::model::instruments::{Instrument, InstrumentInput};

const FRAME: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];

/// A tracker pose measurement of orientation [`measured`](Self::measured) as an
/// [`Instrument`]: one channel, six values (position mm, the rotation from the measured to the
/// predicted orientation mrad), the marker frame on the platform (six parameters of its own)
/// and a tracker frame per session (six parameters). The measurement model makes one per pose
/// measurement ([`Campaign::pose_measurements`](crate::Campaign)).
///
/// ```
/// use cpm_calib::instruments::{Instrument, TrackerPoses};
/// use cpm_calib::instruments::InstrumentInput;
/// use cpm_geometry::Pose;
/// use nalgebra::{Rotation3, Vector3};
/// let tracker = TrackerPoses::default();
/// assert_eq!((tracker.num_values(), tracker.num_instrument_params()), (6, 6));
/// assert_eq!(tracker.num_session_params(), 6);
/// assert_eq!((tracker.param_name(9), tracker.param_unit(9)), ("session rx".into(), "urad"));
/// assert_eq!((tracker.param_name(2), tracker.param_unit(2)), ("marker tz".into(), "um"));
/// // Measured 1 mrad about z off the pose reached, in a frame shifted 2 mm along x.
/// let reached = Pose::new(Vector3::new(1.0, 2.0, 3.0), Rotation3::identity());
/// let measured = Rotation3::new(Vector3::new(0.0, 0.0, 0.001));
/// let tracker = TrackerPoses { measured, ..TrackerPoses::default() };
/// let m = cpm_calib::MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// let ctx = m.pose_context(&reached, vec![0.0; 6], None, None, None).unwrap();
/// let effect = cpm_calib::EffectInput { context: &ctx, commanded: &reached, home: &reached,
///                                       settings: &m.effect_settings, t0_s: 0.0 };
/// let input = InstrumentInput { pose: &reached, effect, up: Vector3::z() };
/// let mut y = [0.0; 6];
/// let (marker, frame) = ([0.0; 6], [2000.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
/// tracker.predict(&input, 0, &[marker, frame].concat(), &mut y);
/// let expected = [3.0, 2.0, 3.0, 0.0, 0.0, -1.0];
/// assert!(y.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-9), "{y:?}");
/// // The measured body 5 mm above the platform origin: the position seen moves with it.
/// tracker.predict(&input, 0, &[[0.0, 0.0, 5000.0, 0.0, 0.0, 0.0], frame].concat(), &mut y);
/// assert!((y[2] - 8.0).abs() < 1e-9, "{y:?}");
/// ```
#[derive(Debug, Clone, Copy)]
pub struct TrackerPoses {
    /// The known registration (`p_tracker = R p + t`, t mm), applied before the estimated
    /// frame. Default: the identity.
    pub known: (Vector3<f64>, Rotation3<f64>),
    /// The effect whose [`tracker_registration`](EffectModel::tracker_registration) maps the
    /// session parameters to a frame. Default: `tracker_frame`'s.
    pub frame: &'static dyn EffectModel,
    /// The measured orientation (tracker frame). Default: the identity.
    pub measured: Rotation3<f64>,
    /// The known marker frame on the platform (`t_m` mm, `R_m`: a previous calibration's
    /// `marker_frame`), composed with the estimated one. Default: the identity.
    pub marker: (Vector3<f64>, Rotation3<f64>),
}

impl Default for TrackerPoses {
    fn default() -> Self {
        Self {
            known: (Vector3::zeros(), Rotation3::identity()),
            frame: &crate::model::effects::TrackerFrame,
            measured: Rotation3::identity(),
            marker: (Vector3::zeros(), Rotation3::identity()),
        }
    }
}

impl TrackerPoses {
    /// The marker frame on the platform (`t_m` mm, `R_m`): the known one composed with the
    /// estimated parameters `own` (tx ty tz um, rx ry rz urad, in the known marker frame).
    pub fn marker_frame(&self, own: &[f64]) -> (Vector3<f64>, Rotation3<f64>) {
        let (te, re) = crate::model::effects::tracker_registration(own);
        let (kt, kr) = self.marker;
        (kt + kr * te, kr * re)
    }

    /// The pose in the session's frame: position (mm) and rotation.
    fn tracked(&self, input: &InstrumentInput, nuisance: &[f64]) -> (Vector3<f64>, Rotation3<f64>) {
        let (tm, rm) = self.marker_frame(&nuisance[..6]);
        let ((kt, kr), (rt, rr)) = (self.known, self.frame.tracker_registration(&nuisance[6..]));
        let pose = input.pose;
        let position = pose.position_mm + pose.rotation * tm;
        (rr * (kr * position + kt) + rt, rr * kr * pose.rotation * rm)
    }

    /// The rotation vector from the measured to the predicted orientation, rad.
    fn residual(&self, tracked: &Rotation3<f64>) -> Vector3<f64> {
        log(&(tracked * self.measured.inverse()))
    }
}

impl Instrument for TrackerPoses {
    fn name(&self) -> &str {
        "tracker_pose"
    }
    fn num_values(&self) -> usize {
        6
    }
    fn unit(&self) -> &str {
        "mm (position), mrad (orientation)"
    }
    fn num_instrument_params(&self) -> usize {
        6
    }
    fn num_session_params(&self) -> usize {
        6
    }
    fn param_name(&self, k: usize) -> String {
        let what = if k < 6 { "marker" } else { "session" };
        format!("{what} {}", FRAME[k % 6])
    }
    fn param_unit(&self, k: usize) -> &str {
        if k % 6 >= 3 {
            "urad"
        } else {
            "um"
        }
    }
    fn predict(&self, input: &InstrumentInput, _: usize, nuisance: &[f64], values: &mut [f64]) {
        let (p, r) = self.tracked(input, nuisance);
        let w = self.residual(&r) * 1e3;
        values[..3].copy_from_slice(p.as_slice());
        values[3..].copy_from_slice(w.as_slice());
    }
    fn jacobian(
        &self,
        input: &InstrumentInput,
        _: usize,
        nuisance: &[f64],
        d_pose: &mut DMatrix<f64>,
        d_nuisance: &mut DMatrix<f64>,
    ) {
        let (p, r) = self.tracked(input, nuisance);
        let w = self.residual(&r);
        let (rt, rr) = self.frame.tracker_registration(&nuisance[6..]);
        let (tm, rm) = self.marker_frame(&nuisance[..6]);
        let rr_all = (rr * self.known.1).into_inner();
        let rot = input.pose.rotation.into_inner();
        let jl_inv = left_jacobian_inverse(&w);
        // The measured body's position p + R t_m turns with the platform: -[R t_m]x per rad.
        d_pose.view_mut((0, 0), (3, 3)).copy_from(&rr_all);
        d_pose
            .view_mut((0, 3), (3, 3))
            .copy_from(&(rr_all * -(rot * tm).cross_matrix()));
        d_pose
            .view_mut((3, 3), (3, 3))
            .copy_from(&(jl_inv * rr_all * 1e3));
        // The marker frame, per um and urad: R (R_k t_e) moves the position; R R_k exp(w_e)
        // exp(J_r(w_e) d) turns the orientation by (A R R_m) J_r d on the left.
        let kr = self.marker.1.into_inner();
        d_nuisance
            .view_mut((0, 0), (3, 3))
            .copy_from(&(rr_all * rot * kr * 1e-3));
        let we = Vector3::new(nuisance[3], nuisance[4], nuisance[5]) * 1e-6;
        let jr = left_jacobian(&we).transpose();
        d_nuisance
            .view_mut((3, 3), (3, 3))
            .copy_from(&(jl_inv * rr_all * rot * rm.into_inner() * jr * 1e-3));
        // The frame's rotation exp(w_f + d) = exp(J_l(w_f) d) exp(w_f): d(exp(v) R x)/dv =
        // -[R x]x, per urad; the orientation through J_l^-1, per urad.
        let wf = Vector3::new(nuisance[9], nuisance[10], nuisance[11]) * 1e-6;
        let jl_f = left_jacobian(&wf);
        let sk = (p - rt).cross_matrix() * jl_f * -1e-6;
        for a in 0..3 {
            d_nuisance[(a, 6 + a)] = 1e-3;
        }
        d_nuisance.view_mut((0, 9), (3, 3)).copy_from(&sk);
        d_nuisance
            .view_mut((3, 9), (3, 3))
            .copy_from(&(jl_inv * jl_f * 1e-3));
    }
}
