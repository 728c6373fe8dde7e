//! The Levenberg-Marquardt driver, its entry points and the linear solvers.
//!
//! [`minimize`] and [`minimize_sparse`] run a solve with [`Options`]; [`Solver`] does the
//! same with an iteration callback that can stop the solve.

use std::ops::ControlFlow;

use crate::error::LmError;
pub use crate::options::LinearSolver;
use crate::options::Options;
use crate::problem::{DenseJacobian, NormalEquations, SparseJacobian};
use crate::report::{IterationRecord, Report};

mod boxed;
mod dense_cholesky;
mod dense_qr;
mod engine;
pub(crate) mod jacobian;
mod model;
mod schur;
pub(crate) mod small;
mod sparse_cholesky;
mod trust_region;

use jacobian::Jacobian;
use model::{DenseModel, SparseModel};

/// A linear solver for the damped system, set up once per solve.
pub(crate) trait LinearSystem {
    /// Damping-independent work for a new Jacobian `jac` and (weighted) residual `r`.
    fn prepare(&mut self, jac: &Jacobian, r: &[f64]) -> Result<(), String>;
    /// Solves `(J^T J + mu D^2) h = -g` where `g = J^T r`, `D = diag(d)`, for the `jac` last
    /// given to [`prepare`](Self::prepare). Returns `false`
    /// when the system could not be solved (not numerically positive definite).
    fn solve(&mut self, jac: &Jacobian, mu: f64, d: &[f64], g: &[f64], h: &mut [f64]) -> bool;
    /// Solves `(J^T J + mu D^2) h = -g` for another `g` with the `mu` and `D` of the last
    /// successful [`solve`](Self::solve) (the geodesic acceleration's second solve). The
    /// default solves afresh; a solver whose `solve` reads its right-hand side from
    /// [`prepare`](Self::prepare) reuses its factor instead.
    fn resolve(&mut self, jac: &Jacobian, mu: f64, d: &[f64], g: &[f64], h: &mut [f64]) -> bool {
        self.solve(jac, mu, d, g, h)
    }
    /// `w^T (J^T J + mu D^2)^-1 w` for the `mu` and `D` of the last successful
    /// [`solve`](Self::solve) since the last [`prepare`](Self::prepare); `None` when that
    /// system is singular or there is none. Used by the trust-region damping for the
    /// derivative of the step norm with respect to `mu`.
    fn inverse_quadratic(&mut self, jac: &Jacobian, w: &[f64]) -> Option<f64>;
}

/// A linear system built for one solve: the default dense QR held in place (one allocation
/// fewer per solve: on small problems the allocator is a fair part of the time), the others
/// boxed.
pub(crate) enum Linear {
    DenseQr(dense_qr::DenseQr),
    Other(Box<dyn LinearSystem>),
}

impl Linear {
    pub(crate) fn as_dyn(&mut self) -> &mut dyn LinearSystem {
        match self {
            Linear::DenseQr(q) => q,
            Linear::Other(b) => b.as_mut(),
        }
    }
}

pub(crate) fn build_linear(solver: &LinearSolver, jac: &Jacobian) -> Result<Linear, LmError> {
    let (m, n) = match jac {
        Jacobian::Dense(j) => (j.nrows(), j.ncols()),
        Jacobian::Sparse(s) => (s.nrows, s.ncols),
    };
    Ok(match (solver, jac) {
        (LinearSolver::DenseQr, _) => Linear::DenseQr(dense_qr::DenseQr::new(m, n)),
        (LinearSolver::DenseCholesky, _) => {
            Linear::Other(Box::new(dense_cholesky::DenseCholesky::new(n)))
        }
        (LinearSolver::SparseCholesky, Jacobian::Sparse(s)) => {
            Linear::Other(Box::new(sparse_cholesky::SparseCholesky::new(s)?))
        }
        (LinearSolver::Schur { local_block_sizes }, Jacobian::Sparse(s)) => {
            Linear::Other(Box::new(schur::Schur::new(s, local_block_sizes)?))
        }
        _ => {
            return Err(LmError::Numerical(
                "internal: Jacobian storage does not match the linear solver".into(),
            ))
        }
    })
}

/// The callback type of [`Solver`]: sees every iteration, returns
/// `ControlFlow::Break(())` to stop the solve (reported as
/// [`TerminationReason::UserStop`](crate::TerminationReason::UserStop)).
pub type IterationCallback<'a> = Box<dyn FnMut(&IterationRecord) -> ControlFlow<()> + 'a>;

/// A solver holding options and an optional iteration callback.
///
/// ```
/// use std::ops::ControlFlow;
/// use cpm_lm::{DenseJacobian, ModelError, Options, Problem, Solver, TerminationReason};
///
/// struct Line;
/// impl Problem for Line {
///     fn num_params(&self) -> usize { 2 }
///     fn num_residuals(&self) -> usize { 3 }
///     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
///         for (i, ri) in r.iter_mut().enumerate() {
///             let t = i as f64;
///             *ri = x[0] + x[1] * t - (1.0 + 2.0 * t);
///         }
///         Ok(())
///     }
/// }
/// impl DenseJacobian for Line {
///     fn jacobian(&mut self, _x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
///         for i in 0..3 { j[(i, 0)] = 1.0; j[(i, 1)] = i as f64; }
///         Ok(())
///     }
/// }
///
/// let mut seen = 0;
/// let mut solver = Solver::new(Options::default()).with_callback(|_rec| {
///     seen += 1;
///     ControlFlow::Break(())
/// });
/// let mut x = [0.0, 0.0];
/// let report = solver.minimize(&mut Line, &mut x).unwrap();
/// assert_eq!(report.termination, TerminationReason::UserStop);
/// drop(solver);
/// assert_eq!(seen, 1);
/// ```
pub struct Solver<'a> {
    options: Options,
    callback: Option<IterationCallback<'a>>,
}

impl std::fmt::Debug for Solver<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Solver")
            .field("options", &self.options)
            .field("callback", &self.callback.as_ref().map(|_| "FnMut"))
            .finish()
    }
}

impl<'a> Solver<'a> {
    /// A solver with these options and no callback.
    pub fn new(options: Options) -> Self {
        Self {
            options,
            callback: None,
        }
    }

    /// Sets the iteration callback, called after every trial step.
    pub fn with_callback(
        mut self,
        callback: impl FnMut(&IterationRecord) -> ControlFlow<()> + 'a,
    ) -> Self {
        self.callback = Some(Box::new(callback));
        self
    }

    /// The options.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// The options, mutably.
    pub fn options_mut(&mut self) -> &mut Options {
        &mut self.options
    }

    /// Minimises a problem with a dense Jacobian; `x` is the start on input and the
    /// solution on output. See [`minimize`].
    pub fn minimize<P: DenseJacobian + ?Sized>(
        &mut self,
        problem: &mut P,
        x: &mut [f64],
    ) -> Result<Report, LmError> {
        let mut model = DenseModel::new(problem);
        let cb = self.callback.as_mut().map(|c| c.as_mut() as _);
        engine::run_stored(&mut model, x, &self.options, cb)
    }

    /// Minimises a problem that forms its own normal equations. See [`minimize_normal`].
    pub fn minimize_normal<P: NormalEquations>(
        &mut self,
        problem: &mut P,
        x: &mut [f64],
    ) -> Result<Report, LmError> {
        let cb = self.callback.as_mut().map(|c| c.as_mut() as _);
        engine::run(engine::Backend::normal(problem), x, &self.options, None, cb)
    }

    /// Minimises a problem with a sparse Jacobian. See [`minimize_sparse`].
    pub fn minimize_sparse<P: SparseJacobian + ?Sized>(
        &mut self,
        problem: &mut P,
        x: &mut [f64],
    ) -> Result<Report, LmError> {
        let mut model = SparseModel::new(problem);
        let cb = self.callback.as_mut().map(|c| c.as_mut() as _);
        engine::run_stored(&mut model, x, &self.options, cb)
    }
}

/// Minimises `0.5 * sum_i rho(r_i(x)^2)` for a problem with a dense Jacobian.
///
/// `x` holds the starting point on input and the best point found on output (projected
/// onto the bounds, if any). Setup errors (invalid options, wrong sizes) are returned
/// before any evaluation; a model error stops the solve and is returned as
/// [`LmError::Model`]; otherwise the [`Report`] says how the solve ended. Any
/// [`LinearSolver`] can be used (the sparse ones see a fully dense pattern).
pub fn minimize<P: DenseJacobian + ?Sized>(
    problem: &mut P,
    x: &mut [f64],
    options: &Options,
) -> Result<Report, LmError> {
    let mut model = DenseModel::new(problem);
    engine::run_stored(&mut model, x, options, None)
}

/// Minimises `0.5 * sum_i rho(r_i(x)^2)` for a problem with a sparse Jacobian.
///
/// Same contract as [`minimize`]. With [`LinearSolver::DenseQr`] or
/// [`LinearSolver::DenseCholesky`] the Jacobian is scattered into a dense matrix.
pub fn minimize_sparse<P: SparseJacobian + ?Sized>(
    problem: &mut P,
    x: &mut [f64],
    options: &Options,
) -> Result<Report, LmError> {
    let mut model = SparseModel::new(problem);
    engine::run_stored(&mut model, x, options, None)
}

/// Minimises `0.5 * sum_i r_i(x)^2` for a problem that forms and solves its own damped
/// normal equations ([`NormalEquations`]): the same iteration, stopping tests and report as
/// [`minimize`], with the options [`Options::validate_normal`] accepts (start from
/// [`Options::normal_equations`]). The report keeps no Jacobian (no statistics).
///
/// ```
/// use cpm_lm::{minimize_normal, DampedStep, Linearization, ModelError, NormalEquations, Options};
///
/// /// r = A x - b with A = [[2, 0], [1, 1], [0, 3]], solved from its normal equations.
/// struct Small { mu: f64 }
/// const A: [[f64; 2]; 3] = [[2.0, 0.0], [1.0, 1.0], [0.0, 3.0]];
/// const B: [f64; 3] = [2.0, 3.0, 6.0];
/// fn residuals(x: &[f64]) -> [f64; 3] {
///     std::array::from_fn(|i| A[i][0] * x[0] + A[i][1] * x[1] - B[i])
/// }
/// impl NormalEquations for Small {
///     fn num_params(&self) -> usize { 2 }
///     fn num_residuals(&self) -> usize { 3 }
///     fn cost(&mut self, x: &[f64]) -> Result<f64, ModelError> {
///         Ok(0.5 * residuals(x).iter().map(|r| r * r).sum::<f64>())
///     }
///     fn assemble(&mut self, x: &[f64], mu: f64, d: &mut [f64], lin: Option<Linearization<'_>>)
///         -> Result<f64, ModelError> {
///         if let Some(lin) = lin {
///             let r = residuals(x);
///             for j in 0..2 {
///                 lin.gradient[j] = (0..3).map(|i| A[i][j] * r[i]).sum();
///                 lin.col_norms2[j] = (0..3).map(|i| A[i][j] * A[i][j]).sum();
///                 lin.scale.apply(&mut d[j], lin.col_norms2[j]);
///             }
///         }
///         self.mu = mu;
///         self.cost(x)
///     }
///     fn solve(&mut self, x: &[f64], d: &[f64], h: &mut [f64])
///         -> Result<Option<DampedStep>, ModelError> {
///         let r = residuals(x);
///         let n = |a: usize, b: usize| (0..3).map(|i| A[i][a] * A[i][b]).sum::<f64>();
///         let (a, b, c) = (n(0, 0) + self.mu * d[0] * d[0], n(0, 1), n(1, 1) + self.mu * d[1] * d[1]);
///         let g: Vec<f64> = (0..2).map(|j| (0..3).map(|i| A[i][j] * r[i]).sum()).collect();
///         let det = a * c - b * b;
///         h[0] = -(c * g[0] - b * g[1]) / det;
///         h[1] = -(a * g[1] - b * g[0]) / det;
///         let jh2 = (0..3).map(|i| (A[i][0] * h[0] + A[i][1] * h[1]).powi(2)).sum();
///         Ok(Some(DampedStep { jh_norm2: jh2, trial_cost: None }))
///     }
/// }
///
/// let mut x = [0.0, 0.0];
/// let report = minimize_normal(&mut Small { mu: 0.0 }, &mut x, &Options::normal_equations())?;
/// assert!(report.was_successful(), "{report:#}");
/// assert_eq!(report.damping, "Gauss-Newton, then Nielsen");
/// // The least-squares solution of A x = b.
/// assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 2.0).abs() < 1e-12, "{x:?}");
/// assert!(report.statistics().is_none());
/// // Options such a problem cannot serve are refused.
/// assert!(minimize_normal(&mut Small { mu: 0.0 }, &mut x, &Options::default()).is_err());
/// # Ok::<(), cpm_lm::LmError>(())
/// ```
pub fn minimize_normal<P: NormalEquations>(
    problem: &mut P,
    x: &mut [f64],
    options: &Options,
) -> Result<Report, LmError> {
    engine::run(engine::Backend::normal(problem), x, options, None, None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::jacobian::SparseJac;
    use faer::prelude::*;
    use faer::Mat;

    /// A block-structured sparse Jacobian: `nb` local blocks of sizes 2 and 3 (4 rows each,
    /// touching the block and some of the 3 globals), plus 2 rows on the globals only.
    fn block_jacobian() -> (SparseJac, Vec<usize>) {
        let sizes: Vec<usize> = (0..5).map(|k| 2 + k % 2).collect();
        let nl: usize = sizes.iter().sum();
        let ng = 3;
        let mut pattern = Vec::new();
        let (mut row, mut p0) = (0, 0);
        for &s in &sizes {
            for i in 0..4 {
                for a in 0..s {
                    pattern.push((row, p0 + a));
                }
                for b in 0..ng {
                    if (i + b) % 3 != 0 {
                        pattern.push((row, nl + b));
                    }
                }
                row += 1;
            }
            p0 += s;
        }
        for b in 0..ng {
            pattern.push((row + b % 2, nl + b));
        }
        let (mut jac, _) = SparseJac::from_pattern(row + 2, nl + ng, &pattern).unwrap();
        for (q, v) in jac.values.iter_mut().enumerate() {
            *v = ((q * 37 % 23) as f64 - 11.0) / 7.0 + if q % 5 == 0 { 1.5 } else { 0.0 };
        }
        (jac, sizes)
    }

    #[test]
    fn every_solver_gives_the_damped_step_and_inverse_quadratic() {
        let (sparse, sizes) = block_jacobian();
        let (m, n) = (sparse.nrows, sparse.ncols);
        let dense = Jacobian::Sparse(sparse.clone()).to_dense();
        let r: Vec<f64> = (0..m).map(|i| (i as f64 * 0.37).sin()).collect();
        let g: Vec<f64> = (0..n)
            .map(|c| (0..m).map(|i| dense[(i, c)] * r[i]).sum())
            .collect();
        let d: Vec<f64> = (0..n).map(|c| 0.5 + 0.1 * c as f64).collect();
        let w: Vec<f64> = (0..n).map(|c| 1.0 - 0.2 * c as f64).collect();
        let jtj = dense.transpose() * &dense;
        let solvers = [
            LinearSolver::DenseQr,
            LinearSolver::DenseCholesky,
            LinearSolver::SparseCholesky,
            LinearSolver::Schur {
                local_block_sizes: sizes,
            },
        ];
        for solver in solvers {
            let jac = if solver.is_sparse() {
                Jacobian::Sparse(sparse.clone())
            } else {
                Jacobian::Dense(dense.clone())
            };
            let mut linear = build_linear(&solver, &jac).unwrap();
            let sys = linear.as_dyn();
            sys.prepare(&jac, &r).unwrap();
            assert!(sys.inverse_quadratic(&jac, &w).is_none(), "{solver:?}");
            for mu in [0.0, 1e-3, 1.0, 50.0] {
                let mut a = jtj.clone();
                for k in 0..n {
                    a[(k, k)] += mu * d[k] * d[k];
                }
                let lu = a.partial_piv_lu();
                let want = lu.solve(Mat::from_fn(n, 1, |k, _| -g[k]));
                let aw = lu.solve(Mat::from_fn(n, 1, |k, _| w[k]));
                let q_ref: f64 = (0..n).map(|k| w[k] * aw[(k, 0)]).sum();
                let mut h = vec![0.0; n];
                assert!(sys.solve(&jac, mu, &d, &g, &mut h), "{solver:?} mu={mu}");
                for k in 0..n {
                    let e = (h[k] - want[(k, 0)]).abs();
                    assert!(
                        e < 1e-9 * (1.0 + want[(k, 0)].abs()),
                        "{solver:?} mu={mu}: {h:?}"
                    );
                }
                let q = sys.inverse_quadratic(&jac, &w).unwrap();
                assert!(
                    (q - q_ref).abs() < 1e-9 * q_ref,
                    "{solver:?} mu={mu}: {q} vs {q_ref}"
                );
                // Another right-hand side with the same damping: -(J^T J + mu D^2)^-1 w.
                let mut hr = vec![0.0; n];
                assert!(sys.resolve(&jac, mu, &d, &w, &mut hr), "{solver:?} mu={mu}");
                for k in 0..n {
                    let e = (hr[k] + aw[(k, 0)]).abs();
                    assert!(
                        e < 1e-9 * (1.0 + aw[(k, 0)].abs()),
                        "{solver:?} mu={mu}: {hr:?}"
                    );
                }
            }
        }
    }
}
