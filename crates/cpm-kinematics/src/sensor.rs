//! Length-sensor readings and their sensitivity to the pose.
use cpm_geometry::{Pose, Sensor};
use nalgebra::Vector6;

/// The sensor length `|t + R p_s - b_s|` at `pose`, mm.
pub fn sensor_length_mm(sensor: &Sensor, pose: &Pose) -> f64 {
    sensor.length_mm(pose)
}

/// Gradient of the sensor length with respect to the pose twist `[dt; dw]` (base frame):
/// `[u^T, ((R p_s) x u)^T]` with `u` the unit vector from base to platform socket.
pub fn sensor_pose_gradient(sensor: &Sensor, pose: &Pose) -> Vector6<f64> {
    let s = pose.rotation * sensor.platform_mm;
    let q = pose.position_mm + s - sensor.base_mm;
    let u = q / q.norm();
    let m = s.cross(&u);
    Vector6::new(u.x, u.y, u.z, m.x, m.y, m.z)
}
