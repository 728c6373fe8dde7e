//! Residual diagnostics: size against the declared noise (chi-square), whiteness along the
//! acquisition order (runs test, autocorrelation, Ljung-Box), outliers, and correlation with
//! regressors (pose coordinates, time, temperature, each link's length, force and motion
//! direction).
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor, Normal, StudentsT};

use crate::model::Prepared;
use crate::{Campaign, MeasurementModel};

/// A named per-reading quantity that residuals may follow.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Regressor {
    /// Name, e.g. `pose z`, `link 3 force`, `time`.
    pub name: String,
    /// Value per reading.
    pub values: Vec<f64>,
}

/// The regressors of a campaign, one value per reading.
pub fn regressors(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
) -> Vec<Regressor> {
    let m = campaign.len();
    let mut out = Vec::new();
    let mut push = |name: String, f: &dyn Fn(usize) -> f64| {
        let values: Vec<f64> = (0..m).map(f).collect();
        if values.iter().all(|v| v.is_finite()) {
            out.push(Regressor { name, values });
        }
    };
    let pose = |k: usize| &campaign.poses[campaign.observation_pose(k)];
    let home = model.nominal.home.position_mm;
    for (a, axis) in ["x", "y", "z"].iter().enumerate() {
        push(format!("pose {axis}"), &|k| pose(k).position_mm[a]);
        push(format!("pose {axis} squared"), &|k| {
            (pose(k).position_mm[a] - home[a]).powi(2)
        });
    }
    for (a, axis) in ["roll", "pitch", "yaw"].iter().enumerate() {
        push(format!("pose {axis}"), &|k| {
            let (r, p, y) = pose(k).rpy();
            [r, p, y][a]
        });
    }
    push("acquisition order".into(), &|k| k as f64);
    let ctx = |k: usize| &prepared.contexts[campaign.observation_pose(k)];
    if (0..m).all(|k| ctx(k).time_s.is_some()) {
        push("time".into(), &|k| ctx(k).time_s.unwrap_or(0.0));
    }
    if (0..m).all(|k| ctx(k).temperature_c.is_some()) {
        push("temperature".into(), &|k| {
            ctx(k).temperature_c.unwrap_or(0.0)
        });
    }
    if campaign.readings.len() == campaign.len() {
        push("reading length".into(), &|k| campaign.readings[k].length_mm);
    }
    let n = model.nominal.num_links();
    let forces: Vec<Option<Vec<f64>>> = campaign
        .poses
        .iter()
        .map(|p| cpm_clearance::link_forces_n(model.statics_table(), p, &model.load).ok())
        .collect();
    for i in 0..n {
        push(format!("link {} length", i + 1), &|k| {
            ctx(k).commanded_mm[i]
        });
        push(format!("link {} motion direction", i + 1), &|k| {
            ctx(k).motion_sign[i]
        });
        push(format!("link {} force", i + 1), &|k| {
            forces[campaign.observation_pose(k)]
                .as_ref()
                .map(|t| t[i])
                .unwrap_or(f64::NAN)
        });
    }
    out
}

/// Correlation of the residual with one regressor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Correlation {
    /// Regressor name.
    pub regressor: String,
    /// Pearson correlation coefficient.
    pub r: f64,
    /// Two-sided p-value of r = 0 (t-test with n - 2 degrees of freedom).
    pub p_value: f64,
}

/// The diagnostics of a residual vector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualDiagnostics {
    /// Number of residuals.
    pub n: usize,
    /// Degrees of freedom (readings minus identifiable parameters).
    pub dof: usize,
    /// RMS, um.
    pub rms_um: f64,
    /// Declared noise, um, if any.
    pub sigma_declared_um: Option<f64>,
    /// `sum r^2 / sigma^2` when the noise is declared.
    pub chi2: Option<f64>,
    /// Upper-tail p-value of `chi2` (small: residual larger than the noise explains).
    pub chi2_p: Option<f64>,
    /// Wald-Wolfowitz runs test on residual signs along the acquisition order: z statistic.
    pub runs_z: f64,
    /// Two-sided p-value of the runs test.
    pub runs_p: f64,
    /// Lag-1 autocorrelation along the acquisition order.
    pub lag1_autocorrelation: f64,
    /// Ljung-Box p-value over lags 1..=10.
    pub ljung_box_p: f64,
    /// Readings whose residual exceeds 5 robust standard deviations (1.4826 MAD).
    pub outliers: Vec<usize>,
    /// Correlations with the regressors, most significant first.
    pub correlations: Vec<Correlation>,
    /// Regressors significant after a Bonferroni correction at level `alpha`.
    pub significant: Vec<String>,
    /// True when the runs and Ljung-Box tests both pass at level `alpha`.
    pub white: bool,
    /// True when the residual is consistent with the declared noise (chi-square at `alpha`);
    /// `None` when no noise is declared.
    pub consistent_with_noise: Option<bool>,
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// The fewest observations of one kind whose own robust spread [`outliers_by_kind`] trusts;
/// smaller kinds are judged against the pooled spread of all observations.
pub const MIN_KIND_OBSERVATIONS: usize = 8;

/// An outlier of its kind must also be this many noise standard deviations off (the declared
/// noise, else the robust spread of all observations): a kind far more precise than the rest
/// (noise-free orientations beside 2 um positions) has a robust spread of almost nothing, and
/// the small residuals the fit leaves there are not outliers of the measurement.
pub const OUTLIER_FLOOR_SIGMAS: f64 = 3.0;

/// [`outliers`] judged per kind of observation: each sensor's readings, the tracker's
/// positions, its orientations and the point targets' positions have their own noise, so each kind gets its own median and
/// robust spread (never pooled: noise-free orientations pooled with noisy positions would
/// make every position an "outlier"). A kind with fewer than [`MIN_KIND_OBSERVATIONS`]
/// observations is judged against the pooled spread. Every outlier is also more than
/// [`OUTLIER_FLOOR_SIGMAS`] times the noise (`sigma_um`, the declared noise of a weighted
/// residual, else the robust spread of all residuals) from its kind's median.
///
/// ```
/// use cpm_calib::{campaign::PoseMeasurement, diagnostics::outliers_by_kind, Campaign};
/// use cpm_geometry::Pose;
/// let c = Campaign {
///     poses: vec![Pose::identity(); 20],
///     pose_measurements: (0..20)
///         .map(|j| PoseMeasurement { pose: j, measured: Pose::identity(), time_s: None, temperature_c: None })
///         .collect(),
///     ..Campaign::default()
/// };
/// // Positions with 2 um noise; orientations almost noise-free, one a little larger.
/// let mut r: Vec<f64> = (0..120)
///     .map(|k| if k % 6 < 3 { 2.0 * ((k * 37 % 11) as f64 - 5.0) / 3.0 } else { 0.01 * ((k % 5) as f64 - 2.0) })
///     .collect();
/// r[10] = 0.8; // an orientation residual 40 of its kind's spreads off, but well within the noise
/// assert!(outliers_by_kind(&r, &c, Some(2.0)).is_empty());
/// r[6] = 200.0; // a position slip of 0.2 mm
/// assert_eq!(outliers_by_kind(&r, &c, Some(2.0)), vec![6]);
/// ```
pub fn outliers_by_kind(
    residuals_um: &[f64],
    campaign: &Campaign,
    sigma_um: Option<f64>,
) -> Vec<usize> {
    outliers_by_kind_beyond(residuals_um, campaign, sigma_um, OUTLIER_SIGMAS)
}

/// Robust standard deviations beyond which [`outliers`] flags a residual.
pub const OUTLIER_SIGMAS: f64 = 5.0;

/// [`outliers_by_kind`] with the line at `sigmas` robust standard deviations of each kind
/// instead of [`OUTLIER_SIGMAS`] (the floor stays [`OUTLIER_FLOOR_SIGMAS`] noise standard
/// deviations).
pub fn outliers_by_kind_beyond(
    residuals_um: &[f64],
    campaign: &Campaign,
    sigma_um: Option<f64>,
    sigmas: f64,
) -> Vec<usize> {
    let kind = |k: usize| -> usize {
        match campaign.observation_kind(k) {
            crate::ObservationKind::Reading(i) => campaign.readings[i].sensor,
            crate::ObservationKind::TrackerPosition(..) => usize::MAX - 1,
            crate::ObservationKind::TrackerOrientation(..) => usize::MAX,
            crate::ObservationKind::Point(..) => usize::MAX - 2,
            crate::ObservationKind::Tilt(..) => usize::MAX - 3,
            crate::ObservationKind::Instrument(q, _) => {
                usize::MAX - 4 - campaign.instrument_measurements[q].instrument
            }
        }
    };
    // The observations of each kind, in one pass (kinds in ascending order).
    let mut by_kind: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for k in 0..residuals_um.len() {
        by_kind.entry(kind(k)).or_default().push(k);
    }
    let pooled = outliers_beyond(residuals_um, sigmas);
    let floor = OUTLIER_FLOOR_SIGMAS
        * sigma_um
            .filter(|s| *s > 0.0)
            .unwrap_or_else(|| robust_spread(residuals_um).1);
    let mut out = Vec::new();
    let mut r: Vec<f64> = Vec::new();
    for idx in by_kind.into_values() {
        r.clear();
        r.extend(idx.iter().map(|&k| residuals_um[k]));
        let (median, _) = robust_spread(&r);
        let flagged: Vec<usize> = if idx.len() < MIN_KIND_OBSERVATIONS {
            idx.iter()
                .copied()
                .filter(|k| pooled.binary_search(k).is_ok())
                .collect()
        } else {
            outliers_beyond(&r, sigmas)
                .into_iter()
                .map(|i| idx[i])
                .collect()
        };
        out.extend(
            flagged
                .into_iter()
                .filter(|&k| (residuals_um[k] - median).abs() > floor),
        );
    }
    out.sort_unstable();
    out
}

/// The observations a least-squares fit sets aside as gross outliers: those more than
/// [`SET_ASIDE_SIGMAS`](crate::SET_ASIDE_SIGMAS) robust standard deviations of their kind off
/// ([`outliers_by_kind_beyond`]), a reflector point set aside whole (its three coordinates
/// are one measurement, and a glitch of the point in the tracker's frame reaches every
/// coordinate of the base frame's residual). One rule for the fit and for a session
/// registered afresh ([`crate::session::register_session`]), so that a description read back
/// registers its fit's sessions as the fit did.
pub fn to_set_aside(
    residuals_um: &[f64],
    campaign: &Campaign,
    sigma_um: Option<f64>,
) -> Vec<usize> {
    let mut out =
        outliers_by_kind_beyond(residuals_um, campaign, sigma_um, crate::SET_ASIDE_SIGMAS);
    let p0 = campaign.first_point_observation();
    let whole: Vec<usize> = out
        .iter()
        .filter_map(|&k| match campaign.observation_kind(k) {
            crate::ObservationKind::Point(q, _) => Some(q),
            _ => None,
        })
        .flat_map(|q| (0..3).map(move |a| p0 + 3 * q + a))
        .collect();
    if !whole.is_empty() {
        out.extend(whole);
        out.sort_unstable();
        out.dedup();
    }
    out
}

/// The element `n / 2` of `values` in ascending order (`total_cmp`), found in linear time:
/// the upper median, what a sort would give at `n / 2`. `values` is reordered.
fn upper_median(values: &mut [f64]) -> f64 {
    let n = values.len();
    *values.select_nth_unstable_by(n / 2, f64::total_cmp).1
}

/// Median and robust standard deviation (1.4826 x the median absolute deviation).
fn robust_spread(residuals_um: &[f64]) -> (f64, f64) {
    let n = residuals_um.len();
    if n == 0 {
        return (0.0, 0.0);
    }
    let mut work = residuals_um.to_vec();
    let median = upper_median(&mut work);
    for (d, r) in work.iter_mut().zip(residuals_um) {
        *d = (r - median).abs();
    }
    (median, upper_median(&mut work) * 1.4826)
}

/// The robust standard deviation of `residuals_um` (1.4826 x the median absolute deviation
/// from the median).
pub fn robust_sd(residuals_um: &[f64]) -> f64 {
    robust_spread(residuals_um).1
}

/// Indices of residuals more than 5 robust standard deviations (1.4826 x the median absolute
/// deviation) from the median.
pub fn outliers(residuals_um: &[f64]) -> Vec<usize> {
    outliers_beyond(residuals_um, OUTLIER_SIGMAS)
}

/// The residual, um (weighted), below which no observation is an outlier: rounding, not
/// measurement (1 pm; exact data fit to about 1e-9 um, and their robust spread is rounding
/// too: an exact angle was flagged at 0.0 urad).
pub const NUMERICAL_RESIDUAL_UM: f64 = 1e-6;

/// [`outliers`] beyond `sigmas` robust standard deviations, and beyond
/// [`NUMERICAL_RESIDUAL_UM`] from the median.
pub fn outliers_beyond(residuals_um: &[f64], sigmas: f64) -> Vec<usize> {
    let (median, mad) = robust_spread(residuals_um);
    residuals_um
        .iter()
        .enumerate()
        .filter(|(_, r)| {
            let off = (**r - median).abs();
            mad > 0.0 && off > sigmas * mad && off > NUMERICAL_RESIDUAL_UM
        })
        .map(|(k, _)| k)
        .collect()
}

fn normal_two_sided(z: f64) -> f64 {
    let n = Normal::new(0.0, 1.0).expect("standard normal");
    2.0 * n.sf(z.abs())
}

/// Diagnoses residuals (um, in acquisition order) with `dof` degrees of freedom.
pub fn diagnose(
    residuals_um: &[f64],
    dof: usize,
    sigma_um: Option<f64>,
    regressors: &[Regressor],
    alpha: f64,
) -> ResidualDiagnostics {
    let n = residuals_um.len();
    let rms_um = (residuals_um.iter().map(|r| r * r).sum::<f64>() / n.max(1) as f64).sqrt();
    let dofc = dof.max(1);
    let (chi2, chi2_p) = match sigma_um {
        Some(s) if s > 0.0 => {
            // The crate's one chi-square rule (see `misfit`); the verdict below is the plain
            // test at `alpha` on every residual.
            let (c, _) = crate::analysis::misfit::statistic(residuals_um, s, &[]);
            let p = crate::analysis::misfit::upper_tail(c, dofc).unwrap_or(f64::NAN);
            (Some(c), Some(p))
        }
        _ => (None, None),
    };
    // Runs test on signs about the median.
    let median = if n == 0 {
        0.0
    } else {
        upper_median(&mut residuals_um.to_vec())
    };
    let signs: Vec<bool> = residuals_um.iter().map(|r| *r > median).collect();
    let n1 = signs.iter().filter(|s| **s).count() as f64;
    let n2 = n as f64 - n1;
    let runs = 1.0 + signs.windows(2).filter(|w| w[0] != w[1]).count() as f64;
    let (runs_z, runs_p) = if n1 > 0.0 && n2 > 0.0 {
        let mu = 2.0 * n1 * n2 / (n1 + n2) + 1.0;
        let var = (mu - 1.0) * (mu - 2.0) / (n1 + n2 - 1.0);
        let z = (runs - mu) / var.max(1e-300).sqrt();
        (z, normal_two_sided(z))
    } else {
        (0.0, 1.0)
    };
    // Autocorrelation and Ljung-Box.
    let mean = residuals_um.iter().sum::<f64>() / n.max(1) as f64;
    let c0: f64 = residuals_um.iter().map(|r| (r - mean).powi(2)).sum();
    let acf = |lag: usize| -> f64 {
        if c0 <= 0.0 || lag >= n {
            return 0.0;
        }
        (0..n - lag)
            .map(|t| (residuals_um[t] - mean) * (residuals_um[t + lag] - mean))
            .sum::<f64>()
            / c0
    };
    let lags = 10.min(n.saturating_sub(2)).max(1);
    let q: f64 = (1..=lags)
        .map(|h| acf(h).powi(2) / (n as f64 - h as f64).max(1.0))
        .sum::<f64>()
        * n as f64
        * (n as f64 + 2.0);
    let ljung_box_p = ChiSquared::new(lags as f64).map(|d| d.sf(q)).unwrap_or(1.0);
    let outliers = outliers(residuals_um);
    // Correlations.
    let mut correlations: Vec<Correlation> = regressors
        .iter()
        .filter(|g| g.values.len() == n && n > 3)
        .map(|g| {
            let r = pearson(&g.values, residuals_um);
            let t = r * ((n as f64 - 2.0) / (1.0 - r * r).max(1e-300)).sqrt();
            let p = StudentsT::new(0.0, 1.0, n as f64 - 2.0)
                .map(|d| 2.0 * d.sf(t.abs()))
                .unwrap_or(1.0);
            Correlation {
                regressor: g.name.clone(),
                r,
                p_value: p,
            }
        })
        .collect();
    correlations.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
    let bonferroni = alpha / correlations.len().max(1) as f64;
    let significant = correlations
        .iter()
        .filter(|c| c.p_value < bonferroni)
        .map(|c| c.regressor.clone())
        .collect();
    ResidualDiagnostics {
        n,
        dof,
        rms_um,
        sigma_declared_um: sigma_um,
        chi2,
        chi2_p,
        runs_z,
        runs_p,
        lag1_autocorrelation: acf(1),
        ljung_box_p,
        outliers,
        correlations,
        significant,
        white: runs_p > alpha && ljung_box_p > alpha,
        consistent_with_noise: chi2_p.map(|p| p > alpha),
    }
}

/// How much of a residual one pose map term would explain (a score test: the F statistic of
/// the residual's projection on the term's Jacobian columns outside the current model's column
/// space, without refitting).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseStructure {
    /// The pose map term.
    pub effect: crate::Effect,
    /// Dimensions the term adds beyond the current model.
    pub dimensions: usize,
    /// Share of the residual sum of squares it would explain.
    pub explained_share: f64,
    /// Upper-tail p-value of its F statistic (no correction for the number of terms scanned).
    pub p_value: f64,
}

/// Scans every pose map term of degree 1 to `degree` not already in `model` against the
/// residual `residuals_um` (weighted as [`crate::identify()`] weighs them, with `sigma_um` as
/// the reference noise) of a fit at `at`: the pose-correlated structure a platform pose error
/// map could remove, most significant first. Directions of a term less than `min_novelty` outside
/// the model's column space (relative to the term's column norm) count as confounded.
pub fn pose_map_scan(
    model: &MeasurementModel,
    campaign: &Campaign,
    at: &[f64],
    residuals_um: &[f64],
    sigma_um: Option<f64>,
    degree: u8,
    rank_rtol: f64,
    min_novelty: f64,
) -> Result<Vec<PoseStructure>, crate::CalibError> {
    let terms: Vec<crate::Effect> = crate::Effect::pose_maps(degree)
        .into_iter()
        .filter(|e| !model.effects.contains(e))
        .collect();
    let m = campaign.len();
    if terms.is_empty() || residuals_um.len() != m {
        return Ok(Vec::new());
    }
    let mut aug = model.clone();
    aug.effects.extend(terms.iter().copied());
    let mut start = at.to_vec();
    start.resize(aug.num_params(), 0.0);
    let prepared = Prepared::new(&aug, campaign)?;
    let mut j = nalgebra::DMatrix::zeros(m, aug.num_params());
    crate::model::predict(&aug, &prepared, campaign, &start, Some(&mut j))?;
    let w = campaign.observation_weights(sigma_um.unwrap_or(campaign.pose_sigma()));
    for (r, w) in w.iter().enumerate() {
        let mut row = j.row_mut(r);
        row *= 1e3 * w;
    }
    let old = j.columns(0, model.num_params()).into_owned();
    let (sv, u, _) = crate::linalg::thin_svd(&old)?;
    let smax = sv.first().copied().unwrap_or(0.0);
    let keep: Vec<usize> = (0..sv.len())
        .filter(|&i| sv[i] > rank_rtol * smax)
        .collect();
    let k0 = keep.len();
    let u = u.select_columns(&keep);
    let r = nalgebra::DVector::from_column_slice(residuals_um);
    let rss: f64 = r.norm_squared();
    let mut out = Vec::new();
    for (t, e) in terms.iter().enumerate() {
        let b = j.columns(model.num_params() + 6 * t, 6).into_owned();
        let outside = &b - &u * (u.transpose() * &b);
        let Ok((sb, ub, _)) = crate::linalg::thin_svd(&outside) else {
            continue;
        };
        let bmax = b.norm();
        let keep: Vec<usize> = (0..sb.len())
            .filter(|&i| sb[i] > min_novelty * bmax && bmax > 0.0)
            .collect();
        let dk = keep.len();
        if dk == 0 || m <= k0 + dk || rss <= 0.0 {
            continue;
        }
        let q = ub.select_columns(&keep);
        let explained = (q.transpose() * &r).norm_squared().min(rss);
        let f = (explained / dk as f64) / ((rss - explained).max(1e-300) / (m - k0 - dk) as f64);
        let p_value = FisherSnedecor::new(dk as f64, (m - k0 - dk) as f64)
            .map(|d| d.sf(f))
            .unwrap_or(1.0);
        out.push(PoseStructure {
            effect: *e,
            dimensions: dk,
            explained_share: explained / rss,
            p_value,
        });
    }
    // p-values underflow to 0 for strong structure: the explained share breaks the tie.
    out.sort_by(|a, b| {
        a.p_value
            .total_cmp(&b.p_value)
            .then(b.explained_share.total_cmp(&a.explained_share))
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Small p-values are numbers, from the survival functions (issue 61: `1 - cdf` printed
    /// "< 1e-300" for a Ljung-Box p of about 1e-17): a slowly drifting residual gives a
    /// Ljung-Box statistic whose upper tail is far below 1e-16 yet above zero, equal to the
    /// chi-squared survival function at it; the runs test's the same.
    #[test]
    fn small_p_values_come_from_the_survival_function() {
        let r: Vec<f64> = (0..60)
            .map(|k| (k as f64 * 0.05).sin() + 0.01 * (k % 3) as f64)
            .collect();
        let d = diagnose(&r, 50, None, &[], 0.05);
        assert!(
            d.ljung_box_p > 0.0 && d.ljung_box_p < 1e-16,
            "{}",
            d.ljung_box_p
        );
        assert!(d.runs_p > 0.0 && d.runs_p < 1e-10, "{}", d.runs_p);
    }

    /// The linear-time median is the element a sort puts at `n / 2`, ties, signed zeros and
    /// all; the robust spread follows it.
    #[test]
    fn the_upper_median_is_the_sorted_middle() {
        let mut state = 7u64;
        for n in [1usize, 2, 3, 10, 101, 1000] {
            let v: Vec<f64> = (0..n)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((state >> 40) % 21) as f64 - 10.0
                })
                .chain([-0.0, 0.0])
                .collect();
            let mut sorted = v.clone();
            sorted.sort_by(f64::total_cmp);
            let m = upper_median(&mut v.clone());
            assert_eq!(m.to_bits(), sorted[v.len() / 2].to_bits(), "n = {n}");
            let (median, spread) = robust_spread(&v);
            let mut dev: Vec<f64> = v.iter().map(|r| (r - median).abs()).collect();
            dev.sort_by(f64::total_cmp);
            assert_eq!(spread, dev[v.len() / 2] * 1.4826);
        }
    }

    /// Outliers are judged within their kind: a residual ordinary for a noisy sensor is an
    /// outlier for a quiet one.
    #[test]
    fn outliers_are_judged_within_their_kind() {
        let poses = vec![cpm_geometry::Pose::identity(); 200];
        let readings = (0..400)
            .map(|k| crate::Reading {
                pose: k / 2,
                sensor: k % 2,
                length_mm: 0.0,
                time_s: crate::Logged::NONE,
                temperature_c: crate::Logged::NONE,
            })
            .collect();
        let c = Campaign {
            poses,
            readings,
            ..Campaign::default()
        };
        // Sensor 0 quiet (+-0.1 um), sensor 1 noisy (+-10 um).
        let mut r: Vec<f64> = (0..400)
            .map(|k| {
                let s = if k % 2 == 0 { 0.1 } else { 10.0 };
                s * (((k * 37) % 11) as f64 - 5.0) / 5.0
            })
            .collect();
        r[10] = 9.0; // sensor 0: 90 of its spreads off
        r[11] = 9.0; // sensor 1: within its spread
        assert_eq!(outliers_by_kind(&r, &c, Some(0.1)), vec![10]);
    }
}
