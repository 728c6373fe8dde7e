//! Errors of the kinematics crate.
use nalgebra::Matrix6;
use thiserror::Error;

use crate::linalg::SvdError;

/// What can go wrong in kinematics.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum KinematicsError {
    /// Newton-Raphson did not reach the tolerance.
    #[error("forward kinematics did not converge in {iterations} iterations: residual {residual_mm:.3e} mm, J1 condition number {condition:.3e}")]
    NonConvergence {
        /// Iterations run.
        iterations: usize,
        /// Largest link length residual at the end, mm.
        residual_mm: f64,
        /// Condition number of J1 at the last iterate.
        condition: f64,
    },
    /// J1 is singular (or numerically so) at an iterate.
    #[error("singular configuration in forward kinematics at iteration {iteration}: J1 condition number {condition:.3e}")]
    Singular {
        /// Iteration at which it happened.
        iteration: usize,
        /// Condition number of J1 there.
        condition: f64,
    },
    /// Fewer than six links, or inputs of mismatched sizes.
    #[error("dimension mismatch: {what}")]
    Dimension {
        /// Description.
        what: String,
    },
    /// The SVD behind a condition number or a solve could not be computed (a named
    /// failure, never reported as an infinite condition number).
    #[error(transparent)]
    Svd(#[from] SvdError),
    /// A non-finite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: String,
    },
}

impl KinematicsError {
    /// [`KinematicsError::Singular`] at `iteration` with the condition number of the 6x6
    /// `j1` (infinite when `j1` has a non-finite entry: a link of zero length), or
    /// [`KinematicsError::Svd`] when the SVD fails on a finite `j1`.
    pub fn singular(iteration: usize, j1: &Matrix6<f64>) -> Self {
        match crate::fk::condition_number(j1) {
            Ok(condition) => Self::Singular {
                iteration,
                condition,
            },
            Err(SvdError::NonFinite { .. }) => Self::Singular {
                iteration,
                condition: f64::INFINITY,
            },
            Err(e) => Self::Svd(e),
        }
    }

    /// Applies `f` to the condition number a [`Singular`](Self::Singular) or
    /// [`NonConvergence`](Self::NonConvergence) carries.
    pub(crate) fn map_condition(self, f: impl Fn(f64) -> f64) -> Self {
        match self {
            Self::Singular {
                iteration,
                condition,
            } => Self::Singular {
                iteration,
                condition: f(condition),
            },
            Self::NonConvergence {
                iterations,
                residual_mm,
                condition,
            } => Self::NonConvergence {
                iterations,
                residual_mm,
                condition: f(condition),
            },
            other => other,
        }
    }
}
