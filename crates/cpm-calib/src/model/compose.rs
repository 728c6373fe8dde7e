//! How the measurement model composes the effects' channels into a prediction and its Jacobian
//! (see [`crate::model::effects::Channel`]): the link channel changes the lengths forward kinematics
//! closes on, the platform pose channel moves the pose forward kinematics found, the socket
//! channel moves the sensors (applied to the joint table), the sensor channel maps the geometric
//! length to the reading, and the tracker frame channel maps the pose into the tracker's frame.
//! The instruments ([`crate::instruments`]: point targets, inclinometers, one's own) see the
//! pose forward kinematics reached, bound to their nuisance parameters' blocks.
use cpm_geometry::rotation::left_jacobian;
use cpm_geometry::{JointTable, Pose, Sensor};
use cpm_kinematics::{KinematicsError, LinkState};
use nalgebra::{DMatrix, Matrix3, Matrix6, Rotation3, Vector3, Vector6};

use crate::model::effects::{Channel, EffectInput, EffectModel};
use crate::model::instruments::{Bound, TrackerPoses};
use crate::model::points::PointTargets;
use crate::model::tilts::Inclinometers;
use crate::{CalibError, Effect, MeasurementModel};

/// One block of estimated (or known) values acting through a channel.
#[derive(Clone, Copy)]
struct Active<'a> {
    model: &'static dyn EffectModel,
    offset: usize,
    values: &'a [f64],
}

/// The effects of a model at a parameter vector, sorted by channel.
pub(crate) struct Channels<'a> {
    link: Vec<Active<'a>>,
    sensor: Vec<Active<'a>>,
    socket: Vec<Active<'a>>,
    pose: Vec<Active<'a>>,
    known_pose: Vec<Active<'a>>,
    /// Tracker poses (with the known registration) and the block of the estimated frames
    /// (one per session with a frame of its own, else one).
    tracker: TrackerPoses,
    tracker_block: Option<(usize, &'a [f64])>,
    /// The block of the estimated marker frame (`marker_frame`), when estimated.
    marker_block: Option<(usize, &'a [f64])>,
    sensor_gain: Vec<f64>,
    sensor_offset_mm: Vec<f64>,
    sensor_corr: f64,
    /// Point targets and the blocks of their positions and session frames.
    targets: PointTargets,
    target_blocks: Blocks<'a>,
    /// Inclinometers and the blocks of their mounts and base tilts.
    inclinometers: Inclinometers,
    inclinometer_blocks: Blocks<'a>,
    /// One's own instruments, bound to their blocks.
    instruments: Vec<Bound<'a>>,
    /// Gravity's up in the base frame.
    pub up: Vector3<f64>,
}

/// Where an instrument's per-instrument and per-session parameters sit (offset, values).
type Blocks<'a> = (Option<(usize, &'a [f64])>, Option<(usize, &'a [f64])>);

/// What the channels make of one pose: link coefficients and lengths, the pose twist.
pub(crate) struct AtPose {
    /// Link-channel coefficients per link: (parameter, mm per unit).
    coeff: Vec<Vec<(usize, f64)>>,
    /// Effective lengths with the estimated link effects, mm.
    pub lengths: Vec<f64>,
    /// Platform pose twist (mm, rad), known and estimated.
    pub twist: Vector6<f64>,
    /// Pose-channel columns: (parameter, twist per unit).
    pose_cols: Vec<(usize, Vector6<f64>)>,
}

impl AtPose {
    pub fn new(links: usize) -> Self {
        Self {
            coeff: vec![Vec::new(); links],
            lengths: vec![0.0; links],
            twist: Vector6::zeros(),
            pose_cols: Vec::new(),
        }
    }
}

/// The kinematic derivatives at the pose forward kinematics found.
pub(crate) struct Kin {
    links: Vec<LinkState>,
    j1: Matrix6<f64>,
    /// LU of J1^T, for `v = J1^-T g` of every reading at the pose.
    lu_t: cpm_kinematics::lu6::Lu6,
    rt: Matrix3<f64>,
    /// exp(twist) and the left Jacobian of SO(3) at the twist's rotation.
    e: Matrix3<f64>,
    jl: Matrix3<f64>,
    moved: bool,
    pose: usize,
}

impl Kin {
    pub fn new(table: &JointTable, fk: &Pose, at: &AtPose, pose: usize) -> Self {
        let links = cpm_kinematics::inverse(table, fk);
        let mut j1 = Matrix6::zeros();
        for (i, ls) in links.iter().enumerate() {
            let m = ls.s_mm.cross(&ls.unit);
            j1.set_row(
                i,
                &Vector6::new(ls.unit.x, ls.unit.y, ls.unit.z, m.x, m.y, m.z).transpose(),
            );
        }
        let w = Vector3::new(at.twist[3], at.twist[4], at.twist[5]);
        Self {
            links,
            lu_t: cpm_kinematics::lu6::Lu6::new(&j1.transpose()),
            j1,
            rt: fk.rotation.matrix().transpose(),
            e: *Rotation3::new(w).matrix(),
            jl: left_jacobian(&w),
            moved: at.twist != Vector6::zeros(),
            pose,
        }
    }

    fn singular(&self) -> CalibError {
        CalibError::Kinematics {
            pose: self.pose,
            source: KinematicsError::singular(0, &self.j1),
        }
    }

    /// A pose-channel twist per unit, as a twist of the final pose.
    fn pose_column(&self, c: &Vector6<f64>) -> Vector6<f64> {
        let r = self.jl * Vector3::new(c[3], c[4], c[5]);
        Vector6::new(c[0], c[1], c[2], r.x, r.y, r.z)
    }
}

fn active<'a>(model: &MeasurementModel, params: &'a [f64], channel: Channel) -> Vec<Active<'a>> {
    model
        .blocks()
        .into_iter()
        .filter_map(|b| {
            let e = b.effect?.model();
            e.channels().contains(&channel).then(|| Active {
                model: e,
                offset: b.offset,
                values: &params[b.offset..b.offset + b.len],
            })
        })
        .collect()
}

impl<'a> Channels<'a> {
    pub fn new(model: &'a MeasurementModel, params: &'a [f64]) -> Self {
        let known = |c: Channel| -> Vec<Active<'a>> {
            model
                .known_effects
                .iter()
                .filter(|k| k.effect.acts_through(c))
                .map(|k| Active {
                    model: k.effect.model(),
                    offset: 0,
                    values: &k.values,
                })
                .collect()
        };
        let identity = (Vector3::zeros(), Rotation3::identity());
        let estimated = active(model, params, Channel::TrackerFrame)
            .first()
            .copied();
        let mut tracker = TrackerPoses {
            known: known(Channel::TrackerFrame)
                .first()
                .map_or(identity, |a| a.model.tracker_registration(a.values)),
            ..TrackerPoses::default()
        };
        if let Some(a) = estimated {
            tracker.frame = a.model;
        }
        if let Some(a) = known(Channel::MarkerFrame).first() {
            tracker.marker = crate::model::effects::tracker_registration(a.values);
        }
        let marker_block = active(model, params, Channel::MarkerFrame)
            .first()
            .map(|a| (a.offset, a.values));
        // Known sensor offsets (mm) and gains per sensor; the estimated ones add on top.
        let s = model.nominal.sensors.len();
        let mut sensor_offset_mm = vec![0.0; s];
        let mut sensor_gain = vec![1.0; s];
        for a in known(Channel::SensorReading) {
            for si in 0..s {
                for (k, v) in a.values.iter().enumerate() {
                    let (g, o) = a.model.sensor_coefficients(k, si);
                    sensor_gain[si] += g * v;
                    sensor_offset_mm[si] += o * v;
                }
            }
        }
        let block = |e: Effect| {
            model
                .blocks()
                .into_iter()
                .find(|b| b.effect == Some(e) && params.len() >= b.offset + b.len)
                .map(|b| (b.offset, &params[b.offset..b.offset + b.len]))
        };
        let instruments = model
            .blocks()
            .into_iter()
            .filter_map(|b| {
                let i = b.instrument?;
                let instrument = &*model.instruments[i];
                let own = instrument.num_instrument_params();
                let bound = params.len() >= b.offset + b.len;
                Some(Bound {
                    instrument,
                    own: bound.then(|| (b.offset, &params[b.offset..b.offset + own])),
                    sessions: bound
                        .then(|| (b.offset + own, &params[b.offset + own..b.offset + b.len])),
                })
            })
            .collect();
        Self {
            targets: PointTargets {
                targets: model.targets.clone(),
            },
            target_blocks: (block(Effect::TargetPosition), block(Effect::PointFrame)),
            inclinometers: Inclinometers {
                inclinometers: model.inclinometers.clone(),
            },
            inclinometer_blocks: (block(Effect::InclinometerMount), block(Effect::BaseTilt)),
            instruments,
            up: crate::model::tilts::nominal_up(model),
            link: active(model, params, Channel::LinkLength),
            sensor: active(model, params, Channel::SensorReading),
            socket: active(model, params, Channel::SensorSocket),
            pose: active(model, params, Channel::PlatformPose),
            known_pose: known(Channel::PlatformPose),
            tracker,
            tracker_block: estimated.map(|a| (a.offset, a.values)),
            marker_block,
            sensor_gain,
            sensor_offset_mm,
            sensor_corr: model.sensor_correction_mm(),
        }
    }

    /// Link lengths and coefficients, and the pose twist, at one pose.
    pub fn at_pose(&self, input: &EffectInput, prepared_mm: &[f64], at: &mut AtPose) {
        at.lengths.copy_from_slice(prepared_mm);
        for (i, c) in at.coeff.iter_mut().enumerate() {
            c.clear();
            for b in &self.link {
                for (k, v) in b.values.iter().enumerate() {
                    let a = b.model.link_coefficient(k, i, input);
                    if a != 0.0 {
                        c.push((b.offset + k, a));
                        at.lengths[i] += a * v;
                    }
                }
            }
        }
        at.twist.fill(0.0);
        at.pose_cols.clear();
        for b in &self.known_pose {
            for (k, v) in b.values.iter().enumerate() {
                at.twist += b.model.pose_coefficients(k, input) * *v;
            }
        }
        for b in &self.pose {
            for (k, v) in b.values.iter().enumerate() {
                let c = b.model.pose_coefficients(k, input);
                if c != Vector6::zeros() {
                    at.twist += c * *v;
                    at.pose_cols.push((b.offset + k, c));
                }
            }
        }
    }

    /// The reading of sensor `si` whose geometric length is `geometric` mm.
    pub fn reading(&self, si: usize, geometric: f64) -> f64 {
        let mut y = geometric * self.sensor_gain[si] + self.sensor_offset_mm[si] + self.sensor_corr;
        for b in &self.sensor {
            for (q, v) in b.values.iter().enumerate() {
                let (g, o) = b.model.sensor_coefficients(q, si);
                y += (g * geometric + o) * v;
            }
        }
        y
    }

    /// The tracker instrument of the model (known registration, frame map), measuring the
    /// identity orientation.
    pub fn tracker_poses(&self) -> TrackerPoses {
        self.tracker
    }

    /// The estimated marker frame's parameters (tx ty tz um, rx ry rz urad), zero when it
    /// is not estimated.
    pub fn marker_params(&self) -> [f64; 6] {
        let mut q = [0.0; 6];
        if let Some((_, v)) = self.marker_block {
            q.copy_from_slice(&v[..6]);
        }
        q
    }

    /// A tracker instrument bound to the estimated marker frame and session frames (a
    /// session each: the frame index).
    pub fn tracker<'b>(&'b self, instrument: &'b TrackerPoses) -> Bound<'b> {
        Bound {
            instrument,
            own: self.marker_block,
            sessions: self.tracker_block,
        }
    }

    /// The point targets bound to their blocks.
    pub fn points(&self) -> Bound<'_> {
        Bound {
            instrument: &self.targets,
            own: self.target_blocks.0,
            sessions: self.target_blocks.1,
        }
    }

    /// The inclinometers bound to their blocks.
    pub fn tilts(&self) -> Bound<'_> {
        Bound {
            instrument: &self.inclinometers,
            own: self.inclinometer_blocks.0,
            sessions: self.inclinometer_blocks.1,
        }
    }

    /// The inclinometer channel of a tilt measurement.
    pub fn tilt_channel(&self, t: &crate::TiltMeasurement) -> usize {
        self.inclinometers.channel(t.inclinometer, t.axis)
    }

    /// One's own instrument `i` ([`MeasurementModel::instruments`]) bound to its block.
    pub fn instrument(&self, i: usize) -> &Bound<'a> {
        &self.instruments[i]
    }

    /// The Jacobian row (mm per unit) of a reading of `sensor` (index `si`) at `pose`.
    pub fn reading_row(
        &self,
        kin: &Kin,
        at: &AtPose,
        sensor: &Sensor,
        si: usize,
        pose: &Pose,
        row: &mut [f64],
    ) -> Result<(), CalibError> {
        let g = cpm_kinematics::sensor_pose_gradient(sensor, pose);
        // The gradient with respect to the pose forward kinematics found.
        let g_fk = if kin.moved {
            let w = kin.e.transpose() * Vector3::new(g[3], g[4], g[5]);
            Vector6::new(g[0], g[1], g[2], w.x, w.y, w.z)
        } else {
            g
        };
        let v = kin.lu_t.solve(&g_fk).ok_or_else(|| kin.singular())?;
        row.fill(0.0);
        // dy/de = -v^T J2, J2 row i: [-z_i^T, (R^T z_i)^T] in the columns of link i.
        for (i, ls) in kin.links.iter().enumerate() {
            let zp = kin.rt * ls.unit;
            for a in 0..3 {
                row[6 * i + a] = v[i] * ls.unit[a] * 1e-3;
                row[6 * i + 3 + a] = -v[i] * zp[a] * 1e-3;
            }
            for &(p, a) in &at.coeff[i] {
                row[p] += v[i] * a;
            }
        }
        if !self.socket.is_empty() {
            // Sockets move the reading directly, not the closure.
            let q = pose.transform_point(&sensor.platform_mm) - sensor.base_mm;
            let u = q / q.norm();
            let up = pose.rotation.matrix().transpose() * u;
            for b in &self.socket {
                for k in 0..b.values.len() {
                    let (db, dp) = b.model.socket_coefficients(k, si);
                    if db != Vector3::zeros() || dp != Vector3::zeros() {
                        row[b.offset + k] += -u.dot(&db) + up.dot(&dp);
                    }
                }
            }
        }
        for (p, c) in &at.pose_cols {
            row[*p] += g.dot(&kin.pose_column(c));
        }
        // Everything so far moves the geometric length, which the sensor's gain multiplies.
        let mut gain = self.sensor_gain[si];
        let mut est = 0.0;
        for b in &self.sensor {
            for (q, v) in b.values.iter().enumerate() {
                est += b.model.sensor_coefficients(q, si).0 * v;
            }
        }
        gain += est;
        if gain != 1.0 {
            row.iter_mut().for_each(|v| *v *= gain);
        }
        let geometric = sensor.length_mm(pose);
        for b in &self.sensor {
            for q in 0..b.values.len() {
                let (g, o) = b.model.sensor_coefficients(q, si);
                row[b.offset + q] += g * geometric + o;
            }
        }
        Ok(())
    }

    /// The final pose's twist per parameter (6 x np): `J1^-1 (dL/dp - J2 de/dp)` moved by the
    /// pose channel, plus the pose channel's own columns.
    pub fn twist_columns(
        &self,
        kin: &Kin,
        at: &AtPose,
        np: usize,
    ) -> Result<DMatrix<f64>, CalibError> {
        let n = kin.links.len();
        // dx = -J1^-1 J2 de: the right-hand sides are sparse (an installation error touches
        // one link, an effect's coefficient one link each), so each column is a column of
        // J1^-1 scaled, summed over the links it touches.
        let inv = cpm_kinematics::lu6::try_inverse6(&kin.j1).ok_or_else(|| kin.singular())?;
        let mut dx = DMatrix::zeros(6, np);
        for p in 0..(6 * n).min(np) {
            let (i, a) = (p / 6, p % 6);
            let ls = &kin.links[i];
            // J2 entry per um: base -z, platform R^T z.
            let v = if a < 3 {
                ls.unit[a]
            } else {
                -(kin.rt * ls.unit)[a - 3]
            } * 1e-3;
            dx.set_column(p, &(inv.column(i) * v));
        }
        for (i, c) in at.coeff.iter().enumerate() {
            for &(q, a) in c {
                if q < np {
                    let col = inv.column(i) * a;
                    let mut d = dx.column_mut(q);
                    d += col;
                }
            }
        }
        if kin.moved {
            let bottom = kin.e * dx.rows(3, 3);
            dx.rows_mut(3, 3).copy_from(&bottom);
        }
        for (p, c) in &at.pose_cols {
            let col = kin.pose_column(c);
            for a in 0..6 {
                dx[(a, *p)] += col[a];
            }
        }
        Ok(dx)
    }
}
