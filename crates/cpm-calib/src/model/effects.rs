//! The effect library: named blocks of extra parameters for what installation errors alone do
//! not explain (link offsets, actuator scale, sensor offset, thermal drift, backlash, ...).
//!
//! Every effect here acts through one of two channels, linearly in its parameters given the
//! pose context (commanded lengths, link forces, motion direction, time, temperature):
//! - **link channel**: a change of the effective link lengths, `dL_i = sum_p A_ip theta_p`,
//!   which moves the platform through forward kinematics (`dx = J1^-1 dL`);
//! - **sensor channel**: a change of the reading itself, `dy = sum_p B_p theta_p`.
//!
//! `socket_error` is the one geometric effect: it moves the sensor sockets, and the reading
//! changes through the socket gradient (`dy = -u . db_s + (R^T u) . dp_s`).
//!
//! | effect | parameters | physics | identifiable when |
//! |---|---|---|---|
//! | `link_offset` | 1 per link, um | constant length error (encoder zero, screw end) | the readings see each link's length change apart from joints moved along the link: needs orientation changes (a joint moved along its link mimics an offset only where the link direction is constant) |
//! | `link_scale` | 1 per link, ppm | screw lead / encoder scale: `dL = theta 1e-6 L` | link lengths vary over the campaign by a good fraction of their stroke |
//! | `link_nonlinearity` | 2 per link (quadratic, cubic), um | `dL = a u^2 + b u^3`, `u = (L - L_home) / 100 mm` | strokes large enough for curvature; orthogonal to offset and scale by construction only approximately |
//! | `sensor_offset` | 1 per sensor, um | gauge zero (ballbar calibration length) | always, unless confounded with the sockets' distance (it is, to first order, with socket moves along the gauge) |
//! | `sensor_scale` | 1 per sensor, ppm | gauge scale | sensor lengths vary over the campaign |
//! | `clearance` | 1, um | joint clearance radius correction: `dL_i = 2 theta sign(t_i)` | link forces change sign across the campaign, or the sign pattern differs between links |
//! | `thermal_drift` | 1 per link, ppm per deg C (or per hour without temperature) | `dL = theta 1e-6 L (T - T_0)` | temperature (or time) varies during the campaign, not in step with the poses |
//! | `backlash` | 1 per link, um | half the lost motion: `dL = theta s_i`, `s_i` = +1 after extending, -1 after retracting | poses are approached from both directions |
//! | `compliance` | 1 per link, um per kN | axial stretch under load: `dL = theta t_i / 1000` | link forces vary over the campaign (payload changes, large tilts) |
//! | `screw_periodic` | 2 per link (sin, cos), um | periodic screw error with the lead as period: `dL = a sin(2 pi L / lead) + b cos(2 pi L / lead)` | lengths sample the period densely (stroke steps not multiples of the lead) |
//! | `socket_error` | 6 per sensor (base xyz, platform xyz), um | socket positions off their nominal place | several poses with varied orientation; gauge freedoms as for joints |
//!
//! `pose_map_*` terms (6 parameters each: dx, dy, dz um, rx, ry, rz urad per unit of a monomial
//! in the commanded pose) act on the platform pose itself: see [`PoseTerm`] for when they are
//! identifiable and why they never extrapolate.
//!
//! `tracker_frame` (6 parameters: translation um, rotation urad) registers a tracker's frame in
//! the base frame; it acts on pose measurements only and brings 6 gauge freedoms with it (the
//! whole machine and the tracker frame moved or rotated together), which the identifiability
//! analysis names. `marker_frame` (the same six parameters, in the platform frame) places the
//! body the tracker measures on the platform (a motion-capture rigid body's origin sits
//! wherever its markers put it, millimetres from the design's platform frame); it brings the
//! six gauge freedoms of the platform joints moved or rotated together with it, and a fit to
//! tracker poses alone keeps that motion out of the joints (it is the marker's, not the
//! machine's).
//!
//! ## Effects as a trait
//! Every effect is a type implementing [`EffectModel`]: its name, parameter names and units,
//! the [`Channel`]s it acts through, and its coefficients (linear in its parameters) given a
//! pose's [`EffectInput`]. [`Effect`] is the copyable catalogue id the model, the files and the
//! command line use: the twelve built-ins, the pose-map terms, and user effects
//! ([`Effect::user`]: the effect carries its model; nothing is registered anywhere, and a
//! reader of files that name it is given it, [`Effect::parse_among`]). The measurement model
//! composes the channels, so a new effect is one type in one file:
//!
//! ```
//! use cpm_calib::effects::{Channel, EffectInput, EffectModel};
//! use cpm_calib::paper::{designed_sensors, random_workspace_poses};
//! use cpm_calib::{model::Predictions, *};
//!
//! /// Links that grow with the platform height: `dL_i = theta_i (z - z_home) / 100 mm`, um.
//! #[derive(Debug)]
//! struct HeightGrowth;
//! impl EffectModel for HeightGrowth {
//!     fn name(&self) -> &str { "height_growth" }
//!     fn num_params(&self, links: usize, _sensors: usize) -> usize { links }
//!     fn param_name(&self, k: usize, _: &[String]) -> String { format!("link {}", k + 1) }
//!     fn unit(&self) -> &str { "um" }
//!     fn channels(&self) -> &[Channel] { &[Channel::LinkLength] }
//!     fn link_coefficient(&self, k: usize, link: usize, input: &EffectInput) -> f64 {
//!         let dz = input.commanded.position_mm.z - input.home.position_mm.z;
//!         if k == link { 1e-3 * dz / 100.0 } else { 0.0 }
//!     }
//! }
//! static HEIGHT_GROWTH: HeightGrowth = HeightGrowth;
//! let effect = Effect::user(&HEIGHT_GROWTH).unwrap();
//! assert_eq!(Effect::parse_among("height_growth", &[effect]), Ok(effect));
//! assert!(Effect::parse("height_growth").is_err()); // nothing global knows it
//! let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
//! model.nominal.sensors = designed_sensors();
//! model.effects = vec![effect];
//! let poses = random_workspace_poses(&model.nominal, 30, 100.0, 25.0, 3.0, 7);
//! let skeleton = Plan { poses, sensors: (0..16).collect() }.skeleton();
//! let truth = [vec![0.0; 36], vec![20.0, -15.0, 10.0, 25.0, -20.0, 15.0]].concat();
//! // Its Jacobian against central differences (cpm-lm's checker, relative step 0.025).
//! let mut problem = Predictions::new(&model, &skeleton).unwrap();
//! let check = cpm_lm::check_jacobian(&mut problem, &truth, 0.025).unwrap();
//! assert!(check.is_consistent(1e-5), "{check}");
//! // Data that carry it: refine, offered it as a candidate, adds it.
//! let sim = SimulationOptions { noise: Noise::Gaussian { sigma_um: 2.0 }, repeats: 1, seed: 1 };
//! let data = simulate_campaign(&model, &truth, &skeleton, &sim).unwrap();
//! let mut options = RefineOptions { candidates: vec![Effect::LinkScale, effect], ..Default::default() };
//! options.identify.sigma_um = Some(2.0);
//! model.effects.clear();
//! let r = refine(&model, &data, &options).unwrap();
//! assert_eq!(r.steps[0].effect, effect);
//! ```

use cpm_geometry::Pose;
use nalgebra::{Rotation3, Vector3, Vector6};
use serde::{Deserialize, Serialize};

mod builtin;
pub(crate) mod instrument_blocks;
mod pose_map;

pub use builtin::*;
pub use instrument_blocks::{BaseTilt, InclinometerMount, PointFrame, TargetPosition};
pub use pose_map::{PoseMap, PoseTerm, POSE_ANGLE_SCALE_DEG, POSE_LENGTH_SCALE_MM};

/// A way an effect reaches the predicted observations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// The effective link lengths, `dL_i = sum_k c_ik theta_k` ([`EffectModel::link_coefficient`]):
    /// the platform moves through forward kinematics.
    LinkLength,
    /// The reading itself, `y = g (1 + sum_k a_k theta_k) + sum_k b_k theta_k` with `g` the
    /// geometric length ([`EffectModel::sensor_coefficients`]).
    SensorReading,
    /// The sensor sockets, moved by `sum_k (db_k, dp_k) theta_k`
    /// ([`EffectModel::socket_coefficients`]).
    SensorSocket,
    /// The platform pose after forward kinematics, moved by the twist `sum_k c_k theta_k`
    /// (translation mm, rotation rad, base frame; [`EffectModel::pose_coefficients`]).
    PlatformPose,
    /// The tracker frame: six parameters, translation (um) then rotation vector (urad), through
    /// [`EffectModel::tracker_registration`]; acts on pose measurements only.
    TrackerFrame,
    /// The frame the tracker measures on the platform (a motion-capture rigid body, a 6-D
    /// probe), in the platform frame: six parameters in the convention of
    /// [`TrackerFrame`](Channel::TrackerFrame); acts on pose measurements only.
    MarkerFrame,
}

/// What an effect may know about a pose.
#[derive(Debug, Clone, Copy)]
pub struct EffectInput<'a> {
    /// Commanded link lengths, forces, motion direction, temperature, time.
    pub context: &'a PoseContext,
    /// The commanded platform pose.
    pub commanded: &'a Pose,
    /// The machine's home pose.
    pub home: &'a Pose,
    /// Settings of the effects.
    pub settings: &'a EffectSettings,
    /// Start of the campaign's clock, s.
    pub t0_s: f64,
}

/// An effect: a named block of parameters and the channels it acts through. Coefficients are
/// per unit of a parameter, in mm (or rad, or per unit of reading for a sensor gain); every
/// channel but the tracker frame is linear in the parameters. Methods of channels the effect
/// does not list keep their default (zero).
pub trait EffectModel: std::fmt::Debug + Send + Sync {
    /// Name in files and on the command line (lower case, no spaces or commas).
    fn name(&self) -> &str;
    /// Number of parameters for a machine with `links` links and `sensors` sensors.
    fn num_params(&self, links: usize, sensors: usize) -> usize;
    /// Name of parameter `k` (`sensor_names` for effects per sensor).
    fn param_name(&self, k: usize, sensor_names: &[String]) -> String;
    /// Unit of the parameters, as shown in parameter names.
    fn unit(&self) -> &str;
    /// Unit of parameter `k`. Default: [`unit`](Self::unit).
    fn param_unit(&self, _k: usize) -> &str {
        self.unit()
    }
    /// The channels the effect acts through.
    fn channels(&self) -> &[Channel];
    /// True when the effect needs the axial link forces in [`PoseContext::forces_n`].
    fn needs_forces(&self) -> bool {
        false
    }
    /// Link length channel: mm of link `link`'s effective length per unit of parameter `k`.
    fn link_coefficient(&self, _k: usize, _link: usize, _input: &EffectInput) -> f64 {
        0.0
    }
    /// Sensor reading channel: (gain per unit, offset mm per unit) of parameter `k` on the
    /// readings of `sensor`.
    fn sensor_coefficients(&self, _k: usize, _sensor: usize) -> (f64, f64) {
        (0.0, 0.0)
    }
    /// Sensor socket channel: (base socket, platform socket) moves of `sensor` per unit of
    /// parameter `k`, mm (platform socket in platform coordinates).
    fn socket_coefficients(&self, _k: usize, _sensor: usize) -> (Vector3<f64>, Vector3<f64>) {
        (Vector3::zeros(), Vector3::zeros())
    }
    /// Platform pose channel: the twist (mm, rad; base frame) of the platform per unit of
    /// parameter `k` at a pose.
    fn pose_coefficients(&self, _k: usize, _input: &EffectInput) -> Vector6<f64> {
        Vector6::zeros()
    }
    /// Tracker frame channel: the registration `p_tracker = R p + t` (t in mm) for parameter
    /// values `q` (tx, ty, tz um; rx, ry, rz urad).
    fn tracker_registration(&self, q: &[f64]) -> (Vector3<f64>, Rotation3<f64>) {
        tracker_registration(q)
    }
}

/// A named effect: the copyable catalogue id of an [`EffectModel`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Effect {
    /// Constant length offset per link, um.
    LinkOffset,
    /// Actuator scale per link, ppm.
    LinkScale,
    /// Quadratic and cubic terms in the link length per link, um.
    LinkNonlinearity,
    /// Reading offset per sensor, um.
    SensorOffset,
    /// Reading scale per sensor, ppm.
    SensorScale,
    /// Correction of the clearance radius, um.
    Clearance,
    /// Link length drift per degree (or hour), ppm.
    ThermalDrift,
    /// Direction-dependent lost motion per link, um.
    Backlash,
    /// Axial compliance per link, um per kN.
    Compliance,
    /// Periodic screw error per link (sin, cos), um.
    ScrewPeriodic,
    /// Sensor socket position errors, um.
    SocketError,
    /// Registration of the tracker frame in the base frame: translation (um) and small
    /// rotation (urad); acts on pose measurements only.
    TrackerFrame,
    /// The frame a tracker measures on the platform (a motion-capture rigid body, a 6-D
    /// probe) in the platform frame: translation (um) and small rotation (urad); acts on pose
    /// measurements only. Not among [`Effect::ALL`]: a tracker fit adds it with
    /// `tracker_frame` (see [`Effect::TRACKER`]).
    MarkerFrame,
    /// The platform positions of the model's point targets (3 per target, um), sized by
    /// [`MeasurementModel::targets`](crate::MeasurementModel::targets); acts on point
    /// measurements only.
    TargetPosition,
    /// One tracker frame per point-measurement session (6 per session: translation um,
    /// rotation urad), sized by
    /// [`MeasurementModel::point_sessions`](crate::MeasurementModel::point_sessions); acts on
    /// point measurements only, and describes the session, not the machine.
    PointFrame,
    /// The mount rotation of each inclinometer on the platform (3 per inclinometer, urad),
    /// sized by [`MeasurementModel::inclinometers`](crate::MeasurementModel::inclinometers).
    InclinometerMount,
    /// The base's tilt against gravity per inclinometer session (2 per session: about x and
    /// y, urad), sized by
    /// [`MeasurementModel::tilt_sessions`](crate::MeasurementModel::tilt_sessions); describes
    /// the session (a machine is re-levelled), not the machine.
    BaseTilt,
    /// One term of the pose error map: a monomial in the commanded pose acting on the
    /// platform pose's six components.
    PoseMap(PoseTerm),
    /// A user effect ([`Effect::user`]): it carries its model, so it goes wherever the
    /// model's effects go, and a file names it only where its reader is given it
    /// ([`Effect::parse_among`]). Nothing global holds it.
    User(UserEffect),
}

/// A user effect's model, as an [`Effect`] carries it: a `'static` value of the user's (a
/// `static`, or a value the user owns for the program's life). Two are the same effect when
/// they have the same name.
#[derive(Clone, Copy)]
pub struct UserEffect(&'static dyn EffectModel);

impl UserEffect {
    /// The effect's model.
    pub fn model(&self) -> &'static dyn EffectModel {
        self.0
    }
}

impl PartialEq for UserEffect {
    fn eq(&self, other: &Self) -> bool {
        self.0.name() == other.0.name()
    }
}

impl Eq for UserEffect {}

impl std::hash::Hash for UserEffect {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        self.0.name().hash(h);
    }
}

impl std::fmt::Debug for UserEffect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "UserEffect({:?})", self.0.name())
    }
}

impl Effect {
    /// Every built-in effect of the library, in a fixed order (the pose map terms are a
    /// family apart: [`Effect::pose_maps`]).
    pub const ALL: [Effect; 12] = [
        Effect::LinkOffset,
        Effect::LinkScale,
        Effect::LinkNonlinearity,
        Effect::SensorOffset,
        Effect::SensorScale,
        Effect::Clearance,
        Effect::ThermalDrift,
        Effect::Backlash,
        Effect::Compliance,
        Effect::ScrewPeriodic,
        Effect::SocketError,
        Effect::TrackerFrame,
    ];

    /// The tracker's own unknowns that describe the machine's set-up rather than an effect:
    /// the measured body's frame on the platform ([`Effect::MarkerFrame`]).
    pub const TRACKER: [Effect; 1] = [Effect::MarkerFrame];

    /// The blocks of the instruments' own unknowns (sized by the model, not by the machine's
    /// links and sensors): point targets ([`Effect::TargetPosition`], [`Effect::PointFrame`])
    /// and inclinometers ([`Effect::InclinometerMount`], [`Effect::BaseTilt`]).
    pub const INSTRUMENTS: [Effect; 4] = [
        Effect::TargetPosition,
        Effect::PointFrame,
        Effect::InclinometerMount,
        Effect::BaseTilt,
    ];

    /// True for the blocks of an instrument ([`Effect::INSTRUMENTS`]).
    pub fn is_instrument(&self) -> bool {
        Effect::INSTRUMENTS.contains(self)
    }

    /// Every pose map term up to `degree` (at most 3), lowest degree first.
    pub fn pose_maps(degree: u8) -> Vec<Effect> {
        PoseTerm::all(degree)
            .into_iter()
            .map(Effect::PoseMap)
            .collect()
    }

    /// A user effect of `model` (a `static` of the user's, or a value that lives as long as
    /// the program, leaked on purpose in the user's own code). Fails when the name is a
    /// built-in's, a pose map term's, empty, or holds whitespace or a comma.
    ///
    /// Nothing is registered anywhere: the effect carries its model into the
    /// [`MeasurementModel`](crate::MeasurementModel) it is put in, and a reader of files
    /// that name it is given it ([`Effect::parse_among`]).
    pub fn user(model: &'static dyn EffectModel) -> Result<Effect, String> {
        let name = model.name();
        if name.is_empty() || name.contains(|c: char| c.is_whitespace() || c == ',') {
            return Err(format!(
                "effect name `{name}` must be non-empty, without spaces or commas"
            ));
        }
        if Effect::parse(name).is_ok() {
            return Err(format!(
                "effect name `{name}` is taken by a built-in effect"
            ));
        }
        Ok(Effect::User(UserEffect(model)))
    }

    /// The effect's model (its name, parameters, channels and coefficients).
    pub fn model(&self) -> &'static dyn EffectModel {
        match self {
            Effect::LinkOffset => &LinkOffset,
            Effect::LinkScale => &LinkScale,
            Effect::LinkNonlinearity => &LinkNonlinearity,
            Effect::SensorOffset => &SensorOffset,
            Effect::SensorScale => &SensorScale,
            Effect::Clearance => &Clearance,
            Effect::ThermalDrift => &ThermalDrift,
            Effect::Backlash => &Backlash,
            Effect::Compliance => &Compliance,
            Effect::ScrewPeriodic => &ScrewPeriodic,
            Effect::SocketError => &SocketError,
            Effect::TrackerFrame => &TrackerFrame,
            Effect::MarkerFrame => &MarkerFrame,
            Effect::TargetPosition => &TargetPosition,
            Effect::PointFrame => &PointFrame,
            Effect::InclinometerMount => &InclinometerMount,
            Effect::BaseTilt => &BaseTilt,
            Effect::PoseMap(t) => t.model(),
            Effect::User(u) => u.model(),
        }
    }

    /// The effect's name in files and on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::PoseMap(t) => t.name(),
            Effect::User(u) => u.model().name(),
            e => e.model().name(),
        }
    }

    /// Parses a name of the library's (a built-in, a pose map term such as `pose_map_y2` or
    /// `pose_map_x_roll`); the error lists the known names. User effects:
    /// [`Effect::parse_among`].
    pub fn parse(name: &str) -> Result<Effect, String> {
        Effect::parse_among(name, &[])
    }

    /// [`Effect::parse`], or one of the user effects among `user` by its name.
    pub fn parse_among(name: &str, user: &[Effect]) -> Result<Effect, String> {
        if let Some(e) = Effect::ALL
            .iter()
            .chain(&Effect::INSTRUMENTS)
            .chain(&Effect::TRACKER)
            .copied()
            .find(|e| e.name() == name)
        {
            return Ok(e);
        }
        if let Some(t) = PoseTerm::parse(name) {
            return Ok(Effect::PoseMap(t));
        }
        let users: Vec<Effect> = user
            .iter()
            .copied()
            .filter(|e| matches!(e, Effect::User(_)))
            .collect();
        if let Some(e) = users.iter().find(|e| e.name() == name) {
            return Ok(*e);
        }
        let users: Vec<&str> = users.iter().map(|e| e.name()).collect();
        Err(format!(
            "unknown effect `{name}` (known: {}, marker_frame, {}and pose map terms pose_map_<monomial> such as pose_map_y, pose_map_y2, pose_map_x_roll)",
            Effect::ALL.map(|e| e.name()).join(", "),
            if users.is_empty() {
                String::new()
            } else {
                format!("the user effects {}, ", users.join(", "))
            }
        ))
    }

    /// Number of parameters for a machine with `links` links and `sensors` sensors.
    pub fn num_params(&self, links: usize, sensors: usize) -> usize {
        self.model().num_params(links, sensors)
    }

    /// Unit of the parameters.
    pub fn unit(&self) -> &'static str {
        self.model().unit()
    }

    /// Unit of parameter `k`.
    pub fn param_unit(&self, k: usize) -> &'static str {
        self.model().param_unit(k)
    }

    /// Name of parameter `k` of this effect.
    pub fn param_name(&self, k: usize, sensor_names: &[String]) -> String {
        self.model().param_name(k, sensor_names)
    }

    /// True when the effect acts through `channel`.
    pub fn acts_through(&self, channel: Channel) -> bool {
        self.model().channels().contains(&channel)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Effect {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Effect {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        Effect::parse(&name).map_err(serde::de::Error::custom)
    }
}

/// Known values of an effect (a previous calibration's result): applied in every
/// prediction of a [`MeasurementModel`](crate::MeasurementModel), not estimated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KnownEffect {
    /// The effect.
    pub effect: Effect,
    /// One value per parameter, in the effect's units ([`Effect::param_unit`]) and
    /// parameter order ([`Effect::param_name`]).
    pub values: Vec<f64>,
}

/// Settings the effects need.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EffectSettings {
    /// Screw lead for `screw_periodic`, mm. Default 5.
    pub screw_lead_mm: f64,
    /// Reference temperature for `thermal_drift`, deg C. Default 20.
    pub reference_temperature_c: f64,
    /// Length scale of `link_nonlinearity`'s polynomial variable, mm. Default 100.
    pub nonlinearity_scale_mm: f64,
    /// Time origin of `thermal_drift` without temperatures, s: hours are counted from it.
    /// Default `None`: from the earliest logged time of the campaign predicted (which then
    /// depends on the part of a log given; a calibrated description declares it).
    pub reference_time_s: Option<f64>,
}

impl Default for EffectSettings {
    fn default() -> Self {
        Self {
            screw_lead_mm: 5.0,
            reference_temperature_c: 20.0,
            nonlinearity_scale_mm: 100.0,
            reference_time_s: None,
        }
    }
}

/// What an effect needs to know about a pose.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseContext {
    /// Commanded link lengths, mm.
    pub commanded_mm: Vec<f64>,
    /// Link lengths at home, mm (reference for the polynomial).
    pub home_mm: Vec<f64>,
    /// Axial link forces, N (tension positive).
    pub forces_n: Vec<f64>,
    /// Direction of the last motion of each link: +1 extending, -1 retracting, 0 unknown.
    pub motion_sign: Vec<f64>,
    /// Temperature, deg C, if logged.
    pub temperature_c: Option<f64>,
    /// Time, s, if logged.
    pub time_s: Option<f64>,
}

impl PoseContext {
    /// The drift variable of `thermal_drift`: temperature above the reference in K when
    /// logged, else hours since the start, else zero.
    pub fn drift_variable(&self, settings: &EffectSettings, t0_s: f64) -> f64 {
        match (self.temperature_c, self.time_s) {
            (Some(t), _) => t - settings.reference_temperature_c,
            (None, Some(s)) => (s - t0_s) / 3600.0,
            _ => 0.0,
        }
    }
}

/// Link-channel coefficient of parameter `k` of `effect` on link `link`: mm of effective
/// length per unit of the parameter (zero where the parameter does not touch that link).
/// The effect sees the identity as commanded and home pose: use
/// [`EffectModel::link_coefficient`] for effects that read the pose.
pub fn link_coefficient(
    effect: Effect,
    k: usize,
    link: usize,
    ctx: &PoseContext,
    settings: &EffectSettings,
    t0_s: f64,
) -> f64 {
    let pose = Pose::identity();
    effect.model().link_coefficient(
        k,
        link,
        &EffectInput {
            context: ctx,
            commanded: &pose,
            home: &pose,
            settings,
            t0_s,
        },
    )
}

/// The `tracker_frame` registration of parameters `q` (tx, ty, tz um; rx, ry, rz urad): the
/// translation (mm) and rotation that take a point of the base frame into the tracker frame,
/// `p_tracker = R p + t`.
pub fn tracker_registration(q: &[f64]) -> (Vector3<f64>, Rotation3<f64>) {
    (
        Vector3::new(q[0], q[1], q[2]) * 1e-3,
        Rotation3::new(Vector3::new(q[3], q[4], q[5]) * 1e-6),
    )
}

/// The parameters (tx, ty, tz um; rx, ry, rz urad) of a frame `(t mm, R)`: the inverse of
/// [`tracker_registration`].
pub fn frame_params(t: &Vector3<f64>, r: &Rotation3<f64>) -> [f64; 6] {
    let w = cpm_geometry::rotation::log(r);
    [
        t.x * 1e3,
        t.y * 1e3,
        t.z * 1e3,
        w.x * 1e6,
        w.y * 1e6,
        w.z * 1e6,
    ]
}

/// True when the effect acts through the link channel.
pub fn is_link_effect(effect: Effect) -> bool {
    effect.acts_through(Channel::LinkLength)
}

/// Sensor-channel coefficient of parameter `k` of `effect` for a reading of `sensor` whose
/// predicted length is `length_mm`: mm of reading per unit of the parameter.
pub fn sensor_coefficient(effect: Effect, k: usize, sensor: usize, length_mm: f64) -> f64 {
    let (gain, offset) = effect.model().sensor_coefficients(k, sensor);
    gain * length_mm + offset
}
