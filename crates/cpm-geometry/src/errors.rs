//! Installation errors: the 3D displacement of every base and platform joint.
//!
//! Parameter order in flat vectors (used by every crate): link by link, base side first then
//! platform side, x y z: index `6 * link + 3 * side + axis` with `side` 0 = base, 1 = platform.
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::{GeometryError, JointTable};

/// Which end of a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Side {
    /// The base joint (expressed in {B}).
    Base,
    /// The platform joint (expressed in {P}).
    Platform,
}

/// How platform-side errors are applied: `p + dp` (the convention of `cpm`) or `p - dp`.
///
/// The paper never states it; `cpm` uses `Plus` everywhere and exposes `Minus` only to test
/// which convention the paper's Table 3 is consistent with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum PlatformSign {
    /// actual platform joint = nominal + dp.
    #[default]
    Plus,
    /// actual platform joint = nominal - dp.
    Minus,
}

/// Installation errors in micrometres, one base and one platform vector per link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstallationErrors {
    /// Base joint displacement in {B}, um.
    pub base_um: Vec<Vector3<f64>>,
    /// Platform joint displacement in {P}, um.
    pub platform_um: Vec<Vector3<f64>>,
}

fn from_rows(rows: &[[f64; 6]]) -> InstallationErrors {
    InstallationErrors {
        base_um: rows
            .iter()
            .map(|r| Vector3::new(r[0], r[1], r[2]))
            .collect(),
        platform_um: rows
            .iter()
            .map(|r| Vector3::new(r[3], r[4], r[5]))
            .collect(),
    }
}

impl InstallationErrors {
    /// All zero for `n` links.
    pub fn zeros(n: usize) -> Self {
        Self {
            base_um: vec![Vector3::zeros(); n],
            platform_um: vec![Vector3::zeros(); n],
        }
    }

    /// Number of links.
    pub fn num_links(&self) -> usize {
        self.base_um.len()
    }

    /// The paper's Table 2: the errors assumed in its simulation, um.
    pub fn paper_table2() -> Self {
        from_rows(&[
            [13.7, 1.2, 89.4, 93.8, 66.8, 37.0],
            [19.9, 29.9, 66.1, 80.3, 64.7, 44.5],
            [28.4, 46.9, 6.5, 79.5, 72.1, 79.5],
            [98.8, 58.3, 42.3, 105.7, 62.3, 88.0],
            [51.6, 33.4, 43.3, 27.3, 108.0, 27.1],
            [22.6, 58.0, 76.0, 35.2, 97.6, 73.7],
        ])
    }

    /// The paper's Table 3: the errors it reports as identified, um.
    pub fn paper_table3() -> Self {
        from_rows(&[
            [13.4, 9.0, 78.7, 99.1, 67.1, 47.7],
            [20.3, 30.3, 81.0, 79.9, 64.3, 29.6],
            [28.4, 46.9, 6.0, 79.5, 72.1, 80.0],
            [113.0, 57.9, 42.3, 91.5, 62.7, 88.0],
            [37.0, 33.8, 43.3, 41.9, 107.6, 27.1],
            [22.9, 68.3, 75.7, 34.9, 87.3, 74.0],
        ])
    }

    /// Flat vector in micrometres (order: see the module doc).
    pub fn to_vec_um(&self) -> Vec<f64> {
        let mut v = Vec::with_capacity(6 * self.num_links());
        for i in 0..self.num_links() {
            v.extend(self.base_um[i].iter());
            v.extend(self.platform_um[i].iter());
        }
        v
    }

    /// From a flat vector in micrometres (order: see the module doc).
    pub fn try_from_vec_um(v: &[f64]) -> Result<Self, GeometryError> {
        // (Not `is_multiple_of`: the MSRV is 1.85.)
        let whole_links = v.len() / 6 * 6 == v.len();
        if !whole_links {
            return Err(GeometryError::WrongErrorCount {
                got: v.len(),
                expected: 6 * v.len().div_ceil(6),
            });
        }
        let rows: Vec<[f64; 6]> = v
            .chunks(6)
            .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5]])
            .collect();
        Ok(from_rows(&rows))
    }

    /// Component `(link, side, axis)` in micrometres.
    pub fn get_um(&self, link: usize, side: Side, axis: usize) -> f64 {
        match side {
            Side::Base => self.base_um[link][axis],
            Side::Platform => self.platform_um[link][axis],
        }
    }

    /// The actual joint table: nominal plus these errors (platform side `p + dp`).
    pub fn apply(&self, nominal: &JointTable) -> Result<JointTable, GeometryError> {
        self.apply_with(nominal, PlatformSign::Plus)
    }

    /// The actual joint table with an explicit platform-side sign convention.
    pub fn apply_with(
        &self,
        nominal: &JointTable,
        sign: PlatformSign,
    ) -> Result<JointTable, GeometryError> {
        if self.num_links() != nominal.num_links() || self.platform_um.len() != self.num_links() {
            return Err(GeometryError::LinkCountMismatch {
                errors: self.num_links(),
                links: nominal.num_links(),
            });
        }
        let s = match sign {
            PlatformSign::Plus => 1.0,
            PlatformSign::Minus => -1.0,
        };
        let mut t = nominal.clone();
        for (i, l) in t.links.iter_mut().enumerate() {
            l.base_mm += self.base_um[i] * 1e-3;
            l.platform_mm += self.platform_um[i] * (1e-3 * s);
        }
        Ok(t)
    }

    /// Human name of flat component `k`, e.g. `link 2 platform dy`.
    pub fn component_name(k: usize) -> String {
        let link = k / 6 + 1;
        let side = if (k % 6) < 3 { "base" } else { "platform" };
        let axis = ["dx", "dy", "dz"][k % 3];
        format!("link {link} {side} {axis}")
    }
}
