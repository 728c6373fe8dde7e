//! The measurement model: commanded pose -> commanded link lengths -> clearance-corrected
//! effective lengths -> forward kinematics with the candidate joints -> sensor socket distance.
//!
//! Parameters are the installation errors in micrometres (order of
//! [`cpm_geometry::errors`]). The Jacobian of the readings with respect to them comes from
//! implicit differentiation of the closure `l(x, e) = L`: `dx/de = -J1^-1 J2`, so a reading
//! `y = |t + R p_s - b_s|` has `dy/de = -(J1^-T g)^T J2` with `g` the sensor's pose gradient.
use cpm_clearance::{ClearanceModel, Load};
use cpm_geometry::{InstallationErrors, JointTable, Pose};
use cpm_kinematics::{forward, ForwardOptions};
use nalgebra::{DMatrix, Matrix6, Vector6};

use crate::{Campaign, CalibError};

/// Exact (nested forward kinematics) or the paper's first-order model (eq. 12/15).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ModelKind {
    /// Forward kinematics with the candidate joint table at every pose (default).
    #[default]
    Exact,
    /// `y = y_nominal + g^T dx` with `dx = -J1^-1 J2 e` at the commanded pose (eq. 12, 15):
    /// linear in the errors, exact only to first order.
    FirstOrder,
}

/// The measurement model of a machine: nominal geometry, clearance and load.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementModel {
    /// Nominal joint table (with sensors and home pose).
    pub nominal: JointTable,
    /// Joint clearance. Default: the paper's 10 um, hard sign rule.
    pub clearance: ClearanceModel,
    /// Platform load for the link force directions.
    pub load: Load,
    /// Spring preload of the length sensor: -1 compression (default), +1 tension, 0 none.
    pub sensor_preload_sign: f64,
    /// Exact or first-order.
    pub kind: ModelKind,
    /// Forward kinematics options.
    pub fk: ForwardOptions,
}

impl MeasurementModel {
    /// The model of a nominal table with the paper's clearance (10 um) and the default load.
    pub fn new(nominal: JointTable) -> Self {
        Self {
            nominal,
            clearance: ClearanceModel::default(),
            load: Load::default(),
            sensor_preload_sign: -1.0,
            kind: ModelKind::Exact,
            fk: ForwardOptions::default(),
        }
    }

    /// Number of installation-error parameters (6 per link).
    pub fn num_params(&self) -> usize {
        6 * self.nominal.num_links()
    }

    /// The joint table with installation errors `errors_um` (flat) applied.
    pub fn table_with(&self, errors_um: &[f64]) -> Result<JointTable, CalibError> {
        if errors_um.len() != self.num_params() {
            return Err(CalibError::invalid(
                "installation errors",
                format!("{} components, expected {}", errors_um.len(), self.num_params()),
            ));
        }
        Ok(InstallationErrors::try_from_vec_um(errors_um)?.apply(&self.nominal)?)
    }

    /// Effective link lengths (mm) the machine has at each commanded pose: the commanded
    /// lengths (logged, or nominal IK) plus the clearance shift from the link forces.
    pub fn effective_lengths(&self, campaign: &Campaign) -> Result<Vec<Vec<f64>>, CalibError> {
        let n = self.nominal.num_links();
        let mut out = Vec::with_capacity(campaign.poses.len());
        for (j, pose) in campaign.poses.iter().enumerate() {
            let mut l = match &campaign.commanded_lengths_mm {
                Some(c) => {
                    let row = c.get(j).ok_or_else(|| {
                        CalibError::invalid("commanded_lengths_mm", format!("no row for pose {j}"))
                    })?;
                    if row.len() != n {
                        return Err(CalibError::invalid(
                            "commanded_lengths_mm",
                            format!("pose {j} has {} lengths, expected {n}", row.len()),
                        ));
                    }
                    row.clone()
                }
                None => cpm_kinematics::inverse_lengths(&self.nominal, pose),
            };
            let dl = self
                .clearance
                .link_corrections_mm(&self.nominal, pose, &self.load)
                .map_err(|source| CalibError::Clearance { pose: j, source })?;
            for (a, b) in l.iter_mut().zip(&dl) {
                *a += b;
            }
            out.push(l);
        }
        Ok(out)
    }

    /// Sensor clearance correction added to every predicted reading, mm (eq. 14).
    pub fn sensor_correction_mm(&self) -> f64 {
        if self.sensor_preload_sign == 0.0 {
            0.0
        } else {
            self.clearance
                .sensor_correction_mm(self.sensor_preload_sign)
        }
    }

    /// Checks the campaign against the model: sensor indices, pose indices, finite values.
    pub fn check_campaign(&self, campaign: &Campaign) -> Result<(), CalibError> {
        if campaign.readings.is_empty() {
            return Err(CalibError::NoInformation("the campaign has no readings".into()));
        }
        for (k, r) in campaign.readings.iter().enumerate() {
            if r.pose >= campaign.poses.len() {
                return Err(CalibError::invalid(
                    format!("reading {k}.pose"),
                    format!("{} but the campaign has {} poses", r.pose, campaign.poses.len()),
                ));
            }
            if r.sensor >= self.nominal.sensors.len() {
                return Err(CalibError::invalid(
                    format!("reading {k}.sensor"),
                    format!("{} but the robot has {} sensors", r.sensor, self.nominal.sensors.len()),
                ));
            }
            if !r.length_mm.is_finite() {
                return Err(CalibError::invalid(
                    format!("reading {k}.length_mm"),
                    format!("{} is not finite", r.length_mm),
                ));
            }
        }
        for (j, p) in campaign.poses.iter().enumerate() {
            if !p.is_finite() {
                return Err(CalibError::invalid(format!("pose {j}"), "not finite"));
            }
        }
        Ok(())
    }
}

/// Per-pose data that does not depend on the parameters, computed once per campaign.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Effective link lengths per pose, mm.
    pub lengths_mm: Vec<Vec<f64>>,
    /// Readings grouped by pose: `by_pose[j]` lists reading indices taken at pose j.
    pub by_pose: Vec<Vec<usize>>,
    /// First-order model only: nominal reading and its gradient per reading.
    first_order: Option<(Vec<f64>, DMatrix<f64>)>,
}

impl Prepared {
    /// Prepares a campaign for repeated predictions.
    pub fn new(model: &MeasurementModel, campaign: &Campaign) -> Result<Self, CalibError> {
        model.check_campaign(campaign)?;
        let lengths_mm = model.effective_lengths(campaign)?;
        let mut by_pose = vec![Vec::new(); campaign.poses.len()];
        for (k, r) in campaign.readings.iter().enumerate() {
            by_pose[r.pose].push(k);
        }
        let mut prepared = Prepared {
            lengths_mm,
            by_pose,
            first_order: None,
        };
        if model.kind == ModelKind::FirstOrder {
            let exact = MeasurementModel {
                kind: ModelKind::Exact,
                ..model.clone()
            };
            let zeros = vec![0.0; model.num_params()];
            let mut jac = DMatrix::zeros(campaign.len(), model.num_params());
            let y0 = predict_exact(&exact, &prepared, campaign, &zeros, Some(&mut jac))?;
            prepared.first_order = Some((y0, jac));
        }
        Ok(prepared)
    }
}

/// Predicted readings (mm) for installation errors `errors_um`; fills `jacobian`
/// (readings x parameters, mm per um) when given.
pub fn predict(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
    errors_um: &[f64],
    jacobian: Option<&mut DMatrix<f64>>,
) -> Result<Vec<f64>, CalibError> {
    match (&prepared.first_order, model.kind) {
        (Some((y0, j0)), ModelKind::FirstOrder) => {
            let e = nalgebra::DVector::from_column_slice(errors_um);
            let y = nalgebra::DVector::from_column_slice(y0) + j0 * e;
            if let Some(j) = jacobian {
                j.copy_from(j0);
            }
            Ok(y.iter().copied().collect())
        }
        _ => predict_exact(model, prepared, campaign, errors_um, jacobian),
    }
}

fn predict_exact(
    model: &MeasurementModel,
    prepared: &Prepared,
    campaign: &Campaign,
    errors_um: &[f64],
    mut jacobian: Option<&mut DMatrix<f64>>,
) -> Result<Vec<f64>, CalibError> {
    let table = model.table_with(errors_um)?;
    if jacobian.is_some() && table.num_links() != 6 {
        return Err(CalibError::invalid(
            "links",
            format!("the identification Jacobian needs six links, the table has {}", table.num_links()),
        ));
    }
    let sensor_corr = model.sensor_correction_mm();
    let mut y = vec![0.0; campaign.len()];
    for (j, readings) in prepared.by_pose.iter().enumerate() {
        if readings.is_empty() {
            continue;
        }
        let start: Pose = campaign.poses[j];
        let (pose, _) = forward(&table, &prepared.lengths_mm[j], &start, &model.fk)
            .map_err(|source| CalibError::Kinematics { pose: j, source })?;
        for &k in readings {
            let s = &table.sensors[campaign.readings[k].sensor];
            y[k] = s.length_mm(&pose) + sensor_corr;
        }
        if let Some(jac) = jacobian.as_deref_mut() {
            let links = cpm_kinematics::inverse(&table, &pose);
            let mut j1 = Matrix6::zeros();
            for (i, ls) in links.iter().enumerate().take(6) {
                let m = ls.s_mm.cross(&ls.unit);
                j1.set_row(
                    i,
                    &Vector6::new(ls.unit.x, ls.unit.y, ls.unit.z, m.x, m.y, m.z).transpose(),
                );
            }
            let lu_t = j1.transpose().lu();
            let rt = pose.rotation.matrix().transpose();
            for &k in readings {
                let s = &table.sensors[campaign.readings[k].sensor];
                let g = cpm_kinematics::sensor_pose_gradient(s, &pose);
                let v = lu_t.solve(&g).ok_or_else(|| CalibError::Kinematics {
                    pose: j,
                    source: cpm_kinematics::KinematicsError::Singular {
                        iteration: 0,
                        condition: cpm_kinematics::fk::condition_number(&j1),
                    },
                })?;
                // dy/de = -v^T J2, J2 row i: [-z_i^T, (R^T z_i)^T] in the columns of link i.
                for (i, ls) in links.iter().enumerate() {
                    let zp = rt * ls.unit;
                    for a in 0..3 {
                        jac[(k, 6 * i + a)] = v[i] * ls.unit[a] * 1e-3;
                        jac[(k, 6 * i + 3 + a)] = -v[i] * zp[a] * 1e-3;
                    }
                }
            }
        }
    }
    Ok(y)
}
