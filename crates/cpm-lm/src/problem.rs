//! The problem traits: residuals into a buffer, Jacobian dense or as the values of a fixed
//! sparsity pattern.

/// The error a user's model may return from any evaluation. It stops the solve and comes
/// back inside [`LmError::Model`](crate::LmError::Model).
pub type ModelError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A nonlinear least-squares problem: minimise `0.5 * sum_i r_i(x)^2` over `x`.
pub trait Problem {
    /// Number of parameters `n` (length of `x`).
    fn num_params(&self) -> usize;

    /// Number of residuals `m` (length of `r`).
    fn num_residuals(&self) -> usize;

    /// Writes the residuals at `x` into `r` (length `num_residuals()`, to be fully
    /// overwritten). An `Err` stops the solve with that error.
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError>;
}

/// A problem with a dense Jacobian.
pub trait DenseJacobian: Problem {
    /// Writes `d r_i / d x_j` at `x` into `jac`.
    ///
    /// `jac` is `num_residuals x num_params`, a column-major faer view, and must be fully
    /// overwritten (it is not zeroed beforehand).
    fn jacobian(&mut self, x: &[f64], jac: faer::MatMut<'_, f64>) -> Result<(), ModelError>;
}

/// A problem with a sparse Jacobian of fixed structure.
pub trait SparseJacobian: Problem {
    /// The structural non-zeros `(row, col)` of the Jacobian, declared once (the solver calls
    /// this a single time per solve). Order is free; duplicated entries are summed.
    fn pattern(&self) -> Vec<(usize, usize)>;

    /// Writes the Jacobian values at `x` into `values`, in the order of
    /// [`pattern()`](SparseJacobian::pattern) (length = number of pattern entries). Entries
    /// not written count as zero.
    fn jacobian_values(&mut self, x: &[f64], values: &mut [f64]) -> Result<(), ModelError>;

    /// Calls `visit(row, col)` for every structural non-zero, in the order of
    /// [`pattern()`](SparseJacobian::pattern). The solvers call this once per solve instead
    /// of `pattern()`; the default visits the entries of `pattern()`.
    ///
    /// Override it for a large problem to avoid building the list at all: a pattern visited
    /// row by row in compressed-sparse-row order (rows ascending, columns strictly ascending
    /// within a row) is stored as it arrives, and the values are then written straight into
    /// the solver's storage, with no copy of the pattern and no map. Any other order works
    /// as well, at the cost of a temporary list and a map.
    fn visit_pattern(&self, visit: &mut dyn FnMut(usize, usize)) {
        for (row, col) in self.pattern() {
            visit(row, col);
        }
    }
}

impl<P: Problem + ?Sized> Problem for &mut P {
    fn num_params(&self) -> usize {
        (**self).num_params()
    }
    fn num_residuals(&self) -> usize {
        (**self).num_residuals()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        (**self).residuals(x, r)
    }
}

impl<P: DenseJacobian + ?Sized> DenseJacobian for &mut P {
    fn jacobian(&mut self, x: &[f64], jac: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
        (**self).jacobian(x, jac)
    }
}

impl<P: SparseJacobian + ?Sized> SparseJacobian for &mut P {
    fn pattern(&self) -> Vec<(usize, usize)> {
        (**self).pattern()
    }
    fn jacobian_values(&mut self, x: &[f64], values: &mut [f64]) -> Result<(), ModelError> {
        (**self).jacobian_values(x, values)
    }
    fn visit_pattern(&self, visit: &mut dyn FnMut(usize, usize)) {
        (**self).visit_pattern(visit)
    }
}
