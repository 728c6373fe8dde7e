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
//! `tracker_frame` (6 parameters: translation um, rotation urad) registers a tracker's frame in
//! the base frame; it acts on pose measurements only and brings 6 gauge freedoms with it (the
//! whole machine and the tracker frame moved or rotated together), which the identifiability
//! analysis names.
use serde::{Deserialize, Serialize};

/// A named effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
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
}

impl Effect {
    /// Every effect of the library, in a fixed order.
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

    /// The effect's name in files and on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::LinkOffset => "link_offset",
            Effect::LinkScale => "link_scale",
            Effect::LinkNonlinearity => "link_nonlinearity",
            Effect::SensorOffset => "sensor_offset",
            Effect::SensorScale => "sensor_scale",
            Effect::Clearance => "clearance",
            Effect::ThermalDrift => "thermal_drift",
            Effect::Backlash => "backlash",
            Effect::Compliance => "compliance",
            Effect::ScrewPeriodic => "screw_periodic",
            Effect::SocketError => "socket_error",
            Effect::TrackerFrame => "tracker_frame",
        }
    }

    /// Parses a name; the error lists the known names.
    pub fn parse(name: &str) -> Result<Effect, String> {
        Effect::ALL
            .iter()
            .copied()
            .find(|e| e.name() == name)
            .ok_or_else(|| {
                format!(
                    "unknown effect `{name}` (known: {})",
                    Effect::ALL.map(|e| e.name()).join(", ")
                )
            })
    }

    /// Number of parameters for a machine with `links` links and `sensors` sensors.
    pub fn num_params(&self, links: usize, sensors: usize) -> usize {
        match self {
            Effect::LinkOffset
            | Effect::LinkScale
            | Effect::ThermalDrift
            | Effect::Backlash
            | Effect::Compliance => links,
            Effect::LinkNonlinearity | Effect::ScrewPeriodic => 2 * links,
            Effect::SensorOffset | Effect::SensorScale => sensors,
            Effect::Clearance => 1,
            Effect::SocketError => 6 * sensors,
            Effect::TrackerFrame => 6,
        }
    }

    /// Unit of the parameters.
    pub fn unit(&self) -> &'static str {
        match self {
            Effect::LinkScale | Effect::SensorScale => "ppm",
            Effect::ThermalDrift => "ppm/K",
            Effect::Compliance => "um/kN",
            Effect::TrackerFrame => "um (translation), urad (rotation)",
            _ => "um",
        }
    }

    /// Unit of parameter `k`.
    pub fn param_unit(&self, k: usize) -> &'static str {
        match self {
            Effect::TrackerFrame if k >= 3 => "urad",
            Effect::TrackerFrame => "um",
            _ => self.unit(),
        }
    }

    /// Name of parameter `k` of this effect.
    pub fn param_name(&self, k: usize, sensor_names: &[String]) -> String {
        let sensor = |s: usize| {
            sensor_names
                .get(s)
                .cloned()
                .unwrap_or_else(|| format!("{}", s + 1))
        };
        match self {
            Effect::LinkNonlinearity => {
                format!("link {} {}", k / 2 + 1, ["quadratic", "cubic"][k % 2])
            }
            Effect::ScrewPeriodic => format!("link {} {}", k / 2 + 1, ["sin", "cos"][k % 2]),
            Effect::SensorOffset | Effect::SensorScale => format!("sensor {}", sensor(k)),
            Effect::Clearance => "radius".to_string(),
            Effect::SocketError => format!(
                "sensor {} {} {}",
                sensor(k / 6),
                if k % 6 < 3 { "base" } else { "platform" },
                ["dx", "dy", "dz"][k % 3]
            ),
            Effect::TrackerFrame => ["tx", "ty", "tz", "rx", "ry", "rz"][k].to_string(),
            _ => format!("link {}", k + 1),
        }
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
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
}

impl Default for EffectSettings {
    fn default() -> Self {
        Self {
            screw_lead_mm: 5.0,
            reference_temperature_c: 20.0,
            nonlinearity_scale_mm: 100.0,
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
pub fn link_coefficient(
    effect: Effect,
    k: usize,
    link: usize,
    ctx: &PoseContext,
    settings: &EffectSettings,
    t0_s: f64,
) -> f64 {
    let l = ctx.commanded_mm[link];
    match effect {
        Effect::LinkOffset if k == link => 1e-3,
        Effect::LinkScale if k == link => 1e-6 * l,
        Effect::LinkNonlinearity if k / 2 == link => {
            let u = (l - ctx.home_mm[link]) / settings.nonlinearity_scale_mm;
            1e-3 * if k.is_multiple_of(2) {
                u * u
            } else {
                u * u * u
            }
        }
        Effect::Clearance => {
            let t = ctx.forces_n[link];
            2e-3 * if t > 0.0 {
                1.0
            } else if t < 0.0 {
                -1.0
            } else {
                0.0
            }
        }
        Effect::ThermalDrift if k == link => 1e-6 * l * ctx.drift_variable(settings, t0_s),
        Effect::Backlash if k == link => 1e-3 * ctx.motion_sign[link],
        Effect::Compliance if k == link => 1e-3 * ctx.forces_n[link] / 1000.0,
        Effect::ScrewPeriodic if k / 2 == link => {
            let ph = std::f64::consts::TAU * l / settings.screw_lead_mm;
            1e-3 * if k.is_multiple_of(2) {
                ph.sin()
            } else {
                ph.cos()
            }
        }
        _ => 0.0,
    }
}

/// The `tracker_frame` registration of parameters `q` (tx, ty, tz um; rx, ry, rz urad): the
/// translation (mm) and rotation that take a point of the base frame into the tracker frame,
/// `p_tracker = R p + t`.
pub fn tracker_registration(q: &[f64]) -> (nalgebra::Vector3<f64>, nalgebra::Rotation3<f64>) {
    (
        nalgebra::Vector3::new(q[0], q[1], q[2]) * 1e-3,
        nalgebra::Rotation3::new(nalgebra::Vector3::new(q[3], q[4], q[5]) * 1e-6),
    )
}

/// True when the effect acts through the link channel.
pub fn is_link_effect(effect: Effect) -> bool {
    !matches!(
        effect,
        Effect::SensorOffset | Effect::SensorScale | Effect::SocketError | Effect::TrackerFrame
    )
}

/// Sensor-channel coefficient of parameter `k` of `effect` for a reading of `sensor` whose
/// predicted length is `length_mm`: mm of reading per unit of the parameter.
pub fn sensor_coefficient(effect: Effect, k: usize, sensor: usize, length_mm: f64) -> f64 {
    match effect {
        Effect::SensorOffset if k == sensor => 1e-3,
        Effect::SensorScale if k == sensor => 1e-6 * length_mm,
        _ => 0.0,
    }
}
