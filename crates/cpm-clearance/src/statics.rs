//! Platform statics: the applied wrench and the axial link forces that balance it.
use cpm_geometry::{JointTable, Pose};
use nalgebra::{DMatrix, DVector, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::ClearanceError;

/// The load on the platform: weights at their centres of mass plus an external wrench.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Load {
    /// Platform mass, kg. Default 20 (an assumption: the paper gives none).
    pub platform_mass_kg: f64,
    /// Platform centre of mass in {P}, mm. Default (0, 0, -100).
    pub platform_com_mm: Vector3<f64>,
    /// Payload mass, kg. Default 0.
    pub payload_mass_kg: f64,
    /// Payload centre of mass in {P}, mm. Default origin.
    pub payload_com_mm: Vector3<f64>,
    /// Gravity in {B}, mm/s^2. Default (0, 0, -9806.65).
    pub gravity_mm_s2: Vector3<f64>,
    /// External force on the platform at its origin, {B}, N. Default zero.
    pub external_force_n: Vector3<f64>,
    /// External moment on the platform, {B}, N mm. Default zero.
    pub external_moment_nmm: Vector3<f64>,
}

impl From<&cpm_geometry::description::LoadSpec> for Load {
    /// The load of a robot description's `[load]` table, field by field.
    fn from(spec: &cpm_geometry::description::LoadSpec) -> Self {
        Self {
            platform_mass_kg: spec.platform_mass_kg,
            platform_com_mm: Vector3::from(spec.platform_com_mm),
            payload_mass_kg: spec.payload_mass_kg,
            payload_com_mm: Vector3::from(spec.payload_com_mm),
            gravity_mm_s2: Vector3::from(spec.gravity_mm_s2),
            external_force_n: Vector3::from(spec.external_force_n),
            external_moment_nmm: Vector3::from(spec.external_moment_nmm),
        }
    }
}

impl Default for Load {
    fn default() -> Self {
        Self {
            platform_mass_kg: 20.0,
            platform_com_mm: Vector3::new(0.0, 0.0, -100.0),
            payload_mass_kg: 0.0,
            payload_com_mm: Vector3::zeros(),
            gravity_mm_s2: Vector3::new(0.0, 0.0, -9806.65),
            external_force_n: Vector3::zeros(),
            external_moment_nmm: Vector3::zeros(),
        }
    }
}

/// The wrench `[F (N); M (N mm)]` applied to the platform at `pose`, moments about the
/// platform origin, both in {B}.
pub fn platform_wrench(load: &Load, pose: &Pose) -> Vector6<f64> {
    let g_n_per_kg = load.gravity_mm_s2 * 1e-3;
    let mut f = load.external_force_n;
    let mut m = load.external_moment_nmm;
    for (mass, com) in [
        (load.platform_mass_kg, load.platform_com_mm),
        (load.payload_mass_kg, load.payload_com_mm),
    ] {
        let w = g_n_per_kg * mass;
        let arm = pose.rotation * com;
        f += w;
        m += arm.cross(&w);
    }
    Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z)
}

/// The signs (-1, 0 or +1) of [`link_forces_n`]'s forces when an LU solve makes them certain
/// (six links, the Frobenius condition number of `J1` below 1e9, every force farther from
/// zero than the solve's error bound), `None` otherwise: the hard sign rule's corrections
/// then need no SVD (the SVD's own acceptance, condition below 1e10, follows from the bound).
pub(crate) fn link_force_signs_if_certain(
    table: &JointTable,
    pose: &Pose,
    load: &Load,
) -> Option<[f64; 6]> {
    if table.num_links() != 6 {
        return None;
    }
    let a = cpm_kinematics::j1_of_six(&cpm_kinematics::inverse(table, pose))?.transpose();
    let inv = cpm_kinematics::lu6::Lu6::new(&a).inverse()?;
    // cond_2 <= cond_F: below 1e9 the pose is well inside the SVD's acceptance.
    let cond_f = a.norm() * inv.norm();
    if !(cond_f < 1e9) {
        return None;
    }
    let t = inv * platform_wrench(load, pose);
    let size = t.amax();
    // Both solves are within about 6 cond eps |t| of the exact forces: a force this far from
    // zero has the same sign in either.
    let margin = cond_f * 1e-12 * size;
    if !(size.is_finite() && t.iter().all(|v| v.abs() > margin)) {
        return None;
    }
    Some(std::array::from_fn(|i| t[i].signum()))
}

/// Axial link forces (N, tension positive) that hold the platform at `pose` under `load`:
/// the solution of `J1^T t = w` (least norm for more than six links).
///
/// A link in tension pulls the platform towards its base joint, i.e. applies `-t_i z_i`; the
/// balance `sum_i -t_i z_i + F = 0`, `sum_i s_i x (-t_i z_i) + M = 0` is `J1^T t = w`.
pub fn link_forces_n(
    table: &JointTable,
    pose: &Pose,
    load: &Load,
) -> Result<Vec<f64>, ClearanceError> {
    let j1: DMatrix<f64> = cpm_kinematics::j1(table, pose);
    let w = platform_wrench(load, pose);
    if j1.nrows() == 6 {
        // Six links (the usual hexapod): the same decomposition on a fixed-size matrix, on
        // the stack (it runs for every pose of a campaign when clearance is modelled).
        let a = nalgebra::Matrix6::from_fn(|r, c| j1[(c, r)]);
        // nalgebra's unbounded SVD can loop for ever on some exactly singular matrices: a
        // bounded number of sweeps, and a failure to converge is a singular pose.
        let svd = a
            .try_svd(true, true, f64::EPSILON, 10_000)
            .ok_or(ClearanceError::Singular {
                condition: f64::INFINITY,
            })?;
        let smax = svd.singular_values.max();
        let smin = svd.singular_values.min();
        if !(smin > smax * 1e-10) {
            return Err(ClearanceError::Singular {
                condition: smax / smin,
            });
        }
        let t = svd.solve(&w, 0.0).map_err(|_| ClearanceError::Singular {
            condition: f64::INFINITY,
        })?;
        return Ok(t.iter().copied().collect());
    }
    let svd = j1
        .transpose()
        .try_svd(true, true, f64::EPSILON, 10_000)
        .ok_or(ClearanceError::Singular {
            condition: f64::INFINITY,
        })?;
    let smax = svd.singular_values.max();
    let smin = svd.singular_values.min();
    if !(smin > smax * 1e-10) {
        return Err(ClearanceError::Singular {
            condition: smax / smin,
        });
    }
    let t = svd
        .solve(&DVector::from_column_slice(w.as_slice()), 0.0)
        .map_err(|_| ClearanceError::Singular {
            condition: f64::INFINITY,
        })?;
    Ok(t.iter().copied().collect())
}
