//! Inverse kinematics: link vectors, lengths and unit vectors for a pose.
use cpm_geometry::{JointTable, Pose};
use nalgebra::Vector3;

/// The state of one link at a pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkState {
    /// `s_i = R p_i`: platform joint relative to the platform origin, base orientation, mm.
    pub s_mm: Vector3<f64>,
    /// `q_i = t + s_i - b_i`, mm.
    pub vector_mm: Vector3<f64>,
    /// `l_i = |q_i|`, mm.
    pub length_mm: f64,
    /// `z_i = q_i / l_i`.
    pub unit: Vector3<f64>,
}

/// Link states of every link at `pose`.
pub fn inverse(table: &JointTable, pose: &Pose) -> Vec<LinkState> {
    table
        .links
        .iter()
        .map(|l| {
            let s = pose.rotation * l.platform_mm;
            let q = pose.position_mm + s - l.base_mm;
            let n = q.norm();
            LinkState {
                s_mm: s,
                vector_mm: q,
                length_mm: n,
                unit: q / n,
            }
        })
        .collect()
}

/// Link lengths (mm) at `pose`.
pub fn inverse_lengths(table: &JointTable, pose: &Pose) -> Vec<f64> {
    let mut out = vec![0.0; table.num_links()];
    inverse_lengths_into(table, pose, &mut out);
    out
}

/// Link lengths (mm) at `pose` into `out` (no allocation). `out.len()` must equal the link count
/// (extra entries are left alone, missing ones skipped; debug builds assert it).
///
/// ```
/// use cpm_geometry::JointTable;
/// use cpm_kinematics::inverse_lengths_into;
/// let t = JointTable::paper_cubic();
/// let mut l = [0.0; 6];
/// inverse_lengths_into(&t, &t.home, &mut l);
/// assert_eq!(l[..5], [354.0; 5]);
/// ```
pub fn inverse_lengths_into(table: &JointTable, pose: &Pose, out: &mut [f64]) {
    debug_assert_eq!(out.len(), table.num_links(), "one output per link");
    let r = pose.rotation.matrix();
    for (o, l) in out.iter_mut().zip(&table.links) {
        *o = (pose.position_mm + r * l.platform_mm - l.base_mm).norm();
    }
}
