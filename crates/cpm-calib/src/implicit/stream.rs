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
//! time is linear in the readings. Gauss-Newton steps are taken while they gain well, then
//! Nielsen's damping rule (one solve per trial) with Marquardt scaling; the stopping tests
//! are those of `cpm-lm`.
use std::time::{Duration, Instant};

use cpm_geometry::JointTable;
use cpm_lm::{IterationRecord, Report, TerminationReason, Timings};
use nalgebra::{DMatrix, Matrix6, Vector6};
use rayon::prelude::*;

use super::Implicit;
use crate::effects::sensor_coefficient;

/// Poses per chunk (the unit of parallel work and of the ordered partial sums).
const POSES_PER_CHUNK: usize = 256;

/// One pose's rows: local part, residual and global entries (`gcols` are indices among
/// the globals).
#[derive(Default)]
struct Block {
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
    /// Evaluates configuration `j`'s residuals and Jacobian rows at `x` into `b` through the
    /// general pattern and value functions (the reference [`Implicit::fill_block`] is
    /// tested against).
    #[cfg(test)]
    fn load_block(&self, x: &[f64], table: &JointTable, j: usize, b: &mut Block) {
        let g0 = 6 * self.num_poses;
        let o = self.row0[j];
        let nrows = 6 + self.readings_of(j).len();
        let mut entries = Vec::new();
        self.visit_pose_pattern(j, &mut |r, c| entries.push((r - o, c)));
        let mut values = vec![0.0; entries.len()];
        self.pose_values(x, table, j, &mut values);
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
        for (&(r, c), &v) in entries.iter().zip(&values) {
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

impl Implicit<'_> {
    /// Evaluates configuration `j`'s residuals and Jacobian rows into `b`, for pose
    /// corrections `p` and globals `globals` (joint table `table`): the work of
    /// [`Implicit::pose_residuals`] and [`Implicit::pose_values`] in one pass over the
    /// links and sensors, with the rows in the same order and the same values.
    fn fill_block(&self, p: &[f64], globals: &[f64], table: &JointTable, j: usize, b: &mut Block) {
        b.r.clear();
        b.local.clear();
        b.gptr.clear();
        b.gcols.clear();
        b.gvals.clear();
        b.gptr.push(0);
        let (pose, dw) = self.pose_from(p, j);
        let jlt = super::left_jacobian(&dw).transpose();
        let rm = pose.rotation.matrix();
        let rt = rm.transpose();
        let w = self.w_enc;
        let lengths = &self.lengths_mm[j];
        for (i, l) in table.links.iter().enumerate() {
            let s = rm * l.platform_mm;
            let q = pose.position_mm + s - l.base_mm;
            let len = q.norm();
            let z = q / len;
            let m = jlt * s.cross(&z) * 1e-3;
            let mut target = lengths[i];
            for &(pi, a) in self.links(j, i) {
                target += a * globals[pi];
            }
            b.r.push((len - target) * 1e3 * w);
            b.local.push(Vector6::new(z.x, z.y, z.z, m.x, m.y, m.z) * w);
            let zp = rt * z;
            for c in 0..3 {
                b.gcols.push(6 * i + c);
                b.gvals.push(-z[c] * w);
            }
            for c in 0..3 {
                b.gcols.push(6 * i + 3 + c);
                b.gvals.push(zp[c] * w);
            }
            for &(pi, a) in self.links(j, i) {
                b.gcols.push(pi);
                b.gvals.push(-a * 1e3 * w);
            }
            b.gptr.push(b.gcols.len());
        }
        for &k in self.readings_of(j) {
            let rd = &self.campaign.readings[k];
            let s = &table.sensors[rd.sensor];
            let sp = rm * s.platform_mm;
            let q = pose.position_mm + sp - s.base_mm;
            let geometric = q.norm();
            let u = q / geometric;
            let m = jlt * sp.cross(&u) * 1e-3;
            let mut y = geometric + self.sensor_corr;
            for &(pi, e, qq) in &self.sensor_params[rd.sensor] {
                let a = sensor_coefficient(e, qq, rd.sensor, geometric);
                y += a * globals[pi];
                b.gcols.push(pi);
                b.gvals.push(a * 1e3);
            }
            b.r.push((y - rd.length_mm) * 1e3);
            b.local.push(Vector6::new(u.x, u.y, u.z, m.x, m.y, m.z));
            b.gptr.push(b.gcols.len());
        }
    }
}

/// Partial sums of the reduce pass over a chunk of poses.
pub(super) struct Reduced {
    /// `sum (G_j^T G_j - Z_j^T Z_j)` (without the global damping), `ng x ng` column-major.
    pub(super) s: Vec<f64>,
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
            s: vec![0.0; ng * ng],
            rhs: vec![0.0; ng],
            gg: vec![0.0; ng],
            norms_g: vec![0.0; ng],
            ss: 0.0,
            gmax_local: 0.0,
            failed: false,
        }
    }

    fn add(&mut self, o: &Reduced) {
        for (a, b) in self.s.iter_mut().zip(&o.s) {
            *a += b;
        }
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
///
/// Per pose, with rows `k` of local part `l_k` and global part `g_k` and
/// `U_j + mu D_j^2 = C C^T`: `G^T G - Z^T Z = sum_{k,k'} (delta_kk' - y_k . y_k') g_k g_k'^T`
/// over the rows that touch globals, `y_k = C^-1 l_k` (the sparsity of the `g_k` is kept:
/// a closure touches only its link's six installation errors).
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
    let g0 = 6 * p.num_poses;
    let globals = &x[g0..];
    let parts: Vec<Reduced> = d
        .par_chunks_mut(6 * POSES_PER_CHUNK)
        .enumerate()
        .map(|(c, dc)| {
            let j0 = c * POSES_PER_CHUNK;
            let mut acc = Reduced::zeros(ng);
            let mut b = Block::default();
            let mut rows: Vec<usize> = Vec::new();
            let mut ys: Vec<Vector6<f64>> = Vec::new();
            for (t, dj) in dc.chunks_mut(6).enumerate() {
                let j = j0 + t;
                p.fill_block(&x[6 * j..6 * j + 6], globals, table, j, &mut b);
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
                rows.clear();
                for k in 0..b.r.len() {
                    let (cols, vals) = b.globals(k);
                    if cols.is_empty() {
                        continue;
                    }
                    rows.push(k);
                    let r = b.r[k];
                    for (&c, &v) in cols.iter().zip(vals) {
                        acc.gg[c] += v * r;
                        acc.norms_g[c] += v * v;
                    }
                }
                let mut a_mat = u;
                for a in 0..6 {
                    a_mat[(a, a)] += mu * dj[a] * dj[a];
                }
                let factor = a_mat.cholesky();
                if factor.is_none() && !skip_singular {
                    acc.failed = true;
                    continue;
                }
                // Without a factor (a singular pose in the identifiability pass) only
                // G^T G enters.
                ys.clear();
                let mut zl = -gl;
                if let Some(ch) = &factor {
                    // The factor's diagonal is positive, so the triangular solves succeed.
                    let lm = ch.l();
                    lm.solve_lower_triangular_mut(&mut zl);
                    for &k in &rows {
                        let mut y = b.local[k];
                        lm.solve_lower_triangular_mut(&mut y);
                        ys.push(y);
                    }
                }
                for (ka, &k) in rows.iter().enumerate() {
                    let (ck, vk) = b.globals(k);
                    if factor.is_some() {
                        let proj = ys[ka].dot(&zl);
                        for (&c, &v) in ck.iter().zip(vk) {
                            acc.rhs[c] -= v * proj;
                        }
                    }
                    for (kb, &k2) in rows.iter().enumerate() {
                        let mut w = if k == k2 { 1.0 } else { 0.0 };
                        if factor.is_some() {
                            w -= ys[ka].dot(&ys[kb]);
                        }
                        let (ck2, vk2) = b.globals(k2);
                        for (&c, &v) in ck.iter().zip(vk) {
                            let wv = w * v;
                            let col = &mut acc.s[c * ng..(c + 1) * ng];
                            for (&c2, &v2) in ck2.iter().zip(vk2) {
                                col[c2] += wv * v2;
                            }
                        }
                    }
                }
            }
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
            let mut gd: Vec<f64> = Vec::new();
            for (t, hj) in hc.chunks_mut(6).enumerate() {
                let j = j0 + t;
                p.fill_block(
                    &x[6 * j..6 * j + 6],
                    &x[6 * p.num_poses..],
                    table,
                    j,
                    &mut b,
                );
                let (mut u, gl) = b.local_normal();
                let dj = &d[6 * j..6 * j + 6];
                for a in 0..6 {
                    u[(a, a)] += mu * dj[a] * dj[a];
                }
                let mut rhs = -gl;
                gd.clear();
                gd.resize(b.r.len(), 0.0);
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
    // Gauss-Newton steps (mu = 0) while they are accepted with a gain ratio of at least
    // 1/4: a nearly linear problem (the usual calibration) then converges in a few passes
    // where Nielsen's rule, lowering mu by at most 3 per step, would crawl. The first
    // failure (singular system, or a poor or rejected step) switches to Nielsen's rule from
    // mu0 = tau * max(||J_k||^2 / d_k^2) = tau (d_k = ||J_k|| at the start).
    let mut gauss_newton = true;
    let mut mu = 0.0;
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
                red.s[c * ng + r]
                    + if r == c {
                        mu * d[nl + r] * d[nl + r]
                    } else {
                        0.0
                    }
            });
            let diag: Vec<f64> = (0..ng).map(|b| s[(b, b)]).collect();
            match s.cholesky() {
                // Undamped, a pivot below 1e-10 of its diagonal entry is a direction the
                // data do not determine (a blind combination): its Gauss-Newton step would
                // be noise of any size, so the damped steps take over.
                Some(ch)
                    if mu == 0.0
                        && (0..ng).any(|b| ch.l_dirty()[(b, b)].powi(2) < 1e-10 * diag[b]) =>
                {
                    solved = false;
                }
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
            if gauss_newton {
                gauss_newton = false;
                mu = options.tau;
            } else {
                mu *= nu;
                nu *= 2.0;
            }
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
        // A Gauss-Newton step that gains poorly hands over to the damped steps.
        let leave_gauss_newton = gauss_newton && !(accept && rho >= 0.25);
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
            if leave_gauss_newton {
                gauss_newton = false;
                mu = options.tau;
            } else if !gauss_newton {
                let t = 2.0 * rho - 1.0;
                mu = (mu * (1.0 / 3.0f64).max(1.0 - t * t * t)).max(1e-300);
                nu = 2.0;
            }
        } else {
            rejected_steps += 1;
            if gauss_newton {
                gauss_newton = false;
                mu = options.tau;
            } else {
                mu *= nu;
                nu *= 2.0;
            }
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
        damping: "Gauss-Newton, then Nielsen",
        linear_solver: "Schur complement (streamed)",
        statistics: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper::{designed_sensors, random_workspace_poses};
    use crate::{simulate, Effect, MeasurementModel, Plan, SimulationOptions};

    /// The fused block evaluation gives the rows of the general pattern / value functions
    /// (which the finite-difference test checks), at a point off the start.
    #[test]
    fn fused_block_matches_the_general_rows() {
        let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
        model.nominal.sensors = designed_sensors();
        model.effects = vec![Effect::LinkOffset, Effect::SensorScale];
        let plan = Plan {
            poses: random_workspace_poses(&model.nominal, 5, 100.0, 25.0, 3.0, 3),
            sensors: (0..16).collect(),
        };
        let truth = vec![2.0; model.num_params()];
        let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).unwrap();
        let p =
            super::super::build(&model, &data, &super::super::ImplicitOptions::default()).unwrap();
        let n = 6 * p.num_poses + p.num_globals;
        let x: Vec<f64> = (0..n).map(|k| 30.0 * ((k as f64) * 0.7).sin()).collect();
        let g0 = 6 * p.num_poses;
        let table = model.table_with(&x[g0..]).unwrap();
        let (mut a, mut b) = (Block::default(), Block::default());
        for j in 0..p.num_poses {
            p.load_block(&x, &table, j, &mut a);
            p.fill_block(&x[6 * j..6 * j + 6], &x[g0..], &table, j, &mut b);
            assert_eq!(a.gptr, b.gptr);
            assert_eq!(a.gcols, b.gcols);
            let close = |u: f64, v: f64| (u - v).abs() <= 1e-12 * (1.0 + u.abs());
            for (u, v) in a.r.iter().zip(&b.r) {
                assert!(close(*u, *v), "pose {j}: residual {u} vs {v}");
            }
            for (u, v) in a.gvals.iter().zip(&b.gvals) {
                assert!(close(*u, *v), "pose {j}: global entry {u} vs {v}");
            }
            for (u, v) in a.local.iter().zip(&b.local) {
                for c in 0..6 {
                    assert!(close(u[c], v[c]), "pose {j}: local entry {u} vs {v}");
                }
            }
        }
    }
}
