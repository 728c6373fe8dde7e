//! Streaming Levenberg-Marquardt for the implicit formulation: the reduced (Schur) normal
//! equations are accumulated pose by pose from Jacobian blocks evaluated on the fly, so no
//! Jacobian, no residual vector and no per-pose factor is stored.
//!
//! Per trial two passes run over the poses (in parallel, in fixed chunks whose partial sums
//! are added in order, so the result does not depend on the number of threads):
//!
//! 1. *reduce*: each pose's rows give `U_j = L_j^T L_j` (6 x 6), `W_j = L_j^T G_j`, the
//!    gradient and the global `G_j^T G_j`; with `U_j + mu D_j^2 = C_j C_j^T`,
//!    `Z_j = C_j^-1 W_j` enters `S -= Z_j^T Z_j` (one matrix product per chunk of poses);
//! 2. *step*: after the dense solve of `(S + mu D_g^2) dg = rhs`, each pose's block is
//!    evaluated again for its step `h_j = (U_j + mu D_j^2)^-1 (-g_j - W_j dg)`, the predicted
//!    reduction, and the residuals at the trial point.
//!
//! Memory is the parameters, their scales and one `ng x ng` matrix per chunk of poses;
//! time is linear in the readings. The damping is Nielsen's rule (one solve per trial) with
//! Marquardt scaling; the stopping tests are those of `cpm-lm`.
use std::time::{Duration, Instant};

use cpm_geometry::JointTable;
use cpm_lm::{IterationRecord, Report, TerminationReason, Timings};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use nalgebra::{DMatrix, Matrix6, Vector6};
use rayon::prelude::*;

use super::Implicit;

/// Poses per chunk (the unit of parallel work and of the ordered partial sums).
const POSES_PER_CHUNK: usize = 256;
/// Poses whose `Z_j` are gathered before each `S -= Z^T Z` product.
const Z_POSES: usize = 32;

/// One pose's rows: local part, residual and global entries (`gcols` are indices among
/// the globals).
#[derive(Default)]
struct Block {
    entries: Vec<(usize, usize)>,
    values: Vec<f64>,
    r: Vec<f64>,
    local: Vec<Vector6<f64>>,
    gptr: Vec<usize>,
    gcols: Vec<usize>,
    gvals: Vec<f64>,
}

impl Block {
    fn globals(&self, k: usize) -> (&[usize], &[f64]) {
        let (a, b) = (self.gptr[k], self.gptr[k + 1]);
        (&self.gcols[a..b], &self.gvals[a..b])
    }

    /// `U = sum l l^T` and `g_l = sum l r` over the rows.
    fn local_normal(&self) -> (Matrix6<f64>, Vector6<f64>) {
        let mut u = Matrix6::zeros();
        let mut g = Vector6::zeros();
        for (l, &r) in self.local.iter().zip(&self.r) {
            u.ger(1.0, l, l, 1.0);
            g.axpy(r, l, 1.0);
        }
        (u, g)
    }
}

impl Implicit<'_> {
    /// Evaluates configuration `j`'s residuals and Jacobian rows at `x` into `b`.
    fn load_block(&self, x: &[f64], table: &JointTable, j: usize, b: &mut Block) {
        let g0 = 6 * self.num_poses;
        let o = self.row0[j];
        let nrows = 6 + self.prepared.by_pose[j].len();
        b.entries.clear();
        self.visit_pose_pattern(j, &mut |r, c| b.entries.push((r - o, c)));
        b.values.clear();
        b.values.resize(b.entries.len(), 0.0);
        self.pose_values(x, table, j, &mut b.values);
        b.r.clear();
        b.r.resize(nrows, 0.0);
        self.pose_residuals(&x[6 * j..6 * j + 6], &x[g0..], table, j, &mut b.r);
        b.local.clear();
        b.local.resize(nrows, Vector6::zeros());
        b.gptr.clear();
        b.gcols.clear();
        b.gvals.clear();
        b.gptr.push(0);
        let mut row = 0;
        for (&(r, c), &v) in b.entries.iter().zip(&b.values) {
            while row < r {
                b.gptr.push(b.gcols.len());
                row += 1;
            }
            if c < g0 {
                b.local[r][c - 6 * j] += v;
            } else {
                b.gcols.push(c - g0);
                b.gvals.push(v);
            }
        }
        while row < nrows {
            b.gptr.push(b.gcols.len());
            row += 1;
        }
    }
}

/// Partial sums of the reduce pass over a chunk of poses.
pub(super) struct Reduced {
    /// `sum (G_j^T G_j - Z_j^T Z_j)` (without the global damping).
    pub(super) s: Mat<f64>,
    /// `-sum Z_j^T z_j`.
    rhs: Vec<f64>,
    /// Gradient of the globals, `sum G_j^T r_j`.
    gg: Vec<f64>,
    /// Squared column norms of the globals.
    norms_g: Vec<f64>,
    /// Sum of squared residuals.
    ss: f64,
    /// Largest `|g_k| / ||J_k||` over the local parameters.
    gmax_local: f64,
    /// Whether some `U_j + mu D_j^2` was not positive definite.
    failed: bool,
}

impl Reduced {
    fn zeros(ng: usize) -> Self {
        Self {
            s: Mat::zeros(ng, ng),
            rhs: vec![0.0; ng],
            gg: vec![0.0; ng],
            norms_g: vec![0.0; ng],
            ss: 0.0,
            gmax_local: 0.0,
            failed: false,
        }
    }

    fn add(&mut self, o: &Reduced) {
        self.s += &o.s;
        for (a, b) in self.rhs.iter_mut().zip(&o.rhs) {
            *a += b;
        }
        for (a, b) in self.gg.iter_mut().zip(&o.gg) {
            *a += b;
        }
        for (a, b) in self.norms_g.iter_mut().zip(&o.norms_g) {
            *a += b;
        }
        self.ss += o.ss;
        self.gmax_local = self.gmax_local.max(o.gmax_local);
        self.failed |= o.failed;
    }
}

/// The reduce pass at `x` and damping `mu`. With `update_scales` the local scales `d`
/// (`6 * num_poses`) grow to the column norms first; with `skip_singular` a pose whose
/// block is singular keeps its `G_j^T G_j` and is left out of the elimination (the
/// identifiability pass), otherwise it marks the result failed.
pub(super) fn reduce(
    p: &Implicit<'_>,
    x: &[f64],
    table: &JointTable,
    mu: f64,
    d: &mut [f64],
    update_scales: bool,
    skip_singular: bool,
) -> Reduced {
    let ng = p.num_globals;
    let parts: Vec<Reduced> = d
        .par_chunks_mut(6 * POSES_PER_CHUNK)
        .enumerate()
        .map(|(c, dc)| {
            let j0 = c * POSES_PER_CHUNK;
            let mut acc = Reduced::zeros(ng);
            let mut b = Block::default();
            let zcap = 6 * Z_POSES;
            let mut zt = Mat::<f64>::zeros(ng, zcap);
            let mut zl = Mat::<f64>::zeros(zcap, 1);
            let mut zcols = 0usize;
            let flush = |acc: &mut Reduced, zt: &Mat<f64>, zl: &Mat<f64>, cols: usize| {
                if cols == 0 || ng == 0 {
                    return;
                }
                let z = zt.as_ref().subcols(0, cols);
                matmul(
                    acc.s.as_mut(),
                    Accum::Add,
                    z,
                    z.transpose(),
                    -1.0,
                    Par::Seq,
                );
                let mut rhs = Mat::<f64>::zeros(ng, 1);
                matmul(
                    rhs.as_mut(),
                    Accum::Replace,
                    z,
                    zl.as_ref().subrows(0, cols),
                    1.0,
                    Par::Seq,
                );
                for (k, v) in acc.rhs.iter_mut().enumerate() {
                    *v -= rhs[(k, 0)];
                }
            };
            for (t, dj) in dc.chunks_mut(6).enumerate() {
                let j = j0 + t;
                p.load_block(x, table, j, &mut b);
                let (u, gl) = b.local_normal();
                acc.ss += b.r.iter().map(|v| v * v).sum::<f64>();
                for a in 0..6 {
                    let cn = u[(a, a)].sqrt();
                    if update_scales {
                        dj[a] = dj[a].max(cn);
                        if dj[a] == 0.0 {
                            dj[a] = 1.0;
                        }
                    }
                    if cn > 0.0 {
                        acc.gmax_local = acc.gmax_local.max(gl[a].abs() / cn);
                    }
                }
                if zcols + 6 > zcap {
                    flush(&mut acc, &zt, &zl, zcols);
                    zcols = 0;
                }
                for a in 0..6 {
                    zt.col_as_slice_mut(zcols + a).fill(0.0);
                }
                for k in 0..b.r.len() {
                    let (cols, vals) = b.globals(k);
                    if cols.is_empty() {
                        continue;
                    }
                    let (l, r) = (&b.local[k], b.r[k]);
                    for (&c, &v) in cols.iter().zip(vals) {
                        acc.gg[c] += v * r;
                        acc.norms_g[c] += v * v;
                        for a in 0..6 {
                            zt[(c, zcols + a)] += l[a] * v;
                        }
                        let sc = acc.s.col_as_slice_mut(c);
                        for (&c2, &v2) in cols.iter().zip(vals) {
                            sc[c2] += v * v2;
                        }
                    }
                }
                let mut a_mat = u;
                for a in 0..6 {
                    a_mat[(a, a)] += mu * dj[a] * dj[a];
                }
                let Some(ch) = a_mat.cholesky() else {
                    if !skip_singular {
                        acc.failed = true;
                    }
                    continue;
                };
                let lm = ch.l();
                // Row a of Z: (w_a - sum_{q<a} L_aq z_q) / L_aa; z = L^-1 (-g_l).
                for a in 0..6 {
                    for q in 0..a {
                        let laq = lm[(a, q)];
                        for c in 0..ng {
                            let v = zt[(c, zcols + q)];
                            zt[(c, zcols + a)] -= laq * v;
                        }
                    }
                    let inv = 1.0 / lm[(a, a)];
                    for c in 0..ng {
                        zt[(c, zcols + a)] *= inv;
                    }
                    let mut v = -gl[a];
                    for q in 0..a {
                        v -= lm[(a, q)] * zl[(zcols + q, 0)];
                    }
                    zl[(zcols + a, 0)] = v * inv;
                }
                zcols += 6;
            }
            flush(&mut acc, &zt, &zl, zcols);
            acc
        })
        .collect();
    let mut total = Reduced::zeros(ng);
    for part in &parts {
        total.add(part);
    }
    total
}

/// Partial sums of the step pass.
#[derive(Default, Clone, Copy)]
struct StepSums {
    jh2: f64,
    gh: f64,
    dx2: f64,
    xn2: f64,
    s2: f64,
    trial_ss: f64,
    failed: bool,
}

/// The step pass: local steps into `h` (`6 * num_poses`), given the global step `dg`.
#[allow(clippy::too_many_arguments)]
fn step(
    p: &Implicit<'_>,
    x: &[f64],
    table: &JointTable,
    trial_globals: &[f64],
    trial_table: &JointTable,
    mu: f64,
    d: &[f64],
    dg: &[f64],
    h: &mut [f64],
) -> StepSums {
    let parts: Vec<StepSums> = h
        .par_chunks_mut(6 * POSES_PER_CHUNK)
        .enumerate()
        .map(|(c, hc)| {
            let j0 = c * POSES_PER_CHUNK;
            let mut s = StepSums::default();
            let mut b = Block::default();
            let mut rt = Vec::new();
            for (t, hj) in hc.chunks_mut(6).enumerate() {
                let j = j0 + t;
                p.load_block(x, table, j, &mut b);
                let (mut u, gl) = b.local_normal();
                let dj = &d[6 * j..6 * j + 6];
                for a in 0..6 {
                    u[(a, a)] += mu * dj[a] * dj[a];
                }
                let mut rhs = -gl;
                let mut gd = vec![0.0; b.r.len()];
                for (k, gdk) in gd.iter_mut().enumerate() {
                    let (cols, vals) = b.globals(k);
                    *gdk = cols.iter().zip(vals).map(|(&c, &v)| v * dg[c]).sum();
                    if *gdk != 0.0 {
                        rhs.axpy(-*gdk, &b.local[k], 1.0);
                    }
                }
                let Some(ch) = u.cholesky() else {
                    s.failed = true;
                    continue;
                };
                let hl = ch.solve(&rhs);
                for (l, &gdk) in b.local.iter().zip(&gd) {
                    s.jh2 += (l.dot(&hl) + gdk).powi(2);
                }
                s.gh += gl.dot(&hl);
                let xj = &x[6 * j..6 * j + 6];
                let mut pt = [0.0; 6];
                for a in 0..6 {
                    hj[a] = hl[a];
                    s.dx2 += (dj[a] * hl[a]).powi(2);
                    s.xn2 += (dj[a] * xj[a]).powi(2);
                    s.s2 += hl[a] * hl[a];
                    pt[a] = xj[a] + hl[a];
                }
                rt.clear();
                rt.resize(b.r.len(), 0.0);
                p.pose_residuals(&pt, trial_globals, trial_table, j, &mut rt);
                s.trial_ss += rt.iter().map(|v| v * v).sum::<f64>();
            }
            s
        })
        .collect();
    let mut t = StepSums::default();
    for s in parts {
        t.jh2 += s.jh2;
        t.gh += s.gh;
        t.dx2 += s.dx2;
        t.xn2 += s.xn2;
        t.s2 += s.s2;
        t.trial_ss += s.trial_ss;
        t.failed |= s.failed;
    }
    t
}

/// Minimises the implicit formulation's cost from `x` (pose corrections, then globals)
/// with the streamed Schur complement; `x` holds the solution on return.
pub(super) fn minimize(
    p: &Implicit<'_>,
    x: &mut [f64],
    options: &cpm_lm::Options,
) -> Result<Report, crate::CalibError> {
    let start = Instant::now();
    let np = p.num_poses;
    let ng = p.num_globals;
    let nl = 6 * np;
    let n = nl + ng;
    let mut timings = Timings::default();
    let mut d = vec![0.0; n];
    let mut h = vec![0.0; nl];
    let mut records: Vec<IterationRecord> = Vec::new();
    let (mut residual_evaluations, mut jacobian_evaluations) = (1usize, 0usize);
    let (mut accepted_steps, mut rejected_steps) = (0usize, 0usize);
    // mu0 = tau * max(||J_k||^2 / d_k^2) = tau with d_k = ||J_k|| at the start.
    let mut mu = options.tau;
    let mut nu = 2.0;
    let mut new_jac = true;
    let mut cost = f64::NAN;
    let mut initial_cost = f64::NAN;
    let mut grad_inf = 0.0;
    let m = p.rows;
    let noise = 32.0 * f64::EPSILON * (m as f64).sqrt();
    let elapsed = |t: Instant| -> Duration { t.elapsed() };
    let termination = loop {
        let t0 = Instant::now();
        let table = p.model.table_with(&x[nl..])?;
        let red = reduce(p, x, &table, mu, &mut d[..nl], new_jac, false);
        timings.jacobian += elapsed(t0);
        if new_jac {
            jacobian_evaluations += 1;
            cost = 0.5 * red.ss;
            if initial_cost.is_nan() {
                initial_cost = cost;
            }
            if !cost.is_finite() {
                break TerminationReason::NonFinite;
            }
            if cost == 0.0 {
                break TerminationReason::ZeroResidual;
            }
            let rnorm = red.ss.sqrt();
            let mut gmax = red.gmax_local;
            for b in 0..ng {
                let cn = red.norms_g[b].sqrt();
                d[nl + b] = d[nl + b].max(cn);
                if d[nl + b] == 0.0 {
                    d[nl + b] = 1.0;
                }
                if cn > 0.0 {
                    gmax = gmax.max(red.gg[b].abs() / cn);
                }
            }
            grad_inf = red.gg.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            new_jac = false;
            if gmax / rnorm <= options.gtol {
                break TerminationReason::ConvergedGtol;
            }
        }
        if records.len() >= options.max_iterations {
            break TerminationReason::MaxIterations;
        }
        if residual_evaluations >= options.max_evaluations {
            break TerminationReason::MaxEvaluations;
        }
        let iteration = records.len() + 1;
        let t1 = Instant::now();
        let mut dg = vec![0.0; ng];
        let mut solved = !red.failed;
        if solved && ng > 0 {
            let s = DMatrix::from_fn(ng, ng, |r, c| {
                red.s[(r, c)] + if r == c { mu * d[nl + r] * d[nl + r] } else { 0.0 }
            });
            match s.cholesky() {
                Some(ch) => {
                    let rhs = nalgebra::DVector::from_fn(ng, |b, _| red.rhs[b] - red.gg[b]);
                    let sol = ch.solve(&rhs);
                    dg.copy_from_slice(sol.as_slice());
                    solved = dg.iter().all(|v| v.is_finite());
                }
                None => solved = false,
            }
        }
        timings.linear_solver += elapsed(t1);
        let mut rec = IterationRecord {
            iteration,
            cost,
            trial_cost: f64::NAN,
            damping: mu,
            step_length: 0.0,
            step_norm: 0.0,
            gain_ratio: f64::NAN,
            accepted: false,
            gradient_norm: grad_inf,
            elapsed: Duration::ZERO,
        };
        let mut sums = StepSums::default();
        if solved {
            let t2 = Instant::now();
            let trial_globals: Vec<f64> = x[nl..].iter().zip(&dg).map(|(a, b)| a + b).collect();
            let trial_table = p.model.table_with(&trial_globals)?;
            sums = step(
                p,
                x,
                &table,
                &trial_globals,
                &trial_table,
                mu,
                &d[..nl],
                &dg,
                &mut h,
            );
            residual_evaluations += 1;
            timings.residuals += elapsed(t2);
            solved = !sums.failed;
        }
        if !solved {
            rejected_steps += 1;
            mu *= nu;
            nu *= 2.0;
            rec.elapsed = start.elapsed();
            records.push(rec);
            if mu.is_nan() || mu >= 1e300 {
                break TerminationReason::SingularSystem;
            }
            continue;
        }
        for b in 0..ng {
            sums.gh += red.gg[b] * dg[b];
            sums.dx2 += (d[nl + b] * dg[b]).powi(2);
            sums.xn2 += (d[nl + b] * x[nl + b]).powi(2);
            sums.s2 += dg[b] * dg[b];
        }
        if sums.dx2.sqrt() <= options.xtol * (sums.xn2.sqrt() + options.xtol) {
            break TerminationReason::ConvergedXtol;
        }
        let pred = -sums.gh - 0.5 * sums.jh2;
        let mut cost_trial = 0.5 * sums.trial_ss;
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
        let accept = cost_trial < cost && rho > 0.0;
        let cost_before = cost;
        if accept {
            for (xv, hv) in x[..nl].iter_mut().zip(&h) {
                *xv += hv;
            }
            for (xv, hv) in x[nl..].iter_mut().zip(&dg) {
                *xv += hv;
            }
            cost = cost_trial;
            new_jac = true;
            accepted_steps += 1;
            let t = 2.0 * rho - 1.0;
            mu = (mu * (1.0 / 3.0f64).max(1.0 - t * t * t)).max(1e-300);
            nu = 2.0;
        } else {
            rejected_steps += 1;
            mu *= nu;
            nu *= 2.0;
        }
        rec.cost = cost;
        rec.trial_cost = cost_trial;
        rec.step_length = 1.0;
        rec.step_norm = sums.s2.sqrt();
        rec.gain_ratio = rho;
        rec.accepted = accept;
        rec.elapsed = start.elapsed();
        records.push(rec);
        if cost == 0.0 {
            break TerminationReason::ZeroResidual;
        }
        if pred <= options.ftol * cost_before
            && ((actred.abs() <= options.ftol * cost_before && rho <= 2.0)
                || actred.abs() <= noise * cost_before
                || actred <= 0.0)
        {
            break TerminationReason::ConvergedFtol;
        }
        if mu.is_nan() || mu >= 1e300 {
            break TerminationReason::SingularSystem;
        }
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
        damping: cpm_lm::Damping::Nielsen.name(),
        linear_solver: "Schur complement (streamed)",
        statistics: None,
    })
}
