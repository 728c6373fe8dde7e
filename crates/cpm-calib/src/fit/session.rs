//! A measurement session re-registered against a machine held fixed: the session's own
//! nuisance parameters (the tracker frame, or the point targets' session frames) fitted through the one prediction path.
//!
//! A tracker or motion-capture system is set up afresh for every session, so a model judged on
//! a later session (or read back on its own training data) must first find that session's
//! frame. [`register_session`] fits the six `tracker_frame` parameters (tx, ty, tz um; rx, ry,
//! rz urad, on top of any known frame and of the rough registration the readers applied)
//! with every machine parameter and known effect of the model held fixed, using
//! [`crate::model::predict`], the code every fit uses, so that a calibrated model read back
//! reproduces the fit it came from. The standard deviations come from the fit's Jacobian and
//! the a-posteriori variance of its weighted residual.
//!
//! ```
//! use cpm_calib::{session::register_session, simulate, MeasurementModel, Plan, SimulationOptions};
//! use cpm_calib::campaign::PoseMeasurement;
//! use cpm_geometry::{JointTable, Pose};
//! let model = MeasurementModel::new(JointTable::paper_cubic());
//! let poses = cpm_calib::paper::random_workspace_poses(&model.nominal, 12, 20.0, 5.0, 3.0, 1);
//! // Tracker measurements of the nominal machine, in a frame 30 um / 50 urad away.
//! let mut c = Plan { poses: poses.clone(), sensors: vec![] }.skeleton();
//! let (t, r) = cpm_calib::effects::tracker_registration(&[30.0, -10.0, 5.0, 50.0, 0.0, -20.0]);
//! for (j, p) in poses.iter().enumerate() {
//!     let exact = cpm_kinematics::forward(&model.nominal,
//!         &model.effective_lengths(&c).unwrap()[j], p, &model.fk).unwrap().0;
//!     c.pose_measurements.push(PoseMeasurement {
//!         pose: j,
//!         measured: Pose::new(r * exact.position_mm + t, r * exact.rotation),
//!         time_s: None,
//!         temperature_c: None,
//!     });
//! }
//! let s = register_session(&model, &c).unwrap();
//! assert!((s.frame[0] - 30.0).abs() < 1e-3 && (s.frame[3] - 50.0).abs() < 1e-2);
//! assert!(s.rms_after_um < 1e-3 && s.rms_before_um > 10.0);
//! ```
use cpm_lm::{DenseJacobian, ModelError, Problem};
use nalgebra::DMatrix;

use crate::fit::identify::rms;
use crate::model::{predict, Prepared};
use crate::{CalibError, Campaign, Effect, MeasurementModel};

/// A session's frame fitted against a fixed machine.
#[derive(Debug, Clone)]
pub struct SessionFit {
    /// The frame correction found: tx, ty, tz (um), rx, ry, rz (urad), in the convention of
    /// the `tracker_frame` effect (`p_tracker = R p_base + t`).
    pub frame: [f64; 6],
    /// Standard deviations of [`frame`](Self::frame), same units.
    pub frame_sd: [f64; 6],
    /// Every frame fitted (six values per point session; the one frame of tracker poses).
    pub frames: Vec<f64>,
    /// Their standard deviations.
    pub frames_sd: Vec<f64>,
    /// Weighted RMS residual (um of a length reading's noise) before the fit.
    pub rms_before_um: f64,
    /// Weighted RMS residual after.
    pub rms_after_um: f64,
    /// Predicted observations with the fitted frame, in the units of
    /// [`Campaign::observations`] (mm, and mrad for tracker orientations).
    pub predicted: Vec<f64>,
    /// The full parameter vector of the frame model (installation errors zero, the frame
    /// last), for [`crate::model::predict`] with [`SessionFit::model`].
    pub params: Vec<f64>,
    /// The model the frame was fitted with: the machine plus `tracker_frame`.
    pub model: MeasurementModel,
    /// The solver's report.
    pub solver: cpm_lm::Report,
    /// The observations set aside as gross outliers (indices into
    /// [`Campaign::observations`]): more than [`SET_ASIDE_SIGMAS`](crate::SET_ASIDE_SIGMAS)
    /// robust standard deviations of their kind off, by the rule the fit sets them aside
    /// with; the frame is fitted without them (their predictions are still given).
    pub set_aside: Vec<usize>,
}

struct FrameProblem<'a> {
    model: &'a MeasurementModel,
    prepared: &'a Prepared,
    campaign: &'a Campaign,
    measured: Vec<f64>,
    weights: Vec<f64>,
    offset: usize,
    nf: usize,
    full: Vec<f64>,
    jac: DMatrix<f64>,
}

impl FrameProblem<'_> {
    fn params(&self, x: &[f64]) -> Vec<f64> {
        let mut p = self.full.clone();
        p[self.offset..self.offset + self.nf].copy_from_slice(x);
        p
    }
}

impl Problem for FrameProblem<'_> {
    fn num_params(&self) -> usize {
        self.nf
    }
    fn num_residuals(&self) -> usize {
        self.measured.len()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        let y = predict(
            self.model,
            self.prepared,
            self.campaign,
            &self.params(x),
            None,
        )?;
        for (((ri, yi), mi), w) in r.iter_mut().zip(&y).zip(&self.measured).zip(&self.weights) {
            *ri = (yi - mi) * 1e3 * w;
        }
        Ok(())
    }
}

impl DenseJacobian for FrameProblem<'_> {
    fn jacobian(&mut self, x: &[f64], mut jac: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
        let p = self.params(x);
        predict(
            self.model,
            self.prepared,
            self.campaign,
            &p,
            Some(&mut self.jac),
        )?;
        for c in 0..self.nf {
            for r in 0..self.measured.len() {
                jac[(r, c)] = self.jac[(r, self.offset + c)] * 1e3 * self.weights[r];
            }
        }
        Ok(())
    }
}

/// Fits the frame of one tracker session (`campaign`'s pose measurements) with the machine
/// of `machine` held fixed (every known effect applied, nothing else estimated). A campaign
/// of point measurements gets its `point_frame` (six parameters per point session, the
/// targets held at the machine's) instead, and a campaign of inclinometer angles its
/// `base_tilt` (two parameters per session: the session is re-levelled; the first two entries
/// of [`SessionFit::frame`]); [`SessionFit::frame`] is then the first session's frame and
/// [`SessionFit::frames`] all of them.
///
/// Errors: a campaign without pose or point measurements, or a model that cannot predict it.
pub fn register_session(
    machine: &MeasurementModel,
    campaign: &Campaign,
) -> Result<SessionFit, CalibError> {
    register_session_keeping(machine, campaign, false)
}

/// [`register_session`], with the gross outliers fitted too when `keep_outliers` (as a fit
/// with `--keep-outliers` fits them) instead of set aside.
pub fn register_session_keeping(
    machine: &MeasurementModel,
    campaign: &Campaign,
    keep_outliers: bool,
) -> Result<SessionFit, CalibError> {
    let mut model = machine.clone();
    model.tracker_frame_sessions.clear();
    let nf = if !campaign.pose_measurements.is_empty() {
        model.effects = vec![Effect::TrackerFrame];
        6
    } else if !campaign.point_measurements.is_empty() {
        model.point_sessions = campaign.point_sessions();
        model.effects = vec![Effect::PointFrame];
        6 * model.point_sessions
    } else if !campaign.tilt_measurements.is_empty() {
        model.tilt_sessions = campaign.tilt_sessions();
        model.effects = vec![Effect::BaseTilt];
        2 * model.tilt_sessions
    } else {
        return Err(CalibError::NoInformation(
            "a session frame needs tracker pose, point or inclinometer measurements".into(),
        ));
    };
    let offset = model.num_installation_params();
    let prepared = Prepared::new(&model, campaign)?;
    let weights = campaign.observation_weights(campaign.pose_sigma());
    let m = campaign.len();
    let mut problem = FrameProblem {
        model: &model,
        prepared: &prepared,
        campaign,
        measured: campaign.observations(),
        weights,
        offset,
        nf,
        full: vec![0.0; model.num_params()],
        jac: DMatrix::zeros(m, model.num_params()),
    };
    let mut x = vec![0.0; nf];
    let mut r = vec![0.0; m];
    problem
        .residuals(&x, &mut r)
        .map_err(|e| CalibError::invalid("session model", e.to_string()))?;
    let rms_before_um = rms(&r);
    let options = cpm_lm::Options {
        ftol: 1e-15,
        xtol: 1e-15,
        gtol: 1e-15,
        ..cpm_lm::Options::default()
    };
    let mut solver = cpm_lm::minimize(&mut problem, &mut x, &options)?;
    // Gross outliers set aside (weight zero) by the rule the fit sets them aside with, until
    // the set settles: one glitch must not drive the frame every other observation is
    // judged in, and a description read back registers its fit's sessions as the fit did.
    let mut set_aside: Vec<usize> = Vec::new();
    if !keep_outliers {
        let all = campaign.observation_weights(campaign.pose_sigma());
        for _ in 0..crate::MAX_SET_ASIDE_ROUNDS {
            // Every observation's residual, at its full weight.
            let kept = std::mem::replace(&mut problem.weights, all.clone());
            let got = problem.residuals(&x, &mut r);
            problem.weights = kept;
            got.map_err(|e| CalibError::invalid("session model", e.to_string()))?;
            let flagged = crate::analysis::diagnostics::to_set_aside(&r, campaign, None);
            if flagged == set_aside {
                break;
            }
            set_aside = flagged;
            problem.weights.clone_from(&all);
            for &k in &set_aside {
                problem.weights[k] = 0.0;
            }
            solver = cpm_lm::minimize(&mut problem, &mut x, &options)?;
        }
    }
    problem
        .residuals(&x, &mut r)
        .map_err(|e| CalibError::invalid("session model", e.to_string()))?;
    // Over the observations the frame was fitted to (those set aside are zero in `r`).
    let kept = m - set_aside.len();
    let rms_after_um = if set_aside.is_empty() {
        rms(&r)
    } else {
        (r.iter().map(|v| v * v).sum::<f64>() / kept.max(1) as f64).sqrt()
    };
    // Covariance: s^2 (J^T J)^-1 with s^2 the weighted residual variance.
    let mut j = faer::Mat::<f64>::zeros(m, nf);
    problem
        .jacobian(&x, j.as_mut())
        .map_err(|e| CalibError::invalid("session model", e.to_string()))?;
    let jn = DMatrix::from_fn(m, nf, |a, b| j[(a, b)]);
    let s2 = r.iter().map(|v| v * v).sum::<f64>() / (kept.saturating_sub(nf).max(1)) as f64;
    let mut frames_sd = vec![f64::NAN; nf];
    if let Some(ch) = (jn.transpose() * &jn).cholesky() {
        let inv = ch.inverse();
        for (k, sd) in frames_sd.iter_mut().enumerate() {
            *sd = (s2 * inv[(k, k)]).sqrt();
        }
    }
    let mut frame_sd = [f64::NAN; 6];
    let k = nf.min(6);
    frame_sd[..k].copy_from_slice(&frames_sd[..k]);
    let params = problem.params(&x);
    let predicted = predict(&model, &prepared, campaign, &params, None)?;
    let mut frame = [0.0; 6];
    frame[..k].copy_from_slice(&x[..k]);
    Ok(SessionFit {
        frame,
        frame_sd,
        frames: x,
        frames_sd,
        rms_before_um,
        rms_after_um,
        predicted,
        params,
        model,
        solver,
        set_aside,
    })
}

/// How far apart two sessions' own estimates of a machine parameter may be, in standard
/// deviations of their difference, before [`consistency`] calls the sessions inconsistent
/// (4: a chance of about 6e-5 per parameter for Gaussian estimates).
pub const SESSION_Z_LIMIT: f64 = 4.0;

/// Two sessions fitted on their own, compared parameter by parameter.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionPair {
    /// The sessions (0 for the first).
    pub sessions: [usize; 2],
    /// Machine parameters determined in both (a session's tracker frame is not compared).
    pub compared: usize,
    /// The parameter whose estimates differ most, in standard deviations of the difference.
    pub worst_parameter: String,
    /// Its difference over the standard deviation of the difference (signed: first - second).
    pub worst_z: f64,
    /// Parameters whose estimates differ by more than 3 standard deviations.
    pub beyond_3sd: usize,
}

/// Whether the estimates of each session, fitted on its own, agree within their deviations.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionConsistency {
    /// Every pair of sessions that both could be fitted.
    pub pairs: Vec<SessionPair>,
    /// False when some pair differs by more than [`SESSION_Z_LIMIT`] in some parameter.
    pub consistent: bool,
}

/// Fits each session of `campaign` ([`Campaign::session_starts`]) on its own with `model` and
/// compares the machine parameters each determines: a machine that moved between sessions, or
/// a model that lacks an effect the sessions see differently, shows estimates that move more
/// than their standard deviations allow. `None` with fewer than two sessions that can be
/// fitted on their own.
///
/// Errors: none from a session that cannot be fitted (it is left out); an invalid model.
pub fn consistency(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &crate::IdentifyOptions,
) -> Result<Option<SessionConsistency>, CalibError> {
    let sessions = campaign.session_starts.len() + 1;
    if sessions < 2 {
        return Ok(None);
    }
    let mut single = model.clone();
    single.tracker_frame_sessions.clear();
    let names = single.parameter_names();
    // Parameters that describe a session rather than the machine.
    let session_block: Vec<bool> = {
        let mut v = vec![false; single.num_params()];
        for b in single.blocks() {
            if matches!(
                b.effect,
                Some(Effect::TrackerFrame | Effect::PointFrame | Effect::BaseTilt)
            ) {
                v[b.offset..b.offset + b.len].fill(true);
            }
            // One's own instruments: their per-session parameters.
            if let Some(i) = b.instrument {
                let own = single.instruments[i].num_instrument_params();
                v[b.offset + own..b.offset + b.len].fill(true);
            }
        }
        v
    };
    let mut fits = Vec::new();
    for s in 0..sessions {
        let part = campaign.filter_poses(|p| campaign.session_of(p) == s);
        if part.is_empty() {
            continue;
        }
        if let Ok(cal) = crate::identify(&single, &part, options) {
            fits.push((s, cal));
        }
    }
    if fits.len() < 2 {
        return Ok(None);
    }
    let mut pairs = Vec::new();
    for a in 0..fits.len() {
        for b in a + 1..fits.len() {
            let (ca, cb) = (&fits[a].1, &fits[b].1);
            let mut z: Vec<(usize, f64)> = (0..names.len())
                .filter(|&k| !session_block[k])
                .filter_map(|k| {
                    let (ea, eb) = (ca.estimate_um[k]?, cb.estimate_um[k]?);
                    let (sa, sb) = (ca.std_um[k]?, cb.std_um[k]?);
                    let sd = (sa * sa + sb * sb).sqrt();
                    (sd > 0.0).then(|| (k, (ea - eb) / sd))
                })
                .collect();
            if z.is_empty() {
                continue;
            }
            z.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
            pairs.push(SessionPair {
                sessions: [fits[a].0, fits[b].0],
                compared: z.len(),
                worst_parameter: names[z[0].0].clone(),
                worst_z: z[0].1,
                beyond_3sd: z.iter().filter(|(_, v)| v.abs() > 3.0).count(),
            });
        }
    }
    if pairs.is_empty() {
        return Ok(None);
    }
    let consistent = pairs.iter().all(|p| p.worst_z.abs() <= SESSION_Z_LIMIT);
    Ok(Some(SessionConsistency { pairs, consistent }))
}
