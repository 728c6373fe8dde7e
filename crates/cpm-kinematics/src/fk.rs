//! Forward kinematics: link lengths to pose by Newton-Raphson with the analytic J1.
use cpm_geometry::{JointTable, Pose};
use nalgebra::{Matrix6, Vector3, Vector6};

use crate::KinematicsError;

/// Options of the forward kinematics solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardOptions {
    /// Maximum Newton iterations. Default 50.
    pub max_iterations: usize,
    /// Converged when the largest link length residual is below this, mm. Default 1e-11.
    pub tolerance_mm: f64,
    /// J1 is treated as singular above this condition number. Default 1e10.
    pub max_condition: f64,
    /// Largest translation step per iteration, mm (damps far starts). Default 50.
    pub max_step_mm: f64,
    /// Largest rotation step per iteration, rad. Default 0.2.
    pub max_step_rad: f64,
}

impl Default for ForwardOptions {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            tolerance_mm: 1e-11,
            max_condition: 1e10,
            max_step_mm: 50.0,
            max_step_rad: 0.2,
        }
    }
}

/// How a forward kinematics solve went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardReport {
    /// Newton iterations used.
    pub iterations: usize,
    /// Largest link length residual at the solution, mm.
    pub residual_mm: f64,
}

/// 2-norm condition number of a 6x6 matrix.
pub fn condition_number(m: &Matrix6<f64>) -> f64 {
    let sv = m.singular_values();
    let (mx, mn) = (sv.max(), sv.min());
    if mn > 0.0 {
        mx / mn
    } else {
        f64::INFINITY
    }
}

/// Residual `l(x) - L` and J1 for six links (or the normal equations for more than six).
fn residual_and_jacobian(
    table: &JointTable,
    pose: &Pose,
    lengths_mm: &[f64],
    jac: &mut Matrix6<f64>,
    rhs: &mut Vector6<f64>,
) -> f64 {
    let r = pose.rotation.matrix();
    let square = table.num_links() == 6;
    if !square {
        jac.fill(0.0);
        rhs.fill(0.0);
    }
    let mut worst = 0.0f64;
    for (i, (l, target)) in table.links.iter().zip(lengths_mm).enumerate() {
        let s: Vector3<f64> = r * l.platform_mm;
        let q = pose.position_mm + s - l.base_mm;
        let n = q.norm();
        let z = q / n;
        let m = s.cross(&z);
        let res = n - target;
        worst = worst.max(res.abs());
        let row = Vector6::new(z.x, z.y, z.z, m.x, m.y, m.z);
        if square {
            jac.set_row(i, &row.transpose());
            rhs[i] = -res;
        } else {
            *jac += row * row.transpose();
            *rhs -= row * res;
        }
    }
    worst
}

/// Forward kinematics: the pose at which the links have `lengths_mm`, by Newton-Raphson from
/// `start`. Six or more links (more: Gauss-Newton on the least-squares closure).
///
/// Fails with [`KinematicsError::Singular`] when J1 is numerically singular at an iterate and
/// [`KinematicsError::NonConvergence`] when the tolerance is not reached; both carry J1's
/// condition number.
pub fn forward(
    table: &JointTable,
    lengths_mm: &[f64],
    start: &Pose,
    options: &ForwardOptions,
) -> Result<(Pose, ForwardReport), KinematicsError> {
    let n = table.num_links();
    if n < 6 || lengths_mm.len() != n {
        return Err(KinematicsError::Dimension {
            what: format!(
                "forward kinematics needs >= 6 links and one length per link; got {n} links, {} lengths",
                lengths_mm.len()
            ),
        });
    }
    if !lengths_mm.iter().all(|v| v.is_finite()) || !start.is_finite() {
        return Err(KinematicsError::NonFinite {
            what: "link lengths or start pose".into(),
        });
    }
    let mut pose = *start;
    let mut jac = Matrix6::zeros();
    let mut rhs = Vector6::zeros();
    let mut worst = 0.0;
    for it in 0..=options.max_iterations {
        worst = residual_and_jacobian(table, &pose, lengths_mm, &mut jac, &mut rhs);
        if worst <= options.tolerance_mm {
            return Ok((
                pose,
                ForwardReport {
                    iterations: it,
                    residual_mm: worst,
                },
            ));
        }
        if it == options.max_iterations {
            break;
        }
        let lu = jac.lu();
        let step = match lu.solve(&rhs) {
            Some(s) if s.iter().all(|v| v.is_finite()) => s,
            _ => {
                return Err(KinematicsError::Singular {
                    iteration: it,
                    condition: condition_number(&jac),
                })
            }
        };
        // Cheap singularity guard: a huge step from a small residual means J1 is near singular.
        let dt = Vector3::new(step[0], step[1], step[2]);
        let dw = Vector3::new(step[3], step[4], step[5]);
        let scale = (options.max_step_mm / dt.norm().max(1e-300))
            .min(options.max_step_rad / dw.norm().max(1e-300))
            .min(1.0);
        if scale < 1.0 {
            let c = condition_number(&jac);
            let limit = if n == 6 {
                options.max_condition
            } else {
                options.max_condition * options.max_condition
            };
            if c > limit {
                return Err(KinematicsError::Singular {
                    iteration: it,
                    condition: c,
                });
            }
        }
        pose = pose.perturbed(&(step * scale));
    }
    let _ = residual_and_jacobian(table, &pose, lengths_mm, &mut jac, &mut rhs);
    Err(KinematicsError::NonConvergence {
        iterations: options.max_iterations,
        residual_mm: worst,
        condition: condition_number(&jac),
    })
}
