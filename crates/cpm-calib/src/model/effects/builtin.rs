//! The built-in effects: one type each, implementing [`EffectModel`].
use nalgebra::Vector3;

use super::{Channel, EffectInput, EffectModel};

fn link_name(k: usize) -> String {
    format!("link {}", k + 1)
}

fn sensor_name(s: usize, sensor_names: &[String]) -> String {
    sensor_names
        .get(s)
        .cloned()
        .unwrap_or_else(|| format!("{}", s + 1))
}

/// The unit of a rigid frame's six parameters (translation, then rotation vector).
pub(crate) const FRAME_UNIT: &str = "um (translation), urad (rotation)";

/// The unit of parameter `k` of a rigid frame: um for tx ty tz, urad for rx ry rz.
pub(crate) fn frame_param_unit(k: usize) -> &'static str {
    if k % 6 >= 3 {
        "urad"
    } else {
        "um"
    }
}

fn sign(t: f64) -> f64 {
    if t > 0.0 {
        1.0
    } else if t < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// One parameter per link acting on that link's length alone: the type, its name, unit, and
/// the length change per unit of the parameter (mm) of link `link` given the pose's input.
macro_rules! per_link_effect {
    ($(#[$doc:meta])* $ty:ident, $name:literal, $unit:literal, forces: $forces:literal,
     |$link:ident, $input:ident| $coefficient:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy)]
        pub struct $ty;
        impl EffectModel for $ty {
            fn name(&self) -> &str {
                $name
            }
            fn num_params(&self, links: usize, _: usize) -> usize {
                links
            }
            fn param_name(&self, k: usize, _: &[String]) -> String {
                link_name(k)
            }
            fn unit(&self) -> &str {
                $unit
            }
            fn channels(&self) -> &[Channel] {
                &[Channel::LinkLength]
            }
            fn needs_forces(&self) -> bool {
                $forces
            }
            fn link_coefficient(&self, k: usize, $link: usize, $input: &EffectInput) -> f64 {
                if k == $link {
                    $coefficient
                } else {
                    0.0
                }
            }
        }
    };
}

per_link_effect!(
    /// `link_offset`: constant length error per link, um.
    LinkOffset, "link_offset", "um", forces: false, |_link, _input| 1e-3
);

per_link_effect!(
    /// `link_scale`: actuator scale per link, `dL = theta 1e-6 L`, ppm.
    LinkScale, "link_scale", "ppm", forces: false,
    |link, input| 1e-6 * input.context.commanded_mm[link]
);

/// `link_nonlinearity`: `dL = a u^2 + b u^3`, `u = (L - L_home) / scale`, um.
#[derive(Debug, Clone, Copy)]
pub struct LinkNonlinearity;
impl EffectModel for LinkNonlinearity {
    fn name(&self) -> &str {
        "link_nonlinearity"
    }
    fn num_params(&self, links: usize, _: usize) -> usize {
        2 * links
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        format!("link {} {}", k / 2 + 1, ["quadratic", "cubic"][k % 2])
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::LinkLength]
    }
    fn link_coefficient(&self, k: usize, link: usize, input: &EffectInput) -> f64 {
        if k / 2 != link {
            return 0.0;
        }
        let ctx = input.context;
        let u = (ctx.commanded_mm[link] - ctx.home_mm[link]) / input.settings.nonlinearity_scale_mm;
        1e-3 * if k.is_multiple_of(2) {
            u * u
        } else {
            u * u * u
        }
    }
}

/// `sensor_offset`: reading offset per sensor, um.
#[derive(Debug, Clone, Copy)]
pub struct SensorOffset;
impl EffectModel for SensorOffset {
    fn name(&self) -> &str {
        "sensor_offset"
    }
    fn num_params(&self, _: usize, sensors: usize) -> usize {
        sensors
    }
    fn param_name(&self, k: usize, names: &[String]) -> String {
        format!("sensor {}", sensor_name(k, names))
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::SensorReading]
    }
    fn sensor_coefficients(&self, k: usize, sensor: usize) -> (f64, f64) {
        (0.0, if k == sensor { 1e-3 } else { 0.0 })
    }
}

/// `sensor_scale`: reading scale per sensor, ppm.
#[derive(Debug, Clone, Copy)]
pub struct SensorScale;
impl EffectModel for SensorScale {
    fn name(&self) -> &str {
        "sensor_scale"
    }
    fn num_params(&self, _: usize, sensors: usize) -> usize {
        sensors
    }
    fn param_name(&self, k: usize, names: &[String]) -> String {
        format!("sensor {}", sensor_name(k, names))
    }
    fn unit(&self) -> &str {
        "ppm"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::SensorReading]
    }
    fn sensor_coefficients(&self, k: usize, sensor: usize) -> (f64, f64) {
        (if k == sensor { 1e-6 } else { 0.0 }, 0.0)
    }
}

/// `clearance`: correction of the joint clearance radius, `dL_i = 2 theta sign(t_i)`, um.
#[derive(Debug, Clone, Copy)]
pub struct Clearance;
impl EffectModel for Clearance {
    fn name(&self) -> &str {
        "clearance"
    }
    fn num_params(&self, _: usize, _: usize) -> usize {
        1
    }
    fn param_name(&self, _: usize, _: &[String]) -> String {
        "radius".to_string()
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::LinkLength]
    }
    fn needs_forces(&self) -> bool {
        true
    }
    fn link_coefficient(&self, _: usize, link: usize, input: &EffectInput) -> f64 {
        2e-3 * sign(input.context.forces_n[link])
    }
}

per_link_effect!(
    /// `thermal_drift`: `dL = theta 1e-6 L (T - T_0)` (or hours without temperature), ppm/K.
    ThermalDrift, "thermal_drift", "ppm/K", forces: false,
    |link, input| {
        let ctx = input.context;
        1e-6 * ctx.commanded_mm[link] * ctx.drift_variable(input.settings, input.t0_s)
    }
);

per_link_effect!(
    /// `backlash`: half the lost motion per link, `dL = theta s_i`, um.
    Backlash, "backlash", "um", forces: false,
    |link, input| 1e-3 * input.context.motion_sign[link]
);

per_link_effect!(
    /// `compliance`: axial stretch under load, `dL = theta t_i / 1000`, um per kN.
    Compliance, "compliance", "um/kN", forces: true,
    |link, input| 1e-3 * input.context.forces_n[link] / 1000.0
);

/// `screw_periodic`: `dL = a sin(2 pi L / lead) + b cos(2 pi L / lead)`, um.
#[derive(Debug, Clone, Copy)]
pub struct ScrewPeriodic;
impl EffectModel for ScrewPeriodic {
    fn name(&self) -> &str {
        "screw_periodic"
    }
    fn num_params(&self, links: usize, _: usize) -> usize {
        2 * links
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        format!("link {} {}", k / 2 + 1, ["sin", "cos"][k % 2])
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::LinkLength]
    }
    fn link_coefficient(&self, k: usize, link: usize, input: &EffectInput) -> f64 {
        if k / 2 != link {
            return 0.0;
        }
        let ph =
            std::f64::consts::TAU * input.context.commanded_mm[link] / input.settings.screw_lead_mm;
        1e-3 * if k.is_multiple_of(2) {
            ph.sin()
        } else {
            ph.cos()
        }
    }
}

/// `socket_error`: sensor socket positions, 6 per sensor (base xyz, platform xyz), um.
#[derive(Debug, Clone, Copy)]
pub struct SocketError;
impl EffectModel for SocketError {
    fn name(&self) -> &str {
        "socket_error"
    }
    fn num_params(&self, _: usize, sensors: usize) -> usize {
        6 * sensors
    }
    fn param_name(&self, k: usize, names: &[String]) -> String {
        format!(
            "sensor {} {} {}",
            sensor_name(k / 6, names),
            if k % 6 < 3 { "base" } else { "platform" },
            ["dx", "dy", "dz"][k % 3]
        )
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::SensorSocket]
    }
    fn socket_coefficients(&self, k: usize, sensor: usize) -> (Vector3<f64>, Vector3<f64>) {
        let mut d = (Vector3::zeros(), Vector3::zeros());
        if k / 6 == sensor {
            if k % 6 < 3 {
                d.0[k % 3] = 1e-3;
            } else {
                d.1[k % 3] = 1e-3;
            }
        }
        d
    }
}

/// `tracker_frame`: the tracker's frame in the base frame, translation um, rotation urad.
#[derive(Debug, Clone, Copy)]
pub struct TrackerFrame;
impl EffectModel for TrackerFrame {
    fn name(&self) -> &str {
        "tracker_frame"
    }
    fn num_params(&self, _: usize, _: usize) -> usize {
        6
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        // Six per frame (one frame per session when the model has several).
        ["tx", "ty", "tz", "rx", "ry", "rz"][k % 6].to_string()
    }
    fn unit(&self) -> &str {
        FRAME_UNIT
    }
    fn param_unit(&self, k: usize) -> &str {
        frame_param_unit(k)
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::TrackerFrame]
    }
}

/// `marker_frame`: the frame a tracker measures on the platform (a motion-capture rigid body,
/// a 6-D probe) in the platform frame, translation um, rotation urad: the measured pose is the
/// platform's composed with it. Its six parameters and the platform joints moved or rotated
/// together are the same data (six gauge freedoms, named by the identifiability analysis).
#[derive(Debug, Clone, Copy)]
pub struct MarkerFrame;
impl EffectModel for MarkerFrame {
    fn name(&self) -> &str {
        "marker_frame"
    }
    fn num_params(&self, _: usize, _: usize) -> usize {
        6
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        ["tx", "ty", "tz", "rx", "ry", "rz"][k % 6].to_string()
    }
    fn unit(&self) -> &str {
        FRAME_UNIT
    }
    fn param_unit(&self, k: usize) -> &str {
        frame_param_unit(k)
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::MarkerFrame]
    }
}
