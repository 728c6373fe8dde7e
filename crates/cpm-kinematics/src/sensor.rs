//! Length-sensor readings and their sensitivity to the pose.
use cpm_geometry::{Pose, Sensor};
use nalgebra::Vector6;

/// The sensor length `|t + R p_s - b_s|` at `pose`, mm.
pub fn sensor_length_mm(sensor: &Sensor, pose: &Pose) -> f64 {
    sensor.length_mm(pose)
}

/// Gradient of the sensor length with respect to the pose twist `[dt; dw]` (base frame):
/// `[u^T, ((R p_s) x u)^T]` with `u` the unit vector from base to platform socket.
///
/// ```
/// use cpm_geometry::JointTable;
/// use cpm_kinematics::{sensor_length_mm, sensor_pose_gradient};
/// let t = JointTable::paper_cubic();
/// let s = t.sensor("paper").unwrap();
/// assert!((sensor_length_mm(s, &t.home) - 295f64.hypot(95.0)).abs() < 1e-12);
/// let g = sensor_pose_gradient(s, &t.home);
/// // The gauge runs along (0, -295, -95) from its base socket: it sees no x motion.
/// assert_eq!(g[0], 0.0);
/// assert!((g[1] + 295.0 / 295f64.hypot(95.0)).abs() < 1e-15);
/// ```
pub fn sensor_pose_gradient(sensor: &Sensor, pose: &Pose) -> Vector6<f64> {
    let s = pose.rotation * sensor.platform_mm;
    let q = pose.position_mm + s - sensor.base_mm;
    let u = q / q.norm();
    let m = s.cross(&u);
    Vector6::new(u.x, u.y, u.z, m.x, m.y, m.z)
}
