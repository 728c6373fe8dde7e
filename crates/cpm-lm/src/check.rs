//! A Jacobian checker: compares an analytic Jacobian with central finite differences.
//!
//! **Step.** Column `j` is differenced with `h_j = step * max(|x_j|, s_j)`:
//! `(r(x + h_j e_j) - r(x - h_j e_j)) / (2 h_j)`, whose error is `O(h^2)` from truncation
//! plus `O(eps T / h)` from rounding, `T` the size of the terms of the residuals. The floor
//! `s_j = min(1, T_max / c_j)` is the change of `x_j` that moves the residuals' terms by
//! their own size, capped at 1 (the scale the checker uses at `x_j = 0`, so that a column
//! of tiny derivatives, an exponential far in its tail, is not differenced with a huge
//! step): `T_max = max_i t_i` with `t_i = |r_i(x)| + sum_k |J_ik x_k|` (the magnitude of
//! the terms that make up residual `i`, to first order) and `c_j = max_i |J_ij|` (the floor
//! is 1 when the column or the terms are zero). A parameter that is small but not zero (the Watson
//! function's first one at its minimum, about 1.5e-5 beside others near 1) is thus not
//! differenced with a step of `1e-6 |x_j|`, lost in rounding; a parameter in small units
//! has a large column and keeps a small step. `step = 1e-6` is a good default.
//!
//! **Allowance.** The relative error of an entry is
//!
//! ```text
//! max(0, |analytic - numeric| - noise) / max(|analytic|, |numeric|, 1e-3 * c_j)
//! ```
//!
//! where `c_j` is the largest magnitude in column `j` (entries tiny compared with their
//! column are judged against the column's scale) and `noise = 16 eps max(t_i, |r_i(x +
//! h_j e_j)|, |r_i(x - h_j e_j)|) / (2 h_j)` estimates the rounding error of the difference
//! from the magnitude of the terms that cancel inside the residual, not from the residual
//! itself (a residual near zero at a minimum is a difference of terms of order one, each
//! rounded at `eps` of its own size). The absolute error is reported as is.

use std::fmt;

use faer::Mat;

use crate::error::{EvalStage, LmError};
use crate::problem::{DenseJacobian, Problem, SparseJacobian};

/// Result of [`check_jacobian`].
#[derive(Clone, Debug)]
pub struct JacobianCheck {
    /// The analytic Jacobian.
    pub analytic: Mat<f64>,
    /// The central-difference Jacobian.
    pub numeric: Mat<f64>,
    /// Largest `|analytic - numeric|`.
    pub max_abs_error: f64,
    /// `(row, col)` of the largest absolute error.
    pub max_abs_entry: (usize, usize),
    /// Largest relative error (see the [module documentation](self)).
    pub max_rel_error: f64,
    /// `(row, col)` of the largest relative error.
    pub max_rel_entry: (usize, usize),
    /// The relative step given (each column's step is this times `max(|x_j|, s_j)`).
    pub step: f64,
}

impl JacobianCheck {
    /// Whether the largest relative error is at most `rel_tol`.
    pub fn is_consistent(&self, rel_tol: f64) -> bool {
        self.max_rel_error <= rel_tol
    }
}

impl fmt::Display for JacobianCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (ai, aj) = self.max_abs_entry;
        let (ri, rj) = self.max_rel_entry;
        write!(
            f,
            "Jacobian check (step {:.1e}): max abs error {:.3e} at ({ai}, {aj}) [analytic {:.6e}, numeric {:.6e}]; \
             max rel error {:.3e} at ({ri}, {rj}) [analytic {:.6e}, numeric {:.6e}]",
            self.step,
            self.max_abs_error,
            self.analytic[(ai, aj)],
            self.numeric[(ai, aj)],
            self.max_rel_error,
            self.analytic[(ri, rj)],
            self.numeric[(ri, rj)],
        )
    }
}

fn model_err(stage: EvalStage) -> impl FnOnce(crate::ModelError) -> LmError {
    move |source| LmError::Model {
        iteration: 0,
        stage,
        source,
    }
}

fn finite_differences<P: Problem + ?Sized>(
    problem: &mut P,
    x: &[f64],
    analytic: &Mat<f64>,
    step: f64,
) -> Result<(Mat<f64>, Mat<f64>), LmError> {
    let (m, n) = (problem.num_residuals(), problem.num_params());
    let mut xp = x.to_vec();
    let mut rp = vec![0.0; m];
    let mut rm = vec![0.0; m];
    problem
        .residuals(x, &mut rp)
        .map_err(model_err(EvalStage::Residuals))?;
    // Magnitude of the terms of each residual, to first order.
    let terms: Vec<f64> = (0..m)
        .map(|i| rp[i].abs() + (0..n).map(|k| (analytic[(i, k)] * x[k]).abs()).sum::<f64>())
        .collect();
    let t_max = terms.iter().fold(0.0f64, |a, &t| a.max(t));
    let mut num = Mat::<f64>::zeros(m, n);
    let mut noise = Mat::<f64>::zeros(m, n);
    for j in 0..n {
        let c = (0..m).fold(0.0f64, |a, i| a.max(analytic[(i, j)].abs()));
        let floor = t_max / c;
        let floor = if floor.is_finite() && floor > 0.0 {
            floor.min(1.0)
        } else {
            1.0
        };
        let h = step * x[j].abs().max(floor);
        xp[j] = x[j] + h;
        let hp = xp[j] - x[j];
        problem
            .residuals(&xp, &mut rp)
            .map_err(model_err(EvalStage::Residuals))?;
        xp[j] = x[j] - h;
        let hm = x[j] - xp[j];
        problem
            .residuals(&xp, &mut rm)
            .map_err(model_err(EvalStage::Residuals))?;
        xp[j] = x[j];
        for i in 0..m {
            num[(i, j)] = (rp[i] - rm[i]) / (hp + hm);
            let size = terms[i].max(rp[i].abs()).max(rm[i].abs());
            noise[(i, j)] = 16.0 * f64::EPSILON * size / (hp + hm);
        }
    }
    Ok((num, noise))
}

fn compare(
    analytic: Mat<f64>,
    (numeric, noise): (Mat<f64>, Mat<f64>),
    step: f64,
) -> Result<JacobianCheck, LmError> {
    let (m, n) = (analytic.nrows(), analytic.ncols());
    let mut out = JacobianCheck {
        analytic,
        numeric,
        max_abs_error: 0.0,
        max_abs_entry: (0, 0),
        max_rel_error: 0.0,
        max_rel_entry: (0, 0),
        step,
    };
    for j in 0..n {
        let mut cmax = 0.0f64;
        for i in 0..m {
            let (a, b) = (out.analytic[(i, j)], out.numeric[(i, j)]);
            if !a.is_finite() || !b.is_finite() {
                return Err(LmError::Numerical(format!(
                    "Jacobian check: non-finite entry ({i}, {j}): analytic {a}, numeric {b}"
                )));
            }
            cmax = cmax.max(a.abs()).max(b.abs());
        }
        let floor = 1e-3 * cmax;
        for i in 0..m {
            let (a, b) = (out.analytic[(i, j)], out.numeric[(i, j)]);
            let err = (a - b).abs();
            if err > out.max_abs_error {
                out.max_abs_error = err;
                out.max_abs_entry = (i, j);
            }
            let den = a.abs().max(b.abs()).max(floor);
            let excess = (err - noise[(i, j)]).max(0.0);
            let rel = if den > 0.0 { excess / den } else { 0.0 };
            if rel > out.max_rel_error {
                out.max_rel_error = rel;
                out.max_rel_entry = (i, j);
            }
        }
    }
    Ok(out)
}

fn check_args<P: Problem + ?Sized>(problem: &P, x: &[f64], step: f64) -> Result<(), LmError> {
    let (m, n) = (problem.num_residuals(), problem.num_params());
    if m == 0 || n == 0 {
        return Err(LmError::EmptyProblem {
            num_params: n,
            num_residuals: m,
        });
    }
    if x.len() != n {
        return Err(LmError::DimensionMismatch {
            what: "x",
            expected: n,
            found: x.len(),
        });
    }
    if !(step.is_finite() && step > 0.0) {
        return Err(LmError::InvalidOptions(format!(
            "Jacobian check step must be finite and > 0, got {step}"
        )));
    }
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(LmError::NonFiniteStart {
            index,
            value: x[index],
        });
    }
    Ok(())
}

/// Compares the analytic Jacobian of `problem` at `x` with central finite differences
/// (relative step `step`, e.g. `1e-6`, applied to `max(|x_j|, s_j)`; see the
/// [module documentation](self) for the floor `s_j` and the rounding allowance).
///
/// ```
/// use cpm_lm::{check_jacobian, DenseJacobian, ModelError, Problem};
/// struct Exp;
/// impl Problem for Exp {
///     fn num_params(&self) -> usize { 1 }
///     fn num_residuals(&self) -> usize { 2 }
///     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
///         r[0] = x[0].exp(); r[1] = (2.0 * x[0]).exp(); Ok(())
///     }
/// }
/// impl DenseJacobian for Exp {
///     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
///         j[(0, 0)] = x[0].exp(); j[(1, 0)] = 2.0 * (2.0 * x[0]).exp(); Ok(())
///     }
/// }
/// let c = check_jacobian(&mut Exp, &[0.3], 1e-6).unwrap();
/// assert!(c.is_consistent(1e-7), "{c}");
/// ```
pub fn check_jacobian<P: DenseJacobian + ?Sized>(
    problem: &mut P,
    x: &[f64],
    step: f64,
) -> Result<JacobianCheck, LmError> {
    check_args(problem, x, step)?;
    let mut analytic = Mat::<f64>::zeros(problem.num_residuals(), problem.num_params());
    problem
        .jacobian(x, analytic.as_mut())
        .map_err(model_err(EvalStage::Jacobian))?;
    let numeric = finite_differences(problem, x, &analytic, step)?;
    compare(analytic, numeric, step)
}

/// [`check_jacobian`] for a problem with a sparse Jacobian (the values are scattered into
/// a dense matrix; entries outside the pattern count as zero, so a missing pattern entry
/// shows up as an error).
pub fn check_sparse_jacobian<P: SparseJacobian + ?Sized>(
    problem: &mut P,
    x: &[f64],
    step: f64,
) -> Result<JacobianCheck, LmError> {
    check_args(problem, x, step)?;
    let (m, n) = (problem.num_residuals(), problem.num_params());
    let pattern = problem.pattern();
    for (index, &(row, col)) in pattern.iter().enumerate() {
        if row >= m || col >= n {
            return Err(LmError::PatternOutOfBounds {
                index,
                row,
                col,
                nrows: m,
                ncols: n,
            });
        }
    }
    let mut values = vec![0.0; pattern.len()];
    problem
        .jacobian_values(x, &mut values)
        .map_err(model_err(EvalStage::Jacobian))?;
    let mut analytic = Mat::<f64>::zeros(m, n);
    for (&(r, c), v) in pattern.iter().zip(values) {
        analytic[(r, c)] += v;
    }
    let numeric = finite_differences(problem, x, &analytic, step)?;
    compare(analytic, numeric, step)
}
