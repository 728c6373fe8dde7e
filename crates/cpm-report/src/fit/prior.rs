//! What the prior of a fit did: the tolerance of each group, how much of each parameter the
//! data determined (posterior against prior), and the directions held near nominal, in words.
use cpm_calib::fit::prior::{group_name, group_unit, PriorSummary};
use cpm_calib::{Calibration, MeasurementModel};
use serde::Serialize;

use crate::format::sig;

/// A group of parameters and its a-priori tolerance as the fit applied it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GroupReport {
    /// The group (`installation_errors`, an effect's name, an instrument's name).
    pub group: String,
    /// The unit of its tolerance and parameters.
    pub unit: String,
    /// `prior` (a tolerance), `free` (no prior: a set-up's nuisance or no physical scale) or
    /// `held` (not fitted: kept at its start).
    pub treatment: String,
    /// The tolerance (a-priori standard deviation), `null` when free or held.
    pub tolerance: Option<f64>,
    /// Its parameters the data determined (share of at least 0.5).
    pub determined: usize,
    /// Its parameters.
    pub parameters: usize,
}

/// One parameter: prior, posterior and the data's share.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ParameterPrior {
    /// Its name, with its unit.
    pub name: String,
    /// Prior standard deviation (`null` free, 0 held).
    pub prior_std: Option<f64>,
    /// Posterior standard deviation (`null` where undefined or held).
    pub posterior_std: Option<f64>,
    /// `1 - posterior variance / prior variance` (`null` without a prior).
    pub data_share: Option<f64>,
}

/// A direction held near nominal because the data see it less well than its tolerance.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct HeldDirectionReport {
    /// The data's standard deviation of the direction, in tolerances.
    pub data_std_in_tolerances: f64,
    /// What moves, in words: the largest loadings (tolerance-scaled) by parameter name.
    pub description: String,
}

/// `calibration.json` `prior`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PriorReport {
    /// The estimator, in words.
    pub method: String,
    /// The groups and their tolerances.
    pub groups: Vec<GroupReport>,
    /// Every parameter, in model order.
    pub parameters: Vec<ParameterPrior>,
    /// Directions held near nominal, weakest first.
    pub held_directions: Vec<HeldDirectionReport>,
    /// How many tolerances a fitted parameter may reach (`null`: no limit): one the data
    /// pulled further is held there.
    pub limit_in_tolerances: Option<f64>,
    /// The parameters the data pulled beyond the limit, held at it (not measured).
    pub held_at_limit: Vec<String>,
    /// The parameters that end beyond their tolerance without being held at the limit
    /// (directions the limit does not act on, such as a frame's gauge freedoms; the
    /// "Beyond tolerance" warning).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub beyond_tolerance: Vec<String>,
    /// Directions the data determine better than their tolerance.
    pub determined_dimensions: usize,
    /// Effective number of parameters fitted (trace of the hat matrix).
    pub effective_params: f64,
}

/// Words for a direction: its largest loadings by parameter name.
pub fn describe(names: &[String], loadings: &[(usize, f64)]) -> String {
    loadings
        .iter()
        .filter(|(_, c)| c.abs() >= 0.2)
        .map(|(k, c)| format!("{} {}", sig(*c, 2), names[*k]))
        .collect::<Vec<_>>()
        .join(" + ")
}

impl PriorReport {
    /// The report of a fit's prior (`None` for a fit without one).
    pub fn new(model: &MeasurementModel, cal: &Calibration) -> Option<Self> {
        let p: &PriorSummary = cal.prior.as_ref()?;
        let names = model.parameter_names();
        let groups = model
            .blocks()
            .iter()
            .map(|b| {
                let t = cal
                    .prior_std
                    .get(b.offset)
                    .copied()
                    .unwrap_or(f64::INFINITY);
                let treatment = if t == 0.0 {
                    "held"
                } else if t.is_finite() {
                    "prior"
                } else {
                    "free"
                };
                GroupReport {
                    group: group_name(model, b),
                    unit: group_unit(model, b),
                    treatment: treatment.into(),
                    tolerance: (t.is_finite() && t > 0.0).then_some(t),
                    determined: (b.offset..b.offset + b.len)
                        .filter(|&k| cal.estimate_um[k].is_some())
                        .count(),
                    parameters: b.len,
                }
            })
            .collect();
        Some(Self {
            method: "maximum a posteriori: least squares plus each parameter's departure from nominal over its tolerance (a Gaussian prior); noise estimated with the fit when not declared".into(),
            groups,
            parameters: names
                .iter()
                .enumerate()
                .map(|(k, n)| ParameterPrior {
                    name: n.clone(),
                    prior_std: p.prior_std[k],
                    posterior_std: p.posterior_std[k],
                    data_share: p.data_share[k],
                })
                .collect(),
            held_directions: p
                .held_directions
                .iter()
                .map(|h| HeldDirectionReport {
                    data_std_in_tolerances: h.data_std_in_tolerances,
                    description: describe(&names, &h.loadings),
                })
                .collect(),
            limit_in_tolerances: cal.tolerance_limit.is_finite().then_some(cal.tolerance_limit),
            held_at_limit: cal
                .held_at_limit
                .iter()
                .map(|&k| names.get(k).cloned().unwrap_or_else(|| format!("#{k}")))
                .collect(),
            beyond_tolerance: beyond(cal)
                .iter()
                .map(|&(k, _)| names.get(k).cloned().unwrap_or_else(|| format!("#{k}")))
                .collect(),
            determined_dimensions: p.determined_dimensions,
            effective_params: p.effective_params,
        })
    }

    /// The report.md section.
    pub fn markdown(&self, s: &mut String) {
        s.push_str("## What the data determine at their noise\n\n");
        s.push_str(&format!(
            "Estimator: {}. {} directions seen by the data better than their tolerance; {} held near nominal by it; {} effective parameters.\n\n",
            self.method,
            self.determined_dimensions,
            self.held_directions.len(),
            sig(self.effective_params, 3)
        ));
        s.push_str("| group | treatment | tolerance | determined |\n|---|---|---|---|\n");
        for g in &self.groups {
            s.push_str(&format!(
                "| {} | {} | {} | {} of {} |\n",
                g.group,
                g.treatment,
                g.tolerance
                    .map_or("-".to_string(), |t| format!("{} {}", sig(t, 3), g.unit)),
                g.determined,
                g.parameters
            ));
        }
        s.push('\n');
        if let Some(limit) = self.limit_in_tolerances {
            s.push_str(&format!(
                "A fitted parameter may reach {} tolerance{} (`[calibration] tolerance_limit`); {}.\n\n",
                sig(limit, 3),
                if limit == 1.0 { "" } else { "s" },
                if self.held_at_limit.is_empty() && self.beyond_tolerance.is_empty() {
                    "none was pulled beyond it".to_string()
                } else if self.held_at_limit.is_empty() {
                    format!(
                        "none was held at it, but {} end{} beyond the tolerance (the limit holds only parameters the data supply less than half of; see \"Beyond tolerance\")",
                        self.beyond_tolerance.len(),
                        if self.beyond_tolerance.len() == 1 { "s" } else { "" }
                    )
                } else {
                    format!(
                        "the data pulled {} beyond it, held there and not measured: {}",
                        self.held_at_limit.len(),
                        self.held_at_limit.join(", ")
                    )
                }
            ));
        }
        // Per parameter, how much of it the data determined (1 - posterior / prior variance),
        // and what stayed at its nominal.
        let stayed: Vec<&ParameterPrior> = self
            .parameters
            .iter()
            .filter(|p| p.data_share.is_some_and(|x| x < 0.1))
            .collect();
        let shares: Vec<String> = self
            .parameters
            .iter()
            .filter_map(|p| {
                p.data_share
                    .map(|x| format!("{} {}", p.name, crate::format::fixed(x, 2)))
            })
            .collect();
        if !shares.is_empty() {
            s.push_str(&format!(
                "The data's share of each parameter's determination (1 = the data alone, 0 = its tolerance alone): {}.\n\n",
                shares.join("; ")
            ));
        }
        if !stayed.is_empty() {
            s.push_str(&format!(
                "Stayed at nominal (the data supply under a tenth of their determination): {}.\n\n",
                stayed
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if !self.held_directions.is_empty() {
            s.push_str("Held near nominal (the data see these less well than their tolerance; they are not measured):\n\n");
            for h in self.held_directions.iter().take(12) {
                s.push_str(&format!(
                    "- {} (data std {})\n",
                    h.description,
                    in_tolerances(h.data_std_in_tolerances)
                ));
            }
            if self.held_directions.len() > 12 {
                s.push_str(&format!(
                    "- and {} more (calibration.json `prior.held_directions`)\n",
                    self.held_directions.len() - 12
                ));
            }
            s.push('\n');
        }
    }
}

/// A data standard deviation in tolerances, in words when the data alone do not see it.
fn in_tolerances(x: f64) -> String {
    if x.is_finite() {
        format!("{} tolerances", sig(x, 2))
    } else {
        "infinite: the data alone do not see it".to_string()
    }
}

/// The warning when the prior held directions near nominal: the data do not measure them.
pub fn warning(model: &MeasurementModel, cal: &Calibration) -> Option<String> {
    let p = cal.prior.as_ref()?;
    let weakest = p.held_directions.first()?;
    let names = model.parameter_names();
    Some(format!(
        "**Held near nominal**: {} direction{} of the parameters the data see less well than their tolerance (the weakest: {}; its standard deviation from the data alone: {}); the fit keeps them near nominal instead of measuring them. They are listed under \"What the data determine at their noise\"; a campaign with more varied poses, another instrument or a declared effect the model lacks would determine them.",
        p.held_directions.len(),
        if p.held_directions.len() == 1 { "" } else { "s" },
        describe(&names, &weakest.loadings),
        in_tolerances(weakest.data_std_in_tolerances)
    ))
}

/// The warning when the fit held parameters at their limit ([`Calibration::held_at_limit`]):
/// the data pulled them beyond what their tolerance allows. `None` when it held none.
pub fn limit_warning(model: &MeasurementModel, cal: &Calibration) -> Option<String> {
    let first = *cal.held_at_limit.first()?;
    let names = model.parameter_names();
    let n = cal.held_at_limit.len();
    Some(format!(
        "**Held at tolerance**: the data pulled {n} parameter{} beyond {} tolerance{} (the first: {}); {} held there, not measured, and the fit repeated. An effect the model lacks (`cpm refine`), a set-up that moved, or a tolerance set too tight can do that.",
        if n == 1 { "" } else { "s" },
        sig(cal.tolerance_limit, 3),
        if cal.tolerance_limit == 1.0 { "" } else { "s" },
        names.get(first).map_or("?", |s| s.as_str()),
        if n == 1 { "it is" } else { "they are" },
    ))
}

/// The parameters (index, in tolerances) that end beyond their a-priori tolerance without
/// being held at the limit, furthest first; none without a prior.
fn beyond(cal: &Calibration) -> Vec<(usize, f64)> {
    if cal.prior.is_none() {
        return Vec::new();
    }
    let mut beyond: Vec<(usize, f64)> = cal
        .prior_std
        .iter()
        .zip(&cal.minimum_norm_um)
        .enumerate()
        .filter_map(|(k, (t, v))| match t {
            t if *t > 0.0
                && t.is_finite()
                && v.abs() > *t * (1.0 + 1e-9)
                && !cal.held_at_limit.contains(&k) =>
            {
                Some((k, v.abs() / t))
            }
            _ => None,
        })
        .collect();
    beyond.sort_by(|a, b| b.1.total_cmp(&a.1));
    beyond
}

/// The warning when the fit ends with parameters beyond their a-priori tolerance (no limit, or
/// one a frame's gauge moved past it): the prior is a Gaussian of that standard deviation, so
/// the data can pull a parameter past it, and a user should know. `None` when every parameter
/// with a tolerance is within it.
pub fn beyond_warning(model: &MeasurementModel, cal: &Calibration) -> Option<String> {
    let names = model.parameter_names();
    let beyond = beyond(cal);
    let (worst, ratio) = *beyond.first()?;
    Some(format!(
        "**Beyond tolerance**: {} parameter{} end{} beyond the a-priori tolerance (the largest: {} at {} tolerances); the tolerance is the prior's standard deviation, and the data pulled {} past it. An effect the model lacks (`cpm refine`), a set-up that moved, or a tolerance set too tight can do that; the values are written as fitted.",
        beyond.len(),
        if beyond.len() == 1 { "" } else { "s" },
        if beyond.len() == 1 { "s" } else { "" },
        names.get(worst).map_or("?", |n| n.as_str()),
        sig(ratio, 3),
        if beyond.len() == 1 { "it" } else { "them" },
    ))
}
