//! The report of `cpm refine`: `refine.json`, the final model's `calibration.json` and
//! report.md (hence report.html), all from one [`RefineReport`].
use serde::Serialize;

use super::calibrate::CalibratedFile;
use super::fit::FitReport;
use super::format::{fixed, opt_with_sd, p_value, short, sig, yes_no};
use cpm_calib::{AgainstCalibrate, Refinement};

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// The residual of the starting model.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Initial {
    /// Residual RMS over every observation, um (as the final one).
    pub rms_um: f64,
    /// The residual passed the whiteness tests.
    pub residual_white: bool,
    /// The structure the tests found.
    pub significant: Vec<String>,
}

/// One fitted parameter of an added effect.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct StepParameter {
    /// Its name.
    pub name: String,
    /// Its estimate (`null`: not determined).
    pub value: Option<f64>,
    /// Its standard deviation.
    pub std: Option<f64>,
    /// The unit of both.
    pub unit: String,
}

/// A candidate's score in a round.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CandidateReport {
    /// The effect.
    pub effect: String,
    /// Fraction of its signature the model cannot already explain.
    pub novelty: f64,
    /// F-test p-value.
    pub p_value: Option<f64>,
    /// BIC change.
    pub delta_bic: Option<f64>,
    /// Residual RMS with it, um.
    pub rms_um: Option<f64>,
    /// Cross-validated RMS with it (blocked folds), um.
    pub cv_rms_um: Option<f64>,
    /// Present parameters the data would no longer determine with it (it is then refused).
    pub determined_lost: Option<usize>,
    /// The data determine none of its parameters better than its tolerance (refused).
    pub undetermined: bool,
}

/// One added effect.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct StepReport {
    /// The effect.
    pub effect: String,
    /// F-test p-value.
    pub p_value: Option<f64>,
    /// BIC change.
    pub delta_bic: Option<f64>,
    /// RMS before, um.
    pub rms_before_um: f64,
    /// RMS after, um.
    pub rms_after_um: f64,
    /// Cross-validated RMS before, um.
    pub cv_rms_before_um: f64,
    /// Cross-validated RMS after, um.
    pub cv_rms_after_um: f64,
    /// Its fitted parameters.
    pub parameters: Vec<StepParameter>,
    /// Every candidate of the round.
    pub candidates: Vec<CandidateReport>,
}

/// A candidate of the last round (which added nothing).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LastRoundCandidate {
    /// The effect.
    pub effect: String,
    /// Its novelty.
    pub novelty: f64,
    /// Left out as confounded with the model (novelty below `min_novelty`).
    pub confounded: bool,
    /// Present parameters the data would no longer determine with it (refused).
    pub determined_lost: Option<usize>,
    /// The data determine none of its parameters better than its tolerance (refused).
    pub undetermined: bool,
    /// F-test p-value.
    pub p_value: Option<f64>,
    /// BIC change.
    pub delta_bic: Option<f64>,
    /// Residual RMS with it, um.
    pub rms_um: Option<f64>,
}

/// The final model.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Final {
    /// Its effects.
    pub effects: Vec<String>,
    /// Residual RMS, um.
    pub rms_um: f64,
    /// Cross-validated RMS, um.
    pub cv_rms_um: f64,
    /// The residual passed the whiteness tests.
    pub residual_white: bool,
    /// The residual is consistent with the declared noise.
    pub consistent_with_noise: Option<bool>,
    /// Structure left in the residual.
    pub unexplained_structure: Vec<String>,
    /// The final fit converged.
    pub converged: bool,
    /// Share down-weighted by the robust loss.
    pub downweighted_share: f64,
    /// The robust fit failed.
    pub robust_failed: bool,
}

/// A library effect that was not a candidate because it cannot act on these data.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct NotApplicable {
    /// The effect.
    pub effect: String,
    /// Why it does not apply (`no tracker poses in the data`).
    pub why: String,
}

/// An effect that passed the F-test and BIC but not cross-validation.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RejectedByCv {
    /// The effect.
    pub effect: String,
    /// Cross-validated RMS without it, um.
    pub cv_rms_before_um: f64,
    /// Cross-validated RMS with it, um.
    pub cv_rms_with_um: f64,
    /// The candidate of the same round that predicted held-out poses better (this one lost to
    /// it, not to the model); absent when none did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost_to: Option<String>,
}

impl RejectedByCv {
    /// Why it was not added, in words: a better candidate of its round, a gain within the
    /// uncertainty of the difference, or no gain.
    pub fn why_not(&self) -> String {
        match &self.lost_to {
            Some(w) => format!("`{w}` predicted held-out poses better in the same round"),
            None if self.cv_rms_with_um < self.cv_rms_before_um => {
                "better, but not by more than the uncertainty of the difference".to_string()
            }
            None => "no better".to_string(),
        }
    }
}

/// A pose map term's share of the first residual (the pose map scan).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PoseStructureReport {
    /// The pose map term.
    pub effect: String,
    /// Dimensions it adds beyond the model.
    pub dimensions: usize,
    /// Share of the residual sum of squares it would explain.
    pub explained_share: f64,
    /// Its p-value (uncorrected).
    pub p_value: f64,
}

/// The commanded poses' range: what a pose map describes.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PoseRangeReport {
    /// Smallest x, y, z (mm), roll, pitch, yaw (deg).
    pub min_xyz_mm_rpy_deg: [f64; 6],
    /// Largest x, y, z (mm), roll, pitch, yaw (deg).
    pub max_xyz_mm_rpy_deg: [f64; 6],
    /// What the range means.
    pub note: String,
}

/// `refine.json`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RefineDoc {
    /// The cpm version.
    pub cpm_version: String,
    /// The data are simulated.
    pub simulated: bool,
    /// The starting model's residual.
    pub initial: Initial,
    /// The added effects, in order.
    pub steps: Vec<StepReport>,
    /// The last round's candidates.
    pub last_round: Vec<LastRoundCandidate>,
    /// The novelty below which a candidate is left out.
    pub min_novelty: f64,
    /// The five pose map terms that explain most of the first residual.
    pub pose_structure: Vec<PoseStructureReport>,
    /// The range of the commanded poses.
    pub pose_range: PoseRangeReport,
    /// The final model.
    #[serde(rename = "final")]
    pub final_: Final,
    /// Outliers flagged by the first fit.
    pub outliers_before: usize,
    /// Effects rejected by cross-validation.
    pub rejected_by_cross_validation: Vec<RejectedByCv>,
    /// Plain calibration against the refined model, on data the fits did not see.
    pub against_calibrate: AgainstCalibrate,
    /// The groups refine tried to hold at nominal, judged out of sample.
    pub hold_trials: Vec<cpm_calib::refine::HoldTrial>,
    /// The groups the final model holds at nominal (declared or chosen).
    pub held_groups: Vec<String>,
    /// Library effects left out of the candidates because they cannot act on these data
    /// (set by the caller that chose the candidates).
    pub not_applicable: Vec<NotApplicable>,
    /// The poses left out with all their observations, as in `calibration.json` (set by the
    /// caller that read the data; absent when none, so a clean campaign's file is unchanged).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub excluded_poses: Vec<crate::fit::ExcludedPoseReport>,
    /// The residual mixes kinds of observation weighed differently (as calibration.json's
    /// `residual_weighted`, set by the caller that made the final fit's report): every RMS
    /// figure `..._um` is then `null`, and written weighted in sigma beside it as
    /// `..._in_sigma` (each residual over its kind's noise at the final fit's noise scale,
    /// as report.md says it). A weighted figure in um is no length.
    pub residual_weighted: bool,
    /// The final fit's noise scale (um of the reference noise) that the weighted figures are
    /// divided by; not written.
    #[serde(skip)]
    pub noise_scale_um: f64,
}

/// Whether `key` of refine.json holds a residual RMS in um (`rms_um`, `cv_rms_before_um`,
/// `calibrate_cv_rms_um`, ...).
fn is_rms_um(key: &str) -> bool {
    key.contains("rms") && key.ends_with("_um")
}

/// Every RMS figure of `v` in um made `null`, and written `..._in_sigma`, divided by `scale`.
fn weigh_rms_keys(v: &mut serde_json::Value, scale: f64) {
    match v {
        serde_json::Value::Object(map) => {
            let keys: Vec<String> = map.keys().filter(|k| is_rms_um(k)).cloned().collect();
            for k in keys {
                let weighted = map[&k].as_f64().map(|x| x / scale);
                map.insert(k.clone(), serde_json::Value::Null);
                let stem = k.strip_suffix("_um").unwrap_or(&k);
                map.insert(format!("{stem}_in_sigma"), serde_json::json!(weighted));
            }
            for x in map.values_mut() {
                weigh_rms_keys(x, scale);
            }
        }
        serde_json::Value::Array(items) => {
            for x in items {
                weigh_rms_keys(x, scale);
            }
        }
        _ => {}
    }
}

impl RefineDoc {
    /// From a refinement (`min_novelty` as used by it).
    pub fn new(r: &Refinement, simulated: bool, min_novelty: f64) -> Self {
        let cal = &r.calibration;
        Self {
            cpm_version: env!("CARGO_PKG_VERSION").to_string(),
            simulated,
            initial: Initial {
                rms_um: r.initial_rms_um,
                residual_white: r.initial_diagnostics.white,
                significant: r.initial_diagnostics.significant.clone(),
            },
            steps: r
                .steps
                .iter()
                .map(|s| StepReport {
                    effect: s.effect.name().to_string(),
                    p_value: finite(s.p_value),
                    delta_bic: finite(s.delta_bic),
                    rms_before_um: s.rms_before_um,
                    rms_after_um: s.rms_after_um,
                    cv_rms_before_um: s.cv_rms_before_um,
                    cv_rms_after_um: s.cv_rms_after_um,
                    parameters: s
                        .parameters
                        .iter()
                        .enumerate()
                        .map(|(k, (n, v, sd))| StepParameter {
                            name: n.clone(),
                            value: v.filter(|x| x.is_finite()),
                            std: sd.filter(|x| x.is_finite()),
                            unit: s.effect.param_unit(k).to_string(),
                        })
                        .collect(),
                    candidates: s
                        .candidates
                        .iter()
                        .map(|c| CandidateReport {
                            effect: c.effect.name().to_string(),
                            novelty: c.novelty,
                            p_value: c.p_value,
                            delta_bic: c.delta_bic,
                            rms_um: c.rms_um,
                            cv_rms_um: c.cv_rms_um,
                            determined_lost: c.determined_lost,
                            undetermined: c.undetermined,
                        })
                        .collect(),
                })
                .collect(),
            last_round: r
                .last_round
                .iter()
                .map(|c| LastRoundCandidate {
                    effect: c.effect.name().to_string(),
                    novelty: c.novelty,
                    // Skipped before any fit (pose map terms below min_novelty, physical
                    // effects below a fraction of it).
                    confounded: c.rms_um.is_none() && c.novelty < min_novelty,
                    p_value: c.p_value,
                    delta_bic: c.delta_bic,
                    rms_um: c.rms_um,
                    determined_lost: c.determined_lost,
                    undetermined: c.undetermined,
                })
                .collect(),
            min_novelty,
            pose_structure: r
                .initial_pose_structure
                .iter()
                .take(5)
                .map(|p| PoseStructureReport {
                    effect: p.effect.name().to_string(),
                    dimensions: p.dimensions,
                    explained_share: p.explained_share,
                    p_value: p.p_value,
                })
                .collect(),
            pose_range: PoseRangeReport {
                min_xyz_mm_rpy_deg: r.pose_range.min,
                max_xyz_mm_rpy_deg: r.pose_range.max,
                note: "pose map terms describe these commanded poses only; they do not extrapolate"
                    .to_string(),
            },
            final_: Final {
                effects: r
                    .model
                    .effects
                    .iter()
                    .map(|e| e.name().to_string())
                    .collect(),
                rms_um: cal.residual_rms_um,
                cv_rms_um: r.final_cv_rms_um,
                residual_white: r.final_diagnostics.white,
                consistent_with_noise: r.final_diagnostics.consistent_with_noise,
                unexplained_structure: r.unexplained_structure.clone(),
                converged: cal.solver.was_successful(),
                downweighted_share: cal.downweighted_share,
                robust_failed: cal.robust_failed,
            },
            outliers_before: r.outliers_before.len(),
            rejected_by_cross_validation: r
                .rejected_by_cv
                .iter()
                .map(|(e, before, after, lost_to)| RejectedByCv {
                    effect: e.name().to_string(),
                    cv_rms_before_um: *before,
                    cv_rms_with_um: *after,
                    lost_to: lost_to.map(|w| w.name().to_string()),
                })
                .collect(),
            against_calibrate: r.against_calibrate,
            hold_trials: r.hold_trials.clone(),
            held_groups: r.held_groups.clone(),
            not_applicable: Vec::new(),
            excluded_poses: Vec::new(),
            residual_weighted: false,
            noise_scale_um: cal.sigma_um,
        }
    }

    /// `refine.json`, pretty-printed (keys sorted).
    pub fn to_json(&self) -> serde_json::Result<String> {
        let mut v = serde_json::to_value(self)?;
        if self.residual_weighted && self.noise_scale_um > 0.0 {
            weigh_rms_keys(&mut v, self.noise_scale_um);
        }
        serde_json::to_string_pretty(&v)
    }

    /// The sentence about a last round that added nothing: candidates left out as confounded
    /// with the model, with their novelty, and those not significant. `None` when the rounds
    /// ended otherwise.
    pub fn last_round_message(&self) -> Option<String> {
        if self.last_round.is_empty() {
            return None;
        }
        let confounded: Vec<String> = self
            .last_round
            .iter()
            .filter(|c| c.confounded)
            .map(|c| format!("`{}` (novelty {})", c.effect, fixed(c.novelty, 4)))
            .collect();
        let losing: Vec<String> = self
            .last_round
            .iter()
            .filter_map(|c| {
                c.determined_lost
                    .map(|n| format!("`{}` ({n} fewer determined)", c.effect))
            })
            .collect();
        let undetermined: Vec<String> = self
            .last_round
            .iter()
            .filter(|c| c.undetermined && c.determined_lost.is_none())
            .map(|c| format!("`{}`", c.effect))
            .collect();
        let weak: Vec<String> = self
            .last_round
            .iter()
            .filter(|c| !c.confounded && c.determined_lost.is_none() && !c.undetermined)
            .map(|c| match c.p_value {
                Some(p) => format!("`{}` (p {})", c.effect, p_value(p)),
                None => format!("`{}` (no fit)", c.effect),
            })
            .collect();
        let mut s = String::new();
        if !confounded.is_empty() {
            s.push_str(&format!(
                "Left out as barely separable from the installation errors and effects already in the model on this design (novelty, the fraction of the effect's signature the model cannot already explain, below {}): {}; the data cannot tell such an effect apart, so the residual says nothing about it: a design with more varied poses (`cpm design`) can. ",
                short(self.min_novelty),
                confounded.join(", ")
            ));
        }
        if !losing.is_empty() {
            s.push_str(&format!(
                "Refused because the data would no longer determine parameters they determine now (more than {} % of each would move along a blind direction): {}. ",
                short(100.0 * cpm_calib::fit::refine::CONFOUNDED_FRACTION),
                losing.join(", ")
            ));
        }
        if !undetermined.is_empty() {
            s.push_str(&format!(
                "Refused because the data would not determine it better than its tolerance (each of its parameters' data share below {}: its value would be its prior, not a measurement): {}. ",
                short(cpm_calib::fit::prior::MIN_DATA_SHARE),
                undetermined.join(", ")
            ));
        }
        if !weak.is_empty() {
            s.push_str(&format!(
                "Not significant (after the Bonferroni correction, or no BIC gain): {}.",
                weak.join(", ")
            ));
        }
        Some(s.trim_end().to_string())
    }
}

/// Everything `cpm refine` reports.
#[derive(Debug, Clone, PartialEq)]
pub struct RefineReport {
    /// refine.json.
    pub doc: RefineDoc,
    /// The final model's fit: calibration.json.
    pub fit: FitReport,
    /// The provenance lines atop the report.
    pub provenance: Vec<String>,
    /// The starting model, in words.
    pub starting_model: String,
    /// The final model's effects, in words.
    pub final_effects: String,
    /// What calibrated.toml holds.
    pub calibrated: CalibratedFile,
    /// The figure files written.
    pub figures: Vec<String>,
    /// Pose map terms of the first residual significant after the Bonferroni correction over
    /// every term scanned (a subset of `doc.pose_structure`, at most three).
    pub significant_pose_structure: Vec<PoseStructureReport>,
}

impl RefineReport {
    /// report.md.
    pub fn markdown(&self) -> String {
        let d = &self.doc;
        // A residual that mixes kinds weighed differently has no one unit: its figures are
        // weighted, in sigma (each residual over its kind's noise at the final fit's noise
        // scale, as calibration.json's weighted_rms_in_sigma), never in um.
        let weighted = self.fit.residual_weighted;
        let sigma = self.fit.scale.sigma;
        let u = if weighted {
            " (weighted, in sigma)"
        } else {
            " um"
        };
        let w = |x: f64, n: usize| {
            if weighted && sigma > 0.0 {
                sig(x / sigma, n)
            } else {
                sig(x, n)
            }
        };
        let mut s = String::from("# Refinement report\n\n");
        if d.simulated {
            s.push_str("**The measurements are SIMULATED.**\n\n");
        }
        for l in &self.provenance {
            s.push_str(&format!("{l}\n\n"));
        }
        s.push('\n');
        for w in &self.fit.text.warnings {
            s.push_str(&format!("- {w}\n"));
        }
        s.push_str(&format!(
            "\nStarting model: {}. Residual RMS {}{u}, white: {}.\n\n## Steps\n\n",
            self.starting_model,
            w(d.initial.rms_um, 3),
            yes_no(d.initial.residual_white)
        ));
        if !d.not_applicable.is_empty() {
            let list: Vec<String> = d
                .not_applicable
                .iter()
                .map(|n| format!("`{}` ({})", n.effect, n.why))
                .collect();
            s.push_str(&format!(
                "Not candidates, as they do not apply to these data: {}.\n\n",
                list.join(", ")
            ));
        }
        if !self.significant_pose_structure.is_empty() {
            let terms: Vec<String> = self
                .significant_pose_structure
                .iter()
                .map(|p| {
                    format!(
                        "`{}` ({} % of the residual sum of squares, p {})",
                        p.effect,
                        fixed(100.0 * p.explained_share, 1),
                        p_value(p.p_value)
                    )
                })
                .collect();
            s.push_str(&format!(
                "Pose-correlated structure in the first residual (pose map scan): {}.\n\n",
                terms.join(", ")
            ));
        }
        if d.outliers_before > 0 {
            s.push_str(&format!(
                "The first fit flagged {} outlier observation(s) (listed under \"Outliers\") before any effect was chosen: the effects were chosen without them (an effect is also added only when it lowers the cross-validated RMS), and the final model was fitted to all observations. The RMS figures of this report count them, at the start and at the end alike.\n\n",
                d.outliers_before
            ));
        }
        for x in &d.rejected_by_cross_validation {
            s.push_str(&format!(
                "- `{}` passed the F-test and BIC but was not added: cross-validated RMS {} -> {}{u} ({}).\n",
                x.effect,
                w(x.cv_rms_before_um, 4),
                w(x.cv_rms_with_um, 4),
                x.why_not()
            ));
        }
        if !d.rejected_by_cross_validation.is_empty() {
            s.push('\n');
        }
        let last = d.last_round_message();
        if d.steps.is_empty() {
            match &last {
                Some(m) => s.push_str(&format!("No effect was added. {m}\n\n")),
                None => s.push_str("No effect was added: the residual was already white and consistent with the noise (or no candidate was left).\n\n"),
            }
        }
        for (i, st) in d.steps.iter().enumerate() {
            s.push_str(&format!(
                "### {}. `{}`\n\n- F-test p-value {}, BIC change {}\n- RMS {} -> {}{u}; cross-validated {} -> {}{u}\n\n| parameter | estimate | std |\n|---|---|---|\n",
                i + 1,
                st.effect,
                st.p_value.map_or("n.d.".into(), p_value),
                st.delta_bic.map_or("n.d.".into(), |b| fixed(b, 1)),
                w(st.rms_before_um, 3),
                w(st.rms_after_um, 3),
                w(st.cv_rms_before_um, 3),
                w(st.cv_rms_after_um, 3)
            ));
            for p in &st.parameters {
                let (v, sd) = opt_with_sd(p.value, p.std, 4);
                s.push_str(&format!("| {} | {v} | {sd} |\n", p.name));
            }
            s.push('\n');
        }
        if let (false, Some(m)) = (d.steps.is_empty(), &last) {
            s.push_str(&format!("The last round added nothing. {m}\n\n"));
        }
        s.push_str(&format!(
            "## Final\n\n- Effects: {}\n- RMS {}{u}, cross-validated {}{u}, residual white: {}\n- Unexplained structure: {}\n- Against plain calibration, on the whole campaign over {} folds (data each fit did not see): {}{u} calibrated, {}{u} refined\n\n",
            self.final_effects,
            w(d.final_.rms_um, 3),
            w(d.final_.cv_rms_um, 3),
            yes_no(d.final_.residual_white),
            if d.final_.unexplained_structure.is_empty() { "none".to_string() } else { d.final_.unexplained_structure.join(", ") },
            d.against_calibrate.folds,
            w(d.against_calibrate.calibrate_cv_rms_um, 4),
            w(d.against_calibrate.refined_cv_rms_um, 4),
        ));
        if d.final_.effects.iter().any(|e| e.starts_with("pose_map")) {
            let (lo, hi) = (
                &d.pose_range.min_xyz_mm_rpy_deg,
                &d.pose_range.max_xyz_mm_rpy_deg,
            );
            let mm = |k: usize| format!("{} to {}", fixed(lo[k], 1), fixed(hi[k], 1));
            let deg = |k: usize| format!("{} to {}", fixed(lo[k], 2), fixed(hi[k], 2));
            s.push_str(&format!(
                "The pose error map describes the poses it was fitted on and does not extrapolate: x {} mm, y {} mm, z {} mm, roll {} deg, pitch {} deg, yaw {} deg (written to `calibrated.toml` `[pose_map]`; `cpm compensate` flags targets outside).\n\n",
                mm(0), mm(1), mm(2), deg(3), deg(4), deg(5)
            ));
        }
        self.fit.markdown_sections(&mut s);
        let c = &self.calibrated;
        s.push_str(&format!(
            "## Outputs\n\n- `refine.json`, `calibration.json` (final model)\n- `calibrated.toml`: the fitted installation errors in `[installation_errors_um]` ({} components not determined on their own, written at the fit's minimum-norm point, which reproduces the fit), effects declared; link_offset/link_scale folded into the link reading models, socket_error into the sensor sockets{}\n",
            c.undetermined,
            if c.known_effects.is_empty() { String::new() } else { format!("; values of {} in `[calibration.known_effects]`", c.known_effects.join(", ")) }
        ));
        for f in &self.figures {
            s.push_str(&format!("- `{f}`\n"));
        }
        s
    }
}
