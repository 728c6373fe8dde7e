//! What a compensation can promise: the pose error a calibrated machine is predicted to
//! leave at a target, with its uncertainty, from the covariance of the fitted parameters.
//!
//! A compensation commands the link lengths the calibrated model needs to reach the target.
//! The true machine, whose parameters differ from the estimate by `d = e_true - e_hat`,
//! settles elsewhere: to first order the twist from target to reached pose (position mm,
//! rotation rad, base frame, as [`Pose::difference`]) is `G d`, with `G` the reached pose's
//! derivative with respect to the parameters at the commanded lengths (the measurement model's
//! own Jacobian of a 6-D pose measurement). `d` has the covariance `C` of the fitted
//! parameters ([`parameter_covariance`]: the posterior under the fit's prior, where a
//! direction the data see less well than its tolerance carries that tolerance), so the twist
//! has `G C G^T` ([`predicted_pose_error`]). Blind free directions carry no covariance: no
//! number about them is known, and the compensation cannot correct them (name them beside the
//! band).
//!
//! The bands are those of a Gaussian: per component `z sigma`, and for the position (and the
//! orientation) the ellipsoid `t^T P^-1 t <= chi2_3(0.95)`, whose largest semi-axis is the
//! radius quoted ([`PredictedPoseError::position_95_um`]). ISO 9283 judges a pose by its
//! accuracy (the attained pose against the commanded one, AP); over targets the predicted
//! figures are the bands of its terms AP_x .. AP_c and of AP_p.
//!
//! ```
//! use cpm_calib::paper::{designed_sensors, random_workspace_poses};
//! use cpm_calib::promise::{parameter_covariance, predicted_pose_error};
//! use cpm_calib::*;
//!
//! let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
//! model.nominal.sensors = designed_sensors();
//! let plan = Plan { poses: random_workspace_poses(&model.nominal, 40, 80.0, 20.0, 3.0, 1),
//!                   sensors: (0..16).collect() };
//! let truth: Vec<f64> = (0..36).map(|k| 40.0 * (k as f64 * 0.9).sin()).collect();
//! let sim = SimulationOptions { noise: Noise::Gaussian { sigma_um: 2.0 }, ..Default::default() };
//! let data = simulate(&model, &truth, &plan, &sim).unwrap();
//! let options = IdentifyOptions { sigma_um: Some(2.0), ..Default::default() };
//! let cal = identify(&model, &data, &options).unwrap();
//! let c = parameter_covariance(&model, &data, &cal).unwrap();
//! // The fit formed it too, and its diagonal is the fit's own (posterior, under the default
//! // prior) standard deviations.
//! assert_eq!(c, cal.covariance);
//! let std = cal.prior.as_ref().unwrap().posterior_std[0].unwrap();
//! assert!((c[(0, 0)].sqrt() - std).abs() < 1e-9 * std);
//! let target = model.nominal.home;
//! let p = predicted_pose_error(&model, &cal.minimum_norm_um, &c, &[target]).unwrap();
//! assert!(p[0].position_95_um() > 0.0 && p[0].position_95_um() < 100.0);
//! ```
use cpm_geometry::Pose;
use cpm_kinematics::inverse_lengths;
use nalgebra::{DMatrix, Matrix3, Matrix6, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::campaign::PoseMeasurement;
use crate::model::{predict, Prepared};
use crate::{CalibError, Calibration, Campaign, MeasurementModel};

/// `chi2_3(0.95)`: the 95 % quantile of the chi-square distribution with 3 degrees of freedom
/// (a 3-D Gaussian's 95 % ellipsoid).
pub const CHI2_3_95: f64 = 7.814_727_903_251_178;

/// The two-sided 95 % quantile of the standard normal (a component's band).
pub const Z_95: f64 = 1.959_963_984_540_054;

/// The covariance of the fitted parameters (model units squared: um^2, ppm^2, ...) at the
/// solution, with the fit's weights (the observations it set aside at weight zero) and its
/// noise `sigma_um`:
/// - under a prior ([`Calibration::prior`]), the posterior `(J^T W J / sigma^2 +
///   diag(1 / t^2))^+` over the unheld parameters, as the fit's summary takes it: its diagonal
///   is the square of [`PriorSummary::posterior_std`](crate::prior::PriorSummary::posterior_std),
///   a direction held by its tolerance carries that tolerance, a held parameter none;
/// - without one, `sigma^2 (J^T W J)^+` over the fit's rank: its diagonal is the square of
///   [`Calibration::std_um`] where the data determine a parameter on its own.
///
/// What neither the data nor a tolerance bounds (a blind free direction) gets zero variance:
/// no number about it is measured, and a promise must name it beside the band.
pub fn parameter_covariance(
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &Calibration,
) -> Result<DMatrix<f64>, CalibError> {
    let np = model.num_params();
    let prepared = Prepared::new(model, campaign)?;
    let mut j = DMatrix::zeros(campaign.len(), np);
    predict(
        model,
        &prepared,
        campaign,
        &cal.minimum_norm_um,
        Some(&mut j),
    )?;
    let mut w = campaign.observation_weights(cal.sigma_ref_um);
    for &k in &cal.set_aside {
        w[k] = 0.0;
    }
    for (r, wr) in w.iter().enumerate() {
        let mut row = j.row_mut(r);
        row *= 1e3 * wr;
    }
    let prior =
        (cal.prior.is_some() && cal.prior_std.len() == np).then_some(cal.prior_std.as_slice());
    if let Some(prior) = prior {
        for (k, p) in prior.iter().enumerate() {
            if *p == 0.0 {
                j.column_mut(k).fill(0.0);
            }
        }
    }
    covariance_of(&j, prior, cal.sigma_um, &cal.identifiability)
}

/// The covariance of a fit's parameters from its weighted Jacobian `j` (um of the reference per
/// unit; held parameters' columns zero), its prior (standard deviation per parameter: 0 held,
/// infinite free; `None` for a fit without one), its noise `sigma_um` and its identifiability
/// at the solution (the rank, and the column scale the prior's cut-offs are taken with).
pub(crate) fn covariance_of(
    j: &DMatrix<f64>,
    prior: Option<&[f64]>,
    sigma_um: f64,
    ident: &crate::Identifiability,
) -> Result<DMatrix<f64>, CalibError> {
    let np = j.ncols();
    if let Some(prior) = prior {
        let scale = &ident.rank_column_scale;
        return Ok(crate::prior::posterior_covariance(
            j,
            prior,
            sigma_um,
            (scale.len() == np).then_some(scale.as_slice()),
        ));
    }
    // sigma^2 (J^T J)^+ over the fit's rank, from the eigenpairs of J^T J (np x np: no
    // decomposition of the tall Jacobian).
    let eig = (j.transpose() * j).symmetric_eigen();
    let mut order: Vec<usize> = (0..np).collect();
    order.sort_by(|a, b| eig.eigenvalues[*b].total_cmp(&eig.eigenvalues[*a]));
    let mut c = DMatrix::zeros(np, np);
    for &i in order.iter().take(ident.rank.min(np)) {
        let l = eig.eigenvalues[i];
        if l > 0.0 {
            let v = eig.eigenvectors.column(i);
            c += (v * v.transpose()) * (sigma_um * sigma_um / l);
        }
    }
    Ok(c)
}

/// The pose error predicted at one target after compensation: the covariance of the twist
/// from target to reached pose (position mm, rotation rad, base frame; mm^2, mm rad, rad^2).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PredictedPoseError {
    /// Covariance of the twist (x, y, z mm; rx, ry, rz rad).
    pub covariance: Matrix6<f64>,
}

impl PredictedPoseError {
    /// Standard deviation of each position component, um.
    pub fn position_std_um(&self) -> Vector3<f64> {
        Vector3::from_fn(|a, _| self.covariance[(a, a)].max(0.0).sqrt() * 1e3)
    }

    /// Standard deviation of each rotation component (about x, y, z of the base), urad.
    pub fn orientation_std_urad(&self) -> Vector3<f64> {
        Vector3::from_fn(|a, _| self.covariance[(3 + a, 3 + a)].max(0.0).sqrt() * 1e6)
    }

    fn block(&self, at: usize) -> Matrix3<f64> {
        self.covariance.fixed_view::<3, 3>(at, at).into_owned()
    }

    /// Radius of the position's 95 % band, um: the largest semi-axis of the ellipsoid
    /// `t^T P^-1 t <= chi2_3(0.95)` (a sphere of this radius holds it).
    pub fn position_95_um(&self) -> f64 {
        largest_semi_axis(&self.block(0)) * 1e3
    }

    /// Radius of the orientation's 95 % band, urad, as [`position_95_um`](Self::position_95_um).
    pub fn orientation_95_urad(&self) -> f64 {
        largest_semi_axis(&self.block(3)) * 1e6
    }

    /// True when the position part of `twist` (mm, as [`Pose::difference`]) lies in the 95 %
    /// ellipsoid.
    pub fn position_covers(&self, twist: &Vector6<f64>) -> bool {
        within(&self.block(0), &twist.fixed_rows::<3>(0).into_owned())
    }

    /// True when the rotation part of `twist` (rad) lies in the 95 % ellipsoid.
    pub fn orientation_covers(&self, twist: &Vector6<f64>) -> bool {
        within(&self.block(3), &twist.fixed_rows::<3>(3).into_owned())
    }
}

fn largest_semi_axis(p: &Matrix3<f64>) -> f64 {
    let lmax = p.symmetric_eigenvalues().max().max(0.0);
    (CHI2_3_95 * lmax).sqrt()
}

fn within(p: &Matrix3<f64>, t: &Vector3<f64>) -> bool {
    // Pseudo-inverse on the eigenvectors the covariance has (a direction with no variance
    // holds no error: only a zero there is inside).
    let eig = p.symmetric_eigen();
    let top = eig.eigenvalues.max().max(0.0);
    let mut d2 = 0.0;
    for k in 0..3 {
        let l = eig.eigenvalues[k];
        let x = eig.eigenvectors.column(k).dot(t);
        if l > 1e-14 * top && l > 0.0 {
            d2 += x * x / l;
        } else if x.abs() > 0.0 {
            return false;
        }
    }
    d2 <= CHI2_3_95
}

/// The pose error predicted at each of `targets` when `model` with the parameters `fitted`
/// (the calibration's [`minimum_norm_um`](Calibration::minimum_norm_um)) commands the machine
/// there, given the parameters' covariance `covariance` ([`parameter_covariance`]).
///
/// The commands are the lengths the fitted joints need for the target (the model's clearance
/// and link effects are in the measurement model's Jacobian); the derivative `G` is the
/// model's own Jacobian of a 6-D pose measurement at those commands.
pub fn predicted_pose_error(
    model: &MeasurementModel,
    fitted: &[f64],
    covariance: &DMatrix<f64>,
    targets: &[Pose],
) -> Result<Vec<PredictedPoseError>, CalibError> {
    let np = model.num_params();
    if covariance.shape() != (np, np) || fitted.len() != np {
        return Err(CalibError::invalid(
            "covariance",
            format!(
                "{}x{} covariance and {} parameters for a model of {np}",
                covariance.nrows(),
                covariance.ncols(),
                fitted.len()
            ),
        ));
    }
    let table = model.table_with(fitted)?;
    let campaign = Campaign {
        poses: targets.to_vec(),
        commanded_lengths_mm: Some(targets.iter().map(|t| inverse_lengths(&table, t)).collect()),
        pose_measurements: targets
            .iter()
            .enumerate()
            .map(|(pose, t)| PoseMeasurement {
                pose,
                measured: *t,
                time_s: None,
                temperature_c: None,
            })
            .collect(),
        ..Campaign::default()
    };
    let prepared = Prepared::new(model, &campaign)?;
    let mut j = DMatrix::zeros(campaign.len(), np);
    predict(model, &prepared, &campaign, fitted, Some(&mut j))?;
    let rows = campaign.pose_observation_rows();
    let mut out = Vec::with_capacity(targets.len());
    for rows in rows.iter().take(targets.len()) {
        // Position mm per unit, rotation mrad per unit: the twist's (mm, rad).
        let g = DMatrix::from_fn(6, np, |a, k| {
            let r = rows[a].expect("a pose measured in full has six rows");
            j[(r, k)] * if a < 3 { 1.0 } else { 1e-3 }
        });
        let p = &g * covariance * g.transpose();
        out.push(PredictedPoseError {
            covariance: Matrix6::from_fn(|a, b| 0.5 * (p[(a, b)] + p[(b, a)])),
        });
    }
    Ok(out)
}
