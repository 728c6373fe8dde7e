//! Schur-complement solver for many small local blocks plus a few global parameters.
//!
//! Ordering the parameters as `[local blocks | globals]`, the damped normal matrix is
//!
//! ```text
//! [ U   W ]   U = blockdiag(U_k)   (U_k = J_k^T J_k + mu D_k^2, one per local block)
//! [ W^T V ]   V = J_g^T J_g + mu D_g^2
//! ```
//!
//! Each `U_k = L_k L_k^T` is factored on its own (small dense Cholesky) and
//! `Z_k = L_k^-1 W_k`, `z_k = L_k^-1 (-g_k)` are formed. The reduced system
//! `(V - Z^T Z) dg = -g_g - Z^T z` (the Schur complement, `Z` stacking the `Z_k`) is
//! assembled with one matrix product and solved densely (faer LLT); the local steps follow
//! by back-substitution, `h_k = L_k^-T (z_k - Z_k dg)`. The cost is linear in the number
//! of blocks.
//!
//! Per Jacobian, `U_k` and `W_k` are accumulated row by row (each row touches at most one
//! local block) and `V = J_g^T J_g` by matrix products over chunks of rows; per damping
//! value only the block factorisations, the reduced system and the back-substitution run.
//! All storage is allocated when the solver is built.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::matmul::matmul;
use faer::{Accum, Conj, Mat, Par};

use crate::error::LmError;
use crate::solver::jacobian::{Jacobian, SparseJac};
use crate::solver::small;
use crate::solver::LinearSystem;

const NO_BLOCK: usize = usize::MAX;
/// Rows gathered before each `V += C C^T` product.
const CHUNK: usize = 128;

/// Workspace of the Schur solver.
pub(crate) struct Schur {
    /// Number of local parameters (sum of the block sizes).
    nl: usize,
    /// Number of global parameters.
    ng: usize,
    /// First parameter of each block (plus one past the end).
    block_start: Vec<usize>,
    /// Offset of each block's `U_k` (`s_k x s_k`, column-major) in `u` / `lf`.
    u_off: Vec<usize>,
    /// Block of each row (`NO_BLOCK` for rows with global parameters only).
    row_block: Vec<usize>,
    /// Per row, the first CSR entry on a global parameter.
    row_split: Vec<usize>,
    u: Vec<f64>,
    lf: Vec<f64>,
    /// `W` (`nl x ng`): block `k` in rows `block_start[k]..block_start[k + 1]`.
    w: Mat<f64>,
    /// `Z = blockdiag(L_k)^-1 W`.
    z: Mat<f64>,
    /// `J_g^T J_g` (`ng x ng`).
    v: Mat<f64>,
    /// Reduced matrix, factored in place.
    s: Mat<f64>,
    /// Chunk of global rows (stored as columns, `ng x CHUNK`) for the products forming `V`.
    chunk: Mat<f64>,
    /// Dense local part of one row.
    lrow: Vec<f64>,
    /// `L^-1 (-g_l)`, then the back-substituted local step.
    zl: Mat<f64>,
    /// Reduced right-hand side, then the global step.
    rhs: Mat<f64>,
    mem: MemBuffer,
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
        let ng = n - nl;
        let mut block_start = Vec::with_capacity(sizes.len() + 1);
        let mut u_off = Vec::with_capacity(sizes.len() + 1);
        let mut col_block = vec![NO_BLOCK; nl];
        let (mut p, mut uo) = (0, 0);
        for (k, &s) in sizes.iter().enumerate() {
            block_start.push(p);
            u_off.push(uo);
            col_block[p..p + s].fill(k);
            p += s;
            uo += s * s;
        }
        block_start.push(p);
        u_off.push(uo);
        // Every row may touch at most one local block.
        let mut row_block = vec![NO_BLOCK; jac.nrows];
        let mut row_split = vec![0usize; jac.nrows];
        for i in 0..jac.nrows {
            let (b, e) = (jac.row_ptr[i], jac.row_ptr[i + 1]);
            let mut split = e;
            for q in b..e {
                let c = jac.row_col[q];
                if c >= nl {
                    split = q;
                    break;
                }
                let k = col_block[c];
                if row_block[i] == NO_BLOCK {
                    row_block[i] = k;
                } else if row_block[i] != k {
                    return Err(LmError::SchurStructure {
                        row: i,
                        first_block: row_block[i],
                        second_block: k,
                    });
                }
            }
            row_split[i] = split;
        }
        let req = StackReq::any_of(&[
            llt::factor::cholesky_in_place_scratch::<f64>(ng, Par::Seq, Default::default()),
            llt::solve::solve_in_place_scratch::<f64>(ng, 1, Par::Seq),
        ]);
        Ok(Self {
            nl,
            ng,
            block_start,
            u_off,
            row_block,
            row_split,
            u: vec![0.0; uo],
            lf: vec![0.0; uo],
            w: Mat::zeros(nl, ng),
            z: Mat::zeros(nl, ng),
            v: Mat::zeros(ng, ng),
            s: Mat::zeros(ng, ng),
            chunk: Mat::zeros(ng, CHUNK),
            lrow: vec![0.0; sizes.iter().copied().max().unwrap_or(0)],
            zl: Mat::zeros(nl, 1),
            rhs: Mat::zeros(ng, 1),
            mem: MemBuffer::new(req),
        })
    }

    fn flush_chunk(&mut self, rows: usize) {
        if rows == 0 {
            return;
        }
        let c = self.chunk.as_ref().subcols(0, rows);
        matmul(self.v.as_mut(), Accum::Add, c, c.transpose(), 1.0, Par::Seq);
    }
}

impl LinearSystem for Schur {
    fn prepare(&mut self, jac: &Jacobian, _r: &[f64]) -> Result<(), String> {
        let Jacobian::Sparse(j) = jac else {
            return Err("Schur solver needs a sparse Jacobian".into());
        };
        let nl = self.nl;
        self.u.fill(0.0);
        self.w.fill(0.0);
        self.v.fill(0.0);
        let mut rows = 0;
        for i in 0..j.nrows {
            let (b, split, e) = (j.row_ptr[i], self.row_split[i], j.row_ptr[i + 1]);
            let blk = self.row_block[i];
            if blk != NO_BLOCK {
                let p0 = self.block_start[blk];
                let s = self.block_start[blk + 1] - p0;
                // Dense copy of the row's local part, then U += l l^T and W += l g^T.
                let l = &mut self.lrow[..s];
                l.fill(0.0);
                for q in b..split {
                    l[j.row_col[q] - p0] = j.values[q];
                }
                let u = &mut self.u[self.u_off[blk]..self.u_off[blk + 1]];
                for (c, &lc) in l.iter().enumerate() {
                    if lc != 0.0 {
                        for (ua, &la) in u[c * s..(c + 1) * s].iter_mut().zip(l.iter()) {
                            *ua += la * lc;
                        }
                    }
                }
                for qg in split..e {
                    let vg = j.values[qg];
                    if vg == 0.0 {
                        continue;
                    }
                    let col = &mut self.w.col_as_slice_mut(j.row_col[qg] - nl)[p0..p0 + s];
                    for (wa, &la) in col.iter_mut().zip(l.iter()) {
                        *wa += la * vg;
                    }
                }
            }
            if split < e {
                // Rows of the chunk are written transposed (one column per row) so that the
                // writes are contiguous; V += C C^T below.
                let col = self.chunk.col_as_slice_mut(rows);
                col.fill(0.0);
                for qg in split..e {
                    col[j.row_col[qg] - nl] = j.values[qg];
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

    fn solve(&mut self, mu: f64, d: &[f64], g: &[f64], h: &mut [f64]) -> bool {
        let (nl, ng) = (self.nl, self.ng);
        let nblocks = self.block_start.len() - 1;
        // Per block: factor U_k + mu D_k^2, then Z_k = L_k^-1 W_k and z_k = L_k^-1 (-g_k).
        for k in 0..nblocks {
            let (p0, p1) = (self.block_start[k], self.block_start[k + 1]);
            let s = p1 - p0;
            let lf = &mut self.lf[self.u_off[k]..self.u_off[k + 1]];
            lf.copy_from_slice(&self.u[self.u_off[k]..self.u_off[k + 1]]);
            for a in 0..s {
                lf[a + a * s] += mu * d[p0 + a] * d[p0 + a];
            }
            if !small::cholesky(lf, s) {
                return false;
            }
            let zl = &mut self.zl.col_as_slice_mut(0)[p0..p1];
            for a in 0..s {
                zl[a] = -g[p0 + a];
            }
            small::forward_solve(lf, s, zl);
            for b in 0..ng {
                let src = &self.w.col_as_slice(b)[p0..p1];
                let dst = &mut self.z.col_as_slice_mut(b)[p0..p1];
                dst.copy_from_slice(src);
                small::forward_solve(lf, s, dst);
            }
        }
        if ng > 0 {
            // Reduced system (V + mu D_g^2 - Z^T Z) dg = -g_g - Z^T z.
            self.s.copy_from(&self.v);
            for b in 0..ng {
                self.s[(b, b)] += mu * d[nl + b] * d[nl + b];
                self.rhs[(b, 0)] = -g[nl + b];
            }
            if nl > 0 {
                matmul(
                    self.s.as_mut(),
                    Accum::Add,
                    self.z.transpose(),
                    self.z.as_ref(),
                    -1.0,
                    Par::Seq,
                );
                matmul(
                    self.rhs.as_mut(),
                    Accum::Add,
                    self.z.transpose(),
                    self.zl.as_ref(),
                    -1.0,
                    Par::Seq,
                );
            }
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
                self.rhs.as_mut(),
                Par::Seq,
                stack,
            );
            for b in 0..ng {
                h[nl + b] = self.rhs[(b, 0)];
            }
            if nl > 0 {
                // z <- z - Z dg
                matmul(
                    self.zl.as_mut(),
                    Accum::Add,
                    self.z.as_ref(),
                    self.rhs.as_ref(),
                    -1.0,
                    Par::Seq,
                );
            }
        }
        // Back-substitution h_k = L_k^-T (z_k - Z_k dg).
        for k in 0..nblocks {
            let (p0, p1) = (self.block_start[k], self.block_start[k + 1]);
            let s = p1 - p0;
            let zl = &mut self.zl.col_as_slice_mut(0)[p0..p1];
            small::backward_solve(&self.lf[self.u_off[k]..self.u_off[k + 1]], s, zl);
            h[p0..p1].copy_from_slice(zl);
        }
        h.iter().all(|v| v.is_finite())
    }
}
