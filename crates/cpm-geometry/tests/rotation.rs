//! Rotations: `R = Rz(yaw) Ry(pitch) Rx(roll)` against hand-built matrices, round trips
//! rpy <-> matrix <-> quaternion, orthonormality, gimbal lock, exp/log.
use std::f64::consts::{FRAC_PI_2, PI};

use cpm_geometry::rotation::{
    exp, from_quaternion, from_rpy, log, quaternion, rot_x, rot_y, rot_z, rpy, try_from_matrix,
};
use cpm_geometry::strategies::{near_gimbal_lock, rotation3, rpy_angles, unit_quaternion};
use cpm_geometry::{GeometryError, Pose};
use nalgebra::{Matrix3, Rotation3, Vector3, Vector6};
use proptest::prelude::*;

fn max_diff(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    (a - b).abs().max()
}

/// Difference of two angles modulo 2 pi, in [0, pi].
fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(2.0 * PI);
    d.min(2.0 * PI - d)
}

fn assert_proper(r: &Rotation3<f64>) {
    let m = r.matrix();
    assert!(max_diff(&(m.transpose() * m), &Matrix3::identity()) < 1e-14);
    assert!((m.determinant() - 1.0).abs() < 1e-14);
}

#[test]
fn elementary_rotations_match_hand_built_matrices() {
    let d = 90f64.to_radians();
    // Roll 90 deg about x maps y to z and z to -y.
    let rx = from_rpy(d, 0.0, 0.0);
    assert!((rx * Vector3::y() - Vector3::z()).norm() < 1e-15);
    assert!((rx * Vector3::z() + Vector3::y()).norm() < 1e-15);
    // Pitch 90 deg about y maps z to x and x to -z.
    let ry = from_rpy(0.0, d, 0.0);
    assert!((ry * Vector3::z() - Vector3::x()).norm() < 1e-15);
    assert!((ry * Vector3::x() + Vector3::z()).norm() < 1e-15);
    // Yaw 90 deg about z maps x to y and y to -x.
    let rz = from_rpy(0.0, 0.0, d);
    assert!((rz * Vector3::x() - Vector3::y()).norm() < 1e-15);
    assert!((rz * Vector3::y() + Vector3::x()).norm() < 1e-15);

    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let hand_x = Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c);
    let hand_y = Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c);
    let hand_z = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    let a = 30f64.to_radians();
    assert!(max_diff(&rot_x(a), &hand_x) < 1e-15);
    assert!(max_diff(&rot_y(a), &hand_y) < 1e-15);
    assert!(max_diff(&rot_z(a), &hand_z) < 1e-15);
}

#[test]
fn order_is_rz_ry_rx_fixed_axes() {
    // Roll 90 then (fixed-axis) yaw 90: y -> z (roll) -> z (yaw leaves z): R y = z.
    let r = from_rpy(FRAC_PI_2, 0.0, FRAC_PI_2);
    assert!((r * Vector3::y() - Vector3::z()).norm() < 1e-15);
    // x -> x (roll) -> y (yaw).
    assert!((r * Vector3::x() - Vector3::y()).norm() < 1e-15);
    // The opposite order Rx Rz would send x to z instead.
    let wrong = rot_x(FRAC_PI_2) * rot_z(FRAC_PI_2);
    assert!((wrong * Vector3::x() - Vector3::z()).norm() < 1e-15);

    // A general triple against the product of the hand-built elementary matrices.
    let (a, b, g) = (0.3, -0.7, 2.1);
    let (ca, sa) = (f64::cos(a), f64::sin(a));
    let (cb, sb) = (f64::cos(b), f64::sin(b));
    let (cg, sg) = (f64::cos(g), f64::sin(g));
    // Closed form of Rz(g) Ry(b) Rx(a).
    let closed = Matrix3::new(
        cg * cb,
        cg * sb * sa - sg * ca,
        cg * sb * ca + sg * sa,
        sg * cb,
        sg * sb * sa + cg * ca,
        sg * sb * ca - cg * sa,
        -sb,
        cb * sa,
        cb * ca,
    );
    assert!(max_diff(from_rpy(a, b, g).matrix(), &closed) < 1e-15);
}

#[test]
fn degrees_in_files_radians_inside() {
    let p = Pose::from_xyz_rpy_deg([1.0, 2.0, 3.0], [10.0, -20.0, 30.0]);
    let q = Pose::from_xyz_rpy(
        1.0,
        2.0,
        3.0,
        10f64.to_radians(),
        -20f64.to_radians(),
        30f64.to_radians(),
    );
    assert_eq!(p, q);
    let back = p.rpy_deg();
    assert!((back[0] - 10.0).abs() < 1e-12);
    assert!((back[1] + 20.0).abs() < 1e-12);
    assert!((back[2] - 30.0).abs() < 1e-12);
}

#[test]
fn gimbal_lock_exact() {
    for sign in [1.0, -1.0] {
        let r = from_rpy(0.4, sign * FRAC_PI_2, -1.1);
        let (a, b, c) = rpy(&r);
        assert!(a.abs() < 1e-12, "roll {a}");
        assert!((b - sign * FRAC_PI_2).abs() < 1e-12);
        // Only yaw - roll (pitch +90) or yaw + roll (pitch -90) is defined.
        let expected = if sign > 0.0 { -1.1 - 0.4 } else { -1.1 + 0.4 };
        assert!(angle_diff(c, expected) < 1e-12, "yaw {c} vs {expected}");
        assert!(max_diff(from_rpy(a, b, c).matrix(), r.matrix()) < 1e-15);
    }
    // A hand-built gimbal-locked matrix: Ry(+90).
    let m = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
    let r = try_from_matrix(m, 1e-12).unwrap();
    assert_eq!(rpy(&r), (0.0, FRAC_PI_2, 0.0));
}

#[test]
fn not_a_rotation_is_rejected() {
    let m = Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0); // a reflection
    assert!(matches!(
        try_from_matrix(m, 1e-9),
        Err(GeometryError::NotARotation { .. })
    ));
    let mut m = Matrix3::identity();
    m[(0, 1)] = f64::NAN;
    assert!(try_from_matrix(m, 1e-9).is_err());
    assert!(matches!(
        from_quaternion(0.0, 0.0, 0.0, 0.0),
        Err(GeometryError::InvalidValue { .. })
    ));
    assert!(from_quaternion(f64::NAN, 0.0, 0.0, 1.0).is_err());
}

#[test]
fn log_at_pi_and_identity() {
    assert_eq!(log(&Rotation3::identity()), Vector3::zeros());
    for axis in [
        Vector3::x(),
        Vector3::y(),
        Vector3::z(),
        Vector3::new(1.0, -2.0, 0.5).normalize(),
    ] {
        let w = axis * PI;
        let l = log(&exp(&w));
        // At pi both signs of the axis are the same rotation.
        assert!((l - w).norm() < 1e-7 || (l + w).norm() < 1e-7, "{l} vs {w}");
        assert!(max_diff(exp(&l).matrix(), exp(&w).matrix()) < 1e-14);
    }
}

proptest! {
    #[test]
    fn rpy_matrix_round_trip((a, b, c) in rpy_angles()) {
        let r = from_rpy(a, b, c);
        assert_proper(&r);
        let (a2, b2, c2) = rpy(&r);
        prop_assert!(angle_diff(a, a2) < 1e-9, "roll {} vs {}", a, a2);
        prop_assert!((b - b2).abs() < 1e-9, "pitch {} vs {}", b, b2);
        prop_assert!(angle_diff(c, c2) < 1e-9, "yaw {} vs {}", c, c2);
        prop_assert!(max_diff(from_rpy(a2, b2, c2).matrix(), r.matrix()) < 1e-14);
    }

    #[test]
    fn matrix_rpy_round_trip_near_gimbal_lock(r in near_gimbal_lock()) {
        let (a, b, c) = rpy(&r);
        prop_assert!(a.is_finite() && b.is_finite() && c.is_finite());
        prop_assert!(b.abs() <= FRAC_PI_2);
        let back = from_rpy(a, b, c);
        assert_proper(&back);
        prop_assert!(max_diff(back.matrix(), r.matrix()) < 1e-14,
            "error {:e}", max_diff(back.matrix(), r.matrix()));
    }

    #[test]
    fn matrix_quaternion_round_trip(r in rotation3()) {
        let q = quaternion(&r);
        prop_assert!(q[0] >= 0.0);
        prop_assert!((q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-14);
        let back = from_quaternion(q[0], q[1], q[2], q[3]).unwrap();
        assert_proper(&back);
        prop_assert!(max_diff(back.matrix(), r.matrix()) < 1e-14);
    }

    #[test]
    fn quaternion_rpy_quaternion_round_trip(q in unit_quaternion()) {
        let r = from_quaternion(q[0], q[1], q[2], q[3]).unwrap();
        assert_proper(&r);
        let (a, b, c) = rpy(&r);
        let q2 = quaternion(&from_rpy(a, b, c));
        // w >= 0 fixes the sign except at w = 0 exactly.
        let d = q.iter().zip(&q2).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let d_neg = q.iter().zip(&q2).map(|(x, y)| (x + y).abs()).fold(0.0, f64::max);
        let err = if q[0] < 1e-12 { d.min(d_neg) } else { d };
        prop_assert!(err < 1e-13, "quaternion error {:e}", err);
    }

    #[test]
    fn exp_log_round_trip(w in prop::array::uniform3(-1.8..1.8f64), scale in -14.0..0.0f64) {
        let w = Vector3::from(w) * 10f64.powf(scale);
        prop_assume!(w.norm() < PI - 1e-6);
        let r = exp(&w);
        assert_proper(&r);
        let l = log(&r);
        prop_assert!((l - w).norm() <= 1e-15 * (1.0 + w.norm()) * 4.0, "{} vs {}", l, w);
    }

    #[test]
    fn log_of_any_rotation_is_its_inverse(r in rotation3()) {
        let w = log(&r);
        prop_assert!(w.norm() <= PI + 1e-12);
        prop_assert!(max_diff(exp(&w).matrix(), r.matrix()) < 1e-14);
    }

    #[test]
    fn difference_inverts_perturbed(
        r in rotation3(),
        t in prop::array::uniform3(-500.0..500.0f64),
        tw in prop::array::uniform6(-1.0..1.0f64),
        scale in -12.0..0.0f64,
    ) {
        let p = Pose::new(Vector3::from(t), r);
        let twist = Vector6::from(tw) * 10f64.powf(scale);
        let d = p.difference(&p.perturbed(&twist));
        prop_assert!((d.fixed_rows::<3>(0) - twist.fixed_rows::<3>(0)).norm() < 1e-12);
        prop_assert!((d.fixed_rows::<3>(3) - twist.fixed_rows::<3>(3)).norm()
            < 1e-15 * (1.0 + twist.fixed_rows::<3>(3).norm()) * 4.0);
    }
}
