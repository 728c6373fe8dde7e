//! Campaigns for the instruments people have beside a gauge: a 6-D tracker, laser-tracker
//! reflectors (point targets), inclinometers, or a mix; what each identifies (rank, the joint
//! errors determined, their Cramér-Rao bounds at each instrument's own noise) and the poses
//! that identify most for an observation budget.
//!
//! Every instrument brings its nuisance parameters, estimated with the machine, one session
//! each: a tracker frame (`tracker_frame`), the targets' platform positions and the points'
//! frame (`target_position`, `point_frame`), the inclinometers' mounts and the base's tilt
//! (`inclinometer_mount`, `base_tilt`) ([`Instruments::model`]). Observations are weighed by
//! their own noise ([`InstrumentNoise`]), so the bounds are in um of joint error.
//!
//! ```
//! use cpm_calib::design::instruments::{Instruments, InstrumentNoise};
//! use cpm_calib::paper::random_workspace_poses;
//! use cpm_calib::MeasurementModel;
//! use cpm_geometry::JointTable;
//! let model = MeasurementModel::new(JointTable::hexapod_66());
//! let poses = random_workspace_poses(&model.nominal, 100, 40.0, 8.0, 4.0, 3);
//! let gauges = Instruments { gauges: vec![0, 1, 2], ..Instruments::default() };
//! let bounds = gauges.bounds(&model, &poses, &InstrumentNoise::default()).unwrap();
//! assert_eq!(bounds.observations, 300);
//! assert_eq!(bounds.joint_errors_determined, 36);
//! assert!(bounds.joint_crb_rms_um > 0.0);
//! ```
use cpm_geometry::Pose;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::select::{select_blocks, SelectOptions};
use crate::analysis::identifiability::{try_analyze, RankOptions};
use crate::data::campaign::{PointMeasurement, PoseMeasurement, TiltMeasurement};
use crate::{identification_jacobian, CalibError, Campaign, Effect, MeasurementModel, Reading};

/// What is measured at every pose of an instrument campaign.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Instruments {
    /// Gauges read at every pose (indices into the joint table's sensors).
    pub gauges: Vec<usize>,
    /// A 6-D tracker pose at every pose.
    pub tracker: bool,
    /// Point targets measured at every pose (indices into [`MeasurementModel::targets`]).
    pub targets: Vec<usize>,
    /// Inclinometers read at every pose, every axis (indices into
    /// [`MeasurementModel::inclinometers`]).
    pub inclinometers: Vec<usize>,
}

/// The noise of each instrument (one standard deviation). The default: a gauge 1 um, a
/// tracker 10 um per coordinate and 20 urad per orientation component, a laser tracker's point
/// 10 um per coordinate, an inclinometer angle 20 urad (about 0.001 deg).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct InstrumentNoise {
    /// Gauge reading, um.
    pub gauge_um: f64,
    /// Tracker position coordinate, um.
    pub tracker_position_um: f64,
    /// Tracker orientation component, urad.
    pub tracker_orientation_urad: f64,
    /// Point coordinate, um.
    pub point_um: f64,
    /// Inclinometer angle, urad.
    pub tilt_urad: f64,
}

impl Default for InstrumentNoise {
    fn default() -> Self {
        Self {
            gauge_um: 1.0,
            tracker_position_um: 10.0,
            tracker_orientation_urad: 20.0,
            point_um: 10.0,
            tilt_urad: 20.0,
        }
    }
}

/// What a campaign identifies, at each instrument's noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentBounds {
    /// Poses.
    pub poses: usize,
    /// Scalar observations.
    pub observations: usize,
    /// Parameters: the 36 (6N) joint errors and the instruments' nuisance parameters.
    pub parameters: usize,
    /// Rank of the identification Jacobian.
    pub rank: usize,
    /// Joint errors determined on their own.
    pub joint_errors_determined: usize,
    /// Cramér-Rao RMS of the determined joint errors, um.
    pub joint_crb_rms_um: f64,
    /// The largest of them, um.
    pub joint_crb_max_um: f64,
    /// Cramér-Rao RMS of the joint-error part of the identifiable combinations (the minimum-
    /// norm solution's joint errors: `sqrt(trace)/sqrt(6N)` of their covariance), um; finite
    /// whatever the blind directions.
    pub joint_min_norm_rms_um: f64,
    /// Blind directions named, in words.
    pub blind_directions: Vec<String>,
}

impl Instruments {
    /// Observations per pose.
    pub fn observations_per_pose(&self, model: &MeasurementModel) -> usize {
        self.gauges.len()
            + if self.tracker { 6 } else { 0 }
            + 3 * self.targets.len()
            + self
                .inclinometers
                .iter()
                .map(|&i| model.inclinometers.get(i).map_or(0, |c| c.axes.len()))
                .sum::<usize>()
    }

    /// The model with the nuisance parameters these instruments bring, one session each.
    pub fn model(&self, model: &MeasurementModel) -> MeasurementModel {
        let mut m = model.clone();
        let mut add = |e: Effect| {
            if !m.effects.contains(&e) {
                m.effects.push(e);
            }
        };
        if self.tracker {
            add(Effect::TrackerFrame);
        }
        if !self.targets.is_empty() {
            add(Effect::TargetPosition);
            add(Effect::PointFrame);
        }
        if !self.inclinometers.is_empty() {
            add(Effect::InclinometerMount);
            add(Effect::BaseTilt);
        }
        m.tracker_frame_sessions.clear();
        m.point_sessions = usize::from(!self.targets.is_empty());
        m.tilt_sessions = usize::from(!self.inclinometers.is_empty());
        m
    }

    /// A plan (every measured value a placeholder at the nominal machine) measuring these at
    /// each of `poses` in one session, with the noise `noise` declared.
    pub fn skeleton(
        &self,
        model: &MeasurementModel,
        poses: &[Pose],
        noise: &InstrumentNoise,
    ) -> Campaign {
        let mut c = Campaign {
            poses: poses.to_vec(),
            pose_sigma_um: noise.tracker_position_um,
            orientation_sigma_urad: noise.tracker_orientation_urad,
            point_sigma_um: noise.point_um,
            tilt_sigma_urad: noise.tilt_urad,
            ..Campaign::default()
        };
        for (j, p) in poses.iter().enumerate() {
            for &s in &self.gauges {
                c.readings.push(Reading {
                    pose: j,
                    sensor: s,
                    length_mm: 0.0,
                    time_s: crate::Logged::NONE,
                    temperature_c: crate::Logged::NONE,
                });
            }
            if self.tracker {
                c.pose_measurements.push(PoseMeasurement {
                    pose: j,
                    measured: *p,
                    time_s: None,
                    temperature_c: None,
                });
            }
            for &t in &self.targets {
                c.point_measurements.push(PointMeasurement {
                    pose: j,
                    target: t,
                    session: 0,
                    measured_mm: nalgebra::Vector3::zeros(),
                    time_s: None,
                });
            }
            for &i in &self.inclinometers {
                let axes = model.inclinometers.get(i).map_or(0, |c| c.axes.len());
                for axis in 0..axes {
                    c.tilt_measurements.push(TiltMeasurement {
                        pose: j,
                        inclinometer: i,
                        axis,
                        session: 0,
                        angle_mrad: 0.0,
                        time_s: None,
                    });
                }
            }
        }
        c
    }

    /// The identification Jacobian of these instruments at `poses`, every row divided by its
    /// observation's noise (unit-noise rows: bounds come out in um of joint error), with the
    /// model it is for.
    pub fn unit_jacobian(
        &self,
        model: &MeasurementModel,
        poses: &[Pose],
        noise: &InstrumentNoise,
    ) -> Result<(MeasurementModel, DMatrix<f64>), CalibError> {
        check_noise(noise)?;
        let m = self.model(model);
        let c = self.skeleton(&m, poses, noise);
        if c.is_empty() {
            return Err(CalibError::NoInformation(
                "no instrument is measured at any pose".into(),
            ));
        }
        // identification_jacobian weighs every row to the tracker position noise (readings
        // at 1): bring each to unit noise.
        let mut j = identification_jacobian(&m, &c, &vec![0.0; m.num_params()])?;
        let readings = c.readings.len();
        for r in 0..j.nrows() {
            let s = if r < readings {
                noise.gauge_um
            } else {
                noise.tracker_position_um
            };
            j.row_mut(r).unscale_mut(s);
        }
        Ok((m, j))
    }

    /// What these instruments identify at `poses` ([`InstrumentBounds`]).
    pub fn bounds(
        &self,
        model: &MeasurementModel,
        poses: &[Pose],
        noise: &InstrumentNoise,
    ) -> Result<InstrumentBounds, CalibError> {
        let (m, j) = self.unit_jacobian(model, poses, noise)?;
        let c = self.skeleton(&m, poses, noise);
        let patterns = crate::analysis::identifiability::physical_patterns(&m, &c);
        let id = try_analyze(&j, 1.0, &RankOptions::default(), &patterns)?;
        let nj = m.num_installation_params();
        let crb: Vec<f64> = id.crlb_std_um[..nj].iter().flatten().copied().collect();
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
        // Covariance of the minimum-norm solution: V_r S^-2 V_r^T; its joint-error diagonal.
        let mut trace = 0.0;
        for k in 0..nj {
            trace += (0..id.rank)
                .map(|c| (id.v[(k, c)] / id.singular_values[c]).powi(2))
                .sum::<f64>();
        }
        Ok(InstrumentBounds {
            poses: poses.len(),
            observations: j.nrows(),
            parameters: m.num_params(),
            rank: id.rank,
            joint_errors_determined: crb.len(),
            joint_crb_rms_um: if crb.is_empty() { f64::NAN } else { rms(&crb) },
            joint_crb_max_um: crb.iter().fold(f64::NAN, |a, b| a.max(*b)),
            joint_min_norm_rms_um: (trace / nj as f64).sqrt(),
            blind_directions: id
                .blind_directions
                .iter()
                .map(|b| b.description.clone())
                .collect(),
        })
    }

    /// Chooses `n` of the `candidates` poses that identify most with these instruments: the
    /// criterion of `options` (A-optimal by default) on the information of the combinations
    /// the whole candidate set identifies (the blind directions every pose shares, such as a
    /// frame's gauge freedoms, are left out, as they must be). Returns the chosen poses in
    /// candidate order.
    pub fn design(
        &self,
        model: &MeasurementModel,
        candidates: &[Pose],
        n: usize,
        noise: &InstrumentNoise,
        options: &SelectOptions,
    ) -> Result<Vec<Pose>, CalibError> {
        if n == 0 || n > candidates.len() {
            return Err(CalibError::invalid(
                "poses",
                format!("{n}: choose 1 to {} of the candidates", candidates.len()),
            ));
        }
        let (m, j) = self.unit_jacobian(model, candidates, noise)?;
        let id = try_analyze(&j, 1.0, &RankOptions::default(), &[])?;
        let basis = id.row_space();
        // Rows of each candidate pose, in the skeleton's order: readings, then tracker poses,
        // then points, then tilts (each kind pose by pose).
        let c = self.skeleton(&m, candidates, noise);
        let mut rows: Vec<Vec<usize>> = vec![Vec::new(); candidates.len()];
        for k in 0..c.len() {
            rows[c.observation_pose(k)].push(k);
        }
        let projected = &j * &basis;
        let blocks: Vec<DMatrix<f64>> = rows
            .iter()
            .map(|r| projected.select_rows(r.iter()))
            .collect();
        let chosen = select_blocks(&blocks, n, None, None, options)?.chosen;
        Ok(chosen.into_iter().map(|i| candidates[i]).collect())
    }
}

fn check_noise(noise: &InstrumentNoise) -> Result<(), CalibError> {
    for (v, name) in [
        (noise.gauge_um, "gauge_um"),
        (noise.tracker_position_um, "tracker_position_um"),
        (noise.tracker_orientation_urad, "tracker_orientation_urad"),
        (noise.point_um, "point_um"),
        (noise.tilt_urad, "tilt_urad"),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(CalibError::invalid(
                format!("noise.{name}"),
                format!("{v}: must be > 0"),
            ));
        }
    }
    Ok(())
}
