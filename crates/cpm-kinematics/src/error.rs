//! Errors of the kinematics crate.
use thiserror::Error;

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
    /// A non-finite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: String,
    },
}
