//! The measurement model: commanded pose -> commanded link lengths -> clearance-corrected
//! effective lengths -> forward kinematics with the candidate joints -> sensor socket distance.
//!
//! Parameters are the installation errors in micrometres (order of
//! [`cpm_geometry::errors`]) followed by the parameters of the declared [`Effect`]s, block by
//! block. The Jacobian comes from implicit differentiation of the closure `l(x, e) = L`:
//! `J1 dx = dL - J2 de`, so a reading `y = |t + R p_s - b_s|` with sensor pose gradient `g`
//! and `v = J1^-T g` has `dy/de = -v^T J2` and `dy/dL = v^T`.
use cpm_clearance::{ClearanceModel, Load};
use cpm_geometry::{InstallationErrors, JointTable, Pose};
use cpm_kinematics::{forward, ForwardOptions};
use nalgebra::{DMatrix, Matrix6, Vector6};

use crate::effects::{
    is_link_effect, link_coefficient, sensor_coefficient, tracker_registration, Effect,
    EffectSettings, KnownEffect, PoseContext,
};
use crate::{CalibError, Campaign};

/// Exact (nested forward kinematics) or the paper's first-order model (eq. 12/15).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ModelKind {
    /// Forward kinematics with the candidate joint table at every pose (default).
    #[default]
    Exact,
    /// `y = y_nominal + g^T dx` with `dx = -J1^-1 J2 e` at the commanded pose (eq. 12, 15):
    /// linear in the errors, exact only to first order.
    FirstOrder,
}

/// The measurement model of a machine: nominal geometry, clearance and load.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementModel {
    /// Nominal joint table (with sensors and home pose).
    pub nominal: JointTable,
    /// Joint clearance. Default: the paper's 10 um, hard sign rule.
    pub clearance: ClearanceModel,
    /// Platform load for the link force directions.
    pub load: Load,
    /// Spring preload of the length sensor: -1 compression (default), +1 tension, 0 none.
    pub sensor_preload_sign: f64,
    /// Exact or first-order.
    pub kind: ModelKind,
    /// Forward kinematics options.
    pub fk: ForwardOptions,
    /// Effects modelled beside the installation errors, in parameter order. Default none.
    pub effects: Vec<Effect>,
    /// Settings of the effects.
    pub effect_settings: EffectSettings,
    /// Known effect values (a previous calibration): applied in every prediction and never
    /// estimated. An effect may be known and in [`effects`](Self::effects) at once; its
    /// parameters are then corrections on top of the known values. Default none.
    pub known_effects: Vec<KnownEffect>,
}

/// Where a block of parameters sits in the parameter vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block {
    /// The effect (`None` for the installation errors).
    pub effect: Option<Effect>,
    /// First index.
    pub offset: usize,
    /// Number of parameters.
    pub len: usize,
}

impl MeasurementModel {
    /// The model of a nominal table with the paper's example clearance and load: the same as
    /// [`with_paper_clearance`](Self::with_paper_clearance), which says so in its name.
    ///
    /// It assumes a 10 um clearance at every joint (hard sign rule) and a 20 kg platform with
    /// its centre of mass 100 mm below the platform frame. For one's own machine use
    /// [`from_description`](Self::from_description) (the clearance and load its description
    /// declares), or set [`clearance`](Self::clearance) and [`load`](Self::load).
    pub fn new(nominal: JointTable) -> Self {
        Self::with_paper_clearance(nominal)
    }

    /// The model of a nominal table with the paper's example clearance and load: a 10 um
    /// clearance at every joint with the paper's hard sign rule ([`ClearanceModel::default`]),
    /// the assumed 20 kg platform load ([`Load::default`]), exact forward kinematics, no
    /// effects beside the installation errors.
    ///
    /// ```
    /// use cpm_calib::MeasurementModel;
    /// let m = MeasurementModel::with_paper_clearance(cpm_geometry::JointTable::paper_cubic());
    /// assert_eq!(m.clearance.radius_um, 10.0);
    /// assert_eq!(m.load.platform_mass_kg, 20.0);
    /// ```
    pub fn with_paper_clearance(nominal: JointTable) -> Self {
        Self {
            nominal,
            clearance: ClearanceModel::default(),
            load: Load::default(),
            sensor_preload_sign: -1.0,
            kind: ModelKind::Exact,
            fk: ForwardOptions::default(),
            effects: Vec::new(),
            effect_settings: EffectSettings::default(),
            known_effects: Vec::new(),
        }
    }

    /// The model of a robot description: its joints (with its `[installation_errors_um]`
    /// applied when it has that table), sensors and home pose; its `[clearance]` (no clearance
    /// without that table) and `[load]` (the default [`Load`] without it); the effect settings
    /// and known effect values of its `[calibration]`. No effect is estimated: set
    /// [`effects`](Self::effects) for that.
    ///
    /// Errors: an invalid description ([`CalibError::Geometry`]) or an unknown or wrongly
    /// sized known effect ([`CalibError::Invalid`]).
    ///
    /// ```
    /// use cpm_calib::MeasurementModel;
    /// use cpm_geometry::RobotDescription;
    /// // One's own machine: examples/hexapod_66.toml declares its clearance and load.
    /// let d = RobotDescription::load("../../examples/hexapod_66.toml").unwrap();
    /// let m = MeasurementModel::from_description(&d).unwrap();
    /// let c = d.clearance.unwrap();
    /// assert_eq!(m.clearance.radius_um, c.radius_um);
    /// assert_eq!(m.load.platform_mass_kg, d.load.unwrap().platform_mass_kg);
    /// assert_eq!(m.nominal.num_links(), 6);
    /// // Without a [clearance] table there is none (not the paper's 10 um).
    /// let mut bare = d.clone();
    /// bare.clearance = None;
    /// assert_eq!(MeasurementModel::from_description(&bare).unwrap().clearance.radius_um, 0.0);
    /// ```
    pub fn from_description(
        description: &cpm_geometry::RobotDescription,
    ) -> Result<Self, CalibError> {
        let nominal = description.joint_table()?;
        let table = match description.installation_errors()? {
            Some(e) => e.apply(&nominal)?,
            None => nominal,
        };
        let mut m = Self::with_paper_clearance(table);
        m.clearance = description
            .clearance
            .as_ref()
            .map_or_else(ClearanceModel::none, ClearanceModel::from);
        m.load = description
            .load
            .as_ref()
            .map(Load::from)
            .unwrap_or_default();
        if let Some(c) = &description.calibration {
            let s = &mut m.effect_settings;
            s.screw_lead_mm = c.screw_lead_mm.unwrap_or(s.screw_lead_mm);
            s.reference_temperature_c = c
                .reference_temperature_c
                .unwrap_or(s.reference_temperature_c);
            s.nonlinearity_scale_mm = c.nonlinearity_scale_mm.unwrap_or(s.nonlinearity_scale_mm);
            for (name, values) in &c.known_effects {
                let effect = Effect::parse(name).map_err(|why| {
                    CalibError::invalid(format!("calibration.known_effects.{name}"), why)
                })?;
                m.known_effects.push(KnownEffect {
                    effect,
                    values: values.clone(),
                });
            }
            m.check_known_effects()?;
        }
        Ok(m)
    }

    /// Checks [`known_effects`](Self::known_effects): one entry per effect, each with as many
    /// finite values as the effect has parameters on this machine.
    pub fn check_known_effects(&self) -> Result<(), CalibError> {
        let (n, s) = (self.nominal.num_links(), self.nominal.sensors.len());
        for (i, k) in self.known_effects.iter().enumerate() {
            let field = format!("known_effects.{}", k.effect.name());
            if self.known_effects[..i].iter().any(|o| o.effect == k.effect) {
                return Err(CalibError::invalid(field, "given twice"));
            }
            let need = k.effect.num_params(n, s);
            if k.values.len() != need {
                return Err(CalibError::invalid(
                    field,
                    format!(
                        "{} values, but {} has {need} parameters on this machine ({} links, {} sensors)",
                        k.values.len(),
                        k.effect.name(),
                        n,
                        s
                    ),
                ));
            }
            if let Some(v) = k.values.iter().find(|v| !v.is_finite()) {
                return Err(CalibError::invalid(field, format!("{v} is not finite")));
            }
        }
        Ok(())
    }

    /// This model read through other sensors. The known values of the old sensors' effects
    /// (`sensor_offset`, `sensor_scale`, `socket_error`) belong to those sensors and are
    /// dropped; every other known value is kept.
    pub fn with_sensors(&self, sensors: Vec<cpm_geometry::Sensor>) -> MeasurementModel {
        let mut m = self.clone();
        m.nominal.sensors = sensors;
        m.known_effects.retain(|k| {
            !matches!(
                k.effect,
                Effect::SensorOffset | Effect::SensorScale | Effect::SocketError
            )
        });
        m
    }

    /// The known values of `effect`, if any.
    pub fn known(&self, effect: Effect) -> Option<&[f64]> {
        self.known_effects
            .iter()
            .find(|k| k.effect == effect)
            .map(|k| k.values.as_slice())
    }

    /// The change of each link's effective length (mm) the known link-channel effects make
    /// at a pose with context `ctx` (`t0_s`: start of the campaign's clock).
    pub fn known_link_shift_mm(&self, ctx: &PoseContext, t0_s: f64) -> Vec<f64> {
        let n = self.nominal.num_links();
        let mut out = vec![0.0; n];
        for k in self
            .known_effects
            .iter()
            .filter(|k| is_link_effect(k.effect))
        {
            for (i, o) in out.iter_mut().enumerate() {
                for (q, v) in k.values.iter().enumerate() {
                    *o += link_coefficient(k.effect, q, i, ctx, &self.effect_settings, t0_s) * v;
                }
            }
        }
        out
    }

    /// True when an effect of the model (estimated or known) needs the link forces.
    fn needs_forces(&self) -> bool {
        self.effects
            .iter()
            .chain(self.known_effects.iter().map(|k| &k.effect))
            .any(|e| matches!(e, Effect::Clearance | Effect::Compliance))
    }

    /// What the effects need to know about a pose: `commanded_mm` the commanded link lengths,
    /// `previous` the context of the pose visited before (for the motion direction; `None`
    /// for the first pose), and the logged temperature and time.
    pub fn pose_context(
        &self,
        pose: &Pose,
        commanded_mm: Vec<f64>,
        previous: Option<&PoseContext>,
        temperature_c: Option<f64>,
        time_s: Option<f64>,
    ) -> Result<PoseContext, cpm_clearance::ClearanceError> {
        let n = self.nominal.num_links();
        let forces_n = if self.needs_forces() {
            cpm_clearance::link_forces_n(&self.nominal, pose, &self.load)?
        } else {
            vec![0.0; n]
        };
        // A link that did not move keeps the direction of its last motion.
        let motion_sign = match previous {
            Some(prev) => (0..n)
                .map(|i| {
                    let d = commanded_mm[i] - prev.commanded_mm[i];
                    if d.abs() < 1e-9 {
                        prev.motion_sign[i]
                    } else {
                        d.signum()
                    }
                })
                .collect(),
            None => vec![0.0; n],
        };
        // The home lengths are the same for every pose: carried over, computed once.
        let home_mm = match previous {
            Some(prev) => prev.home_mm.clone(),
            None => cpm_kinematics::inverse_lengths(&self.nominal, &self.nominal.home),
        };
        Ok(PoseContext {
            commanded_mm,
            home_mm,
            forces_n,
            motion_sign,
            temperature_c,
            time_s,
        })
    }

    /// Number of installation-error parameters (6 per link).
    pub fn num_installation_params(&self) -> usize {
        6 * self.nominal.num_links()
    }

    /// Total number of parameters: installation errors and effect blocks.
    pub fn num_params(&self) -> usize {
        self.blocks().iter().map(|b| b.len).sum()
    }

    /// The parameter blocks in order: installation errors first, then each effect.
    pub fn blocks(&self) -> Vec<Block> {
        let (n, s) = (self.nominal.num_links(), self.nominal.sensors.len());
        let mut out = vec![Block {
            effect: None,
            offset: 0,
            len: 6 * n,
        }];
        let mut o = 6 * n;
        for &e in &self.effects {
            let len = e.num_params(n, s);
            out.push(Block {
                effect: Some(e),
                offset: o,
                len,
            });
            o += len;
        }
        out
    }

    /// Names of all parameters, with units, e.g. `link 2 platform dy [um]`,
    /// `link_scale link 3 [ppm]`.
    pub fn parameter_names(&self) -> Vec<String> {
        let sensors: Vec<String> = self
            .nominal
            .sensors
            .iter()
            .map(|s| s.name.clone())
            .collect();
        let mut out: Vec<String> = (0..self.num_installation_params())
            .map(|k| format!("{} [um]", InstallationErrors::component_name(k)))
            .collect();
        for b in self.blocks().iter().skip(1) {
            let e = b.effect.expect("effect block");
            for k in 0..b.len {
                out.push(format!(
                    "{} {} [{}]",
                    e.name(),
                    e.param_name(k, &sensors),
                    e.unit()
                ));
            }
        }
        out
    }

    /// The joint table with installation errors applied: `params` may be the installation
    /// errors alone or the whole parameter vector (then socket errors move the sensors).
    pub fn table_with(&self, params: &[f64]) -> Result<JointTable, CalibError> {
        let ni = self.num_installation_params();
        if params.len() != ni && params.len() != self.num_params() {
            return Err(CalibError::invalid(
                "parameters",
                format!(
                    "{} values, expected {ni} (installation errors) or {} (with effects)",
                    params.len(),
                    self.num_params()
                ),
            ));
        }
        let mut table = InstallationErrors::try_from_vec_um(&params[..ni])?.apply(&self.nominal)?;
        // Socket errors, um, 6 per sensor (base xyz, platform xyz): known, then estimated.
        let mut move_sockets = |q: &[f64]| {
            for (s, q) in table.sensors.iter_mut().zip(q.chunks_exact(6)) {
                s.base_mm += nalgebra::Vector3::new(q[0], q[1], q[2]) * 1e-3;
                s.platform_mm += nalgebra::Vector3::new(q[3], q[4], q[5]) * 1e-3;
            }
        };
        if let Some(q) = self.known(Effect::SocketError) {
            move_sockets(q);
        }
        if params.len() > ni {
            for b in self.blocks() {
                if b.effect == Some(Effect::SocketError) {
                    move_sockets(&params[b.offset..b.offset + b.len]);
                }
            }
        }
        Ok(table)
    }

    /// Effective link lengths (mm) the machine has at each commanded pose: the commanded
    /// lengths (logged, or nominal IK) plus the clearance shift from the link forces.
    pub fn effective_lengths(&self, campaign: &Campaign) -> Result<Vec<Vec<f64>>, CalibError> {
        let n = self.nominal.num_links();
        let mut out = Vec::with_capacity(campaign.poses.len());
        for (j, pose) in campaign.poses.iter().enumerate() {
            let mut l = match &campaign.commanded_lengths_mm {
                Some(c) => {
                    let row = c.get(j).ok_or_else(|| {
                        CalibError::invalid("commanded_lengths_mm", format!("no row for pose {j}"))
                    })?;
                    if row.len() != n {
                        return Err(CalibError::invalid(
                            "commanded_lengths_mm",
                            format!("pose {j} has {} lengths, expected {n}", row.len()),
                        ));
                    }
                    row.clone()
                }
                None => cpm_kinematics::inverse_lengths(&self.nominal, pose),
            };
            let dl = self
                .clearance
                .link_corrections_mm(&self.nominal, pose, &self.load)
                .map_err(|source| CalibError::Clearance { pose: j, source })?;
            for (a, b) in l.iter_mut().zip(&dl) {
                *a += b;
            }
            out.push(l);
        }
        Ok(out)
    }

    /// Sensor clearance correction added to every predicted reading, mm (eq. 14).
    pub fn sensor_correction_mm(&self) -> f64 {
        if self.sensor_preload_sign == 0.0 {
            0.0
        } else {
            self.clearance
                .sensor_correction_mm(self.sensor_preload_sign)
        }
    }

    /// Checks the campaign against the model: sensor indices, pose indices, finite values.
    pub fn check_campaign(&self, campaign: &Campaign) -> Result<(), CalibError> {
        self.check_known_effects()?;
        if campaign.is_empty() {
            return Err(CalibError::NoInformation(
                "the campaign has no readings and no pose measurements".into(),
            ));
        }
        for (q, pm) in campaign.pose_measurements.iter().enumerate() {
            if pm.pose >= campaign.poses.len() {
                return Err(CalibError::invalid(
                    format!("pose measurement {q}.pose"),
                    format!(
                        "{} but the campaign has {} poses",
                        pm.pose,
                        campaign.poses.len()
                    ),
                ));
            }
            if !pm.measured.is_finite() {
                return Err(CalibError::invalid(
                    format!("pose measurement {q}"),
                    "not finite",
                ));
            }
        }
        for (k, r) in campaign.readings.iter().enumerate() {
            if r.pose >= campaign.poses.len() {
                return Err(CalibError::invalid(
                    format!("reading {k}.pose"),
                    format!(
                        "{} but the campaign has {} poses",
                        r.pose,
                        campaign.poses.len()
                    ),
                ));
            }
            if r.sensor >= self.nominal.sensors.len() {
                return Err(CalibError::invalid(
                    format!("reading {k}.sensor"),
                    format!(
                        "{} but the robot has {} sensors",
                        r.sensor,
                        self.nominal.sensors.len()
                    ),
                ));
            }
            if !r.length_mm.is_finite() {
                return Err(CalibError::invalid(
                    format!("reading {k}.length_mm"),
                    format!("{} is not finite", r.length_mm),
                ));
            }
        }
        for (j, p) in campaign.poses.iter().enumerate() {
            if !p.is_finite() {
                return Err(CalibError::invalid(format!("pose {j}"), "not finite"));
            }
        }
        Ok(())
    }
}

/// Per-pose data that does not depend on the parameters, computed once per campaign.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Effective link lengths per pose (commanded plus clearance plus the known link
    /// effects), mm.
    pub lengths_mm: Vec<Vec<f64>>,
    /// What the effects need to know about each pose.
    pub contexts: Vec<PoseContext>,
    /// Start of the campaign's clock, s (earliest logged time, else 0).
    pub t0_s: f64,
    /// Readings grouped by pose: `by_pose[j]` lists reading indices taken at pose j.
    pub by_pose: Vec<Vec<usize>>,
    /// Pose measurements grouped by pose.
    pub measurements_by_pose: Vec<Vec<usize>>,
    /// First-order model only: nominal reading and its gradient per reading.
    first_order: Option<(Vec<f64>, DMatrix<f64>)>,
}

impl Prepared {
    /// Prepares a campaign for repeated predictions.
    pub fn new(model: &MeasurementModel, campaign: &Campaign) -> Result<Self, CalibError> {
        model.check_campaign(campaign)?;
        let lengths_mm = model.effective_lengths(campaign)?;
        let mut by_pose = vec![Vec::new(); campaign.poses.len()];
        for (k, r) in campaign.readings.iter().enumerate() {
            by_pose[r.pose].push(k);
        }
        let mut measurements_by_pose = vec![Vec::new(); campaign.poses.len()];
        for (q, pm) in campaign.pose_measurements.iter().enumerate() {
            measurements_by_pose[pm.pose].push(q);
        }
        let contexts = contexts(model, campaign, &lengths_mm, &by_pose)?;
        // The known link effects depend on the pose context only: applied here, once.
        let mut lengths_mm = lengths_mm;
        if !model.known_effects.is_empty() {
            let t0 = campaign_t0_s(campaign);
            for (l, ctx) in lengths_mm.iter_mut().zip(&contexts) {
                for (a, d) in l.iter_mut().zip(model.known_link_shift_mm(ctx, t0)) {
                    *a += d;
                }
            }
        }
        let mut prepared = Prepared {
            lengths_mm,
            contexts,
            t0_s: campaign_t0_s(campaign),
            by_pose,
            measurements_by_pose,
            first_order: None,
        };
        if model.kind == ModelKind::FirstOrder {
            let exact = MeasurementModel {
                kind: ModelKind::Exact,
                ..model.clone()
            };
            let zeros = vec![0.0; model.num_params()];
            let mut jac = DMatrix::zeros(campaign.len(), model.num_params());
            let y0 = predict_exact(&exact, &prepared, campaign, &zeros, Some(&mut jac))?;
            prepared.first_order = Some((y0, jac));
        }
        Ok(prepared)
    }
}

/// Start of the campaign's clock, s: the earliest logged reading time, else 0.
fn campaign_t0_s(campaign: &Campaign) -> f64 {
    let t0 = campaign
        .readings
        .iter()
        .filter_map(|r| r.time_s)
        .fold(f64::INFINITY, f64::min);
    if t0.is_finite() {
        t0
    } else {
        0.0
    }
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut s, mut n) = (0.0, 0usize);
    for x in v {
        s += x;
        n += 1;
    }
    (n > 0).then(|| s / n as f64)
}

fn contexts(
    model: &MeasurementModel,
    campaign: &Campaign,
    effective_mm: &[Vec<f64>],
    by_pose: &[Vec<usize>],
) -> Result<Vec<PoseContext>, CalibError> {
    let mut out: Vec<PoseContext> = Vec::with_capacity(campaign.poses.len());
    for (j, pose) in campaign.poses.iter().enumerate() {
        let commanded_mm = match &campaign.commanded_lengths_mm {
            Some(c) => c[j].clone(),
            None => effective_mm[j].clone(),
        };
        let rs = &by_pose[j];
        let temperature_c = mean(
            rs.iter()
                .filter_map(|&k| campaign.readings[k].temperature_c),
        );
        let time_s = mean(
            rs.iter()
                .filter_map(|&k| campaign.readings[k].time_s)
                .chain(
                    campaign
                        .pose_measurements
                        .iter()
                        .filter(|p| p.pose == j)
                        .filter_map(|p| p.time_s),
                ),
        );
        let ctx = model
            .pose_context(pose, commanded_mm, out.last(), temperature_c, time_s)
            .map_err(|source| CalibError::Clearance { pose: j, source })?;
        out.push(ctx);
    }
    Ok(out)
}

/// Predicted readings (mm) for installation errors `errors_um`; fills `jacobian`
/// (readings x parameters, mm per um) when given.
pub fn predict(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
    errors_um: &[f64],
    jacobian: Option<&mut DMatrix<f64>>,
) -> Result<Vec<f64>, CalibError> {
    match (&prepared.first_order, model.kind) {
        (Some((y0, j0)), ModelKind::FirstOrder) => {
            let e = nalgebra::DVector::from_column_slice(errors_um);
            let y = nalgebra::DVector::from_column_slice(y0) + j0 * e;
            if let Some(j) = jacobian {
                j.copy_from(j0);
            }
            Ok(y.iter().copied().collect())
        }
        _ => predict_exact(model, prepared, campaign, errors_um, jacobian),
    }
}

fn predict_exact(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
    params: &[f64],
    mut jacobian: Option<&mut DMatrix<f64>>,
) -> Result<Vec<f64>, CalibError> {
    let np = model.num_params();
    if params.len() != np {
        return Err(CalibError::invalid(
            "parameters",
            format!("{} values, expected {np}", params.len()),
        ));
    }
    let table = model.table_with(params)?;
    let n = table.num_links();
    if jacobian.is_some() && n != 6 {
        return Err(CalibError::invalid(
            "links",
            format!("the identification Jacobian needs six links, the table has {n}"),
        ));
    }
    let blocks = model.blocks();
    let link_blocks: Vec<_> = blocks
        .iter()
        .filter(|b| b.effect.is_some_and(is_link_effect))
        .collect();
    let sensor_blocks: Vec<_> = blocks
        .iter()
        .filter(|b| matches!(b.effect, Some(Effect::SensorOffset | Effect::SensorScale)))
        .collect();
    let socket_block = blocks
        .iter()
        .find(|b| b.effect == Some(Effect::SocketError));
    let tracker_block = blocks
        .iter()
        .find(|b| b.effect == Some(Effect::TrackerFrame));
    // The estimated registration (reg) composed with the known one (known): a point p of the
    // base frame is at reg_r (known_r p + known_t) + reg_t in the tracker frame.
    let (reg_t, reg_r) = match tracker_block {
        Some(b) => tracker_registration(&params[b.offset..b.offset + 6]),
        None => (nalgebra::Vector3::zeros(), nalgebra::Rotation3::identity()),
    };
    let (known_t, known_r) = match model.known(Effect::TrackerFrame) {
        Some(q) => tracker_registration(q),
        None => (nalgebra::Vector3::zeros(), nalgebra::Rotation3::identity()),
    };
    // Known sensor offsets (mm) and scale factors per sensor; the estimated ones add on top.
    let mut sensor_offset_mm = vec![0.0; table.sensors.len()];
    let mut sensor_gain = vec![1.0; table.sensors.len()];
    if let Some(v) = model.known(Effect::SensorOffset) {
        for (o, v) in sensor_offset_mm.iter_mut().zip(v) {
            *o += v * 1e-3;
        }
    }
    if let Some(v) = model.known(Effect::SensorScale) {
        for (g, v) in sensor_gain.iter_mut().zip(v) {
            *g += v * 1e-6;
        }
    }
    let estimated_gain = |si: usize| {
        sensor_blocks
            .iter()
            .filter(|b| b.effect == Some(Effect::SensorScale))
            .map(|b| params[b.offset + si] * 1e-6)
            .sum::<f64>()
    };
    let m_readings = campaign.readings.len();
    let settings = &model.effect_settings;
    let sensor_corr = model.sensor_correction_mm();
    let mut y = vec![0.0; campaign.len()];
    // Link-channel coefficients of one pose: links x (link-effect parameters).
    let mut coeff: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut lengths = vec![0.0; n];
    for (j, readings) in prepared.by_pose.iter().enumerate() {
        let measurements = &prepared.measurements_by_pose[j];
        if readings.is_empty() && measurements.is_empty() {
            continue;
        }
        let ctx = &prepared.contexts[j];
        lengths.copy_from_slice(&prepared.lengths_mm[j]);
        for (i, c) in coeff.iter_mut().enumerate() {
            c.clear();
            for b in &link_blocks {
                let e = b.effect.expect("effect");
                for k in 0..b.len {
                    let a = link_coefficient(e, k, i, ctx, settings, prepared.t0_s);
                    if a != 0.0 {
                        c.push((b.offset + k, a));
                        lengths[i] += a * params[b.offset + k];
                    }
                }
            }
        }
        let start: Pose = campaign.poses[j];
        let (pose, _) = forward(&table, &lengths, &start, &model.fk)
            .map_err(|source| CalibError::Kinematics { pose: j, source })?;
        for &k in readings {
            let si = campaign.readings[k].sensor;
            let geometric = table.sensors[si].length_mm(&pose);
            let mut yk = geometric * sensor_gain[si] + sensor_offset_mm[si] + sensor_corr;
            for b in &sensor_blocks {
                let e = b.effect.expect("effect");
                for q in 0..b.len {
                    yk += sensor_coefficient(e, q, si, geometric) * params[b.offset + q];
                }
            }
            y[k] = yk;
        }
        // Tracker observations: position in the tracker frame (mm) and the rotation from the
        // measured to the predicted orientation (mrad).
        let tracker_position = reg_r * (known_r * pose.position_mm + known_t) + reg_t;
        let tracker_rotation = reg_r * known_r * pose.rotation;
        let mut omegas = Vec::with_capacity(measurements.len());
        for &q in measurements {
            let pm = &campaign.pose_measurements[q];
            let o = m_readings + 6 * q;
            let w =
                cpm_geometry::rotation::log(&(tracker_rotation * pm.measured.rotation.inverse()));
            for a in 0..3 {
                y[o + a] = tracker_position[a];
                y[o + 3 + a] = w[a] * 1e3;
            }
            omegas.push(w);
        }
        if let Some(jac) = jacobian.as_deref_mut() {
            let links = cpm_kinematics::inverse(&table, &pose);
            let mut j1 = Matrix6::zeros();
            for (i, ls) in links.iter().enumerate() {
                let m = ls.s_mm.cross(&ls.unit);
                j1.set_row(
                    i,
                    &Vector6::new(ls.unit.x, ls.unit.y, ls.unit.z, m.x, m.y, m.z).transpose(),
                );
            }
            let lu_t = j1.transpose().lu();
            let rt = pose.rotation.matrix().transpose();
            for &k in readings {
                let si = campaign.readings[k].sensor;
                let s = &table.sensors[si];
                let g = cpm_kinematics::sensor_pose_gradient(s, &pose);
                let v = lu_t.solve(&g).ok_or_else(|| CalibError::Kinematics {
                    pose: j,
                    source: cpm_kinematics::KinematicsError::singular(0, &j1),
                })?;
                let mut row = jac.row_mut(k);
                row.fill(0.0);
                // dy/de = -v^T J2, J2 row i: [-z_i^T, (R^T z_i)^T] in the columns of link i.
                for (i, ls) in links.iter().enumerate() {
                    let zp = rt * ls.unit;
                    for a in 0..3 {
                        row[6 * i + a] = v[i] * ls.unit[a] * 1e-3;
                        row[6 * i + 3 + a] = -v[i] * zp[a] * 1e-3;
                    }
                    for &(p, a) in &coeff[i] {
                        row[p] += v[i] * a;
                    }
                }
                if let Some(b) = socket_block {
                    // Direct socket terms plus nothing through the pose (sockets do not
                    // change the closure).
                    let q = pose.transform_point(&s.platform_mm) - s.base_mm;
                    let u = q / q.norm();
                    let up = rt * u;
                    for a in 0..3 {
                        row[b.offset + 6 * si + a] = -u[a] * 1e-3;
                        row[b.offset + 6 * si + 3 + a] = up[a] * 1e-3;
                    }
                }
                // Everything so far moves the geometric length, which the sensor's scale
                // (known and estimated) multiplies.
                let gain = sensor_gain[si] + estimated_gain(si);
                if gain != 1.0 {
                    row.iter_mut().for_each(|v| *v *= gain);
                }
                let geometric = s.length_mm(&pose);
                for b in &sensor_blocks {
                    let e = b.effect.expect("effect");
                    for q in 0..b.len {
                        row[b.offset + q] += sensor_coefficient(e, q, si, geometric);
                    }
                }
            }
            if !measurements.is_empty() {
                // dx/dp = J1^-1 (dL/dp - J2 de/dp): the pose twist per parameter.
                let lu = j1.lu();
                let mut dx = DMatrix::zeros(6, np);
                let mut rhs = Vector6::zeros();
                for p in 0..np {
                    rhs.fill(0.0);
                    let mut any = false;
                    if p < 6 * n {
                        let (i, a) = (p / 6, p % 6);
                        let ls = &links[i];
                        let zp = rt * ls.unit;
                        // J2 entry per um: base -z, platform R^T z; dx = -J1^-1 J2 de.
                        rhs[i] = if a < 3 { ls.unit[a] } else { -zp[a - 3] } * 1e-3;
                        any = true;
                    }
                    for (i, c) in coeff.iter().enumerate() {
                        for &(q, a) in c {
                            if q == p {
                                rhs[i] += a;
                                any = true;
                            }
                        }
                    }
                    if any {
                        let sol = lu.solve(&rhs).ok_or_else(|| CalibError::Kinematics {
                            pose: j,
                            source: cpm_kinematics::KinematicsError::singular(0, &j1),
                        })?;
                        dx.set_column(p, &sol);
                    }
                }
                let rr = (reg_r * known_r).into_inner();
                for (&q, w) in measurements.iter().zip(&omegas) {
                    let o = m_readings + 6 * q;
                    let jl_inv = left_jacobian_inverse(w);
                    let top = rr * dx.rows(0, 3);
                    let bottom = jl_inv * rr * dx.rows(3, 3) * 1e3;
                    for p in 0..np {
                        for a in 0..3 {
                            jac[(o + a, p)] = top[(a, p)];
                            jac[(o + 3 + a, p)] = bottom[(a, p)];
                        }
                    }
                    if let Some(b) = tracker_block {
                        let skew = tracker_position - reg_t;
                        for a in 0..3 {
                            jac[(o + a, b.offset + a)] = 1e-3;
                        }
                        // d(exp(d) R t)/dd = -[R t]x, per urad.
                        let sk = skew.cross_matrix() * -1e-6;
                        let jr = jl_inv * 1e-3;
                        for a in 0..3 {
                            for c in 0..3 {
                                jac[(o + a, b.offset + 3 + c)] = sk[(a, c)];
                                jac[(o + 3 + a, b.offset + 3 + c)] = jr[(a, c)];
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(y)
}

/// Inverse of the left Jacobian of SO(3) at rotation vector `w`: `d log(exp(d) exp(w)) / dd`.
fn left_jacobian_inverse(w: &nalgebra::Vector3<f64>) -> nalgebra::Matrix3<f64> {
    let th = w.norm();
    let k = w.cross_matrix();
    let i = nalgebra::Matrix3::identity();
    if th < 1e-8 {
        return i - k * 0.5 + k * k / 12.0;
    }
    let c = 1.0 / (th * th) - (1.0 + th.cos()) / (2.0 * th * th.sin());
    i - k * 0.5 + k * k * c
}
