//! Errors of the calibration crate.
use thiserror::Error;

/// What can go wrong in calibration.
#[derive(Debug, Error)]
pub enum CalibError {
    /// Forward kinematics failed at a pose of the campaign.
    #[error("pose {pose}: {source}")]
    Kinematics {
        /// Index of the pose in the campaign.
        pose: usize,
        /// The kinematics failure.
        #[source]
        source: cpm_kinematics::KinematicsError,
    },
    /// Link forces could not be computed at a pose.
    #[error("pose {pose}: {source}")]
    Clearance {
        /// Index of the pose in the campaign.
        pose: usize,
        /// The statics failure.
        #[source]
        source: cpm_clearance::ClearanceError,
    },
    /// An SVD could not be computed (non-finite entries, or faer did not converge).
    #[error(transparent)]
    Svd(#[from] cpm_kinematics::linalg::SvdError),
    /// Geometry error (bad table, unknown sensor, wrong error count).
    #[error(transparent)]
    Geometry(#[from] cpm_geometry::GeometryError),
    /// The least-squares solver refused the problem.
    #[error("least-squares solver: {0}")]
    Solver(#[from] cpm_lm::LmError),
    /// An invalid input or option.
    #[error("invalid `{field}`: {why}")]
    Invalid {
        /// Field or input name.
        field: String,
        /// What is wrong.
        why: String,
    },
    /// The data determine nothing (rank zero) or there are no readings.
    #[error("no information: {0}")]
    NoInformation(String),
    /// The caller cancelled the fit ([`IdentifyOptions::cancel`](crate::IdentifyOptions)).
    #[error("cancelled")]
    Cancelled,
}

impl CalibError {
    pub(crate) fn invalid(field: impl Into<String>, why: impl Into<String>) -> Self {
        CalibError::Invalid {
            field: field.into(),
            why: why.into(),
        }
    }
}
