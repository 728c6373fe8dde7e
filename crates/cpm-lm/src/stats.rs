//! Statistics of a least-squares fit from its Jacobian: numerical rank, parameter
//! covariance, standard deviations, correlations and identifiability.
//!
//! With the SVD `J = U S V^T` (singular values `s_1 >= s_2 >= ...`), the numerical rank is
//! the number of singular values above `tol` (default `max(m, n) * eps * s_1`, the
//! LAPACK/NumPy convention). Then
//!
//! * `(J^T J)^+ = sum_{k < rank} v_k v_k^T / s_k^2` (pseudo-inverse),
//! * `sigma^2 = ||r||^2 / (m - rank) = 2 cost / (m - rank)` (undefined, NaN, when `m = rank`),
//! * `covariance = sigma^2 (J^T J)^+`, `std_j = sqrt(covariance_jj)`,
//!   `correlation_ij = covariance_ij / (std_i std_j)`.
//!
//! The numerical null space is spanned by the remaining right singular vectors. A
//! parameter whose unit vector has a component of norm above
//! [`IDENTIFIABILITY_THRESHOLD`] in it can be changed without changing the fit to first
//! order: it is *unidentifiable*, and its standard deviation is `None` instead of the
//! finite but meaningless number the pseudo-inverse would give.
//!
//! ```
//! use cpm_lm::stats::Statistics;
//! use faer::mat;
//! // Columns 0 and 1 are equal: only their sum is identifiable; parameter 2 is fine.
//! let j = mat![[1.0, 1.0, 0.0], [2.0, 2.0, 1.0], [3.0, 3.0, 0.0], [4.0, 4.0, 2.0]];
//! let r = [0.1, -0.1, 0.05, 0.0];
//! let st = Statistics::from_jacobian(j.as_ref(), &r, None);
//! assert_eq!(st.rank, 2);
//! assert!(st.is_rank_deficient());
//! assert_eq!(st.std_dev[0], None);
//! assert_eq!(st.std_dev[1], None);
//! assert!(st.std_dev[2].is_some());
//! ```

use std::fmt;

use faer::{Mat, MatRef};

use crate::error::LmError;
use crate::solver::small::{dot, norm2};

/// A parameter is unidentifiable when the norm of its unit vector's projection onto the
/// numerical null space of `J` exceeds this value.
pub const IDENTIFIABILITY_THRESHOLD: f64 = 1e-6;

/// Statistics of a fit (see the [module documentation](self) for the formulas).
#[derive(Clone, Debug)]
pub struct Statistics {
    /// Number of residuals `m`.
    pub num_residuals: usize,
    /// Number of parameters `n`.
    pub num_params: usize,
    /// Numerical rank of `J`.
    pub rank: usize,
    /// Threshold on the singular values used for the rank.
    pub rank_tol: f64,
    /// Singular values of `J`, descending (`min(m, n)` of them).
    pub singular_values: Vec<f64>,
    /// Degrees of freedom `m - rank`.
    pub dof: usize,
    /// `0.5 * ||r||^2`.
    pub cost: f64,
    /// Residual variance estimate `||r||^2 / (m - rank)`; NaN when `m == rank`.
    pub sigma2: f64,
    /// `(J^T J)^+`, the pseudo-inverse on the numerical range (`n x n`).
    pub jtj_pinv: Mat<f64>,
    /// `sigma2 * (J^T J)^+` (`n x n`).
    pub covariance: Mat<f64>,
    /// Standard deviation of each parameter; `None` when the parameter is unidentifiable
    /// or `sigma2` is undefined.
    pub std_dev: Vec<Option<f64>>,
    /// Correlation matrix (`n x n`, unit diagonal for identifiable parameters); NaN where a
    /// standard deviation is `None`.
    pub correlation: Mat<f64>,
    /// Orthonormal basis of the numerical null space of `J` (`n x (n - rank)`).
    pub null_space: Mat<f64>,
    /// Per parameter: whether it is identifiable (see [`IDENTIFIABILITY_THRESHOLD`]).
    pub identifiable: Vec<bool>,
}

impl Statistics {
    /// Statistics of the Jacobian `j` (`m x n`) with residuals `residuals` (length `m`).
    ///
    /// `rank_tol` is the absolute threshold on the singular values (default
    /// `max(m, n) * f64::EPSILON * s_max`). Never panics: on a size mismatch, non-finite
    /// input or an SVD failure it returns statistics of rank 0 in which every parameter is
    /// unidentifiable (use [`Statistics::try_from_jacobian`] to get the error instead).
    pub fn from_jacobian(j: MatRef<'_, f64>, residuals: &[f64], rank_tol: Option<f64>) -> Self {
        Self::try_from_jacobian(j, residuals, rank_tol)
            .unwrap_or_else(|_| Self::degenerate(j.nrows(), j.ncols(), residuals))
    }

    /// Like [`from_jacobian`](Self::from_jacobian) but reports bad input as an error.
    pub fn try_from_jacobian(
        j: MatRef<'_, f64>,
        residuals: &[f64],
        rank_tol: Option<f64>,
    ) -> Result<Self, LmError> {
        let (m, n) = (j.nrows(), j.ncols());
        if residuals.len() != m {
            return Err(LmError::DimensionMismatch {
                what: "residuals",
                expected: m,
                found: residuals.len(),
            });
        }
        if m == 0 || n == 0 {
            return Err(LmError::EmptyProblem {
                num_params: n,
                num_residuals: m,
            });
        }
        if let Some(t) = rank_tol {
            if !(t.is_finite() && t >= 0.0) {
                return Err(LmError::InvalidOptions(format!(
                    "rank_tol must be finite and >= 0, got {t}"
                )));
            }
        }
        let finite = (0..n).all(|c| (0..m).all(|i| j[(i, c)].is_finite()))
            && residuals.iter().all(|v| v.is_finite());
        if !finite {
            return Err(LmError::Numerical(
                "statistics: the Jacobian or the residuals contain NaN or infinity".into(),
            ));
        }
        let (singular_values, v) = right_svd(j)?;
        let s_max = singular_values.first().copied().unwrap_or(0.0);
        let tol = rank_tol.unwrap_or(m.max(n) as f64 * f64::EPSILON * s_max);
        let rank = singular_values.iter().filter(|&&s| s > tol).count();

        let ss: f64 = residuals.iter().map(|r| r * r).sum();
        let dof = m - rank;
        let sigma2 = if dof > 0 { ss / dof as f64 } else { f64::NAN };

        let mut jtj_pinv = Mat::<f64>::zeros(n, n);
        for kk in 0..rank {
            let w = 1.0 / (singular_values[kk] * singular_values[kk]);
            for c in 0..n {
                let vc = v[(c, kk)] * w;
                if vc == 0.0 {
                    continue;
                }
                for r in 0..n {
                    jtj_pinv[(r, c)] += v[(r, kk)] * vc;
                }
            }
        }
        let covariance = Mat::<f64>::from_fn(n, n, |r, c| sigma2 * jtj_pinv[(r, c)]);
        let null_space = Mat::<f64>::from_fn(n, n - rank, |r, c| v[(r, rank + c)]);
        let identifiable: Vec<bool> = (0..n)
            .map(|p| {
                let comp: f64 = (0..n - rank).map(|c| null_space[(p, c)].powi(2)).sum();
                comp.sqrt() <= IDENTIFIABILITY_THRESHOLD
            })
            .collect();
        let std_dev: Vec<Option<f64>> = (0..n)
            .map(|p| {
                let var = covariance[(p, p)];
                (identifiable[p] && var.is_finite() && var >= 0.0).then(|| var.sqrt())
            })
            .collect();
        let correlation = Mat::<f64>::from_fn(n, n, |r, c| match (std_dev[r], std_dev[c]) {
            (Some(a), Some(b)) if a > 0.0 && b > 0.0 => {
                if r == c {
                    1.0
                } else {
                    covariance[(r, c)] / (a * b)
                }
            }
            _ => f64::NAN,
        });
        Ok(Self {
            num_residuals: m,
            num_params: n,
            rank,
            rank_tol: tol,
            singular_values,
            dof,
            cost: 0.5 * ss,
            sigma2,
            jtj_pinv,
            covariance,
            std_dev,
            correlation,
            null_space,
            identifiable,
        })
    }

    fn degenerate(m: usize, n: usize, residuals: &[f64]) -> Self {
        let ss: f64 = residuals.iter().map(|r| r * r).sum();
        Self {
            num_residuals: m,
            num_params: n,
            rank: 0,
            rank_tol: f64::NAN,
            singular_values: Vec::new(),
            dof: m,
            cost: 0.5 * ss,
            sigma2: f64::NAN,
            jtj_pinv: Mat::from_fn(n, n, |_, _| f64::NAN),
            covariance: Mat::from_fn(n, n, |_, _| f64::NAN),
            std_dev: vec![None; n],
            correlation: Mat::from_fn(n, n, |_, _| f64::NAN),
            null_space: Mat::from_fn(n, n, |r, c| if r == c { 1.0 } else { 0.0 }),
            identifiable: vec![false; n],
        }
    }

    /// Whether `rank < num_params`.
    pub fn is_rank_deficient(&self) -> bool {
        self.rank < self.num_params
    }

    /// `s_max / s_min` over the singular values counted in the rank (infinite at rank 0).
    pub fn condition_number(&self) -> f64 {
        if self.rank == 0 {
            f64::INFINITY
        } else {
            self.singular_values[0] / self.singular_values[self.rank - 1]
        }
    }

    /// Residual standard deviation `sqrt(sigma2)`.
    pub fn residual_std_dev(&self) -> f64 {
        self.sigma2.sqrt()
    }

    /// Indices of the unidentifiable parameters.
    pub fn unidentifiable(&self) -> Vec<usize> {
        (0..self.num_params)
            .filter(|&p| !self.identifiable[p])
            .collect()
    }
}

/// Up to this many parameters the SVD is a one-sided Jacobi SVD of `R` (fast and accurate
/// for small matrices); above, faer's SVD of `R`.
const JACOBI_MAX: usize = 48;

/// Singular values (descending, `min(m, n)` of them) and right singular vectors (`n x n`)
/// of `j`. A tall `j` is first reduced to its `n x n` triangular factor `R` (Householder
/// QR), which has the same singular values and right singular vectors; the left ones are
/// never formed.
fn right_svd(j: MatRef<'_, f64>) -> Result<(Vec<f64>, Mat<f64>), LmError> {
    let (m, n) = (j.nrows(), j.ncols());
    let k = m.min(n);
    // Column-major copy of J, reduced in place to R when tall.
    let mut a: Vec<f64> = Vec::with_capacity(m * n);
    for c in 0..n {
        a.extend(j.col(c).iter().copied());
    }
    let p = if m > n {
        r_factor(&mut a, m, n);
        n
    } else {
        m
    };
    if n <= JACOBI_MAX {
        let (mut sv, v) = jacobi_svd(a, p, n);
        sv.truncate(k);
        return Ok((sv, v));
    }
    let svd = MatRef::from_column_major_slice(&a, p, n)
        .svd()
        .map_err(|e| LmError::Numerical(format!("statistics: SVD failed: {e:?}")))?;
    let s_diag = svd.S().column_vector();
    let sv = (0..k).map(|i| s_diag[i]).collect();
    Ok((sv, svd.V().to_owned()))
}

/// Reduces the `m x n` column-major `a` (`m > n`) to the `n x n` upper-triangular `R` of
/// `a = Q R` by Householder reflections, stored column-major in the first `n * n` entries
/// (zeros below the diagonal); `a` is truncated to that.
fn r_factor(a: &mut Vec<f64>, m: usize, n: usize) {
    for c in 0..n {
        let (left, right) = a.split_at_mut((c + 1) * m);
        let x = &mut left[c * m + c..];
        let norm = norm2(x).sqrt();
        if norm == 0.0 {
            continue;
        }
        // v = x - alpha e0 with alpha = -sign(x0) ||x||; (I - 2 v v^T / v^T v) x = alpha e0.
        let alpha = if x[0] < 0.0 { norm } else { -norm };
        x[0] -= alpha;
        let vtv = norm2(x);
        for y in right.chunks_exact_mut(m) {
            let y = &mut y[c..];
            let f = 2.0 * dot(x, y) / vtv;
            for (q, p) in y.iter_mut().zip(x.iter()) {
                *q -= f * p;
            }
        }
        x[0] = alpha;
    }
    for c in 0..n {
        for r in 0..n {
            a[c * n + r] = if r <= c { a[c * m + r] } else { 0.0 };
        }
    }
    a.truncate(n * n);
}

/// One-sided Jacobi SVD (Hestenes) of the `p x n` column-major `ac`: rotates pairs of
/// columns until they are orthogonal to working precision. Returns the `n` column norms
/// (the singular values, padded with zeros when `p < n`) in descending order and the
/// matching right singular vectors.
fn jacobi_svd(mut ac: Vec<f64>, p: usize, n: usize) -> (Vec<f64>, Mat<f64>) {
    let mut vc = vec![0.0; n * n];
    for c in 0..n {
        vc[c * n + c] = 1.0;
    }
    fn rotate(buf: &mut [f64], len: usize, i: usize, k: usize, c: f64, s: f64) {
        let (lo, hi) = buf.split_at_mut(k * len);
        let x = &mut lo[i * len..(i + 1) * len];
        let y = &mut hi[..len];
        for (xa, ya) in x.iter_mut().zip(y.iter_mut()) {
            let (u, w) = (*xa, *ya);
            *xa = c * u - s * w;
            *ya = s * u + c * w;
        }
    }
    // Squared column norms, recomputed at the start of each sweep and updated exactly by
    // each rotation in between (||x'||^2 = alpha - t gamma, ||y'||^2 = beta + t gamma), so a
    // pair costs one dot product instead of three.
    let mut sq = vec![0.0; n];
    for _sweep in 0..80 {
        let mut rotated = false;
        for (c, v) in sq.iter_mut().enumerate() {
            *v = norm2(&ac[c * p..(c + 1) * p]);
        }
        for i in 0..n {
            for k in i + 1..n {
                let gamma = dot(&ac[i * p..(i + 1) * p], &ac[k * p..(k + 1) * p]);
                let (alpha, beta) = (sq[i], sq[k]);
                if gamma == 0.0 || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt() {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                rotate(&mut ac, p, i, k, c, s);
                rotate(&mut vc, n, i, k, c, s);
                sq[i] = (alpha - t * gamma).max(0.0);
                sq[k] = beta + t * gamma;
            }
        }
        if !rotated {
            break;
        }
    }
    let norms: Vec<f64> = (0..n)
        .map(|c| norm2(&ac[c * p..(c + 1) * p]).sqrt())
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| norms[y].total_cmp(&norms[x]));
    let sv = order.iter().map(|&c| norms[c]).collect();
    let vs = Mat::from_fn(n, n, |r, c| vc[order[c] * n + r]);
    (sv, vs)
}

impl fmt::Display for Statistics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "statistics: rank {} of {} (tol {:.3e}, condition {:.3e}), {} degrees of freedom, sigma^2 = {:.6e}",
            self.rank,
            self.num_params,
            self.rank_tol,
            self.condition_number(),
            self.dof,
            self.sigma2
        )?;
        if self.is_rank_deficient() {
            writeln!(
                f,
                "rank deficient: unidentifiable parameters {:?}",
                self.unidentifiable()
            )?;
        }
        writeln!(f, "{:>6} {:>14}", "param", "std dev")?;
        for (p, s) in self.std_dev.iter().enumerate() {
            match s {
                Some(s) => writeln!(f, "{p:>6} {s:>14.6e}")?,
                None => writeln!(f, "{p:>6} {:>14}", "unidentified")?,
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_rank_covariance_matches_inverse() {
        // J = diag(2, 4) stacked with a row: JtJ is easy to invert by hand.
        let j = faer::mat![[2.0, 0.0], [0.0, 4.0], [0.0, 0.0]];
        let r = [1.0, 1.0, 1.0];
        let st = Statistics::from_jacobian(j.as_ref(), &r, None);
        assert_eq!(st.rank, 2);
        assert_eq!(st.dof, 1);
        assert!((st.sigma2 - 3.0).abs() < 1e-14);
        assert!((st.covariance[(0, 0)] - 3.0 / 4.0).abs() < 1e-14);
        assert!((st.covariance[(1, 1)] - 3.0 / 16.0).abs() < 1e-14);
        assert!((st.std_dev[0].unwrap() - (0.75f64).sqrt()).abs() < 1e-14);
        assert_eq!(st.correlation[(0, 0)], 1.0);
        assert!(st.correlation[(0, 1)].abs() < 1e-14);
        assert_eq!(st.null_space.ncols(), 0);
    }

    #[test]
    fn wide_jacobian_has_null_space() {
        let j = faer::mat![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let st = Statistics::from_jacobian(j.as_ref(), &[0.0, 0.0], None);
        assert_eq!(st.rank, 2);
        assert_eq!(st.null_space.ncols(), 1);
        assert_eq!(st.identifiable, vec![true, true, false]);
        // dof = 0 -> sigma2 undefined -> no std at all.
        assert!(st.sigma2.is_nan());
        assert!(st.std_dev.iter().all(Option::is_none));
    }

    #[test]
    fn jacobi_and_faer_svds_agree() {
        // Tall, square and wide matrices, one of them rank deficient.
        for (m, n) in [(9usize, 4usize), (5, 5), (3, 6), (70, 60)] {
            let a = Mat::<f64>::from_fn(m, n, |i, k| {
                let v = ((i * 7 + k * 13) % 11) as f64 - 5.0 + 0.1 * k as f64;
                if k == 3 && n > 4 {
                    ((i * 7) % 11) as f64 - 5.0 // column 3 = column 0 without the shift
                } else {
                    v
                }
            });
            let (sv, v) = right_svd(a.as_ref()).unwrap();
            let reference = a.svd().unwrap();
            let s_ref = reference.S().column_vector();
            assert_eq!(sv.len(), m.min(n));
            for i in 0..sv.len() {
                assert!(
                    (sv[i] - s_ref[i]).abs() <= 1e-12 * s_ref[0],
                    "{m}x{n}: {sv:?}"
                );
            }
            // A V = U S: the columns of A V have norms equal to the singular values.
            let av = &a * &v;
            for c in 0..sv.len() {
                let norm = av.col(c).norm_l2();
                assert!((norm - sv[c]).abs() <= 1e-12 * s_ref[0]);
            }
            // V is orthogonal.
            let vtv = v.transpose() * &v;
            for r in 0..n {
                for c in 0..n {
                    let e = if r == c { 1.0 } else { 0.0 };
                    assert!((vtv[(r, c)] - e).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn bad_input_does_not_panic() {
        let j = faer::mat![[f64::NAN, 1.0]];
        let st = Statistics::from_jacobian(j.as_ref(), &[1.0], None);
        assert_eq!(st.rank, 0);
        assert!(Statistics::try_from_jacobian(j.as_ref(), &[1.0, 2.0], None).is_err());
    }
}
