//! A measurement session re-registered against a machine held fixed: the session's own
//! nuisance parameters (the tracker frame) fitted through the one prediction path.
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

use crate::identify::rms;
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
}

struct FrameProblem<'a> {
    model: &'a MeasurementModel,
    prepared: &'a Prepared,
    campaign: &'a Campaign,
    measured: Vec<f64>,
    weights: Vec<f64>,
    offset: usize,
    full: Vec<f64>,
    jac: DMatrix<f64>,
}

impl FrameProblem<'_> {
    fn params(&self, x: &[f64]) -> Vec<f64> {
        let mut p = self.full.clone();
        p[self.offset..self.offset + 6].copy_from_slice(x);
        p
    }
}

impl Problem for FrameProblem<'_> {
    fn num_params(&self) -> usize {
        6
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
        for c in 0..6 {
            for r in 0..self.measured.len() {
                jac[(r, c)] = self.jac[(r, self.offset + c)] * 1e3 * self.weights[r];
            }
        }
        Ok(())
    }
}

/// Fits the frame of one tracker session (`campaign`'s pose measurements) with the machine
/// of `machine` held fixed (every known effect applied, nothing else estimated).
///
/// Errors: a campaign without pose measurements, or a model that cannot predict it.
pub fn register_session(
    machine: &MeasurementModel,
    campaign: &Campaign,
) -> Result<SessionFit, CalibError> {
    if campaign.pose_measurements.is_empty() {
        return Err(CalibError::NoInformation(
            "a session frame needs tracker pose measurements".into(),
        ));
    }
    let mut model = machine.clone();
    model.effects = vec![Effect::TrackerFrame];
    model.tracker_frame_sessions.clear();
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
        full: vec![0.0; model.num_params()],
        jac: DMatrix::zeros(m, model.num_params()),
    };
    let mut x = vec![0.0; 6];
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
    let solver = cpm_lm::minimize(&mut problem, &mut x, &options)?;
    problem
        .residuals(&x, &mut r)
        .map_err(|e| CalibError::invalid("session model", e.to_string()))?;
    let rms_after_um = rms(&r);
    // Covariance: s^2 (J^T J)^-1 with s^2 the weighted residual variance.
    let mut j = faer::Mat::<f64>::zeros(m, 6);
    problem
        .jacobian(&x, j.as_mut())
        .map_err(|e| CalibError::invalid("session model", e.to_string()))?;
    let jn = DMatrix::from_fn(m, 6, |a, b| j[(a, b)]);
    let s2 = r.iter().map(|v| v * v).sum::<f64>() / (m.saturating_sub(6).max(1)) as f64;
    let mut frame_sd = [f64::NAN; 6];
    if let Some(ch) = (jn.transpose() * &jn).cholesky() {
        let inv = ch.inverse();
        for (k, sd) in frame_sd.iter_mut().enumerate() {
            *sd = (s2 * inv[(k, k)]).sqrt();
        }
    }
    let params = problem.params(&x);
    let predicted = predict(&model, &prepared, campaign, &params, None)?;
    let mut frame = [0.0; 6];
    frame.copy_from_slice(&x);
    Ok(SessionFit {
        frame,
        frame_sd,
        rms_before_um,
        rms_after_um,
        predicted,
        params,
        model,
        solver,
    })
}
