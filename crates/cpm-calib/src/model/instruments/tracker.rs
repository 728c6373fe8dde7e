//! The 6-D tracker pose as an [`Instrument`]: a laser tracker's 6-D probe or a motion-capture
//! rigid body reports the platform's position and orientation in its own frame.
//!
//! The values of one pose measurement are the platform position in the tracker frame (mm) and
//! the rotation vector from the measured to the predicted orientation (mrad), whose measured
//! value is zero: the prediction depends on the measured orientation, so the instrument holds
//! it ([`TrackerPoses::measured`]), one per measurement, as a factor of a factor graph holds
//! its measurement. The frame
//! `p_tracker = R_e (R_k p + t_k) + t_e` composes a known registration (`R_k`, `t_k`: a
//! previous calibration's `tracker_frame`) with the estimated one of the session (`R_e`, `t_e`:
//! the six nuisance parameters per session, tx ty tz um and rx ry rz urad, of `tracker_frame`).
use cpm_geometry::rotation::{left_jacobian_inverse, log};
use nalgebra::{DMatrix, Rotation3, Vector3};

use crate::model::effects::EffectModel;
use crate::model::instruments::{Instrument, InstrumentInput};

const FRAME: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];

/// A tracker pose measurement of orientation [`measured`](Self::measured) as an
/// [`Instrument`]: one channel, six values (position mm, the rotation from the measured to the
/// predicted orientation mrad), a tracker frame per session (six parameters). The measurement
/// model makes one per pose measurement ([`Campaign::pose_measurements`](crate::Campaign)).
///
/// ```
/// use cpm_calib::instruments::{Instrument, TrackerPoses};
/// use cpm_calib::instruments::InstrumentInput;
/// use cpm_geometry::Pose;
/// use nalgebra::{Rotation3, Vector3};
/// let tracker = TrackerPoses::default();
/// assert_eq!((tracker.num_values(), tracker.num_session_params()), (6, 6));
/// assert_eq!((tracker.param_name(3), tracker.param_unit(3)), ("session rx".into(), "urad"));
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
/// tracker.predict(&input, 0, &[2000.0, 0.0, 0.0, 0.0, 0.0, 0.0], &mut y);
/// let expected = [3.0, 2.0, 3.0, 0.0, 0.0, -1.0];
/// assert!(y.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-9), "{y:?}");
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
}

impl Default for TrackerPoses {
    fn default() -> Self {
        Self {
            known: (Vector3::zeros(), Rotation3::identity()),
            frame: &crate::model::effects::TrackerFrame,
            measured: Rotation3::identity(),
        }
    }
}

impl TrackerPoses {
    /// The pose in the session's frame: position (mm) and rotation.
    fn tracked(&self, input: &InstrumentInput, nuisance: &[f64]) -> (Vector3<f64>, Rotation3<f64>) {
        let ((kt, kr), (rt, rr)) = (self.known, self.frame.tracker_registration(nuisance));
        let pose = input.pose;
        (
            rr * (kr * pose.position_mm + kt) + rt,
            rr * kr * pose.rotation,
        )
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
    fn num_session_params(&self) -> usize {
        6
    }
    fn param_name(&self, k: usize) -> String {
        format!("session {}", FRAME[k % 6])
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
        let (rt, rr) = self.frame.tracker_registration(nuisance);
        let rr_all = (rr * self.known.1).into_inner();
        let jl_inv = left_jacobian_inverse(&w);
        d_pose.view_mut((0, 0), (3, 3)).copy_from(&rr_all);
        d_pose
            .view_mut((3, 3), (3, 3))
            .copy_from(&(jl_inv * rr_all * 1e3));
        // d(exp(d) R x)/dd = -[R x]x, per urad; the orientation through J_l^-1, per urad.
        let sk = (p - rt).cross_matrix() * -1e-6;
        for a in 0..3 {
            d_nuisance[(a, a)] = 1e-3;
        }
        d_nuisance.view_mut((0, 3), (3, 3)).copy_from(&sk);
        d_nuisance
            .view_mut((3, 3), (3, 3))
            .copy_from(&(jl_inv * 1e-3));
    }
}
