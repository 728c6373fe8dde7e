//! Errors of the clearance crate.
use thiserror::Error;

/// What can go wrong in statics or clearance.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ClearanceError {
    /// J1 is singular: the link forces are not determined by the load.
    #[error(
        "link forces undetermined: J1 is singular at this pose (condition number {condition:.3e})"
    )]
    Singular {
        /// Condition number of J1.
        condition: f64,
    },
    /// An invalid model parameter.
    #[error("invalid clearance parameter `{field}` = {value}: {why}")]
    Invalid {
        /// Field name.
        field: &'static str,
        /// Value.
        value: f64,
        /// Reason.
        why: &'static str,
    },
}
