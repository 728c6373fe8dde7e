//! Rank-aware identification of the installation errors (the cost of eq. 16 with cpm-lm).
//!
//! The fit is done in the identifiable subspace only: with `V_r` the identifiable directions
//! of the Jacobian at the start, the errors are `e = e_0 + V_r theta` and Levenberg-Marquardt
//! minimises `F = 1/2 sum_j (y_j(e) - y_j^measured)^2` over `theta`. Blind directions are left
//! at their start value (zero: the nominal), so the estimate is the minimum-norm solution, and
//! only parameters the data determine on their own are reported as estimates.
use cpm_lm::{DenseJacobian, ModelError, Problem};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::analysis::identifiability::{
    physical_patterns, try_analyze_scaled, Identifiability, RankOptions, RankScaling,
};
pub use crate::fit::prior::Tolerances;
use crate::fit::prior::{prior_std, summarize_with_covariance, Determination, PriorSummary};
use crate::model::{predict, Prepared};
use crate::{CalibError, Campaign, Effect, MeasurementModel};

/// Options of [`identify`]. The default: cpm-lm's defaults, default rank thresholds, noise
/// estimated from the residual, start at the nominal geometry, every group's default
/// tolerance as its prior ([`crate::fit::prior`]).
#[derive(Debug, Clone, Default)]
pub struct IdentifyOptions {
    /// A-priori tolerances per group of parameters and the groups held at their start: the
    /// prior of the maximum a posteriori fit ([`crate::fit::prior`]). Default: every group's
    /// default tolerance, nothing held; [`Tolerances::none`] is the plain least-squares fit.
    pub tolerances: Tolerances,
    /// The noise (weighted, um of the reference) the prior is weighed against when the noise is
    /// not declared: set it to a full fit's estimate to fit a part of the same campaign (a
    /// cross-validation fold) without estimating it again. Default `None`: estimated with the
    /// fit.
    pub prior_noise_um: Option<f64>,
    /// Fit 6-D tracker poses in leg space ([`crate::model::leg_residuals`]: each link's
    /// effective length against the length the joints need for the measured pose, um) rather
    /// than in pose space; the reported residuals, noise and standard deviations stay in pose
    /// space (what `calibrated.toml` reproduces). Applies only where
    /// [`crate::model::leg_space_applies`]; ignored elsewhere. Default false.
    pub leg_space: bool,
    /// Least-squares options (damping strategy etc.). Default: cpm-lm's defaults (the trust-region damping, [`cpm_lm::Damping::TrustRegion`]).
    pub lm: cpm_lm::Options,
    /// Rank thresholds. Default [`RankOptions::default`].
    pub rank: RankOptions,
    /// Sensor noise standard deviation, um, if known; otherwise estimated from the residual.
    pub sigma_um: Option<f64>,
    /// Start values of the installation errors, um. Default zero (the nominal geometry).
    pub start_um: Option<Vec<f64>>,
    /// Keep gross outliers in a least-squares fit. Default false: observations more than
    /// [`SET_ASIDE_SIGMAS`] robust standard deviations off (per kind,
    /// [`crate::analysis::diagnostics::outliers_by_kind_beyond`]) are set aside (weight zero) and the fit is continued without them, until the set
    /// settles ([`MAX_SET_ASIDE_ROUNDS`]); they stay in the residuals, flagged
    /// ([`Calibration::set_aside`]). Ignored with a robust loss (which limits their
    /// influence itself) and in leg space.
    pub keep_outliers: bool,
    /// Set by the caller to stop the fit: checked at every evaluation of the residuals and
    /// the Jacobian inside the least-squares iterations, after which [`identify`] returns
    /// [`CalibError::Cancelled`]. Default `None`: never cancelled.
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

/// [`CalibError::Cancelled`] when `cancel` is set.
pub(crate) fn check_cancel(
    cancel: &Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
) -> Result<(), CalibError> {
    match cancel {
        Some(c) if c.load(std::sync::atomic::Ordering::Relaxed) => Err(CalibError::Cancelled),
        _ => Ok(()),
    }
}

/// Most rounds of setting gross outliers aside ([`IdentifyOptions::keep_outliers`]).
pub const MAX_SET_ASIDE_ROUNDS: usize = 3;

/// Robust standard deviations of its kind beyond which a least-squares fit sets an
/// observation aside ([`IdentifyOptions::keep_outliers`]): twice the line at which outliers
/// are flagged, so that what is set aside is a gross error (a glitch, a slipped ballbar), not
/// the tail of a misfit the model could still learn (judged on the real inclinometer session:
/// at 5 the refined model predicted held-out positions 17 % worse).
pub const SET_ASIDE_SIGMAS: f64 = 10.0;

/// An identifiable combination `v^T e` of the installation errors and its estimate.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Combination {
    /// Singular value of the direction (um of reading per um of error, over the campaign).
    pub singular_value: f64,
    /// Estimate of `v^T e`, um.
    pub estimate_um: f64,
    /// Its standard deviation, um.
    pub std_um: f64,
    /// The largest loadings: (parameter index, coefficient).
    pub loadings: Vec<(usize, f64)>,
}

/// The result of an identification.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// True when the data were simulated.
    pub simulated: bool,
    /// Estimate per parameter, um; `None` where the data do not determine it.
    pub estimate_um: Vec<Option<f64>>,
    /// Standard deviation per parameter, um; `None` where not determined.
    pub std_um: Vec<Option<f64>>,
    /// The minimum-norm solution (determined parts plus identifiable combinations, blind
    /// directions at zero), um. Use for compensation, never report its undetermined entries as
    /// measured values.
    pub minimum_norm_um: Vec<f64>,
    /// Identifiable combinations with their estimates.
    pub combinations: Vec<Combination>,
    /// Identifiability at the solution (sigma as used for the bounds).
    pub identifiability: Identifiability,
    /// Noise standard deviation used for the standard deviations, um.
    pub sigma_um: f64,
    /// True when `sigma_um` was estimated from the residual (not declared).
    pub sigma_estimated: bool,
    /// True when the estimate left the flagged outliers out: with a robust loss the fit does
    /// not follow them, so their residuals would inflate the noise and every standard
    /// deviation.
    pub sigma_excludes_outliers: bool,
    /// Residuals (predicted - measured) at the solution, um.
    pub residuals_um: Vec<f64>,
    /// Observations whose residual is more than 5 robust standard deviations from the median
    /// (flagged whatever the loss; a robust loss also limits their influence).
    pub outliers: Vec<usize>,
    /// Observations set aside by a least-squares fit (weight zero: gross outliers,
    /// [`IdentifyOptions::keep_outliers`]), sorted; their residuals are in `residuals_um` at
    /// their full weight, and the noise estimate leaves them out.
    pub set_aside: Vec<usize>,
    /// RMS residual at the start, um.
    pub initial_rms_um: f64,
    /// RMS residual at the solution, um.
    pub residual_rms_um: f64,
    /// The solver's report (of the last stage: the robust loss itself).
    pub solver: cpm_lm::Report,
    /// Share of the observations a robust loss down-weighted below weight
    /// [`DOWNWEIGHT_LEVEL`] at the solution (0 for least squares).
    pub downweighted_share: f64,
    /// True when a robust fit ignored most of the data (more than
    /// [`MAX_DOWNWEIGHTED_SHARE`] of the observations down-weighted): the fit has failed
    /// whatever the solver says; [`Calibration::robust_failure`] says why.
    pub robust_failed: bool,
    /// The noise, um, that every residual is weighted to (tracker and instrument residuals
    /// are scaled by `sigma_ref_um` over their own noise; readings by 1).
    pub sigma_ref_um: f64,
    /// The leverage of each observation (diagonal of the hat matrix of the weighted
    /// Jacobian in the identifiable subspace, [`crate::noise`]); empty when not computed.
    pub leverages: Vec<f64>,
    /// What the prior did (`None` for a fit without one, [`Tolerances::none`]): per parameter
    /// the prior and posterior standard deviations and the data's share, and the directions
    /// held near nominal because the data see them less well than their tolerance.
    pub prior: Option<PriorSummary>,
    /// The a-priori standard deviation of every parameter from its group's tolerance (model
    /// units; 0 for a held group, infinite free); the parameters held at their limit are in
    /// `held_at_limit`.
    pub prior_std: Vec<f64>,
    /// The parameters the data pulled beyond [`Tolerances::limit`] tolerances, held there (at
    /// the limit, with the sign they were pulled to) in the final fit: not measured, named in
    /// the report (sorted indices).
    pub held_at_limit: Vec<usize>,
    /// The limit applied, in tolerances ([`Tolerances::limit`]; infinite: none).
    pub tolerance_limit: f64,
    /// True when the 6-D tracker poses were fitted in leg space
    /// ([`IdentifyOptions::leg_space`]); the residuals here are in pose space either way.
    pub leg_space: bool,
    /// The covariance of the parameters at the solution (model units squared; parameters x
    /// parameters), as [`crate::promise::parameter_covariance`] defines it: under a prior the
    /// posterior the summary reports, without one the Cramér-Rao covariance over the fit's
    /// rank; zero along what neither the data nor a tolerance bounds. Empty (0 x 0) when the
    /// fit did not form it (the implicit formulation).
    pub covariance: DMatrix<f64>,
}

/// The weight `rho'(r^2)` below which a robust loss is said to down-weight an observation.
pub const DOWNWEIGHT_LEVEL: f64 = 0.5;

/// The largest share of down-weighted observations of a robust fit that is not failed: a fit
/// that ignores more than half of its data describes the rest, not the machine.
pub const MAX_DOWNWEIGHTED_SHARE: f64 = 0.5;

impl Calibration {
    /// Why the fit failed although the solver stopped normally (a robust loss ignoring most of
    /// the data), or `None`.
    pub fn robust_failure(&self) -> Option<String> {
        self.robust_failed.then(|| {
            format!(
                "the robust fit ignored most of the data: {:.0} % of the observations were down-weighted below weight {DOWNWEIGHT_LEVEL} (at most {:.0} % allowed); the loss scale K is too small for these residuals (residual RMS {:.3} um)",
                100.0 * self.downweighted_share,
                100.0 * MAX_DOWNWEIGHTED_SHARE,
                self.residual_rms_um
            )
        })
    }

    /// True when the solver stopped normally and a robust fit did not ignore most of the data.
    pub fn succeeded(&self) -> bool {
        self.solver.was_successful() && !self.robust_failed
    }

    /// What gives parameter `k` its value ([`Determination`]): the data, a tolerance, the
    /// user's hold, or nothing.
    pub fn determination(&self, k: usize) -> Determination {
        let at_limit = self.held_at_limit.binary_search(&k).is_ok();
        let held = self.prior_std.get(k) == Some(&0.0)
            || self
                .prior
                .as_ref()
                .is_some_and(|p| p.prior_std.get(k) == Some(&Some(0.0)));
        if held && !at_limit {
            Determination::HeldByUser
        } else if self.estimate_um.get(k).copied().flatten().is_some() {
            Determination::Determined
        } else if at_limit
            || self
                .prior
                .as_ref()
                .is_some_and(|p| p.posterior_std.get(k).copied().flatten().is_some())
        {
            Determination::HeldByTolerance
        } else {
            Determination::Blind
        }
    }

    /// Parameter `k`'s value and the standard deviation that goes with its determination:
    /// determined, the estimate and its Cramér-Rao bound; held by tolerance, the fitted value
    /// (the one every command applies) and its posterior standard deviation; held by user,
    /// the held value and 0; blind, none (model units: um, ppm, ...).
    pub fn value_and_std(&self, k: usize) -> (Option<f64>, Option<f64>) {
        let fitted = self.minimum_norm_um.get(k).copied();
        match self.determination(k) {
            Determination::Determined => (self.estimate_um[k], self.std_um[k]),
            Determination::HeldByTolerance => (
                fitted,
                self.prior
                    .as_ref()
                    .and_then(|p| p.posterior_std.get(k).copied().flatten()),
            ),
            Determination::HeldByUser => (fitted, Some(0.0)),
            Determination::Blind => (None, None),
        }
    }

    /// How many parameters each [`Determination`] has, in [`Determination::ALL`]'s order.
    pub fn determination_counts(&self) -> [usize; 4] {
        let mut n = [0; 4];
        for k in 0..self.estimate_um.len() {
            let d = self.determination(k);
            n[Determination::ALL.iter().position(|a| *a == d).unwrap_or(3)] += 1;
        }
        n
    }
}

struct Subspace<'a> {
    model: &'a MeasurementModel,
    prepared: &'a Prepared,
    campaign: &'a Campaign,
    start_um: DVector<f64>,
    basis: DMatrix<f64>,
    measured_mm: Vec<f64>,
    weights: Vec<f64>,
    /// The full Jacobian at `cached_theta` (when `cached`), computed with the predictions
    /// there: the solver asks for the Jacobian at the point whose residuals it has just
    /// accepted, and the forward kinematics of every pose would otherwise run twice.
    full_jac: DMatrix<f64>,
    cached_theta: Vec<f64>,
    cached_y: Vec<f64>,
    cached: bool,
    /// Parameters with a finite, non-zero prior: (index, 1 / tolerance).
    prior_rows: Vec<(usize, f64)>,
    /// The noise the prior rows are weighed against (um of the reference).
    prior_sigma: f64,
    /// Leg-space residuals (um of leg length) instead of the predictions' (pose space).
    leg: bool,
    /// The last leg-space residuals (um) and their Jacobian in the fit's directions.
    leg_r: Vec<f64>,
    leg_jac: DMatrix<f64>,
    /// The caller's cancel flag ([`IdentifyOptions::cancel`]).
    cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl Subspace<'_> {
    /// The observations' weights `weights`, those in `set_aside` at zero.
    fn set_aside(&mut self, weights: &[f64], set_aside: &[usize]) {
        self.weights.clear();
        self.weights.extend_from_slice(weights);
        for &k in set_aside {
            self.weights[k] = 0.0;
        }
    }
}

/// Refits the tracker frames of `e` in pose space (the machine held fixed); the problem's
/// start becomes the result and its directions the frames' (so that `theta = 0` is it).
fn reregister_frames(
    problem: &mut Subspace<'_>,
    e: Vec<f64>,
    lm: &cpm_lm::Options,
) -> Result<Vec<f64>, CalibError> {
    let sessions: Vec<_> = problem
        .model
        .blocks()
        .into_iter()
        .filter(|b| {
            matches!(
                b.effect,
                Some(Effect::TrackerFrame | Effect::BaseTilt | Effect::PointFrame)
            )
        })
        .collect();
    let n: usize = sessions.iter().map(|b| b.len).sum();
    let np = e.len();
    let mut basis = DMatrix::zeros(np, n);
    let mut c = 0;
    for b in &sessions {
        for k in 0..b.len {
            basis[(b.offset + k, c)] = 1.0;
            c += 1;
        }
    }
    if n == 0 {
        problem.start_um = DVector::from_vec(e);
        problem.basis = basis;
        problem.leg = false;
        problem.cached = false;
        return Ok(problem.start_um.iter().copied().collect());
    }
    problem.start_um = DVector::from_vec(e);
    problem.basis = basis;
    problem.leg = false;
    problem.prior_rows.clear();
    problem.cached = false;
    let mut x = vec![0.0; n];
    cpm_lm::minimize(
        problem,
        &mut x,
        &cpm_lm::Options {
            loss: cpm_lm::Loss::Squared,
            ..lm.clone()
        },
    )?;
    let out = problem.errors(&x);
    problem.start_um = DVector::from_column_slice(&out);
    problem.cached = false;
    Ok(out)
}

/// Step of the leg-space Jacobian's central differences, in the fit's coordinates.
const LEG_STEP: f64 = 1e-4;

impl Subspace<'_> {
    /// Leg-space residuals at parameters `e`, um.
    fn leg_at(&self, e: &[f64]) -> Result<Vec<f64>, CalibError> {
        let r = crate::model::leg_residuals(self.model, self.prepared, self.campaign, e)?;
        Ok(r.into_iter().map(|x| x * 1e3).collect())
    }

    fn errors(&self, theta: &[f64]) -> Vec<f64> {
        let e = &self.start_um + &self.basis * DVector::from_column_slice(theta);
        e.iter().copied().collect()
    }

    /// Predictions and the full Jacobian at `theta` (kept for a later call at the same
    /// point).
    fn evaluate(&mut self, theta: &[f64]) -> Result<(), CalibError> {
        if self.cached && self.cached_theta == theta {
            return Ok(());
        }
        self.cached = false;
        let e = self.errors(theta);
        self.cached_y = predict(
            self.model,
            self.prepared,
            self.campaign,
            &e,
            Some(&mut self.full_jac),
        )?;
        self.cached_theta.clear();
        self.cached_theta.extend_from_slice(theta);
        self.cached = true;
        Ok(())
    }
}

impl Problem for Subspace<'_> {
    fn num_params(&self) -> usize {
        self.basis.ncols()
    }
    fn num_residuals(&self) -> usize {
        self.measured_mm.len() + self.prior_rows.len()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        check_cancel(&self.cancel)?;
        let m = self.measured_mm.len();
        if self.leg {
            let e = self.errors(x);
            self.leg_r = self.leg_at(&e)?;
            r[..m].copy_from_slice(&self.leg_r);
            for (q, &(k, inv)) in self.prior_rows.iter().enumerate() {
                r[m + q] = self.prior_sigma * inv * e[k];
            }
            return Ok(());
        }
        // Forward kinematics that does not converge at a trial point (the start was
        // evaluated before the solve) rejects that step, as a step that raises the cost
        // would be: the solver raises its damping and tries a shorter one. It is never
        // taken as the fit's end.
        match self.evaluate(x) {
            Ok(()) => {}
            Err(CalibError::Kinematics { .. }) => {
                r.fill(f64::INFINITY);
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
        for (((ri, yi), mi), w) in r[..m]
            .iter_mut()
            .zip(&self.cached_y)
            .zip(&self.measured_mm)
            .zip(&self.weights)
        {
            *ri = (yi - mi) * 1e3 * w;
        }
        // The prior: the departure from nominal in tolerances, weighed against the noise.
        if !self.prior_rows.is_empty() {
            let e = self.errors(x);
            for (q, &(k, inv)) in self.prior_rows.iter().enumerate() {
                r[m + q] = self.prior_sigma * inv * e[k];
            }
        }
        Ok(())
    }
}

impl DenseJacobian for Subspace<'_> {
    fn jacobian(&mut self, x: &[f64], mut jac: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
        check_cancel(&self.cancel)?;
        if self.leg {
            // Central differences along the fit's directions (the leg-space residuals are
            // cheap: inverse kinematics, no forward kinematics).
            let m = self.measured_mm.len();
            let r = self.basis.ncols();
            let mut j = DMatrix::zeros(m, r);
            let mut xp = x.to_vec();
            for c in 0..r {
                let h = LEG_STEP * (1.0 + x[c].abs());
                xp[c] = x[c] + h;
                let up = self.leg_at(&self.errors(&xp))?;
                xp[c] = x[c] - h;
                let down = self.leg_at(&self.errors(&xp))?;
                xp[c] = x[c];
                for row in 0..m {
                    j[(row, c)] = (up[row] - down[row]) / (2.0 * h);
                }
            }
            for c in 0..r {
                for row in 0..m {
                    jac[(row, c)] = j[(row, c)];
                }
            }
            for (q, &(k, inv)) in self.prior_rows.iter().enumerate() {
                for c in 0..r {
                    jac[(m + q, c)] = self.prior_sigma * inv * self.basis[(k, c)];
                }
            }
            self.leg_jac = j;
            return Ok(());
        }
        self.evaluate(x)?;
        // The fit's directions' Jacobian, 1e3 J B, made by faer straight into the solver's
        // storage (nalgebra's matrices viewed in place), then weighed row by row.
        let (m, np, r) = (
            self.full_jac.nrows(),
            self.basis.nrows(),
            self.basis.ncols(),
        );
        let full = faer::MatRef::from_column_major_slice(self.full_jac.as_slice(), m, np);
        let basis = faer::MatRef::from_column_major_slice(self.basis.as_slice(), np, r);
        faer::linalg::matmul::matmul(
            jac.as_mut().subrows_mut(0, m),
            faer::Accum::Replace,
            full,
            basis,
            1e3,
            faer::Par::Seq,
        );
        for c in 0..r {
            for (row, w) in self.weights.iter().enumerate() {
                jac[(row, c)] *= w;
            }
        }
        for (q, &(k, inv)) in self.prior_rows.iter().enumerate() {
            for c in 0..self.basis.ncols() {
                jac[(m + q, c)] = self.prior_sigma * inv * self.basis[(k, c)];
            }
        }
        Ok(())
    }
}

/// The weighted residuals (um of the reference) of predictions `y` against the campaign.
fn r0_of(y: &[f64], campaign: &Campaign, weights: &[f64]) -> Vec<f64> {
    y.iter()
        .zip(campaign.observations())
        .zip(weights)
        .map(|((a, b), w)| (a - b) * 1e3 * w)
        .collect()
}

/// The directions a fit under a prior moves along (columns, in the model's units): the row
/// space of the tolerance-scaled problem `[J diag(t) / sigma; I]` (the identity rows for the
/// parameters with a tolerance). Free parameters' columns are scaled to the median norm of
/// the others (so that a relative cut treats them alike); held ones take no part. Directions
/// below `rtol` of the largest singular value, or below 1/2 (a prior row alone gives 1), are
/// left out: those are blind free directions.
fn prior_basis(j: &DMatrix<f64>, prior: &[f64], sigma: f64, rtol: f64) -> DMatrix<f64> {
    let np = prior.len();
    let mut d = vec![0.0; np];
    let mut norms = Vec::new();
    for k in 0..np {
        if prior[k].is_finite() && prior[k] > 0.0 {
            d[k] = prior[k] / sigma;
            let n = j.column(k).norm() * d[k];
            if n > 0.0 {
                norms.push(n);
            }
        }
    }
    norms.sort_by(f64::total_cmp);
    let typical = norms.get(norms.len() / 2).copied().unwrap_or(1.0);
    for k in 0..np {
        if prior[k].is_infinite() {
            let n = j.column(k).norm();
            d[k] = if n > 0.0 { typical / n } else { 0.0 };
        }
    }
    // A^T A = D J^T J D + diag(1 for the prior rows).
    let mut jd = j.clone();
    for k in 0..np {
        jd.column_mut(k).scale_mut(d[k]);
    }
    let mut ata = jd.transpose() * &jd;
    for k in 0..np {
        if prior[k].is_finite() && prior[k] > 0.0 {
            ata[(k, k)] += 1.0;
        }
    }
    let eig = ata.symmetric_eigen();
    let smax = eig
        .eigenvalues
        .iter()
        .fold(0.0_f64, |a, b| a.max(*b))
        .max(0.0)
        .sqrt();
    let cut = (rtol * smax).min(0.5);
    let keep: Vec<usize> = (0..np)
        .filter(|&i| eig.eigenvalues[i].max(0.0).sqrt() > cut)
        .collect();
    let mut basis = DMatrix::zeros(np, keep.len());
    for (c, &i) in keep.iter().enumerate() {
        for k in 0..np {
            basis[(k, c)] = d[k] * eig.eigenvectors[(k, i)];
        }
    }
    basis
}

/// Most refits while the noise the prior is weighed against settles.
const MAX_NOISE_ROUNDS: usize = 8;

/// Relative change of the noise estimate below which it has settled.
const NOISE_SETTLED: f64 = 0.02;

/// The noise of the weighted data residuals at the problem's current point (um of the
/// reference): their sum of squares over the observations less the effective number of
/// parameters (the prior's share left out); a robust fit's flagged outliers are left out.
fn noise_of_fit(
    problem: &Subspace<'_>,
    campaign: &Campaign,
    robust: bool,
) -> Result<f64, CalibError> {
    let r: Vec<f64> = if problem.leg {
        problem.leg_r.clone()
    } else {
        problem
            .cached_y
            .iter()
            .zip(&problem.measured_mm)
            .zip(&problem.weights)
            .map(|((a, b), w)| (a - b) * 1e3 * w)
            .collect()
    };
    let outliers = if robust {
        crate::analysis::diagnostics::outliers_by_kind(&r, campaign, None)
    } else {
        Vec::new()
    };
    // Observations set aside (weight zero) take no part either.
    let (ssr, count) = r
        .iter()
        .enumerate()
        .filter(|(k, _)| outliers.binary_search(k).is_err())
        .filter(|(k, _)| problem.leg || problem.weights[*k] != 0.0)
        .fold((0.0, 0usize), |(s, n), (_, x)| (s + x * x, n + 1));
    // Effective parameters in the fit's subspace: tr(H^-1 Jr^T Jr / s^2), H = Jr^T Jr / s^2
    // + B^T diag(1/t^2) B.
    let s2 = problem.prior_sigma * problem.prior_sigma;
    let jr = if problem.leg && problem.leg_jac.nrows() > 0 {
        problem.leg_jac.clone()
    } else {
        let mut jr = &problem.full_jac * &problem.basis * 1e3;
        for (row, w) in problem.weights.iter().enumerate() {
            let mut x = jr.row_mut(row);
            x *= *w;
        }
        jr
    };
    let g = jr.transpose() * &jr / s2;
    let mut h = g.clone();
    for &(k, inv) in &problem.prior_rows {
        let b = problem.basis.row(k);
        h += b.transpose() * b * (inv * inv);
    }
    let p_eff = match h.clone().cholesky() {
        Some(c) => (c.solve(&g)).trace(),
        None => problem.basis.ncols() as f64,
    };
    let dof = (count as f64 - p_eff).max(1.0);
    Ok((ssr / dof).sqrt())
}

/// Root mean square (0 for no values).
pub(crate) fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
}

/// The identification Jacobian (observations x parameters, um of reading per um of error;
/// tracker observations weighted to the length-reading noise `sigma_ref_um` = the campaign's
/// tracker position noise) at parameters `params`.
pub fn identification_jacobian(
    model: &MeasurementModel,
    campaign: &Campaign,
    params: &[f64],
) -> Result<DMatrix<f64>, CalibError> {
    let prepared = Prepared::new(model, campaign)?;
    let mut j = DMatrix::zeros(campaign.len(), model.num_params());
    predict(model, &prepared, campaign, params, Some(&mut j))?;
    let w = campaign.observation_weights(campaign.pose_sigma());
    for (r, wr) in w.iter().enumerate() {
        let mut row = j.row_mut(r);
        row *= 1e3 * wr;
    }
    Ok(j)
}

/// Identifiability of a campaign (or plan skeleton) at the nominal geometry.
pub fn identifiability(
    model: &MeasurementModel,
    campaign: &Campaign,
    sigma_um: f64,
    options: &RankOptions,
) -> Result<Identifiability, CalibError> {
    let j = identification_jacobian(model, campaign, &vec![0.0; model.num_params()])?;
    let (columns, rows) = (model.rank_groups(), campaign.kind_groups());
    let scaling = RankScaling {
        column_groups: Some(&columns),
        row_groups: Some(&rows),
    };
    try_analyze_scaled(
        &j,
        sigma_um,
        options,
        &physical_patterns(model, campaign),
        &scaling,
    )
}

impl Calibration {
    /// The parameters to compensate with: the start plus only those identifiable
    /// combinations whose Cramér-Rao standard deviation is at most `max_std_um`.
    ///
    /// The minimum-norm solution also applies combinations the data barely see (a standard
    /// deviation of a millimetre is common on weak designs); compensating with those makes the
    /// machine worse, so a controller should take this truncated solution. Combinations left
    /// out stay at the start value, like the blind directions.
    pub fn compensation_um(&self, start_um: &[f64], max_std_um: f64) -> Vec<f64> {
        let e = DVector::from_column_slice(&self.minimum_norm_um);
        let s = DVector::from_column_slice(start_um);
        let d = &e - &s;
        let mut out = s;
        for (c, std) in self.identifiability.combination_std_um.iter().enumerate() {
            if *std <= max_std_um {
                let v = self.identifiability.v.column(c);
                out += v * v.dot(&d);
            }
        }
        out.iter().copied().collect()
    }
}

/// Identifies the installation errors from a campaign.
///
/// A fit whose [`IdentifyOptions::cancel`] flag is set (before or during its iterations)
/// returns [`CalibError::Cancelled`], whatever the solver was doing then.
pub fn identify(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
) -> Result<Calibration, CalibError> {
    check_cancel(&options.cancel)?;
    let fitted = identify_within_limit(model, campaign, options);
    match fitted {
        Err(_) if check_cancel(&options.cancel).is_err() => Err(CalibError::Cancelled),
        other => other,
    }
}

/// Most refits of [`identify`] that hold at their limit the parameters the previous fit
/// pulled beyond it ([`Tolerances::limit`]).
pub const MAX_LIMIT_ROUNDS: usize = 4;

/// The fit, then every parameter with a tolerance that the data pulled beyond
/// [`Tolerances::limit`] tolerances without determining it (a data share below
/// [`MIN_DATA_SHARE`](crate::fit::prior::MIN_DATA_SHARE)) held at the limit (with the sign it
/// was pulled to) and the fit repeated, until none is beyond or after [`MAX_LIMIT_ROUNDS`]
/// refits (what is still beyond then is reported as such). A misfit the model does not
/// declare pours into the weakly seen directions: the limit keeps the written machine
/// physical, and the report names what it held. A parameter the data determine is measured,
/// however far from its tolerance (the tolerance was wrong: the report says it is beyond).
fn identify_within_limit(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
) -> Result<Calibration, CalibError> {
    let limit = options.tolerances.limit;
    if !(limit > 0.0) {
        return Err(CalibError::invalid(
            "tolerance limit",
            format!("{limit} must be > 0 (in tolerances; inf for none)"),
        ));
    }
    let mut at_limit: Vec<(usize, f64)> = Vec::new();
    let mut cal = identify_uncancelled(model, campaign, options, &at_limit)?;
    if options.tolerances.off || limit.is_infinite() {
        return Ok(cal);
    }
    for _ in 0..MAX_LIMIT_ROUNDS {
        let beyond: Vec<(usize, f64)> = cal
            .prior_std
            .iter()
            .zip(&cal.minimum_norm_um)
            .enumerate()
            .filter(|(k, (t, v))| {
                t.is_finite()
                    && **t > 0.0
                    && v.abs() > limit * **t
                    && !at_limit.iter().any(|(j, _)| j == k)
                    && !cal.prior.as_ref().is_some_and(|p| p.determined(*k))
            })
            .map(|(k, (t, v))| (k, limit * t * v.signum()))
            .collect();
        if beyond.is_empty() {
            break;
        }
        at_limit.extend(beyond);
        at_limit.sort_by_key(|p| p.0);
        cal = identify_uncancelled(model, campaign, options, &at_limit)?;
    }
    Ok(cal)
}

fn identify_uncancelled(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
    at_limit: &[(usize, f64)],
) -> Result<Calibration, CalibError> {
    options.lm.validate()?;
    let np = model.num_params();
    let mut start = checked_start(np, options)?;
    let prepared = Prepared::new(model, campaign)?;
    let m = campaign.len();
    let mut prior = prior_std(model, &options.tolerances)?;
    let group_prior = prior.clone();
    // The parameters held at their limit: at it, out of the fit.
    for &(k, v) in at_limit {
        prior[k] = 0.0;
        start[k] = v;
    }
    let sigma_ref = campaign.reference_sigma(options.sigma_um);
    let w = Weighing {
        with_prior: prior.iter().any(|p| p.is_finite()),
        prior,
        weights: campaign.observation_weights(sigma_ref),
        sigma_ref,
    };
    let mut j0 = DMatrix::zeros(m, np);
    let y0 = predict(model, &prepared, campaign, &start, Some(&mut j0))?;
    let r0_pose = r0_of(&y0, campaign, &w.weights);
    let (first, basis) = fit_directions(model, campaign, &j0, &w, &r0_pose, options)?;
    let prior_rows: Vec<(usize, f64)> = w
        .prior
        .iter()
        .enumerate()
        .filter(|(_, p)| p.is_finite() && **p > 0.0)
        .map(|(k, p)| (k, 1.0 / p))
        .collect();
    let rank = basis.ncols();
    let leg_space = options.leg_space && crate::model::leg_space_applies(campaign);
    let mut problem = Subspace {
        model,
        prepared: &prepared,
        campaign,
        start_um: DVector::from_vec(start),
        basis,
        measured_mm: campaign.observations(),
        weights: w.weights.clone(),
        // The start (theta = 0) is evaluated already.
        full_jac: j0,
        cached_theta: vec![0.0; rank],
        cached_y: y0,
        cached: true,
        prior_rows,
        prior_sigma: 0.0,
        leg: leg_space,
        leg_r: Vec::new(),
        leg_jac: DMatrix::zeros(0, 0),
        cancel: options.cancel.clone(),
    };
    let mut theta = vec![0.0; rank];
    let mut r0 = vec![0.0; m + problem.prior_rows.len()];
    problem
        .residuals(&theta, &mut r0)
        .map_err(|e| CalibError::invalid("model at the start", e.to_string()))?;
    r0.truncate(m);
    // The prior is weighed against the noise: the declared one, else the residual's,
    // estimated with the fit (from the nominal's residual down, until it settles).
    let estimate_noise =
        w.with_prior && options.sigma_um.is_none() && options.prior_noise_um.is_none();
    problem.prior_sigma = match (w.with_prior, options.sigma_um) {
        (false, _) => 0.0,
        (true, Some(s)) => s,
        (true, None) => options
            .prior_noise_um
            .unwrap_or_else(|| rms(&r0).max(1e-9 * w.sigma_ref)),
    };
    let (solver, set_aside) = fit_setting_aside(
        &mut problem,
        &mut theta,
        &w.weights,
        estimate_noise,
        options,
    )?;
    let end = fit_end(&mut problem, theta, set_aside, &w, options)?;
    let noise = noise_estimate(&end, &w, problem.prior_sigma, first.rank, options);
    let FitEnd {
        e_hat,
        residuals_um,
        jf,
        set_aside,
        outliers,
        downweighted_share,
    } = end;
    let sigma_um = noise.sigma_um;
    let (columns, rows) = (model.rank_groups(), campaign.kind_groups());
    let scaling = RankScaling {
        column_groups: Some(&columns),
        row_groups: Some(&rows),
    };
    let mut ident = try_analyze_scaled(&jf, sigma_um, &options.rank, &[], &scaling)?;
    // Under a prior its summary and the parameters' covariance come from one posterior.
    let (prior_summary, prior_covariance) = if w.with_prior {
        let (summary, c) =
            summarize_with_covariance(&jf, &w.prior, sigma_um, Some(&ident.rank_column_scale));
        (Some(summary), Some(c))
    } else {
        (None, None)
    };
    let leverages = match noise.prior_leverages {
        Some(h) => h,
        None => crate::analysis::identifiability::leverages(&jf, &ident),
    };
    // Blind directions are named at the start (the nominal geometry, where the physical
    // patterns are exact); at the solution the errors tilt them by a few microradians.
    ident.blind_directions = first.blind_directions.clone();
    ident.unexplained_null_dimensions = (ident.num_params - ident.rank)
        .saturating_sub(first.blind_directions.iter().map(|b| b.dimensions).sum());
    // A parameter is reported as measured (determined) when the data determine it on its own
    // (the rank of the data alone: a prior never makes a blind direction seen) and, under a
    // prior, supply at least half of its determination; its standard deviation is the
    // Cramér-Rao bound of the data (the posterior one, the prior's share included, is in
    // `prior.posterior_std`). Every other parameter is held by its tolerance, by the user, or
    // blind ([`Calibration::determination`]).
    let measured =
        |k: usize| ident.determined[k] && prior_summary.as_ref().is_none_or(|p| p.determined(k));
    let estimate_um: Vec<Option<f64>> = (0..np).map(|k| measured(k).then_some(e_hat[k])).collect();
    let std_um: Vec<Option<f64>> = (0..np)
        .map(|k| match &prior_summary {
            Some(_) if measured(k) => ident.crlb_std_um[k],
            Some(_) => None,
            None => ident.crlb_std_um[k],
        })
        .collect();
    let combinations = combinations(&ident, &e_hat);
    let covariance = match prior_covariance {
        Some(c) => c,
        None => crate::promise::covariance_of(&jf, None, sigma_um, &ident)?,
    };
    Ok(Calibration {
        covariance,
        simulated: campaign.simulated,
        estimate_um,
        std_um,
        minimum_norm_um: e_hat,
        combinations,
        identifiability: ident,
        sigma_um,
        sigma_estimated: noise.sigma_estimated,
        sigma_excludes_outliers: noise.sigma_excludes_outliers,
        outliers,
        set_aside,
        initial_rms_um: rms(&r0_pose),
        residual_rms_um: rms(&residuals_um),
        residuals_um,
        solver,
        downweighted_share,
        robust_failed: downweighted_share > MAX_DOWNWEIGHTED_SHARE,
        sigma_ref_um: w.sigma_ref,
        leverages,
        prior: prior_summary,
        prior_std: group_prior,
        held_at_limit: at_limit.iter().map(|p| p.0).collect(),
        tolerance_limit: if options.tolerances.off {
            f64::INFINITY
        } else {
            options.tolerances.limit
        },
        leg_space,
    })
}

/// How a fit weighs the observations and the parameters.
struct Weighing {
    /// The parameters' prior standard deviations (0: held; infinite: free).
    prior: Vec<f64>,
    /// Whether any parameter has a finite prior.
    with_prior: bool,
    /// The reference noise the weights are relative to, um.
    sigma_ref: f64,
    /// The observations' weights.
    weights: Vec<f64>,
}

/// The start of a fit of `np` parameters (zero unless given), and the checks of the options
/// that are not the solver's.
fn checked_start(np: usize, options: &IdentifyOptions) -> Result<Vec<f64>, CalibError> {
    let start = options.start_um.clone().unwrap_or_else(|| vec![0.0; np]);
    if start.len() != np {
        return Err(CalibError::invalid(
            "start_um",
            format!("{} values, expected {np}", start.len()),
        ));
    }
    if let Some(s) = options.sigma_um {
        if !(s.is_finite() && s > 0.0) {
            return Err(CalibError::invalid(
                "sigma_um",
                format!("{s} must be finite and > 0"),
            ));
        }
    }
    Ok(start)
}

/// The directions the fit moves along, from the Jacobian `j0` at the start (residuals
/// `r0_pose`): the analysis of the free parameters' weighted Jacobian (held parameters' columns
/// left out), and the basis. Under a prior the fit moves in the directions of the
/// tolerance-scaled problem (the data's Jacobian in tolerances, with the prior's rows): every
/// direction with a tolerance takes part (the prior holds what the data do not see), and a
/// free parameter's blind directions stay out. Without one, in the identifiable subspace of
/// the data alone.
fn fit_directions(
    model: &MeasurementModel,
    campaign: &Campaign,
    j0: &DMatrix<f64>,
    w: &Weighing,
    r0_pose: &[f64],
    options: &IdentifyOptions,
) -> Result<(Identifiability, DMatrix<f64>), CalibError> {
    let patterns = physical_patterns(model, campaign);
    // Held parameters take no part in the fit: their columns are left out of the directions
    // the fit moves along.
    let mut j_free = j0.clone();
    for (r, wr) in w.weights.iter().enumerate() {
        let mut row = j_free.row_mut(r);
        row *= 1e3 * wr;
    }
    for (k, p) in w.prior.iter().enumerate() {
        if *p == 0.0 {
            j_free.column_mut(k).fill(0.0);
        }
    }
    let (columns, rows) = (model.rank_groups(), campaign.kind_groups());
    let scaling = RankScaling {
        column_groups: Some(&columns),
        row_groups: Some(&rows),
    };
    let first = try_analyze_scaled(&j_free, 1.0, &options.rank, &patterns, &scaling)?;
    if first.rank == 0 {
        return Err(CalibError::NoInformation(
            "the identification Jacobian is zero: the readings do not depend on any installation error".into(),
        ));
    }
    let basis = if w.with_prior {
        let sigma0 = options
            .sigma_um
            .or(options.prior_noise_um)
            .unwrap_or_else(|| rms(r0_pose).max(1e-9 * w.sigma_ref));
        prior_basis(&j_free, &w.prior, sigma0, options.rank.rank_rtol)
    } else {
        first.row_space()
    };
    Ok((first, basis))
}

/// One solve from `theta`. A robust (above all a redescending) loss started far from the
/// solution sees every residual beyond its scale and down-weights everything: it is started
/// from least squares, and a redescending one from Huber's solution at the same scale.
fn solve_staged(
    problem: &mut Subspace<'_>,
    theta: &mut [f64],
    options: &IdentifyOptions,
) -> Result<cpm_lm::Report, CalibError> {
    let robust = !options.lm.loss.is_squared();
    Ok(if robust {
        let stage = |loss| cpm_lm::Options {
            loss,
            ..options.lm.clone()
        };
        cpm_lm::minimize(problem, theta, &stage(cpm_lm::Loss::Squared))?;
        if let cpm_lm::Loss::Tukey(k) | cpm_lm::Loss::Cauchy(k) = options.lm.loss {
            cpm_lm::minimize(problem, theta, &stage(cpm_lm::Loss::Huber(k)))?;
        }
        cpm_lm::minimize(problem, theta, &options.lm)?
    } else {
        cpm_lm::minimize(problem, theta, &options.lm)?
    })
}

/// The fit ([`solve_staged`]); with `estimate_noise`, the noise the prior is weighed
/// against estimated from the residual and the fit solved again, until it settles.
fn solve_with_noise(
    problem: &mut Subspace<'_>,
    theta: &mut [f64],
    estimate_noise: bool,
    options: &IdentifyOptions,
) -> Result<cpm_lm::Report, CalibError> {
    let robust = !options.lm.loss.is_squared();
    let campaign = problem.campaign;
    let mut report = solve_staged(problem, theta, options)?;
    if estimate_noise {
        for _ in 0..MAX_NOISE_ROUNDS {
            if problem.leg {
                problem.leg_r = problem.leg_at(&problem.errors(theta))?;
            } else {
                problem.evaluate(theta)?;
            }
            let s = noise_of_fit(problem, campaign, robust)?;
            let settled = (s - problem.prior_sigma).abs() <= NOISE_SETTLED * problem.prior_sigma;
            problem.prior_sigma = s;
            if settled {
                break;
            }
            report = solve_staged(problem, theta, options)?;
        }
    }
    Ok(report)
}

/// The fit ([`solve_with_noise`]), then the gross outliers of a least-squares fit set aside
/// (weight zero, the others at `weights`) and the fit continued from where it stands, until
/// the set settles. Returns the last solve's report and the observations set aside.
fn fit_setting_aside(
    problem: &mut Subspace<'_>,
    theta: &mut [f64],
    weights: &[f64],
    estimate_noise: bool,
    options: &IdentifyOptions,
) -> Result<(cpm_lm::Report, Vec<usize>), CalibError> {
    let robust = !options.lm.loss.is_squared();
    let campaign = problem.campaign;
    let mut solver = solve_with_noise(problem, theta, estimate_noise, options)?;
    let mut set_aside: Vec<usize> = Vec::new();
    if !robust && !problem.leg && !options.keep_outliers {
        if let Some(aside) = robust_start(problem, theta, weights, options)? {
            set_aside = aside;
            problem.set_aside(weights, &set_aside);
            solver = solve_with_noise(problem, theta, estimate_noise, options)?;
        }
        for _ in 0..MAX_SET_ASIDE_ROUNDS {
            problem.evaluate(theta)?;
            let r = r0_of(&problem.cached_y, campaign, weights);
            let flagged =
                crate::analysis::diagnostics::to_set_aside(&r, campaign, options.sigma_um);
            if flagged == set_aside {
                break;
            }
            set_aside = flagged;
            problem.set_aside(weights, &set_aside);
            solver = solve_with_noise(problem, theta, estimate_noise, options)?;
        }
    }
    Ok((solver, set_aside))
}

/// The share of the observations flagged as outliers (beyond
/// [`OUTLIER_SIGMAS`](crate::analysis::diagnostics::OUTLIER_SIGMAS) robust standard deviations
/// of their kind, at least [`ROBUST_START_MIN`] of them) from which a least-squares fit is
/// checked by a robust start (a Cauchy fit first): many glitches smear a least-squares residual
/// until none reaches the set-aside rule (a tenth of the readings 400 sd off: 16 flagged,
/// none set aside, the installation errors 684 um off). A few isolated outliers (the real
/// inclinometer session's 3 of 570) are left to the least-squares rule.
pub const ROBUST_START_SHARE: f64 = 0.02;

/// The fewest flagged outliers that trigger a robust start ([`ROBUST_START_SHARE`]).
pub const ROBUST_START_MIN: usize = 3;

/// When the least-squares residual at `theta` flags many outliers ([`ROBUST_START_SHARE`]), a
/// robust fit from the same point (Cauchy loss, its scale the residual's robust standard
/// deviation, refined once on the robust residual) and the gross outliers of *its* residual
/// ([`to_set_aside`](crate::analysis::diagnostics::to_set_aside)): `Some` with them, `theta`
/// at the robust solution, when it finds any; `None` (and `theta` as it was) otherwise.
fn robust_start(
    problem: &mut Subspace<'_>,
    theta: &mut [f64],
    weights: &[f64],
    options: &IdentifyOptions,
) -> Result<Option<Vec<usize>>, CalibError> {
    use crate::analysis::diagnostics::{
        outliers_by_kind_beyond, robust_sd, to_set_aside, OUTLIER_SIGMAS,
    };
    let campaign = problem.campaign;
    problem.evaluate(theta)?;
    let r = r0_of(&problem.cached_y, campaign, weights);
    let flagged = outliers_by_kind_beyond(&r, campaign, options.sigma_um, OUTLIER_SIGMAS);
    let enough = (ROBUST_START_SHARE * r.len() as f64).max(ROBUST_START_MIN as f64);
    if (flagged.len() as f64) < enough {
        return Ok(None);
    }
    let mut robust_theta = theta.to_vec();
    let mut scale = robust_sd(&r);
    for _ in 0..2 {
        if !(scale > 0.0 && scale.is_finite()) {
            return Ok(None);
        }
        let mut o = options.clone();
        o.lm.loss = cpm_lm::Loss::Cauchy(scale);
        solve_staged(problem, &mut robust_theta, &o)?;
        problem.evaluate(&robust_theta)?;
        scale = robust_sd(&r0_of(&problem.cached_y, campaign, weights));
    }
    let aside = to_set_aside(
        &r0_of(&problem.cached_y, campaign, weights),
        campaign,
        options.sigma_um,
    );
    if aside.is_empty() {
        return Ok(None);
    }
    theta.copy_from_slice(&robust_theta);
    Ok(Some(aside))
}

/// What a fit ended with, told on every observation.
struct FitEnd {
    /// The errors at the solution, um.
    e_hat: Vec<f64>,
    /// The weighted residuals of every observation, um of the reference.
    residuals_um: Vec<f64>,
    /// The weighted Jacobian as the fit saw it: the set-aside observations' rows at weight
    /// zero, the held parameters' columns zero.
    jf: DMatrix<f64>,
    /// The observations the fit set aside.
    set_aside: Vec<usize>,
    /// The outliers: flagged by their rule at the solution, and those set aside.
    outliers: Vec<usize>,
    /// The share of observations a robust loss down-weighted below [`DOWNWEIGHT_LEVEL`].
    downweighted_share: f64,
}

/// The end of the fit at `theta`: the sessions' frames registered again on every
/// observation, as `validate` registers a session, so that the written description
/// reproduces the fit; the base frame made the base joints' own; the residuals, the
/// Jacobian and the outliers there.
fn fit_end(
    problem: &mut Subspace<'_>,
    mut theta: Vec<f64>,
    set_aside: Vec<usize>,
    w: &Weighing,
    options: &IdentifyOptions,
) -> Result<FitEnd, CalibError> {
    let (model, campaign) = (problem.model, problem.campaign);
    let (m, np) = (campaign.len(), model.num_params());
    let robust = !options.lm.loss.is_squared();
    let mut e_hat = problem.errors(&theta);
    // The weights the fit used (zero for what it set aside), for the statistics.
    let fit_weights = problem.weights.clone();
    problem.weights.clone_from(&w.weights);
    if problem.leg || (w.with_prior && options.lm.loss.is_squared()) {
        // The sessions' own parameters (tracker and point frames, base tilts) registered
        // again in pose space with the machine held fixed, as `validate` registers a session:
        // the written machine then reproduces the fit to the solver's precision, whatever
        // the prior did to the rest. What the fit set aside stays aside here too (weight
        // zero), as `validate` sets it aside by the same rule: a glitch must not drive the
        // frame the other observations are judged in.
        problem.weights.clone_from(&fit_weights);
        e_hat = reregister_frames(problem, e_hat, &options.lm)?;
        problem.weights.clone_from(&w.weights);
        theta = vec![0.0; problem.basis.ncols()];
    }
    problem.evaluate(&theta)?;
    let based = base_frame_gauge(model, campaign, &e_hat)?;
    let moved = platform_frame_gauge(model, campaign, based.as_deref().unwrap_or(&e_hat))?;
    let (e_hat, y, jf) = match moved.or(based) {
        // The same fit, told in the base joints' own frame: predicted again there (equal to
        // rounding, the move being a symmetry of the data).
        Some(e) => {
            let mut j = DMatrix::zeros(m, np);
            let y = predict(model, problem.prepared, campaign, &e, Some(&mut j))?;
            (e, y, j)
        }
        None => (
            e_hat,
            std::mem::take(&mut problem.cached_y),
            std::mem::replace(&mut problem.full_jac, DMatrix::zeros(0, 0)),
        ),
    };
    let residuals_um: Vec<f64> = y
        .iter()
        .zip(&problem.measured_mm)
        .zip(&w.weights)
        .map(|((a, b), w)| (a - b) * 1e3 * w)
        .collect();
    // The statistics see what the fit saw: the set-aside observations at weight zero.
    let mut jf = jf;
    for (r, wr) in fit_weights.iter().enumerate() {
        let mut row = jf.row_mut(r);
        row *= 1e3 * wr;
    }
    for (k, p) in w.prior.iter().enumerate() {
        if *p == 0.0 {
            jf.column_mut(k).fill(0.0);
        }
    }
    // What the fit set aside is an outlier by its rule; the frames registered again on every
    // observation may move a few more across the line.
    let mut outliers =
        crate::analysis::diagnostics::outliers_by_kind(&residuals_um, campaign, options.sigma_um);
    if !set_aside.is_empty() {
        outliers.extend_from_slice(&set_aside);
        outliers.sort_unstable();
        outliers.dedup();
    }
    let downweighted_share = if robust && !residuals_um.is_empty() {
        residuals_um
            .iter()
            .filter(|r| options.lm.loss.evaluate(*r * *r)[1] < DOWNWEIGHT_LEVEL)
            .count() as f64
            / residuals_um.len() as f64
    } else {
        0.0
    };
    Ok(FitEnd {
        e_hat,
        residuals_um,
        jf,
        set_aside,
        outliers,
        downweighted_share,
    })
}

/// The noise of a fit: declared, or estimated from the residual.
struct NoiseEstimate {
    sigma_um: f64,
    sigma_estimated: bool,
    /// Whether the estimate leaves out the outliers of a robust fit or those set aside.
    sigma_excludes_outliers: bool,
    /// Under a prior, the leverages of the regularised hat matrix.
    prior_leverages: Option<Vec<f64>>,
}

/// The noise of the fit that ended at `end`: the declared one, else the residual's over its
/// degrees of freedom (the observations less the parameters used: the rank `first_rank` of
/// the start, or under a prior the effective number, at the noise `prior_sigma` the prior was
/// weighed against).
fn noise_estimate(
    end: &FitEnd,
    w: &Weighing,
    prior_sigma: f64,
    first_rank: usize,
    options: &IdentifyOptions,
) -> NoiseEstimate {
    let robust = !options.lm.loss.is_squared();
    let (outliers, set_aside) = (&end.outliers, &end.set_aside);
    let sigma_excludes_outliers =
        options.sigma_um.is_none() && ((robust && !outliers.is_empty()) || !set_aside.is_empty());
    // Residuals the noise estimate uses: all, or without the outliers of a robust fit and
    // those set aside.
    let left_out = |k: usize| {
        (robust && sigma_excludes_outliers && outliers.binary_search(&k).is_ok())
            || set_aside.binary_search(&k).is_ok()
    };
    let (ssr, count) = end
        .residuals_um
        .iter()
        .enumerate()
        .filter(|(k, _)| !left_out(*k))
        .fold((0.0, 0usize), |(s, n), (_, r)| (s + r * r, n + 1));
    // Under a prior, the leverages of the regularised hat matrix (at the noise the prior was
    // weighed against): they add up to the effective number of parameters.
    let prior_leverages = w.with_prior.then(|| {
        crate::fit::prior::leverages(&end.jf, &w.prior, options.sigma_um.unwrap_or(prior_sigma))
    });
    let (sigma_um, sigma_estimated) = match options.sigma_um {
        Some(s) => (s, false),
        None if w.with_prior => {
            // The residual's degrees of freedom: the observations less the effective number
            // of parameters the fit used (the prior takes the rest), counted over the
            // observations the estimate uses.
            let h = prior_leverages.as_deref().unwrap_or(&[]);
            let p_eff: f64 = h
                .iter()
                .enumerate()
                .filter(|(k, _)| !left_out(*k))
                .map(|(_, x)| x)
                .sum();
            let dof = (count as f64 - p_eff).max(1.0);
            ((ssr / dof).sqrt(), true)
        }
        None => {
            let dof = count.saturating_sub(first_rank).max(1);
            ((ssr / dof as f64).sqrt(), true)
        }
    };
    NoiseEstimate {
        sigma_um,
        sigma_estimated,
        sigma_excludes_outliers,
        prior_leverages,
    }
}

/// The identifiable combinations of the errors `e_hat`: each with its singular value,
/// estimate, standard deviation and four largest loadings.
fn combinations(ident: &Identifiability, e_hat: &[f64]) -> Vec<Combination> {
    (0..ident.rank)
        .map(|c| {
            let v = ident.v.column(c);
            let mut load: Vec<(usize, f64)> = v.iter().copied().enumerate().collect();
            load.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            load.truncate(4);
            Combination {
                singular_value: ident.singular_values[c],
                estimate_um: v.dot(&DVector::from_column_slice(e_hat)),
                std_um: ident.combination_std_um[c],
                loadings: load,
            }
        })
        .collect()
}

/// The least-squares rigid motion (translation mm, small rotation rad) that takes the
/// `centres` (mm) to the same points moved by `moves` (um, one 3-vector each), `None` when
/// it is nil.
fn rigid_part(
    centres: &[nalgebra::Vector3<f64>],
    moves: impl Fn(usize) -> nalgebra::Vector3<f64>,
) -> Option<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)> {
    let n = centres.len();
    let mut a = nalgebra::DMatrix::zeros(3 * n, 6);
    let mut y = nalgebra::DVector::zeros(3 * n);
    for (i, b) in centres.iter().enumerate() {
        let d = moves(i);
        for ax in 0..3 {
            let mut unit = nalgebra::Vector3::zeros();
            unit[ax] = 1.0;
            a[(3 * i + ax, ax)] = 1.0;
            let c = b.cross(&unit);
            for k in 0..3 {
                a[(3 * i + ax, 3 + k)] = c[k];
            }
            y[3 * i + ax] = d[ax] * 1e-3;
        }
    }
    // The crate's accurate SVD (faer, exactly scaled), singular values below 1e-12 of the
    // largest dropped.
    let svd = cpm_kinematics::linalg::Svd::new(&a).ok()?;
    let c = svd.solve(&y, 1e-12);
    let (t, w) = (
        nalgebra::Vector3::new(c[0], c[1], c[2]),
        nalgebra::Vector3::new(c[3], c[4], c[5]),
    );
    (t.norm() >= 1e-9 || w.norm() >= 1e-12).then_some((t, w))
}

/// The platform frame of a fit to tracker poses alone, made the platform joints' own.
///
/// Tracker poses see the body the tracker measures (`marker_frame`), not the platform frame
/// the joints are given in: moving every platform joint rigidly and the marker frame with
/// them predicts the same data (six gauge freedoms). The convention, as for the base
/// ([`base_frame_gauge`]): the platform joints' installation errors have no common rigid
/// motion (about the platform origin), the marker frame takes the rest; the move is exact.
///
/// Applies to a model that estimates `marker_frame` without a known one, on a campaign of
/// tracker poses alone, with no load-dependent term (joint clearance, an effect that reads
/// the link forces: the platform frame places the load); `None` otherwise.
fn platform_frame_gauge(
    model: &MeasurementModel,
    campaign: &Campaign,
    e: &[f64],
) -> Result<Option<Vec<f64>>, CalibError> {
    let Some(marker) = model
        .blocks()
        .into_iter()
        .find(|b| b.effect == Some(Effect::MarkerFrame))
    else {
        return Ok(None);
    };
    let loaded = model.clearance.radius_um != 0.0
        || model
            .effects
            .iter()
            .chain(model.known_effects.iter().map(|k| &k.effect))
            .any(|e| e.model().needs_forces());
    if loaded
        || campaign.pose_measurements.is_empty()
        || !campaign.readings.is_empty()
        || !campaign.point_measurements.is_empty()
        || !campaign.tilt_measurements.is_empty()
        || !campaign.instrument_measurements.is_empty()
        || model.known(Effect::MarkerFrame).is_some()
    {
        return Ok(None);
    }
    let n = model.nominal.num_links();
    let platform: Vec<nalgebra::Vector3<f64>> =
        (0..n).map(|i| model.nominal.links[i].platform_mm).collect();
    let v3 = |k: usize| nalgebra::Vector3::new(e[k], e[k + 1], e[k + 2]);
    let Some((t, w)) = rigid_part(&platform, |i| v3(6 * i + 3)) else {
        return Ok(None);
    };
    // Undo that motion exactly: every platform joint q' = R^T (q - t); the marker frame
    // (t_m, R_m) becomes (R^T (t_m - t), R^T R_m).
    let r = cpm_geometry::rotation::exp(&w);
    let mut out = e.to_vec();
    for (i, p) in platform.iter().enumerate() {
        let back = r.inverse() * (p + v3(6 * i + 3) * 1e-3 - t) - p;
        for ax in 0..3 {
            out[6 * i + 3 + ax] = back[ax] * 1e3;
        }
    }
    let o = marker.offset;
    let (tm, rm) = crate::model::effects::tracker_registration(&e[o..o + 6]);
    out[o..o + 6].copy_from_slice(&crate::model::effects::frame_params(
        &(r.inverse() * (tm - t)),
        &(r.inverse() * rm),
    ));
    Ok(Some(out))
}

/// The base frame of a fit to tracker poses alone, made the base joints' own.
///
/// Tracker poses cannot tell the machine's base frame from the tracker's: moving every base
/// joint rigidly and the tracker frames with them predicts the same data (the six gauge
/// freedoms the identifiability analysis names). A solver leaves that motion wherever its
/// parameterization puts it, up to a milliradian in practice, which `calibrated.toml` would
/// carry into every compensated target. The convention here: the base joints' installation
/// errors have no common rigid motion (their least-squares translation and rotation about
/// the base origin are zero), the tracker frames (`tracker_frame`) take the rest. The move is
/// exact (rigid, the frames composed), so the predictions do not change.
///
/// Applies to a model that estimates `tracker_frame` on a campaign without length readings
/// (a gauge's base sockets fix the base frame), without pose maps (which act in the base
/// frame) and without a known tracker frame; `None` otherwise, or when the errors have no
/// rigid part to remove.
fn base_frame_gauge(
    model: &MeasurementModel,
    campaign: &Campaign,
    e: &[f64],
) -> Result<Option<Vec<f64>>, CalibError> {
    let frame = model
        .blocks()
        .into_iter()
        .find(|b| b.effect == Some(Effect::TrackerFrame));
    let pose_maps = model
        .effects
        .iter()
        .chain(model.known_effects.iter().map(|k| &k.effect))
        .any(|e| matches!(e, Effect::PoseMap(_)));
    let Some(frame) = frame else { return Ok(None) };
    if !campaign.readings.is_empty()
        || campaign.pose_measurements.is_empty()
        || pose_maps
        || model.known(Effect::TrackerFrame).is_some()
    {
        return Ok(None);
    }
    let n = model.nominal.num_links();
    // Base joints with their errors (mm), and the least-squares rigid motion (translation
    // mm, small rotation rad) from the nominal ones.
    let base: Vec<nalgebra::Vector3<f64>> =
        (0..n).map(|i| model.nominal.links[i].base_mm).collect();
    let Some((t, w)) = rigid_part(&base, |i| {
        nalgebra::Vector3::new(e[6 * i], e[6 * i + 1], e[6 * i + 2])
    }) else {
        return Ok(None);
    };
    // Undo that motion exactly: every base joint b' = R^T (b - t), every tracker frame
    // (p_tracker = R_f p + t_f) composed with it: R_f' = R_f R, t_f' = t_f + R_f t.
    let r = cpm_geometry::rotation::exp(&w);
    let mut out = e.to_vec();
    for (i, b) in base.iter().enumerate() {
        let moved = b + nalgebra::Vector3::new(e[6 * i], e[6 * i + 1], e[6 * i + 2]) * 1e-3;
        let back = r.inverse() * (moved - t) - b;
        for ax in 0..3 {
            out[6 * i + ax] = back[ax] * 1e3;
        }
    }
    for f in 0..frame.len / 6 {
        let o = frame.offset + 6 * f;
        let (tf, rf) = crate::model::effects::tracker_registration(&e[o..o + 6]);
        out[o..o + 6].copy_from_slice(&crate::model::effects::frame_params(
            &(tf + rf * t),
            &(rf * r),
        ));
    }
    Ok(Some(out))
}
