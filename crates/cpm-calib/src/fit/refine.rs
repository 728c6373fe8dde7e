//! Closing the loop: fit, study the residual, find the effect the model lacks, add it, refit,
//! and report the error before and after (in-sample and cross-validated).
//!
//! Each round tries every candidate [`Effect`] not yet in the model:
//! 1. **confounding**: the part of its Jacobian outside the column space of the current model
//!    (`novelty`, 0 = entirely explained by what is there, 1 = new); a pose map term below
//!    [`RefineOptions::min_novelty`] is skipped as confounded, a physical effect only below
//!    [`PHYSICAL_NOVELTY_FRACTION`] of it (a small novelty is a reason for care, not to skip);
//!    an effect that would confound present parameters with a blind direction (more than
//!    [`CONFOUNDED_FRACTION`] of one the data saw on its own) is refused;
//! 2. the augmented model is fitted, and scored by an F-test on the drop of the residual sum of
//!    squares per added identifiable dimension, and by the change of BIC
//!    (`m ln(RSS/m) + k ln m`);
//! 3. among those significant at `alpha / candidates` (Bonferroni) with negative delta BIC,
//!    physical effects first and pose map terms last, each in order of BIC, the first whose
//!    blocked cross-validated RMS ([`cross_validated_rms`]: leave one session out, or
//!    contiguous blocks in acquisition order) is lower than the current model's
//!    is added: an effect that fits the campaign better but predicts unseen poses worse (a
//!    spike it bends to) is never added. A candidate whose robust fit failed is not added.
//!
//! The observations the first fit flags as outliers ([`Refinement::outliers_before`]) are set
//! aside before any effect is chosen, unless they follow a physical candidate's signature
//! (its fit leaves them within the noise: [`Refinement::outliers_explained`]; clearance
//! flipping a link's shift looks like spikes to a model without it): the rounds (fits, tests, cross-validation) run on the
//! campaign without them, so no effect is bent to a spike. The final model is then fitted to
//! the whole campaign ([`Refinement::calibration`], which flags them again).
//!
//! **Pose error maps.** Each round the diagnostics also scan every pose map term up to
//! [`RefineOptions::pose_map_degree`] ([`crate::analysis::diagnostics::pose_map_scan`], a score test on
//! the residual); the terms significant at `alpha / (terms scanned)` (at most
//! [`RefineOptions::pose_map_proposals`], most significant first) join the round's candidates
//! and go through the same confounding check, F-test, BIC and cross-validation. The
//! Bonferroni correction of the round counts every scanned term. A model with a pose map
//! describes the poses it was fitted on only: [`Refinement::pose_range`] reports them.
//!
//! User effects ([`Effect::user`]) are candidates like the built-ins: list them in
//! [`RefineOptions::candidates`].
//!
//! Rounds stop when no candidate is significant, when the residual is white and consistent with
//! the declared noise, or after `max_steps`. What remains correlated with a regressor is
//! reported as unexplained structure, by name, rather than forced into an effect.
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use crate::analysis::diagnostics::{diagnose, regressors, ResidualDiagnostics};
use crate::model::{predict, Prepared};
use crate::{
    identify, CalibError, Calibration, Campaign, Effect, IdentifyOptions, MeasurementModel,
};

/// The null-space fraction of a parameter (the norm of its unit vector's projection on the
/// blind directions) above which a candidate effect counts as taking it from the data: such an
/// effect is refused. Smaller leaks (a pose map term sharing a thousandth to a hundredth of an
/// offset with the frame gauges) are left to the out-of-sample judgement.
pub const CONFOUNDED_FRACTION: f64 = 0.05;

/// Options of [`refine`].
#[derive(Debug, Clone)]
pub struct RefineOptions {
    /// Candidate effects. Default: the whole library.
    pub candidates: Vec<Effect>,
    /// Significance level (before the Bonferroni correction over candidates). Default 0.01.
    pub alpha: f64,
    /// Most effects added. Default 4.
    pub max_steps: usize,
    /// Folds of the cross-validation over poses. Default 5.
    pub folds: usize,
    /// Smallest fraction of a candidate's Jacobian outside the current model's column space for
    /// it to be tried. Default 0.02 (link offsets are typically ~0.01 against installation
    /// errors: a joint moved along its link is an offset but for the link's change of direction).
    pub min_novelty: f64,
    /// Highest degree of the pose map terms the diagnostics scan for and propose (0: none,
    /// at most 3). Default 2 (27 terms).
    pub pose_map_degree: u8,
    /// Most pose map terms proposed per round. Default 3.
    pub pose_map_proposals: usize,
    /// Identification options (declared noise in `sigma_um`).
    pub identify: IdentifyOptions,
    /// Groups of parameters refine may hold at nominal (`[calibration] hold`), each tried
    /// before any effect is added and held when the model without it predicts held-out data
    /// clearly better. Default `["installation_errors"]` (where the data see the joints worse
    /// than their effects, a model of the effects alone generalises better).
    pub hold_candidates: Vec<String>,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            candidates: Effect::ALL.to_vec(),
            alpha: 0.01,
            max_steps: 4,
            folds: 5,
            min_novelty: 0.02,
            pose_map_degree: 2,
            pose_map_proposals: 3,
            identify: IdentifyOptions::default(),
            hold_candidates: vec![crate::fit::prior::INSTALLATION_ERRORS.to_string()],
        }
    }
}

/// How a candidate fared in a round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateScore {
    /// The effect.
    pub effect: Effect,
    /// Fraction of its Jacobian outside the current model's column space.
    pub novelty: f64,
    /// F-test p-value (`None` when skipped as confounded or adding no identifiable dimension).
    pub p_value: Option<f64>,
    /// BIC change (negative: better).
    pub delta_bic: Option<f64>,
    /// RMS residual with the effect, um.
    pub rms_um: Option<f64>,
    /// Cross-validated RMS with the effect, um (computed for the candidates that passed the
    /// tests, in order of BIC, until one improved on the current model).
    #[serde(default)]
    pub cv_rms_um: Option<f64>,
    /// How many of the present parameters the effect would confound with a blind direction
    /// (null-space fraction above [`CONFOUNDED_FRACTION`]; `Some` only when it confounds
    /// some: the effect is then refused).
    #[serde(default)]
    pub determined_lost: Option<usize>,
    /// True when the data determine none of the effect's parameters better than its
    /// tolerance (each one's data share below
    /// [`MIN_DATA_SHARE`](crate::fit::prior::MIN_DATA_SHARE)): its fitted value would be
    /// mostly its prior, so it is refused whatever its fit.
    #[serde(default)]
    pub undetermined: bool,
}

/// One accepted refinement step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineStep {
    /// The effect added.
    pub effect: Effect,
    /// Its F-test p-value.
    pub p_value: f64,
    /// BIC change.
    pub delta_bic: f64,
    /// Residual RMS before and after, um.
    pub rms_before_um: f64,
    /// Residual RMS after, um.
    pub rms_after_um: f64,
    /// Cross-validated RMS before, um.
    pub cv_rms_before_um: f64,
    /// Cross-validated RMS after, um.
    pub cv_rms_after_um: f64,
    /// The effect's parameters: (name, estimate or `None` when not determined, std).
    pub parameters: Vec<(String, Option<f64>, Option<f64>)>,
    /// All candidates of the round.
    pub candidates: Vec<CandidateScore>,
}

/// The outcome of a refinement.
#[derive(Debug, Clone)]
pub struct Refinement {
    /// Accepted steps in order.
    pub steps: Vec<RefineStep>,
    /// The final model (declared effects plus those added).
    pub model: MeasurementModel,
    /// The final calibration.
    pub calibration: Calibration,
    /// Diagnostics of the first fit (without the outliers it flagged, as the effects are
    /// chosen).
    pub initial_diagnostics: ResidualDiagnostics,
    /// The first fit's residual RMS over every observation, um (weighted as that fit weighed
    /// them): computed as the final fit's [`Calibration::residual_rms_um`] is.
    pub initial_rms_um: f64,
    /// Diagnostics of the final fit.
    pub final_diagnostics: ResidualDiagnostics,
    /// Final cross-validated RMS, um.
    pub final_cv_rms_um: f64,
    /// Regressors the final residual still follows (no library effect explained them), and
    /// pose map terms it still follows (`pose map pose_map_y2`).
    pub unexplained_structure: Vec<String>,
    /// Residuals of the first fit, um (for plots): weighted as the first fit weighed them,
    /// predicted minus measured ([`Calibration::residuals_um`]).
    pub initial_residuals_um: Vec<f64>,
    /// The reference noise the first fit's residuals are weighted by, um
    /// ([`Calibration::sigma_ref_um`]): [`crate::noise::measured_minus_predicted`] gives them in
    /// their own units.
    pub initial_sigma_ref_um: f64,
    /// The candidates of the last round when it added nothing (empty when the rounds ended
    /// otherwise): which were skipped as confounded with the model (novelty below
    /// [`RefineOptions::min_novelty`]) and which were not significant.
    pub last_round: Vec<CandidateScore>,
    /// Observations the first fit flagged as outliers (more than 5 robust standard deviations
    /// off) and no physical candidate explained, before any effect was chosen; the rounds ran
    /// without them.
    pub outliers_before: Vec<usize>,
    /// First-fit outliers that followed a candidate's signature and were kept as signal:
    /// the physical effect whose fit left them within the noise, and how many it explained.
    pub outliers_explained: Option<(Effect, usize)>,
    /// Candidates that passed the F-test and BIC but were not added: (effect, CV RMS before,
    /// with it, um; the candidate of the same round that predicted held-out poses better, when
    /// one did: it lost to that one, not to the model).
    pub rejected_by_cv: Vec<(Effect, f64, f64, Option<Effect>)>,
    /// The pose map scan of the first fit's residual (empty when
    /// [`RefineOptions::pose_map_degree`] is 0), most significant first.
    pub initial_pose_structure: Vec<crate::analysis::diagnostics::PoseStructure>,
    /// The range of the commanded poses the final model was fitted on; a pose map term
    /// describes these poses only and does not extrapolate.
    pub pose_range: PoseRange,
    /// Plain calibration against refinement, judged on data the fits did not see.
    pub against_calibrate: AgainstCalibrate,
    /// The groups refine tried to hold at nominal, with their out-of-sample scores.
    pub hold_trials: Vec<HoldTrial>,
    /// The groups held (declared or chosen): the final fit keeps them at nominal.
    pub held_groups: Vec<String>,
}

/// A group of parameters refine tried to hold at nominal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HoldTrial {
    /// The group.
    pub group: String,
    /// Cross-validated RMS with the group fitted (weighted, um of the reference).
    pub cv_rms_fitted_um: f64,
    /// Cross-validated RMS with the group held.
    pub cv_rms_held_um: f64,
    /// True when held (clearly better out of sample).
    pub held: bool,
}

/// What [`choose_holds`] decided: the identification options with the groups held, the
/// trials, and the fits it made on the way that the rest of refine needs again (the same fits
/// of the same campaign give the same numbers: they are not made twice).
struct Holds {
    /// The options with the chosen groups held.
    identify: IdentifyOptions,
    /// The groups tried.
    trials: Vec<HoldTrial>,
    /// The fit with the chosen groups held (`None` when no trial was made).
    chosen: Option<Calibration>,
    /// The fit with nothing held but what was declared (`None` when no trial was made).
    declared: Option<Calibration>,
}

/// Refine's choice of groups to hold: each candidate group held in turn (on top of those
/// already held), kept when the fit without it predicts held-out data clearly better.
fn choose_holds(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &RefineOptions,
) -> Result<Holds, CalibError> {
    let mut opts = options.identify.clone();
    let mut trials = Vec::new();
    let mut declared: Option<Calibration> = None;
    if opts.tolerances.off || options.hold_candidates.is_empty() {
        return Ok(Holds {
            identify: opts,
            trials,
            chosen: None,
            declared,
        });
    }
    let np = model.num_params();
    let score = |o: &IdentifyOptions| -> Result<(Calibration, CvErrors), CalibError> {
        let c = identify(model, campaign, o)?;
        let cvo = IdentifyOptions {
            prior_noise_um: c.sigma_estimated.then_some(c.sigma_um),
            ..o.clone()
        };
        let e = cross_validated_errors(model, campaign, &cvo, options.folds, &vec![0.0; np])?;
        Ok((c, e))
    };
    let mut current: Option<(Calibration, CvErrors)> = None;
    for g in &options.hold_candidates {
        if opts.tolerances.hold.contains(g) {
            continue;
        }
        let mut held = opts.clone();
        held.tolerances.hold.push(g.clone());
        // A group this model does not have, or holding which leaves nothing to fit.
        if crate::fit::prior::prior_std(model, &held.tolerances).is_err() {
            continue;
        }
        if model.effects.is_empty() && g == crate::fit::prior::INSTALLATION_ERRORS {
            continue;
        }
        let base = match current.take() {
            Some(c) => c,
            None => {
                let first = score(&opts)?;
                declared = Some(first.0.clone());
                first
            }
        };
        let Ok(with) = score(&held) else {
            current = Some(base);
            continue;
        };
        let better = base.1.clearly_worse_than(&with.1);
        trials.push(HoldTrial {
            group: g.clone(),
            cv_rms_fitted_um: base.1.rms(),
            cv_rms_held_um: with.1.rms(),
            held: better,
        });
        if better {
            opts = held;
            current = Some(with);
        } else {
            current = Some(base);
        }
    }
    Ok(Holds {
        identify: opts,
        trials,
        chosen: current.map(|c| c.0),
        declared,
    })
}

/// Plain calibration (the starting model, as `cpm calibrate` fits it) against the refined
/// model, both scored by the same blocked cross-validation ([`cross_validated_rms`]: leave
/// one session out, or contiguous blocks in acquisition order) on the whole campaign, first-fit
/// outliers included. Refinement is only worth writing when it is not worse, and, once it
/// added an effect, clearly better ([`AgainstCalibrate::within_uncertainty`]).
///
/// Once an effect was added, contiguous blocks are at least [`GUARD_MIN_FOLDS`] here,
/// whatever the rounds used ([`RefineOptions::folds`]): each fit then keeps nine tenths of the
/// poses, close to the fit that is written. With fewer (`--folds 3` on 18 poses: fits on 12
/// poses) a model can look better only because the folds' fits are starved, and lose on the
/// next session.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AgainstCalibrate {
    /// The starting model's cross-validated RMS, um.
    pub calibrate_cv_rms_um: f64,
    /// The refined model's cross-validated RMS, um.
    pub refined_cv_rms_um: f64,
    /// The folds both were scored on (sessions, positions or contiguous blocks).
    pub folds: usize,
    /// The refined model added effects and is not worse, but its gain is within one standard
    /// error of the difference of the two models' held-out errors
    /// ([`CvErrors::clearly_worse_than`], the rule each round's choice passed on its own
    /// folds): the data do not show it predicts better, and it is refused as a worse one is.
    /// False when no effect was added.
    pub within_uncertainty: bool,
}

/// Fewest contiguous blocks of the final guard ([`AgainstCalibrate`]), fewer only when the
/// campaign has fewer poses (then one pose per fold).
pub const GUARD_MIN_FOLDS: usize = 10;

/// How many folds the final guard scores on once an effect was added: as many as the rounds'
/// own ([`cv_folds`] of the `folds` asked) when they leave out sessions or positions, or are at
/// least [`GUARD_MIN_FOLDS`] blocks; else that many blocks (at most one per pose). The count
/// is also what [`cv_folds`] is asked for: blocks are as many as asked, and sessions or
/// positions ignore it.
fn guard_folds(campaign: &Campaign, folds: usize) -> usize {
    let own = cv_folds(campaign, folds);
    if own.kind != FoldKind::Blocks || own.count >= GUARD_MIN_FOLDS {
        return own.count;
    }
    GUARD_MIN_FOLDS.min(campaign.poses.len()).max(own.count)
}

impl AgainstCalibrate {
    /// Relative margin within which the refined model counts as not worse (rounding of two
    /// fits of the same model).
    pub const TOLERANCE: f64 = 1e-9;

    /// Whether the refined model predicts held-out data at least as well as plain
    /// calibration.
    pub fn not_worse(&self) -> bool {
        self.refined_cv_rms_um <= self.calibrate_cv_rms_um * (1.0 + Self::TOLERANCE)
    }

    /// The refusal to state when the refined model is worse, or better only within the
    /// uncertainty (`None` when it is clearly better, or refine changed nothing). With
    /// `weighted_scale_um` (the final fit's noise scale when its residual mixes kinds weighed
    /// differently) the figures are said weighted, in sigma, never in um.
    pub fn refusal(&self, weighted_scale_um: Option<f64>) -> Option<String> {
        let figures = match weighted_scale_um.filter(|s| *s > 0.0) {
            Some(s) => format!(
                "blocked cross-validated RMS {:.4} against {:.4}, weighted, in sigma, over {} folds",
                self.refined_cv_rms_um / s,
                self.calibrate_cv_rms_um / s,
                self.folds
            ),
            None => format!(
                "blocked cross-validated RMS {:.4} um against {:.4} um over {} folds",
                self.refined_cv_rms_um, self.calibrate_cv_rms_um, self.folds
            ),
        };
        if !self.not_worse() {
            Some(format!(
                "the refined model predicts held-out data worse than plain calibration ({figures}): use `cpm calibrate`"
            ))
        } else if self.within_uncertainty {
            Some(format!(
                "the refined model predicts held-out data better than plain calibration only within the uncertainty of the difference ({figures}): the data do not show that its effects carry to another session; use `cpm calibrate`"
            ))
        } else {
            None
        }
    }
}

/// The range of a campaign's commanded poses: x, y, z (mm) and roll, pitch, yaw (deg).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseRange {
    /// Smallest x, y, z (mm), roll, pitch, yaw (deg).
    pub min: [f64; 6],
    /// Largest x, y, z (mm), roll, pitch, yaw (deg).
    pub max: [f64; 6],
}

impl PoseRange {
    /// The range of `campaign`'s poses.
    pub fn of(campaign: &Campaign) -> PoseRange {
        let mut r = PoseRange {
            min: [f64::INFINITY; 6],
            max: [f64::NEG_INFINITY; 6],
        };
        for p in &campaign.poses {
            let a = p.rpy_deg();
            let v = [
                p.position_mm.x,
                p.position_mm.y,
                p.position_mm.z,
                a[0],
                a[1],
                a[2],
            ];
            for i in 0..6 {
                r.min[i] = r.min[i].min(v[i]);
                r.max[i] = r.max[i].max(v[i]);
            }
        }
        r
    }

    /// True when `pose` lies inside the range (within `margin` mm and degrees).
    pub fn contains(&self, pose: &cpm_geometry::Pose, margin: f64) -> bool {
        let a = pose.rpy_deg();
        let v = [
            pose.position_mm.x,
            pose.position_mm.y,
            pose.position_mm.z,
            a[0],
            a[1],
            a[2],
        ];
        (0..6).all(|i| v[i] >= self.min[i] - margin && v[i] <= self.max[i] + margin)
    }
}

/// A residual RMS below this (um) is rounding, not a signal: no effect is added to explain it.
pub const RESIDUAL_FLOOR_UM: f64 = 1e-6;

/// A physical (library or user) effect is skipped as confounded only when its novelty is below
/// this fraction of [`RefineOptions::min_novelty`] (pose map terms: below `min_novelty`).
pub const PHYSICAL_NOVELTY_FRACTION: f64 = 0.05;

fn rss(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

fn bic(rss: f64, m: usize, k: f64) -> f64 {
    let m = m as f64;
    m * (rss / m).max(1e-300).ln() + k * m.ln()
}

/// Most candidates of a family (physical effects, pose map terms) cross-validated per round:
/// the best by BIC.
pub const CV_CANDIDATES: usize = 3;

/// The least number of effective parameters an effect must add to be tested (a block the
/// prior holds whole adds nothing the data determine).
const MIN_ADDED_DIMENSION: f64 = 0.5;

/// The parameters a fit used: its rank, or under a prior its effective number (trace of the
/// hat matrix).
fn params_used(c: &Calibration) -> f64 {
    c.prior
        .as_ref()
        .map_or(c.identifiability.rank as f64, |p| p.effective_params)
}

/// Cross-validated RMS (um) over folds that respect the order the data were taken in: with
/// two or more sessions ([`Campaign::session_starts`], a file each), one fold per session
/// (leave one session out); within one session, `folds` contiguous blocks of poses in
/// acquisition order. Each fold is fitted on the other poses and predicts its own
/// observations. Random or interleaved folds inside one sitting flatter effects that real
/// drift and frames defeat; blocked folds make a model predict poses it did not see, later.
/// A held-out tracker session is re-registered first (its six frame parameters fitted with
/// the machine held fixed, [`MeasurementModel::held_fixed`]) when the model estimates a
/// `tracker_frame`: a new session brings a new frame, as in `cpm validate`.
pub fn cross_validated_rms(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
    folds: usize,
    start: &[f64],
) -> Result<f64, CalibError> {
    let e = cross_validated_errors(model, campaign, options, folds, start)?;
    Ok((e.squared.iter().sum::<f64>() / e.squared.len().max(1) as f64).sqrt())
}

/// How the poses of a campaign are split into folds for cross-validation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FoldKind {
    /// One fold per measurement session (file): a new session brings a new set-up.
    Sessions,
    /// One fold per commanded XY position (leave-position-out): where the poses repeat at the
    /// same commanded positions (a tilt grid), a model must predict a position it never saw.
    Positions,
    /// Contiguous blocks in acquisition order.
    Blocks,
}

/// The fold scheme in words, for reports: `one fold per session (file)`,
/// `leave-position-out folds` or `contiguous blocks in acquisition order`.
impl std::fmt::Display for FoldKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FoldKind::Sessions => "one fold per session (file)",
            FoldKind::Positions => "leave-position-out folds (whole commanded positions left out)",
            FoldKind::Blocks => "contiguous blocks in acquisition order",
        })
    }
}

/// The folds of a cross-validation: their kind, count and each pose's fold.
#[derive(Debug, Clone, PartialEq)]
pub struct Folds {
    /// How the poses were split.
    pub kind: FoldKind,
    /// Number of folds.
    pub count: usize,
    /// The fold of each pose.
    pub fold_of_pose: Vec<usize>,
    /// The independent unit of each pose for the standard error of a comparison
    /// ([`CvErrors::clearly_worse_than`]): its commanded XY position in a leave-position-out
    /// split (poses at one position share its systematic error, so they are one unit), else
    /// the pose itself.
    pub unit_of_pose: Vec<usize>,
}

/// Most folds of a leave-position-out split: more positions are grouped, in order of first
/// visit, into this many folds (each fold leaves out whole positions).
const MAX_POSITION_FOLDS: usize = 6;

/// The folds of `campaign`: by session when it has several, by commanded XY position when
/// the poses repeat at a few positions (at least 3 positions, each visited at least twice on
/// average), else `folds` contiguous blocks in acquisition order. Never random: random folds
/// inside one sitting flatter effects that drift and set-ups defeat.
pub fn cv_folds(campaign: &Campaign, folds: usize) -> Folds {
    let n = campaign.poses.len().max(1);
    if !campaign.session_starts.is_empty() {
        let starts = &campaign.session_starts;
        return Folds {
            kind: FoldKind::Sessions,
            count: starts.len() + 1,
            fold_of_pose: (0..campaign.poses.len())
                .map(|p| starts.partition_point(|s| *s <= p))
                .collect(),
            unit_of_pose: (0..campaign.poses.len()).collect(),
        };
    }
    // Commanded XY positions, to 0.5 mm, in order of first appearance.
    let mut keys: Vec<(i64, i64)> = Vec::new();
    let group: Vec<usize> = campaign
        .poses
        .iter()
        .map(|p| {
            let k = (
                (p.position_mm.x * 2.0).round() as i64,
                (p.position_mm.y * 2.0).round() as i64,
            );
            match keys.iter().position(|x| *x == k) {
                Some(i) => i,
                None => {
                    keys.push(k);
                    keys.len() - 1
                }
            }
        })
        .collect();
    let g = keys.len();
    if g >= 3 && 2 * g <= campaign.poses.len() {
        let count = g.min(MAX_POSITION_FOLDS);
        return Folds {
            kind: FoldKind::Positions,
            count,
            fold_of_pose: group.iter().map(|&i| i * count / g).collect(),
            unit_of_pose: group,
        };
    }
    let folds = folds.max(2);
    Folds {
        kind: FoldKind::Blocks,
        count: folds,
        fold_of_pose: (0..campaign.poses.len()).map(|p| p * folds / n).collect(),
        unit_of_pose: (0..campaign.poses.len()).collect(),
    }
}

/// Out-of-sample errors of a model: the squared weighted error of every held-out observation
/// (um of the reference, squared), and the held-out pose each belongs to (a key unique over
/// the folds), in fold order.
#[derive(Debug, Clone, PartialEq)]
pub struct CvErrors {
    /// Squared weighted errors.
    pub squared: Vec<f64>,
    /// The independent unit of each ([`Folds::unit_of_pose`]: its held-out pose, or its
    /// commanded position in a leave-position-out split).
    pub pose: Vec<usize>,
    /// How the folds were made.
    pub kind: FoldKind,
}

impl CvErrors {
    /// Their root mean square, um of the reference.
    pub fn rms(&self) -> f64 {
        (self.squared.iter().sum::<f64>() / self.squared.len().max(1) as f64).sqrt()
    }

    /// True when `other` predicts the held-out data better than `self` by more than one
    /// standard error of the difference of their mean squared errors (the poses, or the
    /// positions of a leave-position-out split, as the independent units): a candidate
    /// chosen among many on a small campaign must beat the current model clearly, not by the
    /// luck of the folds.
    pub fn clearly_worse_than(&self, other: &CvErrors) -> bool {
        match self.gain_of(other) {
            Some((gain, Some(se))) => gain > se,
            Some((gain, None)) => gain > 0.0,
            None => false,
        }
    }

    /// How much better `other` predicts the held-out data than `self`: the difference of
    /// their mean squared errors (positive: `other` better) and its standard error over the
    /// poses (or positions) as the independent units (`None` with fewer than two). `None`
    /// when the two were not judged on the same observations.
    pub fn gain_of(&self, other: &CvErrors) -> Option<(f64, Option<f64>)> {
        if self.squared.len() != other.squared.len() || self.squared.is_empty() {
            return None;
        }
        let n = self.squared.len() as f64;
        let mut by_pose = std::collections::BTreeMap::<usize, f64>::new();
        for ((a, b), p) in self.squared.iter().zip(&other.squared).zip(&self.pose) {
            *by_pose.entry(*p).or_default() += a - b;
        }
        let per_pose: Vec<f64> = by_pose.into_values().collect();
        let np = per_pose.len() as f64;
        let gain = per_pose.iter().sum::<f64>() / n;
        if np < 2.0 {
            return Some((gain, None));
        }
        let mean = per_pose.iter().sum::<f64>() / np;
        let var = per_pose.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (np - 1.0);
        Some((gain, Some((np * var).sqrt() / n)))
    }
}

/// The out-of-sample errors of `model` on `campaign` ([`cv_folds`]): each fold fitted on the
/// others and predicted (a held-out tracker session re-registered first, as `cpm validate`
/// does).
pub fn cross_validated_errors(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
    folds: usize,
    start: &[f64],
) -> Result<CvErrors, CalibError> {
    let split = cv_folds(campaign, folds);
    let fold_of = |p: usize| split.fold_of_pose[p];
    let mut out = CvErrors {
        squared: Vec::new(),
        pose: Vec::new(),
        kind: split.kind,
    };
    // The folds' fits are independent: in parallel, gathered in fold order.
    let per_fold: Vec<Option<FoldErrors>> = (0..split.count)
        .into_par_iter()
        .map(|f| fold_errors(model, campaign, options, start, &|p| fold_of(p) == f))
        .collect::<Result<_, _>>()?;
    // The held-out campaigns keep the poses' numbering (`filter_poses`).
    for (sq, pose) in per_fold.into_iter().flatten() {
        out.squared.extend(sq);
        out.pose
            .extend(pose.into_iter().map(|p| split.unit_of_pose[p]));
    }
    Ok(out)
}

/// A fold's squared errors and their poses (numbered as in the whole campaign).
type FoldErrors = (Vec<f64>, Vec<usize>);

/// One fold of a cross-validation: fitted without the poses `held`, the squared weighted
/// errors of the held-out observations and their poses (numbered as in `campaign`); `None`
/// for an empty fold.
fn fold_errors(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
    start: &[f64],
    held: &(dyn Fn(usize) -> bool + Sync),
) -> Result<Option<FoldErrors>, CalibError> {
    {
        let train = campaign.filter_poses(|p| !held(p));
        let test = campaign.filter_poses(held);
        if test.is_empty() || train.is_empty() {
            return Ok(None);
        }
        let opts = IdentifyOptions {
            start_um: Some(start.to_vec()),
            ..options.clone()
        };
        let cal = identify(model, &train, &opts)?;
        // A held-out session of a tracker whose frame the model estimates is registered
        // afresh against the machine held fixed, as `validate` does: its frame is the
        // session's, not the machine's.
        let reregister = !campaign.session_starts.is_empty()
            && !test.pose_measurements.is_empty()
            && model.effects.contains(&Effect::TrackerFrame);
        let y = if reregister {
            let mut test = test.clone();
            model.log_commands(&mut test);
            let machine = model.held_fixed(&cal.minimum_norm_um)?;
            crate::fit::session::register_session(&machine, &test)?.predicted
        } else {
            let prepared = Prepared::new(model, &test)?;
            predict(model, &prepared, &test, &cal.minimum_norm_um, None)?
        };
        let w = test.observation_weights(test.reference_sigma(options.sigma_um));
        let mut sq = Vec::with_capacity(y.len());
        let mut pose = Vec::with_capacity(y.len());
        for (k, ((yk, mk), wk)) in y.iter().zip(test.observations()).zip(w).enumerate() {
            sq.push(((yk - mk) * 1e3 * wk).powi(2));
            pose.push(test.observation_pose(k));
        }
        Ok(Some((sq, pose)))
    }
}

/// The campaign without the observations `drop` (indices of [`Campaign::observations`]): a
/// reading is left out, a tracker pose measurement when any of its six observations is, a
/// point (an instrument) measurement when any of its values is.
fn without_observations(campaign: &Campaign, drop: &[usize]) -> Campaign {
    if drop.is_empty() {
        return campaign.clone();
    }
    let mut c = campaign.clone();
    let mut k = 0;
    c.readings.retain(|_| {
        k += 1;
        drop.binary_search(&(k - 1)).is_err()
    });
    let kept: Vec<bool> = campaign
        .pose_observation_rows()
        .iter()
        .map(|rows| !rows.iter().flatten().any(|o| drop.binary_search(o).is_ok()))
        .collect();
    c.retain_pose_measurements(&kept);
    let p0 = campaign.first_point_observation();
    let mut q = 0;
    c.point_measurements.retain(|_| {
        q += 1;
        let first = p0 + 3 * (q - 1);
        !(first..first + 3).any(|o| drop.binary_search(&o).is_ok())
    });
    let t0 = campaign.first_tilt_observation();
    let mut q = 0;
    c.tilt_measurements.retain(|_| {
        q += 1;
        drop.binary_search(&(t0 + q - 1)).is_err()
    });
    let rows = campaign.instrument_observation_rows();
    let mut q = 0;
    c.instrument_measurements.retain(|m| {
        q += 1;
        let first = rows[q - 1];
        !(first..first + m.values.len()).any(|o| drop.binary_search(&o).is_ok())
    });
    c
}

fn with_effect(model: &MeasurementModel, e: Effect) -> MeasurementModel {
    let mut m = model.clone();
    m.effects.push(e);
    m
}

/// Start vector of an augmented model: the current estimate, zeros for the new block.
fn extend_start(current: &[f64], augmented: &MeasurementModel) -> Vec<f64> {
    let mut s = current.to_vec();
    s.resize(augmented.num_params(), 0.0);
    s
}

/// Fraction of the new block's Jacobian outside the identifiable column space of the rest.
fn novelty(
    augmented: &MeasurementModel,
    campaign: &Campaign,
    at: &[f64],
    old_params: usize,
    rank_rtol: f64,
) -> Result<f64, CalibError> {
    let prepared = Prepared::new(augmented, campaign)?;
    let mut j = nalgebra::DMatrix::zeros(campaign.len(), augmented.num_params());
    predict(augmented, &prepared, campaign, at, Some(&mut j))?;
    let old = j.columns(0, old_params).into_owned();
    let new = j.columns(old_params, j.ncols() - old_params).into_owned();
    let norm = new.norm();
    if norm == 0.0 {
        return Ok(0.0);
    }
    let (sv, u, _) = crate::linalg::thin_svd(&old)?;
    let smax = sv.first().copied().unwrap_or(0.0);
    let keep: Vec<usize> = (0..sv.len())
        .filter(|&i| sv[i] > rank_rtol * smax)
        .collect();
    let ur = u.select_columns(&keep);
    let outside = &new - &ur * (ur.transpose() * &new);
    Ok(outside.norm() / norm)
}

/// Observations set aside, and the effect that explained the others (with their count).
type SetAside = (Vec<usize>, Option<(Effect, usize)>);

/// The first fit's outliers, less those that follow a physical candidate's signature.
///
/// Residuals the first model cannot follow (joint clearance flipping a link's shift where its
/// force changes sign, a backlash step) look like outliers of that model; setting them aside
/// would remove the very signal `refine` is looking for. Each physical candidate is fitted to
/// the whole campaign; the one whose own fit leaves the fewest of the flagged observations
/// outlying explains the others, which are kept. Returns the observations to set aside and
/// the explaining effect with the count it explained.
fn outliers_or_signal(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &RefineOptions,
    first: &Calibration,
) -> Result<SetAside, CalibError> {
    let flagged = &first.outliers;
    if flagged.is_empty() {
        return Ok((Vec::new(), None));
    }
    let mut best: Option<(Effect, Vec<usize>)> = None;
    let tried: Vec<Effect> = options
        .candidates
        .iter()
        .copied()
        .filter(|e| !matches!(e, Effect::PoseMap(_)) && !model.effects.contains(e))
        .collect();
    // The candidates' fits are independent: in parallel, taken in order.
    let fits: Vec<Option<Calibration>> = tried
        .par_iter()
        .map(|&e| {
            let aug = with_effect(model, e);
            let opts = IdentifyOptions {
                start_um: Some(extend_start(&first.minimum_norm_um, &aug)),
                prior_noise_um: first.sigma_estimated.then_some(first.sigma_um),
                ..options.identify.clone()
            };
            identify(&aug, campaign, &opts).ok()
        })
        .collect();
    for (&e, cal) in tried.iter().zip(fits) {
        // A candidate the data cannot fit (no readings for a sensor effect) explains nothing.
        let Some(cal) = cal else {
            continue;
        };
        let left: Vec<usize> = flagged
            .iter()
            .copied()
            .filter(|k| cal.outliers.binary_search(k).is_ok())
            .collect();
        if best.as_ref().is_none_or(|(_, b)| left.len() < b.len()) {
            best = Some((e, left));
        }
    }
    Ok(match best {
        Some((e, left)) if left.len() < flagged.len() => {
            let explained = flagged.len() - left.len();
            (left, Some((e, explained)))
        }
        _ => (flagged.clone(), None),
    })
}

/// Runs the refinement loop on a campaign, starting from `model` (its declared effects):
/// first the groups to hold ([`RefineOptions::hold_candidates`]), then the effects, each
/// choice judged out of sample.
pub fn refine(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &RefineOptions,
) -> Result<Refinement, CalibError> {
    // A cancelled candidate fit only fails that candidate: the flag decides at the end.
    let cancel = &options.identify.cancel;
    crate::fit::identify::check_cancel(cancel)?;
    let refined = refine_uncancelled(model, campaign, options);
    crate::fit::identify::check_cancel(cancel)?;
    refined
}

fn refine_uncancelled(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &RefineOptions,
) -> Result<Refinement, CalibError> {
    if !(options.alpha > 0.0 && options.alpha < 1.0) {
        return Err(CalibError::invalid(
            "alpha",
            format!("{} must be in (0, 1)", options.alpha),
        ));
    }
    let holds = choose_holds(model, campaign, options)?;
    let hold_trials = holds.trials;
    let held = RefineOptions {
        identify: holds.identify,
        ..options.clone()
    };
    let mut r = refine_effects(model, campaign, &held, holds.chosen)?;
    if hold_trials.iter().any(|t| t.held) {
        // Plain calibration is the model with nothing held but what was declared.
        let c = match holds.declared {
            Some(c) => c,
            None => identify(model, campaign, &options.identify)?,
        };
        let o = IdentifyOptions {
            prior_noise_um: c.sigma_estimated.then_some(c.sigma_um),
            ..options.identify.clone()
        };
        if r.steps.is_empty() {
            // Holds alone, each judged clearly better on the rounds' folds: plain calibration
            // on the same folds.
            r.against_calibrate.calibrate_cv_rms_um = cross_validated_rms(
                model,
                campaign,
                &o,
                r.against_calibrate.folds,
                &c.minimum_norm_um,
            )?;
        } else {
            // The refined model holds what plain calibration fits: never unchanged.
            r.against_calibrate = against_calibrate_on(
                (model, &c, &o),
                &r.model,
                &r.calibration,
                false,
                campaign,
                options,
                r.against_calibrate.folds,
            )?;
        }
    }
    r.held_groups = held.identify.tolerances.hold.clone();
    r.hold_trials = hold_trials;
    Ok(r)
}

/// The rounds of effects on top of `model` (its fit with `options.identify` given as `first`
/// when already made).
fn refine_effects(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &RefineOptions,
    first: Option<Calibration>,
) -> Result<Refinement, CalibError> {
    let first = match first {
        Some(c) => c,
        None => identify(model, campaign, &options.identify)?,
    };
    let (outliers_before, outliers_explained) =
        outliers_or_signal(model, campaign, options, &first)?;
    let full = campaign;
    let reduced = without_observations(campaign, &outliers_before);
    let rounds = Rounds {
        campaign: &reduced,
        options,
        m: reduced.len(),
    };
    let mut current = model.clone();
    let mut cal = if outliers_before.is_empty() {
        first.clone()
    } else {
        identify(&current, &reduced, &options.identify)?
    };
    let initial_residuals_um = first.residuals_um.clone();
    let initial_sigma_ref_um = first.sigma_ref_um;
    let initial_diagnostics = rounds.diagnostics(&current, &cal)?;
    let mut diag = initial_diagnostics.clone();
    let mut cv_err = cross_validated_errors(
        &current,
        &reduced,
        &cv_options(options, &cal),
        options.folds,
        &cal.minimum_norm_um,
    )?;
    let mut cv = cv_err.rms();
    let initial_cv = cv;
    let mut rejected_by_cv = Vec::new();
    let initial_pose_structure = rounds.scan(&current, &cal)?;
    let mut pose_structure = initial_pose_structure.clone();
    let mut steps = Vec::new();
    let mut last_round = Vec::new();
    for _ in 0..options.max_steps {
        if diag.white && diag.consistent_with_noise == Some(true) && diag.significant.is_empty() {
            break;
        }
        let (remaining, level) = rounds.proposals(&current, &pose_structure);
        if remaining.is_empty() {
            break;
        }
        let (mut scores, eligible) = rounds.screen(&current, &cal, remaining, level)?;
        let best = rounds.judge(&mut scores, eligible, &cv_err, cv, &mut rejected_by_cv)?;
        let Some((i, aug, c1, cv1, e1)) = best else {
            last_round = scores;
            break;
        };
        steps.push(refine_step(&aug, &c1, i, scores, &cal, cv, cv1));
        current = aug;
        cal = c1;
        cv = cv1;
        cv_err = e1;
        diag = rounds.diagnostics(&current, &cal)?;
        pose_structure = rounds.scan(&current, &cal)?;
    }
    let unexplained_structure = unexplained_structure(&diag, &pose_structure, options.alpha);
    // The final model on the whole campaign (residuals and outliers for every observation),
    // its noise estimated with it.
    let cal = if outliers_before.is_empty() && steps.is_empty() {
        cal
    } else {
        let opts = IdentifyOptions {
            start_um: Some(cal.minimum_norm_um.clone()),
            ..options.identify.clone()
        };
        identify(&current, full, &opts)?
    };
    // Plain calibration against the refined model on the whole campaign, as a user's next
    // session would judge them (the rounds above scored the campaign without its outliers, and
    // perhaps on fewer blocks than the guard's).
    let folds = if steps.is_empty() {
        cv_folds(full, options.folds).count
    } else {
        guard_folds(full, options.folds)
    };
    let against_calibrate = if outliers_before.is_empty() && steps.is_empty() {
        AgainstCalibrate {
            calibrate_cv_rms_um: initial_cv,
            refined_cv_rms_um: cv,
            folds,
            within_uncertainty: false,
        }
    } else {
        against_calibrate_on(
            (model, &first, &cv_options(options, &first)),
            &current,
            &cal,
            steps.is_empty(),
            full,
            options,
            folds,
        )?
    };
    Ok(Refinement {
        steps,
        model: current,
        calibration: cal,
        initial_diagnostics,
        initial_rms_um: first.residual_rms_um,
        final_diagnostics: diag,
        final_cv_rms_um: cv,
        unexplained_structure,
        initial_residuals_um,
        initial_sigma_ref_um,
        last_round,
        outliers_before,
        outliers_explained,
        rejected_by_cv,
        initial_pose_structure,
        pose_range: PoseRange::of(full),
        against_calibrate,
        hold_trials: Vec::new(),
        held_groups: Vec::new(),
    })
}

/// The options of the fits inside the folds: the prior weighed against the noise of `c`,
/// the whole campaign's (not estimated again on each fold).
fn cv_options(options: &RefineOptions, c: &Calibration) -> IdentifyOptions {
    IdentifyOptions {
        prior_noise_um: c.sigma_estimated.then_some(c.sigma_um),
        ..options.identify.clone()
    }
}

/// A candidate that passed the screening: its index in the round's scores, the augmented
/// model and its fit.
type Eligible = (usize, MeasurementModel, Calibration);

/// The candidate a round adds: its index in the scores, the augmented model, its fit, its
/// cross-validated RMS and errors.
type Chosen = (usize, MeasurementModel, Calibration, f64, CvErrors);

/// What the rounds of [`refine_effects`] work on: the campaign without the first fit's
/// outliers (`m` observations) and the options.
struct Rounds<'a> {
    campaign: &'a Campaign,
    options: &'a RefineOptions,
    m: usize,
}

impl Rounds<'_> {
    /// The residual diagnostics of the fit `cal` of `mdl`.
    fn diagnostics(
        &self,
        mdl: &MeasurementModel,
        cal: &Calibration,
    ) -> Result<ResidualDiagnostics, CalibError> {
        let prepared = Prepared::new(mdl, self.campaign)?;
        let regs = regressors(mdl, &prepared, self.campaign);
        Ok(diagnose(
            &cal.residuals_um,
            self.m.saturating_sub(cal.identifiability.rank),
            self.options.identify.sigma_um,
            &regs,
            self.options.alpha,
        ))
    }

    /// The pose map scan of the residual of `cal` (none when pose maps are off).
    fn scan(
        &self,
        mdl: &MeasurementModel,
        cal: &Calibration,
    ) -> Result<Vec<crate::analysis::diagnostics::PoseStructure>, CalibError> {
        let options = self.options;
        if options.pose_map_degree == 0 {
            return Ok(Vec::new());
        }
        crate::analysis::diagnostics::pose_map_scan(
            mdl,
            self.campaign,
            &cal.minimum_norm_um,
            &cal.residuals_um,
            options.identify.sigma_um,
            options.pose_map_degree,
            options.identify.rank.rank_rtol,
            options.min_novelty,
        )
    }

    /// The round's candidates: the library's effects not in `current`, then the pose map
    /// terms the scan finds significant (Bonferroni over every scanned term); and the
    /// round's significance level (Bonferroni over library and scanned terms).
    fn proposals(
        &self,
        current: &MeasurementModel,
        pose_structure: &[crate::analysis::diagnostics::PoseStructure],
    ) -> (Vec<Effect>, f64) {
        let options = self.options;
        let mut remaining: Vec<Effect> = options
            .candidates
            .iter()
            .copied()
            .filter(|e| !current.effects.contains(e))
            .collect();
        let scanned = pose_structure.len();
        let library = remaining.len();
        for s in pose_structure
            .iter()
            .filter(|s| s.p_value < options.alpha / scanned as f64)
            .take(options.pose_map_proposals)
        {
            if !remaining.contains(&s.effect) {
                remaining.push(s.effect);
            }
        }
        (remaining, options.alpha / (library + scanned).max(1) as f64)
    }

    /// Screens the candidates `remaining` against the current fit `cal` of `current`:
    /// novelty, fit, F-test and BIC at `level`, the determined parameters kept. Returns every
    /// candidate's score and those eligible for the cross-validation.
    fn screen(
        &self,
        current: &MeasurementModel,
        cal: &Calibration,
        remaining: Vec<Effect>,
        level: f64,
    ) -> Result<(Vec<CandidateScore>, Vec<Eligible>), CalibError> {
        let (options, campaign, m) = (self.options, self.campaign, self.m);
        let rss0 = rss(&cal.residuals_um);
        let k0 = params_used(cal);
        let bic0 = bic(rss0, m, k0);
        let mut scores = Vec::new();
        let mut eligible: Vec<Eligible> = Vec::new();
        // Every candidate's novelty and fit, in parallel (independent), then judged in order.
        let tried: Vec<(f64, Option<Calibration>)> = remaining
            .par_iter()
            .map(|&e| -> Result<(f64, Option<Calibration>), CalibError> {
                let aug = with_effect(current, e);
                let start = extend_start(&cal.minimum_norm_um, &aug);
                let nov = novelty(
                    &aug,
                    campaign,
                    &start,
                    current.num_params(),
                    options.identify.rank.rank_rtol,
                )?;
                if nov < novelty_threshold(options, e) {
                    return Ok((nov, None));
                }
                // Screened with the prior weighed against the current fit's noise (the
                // accepted model is fitted again at the end with its own).
                let opts = IdentifyOptions {
                    start_um: Some(start),
                    prior_noise_um: cal.sigma_estimated.then_some(cal.sigma_um),
                    ..options.identify.clone()
                };
                Ok((nov, identify(&aug, campaign, &opts).ok()))
            })
            .collect::<Result<_, _>>()?;
        for (e, (nov, fitted)) in remaining.into_iter().zip(tried) {
            let aug = with_effect(current, e);
            let mut score = CandidateScore {
                effect: e,
                novelty: nov,
                p_value: None,
                delta_bic: None,
                rms_um: None,
                cv_rms_um: None,
                determined_lost: None,
                undetermined: false,
            };
            if nov < novelty_threshold(options, e) {
                scores.push(score);
                continue;
            }
            let Some(c1) = fitted else {
                scores.push(score);
                continue;
            };
            let k1 = params_used(&c1);
            let rss1 = rss(&c1.residuals_um);
            score.rms_um = Some(c1.residual_rms_um);
            // The parameters a fit used: its rank, or under a prior its effective number
            // (a direction the prior holds costs no degree of freedom).
            if k1 > k0 + MIN_ADDED_DIMENSION && (m as f64) > k1 + 1.0 && rss1 > 0.0 {
                let dk = k1 - k0;
                let f = ((rss0 - rss1).max(0.0) / dk) / (rss1 / (m as f64 - k1));
                let p = FisherSnedecor::new(dk, m as f64 - k1)
                    .map(|d| d.sf(f))
                    .unwrap_or(1.0);
                let db = bic(rss1, m, k1) - bic0;
                score.p_value = Some(p);
                score.delta_bic = Some(db);
                // An effect that confounds present parameters with a blind direction (a
                // sizeable part of a parameter the data saw on its own moves along it) makes
                // the model less useful, whatever its fit: refused. A leak below
                // [`CONFOUNDED_FRACTION`] is not a reason: the cross-validation judges it.
                // Compared like with like: a parameter either fit holds at its tolerance
                // limit is held in both (holding one pins the blind directions it spans, so a
                // fit that needs fewer holds would otherwise look as if it lost what they
                // pinned).
                let np0 = current.num_params();
                let held = held_in_either(cal, &c1);
                let determined = |c: &Calibration| {
                    let f = null_fraction_holding(&c.identifiability, &held);
                    f[..np0.min(f.len())]
                        .iter()
                        .enumerate()
                        .filter(|(k, x)| **x <= CONFOUNDED_FRACTION && !held.contains(k))
                        .count()
                };
                let (before, after) = (determined(cal), determined(&c1));
                let loses = after < before;
                if loses {
                    score.determined_lost = Some(before - after);
                }
                // An effect the data determine no better than its tolerance adds its prior,
                // not a measurement (issue 32: a direction is kept only where its standard
                // deviation is below the tolerance): refused.
                score.undetermined = undetermined_effect(&aug, e, &c1);
                // A residual at rounding level has nothing left to explain: the F-test on it
                // measures floating-point noise.
                let explainable = cal.residual_rms_um > RESIDUAL_FLOOR_UM;
                // Only the candidates that pass the screening are cross-validated (a
                // cross-validation is a fit per fold; the others' would only be reported).
                if p < level
                    && db < 0.0
                    && !c1.robust_failed
                    && !loses
                    && !score.undetermined
                    && explainable
                {
                    eligible.push((scores.len(), aug, c1));
                }
            }
            scores.push(score);
        }
        Ok((scores, eligible))
    }

    /// Out of sample decides: every eligible candidate of a family (physical effects first,
    /// in order of BIC, pose map terms only when no physical effect helps) is
    /// cross-validated, and the one that predicts held-out poses best is chosen if it beats
    /// the current model (errors `cv_err`, RMS `cv`) clearly (by more than a standard error
    /// of the difference). The others judged go to `rejected_by_cv`.
    fn judge(
        &self,
        scores: &mut [CandidateScore],
        mut eligible: Vec<Eligible>,
        cv_err: &CvErrors,
        cv: f64,
        rejected_by_cv: &mut Vec<(Effect, f64, f64, Option<Effect>)>,
    ) -> Result<Option<Chosen>, CalibError> {
        let options = self.options;
        // Physics first: every physical effect (in order of BIC) before any pose map term,
        // which fits anything smooth and extrapolates nothing.
        eligible.sort_by(|a, b| {
            let key = |i: usize| {
                (
                    matches!(scores[i].effect, Effect::PoseMap(_)),
                    scores[i].delta_bic.unwrap_or(f64::INFINITY),
                )
            };
            let (ka, kb) = (key(a.0), key(b.0));
            ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
        });
        let mut best = None;
        let (physical, maps): (Vec<_>, Vec<_>) = eligible
            .into_iter()
            .partition(|(i, _, _)| !matches!(scores[*i].effect, Effect::PoseMap(_)));
        for mut family in [physical, maps] {
            if best.is_some() || family.is_empty() {
                continue;
            }
            // The best few by BIC are judged (a cross-validation is a fit per fold).
            family.truncate(CV_CANDIDATES);
            let judged: Vec<CvErrors> = family
                .par_iter()
                .map(|(_, aug, c1)| {
                    cross_validated_errors(
                        aug,
                        self.campaign,
                        &cv_options(options, c1),
                        options.folds,
                        &c1.minimum_norm_um,
                    )
                })
                .collect::<Result<_, _>>()?;
            let mut pick: Option<usize> = None;
            for (f, ((i, _, _), e1)) in family.iter().zip(&judged).enumerate() {
                scores[*i].cv_rms_um = Some(e1.rms());
                if pick.is_none_or(|b| e1.rms() < judged[b].rms()) {
                    pick = Some(f);
                }
            }
            let b = pick.expect("a non-empty family");
            let winner = scores[family[b].0].effect;
            let mut judged: Vec<Option<CvErrors>> = judged.into_iter().map(Some).collect();
            for (f, (i, aug, c1)) in family.into_iter().enumerate() {
                let e1 = judged[f].take().expect("judged once");
                let cv1 = e1.rms();
                if f == b && cv_err.clearly_worse_than(&e1) {
                    best = Some((i, aug, c1, cv1, e1));
                } else {
                    let lost_to = (f != b).then_some(winner);
                    rejected_by_cv.push((scores[i].effect, cv, cv1, lost_to));
                }
            }
        }
        Ok(best)
    }
}

/// The parameters `a` or `b` holds at its tolerance limit (`b` may have more parameters than
/// `a`: the current model's come first), sorted.
fn held_in_either(a: &Calibration, b: &Calibration) -> Vec<usize> {
    let mut held: Vec<usize> = a
        .held_at_limit
        .iter()
        .chain(&b.held_at_limit)
        .copied()
        .collect();
    held.sort_unstable();
    held.dedup();
    held
}

/// Each parameter's null-space fraction (as [`Identifiability::null_fraction`]) when the
/// parameters `held` are held as well: the blind directions that leave every held parameter
/// where it is (`N Z`, with `Z` the null space of the held rows of the null-space basis `N`).
/// A held parameter itself counts as blind (1). Without holds: the fit's own fractions.
///
/// [`Identifiability::null_fraction`]: crate::analysis::identifiability::Identifiability::null_fraction
fn null_fraction_holding(
    ident: &crate::analysis::identifiability::Identifiability,
    held: &[usize],
) -> Vec<f64> {
    let held: Vec<usize> = held
        .iter()
        .copied()
        .filter(|k| *k < ident.num_params)
        .collect();
    let d = ident.num_params - ident.rank;
    if held.is_empty() || d == 0 || ident.v.ncols() != ident.num_params {
        return ident.null_fraction.clone();
    }
    let null = ident.null_space();
    // The held rows, padded to at least d rows so that the SVD's V is complete.
    let mut a = nalgebra::DMatrix::zeros(held.len().max(d), d);
    for (r, &k) in held.iter().enumerate() {
        a.row_mut(r).copy_from(&null.row(k));
    }
    let Ok((sv, z)) = crate::linalg::svd_values_and_v(&a) else {
        return ident.null_fraction.clone();
    };
    // The rows are parts of orthonormal vectors: a singular value below 1e-9 is zero.
    let r = sv.iter().filter(|s| **s > 1e-9).count();
    let kept = &null * z.columns(r, d - r);
    (0..ident.num_params)
        .map(|k| {
            if held.contains(&k) {
                1.0
            } else {
                kept.row(k).norm()
            }
        })
        .collect()
}

/// True when the data determine none of `e`'s parameters in `fitted`: each one with a
/// tolerance has a data share below [`MIN_DATA_SHARE`](crate::fit::prior::MIN_DATA_SHARE)
/// ([`PriorSummary::determined`](crate::fit::prior::PriorSummary::determined)), and each
/// free one is left mixed in a blind direction (`n.d.`: a pose map term along the frames'
/// gauge freedoms was accepted with all six parameters n.d.). A parameter with a tolerance
/// that the data supply most of counts as seen even where the data alone leave it mixed (the
/// rank-deficient inclinometer data see compliance so).
fn undetermined_effect(model: &MeasurementModel, e: Effect, fitted: &Calibration) -> bool {
    let Some(block) = model.blocks().into_iter().find(|b| b.effect == Some(e)) else {
        return false;
    };
    let seen = |k: usize| match fitted.prior.as_ref() {
        Some(p) if matches!(p.prior_std.get(k), Some(Some(t)) if *t > 0.0 && t.is_finite()) => {
            p.determined(k)
        }
        _ => fitted.estimate_um.get(k).copied().flatten().is_some(),
    };
    block.len > 0 && !(block.offset..block.offset + block.len).any(seen)
}

/// The novelty below which a candidate is not fitted: a physical effect with a small novelty
/// is tried with care (only a numerically confounded one is skipped); a pose map term must be
/// clearly new.
fn novelty_threshold(options: &RefineOptions, e: Effect) -> f64 {
    if matches!(e, Effect::PoseMap(_)) {
        options.min_novelty
    } else {
        options.min_novelty * PHYSICAL_NOVELTY_FRACTION
    }
}

/// The step that adds candidate `i` (model `aug`, fit `c1`, cross-validated RMS `cv1`) to
/// the current fit `cal` (cross-validated RMS `cv`).
fn refine_step(
    aug: &MeasurementModel,
    c1: &Calibration,
    i: usize,
    scores: Vec<CandidateScore>,
    cal: &Calibration,
    cv: f64,
    cv1: f64,
) -> RefineStep {
    let names = aug.parameter_names();
    let block = *aug.blocks().last().expect("augmented block");
    let parameters = (block.offset..block.offset + block.len)
        .map(|k| (names[k].clone(), c1.estimate_um[k], c1.std_um[k]))
        .collect();
    RefineStep {
        effect: scores[i].effect,
        p_value: scores[i].p_value.unwrap_or(f64::NAN),
        delta_bic: scores[i].delta_bic.unwrap_or(f64::NAN),
        rms_before_um: cal.residual_rms_um,
        rms_after_um: c1.residual_rms_um,
        cv_rms_before_um: cv,
        cv_rms_after_um: cv1,
        parameters,
        candidates: scores,
    }
}

/// What the final residual still follows, by name: the diagnostics' significant regressors
/// and the pose map terms significant at `alpha` (Bonferroni over the scanned terms), or the
/// acquisition order when only whiteness fails; nothing when the residual is white and
/// consistent with the noise.
fn unexplained_structure(
    diag: &ResidualDiagnostics,
    pose_structure: &[crate::analysis::diagnostics::PoseStructure],
    alpha: f64,
) -> Vec<String> {
    if diag.consistent_with_noise == Some(true) && diag.white {
        return Vec::new();
    }
    let mut u = diag.significant.clone();
    // Pose map terms the final residual still follows (not added: steps exhausted, or
    // they did not pass the tests).
    let scanned = pose_structure.len().max(1) as f64;
    u.extend(
        pose_structure
            .iter()
            .filter(|s| s.p_value < alpha / scanned)
            .map(|s| format!("pose map {}", s.effect.name())),
    );
    if u.is_empty() && !diag.white {
        u.push("acquisition order".to_string());
    }
    u
}

/// Plain calibration (`plain`: its model, its fit and the options of its folds' fits)
/// against the refined model (`current`, its fit `cal`, with effects added; the same when
/// `unchanged`) cross-validated on the whole campaign `full` over `folds` ([`guard_folds`]
/// once an effect was added, else the rounds' own). Only an added effect can be
/// `within_uncertainty`: holds alone were each judged clearly better already, and the
/// callers judge them apart.
fn against_calibrate_on(
    plain: (&MeasurementModel, &Calibration, &IdentifyOptions),
    current: &MeasurementModel,
    cal: &Calibration,
    unchanged: bool,
    full: &Campaign,
    options: &RefineOptions,
    folds: usize,
) -> Result<AgainstCalibrate, CalibError> {
    let (model, first, first_options) = plain;
    let before = cross_validated_errors(model, full, first_options, folds, &first.minimum_norm_um)?;
    if unchanged {
        return Ok(AgainstCalibrate {
            calibrate_cv_rms_um: before.rms(),
            refined_cv_rms_um: before.rms(),
            folds,
            within_uncertainty: false,
        });
    }
    let after = cross_validated_errors(
        current,
        full,
        &cv_options(options, cal),
        folds,
        &cal.minimum_norm_um,
    )?;
    Ok(AgainstCalibrate {
        calibrate_cv_rms_um: before.rms(),
        refined_cv_rms_um: after.rms(),
        folds,
        within_uncertainty: !before.clearly_worse_than(&after),
    })
}

#[cfg(test)]
mod tests {
    /// The gain of one set of held-out errors over another comes with its standard error
    /// over the poses: a difference within it is not "clearly" better (the tracker residuals'
    /// choice and refine's candidates decide on it).
    #[test]
    fn a_gain_within_its_standard_error_decides_nothing() {
        use super::{CvErrors, FoldKind};
        let errors = |squared: Vec<f64>| CvErrors {
            pose: (0..squared.len()).collect(),
            squared,
            kind: FoldKind::Blocks,
        };
        let a = errors(vec![4.0, 5.0, 6.0, 7.0]);
        // Better on every pose by 0.5: a gain of 0.5, standard error 0.
        let b = errors(vec![3.5, 4.5, 5.5, 6.5]);
        let (gain, se) = a.gain_of(&b).unwrap();
        assert!((gain - 0.5).abs() < 1e-12 && se.unwrap() < 1e-12);
        assert!(a.clearly_worse_than(&b));
        // Better on average by 0.25, but by +-3 per pose: within its standard error.
        let c = errors(vec![1.0, 8.0, 3.0, 9.0]);
        let (gain, se) = a.gain_of(&c).unwrap();
        assert!(
            (gain - 0.25).abs() < 1e-12 && se.unwrap() > gain,
            "{gain} {se:?}"
        );
        assert!(!a.clearly_worse_than(&c));
        // Not judged on the same observations: no gain at all.
        assert!(a.gain_of(&errors(vec![1.0])).is_none());
    }
    use super::{AgainstCalibrate, CvErrors, FoldKind};

    /// Holding a parameter pins the blind directions it spans: with `p0 + p1` and `p2` seen,
    /// `p0` and `p1` are half blind (`(1, -1, 0, 0)` unseen) and `p3` wholly; holding `p0`
    /// leaves `p1` determined, holding `p3` changes nothing else.
    #[test]
    fn holding_a_parameter_determines_what_it_pinned() {
        use super::null_fraction_holding;
        use crate::analysis::identifiability::{analyze, RankOptions};
        use nalgebra::DMatrix;
        let j = DMatrix::from_row_slice(2, 4, &[1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let ident = analyze(&j, 1.0, &RankOptions::default(), &[]);
        assert_eq!(ident.rank, 2);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(close(
            &null_fraction_holding(&ident, &[]),
            &[h, h, 0.0, 1.0]
        ));
        let f0 = null_fraction_holding(&ident, &[0]);
        assert!(close(&f0, &[1.0, 0.0, 0.0, 1.0]), "{f0:?}");
        let f3 = null_fraction_holding(&ident, &[3]);
        assert!(close(&f3, &[h, h, 0.0, 1.0]), "{f3:?}");
        // An index beyond the parameters (a candidate's own) is ignored.
        assert!(close(
            &null_fraction_holding(&ident, &[7]),
            &[h, h, 0.0, 1.0]
        ));
    }

    /// A grid visiting 3 positions 4 times each is split leaving positions out, each pose's
    /// unit its position; poses that never repeat are split in blocks, each pose its own unit.
    #[test]
    fn a_repeated_grid_is_split_by_position_with_positions_as_units() {
        use super::cv_folds;
        use crate::Campaign;
        use cpm_geometry::Pose;
        use nalgebra::{Rotation3, Vector3};
        let at = |x: f64, y: f64, roll: f64| {
            Pose::new(
                Vector3::new(x, y, 500.0),
                Rotation3::from_euler_angles(roll, 0.0, 0.0),
            )
        };
        let grid = [(0.0, 0.0), (100.0, 0.0), (0.0, 100.0)];
        let mut tilts = Campaign::default();
        for k in 0..4 {
            for (x, y) in grid {
                tilts.poses.push(at(x, y, 0.01 * k as f64));
            }
        }
        let folds = cv_folds(&tilts, 5);
        assert_eq!(folds.kind, FoldKind::Positions);
        assert_eq!(folds.count, 3);
        assert_eq!(folds.unit_of_pose, [0, 1, 2].repeat(4));
        assert_eq!(folds.fold_of_pose, folds.unit_of_pose);
        let mut walk = Campaign::default();
        for k in 0..12 {
            walk.poses.push(at(10.0 * k as f64, 0.0, 0.0));
        }
        let folds = cv_folds(&walk, 4);
        assert_eq!(folds.kind, FoldKind::Blocks);
        assert_eq!(folds.unit_of_pose, (0..12).collect::<Vec<_>>());
    }

    /// Two of three positions favour the candidate, one disfavours it: counted pose by pose
    /// (30 independent units) the gain is clear, counted position by position (3 units, the
    /// poses of one position sharing its error) it is within a standard error.
    #[test]
    fn positions_not_poses_are_the_units_of_a_leave_position_out_comparison() {
        let gain: Vec<f64> = (0..30).map(|i| if i < 20 { 2.0 } else { -1.5 }).collect();
        let current = |pose: Vec<usize>, kind| CvErrors {
            squared: gain.iter().map(|d| 10.0 + d).collect(),
            pose,
            kind,
        };
        let candidate = |pose: Vec<usize>, kind| CvErrors {
            squared: vec![10.0; 30],
            pose,
            kind,
        };
        let by_pose: Vec<usize> = (0..30).collect();
        let by_position: Vec<usize> = (0..30).map(|i| i / 10).collect();
        assert!(current(by_pose.clone(), FoldKind::Blocks)
            .clearly_worse_than(&candidate(by_pose, FoldKind::Blocks)));
        assert!(!current(by_position.clone(), FoldKind::Positions)
            .clearly_worse_than(&candidate(by_position, FoldKind::Positions)));
    }

    /// An effect whose every parameter the data determine worse than its tolerance is
    /// undetermined (refine refuses it); the same effect with its default tolerance, which the
    /// designed campaign determines far better, is not.
    #[test]
    fn an_effect_the_data_see_worse_than_its_tolerance_is_undetermined() {
        use super::undetermined_effect;
        use crate::paper::{designed_sensors, random_workspace_poses};
        use crate::{
            identify, simulate, Effect, IdentifyOptions, MeasurementModel, Plan, SimulationOptions,
            Tolerances,
        };
        let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
        model.nominal.sensors = designed_sensors();
        model.effects = vec![Effect::LinkOffset];
        let plan = Plan {
            poses: random_workspace_poses(&model.nominal, 30, 100.0, 25.0, 3.0, 3),
            sensors: (0..model.nominal.sensors.len()).collect(),
        };
        let data = simulate(
            &model,
            &vec![0.0; model.num_params()],
            &plan,
            &SimulationOptions::default(),
        )
        .unwrap();
        let fit = |tolerance: Option<f64>| {
            let mut t = Tolerances::default();
            if let Some(v) = tolerance {
                t.set("link_offset", v).unwrap();
            }
            identify(
                &model,
                &data,
                &IdentifyOptions {
                    tolerances: t,
                    sigma_um: Some(1.0),
                    ..IdentifyOptions::default()
                },
            )
            .unwrap()
        };
        assert!(!undetermined_effect(&model, Effect::LinkOffset, &fit(None)));
        // A tolerance of a thousandth of a micrometre: the data (about a micrometre) supply
        // almost none of its determination.
        assert!(undetermined_effect(
            &model,
            Effect::LinkOffset,
            &fit(Some(1e-3))
        ));
        // An effect the model does not have is not judged.
        assert!(!undetermined_effect(&model, Effect::LinkScale, &fit(None)));
    }

    #[test]
    fn a_refined_model_worse_than_calibration_is_refused() {
        let worse = AgainstCalibrate {
            calibrate_cv_rms_um: 378.0,
            refined_cv_rms_um: 3330.0,
            folds: 5,
            within_uncertainty: false,
        };
        assert!(!worse.not_worse());
        let why = worse.refusal(None).unwrap();
        assert!(why.contains("3330.0000 um against 378.0000 um"), "{why}");
        let better = AgainstCalibrate {
            calibrate_cv_rms_um: 378.0,
            refined_cv_rms_um: 377.0,
            folds: 5,
            within_uncertainty: false,
        };
        assert!(better.not_worse() && better.refusal(None).is_none());
        // Not worse, but better only within the uncertainty of the difference: refused too.
        let unclear = AgainstCalibrate {
            within_uncertainty: true,
            folds: 10,
            ..better
        };
        let why = unclear.refusal(None).unwrap();
        assert!(
            why.contains("only within the uncertainty") && why.contains("over 10 folds"),
            "{why}"
        );
        // A weighted residual (angles beside lengths): in sigma, never in um.
        let why = worse.refusal(Some(2.0)).unwrap();
        assert!(
            why.contains("1665.0000 against 189.0000, weighted, in sigma") && !why.contains(" um"),
            "{why}"
        );
        // Rounding between two fits of the same model is not "worse".
        let same = AgainstCalibrate {
            calibrate_cv_rms_um: 1.0,
            refined_cv_rms_um: 1.0 + 1e-12,
            folds: 5,
            within_uncertainty: false,
        };
        assert!(same.not_worse());
    }
}
