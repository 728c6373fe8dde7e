//! Schur-complement solver for many small local blocks plus a few global parameters.
//!
//! Ordering the parameters as `[local blocks | globals]`, the damped normal matrix is
//!
//! ```text
//! [ U   W ]   U = blockdiag(U_k)   (U_k = J_k^T J_k + mu D_k^2, one per local block)
//! [ W^T V ]   V = J_g^T J_g + mu D_g^2,  W_k = J_k^T J_g
//! ```
//!
//! Each `U_k = L_k L_k^T` is factored on its own (small dense Cholesky) and
//! `Z_k = L_k^-1 W_k`, `z_k = L_k^-1 (-g_k)` are formed. The reduced system
//! `(V - Z^T Z) dg = -g_g - Z^T z` (the Schur complement) is accumulated with one matrix
//! product per chunk of blocks and solved densely (faer LLT); the local steps follow by
//! back-substitution, `h_k = U_k^-1 (-g_k - J_k^T (J_g dg))`. The cost is linear in the
//! number of blocks.
//!
//! Memory is kept to what the blocks need: per Jacobian only `J_g^T J_g` is formed (by
//! matrix products over chunks of rows); per damping value each block's `U_k` and `W_k` are
//! accumulated from its rows of the Jacobian into a small chunk buffer and turned into
//! `Z_k` there, so neither `W` nor `Z` is ever stored whole. What persists is the factor
//! `L_k` of every block (`sum s_k^2` values), the list of rows of each block (`u32`) and
//! the `ng x ng` matrices.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Conj, Mat, MatRef, Par};

use crate::error::LmError;
use crate::solver::jacobian::{Jacobian, SparseJac};
use crate::solver::small;
use crate::solver::LinearSystem;

const NO_BLOCK: u32 = u32::MAX;
/// Rows gathered before each `V += C C^T` product.
const CHUNK: usize = 128;
/// Local parameters (rows of `Z`) gathered before each `S -= Z^T Z` product.
const ZCHUNK: usize = 192;

/// Workspace of the Schur solver.
pub(crate) struct Schur {
    /// Number of local parameters (sum of the block sizes).
    nl: usize,
    /// Number of global parameters.
    ng: usize,
    /// First parameter of each block (plus one past the end).
    block_start: Vec<usize>,
    /// Offset of each block's factor (`s_k x s_k`, column-major) in `lf`.
    lf_off: Vec<usize>,
    /// Cholesky factors of `U_k + mu D_k^2` from the last solve.
    lf: Vec<f64>,
    /// Rows of block `k`: `block_rows[block_row_ptr[k]..block_row_ptr[k + 1]]`.
    block_row_ptr: Vec<usize>,
    block_rows: Vec<u32>,
    /// `J_g^T J_g` (`ng x ng`).
    v: Mat<f64>,
    /// Reduced matrix, factored in place.
    s: Mat<f64>,
    /// Chunk of global rows (stored as columns, `ng x CHUNK`) for the products forming `V`.
    chunk: Mat<f64>,
    /// Chunk of `Z` rows, transposed: `ng x zrows` column-major, one contiguous column of
    /// length `ng` per local parameter; holds `W_k^T`, then `(L_k^-1 W_k)^T`, block after
    /// block.
    zt: Vec<f64>,
    /// Capacity of the chunk in local parameters.
    zrows: usize,
    /// The matching chunk of `z` (`zrows x 1`).
    zlc: Mat<f64>,
    /// Dense local part of one row, and a local right-hand side.
    lrow: Vec<f64>,
    tl: Vec<f64>,
    /// Global right-hand side, then the global step.
    tg: Mat<f64>,
    mem: MemBuffer,
    /// Whether `lf` and `s` hold the factors of the last solve.
    factored: bool,
}

/// Position of the first entry of a sorted row on a global parameter.
#[inline]
fn split(cols: &[u32], nl: usize) -> usize {
    cols.partition_point(|&c| (c as usize) < nl)
}

impl Schur {
    pub(crate) fn new(jac: &SparseJac, sizes: &[usize]) -> Result<Self, LmError> {
        let n = jac.ncols;
        let nl: usize = sizes.iter().sum();
        if nl > n {
            return Err(LmError::InvalidOptions(format!(
                "Schur local blocks cover {nl} parameters but the problem has only {n}"
            )));
        }
        if u32::try_from(jac.nrows).is_err() {
            return Err(LmError::InvalidOptions(format!(
                "the Schur solver supports at most {} residuals, the problem has {}",
                u32::MAX,
                jac.nrows
            )));
        }
        let ng = n - nl;
        let nb = sizes.len();
        let mut block_start = Vec::with_capacity(nb + 1);
        let mut lf_off = Vec::with_capacity(nb + 1);
        let mut col_block = vec![NO_BLOCK; nl];
        let (mut p, mut uo) = (0, 0);
        for (k, &s) in sizes.iter().enumerate() {
            block_start.push(p);
            lf_off.push(uo);
            col_block[p..p + s].fill(k as u32);
            p += s;
            uo += s * s;
        }
        block_start.push(p);
        lf_off.push(uo);
        // Block of row i (every row may touch at most one local block).
        let row_block = |i: usize| -> Result<u32, LmError> {
            let (cols, _) = jac.row(i);
            let locals = &cols[..split(cols, nl)];
            let Some(&first) = locals.first() else {
                return Ok(NO_BLOCK);
            };
            let k = col_block[first as usize];
            let last = col_block[locals[locals.len() - 1] as usize];
            if last != k {
                return Err(LmError::SchurStructure {
                    row: i,
                    first_block: k as usize,
                    second_block: last as usize,
                });
            }
            Ok(k)
        };
        let mut block_row_ptr = vec![0usize; nb + 1];
        for i in 0..jac.nrows {
            let k = row_block(i)?;
            if k != NO_BLOCK {
                block_row_ptr[k as usize + 1] += 1;
            }
        }
        for k in 0..nb {
            block_row_ptr[k + 1] += block_row_ptr[k];
        }
        let mut next = block_row_ptr.clone();
        let mut block_rows = vec![0u32; block_row_ptr[nb]];
        for i in 0..jac.nrows {
            let k = row_block(i)?;
            if k != NO_BLOCK {
                block_rows[next[k as usize]] = i as u32;
                next[k as usize] += 1;
            }
        }
        drop(next);
        drop(col_block);
        let smax = sizes.iter().copied().max().unwrap_or(0);
        let zrows = ZCHUNK.max(smax);
        let req = StackReq::any_of(&[
            llt::factor::cholesky_in_place_scratch::<f64>(ng, Par::Seq, Default::default()),
            llt::solve::solve_in_place_scratch::<f64>(ng, 1, Par::Seq),
        ]);
        Ok(Self {
            nl,
            ng,
            block_start,
            lf_off,
            lf: vec![0.0; uo],
            block_row_ptr,
            block_rows,
            v: Mat::zeros(ng, ng),
            s: Mat::zeros(ng, ng),
            chunk: Mat::zeros(ng, CHUNK),
            zt: vec![0.0; zrows * ng],
            zrows,
            zlc: Mat::zeros(zrows, 1),
            lrow: vec![0.0; smax],
            tl: vec![0.0; smax],
            tg: Mat::zeros(ng, 1),
            mem: MemBuffer::new(req),
            factored: false,
        })
    }

    fn flush_chunk(&mut self, rows: usize) {
        if rows == 0 {
            return;
        }
        let c = self.chunk.as_ref().subcols(0, rows);
        matmul(self.v.as_mut(), Accum::Add, c, c.transpose(), 1.0, Par::Seq);
    }

    /// `S -= Z_c^T Z_c`, `tg -= Z_c^T z_c` over the first `rows` local parameters of the
    /// chunk.
    fn flush_z(&mut self, rows: usize) {
        let ng = self.ng;
        if rows == 0 || ng == 0 {
            return;
        }
        let zt = MatRef::from_column_major_slice(&self.zt[..rows * ng], ng, rows);
        matmul(
            self.s.as_mut(),
            Accum::Add,
            zt,
            zt.transpose(),
            -1.0,
            Par::Seq,
        );
        matmul(
            self.tg.as_mut(),
            Accum::Add,
            zt,
            self.zlc.as_ref().subrows(0, rows),
            -1.0,
            Par::Seq,
        );
    }

    fn sparse(jac: &Jacobian) -> &SparseJac {
        match jac {
            Jacobian::Sparse(j) => j,
            Jacobian::Dense(_) => unreachable!("the Schur solver is built for sparse Jacobians"),
        }
    }
}

impl LinearSystem for Schur {
    fn prepare(&mut self, jac: &Jacobian, _r: &[f64]) -> Result<(), String> {
        let Jacobian::Sparse(j) = jac else {
            return Err("Schur solver needs a sparse Jacobian".into());
        };
        self.factored = false;
        let nl = self.nl;
        self.v.fill(0.0);
        if self.ng == 0 {
            return Ok(());
        }
        let mut rows = 0;
        for i in 0..j.nrows {
            let (cols, vals) = j.row(i);
            let sp = split(cols, nl);
            if sp < cols.len() {
                // Rows of the chunk are written transposed (one column per row) so that the
                // writes are contiguous; V += C C^T below.
                let col = self.chunk.col_as_slice_mut(rows);
                col.fill(0.0);
                for (&c, &v) in cols[sp..].iter().zip(&vals[sp..]) {
                    col[c as usize - nl] = v;
                }
                rows += 1;
                if rows == CHUNK {
                    self.flush_chunk(rows);
                    rows = 0;
                }
            }
        }
        self.flush_chunk(rows);
        Ok(())
    }

    fn solve(&mut self, jac: &Jacobian, mu: f64, d: &[f64], g: &[f64], h: &mut [f64]) -> bool {
        self.factored = false;
        let j = Self::sparse(jac);
        let (nl, ng) = (self.nl, self.ng);
        let nblocks = self.block_start.len() - 1;
        if ng > 0 {
            // Reduced system (V + mu D_g^2 - Z^T Z) dg = -g_g - Z^T z, accumulated below.
            self.s.copy_from(&self.v);
            for b in 0..ng {
                self.s[(b, b)] += mu * d[nl + b] * d[nl + b];
                self.tg[(b, 0)] = -g[nl + b];
            }
        }
        let zrows = self.zrows;
        let mut zrow = 0;
        for k in 0..nblocks {
            let (p0, p1) = (self.block_start[k], self.block_start[k + 1]);
            let sz = p1 - p0;
            if zrow + sz > zrows {
                self.flush_z(zrow);
                zrow = 0;
            }
            // U_k (lower triangle, in lf) and W_k^T (in the chunk) from the block's rows.
            let lf = &mut self.lf[self.lf_off[k]..self.lf_off[k + 1]];
            lf.fill(0.0);
            let wt = &mut self.zt[zrow * ng..(zrow + sz) * ng];
            wt.fill(0.0);
            let l = &mut self.lrow[..sz];
            for &i in &self.block_rows[self.block_row_ptr[k]..self.block_row_ptr[k + 1]] {
                let (cols, vals) = j.row(i as usize);
                let sp = split(cols, nl);
                l.fill(0.0);
                for (&c, &v) in cols[..sp].iter().zip(&vals[..sp]) {
                    l[c as usize - p0] = v;
                }
                for c in 0..sz {
                    let lc = l[c];
                    if lc != 0.0 {
                        for (ua, &la) in lf[c * sz + c..(c + 1) * sz].iter_mut().zip(&l[c..]) {
                            *ua += la * lc;
                        }
                    }
                }
                if sp == cols.len() {
                    continue;
                }
                let (gcols, gvals) = (&cols[sp..], &vals[sp..]);
                for (a, &la) in l.iter().enumerate() {
                    if la == 0.0 {
                        continue;
                    }
                    let wrow = &mut wt[a * ng..(a + 1) * ng];
                    for (&c, &vg) in gcols.iter().zip(gvals) {
                        wrow[c as usize - nl] += la * vg;
                    }
                }
            }
            for a in 0..sz {
                lf[a + a * sz] += mu * d[p0 + a] * d[p0 + a];
            }
            if !small::cholesky(lf, sz) {
                return false;
            }
            if ng > 0 {
                // Z_k = L_k^-1 W_k (row by row of Z_k, i.e. column by column of the chunk)
                // and z_k = L_k^-1 (-g_k).
                for a in 0..sz {
                    let (done, rest) = wt.split_at_mut(a * ng);
                    let ra = &mut rest[..ng];
                    for p in 0..a {
                        let lap = lf[a + p * sz];
                        if lap != 0.0 {
                            for (x, &y) in ra.iter_mut().zip(&done[p * ng..(p + 1) * ng]) {
                                *x -= lap * y;
                            }
                        }
                    }
                    let inv = 1.0 / lf[a + a * sz];
                    for x in ra.iter_mut() {
                        *x *= inv;
                    }
                }
                let zl = &mut self.zlc.col_as_slice_mut(0)[zrow..zrow + sz];
                for a in 0..sz {
                    zl[a] = -g[p0 + a];
                }
                small::forward_solve(lf, sz, zl);
            }
            zrow += sz;
        }
        self.flush_z(zrow);
        if ng > 0 {
            let stack = MemStack::new(&mut self.mem);
            if llt::factor::cholesky_in_place(
                self.s.as_mut(),
                Default::default(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .is_err()
            {
                return false;
            }
            llt::solve::solve_in_place_with_conj(
                self.s.as_ref(),
                Conj::No,
                self.tg.as_mut(),
                Par::Seq,
                stack,
            );
            for b in 0..ng {
                h[nl + b] = self.tg[(b, 0)];
            }
        }
        // Back-substitution h_k = U_k^-1 (-g_k - J_k^T (J_g dg)).
        let mut ok = h[nl..].iter().all(|v| v.is_finite());
        let (hl, _) = h.split_at_mut(nl);
        for k in 0..nblocks {
            let (p0, p1) = (self.block_start[k], self.block_start[k + 1]);
            let sz = p1 - p0;
            let t = &mut self.tl[..sz];
            for a in 0..sz {
                t[a] = -g[p0 + a];
            }
            if ng > 0 {
                for &i in &self.block_rows[self.block_row_ptr[k]..self.block_row_ptr[k + 1]] {
                    let (cols, vals) = j.row(i as usize);
                    let sp = split(cols, nl);
                    let gd: f64 = cols[sp..]
                        .iter()
                        .zip(&vals[sp..])
                        .map(|(&c, &v)| v * self.tg[(c as usize - nl, 0)])
                        .sum();
                    if gd != 0.0 {
                        for (&c, &v) in cols[..sp].iter().zip(&vals[..sp]) {
                            t[c as usize - p0] -= v * gd;
                        }
                    }
                }
            }
            let lf = &self.lf[self.lf_off[k]..self.lf_off[k + 1]];
            small::forward_solve(lf, sz, t);
            small::backward_solve(lf, sz, t);
            hl[p0..p1].copy_from_slice(t);
            ok &= t.iter().all(|v| v.is_finite());
        }
        self.factored = ok;
        ok
    }

    fn inverse_quadratic(&mut self, jac: &Jacobian, w: &[f64]) -> Option<f64> {
        if !self.factored {
            return None;
        }
        // With A = L L^T, L = [L_U 0; Z^T L_S]: w^T A^-1 w = ||L_U^-1 w_l||^2 + ||y||^2,
        // y = L_S^-1 (w_g - W^T U^-1 w_l), and W^T U^-1 w_l = J_g^T (J_l U^-1 w_l) row by row.
        let j = Self::sparse(jac);
        let (nl, ng) = (self.nl, self.ng);
        for b in 0..ng {
            self.tg[(b, 0)] = w[nl + b];
        }
        let mut quad = 0.0;
        for k in 0..self.block_start.len() - 1 {
            let (p0, p1) = (self.block_start[k], self.block_start[k + 1]);
            let sz = p1 - p0;
            let lf = &self.lf[self.lf_off[k]..self.lf_off[k + 1]];
            let t = &mut self.tl[..sz];
            t.copy_from_slice(&w[p0..p1]);
            small::forward_solve(lf, sz, t);
            quad += t.iter().map(|v| v * v).sum::<f64>();
            if ng == 0 {
                continue;
            }
            small::backward_solve(lf, sz, t);
            for &i in &self.block_rows[self.block_row_ptr[k]..self.block_row_ptr[k + 1]] {
                let (cols, vals) = j.row(i as usize);
                let sp = split(cols, nl);
                let sc: f64 = cols[..sp]
                    .iter()
                    .zip(&vals[..sp])
                    .map(|(&c, &v)| v * t[c as usize - p0])
                    .sum();
                if sc != 0.0 {
                    for (&c, &v) in cols[sp..].iter().zip(&vals[sp..]) {
                        self.tg[(c as usize - nl, 0)] -= v * sc;
                    }
                }
            }
        }
        if ng > 0 {
            solve_lower_triangular_in_place(self.s.as_ref(), self.tg.as_mut(), Par::Seq);
            quad += (0..ng).map(|b| self.tg[(b, 0)].powi(2)).sum::<f64>();
        }
        quad.is_finite().then_some(quad)
    }
}
