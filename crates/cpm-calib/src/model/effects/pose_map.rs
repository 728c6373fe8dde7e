//! The pose error map: low-order polynomial terms in the commanded pose acting on the
//! platform pose's six components.
//!
//! A term is a monomial `m(c)` in the commanded pose coordinates, each scaled to order one:
//! `x, y, z` as `(c - c_home) / 100 mm`, `roll, pitch, yaw` as `(angle - angle_home) / 10 deg`.
//! Its six parameters move the platform after forward kinematics by the twist
//! `(dx, dy, dz) m(c)` um and `(rx, ry, rz) m(c)` urad (base frame), so the reading sees
//! `g . twist` and a tracker the moved pose.
//!
//! **Identifiable** when the campaign's poses span the term's variable (a term in `y^2` needs
//! poses at several `y`, both sides of home for odd degrees) and the map is not already explained
//! by the installation errors: a constant term is a gauge of the platform joints and is not in the
//! family; linear terms in the position are partly confounded with joint positions, which the
//! confounding check of [`refine`](crate::refine) measures (`novelty`). Components the readings do
//! not see (a rotation about a gauge's axis) stay undetermined and are reported so.
//!
//! **Extrapolation: none.** A polynomial fitted on a pose range says nothing outside it; the
//! range it was fitted on is reported ([`crate::fit::refine::Refinement::pose_range`]) and a pose
//! outside it should not be compensated with the map.
use std::collections::HashMap;
use std::sync::OnceLock;

use nalgebra::Vector6;

use super::{Channel, EffectInput, EffectModel};

/// Length scale of the position variables, mm.
pub const POSE_LENGTH_SCALE_MM: f64 = 100.0;
/// Angle scale of the orientation variables, degrees.
pub const POSE_ANGLE_SCALE_DEG: f64 = 10.0;

const VARS: [&str; 6] = ["x", "y", "z", "roll", "pitch", "yaw"];

/// A monomial in the commanded pose: exponents of (x, y, z, roll, pitch, yaw), of degree 1
/// to 3 (made by [`PoseTerm::all`] or [`PoseTerm::parse`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PoseTerm([u8; 6]);

/// Every term of degree 1 to 3 with its effect model, made once: a term's model and name are
/// borrowed from here (nothing is leaked, and the table never grows).
struct Table {
    maps: Vec<PoseMap>,
    index: HashMap<PoseTerm, usize>,
}

fn table() -> &'static Table {
    static TABLE: OnceLock<Table> = OnceLock::new();
    TABLE.get_or_init(|| {
        let maps: Vec<PoseMap> = PoseTerm::all(3)
            .into_iter()
            .map(|term| PoseMap {
                term,
                name: term.spelled(),
            })
            .collect();
        let index = maps.iter().enumerate().map(|(i, m)| (m.term, i)).collect();
        Table { maps, index }
    })
}

impl PoseTerm {
    /// The exponents of (x, y, z, roll, pitch, yaw).
    pub fn exponents(&self) -> [u8; 6] {
        self.0
    }

    /// The term's degree.
    pub fn degree(&self) -> u8 {
        self.0.iter().sum()
    }

    /// Every term of degree 1 to `degree` (capped at 3), lowest degree first.
    pub fn all(degree: u8) -> Vec<PoseTerm> {
        let degree = degree.min(3);
        let mut out = Vec::new();
        for d in 1..=degree {
            let mut rec = |e: [u8; 6]| {
                if e.iter().sum::<u8>() == d {
                    out.push(PoseTerm(e));
                }
            };
            for a in 0..=d {
                for b in 0..=d - a {
                    for c in 0..=d - a - b {
                        for e in 0..=d - a - b - c {
                            for f in 0..=d - a - b - c - e {
                                rec([a, b, c, e, f, d - a - b - c - e - f]);
                            }
                        }
                    }
                }
            }
        }
        out.sort_by(|a, b| a.degree().cmp(&b.degree()).then(b.0.cmp(&a.0)));
        out.dedup();
        out
    }

    /// The name, e.g. `pose_map_y`, `pose_map_y2`, `pose_map_x_roll`.
    pub fn name(&self) -> &'static str {
        &self.model().name
    }

    /// The name spelled out from the exponents.
    fn spelled(&self) -> String {
        let parts: Vec<String> = self
            .0
            .iter()
            .zip(VARS)
            .filter(|(e, _)| **e > 0)
            .map(|(e, v)| {
                if *e == 1 {
                    v.to_string()
                } else {
                    format!("{v}{e}")
                }
            })
            .collect();
        format!("pose_map_{}", parts.join("_"))
    }

    /// Parses a name such as `pose_map_y2` or `pose_map_x_roll` (degree 1 to 3).
    pub fn parse(name: &str) -> Option<PoseTerm> {
        let rest = name.strip_prefix("pose_map_")?;
        let mut e = [0u8; 6];
        for tok in rest.split('_') {
            let digits = tok.trim_start_matches(|c: char| c.is_ascii_alphabetic());
            let var = &tok[..tok.len() - digits.len()];
            let i = VARS.iter().position(|v| *v == var)?;
            let p: u8 = if digits.is_empty() {
                1
            } else {
                digits.parse().ok()?
            };
            if e[i] != 0 || p == 0 {
                return None;
            }
            e[i] = p;
        }
        let t = PoseTerm(e);
        (1..=3).contains(&t.degree()).then_some(t)
    }

    /// The monomial's value at a commanded pose.
    pub fn value(&self, commanded: &cpm_geometry::Pose, home: &cpm_geometry::Pose) -> f64 {
        let (r, p, y) = commanded.rpy();
        let (hr, hp, hy) = home.rpy();
        let d = commanded.position_mm - home.position_mm;
        let u = [
            d.x / POSE_LENGTH_SCALE_MM,
            d.y / POSE_LENGTH_SCALE_MM,
            d.z / POSE_LENGTH_SCALE_MM,
            (r - hr).to_degrees() / POSE_ANGLE_SCALE_DEG,
            (p - hp).to_degrees() / POSE_ANGLE_SCALE_DEG,
            (y - hy).to_degrees() / POSE_ANGLE_SCALE_DEG,
        ];
        self.0
            .iter()
            .zip(u)
            .map(|(e, v)| v.powi(i32::from(*e)))
            .product()
    }

    /// The name of the residual regressor of [`crate::analysis::diagnostics::regressors`] this term
    /// answers, when there is one (`pose y`, `pose x squared`, ...).
    pub fn regressor(&self) -> Option<String> {
        let i = self.0.iter().position(|e| *e > 0)?;
        if self.0.iter().filter(|e| **e > 0).count() != 1 {
            return None;
        }
        match self.0[i] {
            1 => Some(format!("pose {}", VARS[i])),
            2 if i < 3 => Some(format!("pose {} squared", VARS[i])),
            _ => None,
        }
    }

    /// The term's effect model.
    pub fn model(&self) -> &'static PoseMap {
        let t = table();
        &t.maps[t.index[self]]
    }
}

/// The effect of one pose map term.
#[derive(Debug, Clone)]
pub struct PoseMap {
    /// The monomial.
    pub term: PoseTerm,
    name: String,
}

impl EffectModel for PoseMap {
    fn name(&self) -> &str {
        &self.name
    }
    fn num_params(&self, _: usize, _: usize) -> usize {
        6
    }
    fn param_name(&self, k: usize, _: &[String]) -> String {
        ["dx", "dy", "dz", "rx", "ry", "rz"][k].to_string()
    }
    fn unit(&self) -> &str {
        "um (position), urad (orientation)"
    }
    fn param_unit(&self, k: usize) -> &str {
        if k >= 3 {
            "urad"
        } else {
            "um"
        }
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::PlatformPose]
    }
    fn pose_coefficients(&self, k: usize, input: &EffectInput) -> Vector6<f64> {
        let mut c = Vector6::zeros();
        c[k] = self.term.value(input.commanded, input.home) * if k < 3 { 1e-3 } else { 1e-6 };
        c
    }
}
