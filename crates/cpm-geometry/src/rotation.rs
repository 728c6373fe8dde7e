//! Roll-pitch-yaw rotations `R = Rz(yaw) Ry(pitch) Rx(roll)` and conversions.
//!
//! The paper (Lim et al. 2002) describes its eq. 1 as a rotation about the fixed x axis by
//! alpha (roll), then the fixed y axis by beta (pitch), then the fixed z axis by gamma (yaw),
//! i.e. `R = Rz(gamma) Ry(beta) Rx(alpha)`. The printed matrix of eq. 1 has typos (alpha where
//! gamma belongs); this module follows the text, which is also what the paper's numbers need.
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

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

/// Roll, pitch, yaw (radians) of `R = Rz(yaw) Ry(pitch) Rx(roll)`; pitch in [-pi/2, pi/2].
/// At pitch = +-pi/2 (gimbal lock) roll is set to zero and yaw carries the rotation.
pub fn rpy(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    let sp = (-m[(2, 0)]).clamp(-1.0, 1.0);
    let pitch = sp.asin();
    let cp = (m[(0, 0)].powi(2) + m[(1, 0)].powi(2)).sqrt();
    if cp > 1e-12 {
        let roll = m[(2, 1)].atan2(m[(2, 2)]);
        let yaw = m[(1, 0)].atan2(m[(0, 0)]);
        (roll, pitch, yaw)
    } else {
        // Gimbal lock: R = Rz(yaw) Ry(+-pi/2); only yaw -+ roll is defined.
        let yaw = (-m[(0, 1)]).atan2(m[(1, 1)]);
        (0.0, pitch, yaw)
    }
}

/// Checks that `m` is a proper rotation (orthonormal to `tol`, det +1) and wraps it.
pub fn try_from_matrix(m: Matrix3<f64>, tol: f64) -> Result<Rotation3<f64>, GeometryError> {
    let err = (m.transpose() * m - Matrix3::identity()).abs().max();
    let det = m.determinant();
    if !(err <= tol) || !((det - 1.0).abs() <= tol) {
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
