//! Candidate poses inside the workspace: random, grids and ballbar-like circles, filtered by
//! link length limits, a tilt limit, J1's conditioning and forward-kinematics convergence.
//!
//! A pose is *admissible* ([`Workspace::check`]) when
//! - every link length (nominal inverse kinematics) is within its limits, if the table has any;
//! - the platform's z axis is tilted from its home direction by at most `max_tilt_deg`;
//! - J1's condition number is at most `max_condition_ratio` times its value at home
//!   (the rule of [`crate::data::poses::random_workspace_poses`]);
//! - forward kinematics started at home converges to the pose from its nominal link lengths
//!   (so the controller reaches it in home's assembly mode).
//!
//! ```
//! use cpm_calib::design::candidates::{circle_poses, Workspace};
//! use cpm_geometry::JointTable;
//! let table = JointTable::paper_cubic();
//! let ws = Workspace::default();
//! // Two circles of radius 100 mm, 50 mm below and above home, level: 2 x 12 poses.
//! let poses = circle_poses(&table.home, &[100.0], &[-50.0, 50.0], &[0.0], 1, 12);
//! let (ok, rejected) = ws.filter(&table, &poses);
//! assert_eq!(ok.len() + rejected.total(), 24);
//! assert!(ok.iter().all(|p| ws.check(&table, p).is_ok()));
//! ```
use cpm_geometry::rotation::from_rpy;
use cpm_geometry::{JointTable, Pose};
use cpm_kinematics::{forward, inverse_lengths, ForwardOptions};
use nalgebra::{Rotation3, Unit, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::data::poses::j1_condition;
/// The random poses about home ([`crate::data::poses::random_poses`]; its path here is kept).
pub use crate::data::poses::random_poses;

/// Limits of the poses a design may use.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Workspace {
    /// Largest J1 condition number, relative to its value at home. Default 3.
    pub max_condition_ratio: f64,
    /// Largest tilt of the platform's z axis from its home direction, deg. Default 30.
    pub max_tilt_deg: f64,
    /// Forward kinematics from home must return the pose to this distance, mm. Default 1e-6.
    pub forward_tolerance_mm: f64,
}

impl Default for Workspace {
    fn default() -> Self {
        Self {
            max_condition_ratio: 3.0,
            max_tilt_deg: 30.0,
            forward_tolerance_mm: 1e-6,
        }
    }
}

/// Why a candidate pose was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Rejection {
    /// A link length outside its limits (or not finite).
    LengthLimit,
    /// Tilted beyond the limit.
    Tilt,
    /// J1 too badly conditioned.
    Condition,
    /// Forward kinematics from home did not converge to the pose.
    ForwardKinematics,
}

/// Counts of rejected candidates by reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Rejections {
    /// Outside link length limits.
    pub length_limit: usize,
    /// Beyond the tilt limit.
    pub tilt: usize,
    /// J1 badly conditioned.
    pub condition: usize,
    /// Forward kinematics failed.
    pub forward_kinematics: usize,
}

impl Rejections {
    /// All rejected candidates.
    pub fn total(&self) -> usize {
        self.length_limit + self.tilt + self.condition + self.forward_kinematics
    }
}

/// Tilt of the platform's z axis at `pose` from its direction at `home`, deg.
pub fn tilt_deg(home: &Pose, pose: &Pose) -> f64 {
    let z0 = home.rotation * Vector3::z();
    let z1 = pose.rotation * Vector3::z();
    z0.dot(&z1).clamp(-1.0, 1.0).acos().to_degrees()
}

impl Workspace {
    /// Checks one pose (see the module doc).
    pub fn check(&self, table: &JointTable, pose: &Pose) -> Result<(), Rejection> {
        if !pose.is_finite() {
            return Err(Rejection::LengthLimit);
        }
        let lengths = inverse_lengths(table, pose);
        let within =
            lengths
                .iter()
                .zip(&table.links)
                .all(|(l, link)| match link.length_limits_mm {
                    Some((lo, hi)) => *l >= lo && *l <= hi,
                    None => l.is_finite(),
                });
        if !within {
            return Err(Rejection::LengthLimit);
        }
        // Comparisons that are false for NaN, so that NaN is rejected too.
        let level_enough = tilt_deg(&table.home, pose) <= self.max_tilt_deg;
        if !level_enough {
            return Err(Rejection::Tilt);
        }
        let c0 = j1_condition(table, &table.home);
        let conditioned = j1_condition(table, pose) <= self.max_condition_ratio * c0;
        if !conditioned {
            return Err(Rejection::Condition);
        }
        match forward(table, &lengths, &table.home, &ForwardOptions::default()) {
            Ok((p, _)) => {
                let d = p.difference(pose);
                let radius = table
                    .links
                    .iter()
                    .map(|l| l.platform_mm.norm())
                    .fold(1.0f64, f64::max);
                let gap = d.fixed_rows::<3>(0).norm() + radius * d.fixed_rows::<3>(3).norm();
                if gap <= self.forward_tolerance_mm {
                    Ok(())
                } else {
                    Err(Rejection::ForwardKinematics)
                }
            }
            Err(_) => Err(Rejection::ForwardKinematics),
        }
    }

    /// The admissible poses of `poses` (in order) and the rejection counts.
    pub fn filter(&self, table: &JointTable, poses: &[Pose]) -> (Vec<Pose>, Rejections) {
        let verdicts: Vec<Result<(), Rejection>> =
            poses.par_iter().map(|p| self.check(table, p)).collect();
        let mut ok = Vec::with_capacity(poses.len());
        let mut rej = Rejections::default();
        for (p, v) in poses.iter().zip(verdicts) {
            match v {
                Ok(()) => ok.push(*p),
                Err(Rejection::LengthLimit) => rej.length_limit += 1,
                Err(Rejection::Tilt) => rej.tilt += 1,
                Err(Rejection::Condition) => rej.condition += 1,
                Err(Rejection::ForwardKinematics) => rej.forward_kinematics += 1,
            }
        }
        (ok, rej)
    }
}

/// Evenly spaced values from `-half` to `half` (`steps` of them; one step gives 0).
fn ladder(half: f64, steps: usize) -> Vec<f64> {
    if steps <= 1 {
        return vec![0.0];
    }
    (0..steps)
        .map(|i| -half + 2.0 * half * i as f64 / (steps - 1) as f64)
        .collect()
}

/// A full grid about `home`: `position_steps` values per axis in +-`half_range_mm` times
/// `angle_steps` values of roll, pitch and yaw in +-`half_range_deg`
/// (`position_steps^3 * angle_steps^3` poses). Not filtered.
pub fn grid_poses(
    home: &Pose,
    half_range_mm: f64,
    position_steps: usize,
    half_range_deg: f64,
    angle_steps: usize,
) -> Vec<Pose> {
    let xs = ladder(half_range_mm, position_steps);
    let angs: Vec<f64> = ladder(half_range_deg, angle_steps)
        .into_iter()
        .map(f64::to_radians)
        .collect();
    let mut out = Vec::new();
    for &x in &xs {
        for &y in &xs {
            for &z in &xs {
                for &r in &angs {
                    for &p in &angs {
                        for &w in &angs {
                            out.push(Pose::new(
                                home.position_mm + Vector3::new(x, y, z),
                                from_rpy(r, p, w) * home.rotation,
                            ));
                        }
                    }
                }
            }
        }
    }
    out
}

/// Ballbar-like circles: for every radius, height offset and tilt, `tilt_azimuths` circles
/// (the platform tilted by the tilt angle about a horizontal axis at evenly spaced azimuths;
/// one azimuth for a zero tilt) of `points` poses each, counter-clockwise in the horizontal
/// plane through `home` raised by the height offset. Not filtered.
pub fn circle_poses(
    home: &Pose,
    radii_mm: &[f64],
    heights_mm: &[f64],
    tilts_deg: &[f64],
    tilt_azimuths: usize,
    points: usize,
) -> Vec<Pose> {
    let mut out = Vec::new();
    for &r in radii_mm {
        for &h in heights_mm {
            for &t in tilts_deg {
                let azimuths = if t == 0.0 { 1 } else { tilt_azimuths.max(1) };
                for a in 0..azimuths {
                    let phi = std::f64::consts::TAU * a as f64 / azimuths as f64;
                    let axis = Unit::new_normalize(Vector3::new(phi.cos(), phi.sin(), 0.0));
                    let rot = Rotation3::from_axis_angle(&axis, t.to_radians()) * home.rotation;
                    for k in 0..points {
                        let th = std::f64::consts::TAU * k as f64 / points.max(1) as f64;
                        let p = home.position_mm + Vector3::new(r * th.cos(), r * th.sin(), h);
                        out.push(Pose::new(p, rot));
                    }
                }
            }
        }
    }
    out
}

/// The default candidate set of a design: `n_random` random poses (+-`half_range_mm`,
/// +-`half_range_deg`, seeded) plus ballbar circles (radii 50 and 100 % of the range, heights
/// -1/2, 0, +1/2 of it, tilts 0, 1/2 and 1 of the angle range at 4 azimuths, 12 points per
/// circle), filtered by `workspace`.
pub fn default_candidates(
    table: &JointTable,
    workspace: &Workspace,
    n_random: usize,
    half_range_mm: f64,
    half_range_deg: f64,
    seed: u64,
) -> (Vec<Pose>, Rejections) {
    let mut raw = random_poses(&table.home, n_random, half_range_mm, half_range_deg, seed);
    let r = half_range_mm;
    let a = half_range_deg;
    raw.extend(circle_poses(
        &table.home,
        &[0.5 * r, r],
        &[-0.5 * r, 0.0, 0.5 * r],
        &[0.0, 0.5 * a, a],
        4,
        12,
    ));
    workspace.filter(table, &raw)
}
