//! The error type of the crate: what can go wrong before or during a solve.
//!
//! Setup problems (bad options, mismatched lengths, a malformed sparsity pattern) are
//! returned as `Err` before the first evaluation. An error returned by the user's model
//! stops the solve and is passed back as [`LmError::Model`]. Everything else about how a
//! solve ended (convergence, iteration limits, numerical trouble, a user stop) is a
//! [`TerminationReason`](crate::TerminationReason) inside an `Ok` [`Report`](crate::Report).

use std::fmt;

/// The error a user's model may return from any evaluation. It stops the solve and comes
/// back inside [`LmError::Model`].
pub type ModelError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Which user callback failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvalStage {
    /// [`Problem::residuals`](crate::Problem::residuals).
    Residuals,
    /// [`DenseJacobian::jacobian`](crate::DenseJacobian::jacobian) or
    /// [`SparseJacobian::jacobian_values`](crate::SparseJacobian::jacobian_values).
    Jacobian,
}

impl fmt::Display for EvalStage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EvalStage::Residuals => f.write_str("residuals"),
            EvalStage::Jacobian => f.write_str("Jacobian"),
        }
    }
}

/// Errors of `cpm-lm`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LmError {
    /// An option is out of range or inconsistent with another; the message names the
    /// option, the offending value and the accepted range.
    #[error("invalid options: {0}")]
    InvalidOptions(String),

    /// A slice or matrix does not have the size the problem declares.
    #[error("dimension mismatch: {what} has length {found}, expected {expected}")]
    DimensionMismatch {
        /// What was measured (e.g. `"x"`, `"options.lower"`).
        what: &'static str,
        /// The size implied by the problem.
        expected: usize,
        /// The size that was passed.
        found: usize,
    },

    /// The problem declares no parameters or no residuals.
    #[error(
        "empty problem: {num_params} parameters and {num_residuals} residuals (both must be >= 1)"
    )]
    EmptyProblem {
        /// `Problem::num_params()`.
        num_params: usize,
        /// `Problem::num_residuals()`.
        num_residuals: usize,
    },

    /// An entry of [`SparseJacobian::pattern`](crate::SparseJacobian::pattern) lies outside
    /// the `num_residuals x num_params` Jacobian.
    #[error(
        "sparsity pattern entry #{index} = ({row}, {col}) lies outside the {nrows} x {ncols} Jacobian"
    )]
    PatternOutOfBounds {
        /// Position of the entry in the pattern.
        index: usize,
        /// Its row.
        row: usize,
        /// Its column.
        col: usize,
        /// Number of residuals.
        nrows: usize,
        /// Number of parameters.
        ncols: usize,
    },

    /// The Schur-complement solver needs every residual to depend on at most one local
    /// block; this residual depends on two.
    #[error(
        "Schur solver: residual {row} depends on local blocks {first_block} and {second_block}; \
         each residual may touch at most one local block (plus any global parameters)"
    )]
    SchurStructure {
        /// The residual (row of the Jacobian).
        row: usize,
        /// The first local block it touches.
        first_block: usize,
        /// Another local block it touches.
        second_block: usize,
    },

    /// The starting point contains NaN or infinity.
    #[error("starting point x[{index}] = {value} is not finite")]
    NonFiniteStart {
        /// Index of the first non-finite parameter.
        index: usize,
        /// Its value.
        value: f64,
    },

    /// The user's model returned an error; the solve stopped there.
    #[error("model error at iteration {iteration} while evaluating the {stage}: {source}")]
    Model {
        /// The iteration during which the error happened (0 = the initial evaluation).
        iteration: usize,
        /// Which callback failed.
        stage: EvalStage,
        /// The model's own error.
        #[source]
        source: ModelError,
    },

    /// A numerical routine failed outside the iteration proper (for example the
    /// Jacobian checker met a non-finite value, or a factorisation could not be set up).
    #[error("numerical failure: {0}")]
    Numerical(String),
}
