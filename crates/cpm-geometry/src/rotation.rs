//! Roll-pitch-yaw rotations `R = Rz(yaw) Ry(pitch) Rx(roll)` and conversions.
//!
//! The paper (Lim et al. 2002) describes its eq. 1 as a rotation about the fixed x axis by
//! alpha (roll), then the fixed y axis by beta (pitch), then the fixed z axis by gamma (yaw),
//! i.e. `R = Rz(gamma) Ry(beta) Rx(alpha)`. The printed matrix of eq. 1 has typos (alpha where
//! gamma belongs); this module follows the text, which is also what the paper's numbers need.
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use crate::GeometryError;

/// Rotation about the x axis by `a` radians.
pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Rotation about the y axis by `a` radians.
pub fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// Rotation about the z axis by `a` radians.
pub fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// `R = Rz(yaw) Ry(pitch) Rx(roll)`, angles in radians.
///
/// ```
/// use cpm_geometry::rotation::{from_rpy, rpy};
/// let r = from_rpy(0.1, -0.2, 0.3);
/// let (a, b, c) = rpy(&r);
/// assert!((a - 0.1).abs() < 1e-14 && (b + 0.2).abs() < 1e-14 && (c - 0.3).abs() < 1e-14);
/// ```
pub fn from_rpy(roll: f64, pitch: f64, yaw: f64) -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(rot_z(yaw) * rot_y(pitch) * rot_x(roll))
}

/// Roll, pitch, yaw (radians) of `R = Rz(yaw) Ry(pitch) Rx(roll)`; pitch in [-pi/2, pi/2],
/// roll and yaw in [-pi, pi].
///
/// At pitch = +-pi/2 (gimbal lock) only `yaw - roll` (pitch +pi/2) or `yaw + roll`
/// (pitch -pi/2) is defined: roll comes out as zero (to rounding) and yaw carries the rotation.
///
/// The extraction is stable everywhere, including close to gimbal lock: pitch comes from
/// `atan2` (not `asin`, which loses half the digits near +-pi/2) and roll is computed after
/// removing the extracted yaw, so `from_rpy(rpy(R))` reproduces `R` to rounding even when the
/// individual angles are ill-determined.
///
/// ```
/// use cpm_geometry::rotation::{from_rpy, rpy};
/// use std::f64::consts::FRAC_PI_2;
/// // Gimbal lock: pitch = 90 deg, only yaw - roll = 0.2 matters.
/// let r = from_rpy(0.3, FRAC_PI_2, 0.5);
/// let (a, b, c) = rpy(&r);
/// assert!(a.abs() < 1e-12 && (b - FRAC_PI_2).abs() < 1e-12 && (c - 0.2).abs() < 1e-12);
/// assert!((from_rpy(a, b, c).matrix() - r.matrix()).abs().max() < 1e-14);
/// ```
pub fn rpy(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    // First column of R is (cp cy, cp sy, -sp).
    let cp = m[(0, 0)].hypot(m[(1, 0)]);
    let pitch = (-m[(2, 0)]).atan2(cp);
    let yaw = if cp > 1e-15 {
        m[(1, 0)].atan2(m[(0, 0)])
    } else {
        // Gimbal lock: R = Rz(yaw -+ roll) Ry(+-pi/2); choose roll = 0.
        (-m[(0, 1)]).atan2(m[(1, 1)])
    };
    // Row 1 of Rz(-yaw) R = Ry(pitch) Rx(roll) is (0, cos roll, -sin roll).
    let (sy, cy) = yaw.sin_cos();
    let c = -sy * m[(0, 1)] + cy * m[(1, 1)];
    let s = sy * m[(0, 2)] - cy * m[(1, 2)];
    let roll = s.atan2(c);
    (roll, pitch, yaw)
}

/// Checks that `m` is a proper rotation (orthonormal to `tol`, det +1) and wraps it.
pub fn try_from_matrix(m: Matrix3<f64>, tol: f64) -> Result<Rotation3<f64>, GeometryError> {
    let err = (m.transpose() * m - Matrix3::identity()).abs().max();
    let det = m.determinant();
    // Written so that NaN fails the check.
    let proper = err <= tol && (det - 1.0).abs() <= tol;
    if !proper {
        return Err(GeometryError::NotARotation {
            orthonormality_error: err,
            det,
        });
    }
    Ok(Rotation3::from_matrix_unchecked(m))
}

/// Rotation from a unit quaternion (w, x, y, z); the quaternion is normalised first.
pub fn from_quaternion(w: f64, x: f64, y: f64, z: f64) -> Result<Rotation3<f64>, GeometryError> {
    let n = (w * w + x * x + y * y + z * z).sqrt();
    if !(n.is_finite() && n > 1e-12) {
        return Err(GeometryError::InvalidValue {
            field: "quaternion".into(),
            value: n,
            why: "norm must be finite and non-zero".into(),
        });
    }
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    Ok(q.to_rotation_matrix())
}

/// The unit quaternion (w, x, y, z) of a rotation, with w >= 0.
pub fn quaternion(r: &Rotation3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(r);
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// Exponential map: the rotation by angle |w| about axis w/|w| (radians).
pub fn exp(w: &nalgebra::Vector3<f64>) -> Rotation3<f64> {
    Rotation3::new(*w)
}

/// Left Jacobian of SO(3) at rotation vector `w` (radians): `exp(w + d) = exp(J_l d) exp(w)`
/// to first order in `d`.
///
/// ```
/// use cpm_geometry::rotation::{exp, left_jacobian, log};
/// use nalgebra::Vector3;
/// let (w, d) = (Vector3::new(0.3, -0.2, 0.5), Vector3::new(1e-7, 2e-7, -1e-7));
/// let by_map = log(&(exp(&(w + d)) * exp(&w).inverse()));
/// assert!((by_map - left_jacobian(&w) * d).norm() < 1e-13);
/// ```
pub fn left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let th = w.norm();
    let k = w.cross_matrix();
    let i = Matrix3::identity();
    if th < 1e-8 {
        return i + k * 0.5 + k * k / 6.0;
    }
    i + k * ((1.0 - th.cos()) / (th * th)) + k * k * ((th - th.sin()) / (th * th * th))
}

/// Inverse of the left Jacobian of SO(3) at rotation vector `w`:
/// `d log(exp(d) exp(w)) / dd` at `d = 0`.
///
/// ```
/// use cpm_geometry::rotation::{left_jacobian, left_jacobian_inverse};
/// use nalgebra::{Matrix3, Vector3};
/// let w = Vector3::new(0.3, -0.2, 0.5);
/// assert!((left_jacobian_inverse(&w) * left_jacobian(&w) - Matrix3::identity()).norm() < 1e-14);
/// let tiny = Vector3::new(1e-10, 0.0, -2e-10);
/// assert!((left_jacobian_inverse(&tiny) * left_jacobian(&tiny) - Matrix3::identity()).norm() < 1e-15);
/// ```
pub fn left_jacobian_inverse(w: &Vector3<f64>) -> Matrix3<f64> {
    let th = w.norm();
    let k = w.cross_matrix();
    let i = Matrix3::identity();
    if th < 1e-8 {
        return i - k * 0.5 + k * k / 12.0;
    }
    let c = 1.0 / (th * th) - (1.0 + th.cos()) / (2.0 * th * th.sin());
    i - k * 0.5 + k * k * c
}

/// Logarithm map: the rotation vector `w` (axis times angle, radians, `|w| <= pi`) with
/// `exp(w) = r`; the inverse of [`exp`].
///
/// Accurate to rounding at every angle: small angles use the skew part of `r` with the angle
/// from `atan2` (nalgebra's `scaled_axis` takes the angle from `acos` and so has a floor of
/// about 1e-8 rad near the identity); angles past pi/2 take the axis from the symmetric part.
///
/// ```
/// use cpm_geometry::rotation::{exp, log};
/// use nalgebra::Vector3;
/// let w = Vector3::new(1e-12, -2e-12, 3e-12);
/// assert!((log(&exp(&w)) - w).norm() < 1e-24);
/// let w = Vector3::new(0.0, 0.0, 3.0);
/// assert!((log(&exp(&w)) - w).norm() < 1e-14);
/// ```
pub fn log(r: &Rotation3<f64>) -> nalgebra::Vector3<f64> {
    let m = r.matrix();
    // Skew part: sin(theta) * axis; trace: 1 + 2 cos(theta).
    let v = nalgebra::Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    ) * 0.5;
    let s = v.norm();
    let c = ((m.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = s.atan2(c);
    if c >= 0.0 {
        if s > 0.0 {
            v * (theta / s)
        } else {
            nalgebra::Vector3::zeros()
        }
    } else {
        // (R + R^T)/2 - c I = (1 - c) a a^T: take the best-conditioned column for the axis.
        let sym = (m + m.transpose()) * 0.5 - Matrix3::identity() * c;
        let k = (0..3)
            .max_by(|&i, &j| sym[(i, i)].total_cmp(&sym[(j, j)]))
            .unwrap_or(0);
        let col = sym.column(k).into_owned();
        let n = col.norm();
        let usable = n > 0.0;
        if !usable {
            return nalgebra::Vector3::zeros();
        }
        let mut a = col / n;
        if a.dot(&v) < 0.0 {
            a = -a;
        }
        a * theta
    }
}
