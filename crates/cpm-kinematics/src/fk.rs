//! Forward kinematics: link lengths to pose by Newton-Raphson with the analytic J1.
use cpm_geometry::{JointTable, Pose};
use nalgebra::{DMatrix, Matrix6, Vector3, Vector6};

use crate::linalg::SvdError;
use crate::lu6::Lu6;
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

/// 2-norm condition number of a 6x6 matrix (infinite when it is exactly singular); an
/// error when an entry is not finite or the SVD fails (see [`crate::linalg`]).
///
/// nalgebra's SVD of the fixed-size matrix, several times faster than the general one
/// (forward kinematics over a long step and the reachability check of every pose of a
/// 10^6-row file call it); the general, exactly scaled one ([`crate::linalg`]) when that does
/// not converge or the matrix is so large or small that it could overflow.
pub fn condition_number(m: &Matrix6<f64>) -> Result<f64, SvdError> {
    let largest = m.amax();
    if m.iter().all(|v| v.is_finite()) && (1e-100..1e100).contains(&largest) {
        if let Some(svd) = m.try_svd(false, false, f64::EPSILON, 10_000) {
            let sv = svd.singular_values;
            let (max, min) = (sv.max(), sv.min());
            if max.is_finite() && min >= 0.0 {
                return Ok(if min > 0.0 { max / min } else { f64::INFINITY });
            }
        }
    }
    let d = DMatrix::from_column_slice(6, 6, m.as_slice());
    crate::linalg::condition_number(&d)
}

/// True when the 2-norm condition number of `m` is certainly at most `bound`:
/// `|m|_F |m^-1|_F` bounds it from above (and is at most 6 times it), at the cost of an
/// LU factorisation rather than an SVD ([`crate::lu6::Lu6::inverse_norm`]), with a margin
/// of [`BOUND_MARGIN`] for its rounding. False when that bound exceeds `bound` (the
/// condition number may still be below: compute it), or `m` is singular or not finite.
///
/// Every caller computes the condition number itself when this is false, so a verdict never
/// rests on the rounding of this bound, only the time taken to reach it.
pub fn condition_at_most(m: &Matrix6<f64>, bound: f64) -> bool {
    condition_at_most_factored(m, &crate::lu6::Lu6::new(m), bound)
}

/// [`condition_at_most`] of `m` whose factors `lu` (`Lu6::new(m)`) are at hand.
pub fn condition_at_most_factored(m: &Matrix6<f64>, lu: &crate::lu6::Lu6, bound: f64) -> bool {
    let Some(inv_norm) = lu.inverse_norm() else {
        return false;
    };
    m.norm() * inv_norm * BOUND_MARGIN <= bound // false for NaN
}

/// The factor [`condition_at_most`] widens its bound by: above the relative rounding of
/// `|m^-1|_F` (about the condition number times 10^-16, so 10^-6 at the forward solver's
/// default limit of 10^10), far below the slack of the bound itself (up to 6).
pub const BOUND_MARGIN: f64 = 1.0 + 1e-4;

/// A 6x6 matrix as rows, for the allocation-free solver.
type Mat6 = [[f64; 6]; 6];

/// Condition number of J1 from the assembled system: `jac` is J1 itself for six links and
/// `J1^T J1` (whose condition number is the square) for more.
fn j1_condition(jac: &Mat6, links: usize) -> Result<f64, SvdError> {
    let c = condition_number(&Matrix6::from_fn(|i, j| jac[i][j]))?;
    Ok(if links == 6 { c } else { c.sqrt() })
}

/// J1's condition number for an error report: infinite when J1 is not finite (a link of
/// zero length), the SVD's own error when it fails on a finite J1.
fn reported_condition(jac: &Mat6, links: usize) -> Result<f64, KinematicsError> {
    match j1_condition(jac, links) {
        Ok(c) => Ok(c),
        Err(SvdError::NonFinite { .. }) => Ok(f64::INFINITY),
        Err(e) => Err(e.into()),
    }
}

/// [`KinematicsError::Singular`] with J1's condition number (infinite when J1 is not
/// finite: a link of zero length), or the SVD's own error when it fails on a finite J1.
fn singular(iteration: usize, jac: &Mat6, links: usize) -> KinematicsError {
    KinematicsError::singular(iteration, &Matrix6::from_fn(|i, j| jac[i][j])).map_condition(|c| {
        if links == 6 {
            c
        } else {
            c.sqrt()
        }
    })
}

/// Solves `a x = b` by the LU with partial pivoting of [`crate::lu6`] (nalgebra's, bit for
/// bit; allocation-free). `None` when a pivot is zero or anything is not finite.
fn solve6(a: &Mat6, b: &[f64; 6]) -> Option<Vector6<f64>> {
    solve_lu(&Lu6::from_rows(a), b)
}

/// [`solve6`] with the LU factors of `a`.
fn solve_lu(lu: &Lu6, b: &[f64; 6]) -> Option<Vector6<f64>> {
    let x = lu.solve(&Vector6::from(*b))?;
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Forward kinematics' first step from one start pose, computed once for many solves from it
/// ([`forward_from`]; the reachability of every pose of a file starts at home): six links'
/// lengths at the start, J1 there and its LU factors, and whether J1's condition number there
/// is surely acceptable.
#[derive(Debug, Clone)]
pub struct ForwardStart {
    pose: Pose,
    options: ForwardOptions,
    lengths_mm: [f64; 6],
    jac: Mat6,
    lu: Lu6,
    surely_acceptable: bool,
}

impl ForwardStart {
    /// The first step of [`forward`] from `start` on `table` with `options`; `None` unless
    /// the table has six links.
    pub fn new(table: &JointTable, start: &Pose, options: &ForwardOptions) -> Option<Self> {
        if table.num_links() != 6 {
            return None;
        }
        let (mut jac, mut rhs) = ([[0.0; 6]; 6], [0.0; 6]);
        // Against lengths of zero the residuals are the lengths themselves (negated: exact).
        residual_and_jacobian(table, start, &[0.0; 6], &mut jac, &mut rhs);
        let m = Matrix6::from_fn(|i, j| jac[i][j]);
        Some(ForwardStart {
            pose: *start,
            options: *options,
            lengths_mm: rhs.map(|r| -r),
            jac,
            lu: Lu6::new(&m),
            surely_acceptable: condition_at_most(&m, options.max_condition),
        })
    }

    /// What [`residual_and_jacobian`] gives at the start for `lengths_mm`.
    fn residual_and_jacobian(&self, lengths_mm: &[f64], jac: &mut Mat6, rhs: &mut [f64; 6]) -> f64 {
        *jac = self.jac;
        let mut worst = 0.0f64;
        let mut finite = true;
        for (i, (at_start, target)) in self.lengths_mm.iter().zip(lengths_mm).enumerate() {
            let res = at_start - target;
            finite &= res.is_finite();
            worst = worst.max(res.abs());
            rhs[i] = -res;
        }
        if finite {
            worst
        } else {
            f64::NAN
        }
    }
}

/// Residual `l(x) - L` and J1 for six links (or the normal equations `J1^T J1`, `-J1^T r`
/// for more than six) into `jac`, `rhs`. Returns the largest |residual|, NaN if any is NaN.
fn residual_and_jacobian(
    table: &JointTable,
    pose: &Pose,
    lengths_mm: &[f64],
    jac: &mut Mat6,
    rhs: &mut [f64; 6],
) -> f64 {
    let r = pose.rotation.matrix();
    let square = table.num_links() == 6;
    if !square {
        *jac = [[0.0; 6]; 6];
        *rhs = [0.0; 6];
    }
    let mut worst = 0.0f64;
    let mut finite = true;
    for (i, (l, target)) in table.links.iter().zip(lengths_mm).enumerate() {
        let s: Vector3<f64> = r * l.platform_mm;
        let q = pose.position_mm + s - l.base_mm;
        let n = q.norm();
        let z = q / n;
        let m = s.cross(&z);
        let res = n - target;
        finite &= res.is_finite();
        worst = worst.max(res.abs());
        let row = [z.x, z.y, z.z, m.x, m.y, m.z];
        if square {
            jac[i] = row;
            rhs[i] = -res;
        } else {
            for a in 0..6 {
                for b in 0..6 {
                    jac[a][b] += row[a] * row[b];
                }
                rhs[a] -= row[a] * res;
            }
        }
    }
    if finite {
        worst
    } else {
        f64::NAN
    }
}

/// Forward kinematics: the pose at which the links have `lengths_mm`, by Newton-Raphson from
/// `start`. Six or more links (more: Gauss-Newton on the least-squares closure, converged
/// when the residual is below the tolerance or the step moves no joint by more than it).
///
/// Fails with [`KinematicsError::Singular`] when J1 is numerically singular at an iterate and
/// [`KinematicsError::NonConvergence`] when the tolerance is not reached; both carry J1's
/// condition number. Never panics.
///
/// Newton converges to the solution (assembly mode) whose basin holds `start`: a target
/// that is separated from `start` by a singular configuration (det J1 changes sign on the
/// way) may come out as another pose with the same link lengths. See
/// [`crate::workspace::reachable_from_home`].
pub fn forward(
    table: &JointTable,
    lengths_mm: &[f64],
    start: &Pose,
    options: &ForwardOptions,
) -> Result<(Pose, ForwardReport), KinematicsError> {
    newton(table, lengths_mm, start, options, None, None)
}

/// [`forward`] from the pose and with the options `start` was made with, on the table it was
/// made for: the same result, the first step from what `start` holds.
pub fn forward_from(
    table: &JointTable,
    lengths_mm: &[f64],
    start: &ForwardStart,
) -> Result<(Pose, ForwardReport), KinematicsError> {
    newton(
        table,
        lengths_mm,
        &start.pose,
        &start.options,
        Some(start),
        None,
    )
}

/// How close to a known solution an iterate of [`forward_from_toward`] must come to stop
/// there: its position within this many mm and its rotation matrix within this much
/// (Frobenius norm) times the platform's joint radius. A millionth of a millimetre: far
/// inside Newton's basin of a regular solution (whose size is of millimetres), so that from
/// there Newton converges to it.
pub const NEAR_SOLUTION_MM: f64 = 1e-6;

/// [`forward_from`] where a solution `near` is known (the pose whose inverse kinematics gave
/// `lengths_mm`), to learn whether Newton from the start lands there: the same iterates, up
/// to the first that comes within [`NEAR_SOLUTION_MM`] of `near`, where Newton would go on to
/// converge to `near` (it is then returned, one or two iterations early, with the report's
/// residual that of the iterate before it). Otherwise [`forward_from`]'s result.
pub fn forward_from_toward(
    table: &JointTable,
    lengths_mm: &[f64],
    start: &ForwardStart,
    near: &Pose,
) -> Result<(Pose, ForwardReport), KinematicsError> {
    newton(
        table,
        lengths_mm,
        &start.pose,
        &start.options,
        Some(start),
        Some(near),
    )
}

/// [`forward_from_toward`] from `start` with `options` (no first step made).
pub(crate) fn forward_toward(
    table: &JointTable,
    lengths_mm: &[f64],
    start: &Pose,
    options: &ForwardOptions,
    near: &Pose,
) -> Result<(Pose, ForwardReport), KinematicsError> {
    newton(table, lengths_mm, start, options, None, Some(near))
}

/// Whether `pose` is within [`NEAR_SOLUTION_MM`] of `near` (see there), `radius_mm` the
/// platform's joint radius.
fn is_near(pose: &Pose, near: &Pose, radius_mm: f64) -> bool {
    let dt = (pose.position_mm - near.position_mm).norm();
    let dr = (pose.rotation.matrix() - near.rotation.matrix()).norm();
    dt + dr * radius_mm <= NEAR_SOLUTION_MM // false for NaN
}

/// [`forward`], the first step from `first` when given (six links), stopping at an iterate
/// near `near` when given (see [`forward_from_toward`]).
fn newton(
    table: &JointTable,
    lengths_mm: &[f64],
    start: &Pose,
    options: &ForwardOptions,
    first: Option<&ForwardStart>,
    near: Option<&Pose>,
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
    // Joint radius that turns a rotation step into a joint displacement (redundant case).
    let radius_mm = table
        .links
        .iter()
        .map(|l| l.platform_mm.norm())
        .fold(1.0f64, f64::max);
    let mut pose = *start;
    let mut jac: Mat6 = [[0.0; 6]; 6];
    let mut rhs = [0.0; 6];
    let mut worst = f64::NAN;
    for it in 0..=options.max_iterations {
        let first = first.filter(|_| it == 0 && n == 6);
        worst = match first {
            Some(f) => f.residual_and_jacobian(lengths_mm, &mut jac, &mut rhs),
            None => residual_and_jacobian(table, &pose, lengths_mm, &mut jac, &mut rhs),
        };
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
        let step = match first {
            Some(f) => solve_lu(&f.lu, &rhs),
            None => solve6(&jac, &rhs),
        };
        let Some(step) = step else {
            return Err(singular(it, &jac, n));
        };
        // Cheap singularity guard: a huge step from a small residual means J1 is near singular.
        let dt = Vector3::new(step[0], step[1], step[2]);
        let dw = Vector3::new(step[3], step[4], step[5]);
        let scale = (options.max_step_mm / dt.norm().max(1e-300))
            .min(options.max_step_rad / dw.norm().max(1e-300))
            .min(1.0);
        // The condition number only when an upper bound of it (cheap) could exceed the limit:
        // the same decision, without an SVD at every long step.
        let surely_acceptable = || {
            if let Some(f) = first {
                return f.surely_acceptable;
            }
            let m = Matrix6::from_fn(|i, j| jac[i][j]);
            if n == 6 {
                condition_at_most(&m, options.max_condition)
            } else {
                condition_at_most(&m, options.max_condition * options.max_condition)
            }
        };
        if scale < 1.0 && !surely_acceptable() {
            let c = reported_condition(&jac, n)?;
            let acceptable = c <= options.max_condition; // false for NaN
            if !acceptable {
                return Err(KinematicsError::Singular {
                    iteration: it,
                    condition: c,
                });
            }
        }
        pose = pose.perturbed(&(step * scale));
        if near.is_some_and(|p| is_near(&pose, p, radius_mm)) {
            return Ok((
                pose,
                ForwardReport {
                    iterations: it + 1,
                    residual_mm: worst,
                },
            ));
        }
        if n > 6 && scale == 1.0 && dt.norm() + dw.norm() * radius_mm <= options.tolerance_mm {
            // Least-squares closure of redundant links: stationary, the residual need not vanish.
            let worst = residual_and_jacobian(table, &pose, lengths_mm, &mut jac, &mut rhs);
            if worst.is_finite() {
                return Ok((
                    pose,
                    ForwardReport {
                        iterations: it + 1,
                        residual_mm: worst,
                    },
                ));
            }
        }
    }
    Err(KinematicsError::NonConvergence {
        iterations: options.max_iterations,
        residual_mm: worst,
        condition: reported_condition(&jac, n)?,
    })
}
