//! General pose generators: random poses about home, and random poses kept only where the
//! machine is well conditioned and reachable (the rule the readers judge a pose by).
//!
//! ```
//! use cpm_calib::data::poses::random_workspace_poses;
//! use cpm_geometry::JointTable;
//! let table = JointTable::paper_cubic();
//! let poses = random_workspace_poses(&table, 5, 50.0, 5.0, 3.0, 1);
//! assert_eq!(poses.len(), 5);
//! ```
use cpm_geometry::{JointTable, Pose};
use rand::{Rng, SeedableRng};

/// Random poses around `home`: position uniform in +-`dpos_mm`, roll/pitch/yaw uniform in
/// +-`dang_deg`, seeded.
pub fn random_poses(home: &Pose, n: usize, dpos_mm: f64, dang_deg: f64, seed: u64) -> Vec<Pose> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let a = dang_deg.to_radians();
    (0..n)
        .map(|_| {
            let mut u = || rng.random_range(-1.0..=1.0);
            let (x, y, z) = (u() * dpos_mm, u() * dpos_mm, u() * dpos_mm);
            let (r, p, w) = (u() * a, u() * a, u() * a);
            Pose::new(
                home.position_mm + nalgebra::Vector3::new(x, y, z),
                cpm_geometry::rotation::from_rpy(r, p, w) * home.rotation,
            )
        })
        .collect()
}

/// Condition number of J1 at a pose (6x6 only; infinity otherwise, and where J1 is exactly
/// singular or has a zero-length link). NaN when the SVD fails on a finite J1 (not seen in
/// 10^6 random J1), so that a pose-selection filter (`c <= bound`) leaves such a pose out
/// rather than calling it singular.
pub fn j1_condition(table: &JointTable, pose: &Pose) -> f64 {
    if table.num_links() != 6 {
        return f64::INFINITY;
    }
    cpm_kinematics::workspace::j1_condition(table, pose).unwrap_or(f64::NAN)
}

/// Like [`random_poses`], keeping only poses where the machine is well conditioned and that
/// [`cpm_kinematics::reachable_at`] accepts: J1's condition number at most
/// `max_condition_ratio` times its value at home, link lengths within their limits where the
/// table has any, and the pose in home's assembly mode. Draws until `n` are found (at most 100 n
/// draws).
pub fn random_workspace_poses(
    table: &JointTable,
    n: usize,
    dpos_mm: f64,
    dang_deg: f64,
    max_condition_ratio: f64,
    seed: u64,
) -> Vec<Pose> {
    let c0 = j1_condition(table, &table.home);
    let mut out = Vec::with_capacity(n);
    // At most 100 batches, seeded `seed, seed + 1, ...` (wrapping: every u64 is a seed).
    for k in 0..100u64 {
        if out.len() >= n {
            break;
        }
        let batch = seed.wrapping_add(k);
        for p in random_poses(&table.home, n, dpos_mm, dang_deg, batch.wrapping_mul(7919)) {
            if out.len() == n {
                break;
            }
            // Length limits and J1's condition at the pose, and home's assembly mode: the
            // rule by which the readers judge a pose (`cpm_kinematics::reachable_at`).
            if cpm_kinematics::reachable_at(table, &p, max_condition_ratio * c0).is_ok() {
                out.push(p);
            }
        }
    }
    out
}
