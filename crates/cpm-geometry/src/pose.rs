//! Platform pose: position (mm) and orientation of the platform frame {P} in the base frame {B}.
use nalgebra::{Rotation3, UnitQuaternion, Vector3, Vector6};

use crate::{rotation, GeometryError};

/// Pose of the platform frame in the base frame: `x_B = R x_P + t`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// Position `t` of the platform origin, millimetres.
    pub position_mm: Vector3<f64>,
    /// Orientation `R`.
    pub rotation: Rotation3<f64>,
}

impl Default for Pose {
    fn default() -> Self {
        Self::identity()
    }
}

impl Pose {
    /// The identity pose (origin, no rotation).
    pub fn identity() -> Self {
        Self {
            position_mm: Vector3::zeros(),
            rotation: Rotation3::identity(),
        }
    }

    /// From position (mm) and a rotation.
    pub fn new(position_mm: Vector3<f64>, rotation: Rotation3<f64>) -> Self {
        Self {
            position_mm,
            rotation,
        }
    }

    /// From position (mm) and roll, pitch, yaw in radians (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
    pub fn from_xyz_rpy(x_mm: f64, y_mm: f64, z_mm: f64, roll: f64, pitch: f64, yaw: f64) -> Self {
        Self::new(
            Vector3::new(x_mm, y_mm, z_mm),
            rotation::from_rpy(roll, pitch, yaw),
        )
    }

    /// From position (mm) and roll, pitch, yaw in degrees (the file convention).
    pub fn from_xyz_rpy_deg(position_mm: [f64; 3], rpy_deg: [f64; 3]) -> Self {
        Self::from_xyz_rpy(
            position_mm[0],
            position_mm[1],
            position_mm[2],
            rpy_deg[0].to_radians(),
            rpy_deg[1].to_radians(),
            rpy_deg[2].to_radians(),
        )
    }

    /// From position (mm) and a quaternion (w, x, y, z), normalised.
    pub fn try_from_quaternion(
        position_mm: Vector3<f64>,
        wxyz: [f64; 4],
    ) -> Result<Self, GeometryError> {
        Ok(Self::new(
            position_mm,
            rotation::from_quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3])?,
        ))
    }

    /// From position (mm) and a rotation matrix, checked to be a rotation within 1e-9.
    pub fn try_from_matrix(
        position_mm: Vector3<f64>,
        m: nalgebra::Matrix3<f64>,
    ) -> Result<Self, GeometryError> {
        Ok(Self::new(position_mm, rotation::try_from_matrix(m, 1e-9)?))
    }

    /// Roll, pitch, yaw in radians.
    pub fn rpy(&self) -> (f64, f64, f64) {
        rotation::rpy(&self.rotation)
    }

    /// Roll, pitch, yaw in degrees.
    pub fn rpy_deg(&self) -> [f64; 3] {
        let (a, b, c) = self.rpy();
        [a.to_degrees(), b.to_degrees(), c.to_degrees()]
    }

    /// Orientation as a unit quaternion (w, x, y, z), w >= 0.
    pub fn quaternion(&self) -> [f64; 4] {
        rotation::quaternion(&self.rotation)
    }

    /// Orientation as a nalgebra unit quaternion.
    pub fn unit_quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&self.rotation)
    }

    /// A platform point (platform frame, mm) expressed in the base frame.
    pub fn transform_point(&self, p_mm: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p_mm + self.position_mm
    }

    /// The pose moved by a small twist `[dt (mm); dw (rad)]` expressed in the base frame:
    /// `t + dt`, `exp(dw) R`. This is the increment the Jacobian `J1` refers to.
    pub fn perturbed(&self, twist: &Vector6<f64>) -> Self {
        let dt = Vector3::new(twist[0], twist[1], twist[2]);
        let dw = Vector3::new(twist[3], twist[4], twist[5]);
        Self::new(self.position_mm + dt, rotation::exp(&dw) * self.rotation)
    }

    /// The twist `[dt; dw]` (base frame) that takes `self` to `other`: the inverse of
    /// [`Pose::perturbed`]. The rotation part is [`rotation::log`], accurate to rounding even
    /// for tiny differences.
    ///
    /// ```
    /// use cpm_geometry::Pose;
    /// use nalgebra::Vector6;
    /// let a = Pose::from_xyz_rpy(1.0, 2.0, 3.0, 0.1, 0.2, 0.3);
    /// let twist = Vector6::new(1e-9, 0.0, 0.0, 1e-12, 0.0, -2e-12);
    /// let d = a.difference(&a.perturbed(&twist));
    /// // Tiny rotations come back to rounding (an acos-based angle would be off by ~1e-8 rad).
    /// assert!((d.fixed_rows::<3>(3) - twist.fixed_rows::<3>(3)).norm() < 1e-15);
    /// assert!((d.fixed_rows::<3>(0) - twist.fixed_rows::<3>(0)).norm() < 1e-15);
    /// ```
    pub fn difference(&self, other: &Pose) -> Vector6<f64> {
        let dt = other.position_mm - self.position_mm;
        let dw = rotation::log(&(other.rotation * self.rotation.inverse()));
        Vector6::new(dt.x, dt.y, dt.z, dw.x, dw.y, dw.z)
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.position_mm.iter().all(|v| v.is_finite())
            && self.rotation.matrix().iter().all(|v| v.is_finite())
    }
}
