//! Point targets: laser-tracker reflectors (SMRs) in nests on the platform, each measured as a
//! 3-D point in the tracker's frame, with no orientation.
//!
//! A point measurement of target `k` at a pose is predicted through the same forward
//! kinematics as every other observation ([`crate::model::predict`]): the platform reaches
//! pose `(R, p)`, the target sits at `b = R (t_k + dt_k) + p` in the base frame (`t_k` its
//! platform position from the description's `[[target]]`, `dt_k` the estimated correction of
//! [`Effect::TargetPosition`], um), and the tracker of session
//! `s` reports `y = R_s b + T_s` ([`Effect::PointFrame`]: 6
//! parameters per session, translation um and rotation vector urad, in the convention of
//! `tracker_frame`). A file is a session: the readers register each file roughly
//! ([`rough_frame`]) and apply that registration to its points; the fit refines the rest.
//!
//! What point targets see: the targets' platform positions and the session frames come with
//! the gauge freedoms of the machine: the base joints moved or rotated together with every
//! session frame (6), the platform joints and every target moved or rotated together in the
//! platform (6), whatever the number of targets. One target does not see the platform's
//! orientation at a pose, yet the 36 joint errors move position and orientation together, so
//! one target leaves no further blind direction: it only knows them less well than three (see
//! the Cramér-Rao bounds of `tests/points.rs`). `patterns` names these directions for the
//! identifiability analysis.
use cpm_geometry::rotation::left_jacobian;
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::model::effects::EffectModel;
use crate::model::instruments::{Instrument, InstrumentInput};
use crate::model::patterns::Pattern;
use crate::{Effect, MeasurementModel};

/// A point target on the platform (`[[target]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointTarget {
    /// Name in the `target` column of point measurement files.
    pub name: String,
    /// Position in the platform frame {P}, mm.
    pub platform_mm: Vector3<f64>,
}

/// The point targets of a model as an [`Instrument`]: a channel per target, three values
/// (x y z in the session's tracker frame, mm) per measurement; nuisance parameters the
/// targets' platform positions (x y z um per target, [`TargetPosition`]) and a tracker frame
/// per session (tx ty tz um, rx ry rz urad, [`PointFrame`]).
///
/// ```
/// use cpm_calib::instruments::Instrument;
/// use cpm_calib::points::{PointTarget, PointTargets};
/// let smr = PointTargets { targets: vec![PointTarget { name: "a".into(),
///                                                      platform_mm: [10.0, 0.0, 0.0].into() }] };
/// assert_eq!((smr.num_values(), smr.num_instrument_params(), smr.num_session_params()), (3, 3, 6));
/// assert_eq!(smr.param_name(4), "session ty");
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct PointTargets {
    /// The targets, in the order of the channels.
    pub targets: Vec<PointTarget>,
}

impl PointTargets {
    /// Target `k`'s position on the platform, mm: nominal plus the correction in `nuisance`.
    fn target(&self, k: usize, nuisance: &[f64]) -> Vector3<f64> {
        self.targets[k].platform_mm
            + Vector3::new(nuisance[3 * k], nuisance[3 * k + 1], nuisance[3 * k + 2]) * 1e-3
    }

    /// The session frame (`p_tracker = R p + t`, t mm) in `nuisance`.
    fn frame<'n>(&self, nuisance: &'n [f64]) -> &'n [f64] {
        &nuisance[3 * self.targets.len()..]
    }
}

impl Instrument for PointTargets {
    fn name(&self) -> &str {
        "point_target"
    }
    fn num_channels(&self) -> usize {
        self.targets.len()
    }
    fn num_values(&self) -> usize {
        3
    }
    fn unit(&self) -> &str {
        "mm"
    }
    fn num_instrument_params(&self) -> usize {
        3 * self.targets.len()
    }
    fn num_session_params(&self) -> usize {
        6
    }
    fn param_name(&self, k: usize) -> String {
        let own = self.num_instrument_params();
        match self.targets.get(k / 3).filter(|_| k < own) {
            Some(t) => format!("target `{}` {}", t.name, AXES[k % 3]),
            None => format!("session {}", FRAME[(k - own) % 6]),
        }
    }
    fn param_unit(&self, k: usize) -> &str {
        let own = self.num_instrument_params();
        if k >= own + 3 {
            "urad"
        } else {
            "um"
        }
    }
    fn predict(&self, input: &InstrumentInput, k: usize, nuisance: &[f64], values: &mut [f64]) {
        let (t, r) = crate::model::effects::tracker_registration(self.frame(nuisance));
        let y = r * input.pose.transform_point(&self.target(k, nuisance)) + t;
        values.copy_from_slice(y.as_slice());
    }
    fn jacobian(
        &self,
        input: &InstrumentInput,
        k: usize,
        nuisance: &[f64],
        d_pose: &mut DMatrix<f64>,
        d_nuisance: &mut DMatrix<f64>,
    ) {
        let pose = input.pose;
        let frame = self.frame(nuisance);
        let (_, r) = crate::model::effects::tracker_registration(frame);
        let rf = r.into_inner();
        let target = self.target(k, nuisance);
        // The pose moved by (dp, dtheta) moves the target by dp - [R t]x dtheta.
        let rt = pose.rotation * target;
        d_pose.view_mut((0, 0), (3, 3)).copy_from(&rf);
        d_pose
            .view_mut((0, 3), (3, 3))
            .copy_from(&(-rf * rt.cross_matrix()));
        let m = rf * pose.rotation.matrix() * 1e-3;
        d_nuisance.view_mut((0, 3 * k), (3, 3)).copy_from(&m);
        let o = self.num_instrument_params();
        let b = pose.transform_point(&target);
        let w = Vector3::new(frame[3], frame[4], frame[5]) * 1e-6;
        // d(exp(w + d) b)/dd = -[exp(w) b]x J_l(w), per urad.
        let m = (r * b).cross_matrix() * left_jacobian(&w) * -1e-6;
        for a in 0..3 {
            d_nuisance[(a, o + a)] = 1e-3;
        }
        d_nuisance.view_mut((0, o + 3), (3, 3)).copy_from(&m);
    }
}

use crate::model::effects::instrument_blocks::{AXES, FRAME};
/// Their effects, defined with the other effects (the effect list dispatches to them).
pub use crate::model::effects::{PointFrame, TargetPosition};

/// The name of parameter `k` of an instrument block, with the model's target names.
pub(crate) fn param_name(model: &MeasurementModel, effect: Effect, k: usize) -> String {
    match effect {
        Effect::TargetPosition => match model.targets.get(k / 3) {
            Some(t) => format!("target `{}` {}", t.name, AXES[k % 3]),
            None => TargetPosition.param_name(k, &[]),
        },
        _ => effect.param_name(k, &[]),
    }
}

/// The rigid frame that takes `base` points onto `tracker` points in the least-squares sense
/// (`tracker ~ R base + t`; Kabsch), or `None` when the points do not fix it (fewer than three,
/// or all on a line).
///
/// ```
/// use cpm_calib::points::rough_frame;
/// use nalgebra::{Rotation3, Vector3};
/// let r = Rotation3::from_euler_angles(0.3, -0.2, 2.0);
/// let t = Vector3::new(1500.0, -300.0, 80.0);
/// let base: Vec<_> = [[0.0, 0.0, 0.0], [100.0, 0.0, 5.0], [0.0, 80.0, -3.0], [40.0, 30.0, 90.0]]
///     .iter().map(|p| Vector3::from(*p)).collect();
/// let tracker: Vec<_> = base.iter().map(|p| r * p + t).collect();
/// let (t2, r2) = rough_frame(&base, &tracker).unwrap();
/// assert!((t2 - t).norm() < 1e-9 && r2.angle_to(&r) < 1e-12);
/// assert!(rough_frame(&base[..2], &tracker[..2]).is_none());
/// ```
pub fn rough_frame(
    base: &[Vector3<f64>],
    tracker: &[Vector3<f64>],
) -> Option<(Vector3<f64>, Rotation3<f64>)> {
    if base.len() != tracker.len() || base.len() < 3 {
        return None;
    }
    let n = base.len() as f64;
    let cb = base.iter().sum::<Vector3<f64>>() / n;
    let ct = tracker.iter().sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    for (b, t) in base.iter().zip(tracker) {
        h += (b - cb) * (t - ct).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    let mut order = [s[0], s[1], s[2]];
    order.sort_by(|a, b| b.total_cmp(a));
    if !(order[0] > 0.0 && order[1] > 1e-9 * order[0]) {
        return None;
    }
    let v = vt.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let r = Rotation3::from_matrix_unchecked(r);
    Some((ct - r * cb, r))
}

/// The blind directions point targets bring, for [`crate::identifiability`]'s words: the
/// base joints moved (rotated) together with every session frame, and the platform joints
/// moved (rotated) together with every target.
pub(crate) fn patterns(model: &MeasurementModel) -> Vec<Pattern> {
    let np = model.num_params();
    let n = model.nominal.num_links();
    let blocks = model.blocks();
    let find = |e: Effect| blocks.iter().find(|b| b.effect == Some(e)).copied();
    let mut out = Vec::new();
    if let Some(b) = find(Effect::PointFrame) {
        let sessions = b.len / 6;
        let trans = (0..3)
            .map(|a| {
                let mut v = DVector::zeros(np);
                for i in 0..n {
                    v[6 * i + a] = 1.0;
                }
                for s in 0..sessions {
                    v[b.offset + 6 * s + a] = -1.0;
                }
                v
            })
            .collect();
        out.push(Pattern {
            description: "all base joints and every session's point frame translated together"
                .into(),
            vectors: trans,
        });
        let rot = (0..3)
            .map(|a| {
                let mut w = Vector3::zeros();
                w[a] = 1.0;
                let mut v = DVector::zeros(np);
                for (i, l) in model.nominal.links.iter().enumerate() {
                    let d = w.cross(&l.base_mm) * 1e-3;
                    for c in 0..3 {
                        v[6 * i + c] = d[c];
                    }
                }
                for s in 0..sessions {
                    v[b.offset + 6 * s + 3 + a] = -1.0;
                }
                v
            })
            .collect();
        out.push(Pattern {
            description:
                "all base joints and every session's point frame rotated together about the base origin"
                    .into(),
            vectors: rot,
        });
    }
    if let Some(b) = find(Effect::TargetPosition) {
        let trans = (0..3)
            .map(|a| {
                let mut v = DVector::zeros(np);
                for i in 0..n {
                    v[6 * i + 3 + a] = 1.0;
                }
                for k in 0..b.len / 3 {
                    v[b.offset + 3 * k + a] = 1.0;
                }
                v
            })
            .collect();
        out.push(Pattern {
            description: "all platform joints and every target translated together".into(),
            vectors: trans,
        });
        let rot = (0..3)
            .map(|a| {
                let mut w = Vector3::zeros();
                w[a] = 1.0;
                let mut v = DVector::zeros(np);
                for (i, l) in model.nominal.links.iter().enumerate() {
                    let d = w.cross(&l.platform_mm);
                    for c in 0..3 {
                        v[6 * i + 3 + c] = d[c];
                    }
                }
                for (k, t) in model.targets.iter().enumerate().take(b.len / 3) {
                    let d = w.cross(&t.platform_mm);
                    for c in 0..3 {
                        v[b.offset + 3 * k + c] = d[c];
                    }
                }
                v
            })
            .collect();
        out.push(Pattern {
            description:
                "all platform joints and every target rotated together about the platform origin"
                    .into(),
            vectors: rot,
        });
    }
    out
}
