//! Open instruments: a measurement channel is a type implementing [`Instrument`], as an effect
//! is a type implementing [`EffectModel`](crate::model::effects::EffectModel).
//!
//! An instrument predicts the values one measurement gives from the platform pose forward
//! kinematics reached (with the candidate joints and every effect) and its own nuisance
//! parameters: some per instrument (a target's position on the platform, a mount), some per
//! session (a tracker frame, the base's levelling). It gives the Jacobian of those values with
//! respect to a twist of the reached pose (6 columns: translation mm, rotation rad, base frame,
//! `R -> exp(dtheta) R`, `p -> p + dp`) and with respect to its nuisance parameters; the
//! measurement model supplies the joint errors' and the effects' columns by the kinematic
//! chain rule ([`crate::model::predict`]), so one prediction path serves the fit
//! ([`crate::identify()`]), the identifiability analysis and cross-validation.
//!
//! The built-in tracker poses ([`TrackerPoses`]), point targets
//! ([`PointTargets`](crate::model::points::PointTargets)) and inclinometers
//! ([`Inclinometers`](crate::model::tilts::Inclinometers)) are implementations; the model binds their
//! nuisance parameters to the effect blocks that estimate them (`tracker_frame`,
//! `target_position`, `point_frame`, `inclinometer_mount`, `base_tilt`). A tracker pose's
//! orientation is observed as the rotation from the measured to the predicted orientation, so
//! its instrument holds the measured orientation (one per measurement), and rows lacking
//! components ([`Campaign::unmeasured`](crate::Campaign::unmeasured)) keep the rest. The length-gauge reading stays apart: it
//! is not a function of the reached pose alone (the sensor sockets move it directly, and the
//! sensor channel's gain and offset act on it), so it keeps its own row in `compose.rs`.
//!
//! One's own instrument goes into [`MeasurementModel::instruments`](crate::MeasurementModel::instruments); its measurements into
//! [`Campaign::instrument_measurements`](crate::Campaign::instrument_measurements). Its nuisance parameters are estimated (one block per
//! instrument after the effects' blocks: the per-instrument ones, then the per-session ones of
//! each of [`MeasurementModel::instrument_sessions`](crate::MeasurementModel::instrument_sessions) sessions), in the instrument's own units.
//!
//! Here a laser distance sensor: each of its beams runs from a fixed point on the base to a
//! reflector on the platform, and reads that distance with an unknown zero offset per beam.
//!
//! ```
//! use std::sync::Arc;
//! use cpm_calib::instruments::{Instrument, InstrumentInput};
//! use cpm_calib::simulate::simulate_instruments;
//! use cpm_calib::{paper::random_workspace_poses, *};
//! use nalgebra::{DMatrix, Vector3};
//!
//! /// Beams from base points to platform points (mm); one zero offset per beam, um.
//! #[derive(Debug)]
//! struct Laser { beams: Vec<(Vector3<f64>, Vector3<f64>)> }
//! impl Laser {
//!     fn beam(&self, input: &InstrumentInput, beam: usize) -> (Vector3<f64>, Vector3<f64>) {
//!         let (base, platform) = self.beams[beam];
//!         let rp = input.pose.rotation * platform;
//!         (rp, rp + input.pose.position_mm - base) // (R p, the beam)
//!     }
//! }
//! impl Instrument for Laser {
//!     fn name(&self) -> &str { "laser" }
//!     fn num_channels(&self) -> usize { self.beams.len() }
//!     fn num_values(&self) -> usize { 1 }
//!     fn unit(&self) -> &str { "mm" }
//!     fn num_instrument_params(&self) -> usize { self.beams.len() }
//!     fn predict(&self, input: &InstrumentInput, beam: usize, nuisance: &[f64], y: &mut [f64]) {
//!         y[0] = self.beam(input, beam).1.norm() + nuisance[beam] * 1e-3;
//!     }
//!     fn jacobian(&self, input: &InstrumentInput, beam: usize, _: &[f64],
//!                 d_pose: &mut DMatrix<f64>, d_nuisance: &mut DMatrix<f64>) {
//!         let (rp, d) = self.beam(input, beam);
//!         let (u, w) = (d.normalize(), rp.cross(&d.normalize()));
//!         for a in 0..3 { d_pose[(0, a)] = u[a]; d_pose[(0, 3 + a)] = w[a]; }
//!         d_nuisance[(0, beam)] = 1e-3;
//!     }
//! }
//!
//! let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
//! model.nominal.sensors = paper::designed_sensors();
//! let beams = [([900.0, 0.0, 0.0], [100.0, 0.0, 0.0]), ([0.0, 900.0, 0.0], [0.0, 100.0, 0.0]),
//!              ([0.0, 0.0, -600.0], [0.0, 0.0, 0.0])];
//! let beams = beams.iter().map(|(b, p)| (Vector3::from(*b), Vector3::from(*p))).collect();
//! model.instruments = vec![Arc::new(Laser { beams })];
//! let poses = random_workspace_poses(&model.nominal, 40, 80.0, 20.0, 3.0, 5);
//! let mut skeleton = Plan { poses, sensors: (0..16).collect() }.skeleton();
//! for (pose, beam) in (0..40).flat_map(|j| (0..3).map(move |b| (j, b))) {
//!     skeleton.instrument_measurements.push(InstrumentMeasurement {
//!         pose, instrument: 0, channel: beam, session: 0, values: vec![0.0], sigma: 0.002 });
//! }
//! let truth = [vec![0.0; 36], vec![150.0, -80.0, 40.0]].concat(); // offsets, um
//! let sim = SimulationOptions { noise: Noise::Gaussian { sigma_um: 2.0 }, ..Default::default() };
//! let data = simulate_instruments(&model, &truth, &skeleton, &sim).unwrap();
//! let options = IdentifyOptions { sigma_um: Some(2.0), ..IdentifyOptions::default() };
//! let cal = identify(&model, &data, &options).unwrap();
//! for (k, t) in [150.0, -80.0, 40.0].iter().enumerate() {
//!     let (est, std) = (cal.estimate_um[36 + k].unwrap(), cal.std_um[36 + k].unwrap());
//!     assert!((est - t).abs() < 4.0 * std && std < 5.0, "beam {k}: {est} +- {std} um");
//! }
//! ```
use std::fmt::Debug;

use cpm_geometry::Pose;
use nalgebra::{DMatrix, Vector3};

use crate::model::effects::EffectInput;
use crate::model::JacobianRows;

mod tracker;

pub use tracker::TrackerPoses;

/// What an instrument may know about a pose.
#[derive(Debug, Clone, Copy)]
pub struct InstrumentInput<'a> {
    /// The platform pose reached: forward kinematics with the candidate joints, moved by the
    /// platform pose channel; base frame, mm.
    pub pose: &'a Pose,
    /// What the effects know of the pose: the commanded pose, commanded lengths, link forces,
    /// temperature, time.
    pub effect: EffectInput<'a>,
    /// Gravity's up in the base frame (unit): minus the model's load gravity, normalised.
    pub up: Vector3<f64>,
}

/// A measurement channel: the values one measurement gives at a pose, given the instrument's
/// nuisance parameters, and their Jacobian.
///
/// `nuisance` is the instrument's parameters (the [`num_instrument_params`] of the instrument,
/// then the [`num_session_params`] of the measurement's session), in the units
/// [`param_unit`] names; `d_pose` (values x 6) and `d_nuisance` (values x nuisance) come zeroed
/// and are filled with the derivatives per unit of the values' [`unit`].
///
/// [`num_instrument_params`]: Instrument::num_instrument_params
/// [`num_session_params`]: Instrument::num_session_params
/// [`param_unit`]: Instrument::param_unit
/// [`unit`]: Instrument::unit
pub trait Instrument: Debug + Send + Sync {
    /// Name in reports (lower case, no spaces).
    fn name(&self) -> &str;
    /// Number of channels (targets, axes, beams) a measurement may be of. Default 1.
    fn num_channels(&self) -> usize {
        1
    }
    /// Number of values one measurement gives.
    fn num_values(&self) -> usize;
    /// Unit of the values (the measurements' values and their `sigma` are in it).
    fn unit(&self) -> &str;
    /// Number of nuisance parameters of the instrument (estimated once). Default 0.
    fn num_instrument_params(&self) -> usize {
        0
    }
    /// Number of nuisance parameters per session (estimated once per session). Default 0.
    fn num_session_params(&self) -> usize {
        0
    }
    /// Name of nuisance parameter `k` (the instrument's first, then one session's). Default
    /// `instrument k` / `session k`.
    fn param_name(&self, k: usize) -> String {
        let own = self.num_instrument_params();
        if k < own {
            format!("instrument {}", k + 1)
        } else {
            format!("session {}", k - own + 1)
        }
    }
    /// Unit of nuisance parameter `k`. Default `um`.
    fn param_unit(&self, _k: usize) -> &str {
        "um"
    }
    /// The values a measurement of `channel` gives at `input`'s pose.
    fn predict(
        &self,
        input: &InstrumentInput,
        channel: usize,
        nuisance: &[f64],
        values: &mut [f64],
    );
    /// Their derivatives: `d_pose` with respect to a twist of the reached pose (translation mm,
    /// rotation rad, base frame), `d_nuisance` with respect to the nuisance parameters.
    fn jacobian(
        &self,
        input: &InstrumentInput,
        channel: usize,
        nuisance: &[f64],
        d_pose: &mut DMatrix<f64>,
        d_nuisance: &mut DMatrix<f64>,
    );
}

/// Two instruments are equal when they have the same name and the same debug rendering (their
/// data): what a model's equality needs.
impl PartialEq for dyn Instrument {
    fn eq(&self, other: &Self) -> bool {
        self.name() == other.name() && format!("{self:?}") == format!("{other:?}")
    }
}

/// An instrument bound to a parameter vector: where its nuisance parameters sit (none when
/// they are not estimated: zero).
pub(crate) struct Bound<'a> {
    pub instrument: &'a dyn Instrument,
    /// Offset and values of the per-instrument parameters.
    pub own: Option<(usize, &'a [f64])>,
    /// Offset and values of the per-session parameters (every session's, in order).
    pub sessions: Option<(usize, &'a [f64])>,
}

impl Bound<'_> {
    fn nuisance(&self, session: usize) -> Vec<f64> {
        let (p, q) = (
            self.instrument.num_instrument_params(),
            self.instrument.num_session_params(),
        );
        let mut v = vec![0.0; p + q];
        if let Some((_, own)) = self.own {
            v[..p].copy_from_slice(&own[..p]);
        }
        if let Some((_, s)) = self.sessions {
            v[p..].copy_from_slice(&s[q * session..q * session + q]);
        }
        v
    }

    /// The measurement's values at `input`, into `values`.
    pub fn predict(
        &self,
        input: &InstrumentInput,
        channel: usize,
        session: usize,
        values: &mut [f64],
    ) {
        self.instrument
            .predict(input, channel, &self.nuisance(session), values);
    }

    /// The measurement's Jacobian rows from `row0` (per unit of the parameters): the pose
    /// derivatives through `dx` (the reached pose's twist per parameter, 6 x np), the
    /// nuisance derivatives in their blocks' columns; each row made in `row` (np values,
    /// the caller's) and written whole into `jac`.
    pub fn rows(
        &self,
        input: &InstrumentInput,
        channel: usize,
        session: usize,
        dx: &DMatrix<f64>,
        jac: &mut dyn JacobianRows,
        row0: usize,
        row: &mut [f64],
    ) {
        let m = self.instrument.num_values();
        let rows: [Option<usize>; 8] = std::array::from_fn(|a| (a < m).then_some(row0 + a));
        if m <= rows.len() {
            self.rows_at(input, channel, session, dx, jac, &rows[..m], row);
        } else {
            let rows: Vec<Option<usize>> = (row0..row0 + m).map(Some).collect();
            self.rows_at(input, channel, session, dx, jac, &rows, row);
        }
    }

    /// [`rows`](Self::rows) with value `a` at row `at[a]`, none where it was not measured.
    #[allow(clippy::too_many_arguments)]
    pub fn rows_at(
        &self,
        input: &InstrumentInput,
        channel: usize,
        session: usize,
        dx: &DMatrix<f64>,
        jac: &mut dyn JacobianRows,
        at: &[Option<usize>],
        row: &mut [f64],
    ) {
        let m = self.instrument.num_values();
        let (p, q) = (
            self.instrument.num_instrument_params(),
            self.instrument.num_session_params(),
        );
        let mut d_pose = DMatrix::zeros(m, 6);
        let mut d_nuisance = DMatrix::zeros(m, p + q);
        self.instrument.jacobian(
            input,
            channel,
            &self.nuisance(session),
            &mut d_pose,
            &mut d_nuisance,
        );
        let rows = (m > 5).then(|| &d_pose * dx);
        for (a, r) in at.iter().enumerate() {
            let Some(r) = *r else { continue };
            if let Some(rows) = &rows {
                row.iter_mut()
                    .zip(rows.row(a).iter())
                    .for_each(|(x, v)| *x = *v);
            } else {
                // Row `a` of `d_pose * dx`, made here: a measurement of one to five values
                // (an angle, a point), where a general product of such thin matrices spends
                // its time in loop overhead. The sums run in the order of nalgebra's product
                // for these sizes (column by column): the same bits.
                let d: [f64; 6] = std::array::from_fn(|k| d_pose[(a, k)]);
                // `dx` is 6 x np, column-major: its columns are the chunks of six.
                debug_assert_eq!(dx.nrows(), 6);
                for (x, c) in row.iter_mut().zip(dx.as_slice().chunks_exact(6)) {
                    let mut s = d[0] * c[0];
                    s += d[1] * c[1];
                    s += d[2] * c[2];
                    s += d[3] * c[3];
                    s += d[4] * c[4];
                    s += d[5] * c[5];
                    *x = s;
                }
            }
            for c in 0..p + q {
                let col = if c < p {
                    self.own.map(|(o, _)| o + c)
                } else {
                    self.sessions.map(|(o, _)| o + q * session + c - p)
                };
                if let Some(col) = col {
                    row[col] += d_nuisance[(a, c)];
                }
            }
            jac.set_row(r, row);
        }
    }
}
