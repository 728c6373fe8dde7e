//! Adapters from the user's problem traits to the solver's Jacobian storage: dense
//! problems and sparse problems can each feed a dense or a sparse linear solver.

use faer::Mat;

use crate::error::LmError;
use crate::problem::{DenseJacobian, ModelError, SparseJacobian};
use crate::solver::jacobian::{Jacobian, SparseJac};

/// What the iteration needs from a problem.
pub(crate) trait Model {
    fn num_params(&self) -> usize;
    fn num_residuals(&self) -> usize;
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError>;
    /// Fills `jac` (created by [`Model::new_jacobian`]) at `x`.
    fn jacobian(&mut self, x: &[f64], jac: &mut Jacobian) -> Result<(), ModelError>;
    /// Storage for the Jacobian: sparse when the linear solver is sparse.
    fn new_jacobian(&mut self, sparse: bool) -> Result<Jacobian, LmError>;
}

/// A [`DenseJacobian`] problem.
pub(crate) struct DenseModel<'a, P: ?Sized> {
    problem: &'a mut P,
    /// Dense scratch when the solver wants the sparse (full-pattern) form.
    scratch: Option<Mat<f64>>,
}

impl<'a, P: DenseJacobian + ?Sized> DenseModel<'a, P> {
    pub(crate) fn new(problem: &'a mut P) -> Self {
        Self {
            problem,
            scratch: None,
        }
    }
}

impl<P: DenseJacobian + ?Sized> Model for DenseModel<'_, P> {
    fn num_params(&self) -> usize {
        self.problem.num_params()
    }
    fn num_residuals(&self) -> usize {
        self.problem.num_residuals()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.problem.residuals(x, r)
    }
    fn jacobian(&mut self, x: &[f64], jac: &mut Jacobian) -> Result<(), ModelError> {
        match jac {
            Jacobian::Dense(j) => self.problem.jacobian(x, j.as_mut()),
            Jacobian::Sparse(s) => {
                let (m, n) = (s.nrows, s.ncols);
                let scratch = self.scratch.get_or_insert_with(|| Mat::zeros(m, n));
                self.problem.jacobian(x, scratch.as_mut())?;
                for c in 0..n {
                    for (i, &v) in scratch.col_as_slice(c).iter().enumerate() {
                        s.values[i * n + c] = v;
                    }
                }
                Ok(())
            }
        }
    }
    fn new_jacobian(&mut self, sparse: bool) -> Result<Jacobian, LmError> {
        let (m, n) = (self.num_residuals(), self.num_params());
        Ok(if sparse {
            Jacobian::Sparse(SparseJac::full(m, n))
        } else {
            Jacobian::Dense(Mat::zeros(m, n))
        })
    }
}

/// A [`SparseJacobian`] problem.
pub(crate) struct SparseModel<'a, P: ?Sized> {
    problem: &'a mut P,
    pattern: Vec<(usize, usize)>,
    /// Values in the user's pattern order.
    user_values: Vec<f64>,
    /// For each pattern entry, its position in the sparse storage.
    user_to_csr: Vec<usize>,
}

impl<'a, P: SparseJacobian + ?Sized> SparseModel<'a, P> {
    pub(crate) fn new(problem: &'a mut P) -> Self {
        let pattern = problem.pattern();
        let len = pattern.len();
        Self {
            problem,
            pattern,
            user_values: vec![0.0; len],
            user_to_csr: Vec::new(),
        }
    }
}

impl<P: SparseJacobian + ?Sized> Model for SparseModel<'_, P> {
    fn num_params(&self) -> usize {
        self.problem.num_params()
    }
    fn num_residuals(&self) -> usize {
        self.problem.num_residuals()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.problem.residuals(x, r)
    }
    fn jacobian(&mut self, x: &[f64], jac: &mut Jacobian) -> Result<(), ModelError> {
        self.problem.jacobian_values(x, &mut self.user_values)?;
        match jac {
            Jacobian::Dense(j) => {
                j.fill(0.0);
                for (&(r, c), &v) in self.pattern.iter().zip(&self.user_values) {
                    j[(r, c)] += v;
                }
            }
            Jacobian::Sparse(s) => {
                s.values.fill(0.0);
                for (&p, &v) in self.user_to_csr.iter().zip(&self.user_values) {
                    s.values[p] += v;
                }
            }
        }
        Ok(())
    }
    fn new_jacobian(&mut self, sparse: bool) -> Result<Jacobian, LmError> {
        let (m, n) = (self.num_residuals(), self.num_params());
        let (s, map) = SparseJac::from_pattern(m, n, &self.pattern)?;
        Ok(if sparse {
            self.user_to_csr = map;
            Jacobian::Sparse(s)
        } else {
            Jacobian::Dense(Mat::zeros(m, n))
        })
    }
}
