//! The Levenberg-Marquardt iteration shared by every problem kind and linear solver.
//!
//! Per Jacobian: robust reweighting of the rows, gradient `g = J^T r`, freezing of
//! parameters held at a bound, update of the scaling `D`, the damping-independent part of
//! the linear solve, and the gradient test. Per trial step: solve the damped system, project
//! onto the bounds, step test, evaluate, gain ratio, accept or reject, cost test.

use std::ops::ControlFlow;
use std::time::Instant;

use crate::bounds::Bounds;
use crate::damping::{Damping, DampingState, LineInfo};
use crate::error::{EvalStage, LmError};
use crate::options::{Options, Scaling};
use crate::report::{IterationRecord, Report, TerminationReason, Timings};
use crate::solver::build_linear;
use crate::solver::jacobian::Jacobian;
use crate::solver::model::Model;
use crate::solver::small::{dot, norm2};
use crate::solver::trust_region::lmpar;
use crate::stats::Statistics;

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

pub(crate) fn run<M: Model>(
    model: &mut M,
    x: &mut [f64],
    options: &Options,
    mut callback: Callback<'_, '_>,
) -> Result<Report, LmError> {
    let start = Instant::now();
    let n = model.num_params();
    let m = model.num_residuals();
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
    options.validate_for(n)?;
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
    let mut jac = model.new_jacobian(options.linear_solver.is_sparse())?;
    let mut linear = build_linear(&options.linear_solver, &jac)?;

    let mut timings = Timings::default();
    // Residual-sized buffers: the robust-loss ones only with a robust loss, the products
    // with J only for a dense Jacobian or the cubic control (a sparse product is reduced
    // row by row).
    let robust = !options.loss.is_squared();
    let cubic = options.damping == Damping::CubicInterpolation;
    let dense_jac = matches!(jac, Jacobian::Dense(_));
    let buffer = |needed: bool, v: f64| if needed { vec![v; m] } else { Vec::new() };
    let mut r = vec![0.0; m];
    let mut r_trial = vec![0.0; m];
    let mut rw = buffer(robust, 0.0);
    let mut row_scale = buffer(robust, 1.0);
    let accel = options.acceleration;
    let mut jstep = buffer(dense_jac || cubic, 0.0);
    let mut jdir = buffer(cubic || accel.is_some(), 0.0);
    // Geodesic acceleration: residuals at x + h v, the acceleration and its right-hand side.
    let mut r_probe = buffer(accel.is_some(), 0.0);
    let mut acc = if accel.is_some() {
        vec![0.0; 2 * n]
    } else {
        Vec::new()
    };
    // The parameter-sized vectors share one allocation (small problems spend a fair part
    // of their time in the allocator).
    let mut nbuf = vec![0.0; 7 * n];
    let (wa, rest) = nbuf.split_at_mut(n);
    let (x_trial, rest) = rest.split_at_mut(n);
    let (h, rest) = rest.split_at_mut(n);
    let (step, rest) = rest.split_at_mut(n);
    let (g, rest) = rest.split_at_mut(n);
    let (norms2, d) = rest.split_at_mut(n);
    let mut frozen = if bounds.is_some() {
        vec![false; n]
    } else {
        Vec::new()
    };
    let mut any_frozen = false;
    let mut records: Vec<IterationRecord> = Vec::with_capacity(options.max_iterations.min(32));
    let (mut residual_evaluations, mut jacobian_evaluations) = (0usize, 0usize);
    let (mut accepted_steps, mut rejected_steps) = (0usize, 0usize);

    // Timestamps are chained (one clock read per phase boundary): on small problems the
    // clock costs as much as the arithmetic.
    let mut clock = Instant::now();
    model
        .residuals(x, &mut r)
        .map_err(|source| LmError::Model {
            iteration: 0,
            stage: EvalStage::Residuals,
            source,
        })?;
    let now = Instant::now();
    timings.residuals += now - clock;
    clock = now;
    residual_evaluations += 1;
    let mut cost = options.loss.cost(&r);
    let initial_cost = cost;

    let mut termination = if !cost.is_finite() {
        Some(TerminationReason::NonFinite)
    } else if cost == 0.0 {
        Some(TerminationReason::ZeroResidual)
    } else {
        None
    };
    let mut damping = DampingState::new(options.damping, 1.0);
    let mut first = true;
    let mut need_jac = true;
    let mut jac_current = false;
    let mut grad_inf = 0.0;
    // Relative rounding level of a computed cost (sum of m squares, each residual usually a
    // difference of larger numbers, hence the margin over eps).
    let noise = 32.0 * f64::EPSILON * (m as f64).sqrt();

    while termination.is_none() {
        if need_jac {
            model
                .jacobian(x, &mut jac)
                .map_err(|source| LmError::Model {
                    iteration: records.len(),
                    stage: EvalStage::Jacobian,
                    source,
                })?;
            jacobian_evaluations += 1;
            if !jac.is_finite() {
                termination = Some(TerminationReason::NonFinite);
                break;
            }
            if robust {
                weigh(options, &r, &mut rw, &mut row_scale, Some(&mut jac));
            }
            let rw: &[f64] = if robust { &rw } else { &r };
            jac.gradient_and_norms(rw, g, norms2);
            any_frozen = match &bounds {
                Some(b) => b.freeze(x, g, &mut frozen),
                None => false,
            };
            if any_frozen {
                jac.zero_cols(&frozen);
                for j in 0..n {
                    if frozen[j] {
                        g[j] = 0.0;
                        norms2[j] = 0.0;
                    }
                }
            }
            match options.scaling {
                Scaling::Marquardt => {
                    for j in 0..n {
                        let c = norms2[j].sqrt();
                        d[j] = if first { c } else { d[j].max(c) };
                        if d[j] == 0.0 {
                            d[j] = 1.0;
                        }
                    }
                }
                Scaling::Identity => d.fill(1.0),
            }
            // The Jacobian's time includes the reweighting and the gradient.
            let now = Instant::now();
            timings.jacobian += now - clock;
            clock = now;
            linear.prepare(&jac, rw).map_err(LmError::Numerical)?;
            let now = Instant::now();
            timings.linear_solver += now - clock;
            clock = now;

            if first {
                let mut mu0 = 0.0f64;
                for j in 0..n {
                    mu0 = mu0.max(norms2[j] / (d[j] * d[j]));
                }
                mu0 *= options.tau;
                if !(mu0.is_finite() && mu0 > 0.0) {
                    mu0 = options.tau;
                }
                damping = DampingState::new(options.damping, mu0);
                if damping.is_trust_region() {
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
                    damping.init_radius(xn, gn / mu0);
                }
                first = false;
            } else if damping.needs_slope() {
                damping.new_slope(2.0 * dot(g, h));
            }
            // Gradient test (cosine between the residual and each column).
            let rnorm = norm2(rw).sqrt();
            let mut gnorm = 0.0f64;
            grad_inf = 0.0f64;
            for j in 0..n {
                grad_inf = grad_inf.max(g[j].abs());
                if norms2[j] > 0.0 && rnorm > 0.0 {
                    gnorm = gnorm.max(g[j].abs() / (norms2[j].sqrt() * rnorm));
                }
            }
            need_jac = false;
            jac_current = true;
            if gnorm <= options.gtol {
                termination = Some(TerminationReason::ConvergedGtol);
                break;
            }
        }
        if records.len() >= options.max_iterations {
            termination = Some(TerminationReason::MaxIterations);
            break;
        }
        if residual_evaluations >= options.max_evaluations {
            termination = Some(TerminationReason::MaxEvaluations);
            break;
        }
        let iteration = records.len() + 1;
        let (solved, mu) = if damping.is_trust_region() {
            match lmpar(
                linear.as_mut(),
                &jac,
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
            (linear.solve(&jac, mu, d, g, h), mu)
        };
        if !solved {
            let now = Instant::now();
            timings.linear_solver += now - clock;
            clock = now;
            rejected_steps += 1;
            damping.singular();
            let rec = IterationRecord {
                iteration,
                cost,
                trial_cost: f64::NAN,
                damping: mu,
                step_length: 0.0,
                step_norm: 0.0,
                gain_ratio: f64::NAN,
                accepted: false,
                gradient_norm: grad_inf,
                elapsed: clock - start,
            };
            records.push(rec);
            if damping.exhausted() {
                termination = Some(TerminationReason::SingularSystem);
            } else if let Some(cb) = callback.as_mut() {
                if cb(&rec).is_break() {
                    termination = Some(TerminationReason::UserStop);
                }
            }
            continue;
        }
        let alpha = damping.step_length();
        // Geodesic acceleration: a = -(J^T J + mu D^2)^-1 J^T r_vv, tried as v + a / 2 when
        // 2 ||D a|| / ||D v|| <= max_ratio; a larger ratio rejects the trial.
        let mut accel_ratio = None;
        if let Some(ga) = accel {
            let fd = ga.fd_step;
            for j in 0..n {
                x_trial[j] = x[j] + fd * h[j];
            }
            let now = Instant::now();
            timings.linear_solver += now - clock;
            model
                .residuals(x_trial, &mut r_probe)
                .map_err(|source| LmError::Model {
                    iteration,
                    stage: EvalStage::Residuals,
                    source,
                })?;
            clock = Instant::now();
            timings.residuals += clock - now;
            residual_evaluations += 1;
            jac.mul(h, &mut jdir);
            for i in 0..m {
                r_probe[i] = (2.0 / fd) * ((r_probe[i] - r[i]) / fd - jdir[i]);
            }
            let (a, rhs) = acc.split_at_mut(n);
            jac.transpose_mul(&r_probe, rhs);
            // An acceleration that cannot be solved for leaves the plain step (ratio 0).
            let ratio = if linear.resolve(&jac, mu, d, rhs, a) {
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
            };
            accel_ratio = Some(ratio);
            if !(ratio <= ga.max_ratio) {
                // The velocity is not to be trusted this far: a rejected trial (the cost at
                // the step is not evaluated; the damping grows as after a failed step).
                let now = Instant::now();
                timings.linear_solver += now - clock;
                clock = now;
                rejected_steps += 1;
                let dv = d
                    .iter()
                    .zip(h.iter())
                    .map(|(a, b)| (a * b) * (a * b))
                    .sum::<f64>()
                    .sqrt();
                damping.rejected(
                    -1.0,
                    LineInfo {
                        f0: 2.0 * cost,
                        slope0: 0.0,
                        alpha,
                        f_trial: 2.0 * cost,
                        est_sum: 0.0,
                        scaled_step: dv,
                        gs: dot(g, h),
                    },
                );
                let rec = IterationRecord {
                    iteration,
                    cost,
                    trial_cost: f64::NAN,
                    damping: mu,
                    step_length: alpha,
                    step_norm: norm2(h).sqrt(),
                    gain_ratio: f64::NAN,
                    accepted: false,
                    gradient_norm: grad_inf,
                    elapsed: clock - start,
                };
                records.push(rec);
                if damping.exhausted() {
                    termination = Some(TerminationReason::SingularSystem);
                } else if let Some(cb) = callback.as_mut() {
                    if cb(&rec).is_break() {
                        termination = Some(TerminationReason::UserStop);
                    }
                }
                continue;
            }
            for j in 0..n {
                h[j] += 0.5 * a[j];
            }
        }
        for j in 0..n {
            x_trial[j] = x[j] + alpha * h[j];
        }
        let mut clipped = false;
        if let Some(b) = &bounds {
            b.project(x_trial);
            clipped = (0..n).any(|j| x_trial[j] != x[j] + alpha * h[j]);
        }
        let (mut dx2, mut xn2, mut s2) = (0.0, 0.0, 0.0);
        for j in 0..n {
            step[j] = x_trial[j] - x[j];
            dx2 += (d[j] * step[j]).powi(2);
            xn2 += (d[j] * x[j]).powi(2);
            s2 += step[j] * step[j];
        }
        if dx2.sqrt() <= options.xtol * (xn2.sqrt() + options.xtol) {
            termination = Some(TerminationReason::ConvergedXtol);
            break;
        }
        // With acceleration the prediction is the linear model's for the velocity (GSL's
        // convention): the acceleration is a correction the model does not see.
        let (js2, gs) = if accel_ratio.is_some() {
            let a = &acc[..n];
            for j in 0..n {
                wa[j] = step[j] - 0.5 * alpha * a[j];
            }
            (jac.product_norm2(wa, &mut jstep), dot(g, wa))
        } else {
            (jac.product_norm2(step, &mut jstep), dot(g, step))
        };
        let pred = -gs - 0.5 * js2;

        // The linear solver's time includes forming the step and its predicted reduction.
        let now = Instant::now();
        timings.linear_solver += now - clock;
        model
            .residuals(x_trial, &mut r_trial)
            .map_err(|source| LmError::Model {
                iteration,
                stage: EvalStage::Residuals,
                source,
            })?;
        clock = Instant::now();
        timings.residuals += clock - now;
        residual_evaluations += 1;
        let mut cost_trial = options.loss.cost(&r_trial);
        if !cost_trial.is_finite() {
            cost_trial = f64::INFINITY;
        }
        let actred = cost - cost_trial;
        let rho = if pred > 0.0 {
            actred / pred
        } else if actred > 0.0 {
            1.0
        } else {
            -1.0
        };
        let line = if cubic {
            let jh2 = if alpha == 1.0 && !clipped {
                js2
            } else {
                jac.mul(h, &mut jdir);
                norm2(&jdir)
            };
            let gh = dot(g, h);
            LineInfo {
                f0: 2.0 * cost,
                slope0: 2.0 * gh,
                alpha,
                f_trial: 2.0 * cost_trial,
                est_sum: 2.0 * cost + 2.0 * gh + jh2,
                scaled_step: dx2.sqrt(),
                gs,
            }
        } else {
            LineInfo {
                f0: 2.0 * cost,
                slope0: 0.0,
                alpha,
                f_trial: 2.0 * cost_trial,
                est_sum: 0.0,
                scaled_step: dx2.sqrt(),
                gs,
            }
        };
        let cost_before = cost;
        let accept = damping.accepts(rho, cost_trial < cost);
        if accept {
            x.copy_from_slice(x_trial);
            std::mem::swap(&mut r, &mut r_trial);
            cost = cost_trial;
            need_jac = true;
            // A step below sqrt(eps) of the scaled parameters leaves the Jacobian as it was
            // to about 1e-8: good enough for the statistics (with the plain loss, whose
            // Jacobian is not reweighted).
            jac_current = !robust && dx2 <= f64::EPSILON * xn2;
            accepted_steps += 1;
            damping.accepted(rho, line);
        } else {
            rejected_steps += 1;
            damping.rejected(rho, line);
        }
        let rec = IterationRecord {
            iteration,
            cost,
            trial_cost: cost_trial,
            damping: mu,
            step_length: alpha,
            step_norm: s2.sqrt(),
            gain_ratio: rho,
            accepted: accept,
            gradient_norm: grad_inf,
            elapsed: clock - start,
        };
        records.push(rec);
        if cost == 0.0 {
            termination = Some(TerminationReason::ZeroResidual);
        } else if pred <= options.ftol * cost_before
            && ((actred.abs() <= options.ftol * cost_before && rho <= 2.0)
                || actred.abs() <= noise * cost_before
                || actred <= 0.0)
        {
            termination = Some(TerminationReason::ConvergedFtol);
        } else if let Some(cb) = callback.as_mut() {
            if cb(&rec).is_break() {
                termination = Some(TerminationReason::UserStop);
            }
        }
    }
    let termination = termination.unwrap_or(TerminationReason::MaxIterations);

    let statistics = if options.compute_statistics
        && n <= options.statistics_max_params
        && termination != TerminationReason::NonFinite
    {
        let t = Instant::now();
        if !jac_current || any_frozen {
            model
                .jacobian(x, &mut jac)
                .map_err(|source| LmError::Model {
                    iteration: records.len(),
                    stage: EvalStage::Jacobian,
                    source,
                })?;
            jacobian_evaluations += 1;
            if robust {
                weigh(options, &r, &mut rw, &mut row_scale, Some(&mut jac));
            }
        }
        let rw: &[f64] = if robust { &rw } else { &r };
        let st = match &jac {
            Jacobian::Dense(j) => Statistics::from_jacobian(j.as_ref(), rw, options.rank_tol),
            Jacobian::Sparse(_) => {
                let dense = jac.to_dense();
                Statistics::from_jacobian(dense.as_ref(), rw, options.rank_tol)
            }
        };
        timings.statistics = t.elapsed();
        Some(st)
    } else {
        None
    };

    Ok(Report {
        termination,
        initial_cost,
        final_cost: cost,
        iterations: records,
        accepted_steps,
        rejected_steps,
        residual_evaluations,
        jacobian_evaluations,
        elapsed: start.elapsed(),
        timings,
        num_params: n,
        num_residuals: m,
        damping: options.damping.name(),
        linear_solver: options.linear_solver.name(),
        statistics,
    })
}
