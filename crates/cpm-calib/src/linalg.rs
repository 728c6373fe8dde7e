//! Dense SVD through faer (accurate and fast on the tall Jacobians of calibration), after
//! an exact power-of-two scaling of the matrix (see [`cpm_kinematics::linalg`]).
use cpm_kinematics::linalg::{scaling_exponent, times_pow2, SvdError};
use nalgebra::DMatrix;

/// Singular values (largest first), `U` and `V` of a thin SVD.
pub type ThinSvd = (Vec<f64>, DMatrix<f64>, DMatrix<f64>);

/// Thin SVD `A = U diag(s) V^T` of an `m x n` matrix (`k = min(m, n)` singular values, largest
/// first, `U` is `m x k`, `V` is `n x k`). The matrix is first scaled by the power of two that
/// brings its largest entry into `[1, 2)` (exact), so no unit makes it overflow or underflow.
/// Errors: a non-finite entry ([`SvdError::NonFinite`]), an empty matrix
/// ([`SvdError::Shape`]), faer not converging ([`SvdError::NoConvergence`]).
pub fn thin_svd(a: &DMatrix<f64>) -> Result<ThinSvd, SvdError> {
    let (m, n) = a.shape();
    if m == 0 || n == 0 {
        return Err(SvdError::Shape { rows: m, cols: n });
    }
    if let Some(k) = a.iter().position(|v| !v.is_finite()) {
        return Err(SvdError::NonFinite {
            rows: m,
            cols: n,
            row: k % m + 1,
            col: k / m + 1,
        });
    }
    let e = scaling_exponent(a.iter()).unwrap_or(0);
    let f = faer::Mat::<f64>::from_fn(m, n, |i, j| times_pow2(a[(i, j)], -e));
    let svd = f
        .thin_svd()
        .map_err(|_| SvdError::NoConvergence { rows: m, cols: n })?;
    let k = m.min(n);
    let s = svd.S().column_vector();
    let sv: Vec<f64> = (0..k).map(|i| times_pow2(s[i], e)).collect();
    let u = svd.U();
    let v = svd.V();
    Ok((
        sv,
        DMatrix::from_fn(m, k, |i, j| u[(i, j)]),
        DMatrix::from_fn(n, k, |i, j| v[(i, j)]),
    ))
}

/// Singular values (descending) and right singular vectors (`n x min(m, n)`) of `a`, like
/// [`thin_svd`] without the left vectors (which the identifiability analysis does not use:
/// for a tall Jacobian forming them costs more than the rest of the decomposition).
pub fn svd_values_and_v(a: &DMatrix<f64>) -> Result<(Vec<f64>, DMatrix<f64>), SvdError> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors};
    let (m, n) = a.shape();
    if m == 0 || n == 0 {
        return Err(SvdError::Shape { rows: m, cols: n });
    }
    if let Some(k) = a.iter().position(|v| !v.is_finite()) {
        return Err(SvdError::NonFinite {
            rows: m,
            cols: n,
            row: k % m + 1,
            col: k / m + 1,
        });
    }
    let e = scaling_exponent(a.iter()).unwrap_or(0);
    let f = faer::Mat::<f64>::from_fn(m, n, |i, j| times_pow2(a[(i, j)], -e));
    let k = m.min(n);
    let mut s = faer::diag::Diag::<f64>::zeros(k);
    let mut v = faer::Mat::<f64>::zeros(n, k);
    let par = faer::get_global_parallelism();
    let mut mem = MemBuffer::new(svd_scratch::<f64>(
        m,
        n,
        ComputeSvdVectors::No,
        ComputeSvdVectors::Thin,
        par,
        Default::default(),
    ));
    svd(
        f.as_ref(),
        s.as_mut(),
        None,
        Some(v.as_mut()),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|_| SvdError::NoConvergence { rows: m, cols: n })?;
    let sc = s.column_vector();
    let sv: Vec<f64> = (0..k).map(|i| times_pow2(sc[i], e)).collect();
    Ok((sv, DMatrix::from_fn(n, k, |i, j| v[(i, j)])))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_v_match_the_thin_svd() {
        for (m, n) in [(7, 4), (40, 36), (3, 5)] {
            let a = DMatrix::from_fn(m, n, |i, j| {
                ((i * 7 + j * 3) as f64).cos() + 2.0 * (i == j) as u8 as f64
            });
            let (s0, _, v0) = thin_svd(&a).unwrap();
            let (s1, v1) = svd_values_and_v(&a).unwrap();
            for (x, y) in s0.iter().zip(&s1) {
                assert!((x - y).abs() < 1e-12 * s0[0], "{m}x{n}: {x} vs {y}");
            }
            // Singular vectors up to sign (the values are distinct here).
            for c in 0..s0.len() {
                let d = v0.column(c).dot(&v1.column(c)).abs();
                assert!((d - 1.0).abs() < 1e-10, "{m}x{n} column {c}: {d}");
            }
        }
        assert!(svd_values_and_v(&DMatrix::from_element(2, 2, f64::NAN)).is_err());
    }

    #[test]
    fn reconstructs_a_matrix() {
        let a = DMatrix::from_fn(7, 4, |i, j| {
            ((i * 3 + j * 5) as f64).sin() + (i == j) as u8 as f64
        });
        let (s, u, v) = thin_svd(&a).unwrap();
        assert!(s.windows(2).all(|w| w[0] >= w[1]));
        let back = &u * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(s)) * v.transpose();
        assert!((back - a).amax() < 1e-13);
    }

    #[test]
    fn extreme_scales_and_bad_input() {
        let a = DMatrix::from_fn(9, 5, |i, j| {
            ((i * 37 + j * 101) % 17) as f64 / 17.0 + (i == j) as u8 as f64
        });
        let (s0, _, _) = thin_svd(&a).unwrap();
        for c in [1e150, 1e-200] {
            let (s, u, v) = thin_svd(&(&a * c)).unwrap();
            for (x, y) in s.iter().zip(&s0) {
                assert!((x / c - y).abs() < 1e-13 * s0[0]);
            }
            let back = &u * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(s)) * v.transpose();
            assert!((back - &a * c).amax() < 1e-13 * c);
        }
        let mut b = a.clone();
        b[(3, 2)] = f64::NAN;
        assert!(matches!(
            thin_svd(&b),
            Err(SvdError::NonFinite { row: 4, col: 3, .. })
        ));
        assert!(thin_svd(&DMatrix::zeros(0, 3)).is_err());
    }
}
