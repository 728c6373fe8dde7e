//! Statistics of a least-squares fit from its Jacobian: numerical rank, parameter
//! covariance, standard deviations, correlations and identifiability.
//!
//! The Jacobian's columns are first equilibrated: `J_s = J D^-1` with `D = diag(d_j)`, `d_j`
//! the Euclidean norm of column `j` (1 for a zero column), computed without overflow. With
//! the SVD `J_s = U S W^T` (singular values `s_1 >= s_2 >= ...`, computed by faer after a
//! Householder QR of `J_s`), the numerical rank is the number of singular values above `tol`
//! (default `max(m, n) * eps * s_1`, the LAPACK/NumPy convention). Then, with
//! `v_k = D^-1 w_k`,
//!
//! * `(J^T J)^+ = sum_{k < rank} v_k v_k^T / s_k^2` (the inverse when `J` has full column
//!   rank; otherwise a generalised inverse whose entries for identifiable parameters are
//!   the pseudo-inverse's),
//! * `sigma^2 = ||r||^2 / (m - rank) = 2 cost / (m - rank)` (undefined, NaN, when `m = rank`),
//! * `covariance = sum_k (sigma v_k / s_k)(sigma v_k / s_k)^T`, `std_j = sqrt(covariance_jj)`
//!   computed as the norm of `(sigma v_jk / s_k)_k` (never `sigma^2 * 1/s^2`, which
//!   overflows to `inf * 0`), `correlation_ij = covariance_ij / (std_i std_j)`.
//!
//! The numerical null space is spanned by the remaining `w_k`. A parameter whose unit
//! vector has a component of norm above [`IDENTIFIABILITY_THRESHOLD`] in it can be changed
//! without changing the fit to first order: it is *unidentifiable*, and its standard
//! deviation is `None` instead of the finite but meaningless number the pseudo-inverse would
//! give.
//!
//! **Scale invariance.** Equilibration makes the rank, the singular values, the
//! identifiability and the standard deviations times the column scales independent of the
//! parameters' units: a Jacobian with entries near `1e150` or `1e-200` (residuals scaled
//! alike), or with column scales spread over `1e-100 .. 1e100`, gives the rank and
//! relative standard deviations of the unscaled problem to rounding, and no NaN
//! (`tests/stats_scale.rs`). Only `sigma2`, `cost` and `jtj_pinv` may leave the range of
//! `f64` at such scales, as the numbers themselves do.
//!
//! **AVX-512.** faer's matrix products above 16^3 multiply-adds run hand-written AVX-512
//! kernels on machines that have it, and those leave the upper halves of the vector
//! registers dirty (no `vzeroupper`); the ordinary SSE floating-point code that runs next
//! then slows down until something clears them. Measured on this project's AMD EPYC build
//! machine (`tests/avx_after_svd.rs`, release): 10^6 scalar multiply-adds took 1.2 ms, and
//! 2.2-6.4 ms (2-5x) right after a faer SVD of a 40x40 or 60x60 matrix. The statistics
//! therefore end with [`clear_upper_vector_registers`] (one 256-bit operation in pulp's AVX2
//! dispatch, which the compiler closes with `vzeroupper`): after `Statistics` of a 2000x60
//! Jacobian the same loop takes 1.17 ms (0.97x). A 6x6 SVD (kinematics) does not reach
//! those kernels (1.16 ms, 0.97x).

use std::fmt;

use faer::{Mat, MatRef};

use crate::error::LmError;

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
        // Column equilibration J_s = J D^-1 (entries at most 1 in magnitude).
        let d: Vec<f64> = (0..n)
            .map(|c| {
                let norm = robust_norm((0..m).map(|i| j[(i, c)]));
                if norm > 0.0 {
                    norm
                } else {
                    1.0
                }
            })
            .collect();
        let (singular_values, w) = right_svd(j, &d)?;
        let s_max = singular_values.first().copied().unwrap_or(0.0);
        let tol = rank_tol.unwrap_or(m.max(n) as f64 * f64::EPSILON * s_max);
        let rank = singular_values.iter().filter(|&&s| s > tol).count();

        let rnorm = robust_norm(residuals.iter().copied());
        let ss = rnorm * rnorm;
        let dof = m - rank;
        let sigma = if dof > 0 {
            rnorm / (dof as f64).sqrt()
        } else {
            f64::NAN
        };
        let sigma2 = sigma * sigma;

        // a[p][k] = w_pk / (d_p s_k): the columns of V S^-1 in the parameters' units.
        let a_fac = Mat::<f64>::from_fn(n, rank, |p, k| w[(p, k)] / d[p] / singular_values[k]);
        let mut jtj_pinv = Mat::<f64>::zeros(n, n);
        let mut covariance = Mat::<f64>::zeros(n, n);
        for c in 0..n {
            for r in 0..n {
                let (mut pinv, mut cov) = (0.0, 0.0);
                for k in 0..rank {
                    pinv += a_fac[(r, k)] * a_fac[(c, k)];
                    cov += (sigma * a_fac[(r, k)]) * (sigma * a_fac[(c, k)]);
                }
                jtj_pinv[(r, c)] = pinv;
                covariance[(r, c)] = cov;
            }
        }
        let null_space = null_space_basis(&w, &d, rank);
        // faer is done: leave the upper vector registers clean for the scalar code after.
        clear_upper_vector_registers();
        let identifiable: Vec<bool> = (0..n)
            .map(|p| {
                let comp: f64 = (rank..n).map(|c| w[(p, c)].powi(2)).sum();
                comp.sqrt() <= IDENTIFIABILITY_THRESHOLD
            })
            .collect();
        let std_dev: Vec<Option<f64>> = (0..n)
            .map(|p| {
                let sd = robust_norm((0..rank).map(|k| sigma * a_fac[(p, k)]));
                (identifiable[p] && sd.is_finite()).then_some(sd)
            })
            .collect();
        let correlation = Mat::<f64>::from_fn(n, n, |r, c| match (std_dev[r], std_dev[c]) {
            (Some(a), Some(b)) if a > 0.0 && b > 0.0 => {
                if r == c {
                    1.0
                } else {
                    // From the factors, so that a covariance beyond f64's range does not
                    // turn into inf / inf.
                    (0..rank)
                        .map(|k| (sigma * a_fac[(r, k)] / a) * (sigma * a_fac[(c, k)] / b))
                        .sum()
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

/// The Euclidean norm of `values` without overflow or underflow (scaled by the largest
/// magnitude first); 0 for no values or all zeros, NaN if any is NaN.
fn robust_norm(values: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = values.clone().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(max > 0.0) || max.is_infinite() {
        return if values.clone().any(f64::is_nan) {
            f64::NAN
        } else {
            max
        };
    }
    let ss: f64 = values.map(|v| (v / max) * (v / max)).sum();
    max * ss.sqrt()
}

/// Singular values (descending, `min(m, n)` of them) and right singular vectors (`n x n`)
/// of the column-equilibrated `j D^-1`. A tall matrix is first reduced to its `n x n`
/// triangular factor `R` (faer's Householder QR, in place on the one copy), which has the
/// same singular values and right singular vectors; the left ones are never formed. faer
/// runs sequentially.
fn right_svd(j: MatRef<'_, f64>, d: &[f64]) -> Result<(Vec<f64>, Mat<f64>), LmError> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::qr::no_pivoting::factor as qr;
    use faer::linalg::svd::{self, ComputeSvdVectors};
    use faer::Par;
    let (m, n) = (j.nrows(), j.ncols());
    let k = m.min(n);
    let par = Par::Seq;
    let mut a = Mat::<f64>::from_fn(m, n, |i, c| j[(i, c)] / d[c]);
    let r = if m > n {
        let bs = qr::recommended_block_size::<f64>(m, n);
        let mut coeff = Mat::<f64>::zeros(bs, n);
        let mut buf = MemBuffer::new(qr::qr_in_place_scratch::<f64>(
            m,
            n,
            bs,
            par,
            Default::default(),
        ));
        qr::qr_in_place(
            a.as_mut(),
            coeff.as_mut(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        );
        Mat::<f64>::from_fn(n, n, |i, c| if i <= c { a[(i, c)] } else { 0.0 })
    } else {
        a
    };
    let (p, _) = r.shape();
    let mut s = faer::diag::Diag::<f64>::zeros(p.min(n));
    let mut v = Mat::<f64>::zeros(n, n);
    let mut buf = MemBuffer::new(svd::svd_scratch::<f64>(
        p,
        n,
        ComputeSvdVectors::No,
        ComputeSvdVectors::Full,
        par,
        Default::default(),
    ));
    svd::svd(
        r.as_ref(),
        s.as_mut(),
        None,
        Some(v.as_mut()),
        par,
        MemStack::new(&mut buf),
        Default::default(),
    )
    .map_err(|e| LmError::Numerical(format!("statistics: faer's SVD failed: {e:?}")))?;
    let sv = s.column_vector().iter().take(k).copied().collect();
    Ok((sv, v))
}

/// Leaves the upper halves of the vector registers clean after faer (see the module doc;
/// call it after other faer work whose caller runs long scalar code next):
/// runs one 256-bit operation inside pulp's AVX2 dispatch, whose compiled function ends
/// with `vzeroupper`. A no-op where the processor has no AVX2.
pub fn clear_upper_vector_registers() {
    struct Touch;
    impl pulp::WithSimd for Touch {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, simd: S) {
            let z = simd.splat_f64s(std::hint::black_box(0.0));
            std::hint::black_box(simd.add_f64s(z, z));
        }
    }
    pulp::Arch::new().dispatch(Touch);
}

/// Orthonormal basis of the null space of `J` from that of `J D^-1` (the columns `rank..`
/// of `w`): `D^-1 w_k`, each column scaled to unit max entry, orthonormalised by faer's QR.
fn null_space_basis(w: &Mat<f64>, d: &[f64], rank: usize) -> Mat<f64> {
    let n = w.nrows();
    let q = n - rank;
    if q == 0 {
        return Mat::zeros(n, 0);
    }
    let mut b = Mat::<f64>::from_fn(n, q, |r, c| w[(r, rank + c)] / d[r]);
    for c in 0..q {
        let max = (0..n).fold(0.0f64, |m, r| m.max(b[(r, c)].abs()));
        if max > 0.0 && max.is_finite() {
            for r in 0..n {
                b[(r, c)] /= max;
            }
        }
    }
    let uniform = d.iter().all(|&x| x == d[0]);
    if uniform {
        // D is a multiple of the identity: the w_k themselves are the basis.
        return Mat::from_fn(n, q, |r, c| w[(r, rank + c)]);
    }
    b.qr().compute_thin_Q()
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
    fn right_svd_agrees_with_faer_on_the_equilibrated_matrix() {
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
            let d: Vec<f64> = (0..n).map(|c| a.col(c).norm_l2()).collect();
            let (sv, v) = right_svd(a.as_ref(), &d).unwrap();
            let scaled = Mat::<f64>::from_fn(m, n, |i, c| a[(i, c)] / d[c]);
            let reference = scaled.svd().unwrap();
            let s_ref = reference.S().column_vector();
            assert_eq!(sv.len(), m.min(n));
            for i in 0..sv.len() {
                assert!(
                    (sv[i] - s_ref[i]).abs() <= 1e-12 * s_ref[0],
                    "{m}x{n}: {sv:?}"
                );
            }
            // A_s V = U S: the columns of A_s V have norms equal to the singular values.
            let av = &scaled * &v;
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
