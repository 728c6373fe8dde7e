//! Proptest strategies for geometry types, for reuse by downstream crates.
use std::f64::consts::{FRAC_PI_2, PI};

use proptest::prelude::*;

use crate::{InstallationErrors, Pose};

/// Poses within `+-dpos_mm` and `+-dang_deg` (roll, pitch, yaw) of `centre`.
///
/// The position offset is added in {B}; the rotation `Rz Ry Rx` of the drawn angles is applied
/// before `centre`'s (in {B}), so the pose is `centre` moved and turned about {B}'s axes.
pub fn pose_near(centre: Pose, dpos_mm: f64, dang_deg: f64) -> impl Strategy<Value = Pose> {
    let a = dang_deg.to_radians();
    (
        prop::array::uniform3(-dpos_mm..=dpos_mm),
        prop::array::uniform3(-a..=a),
    )
        .prop_map(move |(p, r)| {
            let rot = crate::rotation::from_rpy(r[0], r[1], r[2]);
            Pose::new(
                centre.position_mm + nalgebra::Vector3::from(p),
                rot * centre.rotation,
            )
        })
}

/// Roll, pitch, yaw (radians) in the canonical range of [`crate::rotation::rpy`]: roll and
/// yaw in [-pi, pi), pitch in (-pi/2, pi/2) kept `1e-6` away from gimbal lock.
pub fn rpy_angles() -> impl Strategy<Value = (f64, f64, f64)> {
    (-PI..PI, -FRAC_PI_2 + 1e-6..FRAC_PI_2 - 1e-6, -PI..PI)
}

/// Any rotation, from uniformly drawn roll, yaw in (-pi, pi] and pitch in (-pi/2, pi/2).
pub fn rotation3() -> impl Strategy<Value = nalgebra::Rotation3<f64>> {
    rpy_angles().prop_map(|(a, b, c)| crate::rotation::from_rpy(a, b, c))
}

/// Rotations at or within `1e-3` rad of gimbal lock (pitch = +-pi/2), including exactly
/// +-pi/2 and offsets down to `1e-15` rad.
pub fn near_gimbal_lock() -> impl Strategy<Value = nalgebra::Rotation3<f64>> {
    (
        -PI..PI,
        prop::bool::ANY,
        prop_oneof![Just(0.0), -15.0..-3.0f64],
        -PI..PI,
    )
        .prop_map(|(roll, up, log_off, yaw)| {
            let off = if log_off == 0.0 {
                0.0
            } else {
                10f64.powf(log_off)
            };
            let pitch = if up {
                FRAC_PI_2 - off
            } else {
                -FRAC_PI_2 + off
            };
            crate::rotation::from_rpy(roll, pitch, yaw)
        })
}

/// Unit quaternions `(w, x, y, z)` with `w >= 0`, drawn as normalised Gaussian-like 4-vectors.
pub fn unit_quaternion() -> impl Strategy<Value = [f64; 4]> {
    prop::array::uniform4(-1.0..1.0f64)
        .prop_filter("need a usable norm", |q| {
            q.iter().map(|v| v * v).sum::<f64>() > 1e-2
        })
        .prop_map(|q| {
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            let s = if q[0] < 0.0 { -1.0 / n } else { 1.0 / n };
            q.map(|v| v * s)
        })
}

/// Installation errors for `links` links, every component in `+-max_um`.
pub fn installation_errors(links: usize, max_um: f64) -> impl Strategy<Value = InstallationErrors> {
    prop::collection::vec(-max_um..=max_um, 6 * links).prop_map(|v| {
        InstallationErrors::try_from_vec_um(&v).expect("6 components per link by construction")
    })
}
