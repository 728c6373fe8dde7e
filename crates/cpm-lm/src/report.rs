//! What a solve returns: how it ended, the cost history, counts, timings and statistics.

use std::fmt;
use std::fmt::Write as _;
use std::sync::OnceLock;
use std::time::Duration;

use crate::solver::jacobian::Jacobian;
use crate::stats::Statistics;

/// How a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TerminationReason {
    /// Actual and predicted relative cost reductions fell below `ftol`.
    ConvergedFtol,
    /// The scaled step fell below `xtol` relative to the scaled parameters.
    ConvergedXtol,
    /// The scaled gradient fell below `gtol`.
    ConvergedGtol,
    /// The residuals are zero: nothing is left to fit.
    ZeroResidual,
    /// `max_iterations` trial steps were taken.
    MaxIterations,
    /// `max_evaluations` residual evaluations were spent.
    MaxEvaluations,
    /// The residuals at the start, or a Jacobian, contained NaN or infinity.
    NonFinite,
    /// The damped linear system could not be solved even with very large damping.
    SingularSystem,
    /// The iteration callback asked to stop.
    UserStop,
    /// A bounded solve stopped making progress (the cost, step or gradient test held) at a
    /// point that is not first-order optimal in the box: [`Report::optimality`] says how far
    /// from it. The point is the best found and can be used, but it is not a solution.
    Stalled,
}

impl TerminationReason {
    /// Whether the solve converged (one of the tolerance tests, or zero residual).
    pub fn was_successful(&self) -> bool {
        matches!(
            self,
            TerminationReason::ConvergedFtol
                | TerminationReason::ConvergedXtol
                | TerminationReason::ConvergedGtol
                | TerminationReason::ZeroResidual
        )
    }
}

impl fmt::Display for TerminationReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            TerminationReason::ConvergedFtol => "converged (relative cost reduction below ftol)",
            TerminationReason::ConvergedXtol => "converged (relative step below xtol)",
            TerminationReason::ConvergedGtol => "converged (scaled gradient below gtol)",
            TerminationReason::ZeroResidual => "converged (zero residual)",
            TerminationReason::MaxIterations => "stopped: maximum number of iterations reached",
            TerminationReason::MaxEvaluations => "stopped: maximum number of evaluations reached",
            TerminationReason::NonFinite => "failed: non-finite residuals or Jacobian",
            TerminationReason::SingularSystem => "failed: singular damped system",
            TerminationReason::UserStop => "stopped by the iteration callback",
            TerminationReason::Stalled => {
                "stalled: no progress at a point that is not first-order optimal in the box"
            }
        })
    }
}

/// One trial step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationRecord {
    /// 1-based iteration number (each trial step counts, accepted or not).
    pub iteration: usize,
    /// Cost `0.5 * sum rho(r_i^2)` after this iteration (the trial cost if accepted, the
    /// previous cost otherwise).
    pub cost: f64,
    /// Cost at the trial point (may be infinite when the model returned non-finite values).
    pub trial_cost: f64,
    /// Damping parameter (`mu` or `lambda`) used for the step.
    pub damping: f64,
    /// Step length along the solved direction (1 except for the cubic-interpolation control).
    pub step_length: f64,
    /// Euclidean norm of the step actually taken (after projection onto the bounds).
    pub step_norm: f64,
    /// Gain ratio: actual over predicted cost reduction.
    pub gain_ratio: f64,
    /// Whether the step was accepted.
    pub accepted: bool,
    /// Infinity norm of the (projected) gradient `J^T r` at the point the step started from.
    pub gradient_norm: f64,
    /// Time since the start of the solve.
    pub elapsed: Duration,
}

/// Where the time went.
///
/// Timed only when the set-up and the first linearisation of the solve took at least
/// 20 µs: for a quicker (small) problem a clock read costs as much as a phase, so the phases
/// are not timed, every duration is zero and [`Timings::phases_timed`] is false
/// ([`Report::elapsed`] and each iteration's `elapsed` are still measured).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// In the user's residual function.
    pub residuals: Duration,
    /// In the user's Jacobian function (including scattering into the solver's storage).
    pub jacobian: Duration,
    /// Factorising and solving the damped systems.
    pub linear_solver: Duration,
    /// Keeping the Jacobian at the solution (re-evaluated when stale) and, with
    /// [`StatisticsMode::AtEnd`](crate::StatisticsMode::AtEnd), computing the statistics;
    /// statistics computed on demand are not timed here.
    pub statistics: Duration,
    /// Whether the phases above were timed (false for a quick solve: then they are zero, not
    /// measured).
    pub phases_timed: bool,
}

/// The outcome of a solve.
#[derive(Clone, Debug)]
pub struct Report {
    /// How the solve ended.
    pub termination: TerminationReason,
    /// Cost at the starting point (after projection onto the bounds).
    pub initial_cost: f64,
    /// Cost at the returned point.
    pub final_cost: f64,
    /// Every trial step, in order.
    pub iterations: Vec<IterationRecord>,
    /// Number of accepted steps.
    pub accepted_steps: usize,
    /// Number of rejected steps (including those whose linear system failed).
    pub rejected_steps: usize,
    /// Number of residual evaluations.
    pub residual_evaluations: usize,
    /// Number of Jacobian evaluations.
    pub jacobian_evaluations: usize,
    /// Wall-clock time of the whole solve.
    pub elapsed: Duration,
    /// Breakdown of the time.
    pub timings: Timings,
    /// Number of parameters.
    pub num_params: usize,
    /// Number of residuals.
    pub num_residuals: usize,
    /// Name of the damping strategy used.
    pub damping: &'static str,
    /// Name of the linear solver used.
    pub linear_solver: &'static str,
    /// Parameters that evaporated: their Jacobian column ended below
    /// [`Evaporation::threshold`](crate::Evaporation::threshold) of its largest (empty when
    /// not checked).
    pub evaporated: Vec<usize>,
    /// First-order optimality at the returned point of a bounded solve (`None` without
    /// bounds): the projected gradient, a scale-free measure and the parameters on a bound.
    /// A bounded solve reports success only where [`BoxOptimality::optimal`] holds.
    pub optimality: Option<BoxOptimality>,
    /// Number of restarts (see [`Evaporation`](crate::Evaporation)): the counts of steps and
    /// evaluations and the timings include every run; the termination, the costs, the
    /// iteration records and the statistics are those of the run returned.
    pub restarts: usize,
    /// Rank, covariance and standard deviations at the solution: computed at the end or on
    /// the first call of [`Report::statistics`].
    pub(crate) statistics: OnceLock<Statistics>,
    /// What the statistics are computed from, when kept.
    pub(crate) fit: Option<FitAtSolution>,
}

/// First-order optimality of a point in the box `lower <= x <= upper`, with the gradient
/// `g = J^T r` there (reweighted with a robust loss).
///
/// ```
/// use cpm_lm::{minimize, DenseJacobian, ModelError, Options, Problem};
///
/// /// Rosenbrock: r = [10 (x1 - x0^2), 1 - x0].
/// struct Rosenbrock;
/// impl Problem for Rosenbrock {
///     fn num_params(&self) -> usize { 2 }
///     fn num_residuals(&self) -> usize { 2 }
///     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
///         r[0] = 10.0 * (x[1] - x[0] * x[0]);
///         r[1] = 1.0 - x[0];
///         Ok(())
///     }
/// }
/// impl DenseJacobian for Rosenbrock {
///     fn jacobian(&mut self, x: &[f64], mut j: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
///         j[(0, 0)] = -20.0 * x[0];
///         j[(0, 1)] = 10.0;
///         j[(1, 0)] = -1.0;
///         j[(1, 1)] = 0.0;
///         Ok(())
///     }
/// }
///
/// // x0 <= 0.5 cuts the valley: the constrained minimum is (0.5, 0.25), cost 0.125.
/// let options = Options {
///     lower: Some(vec![-2.0, -2.0]),
///     upper: Some(vec![0.5, 2.0]),
///     ..Options::default()
/// };
/// let mut x = [-1.2, 1.0];
/// let report = minimize(&mut Rosenbrock, &mut x, &options)?;
/// assert!(report.was_successful(), "{report:#}");
/// assert!((report.final_cost - 0.125).abs() < 1e-12);
/// let opt = report.optimality.as_ref().expect("a bounded solve");
/// assert!(opt.optimal);
/// assert_eq!(opt.active, vec![1, 0]); // x0 on its upper bound
/// assert!(opt.projected_gradient < 1e-9);
/// # Ok::<(), cpm_lm::LmError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct BoxOptimality {
    /// `||x - P(x - g)||_inf`, `P` the projection onto the box: SciPy's `optimality` for a
    /// bounded problem in its plainest form (in the units of `g` away from the bounds, of
    /// `x` next to them).
    pub projected_gradient: f64,
    /// The scale-free first-order measure: the largest over the parameters of
    /// `sqrt(red_j / cost)`, `red_j` the reduction the Gauss-Newton model predicts from
    /// moving parameter `j` alone to its best place in the box. In the interior this is the
    /// cosine of MINPACK's gradient test, `|g_j| / (||J e_j|| ||r||)`; against a bound that
    /// the gradient pushes on it is zero. At a zero residual the model still predicts the
    /// whole cost, along a move at the rounding level of `x`: moves below `1e-10` of the
    /// parameter's value do not count, and a cost below `(32 eps sqrt(m))^2` times the
    /// start's measures zero.
    pub measure: f64,
    /// SciPy's `active_mask`: `-1` for a parameter on its lower bound, `1` on its upper
    /// bound, `0` otherwise.
    pub active: Vec<i8>,
    /// Whether the point is first-order optimal: `measure <= 1e-6`.
    pub optimal: bool,
}

/// The (reweighted) Jacobian and residuals at the solution, kept for the statistics.
#[derive(Clone, Debug)]
pub(crate) struct FitAtSolution {
    pub(crate) jacobian: Jacobian,
    pub(crate) residuals: Vec<f64>,
    pub(crate) rank_tol: Option<f64>,
}

impl FitAtSolution {
    pub(crate) fn statistics(&self) -> Statistics {
        match &self.jacobian {
            Jacobian::Dense(j) => {
                Statistics::from_jacobian(j.as_ref(), &self.residuals, self.rank_tol)
            }
            Jacobian::Sparse(_) => {
                let dense = self.jacobian.to_dense();
                Statistics::from_jacobian(dense.as_ref(), &self.residuals, self.rank_tol)
            }
        }
    }
}

impl Report {
    /// Whether the solve converged (see [`TerminationReason::was_successful`]). A bounded
    /// solve that met a tolerance at a point that is not first-order optimal in the box ends
    /// as [`TerminationReason::Stalled`], not as a success.
    pub fn was_successful(&self) -> bool {
        self.termination.was_successful()
    }

    /// Whether the returned point can be used (Ceres' `IsSolutionUsable`): the solve
    /// converged, or it stopped short (a limit, a stall, the callback, a singular system) at a
    /// point of finite cost, the best it found. Not after non-finite residuals or Jacobians.
    pub fn is_solution_usable(&self) -> bool {
        self.termination != TerminationReason::NonFinite && self.final_cost.is_finite()
    }

    /// Rank, covariance and standard deviations at the solution (see
    /// [`Options::statistics`](crate::Options::statistics)): computed on the first call from
    /// the Jacobian the report kept, then cached. `None` with
    /// [`StatisticsMode::Off`](crate::StatisticsMode::Off), for a problem with more than
    /// [`Options::statistics_max_params`](crate::Options::statistics_max_params) parameters,
    /// for a solve that ended on non-finite values, and for problems that supply their
    /// normal equations (no Jacobian exists to keep).
    pub fn statistics(&self) -> Option<&Statistics> {
        if let Some(st) = self.statistics.get() {
            return Some(st);
        }
        let fit = self.fit.as_ref()?;
        Some(self.statistics.get_or_init(|| fit.statistics()))
    }

    /// The Jacobian at the solution (reweighted rows with a robust loss, zero columns for
    /// parameters a bound froze), when the report kept one; dense.
    pub fn jacobian(&self) -> Option<faer::Mat<f64>> {
        self.fit.as_ref().map(|f| f.jacobian.to_dense())
    }

    /// Number of iterations (trial steps).
    pub fn num_iterations(&self) -> usize {
        self.iterations.len()
    }

    /// One-line summary: [`Report::brief_without_time`] and the wall time.
    pub fn brief(&self) -> String {
        format!("{}, {:.3?}", self.brief_without_time(), self.elapsed)
    }

    /// One-line summary without the wall time: how the solve ended, the costs and the counts,
    /// which a rerun reproduces exactly (for files that must not differ between runs).
    pub fn brief_without_time(&self) -> String {
        format!(
            "{}: cost {:.6e} -> {:.6e} in {} iterations ({} accepted, {} rejected), \
             {} residual / {} Jacobian evaluations",
            self.termination,
            self.initial_cost,
            self.final_cost,
            self.iterations.len(),
            self.accepted_steps,
            self.rejected_steps,
            self.residual_evaluations,
            self.jacobian_evaluations,
        )
    }

    /// Multi-line summary: settings, an iteration table, counts, timings and statistics.
    pub fn full(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "Levenberg-Marquardt: {} parameters, {} residuals, {} damping, {} solver",
            self.num_params, self.num_residuals, self.damping, self.linear_solver
        );
        let _ = writeln!(
            s,
            "{:>5} {:>14} {:>14} {:>10} {:>6} {:>10} {:>10} {:>10} {:>4}",
            "iter", "cost", "trial cost", "damping", "alpha", "|step|", "gain", "|grad|", "acc"
        );
        for r in &self.iterations {
            let _ = writeln!(
                s,
                "{:>5} {:>14.7e} {:>14.7e} {:>10.3e} {:>6.3} {:>10.3e} {:>10.3e} {:>10.3e} {:>4}",
                r.iteration,
                r.cost,
                r.trial_cost,
                r.damping,
                r.step_length,
                r.step_norm,
                r.gain_ratio,
                r.gradient_norm,
                if r.accepted { "yes" } else { "no" }
            );
        }
        let _ = writeln!(s, "termination: {}", self.termination);
        let _ = writeln!(
            s,
            "cost: initial {:.10e}, final {:.10e}",
            self.initial_cost, self.final_cost
        );
        if let Some(o) = &self.optimality {
            let _ = writeln!(
                s,
                "first-order optimality in the box: {} (measure {:.3e}, projected gradient {:.3e}, {} of {} parameters on a bound)",
                if o.optimal { "yes" } else { "no" },
                o.measure,
                o.projected_gradient,
                o.active.iter().filter(|a| **a != 0).count(),
                o.active.len()
            );
        }
        let _ = writeln!(
            s,
            "steps: {} accepted, {} rejected; evaluations: {} residual, {} Jacobian",
            self.accepted_steps,
            self.rejected_steps,
            self.residual_evaluations,
            self.jacobian_evaluations
        );
        let t = &self.timings;
        let _ = if t.phases_timed {
            writeln!(
                s,
                "time: {:.3?} total ({:.3?} residuals, {:.3?} Jacobian, {:.3?} linear solver, {:.3?} statistics)",
                self.elapsed, t.residuals, t.jacobian, t.linear_solver, t.statistics
            )
        } else {
            writeln!(
                s,
                "time: {:.3?} total (a quick solve: its phases were not timed)",
                self.elapsed
            )
        };
        if let Some(st) = self.statistics() {
            let _ = write!(s, "{st}");
        }
        s
    }
}

/// `{}` prints [`Report::brief`], `{:#}` prints [`Report::full`].
impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if f.alternate() {
            f.write_str(&self.full())
        } else {
            f.write_str(&self.brief())
        }
    }
}
