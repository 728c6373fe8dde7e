//! The clearance correction of link lengths from the direction of the link forces.
use cpm_geometry::{JointTable, Pose};
use serde::{Deserialize, Serialize};

use crate::{link_forces_n, ClearanceError, Load};

/// How the force sign turns into a clearance shift.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub enum SignRule {
    /// The paper's rule: `sign(t)`; zero force gives zero shift. Discontinuous where a link's
    /// force passes through zero, which makes a least-squares cost discontinuous too.
    #[default]
    Hard,
    /// `tanh(t / force_scale_n)`: equal to the hard rule for |t| >> `force_scale_n`, smooth
    /// through zero (a ball that floats in its socket when the link is unloaded).
    Smooth {
        /// Force (N) over which the shift goes from one side to the other.
        force_scale_n: f64,
    },
}

impl SignRule {
    /// The factor in [-1, 1] applied to the summed clearances for axial force `t_n`.
    pub fn factor(&self, t_n: f64) -> f64 {
        match *self {
            SignRule::Hard => {
                if t_n > 0.0 {
                    1.0
                } else if t_n < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            SignRule::Smooth { force_scale_n } => (t_n / force_scale_n).tanh(),
        }
    }
}

/// Spherical joint clearance, the same radius at every joint of every link.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClearanceModel {
    /// Clearance radius of each joint, um. Default 10 (the paper's example).
    pub radius_um: f64,
    /// Sign rule. Default [`SignRule::Hard`] (the paper's).
    pub rule: SignRule,
}

impl Default for ClearanceModel {
    fn default() -> Self {
        Self {
            radius_um: 10.0,
            rule: SignRule::Hard,
        }
    }
}

impl From<&cpm_geometry::description::ClearanceSpec> for ClearanceModel {
    /// The clearance of a robot description's `[clearance]` table: its radius, the hard sign
    /// rule when `smooth_force_n` is 0 and the smooth one of that width otherwise.
    fn from(spec: &cpm_geometry::description::ClearanceSpec) -> Self {
        Self {
            radius_um: spec.radius_um,
            rule: if spec.smooth_force_n > 0.0 {
                SignRule::Smooth {
                    force_scale_n: spec.smooth_force_n,
                }
            } else {
                SignRule::Hard
            },
        }
    }
}

impl ClearanceModel {
    /// No clearance.
    pub fn none() -> Self {
        Self {
            radius_um: 0.0,
            rule: SignRule::Hard,
        }
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), ClearanceError> {
        if !(self.radius_um.is_finite() && self.radius_um >= 0.0) {
            return Err(ClearanceError::Invalid {
                field: "radius_um",
                value: self.radius_um,
                why: "must be finite and >= 0",
            });
        }
        if let SignRule::Smooth { force_scale_n } = self.rule {
            if !(force_scale_n.is_finite() && force_scale_n > 0.0) {
                return Err(ClearanceError::Invalid {
                    field: "force_scale_n",
                    value: force_scale_n,
                    why: "must be finite and > 0",
                });
            }
        }
        Ok(())
    }

    /// Effective length change of each link (mm) from clearance at `pose` under `load`:
    /// `+2r` in tension, `-2r` in compression (eq. 13 removes it from the readings).
    pub fn link_corrections_mm(
        &self,
        table: &JointTable,
        pose: &Pose,
        load: &Load,
    ) -> Result<Vec<f64>, ClearanceError> {
        self.validate()?;
        if self.radius_um == 0.0 {
            return Ok(vec![0.0; table.num_links()]);
        }
        if self.rule == SignRule::Hard {
            // The hard rule needs only the forces' signs: from an LU solve when they are
            // certain, else (near zero or near singular) from the SVD below.
            if let Some(signs) = crate::statics::link_force_signs_if_certain(table, pose, load) {
                return Ok(self.corrections_from_forces_mm(&signs));
            }
        }
        let t = link_forces_n(table, pose, load)?;
        Ok(self.corrections_from_forces_mm(&t))
    }

    /// Length changes (mm) for given axial forces (N, tension positive).
    pub fn corrections_from_forces_mm(&self, forces_n: &[f64]) -> Vec<f64> {
        let two_r_mm = 2.0 * self.radius_um * 1e-3;
        forces_n
            .iter()
            .map(|&t| two_r_mm * self.rule.factor(t))
            .collect()
    }

    /// The correction of a length sensor's reading (mm, eq. 14): its two sockets have the same
    /// clearance and the gauge's spring preload keeps it in compression (`preload_sign` = -1)
    /// or tension (+1).
    pub fn sensor_correction_mm(&self, preload_sign: f64) -> f64 {
        2.0 * self.radius_um * 1e-3 * preload_sign.signum()
    }
}
