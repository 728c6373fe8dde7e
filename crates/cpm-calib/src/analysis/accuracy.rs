//! Platform pose accuracy over validation poses: nominal control against calibrated control.
//!
//! For a target pose the controller commands link lengths from a model's inverse kinematics
//! (minus the clearance shift it expects); the machine (the true joint table) settles where
//! forward kinematics puts it. The pose error is the twist from target to reached pose.
use cpm_geometry::{JointTable, Pose};
use cpm_kinematics::{forward, inverse_lengths};
use serde::{Deserialize, Serialize};

use crate::{CalibError, MeasurementModel};

/// Pose error statistics over a set of poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseErrorStats {
    /// RMS position error, um.
    pub rms_position_um: f64,
    /// Largest position error, um.
    pub max_position_um: f64,
    /// RMS orientation error, urad.
    pub rms_orientation_urad: f64,
    /// Largest orientation error, urad.
    pub max_orientation_urad: f64,
}

/// Pose accuracy with the nominal model and with the calibrated one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AccuracyReport {
    /// Number of validation poses.
    pub poses: usize,
    /// Errors when commanding from the nominal geometry.
    pub nominal: PoseErrorStats,
    /// Errors when commanding from the calibrated geometry.
    pub calibrated: PoseErrorStats,
}

/// Pose errors reached on `truth` when commanding from `control` over `targets`.
pub fn pose_errors(
    model: &MeasurementModel,
    truth: &JointTable,
    control: &JointTable,
    targets: &[Pose],
) -> Result<PoseErrorStats, CalibError> {
    let mut pos = Vec::with_capacity(targets.len());
    let mut ori = Vec::with_capacity(targets.len());
    for (j, target) in targets.iter().enumerate() {
        // The controller pre-subtracts the clearance shift it expects and the machine adds it
        // back, so the effective lengths are the control model's inverse kinematics.
        let l = inverse_lengths(control, target);
        let (reached, _) = forward(truth, &l, target, &model.fk)
            .map_err(|source| CalibError::Kinematics { pose: j, source })?;
        let d = target.difference(&reached);
        pos.push((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() * 1e3);
        ori.push((d[3] * d[3] + d[4] * d[4] + d[5] * d[5]).sqrt() * 1e6);
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    Ok(PoseErrorStats {
        rms_position_um: rms(&pos),
        max_position_um: max(&pos),
        rms_orientation_urad: rms(&ori),
        max_orientation_urad: max(&ori),
    })
}

/// Nominal against calibrated control on the true machine.
pub fn accuracy(
    model: &MeasurementModel,
    truth_um: &[f64],
    calibrated_um: &[f64],
    targets: &[Pose],
) -> Result<AccuracyReport, CalibError> {
    let truth = model.table_with(truth_um)?;
    let calibrated = model.table_with(calibrated_um)?;
    Ok(AccuracyReport {
        poses: targets.len(),
        nominal: pose_errors(model, &truth, &model.nominal, targets)?,
        calibrated: pose_errors(model, &truth, &calibrated, targets)?,
    })
}
