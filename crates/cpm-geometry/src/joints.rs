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

    /// A general 6-6 Gough-Stewart platform (not from the paper), the geometry of
    /// `examples/hexapod_66.toml`.
    ///
    /// - Base joints on a radius-200 mm circle in the plane z = 0 of {B}, in pairs at +-15 deg
    ///   around 0, 120 and 240 deg.
    /// - Platform joints on a radius-120 mm circle in the plane z = 0 of {P}, in pairs at
    ///   +-15 deg around 60, 180 and 300 deg.
    /// - Link `i` joins base joint at angle `beta_i` = -15, 15, 105, 135, 225, 255 deg to the
    ///   nearest platform joint of the neighbouring pair, at `pi_i` = -45, 45, 75, 165, 195,
    ///   285 deg (the usual crossed-leg arrangement).
    /// - Length limits 250..400 mm; home pose (0, 0, 300) mm, R = I, where every link is
    ///   `sqrt(300^2 + d^2)` mm long with `d` the horizontal joint distance (about 320.7 mm).
    /// - Coordinates are rounded to 1e-9 mm (so the file lists them exactly).
    /// - Three length sensors `s1`, `s2`, `s3`: base sockets on a radius-400 mm circle at
    ///   z = 100 mm at 20, 140, 260 deg, platform sockets on the platform rim (radius 120 mm,
    ///   z = 0 in {P}) at 0, 120, 240 deg, so each gauge is inclined and has a tangential
    ///   component (it sees the platform's yaw as well as its translation).
    ///
    /// ```
    /// use cpm_geometry::JointTable;
    /// let t = JointTable::hexapod_66();
    /// assert_eq!(t.num_links(), 6);
    /// assert_eq!(t.sensors.len(), 3);
    /// assert!((t.links[0].base_mm.norm() - 200.0).abs() < 1e-8);
    /// assert!((t.links[0].platform_mm.norm() - 120.0).abs() < 1e-8);
    /// ```
    pub fn hexapod_66() -> Self {
        // Coordinates are rounded to 1e-9 mm so that the example file can list them exactly
        // with nine decimals (the quotient is the double nearest to that decimal).
        let r9 = |x: f64| (x * 1e9).round() / 1e9 + 0.0;
        let on_circle = |radius: f64, deg: f64, z: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            [r9(radius * c), r9(radius * s), z]
        };
        let base_deg = [-15.0, 15.0, 105.0, 135.0, 225.0, 255.0];
        let platform_deg = [-45.0, 45.0, 75.0, 165.0, 195.0, 285.0];
        let links = base_deg
            .iter()
            .zip(&platform_deg)
            .map(|(b, p)| Link {
                length_limits_mm: Some((250.0, 400.0)),
                ..Link::new(on_circle(200.0, *b, 0.0), on_circle(120.0, *p, 0.0))
            })
            .collect();
        let sensors = (0..3)
            .map(|k| {
                let a = 120.0 * k as f64;
                Sensor::new(
                    &format!("s{}", k + 1),
                    on_circle(400.0, a + 20.0, 100.0),
                    on_circle(120.0, a, 0.0),
                )
            })
            .collect();
        Self {
            links,
            sensors,
            home: Pose::from_xyz_rpy(0.0, 0.0, 300.0, 0.0, 0.0, 0.0),
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
