//! Errors of the geometry crate.
use thiserror::Error;

/// What can go wrong when building or loading geometry.
#[derive(Debug, Error)]
pub enum GeometryError {
    /// A vector of installation errors had the wrong length.
    #[error("installation error vector has {got} components, expected {expected} (6 per link)")]
    WrongErrorCount {
        /// Components supplied.
        got: usize,
        /// Components expected.
        expected: usize,
    },
    /// The installation errors are for a different number of links than the joint table.
    #[error("installation errors cover {errors} links but the joint table has {links}")]
    LinkCountMismatch {
        /// Links in the error set.
        errors: usize,
        /// Links in the table.
        links: usize,
    },
    /// A value was not finite or out of its allowed range.
    #[error("invalid value for `{field}`: {value} ({why})")]
    InvalidValue {
        /// The offending field.
        field: String,
        /// Its value.
        value: f64,
        /// Why it is invalid.
        why: String,
    },
    /// A rotation matrix was not orthonormal with determinant +1.
    #[error(
        "not a rotation matrix: orthonormality error {orthonormality_error:.3e}, det {det:.6}"
    )]
    NotARotation {
        /// max |R^T R - I|.
        orthonormality_error: f64,
        /// det R.
        det: f64,
    },
    /// A sensor name was not found.
    #[error("unknown sensor `{name}` (known: {known})")]
    UnknownSensor {
        /// The requested name.
        name: String,
        /// Comma-separated names that exist.
        known: String,
    },
    /// A robot description file could not be read or parsed.
    #[error("{path}: {message}")]
    Description {
        /// File path (or `<string>`).
        path: String,
        /// What is wrong, with line and key where known.
        message: String,
    },
}
