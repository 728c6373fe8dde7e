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
use nalgebra::DMatrix;

use crate::model::compose::{AtPose, Channels, Kin};
use crate::model::effects::{
    Channel, Effect, EffectInput, EffectSettings, KnownEffect, PoseContext,
};
use crate::model::instruments::TrackerPoses;
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
    /// The design geometry, when it differs from [`nominal`](Self::nominal): the joints of a
    /// robot description without its `[installation_errors_um]`. The link forces (joint
    /// clearance, compliance) and the home link lengths of the effects are computed on it, so
    /// that a calibrated description (the design plus the fitted installation errors) predicts
    /// exactly what the fit predicted. Default `None`: [`nominal`](Self::nominal).
    pub design: Option<JointTable>,
    /// The sessions ([`Campaign::session_starts`], a file each) whose tracker frames
    /// `tracker_frame` estimates, one frame (6 parameters) each, in this order: every session
    /// brings its own tracker set-up. Empty (the default): one frame shared by every pose
    /// measurement.
    pub tracker_frame_sessions: Vec<usize>,
    /// Point targets on the platform (`[[target]]`), in the order point measurements index
    /// them; [`Effect::TargetPosition`] estimates corrections of their positions. Default
    /// none.
    pub targets: Vec<crate::model::points::PointTarget>,
    /// Number of point-measurement sessions whose tracker frames [`Effect::PointFrame`]
    /// estimates (6 parameters each). Default 0.
    pub point_sessions: usize,
    /// Inclinometers on the platform (`[[inclinometer]]`), in the order tilt measurements
    /// index them; [`Effect::InclinometerMount`] estimates corrections of their mounts.
    /// Default none.
    pub inclinometers: Vec<crate::model::tilts::Inclinometer>,
    /// Number of inclinometer sessions whose base tilts [`Effect::BaseTilt`] estimates (2
    /// parameters each). Default 0.
    pub tilt_sessions: usize,
    /// One's own instruments ([`crate::instruments`]), in the order instrument measurements
    /// index them. Each brings a block of nuisance parameters after the effects' blocks, always
    /// estimated: its per-instrument parameters, then its per-session ones for each of
    /// [`instrument_sessions`](Self::instrument_sessions). Default none.
    pub instruments: Vec<std::sync::Arc<dyn crate::model::instruments::Instrument>>,
    /// Number of sessions of the instrument measurements (their
    /// [`session`](crate::InstrumentMeasurement::session) is below it), each with the
    /// instruments' per-session parameters. Default 0.
    pub instrument_sessions: usize,
}

/// Where a block of parameters sits in the parameter vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block {
    /// The effect (`None` for the installation errors and the instruments' blocks).
    pub effect: Option<Effect>,
    /// The instrument ([`MeasurementModel::instruments`]) whose nuisance parameters the block
    /// holds (`None` for the installation errors and the effects).
    pub instrument: Option<usize>,
    /// First index.
    pub offset: usize,
    /// Number of parameters.
    pub len: usize,
}

/// The unit of a parameter named as [`MeasurementModel::parameter_names`] names it (the text
/// in its last brackets: `link 2 platform dy [um]` is in `um`); empty when it names none.
pub fn unit_of_parameter(name: &str) -> &str {
    name.rsplit_once('[')
        .map_or("", |(_, u)| u.trim_end_matches(']'))
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
            design: None,
            tracker_frame_sessions: Vec::new(),
            targets: Vec::new(),
            point_sessions: 0,
            inclinometers: Vec::new(),
            tilt_sessions: 0,
            instruments: Vec::new(),
            instrument_sessions: 0,
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
        Self::from_description_among(description, &[])
    }

    /// [`from_description`](Self::from_description) whose `[calibration] known_effects` may
    /// name the user effects `user` ([`Effect::parse_among`]): the one builder of a model
    /// from a description (`cpm_io::Robot::model` is this, with the effects to estimate).
    pub fn from_description_among(
        description: &cpm_geometry::RobotDescription,
        user: &[Effect],
    ) -> Result<Self, CalibError> {
        let nominal = description.joint_table()?;
        let (table, design) = match description.installation_errors()? {
            Some(e) => (e.apply(&nominal)?, Some(nominal)),
            None => (nominal, None),
        };
        Self::on_table(table, design, description, user)
    }

    /// The model of the joint table `table` (the design `design`, when it differs: the
    /// description's joints without its installation errors) with everything else the
    /// description declares: clearance, load, effect settings, known effects (which may name
    /// the user effects `user`), targets and inclinometers.
    /// [`from_description_among`](Self::from_description_among) is this on the description's
    /// own table; a caller that holds the table (`cpm_io::Robot`, whose table may be edited)
    /// gives it.
    pub fn on_table(
        table: JointTable,
        design: Option<JointTable>,
        description: &cpm_geometry::RobotDescription,
        user: &[Effect],
    ) -> Result<Self, CalibError> {
        let mut m = Self::with_paper_clearance(table);
        m.design = design;
        m.targets = description
            .targets
            .iter()
            .map(|t| crate::model::points::PointTarget {
                name: t.name.clone(),
                platform_mm: t.platform_mm.into(),
            })
            .collect();
        m.inclinometers = description
            .inclinometers
            .iter()
            .map(crate::model::tilts::Inclinometer::from_spec)
            .collect();
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
            s.reference_time_s = c.reference_time_s.or(s.reference_time_s);
            for (name, values) in &c.known_effects {
                let effect = Effect::parse_among(name, user).map_err(|why| {
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
            !(k.effect.acts_through(Channel::SensorReading)
                || k.effect.acts_through(Channel::SensorSocket))
        });
        m
    }

    /// The geometry the link forces and the effects' home lengths are computed on: the
    /// [`design`](Self::design) when set, else the [`nominal`](Self::nominal) table.
    pub fn statics_table(&self) -> &JointTable {
        self.design.as_ref().unwrap_or(&self.nominal)
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
    /// Effects that read the commanded pose see the home pose: use
    /// [`known_link_shift_at`](Self::known_link_shift_at) for those.
    pub fn known_link_shift_mm(&self, ctx: &PoseContext, t0_s: f64) -> Vec<f64> {
        self.known_link_shift_at(ctx, &self.nominal.home, t0_s)
    }

    /// [`known_link_shift_mm`](Self::known_link_shift_mm) at the commanded pose `commanded`.
    pub fn known_link_shift_at(&self, ctx: &PoseContext, commanded: &Pose, t0_s: f64) -> Vec<f64> {
        let input = EffectInput {
            context: ctx,
            commanded,
            home: &self.nominal.home,
            settings: &self.effect_settings,
            t0_s,
        };
        let mut out = vec![0.0; self.nominal.num_links()];
        for k in self
            .known_effects
            .iter()
            .filter(|k| k.effect.acts_through(Channel::LinkLength))
        {
            let e = k.effect.model();
            for (i, o) in out.iter_mut().enumerate() {
                for (q, v) in k.values.iter().enumerate() {
                    *o += e.link_coefficient(q, i, &input) * v;
                }
            }
        }
        out
    }

    /// The platform pose twist (mm, rad) the known pose-channel effects (the pose map) make
    /// at commanded pose `commanded`: the platform sits at `pose.perturbed(twist)`.
    pub fn known_pose_twist(
        &self,
        ctx: &PoseContext,
        commanded: &Pose,
        t0_s: f64,
    ) -> nalgebra::Vector6<f64> {
        let input = EffectInput {
            context: ctx,
            commanded,
            home: &self.nominal.home,
            settings: &self.effect_settings,
            t0_s,
        };
        let mut out = nalgebra::Vector6::zeros();
        for k in self
            .known_effects
            .iter()
            .filter(|k| k.effect.acts_through(Channel::PlatformPose))
        {
            for (q, v) in k.values.iter().enumerate() {
                out += k.effect.model().pose_coefficients(q, &input) * *v;
            }
        }
        out
    }

    /// True when an effect of the model (estimated or known) needs the link forces.
    fn needs_forces(&self) -> bool {
        self.effects
            .iter()
            .chain(self.known_effects.iter().map(|k| &k.effect))
            .any(|e| e.model().needs_forces())
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
            cpm_clearance::link_forces_n(self.statics_table(), pose, &self.load)?
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
            None => cpm_kinematics::inverse_lengths(self.statics_table(), &self.nominal.home),
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

    /// The parameter blocks in order: installation errors first, then each effect, then each
    /// of one's own [`instruments`](Self::instruments).
    pub fn blocks(&self) -> Vec<Block> {
        let (n, s) = (self.nominal.num_links(), self.nominal.sensors.len());
        let mut out = vec![Block {
            effect: None,
            instrument: None,
            offset: 0,
            len: 6 * n,
        }];
        let mut o = 6 * n;
        for &e in &self.effects {
            let len = match e {
                Effect::TrackerFrame => 6 * self.tracker_frames(),
                Effect::TargetPosition => 3 * self.targets.len(),
                Effect::PointFrame => 6 * self.point_sessions,
                Effect::InclinometerMount => 3 * self.inclinometers.len(),
                Effect::BaseTilt => 2 * self.tilt_sessions,
                _ => e.num_params(n, s),
            };
            out.push(Block {
                effect: Some(e),
                instrument: None,
                offset: o,
                len,
            });
            o += len;
        }
        for (i, instrument) in self.instruments.iter().enumerate() {
            let len = instrument.num_instrument_params()
                + self.instrument_sessions * instrument.num_session_params();
            out.push(Block {
                effect: None,
                instrument: Some(i),
                offset: o,
                len,
            });
            o += len;
        }
        out
    }

    /// The group of every parameter for a rank that does not depend on units
    /// ([`RankScaling::column_groups`](crate::RankScaling::column_groups)): one group per
    /// unit, group 0 the installation errors' (um). Parameters of one unit keep their relative
    /// scale (a link offset beside a joint error, both in um); a block in another unit (a
    /// compliance in um/kN, whose scale follows the platform's mass) is brought to it.
    ///
    /// ```
    /// use cpm_calib::{Effect, MeasurementModel};
    /// let mut m = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
    /// m.effects = vec![Effect::LinkScale, Effect::LinkOffset, Effect::TrackerFrame];
    /// let g = m.rank_groups();
    /// assert_eq!((g[0], g[35], g[36], g[41]), (0, 0, 1, 1)); // um, then ppm
    /// assert_eq!((g[42], g[48], g[51]), (0, 0, 2)); // offsets and translations um, rotations urad
    /// ```
    pub fn rank_groups(&self) -> Vec<usize> {
        let units = self.parameter_units();
        let mut keys: Vec<&str> = vec!["um"];
        units
            .iter()
            .map(|u| match keys.iter().position(|k| *k == u.as_str()) {
                Some(g) => g,
                None => {
                    keys.push(u.as_str());
                    keys.len() - 1
                }
            })
            .collect()
    }

    /// The unit of every parameter (`um`, `ppm`, `urad`, ...), as its name in
    /// [`parameter_names`](Self::parameter_names) gives it.
    pub fn parameter_units(&self) -> Vec<String> {
        self.parameter_names()
            .iter()
            .map(|n| unit_of_parameter(n).to_string())
            .collect()
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
            if let Some(i) = b.instrument {
                let instrument = &self.instruments[i];
                let own = instrument.num_instrument_params();
                let per_session = instrument.num_session_params();
                for k in 0..b.len {
                    let (name, q) = if k < own {
                        (instrument.param_name(k), k)
                    } else {
                        let q = own + (k - own) % per_session;
                        (
                            format!(
                                "{} (session {})",
                                instrument.param_name(q),
                                (k - own) / per_session + 1
                            ),
                            q,
                        )
                    };
                    out.push(format!(
                        "{} {name} [{}]",
                        instrument.name(),
                        instrument.param_unit(q)
                    ));
                }
                continue;
            }
            let e = b.effect.expect("effect block");
            for k in 0..b.len {
                if e.is_instrument() {
                    out.push(format!(
                        "{} {} [{}]",
                        e.name(),
                        if matches!(e, Effect::InclinometerMount) {
                            crate::model::tilts::param_name(self, e, k)
                        } else {
                            crate::model::points::param_name(self, e, k)
                        },
                        e.param_unit(k)
                    ));
                    continue;
                }
                let name = if e == Effect::TrackerFrame && self.tracker_frames() > 1 {
                    format!(
                        "{} (session {})",
                        e.param_name(k % 6, &sensors),
                        self.tracker_frame_sessions[k / 6] + 1
                    )
                } else {
                    e.param_name(k, &sensors)
                };
                // Each parameter in its own unit (a frame's translation in um, its rotation
                // in urad), never the group's list of units.
                out.push(format!("{} {} [{}]", e.name(), name, e.param_unit(k)));
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
        // The socket channel: known values, then estimated ones.
        let mut move_sockets = |e: Effect, q: &[f64]| {
            let e = e.model();
            for (si, s) in table.sensors.iter_mut().enumerate() {
                for (k, v) in q.iter().enumerate() {
                    let (db, dp) = e.socket_coefficients(k, si);
                    s.base_mm += db * *v;
                    s.platform_mm += dp * *v;
                }
            }
        };
        for k in &self.known_effects {
            if k.effect.acts_through(Channel::SensorSocket) {
                move_sockets(k.effect, &k.values);
            }
        }
        if params.len() > ni {
            for b in self.blocks() {
                if let Some(e) = b.effect.filter(|e| e.acts_through(Channel::SensorSocket)) {
                    move_sockets(e, &params[b.offset..b.offset + b.len]);
                }
            }
        }
        Ok(table)
    }

    /// Number of tracker frames `tracker_frame` estimates: one per
    /// [`tracker_frame_sessions`](Self::tracker_frame_sessions), at least one.
    pub fn tracker_frames(&self) -> usize {
        self.tracker_frame_sessions.len().max(1)
    }

    /// The frame (index into the `tracker_frame` block, 6 parameters each) of a pose
    /// measurement at pose `pose` of `campaign`: its session's, or the one shared frame.
    ///
    /// Errors: a session with no frame of its own in
    /// [`tracker_frame_sessions`](Self::tracker_frame_sessions).
    pub fn tracker_frame_of(&self, campaign: &Campaign, pose: usize) -> Result<usize, CalibError> {
        if self.tracker_frame_sessions.is_empty() {
            return Ok(0);
        }
        let s = campaign.session_of(pose);
        self.tracker_frame_sessions
            .iter()
            .position(|x| *x == s)
            .ok_or_else(|| {
                CalibError::invalid(
                    "tracker_frame_sessions",
                    format!(
                        "pose {pose} is in session {} which has no tracker frame ({:?})",
                        s + 1,
                        self.tracker_frame_sessions
                    ),
                )
            })
    }

    /// The machine this model describes at `params`, held fixed: the installation errors
    /// applied to the joints (link forces and home lengths still on the design geometry,
    /// [`statics_table`](Self::statics_table)), every estimated effect's values made known
    /// (added to known values of the same effect; a `tracker_frame` composed with a known
    /// one), nothing left to estimate. Errors: one's own instrument with nuisance parameters
    /// (their values are not carried). What [`crate::fit::session::register_session`] and a held-out
    /// prediction need. A campaign without logged commands must have them logged first
    /// ([`log_commands`](Self::log_commands)): the held machine's own inverse kinematics
    /// would be other commands.
    ///
    /// ```
    /// use cpm_calib::{model::{predict, Prepared}, Effect, MeasurementModel, Plan};
    /// let mut m = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
    /// m.nominal.sensors = cpm_calib::paper::designed_sensors();
    /// m.effects = vec![Effect::LinkOffset];
    /// let poses = cpm_calib::paper::random_workspace_poses(&m.nominal, 5, 50.0, 5.0, 3.0, 1);
    /// let mut c = Plan { poses, sensors: vec![0, 1, 2] }.skeleton();
    /// m.log_commands(&mut c);
    /// let params: Vec<f64> = (0..m.num_params()).map(|k| (k as f64 * 0.7).sin() * 20.0).collect();
    /// let fixed = m.held_fixed(&params).unwrap();
    /// assert_eq!(fixed.num_params(), 36);
    /// let a = predict(&m, &Prepared::new(&m, &c).unwrap(), &c, &params, None).unwrap();
    /// let b = predict(&fixed, &Prepared::new(&fixed, &c).unwrap(), &c, &[0.0; 36], None).unwrap();
    /// assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9));
    /// ```
    pub fn held_fixed(&self, params: &[f64]) -> Result<MeasurementModel, CalibError> {
        let np = self.num_params();
        if params.len() != np {
            return Err(CalibError::invalid(
                "parameters",
                format!("{} values, expected {np}", params.len()),
            ));
        }
        if let Some(b) = self
            .blocks()
            .iter()
            .find(|b| b.instrument.is_some() && b.len > 0)
        {
            return Err(CalibError::invalid(
                "instruments",
                format!(
                    "instrument `{}` has nuisance parameters, which a machine held fixed does not carry",
                    self.instruments[b.instrument.unwrap_or_default()].name()
                ),
            ));
        }
        let ni = self.num_installation_params();
        let mut fixed = self.clone();
        fixed.nominal = InstallationErrors::try_from_vec_um(&params[..ni])?.apply(&self.nominal)?;
        fixed.design = Some(self.statics_table().clone());
        fixed.effects.clear();
        fixed.tracker_frame_sessions.clear();
        for b in self.blocks() {
            let Some(e) = b.effect else { continue };
            let v = &params[b.offset..b.offset + b.len];
            match e {
                // Frames and levelling of several sessions describe those sessions, not the
                // machine.
                Effect::TrackerFrame if self.tracker_frames() > 1 => continue,
                Effect::PointFrame | Effect::BaseTilt => continue,
                // Not carried (the mount's convention lives with the tilt model): a held
                // machine predicts tilts with the declared mounts.
                Effect::InclinometerMount => continue,
                // The instruments' own unknowns go into their descriptions.
                Effect::TargetPosition => {
                    for (t, d) in fixed.targets.iter_mut().zip(v.chunks(3)) {
                        t.platform_mm += nalgebra::Vector3::new(d[0], d[1], d[2]) * 1e-3;
                    }
                    continue;
                }
                _ => {}
            }
            match fixed.known_effects.iter_mut().find(|k| k.effect == e) {
                None => fixed.known_effects.push(KnownEffect {
                    effect: e,
                    values: v.to_vec(),
                }),
                Some(k) if e == Effect::TrackerFrame => {
                    // p -> R_e (R_k p + t_k) + t_e.
                    let (tk, rk) = crate::model::effects::tracker_registration(&k.values);
                    let (te, re) = crate::model::effects::tracker_registration(v);
                    k.values =
                        crate::model::effects::frame_params(&(re * tk + te), &(re * rk)).to_vec();
                }
                Some(k) => {
                    for (a, b) in k.values.iter_mut().zip(v) {
                        *a += b;
                    }
                }
            }
        }
        Ok(fixed)
    }

    /// Logs the commands this model assumes for a campaign that has none: the nominal inverse
    /// kinematics of each commanded pose (what the controller sent), so that another model
    /// of the machine (say [`held_fixed`](Self::held_fixed)) sees the same commands.
    pub fn log_commands(&self, campaign: &mut Campaign) {
        if campaign.commanded_lengths_mm.is_none() {
            campaign.commanded_lengths_mm = Some(
                campaign
                    .poses
                    .iter()
                    .map(|p| cpm_kinematics::inverse_lengths(&self.nominal, p))
                    .collect(),
            );
        }
    }

    /// Effective link lengths (mm) the machine has at each commanded pose: the commanded
    /// lengths (logged, or nominal IK) plus the clearance shift from the link forces.
    pub fn effective_lengths(&self, campaign: &Campaign) -> Result<Vec<Vec<f64>>, CalibError> {
        self.effective_lengths_commanded(campaign, campaign.commanded_lengths_mm.as_deref())
    }

    /// [`effective_lengths`](Self::effective_lengths) with the commanded lengths `commanded`
    /// in place of the campaign's.
    fn effective_lengths_commanded(
        &self,
        campaign: &Campaign,
        commanded: Option<&[Vec<f64>]>,
    ) -> Result<Vec<Vec<f64>>, CalibError> {
        use rayon::prelude::*;
        let n = self.nominal.num_links();
        // Pose by pose in parallel (the statics of each pose are its own); the first error
        // in pose order, as one pass would give it.
        let rows: Vec<Result<Vec<f64>, CalibError>> = campaign
            .poses
            .par_iter()
            .enumerate()
            .map(|(j, pose)| self.effective_lengths_at(commanded, j, pose, n))
            .collect();
        rows.into_iter().collect()
    }

    /// The row of [`effective_lengths`](Self::effective_lengths) of pose `j`, the commanded
    /// lengths `commanded` (`None`: the nominal inverse kinematics).
    fn effective_lengths_at(
        &self,
        commanded: Option<&[Vec<f64>]>,
        j: usize,
        pose: &Pose,
        n: usize,
    ) -> Result<Vec<f64>, CalibError> {
        let mut l = match commanded {
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
            .link_corrections_mm(self.statics_table(), pose, &self.load)
            .map_err(|source| CalibError::Clearance { pose: j, source })?;
        for (a, b) in l.iter_mut().zip(&dl) {
            *a += b;
        }
        Ok(l)
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
        let levels = self.effects.contains(&Effect::BaseTilt);
        for (q, t) in campaign.tilt_measurements.iter().enumerate() {
            let field = |f: &str| format!("tilt measurement {q}.{f}");
            if t.pose >= campaign.poses.len() {
                return Err(CalibError::invalid(
                    field("pose"),
                    format!(
                        "{} but the campaign has {} poses",
                        t.pose,
                        campaign.poses.len()
                    ),
                ));
            }
            let Some(c) = self.inclinometers.get(t.inclinometer) else {
                return Err(CalibError::invalid(
                    field("inclinometer"),
                    format!(
                        "{} but the robot has {} [[inclinometer]] tables",
                        t.inclinometer,
                        self.inclinometers.len()
                    ),
                ));
            };
            if t.axis >= c.axes.len() {
                return Err(CalibError::invalid(
                    field("axis"),
                    format!("{} but `{}` has {} axes", t.axis, c.name, c.axes.len()),
                ));
            }
            if levels && t.session >= self.tilt_sessions {
                return Err(CalibError::invalid(
                    field("session"),
                    format!(
                        "{} but the model has {} tilt sessions (MeasurementModel::tilt_sessions)",
                        t.session, self.tilt_sessions
                    ),
                ));
            }
            if !t.angle_mrad.is_finite() {
                return Err(CalibError::invalid(field("angle_mrad"), "not finite"));
            }
        }
        for (i, &(q, a)) in campaign.unmeasured.iter().enumerate() {
            if q >= campaign.pose_measurements.len() || a >= 6 {
                return Err(CalibError::invalid(
                    format!("unmeasured {i}"),
                    format!(
                        "({q}, {a}): no such component (pose measurements {}, components 0..6)",
                        campaign.pose_measurements.len()
                    ),
                ));
            }
            if i > 0 && campaign.unmeasured[i - 1] >= (q, a) {
                return Err(CalibError::invalid(
                    format!("unmeasured {i}"),
                    "not sorted, or given twice",
                ));
            }
        }
        let frames = self.effects.contains(&Effect::PointFrame);
        for (q, pm) in campaign.point_measurements.iter().enumerate() {
            let field = |f: &str| format!("point measurement {q}.{f}");
            if pm.pose >= campaign.poses.len() {
                return Err(CalibError::invalid(
                    field("pose"),
                    format!(
                        "{} but the campaign has {} poses",
                        pm.pose,
                        campaign.poses.len()
                    ),
                ));
            }
            if pm.target >= self.targets.len() {
                return Err(CalibError::invalid(
                    field("target"),
                    format!(
                        "{} but the robot has {} [[target]] tables",
                        pm.target,
                        self.targets.len()
                    ),
                ));
            }
            if frames && pm.session >= self.point_sessions {
                return Err(CalibError::invalid(
                    field("session"),
                    format!(
                        "{} but the model has {} point sessions (MeasurementModel::point_sessions)",
                        pm.session, self.point_sessions
                    ),
                ));
            }
            if !pm.measured_mm.iter().all(|v| v.is_finite()) {
                return Err(CalibError::invalid(field("measured_mm"), "not finite"));
            }
        }
        for (q, m) in campaign.instrument_measurements.iter().enumerate() {
            let field = |f: &str| format!("instrument measurement {q}.{f}");
            if m.pose >= campaign.poses.len() {
                return Err(CalibError::invalid(
                    field("pose"),
                    format!(
                        "{} but the campaign has {} poses",
                        m.pose,
                        campaign.poses.len()
                    ),
                ));
            }
            let Some(instrument) = self.instruments.get(m.instrument) else {
                return Err(CalibError::invalid(
                    field("instrument"),
                    format!(
                        "{} but the model has {} instruments",
                        m.instrument,
                        self.instruments.len()
                    ),
                ));
            };
            if m.channel >= instrument.num_channels() {
                return Err(CalibError::invalid(
                    field("channel"),
                    format!(
                        "{} but `{}` has {} channels",
                        m.channel,
                        instrument.name(),
                        instrument.num_channels()
                    ),
                ));
            }
            if instrument.num_session_params() > 0 && m.session >= self.instrument_sessions {
                return Err(CalibError::invalid(
                    field("session"),
                    format!(
                        "{} but the model has {} instrument sessions (MeasurementModel::instrument_sessions)",
                        m.session, self.instrument_sessions
                    ),
                ));
            }
            if m.values.len() != instrument.num_values() {
                return Err(CalibError::invalid(
                    field("values"),
                    format!(
                        "{} values but `{}` gives {}",
                        m.values.len(),
                        instrument.name(),
                        instrument.num_values()
                    ),
                ));
            }
            if !m.values.iter().all(|v| v.is_finite()) {
                return Err(CalibError::invalid(field("values"), "not finite"));
            }
            if !(m.sigma.is_finite() && m.sigma > 0.0) {
                return Err(CalibError::invalid(
                    field("sigma"),
                    format!("{} must be finite and > 0", m.sigma),
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

/// The measurements of one kind grouped by pose: `by_pose[j]` lists the indices of those
/// taken at pose j (in the campaign's order). A kind the campaign has none of holds nothing,
/// not an empty list per pose (10^5 poses: 2.4 MB each).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ByPose(Vec<Vec<usize>>);

impl ByPose {
    /// The measurements taken at each of `poses` poses, from the pose of each measurement in
    /// order.
    pub fn group(poses: usize, pose_of: impl ExactSizeIterator<Item = usize>) -> Self {
        if pose_of.len() == 0 {
            return ByPose::default();
        }
        let mut out = vec![Vec::new(); poses];
        for (q, j) in pose_of.enumerate() {
            out[j].push(q);
        }
        ByPose(out)
    }
}

impl std::ops::Index<usize> for ByPose {
    type Output = [usize];
    /// The measurements taken at pose `j` (none past the poses of a kind without any).
    fn index(&self, j: usize) -> &[usize] {
        self.0.get(j).map_or(&[], Vec::as_slice)
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
    pub measurements_by_pose: ByPose,
    /// Point measurements grouped by pose.
    pub points_by_pose: ByPose,
    /// Tilt measurements grouped by pose.
    pub tilts_by_pose: ByPose,
    /// Instrument measurements grouped by pose.
    pub instruments_by_pose: ByPose,
    /// The observation index of the first value of each instrument measurement
    /// ([`Campaign::instrument_observation_rows`]).
    pub instrument_rows: Vec<usize>,
    /// The observation index of each component of each pose measurement (`None`: not
    /// measured; [`Campaign::pose_observation_rows`]).
    pub pose_rows: Vec<[Option<usize>; 6]>,
    /// First-order model only: nominal reading and its gradient per reading.
    first_order: Option<(Vec<f64>, DMatrix<f64>)>,
}

impl Prepared {
    /// Whether pose `j` has anything observed at it (readings or measurements).
    fn observed_at(&self, j: usize) -> bool {
        !(self.by_pose[j].is_empty()
            && self.measurements_by_pose[j].is_empty()
            && self.points_by_pose[j].is_empty()
            && self.tilts_by_pose[j].is_empty()
            && self.instruments_by_pose[j].is_empty())
    }

    /// Prepares a campaign for repeated predictions.
    pub fn new(model: &MeasurementModel, campaign: &Campaign) -> Result<Self, CalibError> {
        Self::with_commanded(model, campaign, campaign.commanded_lengths_mm.as_deref())
    }

    /// [`new`](Self::new) with the commanded lengths `commanded` (mm, per pose and link;
    /// `None`: none logged) in place of the campaign's `commanded_lengths_mm`: one campaign
    /// prepared for two machines commanded alike but with their own reading models, without
    /// a copy of it.
    pub fn with_commanded(
        model: &MeasurementModel,
        campaign: &Campaign,
        commanded: Option<&[Vec<f64>]>,
    ) -> Result<Self, CalibError> {
        model.check_campaign(campaign)?;
        let lengths_mm = model.effective_lengths_commanded(campaign, commanded)?;
        // Sized first: one allocation per pose.
        let mut per_pose = vec![0usize; campaign.poses.len()];
        for r in &campaign.readings {
            per_pose[r.pose] += 1;
        }
        let mut by_pose: Vec<Vec<usize>> =
            per_pose.iter().map(|&n| Vec::with_capacity(n)).collect();
        drop(per_pose);
        for (k, r) in campaign.readings.iter().enumerate() {
            by_pose[r.pose].push(k);
        }
        let n = campaign.poses.len();
        let measurements_by_pose =
            ByPose::group(n, campaign.pose_measurements.iter().map(|m| m.pose));
        let points_by_pose = ByPose::group(n, campaign.point_measurements.iter().map(|m| m.pose));
        let tilts_by_pose = ByPose::group(n, campaign.tilt_measurements.iter().map(|m| m.pose));
        let instruments_by_pose =
            ByPose::group(n, campaign.instrument_measurements.iter().map(|m| m.pose));
        let contexts = contexts(
            model,
            campaign,
            commanded,
            &lengths_mm,
            &by_pose,
            &measurements_by_pose,
        )?;
        // The known link effects depend on the pose context only: applied here, once.
        let mut lengths_mm = lengths_mm;
        if !model.known_effects.is_empty() {
            let t0 = campaign_t0_s(model, campaign);
            for ((l, ctx), pose) in lengths_mm.iter_mut().zip(&contexts).zip(&campaign.poses) {
                for (a, d) in l.iter_mut().zip(model.known_link_shift_at(ctx, pose, t0)) {
                    *a += d;
                }
            }
        }
        let mut prepared = Prepared {
            lengths_mm,
            contexts,
            t0_s: campaign_t0_s(model, campaign),
            by_pose,
            measurements_by_pose,
            points_by_pose,
            tilts_by_pose,
            instruments_by_pose,
            instrument_rows: campaign.instrument_observation_rows(),
            pose_rows: campaign.pose_observation_rows(),
            first_order: None,
        };
        if model.kind == ModelKind::FirstOrder {
            let exact = MeasurementModel {
                kind: ModelKind::Exact,
                ..model.clone()
            };
            let zeros = vec![0.0; model.num_params()];
            let mut jac = DMatrix::zeros(campaign.len(), model.num_params());
            let y0 = predict_exact(&exact, &prepared, campaign, &zeros, Some(&mut jac as _))?;
            prepared.first_order = Some((y0, jac));
        }
        Ok(prepared)
    }
}

/// Start of the campaign's clock, s: the model's declared time origin
/// ([`EffectSettings::reference_time_s`](crate::EffectSettings::reference_time_s)), else the
/// earliest logged time of the campaign ([`Campaign::first_time_s`]), else 0.
fn campaign_t0_s(model: &MeasurementModel, campaign: &Campaign) -> f64 {
    model
        .effect_settings
        .reference_time_s
        .or_else(|| campaign.first_time_s())
        .unwrap_or(0.0)
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let mut m = Mean::default();
    for x in v {
        m.add(Some(x));
    }
    m.get()
}

/// A mean summed value after value ([`mean`] of the values given).
#[derive(Default)]
struct Mean {
    sum: f64,
    count: usize,
}

impl Mean {
    /// Adds `x` when it is given.
    fn add(&mut self, x: Option<f64>) {
        if let Some(x) = x {
            self.sum += x;
            self.count += 1;
        }
    }

    /// The mean, `None` of no value.
    fn get(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }
}

/// Each pose's context ([`MeasurementModel::pose_context`]), pose after pose (the motion
/// directions follow the poses visited); the first error in pose order. (Found in parallel,
/// the contexts' small vectors spread over the allocator's thread arenas and the peak memory
/// of `cpm validate --out` on 10^6 readings grew by 20 MB for 15 ms: kept in one pass.)
fn contexts(
    model: &MeasurementModel,
    campaign: &Campaign,
    commanded: Option<&[Vec<f64>]>,
    effective_mm: &[Vec<f64>],
    by_pose: &[Vec<usize>],
    measurements_by_pose: &ByPose,
) -> Result<Vec<PoseContext>, CalibError> {
    let mut out: Vec<PoseContext> = Vec::with_capacity(campaign.poses.len());
    for (j, pose) in campaign.poses.iter().enumerate() {
        // The commanded lengths: logged, or the nominal inverse kinematics (never the
        // effective lengths, which carry the clearance shift: an effect that reads the
        // commanded length must see the same value whether the controller logged it or not).
        let commanded_mm = match commanded {
            Some(c) => c[j].clone(),
            None if model.clearance.radius_um == 0.0 => effective_mm[j].clone(),
            None => cpm_kinematics::inverse_lengths(&model.nominal, pose),
        };
        let rs = &by_pose[j];
        // The pose's tracker measurements, in the campaign's order.
        let measured = || {
            measurements_by_pose[j]
                .iter()
                .map(|&q| &campaign.pose_measurements[q])
        };
        // The means of the readings' temperatures and times in one pass over the readings
        // (the same sums, in the same order, as one pass for each).
        let (mut temperature, mut time) = (Mean::default(), Mean::default());
        for &k in rs {
            let r = &campaign.readings[k];
            temperature.add(r.temperature_c.get());
            time.add(r.time_s.get());
        }
        let temperature_c = temperature
            .get()
            .or_else(|| mean(measured().filter_map(|p| p.temperature_c)));
        for p in measured() {
            time.add(p.time_s);
        }
        let time_s = time.get();
        let previous = if campaign.starts_session(j) {
            None
        } else {
            out.last()
        };
        let ctx = model
            .pose_context(pose, commanded_mm, previous, temperature_c, time_s)
            .map_err(|source| CalibError::Clearance { pose: j, source })?;
        out.push(ctx);
    }
    Ok(out)
}

/// Storage a prediction writes its Jacobian into (observations x parameters, per unit of
/// the parameters), row by row, each row whole: a nalgebra matrix, or the solver's own faer
/// matrix ([`predict_into`]: no matrix in between and no copy after).
pub trait JacobianRows {
    /// Writes `row` (one value per parameter) as row `r`.
    fn set_row(&mut self, r: usize, row: &[f64]);
}

impl JacobianRows for DMatrix<f64> {
    fn set_row(&mut self, r: usize, row: &[f64]) {
        for (c, v) in row.iter().enumerate() {
            self[(r, c)] = *v;
        }
    }
}

impl JacobianRows for cpm_lm::faer::MatMut<'_, f64> {
    fn set_row(&mut self, r: usize, row: &[f64]) {
        for (c, v) in row.iter().enumerate() {
            self[(r, c)] = *v;
        }
    }
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
    predict_into(
        model,
        prepared,
        campaign,
        errors_um,
        jacobian.map(|j| j as &mut dyn JacobianRows),
    )
}

/// [`predict`] with the Jacobian written into `jacobian`'s own storage (the solver's faer
/// matrix, say), row by row: every observation's row is written whole.
pub fn predict_into(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
    errors_um: &[f64],
    jacobian: Option<&mut dyn JacobianRows>,
) -> Result<Vec<f64>, CalibError> {
    match (&prepared.first_order, model.kind) {
        (Some((y0, j0)), ModelKind::FirstOrder) => {
            let e = nalgebra::DVector::from_column_slice(errors_um);
            let y = nalgebra::DVector::from_column_slice(y0) + j0 * e;
            if let Some(j) = jacobian {
                let mut row = vec![0.0; j0.ncols()];
                for r in 0..j0.nrows() {
                    row.iter_mut()
                        .zip(j0.row(r).iter())
                        .for_each(|(x, v)| *x = *v);
                    j.set_row(r, &row);
                }
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
    mut jacobian: Option<&mut dyn JacobianRows>,
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
    let channels = Channels::new(model, params);
    let mut y = vec![0.0; campaign.len()];
    let mut at = AtPose::new(n);
    // One Jacobian row, made here and written whole into the caller's storage.
    let mut row = vec![0.0; if jacobian.is_some() { np } else { 0 }];
    let input_at = |j: usize| EffectInput {
        context: &prepared.contexts[j],
        commanded: &campaign.poses[j],
        home: &model.nominal.home,
        settings: &model.effect_settings,
        t0_s: prepared.t0_s,
    };
    // Forward kinematics of every observed pose (the bulk of a prediction) first, in
    // parallel (each pose's own); the rest pose by pose in order, the first error in pose
    // order as before.
    let mut fks: Vec<Option<Result<Pose, cpm_kinematics::KinematicsError>>> = {
        use rayon::prelude::*;
        (0..prepared.by_pose.len())
            .into_par_iter()
            .with_min_len(64)
            .map_init(
                || AtPose::new(n),
                |at, j| {
                    if !prepared.observed_at(j) {
                        return None;
                    }
                    channels.at_pose(&input_at(j), &prepared.lengths_mm[j], at);
                    Some(forward(&table, &at.lengths, &campaign.poses[j], &model.fk).map(|r| r.0))
                },
            )
            .collect()
    };
    for (j, readings) in prepared.by_pose.iter().enumerate() {
        let measurements = &prepared.measurements_by_pose[j];
        let points = &prepared.points_by_pose[j];
        let tilts = &prepared.tilts_by_pose[j];
        let instruments = &prepared.instruments_by_pose[j];
        let Some(fk) = fks[j].take() else {
            continue;
        };
        let input = input_at(j);
        channels.at_pose(&input, &prepared.lengths_mm[j], &mut at);
        let fk = fk.map_err(|source| CalibError::Kinematics { pose: j, source })?;
        let pose = if at.twist == nalgebra::Vector6::zeros() {
            fk
        } else {
            fk.perturbed(&at.twist)
        };
        for &k in readings {
            let si = campaign.readings[k].sensor;
            y[k] = channels.reading(si, table.sensors[si].length_mm(&pose));
        }
        // The instruments see the pose reached: tracker poses (position in the session's
        // tracker frame, mm, and the rotation from the measured to the predicted orientation,
        // mrad), point targets (the target in its session's tracker frame, mm), inclinometers
        // (each axis's elevation, mrad), one's own.
        let seen = crate::model::instruments::InstrumentInput {
            pose: &pose,
            effect: input,
            up: channels.up,
        };
        let frame = if measurements.is_empty() {
            0
        } else {
            model.tracker_frame_of(campaign, j)?
        };
        // The tracker instrument of a pose measurement: its orientation residual is taken
        // against the measured orientation.
        let tracker_of = |q: usize| TrackerPoses {
            measured: campaign.pose_measurements[q].measured.rotation,
            ..channels.tracker_poses()
        };
        let mut values = [0.0; 6];
        for &q in measurements {
            let instrument = tracker_of(q);
            channels
                .tracker(&instrument)
                .predict(&seen, 0, frame, &mut values);
            for (a, row) in prepared.pose_rows[q].iter().enumerate() {
                if let Some(o) = row {
                    y[*o] = values[a];
                }
            }
        }
        let p0 = campaign.first_point_observation();
        let targets = channels.points();
        for &q in points {
            let pm = &campaign.point_measurements[q];
            let o = p0 + 3 * q;
            targets.predict(&seen, pm.target, pm.session, &mut y[o..o + 3]);
        }
        let t0 = campaign.first_tilt_observation();
        let inclinometers = channels.tilts();
        for &q in tilts {
            let t = &campaign.tilt_measurements[q];
            let c = channels.tilt_channel(t);
            inclinometers.predict(&seen, c, t.session, &mut y[t0 + q..t0 + q + 1]);
        }
        for &q in instruments {
            let m = &campaign.instrument_measurements[q];
            let o = prepared.instrument_rows[q];
            let bound = channels.instrument(m.instrument);
            let n = bound.instrument.num_values();
            bound.predict(&seen, m.channel, m.session, &mut y[o..o + n]);
        }
        if let Some(jac) = jacobian.as_deref_mut() {
            let kin = Kin::new(&table, &fk, &at, j);
            for &k in readings {
                let si = campaign.readings[k].sensor;
                channels.reading_row(&kin, &at, &table.sensors[si], si, &pose, &mut row)?;
                jac.set_row(k, &row);
            }
            if !measurements.is_empty()
                || !points.is_empty()
                || !tilts.is_empty()
                || !instruments.is_empty()
            {
                let dx = channels.twist_columns(&kin, &at, np)?;
                for &q in tilts {
                    let t = &campaign.tilt_measurements[q];
                    let c = channels.tilt_channel(t);
                    inclinometers.rows(&seen, c, t.session, &dx, jac, t0 + q, &mut row);
                }
                for &q in points {
                    let pm = &campaign.point_measurements[q];
                    targets.rows(&seen, pm.target, pm.session, &dx, jac, p0 + 3 * q, &mut row);
                }
                for &q in instruments {
                    let m = &campaign.instrument_measurements[q];
                    let bound = channels.instrument(m.instrument);
                    let o = prepared.instrument_rows[q];
                    bound.rows(&seen, m.channel, m.session, &dx, jac, o, &mut row);
                }
                for &q in measurements {
                    let instrument = tracker_of(q);
                    let rows = &prepared.pose_rows[q];
                    channels
                        .tracker(&instrument)
                        .rows_at(&seen, 0, frame, &dx, jac, rows, &mut row);
                }
            }
        }
    }
    Ok(y)
}

/// True when every observation of `campaign` is a tracker pose measured in full (six
/// components) at a pose whose link lengths were logged: the campaigns the leg-space
/// formulation ([`leg_residuals`]) applies to.
pub fn leg_space_applies(campaign: &Campaign) -> bool {
    !campaign.pose_measurements.is_empty()
        && campaign.readings.is_empty()
        && campaign.point_measurements.is_empty()
        && campaign.tilt_measurements.is_empty()
        && campaign.instrument_measurements.is_empty()
        && campaign
            .pose_observation_rows()
            .iter()
            .all(|rows| rows.iter().all(Option::is_some))
}

/// Leg-space residuals of the tracker pose measurements, mm: for each pose measurement (in
/// order) and link, the effective length of the commanded link (commanded, clearance and every
/// link effect at `params`) less the length the candidate joints need for the *measured* pose
/// (inverse kinematics of the measured pose taken into the base frame through the session's
/// tracker frame, the pose channel's twist undone). The same parameters as [`predict`]; the
/// formulation of an independent inverse-kinematics calibration, whose residuals are in the
/// legs' own unit and need no forward kinematics.
///
/// Only for a campaign where [`leg_space_applies`].
pub fn leg_residuals(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
    params: &[f64],
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
    let channels = Channels::new(model, params);
    let tracker = channels.tracker_poses();
    let block = model
        .blocks()
        .into_iter()
        .find(|b| b.effect == Some(Effect::TrackerFrame));
    let mut out = Vec::with_capacity(n * campaign.pose_measurements.len());
    let mut at = AtPose::new(n);
    let mut needed = vec![0.0; n];
    let (tm, rm) = tracker.marker_frame(&channels.marker_params());
    for pm in &campaign.pose_measurements {
        let j = pm.pose;
        let input = EffectInput {
            context: &prepared.contexts[j],
            commanded: &campaign.poses[j],
            home: &model.nominal.home,
            settings: &model.effect_settings,
            t0_s: prepared.t0_s,
        };
        channels.at_pose(&input, &prepared.lengths_mm[j], &mut at);
        // The session's frame: p_tracker = rr (kr p + kt) + rt.
        let (kt, kr) = tracker.known;
        let (rt, rr) = match block {
            Some(b) => {
                let f = model.tracker_frame_of(campaign, j)?;
                let q = &params[b.offset + 6 * f..b.offset + 6 * f + 6];
                tracker.frame.tracker_registration(q)
            }
            None => (nalgebra::Vector3::zeros(), nalgebra::Rotation3::identity()),
        };
        let m = &pm.measured;
        // The measured body in the base frame, then the platform under it: (p, R) with
        // (p + R t_m, R R_m) the body's pose.
        let body_rotation = kr.inverse() * rr.inverse() * m.rotation;
        let rotation = body_rotation * rm.inverse();
        let base = Pose::new(
            kr.inverse() * (rr.inverse() * (m.position_mm - rt) - kt) - rotation * tm,
            rotation,
        );
        let base = if at.twist == nalgebra::Vector6::zeros() {
            base
        } else {
            base.perturbed(&-at.twist)
        };
        cpm_kinematics::inverse_lengths_into(&table, &base, &mut needed);
        out.extend(at.lengths.iter().zip(&needed).map(|(l, nd)| l - nd));
    }
    Ok(out)
}

/// A campaign's predictions as a [`cpm_lm`] problem (residuals = predicted observations, mm;
/// parameters in the model's units): to check a model's Jacobian, a user effect's above all,
/// with [`cpm_lm::check_jacobian`].
pub struct Predictions<'a> {
    model: &'a MeasurementModel,
    prepared: Prepared,
    campaign: &'a Campaign,
}

impl<'a> Predictions<'a> {
    /// Prepares `campaign` for `model`.
    pub fn new(model: &'a MeasurementModel, campaign: &'a Campaign) -> Result<Self, CalibError> {
        Ok(Self {
            model,
            prepared: Prepared::new(model, campaign)?,
            campaign,
        })
    }
}

impl cpm_lm::Problem for Predictions<'_> {
    fn num_params(&self) -> usize {
        self.model.num_params()
    }
    fn num_residuals(&self) -> usize {
        self.campaign.len()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), cpm_lm::ModelError> {
        r.copy_from_slice(&predict(
            self.model,
            &self.prepared,
            self.campaign,
            x,
            None,
        )?);
        Ok(())
    }
}

impl cpm_lm::DenseJacobian for Predictions<'_> {
    fn jacobian(
        &mut self,
        x: &[f64],
        mut jac: cpm_lm::faer::MatMut<'_, f64>,
    ) -> Result<(), cpm_lm::ModelError> {
        // Straight into the solver's storage.
        predict_into(
            self.model,
            &self.prepared,
            self.campaign,
            x,
            Some(&mut jac as &mut dyn JacobianRows),
        )?;
        Ok(())
    }
}
