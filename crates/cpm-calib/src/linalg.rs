//! Dense SVD through faer (accurate and fast on the tall Jacobians of calibration).
use nalgebra::DMatrix;

/// Thin SVD `A = U diag(s) V^T` of an `m x n` matrix (`k = min(m, n)` singular values, largest
/// first, `U` is `m x k`, `V` is `n x k`). `None` when an entry is not finite or faer fails.
pub fn thin_svd(a: &DMatrix<f64>) -> Option<(Vec<f64>, DMatrix<f64>, DMatrix<f64>)> {
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let (m, n) = a.shape();
    let f = faer::Mat::<f64>::from_fn(m, n, |i, j| a[(i, j)]);
    let svd = f.thin_svd().ok()?;
    let k = m.min(n);
    let s = svd.S().column_vector();
    let sv: Vec<f64> = (0..k).map(|i| s[i]).collect();
    let u = svd.U();
    let v = svd.V();
    Some((
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
}
