//! Joint tables: where each link's base and platform joints are, plus length-sensor sockets.
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::{GeometryError, Pose};

/// One actuated link: a base joint (base frame) and a platform joint (platform frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Link {
    /// Base joint centre in {B}, mm.
    pub base_mm: Vector3<f64>,
    /// Platform joint centre in {P}, mm.
    pub platform_mm: Vector3<f64>,
    /// Allowed link length range (min, max), mm, if known.
    pub length_limits_mm: Option<(f64, f64)>,
}

impl Link {
    /// A link from base and platform joint positions, no length limits.
    pub fn new(base_mm: [f64; 3], platform_mm: [f64; 3]) -> Self {
        Self {
            base_mm: Vector3::from(base_mm),
            platform_mm: Vector3::from(platform_mm),
            length_limits_mm: None,
        }
    }
}

/// A length sensor (ballbar-like gauge) between a base socket and a platform socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sensor {
    /// Name used in measurement files.
    pub name: String,
    /// Base socket centre in {B}, mm.
    pub base_mm: Vector3<f64>,
    /// Platform socket centre in {P}, mm.
    pub platform_mm: Vector3<f64>,
}

impl Sensor {
    /// A sensor from its name and socket positions.
    pub fn new(name: &str, base_mm: [f64; 3], platform_mm: [f64; 3]) -> Self {
        Self {
            name: name.to_string(),
            base_mm: Vector3::from(base_mm),
            platform_mm: Vector3::from(platform_mm),
        }
    }

    /// Sensor length at a pose: `|t + R p_s - b_s|`, mm.
    pub fn length_mm(&self, pose: &Pose) -> f64 {
        (pose.transform_point(&self.platform_mm) - self.base_mm).norm()
    }
}

/// The joint table of an N-link parallel manipulator plus its sensors and home pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointTable {
    /// The actuated links.
    pub links: Vec<Link>,
    /// Length sensors (socket pairs).
    pub sensors: Vec<Sensor>,
    /// Home pose: the start of forward kinematics and the centre of the paper's circle.
    pub home: Pose,
}

impl JointTable {
    /// Number of actuated links.
    pub fn num_links(&self) -> usize {
        self.links.len()
    }

    /// The sensor with this name.
    pub fn sensor(&self, name: &str) -> Result<&Sensor, GeometryError> {
        self.sensors
            .iter()
            .find(|s| s.name == name)
            .ok_or_else(|| GeometryError::UnknownSensor {
                name: name.to_string(),
                known: self
                    .sensors
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// Index of the sensor with this name.
    pub fn sensor_index(&self, name: &str) -> Option<usize> {
        self.sensors.iter().position(|s| s.name == name)
    }

    /// The cubic manipulator of the paper (Lim et al. 2002, Table 1) with its length sensor
    /// `"paper"` (base socket (-200, 500, 500), platform socket (-200, 205, -5) mm).
    ///
    /// Home pose (0, 0, 410) mm, R = I: **an assumption**; the paper gives none. At this pose
    /// the three z links are 354 mm long and the two x links are horizontal.
    pub fn paper_cubic() -> Self {
        let rows: [([f64; 3], [f64; 3]); 6] = [
            ([-140.0, -140.0, 28.0], [-140.0, -140.0, -28.0]),
            ([-140.0, 140.0, 28.0], [-140.0, 140.0, -28.0]),
            ([140.0, 0.0, 28.0], [140.0, 0.0, -28.0]),
            ([177.0, 70.0, 130.0], [-177.0, 70.0, -280.0]),
            ([177.0, -70.0, 130.0], [-177.0, -70.0, -280.0]),
            ([0.0, -205.0, 280.0], [0.0, 177.0, -140.0]),
        ];
        Self {
            links: rows.iter().map(|(b, p)| Link::new(*b, *p)).collect(),
            sensors: vec![Sensor::new(
                "paper",
                [-200.0, 500.0, 500.0],
                [-200.0, 205.0, -5.0],
            )],
            home: Pose::from_xyz_rpy(0.0, 0.0, 410.0, 0.0, 0.0, 0.0),
        }
    }

    /// Checks that every coordinate is finite and limits are ordered.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let bad = |field: String, value: f64, why: &str| GeometryError::InvalidValue {
            field,
            value,
            why: why.into(),
        };
        for (i, l) in self.links.iter().enumerate() {
            for (k, v) in l.base_mm.iter().chain(l.platform_mm.iter()).enumerate() {
                if !v.is_finite() {
                    let side = if k < 3 { "base_mm" } else { "platform_mm" };
                    return Err(bad(format!("link[{}].{side}", i + 1), *v, "not finite"));
                }
            }
            if let Some((lo, hi)) = l.length_limits_mm {
                if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi) {
                    return Err(bad(
                        format!("link[{}].length_limits_mm", i + 1),
                        lo,
                        "need 0 < min < max, finite",
                    ));
                }
            }
        }
        for s in &self.sensors {
            for v in s.base_mm.iter().chain(s.platform_mm.iter()) {
                if !v.is_finite() {
                    return Err(bad(format!("sensor `{}`", s.name), *v, "not finite"));
                }
            }
        }
        if !self.home.is_finite() {
            return Err(bad("home".into(), f64::NAN, "not finite"));
        }
        Ok(())
    }
}
