//! The Levenberg-Marquardt iteration shared by every problem kind and linear solver.
//!
//! Two kinds of problem run through the same loop ([`run`]): one with a stored Jacobian
//! ([`Model`], dense or sparse, any [`LinearSystem`](crate::solver::LinearSystem)), and one
//! that forms and solves its own damped normal equations
//! ([`NormalEquations`](crate::NormalEquations)). [`Backend`] holds what differs; the
//! damping schedule, the stopping tests, the records and the report are the loop's.
//!
//! Per linearisation: robust reweighting of the rows, gradient `g = J^T r`, freezing of
//! parameters held at a bound, update of the scaling `D`, the damping-independent part of
//! the linear solve, and the gradient test. Per trial step: solve the damped system (with
//! bounds, again while the step pushes a parameter on a bound out of the box), a step that
//! the box cuts replaced by the best candidate of [`boxed`](crate::solver::boxed), step
//! test, evaluate, gain ratio, accept or reject, cost test. A bounded solve ends with the
//! first-order optimality at its point, and a tolerance met where it fails is a stall.

use std::ops::ControlFlow;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use crate::bounds::Bounds;
use crate::damping::{Damping, DampingState, LineInfo};
use crate::error::{EvalStage, LmError};
use crate::options::{Options, ScaleUpdate, StatisticsMode};
use crate::problem::{Linearization, NormalEquations};
use crate::report::{
    BoxOptimality, FitAtSolution, IterationRecord, Report, TerminationReason, Timings,
};
use crate::solver::boxed::{self, CutStep, OPTIMALITY_TOL};
use crate::solver::jacobian::Jacobian;
use crate::solver::model::Model;
use crate::solver::small::{dot, norm2};
use crate::solver::trust_region::lmpar;
use crate::solver::LinearSystem;
use crate::solver::{build_linear, Linear};

/// Robust reweighting of the residuals at the current point (non-square losses only):
/// fills `rw` and scales the Jacobian rows.
fn weigh(
    options: &Options,
    r: &[f64],
    rw: &mut [f64],
    scale: &mut [f64],
    jac: Option<&mut Jacobian>,
) {
    for i in 0..r.len() {
        let (a, b) = options.loss.correction(r[i]);
        rw[i] = a * r[i];
        scale[i] = b;
    }
    if let Some(j) = jac {
        j.scale_rows(scale);
    }
}

/// The optional iteration callback, borrowed for one solve.
pub(crate) type Callback<'a, 'b> =
    Option<&'a mut (dyn FnMut(&IterationRecord) -> ControlFlow<()> + 'b)>;

/// Chained timestamps: one clock read per phase boundary. On small problems a read costs
/// as much as a phase: when the set-up and the first linearisation took less than
/// [`PHASE_TIMING_MIN`], the phases are no longer timed (the report's [`Timings`] are zero
/// and say so) and the clock is read once per iteration, for the iteration's time.
struct Clock {
    start: Instant,
    last: Instant,
    phases: bool,
}

/// The shortest set-up and first linearisation after which the phases of a solve are timed.
const PHASE_TIMING_MIN: Duration = Duration::from_micros(20);

impl Clock {
    fn new(start: Instant) -> Self {
        Self {
            start,
            last: Instant::now(),
            phases: true,
        }
    }

    /// Time since the last lap (zero when the phases are not timed).
    fn lap(&mut self) -> Duration {
        if !self.phases {
            return Duration::ZERO;
        }
        let now = Instant::now();
        let d = now - self.last;
        self.last = now;
        d
    }

    /// Time since the start: at the last lap, or now when the phases are not timed.
    fn elapsed(&self) -> Duration {
        if self.phases {
            self.last - self.start
        } else {
            self.start.elapsed()
        }
    }

    /// After the first linearisation: stops timing the phases of a quick solve.
    fn settle(&mut self, timings: &mut Timings) {
        if self.phases && self.last - self.start < PHASE_TIMING_MIN {
            self.phases = false;
            *timings = Timings::default();
        }
    }
}

fn model_error(iteration: usize, stage: EvalStage) -> impl FnOnce(crate::ModelError) -> LmError {
    move |source| LmError::Model {
        iteration,
        stage,
        source,
    }
}

/// A problem with a stored Jacobian: the Jacobian, the linear solver and the residual
/// vectors.
pub(crate) struct Stored<'p, M> {
    model: &'p mut M,
    jac: Jacobian,
    linear: Linear,
    robust: bool,
    /// Number of residuals.
    m: usize,
    /// The residuals at the current point and at the trial point, then `J s` (see
    /// [`jstep`]), in one allocation of slots of length `m`: slot `cur` holds the current
    /// residuals, slot `1 - cur` the trial's (an accepted trial flips `cur`).
    rbuf: Vec<f64>,
    cur: usize,
    rw: Vec<f64>,
    row_scale: Vec<f64>,
    jdir: Vec<f64>,
    /// Geodesic acceleration: residuals at x + h v, the acceleration and its right-hand side.
    r_probe: Vec<f64>,
    acc: Vec<f64>,
    /// Whether `jac` is the Jacobian at the current point.
    jac_current: bool,
}

/// A problem that forms its own normal equations.
pub(crate) struct Normal<'p> {
    problem: &'p mut dyn NormalEquations,
    /// Whether the current point is linearised (gradient and scales up to date).
    linearised: bool,
    /// Cost the last assembly reported.
    assembled_cost: f64,
    /// Damping of the system last assembled at the current point.
    assembled_mu: Option<f64>,
    /// What the last solve reported.
    jh_norm2: f64,
    trial_cost: Option<f64>,
}

/// What differs between the problem kinds.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Backend<'p, M> {
    /// A stored Jacobian (held in place: one allocation fewer per solve).
    Stored(Stored<'p, M>),
    /// Normal equations formed by the problem.
    Normal(Normal<'p>),
}

/// No stored problem (the type parameter of a [`Backend::Normal`]).
pub(crate) enum NoModel {}

impl Model for NoModel {
    fn num_params(&self) -> usize {
        match *self {}
    }
    fn num_residuals(&self) -> usize {
        match *self {}
    }
    fn residuals(&mut self, _: &[f64], _: &mut [f64]) -> Result<(), crate::ModelError> {
        match *self {}
    }
    fn jacobian(&mut self, _: &[f64], _: &mut Jacobian) -> Result<(), crate::ModelError> {
        match *self {}
    }
    fn new_jacobian(&mut self, _: bool) -> Result<Jacobian, LmError> {
        match *self {}
    }
}

impl<'p> Backend<'p, NoModel> {
    pub(crate) fn normal(problem: &'p mut dyn NormalEquations) -> Self {
        Backend::Normal(Normal {
            problem,
            linearised: false,
            assembled_cost: f64::NAN,
            assembled_mu: None,
            jh_norm2: 0.0,
            trial_cost: None,
        })
    }
}

impl<'p, M: Model> Backend<'p, M> {
    pub(crate) fn stored(model: &'p mut M) -> Self {
        Backend::Stored(Stored {
            model,
            jac: Jacobian::Dense(faer::Mat::zeros(0, 0)),
            linear: Linear::Other(Box::new(NoSystem)),
            robust: false,
            m: 0,
            rbuf: Vec::new(),
            cur: 0,
            rw: Vec::new(),
            row_scale: Vec::new(),
            jdir: Vec::new(),
            r_probe: Vec::new(),
            acc: Vec::new(),
            jac_current: false,
        })
    }

    fn dims(&self) -> (usize, usize) {
        match self {
            Backend::Stored(s) => (s.model.num_params(), s.model.num_residuals()),
            Backend::Normal(p) => (p.problem.num_params(), p.problem.num_residuals()),
        }
    }

    /// Storage for a solve of `n` parameters and `m` residuals.
    fn setup(&mut self, options: &Options, m: usize, n: usize) -> Result<(), LmError> {
        let Backend::Stored(s) = self else {
            return Ok(());
        };
        s.jac = s.model.new_jacobian(options.linear_solver.is_sparse())?;
        s.linear = build_linear(&options.linear_solver, &s.jac)?;
        // Residual-sized buffers: the robust-loss ones only with a robust loss, the
        // products with J only for a dense Jacobian or the cubic control (a sparse product
        // is reduced row by row).
        let robust = !options.loss.is_squared();
        let cubic = options.damping == Damping::CubicInterpolation;
        let dense_jac = matches!(s.jac, Jacobian::Dense(_));
        let accel = options.acceleration.is_some();
        let buffer = |needed: bool, v: f64| if needed { vec![v; m] } else { Vec::new() };
        s.robust = robust;
        s.m = m;
        s.rbuf = vec![0.0; if dense_jac || cubic { 3 * m } else { 2 * m }];
        s.cur = 0;
        s.rw = buffer(robust, 0.0);
        s.row_scale = buffer(robust, 1.0);
        s.jdir = buffer(cubic || accel, 0.0);
        s.r_probe = buffer(accel, 0.0);
        s.acc = if accel { vec![0.0; 2 * n] } else { Vec::new() };
        Ok(())
    }

    /// The cost at the start (a normal-equations problem linearises there at once).
    fn start(
        &mut self,
        options: &Options,
        x: &[f64],
        mu: f64,
        g: &mut [f64],
        norms2: &mut [f64],
        d: &mut [f64],
    ) -> Result<f64, LmError> {
        match self {
            Backend::Stored(s) => {
                let r = slot_mut(&mut s.rbuf, s.cur, s.m);
                s.model
                    .residuals(x, r)
                    .map_err(model_error(0, EvalStage::Residuals))?;
                Ok(options.loss.cost(r))
            }
            Backend::Normal(p) => {
                let lin = Linearization {
                    gradient: g,
                    col_norms2: norms2,
                    scale: ScaleUpdate::new(options.scaling, true),
                };
                let cost = p
                    .problem
                    .assemble(x, mu, d, Some(lin))
                    .map_err(model_error(0, EvalStage::Jacobian))?;
                p.linearised = true;
                p.assembled_mu = Some(mu);
                p.assembled_cost = cost;
                Ok(cost)
            }
        }
    }

    /// Linearises at the current point `x`: gradient, column norms, scales. Returns the
    /// norm of the (reweighted) residuals, or `None` when the Jacobian is not finite.
    #[allow(clippy::too_many_arguments)]
    fn linearise(
        &mut self,
        options: &Options,
        x: &[f64],
        iteration: usize,
        first: bool,
        mu: f64,
        bounds: Option<&Bounds>,
        frozen: &mut [bool],
        any_frozen: &mut bool,
        g: &mut [f64],
        norms2: &mut [f64],
        d: &mut [f64],
        timings: &mut Timings,
        clock: &mut Clock,
    ) -> Result<Option<f64>, LmError> {
        let rule = ScaleUpdate::new(options.scaling, first);
        match self {
            Backend::Stored(s) => {
                let n = g.len();
                s.model
                    .jacobian(x, &mut s.jac)
                    .map_err(model_error(iteration, EvalStage::Jacobian))?;
                if !s.jac.is_finite() {
                    return Ok(None);
                }
                let r = slot(&s.rbuf, s.cur, s.m);
                if s.robust {
                    weigh(options, r, &mut s.rw, &mut s.row_scale, Some(&mut s.jac));
                }
                let rw: &[f64] = if s.robust { &s.rw } else { r };
                s.jac.gradient_and_norms(rw, g, norms2);
                *any_frozen = match bounds {
                    Some(b) => b.freeze(x, g, frozen),
                    None => false,
                };
                if *any_frozen {
                    s.jac.zero_cols(frozen);
                    for j in 0..n {
                        if frozen[j] {
                            g[j] = 0.0;
                            norms2[j] = 0.0;
                        }
                    }
                }
                for j in 0..n {
                    rule.apply(&mut d[j], norms2[j]);
                }
                // The Jacobian's time includes the reweighting and the gradient.
                timings.jacobian += clock.lap();
                // The preparation is timed with the solve that follows (one clock read
                // fewer per iteration: on small problems a read costs as much as a solve).
                s.linear
                    .as_dyn()
                    .prepare(&s.jac, rw)
                    .map_err(LmError::Numerical)?;
                s.jac_current = true;
                Ok(Some(norm2(rw).sqrt()))
            }
            Backend::Normal(p) => {
                if !p.linearised {
                    let lin = Linearization {
                        gradient: g,
                        col_norms2: norms2,
                        scale: rule,
                    };
                    p.assembled_cost = p
                        .problem
                        .assemble(x, mu, d, Some(lin))
                        .map_err(model_error(iteration, EvalStage::Jacobian))?;
                    p.assembled_mu = Some(mu);
                    p.linearised = true;
                }
                timings.jacobian += clock.lap();
                if !(g.iter().all(|v| v.is_finite()) && p.assembled_cost.is_finite()) {
                    return Ok(None);
                }
                Ok(Some((2.0 * p.assembled_cost).sqrt()))
            }
        }
    }

    /// Solves the damped system for `h` (the trust region searches its damping). Returns
    /// whether it was solved and the damping used.
    #[allow(clippy::too_many_arguments)]
    fn solve(
        &mut self,
        x: &[f64],
        iteration: usize,
        damping: &mut DampingState,
        d: &mut [f64],
        g: &[f64],
        h: &mut [f64],
        wa: &mut [f64],
        timings: &mut Timings,
        clock: &mut Clock,
    ) -> Result<(bool, f64), LmError> {
        match self {
            Backend::Stored(s) => Ok(if damping.is_trust_region() {
                match lmpar(
                    s.linear.as_dyn(),
                    &s.jac,
                    damping.radius(),
                    damping.gn_scale(),
                    damping.mu(),
                    d,
                    g,
                    h,
                    wa,
                ) {
                    Some(mu) => {
                        damping.set_mu(mu);
                        (true, mu)
                    }
                    None => (false, damping.mu()),
                }
            } else {
                let mu = damping.mu();
                (s.linear.as_dyn().solve(&s.jac, mu, d, g, h), mu)
            }),
            Backend::Normal(p) => {
                let mu = damping.mu();
                if p.assembled_mu != Some(mu) {
                    p.assembled_cost = p
                        .problem
                        .assemble(x, mu, d, None)
                        .map_err(model_error(iteration, EvalStage::Jacobian))?;
                    p.assembled_mu = Some(mu);
                    timings.jacobian += clock.lap();
                }
                let step = p
                    .problem
                    .solve(x, d, h)
                    .map_err(model_error(iteration, EvalStage::Jacobian))?;
                Ok(match step {
                    Some(st) if st.jh_norm2.is_finite() && h.iter().all(|v| v.is_finite()) => {
                        p.jh_norm2 = st.jh_norm2;
                        p.trial_cost = st.trial_cost;
                        (true, mu)
                    }
                    _ => (false, mu),
                })
            }
        }
    }

    /// Bounded solves: zeroes the Jacobian columns and gradient entries of the `frozen`
    /// parameters and prepares the linear system again (a normal-equations problem takes no
    /// bounds).
    fn hold(&mut self, frozen: &[bool], g: &mut [f64], norms2: &mut [f64]) -> Result<(), LmError> {
        let Backend::Stored(s) = self else {
            return Ok(());
        };
        s.jac.zero_cols(frozen);
        for j in 0..g.len() {
            if frozen[j] {
                g[j] = 0.0;
                norms2[j] = 0.0;
            }
        }
        let rw: &[f64] = if s.robust {
            &s.rw
        } else {
            slot(&s.rbuf, s.cur, s.m)
        };
        s.linear
            .as_dyn()
            .prepare(&s.jac, rw)
            .map_err(LmError::Numerical)
    }

    /// Bounded solves, at the end: the gradient and squared column norms at `x` of the whole
    /// Jacobian (no parameter frozen), evaluated again unless the stored one is that.
    /// Returns whether a Jacobian was evaluated and whether it is finite.
    fn final_gradient(
        &mut self,
        options: &Options,
        x: &[f64],
        stale: bool,
        iteration: usize,
        g: &mut [f64],
        norms2: &mut [f64],
    ) -> Result<(bool, bool), LmError> {
        let Backend::Stored(s) = self else {
            return Ok((false, true));
        };
        if !stale {
            return Ok((false, true));
        }
        s.model
            .jacobian(x, &mut s.jac)
            .map_err(model_error(iteration, EvalStage::Jacobian))?;
        if !s.jac.is_finite() {
            s.jac_current = false;
            return Ok((true, false));
        }
        let r = slot(&s.rbuf, s.cur, s.m);
        if s.robust {
            weigh(options, r, &mut s.rw, &mut s.row_scale, Some(&mut s.jac));
        }
        let rw: &[f64] = if s.robust { &s.rw } else { r };
        s.jac.gradient_and_norms(rw, g, norms2);
        s.jac_current = true;
        Ok((true, true))
    }

    /// `||J s||^2` for the step `s = alpha h` taken along the solved direction `h`
    /// (`scratch`: length `n`).
    fn step_norm2(&mut self, step: &[f64], alpha: f64) -> f64 {
        match self {
            Backend::Stored(s) => s.jac.product_norm2(step, jstep(&mut s.rbuf, s.m)),
            Backend::Normal(p) => alpha * alpha * p.jh_norm2,
        }
    }

    /// The cost at the trial point `x_trial = x + h` (`unmodified`: no step length or
    /// projection changed it).
    fn trial_cost(
        &mut self,
        options: &Options,
        x_trial: &[f64],
        unmodified: bool,
        iteration: usize,
    ) -> Result<f64, LmError> {
        match self {
            Backend::Stored(s) => {
                let r_trial = slot_mut(&mut s.rbuf, 1 - s.cur, s.m);
                s.model
                    .residuals(x_trial, r_trial)
                    .map_err(model_error(iteration, EvalStage::Residuals))?;
                Ok(options.loss.cost(r_trial))
            }
            Backend::Normal(p) => match p.trial_cost.take() {
                Some(c) if unmodified => Ok(c),
                _ => p
                    .problem
                    .cost(x_trial)
                    .map_err(model_error(iteration, EvalStage::Residuals)),
            },
        }
    }

    /// The trial point became the current point.
    fn accept(&mut self, jacobian_still_good: bool) {
        match self {
            Backend::Stored(s) => {
                s.cur = 1 - s.cur;
                s.jac_current = !s.robust && jacobian_still_good;
            }
            Backend::Normal(p) => {
                p.linearised = false;
                p.assembled_mu = None;
            }
        }
    }
}

impl<M: Model> Stored<'_, M> {
    /// Storage for geodesic acceleration switched on during a solve (`m` residuals, `n`
    /// parameters).
    fn enable_acceleration(&mut self, m: usize, n: usize) {
        if self.jdir.len() != m {
            self.jdir = vec![0.0; m];
        }
        self.r_probe = vec![0.0; m];
        self.acc = vec![0.0; 2 * n];
    }

    /// Geodesic acceleration: `a = -(J^T J + mu D^2)^-1 J^T r_vv` into `acc[..n]`, from the
    /// residuals at `x + fd h`. Returns `2 ||D a|| / ||D h||` (0 when no acceleration could
    /// be solved for: the plain step).
    #[allow(clippy::too_many_arguments)]
    fn accelerate(
        &mut self,
        x: &[f64],
        x_probe: &mut [f64],
        h: &[f64],
        fd: f64,
        mu: f64,
        d: &[f64],
        iteration: usize,
    ) -> Result<f64, LmError> {
        let n = x.len();
        for j in 0..n {
            x_probe[j] = x[j] + fd * h[j];
        }
        self.model
            .residuals(x_probe, &mut self.r_probe)
            .map_err(model_error(iteration, EvalStage::Residuals))?;
        self.jac.mul(h, &mut self.jdir);
        let r = slot(&self.rbuf, self.cur, self.m);
        for i in 0..self.m {
            self.r_probe[i] = (2.0 / fd) * ((self.r_probe[i] - r[i]) / fd - self.jdir[i]);
        }
        let (a, rhs) = self.acc.split_at_mut(n);
        self.jac.transpose_mul(&self.r_probe, rhs);
        Ok(if self.linear.as_dyn().resolve(&self.jac, mu, d, rhs, a) {
            let (mut da2, mut dv2) = (0.0, 0.0);
            for j in 0..n {
                da2 += (d[j] * a[j]).powi(2);
                dv2 += (d[j] * h[j]).powi(2);
            }
            if dv2 > 0.0 {
                2.0 * (da2 / dv2).sqrt()
            } else {
                0.0
            }
        } else {
            a.fill(0.0);
            0.0
        })
    }
}

/// Slot `k` (length `m`) of a residual buffer.
fn slot(buf: &[f64], k: usize, m: usize) -> &[f64] {
    &buf[k * m..(k + 1) * m]
}

/// Slot `k` (length `m`) of a residual buffer, mutably.
fn slot_mut(buf: &mut [f64], k: usize, m: usize) -> &mut [f64] {
    &mut buf[k * m..(k + 1) * m]
}

/// The scratch for `J s` after the two residual slots: empty when the buffer has none (a
/// sparse product is reduced row by row).
fn jstep(buf: &mut [f64], m: usize) -> &mut [f64] {
    let from = (2 * m).min(buf.len());
    &mut buf[from..]
}

/// A placeholder linear system before [`Backend::setup`].
struct NoSystem;

impl LinearSystem for NoSystem {
    fn prepare(&mut self, _: &Jacobian, _: &[f64]) -> Result<(), String> {
        Err("internal: linear system used before setup".into())
    }
    fn solve(&mut self, _: &Jacobian, _: f64, _: &[f64], _: &[f64], _: &mut [f64]) -> bool {
        false
    }
    fn inverse_quadratic(&mut self, _: &Jacobian, _: &[f64]) -> Option<f64> {
        None
    }
}

/// Records a trial that produced no evaluated point (singular system, or an acceleration
/// too large) and asks the callback; returns the termination, if any.
fn record_failed_trial(
    records: &mut Vec<IterationRecord>,
    rec: IterationRecord,
    damping: &DampingState,
    callback: &mut Callback<'_, '_>,
) -> Option<TerminationReason> {
    records.push(rec);
    if damping.exhausted() {
        Some(TerminationReason::SingularSystem)
    } else if let Some(cb) = callback.as_mut() {
        cb(&rec).is_break().then_some(TerminationReason::UserStop)
    } else {
        None
    }
}

/// [`run`] for a stored problem, with the restart of [`Evaporation`](crate::Evaporation):
/// when a parameter evaporated, the solve runs again from the same start with geodesic
/// acceleration and the lower final cost wins.
pub(crate) fn run_stored<M: Model>(
    model: &mut M,
    x: &mut [f64],
    options: &Options,
    mut callback: Callback<'_, '_>,
) -> Result<Report, LmError> {
    let restart = globalised(options);
    // The start, for a restart: on the stack for a small problem (no allocation).
    let mut x0_small = [0.0; SMALL_START];
    let mut x0_heap = Vec::new();
    let x0: &mut [f64] = if !restart {
        &mut []
    } else if x.len() <= SMALL_START {
        let s = &mut x0_small[..x.len()];
        s.copy_from_slice(x);
        s
    } else {
        x0_heap.extend_from_slice(x);
        &mut x0_heap
    };
    let first = run(
        Backend::stored(&mut *model),
        x,
        options,
        None,
        callback.as_deref_mut(),
    )?;
    // A solve that switched to acceleration when it crawled already used the remedy: no
    // restart (it would repeat the remedy from the start).
    let crawled =
        crawl_limit(options, model.num_params()).is_some_and(|k| first.residual_evaluations > k);
    if !restart
        || crawled
        || first.evaporated.is_empty()
        || first.termination == TerminationReason::UserStop
    {
        return Ok(first);
    }
    let accelerated = Options {
        acceleration: Some(crate::GeodesicAcceleration::default()),
        evaporation_restart: None,
        ..options.clone()
    };
    // With bounds the rerun is not abandoned on the plateau: the accelerated steps can
    // leave it once there (NIST's BoxBOD from its first start with b >= 0 reaches the
    // plain solve's plateau cost exactly, then the minimum).
    let bounded = options.lower.is_some() || options.upper.is_some();
    let abandon = options
        .evaporation_restart
        .filter(|_| !bounded)
        .map(|e| Abandon {
            threshold: e.threshold,
            cost: first.final_cost,
            evaporated: first.evaporated.clone(),
        });
    let second = run(
        Backend::stored(model),
        &mut *x0,
        &accelerated,
        abandon,
        callback,
    )?;
    let (mut keep, other) = if second.final_cost < first.final_cost {
        x.copy_from_slice(x0);
        (second, first)
    } else {
        (first, second)
    };
    keep.restarts = 1;
    keep.residual_evaluations += other.residual_evaluations;
    keep.jacobian_evaluations += other.jacobian_evaluations;
    keep.accepted_steps += other.accepted_steps;
    keep.rejected_steps += other.rejected_steps;
    keep.elapsed += other.elapsed;
    keep.timings.residuals += other.timings.residuals;
    keep.timings.jacobian += other.timings.jacobian;
    keep.timings.linear_solver += other.timings.linear_solver;
    keep.timings.statistics += other.timings.statistics;
    Ok(keep)
}

/// Largest number of parameters whose start [`run_stored`] keeps on the stack.
const SMALL_START: usize = 16;

/// Whether the globalisation of [`Evaporation`](crate::Evaporation) applies: a stored
/// problem solved with plain steps, plain least squares and a damping other than the cubic
/// control (with or without bounds).
fn globalised(options: &Options) -> bool {
    options.evaporation_restart.is_some()
        && options.acceleration.is_none()
        && options.loss.is_squared()
        && options.damping != Damping::CubicInterpolation
}

/// Residual evaluations after which a globalised solve of `n` parameters that has not
/// converged continues with geodesic acceleration (see [`Evaporation`](crate::Evaporation)).
fn crawl_limit(options: &Options, n: usize) -> Option<usize> {
    let e = options.evaporation_restart?;
    if !globalised(options) {
        return None;
    }
    e.crawl_evaluations
        .map(|k| k.saturating_mul(n.saturating_add(1)))
}

/// How close (relative) to the plain solve's final cost the restart must be to count as on
/// the same plateau.
const ABANDON_BAND: f64 = 1e-6;

/// When the accelerated restart of an evaporated solve is abandoned: once every parameter
/// in `evaporated` has evaporated (squared column norm below `threshold` times its peak)
/// at a cost not below `cost`, the plain solve's final one, and within [`ABANDON_BAND`] of
/// it. It is then on the plateau where the plain solve ended and can only approach the same
/// cost; higher up (NIST's BoxBOD from its first start passes over the plateau 16 times
/// above its cost) it may still come back.
#[derive(Clone, Debug)]
pub(crate) struct Abandon {
    threshold: f64,
    cost: f64,
    evaporated: Vec<usize>,
}

/// One solve. `abandon`: the restart's early stop (see [`Abandon`]); an abandoned run ends
/// with [`TerminationReason::UserStop`], never reported since its cost is not below the
/// plain run's.
///
/// The stages: [`check_start`] and the backend's set-up, [`Solve::begin`] (the cost at the
/// start), then [`Solve::iteration`] until one says why the solve ends, and
/// [`Solve::finish`] (the statistics at the solution and the [`Report`]).
pub(crate) fn run<M: Model>(
    mut backend: Backend<'_, M>,
    x: &mut [f64],
    options: &Options,
    abandon: Option<Abandon>,
    mut callback: Callback<'_, '_>,
) -> Result<Report, LmError> {
    let start = Instant::now();
    let (n, m) = backend.dims();
    let bounds = check_start(&backend, x, options, n, m)?;
    backend.setup(options, m, n)?;
    // The parameter-sized vectors share one allocation (small problems spend a fair part
    // of their time in the allocator).
    let track = options.evaporation_restart.is_some() || abandon.is_some();
    let mut nbuf = vec![0.0; if track { 8 * n } else { 7 * n }];
    let work = Work::split(&mut nbuf, n, track);
    let mut solve = Solve::new(&backend, options, work, bounds.is_some(), start, n, m);
    let mut termination = solve.begin(&mut backend, options, x)?;
    while termination.is_none() {
        termination = solve.iteration(
            &mut backend,
            options,
            x,
            bounds.as_ref(),
            abandon.as_ref(),
            &mut callback,
        )?;
    }
    solve.finish(backend, options, x, bounds.as_ref(), termination)
}

/// The checks before a solve (a problem with parameters and residuals, a start of the
/// right size, valid options, a finite start), and the bounds, with `x` projected onto them.
fn check_start<M: Model>(
    backend: &Backend<'_, M>,
    x: &mut [f64],
    options: &Options,
    n: usize,
    m: usize,
) -> Result<Option<Bounds>, LmError> {
    if n == 0 || m == 0 {
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
    match backend {
        Backend::Stored(_) => options.validate_for(n)?,
        Backend::Normal(_) => options.validate_normal()?,
    }
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(LmError::NonFiniteStart {
            index,
            value: x[index],
        });
    }
    let bounds = Bounds::new(n, options.lower.as_deref(), options.upper.as_deref());
    if let Some(b) = &bounds {
        b.project(x);
    }
    Ok(bounds)
}

/// The parameter-sized vectors of a solve: slices of one allocation.
struct Work<'w> {
    /// The peak squared column norms (evaporation watched or an abandon test; else empty).
    peak2: &'w mut [f64],
    /// Scratch.
    wa: &'w mut [f64],
    /// The trial point.
    x_trial: &'w mut [f64],
    /// The step direction (the velocity, plus half the acceleration when accelerated).
    h: &'w mut [f64],
    /// The step taken, `x_trial - x`.
    step: &'w mut [f64],
    /// The gradient `J^T r`.
    g: &'w mut [f64],
    /// The squared column norms of `J`.
    norms2: &'w mut [f64],
    /// The scaling `D`.
    d: &'w mut [f64],
}

impl<'w> Work<'w> {
    /// `buf` (`8 n` long with `track`, else `7 n`) cut into the vectors.
    fn split(buf: &'w mut [f64], n: usize, track: bool) -> Self {
        let (peak2, buf7) = buf.split_at_mut(if track { n } else { 0 });
        let (wa, rest) = buf7.split_at_mut(n);
        let (x_trial, rest) = rest.split_at_mut(n);
        let (h, rest) = rest.split_at_mut(n);
        let (step, rest) = rest.split_at_mut(n);
        let (g, rest) = rest.split_at_mut(n);
        let (norms2, d) = rest.split_at_mut(n);
        Self {
            peak2,
            wa,
            x_trial,
            h,
            step,
            g,
            norms2,
            d,
        }
    }
}

/// How the velocity of a trial step was used ([`Solve::accelerate`]).
enum Velocity {
    /// The plain step.
    Plain,
    /// The step with half the geodesic acceleration added.
    Accelerated,
    /// The acceleration was too large: the trial is rejected (and recorded), with the
    /// termination that gives, if any.
    Rejected(Option<TerminationReason>),
}

/// A trial point, formed ([`Solve::propose`]): whether the bounds clipped it and the sizes
/// of its step.
struct Proposal {
    /// The bounds moved the trial point.
    clipped: bool,
    /// `||D step||^2`.
    dx2: f64,
    /// `||D x||^2`.
    xn2: f64,
    /// `||step||^2`.
    s2: f64,
}

/// A trial point, evaluated ([`Solve::evaluate`]).
struct Trial {
    /// The cost there (infinite when not finite).
    cost: f64,
    /// The predicted reduction of the cost.
    pred: f64,
    /// The actual reduction.
    actred: f64,
    /// The gain ratio `actred / pred`.
    rho: f64,
    /// What the damping control needs.
    line: LineInfo,
}

/// The state of one solve between its stages: the point's cost, the damping, the work
/// vectors, the counters, the records and the clock.
struct Solve<'w> {
    n: usize,
    m: usize,
    v: Work<'w>,
    cost: f64,
    initial_cost: f64,
    damping: DampingState,
    /// The geodesic acceleration, once on (from the options or after a crawl).
    accel: Option<crate::GeodesicAcceleration>,
    /// Residual evaluations after which plain steps switch to geodesic acceleration.
    crawl_limit: Option<usize>,
    cubic: bool,
    /// Relative rounding level of a computed cost (sum of m squares, each residual usually a
    /// difference of larger numbers, hence the margin over eps).
    noise: f64,
    /// The first linearisation is still to come.
    first: bool,
    /// The point moved: linearise again.
    need_jac: bool,
    /// The largest gradient component at the last linearisation.
    grad_inf: f64,
    /// Parameters held at a bound (empty without bounds).
    frozen: Vec<bool>,
    /// Bounded solves: whether a parameter was held because the solved step pushed it out
    /// ([`Solve::hold_blocked`]) since the last linearisation.
    held: bool,
    /// Bounded solves: no such holding until the next accepted step (the held parameters
    /// left no step: the next linearisation leaves the choice to [`Solve::cut`]).
    no_hold: bool,
    any_frozen: bool,
    records: Vec<IterationRecord>,
    residual_evaluations: usize,
    jacobian_evaluations: usize,
    accepted_steps: usize,
    rejected_steps: usize,
    timings: Timings,
    clock: Clock,
}

impl<'w> Solve<'w> {
    fn new<M: Model>(
        backend: &Backend<'_, M>,
        options: &Options,
        v: Work<'w>,
        bounded: bool,
        start: Instant,
        n: usize,
        m: usize,
    ) -> Self {
        let timings = Timings {
            phases_timed: true,
            ..Timings::default()
        };
        let crawl_limit = match backend {
            Backend::Stored(_) => crawl_limit(options, n),
            Backend::Normal(_) => None,
        };
        let frozen = if bounded { vec![false; n] } else { Vec::new() };
        let records = Vec::with_capacity(options.max_iterations.min(32));
        let damping = DampingState::new(options.damping, 1.0);
        Self {
            n,
            m,
            v,
            cost: f64::NAN,
            initial_cost: f64::NAN,
            damping,
            accel: options.acceleration,
            crawl_limit,
            cubic: options.damping == Damping::CubicInterpolation,
            noise: 32.0 * f64::EPSILON * (m as f64).sqrt(),
            first: true,
            need_jac: true,
            grad_inf: 0.0,
            frozen,
            held: false,
            no_hold: false,
            any_frozen: false,
            records,
            residual_evaluations: 0,
            jacobian_evaluations: 0,
            accepted_steps: 0,
            rejected_steps: 0,
            timings,
            clock: Clock::new(start),
        }
    }

    /// The cost at the start; the termination when it is already not finite or zero.
    fn begin<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        x: &[f64],
    ) -> Result<Option<TerminationReason>, LmError> {
        let v = &mut self.v;
        self.cost = backend.start(options, x, self.damping.mu(), v.g, v.norms2, v.d)?;
        match backend {
            Backend::Stored(_) => self.timings.residuals += self.clock.lap(),
            Backend::Normal(_) => self.timings.jacobian += self.clock.lap(),
        }
        self.residual_evaluations += 1;
        self.initial_cost = self.cost;
        Ok(if !self.cost.is_finite() {
            Some(TerminationReason::NonFinite)
        } else if self.cost == 0.0 {
            Some(TerminationReason::ZeroResidual)
        } else {
            None
        })
    }

    /// One iteration: a linearisation when the point moved (with the gradient test), the
    /// limits, then one trial step, accepted or rejected. Returns why the solve ends, if it
    /// does.
    fn iteration<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        x: &mut [f64],
        bounds: Option<&Bounds>,
        abandon: Option<&Abandon>,
        callback: &mut Callback<'_, '_>,
    ) -> Result<Option<TerminationReason>, LmError> {
        if self.need_jac {
            if let Some(t) = self.linearise(backend, options, x, bounds, abandon)? {
                return Ok(Some(t));
            }
        }
        if let Some(t) = self.limits(options) {
            return Ok(Some(t));
        }
        if self.accel.is_none()
            && self
                .crawl_limit
                .is_some_and(|k| self.residual_evaluations >= k)
        {
            if let Backend::Stored(s) = backend {
                s.enable_acceleration(self.m, self.n);
                self.accel = Some(crate::GeodesicAcceleration::default());
            }
        }
        let iteration = self.records.len() + 1;
        let (mut solved, mut mu) = self.solve_step(backend, x, iteration)?;
        if let Some(b) = bounds.filter(|_| !self.no_hold) {
            (solved, mu) = self.hold_blocked(backend, x, b, iteration, solved, mu)?;
        }
        if !solved {
            self.timings.linear_solver += self.clock.lap();
            self.rejected_steps += 1;
            self.damping.singular();
            let rec = self.failed_record(iteration, mu, 0.0, 0.0);
            return Ok(record_failed_trial(
                &mut self.records,
                rec,
                &self.damping,
                callback,
            ));
        }
        let alpha = self.damping.step_length();
        let accelerated =
            match self.accelerate(backend, x, bounds, mu, alpha, iteration, callback)? {
                Velocity::Rejected(t) => return Ok(t),
                Velocity::Accelerated => true,
                Velocity::Plain => false,
            };
        let proposal = match self.propose(backend, options, x, bounds, alpha) {
            Ok(p) => p,
            Err(_) if self.held && !self.no_hold => {
                // The parameters held for the step left none: linearise again at x and let
                // the box's candidates choose the step from the whole gradient.
                self.no_hold = true;
                self.need_jac = true;
                return Ok(None);
            }
            Err(t) => return Ok(Some(t)),
        };
        let trial = self.evaluate(backend, options, alpha, accelerated, &proposal, iteration)?;
        Ok(self.conclude(
            backend, options, x, bounds, trial, &proposal, mu, alpha, iteration, callback,
        ))
    }

    /// Bounded solves: while the solved step pushes a parameter on a bound out of the box,
    /// holds that parameter there (an active set, as a projected Newton method) and solves
    /// again. Returns whether the last system was solved and its damping.
    fn hold_blocked<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        x: &[f64],
        b: &Bounds,
        iteration: usize,
        mut solved: bool,
        mut mu: f64,
    ) -> Result<(bool, f64), LmError> {
        // Each pass holds at least one more parameter: at most n passes.
        while solved && b.block(x, self.v.h, &mut self.frozen) {
            self.any_frozen = true;
            self.held = true;
            backend.hold(&self.frozen, self.v.g, self.v.norms2)?;
            (solved, mu) = self.solve_step(backend, x, iteration)?;
        }
        Ok((solved, mu))
    }

    /// Solves the damped system for the step `h` ([`Backend::solve`]).
    fn solve_step<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        x: &[f64],
        iteration: usize,
    ) -> Result<(bool, f64), LmError> {
        let v = &mut self.v;
        backend.solve(
            x,
            iteration,
            &mut self.damping,
            v.d,
            v.g,
            v.h,
            v.wa,
            &mut self.timings,
            &mut self.clock,
        )
    }

    /// Bounded solves: replaces the trial point `P(x + alpha h)`, which the box cut, by
    /// `x` plus the best candidate step of [`CutStep`].
    fn cut<M: Model>(&mut self, backend: &mut Backend<'_, M>, x: &[f64], b: &Bounds, alpha: f64) {
        let Backend::Stored(s) = backend else {
            return;
        };
        let (n, v) = (self.n, &mut self.v);
        let mut dh2 = 0.0;
        for j in 0..n {
            v.step[j] = v.x_trial[j] - x[j];
            // The solved step alpha h, in the trial point's storage for the choice.
            v.x_trial[j] = alpha * v.h[j];
            dh2 += (v.d[j] * v.x_trial[j]).powi(2);
        }
        let radius = if self.damping.is_trust_region() {
            self.damping.radius()
        } else {
            dh2.sqrt()
        };
        let mut cut = CutStep {
            jac: &s.jac,
            scratch: jstep(&mut s.rbuf, s.m),
            bounds: b,
            x,
            g: v.g,
            d: v.d,
            radius,
        };
        cut.choose(v.x_trial, v.step, v.wa);
        for j in 0..n {
            v.x_trial[j] = x[j] + v.step[j];
        }
        b.project(v.x_trial);
    }

    /// Linearises at `x` (gradient, column norms, scales), sets the damping at the first
    /// linearisation, and runs the gradient test. Returns why the solve ends, if it does (a
    /// Jacobian not finite, an abandoned restart, the gradient test).
    fn linearise<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        x: &[f64],
        bounds: Option<&Bounds>,
        abandon: Option<&Abandon>,
    ) -> Result<Option<TerminationReason>, LmError> {
        let v = &mut self.v;
        let rnorm = backend.linearise(
            options,
            x,
            self.records.len(),
            self.first,
            self.damping.mu(),
            bounds,
            &mut self.frozen,
            &mut self.any_frozen,
            v.g,
            v.norms2,
            v.d,
            &mut self.timings,
            &mut self.clock,
        )?;
        self.jacobian_evaluations += 1;
        self.held = false;
        let Some(rnorm) = rnorm else {
            return Ok(Some(TerminationReason::NonFinite));
        };
        for (p, &c) in v.peak2.iter_mut().zip(v.norms2.iter()) {
            *p = p.max(c);
        }
        if let Some(a) = abandon {
            if self.cost >= a.cost
                && self.cost <= a.cost * (1.0 + ABANDON_BAND)
                && a.evaporated
                    .iter()
                    .all(|&j| v.norms2[j] < a.threshold * v.peak2[j])
            {
                return Ok(Some(TerminationReason::UserStop));
            }
        }
        if self.first {
            self.clock.settle(&mut self.timings);
            self.first_damping(options, x);
            self.first = false;
        } else if self.damping.needs_slope() {
            self.damping.new_slope(2.0 * dot(self.v.g, self.v.h));
        }
        // Gradient test (cosine between the residual and each column).
        let v = &self.v;
        let mut gnorm = 0.0f64;
        self.grad_inf = 0.0f64;
        for j in 0..self.n {
            self.grad_inf = self.grad_inf.max(v.g[j].abs());
            if v.norms2[j] > 0.0 && rnorm > 0.0 {
                gnorm = gnorm.max(v.g[j].abs() / (v.norms2[j].sqrt() * rnorm));
            }
        }
        self.need_jac = false;
        Ok((gnorm <= options.gtol).then_some(TerminationReason::ConvergedGtol))
    }

    /// The damping at the first linearisation: `tau` times the largest scaled squared
    /// column norm, and for a trust region its radius.
    fn first_damping(&mut self, options: &Options, x: &[f64]) {
        let (g, norms2, d) = (&*self.v.g, &*self.v.norms2, &*self.v.d);
        let mut mu0 = 0.0f64;
        for j in 0..self.n {
            mu0 = mu0.max(norms2[j] / (d[j] * d[j]));
        }
        mu0 *= options.tau;
        if !(mu0.is_finite() && mu0 > 0.0) {
            mu0 = options.tau;
        }
        self.damping = DampingState::new(options.damping, mu0);
        if self.damping.is_trust_region() {
            let xn = x
                .iter()
                .zip(d.iter())
                .map(|(a, b)| (a * b) * (a * b))
                .sum::<f64>()
                .sqrt();
            // Bound on ||D h|| of the step damped with mu0: ||D^-1 g|| / mu0.
            let gn = g
                .iter()
                .zip(d.iter())
                .map(|(a, b)| (a / b) * (a / b))
                .sum::<f64>()
                .sqrt();
            self.damping.init_radius(xn, gn / mu0);
        }
    }

    /// The limits on iterations and residual evaluations.
    fn limits(&self, options: &Options) -> Option<TerminationReason> {
        if self.records.len() >= options.max_iterations {
            Some(TerminationReason::MaxIterations)
        } else if self.residual_evaluations >= options.max_evaluations {
            Some(TerminationReason::MaxEvaluations)
        } else {
            None
        }
    }

    /// The record of a trial that produced no evaluated point.
    fn failed_record(
        &self,
        iteration: usize,
        mu: f64,
        step_length: f64,
        step_norm: f64,
    ) -> IterationRecord {
        IterationRecord {
            iteration,
            cost: self.cost,
            trial_cost: f64::NAN,
            damping: mu,
            step_length,
            step_norm,
            gain_ratio: f64::NAN,
            accepted: false,
            gradient_norm: self.grad_inf,
            elapsed: self.clock.elapsed(),
        }
    }

    /// Geodesic acceleration: a = -(J^T J + mu D^2)^-1 J^T r_vv, tried as v + a / 2 when
    /// 2 ||D a|| / ||D v|| <= max_ratio; a larger ratio rejects the trial. Not for a
    /// velocity below sqrt(eps) of the scaled parameters: there the finite difference
    /// r_vv is rounding noise (its error grows as 1 / ||v||, so each rejection, shortening
    /// v, would make the next ratio larger), and the plain step is taken. Nor where the
    /// probe `x + fd v` would leave the box (the model is never evaluated outside it).
    fn accelerate<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        x: &[f64],
        bounds: Option<&Bounds>,
        mu: f64,
        alpha: f64,
        iteration: usize,
        callback: &mut Callback<'_, '_>,
    ) -> Result<Velocity, LmError> {
        let (n, v) = (self.n, &mut self.v);
        let resolvable = self.accel.is_some()
            && {
                let (mut dv2, mut dx2) = (0.0, 0.0);
                for j in 0..n {
                    dv2 += (v.d[j] * v.h[j]).powi(2);
                    dx2 += (v.d[j] * x[j]).powi(2);
                }
                dv2 > f64::EPSILON * dx2
            }
            && match (bounds, self.accel) {
                (Some(b), Some(ga)) => b.holds(x, v.h, ga.fd_step),
                _ => true,
            };
        let (Some(ga), Backend::Stored(s), true) = (self.accel, backend, resolvable) else {
            return Ok(Velocity::Plain);
        };
        self.timings.linear_solver += self.clock.lap();
        let ratio = s.accelerate(x, v.x_trial, v.h, ga.fd_step, mu, v.d, iteration)?;
        self.timings.residuals += self.clock.lap();
        self.residual_evaluations += 1;
        if !(ratio <= ga.max_ratio) {
            // The velocity is not to be trusted this far: a rejected trial (the cost at
            // the step is not evaluated; the damping grows as after a failed step).
            self.timings.linear_solver += self.clock.lap();
            self.rejected_steps += 1;
            let dv =
                v.d.iter()
                    .zip(v.h.iter())
                    .map(|(a, b)| (a * b) * (a * b))
                    .sum::<f64>()
                    .sqrt();
            self.damping.rejected(
                -1.0,
                LineInfo {
                    f0: 2.0 * self.cost,
                    slope0: 0.0,
                    alpha,
                    f_trial: 2.0 * self.cost,
                    est_sum: 0.0,
                    scaled_step: dv,
                    gs: dot(v.g, v.h),
                },
            );
            let rec = self.failed_record(iteration, mu, alpha, norm2(self.v.h).sqrt());
            return Ok(Velocity::Rejected(record_failed_trial(
                &mut self.records,
                rec,
                &self.damping,
                callback,
            )));
        }
        for j in 0..n {
            v.h[j] += 0.5 * s.acc[j];
        }
        Ok(Velocity::Accelerated)
    }

    /// The trial point `x + alpha h` (when the box cuts it, see [`Solve::cut`]) and its step;
    /// the step test's termination when the step is negligible.
    fn propose<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        x: &[f64],
        bounds: Option<&Bounds>,
        alpha: f64,
    ) -> Result<Proposal, TerminationReason> {
        let (n, v) = (self.n, &mut self.v);
        for j in 0..n {
            v.x_trial[j] = x[j] + alpha * v.h[j];
        }
        let mut clipped = false;
        if let Some(b) = bounds {
            b.project(v.x_trial);
            clipped = (0..n).any(|j| v.x_trial[j] != x[j] + alpha * v.h[j]);
            if clipped {
                self.cut(backend, x, b, alpha);
            }
        }
        let v = &mut self.v;
        let (mut dx2, mut xn2, mut s2) = (0.0, 0.0, 0.0);
        for j in 0..n {
            v.step[j] = v.x_trial[j] - x[j];
            dx2 += (v.d[j] * v.step[j]).powi(2);
            xn2 += (v.d[j] * x[j]).powi(2);
            s2 += v.step[j] * v.step[j];
        }
        if dx2.sqrt() <= options.xtol * (xn2.sqrt() + options.xtol)
            && !self.box_step_counts(x, bounds, s2)
        {
            return Err(TerminationReason::ConvergedXtol);
        }
        Ok(Proposal {
            clipped,
            dx2,
            xn2,
            s2,
        })
    }

    /// The trial point's predicted and actual reductions of the cost, its gain ratio and
    /// what the damping control needs.
    fn evaluate<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        alpha: f64,
        accelerated: bool,
        p: &Proposal,
        iteration: usize,
    ) -> Result<Trial, LmError> {
        let (n, v) = (self.n, &mut self.v);
        // With acceleration the prediction is the linear model's for the velocity (GSL's
        // convention): the acceleration is a correction the model does not see.
        let (js2, gs) = match (&mut *backend, accelerated) {
            (Backend::Stored(s), true) if !p.clipped => {
                for j in 0..n {
                    v.wa[j] = v.step[j] - 0.5 * alpha * s.acc[j];
                }
                (
                    s.jac.product_norm2(v.wa, jstep(&mut s.rbuf, s.m)),
                    dot(v.g, v.wa),
                )
            }
            _ => (backend.step_norm2(v.step, alpha), dot(v.g, v.step)),
        };
        let pred = -gs - 0.5 * js2;

        // The linear solver's time includes forming the step and its predicted reduction.
        self.timings.linear_solver += self.clock.lap();
        let unmodified = alpha == 1.0 && !p.clipped && !accelerated;
        let mut cost_trial = backend.trial_cost(options, v.x_trial, unmodified, iteration)?;
        self.timings.residuals += self.clock.lap();
        self.residual_evaluations += 1;
        if !cost_trial.is_finite() {
            cost_trial = f64::INFINITY;
        }
        let cost = self.cost;
        let actred = cost - cost_trial;
        let rho = if pred > 0.0 {
            actred / pred
        } else if actred > 0.0 {
            1.0
        } else {
            -1.0
        };
        let line = match (backend, self.cubic) {
            (Backend::Stored(s), true) => {
                let jh2 = if alpha == 1.0 && !p.clipped {
                    js2
                } else {
                    s.jac.mul(v.h, &mut s.jdir);
                    norm2(&s.jdir)
                };
                let gh = dot(v.g, v.h);
                LineInfo {
                    f0: 2.0 * cost,
                    slope0: 2.0 * gh,
                    alpha,
                    f_trial: 2.0 * cost_trial,
                    est_sum: 2.0 * cost + 2.0 * gh + jh2,
                    scaled_step: p.dx2.sqrt(),
                    gs,
                }
            }
            _ => LineInfo {
                f0: 2.0 * cost,
                slope0: 0.0,
                alpha,
                f_trial: 2.0 * cost_trial,
                est_sum: 0.0,
                scaled_step: p.dx2.sqrt(),
                gs,
            },
        };
        Ok(Trial {
            cost: cost_trial,
            pred,
            actred,
            rho,
            line,
        })
    }

    /// Accepts or rejects the trial, records it, and runs the cost tests and the callback.
    /// Returns why the solve ends, if it does.
    fn conclude<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        x: &mut [f64],
        bounds: Option<&Bounds>,
        trial: Trial,
        p: &Proposal,
        mu: f64,
        alpha: f64,
        iteration: usize,
        callback: &mut Callback<'_, '_>,
    ) -> Option<TerminationReason> {
        let cost_before = self.cost;
        let accept = self.damping.accepts(trial.rho, trial.cost < self.cost);
        if accept {
            x.copy_from_slice(self.v.x_trial);
            self.cost = trial.cost;
            self.need_jac = true;
            // A step below sqrt(eps) of the scaled parameters leaves the Jacobian as it was
            // to about 1e-8: good enough for the statistics (with the plain loss, whose
            // Jacobian is not reweighted).
            backend.accept(p.dx2 <= f64::EPSILON * p.xn2);
            self.accepted_steps += 1;
            self.no_hold = false;
            self.damping.accepted(trial.rho, trial.line);
        } else {
            self.rejected_steps += 1;
            self.damping.rejected(trial.rho, trial.line);
        }
        let rec = IterationRecord {
            iteration,
            cost: self.cost,
            trial_cost: trial.cost,
            damping: mu,
            step_length: alpha,
            step_norm: p.s2.sqrt(),
            gain_ratio: trial.rho,
            accepted: accept,
            gradient_norm: self.grad_inf,
            elapsed: self.clock.elapsed(),
        };
        self.records.push(rec);
        let (pred, actred, rho) = (trial.pred, trial.actred, trial.rho);
        if self.cost == 0.0 {
            Some(TerminationReason::ZeroResidual)
        } else if pred <= options.ftol * cost_before
            && ((actred.abs() <= options.ftol * cost_before && rho <= 2.0)
                || actred.abs() <= self.noise * cost_before
                || actred <= 0.0)
            && !self.box_progress_possible(x, bounds, accept, p, pred)
        {
            Some(TerminationReason::ConvergedFtol)
        } else if let Some(cb) = callback.as_mut() {
            cb(&rec).is_break().then_some(TerminationReason::UserStop)
        } else {
            None
        }
    }

    /// Bounded solves, when the step test holds: whether the step is still taken, because it
    /// is above the rounding level of `x` (`||s||^2 = s2`) and the first-order measure at
    /// `x` is above [`OPTIMALITY_TOL`]. (The scaled step test can hold far from a solution:
    /// after a start where a column was huge, Marquardt's running maximum makes every later
    /// step look negligible beside `||D x||`.)
    fn box_step_counts(&self, x: &[f64], bounds: Option<&Bounds>, s2: f64) -> bool {
        let Some(b) = bounds else {
            return false;
        };
        let v = &self.v;
        s2 > f64::EPSILON * f64::EPSILON * norm2(x)
            && boxed::measure(x, v.g, v.norms2, b, self.cost, self.zero_cost()) > OPTIMALITY_TOL
    }

    /// Bounded solves, when the cost test holds: whether the box still allows progress, so
    /// that the solve goes on (the damping grows, the trust region shrinks) instead of
    /// ending. A rejected cut step that the model did not even predict to descend, or a
    /// point whose first-order measure (at the last linearisation) is above
    /// [`OPTIMALITY_TOL`], is not the end.
    fn box_progress_possible(
        &self,
        x: &[f64],
        bounds: Option<&Bounds>,
        accept: bool,
        p: &Proposal,
        pred: f64,
    ) -> bool {
        let Some(b) = bounds else {
            return false;
        };
        if !accept && p.clipped && pred <= 0.0 {
            return true;
        }
        let v = &self.v;
        boxed::measure(x, v.g, v.norms2, b, self.cost, self.zero_cost()) > OPTIMALITY_TOL
    }

    /// The cost at the rounding level of the start's, `(32 eps sqrt(m))^2` times it: the
    /// optimality measure takes it for zero.
    fn zero_cost(&self) -> f64 {
        self.noise * self.noise * self.initial_cost
    }

    /// Bounded solves, at the end: the first-order optimality at `x` (the Jacobian evaluated
    /// again when the stored one is not the whole Jacobian at `x`).
    fn box_optimality<M: Model>(
        &mut self,
        backend: &mut Backend<'_, M>,
        options: &Options,
        x: &[f64],
        b: &Bounds,
    ) -> Result<BoxOptimality, LmError> {
        let stale = self.need_jac || self.any_frozen;
        let v = &mut self.v;
        let (evaluated, finite) =
            backend.final_gradient(options, x, stale, self.records.len(), v.g, v.norms2)?;
        if evaluated {
            self.jacobian_evaluations += 1;
            self.any_frozen = false;
        }
        let v = &self.v;
        let (measure, projected_gradient) = if finite {
            (
                boxed::measure(x, v.g, v.norms2, b, self.cost, self.zero_cost()),
                boxed::projected_gradient(x, v.g, b),
            )
        } else {
            (f64::NAN, f64::NAN)
        };
        Ok(BoxOptimality {
            projected_gradient,
            measure,
            active: b.active(x),
            optimal: measure <= OPTIMALITY_TOL,
        })
    }

    /// The end of a solve: the parameters that evaporated, the statistics at the solution
    /// (when kept) and the report.
    fn finish<M: Model>(
        mut self,
        mut backend: Backend<'_, M>,
        options: &Options,
        x: &[f64],
        bounds: Option<&Bounds>,
        termination: Option<TerminationReason>,
    ) -> Result<Report, LmError> {
        // What the last lap left (a preparation not followed by a solve).
        match backend {
            Backend::Stored(_) => self.timings.linear_solver += self.clock.lap(),
            Backend::Normal(_) => self.timings.jacobian += self.clock.lap(),
        }
        let mut termination = termination.unwrap_or(TerminationReason::MaxIterations);
        let evaporated = self.evaporated(options);
        let optimality = match bounds {
            Some(b) if self.jacobian_evaluations > 0 => {
                let o = self.box_optimality(&mut backend, options, x, b)?;
                // A tolerance met short of a first-order point is a stall, not a success.
                if !o.optimal
                    && matches!(
                        termination,
                        TerminationReason::ConvergedFtol
                            | TerminationReason::ConvergedXtol
                            | TerminationReason::ConvergedGtol
                    )
                {
                    termination = TerminationReason::Stalled;
                }
                self.timings.jacobian += self.clock.lap();
                Some(o)
            }
            _ => None,
        };
        let keep = options.statistics != StatisticsMode::Off
            && self.n <= options.statistics_max_params
            && termination != TerminationReason::NonFinite;
        let statistics = OnceLock::new();
        let fit = match backend {
            Backend::Stored(s) if keep => Some(self.fit_at_solution(s, options, x, &statistics)?),
            _ => None,
        };
        Ok(Report {
            termination,
            initial_cost: self.initial_cost,
            final_cost: self.cost,
            iterations: self.records,
            accepted_steps: self.accepted_steps,
            rejected_steps: self.rejected_steps,
            residual_evaluations: self.residual_evaluations,
            jacobian_evaluations: self.jacobian_evaluations,
            // The last lap ended the solve (the report's assembly is not timed).
            elapsed: self.clock.elapsed(),
            timings: self.timings,
            num_params: self.n,
            num_residuals: self.m,
            damping: options.damping.name(),
            linear_solver: options.linear_solver.name(),
            evaporated,
            optimality,
            restarts: 0,
            statistics,
            fit,
        })
    }

    /// The parameters whose squared column norm fell below the threshold of
    /// [`Evaporation`](crate::Evaporation) times its peak (none held at a bound).
    fn evaporated(&self, options: &Options) -> Vec<usize> {
        let v = &self.v;
        match options.evaporation_restart {
            Some(e) if self.jacobian_evaluations > 0 => (0..v.peak2.len())
                .filter(|&j| {
                    v.norms2[j] < e.threshold * v.peak2[j]
                        && !self.frozen.get(j).copied().unwrap_or(false)
                })
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The Jacobian and residuals at the solution (the Jacobian evaluated again when the
    /// last one is not the solution's), and the statistics when asked for at the end.
    fn fit_at_solution<M: Model>(
        &mut self,
        mut s: Stored<'_, M>,
        options: &Options,
        x: &[f64],
        statistics: &OnceLock<crate::Statistics>,
    ) -> Result<FitAtSolution, LmError> {
        if !s.jac_current || self.any_frozen {
            s.model
                .jacobian(x, &mut s.jac)
                .map_err(model_error(self.records.len(), EvalStage::Jacobian))?;
            self.jacobian_evaluations += 1;
            if s.robust {
                let r = slot(&s.rbuf, s.cur, s.m);
                weigh(options, r, &mut s.rw, &mut s.row_scale, Some(&mut s.jac));
            }
        }
        let residuals = if s.robust {
            s.rw
        } else {
            // The current residuals moved to the front of their buffer (no copy into a
            // new allocation).
            let mut r = s.rbuf;
            if s.cur != 0 {
                r.copy_within(s.cur * s.m..(s.cur + 1) * s.m, 0);
            }
            r.truncate(s.m);
            r
        };
        let fit = FitAtSolution {
            jacobian: s.jac,
            residuals,
            rank_tol: options.rank_tol,
        };
        if options.statistics == StatisticsMode::AtEnd {
            let _ = statistics.set(fit.statistics());
        }
        // The clock was read at the end of the loop.
        self.timings.statistics = self.clock.lap();
        Ok(fit)
    }
}
