//! Adapters from the user's problem traits to the solver's Jacobian storage: dense
//! problems and sparse problems can each feed a dense or a sparse linear solver.

use faer::Mat;

use crate::error::LmError;
use crate::problem::{DenseJacobian, ModelError, SparseJacobian};
use crate::solver::jacobian::{Jacobian, PatternBuilder, SparseJac, ValueMap};

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
            Jacobian::Sparse(SparseJac::full(m, n)?)
        } else {
            Jacobian::Dense(Mat::zeros(m, n))
        })
    }
}

/// A [`SparseJacobian`] problem.
///
/// The pattern is visited once, when the storage is built: only the CSR structure (and, for
/// a pattern not in CSR order, the map from pattern entries to storage positions) is kept.
pub(crate) struct SparseModel<'a, P: ?Sized> {
    problem: &'a mut P,
    map: ValueMap,
    /// Values in the user's pattern order; empty when the user writes into the storage
    /// directly ([`ValueMap::Identity`]).
    user_values: Vec<f64>,
    /// The sparse storage when the solver wants a dense Jacobian.
    staging: Option<SparseJac>,
}

impl<'a, P: SparseJacobian + ?Sized> SparseModel<'a, P> {
    pub(crate) fn new(problem: &'a mut P) -> Self {
        Self {
            problem,
            map: ValueMap::Identity,
            user_values: Vec::new(),
            staging: None,
        }
    }

    fn fill(&mut self, x: &[f64], s: &mut SparseJac) -> Result<(), ModelError> {
        if self.map == ValueMap::Identity {
            s.values.fill(0.0);
            self.problem.jacobian_values(x, &mut s.values)
        } else {
            self.user_values.fill(0.0);
            self.problem.jacobian_values(x, &mut self.user_values)?;
            self.map.scatter(&self.user_values, &mut s.values);
            Ok(())
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
        match jac {
            Jacobian::Dense(j) => {
                let mut s = self
                    .staging
                    .take()
                    .expect("staging storage of a dense solve");
                let res = self.fill(x, &mut s);
                s.scatter_dense(j);
                self.staging = Some(s);
                res
            }
            Jacobian::Sparse(s) => self.fill(x, s),
        }
    }
    fn new_jacobian(&mut self, sparse: bool) -> Result<Jacobian, LmError> {
        let (m, n) = (self.num_residuals(), self.num_params());
        let mut builder = PatternBuilder::new(m, n)?;
        let mut entries = 0usize;
        self.problem.visit_pattern(&mut |r, c| {
            builder.push(r, c);
            entries += 1;
        });
        let (s, map) = builder.finish()?;
        self.user_values = if map == ValueMap::Identity {
            Vec::new()
        } else {
            vec![0.0; entries]
        };
        self.map = map;
        Ok(if sparse {
            Jacobian::Sparse(s)
        } else {
            self.staging = Some(s);
            Jacobian::Dense(Mat::zeros(m, n))
        })
    }
}
