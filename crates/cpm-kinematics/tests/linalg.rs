//! The SVD (faer, exactly scaled): reconstruction and orthogonality to rounding, rank
//! deficiency, solves, extreme scales, named errors.
use cpm_geometry::{JointTable, Pose};
use cpm_kinematics::linalg::{Svd, SvdError};
use cpm_kinematics::{j1, workspace::j1_condition};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};
use proptest::prelude::*;

fn check(a: &DMatrix<f64>) -> Result<Svd, TestCaseError> {
    let svd = Svd::new(a).unwrap();
    let n = a.ncols();
    let s = &svd.singular_values;
    for k in 1..n {
        prop_assert!(s[k - 1] >= s[k]);
    }
    let recon = &svd.u * DMatrix::from_diagonal(s) * svd.v.transpose();
    let scale = a.abs().max().max(1e-300);
    prop_assert!((recon - a).abs().max() <= 1e-14 * scale, "reconstruction");
    let vtv = svd.v.transpose() * &svd.v;
    prop_assert!((vtv - DMatrix::identity(n, n)).abs().max() < 1e-14);
    for k in 0..n {
        if s[k] > 1e-12 * s[0] {
            prop_assert!((svd.u.column(k).norm() - 1.0).abs() < 1e-14);
        }
    }
    Ok(svd)
}

/// The J1 at which nalgebra 0.34's SVD reconstructs with a 1.6e-6 error.
fn awkward_pose() -> Pose {
    let r = Matrix3::new(
        0.9355451767222764,
        0.35252116288673535,
        0.022001182437957068,
        -0.3523501242196143,
        0.9271267307052612,
        0.12761432197914277,
        0.02458886483973654,
        -0.1271410827732632,
        0.9915798166547841,
    )
    .transpose();
    Pose::new(
        Vector3::new(-25.28516920504481, 78.05988061875073, 410.0),
        Rotation3::from_matrix_unchecked(r),
    )
}

#[test]
fn accurate_on_an_awkward_j1() {
    let a = j1(&JointTable::paper_cubic(), &awkward_pose());
    let svd = check(&a).unwrap();
    let b = DVector::from_fn(6, |i, _| (i as f64 * 0.37).sin());
    let x = svd.solve(&b, 0.0);
    assert!((&a * x - b).norm() < 1e-13);
    let c = j1_condition(&JointTable::paper_cubic(), &awkward_pose()).unwrap();
    assert!((c - 465.51377003342475 / 0.5461639505442041).abs() < 1e-6 * c);
}

#[test]
fn rank_deficient_and_degenerate() {
    // Zero matrix, zero column, duplicate columns.
    let z = DMatrix::<f64>::zeros(6, 6);
    let s = Svd::new(&z).unwrap();
    assert!(s.condition_number().is_infinite());
    let mut a = DMatrix::from_fn(7, 6, |i, j| ((i * 6 + j) as f64).cos());
    a.set_column(2, &DVector::zeros(7));
    let s = check(&a).unwrap();
    assert!(s.singular_values[5] <= 1e-15 * s.singular_values[0]);
    assert!(s.condition_number() > 1e14);
    let mut a = DMatrix::from_fn(6, 6, |i, j| ((i * 6 + j) as f64).sin());
    let c0 = a.column(0).into_owned();
    a.set_column(4, &(c0 * 2.0));
    let s = check(&a).unwrap();
    assert!(s.condition_number() > 1e14);
    // Minimum-norm solve ignores the null space.
    let b = &a * DVector::from_element(6, 1.0);
    let x = s.solve(&b, 1e-12);
    assert!((&a * &x - b).norm() < 1e-12);
    // Bad inputs.
    let mut n = DMatrix::<f64>::identity(6, 6);
    n[(1, 1)] = f64::NAN;
    assert!(matches!(
        Svd::new(&n),
        Err(SvdError::NonFinite { row: 2, col: 2, .. })
    ));
    assert!(matches!(
        Svd::new(&DMatrix::<f64>::identity(3, 4)),
        Err(SvdError::Shape { rows: 3, cols: 4 })
    ));
    assert!(matches!(
        Svd::new(&DMatrix::<f64>::zeros(3, 0)),
        Err(SvdError::Shape { .. })
    ));
}

proptest! {
    #[test]
    fn svd_of_random_matrices(
        rows in 6usize..10,
        v in prop::collection::vec(-1.0..1.0f64, 60),
        col_scales in prop::array::uniform6(-3.0..3.0f64),
    ) {
        // Columns of very different size, like J1's (unit vectors and mm moments).
        let a = DMatrix::from_fn(rows, 6, |i, j| v[i * 6 + j] * 10f64.powf(col_scales[j]));
        check(&a)?;
    }

    #[test]
    fn condition_of_j1_agrees_with_eigenvalues_of_normal_matrix(
        x in -50.0..50.0f64, y in -50.0..50.0f64, rz in -0.3..0.3f64,
    ) {
        let t = JointTable::paper_cubic();
        let p = Pose::from_xyz_rpy(x, y, 410.0, 0.0, 0.0, rz);
        let j = j1(&t, &p);
        let ev = (j.transpose() * &j).symmetric_eigenvalues();
        let c2 = ev.max() / ev.min();
        let c = j1_condition(&t, &p).unwrap();
        prop_assert!((c * c - c2).abs() < 1e-6 * c2);
    }

    #[test]
    fn condition_of_j1_agrees_with_the_general_svd(
        x in -300.0..300.0f64, y in -300.0..300.0f64, z in -100.0..900.0f64,
        r in -1.5..1.5f64, p in -1.5..1.5f64, w in -3.1..3.1f64, hexapod in any::<bool>(),
    ) {
        // j1_condition takes nalgebra's fixed-size SVD for six links; the faer one (exactly
        // scaled) is the reference, over poses far and near singular alike.
        let t = if hexapod { JointTable::hexapod_66() } else { JointTable::paper_cubic() };
        let pose = Pose::from_xyz_rpy(x, y, z, r, p, w);
        let fast = j1_condition(&t, &pose).unwrap();
        let general = cpm_kinematics::linalg::condition_number(&j1(&t, &pose)).unwrap();
        // The cheap bound never accepts what the condition number refuses, and is tight to
        // a factor 6.
        let m = nalgebra::Matrix6::from_iterator(j1(&t, &pose).iter().copied());
        for limit in [general * 0.999, general * 1.001, general * 6.001, 1e10] {
            let sure = cpm_kinematics::fk::condition_at_most(&m, limit);
            prop_assert!(!sure || general <= limit * (1.0 + 1e-9), "{limit} {general}");
            if limit >= general * 6.001 && general < 1e8 {
                prop_assert!(sure, "{limit} {general}");
            }
        }
        if general < 1e12 {
            prop_assert!((fast / general - 1.0).abs() < 1e-9 * general.max(1.0), "{fast} vs {general}");
        } else {
            prop_assert!(fast > 1e10, "{fast} vs {general}");
        }
    }
}

#[test]
fn extreme_scales_give_the_same_factors() {
    // Exact power-of-two scaling: J1 times 1e150 or 1e-200 (or a subnormal factor) has the
    // same U and V and singular values scaled alike, to rounding.
    let a = j1(&JointTable::paper_cubic(), &awkward_pose());
    let base = Svd::new(&a).unwrap();
    for c in [1e150, 1e-200, 1e-300] {
        let s = Svd::new(&(&a * c)).unwrap();
        for k in 0..6 {
            let rel = s.singular_values[k] / (c * base.singular_values[k]) - 1.0;
            assert!(rel.abs() < 1e-12, "scale {c:e}: {rel:e}");
        }
        let cond = s.condition_number() / base.condition_number() - 1.0;
        assert!(cond.abs() < 1e-12, "scale {c:e}: {cond:e}");
    }
    // Subnormal entries (the matrix itself has lost digits): still decomposed.
    let c = 2f64.powi(-1060);
    let s = Svd::new(&(&a * c)).unwrap();
    assert!((s.singular_values[0] / (c * base.singular_values[0]) - 1.0).abs() < 1e-6);
}
