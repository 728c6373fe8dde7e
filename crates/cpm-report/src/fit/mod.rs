//! The report of one fit (`cpm calibrate`, and the final model of `cpm refine`): the typed
//! value behind `calibration.json` and the fit sections of report.md.
//!
//! [`FitReport`] serialises to `calibration.json` (every key listed in docs/formats.md);
//! [`FitReport::markdown_sections`] renders the "Data / Fit", "What the data identify",
//! "Estimates", "Outliers" and "Tracker registration" sections from the same value.
use serde::Serialize;

use crate::format::{finite, fixed, opt_fixed, opt_with_sd, short, sig, with_sd};
use cpm_calib::{Calibration, Determination, Effect, MeasurementModel};
use cpm_geometry::InstallationErrors;
use cpm_io::{Merged, Provenance, Robot};

pub use crate::identifiability::{
    BlindDirection, IdentifiabilityDoc, IdentifiabilityReport, ParameterIdentifiability,
};

pub mod prior;
mod words;
/// For `skip_serializing_if`: a count of zero is left out.
fn is_zero(n: &usize) -> bool {
    *n == 0
}

#[cfg(test)]
pub(crate) use words::write_reading_what;
pub use words::{
    describe_loss, describe_model, effect_list, misfit, misfit_message, observation_origin,
    warnings, write_observation_origin, Formulation, ObservationOrigin,
};

/// What a fit's report needs besides the model and the calibration: the robot, the merged
/// data (campaign, registration, where each observation came from), the provenance and the
/// loss the fit used. The command line fills it from what it loaded.
#[derive(Debug, Clone, Copy)]
pub struct FitInputs<'a> {
    /// The robot.
    pub robot: &'a Robot,
    /// The merged data.
    pub merged: &'a Merged,
    /// Where it all came from.
    pub provenance: &'a Provenance,
    /// The loss of the fit.
    pub loss: &'a cpm_lm::Loss,
}

/// Installation errors per joint, um: `base[i] = [dx, dy, dz]` of link i+1's base joint.
#[derive(Debug, Clone, Serialize, PartialEq, Default)]
pub struct PerJoint {
    /// Base joints.
    pub base: Vec<[Option<f64>; 3]>,
    /// Platform joints.
    pub platform: Vec<[Option<f64>; 3]>,
}

impl PerJoint {
    /// From installation-error values in model order (6 per link; `None` where unknown).
    pub fn new(values: &[Option<f64>]) -> Self {
        let side = |s: usize| {
            (0..values.len() / 6)
                .map(|i| std::array::from_fn(|a| finite(values[6 * i + 3 * s + a])))
                .collect()
        };
        Self {
            base: side(0),
            platform: side(1),
        }
    }
}

/// One fitted parameter of an effect.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct EffectParameter {
    /// Its name (`backlash.1`, ...).
    pub name: String,
    /// The estimate (`null`: not determined by the data; `determination` says what holds
    /// it, and `parameters` its value).
    pub value: Option<f64>,
    /// Its standard deviation.
    pub std: Option<f64>,
    /// The unit of both.
    pub unit: String,
    /// What gives it its value ([`Determination`]).
    pub determination: Determination,
}

/// The fitted parameters of one effect.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct EffectEstimates {
    /// The effect's name.
    pub effect: String,
    /// Its parameters.
    pub parameters: Vec<EffectParameter>,
}

/// A known (not fitted) effect applied in every prediction.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct KnownEffectValues {
    /// The effect's name.
    pub effect: String,
    /// The unit of the values.
    pub unit: String,
    /// The values.
    pub values: Vec<f64>,
}

/// `calibration.json`'s `solver` object.
#[derive(Debug, Clone, Serialize, PartialEq, Default)]
pub struct SolverReport {
    /// The solver converged.
    pub converged: bool,
    /// Why it stopped.
    pub termination: String,
    /// Iterations.
    pub iterations: usize,
    /// Cost at the start.
    pub initial_cost: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// One line.
    pub summary: String,
}

/// `calibration.json`'s `robust` object (calibrate only).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RobustReport {
    /// Share of observations the robust loss down-weighted.
    pub downweighted_share: f64,
    /// Weight below which an observation counts as down-weighted.
    pub downweight_level: f64,
    /// Share above which the robust fit is declared failed.
    pub max_downweighted_share: f64,
    /// The robust fit failed.
    pub failed: bool,
}

/// One flagged outlier observation.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Outlier {
    /// 1-based observation number.
    pub observation: usize,
    /// Its file.
    pub file: Option<String>,
    /// Its line.
    pub line: Option<usize>,
    /// What it is.
    pub what: Option<String>,
    /// Its residual (measured minus predicted) as weighed by the fit, um of the reference
    /// noise (a length for lengths of the reference noise; see `residual` for its own unit).
    pub residual_um: Option<f64>,
    /// Its residual in its own unit (`unit`): measured minus predicted, the value of its row
    /// of `residuals.csv` (tracker positions and points in the tracker's own axes).
    pub residual: Option<f64>,
    /// The unit of `residual`: `um` or `urad`.
    pub unit: Option<String>,
    /// The fit set it aside (weight zero) rather than follow it.
    pub set_aside: bool,
}

/// A pose left out of the fit with all its observations (`calibration.json`'s
/// `excluded_poses`): the machine cannot be there, or forward kinematics did not converge at
/// it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ExcludedPoseReport {
    /// Its file.
    pub file: String,
    /// Its first line.
    pub line: usize,
    /// Its `pose` label.
    pub label: String,
    /// Why.
    pub reason: String,
}

impl From<&cpm_io::ExcludedPose> for ExcludedPoseReport {
    fn from(e: &cpm_io::ExcludedPose) -> Self {
        Self {
            file: e.file.clone(),
            line: e.line,
            label: e.label.clone(),
            reason: e.reason.clone(),
        }
    }
}

/// `calibration.json`'s `misfit` object.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MisfitReport {
    /// Sum of squared residuals over their declared noise squared.
    pub chi2: f64,
    /// Degrees of freedom: observations used minus the rank.
    pub dof: usize,
    /// chi2 / dof (1 expected).
    pub chi2_per_dof: f64,
    /// Probability of a chi2 this large or larger under the declared noise.
    pub p_value: f64,
    /// RMS of the residuals used, um; `None` when the residual is weighted
    /// ([`FitReport::residual_weighted`]: then `chi2_per_dof` says it, unit-free).
    pub residual_rms_um: Option<f64>,
    /// The declared noise, um; `None` when the residual is weighted (each kind's is in
    /// `noise_by_kind`).
    pub sigma_um: Option<f64>,
    /// Observations left out as outliers.
    pub outliers_left_out: usize,
    /// The test rejects the model.
    pub inconsistent: bool,
    /// The rule.
    pub rule: String,
    /// What it means (when inconsistent).
    pub message: Option<String>,
}

/// A fit's residual and noise figures as the fit computed them: um, or um of the reference
/// noise when the residual is weighted ([`FitReport::residual_weighted`]), where only their
/// ratios (in sigma) mean anything.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitScale {
    /// Residual RMS at the solution.
    pub residual_rms: f64,
    /// Residual RMS at the start.
    pub initial_rms: f64,
    /// The noise every residual is weighted to.
    pub sigma: f64,
}

/// One tracker session's registration.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SessionReport {
    /// The file.
    pub file: String,
    /// Poses in it.
    pub poses: usize,
    /// The frame was applied to the data.
    pub applied: bool,
    /// Largest move of a measured position, mm.
    pub largest_move_mm: f64,
    /// Translation, mm.
    pub translation_mm: [f64; 3],
    /// Its standard deviations, mm.
    pub translation_sd_mm: [f64; 3],
    /// Rotation vector, deg.
    pub rotation_vector_deg: [f64; 3],
    /// Its standard deviations, deg.
    pub rotation_sd_deg: [f64; 3],
    /// Rotation angle, deg.
    pub rotation_angle_deg: f64,
    /// Roll, pitch, yaw, deg.
    pub roll_pitch_yaw_deg: [f64; 3],
    /// Position RMS before, mm.
    pub rms_before_mm: f64,
    /// Position RMS after, mm.
    pub rms_after_mm: f64,
    /// Orientation RMS before, deg.
    pub orientation_rms_before_deg: f64,
    /// Orientation RMS after, deg.
    pub orientation_rms_after_deg: f64,
}

/// A fitted value refining the registration.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct NamedEstimate {
    /// The parameter.
    pub name: String,
    /// Its estimate.
    pub value: Option<f64>,
    /// Its standard deviation.
    pub std: Option<f64>,
}

/// What the fit refined on top of the registration.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RefinedByFit {
    /// `tracker_frame` parameters (when modelled).
    pub tracker_frame: Option<Vec<NamedEstimate>>,
    /// `link_offset` parameters (when modelled).
    pub link_offset: Option<Vec<NamedEstimate>>,
    /// `marker_frame` (when modelled): the tracked body's frame on the platform as written to
    /// `calibrated.toml` (`value`: the point the fit ended at, under the convention that the
    /// platform joints have no common rigid motion on tracker data alone; `std` where the
    /// data determine a parameter on its own).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub marker_frame: Option<Vec<NamedEstimate>>,
    /// Gauge freedoms of the refinement.
    pub gauge_freedoms: Vec<String>,
}

/// `calibration.json`'s `registration` object.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RegistrationSummary {
    /// Frames moving a position by more than this are applied, mm.
    pub apply_threshold_mm: f64,
    /// Why the registration failed.
    pub failure: Option<String>,
    /// Per tracker file.
    pub sessions: Vec<SessionReport>,
    /// Link reading offsets, mm.
    pub link_reading_offset_mm: Vec<f64>,
    /// Their standard deviations, mm.
    pub link_reading_offset_sd_mm: Vec<f64>,
    /// The offsets were estimated.
    pub offsets_estimated: bool,
    /// The offsets were applied.
    pub offsets_applied: bool,
    /// Variance factor of the registration.
    pub variance_factor: f64,
    /// The fit's refinements.
    pub refined_by_fit: RefinedByFit,
}

/// One row of the estimates table (every parameter of the model), and one entry of
/// `calibration.json`'s `parameters`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterRow {
    /// Its name, with its unit.
    pub name: String,
    /// What gives it its value: `determined`, `held_by_tolerance`, `held_by_user` or
    /// `blind` ([`Determination`]).
    pub determination: Determination,
    /// Its value (the one every command applies; `None`: blind): the data's estimate when
    /// determined, the fit's value between the data and the tolerance when held by
    /// tolerance, the held value when held by user.
    #[serde(rename = "value")]
    pub estimate: Option<f64>,
    /// The standard deviation that goes with its determination: the Cramér-Rao bound
    /// (determined), the posterior one (held by tolerance), 0 (held by user).
    pub std: Option<f64>,
}

/// How many parameters each [`Determination`] has (`calibration.json` `determination`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
pub struct DeterminationCounts {
    /// Determined by the data on their own.
    pub determined: usize,
    /// Held by their tolerance (or the tolerance limit).
    pub held_by_tolerance: usize,
    /// Held by the user at nominal.
    pub held_by_user: usize,
    /// Neither determined nor held: no estimate.
    pub blind: usize,
}

impl DeterminationCounts {
    /// The counts of `cal`.
    pub fn of(cal: &Calibration) -> Self {
        let [determined, held_by_tolerance, held_by_user, blind] = cal.determination_counts();
        DeterminationCounts {
            determined,
            held_by_tolerance,
            held_by_user,
            blind,
        }
    }

    /// In words, the zero counts left out but the determined one: `"30 determined, 6 held
    /// by tolerance"`, the same in stdout and report.md.
    pub fn words(&self) -> String {
        let mut v = vec![format!("{} determined", self.determined)];
        for (n, d) in [
            (self.held_by_tolerance, Determination::HeldByTolerance),
            (self.held_by_user, Determination::HeldByUser),
            (self.blind, Determination::Blind),
        ] {
            if n > 0 {
                v.push(format!("{n} {d}"));
            }
        }
        v.join(", ")
    }
}

/// Every parameter of `model` with its determination, value and standard deviation.
pub fn parameter_rows(model: &MeasurementModel, cal: &Calibration) -> Vec<ParameterRow> {
    model
        .parameter_names()
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let (estimate, std) = cal.value_and_std(k);
            ParameterRow {
                name: n.clone(),
                determination: cal.determination(k),
                estimate: estimate.filter(|v| v.is_finite()),
                std: std.filter(|v| v.is_finite()),
            }
        })
        .collect()
}

/// What report.md says about the fit beyond calibration.json.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FitText {
    /// Robot description file.
    pub robot_file: String,
    /// Links.
    pub links: usize,
    /// Sensors.
    pub sensors: usize,
    /// Joint clearance radius, um.
    pub clearance_um: f64,
    /// The model, in words.
    pub model: String,
    /// The formulation, in words (calibrate).
    pub formulation: Option<String>,
    /// Every parameter, in model order.
    pub parameters: Vec<ParameterRow>,
    /// The warnings, in markdown.
    pub warnings: Vec<String>,
    /// Whether the standard deviations use a noise estimated without the outliers.
    pub sigma_excludes_outliers_note: bool,
}

/// The noise of one kind of observation (`calibration.json` `noise_by_kind`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct NoiseKindReport {
    /// The kind, in words: `gauge s1`, `tracker positions`, `tracker orientations`, `point
    /// targets`, `inclinometer angles`.
    pub kind: String,
    /// The unit of the noise (`um` or `urad`).
    pub unit: String,
    /// Number of observations.
    pub observations: usize,
    /// Its share of the residual degrees of freedom (the sum of its redundancy numbers).
    pub degrees_of_freedom: f64,
    /// The noise the fit weighed it with.
    pub assumed: f64,
    /// The noise its residual says (`null` below one degree of freedom).
    pub estimated: Option<f64>,
    /// The RMS of its residuals after the fit, in `unit` (not weighted), those set aside
    /// left out.
    pub rms: f64,
    /// Its observations the fit set aside as gross outliers (weight zero; listed under
    /// `outliers` with `set_aside: true`).
    pub set_aside: usize,
}

/// The note when no noise was declared and the fit estimated it (issue 60 item 11: it said
/// nothing): how large, per kind in its own unit, and that a declared instrument noise would
/// test the model. `None` when a noise was declared, or the residual cannot give one (no
/// degree of freedom, data fitted exactly).
pub fn estimated_noise_note(
    kinds: &[cpm_calib::noise::KindNoise],
    cal: &Calibration,
) -> Option<String> {
    if !cal.sigma_estimated
        || cal.residuals_um.len() <= cal.identifiability.rank
        || cal.residual_rms_um < cpm_calib::analysis::diagnostics::NUMERICAL_RESIDUAL_UM
    {
        return None;
    }
    let list: Vec<String> = kinds
        .iter()
        .filter_map(|k| {
            k.estimated
                .map(|e| format!("{} {} {}", k.name, sig(e, 3), k.unit))
        })
        .collect();
    if list.is_empty() {
        return None;
    }
    Some(format!(
        "**Noise estimated, none declared**: the fit weighed the observations by the noise their own residual shows ({}); every standard deviation rests on it, and a misfit the model lacks would pass for noise. A known instrument noise, declared (`--sigma-um`, `--pose-sigma-um`, `--orientation-sigma-urad`, or `[calibration]` of the description), lets the chi-square test check the model.",
        list.join(", ")
    ))
}

/// The warning when the kinds of observation are weighed against each other wrongly: a kind's
/// residual says a noise more than 3 times above or below the one the fit weighed it with,
/// relative to what the kind with the most degrees of freedom says (at least 10 each). Kinds all
/// off by one factor (the gauges of a fit whose noise is estimated from the residual, weighed
/// with a placeholder) are weighed rightly against each other: no warning.
pub fn noise_warning(kinds: &[cpm_calib::noise::KindNoise]) -> Option<String> {
    let off = cpm_calib::noise::mismatched(kinds, 3.0);
    if off.is_empty() || kinds.len() < 2 {
        return None;
    }
    let min = cpm_calib::noise::MIN_REDUNDANCY;
    let scale = kinds
        .iter()
        .filter(|k| k.redundancy >= min)
        .filter_map(|k| k.ratio().map(|r| (k.redundancy, r)))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map_or(1.0, |(_, r)| r);
    let off: Vec<_> = kinds
        .iter()
        .filter(|k| k.redundancy >= min)
        .filter(|k| {
            k.ratio()
                .is_some_and(|r| r / scale > 3.0 || r / scale < 1.0 / 3.0)
        })
        .collect();
    if off.is_empty() {
        return None;
    }
    let list: Vec<String> = off
        .iter()
        .map(|k| {
            format!(
                "{} {} {} (weighed as {} {})",
                k.name,
                sig(k.estimated.unwrap_or(f64::NAN), 3),
                k.unit,
                sig(k.assumed, 3),
                k.unit
            )
        })
        .collect();
    Some(format!(
        "**Noise not as weighed**: the residual of each kind of observation says {}; the kinds are weighed against each other wrongly, and the standard deviations with them. Declare the noise (`--sigma-um`, `--pose-sigma-um`, `--orientation-sigma-urad`, or `[calibration]` of the description) or let `--noise-per-kind` estimate it.",
        list.join(", ")
    ))
}

/// The report of one fit: `calibration.json` when serialised, the fit sections of report.md
/// through [`FitReport::markdown_sections`].
#[derive(Debug, Clone, Serialize, PartialEq, Default)]
pub struct FitReport {
    /// The cpm version.
    pub cpm_version: String,
    /// The data are simulated.
    pub simulated: bool,
    /// The robot description file.
    pub robot: String,
    /// The measurement files.
    pub data: Vec<String>,
    /// Length readings.
    pub readings: usize,
    /// Tracker pose measurements.
    pub pose_measurements: usize,
    /// Reflector point measurements (three coordinates each); absent when none.
    #[serde(skip_serializing_if = "is_zero")]
    pub point_measurements: usize,
    /// Inclinometer angles (one per axis and pose); absent when none.
    #[serde(skip_serializing_if = "is_zero")]
    pub tilt_measurements: usize,
    /// Measurements of one's own instruments; absent when none.
    #[serde(skip_serializing_if = "is_zero")]
    pub instrument_measurements: usize,
    /// Poses.
    pub poses: usize,
    /// Installation errors, um.
    pub installation_errors_um: PerJoint,
    /// Their standard deviations, um.
    pub std_um: PerJoint,
    /// The minimum-norm solution, um.
    pub minimum_norm_um: PerJoint,
    /// Installation-error components not determined.
    pub not_determined: Vec<String>,
    /// The fitted effects.
    pub effects: Vec<EffectEstimates>,
    /// Every parameter of the model in model order, each with what gives it its value
    /// (`determined`, `held_by_tolerance`, `held_by_user`, `blind`), the value every command
    /// applies (what `calibrated.toml` writes; `null` when blind) and the standard deviation
    /// that goes with it. `installation_errors_um`, `std_um` and `effects` hold the
    /// determined ones alone.
    pub parameters: Vec<ParameterRow>,
    /// How many parameters each determination has.
    pub determination: DeterminationCounts,
    /// Known values applied in every prediction (the estimates are on top of them).
    pub known_effects: Vec<KnownEffectValues>,
    /// Residual RMS over every observation, um; `None` (`null`) when `residual_weighted`:
    /// no one unit holds a residual that mixes kinds weighed differently. Each kind's RMS in
    /// its own unit is then `noise_by_kind[].rms`, the whole residual's
    /// `weighted_rms_in_sigma`.
    pub residual_rms_um: Option<f64>,
    /// Residual RMS at the start, um; `None` when `residual_weighted` (then
    /// `initial_weighted_rms_in_sigma`).
    pub initial_rms_um: Option<f64>,
    /// The residual mixes kinds of observation weighed differently (angles beside lengths,
    /// or lengths of different noise): its figures are then weighted, in sigma, and each
    /// kind's RMS in its own unit is `noise_by_kind[].rms`.
    pub residual_weighted: bool,
    /// Weighted residual RMS in sigma: each residual over its kind's noise, scaled by the
    /// fit's noise scale (declared or estimated; about 1 when the noise is as taken).
    pub weighted_rms_in_sigma: f64,
    /// Weighted residual RMS in sigma at the start.
    pub initial_weighted_rms_in_sigma: f64,
    /// The noise, um; `None` when `residual_weighted` (each kind's is then
    /// `noise_by_kind[].assumed`, in its own unit).
    pub sigma_um: Option<f64>,
    /// The fit's own figures, um, or um of the reference noise when `residual_weighted`
    /// (not written: a weighted figure in um is no length).
    #[serde(skip)]
    pub scale: FitScale,
    /// The noise was estimated from the residual.
    pub sigma_estimated: bool,
    /// The noise estimate leaves the outliers out.
    pub sigma_excludes_outliers: bool,
    /// What the data identify.
    pub identifiability: IdentifiabilityReport,
    /// How the solver ended.
    pub solver: SolverReport,
    /// `nested` or `implicit` (calibrate only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub formulation: Option<String>,
    /// The loss, in words.
    pub robust_loss: String,
    /// The robust fit's bookkeeping (calibrate only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robust: Option<RobustReport>,
    /// Flagged outliers.
    pub outliers: Vec<Outlier>,
    /// The poses left out with all their observations (absent when none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub excluded_poses: Vec<ExcludedPoseReport>,
    /// The tracker registration (`null` without tracker files).
    pub registration: Option<RegistrationSummary>,
    /// The chi-square test against the declared noise (`null` when estimated).
    pub misfit: Option<MisfitReport>,
    /// The noise of each kind of observation: assumed by the fit, and what its own residual
    /// says (cpm_calib::noise).
    pub noise_by_kind: Vec<NoiseKindReport>,
    /// What the prior did: tolerances per group, each parameter's posterior against its prior,
    /// the directions held near nominal (`null` for a fit without a prior).
    pub prior: Option<prior::PriorReport>,
    /// The residuals the tracker poses were fitted on: `pose` or `legs` (the
    /// inverse-kinematics formulation); `null` without tracker poses.
    pub tracker_residuals: Option<String>,
    /// The warnings, plain text.
    pub warnings: Vec<String>,
    /// What only the text says.
    #[serde(skip)]
    pub text: FitText,
}

fn named_block(
    model: &MeasurementModel,
    cal: &Calibration,
    e: Effect,
) -> Option<Vec<NamedEstimate>> {
    let names = model.parameter_names();
    let b = model.blocks().into_iter().find(|b| b.effect == Some(e))?;
    Some(
        (b.offset..b.offset + b.len)
            .map(|k| NamedEstimate {
                name: names[k].clone(),
                value: cal.estimate_um.get(k).copied().flatten(),
                std: cal.std_um.get(k).copied().flatten(),
            })
            .collect(),
    )
}

/// The fitted effects' parameters, named, with their units and determinations.
fn effect_estimates(model: &MeasurementModel, cal: &Calibration) -> Vec<EffectEstimates> {
    let sensors: Vec<String> = model
        .nominal
        .sensors
        .iter()
        .map(|s| s.name.clone())
        .collect();
    let at = |v: &[Option<f64>], k: usize| finite(v.get(k).copied().flatten());
    model
        .blocks()
        .iter()
        .filter_map(|b| b.effect.map(|e| (e, b)))
        .map(|(e, b)| EffectEstimates {
            effect: e.name().to_string(),
            parameters: (0..b.len)
                .map(|k| EffectParameter {
                    name: e.param_name(k, &sensors),
                    value: at(&cal.estimate_um, b.offset + k),
                    std: at(&cal.std_um, b.offset + k),
                    unit: e.param_unit(k).to_string(),
                    determination: cal.determination(b.offset + k),
                })
                .collect(),
        })
        .collect()
}

/// The flagged outliers with the file, line and what each observed.
fn outliers(inputs: &FitInputs<'_>, model: &MeasurementModel, cal: &Calibration) -> Vec<Outlier> {
    let campaign = &inputs.merged.campaign;
    // The units of each kind; the values are residuals.csv's (measured minus predicted, in
    // the own unit, tracker positions and points in the tracker's axes), number for number.
    let units = cpm_calib::noise::native_residuals(
        model,
        campaign,
        cal.sigma_ref_um,
        &cal.residuals_um,
        &cal.outliers,
    );
    let in_csv = if cal.outliers.is_empty() {
        Vec::new()
    } else {
        let native = cpm_calib::noise::measured_minus_predicted(
            campaign,
            cal.sigma_ref_um,
            &cal.residuals_um,
        );
        inputs.merged.in_tracker_axes(&native).into_owned()
    };
    cal.outliers
        .iter()
        .zip(units)
        .map(|(&k, native)| {
            let o = observation_origin(inputs.robot, inputs.merged, k);
            Outlier {
                observation: k + 1,
                file: o.as_ref().map(|o| o.file.clone()),
                line: o.as_ref().map(|o| o.line),
                what: o.as_ref().map(|o| o.what.clone()),
                residual_um: finite(cal.residuals_um.get(k).map(|r| -r)),
                residual: finite(native.as_ref().and(in_csv.get(k).copied())),
                unit: native.map(|n| n.1),
                set_aside: cal.set_aside.binary_search(&k).is_ok(),
            }
        })
        .collect()
}

/// One tracker session's registered frame.
fn session_report(s: &cpm_io::SessionRegistration) -> SessionReport {
    let f = &s.frame;
    SessionReport {
        file: s.file.clone(),
        poses: f.poses,
        applied: s.applied,
        largest_move_mm: s.largest_move_mm,
        translation_mm: [f.translation_mm.x, f.translation_mm.y, f.translation_mm.z],
        translation_sd_mm: f.translation_sd_mm,
        rotation_vector_deg: f.rotation_vector_deg(),
        rotation_sd_deg: f.rotation_sd_deg,
        rotation_angle_deg: f.rotation_angle_deg(),
        roll_pitch_yaw_deg: f.as_pose().rpy_deg(),
        rms_before_mm: f.rms_before_mm,
        rms_after_mm: f.rms_after_mm,
        orientation_rms_before_deg: f.orientation_rms_before_deg,
        orientation_rms_after_deg: f.orientation_rms_after_deg,
    }
}

/// The tracker registration and what the fit refined on top of it (`None` without tracker
/// files).
fn registration(
    merged: &Merged,
    model: &MeasurementModel,
    cal: &Calibration,
) -> Option<RegistrationSummary> {
    let r = merged.registration.as_ref()?;
    Some(RegistrationSummary {
        apply_threshold_mm: cpm_io::REGISTRATION_APPLY_MM,
        failure: r.failure.clone(),
        sessions: r.sessions.iter().map(session_report).collect(),
        link_reading_offset_mm: r.link_offset_mm.clone(),
        link_reading_offset_sd_mm: r.link_offset_sd_mm.clone(),
        offsets_estimated: r.offsets_estimated,
        offsets_applied: r.offsets_applied,
        variance_factor: r.variance_factor,
        refined_by_fit: RefinedByFit {
            tracker_frame: named_block(model, cal, Effect::TrackerFrame),
            link_offset: named_block(model, cal, Effect::LinkOffset),
            marker_frame: named_block(model, cal, Effect::MarkerFrame).map(|mut v| {
                let b = model
                    .blocks()
                    .into_iter()
                    .find(|b| b.effect == Some(Effect::MarkerFrame));
                for (k, p) in v.iter_mut().enumerate() {
                    p.value = b.and_then(|b| cal.minimum_norm_um.get(b.offset + k).copied());
                }
                v
            }),
            gauge_freedoms: cal
                .identifiability
                .blind_directions
                .iter()
                .filter(|b| b.description.contains("tracker") || b.description.contains("marker"))
                .map(|b| b.description.clone())
                .collect(),
        },
    })
}

/// The chi-square test against the declared noise (`None` when the noise was estimated);
/// `weighted` as [`FitReport::residual_weighted`].
fn misfit_report(cal: &Calibration, weighted: bool) -> Option<MisfitReport> {
    misfit(cal).map(|m| MisfitReport {
        chi2: m.chi2,
        dof: m.dof,
        chi2_per_dof: m.chi2_per_dof,
        p_value: m.p_value,
        residual_rms_um: (!weighted).then_some(m.residual_rms_um),
        sigma_um: (!weighted).then_some(m.sigma_um),
        outliers_left_out: m.outliers_left_out,
        inconsistent: m.inconsistent(),
        rule: format!(
            "inconsistent when p < {} and chi2/dof > {}",
            cpm_calib::misfit::MISFIT_P,
            cpm_calib::misfit::MISFIT_CHI2_PER_DOF
        ),
        message: m
            .inconsistent()
            .then(|| misfit_message(&m, weighted).replace("**", "")),
    })
}

/// How the solver ended.
fn solver_report(cal: &Calibration) -> SolverReport {
    SolverReport {
        converged: cal.solver.was_successful(),
        termination: cal.solver.termination.to_string(),
        iterations: cal.solver.num_iterations(),
        initial_cost: cal.solver.initial_cost,
        final_cost: cal.solver.final_cost,
        summary: cal.solver.brief(),
    }
}

/// What only report.md says: the robot, the model and formulation in words, every parameter's
/// row, the warnings in Markdown.
fn fit_text(
    inputs: &FitInputs<'_>,
    model: &MeasurementModel,
    cal: &Calibration,
    formulation: Option<Formulation>,
    warnings_md: Vec<String>,
) -> FitText {
    FitText {
        robot_file: inputs.robot.file.clone(),
        links: inputs.robot.num_links(),
        sensors: inputs.robot.table.sensors.len(),
        clearance_um: model.clearance.radius_um,
        model: describe_model(model),
        formulation: formulation.map(|f| f.describe().to_string()),
        parameters: parameter_rows(model, cal),
        warnings: warnings_md,
        sigma_excludes_outliers_note: cal.sigma_excludes_outliers,
    }
}

impl FitReport {
    /// The report of `cal`, a fit of `model` to the inputs' campaign; `formulation` is the
    /// one `cpm calibrate` fitted with (`None` for `cpm refine`'s final model).
    pub fn new(
        inputs: &FitInputs<'_>,
        model: &MeasurementModel,
        cal: &Calibration,
        formulation: Option<Formulation>,
    ) -> Self {
        let campaign = &inputs.merged.campaign;
        let ni = model.num_installation_params();
        let minimum_norm: Vec<Option<f64>> = cal.minimum_norm_um.iter().map(|v| Some(*v)).collect();
        let kinds = cpm_calib::noise::by_kind(model, campaign, cal);
        let weighted = cpm_calib::noise::residual_is_weighted(&kinds);
        let mut warnings_md = warnings(model, cal, weighted);
        warnings_md.extend(noise_warning(&kinds));
        warnings_md.extend(estimated_noise_note(&kinds, cal));
        warnings_md.extend(prior::warning(model, cal));
        warnings_md.extend(prior::limit_warning(model, cal));
        warnings_md.extend(prior::beyond_warning(model, cal));
        Self {
            cpm_version: env!("CARGO_PKG_VERSION").to_string(),
            simulated: cal.simulated,
            robot: inputs.provenance.robot.clone(),
            data: inputs.provenance.data.clone(),
            readings: campaign.readings.len(),
            pose_measurements: campaign.pose_measurements.len(),
            point_measurements: campaign.point_measurements.len(),
            tilt_measurements: campaign.tilt_measurements.len(),
            instrument_measurements: campaign.instrument_measurements.len(),
            poses: campaign.poses.len(),
            installation_errors_um: PerJoint::new(&cal.estimate_um[..ni]),
            std_um: PerJoint::new(&cal.std_um[..ni]),
            minimum_norm_um: PerJoint::new(&minimum_norm[..ni]),
            not_determined: (0..ni)
                .filter(|&k| cal.estimate_um[k].is_none())
                .map(InstallationErrors::component_name)
                .collect(),
            effects: effect_estimates(model, cal),
            parameters: parameter_rows(model, cal),
            determination: DeterminationCounts::of(cal),
            known_effects: model
                .known_effects
                .iter()
                .map(|k| KnownEffectValues {
                    effect: k.effect.name().to_string(),
                    unit: k.effect.unit().to_string(),
                    values: k.values.clone(),
                })
                .collect(),
            residual_rms_um: (!weighted).then_some(cal.residual_rms_um),
            initial_rms_um: (!weighted).then_some(cal.initial_rms_um),
            residual_weighted: weighted,
            weighted_rms_in_sigma: cal.residual_rms_um / cal.sigma_um,
            initial_weighted_rms_in_sigma: cal.initial_rms_um / cal.sigma_um,
            sigma_um: (!weighted).then_some(cal.sigma_um),
            scale: FitScale {
                residual_rms: cal.residual_rms_um,
                initial_rms: cal.initial_rms_um,
                sigma: cal.sigma_um,
            },
            sigma_estimated: cal.sigma_estimated,
            sigma_excludes_outliers: cal.sigma_excludes_outliers,
            identifiability: IdentifiabilityReport::new(
                &cal.identifiability,
                &model.parameter_names(),
            ),
            solver: solver_report(cal),
            formulation: formulation.map(|f| f.key().to_string()),
            robust_loss: describe_loss(inputs.loss),
            robust: formulation.is_some().then_some(RobustReport {
                downweighted_share: cal.downweighted_share,
                downweight_level: cpm_calib::DOWNWEIGHT_LEVEL,
                max_downweighted_share: cpm_calib::MAX_DOWNWEIGHTED_SHARE,
                failed: cal.robust_failed,
            }),
            outliers: outliers(inputs, model, cal),
            excluded_poses: inputs
                .merged
                .excluded
                .iter()
                .map(ExcludedPoseReport::from)
                .collect(),
            registration: registration(inputs.merged, model, cal),
            misfit: misfit_report(cal, weighted),
            noise_by_kind: kinds
                .iter()
                .map(|k| NoiseKindReport {
                    kind: k.name.clone(),
                    unit: k.unit.clone(),
                    observations: k.observations,
                    degrees_of_freedom: k.redundancy,
                    assumed: k.assumed,
                    estimated: k.estimated,
                    rms: k.rms,
                    set_aside: k.set_aside,
                })
                .collect(),
            prior: prior::PriorReport::new(model, cal),
            tracker_residuals: (!campaign.pose_measurements.is_empty())
                .then(|| if cal.leg_space { "legs" } else { "pose" }.to_string()),
            warnings: warnings_md.iter().map(|w| w.replace("**", "")).collect(),
            text: fit_text(inputs, model, cal, formulation, warnings_md),
        }
    }

    /// `calibration.json`, pretty-printed (keys sorted, as every cpm JSON file).
    pub fn to_json(&self) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&serde_json::to_value(self)?)
    }

    /// The weighted residual RMS in sigma, or, for data fitted exactly (a residual below
    /// [`NUMERICAL_RESIDUAL_UM`](cpm_calib::analysis::diagnostics::NUMERICAL_RESIDUAL_UM),
    /// rounding), that: an estimated noise is then rounding too, and the ratio of two
    /// roundings (0.871 sigma for a zero residual) says nothing.
    pub fn weighted_rms_words(&self) -> String {
        if self.scale.residual_rms < cpm_calib::analysis::diagnostics::NUMERICAL_RESIDUAL_UM {
            "0 (the data are fitted exactly: the residual is rounding, below 1 pm)".to_string()
        } else {
            sig(self.weighted_rms_in_sigma, 3)
        }
    }

    /// The warnings as a markdown list (with the note on the noise estimate), then a blank line.
    pub fn markdown_warnings(&self, s: &mut String) {
        for w in &self.text.warnings {
            s.push_str(&format!("- {w}\n"));
        }
        if self.text.sigma_excludes_outliers_note {
            s.push_str("- The noise was estimated from the residuals without the flagged outliers (robust fit); the standard deviations use it.\n");
        }
        s.push('\n');
    }

    /// The report's sections on the fit: data and fit, what the data identify, estimates,
    /// outliers, tracker registration.
    pub fn markdown_sections(&self, s: &mut String) {
        let t = &self.text;
        s.push_str("## Data and fit\n\n");
        s.push_str(&format!(
            "- Robot: `{}` ({} links, {} sensors); clearance {} um per joint.\n",
            t.robot_file,
            t.links,
            t.sensors,
            short(t.clearance_um)
        ));
        // Every kind counted: the gauges and the tracker always, the others where present.
        let mut kinds = vec![
            format!("{} length readings", self.readings),
            format!("{} tracker pose measurements", self.pose_measurements),
        ];
        if self.point_measurements > 0 {
            kinds.push(format!(
                "{} reflector points ({} coordinates)",
                self.point_measurements,
                3 * self.point_measurements
            ));
        }
        if self.tilt_measurements > 0 {
            kinds.push(format!("{} inclinometer angles", self.tilt_measurements));
        }
        if self.instrument_measurements > 0 {
            kinds.push(format!(
                "{} measurements of one's own instruments",
                self.instrument_measurements
            ));
        }
        let last = kinds.pop().expect("two kinds at least");
        s.push_str(&format!(
            "- Data: {} and {last} at {} poses{}.\n",
            kinds.join(", "),
            self.poses,
            if self.simulated {
                " (**SIMULATED**)"
            } else {
                ""
            }
        ));
        s.push_str(&format!("- Model: {}.\n", t.model));
        s.push_str(&format!("- Loss: {}.\n", self.robust_loss));
        if self.residual_weighted {
            // Kinds weighed differently: the RMS of the mix is weighted; each kind in its unit.
            let list: Vec<String> = self
                .noise_by_kind
                .iter()
                .map(|k| {
                    format!(
                        "{} RMS {} {}{} (weighed as {} {}, its own residual says {}; {} degrees of freedom)",
                        k.kind,
                        sig(k.rms, 3),
                        k.unit,
                        if k.set_aside > 0 {
                            format!(" without the {} set aside", k.set_aside)
                        } else {
                            String::new()
                        },
                        sig(k.assumed, 3),
                        k.unit,
                        k.estimated
                            .map_or("n/a".to_string(), |e| format!("{} {}", sig(e, 3), k.unit)),
                        fixed(k.degrees_of_freedom, 1)
                    )
                })
                .collect();
            s.push_str(&format!(
                "- Weighted residual RMS {} (in sigma: each residual over its kind's noise at the fit's noise scale; at the start {}); noise scale {}.\n- Residual per kind of observation, in its own unit: {}.\n",
                self.weighted_rms_words(),
                sig(self.initial_weighted_rms_in_sigma, 3),
                if self.sigma_estimated {
                    "estimated from the residual"
                } else {
                    "declared"
                },
                list.join("; ")
            ));
        } else {
            s.push_str(&format!(
                "- Residual RMS {} um (at the start {} um); noise {} {} um.\n",
                sig(self.scale.residual_rms, 3),
                sig(self.scale.initial_rms, 3),
                if self.sigma_estimated {
                    "estimated from the residual:"
                } else {
                    "declared:"
                },
                if self.sigma_estimated {
                    sig(self.scale.sigma, 3)
                } else {
                    short(self.scale.sigma)
                }
            ));
            if self.noise_by_kind.len() > 1 {
                let list: Vec<String> = self
                    .noise_by_kind
                    .iter()
                    .map(|k| {
                        format!(
                            "{} {} -> {} {} ({} degrees of freedom)",
                            k.kind,
                            sig(k.assumed, 3),
                            k.estimated.map_or("n/a".to_string(), |e| sig(e, 3)),
                            k.unit,
                            fixed(k.degrees_of_freedom, 1)
                        )
                    })
                    .collect();
                s.push_str(&format!(
                    "- Noise per kind of observation, weighed as -> from its own residual: {}.\n",
                    list.join("; ")
                ));
            }
        }
        s.push_str(&format!(
            "- Solver: {}{}.\n\n",
            self.solver.summary,
            if self.solver.converged {
                ""
            } else {
                " — **did not converge: treat the estimates with suspicion**"
            }
        ));
        let id = &self.identifiability;
        s.push_str("## What the data identify\n\n");
        s.push_str(&format!(
            "Rank {} of {} from {} readings (threshold {} = rtol x s_max{}); the data alone see {} parameters on their own. Parameters: {} (see \"Estimates\").\n\n",
            id.rank,
            id.parameters,
            id.observations,
            crate::format::sci(id.threshold, 3),
            if id.scaled_singular_values.is_empty() {
                ""
            } else {
                ", on the Jacobian scaled per unit of parameters and per kind of observation so that the rank does not depend on units or weights"
            },
            id.determined,
            self.determination.words()
        ));
        if id.rank < id.parameters {
            let blind = id.parameters - id.rank;
            s.push_str(&format!(
                "{blind} blind direction{}:\n\n",
                if blind == 1 { "" } else { "s" }
            ));
            for b in &id.blind_directions {
                s.push_str(&format!("- {} ({} dim)\n", b.description, b.dimensions));
            }
            if id.unexplained_null_dimensions > 0 {
                s.push_str(&format!(
                    "- {} further combined directions (mixtures of several joints; see the null-space vectors)\n",
                    id.unexplained_null_dimensions
                ));
            }
        }
        s.push_str(&format!(
            "\nCramér-Rao bounds: {} over the determined parameters.\n\n",
            id.crlb_words(|v| sig(v, 3))
        ));
        if let Some(p) = &self.prior {
            p.markdown(s);
        }
        s.push_str("## Estimates\n\nEach parameter says what gives it its value: **determined** (the data determine it on their own; std = its Cramér-Rao bound), **held by tolerance** (the data alone do not determine it; the value is where the fit ends between the data and the tolerance, std = the posterior one: not a measurement), **held by user** (held at its nominal value), **blind** (neither the data nor a tolerance determine it: no estimate exists, `n.d.`, whatever a solver would print). Each value is rounded to two significant digits of its standard deviation. The numbers `#` match `estimates.svg`.\n\n| # | parameter | value | std | determination |\n|---|---|---|---|---|\n");
        let mut plotted = 0;
        for p in &t.parameters {
            let plots = matches!(
                p.determination,
                Determination::Determined | Determination::HeldByTolerance
            ) && p.estimate.is_some();
            let num = if plots {
                plotted += 1;
                plotted.to_string()
            } else {
                String::new()
            };
            let (v, sd) = opt_with_sd(p.estimate, p.std, 3);
            s.push_str(&format!(
                "| {num} | {} | {v} | {sd} | {} |\n",
                p.name, p.determination
            ));
        }
        s.push('\n');
        self.markdown_excluded(s);
        self.markdown_outliers(s);
        self.markdown_registration(s);
    }

    /// The poses left out, when any.
    fn markdown_excluded(&self, s: &mut String) {
        if self.excluded_poses.is_empty() {
            return;
        }
        s.push_str("## Poses left out\n\nThese poses were left out with all their observations: the machine cannot be there, or forward kinematics did not converge at them (at most one pose in 20 of a file, or of the fit, is left out so; more refuse the data). Check the log at these lines.\n\n| file:line | pose | why |\n|---|---|---|\n");
        for e in &self.excluded_poses {
            s.push_str(&format!(
                "| {}:{} | {} | {} |\n",
                e.file,
                e.line,
                e.label.replace('|', "\\|"),
                e.reason.replace('|', "\\|")
            ));
        }
        s.push('\n');
    }

    fn markdown_outliers(&self, s: &mut String) {
        if self.outliers.is_empty() {
            return;
        }
        let aside = self.outliers.iter().filter(|o| o.set_aside).count();
        s.push_str("## Outliers\n\nObservations whose residual is more than 5 robust standard deviations (1.4826 x MAD) from the median. ");
        if aside > 0 {
            s.push_str(&format!("The least-squares fit set {aside} of them, those more than 10 robust standard deviations off, aside (weight zero; `--keep-outliers` fits them) and continued without them; their residuals are those of the fit without them, and the noise estimate leaves them out. "));
        } else {
            s.push_str("With `--robust` their influence on the fit is limited. ");
        }
        s.push_str("Check the instrument log at these lines.\n\n| file:line | observation | residual | set aside |\n|---|---|---|---|\n");
        for o in &self.outliers {
            let set = if o.set_aside { "yes" } else { "no" };
            let r = match (o.residual, &o.unit) {
                (Some(v), Some(u)) => format!("{} {u}", fixed(v, 3)),
                _ => format!("{} um (weighted)", opt_fixed(o.residual_um, 3)),
            };
            match (&o.file, o.line, &o.what) {
                (Some(f), Some(l), Some(w)) => {
                    s.push_str(&format!("| {f}:{l} | {w} | {r} | {set} |\n"))
                }
                _ => s.push_str(&format!(
                    "| ? | observation {} | {r} | {set} |\n",
                    o.observation
                )),
            }
        }
        s.push('\n');
    }

    fn markdown_registration(&self, s: &mut String) {
        let Some(r) = &self.registration else {
            return;
        };
        s.push_str("## Tracker registration\n\n");
        if let Some(why) = &r.failure {
            s.push_str(&format!("The automatic registration of the tracker frames failed ({why}); the measured poses were used as logged.\n\n"));
            return;
        }
        s.push_str(&format!("Each tracker file (session) gets its own frame, found from the data against the nominal forward kinematics of its readings (closed form, then Gauss-Newton with one reading offset per link shared by the files); a frame that moves a measured position by more than {} mm, or offsets larger than that, are applied to the data before the fit, smaller ones are left to the fit. Standard deviations are scaled by the registration's variance factor ({}).\n\n", short(r.apply_threshold_mm), sig(r.variance_factor, 3)));
        s.push_str("| file | poses | translation, mm (sd) | rotation vector, deg (sd) | angle, deg | RMS before, mm | RMS after, mm | applied |\n|---|---|---|---|---|---|---|---|\n");
        let triple = |v: &[f64; 3], sd: &[f64; 3]| {
            (0..3)
                .map(|a| {
                    let (v, sd) = with_sd(v[a], sd[a]);
                    format!("{v} ({sd})")
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        for x in &r.sessions {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                x.file,
                x.poses,
                triple(&x.translation_mm, &x.translation_sd_mm),
                triple(&x.rotation_vector_deg, &x.rotation_sd_deg),
                fixed(x.rotation_angle_deg, 4),
                sig(x.rms_before_mm, 3),
                sig(x.rms_after_mm, 3),
                if x.applied { "yes" } else { "no (small)" }
            ));
        }
        s.push('\n');
        if r.offsets_estimated {
            s.push_str(&format!(
                "Link reading offsets (true length = logged length + offset), mm: {}; {}.\n\n",
                r.link_reading_offset_mm
                    .iter()
                    .zip(&r.link_reading_offset_sd_mm)
                    .enumerate()
                    .map(|(i, (o, sd))| {
                        let (o, sd) = with_sd(*o, *sd);
                        format!("link {} {o} +- {sd}", i + 1)
                    })
                    .collect::<Vec<_>>()
                    .join(", "),
                if r.offsets_applied {
                    "applied to the commanded lengths before the fit and folded into `calibrated.toml`"
                } else {
                    "not applied (small: left to `link_offset`)"
                }
            ));
        } else {
            s.push_str("Link reading offsets were not estimated (the poses cannot tell them from the frames).\n\n");
        }
        for (e, v) in [
            (Effect::TrackerFrame, &r.refined_by_fit.tracker_frame),
            (Effect::LinkOffset, &r.refined_by_fit.link_offset),
        ] {
            if let Some(v) = v {
                s.push_str(&format!(
                    "Refined by the fit, `{}` (on top of the registration): {}.\n\n",
                    e.name(),
                    v.iter()
                        .map(|p| match (p.value, p.std) {
                            (Some(v), Some(sd)) => {
                                let (v, sd) = with_sd(v, sd);
                                format!("{} {v} +- {sd}", p.name)
                            }
                            _ => format!("{} not determined", p.name),
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
        }
        if let Some(v) = &r.refined_by_fit.marker_frame {
            s.push_str(&format!(
                "The body the tracker measures, on the platform (`marker_frame`, written to `calibrated.toml`; the platform joints keep no common rigid motion when only tracker poses are fitted): {}.\n\n",
                v.iter()
                    .map(|p| match (p.value, p.std) {
                        (Some(v), Some(sd)) => {
                            let (v, sd) = with_sd(v, sd);
                            format!("{} {v} +- {sd}", p.name)
                        }
                        (Some(v), None) => format!("{} {v:.0} (by that convention)", p.name),
                        _ => format!("{} not determined", p.name),
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let gauge = &r.refined_by_fit.gauge_freedoms;
        if !gauge.is_empty() {
            s.push_str(&format!("Gauge freedoms of the refinement: {} (the fit determines the tracker frame only together with the installation errors; these directions are not determined).\n\n", gauge.join("; ")));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::find_artefact;

    #[test]
    fn markdown_rounds_to_the_deviation_and_shows_no_artefact() {
        let row = |name: &str, estimate: Option<f64>, std| ParameterRow {
            name: name.into(),
            determination: if estimate.is_some() {
                Determination::Determined
            } else {
                Determination::Blind
            },
            estimate,
            std,
        };
        let f = FitReport {
            residual_rms_um: Some(3.0000000000000004),
            initial_rms_um: Some(0.1 + 0.2),
            sigma_um: Some(1.0),
            scale: FitScale {
                residual_rms: 3.0000000000000004,
                initial_rms: 0.1 + 0.2,
                sigma: 1.0,
            },
            identifiability: IdentifiabilityReport {
                rank: 3,
                parameters: 4,
                crlb_rms_um: Some(-0.0),
                ..Default::default()
            },
            outliers: vec![Outlier {
                observation: 7,
                file: None,
                line: None,
                what: None,
                residual_um: Some(-0.00001),
                residual: None,
                unit: None,
                set_aside: false,
            }],
            text: FitText {
                clearance_um: 10.000000000000002,
                parameters: vec![
                    row("a [um]", Some(-0.00001), Some(0.02)),
                    row("b [um]", Some(12.34567), Some(1.5)),
                    row("c [um]", None, None),
                    row("d [um]", Some(0.1 + 0.2), None),
                ],
                ..Default::default()
            },
            ..Default::default()
        };
        let mut s = String::new();
        f.markdown_sections(&mut s);
        assert_eq!(find_artefact(&s), None, "{s}");
        for want in [
            "| 1 | a [um] | 0.000 | 0.020 |",
            "| 2 | b [um] | 12.3 | 1.5 |",
            "|  | c [um] | n.d. | n.d. |",
            "| 3 | d [um] | 0.300 | n.d. |",
            "Residual RMS 3.00 um (at the start 0.300 um); noise declared: 1 um",
            "clearance 10 um",
            "| ? | observation 7 | 0.000 um (weighted) | no |",
            "1 blind direction:",
        ] {
            assert!(s.contains(want), "{want:?} not in\n{s}");
        }
    }
}
