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
use crate::stats::Statistics;

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| p * q).sum()
}

fn norm2(a: &[f64]) -> f64 {
    a.iter().map(|v| v * v).sum()
}

/// Robust reweighting of the residuals at the current point: fills `rw` and, for a
/// non-square loss, scales the Jacobian rows.
fn weigh(
    options: &Options,
    r: &[f64],
    rw: &mut [f64],
    scale: &mut [f64],
    jac: Option<&mut Jacobian>,
) {
    if options.loss.is_squared() {
        rw.copy_from_slice(r);
        return;
    }
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
    let mut r = vec![0.0; m];
    let mut r_trial = vec![0.0; m];
    let mut rw = vec![0.0; m];
    let mut row_scale = vec![1.0; m];
    let mut jstep = vec![0.0; m];
    let mut jdir = vec![0.0; m];
    let mut x_trial = vec![0.0; n];
    let mut h = vec![0.0; n];
    let mut step = vec![0.0; n];
    let mut g = vec![0.0; n];
    let mut norms2 = vec![0.0; n];
    let mut d = vec![0.0; n];
    let mut frozen = vec![false; n];
    let mut any_frozen = false;
    let mut records: Vec<IterationRecord> = Vec::with_capacity(options.max_iterations.min(256));
    let (mut residual_evaluations, mut jacobian_evaluations) = (0usize, 0usize);
    let (mut accepted_steps, mut rejected_steps) = (0usize, 0usize);

    let t = Instant::now();
    model
        .residuals(x, &mut r)
        .map_err(|source| LmError::Model {
            iteration: 0,
            stage: EvalStage::Residuals,
            source,
        })?;
    timings.residuals += t.elapsed();
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
    // Relative rounding level of a computed cost (sum of m squares).
    let noise = 8.0 * f64::EPSILON * (m as f64).sqrt();

    while termination.is_none() {
        if need_jac {
            let t = Instant::now();
            model
                .jacobian(x, &mut jac)
                .map_err(|source| LmError::Model {
                    iteration: records.len(),
                    stage: EvalStage::Jacobian,
                    source,
                })?;
            timings.jacobian += t.elapsed();
            jacobian_evaluations += 1;
            if !jac.is_finite() {
                termination = Some(TerminationReason::NonFinite);
                break;
            }
            weigh(options, &r, &mut rw, &mut row_scale, Some(&mut jac));
            jac.gradient_and_norms(&rw, &mut g, &mut norms2);
            any_frozen = match &bounds {
                Some(b) => b.freeze(x, &g, &mut frozen),
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
            let t = Instant::now();
            linear.prepare(&jac, &rw).map_err(LmError::Numerical)?;
            timings.linear_solver += t.elapsed();

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
                first = false;
            } else if damping.needs_slope() {
                damping.new_slope(2.0 * dot(&g, &h));
            }
            // Gradient test (cosine between the residual and each column).
            let rnorm = norm2(&rw).sqrt();
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
        let mu = damping.mu();
        let t = Instant::now();
        let solved = linear.solve(mu, &d, &g, &mut h);
        timings.linear_solver += t.elapsed();

        if !solved {
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
                elapsed: start.elapsed(),
            };
            records.push(rec);
            if damping.mu().is_nan() || damping.mu() >= 1e300 {
                termination = Some(TerminationReason::SingularSystem);
            } else if let Some(cb) = callback.as_mut() {
                if cb(&rec).is_break() {
                    termination = Some(TerminationReason::UserStop);
                }
            }
            continue;
        }
        let alpha = damping.step_length();
        for j in 0..n {
            x_trial[j] = x[j] + alpha * h[j];
        }
        let mut clipped = false;
        if let Some(b) = &bounds {
            b.project(&mut x_trial);
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
        jac.mul(&step, &mut jstep);
        let gs = dot(&g, &step);
        let pred = -gs - 0.5 * norm2(&jstep);

        let t = Instant::now();
        model
            .residuals(&x_trial, &mut r_trial)
            .map_err(|source| LmError::Model {
                iteration,
                stage: EvalStage::Residuals,
                source,
            })?;
        timings.residuals += t.elapsed();
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
        let line = if options.damping == Damping::CubicInterpolation {
            let jh2 = if alpha == 1.0 && !clipped {
                norm2(&jstep)
            } else {
                jac.mul(&h, &mut jdir);
                norm2(&jdir)
            };
            let gh = dot(&g, &h);
            LineInfo {
                f0: 2.0 * cost,
                slope0: 2.0 * gh,
                alpha,
                f_trial: 2.0 * cost_trial,
                est_sum: 2.0 * cost + 2.0 * gh + jh2,
            }
        } else {
            LineInfo {
                f0: 2.0 * cost,
                slope0: 0.0,
                alpha,
                f_trial: 2.0 * cost_trial,
                est_sum: 0.0,
            }
        };
        let cost_before = cost;
        let accept = damping.accepts(rho, cost_trial < cost);
        if accept {
            x.copy_from_slice(&x_trial);
            std::mem::swap(&mut r, &mut r_trial);
            cost = cost_trial;
            need_jac = true;
            jac_current = false;
            accepted_steps += 1;
            damping.accepted(rho, line);
        } else {
            rejected_steps += 1;
            damping.rejected(line);
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
            elapsed: start.elapsed(),
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
            weigh(options, &r, &mut rw, &mut row_scale, Some(&mut jac));
        }
        let st = match &jac {
            Jacobian::Dense(j) => Statistics::from_jacobian(j.as_ref(), &rw, options.rank_tol),
            Jacobian::Sparse(_) => {
                let dense = jac.to_dense();
                Statistics::from_jacobian(dense.as_ref(), &rw, options.rank_tol)
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
