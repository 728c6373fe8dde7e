//! Solver options: one flat struct with public fields, each default stated in its doc.

use crate::damping::Damping;
use crate::error::LmError;
use crate::loss::Loss;

/// How the damping term is scaled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Scaling {
    /// Marquardt scaling (default): the damping term is `mu * D^2` with
    /// `D_j = max over iterations of ||J e_j||` (a running maximum of the column norms,
    /// as in MINPACK; a column that has always been zero gets `D_j = 1`). The solver is
    /// then invariant to rescaling of the parameters.
    #[default]
    Marquardt,
    /// Identity damping: the damping term is `mu * I` (Levenberg's original form).
    Identity,
}

/// The update of the scale `D_j` of a parameter from the squared norm of its Jacobian column
/// at a new point, under the solve's [`Scaling`]: the running maximum of the column norms
/// (a column that has always been zero gets 1) or the identity. The engine applies it to
/// stored Jacobians; a [`NormalEquations`](crate::NormalEquations) problem applies it
/// itself while it forms its system.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScaleUpdate {
    scaling: Scaling,
    first: bool,
}

impl ScaleUpdate {
    pub(crate) fn new(scaling: Scaling, first: bool) -> Self {
        Self { scaling, first }
    }

    /// Updates the scale `d` of a column whose squared norm is `col_norm2`.
    #[inline]
    pub fn apply(&self, d: &mut f64, col_norm2: f64) {
        match self.scaling {
            Scaling::Marquardt => {
                let c = col_norm2.sqrt();
                *d = if self.first { c } else { d.max(c) };
                if *d == 0.0 {
                    *d = 1.0;
                }
            }
            Scaling::Identity => *d = 1.0,
        }
    }
}

/// Geodesic acceleration of the Levenberg-Marquardt step (Transtrum & Sethna 2012,
/// "Improvements to the Levenberg-Marquardt algorithm for nonlinear least-squares
/// minimization", arXiv:1201.5885; the form of GSL's `multifit_nlinear`).
///
/// The damped step `v` (the "velocity") is the first-order term of a geodesic on the model
/// manifold; the second-order term, the "acceleration" `a`, solves the same damped system
/// with the second directional derivative of the residuals along `v`:
///
/// ```text
/// (J^T J + mu D^2) a = -J^T r_vv,   r_vv ~ (2 / h) ((r(x + h v) - r(x)) / h - J v)
/// ```
///
/// (one extra residual evaluation at `x + h v` and one extra solve with the same damping
/// per trial). The trial step is `v + a / 2`, tried only when the acceleration is small
/// beside the velocity, `2 ||D a|| / ||D v|| <= max_ratio`; otherwise the trial counts as
/// rejected and the damping grows (the trust region shrinks). A velocity below `sqrt(eps)`
/// of the scaled parameters (`||D v||^2 <= eps ||D x||^2`) is taken plain: there `r_vv` is
/// rounding noise, growing as `1 / ||v||`, and the ratio test would reject every shorter
/// trial. The predicted reduction of the gain ratio is the linear model's for `v`, as in GSL. On a curved valley or a plateau the
/// ratio test keeps the iteration from stepping far along a direction whose curvature it
/// does not know: from NIST's first start of BoxBOD the plain method jumps onto the plateau
/// (residual sum of squares 9771.5), the accelerated one reaches the certified minimum. It
/// costs one more residual evaluation and one more solve per trial and more trials (over
/// the 46 vendored NIST runs about 2.0 times the residual evaluations), and from MGH09's
/// first start the ratio test rejects most trials along the valley until the iteration
/// limit: hence not on by default, but the restart of the default solve when a parameter
/// evaporated ([`Evaporation`]).
/// Not combined with a robust loss or [`Damping::CubicInterpolation`] (rejected by
/// [`Options::validate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeodesicAcceleration {
    /// Largest accepted `2 ||D a|| / ||D v||` (Transtrum and Sethna's `alpha`).
    /// Default: `0.75`.
    pub max_ratio: f64,
    /// Finite-difference step `h` (relative to the velocity) for the second directional
    /// derivative. Default: `0.1`.
    pub fd_step: f64,
}

impl Default for GeodesicAcceleration {
    fn default() -> Self {
        Self {
            max_ratio: 0.75,
            fd_step: 0.1,
        }
    }
}

/// When the statistics of the fit ([`Statistics`](crate::stats::Statistics): numerical rank,
/// covariance, standard deviations) are computed.
///
/// They need the Jacobian at the solution and a dense SVD of it: on small problems the SVD
/// costs as much as the whole solve, so by default the report only keeps the Jacobian (one
/// more Jacobian evaluation when the last accepted step left it stale, see below) and the
/// SVD runs when [`Report::statistics`](crate::Report::statistics) is first called.
///
/// The Jacobian kept is the one at the returned point: when the last accepted step was
/// longer than `sqrt(eps)` of the scaled parameters (or a bound froze a parameter) it is
/// evaluated once more at the end.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StatisticsMode {
    /// No statistics: the report keeps no Jacobian and
    /// [`Report::statistics`](crate::Report::statistics) returns `None`.
    Off,
    /// The report keeps the Jacobian at the solution; the SVD runs on the first call of
    /// [`Report::statistics`](crate::Report::statistics) (default).
    #[default]
    OnDemand,
    /// Computed at the end of the solve (timed in
    /// [`Timings::statistics`](crate::Timings::statistics)).
    AtEnd,
}

/// The globalisation of the default solve: a restart when a parameter *evaporates*, and
/// geodesic acceleration when the plain steps crawl.
///
/// Transtrum, Machta and Sethna ("Geometry of nonlinear least squares with applications to
/// sloppy models and optimization", Phys. Rev. E 83, 036701, 2011) call it parameter
/// evaporation when a step carries a parameter to where the model no longer depends on it
/// (an exponential rate to infinity, a saturating term switched off): the iteration then
/// stops on a plateau of the cost, at the boundary of the model manifold, with a
/// numerically zero gradient. Their remedy is the geodesic acceleration
/// ([`GeodesicAcceleration`]), whose ratio test keeps each step within the region where the
/// curvature of the model is known. Acceleration from the start costs one more residual
/// evaluation and one more solve per trial and stalls along some valleys (NIST's MGH09 from
/// its first start), so the default solve is plain and only a solve that ended with an
/// evaporated parameter is run again, from the same start, with acceleration; the better of
/// the two ends (lower cost) is returned, the report counting the work of both
/// ([`Report::restarts`](crate::Report::restarts)). NIST's BoxBOD from its first start is
/// the case in point: the plain method jumps to `b2 = 44.9`, where `exp(-b2 x)` vanishes, and
/// stops with a residual sum of squares of 9771.5; the restart reaches the certified minimum.
///
/// The restart stops early when it has arrived where the plain solve ended: as soon as every
/// parameter that evaporated in the plain solve has evaporated in the restart too while its
/// cost is within `1e-6` (relative) above the plain solve's final cost, the restart is
/// abandoned and the plain solve's end returned (what remains of such a restart is a creep
/// along the same plateau towards the same cost: Bard's function from 100 times its standard
/// start, where both solves run to the local minimum at infinity). Higher up the restart may
/// still come back (BoxBOD's passes over the plateau at 16 times its cost).
///
/// The same acceleration is the remedy for a plain solve that crawls along a narrow curved
/// valley, each step limited by the curvature of the model: after
/// `crawl_evaluations * (n + 1)` residual evaluations (`n` parameters; MINPACK's default
/// budget for the whole solve with the default `100`) a solve that has not converged
/// continues from where it is with geodesic acceleration. Meyer's function from 10 times its
/// standard start is the case in point: the plain method is still 600 times above the
/// minimum after 1000 iterations (MINPACK gives up at 400 evaluations); with acceleration
/// from the 400th evaluation on it reaches the minimum (752 evaluations in all). A solve that
/// switched is not restarted when a parameter evaporated (it already used the remedy).
/// Acceleration is not applied to a velocity below `sqrt(eps)` of the scaled parameters,
/// where its finite difference is rounding noise: the plain step is taken there.
///
/// A parameter `j` counts as evaporated when the squared norm of its Jacobian column at the
/// last linearisation is below `threshold` times the largest it has been during the solve.
/// Not applied with a robust loss, the cubic-interpolation damping, geodesic acceleration
/// already on, or to [`NormalEquations`](crate::NormalEquations) problems. With bounds the
/// rerun is not abandoned on the plateau (NIST's BoxBOD from its first start with `b >= 0`
/// meets the plain solve's plateau cost exactly on its way to the minimum), and an
/// accelerated step whose probe `x + fd_step v` would leave the box is taken plain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evaporation {
    /// Relative squared column norm below which a parameter has evaporated. Default:
    /// `1e-20` (a column 10^10 times shorter than it was).
    pub threshold: f64,
    /// Residual evaluations per parameter (plus one) after which a solve that has not
    /// converged continues with geodesic acceleration (`None`: never). Default: `Some(100)`.
    pub crawl_evaluations: Option<usize>,
}

impl Default for Evaporation {
    fn default() -> Self {
        Self {
            threshold: 1e-20,
            crawl_evaluations: Some(100),
        }
    }
}

/// Options of a solve. All fields are public; [`Options::default()`] gives the values
/// stated in each field's documentation, and [`Options::validate`] explains what is wrong
/// with a combination.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Damping schedule. Default: [`Damping::TrustRegion`] (MINPACK's trust-region control;
    /// [`Damping::Nielsen`] remains available).
    pub damping: Damping,
    /// Scaling of the damping term. Default: [`Scaling::Marquardt`].
    pub scaling: Scaling,
    /// Linear solver for the damped normal equations. Default: [`LinearSolver::DenseQr`].
    pub linear_solver: LinearSolver,
    /// Robust loss applied to each residual. Default: [`Loss::Squared`] (plain least squares).
    pub loss: Loss,
    /// Stop when the predicted relative reduction of the cost in a step is at most `ftol`
    /// and the actual relative reduction is too: at most `ftol` with a gain ratio of at most
    /// 2 (MINPACK's test), at the rounding level of the cost (`32 eps sqrt(m)`), or not a
    /// reduction at all (the step is below what the evaluation can resolve; damping more
    /// would only shrink it further). Default: `1e-15`.
    pub ftol: f64,
    /// Stop when the scaled step is small relative to the scaled parameters:
    /// `||D h|| <= xtol * (||D x|| + xtol)`. Default: `1e-15`.
    pub xtol: f64,
    /// Stop when the scaled gradient is small: `max_j |(J^T r)_j| / (||J e_j|| ||r||) <= gtol`
    /// (the cosine of the angle between the residual and each Jacobian column, as in
    /// MINPACK). Default: `1e-15`.
    pub gtol: f64,
    /// Maximum number of iterations; each trial step (accepted or rejected) is one
    /// iteration. Default: `1000`.
    pub max_iterations: usize,
    /// Maximum number of residual evaluations, the initial one included. Default: `10_000`.
    pub max_evaluations: usize,
    /// Lower bounds on the parameters (length `num_params`; `f64::NEG_INFINITY` for none).
    /// The start is projected onto the box and every evaluation stays in it. A parameter on
    /// a bound that the gradient, or the solved step, pushes outwards is held there for the
    /// step (an active set); a step the box still cuts is replaced by the best, by the
    /// model's predicted reduction, of its projection, itself shortened to the boundary, and
    /// the projected Cauchy step (never one that can only go uphill). A bounded solve ends
    /// with its first-order optimality in [`Report::optimality`](crate::Report::optimality),
    /// and a tolerance met where that fails ends as
    /// [`TerminationReason::Stalled`](crate::TerminationReason::Stalled), not as a success.
    /// Default: `None`.
    pub lower: Option<Vec<f64>>,
    /// Upper bounds on the parameters (length `num_params`; `f64::INFINITY` for none).
    /// Default: `None`.
    pub upper: Option<Vec<f64>>,
    /// Initial damping relative to the largest diagonal entry of the (scaled) `J^T J`:
    /// `mu_0 = tau * max_j (J^T J)_jj / D_j^2`. The trust region uses it only when starting
    /// from `x = 0` (initial radius `||D^-1 g|| / mu_0`). Default: `1e-3`.
    pub tau: f64,
    /// Absolute threshold on the singular values of `J` for the numerical rank used by the
    /// statistics. Default: `None`, meaning `max(m, n) * f64::EPSILON * s_max`.
    pub rank_tol: Option<f64>,
    /// When the [`Statistics`](crate::stats::Statistics) (rank, covariance, standard
    /// deviations) at the solution are computed; see [`StatisticsMode`]. With a robust loss
    /// they use the reweighted Jacobian and residuals the last step saw. Default:
    /// [`StatisticsMode::OnDemand`] (the report keeps the Jacobian at the solution and
    /// computes them on the first call of [`Report::statistics`](crate::Report::statistics)).
    pub statistics: StatisticsMode,
    /// Statistics use a dense SVD of the Jacobian; a problem with more parameters than this
    /// keeps no Jacobian in its report and gets none (and [`StatisticsMode::AtEnd`] is
    /// skipped). Default: `1000`.
    pub statistics_max_params: usize,
    /// Restart once with geodesic acceleration when a parameter evaporated (see
    /// [`Evaporation`]). Default: `Some(Evaporation::default())`.
    pub evaporation_restart: Option<Evaporation>,
    /// Geodesic acceleration of each step (see [`GeodesicAcceleration`]). Default: `None`
    /// (plain steps).
    pub acceleration: Option<GeodesicAcceleration>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            damping: Damping::default(),
            scaling: Scaling::default(),
            linear_solver: LinearSolver::default(),
            loss: Loss::default(),
            ftol: 1e-15,
            xtol: 1e-15,
            gtol: 1e-15,
            max_iterations: 1000,
            max_evaluations: 10_000,
            lower: None,
            upper: None,
            tau: 1e-3,
            rank_tol: None,
            statistics: StatisticsMode::OnDemand,
            statistics_max_params: 1000,
            evaporation_restart: Some(Evaporation::default()),
            acceleration: None,
        }
    }
}

fn check_tol(name: &str, v: f64) -> Result<(), LmError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(LmError::InvalidOptions(format!(
            "{name} must be finite and >= 0, got {v}"
        )))
    }
}

impl Options {
    /// Checks the options on their own (independently of a problem): tolerances finite and
    /// non-negative, limits at least 1, `tau > 0`, loss scale `> 0`, bounds not NaN and
    /// `lower <= upper`, Schur block sizes non-zero. The error message says which option is
    /// wrong and why.
    pub fn validate(&self) -> Result<(), LmError> {
        check_tol("ftol", self.ftol)?;
        check_tol("xtol", self.xtol)?;
        check_tol("gtol", self.gtol)?;
        if self.max_iterations == 0 {
            return Err(LmError::InvalidOptions(
                "max_iterations must be >= 1, got 0".into(),
            ));
        }
        if self.max_evaluations < 2 {
            return Err(LmError::InvalidOptions(format!(
                "max_evaluations must be >= 2 (the initial evaluation and one trial), got {}",
                self.max_evaluations
            )));
        }
        if !(self.tau.is_finite() && self.tau > 0.0) {
            return Err(LmError::InvalidOptions(format!(
                "tau (initial damping factor) must be finite and > 0, got {}",
                self.tau
            )));
        }
        if let Some(t) = self.rank_tol {
            if !(t.is_finite() && t >= 0.0) {
                return Err(LmError::InvalidOptions(format!(
                    "rank_tol must be finite and >= 0 when set, got {t}"
                )));
            }
        }
        self.loss.validate()?;
        self.linear_solver.validate()?;
        if let Some(e) = &self.evaporation_restart {
            if !(e.threshold.is_finite() && e.threshold >= 0.0 && e.threshold < 1.0) {
                return Err(LmError::InvalidOptions(format!(
                    "evaporation_restart.threshold must be in [0, 1), got {}",
                    e.threshold
                )));
            }
            if e.crawl_evaluations == Some(0) {
                return Err(LmError::InvalidOptions(
                    "evaporation_restart.crawl_evaluations must be >= 1 when set, got 0 \
                     (set GeodesicAcceleration to accelerate from the start)"
                        .into(),
                ));
            }
        }
        if let Some(a) = &self.acceleration {
            if !(a.max_ratio.is_finite() && a.max_ratio > 0.0) {
                return Err(LmError::InvalidOptions(format!(
                    "acceleration.max_ratio must be finite and > 0, got {}",
                    a.max_ratio
                )));
            }
            if !(a.fd_step.is_finite() && a.fd_step > 0.0) {
                return Err(LmError::InvalidOptions(format!(
                    "acceleration.fd_step must be finite and > 0, got {}",
                    a.fd_step
                )));
            }
            if !self.loss.is_squared() {
                return Err(LmError::InvalidOptions(
                    "geodesic acceleration is not combined with a robust loss".into(),
                ));
            }
            if self.damping == Damping::CubicInterpolation {
                return Err(LmError::InvalidOptions(
                    "geodesic acceleration is not combined with the cubic-interpolation damping"
                        .into(),
                ));
            }
        }
        if let Some(lo) = &self.lower {
            if let Some(i) = lo.iter().position(|v| v.is_nan() || *v == f64::INFINITY) {
                return Err(LmError::InvalidOptions(format!(
                    "lower[{i}] = {} is not a usable lower bound (NaN or +inf)",
                    lo[i]
                )));
            }
        }
        if let Some(up) = &self.upper {
            if let Some(i) = up
                .iter()
                .position(|v| v.is_nan() || *v == f64::NEG_INFINITY)
            {
                return Err(LmError::InvalidOptions(format!(
                    "upper[{i}] = {} is not a usable upper bound (NaN or -inf)",
                    up[i]
                )));
            }
        }
        if let (Some(lo), Some(up)) = (&self.lower, &self.upper) {
            if lo.len() != up.len() {
                return Err(LmError::InvalidOptions(format!(
                    "lower has {} entries but upper has {}",
                    lo.len(),
                    up.len()
                )));
            }
            if let Some(i) = (0..lo.len()).find(|&i| lo[i] > up[i]) {
                return Err(LmError::InvalidOptions(format!(
                    "lower[{i}] = {} exceeds upper[{i}] = {}",
                    lo[i], up[i]
                )));
            }
        }
        Ok(())
    }

    /// The defaults for a [`NormalEquations`](crate::NormalEquations) problem: the options
    /// of [`Options::default`] with [`Damping::GaussNewtonThenNielsen`],
    /// [`LinearSolver::Supplied`] (named "normal equations of the problem"),
    /// [`StatisticsMode::Off`] and no evaporation restart.
    pub fn normal_equations() -> Self {
        Self {
            damping: Damping::GaussNewtonThenNielsen,
            linear_solver: LinearSolver::Supplied {
                name: "normal equations of the problem",
            },
            statistics: StatisticsMode::Off,
            evaporation_restart: None,
            ..Self::default()
        }
    }

    /// [`validate`](Options::validate) plus what a problem that forms its own normal
    /// equations ([`NormalEquations`](crate::NormalEquations)) can serve: a damping schedule
    /// with one solve per trial ([`Damping::GaussNewtonThenNielsen`], [`Damping::Nielsen`]
    /// or [`Damping::Marquardt`]; the trust region needs products with the inverse of the
    /// system, the cubic control products with `J`), [`LinearSolver::Supplied`], plain least
    /// squares, no bounds, no geodesic acceleration, and [`StatisticsMode::Off`] (there is no
    /// Jacobian to keep). Anything else is [`LmError::InvalidOptions`], never ignored.
    ///
    /// (No evaporation restart either: it would run the whole solve again.)
    pub fn validate_normal(&self) -> Result<(), LmError> {
        self.validate()?;
        let refuse = |what: &str| {
            Err(LmError::InvalidOptions(format!(
                "a problem that forms its own normal equations cannot serve {what}"
            )))
        };
        if matches!(
            self.damping,
            Damping::TrustRegion | Damping::CubicInterpolation
        ) {
            return refuse(&format!(
                "the {} damping (use Gauss-Newton-then-Nielsen, Nielsen or Marquardt)",
                self.damping.name()
            ));
        }
        if !matches!(self.linear_solver, LinearSolver::Supplied { .. }) {
            return refuse(&format!(
                "the {} linear solver (use LinearSolver::Supplied)",
                self.linear_solver.name()
            ));
        }
        if !self.loss.is_squared() {
            return refuse("a robust loss");
        }
        if self.lower.is_some() || self.upper.is_some() {
            return refuse("bounds");
        }
        if self.acceleration.is_some() {
            return refuse("geodesic acceleration");
        }
        if self.evaporation_restart.is_some() {
            return refuse("an evaporation restart (set evaporation_restart: None)");
        }
        if self.statistics != StatisticsMode::Off {
            return refuse("statistics (set StatisticsMode::Off)");
        }
        Ok(())
    }

    /// [`validate`](Options::validate) plus the checks that need the problem size.
    pub(crate) fn validate_for(&self, num_params: usize) -> Result<(), LmError> {
        self.validate()?;
        if matches!(self.linear_solver, LinearSolver::Supplied { .. }) {
            return Err(LmError::InvalidOptions(
                "LinearSolver::Supplied is for problems that form their own normal equations \
                 (minimize_normal); choose a linear solver for a stored Jacobian"
                    .into(),
            ));
        }
        if let Some(lo) = &self.lower {
            if lo.len() != num_params {
                return Err(LmError::DimensionMismatch {
                    what: "options.lower",
                    expected: num_params,
                    found: lo.len(),
                });
            }
        }
        if let Some(up) = &self.upper {
            if up.len() != num_params {
                return Err(LmError::DimensionMismatch {
                    what: "options.upper",
                    expected: num_params,
                    found: up.len(),
                });
            }
        }
        if let LinearSolver::Schur { local_block_sizes } = &self.linear_solver {
            let total: usize = local_block_sizes.iter().sum();
            if total > num_params {
                return Err(LmError::InvalidOptions(format!(
                    "Schur local blocks cover {total} parameters but the problem has only {num_params}"
                )));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid() {
        Options::default().validate().unwrap();
    }

    #[test]
    fn messages_name_the_option() {
        let o = Options {
            ftol: -1.0,
            ..Options::default()
        };
        let e = o.validate().unwrap_err().to_string();
        assert!(e.contains("ftol") && e.contains("-1"), "{e}");
        let o = Options {
            lower: Some(vec![0.0, 2.0]),
            upper: Some(vec![1.0, 1.0]),
            ..Options::default()
        };
        let e = o.validate().unwrap_err().to_string();
        assert!(e.contains("lower[1] = 2 exceeds upper[1] = 1"), "{e}");
    }

    #[test]
    fn normal_equations_options_are_checked() {
        Options::normal_equations().validate_normal().unwrap();
        for (bad, word) in [
            (Options::default(), "trust region"),
            (
                Options {
                    damping: Damping::Nielsen,
                    ..Options::default()
                },
                "dense QR",
            ),
            (
                Options {
                    loss: Loss::Huber(1.0),
                    ..Options::normal_equations()
                },
                "robust loss",
            ),
            (
                Options {
                    upper: Some(vec![1.0]),
                    ..Options::normal_equations()
                },
                "bounds",
            ),
            (
                Options {
                    acceleration: Some(GeodesicAcceleration::default()),
                    ..Options::normal_equations()
                },
                "acceleration",
            ),
            (
                Options {
                    statistics: StatisticsMode::OnDemand,
                    ..Options::normal_equations()
                },
                "statistics",
            ),
        ] {
            let e = bad.validate_normal().unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        }
        let e = Options::normal_equations()
            .validate_for(3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("Supplied"), "{e}");
    }

    #[test]
    fn acceleration_is_checked() {
        let with = |a: GeodesicAcceleration| Options {
            acceleration: Some(a),
            ..Options::default()
        };
        with(GeodesicAcceleration::default()).validate().unwrap();
        let e = with(GeodesicAcceleration {
            max_ratio: 0.0,
            ..GeodesicAcceleration::default()
        })
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("max_ratio"), "{e}");
        let e = with(GeodesicAcceleration {
            fd_step: f64::NAN,
            ..GeodesicAcceleration::default()
        })
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("fd_step"), "{e}");
        let robust = Options {
            loss: Loss::Huber(1.0),
            ..with(GeodesicAcceleration::default())
        };
        assert!(robust.validate().is_err());
        let cubic = Options {
            damping: Damping::CubicInterpolation,
            ..with(GeodesicAcceleration::default())
        };
        assert!(cubic.validate().is_err());
    }
}

/// Linear solver for the damped normal equations `(J^T J + mu D^2) h = -J^T r`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum LinearSolver {
    /// Pivoted Householder QR of `J`, then Givens elimination of the damping rows per
    /// damping value (MINPACK's approach). Accurate (never forms `J^T J`); default.
    #[default]
    DenseQr,
    /// Dense Cholesky of `J^T J + mu D^2`. Faster for `m >> n`, squares the conditioning.
    DenseCholesky,
    /// Sparse Cholesky of `J^T J + mu D^2` (faer's supernodal/simplicial LLT with an AMD
    /// ordering): the symbolic factorisation is done once, the numeric one per damping value.
    SparseCholesky,
    /// Schur complement for many small local blocks plus a few global parameters: the
    /// local blocks are eliminated block by block, the reduced global system is solved
    /// densely and the local steps are back-substituted. Each residual may depend on at most
    /// one local block (and on any global parameters).
    Schur {
        /// Sizes of the local blocks: parameters `0..sizes[0]` form block 0, the next
        /// `sizes[1]` block 1, and so on; parameters after `sum(sizes)` are global.
        local_block_sizes: Vec<usize>,
    },
    /// The problem solves its own damped normal equations: required by, and only by,
    /// [`NormalEquations`](crate::NormalEquations) problems ([`minimize_normal`](crate::minimize_normal)).
    Supplied {
        /// What the problem's solver is, for reports.
        name: &'static str,
    },
}

impl LinearSolver {
    /// Short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            LinearSolver::DenseQr => "dense QR",
            LinearSolver::DenseCholesky => "dense Cholesky",
            LinearSolver::SparseCholesky => "sparse Cholesky",
            LinearSolver::Schur { .. } => "Schur complement",
            LinearSolver::Supplied { name } => name,
        }
    }

    /// Whether the solver works on the sparse Jacobian structure.
    pub fn is_sparse(&self) -> bool {
        matches!(
            self,
            LinearSolver::SparseCholesky | LinearSolver::Schur { .. }
        )
    }

    pub(crate) fn validate(&self) -> Result<(), LmError> {
        if let LinearSolver::Schur { local_block_sizes } = self {
            if let Some(i) = local_block_sizes.iter().position(|&s| s == 0) {
                return Err(LmError::InvalidOptions(format!(
                    "Schur local_block_sizes[{i}] is 0; every local block needs at least one parameter"
                )));
            }
        }
        Ok(())
    }
}
