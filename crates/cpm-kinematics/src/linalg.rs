//! The SVD of the small, tall Jacobians of kinematics (J1, its condition number, eq. 12),
//! through faer after an exact power-of-two scaling.
//!
//! The matrix is multiplied by the power of two nearest below the inverse of its largest
//! entry (an exact operation: only exponents change), decomposed by faer's bidiagonal SVD
//! with sequential execution, and the singular values are multiplied back. Scaling keeps
//! the computation away from overflow and underflow whatever the units; the factors `U` and
//! `V` do not depend on it.
//!
//! Accuracy. nalgebra 0.34's bidiagonal SVD can lose accuracy on small matrices: on a 6x6
//! J1 of the paper's cube (singular values 465 .. 0.55) its `U S V^T` misses the matrix by
//! 1.6e-6 (nalgebra issue #1172). faer's SVD reconstructs that matrix to rounding, and
//! over 10^6 random J1 of the paper cube and the 6-6 hexapod at random reachable poses its
//! worst relative reconstruction error `||U S V^T - A|| / ||A||` is a few 1e-15, with no
//! failure (`tests/svd_random_j1.rs`). The hand-written one-sided Jacobi SVD this module
//! held before failed to converge on 25 of those 10^6 well-conditioned matrices.
//!
//! AVX-512: faer's AVX-512 matrix-product kernels, which leave the upper vector registers
//! dirty and slow the scalar code after them (see `cpm_lm::stats`), start above 16^3
//! multiply-adds; a 6x6 SVD stays below. Measured: 10^6 scalar multiply-adds 1.16 ms after
//! a 6x6 faer SVD against 1.2 ms after scalar code (`cpm-lm/tests/avx_after_svd.rs`).
//!
//! Failure is an error that names itself ([`SvdError`]), never an infinite condition number.
//!
//! ```
//! use cpm_kinematics::linalg::Svd;
//! use nalgebra::{dmatrix, dvector};
//! let a = dmatrix![3.0, 0.0; 0.0, 4.0; 0.0, 0.0];
//! let svd = Svd::new(&a).unwrap();
//! assert_eq!(svd.singular_values.as_slice(), &[4.0, 3.0]);
//! assert!((svd.condition_number() - 4.0 / 3.0).abs() < 1e-15);
//! let x = svd.solve(&dvector![3.0, 8.0, 1.0], 0.0);
//! assert!((x - dvector![1.0, 2.0]).norm() < 1e-15);
//! // Wider than tall, or not finite: a named error.
//! assert!(Svd::new(&dmatrix![1.0, 2.0]).is_err());
//! ```
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::svd::{self, ComputeSvdVectors};
use faer::{Mat, Par};
use nalgebra::{DMatrix, DVector};
use thiserror::Error;

/// Why an SVD could not be computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SvdError {
    /// An entry is NaN or infinite.
    #[error(
        "SVD: the {rows}x{cols} matrix has a non-finite entry at row {row}, column {col} (1-based)"
    )]
    NonFinite {
        /// Rows of the matrix.
        rows: usize,
        /// Columns of the matrix.
        cols: usize,
        /// Row of the first non-finite entry, 1-based.
        row: usize,
        /// Column of that entry, 1-based.
        col: usize,
    },
    /// The matrix is wider than tall or empty (this SVD needs `rows >= cols >= 1`).
    #[error("SVD: the matrix is {rows}x{cols}; it needs rows >= cols >= 1")]
    Shape {
        /// Rows of the matrix.
        rows: usize,
        /// Columns of the matrix.
        cols: usize,
    },
    /// faer's SVD reached its iteration limit (not seen on 10^6 random J1).
    #[error("SVD: faer's SVD did not converge on the {rows}x{cols} matrix")]
    NoConvergence {
        /// Rows of the matrix.
        rows: usize,
        /// Columns of the matrix.
        cols: usize,
    },
}

/// `2^k` for any `k` in `-2044..=2046` as the product of two normal powers of two.
fn pow2_pair(k: i32) -> (f64, f64) {
    let one = |e: i32| f64::from_bits(((e + 1023) as u64) << 52);
    let h = k / 2;
    (one(h), one(k - h))
}

/// The exponent `e` with `2^e <= x < 2^(e+1)` for a finite `x > 0` (subnormals included).
fn exponent(x: f64) -> i32 {
    let field = ((x.to_bits() >> 52) & 0x7ff) as i32;
    if field == 0 {
        // Subnormal: scale up exactly first.
        exponent(x * f64::from_bits((1023u64 + 64) << 52)) - 64
    } else {
        field - 1023
    }
}

/// The power-of-two exponent `e` such that `x * 2^-e` has its largest absolute entry in
/// `[1, 2)`; `None` for an all-zero slice. The scaling by `2^-e` is exact (entries that
/// would become subnormal aside).
pub fn scaling_exponent<'a>(values: impl IntoIterator<Item = &'a f64>) -> Option<i32> {
    let max = values.into_iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (max > 0.0).then(|| exponent(max))
}

/// Multiplies every entry by `2^k` (exact, barring overflow or subnormal results).
pub fn scale_by_pow2(values: &mut [f64], k: i32) {
    let (a, b) = pow2_pair(k);
    for v in values {
        *v = *v * a * b;
    }
}

/// `x * 2^k`.
pub fn times_pow2(x: f64, k: i32) -> f64 {
    let (a, b) = pow2_pair(k);
    x * a * b
}

/// Checks shape (`rows >= cols >= 1`) and finiteness.
fn check(a: &DMatrix<f64>) -> Result<(), SvdError> {
    let (rows, cols) = a.shape();
    if cols == 0 || rows < cols {
        return Err(SvdError::Shape { rows, cols });
    }
    if let Some(k) = a.iter().position(|v| !v.is_finite()) {
        return Err(SvdError::NonFinite {
            rows,
            cols,
            row: k % rows + 1,
            col: k / rows + 1,
        });
    }
    Ok(())
}

/// Thin `U` and `V` as faer matrices.
type Factors = (Mat<f64>, Mat<f64>);

/// faer's SVD of the scaled `a` (`rows >= cols`): singular values (scaled) and, when asked,
/// thin `U` and `V`.
fn faer_svd(
    a: &DMatrix<f64>,
    e: i32,
    vectors: bool,
) -> Result<(Vec<f64>, Option<Factors>), SvdError> {
    let (m, n) = a.shape();
    let (f1, f2) = pow2_pair(-e);
    let scaled = Mat::<f64>::from_fn(m, n, |i, j| a[(i, j)] * f1 * f2);
    let mut s = faer::diag::Diag::<f64>::zeros(n);
    let compute = if vectors {
        ComputeSvdVectors::Thin
    } else {
        ComputeSvdVectors::No
    };
    let (mut u, mut v) = if vectors {
        (Mat::<f64>::zeros(m, n), Mat::<f64>::zeros(n, n))
    } else {
        (Mat::<f64>::zeros(0, 0), Mat::<f64>::zeros(0, 0))
    };
    let par = Par::Seq;
    let mut buf = MemBuffer::new(svd::svd_scratch::<f64>(
        m,
        n,
        compute,
        compute,
        par,
        Default::default(),
    ));
    svd::svd(
        scaled.as_ref(),
        s.as_mut(),
        vectors.then(|| u.as_mut()),
        vectors.then(|| v.as_mut()),
        par,
        MemStack::new(&mut buf),
        Default::default(),
    )
    .map_err(|_| SvdError::NoConvergence { rows: m, cols: n })?;
    let sv = s.column_vector().iter().copied().collect();
    Ok((sv, vectors.then_some((u, v))))
}

/// The singular values of `a` (`rows >= cols >= 1`), largest first, without the vectors
/// (cheaper; for condition numbers).
pub fn singular_values(a: &DMatrix<f64>) -> Result<Vec<f64>, SvdError> {
    check(a)?;
    let Some(e) = scaling_exponent(a.iter()) else {
        return Ok(vec![0.0; a.ncols()]);
    };
    let (mut sv, _) = faer_svd(a, e, false)?;
    sv.iter_mut().for_each(|s| *s = times_pow2(*s, e));
    Ok(sv)
}

/// Largest over smallest singular value of `a` (`rows >= cols >= 1`); infinite when the
/// smallest is zero (a singular matrix), an error when the SVD cannot be computed.
pub fn condition_number(a: &DMatrix<f64>) -> Result<f64, SvdError> {
    let sv = singular_values(a)?;
    Ok(ratio(&sv))
}

fn ratio(sv: &[f64]) -> f64 {
    let (mx, mn) = (sv[0], sv[sv.len() - 1]);
    if mn > 0.0 {
        mx / mn
    } else {
        f64::INFINITY
    }
}

/// Singular value decomposition `A = U diag(s) V^T` of an `m x n` matrix with `m >= n`.
#[derive(Debug, Clone, PartialEq)]
pub struct Svd {
    /// `m x n`, orthonormal columns.
    pub u: DMatrix<f64>,
    /// The `n` singular values, largest first.
    pub singular_values: DVector<f64>,
    /// `n x n`, orthogonal.
    pub v: DMatrix<f64>,
}

impl Svd {
    /// The SVD of `a` (`rows >= cols >= 1`). Errors: [`SvdError::Shape`] when `a` is wider
    /// than tall or empty, [`SvdError::NonFinite`] for a NaN or infinite entry,
    /// [`SvdError::NoConvergence`] when faer's iteration does not converge.
    pub fn new(a: &DMatrix<f64>) -> Result<Self, SvdError> {
        check(a)?;
        let (m, n) = a.shape();
        let Some(e) = scaling_exponent(a.iter()) else {
            return Ok(Self {
                u: DMatrix::identity(m, n),
                singular_values: DVector::zeros(n),
                v: DMatrix::identity(n, n),
            });
        };
        let (sv, vectors) = faer_svd(a, e, true)?;
        let (u, v) = vectors.expect("vectors were asked for");
        Ok(Self {
            u: DMatrix::from_fn(m, n, |i, j| u[(i, j)]),
            singular_values: DVector::from_iterator(n, sv.iter().map(|s| times_pow2(*s, e))),
            v: DMatrix::from_fn(n, n, |i, j| v[(i, j)]),
        })
    }

    /// Largest over smallest singular value; infinite when the smallest is zero.
    pub fn condition_number(&self) -> f64 {
        ratio(self.singular_values.as_slice())
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
