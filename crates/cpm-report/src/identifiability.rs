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
    /// The singular values the rank was decided on when the blocks' columns were scaled to
    /// the installation errors' median norm (the blocks' units differ): `threshold` is
    /// `rank_rtol` times the first; absent when the rank was decided on `singular_values`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub scaled_singular_values: Vec<f64>,
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
    /// The bounds per unit where the determined parameters have several units (link offsets
    /// in um beside scales in ppm): an RMS over mixed units means nothing; absent with one.
    #[serde(skip_serializing_if = "one_unit")]
    pub crlb_per_unit: Vec<cpm_calib::identifiability::CrlbOfUnit>,
    /// Per parameter.
    pub per_parameter: Vec<ParameterIdentifiability>,
}

impl IdentifiabilityReport {
    /// The Cramér-Rao bounds in words, each figure with its unit: `RMS 17.1 um, worst 28.6 um`
    /// (the form `fmt` gives a figure), or one such pair per unit where the determined
    /// parameters have several (`RMS 17.1 um, worst 28.6 um (36 in um); RMS 41.0 ppm, worst
    /// 55.2 ppm (6 in ppm)`); `n.d.` for none determined.
    pub fn crlb_words(&self, fmt: impl Fn(f64) -> String) -> String {
        if self.crlb_per_unit.len() > 1 {
            return self
                .crlb_per_unit
                .iter()
                .map(|g| {
                    format!(
                        "RMS {} {u}, worst {} {u} ({} in {u})",
                        fmt(g.rms),
                        fmt(g.worst),
                        g.determined,
                        u = g.unit
                    )
                })
                .collect::<Vec<_>>()
                .join("; ");
        }
        let unit = self
            .crlb_per_unit
            .first()
            .map_or("um".to_string(), |g| g.unit.clone());
        let f =
            |v: Option<f64>| v.map_or_else(|| "n.d.".to_string(), |v| format!("{} {unit}", fmt(v)));
        format!("RMS {}, worst {}", f(self.crlb_rms_um), f(self.crlb_max_um))
    }

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
            scaled_singular_values: id.scaled_singular_values.clone(),
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
            crlb_per_unit: {
                let units: Vec<String> = names
                    .iter()
                    .map(|n| cpm_calib::model::unit_of_parameter(n).to_string())
                    .collect();
                id.crlb_per_unit(&units)
            },
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

/// For `skip_serializing_if`: the bounds of one unit (or none) are `crlb_rms_um` already.
fn one_unit(v: &[cpm_calib::identifiability::CrlbOfUnit]) -> bool {
    v.len() <= 1
}
