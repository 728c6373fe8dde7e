//! Proptest strategies for geometry types, for reuse by downstream crates.
use proptest::prelude::*;

use crate::Pose;

/// Poses within `+-dpos_mm` and `+-dang_deg` (roll, pitch, yaw) of `centre`.
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

/// Any rotation, from uniformly drawn roll, yaw in (-pi, pi] and pitch in (-pi/2, pi/2).
pub fn rotation3() -> impl Strategy<Value = nalgebra::Rotation3<f64>> {
    use std::f64::consts::{FRAC_PI_2, PI};
    (-PI..PI, -FRAC_PI_2 + 1e-6..FRAC_PI_2 - 1e-6, -PI..PI)
        .prop_map(|(a, b, c)| crate::rotation::from_rpy(a, b, c))
}
