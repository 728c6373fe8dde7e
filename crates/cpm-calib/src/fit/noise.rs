//! Noise per kind of observation (each gauge, tracker positions, tracker orientations, point
//! targets, inclinometer angles), estimated from a fit's residual, never pooled across kinds.
//!
//! A fit weighs each kind of observation by the noise it assumes for it: the declared one, or
//! a default (10 um for tracker positions and points, 20 urad for orientations and angles). When
//! that assumption is wrong by a large factor, one kind swamps the others and the standard
//! deviations are wrong. The estimate here is the variance-component estimate of each kind
//! (Förstner 1979; Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, 1999,
//! ch. 3.6): the kind's weighted residual sum of squares over its share of the residual degrees
//! of freedom, the sum of its observations' redundancy numbers `r_i = 1 - h_ii` (`h` the hat
//! matrix of the weighted Jacobian in the identifiable subspace; under a prior the regularised one,
//! [`crate::fit::prior::leverages`]). The redundancies add up to
//! `m - rank`, so the kinds' estimates together use every degree of freedom once.
//!
//! [`reweigh`] iterates: fit, estimate the noise of every kind whose noise was not declared,
//! weigh it so, fit again, until the estimates settle.
//!
//! ```
//! use cpm_calib::{noise, IdentifyOptions, MeasurementModel, Plan, SimulationOptions, Noise};
//! use cpm_calib::campaign::paper_circle;
//! use cpm_geometry::{InstallationErrors, JointTable};
//! let model = MeasurementModel::new(JointTable::paper_cubic());
//! let plan = Plan { poses: paper_circle(&model.nominal.home), sensors: vec![0] };
//! let truth = InstallationErrors::paper_table2().to_vec_um();
//! let options = SimulationOptions { noise: Noise::Gaussian { sigma_um: 2.0 }, ..Default::default() };
//! let data = cpm_calib::simulate(&model, &truth, &plan, &options).unwrap();
//! let cal = cpm_calib::identify(&model, &data, &IdentifyOptions::default()).unwrap();
//! let kinds = noise::by_kind(&model, &data, &cal);
//! assert_eq!(kinds.len(), 1); // one gauge, named as in the joint table
//! assert_eq!(kinds[0].name, "gauge paper");
//! // 36 readings less the effective number of parameters the fit used (the leverages' sum:
//! // at most the rank, less what the prior holds): the residual's degrees of freedom.
//! let p_eff: f64 = cal.leverages.iter().sum();
//! assert!(p_eff <= cal.identifiability.rank as f64 + 1e-9);
//! assert!((kinds[0].redundancy - (36.0 - p_eff)).abs() < 1e-6);
//! // One kind alone: its estimate is the fit's own noise estimate.
//! assert!((kinds[0].estimated.unwrap() - cal.sigma_um).abs() < 1e-9 * cal.sigma_um);
//! ```
use serde::{Deserialize, Serialize};

use crate::data::campaign::ObservationKind;
use crate::fit::identify::{identify, Calibration, IdentifyOptions};
use crate::{CalibError, Campaign, MeasurementModel};

/// A kind of observation that shares one noise level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// The readings of gauge (sensor) `i`.
    Gauge(usize),
    /// Tracker position coordinates.
    TrackerPositions,
    /// Tracker orientation components.
    TrackerOrientations,
    /// Point-target coordinates.
    Points,
    /// The values of one's own instrument `i` ([`MeasurementModel::instruments`]).
    Instrument(usize),
    /// Inclinometer angles.
    Tilts,
}

impl Kind {
    /// The kind of observation `k` of a campaign.
    pub fn of(campaign: &Campaign, k: ObservationKind) -> Kind {
        match k {
            ObservationKind::Reading(i) => Kind::Gauge(campaign.readings[i].sensor),
            ObservationKind::TrackerPosition(..) => Kind::TrackerPositions,
            ObservationKind::TrackerOrientation(..) => Kind::TrackerOrientations,
            ObservationKind::Point(..) => Kind::Points,
            ObservationKind::Tilt(..) => Kind::Tilts,
            ObservationKind::Instrument(q, _) => {
                Kind::Instrument(campaign.instrument_measurements[q].instrument)
            }
        }
    }

    /// The unit of its noise: um, urad for orientations and angles, the instrument's own
    /// for one's own instrument.
    pub fn unit(self, model: &MeasurementModel) -> String {
        match self {
            Kind::TrackerOrientations | Kind::Tilts => "urad".into(),
            Kind::Instrument(i) => model
                .instruments
                .get(i)
                .map_or("?".into(), |x| x.unit().to_string()),
            _ => "um".into(),
        }
    }
}

/// The noise of one kind of observation: assumed by the fit, and estimated from its residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KindNoise {
    /// The kind.
    pub kind: Kind,
    /// In words: `gauge s1`, `tracker positions`, ...
    pub name: String,
    /// Its unit (`um` or `urad`).
    pub unit: String,
    /// Number of observations.
    pub observations: usize,
    /// Its share of the residual degrees of freedom (sum of its redundancy numbers).
    pub redundancy: f64,
    /// The noise the fit weighed it with (native unit).
    pub assumed: f64,
    /// The noise its residual says (native unit); `None` below one degree of freedom.
    pub estimated: Option<f64>,
    /// The RMS of its residuals after the fit (native unit: um or urad, not weighted), the
    /// observations set aside left out.
    pub rms: f64,
    /// Its observations the fit set aside as gross outliers ([`Calibration::set_aside`]):
    /// left out of `rms`, `estimated` and `redundancy`.
    pub set_aside: usize,
}

impl KindNoise {
    /// Estimated over assumed noise (`None` when not estimated).
    pub fn ratio(&self) -> Option<f64> {
        self.estimated.map(|e| e / self.assumed)
    }
}

/// Least redundancy for a kind's estimate to be used to weigh it or to warn about it.
pub const MIN_REDUNDANCY: f64 = 10.0;

/// The noise each kind of observation of `campaign` was weighed with by the fit `cal`, and
/// what its residual says, in the order of [`Kind`].
pub fn by_kind(model: &MeasurementModel, campaign: &Campaign, cal: &Calibration) -> Vec<KindNoise> {
    // Without leverages (a formulation that does not keep the Jacobian), every observation
    // gets the mean redundancy.
    let m = cal.residuals_um.len();
    let mean_leverage = cal.identifiability.rank as f64 / m.max(1) as f64;
    let h = |i: usize| cal.leverages.get(i).copied().unwrap_or(mean_leverage);
    // Each kind's totals (squared residuals, redundancy, observations, set aside) in one pass
    // over the observations: each kind's sums add its terms in observation order, as a pass
    // over that kind alone would. The kinds are few; a run of one kind finds its totals once.
    let mut totals: Vec<(Kind, (f64, f64, usize, usize))> = Vec::new();
    let mut at = 0;
    for (i, k) in campaign.observation_kinds().into_iter().enumerate() {
        let kind = Kind::of(campaign, k);
        if totals.get(at).is_none_or(|(k, _)| *k != kind) {
            at = match totals.iter().position(|(k, _)| *k == kind) {
                Some(p) => p,
                None => {
                    totals.push((kind, (0.0, 0.0, 0, 0)));
                    totals.len() - 1
                }
            };
        }
        let t = &mut totals[at].1;
        if cal.set_aside.binary_search(&i).is_ok() {
            t.3 += 1;
            continue;
        }
        t.0 += cal.residuals_um[i].powi(2);
        t.1 += (1.0 - h(i)).max(0.0);
        t.2 += 1;
    }
    totals.sort_by_key(|(k, _)| *k);
    // Residuals are in um of the reference noise `sigma_ref`: a kind assumed at `s` (native)
    // was weighed by `sigma_ref / s`.
    let sigma_ref = cal.sigma_ref_um;
    totals
        .into_iter()
        .map(|(kind, (ssr, red, n, aside))| {
            let assumed = assumed_sigma(campaign, kind, sigma_ref);
            let estimated = (red >= 1.0).then(|| (ssr / red).sqrt() * assumed / sigma_ref);
            let rms = (ssr / n.max(1) as f64).sqrt() * assumed / sigma_ref;
            KindNoise {
                kind,
                name: name(model, kind),
                unit: kind.unit(model),
                observations: n + aside,
                redundancy: red,
                assumed,
                estimated,
                rms,
                set_aside: aside,
            }
        })
        .collect()
}

/// Whether the residual vector of a fit mixes kinds of observation weighed differently (an
/// angle beside a length, or two lengths of different noise): its RMS is then a weighted
/// figure, in um of the reference noise, not a length.
pub fn residual_is_weighted(kinds: &[KindNoise]) -> bool {
    let um: Vec<&KindNoise> = kinds.iter().filter(|k| k.unit == "um").collect();
    um.len() < kinds.len()
        || um
            .windows(2)
            .any(|w| (w[0].assumed - w[1].assumed).abs() > 1e-12 * w[0].assumed.abs())
}

/// The native values and units of residuals `ks` of a fit (`residuals_um`, weighed in um of
/// the reference noise `sigma_ref_um`): um for lengths, urad for angles; `None` for an index
/// past the campaign's observations.
pub fn native_residuals(
    model: &MeasurementModel,
    campaign: &Campaign,
    sigma_ref_um: f64,
    residuals_um: &[f64],
    ks: &[usize],
) -> Vec<Option<(f64, String)>> {
    if ks.is_empty() {
        return Vec::new();
    }
    let kinds = campaign.observation_kinds();
    ks.iter()
        .map(|&k| {
            let kind = Kind::of(campaign, *kinds.get(k)?);
            let assumed = assumed_sigma(campaign, kind, sigma_ref_um);
            Some((
                residuals_um.get(k)? * assumed / sigma_ref_um,
                kind.unit(model),
            ))
        })
        .collect()
}

/// Every observation's residual in its own unit, measured minus predicted (um for lengths,
/// positions and points, urad for angles, the instrument's unit for one's own instruments;
/// in the fit's axes), from the fit's weighted residuals `residuals_um` (predicted minus
/// measured, um of the reference `sigma_ref_um`): what `residuals.csv` writes.
pub fn measured_minus_predicted(
    campaign: &Campaign,
    sigma_ref_um: f64,
    residuals_um: &[f64],
) -> Vec<f64> {
    let w = campaign.observation_weights(sigma_ref_um);
    let mut native: Vec<f64> = residuals_um.iter().zip(&w).map(|(r, w)| -r / w).collect();
    // The weights count one's own instruments' values in thousandths of their unit (as mm
    // in um): back to the unit.
    for v in native
        .iter_mut()
        .skip(campaign.first_instrument_observation())
    {
        *v *= 1e-3;
    }
    native
}

/// The kinds whose estimated noise differs from the assumed one by more than a factor
/// `factor`, with at least [`MIN_REDUNDANCY`] degrees of freedom each.
pub fn mismatched(kinds: &[KindNoise], factor: f64) -> Vec<&KindNoise> {
    kinds
        .iter()
        .filter(|k| k.redundancy >= MIN_REDUNDANCY)
        .filter(|k| k.ratio().is_some_and(|r| r > factor || r < 1.0 / factor))
        .collect()
}

/// Which kinds' noise a user declared (and [`reweigh`] leaves alone).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Declared {
    /// Gauge readings (`IdentifyOptions::sigma_um` or `--sigma-um`).
    pub gauges: bool,
    /// Tracker positions (`Campaign::pose_sigma_um`).
    pub tracker_positions: bool,
    /// Tracker orientations (`Campaign::orientation_sigma_urad`).
    pub tracker_orientations: bool,
    /// Point coordinates (`Campaign::point_sigma_um`).
    pub points: bool,
    /// Inclinometer angles (`Campaign::tilt_sigma_urad`).
    pub tilts: bool,
}

impl Declared {
    /// What a campaign and the options declare: a noise field set (> 0), and `sigma_um`.
    pub fn of(campaign: &Campaign, options: &IdentifyOptions) -> Self {
        Self {
            gauges: options.sigma_um.is_some(),
            tracker_positions: campaign.pose_sigma_um > 0.0,
            tracker_orientations: campaign.orientation_sigma_urad > 0.0,
            points: campaign.point_sigma_um > 0.0,
            tilts: campaign.tilt_sigma_urad > 0.0,
        }
    }
}

/// Whether [`reweigh`] has work: the campaign holds two or more kinds of observation (all
/// gauges count as one kind: they share one noise) and at least one of them has no declared
/// noise. Then one common noise scale cannot weigh the kinds against each other, and the
/// command-line fit estimates each kind's noise by default.
///
/// ```
/// use cpm_calib::{noise, Campaign};
/// let empty = Campaign::default();
/// assert!(!noise::needs_reweighing(&empty, noise::Declared::default()));
/// ```
pub fn needs_reweighing(campaign: &Campaign, declared: Declared) -> bool {
    let rows = campaign.pose_observation_rows();
    let positions = rows.iter().any(|r| r[..3].iter().any(Option::is_some));
    let orientations = rows.iter().any(|r| r[3..].iter().any(Option::is_some));
    let present = [
        (!campaign.readings.is_empty(), declared.gauges),
        (positions, declared.tracker_positions),
        (orientations, declared.tracker_orientations),
        (!campaign.point_measurements.is_empty(), declared.points),
        (!campaign.tilt_measurements.is_empty(), declared.tilts),
        // One's own instruments declare their noise with every measurement.
        (!campaign.instrument_measurements.is_empty(), true),
    ];
    let kinds = present.iter().filter(|(p, _)| *p).count();
    kinds >= 2 && present.iter().any(|(p, d)| *p && !*d)
}

/// The outcome of [`reweigh`].
#[derive(Debug, Clone)]
pub struct Reweighed {
    /// The campaign with the estimated noise of every undeclared kind in its noise fields.
    pub campaign: Campaign,
    /// The options of the final fit (`sigma_um` set when the gauges' noise was estimated and
    /// other kinds were weighed against it).
    pub options: IdentifyOptions,
    /// The final fit.
    pub calibration: Calibration,
    /// The noise per kind at the final fit.
    pub kinds: Vec<KindNoise>,
    /// Fits made (1: nothing to reweigh).
    pub fits: usize,
}

/// Most fits of [`reweigh`].
pub const MAX_REWEIGH_FITS: usize = 8;

/// Fits, then weighs every kind of observation whose noise was not declared by the noise its
/// residual shows (with at least [`MIN_REDUNDANCY`] degrees of freedom; estimates are kept
/// within a factor 1000 of the default), and fits again until every estimate moves by less
/// than 1 %, at most [`MAX_REWEIGH_FITS`] fits. With one kind of observation, or every kind
/// declared, it is one [`identify`].
pub fn reweigh(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &IdentifyOptions,
    declared: Declared,
) -> Result<Reweighed, CalibError> {
    let mut campaign = campaign.clone();
    let mut options = options.clone();
    let mut cal = identify(model, &campaign, &options)?;
    let mut fits = 1;
    loop {
        let kinds = by_kind(model, &campaign, &cal);
        let tracker_kinds = kinds
            .iter()
            .filter(|k| !matches!(k.kind, Kind::Gauge(_)))
            .count();
        let gauge_kinds = kinds.len() - tracker_kinds;
        // One kind alone is weighed by the pooled estimate already.
        if kinds.len() < 2 || fits >= MAX_REWEIGH_FITS {
            return Ok(Reweighed {
                campaign,
                options,
                calibration: cal,
                kinds,
                fits,
            });
        }
        let mut moved = false;
        let mut update = |field: &mut f64, default: f64, k: &KindNoise| {
            let Some(e) = k.estimated.filter(|_| k.redundancy >= MIN_REDUNDANCY) else {
                return;
            };
            let e = e.clamp(default * 1e-3, default * 1e3);
            if (e / k.assumed - 1.0).abs() > 0.01 {
                *field = e;
                moved = true;
            }
        };
        for k in &kinds {
            match k.kind {
                Kind::TrackerPositions if !declared.tracker_positions => {
                    update(&mut campaign.pose_sigma_um, 10.0, k)
                }
                Kind::TrackerOrientations if !declared.tracker_orientations => {
                    update(&mut campaign.orientation_sigma_urad, 20.0, k)
                }
                Kind::Points if !declared.points => update(&mut campaign.point_sigma_um, 10.0, k),
                Kind::Tilts if !declared.tilts => update(&mut campaign.tilt_sigma_urad, 20.0, k),
                _ => {}
            }
        }
        // The gauges (one noise for all, the reference of the weights): estimated from their
        // own residual when other kinds are present and it was not declared.
        if !declared.gauges && gauge_kinds > 0 && tracker_kinds > 0 {
            let (mut ssr, mut red) = (0.0, 0.0);
            for k in kinds.iter().filter(|k| matches!(k.kind, Kind::Gauge(_))) {
                if let Some(e) = k.estimated {
                    ssr += e * e * k.redundancy;
                    red += k.redundancy;
                }
            }
            if red >= MIN_REDUNDANCY {
                let e = (ssr / red).sqrt().max(1e-6);
                let current = options
                    .sigma_um
                    .or(campaign.reading_sigma())
                    .unwrap_or(cal.sigma_ref_um);
                if (e / current - 1.0).abs() > 0.01 {
                    // The reference of the weights and the gauges' own noise, both.
                    options.sigma_um = Some(e);
                    campaign.reading_sigma_um = e;
                    moved = true;
                }
            }
        }
        if !moved {
            return Ok(Reweighed {
                campaign,
                options,
                calibration: cal,
                kinds,
                fits,
            });
        }
        let next = IdentifyOptions {
            start_um: Some(cal.minimum_norm_um.clone()),
            ..options.clone()
        };
        cal = identify(model, &campaign, &next)?;
        fits += 1;
    }
}

/// The noise a kind was weighed with, native unit.
fn assumed_sigma(campaign: &Campaign, kind: Kind, sigma_ref: f64) -> f64 {
    match kind {
        Kind::Gauge(_) => campaign.reading_sigma().unwrap_or(sigma_ref),
        Kind::TrackerPositions => campaign.pose_sigma(),
        Kind::TrackerOrientations => campaign.orientation_sigma(),
        Kind::Points => campaign.point_sigma(),
        Kind::Tilts => campaign.tilt_sigma(),
        // Each measurement declares its own: their RMS.
        Kind::Instrument(i) => {
            let s: Vec<f64> = campaign
                .instrument_measurements
                .iter()
                .filter(|m| m.instrument == i)
                .map(|m| m.sigma)
                .collect();
            (s.iter().map(|v| v * v).sum::<f64>() / s.len().max(1) as f64).sqrt()
        }
    }
}

fn name(model: &MeasurementModel, kind: Kind) -> String {
    match kind {
        Kind::Gauge(i) => match model.nominal.sensors.get(i) {
            Some(s) => format!("gauge {}", s.name),
            None => format!("gauge {}", i + 1),
        },
        Kind::TrackerPositions => "tracker positions".into(),
        Kind::TrackerOrientations => "tracker orientations".into(),
        Kind::Points => "point targets".into(),
        Kind::Tilts => "inclinometer angles".into(),
        Kind::Instrument(i) => match model.instruments.get(i) {
            Some(x) => format!("instrument {}", x.name()),
            None => format!("instrument {}", i + 1),
        },
    }
}
