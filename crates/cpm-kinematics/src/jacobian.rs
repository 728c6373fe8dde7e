//! The Jacobians J1 (pose) and J2 (installation errors) of eq. 10-11, and eq. 12.
use cpm_geometry::{JointTable, Pose};
use nalgebra::{DMatrix, DVector, Matrix6, Vector6};

use crate::linalg::Svd;
use crate::{inverse, KinematicsError, LinkState};

/// `J1` (N x 6): row i is `[z_i^T, (s_i x z_i)^T]`, so `dl = J1 [dt; dw]`.
///
/// ```
/// use cpm_geometry::JointTable;
/// use cpm_kinematics::j1;
/// let t = JointTable::paper_cubic();
/// let j = j1(&t, &t.home);
/// // Link 1 is vertical at home: it only feels z and the tilts, s_1 x z = (-140, 140, 0).
/// assert_eq!(j.row(0).iter().copied().collect::<Vec<_>>(), [0.0, 0.0, 1.0, -140.0, 140.0, 0.0]);
/// ```
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

/// [`j1`] of six links as a 6x6 matrix on the stack, from the links at the pose
/// ([`inverse`]): the same numbers, without the dynamic matrix. `None` unless there are six.
///
/// ```
/// use cpm_geometry::JointTable;
/// use cpm_kinematics::{inverse, j1, j1_of_six};
/// let t = JointTable::paper_cubic();
/// let j = j1_of_six(&inverse(&t, &t.home)).unwrap();
/// assert_eq!(j.as_slice(), j1(&t, &t.home).as_slice());
/// ```
pub fn j1_of_six(links: &[LinkState]) -> Option<Matrix6<f64>> {
    (links.len() == 6).then(|| {
        Matrix6::from_fn(|r, c| {
            let l = &links[r];
            if c < 3 {
                l.unit[c]
            } else {
                l.s_mm.cross(&l.unit)[c - 3]
            }
        })
    })
}

/// `J2` (N x 6N): `dl_i = -z_i^T db_i + z_i^T R dp_i`, columns ordered link by link, base then
/// platform, x y z (lengths in mm per mm of joint error).
///
/// ```
/// use cpm_geometry::JointTable;
/// use cpm_kinematics::j2;
/// let t = JointTable::paper_cubic();
/// let j = j2(&t, &t.home);
/// assert_eq!(j.shape(), (6, 36));
/// // Raising link 1's base joint shortens it; raising its platform joint lengthens it.
/// assert_eq!((j[(0, 2)], j[(0, 5)]), (-1.0, 1.0));
/// ```
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
///
/// ```
/// use cpm_geometry::{InstallationErrors, JointTable};
/// use cpm_kinematics::first_order_pose_error;
/// let t = JointTable::paper_cubic();
/// // Every joint of link 1 raised by 10 um: with the lengths held, nothing moves...
/// let mut e = vec![0.0; 36];
/// e[2] = 0.01; // base dz, mm
/// e[5] = 0.01; // platform dz, mm
/// let dx = first_order_pose_error(&t, &t.home, &[0.0; 6], &e).unwrap();
/// assert!(dx.norm() < 1e-15);
/// // ...but the base joint alone lifts that corner of the platform by 10 um.
/// e[5] = 0.0;
/// let dx = first_order_pose_error(&t, &t.home, &[0.0; 6], &e).unwrap();
/// assert!(dx[2] > 0.0 && dx.norm() > 1e-4);
/// # let _ = InstallationErrors::zeros(6);
/// ```
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
    if !pose.is_finite() || !dl_mm.iter().chain(de_mm).all(|v| v.is_finite()) {
        return Err(KinematicsError::NonFinite {
            what: "pose, length changes or joint errors".into(),
        });
    }
    let a = j1(table, pose);
    if !a.iter().all(|v| v.is_finite()) {
        return Err(KinematicsError::Singular {
            iteration: 0,
            condition: f64::INFINITY,
        });
    }
    let b = j2(table, pose);
    let rhs = DVector::from_column_slice(dl_mm) - b * DVector::from_column_slice(de_mm);
    // faer's SVD after exact scaling: nalgebra's is not accurate enough here (see `linalg`).
    let svd = Svd::new(&a)?;
    let condition = svd.condition_number();
    let regular = condition < 1e12; // false for NaN
    if !regular {
        return Err(KinematicsError::Singular {
            iteration: 0,
            condition,
        });
    }
    let x = svd.solve(&rhs, 0.0);
    Ok(Vector6::from_iterator(x.iter().copied()))
}
