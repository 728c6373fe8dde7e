//! Sparse Cholesky solver: `J^T J + mu D^2 = L L^T` with faer's sparse LLT.
//!
//! At construction the structure of the upper triangle of `J^T J` is derived from the
//! Jacobian's pattern and factored symbolically once (AMD fill-reducing ordering, faer
//! picks simplicial or supernodal). Per Jacobian, `J^T J` is assembled column by column
//! through the row-wise index of `J` (a dense scatter vector of length `n`, no allocation);
//! per damping value only the numeric factorisation and two triangular solves run.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Mat, Par, Side};

use crate::error::LmError;
use crate::solver::jacobian::{Jacobian, SparseJac};
use crate::solver::small::{load_negated, store_finite};
use crate::solver::LinearSystem;

/// From this many parameters on, the supernodal factorisation is always used.
const SUPERNODAL_FROM: usize = 1000;
/// Upper bound on the scratch (in values) of the grouped `J^T J` assembly.
const WORK_BUDGET: usize = 1 << 22;

/// Workspace of the sparse Cholesky solver.
pub(crate) struct SparseCholesky {
    n: usize,
    /// Upper triangle of `J^T J`: CSC structure with sorted rows, diagonal always present.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Position of the diagonal entry of each column.
    diag_pos: Vec<usize>,
    jtj: Vec<f64>,
    a: Vec<f64>,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    /// Consecutive columns of `J` with identical row sets, assembled together:
    /// `(first column, one past the last)`.
    groups: Vec<(usize, usize)>,
    /// Per group, `(row, CSR position)` of the entries of its first column:
    /// `lead_src[lead_ptr[k]..lead_ptr[k + 1]]`.
    lead_ptr: Vec<usize>,
    lead_src: Vec<(usize, usize)>,
    /// Widest group.
    width: usize,
    /// Dense scratch `n x width` (row-major: entry `(a, t)` at `a * width + t`).
    work: Vec<f64>,
    rhs: Mat<f64>,
    /// Whether `l_values` holds the factor of the last solve.
    factored: bool,
}

impl SparseCholesky {
    pub(crate) fn new(jac: &SparseJac) -> Result<Self, LmError> {
        let n = jac.ncols;
        // Column-wise index of J (transient): rows of each column and their CSR positions.
        let mut jcol_ptr = vec![0usize; n + 1];
        for &c in &jac.row_col {
            jcol_ptr[c as usize + 1] += 1;
        }
        for c in 0..n {
            jcol_ptr[c + 1] += jcol_ptr[c];
        }
        let nnz_j = jac.row_col.len();
        let mut next = jcol_ptr.clone();
        let mut jcol_row = vec![0u32; nnz_j];
        let mut jcol_src = vec![0usize; nnz_j];
        for r in 0..jac.nrows {
            for q in jac.row_ptr[r]..jac.row_ptr[r + 1] {
                let c = jac.row_col[q] as usize;
                jcol_row[next[c]] = r as u32;
                jcol_src[next[c]] = q;
                next[c] += 1;
            }
        }
        drop(next);
        // Structure of the upper triangle of J^T J.
        let mut marker = vec![usize::MAX; n];
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut diag_pos = vec![0usize; n];
        col_ptr.push(0);
        for b in 0..n {
            let begin = row_idx.len();
            marker[b] = b;
            row_idx.push(b);
            for p in jcol_ptr[b]..jcol_ptr[b + 1] {
                let i = jcol_row[p] as usize;
                // Entries a <= b of row i: the row prefix up to (i, b) itself.
                for &a in &jac.row_col[jac.row_ptr[i]..jcol_src[p]] {
                    let a = a as usize;
                    if marker[a] != b {
                        marker[a] = b;
                        row_idx.push(a);
                    }
                }
            }
            row_idx[begin..].sort_unstable();
            diag_pos[b] = row_idx.len() - 1;
            col_ptr.push(row_idx.len());
        }
        let nnz = row_idx.len();
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic = factorize_symbolic_cholesky(
            sym,
            Side::Upper,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams {
                // faer's flop-based choice prefers the simplicial kernel on arrow-shaped
                // (bundle-like) systems, where the supernodal one is several times faster
                // once the problem is large.
                supernodal_flop_ratio_threshold: if n >= SUPERNODAL_FROM {
                    SupernodalThreshold::FORCE_SUPERNODAL
                } else {
                    SupernodalThreshold::AUTO
                },
                ..Default::default()
            },
        )
        .map_err(|e| {
            LmError::Numerical(format!(
                "sparse Cholesky symbolic factorisation failed: {e:?}"
            ))
        })?;
        // Group consecutive columns with the same rows (e.g. the parameters of one block, or
        // the global parameters): their J^T J columns are assembled in one pass over the rows.
        let max_width = (WORK_BUDGET / n.max(1)).clamp(1, 64);
        let mut groups = Vec::new();
        let mut lead_ptr = vec![0usize];
        let mut lead_src = Vec::new();
        let mut c = 0;
        while c < n {
            let rows = &jcol_row[jcol_ptr[c]..jcol_ptr[c + 1]];
            let mut e = c + 1;
            while e < n && e - c < max_width && &jcol_row[jcol_ptr[e]..jcol_ptr[e + 1]] == rows {
                e += 1;
            }
            groups.push((c, e));
            lead_src.extend(
                (jcol_ptr[c]..jcol_ptr[c + 1]).map(|p| (jcol_row[p] as usize, jcol_src[p])),
            );
            lead_ptr.push(lead_src.len());
            c = e;
        }
        drop((jcol_ptr, jcol_row, jcol_src));
        let width = groups.iter().map(|(a, b)| b - a).max().unwrap_or(1);
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let l_values = vec![0.0; symbolic.len_val()];

        Ok(Self {
            n,
            col_ptr,
            row_idx,
            diag_pos,
            jtj: vec![0.0; nnz],
            a: vec![0.0; nnz],
            symbolic,
            l_values,
            mem: MemBuffer::new(req),
            groups,
            lead_ptr,
            lead_src,
            width,
            work: vec![0.0; n * width],
            rhs: Mat::zeros(n, 1),
            factored: false,
        })
    }
}

impl LinearSystem for SparseCholesky {
    fn prepare(&mut self, jac: &Jacobian, _r: &[f64]) -> Result<(), String> {
        let Jacobian::Sparse(j) = jac else {
            return Err("sparse Cholesky needs a sparse Jacobian".into());
        };
        self.factored = false;
        // Columns c0..c1 of a group share their rows. For a row i, the entries (i, c0..c1)
        // are consecutive in CSR order; column b = c0 + t of the upper triangle receives
        // J[i, b] * J[i, a] for the entries a <= b of row i (a prefix of the sorted row).
        let w = self.width;
        for (k, &(c0, c1)) in self.groups.iter().enumerate() {
            let gw = c1 - c0;
            for &(row, q0) in &self.lead_src[self.lead_ptr[k]..self.lead_ptr[k + 1]] {
                let vals = &j.values[q0..q0 + gw];
                let begin = j.row_ptr[row];
                for q in begin..q0 + gw {
                    let va = j.values[q];
                    if va == 0.0 {
                        continue;
                    }
                    let a = j.row_col[q] as usize;
                    let t0 = q.saturating_sub(q0);
                    let dst = &mut self.work[a * w + t0..a * w + gw];
                    for (d, &vb) in dst.iter_mut().zip(&vals[t0..]) {
                        *d += va * vb;
                    }
                }
            }
            for t in 0..gw {
                let b = c0 + t;
                for k in self.col_ptr[b]..self.col_ptr[b + 1] {
                    let a = self.row_idx[k];
                    self.jtj[k] = self.work[a * w + t];
                    self.work[a * w + t] = 0.0;
                }
            }
        }
        Ok(())
    }

    fn solve(&mut self, _jac: &Jacobian, mu: f64, d: &[f64], g: &[f64], h: &mut [f64]) -> bool {
        self.factored = false;
        self.a.copy_from_slice(&self.jtj);
        for k in 0..self.n {
            self.a[self.diag_pos[k]] += mu * d[k] * d[k];
        }
        let sym = SymbolicSparseColMatRef::new_checked(
            self.n,
            self.n,
            &self.col_ptr,
            None,
            &self.row_idx,
        );
        let a = SparseColMatRef::new(sym, &self.a);
        let stack = MemStack::new(&mut self.mem);
        let llt = match self.symbolic.factorize_numeric_llt(
            &mut self.l_values,
            a,
            Side::Upper,
            LltRegularization::default(),
            Par::Seq,
            stack,
            Default::default(),
        ) {
            Ok(l) => l,
            Err(_) => return false,
        };
        load_negated(&mut self.rhs, &g[..self.n]);
        llt.solve_in_place_with_conj(Conj::No, self.rhs.as_mut(), Par::Seq, stack);
        let ok = store_finite(&self.rhs, &mut h[..self.n]);
        self.factored = ok;
        ok
    }

    fn inverse_quadratic(&mut self, _jac: &Jacobian, w: &[f64]) -> Option<f64> {
        if !self.factored {
            return None;
        }
        for k in 0..self.n {
            self.rhs[(k, 0)] = w[k];
        }
        let stack = MemStack::new(&mut self.mem);
        LltRef::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(
            Conj::No,
            self.rhs.as_mut(),
            Par::Seq,
            stack,
        );
        let q: f64 = (0..self.n).map(|k| w[k] * self.rhs[(k, 0)]).sum();
        q.is_finite().then_some(q)
    }
}
