//! A small, accurate SVD (one-sided Jacobi) for the tall, thin Jacobians of kinematics.
//!
//! nalgebra 0.34's bidiagonal SVD can lose accuracy on small matrices: on a 6x6 J1 of the
//! paper's cube (singular values 465 .. 0.55) its `U S V^T` misses the matrix by 1.6e-6 and a
//! least-squares solve through it is wrong in the eighth digit (nalgebra issue #1172, open at
//! the time of writing). One-sided Jacobi orthogonalises
//! the columns by plane rotations and is accurate to rounding (singular values to high
//! relative accuracy), which is what eq. 12 and the condition numbers here need.
//!
//! ```
//! use cpm_kinematics::linalg::Svd;
//! use nalgebra::{dmatrix, dvector};
//! let a = dmatrix![3.0, 0.0; 0.0, 4.0; 0.0, 0.0];
//! let svd = Svd::new(&a).unwrap();
//! assert_eq!(svd.singular_values.as_slice(), &[4.0, 3.0]);
//! assert_eq!(svd.condition_number(), 4.0 / 3.0);
//! let x = svd.solve(&dvector![3.0, 8.0, 1.0], 0.0);
//! assert!((x - dvector![1.0, 2.0]).norm() < 1e-15);
//! ```
use nalgebra::{DMatrix, DVector};

/// Singular value decomposition `A = U diag(s) V^T` of an `m x n` matrix with `m >= n`.
#[derive(Debug, Clone, PartialEq)]
pub struct Svd {
    /// `m x n`, orthonormal columns (a column is zero where its singular value is zero).
    pub u: DMatrix<f64>,
    /// The `n` singular values, largest first.
    pub singular_values: DVector<f64>,
    /// `n x n`, orthogonal.
    pub v: DMatrix<f64>,
}

impl Svd {
    /// The SVD of `a` (`rows >= cols >= 1`); `None` when `a` has a non-finite entry, is wider
    /// than tall, or the sweeps do not converge (not seen in practice).
    pub fn new(a: &DMatrix<f64>) -> Option<Self> {
        let (m, n) = a.shape();
        if n == 0 || m < n || !a.iter().all(|v| v.is_finite()) {
            return None;
        }
        // Scale to unit max entry so that squares neither overflow nor underflow.
        let scale = a.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        if scale == 0.0 {
            return Some(Self {
                u: DMatrix::zeros(m, n),
                singular_values: DVector::zeros(n),
                v: DMatrix::identity(n, n),
            });
        }
        let mut w = a / scale;
        let mut v = DMatrix::<f64>::identity(n, n);
        let mut converged = false;
        for _sweep in 0..60 {
            let mut rotated = false;
            for p in 0..n - 1 {
                for q in p + 1..n {
                    let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
                    for i in 0..m {
                        let (x, y) = (w[(i, p)], w[(i, q)]);
                        alpha += x * x;
                        beta += y * y;
                        gamma += x * y;
                    }
                    if gamma == 0.0 || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt() {
                        continue;
                    }
                    rotated = true;
                    let zeta = (beta - alpha) / (2.0 * gamma);
                    let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                    let c = 1.0 / (1.0 + t * t).sqrt();
                    let s = c * t;
                    for i in 0..m {
                        let (x, y) = (w[(i, p)], w[(i, q)]);
                        w[(i, p)] = c * x - s * y;
                        w[(i, q)] = s * x + c * y;
                    }
                    for i in 0..n {
                        let (x, y) = (v[(i, p)], v[(i, q)]);
                        v[(i, p)] = c * x - s * y;
                        v[(i, q)] = s * x + c * y;
                    }
                }
            }
            if !rotated {
                converged = true;
                break;
            }
        }
        if !converged {
            return None;
        }
        let norms: Vec<f64> = (0..n).map(|j| w.column(j).norm()).collect();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&i, &j| norms[j].total_cmp(&norms[i]));
        let mut u = DMatrix::zeros(m, n);
        let mut vs = DMatrix::zeros(n, n);
        let mut s = DVector::zeros(n);
        for (k, &j) in order.iter().enumerate() {
            s[k] = norms[j] * scale;
            if norms[j] > 0.0 {
                u.set_column(k, &(w.column(j) / norms[j]));
            }
            vs.set_column(k, &v.column(j));
        }
        Some(Self {
            u,
            singular_values: s,
            v: vs,
        })
    }

    /// Largest over smallest singular value; infinite when the smallest is zero.
    pub fn condition_number(&self) -> f64 {
        let n = self.singular_values.len();
        let (mx, mn) = (self.singular_values[0], self.singular_values[n - 1]);
        if mn > 0.0 {
            mx / mn
        } else {
            f64::INFINITY
        }
    }

    /// The least-squares, minimum-norm solution `x = V diag(1/s) U^T b`, dropping singular
    /// values at or below `rcond` times the largest. `b.len()` must be the row count.
    pub fn solve(&self, b: &DVector<f64>, rcond: f64) -> DVector<f64> {
        let cut = rcond * self.singular_values[0];
        let mut c = self.u.tr_mul(b);
        for (ck, sk) in c.iter_mut().zip(self.singular_values.iter()) {
            *ck = if *sk > cut && *sk > 0.0 {
                *ck / sk
            } else {
                0.0
            };
        }
        &self.v * c
    }
}
