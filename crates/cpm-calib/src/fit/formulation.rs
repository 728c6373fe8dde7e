//! Which formulation a fit runs in: the nested one (forward kinematics inside
//! every residual, a dense Jacobian in the installation errors) for ordinary campaigns, the
//! implicit one (every pose an unknown, a sparse Schur-complement solve) for large ones.
//!
//! The nested formulation's dense Jacobian and its SVD grow as `readings x parameters`; the
//! implicit one's work and memory grow with the poses' blocks. Both give the same estimates
//! (to a small fraction of a standard deviation) on a campaign either can fit; the implicit
//! one takes length readings only, plain least squares, and no effect with a known value.
use crate::fit::identify::{identify, Calibration, IdentifyOptions};
use crate::fit::implicit::{identify_implicit_calibration, supported};
use crate::{CalibError, Campaign, MeasurementModel};

/// Campaigns with at least this many readings are fitted with the implicit formulation
/// (when it supports them); smaller ones with the nested one.
pub const IMPLICIT_FROM_READINGS: usize = 100_000;

/// A formulation of the calibration problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Formulation {
    /// Forward kinematics in the loop; the unknowns are the installation errors and effects.
    Nested,
    /// The actual poses are unknowns too; the pose blocks are eliminated by a Schur complement.
    Implicit,
}

impl Formulation {
    /// The name written to `calibration.json` (`formulation`).
    pub fn key(self) -> &'static str {
        match self {
            Formulation::Nested => "nested",
            Formulation::Implicit => "implicit",
        }
    }

    /// One sentence for report.md.
    pub fn describe(self) -> &'static str {
        match self {
            Formulation::Nested => {
                "nested (forward kinematics of every pose inside the fit; dense Jacobian in the installation errors)"
            }
            Formulation::Implicit => {
                "implicit (every pose an unknown beside the installation errors, commanded lengths as exact closures; pose blocks eliminated by a sparse Schur complement)"
            }
        }
    }
}

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

/// The residuals a fit to 6-D tracker poses runs on, chosen out of sample.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackerResidualChoice {
    /// True when the leg-space residuals were chosen.
    pub leg_space: bool,
    /// Cross-validated RMS of the pose-space fit (weighted, um of the reference).
    pub pose_cv_rms: f64,
    /// Cross-validated RMS of the leg-space fit, judged on the same held-out pose residuals.
    pub leg_cv_rms: f64,
    /// How the folds were made.
    pub folds: crate::fit::refine::FoldKind,
    /// How much better the leg-space fit predicted the held-out pose residuals: the
    /// difference of the mean squared errors (pose minus legs; weighted, um^2 of the
    /// reference), and its standard error over the held-out poses. Legs are chosen only when
    /// the difference is beyond it.
    #[serde(default)]
    pub legs_gain_um2: f64,
    /// The standard error of [`legs_gain_um2`](Self::legs_gain_um2) (0 when it cannot be
    /// told: one held-out pose).
    #[serde(default)]
    pub legs_gain_se_um2: f64,
}

/// Pose-space or leg-space residuals for a campaign of full tracker poses: each fitted on the
/// folds of [`crate::fit::refine::cv_folds`] (acquisition order, sessions or positions) and
/// judged on the held-out poses' residuals; legs win only when they predict them better by
/// more than the standard error of the difference (pose space otherwise). `None` when
/// the leg-space formulation does not apply ([`crate::model::leg_space_applies`]).
pub fn choose_tracker_residuals(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
    folds: usize,
) -> Result<Option<TrackerResidualChoice>, CalibError> {
    if !crate::model::leg_space_applies(campaign) {
        return Ok(None);
    }
    let start = options
        .start_um
        .clone()
        .unwrap_or_else(|| vec![0.0; model.num_params()]);
    let score = |leg: bool| {
        let o = IdentifyOptions {
            leg_space: leg,
            ..options.clone()
        };
        crate::fit::refine::cross_validated_errors(model, campaign, &o, folds, &start)
    };
    let (pose, leg) = (score(false)?, score(true)?);
    let (gain, se) = pose.gain_of(&leg).unwrap_or((0.0, None));
    Ok(Some(TrackerResidualChoice {
        // A difference within its standard error decides nothing: pose space, the residual
        // the tracker measures, stays.
        leg_space: pose.clearly_worse_than(&leg),
        pose_cv_rms: pose.rms(),
        leg_cv_rms: leg.rms(),
        folds: pose.kind,
        legs_gain_um2: gain,
        legs_gain_se_um2: se.unwrap_or(0.0),
    }))
}
