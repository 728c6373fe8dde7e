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
//! time is linear in the readings. [`Streamed`] hands these passes to `cpm-lm`'s engine as
//! a [`NormalEquations`] problem: the iteration, the damping schedule (by default
//! Gauss-Newton steps while they gain well, then Nielsen's rule), the stopping tests and the
//! report are the engine's.
use cpm_geometry::JointTable;
use cpm_lm::{DampedStep, Linearization, ModelError, NormalEquations, ScaleUpdate};
use nalgebra::{DMatrix, Matrix6, Vector6};
use rayon::prelude::*;

use super::Implicit;
use crate::model::effects::sensor_coefficient;

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
    ///
    /// `U` is summed on and above its diagonal and mirrored: every entry is the sum of the
    /// same products in the same order as nalgebra's `u.ger(1.0, l, l, 1.0)` makes it
    /// (`l_a l_b` and `l_b l_a` are the same number), so the same bits for 21 products a
    /// row instead of 36.
    fn local_normal(&self) -> (Matrix6<f64>, Vector6<f64>) {
        let mut u = [[0.0f64; 6]; 6];
        let mut g = [0.0f64; 6];
        for (l, &r) in self.local.iter().zip(&self.r) {
            for a in 0..6 {
                for b in a..6 {
                    u[a][b] += l[b] * l[a];
                }
                g[a] += r * l[a];
            }
        }
        let u = Matrix6::from_fn(|i, j| if i <= j { u[i][j] } else { u[j][i] });
        (u, Vector6::from(g))
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
    /// `sum (G_j^T G_j - Z_j^T Z_j)` (without the global damping), `ng x ng` column-major:
    /// its lower triangle (row >= column), the upper left at zero. The matrix is symmetric
    /// and its readers (nalgebra's Cholesky and symmetric eigen decomposition) read the
    /// lower triangle alone: summing the upper too was half the reduce pass's updates.
    /// [`Reduced::symmetric`] gives the whole matrix.
    pub(super) s: Vec<f64>,
    /// `-sum Z_j^T z_j`.
    rhs: Vec<f64>,
    /// Gradient of the globals, `sum G_j^T r_j`.
    gg: Vec<f64>,
    /// Squared column norms of the globals.
    norms_g: Vec<f64>,
    /// Sum of squared residuals.
    ss: f64,
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
            failed: false,
        }
    }

    /// The whole `ng x ng` matrix `s` stands for (its lower triangle mirrored), plus
    /// `diagonal[k]` on the diagonal.
    pub(super) fn symmetric(&self, ng: usize, diagonal: impl Fn(usize) -> f64) -> DMatrix<f64> {
        DMatrix::from_fn(ng, ng, |r, c| {
            let (r, c) = (r.max(c), r.min(c));
            self.s[c * ng + r] + if r == c { diagonal(r) } else { 0.0 }
        })
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
        self.failed |= o.failed;
    }
}

/// The local part of a linearisation: the gradient and squared column norms of the pose
/// parameters (`6 * num_poses` each) and the rule their scales follow.
pub(super) struct LocalLinearization<'a> {
    gradient: &'a mut [f64],
    col_norms2: &'a mut [f64],
    scale: ScaleUpdate,
}

/// The reduce pass at `x` and damping `mu`. With `lin` the local gradient and column norms
/// are written and the local scales `d` (`6 * num_poses`) follow the column norms first;
/// with `skip_singular` a pose whose block is singular keeps its `G_j^T G_j` and is left out
/// of the elimination (the identifiability pass), otherwise it marks the result failed.
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
    lin: Option<LocalLinearization<'_>>,
    skip_singular: bool,
) -> Reduced {
    let ng = p.num_globals;
    let g0 = 6 * p.num_poses;
    let globals = &x[g0..];
    let chunk = 6 * POSES_PER_CHUNK;
    let scale = lin.as_ref().map(|l| l.scale);
    // Per chunk of poses: its scales and, when linearising, its gradient and column norms.
    type Chunk<'c> = (&'c mut [f64], Option<(&'c mut [f64], &'c mut [f64])>);
    let chunks: Vec<Chunk<'_>> = match lin {
        Some(l) => d
            .chunks_mut(chunk)
            .zip(
                l.gradient
                    .chunks_mut(chunk)
                    .zip(l.col_norms2.chunks_mut(chunk)),
            )
            .map(|(dc, (gc, nc))| (dc, Some((gc, nc))))
            .collect(),
        None => d.chunks_mut(chunk).map(|dc| (dc, None)).collect(),
    };
    let parts: Vec<Reduced> = chunks
        .into_par_iter()
        .enumerate()
        .map(|(c, (dc, mut lc))| {
            let j0 = c * POSES_PER_CHUNK;
            let mut acc = Reduced::zeros(ng);
            let mut b = Block::default();
            let mut rows: Vec<usize> = Vec::new();
            // Per row of `rows`: where its global columns start when they are consecutive.
            let mut runs: Vec<Option<usize>> = Vec::new();
            let mut ys: Vec<Vector6<f64>> = Vec::new();
            for (t, dj) in dc.chunks_mut(6).enumerate() {
                let j = j0 + t;
                p.fill_block(&x[6 * j..6 * j + 6], globals, table, j, &mut b);
                let (u, gl) = b.local_normal();
                acc.ss += b.r.iter().map(|v| v * v).sum::<f64>();
                if let (Some(rule), Some((gc, nc))) = (scale, lc.as_mut()) {
                    for a in 0..6 {
                        gc[6 * t + a] = gl[a];
                        nc[6 * t + a] = u[(a, a)];
                        rule.apply(&mut dj[a], u[(a, a)]);
                    }
                }
                rows.clear();
                runs.clear();
                for k in 0..b.r.len() {
                    let (cols, vals) = b.globals(k);
                    if cols.is_empty() {
                        continue;
                    }
                    rows.push(k);
                    runs.push(run_start(cols));
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
                        let (ck2, vk2) = b.globals(k2);
                        // Only the lower triangle is summed (see `Reduced::s`): a pair of
                        // runs whose rows all lie above the columns adds nothing.
                        if let (Some(a), Some(b2)) = (runs[ka], runs[kb]) {
                            if b2 + vk2.len() <= a {
                                continue;
                            }
                        }
                        let mut w = if k == k2 { 1.0 } else { 0.0 };
                        if factor.is_some() {
                            w -= ys[ka].dot(&ys[kb]);
                        }
                        for (&c, &v) in ck.iter().zip(vk) {
                            let wv = w * v;
                            let col = &mut acc.s[c * ng..(c + 1) * ng];
                            add_scaled(col, c, runs[kb], ck2, vk2, wv);
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

/// Where `cols` start when they are consecutive (a closure's six installation errors):
/// `None` when they are not (or empty).
fn run_start(cols: &[usize]) -> Option<usize> {
    let first = *cols.first()?;
    let consecutive = cols.iter().enumerate().all(|(k, &c)| c == first + k);
    consecutive.then_some(first)
}

/// `col[cols[k]] += wv * vals[k]` for every `k` with `cols[k] >= lo` (the rows on and
/// below the diagonal of column `lo`), in order: over a slice of `col` when the columns are
/// consecutive from `run` (six of them, a closure's, in fixed-size arrays), otherwise one
/// index after the other. The same products and sums either way, so the same bits; the
/// slices let the compiler drop the bounds checks (the scattered update was the fit's
/// hottest line, a third of `calibrate`'s fit on 10^6 readings).
#[inline(always)]
fn add_scaled(
    col: &mut [f64],
    lo: usize,
    run: Option<usize>,
    cols: &[usize],
    vals: &[f64],
    wv: f64,
) {
    match run {
        Some(c0) => {
            // The columns from `lo` on: all six of a closure's in fixed-size arrays (unrolled).
            let skip = lo.saturating_sub(c0).min(vals.len());
            let (dst, vals) = (&mut col[c0 + skip..c0 + vals.len()], &vals[skip..]);
            if let (Ok(dst), Ok(vals)) = (
                <&mut [f64; 6]>::try_from(&mut *dst),
                <&[f64; 6]>::try_from(vals),
            ) {
                for (d, &v2) in dst.iter_mut().zip(vals) {
                    *d += wv * v2;
                }
            } else {
                for (d, &v2) in dst.iter_mut().zip(vals) {
                    *d += wv * v2;
                }
            }
        }
        None => {
            for (&c2, &v2) in cols.iter().zip(vals) {
                if c2 >= lo {
                    col[c2] += wv * v2;
                }
            }
        }
    }
}

/// Partial sums of the step pass.
#[derive(Default, Clone, Copy)]
struct StepSums {
    /// `||J h||^2`.
    jh2: f64,
    /// Sum of squared residuals at the trial point.
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
                let xj = &x[6 * j..6 * j + 6];
                let mut pt = [0.0; 6];
                for a in 0..6 {
                    hj[a] = hl[a];
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
        t.trial_ss += s.trial_ss;
        t.failed |= s.failed;
    }
    t
}

/// The implicit formulation as a [`NormalEquations`] problem for `cpm-lm`'s engine: each
/// assembly is a reduce pass, each solve the dense solve of the reduced system plus a step
/// pass (which evaluates the cost at the trial point on the way).
pub(super) struct Streamed<'p, 'a> {
    p: &'p Implicit<'a>,
    /// The joint table of the globals assembled at.
    table: Option<JointTable>,
    /// The reduced system last assembled, and its damping.
    reduced: Option<Reduced>,
    mu: f64,
}

impl<'p, 'a> Streamed<'p, 'a> {
    pub(super) fn new(p: &'p Implicit<'a>) -> Self {
        Self {
            p,
            table: None,
            reduced: None,
            mu: 0.0,
        }
    }
}

impl NormalEquations for Streamed<'_, '_> {
    fn num_params(&self) -> usize {
        6 * self.p.num_poses + self.p.num_globals
    }

    fn num_residuals(&self) -> usize {
        self.p.rows
    }

    fn cost(&mut self, x: &[f64]) -> Result<f64, ModelError> {
        let (sc, sr) = self.p.summary(x, None)?;
        // `summary` gives the closures unweighted.
        Ok(0.5 * (sc * self.p.w_enc * self.p.w_enc + sr))
    }

    fn assemble(
        &mut self,
        x: &[f64],
        mu: f64,
        d: &mut [f64],
        lin: Option<Linearization<'_>>,
    ) -> Result<f64, ModelError> {
        let p = self.p;
        let nl = 6 * p.num_poses;
        let table = p.model.table_with(&x[nl..])?;
        let (dl, dg) = d.split_at_mut(nl);
        let red = match lin {
            Some(l) => {
                let (gl, gg) = l.gradient.split_at_mut(nl);
                let (nrl, nrg) = l.col_norms2.split_at_mut(nl);
                let local = LocalLinearization {
                    gradient: gl,
                    col_norms2: nrl,
                    scale: l.scale,
                };
                let red = reduce(p, x, &table, mu, dl, Some(local), false);
                gg.copy_from_slice(&red.gg);
                nrg.copy_from_slice(&red.norms_g);
                for (db, &nb) in dg.iter_mut().zip(&red.norms_g) {
                    l.scale.apply(db, nb);
                }
                red
            }
            None => reduce(p, x, &table, mu, dl, None, false),
        };
        let cost = 0.5 * red.ss;
        self.table = Some(table);
        self.reduced = Some(red);
        self.mu = mu;
        Ok(cost)
    }

    fn solve(
        &mut self,
        x: &[f64],
        d: &[f64],
        h: &mut [f64],
    ) -> Result<Option<DampedStep>, ModelError> {
        let p = self.p;
        let (nl, ng) = (6 * p.num_poses, p.num_globals);
        let (Some(red), Some(table)) = (&self.reduced, &self.table) else {
            return Err("internal: the streamed system was not assembled".into());
        };
        let mu = self.mu;
        if red.failed {
            return Ok(None);
        }
        let (hl, dg) = h.split_at_mut(nl);
        dg.fill(0.0);
        if ng > 0 {
            let s = red.symmetric(ng, |r| mu * d[nl + r] * d[nl + r]);
            let diag: Vec<f64> = (0..ng).map(|b| s[(b, b)]).collect();
            let Some(ch) = s.cholesky() else {
                return Ok(None);
            };
            // Undamped, a pivot below 1e-10 of its diagonal entry is a direction the data do
            // not determine (a blind combination): its Gauss-Newton step would be noise of
            // any size, so the damped steps take over.
            if mu == 0.0 && (0..ng).any(|b| ch.l_dirty()[(b, b)].powi(2) < 1e-10 * diag[b]) {
                return Ok(None);
            }
            let rhs = nalgebra::DVector::from_fn(ng, |b, _| red.rhs[b] - red.gg[b]);
            let sol = ch.solve(&rhs);
            dg.copy_from_slice(sol.as_slice());
            if !dg.iter().all(|v| v.is_finite()) {
                return Ok(None);
            }
        }
        let trial_globals: Vec<f64> = x[nl..].iter().zip(dg.iter()).map(|(a, b)| a + b).collect();
        let trial_table = p.model.table_with(&trial_globals)?;
        let sums = step(
            p,
            x,
            table,
            &trial_globals,
            &trial_table,
            mu,
            &d[..nl],
            dg,
            hl,
        );
        if sums.failed {
            return Ok(None);
        }
        Ok(Some(DampedStep {
            jh_norm2: sums.jh2,
            trial_cost: Some(0.5 * sums.trial_ss),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{poses::random_workspace_poses, sensors::designed_sensors};
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

    /// The mirrored triangle of `local_normal` is nalgebra's `ger` sum bit for bit, and
    /// `add_scaled` over a run of columns the scattered update of the rows from `lo` on bit
    /// for bit (runs of six and of other lengths, columns that are not consecutive, `lo`
    /// before, inside and after them), on rows of wide range.
    #[test]
    fn local_normal_and_add_scaled_are_the_general_sums_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let mut wide = || rng.random_range(-1.0..1.0f64) * 10f64.powi(rng.random_range(-6..6));
        for rows in [0, 1, 6, 22] {
            let mut b = Block::default();
            for _ in 0..rows {
                b.local.push(Vector6::from_fn(|_, _| wide()));
                b.r.push(wide());
            }
            let (u, g) = b.local_normal();
            let (mut u0, mut g0) = (Matrix6::zeros(), Vector6::zeros());
            for (l, &r) in b.local.iter().zip(&b.r) {
                u0.ger(1.0, l, l, 1.0);
                g0.axpy(r, l, 1.0);
            }
            let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(u.as_slice()), bits(u0.as_slice()), "{rows} rows");
            assert_eq!(bits(g.as_slice()), bits(g0.as_slice()), "{rows} rows");
        }
        for cols in [
            vec![12, 13, 14, 15, 16, 17],
            vec![3, 4, 5],
            vec![0, 1, 2, 3, 4, 5, 6],
            vec![7, 2, 30],
            vec![],
        ] {
            let vals: Vec<f64> = cols.iter().map(|_| wide()).collect();
            let start: Vec<f64> = (0..36).map(|_| wide()).collect();
            let wv = wide();
            let consecutive = cols.windows(2).all(|w| w[1] == w[0] + 1) && !cols.is_empty();
            assert_eq!(run_start(&cols).is_some(), consecutive, "{cols:?}");
            let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            for lo in [0, 3, 5, 13, 15, 17, 18, 40] {
                let (mut fast, mut plain) = (start.clone(), start.clone());
                add_scaled(&mut fast, lo, run_start(&cols), &cols, &vals, wv);
                add_scaled(&mut plain, lo, None, &cols, &vals, wv);
                assert_eq!(bits(&fast), bits(&plain), "{cols:?} from {lo}");
                // The scattered update by hand: the rows from `lo` on, the others as they were.
                let mut by_hand = start.clone();
                for (&c2, &v2) in cols.iter().zip(&vals) {
                    if c2 >= lo {
                        by_hand[c2] += wv * v2;
                    }
                }
                assert_eq!(bits(&plain), bits(&by_hand), "{cols:?} from {lo}");
            }
        }
    }
}
