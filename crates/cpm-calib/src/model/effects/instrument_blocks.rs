//! The effects sized by the model's instruments rather than by its links and sensors: point
//! targets' positions and their sessions' tracker frames ([`crate::points`]), inclinometer
//! mounts and the base tilt of their sessions ([`crate::tilts`]). One type each, as the
//! built-in effects; the instruments' own modules predict through them.
use super::builtin::{frame_param_unit, FRAME_UNIT};
use super::{Channel, EffectModel};

pub(crate) const AXES: [&str; 3] = ["x", "y", "z"];
pub(crate) const FRAME: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];

/// `target_position`: each target's platform position, x y z um per target (sized by the
/// model's [`targets`](crate::MeasurementModel::targets)).
#[derive(Debug, Clone, Copy)]
pub struct TargetPosition;
impl EffectModel for TargetPosition {
    fn name(&self) -> &str {
        "target_position"
    }
    /// Sized by the model ([`crate::MeasurementModel::blocks`]), not by links and sensors.
    fn num_params(&self, _: usize, _: usize) -> usize {
        0
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        format!("target {} {}", k / 3 + 1, AXES[k % 3])
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[]
    }
}

/// `point_frame`: the tracker frame of each point-measurement session, tx ty tz um, rx ry rz
/// urad per session (sized by the model's [`point_sessions`](crate::MeasurementModel::point_sessions)).
#[derive(Debug, Clone, Copy)]
pub struct PointFrame;
impl EffectModel for PointFrame {
    fn name(&self) -> &str {
        "point_frame"
    }
    /// Sized by the model ([`crate::MeasurementModel::blocks`]), not by links and sensors.
    fn num_params(&self, _: usize, _: usize) -> usize {
        0
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        format!("session {} {}", k / 6 + 1, FRAME[k % 6])
    }
    fn unit(&self) -> &str {
        FRAME_UNIT
    }
    fn param_unit(&self, k: usize) -> &str {
        frame_param_unit(k)
    }
    fn channels(&self) -> &[Channel] {
        &[]
    }
}

pub(crate) const ROT: [&str; 3] = ["rx", "ry", "rz"];

/// `inclinometer_mount`: each inclinometer's mount rotation on the platform, rx ry rz urad
/// per instrument (a rotation vector in {P}, on top of the known mount).
#[derive(Debug, Clone, Copy)]
pub struct InclinometerMount;
impl EffectModel for InclinometerMount {
    fn name(&self) -> &str {
        "inclinometer_mount"
    }
    /// Sized by the model ([`crate::MeasurementModel::blocks`]), not by links and sensors.
    fn num_params(&self, _: usize, _: usize) -> usize {
        0
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        format!("inclinometer {} {}", k / 3 + 1, ROT[k % 3])
    }
    fn unit(&self) -> &str {
        "urad"
    }
    fn channels(&self) -> &[Channel] {
        &[]
    }
}

/// `base_tilt`: the base's tilt against gravity per inclinometer session, rx ry urad (a
/// rotation of gravity's up in the base frame).
#[derive(Debug, Clone, Copy)]
pub struct BaseTilt;
impl EffectModel for BaseTilt {
    fn name(&self) -> &str {
        "base_tilt"
    }
    /// Sized by the model ([`crate::MeasurementModel::blocks`]), not by links and sensors.
    fn num_params(&self, _: usize, _: usize) -> usize {
        0
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        format!("session {} {}", k / 2 + 1, ROT[k % 2])
    }
    fn unit(&self) -> &str {
        "urad"
    }
    fn channels(&self) -> &[Channel] {
        &[]
    }
}
