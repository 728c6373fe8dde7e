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

#[cfg(test)]
mod tests {
    use super::*;

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
