//! Reachability: link length limits, J1's condition number and singularity-free paths.
//!
//! Newton's forward kinematics finds the solution in whose basin its start lies. A pose is
//! *reachable from home* here when the straight twist path from the home pose to it stays
//! within every link's length limits, keeps J1's condition number below a bound and keeps the
//! sign of det J1 (for six links): the robot can move there without crossing a singular
//! configuration, so the pose is in home's assembly mode and forward kinematics started at
//! home returns it.
//!
//! ```
//! use cpm_geometry::{JointTable, Pose};
//! use cpm_kinematics::workspace::{reachable_from_home, Unreachable};
//! let t = JointTable::paper_cubic();
//! let near = Pose::from_xyz_rpy(10.0, -20.0, 430.0, 0.1, 0.0, -0.1);
//! assert!(reachable_from_home(&t, &near, 1e4).is_ok());
//! // Dropping the platform onto the base plane folds the z links flat: singular.
//! let flat = Pose::from_xyz_rpy(0.0, 0.0, 56.0, 0.0, 0.0, 0.0);
//! assert!(matches!(
//!     reachable_from_home(&t, &flat, 1e4),
//!     Err(Unreachable::NearSingular { .. } | Unreachable::AssemblyModeChange { .. })
//! ));
//! ```
use cpm_geometry::{JointTable, Pose};
use nalgebra::Matrix6;

use crate::{inverse_lengths, j1};

/// Why a pose is not reachable (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unreachable {
    /// A link length is outside its limits (at the target or on the way).
    LengthLimit {
        /// Link index (0-based).
        link: usize,
        /// Its length there, mm.
        length_mm: f64,
        /// Its limits, mm.
        limits_mm: (f64, f64),
    },
    /// J1's condition number exceeds the bound (at the target or on the way).
    NearSingular {
        /// The condition number found.
        condition: f64,
    },
    /// det J1 changes sign on the way: the target is in another assembly mode.
    AssemblyModeChange {
        /// Fraction of the path (0..1] where the sign change was seen.
        at: f64,
    },
    /// A pose or length is not finite, or the table has fewer than six links.
    Invalid,
}

/// Samples checked along a path.
const PATH_SAMPLES: usize = 32;

/// Condition number (2-norm) of J1 at `pose`; infinite when singular or not finite.
pub fn j1_condition(table: &JointTable, pose: &Pose) -> f64 {
    let j = j1(table, pose);
    if j.nrows() < 6 {
        return f64::INFINITY;
    }
    crate::linalg::Svd::new(&j).map_or(f64::INFINITY, |s| s.condition_number())
}

/// Checks every link's length limits at `pose` (links without limits always pass).
pub fn within_length_limits(table: &JointTable, pose: &Pose) -> Result<(), Unreachable> {
    let lengths = inverse_lengths(table, pose);
    for (i, (l, len)) in table.links.iter().zip(&lengths).enumerate() {
        if !len.is_finite() {
            return Err(Unreachable::Invalid);
        }
        if let Some((lo, hi)) = l.length_limits_mm {
            let inside = *len >= lo && *len <= hi;
            if !inside {
                return Err(Unreachable::LengthLimit {
                    link: i,
                    length_mm: *len,
                    limits_mm: (lo, hi),
                });
            }
        }
    }
    Ok(())
}

fn det6(table: &JointTable, pose: &Pose) -> f64 {
    let j = j1(table, pose);
    Matrix6::from_fn(|r, c| j[(r, c)]).determinant()
}

/// Checks the straight twist path from `from` to `to` (32 samples plus the end points):
/// length limits, J1 condition number at most `max_condition`, det J1 keeping its sign
/// (six links).
pub fn reachable_between(
    table: &JointTable,
    from: &Pose,
    to: &Pose,
    max_condition: f64,
) -> Result<(), Unreachable> {
    if table.num_links() < 6 || !from.is_finite() || !to.is_finite() {
        return Err(Unreachable::Invalid);
    }
    let twist = from.difference(to);
    let square = table.num_links() == 6;
    let det0 = if square { det6(table, from) } else { 1.0 };
    for k in 0..=PATH_SAMPLES {
        let s = k as f64 / PATH_SAMPLES as f64;
        let pose = if k == PATH_SAMPLES {
            *to
        } else {
            from.perturbed(&(twist * s))
        };
        within_length_limits(table, &pose)?;
        // The sign first: a path that crosses a singularity says so rather than "near".
        let same_sign = det6(table, &pose) * det0 > 0.0; // false for NaN
        if square && k > 0 && !same_sign {
            return Err(Unreachable::AssemblyModeChange { at: s });
        }
        let c = j1_condition(table, &pose);
        let acceptable = c <= max_condition; // false for NaN
        if !acceptable {
            return Err(Unreachable::NearSingular { condition: c });
        }
    }
    Ok(())
}

/// [`reachable_between`] the table's home pose and `target`.
pub fn reachable_from_home(
    table: &JointTable,
    target: &Pose,
    max_condition: f64,
) -> Result<(), Unreachable> {
    reachable_between(table, &table.home, target, max_condition)
}
