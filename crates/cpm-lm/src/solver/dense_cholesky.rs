//! Dense Cholesky solver: forms `J^T J` once per Jacobian and factors
//! `J^T J + mu D^2 = L L^T` for each damping value with faer's in-place LLT.
//!
//! Faster than QR when `m >> n` but it squares the condition number of `J`, so it loses
//! about twice as many digits on ill-conditioned problems. Storage is allocated once.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Conj, Mat, Par};

use crate::solver::jacobian::Jacobian;
use crate::solver::small::{load_negated, store_finite};
use crate::solver::LinearSystem;

/// Workspace of the dense Cholesky solver.
pub(crate) struct DenseCholesky {
    n: usize,
    jtj: Mat<f64>,
    a: Mat<f64>,
    rhs: Mat<f64>,
    mem: MemBuffer,
    /// Whether `a` holds the factor of the last solve.
    factored: bool,
}

impl DenseCholesky {
    pub(crate) fn new(n: usize) -> Self {
        let req = StackReq::any_of(&[
            llt::factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default()),
            llt::solve::solve_in_place_scratch::<f64>(n, 1, Par::Seq),
        ]);
        Self {
            n,
            jtj: Mat::zeros(n, n),
            a: Mat::zeros(n, n),
            rhs: Mat::zeros(n, 1),
            mem: MemBuffer::new(req),
            factored: false,
        }
    }
}

impl LinearSystem for DenseCholesky {
    fn prepare(&mut self, jac: &Jacobian, _r: &[f64]) -> Result<(), String> {
        let Jacobian::Dense(j) = jac else {
            return Err("dense Cholesky needs a dense Jacobian".into());
        };
        self.factored = false;
        matmul(
            self.jtj.as_mut(),
            Accum::Replace,
            j.transpose(),
            j.as_ref(),
            1.0,
            Par::Seq,
        );
        Ok(())
    }

    fn solve(&mut self, _jac: &Jacobian, mu: f64, d: &[f64], g: &[f64], h: &mut [f64]) -> bool {
        self.factored = false;
        self.a.copy_from(&self.jtj);
        for k in 0..self.n {
            self.a[(k, k)] += mu * d[k] * d[k];
        }
        let stack = MemStack::new(&mut self.mem);
        if llt::factor::cholesky_in_place(
            self.a.as_mut(),
            Default::default(),
            Par::Seq,
            stack,
            Default::default(),
        )
        .is_err()
        {
            return false;
        }
        load_negated(&mut self.rhs, &g[..self.n]);
        llt::solve::solve_in_place_with_conj(
            self.a.as_ref(),
            Conj::No,
            self.rhs.as_mut(),
            Par::Seq,
            stack,
        );
        let ok = store_finite(&self.rhs, &mut h[..self.n]);
        self.factored = ok;
        ok
    }

    fn inverse_quadratic(&mut self, _jac: &Jacobian, w: &[f64]) -> Option<f64> {
        if !self.factored {
            return None;
        }
        // ||L^-1 w||^2 with the factor of the last solve.
        for k in 0..self.n {
            self.rhs[(k, 0)] = w[k];
        }
        solve_lower_triangular_in_place(self.a.as_ref(), self.rhs.as_mut(), Par::Seq);
        let q: f64 = (0..self.n).map(|k| self.rhs[(k, 0)].powi(2)).sum();
        q.is_finite().then_some(q)
    }
}
