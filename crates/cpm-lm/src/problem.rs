//! The problem traits: residuals into a buffer, Jacobian dense or as the values of a fixed
//! sparsity pattern; or, for a problem too large to store its Jacobian, the damped normal
//! equations formed by the problem itself ([`NormalEquations`]).

use crate::options::ScaleUpdate;

pub use crate::error::ModelError;

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

/// A problem that forms and solves its own damped normal equations
/// `(J^T J + mu D^2) h = -J^T r` instead of handing a Jacobian to the solver: for instance a
/// Schur-reduced system accumulated block by block from Jacobian rows evaluated on the fly,
/// with no Jacobian stored (cpm-calib's implicit calibration at 10^5 poses).
///
/// The engine ([`minimize_normal`](crate::minimize_normal)) runs the same iteration, stopping
/// tests and report as for a stored Jacobian. It calls [`assemble`](Self::assemble) at a new
/// point (with a [`Linearization`] to fill) and whenever the damping changed, then
/// [`solve`](Self::solve) for the step with the system last assembled, and
/// [`cost`](Self::cost) only at points where `solve` did not report the cost already.
/// Plain least squares, no bounds, no geodesic acceleration, and a damping schedule with one
/// solve per trial (see [`Options::validate_normal`](crate::Options::validate_normal)).
pub trait NormalEquations {
    /// Number of parameters `n`.
    fn num_params(&self) -> usize;

    /// Number of residuals `m` (for the rounding level of the cost test and the report).
    fn num_residuals(&self) -> usize;

    /// The cost `0.5 * sum_i r_i(x)^2` at `x`.
    fn cost(&mut self, x: &[f64]) -> Result<f64, ModelError>;

    /// Forms `J^T J + mu D^2` (`D = diag(d)`) at `x`, to be solved by the next
    /// [`solve`](Self::solve), and returns the cost at `x`.
    ///
    /// With `lin` (a new point), first writes the gradient `J^T r` and the squared column
    /// norms of `J` into it and updates every scale `d_j` with
    /// [`ScaleUpdate::apply`] before using it (a problem that streams its columns in blocks
    /// may update each block's scales as it goes).
    fn assemble(
        &mut self,
        x: &[f64],
        mu: f64,
        d: &mut [f64],
        lin: Option<Linearization<'_>>,
    ) -> Result<f64, ModelError>;

    /// Solves the system last assembled for `h = -(J^T J + mu D^2)^-1 J^T r` (`d` as it was
    /// assembled with). `Ok(None)` when the system cannot be solved (not numerically
    /// positive definite, or a direction the data do not determine): the damping grows.
    fn solve(
        &mut self,
        x: &[f64],
        d: &[f64],
        h: &mut [f64],
    ) -> Result<Option<DampedStep>, ModelError>;
}

/// What [`NormalEquations::assemble`] writes at a new point.
#[derive(Debug)]
pub struct Linearization<'a> {
    /// The gradient `J^T r` (length `n`).
    pub gradient: &'a mut [f64],
    /// The squared Euclidean norm of each column of `J` (length `n`).
    pub col_norms2: &'a mut [f64],
    /// How the scales follow the column norms.
    pub scale: ScaleUpdate,
}

/// What [`NormalEquations::solve`] found besides the step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DampedStep {
    /// `||J h||^2` for the step `h` (the linear model's predicted reduction is
    /// `-g.h - ||J h||^2 / 2`).
    pub jh_norm2: f64,
    /// The cost at `x + h`, when the problem evaluated it on the way (a streamed problem
    /// evaluates the residuals at the trial point in the same pass); `None` makes the
    /// engine call [`NormalEquations::cost`].
    pub trial_cost: Option<f64>,
}

impl<P: NormalEquations + ?Sized> NormalEquations for &mut P {
    fn num_params(&self) -> usize {
        (**self).num_params()
    }
    fn num_residuals(&self) -> usize {
        (**self).num_residuals()
    }
    fn cost(&mut self, x: &[f64]) -> Result<f64, ModelError> {
        (**self).cost(x)
    }
    fn assemble(
        &mut self,
        x: &[f64],
        mu: f64,
        d: &mut [f64],
        lin: Option<Linearization<'_>>,
    ) -> Result<f64, ModelError> {
        (**self).assemble(x, mu, d, lin)
    }
    fn solve(
        &mut self,
        x: &[f64],
        d: &[f64],
        h: &mut [f64],
    ) -> Result<Option<DampedStep>, ModelError> {
        (**self).solve(x, d, h)
    }
}
