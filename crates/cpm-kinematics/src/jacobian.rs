//! The Jacobians J1 (pose) and J2 (installation errors) of eq. 10-11, and eq. 12.
use cpm_geometry::{JointTable, Pose};
use nalgebra::{DMatrix, DVector, Vector6};

use crate::{inverse, KinematicsError};

/// `J1` (N x 6): row i is `[z_i^T, (s_i x z_i)^T]`, so `dl = J1 [dt; dw]`.
pub fn j1(table: &JointTable, pose: &Pose) -> DMatrix<f64> {
    let links = inverse(table, pose);
    let mut j = DMatrix::zeros(links.len(), 6);
    for (i, ls) in links.iter().enumerate() {
        let m = ls.s_mm.cross(&ls.unit);
        for k in 0..3 {
            j[(i, k)] = ls.unit[k];
            j[(i, 3 + k)] = m[k];
        }
    }
    j
}

/// `J2` (N x 6N): `dl_i = -z_i^T db_i + z_i^T R dp_i`, columns ordered link by link, base then
/// platform, x y z (lengths in mm per mm of joint error).
pub fn j2(table: &JointTable, pose: &Pose) -> DMatrix<f64> {
    let links = inverse(table, pose);
    let n = links.len();
    let mut j = DMatrix::zeros(n, 6 * n);
    let rt = pose.rotation.matrix().transpose();
    for (i, ls) in links.iter().enumerate() {
        let zp = rt * ls.unit; // R^T z: derivative w.r.t. the platform joint in {P}
        for k in 0..3 {
            j[(i, 6 * i + k)] = -ls.unit[k];
            j[(i, 6 * i + 3 + k)] = zp[k];
        }
    }
    j
}

/// First-order pose error (eq. 12): `dx = J1^+ (dl - J2 de)` for link length changes `dl_mm`
/// and installation errors `de_mm` (flat, mm) at `pose` of the nominal `table`.
///
/// With the commanded lengths held (`dl = 0`) this is how far the platform ends up from the
/// commanded pose because of the installation errors, to first order.
pub fn first_order_pose_error(
    table: &JointTable,
    pose: &Pose,
    dl_mm: &[f64],
    de_mm: &[f64],
) -> Result<Vector6<f64>, KinematicsError> {
    let n = table.num_links();
    if dl_mm.len() != n || de_mm.len() != 6 * n || n < 6 {
        return Err(KinematicsError::Dimension {
            what: format!(
                "{} links, {} length changes, {} joint errors",
                n,
                dl_mm.len(),
                de_mm.len()
            ),
        });
    }
    let a = j1(table, pose);
    let b = j2(table, pose);
    let rhs = DVector::from_column_slice(dl_mm) - b * DVector::from_column_slice(de_mm);
    let svd = a.svd(true, true);
    let smax = svd.singular_values.max();
    let smin = svd.singular_values.min();
    if smin <= smax * 1e-12 {
        return Err(KinematicsError::Singular {
            iteration: 0,
            condition: smax / smin,
        });
    }
    let x = svd
        .solve(&rhs, 0.0)
        .map_err(|e| KinematicsError::Dimension { what: e.into() })?;
    Ok(Vector6::from_iterator(x.iter().copied()))
}
