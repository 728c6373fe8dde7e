//! Which formulation `cpm calibrate` fits with: the nested one (forward kinematics inside
//! every residual, a dense Jacobian in the installation errors) for ordinary campaigns, the
//! implicit one (every pose an unknown, a sparse Schur-complement solve) for large ones.
//!
//! The nested formulation's dense Jacobian and its SVD grow as `readings x parameters`; the
//! implicit one's work and memory grow with the poses' blocks. Both give the same estimates
//! (to a small fraction of a standard deviation) on a campaign either can fit; the implicit
//! one takes length readings only, plain least squares, and no effect with a known value.
use crate::calib::implicit::{identify_implicit_calibration, supported};
use crate::calib::{
    identify, CalibError, Calibration, Campaign, IdentifyOptions, MeasurementModel,
};

/// Campaigns with at least this many readings are fitted with the implicit formulation
/// (when it supports them); smaller ones with the nested one.
pub const IMPLICIT_FROM_READINGS: usize = 100_000;

/// `--formulation` of `cpm calibrate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FormulationArg {
    /// Implicit from [`IMPLICIT_FROM_READINGS`] readings when it applies, nested otherwise.
    #[default]
    Auto,
    /// Always nested.
    Nested,
    /// Always implicit (an error when the campaign or the options need the nested one).
    Implicit,
}

pub use crate::report::fit::Formulation;

/// The formulation for this fit: implicit for campaigns of at least
/// [`IMPLICIT_FROM_READINGS`] readings that it supports (length readings only, plain least
/// squares, no start, no known effects), nested otherwise.
pub fn choose(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
) -> Formulation {
    let large = campaign.readings.len() >= IMPLICIT_FROM_READINGS;
    if large
        && options.lm.loss.is_squared()
        && options.start_um.is_none()
        && supported(model, campaign).is_ok()
    {
        Formulation::Implicit
    } else {
        Formulation::Nested
    }
}

/// The formulation `--formulation` asks for.
pub fn resolve(
    arg: FormulationArg,
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
) -> Formulation {
    match arg {
        FormulationArg::Auto => choose(model, campaign, options),
        FormulationArg::Nested => Formulation::Nested,
        FormulationArg::Implicit => Formulation::Implicit,
    }
}

/// Fits with the given formulation.
pub fn identify_with(
    formulation: Formulation,
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
) -> Result<Calibration, CalibError> {
    match formulation {
        Formulation::Nested => identify(model, campaign, options),
        Formulation::Implicit => identify_implicit_calibration(model, campaign, options),
    }
}
