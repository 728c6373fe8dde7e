//! What the data identify, as `calibration.json`'s `identifiability` object and
//! `cpm identifiability --json`: rank, blind directions in words, Cramér-Rao bounds, and per
//! parameter whether the data determine it.
use serde::Serialize;

use crate::format::finite;

/// A blind direction of the fit.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct BlindDirection {
    /// What it is, in words.
    pub description: String,
    /// Its dimension.
    pub dimensions: usize,
}

/// What the data determine about one parameter.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ParameterIdentifiability {
    /// The parameter.
    pub name: String,
    /// Determined on its own.
    pub determined: bool,
    /// The fraction of it in the null space.
    pub null_fraction: f64,
    /// Its Cramér-Rao bound, um.
    pub crlb_std: Option<f64>,
}

/// `calibration.json`'s `identifiability` object.
#[derive(Debug, Clone, Serialize, PartialEq, Default)]
pub struct IdentifiabilityReport {
    /// Parameters fitted.
    pub parameters: usize,
    /// Observations.
    pub observations: usize,
    /// Numerical rank.
    pub rank: usize,
    /// Relative rank tolerance.
    pub rank_rtol: f64,
    /// Absolute singular-value threshold.
    pub threshold: f64,
    /// Parameters determined on their own.
    pub determined: usize,
    /// Singular values of the scaled Jacobian.
    pub singular_values: Vec<f64>,
    /// Named blind directions.
    pub blind_directions: Vec<BlindDirection>,
    /// Null-space dimensions no name explains.
    pub unexplained_null_dimensions: usize,
    /// The noise used, um.
    pub sigma_um: f64,
    /// RMS of the Cramér-Rao bounds of the determined parameters, um.
    pub crlb_rms_um: Option<f64>,
    /// Largest of them, um.
    pub crlb_max_um: Option<f64>,
    /// Per parameter.
    pub per_parameter: Vec<ParameterIdentifiability>,
}

impl IdentifiabilityReport {
    /// The report of an analysis whose parameters are named `names`.
    pub fn new(id: &cpm_calib::Identifiability, names: &[String]) -> Self {
        Self {
            parameters: id.num_params,
            observations: id.num_readings,
            rank: id.rank,
            rank_rtol: id.rank_rtol,
            threshold: id.threshold,
            determined: id.num_determined(),
            singular_values: id.singular_values.clone(),
            blind_directions: id
                .blind_directions
                .iter()
                .map(|b| BlindDirection {
                    description: b.description.clone(),
                    dimensions: b.dimensions,
                })
                .collect(),
            unexplained_null_dimensions: id.unexplained_null_dimensions,
            sigma_um: id.sigma_um,
            crlb_rms_um: finite(id.crlb_rms_um()),
            crlb_max_um: finite(id.crlb_max_um()),
            per_parameter: names
                .iter()
                .enumerate()
                .map(|(k, n)| ParameterIdentifiability {
                    name: n.clone(),
                    determined: id.determined[k],
                    null_fraction: id.null_fraction[k],
                    crlb_std: finite(id.crlb_std_um[k]),
                })
                .collect(),
        }
    }
}

/// `cpm identifiability --json`: the analysis with where it came from.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct IdentifiabilityDoc {
    /// The analysis.
    #[serde(flatten)]
    pub analysis: IdentifiabilityReport,
    /// The measurement files, or `plan`.
    pub source: String,
    /// The measurements are simulated (false for a plan).
    pub simulated: bool,
    /// The effects modelled.
    pub effects: Vec<String>,
    /// At the stated noise, against each group's a-priori tolerance: the directions the data
    /// determine better than their tolerance and those a fit holds near nominal.
    pub against_tolerances: Option<AgainstTolerances>,
}

/// What the data determine at a noise, against the tolerances (`cpm identifiability`).
#[derive(Debug, Clone, serde::Serialize, PartialEq)]
pub struct AgainstTolerances {
    /// The noise, um (of the reference).
    pub sigma_um: f64,
    /// Directions determined better than their tolerance.
    pub determined_dimensions: usize,
    /// Directions held near nominal, weakest first, in words.
    pub held_directions: Vec<crate::fit::prior::HeldDirectionReport>,
}

impl AgainstTolerances {
    /// From the data's weighted Jacobian `j` (um per model unit), the prior standard
    /// deviations and the noise.
    pub fn new(j: &nalgebra::DMatrix<f64>, prior: &[f64], sigma_um: f64, names: &[String]) -> Self {
        let p = cpm_calib::fit::prior::summarize(j, prior, sigma_um);
        Self {
            sigma_um,
            determined_dimensions: p.determined_dimensions,
            held_directions: p
                .held_directions
                .iter()
                .map(|h| crate::fit::prior::HeldDirectionReport {
                    data_std_in_tolerances: h.data_std_in_tolerances,
                    description: crate::fit::prior::describe(names, &h.loadings),
                })
                .collect(),
        }
    }
}
