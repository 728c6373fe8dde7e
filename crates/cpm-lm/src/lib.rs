//! # cpm-lm: Levenberg-Marquardt least squares on faer
//!
//! A general nonlinear least-squares crate: dense and sparse Jacobians, a choice of damping
//! schedules and linear solvers, bounds, robust losses, and the statistics of the fit
//! (rank, covariance, standard deviations) afterwards.
//!
//! ## The maths
//!
//! Given residuals `r(x) in R^m` of parameters `x in R^n`, minimise the cost
//!
//! ```text
//! F(x) = 0.5 * sum_i rho(r_i(x)^2)        (rho(s) = s for ordinary least squares)
//! ```
//!
//! With the Jacobian `J = dr/dx` and gradient `g = J^T r`, each iteration solves the damped
//! Gauss-Newton system
//!
//! ```text
//! (J^T J + mu D^2) h = -g
//! ```
//!
//! where `D` is Marquardt's scaling (running maximum of the column norms of `J`, making the
//! method invariant to the units of the parameters) or the identity. `mu -> 0` gives the
//! Gauss-Newton step, large `mu` a short steepest-descent step. The linear model predicts
//! the reduction `L(0) - L(h) = -g.h - 0.5 ||J h||^2`; the gain ratio
//! `rho = (F(x) - F(x + h)) / (L(0) - L(h))` decides whether the step is accepted and how
//! `mu` changes (see [`Damping`]; the default, [`Damping::TrustRegion`], chooses `mu` so
//! that the scaled step fits a trust region, MINPACK's way). The solve stops on a small
//! relative cost reduction (`ftol`), a small relative step (`xtol`), a small scaled
//! gradient (`gtol`), a zero residual, or a limit.
//!
//! ## A curve fit
//!
//! Fit `y = a * exp(-b t)`: implement [`Problem`] (residuals) and [`DenseJacobian`], then
//! call [`minimize`].
//!
//! ```
//! use cpm_lm::{minimize, DenseJacobian, ModelError, Options, Problem};
//!
//! struct ExpDecay { t: Vec<f64>, y: Vec<f64> }
//!
//! impl Problem for ExpDecay {
//!     fn num_params(&self) -> usize { 2 }
//!     fn num_residuals(&self) -> usize { self.t.len() }
//!     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//!         for i in 0..self.t.len() {
//!             r[i] = x[0] * (-x[1] * self.t[i]).exp() - self.y[i];
//!         }
//!         Ok(())
//!     }
//! }
//!
//! impl DenseJacobian for ExpDecay {
//!     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
//!         for i in 0..self.t.len() {
//!             let e = (-x[1] * self.t[i]).exp();
//!             j[(i, 0)] = e;
//!             j[(i, 1)] = -x[0] * self.t[i] * e;
//!         }
//!         Ok(())
//!     }
//! }
//!
//! let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
//! let y: Vec<f64> = t.iter().enumerate()
//!     .map(|(i, t)| 3.0 * (-0.7 * t).exp() + 1e-3 * ((i * 7 % 5) as f64 - 2.0))
//!     .collect();
//! let mut problem = ExpDecay { t, y };
//! let mut x = [1.0, 0.1];
//! let report = minimize(&mut problem, &mut x, &Options::default())?;
//! assert!(report.was_successful(), "{report:#}");
//! assert!((x[0] - 3.0).abs() < 1e-2 && (x[1] - 0.7).abs() < 1e-2);
//! println!("{report}");     // one line; `{report:#}` prints the iteration table
//! # Ok::<(), cpm_lm::LmError>(())
//! ```
//!
//! ## Options
//!
//! [`Options`] is a flat struct with public fields; each default is in its documentation
//! and [`Options::validate`] explains what is wrong with a combination. Choose the damping
//! schedule ([`Damping::TrustRegion`], [`Damping::Nielsen`], [`Damping::Marquardt`],
//! [`Damping::CubicInterpolation`]),
//! the scaling ([`Scaling`]) and the linear solver ([`LinearSolver`]). `Options::acceleration`
//! adds Transtrum and Sethna's geodesic acceleration ([`GeodesicAcceleration`]) to every
//! step; by default it is used only to run again a solve in which a parameter *evaporated*
//! ([`Evaporation`]: the plain method carried it where the model no longer depends on it, as
//! from NIST's BoxBOD first start, and stopped on a plateau) and to continue a solve that
//! crawls past MINPACK's budget of `100 (n + 1)` evaluations:
//!
//! ```
//! # use cpm_lm::{minimize, DenseJacobian, ModelError, Problem};
//! # struct ExpDecay { t: Vec<f64>, y: Vec<f64> }
//! # impl Problem for ExpDecay {
//! #     fn num_params(&self) -> usize { 2 }
//! #     fn num_residuals(&self) -> usize { self.t.len() }
//! #     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() { r[i] = x[0] * (-x[1] * self.t[i]).exp() - self.y[i]; }
//! #         Ok(())
//! #     }
//! # }
//! # impl DenseJacobian for ExpDecay {
//! #     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() {
//! #             let e = (-x[1] * self.t[i]).exp();
//! #             j[(i, 0)] = e; j[(i, 1)] = -x[0] * self.t[i] * e;
//! #         }
//! #         Ok(())
//! #     }
//! # }
//! # let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
//! # let y: Vec<f64> = t.iter().map(|t| 3.0 * (-0.7 * t).exp()).collect();
//! # let mut problem = ExpDecay { t, y };
//! use cpm_lm::{Damping, LinearSolver, Options, Scaling};
//!
//! let options = Options {
//!     damping: Damping::Marquardt,
//!     scaling: Scaling::Identity,
//!     linear_solver: LinearSolver::DenseCholesky,
//!     ftol: 1e-12,
//!     max_iterations: 200,
//!     ..Options::default()
//! };
//! let mut x = [1.0, 0.1];
//! let report = minimize(&mut problem, &mut x, &options)?;
//! assert!(report.was_successful());
//!
//! let bad = Options { xtol: -1.0, ..Options::default() };
//! assert_eq!(bad.validate().unwrap_err().to_string(),
//!            "invalid options: xtol must be finite and >= 0, got -1");
//! # Ok::<(), cpm_lm::LmError>(())
//! ```
//!
//! ## The report and the statistics
//!
//! A [`Report`] tells how the solve ended ([`TerminationReason`], with
//! [`Report::was_successful`]), the initial and final cost, every iteration
//! ([`IterationRecord`]: cost, damping, step norm, gain ratio, accepted), the counts of
//! accepted and rejected steps and of evaluations, and timings. [`Report::brief`] is one
//! line, [`Report::full`] a table. Unless disabled ([`StatisticsMode`]), it keeps the
//! Jacobian at the solution, and [`Report::statistics`] computes (on the first call) the
//! [`stats::Statistics`] of the fit there: numerical rank of `J` (SVD), the
//! covariance `sigma^2 (J^T J)^+` with `sigma^2 = 2 cost / (m - rank)`, standard deviations
//! and correlations. An unidentifiable parameter (one that moves along the numerical null
//! space) gets `None` rather than an invented number. [`stats::Statistics::from_jacobian`]
//! works on any Jacobian.
//!
//! ```
//! # use cpm_lm::{minimize, DenseJacobian, ModelError, Options, Problem};
//! # struct ExpDecay { t: Vec<f64>, y: Vec<f64> }
//! # impl Problem for ExpDecay {
//! #     fn num_params(&self) -> usize { 2 }
//! #     fn num_residuals(&self) -> usize { self.t.len() }
//! #     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() { r[i] = x[0] * (-x[1] * self.t[i]).exp() - self.y[i]; }
//! #         Ok(())
//! #     }
//! # }
//! # impl DenseJacobian for ExpDecay {
//! #     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() {
//! #             let e = (-x[1] * self.t[i]).exp();
//! #             j[(i, 0)] = e; j[(i, 1)] = -x[0] * self.t[i] * e;
//! #         }
//! #         Ok(())
//! #     }
//! # }
//! # let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
//! # let y: Vec<f64> = t.iter().enumerate()
//! #     .map(|(i, t)| 3.0 * (-0.7 * t).exp() + 1e-3 * ((i * 7 % 5) as f64 - 2.0)).collect();
//! # let mut problem = ExpDecay { t, y };
//! let mut x = [1.0, 0.1];
//! let report = minimize(&mut problem, &mut x, &cpm_lm::Options::default())?;
//! let st = report.statistics().expect("computed on demand by default");
//! assert_eq!(st.rank, 2);
//! let sd_a = st.std_dev[0].expect("a is identifiable");
//! assert!(sd_a > 0.0 && sd_a < 1e-2);
//! assert!(st.correlation[(0, 1)].abs() <= 1.0);
//! assert!(report.brief().starts_with("converged"));
//! # Ok::<(), cpm_lm::LmError>(())
//! ```
//!
//! ## Sparse problems and the Schur complement
//!
//! Implement [`SparseJacobian`] (a fixed pattern declared once, values in that order) and
//! call [`minimize_sparse`]. The solver keeps the Jacobian in compressed-sparse-row form
//! with `u32` column indices; a pattern listed row by row (rows ascending, columns
//! ascending within a row) needs no copy and no map, and a large problem can stream it
//! through [`SparseJacobian::visit_pattern`] instead of building the list.
//! [`LinearSolver::SparseCholesky`] factors `J^T J + mu D^2` with faer's sparse Cholesky
//! (symbolic analysis once); [`LinearSolver::Schur`] eliminates many small local blocks
//! and solves the reduced system in the global parameters, holding only the small factor
//! of each block besides the Jacobian. The dense solvers also accept sparse problems.
//!
//! ```
//! use cpm_lm::{minimize_sparse, LinearSolver, ModelError, Options, Problem, SparseJacobian};
//!
//! /// Two independent lines y = a_k + b_k t (local blocks) sharing an offset c (global).
//! struct Lines;
//! const T: [f64; 4] = [0.0, 1.0, 2.0, 3.0];
//! impl Problem for Lines {
//!     fn num_params(&self) -> usize { 5 }          // a0 b0 | a1 b1 | c
//!     fn num_residuals(&self) -> usize { 9 }       // 4 + 4 points, 1 prior on c
//!     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//!         for k in 0..2 {
//!             for (i, t) in T.iter().enumerate() {
//!                 let truth = (1.0 + k as f64) + 0.5 * t + 0.25;
//!                 r[4 * k + i] = x[2 * k] + x[2 * k + 1] * t + x[4] - truth;
//!             }
//!         }
//!         r[8] = x[4] - 0.25;
//!         Ok(())
//!     }
//! }
//! impl SparseJacobian for Lines {
//!     fn pattern(&self) -> Vec<(usize, usize)> {
//!         let mut p = Vec::new();
//!         for k in 0..2 {
//!             for i in 0..4 {
//!                 p.extend([(4 * k + i, 2 * k), (4 * k + i, 2 * k + 1), (4 * k + i, 4)]);
//!             }
//!         }
//!         p.push((8, 4));
//!         p
//!     }
//!     fn jacobian_values(&mut self, _x: &[f64], v: &mut [f64]) -> Result<(), ModelError> {
//!         let mut n = 0;
//!         for _k in 0..2 {
//!             for t in T {
//!                 v[n] = 1.0; v[n + 1] = t; v[n + 2] = 1.0;
//!                 n += 3;
//!             }
//!         }
//!         v[n] = 1.0;
//!         Ok(())
//!     }
//! }
//!
//! for solver in [
//!     LinearSolver::SparseCholesky,
//!     LinearSolver::Schur { local_block_sizes: vec![2, 2] },
//!     LinearSolver::DenseQr,
//! ] {
//!     let mut x = [0.0; 5];
//!     let options = Options { linear_solver: solver, ..Options::default() };
//!     let report = minimize_sparse(&mut Lines, &mut x, &options)?;
//!     assert!(report.final_cost < 1e-20, "{report}");
//!     assert!((x[2] - 2.0).abs() < 1e-9 && (x[4] - 0.25).abs() < 1e-9);
//! }
//! # Ok::<(), cpm_lm::LmError>(())
//! ```
//!
//! ## Bounds and robust losses
//!
//! `Options::lower` / `Options::upper` keep the parameters in a box: an active set of the
//! parameters a bound holds, a step the box cuts replaced by the best of three candidates
//! (projected, shortened to the boundary, projected Cauchy), and success only at a point
//! that is first-order optimal in the box ([`Report::optimality`], [`BoxOptimality`];
//! otherwise [`TerminationReason::Stalled`]).
//! [`Loss`] (Huber, Cauchy, Tukey) reduces the pull of outliers, folded into the
//! least-squares step with Triggs' correction as in Ceres (see [`loss`]).
//!
//! ```
//! # use cpm_lm::{minimize, DenseJacobian, ModelError, Problem};
//! # struct ExpDecay { t: Vec<f64>, y: Vec<f64> }
//! # impl Problem for ExpDecay {
//! #     fn num_params(&self) -> usize { 2 }
//! #     fn num_residuals(&self) -> usize { self.t.len() }
//! #     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() { r[i] = x[0] * (-x[1] * self.t[i]).exp() - self.y[i]; }
//! #         Ok(())
//! #     }
//! # }
//! # impl DenseJacobian for ExpDecay {
//! #     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() {
//! #             let e = (-x[1] * self.t[i]).exp();
//! #             j[(i, 0)] = e; j[(i, 1)] = -x[0] * self.t[i] * e;
//! #         }
//! #         Ok(())
//! #     }
//! # }
//! use cpm_lm::{Loss, Options};
//! let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
//! let mut y: Vec<f64> = t.iter().map(|t| 3.0 * (-0.7 * t).exp()).collect();
//! y[5] += 2.0; // an outlier
//! let mut problem = ExpDecay { t, y };
//!
//! // Bounded: the decay rate may not exceed 0.5.
//! let options = Options { upper: Some(vec![f64::INFINITY, 0.5]), ..Options::default() };
//! let mut x = [1.0, 0.1];
//! minimize(&mut problem, &mut x, &options)?;
//! assert!(x[1] <= 0.5);
//!
//! // Robust: the outlier barely moves the fit.
//! let options = Options { loss: Loss::Cauchy(0.1), ..Options::default() };
//! let mut x = [1.0, 0.1];
//! minimize(&mut problem, &mut x, &options)?;
//! assert!((x[0] - 3.0).abs() < 1e-2 && (x[1] - 0.7).abs() < 1e-2, "{x:?}");
//! # Ok::<(), cpm_lm::LmError>(())
//! ```
//!
//! ## Watching and stopping, checking Jacobians, errors
//!
//! [`Solver`] holds the options plus an iteration callback that may stop the solve
//! (`ControlFlow::Break`). [`check_jacobian`] compares an analytic Jacobian with central
//! differences. Setup mistakes are an `Err(`[`LmError`]`)` before any evaluation; an error
//! returned by the model stops the solve and comes back as [`LmError::Model`].
//!
//! ```
//! # use cpm_lm::{DenseJacobian, ModelError, Problem};
//! # struct ExpDecay { t: Vec<f64>, y: Vec<f64> }
//! # impl Problem for ExpDecay {
//! #     fn num_params(&self) -> usize { 2 }
//! #     fn num_residuals(&self) -> usize { self.t.len() }
//! #     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//! #         if x[1] < -10.0 { return Err("decay rate out of range".into()); }
//! #         for i in 0..self.t.len() { r[i] = x[0] * (-x[1] * self.t[i]).exp() - self.y[i]; }
//! #         Ok(())
//! #     }
//! # }
//! # impl DenseJacobian for ExpDecay {
//! #     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
//! #         for i in 0..self.t.len() {
//! #             let e = (-x[1] * self.t[i]).exp();
//! #             j[(i, 0)] = e; j[(i, 1)] = -x[0] * self.t[i] * e;
//! #         }
//! #         Ok(())
//! #     }
//! # }
//! # let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
//! # let y: Vec<f64> = t.iter().map(|t| 3.0 * (-0.7 * t).exp()).collect();
//! # let mut problem = ExpDecay { t, y };
//! use std::ops::ControlFlow;
//! use cpm_lm::{check_jacobian, minimize, LmError, Options, Solver, TerminationReason};
//!
//! let check = check_jacobian(&mut problem, &[2.0, 0.5], 1e-6)?;
//! assert!(check.is_consistent(1e-6), "{check}");
//!
//! let mut solver = Solver::new(Options::default())
//!     .with_callback(|rec| if rec.iteration >= 3 { ControlFlow::Break(()) } else { ControlFlow::Continue(()) });
//! let report = solver.minimize(&mut problem, &mut [1.0, 0.1])?;
//! assert_eq!(report.termination, TerminationReason::UserStop);
//! assert_eq!(report.iterations.len(), 3);
//!
//! match minimize(&mut problem, &mut [1.0, -20.0], &Options::default()) {
//!     Err(LmError::Model { iteration: 0, .. }) => {}
//!     other => panic!("expected a model error, got {other:?}"),
//! }
//! # Ok::<(), cpm_lm::LmError>(())
//! ```
#![forbid(unsafe_code)]

mod bounds;
pub mod check;
pub mod damping;
pub mod error;
pub mod loss;
pub mod numeric;
pub mod options;
pub mod problem;
pub mod report;
pub mod solver;
pub mod stats;

pub use check::{check_jacobian, check_sparse_jacobian, JacobianCheck};
pub use damping::Damping;
pub use error::{EvalStage, LmError};
pub use loss::Loss;
pub use numeric::{Difference, NumericJacobian};
pub use options::{
    Evaporation, GeodesicAcceleration, Options, ScaleUpdate, Scaling, StatisticsMode,
};
pub use problem::{
    DampedStep, DenseJacobian, Linearization, ModelError, NormalEquations, Problem, SparseJacobian,
};
pub use report::{BoxOptimality, IterationRecord, Report, TerminationReason, Timings};
pub use solver::{
    minimize, minimize_normal, minimize_sparse, IterationCallback, LinearSolver, Solver,
};
pub use stats::Statistics;

/// The faer version this crate is built on, re-exported so that a user's
/// [`DenseJacobian::jacobian`] can name `cpm_lm::faer::MatMut` without matching faer's version
/// and features by hand.
pub use faer;

/// The examples of the crate's README.md, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
