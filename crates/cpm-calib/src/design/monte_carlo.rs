//! Monte Carlo check of a design: many simulated campaigns and calibrations, their errors
//! against the truth, and the efficiency against the Cramér-Rao bound.
//!
//! Per parameter `k`, over the runs `r`: the bias `mean_r (e_rk - t_k)`, the RMS error
//! `sqrt(mean_r (e_rk - t_k)^2)` and the *efficiency* `rms_k / crlb_k` (1 for an efficient
//! unbiased estimator; above 1 an estimator wastes information or is biased). For the
//! design as a whole: the RMS error over all parameters and runs against the RMS of the bounds,
//! and the distribution over runs of each run's largest error.
//!
//! The bound is `sigma^2 (J^T J)^-1` with `sigma` the noise's standard deviation: exact for
//! Gaussian noise; for the paper's uniform noise it is the best a linear unbiased estimator
//! (least squares) can do, which is what the calibration is.
//!
//! Runs go in parallel (rayon); `progress(done, total)` is called after each (from worker
//! threads, so it must be `Sync`).
//!
//! ```
//! use cpm_calib::design::monte_carlo::monte_carlo_with;
//! use rand::{Rng, SeedableRng};
//! // Estimating a mean from 4 readings of noise sigma = 1: the bound is 1/2.
//! let report = monte_carlo_with(&[3.0], &[0.5], 400, 7, |seed| {
//!     let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
//!     let mean = (0..4).map(|_| 3.0 + rng.random_range(-3f64.sqrt()..3f64.sqrt())).sum::<f64>() / 4.0;
//!     Some(vec![Some(mean)])
//! }, &|_, _| {});
//! assert!((report.efficiency - 1.0).abs() < 0.15, "{}", report.efficiency);
//! ```
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::analysis::identifiability::RankOptions;
use crate::{identify, simulate, CalibError, IdentifyOptions, MeasurementModel, Plan};
use crate::{Noise, SimulationOptions};

/// Options of [`monte_carlo`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MonteCarloOptions {
    /// Simulated campaigns. Default 100.
    pub runs: usize,
    /// Seed of the first run; run `r` uses `seed + r`. Default 1.
    pub seed: u64,
    /// Sensor noise. Default the paper's uniform +-10 um.
    pub noise: Noise,
}

impl Default for MonteCarloOptions {
    fn default() -> Self {
        Self {
            runs: 100,
            seed: 1,
            noise: Noise::Uniform {
                half_width_um: 10.0,
            },
        }
    }
}

/// One parameter's Monte Carlo figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ParameterStats {
    /// Runs in which the parameter was determined (estimated).
    pub runs: usize,
    /// Mean error (estimate - truth), um.
    pub bias_um: f64,
    /// RMS error, um.
    pub rms_error_um: f64,
    /// Cramér-Rao standard deviation, um.
    pub crlb_um: f64,
    /// `rms_error_um / crlb_um`.
    pub efficiency: f64,
}

/// What a Monte Carlo study found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MonteCarloReport {
    /// Runs attempted.
    pub runs: usize,
    /// Runs that failed or left a parameter undetermined (left out of the figures below).
    pub failed_runs: usize,
    /// Per parameter.
    pub parameters: Vec<ParameterStats>,
    /// RMS error over all parameters and successful runs, um.
    pub rms_error_um: f64,
    /// RMS of the parameters' Cramér-Rao bounds, um.
    pub crlb_rms_um: f64,
    /// `rms_error_um / crlb_rms_um`.
    pub efficiency: f64,
    /// Smallest and largest per-parameter efficiency.
    pub efficiency_range: (f64, f64),
    /// Largest |bias| over the parameters, um.
    pub max_abs_bias_um: f64,
    /// Per run, RMS error over the parameters: mean over runs, um.
    pub run_rms_error_um_mean: f64,
    /// Per run, RMS error over the parameters: largest over runs, um.
    pub run_rms_error_um_worst: f64,
    /// Per run, largest |error| over the parameters: mean over runs, um.
    pub max_error_um_mean: f64,
    /// Per run, largest |error|: 95th percentile over runs, um.
    pub max_error_um_p95: f64,
    /// Per run, largest |error|: largest over runs, um.
    pub max_error_um_worst: f64,
    /// Seeds used: `first_seed .. first_seed + runs`.
    pub first_seed: u64,
    /// Per successful run, in seed order: (RMS error, largest |error|), um.
    pub per_run_um: Vec<(f64, f64)>,
}

impl MonteCarloReport {
    /// Fraction of the runs attempted whose RMS error is at most `rms_um` and whose largest
    /// error is at most `max_um` (failed runs count as misses).
    pub fn fraction_within(&self, rms_um: f64, max_um: f64) -> f64 {
        let hits = self
            .per_run_um
            .iter()
            .filter(|(r, m)| *r <= rms_um && *m <= max_um)
            .count();
        hits as f64 / self.runs.max(1) as f64
    }

    /// The parameter with the largest Monte Carlo RMS error: `(index, its figures)`; the
    /// first "worst error" of a design (the other is [`MonteCarloReport::max_error_um_worst`],
    /// the largest absolute error over all runs and parameters). `None` without parameters.
    ///
    /// ```
    /// use cpm_calib::design::monte_carlo::monte_carlo_with;
    /// let r = monte_carlo_with(&[0.0, 0.0], &[1.0, 1.0], 3, 1, |seed| {
    ///     Some(vec![Some(1.0), Some(seed as f64)])
    /// }, &|_, _| {});
    /// let (k, p) = r.worst_parameter().unwrap();
    /// assert_eq!(k, 1); // errors 1, 2, 3: RMS sqrt(14 / 3) > 1
    /// assert!((p.rms_error_um - (14.0f64 / 3.0).sqrt()).abs() < 1e-12);
    /// assert_eq!(r.fraction_max_within(2.0), 2.0 / 3.0);
    /// ```
    pub fn worst_parameter(&self) -> Option<(usize, ParameterStats)> {
        self.parameters
            .iter()
            .copied()
            .enumerate()
            .filter(|(_, p)| p.rms_error_um.is_finite())
            .max_by(|a, b| a.1.rms_error_um.total_cmp(&b.1.rms_error_um))
    }

    /// Fraction of the runs attempted whose largest |error| over the parameters is at most
    /// `max_um` (failed runs count as misses).
    pub fn fraction_max_within(&self, max_um: f64) -> f64 {
        self.fraction_within(f64::INFINITY, max_um)
    }

    /// One line: the headline figures.
    pub fn brief(&self) -> String {
        format!(
            "{} runs ({} failed): RMS error {:.2} um (Cramér-Rao {:.2} um, efficiency {:.3}, per parameter {:.2}..{:.2}); per-run max error mean {:.2} um, 95 % {:.2} um, worst {:.2} um",
            self.runs,
            self.failed_runs,
            self.rms_error_um,
            self.crlb_rms_um,
            self.efficiency,
            self.efficiency_range.0,
            self.efficiency_range.1,
            self.max_error_um_mean,
            self.max_error_um_p95,
            self.max_error_um_worst
        )
    }
}

/// Per-run errors (estimate - truth) of a study, for further statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunErrors {
    /// Seed of the run.
    pub seed: u64,
    /// Errors per parameter, um (`None` where not determined); `None` when the run failed.
    pub errors_um: Option<Vec<Option<f64>>>,
}

/// [`monte_carlo_with`], also returning every run's errors.
pub fn monte_carlo_with_runs<F>(
    truth: &[f64],
    crlb_um: &[f64],
    runs: usize,
    first_seed: u64,
    estimator: F,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> (MonteCarloReport, Vec<RunErrors>)
where
    F: Fn(u64) -> Option<Vec<Option<f64>>> + Sync,
{
    let done = AtomicUsize::new(0);
    let results: Vec<RunErrors> = (0..runs)
        .into_par_iter()
        .map(|r| {
            let seed = first_seed.wrapping_add(r as u64);
            let est = estimator(seed);
            let errors_um = est.and_then(|e| {
                (e.len() == truth.len()).then(|| {
                    e.iter()
                        .zip(truth)
                        .map(|(e, t)| e.map(|e| e - t))
                        .collect::<Vec<_>>()
                })
            });
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(d, runs);
            RunErrors { seed, errors_um }
        })
        .collect();
    (
        summarise(truth.len(), crlb_um, runs, first_seed, &results),
        results,
    )
}

/// Runs `estimator(seed)` for `runs` seeds from `first_seed` in parallel and compares its
/// estimates (one per parameter; `None` for an undetermined parameter, `None` overall for a
/// failed run) with `truth` and the bounds `crlb_um`.
pub fn monte_carlo_with<F>(
    truth: &[f64],
    crlb_um: &[f64],
    runs: usize,
    first_seed: u64,
    estimator: F,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> MonteCarloReport
where
    F: Fn(u64) -> Option<Vec<Option<f64>>> + Sync,
{
    monte_carlo_with_runs(truth, crlb_um, runs, first_seed, estimator, progress).0
}

fn summarise(
    n: usize,
    crlb_um: &[f64],
    runs: usize,
    first_seed: u64,
    results: &[RunErrors],
) -> MonteCarloReport {
    let complete: Vec<&Vec<Option<f64>>> = results
        .iter()
        .filter_map(|r| r.errors_um.as_ref())
        .filter(|e| e.iter().all(|x| x.is_some()))
        .collect();
    let failed_runs = runs - complete.len();
    let mut parameters = Vec::with_capacity(n);
    for k in 0..n {
        let v: Vec<f64> = complete.iter().filter_map(|e| e[k]).collect();
        let cnt = v.len().max(1) as f64;
        let bias = v.iter().sum::<f64>() / cnt;
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / cnt).sqrt();
        let crlb = crlb_um.get(k).copied().unwrap_or(f64::NAN);
        parameters.push(ParameterStats {
            runs: v.len(),
            bias_um: bias,
            rms_error_um: rms,
            crlb_um: crlb,
            efficiency: rms / crlb,
        });
    }
    let mean_sq = |f: &dyn Fn(&ParameterStats) -> f64| {
        (parameters.iter().map(|p| f(p).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt()
    };
    let rms_error_um = mean_sq(&|p| p.rms_error_um);
    let crlb_rms_um = mean_sq(&|p| p.crlb_um);
    let eff = parameters.iter().map(|p| p.efficiency);
    let efficiency_range = (
        eff.clone().fold(f64::INFINITY, f64::min),
        eff.fold(f64::NEG_INFINITY, f64::max),
    );
    let max_abs_bias_um = parameters
        .iter()
        .map(|p| p.bias_um.abs())
        .fold(0.0, f64::max);
    let per_run_um: Vec<(f64, f64)> = complete
        .iter()
        .map(|e| {
            let rms = (e.iter().flatten().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt();
            let max = e.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
            (rms, max)
        })
        .collect();
    let per_run_rms: Vec<f64> = per_run_um.iter().map(|p| p.0).collect();
    let mut per_run_max: Vec<f64> = per_run_um.iter().map(|p| p.1).collect();
    per_run_max.sort_by(f64::total_cmp);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let p95 = if per_run_max.is_empty() {
        f64::NAN
    } else {
        let i = ((0.95 * per_run_max.len() as f64).ceil() as usize).clamp(1, per_run_max.len());
        per_run_max[i - 1]
    };
    MonteCarloReport {
        runs,
        failed_runs,
        parameters,
        rms_error_um,
        crlb_rms_um,
        efficiency: rms_error_um / crlb_rms_um,
        efficiency_range,
        max_abs_bias_um,
        run_rms_error_um_mean: mean(&per_run_rms),
        run_rms_error_um_worst: per_run_rms.iter().copied().fold(0.0, f64::max),
        max_error_um_mean: mean(&per_run_max),
        max_error_um_p95: p95,
        max_error_um_worst: per_run_max.last().copied().unwrap_or(f64::NAN),
        first_seed,
        per_run_um,
    }
}

/// Monte Carlo study of a calibration design: `options.runs` campaigns of `plan` simulated on
/// the machine with installation errors `truth_um` (through `model`, with its sensors), each
/// identified with `identify` (noise declared), against the Cramér-Rao bounds of the plan at
/// the nominal geometry. Runs that fail count as failed, never panic.
pub fn monte_carlo(
    model: &MeasurementModel,
    truth_um: &[f64],
    plan: &Plan,
    identify_options: &IdentifyOptions,
    options: &MonteCarloOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<MonteCarloReport, CalibError> {
    let (crlb, opts) = prepare(model, &plan.skeleton(), identify_options, options)?;
    Ok(monte_carlo_with(
        truth_um,
        &crlb,
        options.runs,
        options.seed,
        |seed| {
            let sim = SimulationOptions {
                noise: options.noise,
                repeats: 1,
                seed,
            };
            let data = simulate(model, truth_um, plan, &sim).ok()?;
            let cal = identify(model, &data, &opts).ok()?;
            Some(cal.estimate_um)
        },
        progress,
    ))
}

/// [`monte_carlo`] for a campaign skeleton instead of a plan (readings need not be every
/// sensor at every pose, e.g. a [`super::SetupDesign::campaign`]): `options.runs` campaigns
/// simulated from `skeleton` on the machine with installation errors `truth_um`, each
/// identified, against the Cramér-Rao bounds of the skeleton at the nominal geometry.
pub fn monte_carlo_campaign(
    model: &MeasurementModel,
    truth_um: &[f64],
    skeleton: &crate::Campaign,
    identify_options: &IdentifyOptions,
    options: &MonteCarloOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<MonteCarloReport, CalibError> {
    let (crlb, opts) = prepare(model, skeleton, identify_options, options)?;
    Ok(monte_carlo_with(
        truth_um,
        &crlb,
        options.runs,
        options.seed,
        |seed| {
            let sim = SimulationOptions {
                noise: options.noise,
                repeats: 1,
                seed,
            };
            let data = crate::simulate_campaign(model, truth_um, skeleton, &sim).ok()?;
            let cal = identify(model, &data, &opts).ok()?;
            Some(cal.estimate_um)
        },
        progress,
    ))
}

/// The checks and bounds every Monte Carlo study starts with: at least one run, noise with a
/// positive standard deviation; the Cramér-Rao bounds of `skeleton` (infinite where a
/// parameter is not determined) and the identification options at that noise.
fn prepare(
    model: &MeasurementModel,
    skeleton: &crate::Campaign,
    identify_options: &IdentifyOptions,
    options: &MonteCarloOptions,
) -> Result<(Vec<f64>, IdentifyOptions), CalibError> {
    if options.runs == 0 {
        return Err(CalibError::invalid("runs", "must be at least 1"));
    }
    let sigma = options.noise.sigma_um();
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(CalibError::invalid(
            "noise",
            "a Monte Carlo study needs noise with a positive standard deviation",
        ));
    }
    let ident = crate::identifiability(model, skeleton, sigma, &RankOptions::default())?;
    let crlb: Vec<f64> = ident
        .crlb_std_um
        .iter()
        .map(|c| c.unwrap_or(f64::INFINITY))
        .collect();
    let opts = IdentifyOptions {
        sigma_um: Some(sigma),
        ..identify_options.clone()
    };
    Ok((crlb, opts))
}
