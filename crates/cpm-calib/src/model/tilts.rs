//! Inclinometers: a two-axis (or one- or three-axis) inclinometer on the platform measures,
//! per axis, the elevation of that axis above the horizontal, `asin(up . a_k)`: what MEMS
//! inclinometers such as the SCL3300 report.
//!
//! A tilt measurement is predicted through the same forward kinematics as every other
//! observation ([`crate::model::predict`]): the platform reaches orientation `R`, the
//! instrument's axis `k` points along `a_k = R M n_k` in the base frame (`n_k` the platform
//! direction the description's `[[inclinometer]]` declares for it, `M` the mount rotation of
//! [`Effect::InclinometerMount`], 3 parameters per instrument,
//! urad, on top of the description's `mount_rpy_deg`), and gravity's up is
//! `u = exp(b) u_0` (`u_0` minus the description's `[load] gravity_mm_s2`, normalised; `b` the
//! base tilt of [`Effect::BaseTilt`], about x and y, 2 parameters per
//! session, urad: a machine is re-levelled between sessions). The observation is
//! `asin(u . a_k)` in mrad. An instrument that reports `atan2` angles of the gravity vector
//! in its own frame (some do, for two axes) differs from `asin` at second order in the other
//! axis's tilt: convert such angles to `asin(g_k / |g|)` before writing the file.
//!
//! What tilts cannot see, whatever the campaign: any position error (only orientation
//! reaches an inclinometer), the platform's rotation about the vertical (yaw), and so the
//! mount's rotation about the instrument's normal at level poses; the base tilt of a session
//! trades against the mount's rotation about x and y wherever the platform keeps its yaw
//! (that combination is named by `patterns`). The identifiability analysis names the rest.
use nalgebra::{DMatrix, DVector, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::model::instruments::{Instrument, InstrumentInput};
use crate::model::patterns::Pattern;
use crate::{Effect, MeasurementModel};
use cpm_geometry::rotation::left_jacobian;

/// An inclinometer on the platform (`[[inclinometer]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Inclinometer {
    /// Name in the `inclinometer` column of tilt files.
    pub name: String,
    /// The platform direction (unit) of each measured axis, in {P}, before the mount
    /// rotation.
    pub axes: Vec<Vector3<f64>>,
    /// The known mount rotation (the description's `mount_rpy_deg`).
    pub mount: Rotation3<f64>,
}

impl Inclinometer {
    /// The instrument a description's `[[inclinometer]]` declares (axes normalised).
    pub fn from_spec(spec: &cpm_geometry::description::InclinometerSpec) -> Self {
        let [r, p, y] = spec.mount_rpy_deg.map(f64::to_radians);
        Self {
            name: spec.name.clone(),
            axes: spec
                .axes
                .iter()
                .map(|a| Vector3::from(*a).normalize())
                .collect(),
            mount: cpm_geometry::rotation::from_rpy(r, p, y),
        }
    }
}

/// The inclinometers of a model as an [`Instrument`]: a channel per axis of each instrument
/// (the first instrument's axes, then the second's, ...: [`channel`](Self::channel)), one
/// value (the angle, mrad) per measurement; nuisance parameters the mounts (rx ry rz urad per
/// instrument, [`InclinometerMount`]) and the base tilt per session (rx ry urad,
/// [`BaseTilt`]).
///
/// ```
/// use cpm_calib::instruments::Instrument;
/// use cpm_calib::tilts::{Inclinometer, Inclinometers};
/// use nalgebra::{Rotation3, Vector3};
/// let two_axes = Inclinometer { name: "scl".into(), axes: vec![Vector3::y(), -Vector3::x()],
///                               mount: Rotation3::identity() };
/// let c = Inclinometers { inclinometers: vec![two_axes.clone(), two_axes] };
/// assert_eq!((c.num_channels(), c.channel(1, 1)), (4, 3));
/// assert_eq!((c.num_instrument_params(), c.num_session_params()), (6, 2));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Inclinometers {
    /// The instruments.
    pub inclinometers: Vec<Inclinometer>,
}

impl Inclinometers {
    /// The channel of axis `axis` of inclinometer `i`.
    pub fn channel(&self, i: usize, axis: usize) -> usize {
        self.inclinometers[..i]
            .iter()
            .map(|c| c.axes.len())
            .sum::<usize>()
            + axis
    }

    /// The inclinometer and axis of a channel.
    fn unflatten(&self, mut channel: usize) -> (usize, usize) {
        for (i, c) in self.inclinometers.iter().enumerate() {
            if channel < c.axes.len() {
                return (i, channel);
            }
            channel -= c.axes.len();
        }
        (self.inclinometers.len(), channel)
    }

    fn at(&self, input: &InstrumentInput, channel: usize, nuisance: &[f64]) -> (usize, TiltAt) {
        let (i, axis) = self.unflatten(channel);
        let c = &self.inclinometers[i];
        let m = Vector3::new(nuisance[3 * i], nuisance[3 * i + 1], nuisance[3 * i + 2]);
        let o = self.num_instrument_params();
        let b = [nuisance[o], nuisance[o + 1]];
        let at = tilt_at(
            &input.up,
            &input.pose.rotation,
            &c.mount,
            &m,
            b,
            &c.axes[axis],
        );
        (i, at)
    }
}

impl Instrument for Inclinometers {
    fn name(&self) -> &str {
        "inclinometer"
    }
    fn num_channels(&self) -> usize {
        self.inclinometers.iter().map(|c| c.axes.len()).sum()
    }
    fn num_values(&self) -> usize {
        1
    }
    fn unit(&self) -> &str {
        "mrad"
    }
    fn num_instrument_params(&self) -> usize {
        3 * self.inclinometers.len()
    }
    fn num_session_params(&self) -> usize {
        2
    }
    fn param_name(&self, k: usize) -> String {
        let own = self.num_instrument_params();
        match self.inclinometers.get(k / 3).filter(|_| k < own) {
            Some(c) => format!("inclinometer `{}` {}", c.name, ROT[k % 3]),
            None => format!("base tilt {}", ROT[(k - own) % 2]),
        }
    }
    fn param_unit(&self, _k: usize) -> &str {
        "urad"
    }
    fn predict(
        &self,
        input: &InstrumentInput,
        channel: usize,
        nuisance: &[f64],
        values: &mut [f64],
    ) {
        values[0] = self.at(input, channel, nuisance).1.angle * 1e3;
    }
    fn jacobian(
        &self,
        input: &InstrumentInput,
        channel: usize,
        nuisance: &[f64],
        d_pose: &mut DMatrix<f64>,
        d_nuisance: &mut DMatrix<f64>,
    ) {
        let (i, at) = self.at(input, channel, nuisance);
        let k = at.slope * 1e3;
        let o = self.num_instrument_params();
        for a in 0..3 {
            d_pose[(0, 3 + a)] = at.pose_rot[a] * k;
            d_nuisance[(0, 3 * i + a)] = at.mount[a] * k;
        }
        for a in 0..2 {
            d_nuisance[(0, o + a)] = at.tilt[a] * k;
        }
    }
}

use crate::model::effects::instrument_blocks::ROT;
/// Their effects, defined with the other effects (the effect list dispatches to them).
pub use crate::model::effects::{BaseTilt, InclinometerMount};

/// The name of parameter `k` of an inclinometer block, with the model's instrument names.
pub(crate) fn param_name(model: &MeasurementModel, effect: Effect, k: usize) -> String {
    match (effect, model.inclinometers.get(k / 3)) {
        (Effect::InclinometerMount, Some(c)) => {
            format!("inclinometer `{}` {}", c.name, ROT[k % 3])
        }
        _ => effect.param_name(k, &[]),
    }
}

/// Gravity's up in the base frame of a model: minus its load's gravity, normalised (+z when
/// the gravity is zero).
pub fn nominal_up(model: &MeasurementModel) -> Vector3<f64> {
    let g = model.load.gravity_mm_s2;
    if g.norm() > 0.0 {
        -g / g.norm()
    } else {
        Vector3::z()
    }
}

/// A tilt prediction's pieces at one pose: the angle (rad) and the derivatives of `u . a`.
struct TiltAt {
    /// `asin(u . a)`, rad.
    pub angle: f64,
    /// `1 / cos(angle)`: d angle / d(u . a).
    pub slope: f64,
    /// `a x u`: d(u . a) / d(platform rotation, base frame).
    pub pose_rot: Vector3<f64>,
    /// d(u . a) / d(mount parameters), per urad.
    pub mount: Vector3<f64>,
    /// d(u . a) / d(base tilt rx, ry), per urad.
    pub tilt: [f64; 2],
}

/// The tilt of axis `n` (platform direction) of an instrument with mount rotation
/// `known * exp(m)` (m in urad), seen at platform orientation `r` with the base tilted by
/// `b` (urad, about x and y) from `up`.
fn tilt_at(
    up: &Vector3<f64>,
    r: &Rotation3<f64>,
    known: &Rotation3<f64>,
    m: &Vector3<f64>,
    b: [f64; 2],
    n: &Vector3<f64>,
) -> TiltAt {
    let mw = m * 1e-6;
    let bw = Vector3::new(b[0], b[1], 0.0) * 1e-6;
    let u = Rotation3::new(bw) * up;
    let am = known * (Rotation3::new(mw) * n);
    let a = r * am;
    let s = u.dot(&a).clamp(-1.0, 1.0);
    let angle = s.asin();
    let slope = 1.0 / (1.0 - s * s).max(1e-300).sqrt();
    // Mount: exp(m + d) = exp(J_l(m) d) exp(m), applied before the known mount.
    let rk = (r * known).into_inner();
    let ur = rk.transpose() * u;
    let nm = Rotation3::new(mw) * n;
    let mount = (left_jacobian(&mw).transpose() * nm.cross(&ur)) * 1e-6;
    let dt = left_jacobian(&bw).transpose() * u.cross(&a) * 1e-6;
    TiltAt {
        angle,
        slope,
        pose_rot: a.cross(&u),
        mount,
        tilt: [dt.x, dt.y],
    }
}

/// The blind directions inclinometers bring, for [`crate::identifiability`]'s words: each
/// instrument's mount rotated about its normal (the cross product of its first two axes; at
/// level poses no axis leaves the horizontal), the base joints rotated about the vertical
/// (yaw), and the base tilt of every session traded against the mounts' rotation about x and
/// y.
pub(crate) fn patterns(model: &MeasurementModel) -> Vec<Pattern> {
    let np = model.num_params();
    let blocks = model.blocks();
    let find = |e: Effect| blocks.iter().find(|b| b.effect == Some(e)).copied();
    let mut out = Vec::new();
    let Some(mb) = find(Effect::InclinometerMount) else {
        return out;
    };
    for (i, c) in model.inclinometers.iter().enumerate() {
        if c.axes.len() >= 2 {
            let normal = c.axes[0].cross(&c.axes[1]);
            if normal.norm() > 1e-9 {
                let mut v = DVector::zeros(np);
                for a in 0..3 {
                    v[mb.offset + 3 * i + a] = normal[a];
                }
                out.push(Pattern {
                    description: format!(
                        "inclinometer `{}` rotated about its normal on the platform (no axis leaves the horizontal)",
                        c.name
                    ),
                    vectors: vec![v],
                });
            }
        }
    }
    // The platform's rotation about the vertical (yaw) reaches no inclinometer: the base
    // joints rotated together about the vertical turn the platform so.
    let up = nominal_up(model);
    let mut v = DVector::zeros(np);
    for (i, l) in model.nominal.links.iter().enumerate() {
        let d = up.cross(&l.base_mm);
        for c in 0..3 {
            v[6 * i + c] = d[c];
        }
    }
    out.push(Pattern {
        description:
            "all base joints rotated together about the vertical (the platform's yaw: no inclinometer sees it)"
                .into(),
        vectors: vec![v],
    });
    if let Some(tb) = find(Effect::BaseTilt) {
        let vectors = (0..2)
            .map(|a| {
                let mut v = DVector::zeros(np);
                for i in 0..model.inclinometers.len() {
                    v[mb.offset + 3 * i + a] = 1.0;
                }
                for s in 0..tb.len / 2 {
                    v[tb.offset + 2 * s + a] = 1.0;
                }
                v
            })
            .collect();
        out.push(Pattern {
            description:
                "every session's base tilt and every inclinometer's mount rotated together about x and y"
                    .into(),
            vectors,
        });
    }
    out
}
