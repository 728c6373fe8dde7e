//! The choice of formulation of a fit (`--formulation` of `cpm calibrate`), resolved to one of
//! cpm-calib's formulations ([`cpm_calib::fit::formulation`], where the choice and the fit
//! live).
pub use crate::calib::fit::formulation::{
    choose, identify_with, Formulation, IMPLICIT_FROM_READINGS,
};
use crate::calib::{Campaign, IdentifyOptions, MeasurementModel};

/// Which formulation a fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum FormulationArg {
    /// Implicit from 100000 readings (`IMPLICIT_FROM_READINGS`) when it applies, nested otherwise.
    #[default]
    Auto,
    /// Always nested.
    Nested,
    /// Always implicit (an error when the campaign or the options need the nested one).
    Implicit,
}

/// The formulation `arg` asks for.
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
