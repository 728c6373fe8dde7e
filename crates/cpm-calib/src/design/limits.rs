//! What a real instrument and a real machine allow: the gauge (its stroke within one setup,
//! its shortest and longest length, its extension bars), the clearance between the gauge and
//! the links, and the joints' cone angles.
//!
//! - A **setup** is one base socket, one platform socket and one extension bar: the gauge then
//!   reads lengths in a *window* `[shortest + bar, shortest + bar + stroke]` (a ballbar: a
//!   stroke of about 2 mm; a telescoping length gauge: tens to a couple of hundred mm). A
//!   setup is what a `sensor` of the readings file names.
//! - **Clearance**: the gauge axis (base socket to platform socket) must stay at least
//!   [`Clearance::gauge_link_mm`] from every link axis (base joint centre to platform joint
//!   centre); that distance is the link's radius plus the gauge's. Between links, only when
//!   [`Clearance::link_link_mm`] is set.
//! - **Joint limits**: the largest cone angle of each base joint (the link direction in {B}
//!   against its direction at home) and of each platform joint (the link direction in {P}
//!   against home), [`JointLimits`]; the link length limits of the joint table apply too.
//!
//! Distances between axes are exact segment-to-segment distances ([`segment_distance_mm`]).
//!
//! ```
//! use cpm_calib::design::limits::{segment_distance_mm, Constraints};
//! use nalgebra::Vector3;
//! // Two skew segments 5 mm apart.
//! let d = segment_distance_mm(
//!     &Vector3::new(-1.0, 0.0, 0.0), &Vector3::new(1.0, 0.0, 0.0),
//!     &Vector3::new(0.0, -1.0, 5.0), &Vector3::new(0.0, 1.0, 5.0),
//! );
//! assert!((d - 5.0).abs() < 1e-12);
//! let c = Constraints::default();
//! assert_eq!(c.gauge.stroke_mm, 200.0);
//! assert_eq!(c.clearance.gauge_link_mm, 30.0);
//! assert_eq!(c.joints.base_cone_deg, 40.0);
//! assert!(c.validate().is_ok());
//! ```
use cpm_geometry::description::{GaugeKindSpec, GaugeSpec, LimitsSpec, RobotDescription};
use cpm_geometry::{JointTable, Pose, Sensor};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::CalibError;

/// The kind of length gauge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum GaugeKind {
    /// A telescoping length gauge (linear encoder between two balls): a stroke of tens to a
    /// couple of hundred mm.
    Telescoping,
    /// A ballbar: a stroke of about 2 mm (+-1 mm), made longer with extension bars.
    Ballbar,
}

impl GaugeKind {
    /// `telescoping` or `ballbar`.
    pub fn name(&self) -> &'static str {
        match self {
            GaugeKind::Telescoping => "telescoping",
            GaugeKind::Ballbar => "ballbar",
        }
    }
}

/// A length gauge (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Gauge {
    /// Kind. Default telescoping.
    pub kind: GaugeKind,
    /// Travel within one setup (one socket pair, one bar), mm. Default 200.
    pub stroke_mm: f64,
    /// Shortest socket-to-socket length the gauge reads (without extension bars), mm.
    /// Default 150.
    pub shortest_mm: f64,
    /// Longest socket-to-socket length the gauge reads with any bar, mm. Default 1000.
    pub longest_mm: f64,
    /// Extension bars available, mm (a setup uses one: its window starts at
    /// `shortest_mm + bar`; list stacked combinations as bars of their own). Empty (the
    /// default): any bar length, i.e. the window may start anywhere from `shortest_mm` to
    /// `longest_mm - stroke_mm` (the design places it).
    pub bars_mm: Vec<f64>,
    /// Noise of one reading (standard deviation), um. Default the paper's uniform +-10 um:
    /// 10 / sqrt(3).
    pub sigma_um: f64,
}

impl Default for Gauge {
    fn default() -> Self {
        Self {
            kind: GaugeKind::Telescoping,
            stroke_mm: 200.0,
            shortest_mm: 150.0,
            longest_mm: 1000.0,
            bars_mm: Vec::new(),
            sigma_um: 10.0 / 3f64.sqrt(),
        }
    }
}

impl Gauge {
    /// A ballbar: stroke 2 mm, shortest 100 mm, longest 1000 mm, any bar length.
    pub fn ballbar() -> Self {
        Self {
            kind: GaugeKind::Ballbar,
            stroke_mm: 2.0,
            shortest_mm: 100.0,
            ..Self::default()
        }
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), CalibError> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.stroke_mm) {
            return Err(CalibError::invalid(
                "gauge.stroke_mm",
                "must be finite and > 0",
            ));
        }
        if !(pos(self.shortest_mm) && self.longest_mm.is_finite()) {
            return Err(CalibError::invalid(
                "gauge.shortest_mm",
                "shortest_mm must be finite and > 0, longest_mm finite",
            ));
        }
        if self.longest_mm < self.shortest_mm + self.stroke_mm {
            return Err(CalibError::invalid(
                "gauge.longest_mm",
                format!(
                    "{} mm is shorter than shortest_mm + stroke_mm = {} mm",
                    self.longest_mm,
                    self.shortest_mm + self.stroke_mm
                ),
            ));
        }
        if let Some(b) = self.bars_mm.iter().find(|b| !(b.is_finite() && **b >= 0.0)) {
            return Err(CalibError::invalid(
                "gauge.bars_mm",
                format!("{b}: bars must be finite and >= 0 mm"),
            ));
        }
        if !pos(self.sigma_um) {
            return Err(CalibError::invalid(
                "gauge.sigma_um",
                "must be finite and > 0",
            ));
        }
        Ok(())
    }

    /// The length windows `(lo, hi)` (mm) the gauge offers that meet `[min_mm, max_mm]`:
    /// one per bar, or, without a bar list, at most `max_windows` windows spread evenly
    /// between the lowest start that still reaches `min_mm` and the highest that still
    /// reaches `max_mm`. Each entry: `(bar_mm, lo, hi)`.
    pub fn windows(&self, min_mm: f64, max_mm: f64, max_windows: usize) -> Vec<(f64, f64, f64)> {
        let s = self.stroke_mm;
        let fits = |lo: f64| lo + s <= self.longest_mm + 1e-9 && lo + s >= min_mm && lo <= max_mm;
        if !self.bars_mm.is_empty() {
            return self
                .bars_mm
                .iter()
                .map(|b| (*b, self.shortest_mm + b, self.shortest_mm + b + s))
                .filter(|w| fits(w.1))
                .collect();
        }
        let first = (min_mm - s).max(self.shortest_mm);
        let last = max_mm.min(self.longest_mm - s);
        if !(first <= last) || max_windows == 0 {
            return Vec::new();
        }
        // Windows that cover [min, max] with as few as needed, at most `max_windows`.
        let span = max_mm - min_mm;
        let needed = (span / s).ceil().max(0.0) as usize + 1;
        let k = needed.clamp(1, max_windows);
        let (first, last) = (min_mm.max(self.shortest_mm), (max_mm - s).max(min_mm));
        let last = last.min(self.longest_mm - s).max(first);
        (0..k)
            .map(|i| {
                let lo = if k == 1 {
                    first
                } else {
                    first + (last - first) * i as f64 / (k - 1) as f64
                };
                (lo - self.shortest_mm, lo, lo + s)
            })
            .filter(|w| fits(w.1))
            .collect()
    }
}

/// Clearances (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Clearance {
    /// Smallest distance between the gauge axis and any link axis, mm (link radius plus gauge
    /// radius). Default 30.
    pub gauge_link_mm: f64,
    /// Smallest distance between two link axes, mm, when the machine declares link radii.
    /// Default `None` (not checked).
    pub link_link_mm: Option<f64>,
}

impl Default for Clearance {
    fn default() -> Self {
        Self {
            gauge_link_mm: 30.0,
            link_link_mm: None,
        }
    }
}

/// Joint cone limits (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JointLimits {
    /// Largest angle of a link from its home direction at its base joint (in {B}), deg.
    /// Default 40.
    pub base_cone_deg: f64,
    /// Largest angle of a link from its home direction at its platform joint (in {P}), deg.
    /// Default 40.
    pub platform_cone_deg: f64,
}

impl Default for JointLimits {
    fn default() -> Self {
        Self {
            base_cone_deg: 40.0,
            platform_cone_deg: 40.0,
        }
    }
}

/// The instrument and the machine's limits a design must honour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Constraints {
    /// The gauge. Default [`Gauge::default`] (telescoping, 200 mm stroke).
    pub gauge: Gauge,
    /// Clearances. Default 30 mm gauge to link.
    pub clearance: Clearance,
    /// Joint cone limits. Default 40 deg at both ends.
    pub joints: JointLimits,
}

impl Constraints {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), CalibError> {
        self.gauge.validate()?;
        if !(self.clearance.gauge_link_mm.is_finite() && self.clearance.gauge_link_mm >= 0.0) {
            return Err(CalibError::invalid(
                "clearance.gauge_link_mm",
                "must be finite and >= 0",
            ));
        }
        if let Some(v) = self.clearance.link_link_mm {
            if !(v.is_finite() && v >= 0.0) {
                return Err(CalibError::invalid(
                    "clearance.link_link_mm",
                    "must be finite and >= 0",
                ));
            }
        }
        for (f, v) in [
            ("joints.base_cone_deg", self.joints.base_cone_deg),
            ("joints.platform_cone_deg", self.joints.platform_cone_deg),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 180.0) {
                return Err(CalibError::invalid(f, "must be in (0, 180] deg"));
            }
        }
        Ok(())
    }

    /// Checks the machine at `pose` against the joint and link limits (not the gauge): the
    /// joint cone angles, the table's link length limits and, when set, the link-link
    /// clearance. `Err` names the first limit broken.
    pub fn check_pose(&self, table: &JointTable, pose: &Pose) -> Result<(), String> {
        let cones = cone_angles_deg(table, pose);
        for (i, (b, p)) in cones.iter().enumerate() {
            if !(*b <= self.joints.base_cone_deg) {
                return Err(format!(
                    "link {}: base joint cone {b:.1} deg > {} deg",
                    i + 1,
                    self.joints.base_cone_deg
                ));
            }
            if !(*p <= self.joints.platform_cone_deg) {
                return Err(format!(
                    "link {}: platform joint cone {p:.1} deg > {} deg",
                    i + 1,
                    self.joints.platform_cone_deg
                ));
            }
        }
        let axes = link_axes(table, pose);
        for (i, ((a, b), link)) in axes.iter().zip(&table.links).enumerate() {
            let l = (b - a).norm();
            if let Some((lo, hi)) = link.length_limits_mm {
                if !(l >= lo && l <= hi) {
                    return Err(format!(
                        "link {}: length {l:.1} mm outside {lo}..{hi} mm",
                        i + 1
                    ));
                }
            }
        }
        if let Some(min) = self.clearance.link_link_mm {
            for i in 0..axes.len() {
                for j in i + 1..axes.len() {
                    let d = segment_distance_mm(&axes[i].0, &axes[i].1, &axes[j].0, &axes[j].1);
                    if !(d >= min) {
                        return Err(format!(
                            "links {} and {}: {d:.1} mm apart < {min} mm",
                            i + 1,
                            j + 1
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

impl Gauge {
    /// From a description's `[[gauge]]`: its values with the defaults the description
    /// documents (noise: the gauge's `noise_um`, else `default_sigma_um`).
    pub fn from_spec(spec: &GaugeSpec, default_sigma_um: f64) -> Self {
        Self {
            kind: match spec.kind {
                GaugeKindSpec::Telescoping => GaugeKind::Telescoping,
                GaugeKindSpec::Ballbar => GaugeKind::Ballbar,
            },
            stroke_mm: spec.stroke_mm,
            shortest_mm: spec.shortest_length_mm(),
            longest_mm: spec.longest_length_mm(),
            bars_mm: spec.bars_mm.clone(),
            sigma_um: spec.noise_um.unwrap_or(default_sigma_um),
        }
    }

    /// As a description's `[[gauge]]` named `name` (every value written out; `radius_mm`
    /// given by the caller).
    pub fn to_spec(&self, name: &str, radius_mm: Option<f64>) -> GaugeSpec {
        GaugeSpec {
            name: name.to_string(),
            kind: match self.kind {
                GaugeKind::Telescoping => GaugeKindSpec::Telescoping,
                GaugeKind::Ballbar => GaugeKindSpec::Ballbar,
            },
            stroke_mm: self.stroke_mm,
            shortest_mm: Some(self.shortest_mm),
            longest_mm: Some(self.longest_mm),
            bars_mm: self.bars_mm.clone(),
            noise_um: Some(self.sigma_um),
            radius_mm,
        }
    }
}

impl Constraints {
    /// The limits a description declares: its `[[gauge]]` named `gauge` (the first when
    /// `None`) and its `[limits]` (defaults stated in [`LimitsSpec`]). `Ok(None)` when the
    /// description has no gauge; `Err` when the named gauge does not exist. The gauge's
    /// noise defaults to `[calibration] sensor_noise_um`, else the paper's uniform +-10 um.
    ///
    /// ```
    /// use cpm_calib::design::Constraints;
    /// use cpm_geometry::description::{GaugeSpec, GaugeKindSpec, LimitsSpec, RobotDescription};
    /// let mut d = RobotDescription::paper_cubic();
    /// assert!(Constraints::from_description(&d, None).unwrap().is_none());
    /// d.gauges.push(GaugeSpec { name: "bb".into(), kind: GaugeKindSpec::Ballbar, stroke_mm: 2.0,
    ///     shortest_mm: None, longest_mm: None, bars_mm: vec![], noise_um: None, radius_mm: Some(5.0) });
    /// d.limits = Some(LimitsSpec { link_radius_mm: Some(20.0), ..LimitsSpec::default() });
    /// let c = Constraints::from_description(&d, None).unwrap().unwrap();
    /// assert_eq!(c.gauge.shortest_mm, 100.0);
    /// assert_eq!(c.clearance.gauge_link_mm, 25.0); // link radius + gauge radius
    /// assert_eq!(c.clearance.link_link_mm, Some(40.0));
    /// assert!(Constraints::from_description(&d, Some("nope")).is_err());
    /// ```
    pub fn from_description(
        desc: &RobotDescription,
        gauge: Option<&str>,
    ) -> Result<Option<Self>, CalibError> {
        let spec = match (gauge, desc.gauge(gauge)) {
            (_, Some(g)) => g,
            (Some(name), None) => {
                return Err(CalibError::invalid(
                    "gauge",
                    format!(
                        "no [[gauge]] named `{name}` in the description (it has: {})",
                        desc.gauges
                            .iter()
                            .map(|g| g.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ))
            }
            (None, None) => return Ok(None),
        };
        let default_sigma = desc
            .calibration
            .as_ref()
            .and_then(|c| c.sensor_noise_um)
            .unwrap_or(10.0 / 3f64.sqrt());
        let limits = desc.limits.unwrap_or_default();
        Ok(Some(Self {
            gauge: Gauge::from_spec(spec, default_sigma),
            clearance: Clearance {
                gauge_link_mm: limits.gauge_link_mm(Some(spec)),
                link_link_mm: limits.link_link_mm(),
            },
            joints: JointLimits {
                base_cone_deg: limits.base_cone_deg,
                platform_cone_deg: limits.platform_cone_deg,
            },
        }))
    }

    /// As a description's `[limits]`, keeping `previous`'s link radius (the link-link
    /// clearance is twice the link radius; one set without a radius is written as the
    /// radius it implies).
    pub fn to_limits_spec(&self, previous: Option<&LimitsSpec>) -> LimitsSpec {
        LimitsSpec {
            base_cone_deg: self.joints.base_cone_deg,
            platform_cone_deg: self.joints.platform_cone_deg,
            link_radius_mm: previous
                .and_then(|l| l.link_radius_mm)
                .or(self.clearance.link_link_mm.map(|d| 0.5 * d)),
            gauge_link_clearance_mm: Some(self.clearance.gauge_link_mm),
        }
    }
}

/// Link axes at `pose`: (base joint centre, platform joint centre) in {B}, mm.
pub fn link_axes(table: &JointTable, pose: &Pose) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    table
        .links
        .iter()
        .map(|l| (l.base_mm, pose.position_mm + pose.rotation * l.platform_mm))
        .collect()
}

/// Per link, the cone angles (base joint, platform joint) at `pose` from home, deg: the angle
/// of the link direction in {B} from its direction at home, and the same in {P}.
pub fn cone_angles_deg(table: &JointTable, pose: &Pose) -> Vec<(f64, f64)> {
    let home = link_axes(table, &table.home);
    let now = link_axes(table, pose);
    let angle = |a: &Vector3<f64>, b: &Vector3<f64>| {
        // atan2 of |a x b| and a . b: accurate at small angles too.
        a.cross(b).norm().atan2(a.dot(b)).to_degrees()
    };
    home.iter()
        .zip(&now)
        .map(|((b0, q0), (b1, q1))| {
            let d0 = q0 - b0;
            let d1 = q1 - b1;
            let p0 = table.home.rotation.inverse() * d0;
            let p1 = pose.rotation.inverse() * d1;
            (angle(&d0, &d1), angle(&p0, &p1))
        })
        .collect()
}

/// Gauge axis of `sensor` at `pose`: (base socket, platform socket) in {B}, mm.
pub fn gauge_axis(sensor: &Sensor, pose: &Pose) -> (Vector3<f64>, Vector3<f64>) {
    (
        sensor.base_mm,
        pose.position_mm + pose.rotation * sensor.platform_mm,
    )
}

/// Smallest distance between the gauge axis of `sensor` and any link axis at `pose`, mm.
pub fn gauge_clearance_mm(table: &JointTable, sensor: &Sensor, pose: &Pose) -> f64 {
    let (g0, g1) = gauge_axis(sensor, pose);
    link_axes(table, pose)
        .iter()
        .map(|(a, b)| segment_distance_mm(&g0, &g1, a, b))
        .fold(f64::INFINITY, f64::min)
}

/// Distance between the segments `p0 p1` and `q0 q1`, mm (closest points by clamping, after
/// Ericson, *Real-Time Collision Detection*, 5.1.9; degenerate segments are points).
pub fn segment_distance_mm(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> f64 {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.dot(&d1);
    let e = d2.dot(&d2);
    let f = d2.dot(&r);
    let eps = 1e-18;
    let (s, t);
    if a <= eps && e <= eps {
        return r.norm();
    }
    if a <= eps {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= eps {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > eps * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    let c1 = p0 + d1 * s;
    let c2 = q0 + d2 * t;
    (c1 - c2).norm()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn brute(p0: &Vector3<f64>, p1: &Vector3<f64>, q0: &Vector3<f64>, q1: &Vector3<f64>) -> f64 {
        // Coarse grid, then a local refinement around the best cell.
        let n = 200;
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for i in 0..=n {
            let s = i as f64 / n as f64;
            let a = p0 + (p1 - p0) * s;
            for j in 0..=n {
                let t = j as f64 / n as f64;
                let d = (a - (q0 + (q1 - q0) * t)).norm();
                if d < best.0 {
                    best = (d, s, t);
                }
            }
        }
        let h = 1.0 / n as f64;
        for i in 0..=100 {
            let s = (best.1 - h + 2.0 * h * i as f64 / 100.0).clamp(0.0, 1.0);
            let a = p0 + (p1 - p0) * s;
            for j in 0..=100 {
                let t = (best.2 - h + 2.0 * h * j as f64 / 100.0).clamp(0.0, 1.0);
                let d = (a - (q0 + (q1 - q0) * t)).norm();
                best.0 = best.0.min(d);
            }
        }
        best.0
    }

    #[test]
    fn segment_distance_matches_brute_force_sampling() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(16);
        let v = |rng: &mut rand::rngs::StdRng, s: f64| {
            Vector3::new(
                rng.random_range(-s..s),
                rng.random_range(-s..s),
                rng.random_range(-s..s),
            )
        };
        for k in 0..300 {
            let scale = [1.0, 100.0, 1000.0][k % 3];
            let p0 = v(&mut rng, scale);
            let mut p1 = v(&mut rng, scale);
            let q0 = v(&mut rng, scale);
            let mut q1 = v(&mut rng, scale);
            match k % 10 {
                // Parallel segments, degenerate segments.
                7 => q1 = q0 + (p1 - p0) * 0.7,
                8 => p1 = p0,
                9 => q1 = q0,
                _ => {}
            }
            let exact = segment_distance_mm(&p0, &p1, &q0, &q1);
            let b = brute(&p0, &p1, &q0, &q1);
            // The sampled distance is never below the exact one, and close above it.
            assert!(exact <= b + 1e-9 * scale, "{k}: {exact} > {b}");
            assert!(b - exact <= 2e-5 * scale, "{k}: exact {exact}, sampled {b}");
            // Symmetric.
            let sym = segment_distance_mm(&q1, &q0, &p1, &p0);
            assert!((sym - exact).abs() <= 1e-9 * scale);
        }
        // Crossing segments: zero.
        let z = segment_distance_mm(
            &Vector3::new(-1.0, 0.0, 0.0),
            &Vector3::new(1.0, 0.0, 0.0),
            &Vector3::new(0.0, -1.0, 0.0),
            &Vector3::new(0.0, 1.0, 0.0),
        );
        assert!(z.abs() < 1e-15);
        // Closest points at the ends (lines would meet, segments do not).
        let d = segment_distance_mm(
            &Vector3::new(0.0, 0.0, 0.0),
            &Vector3::new(1.0, 0.0, 0.0),
            &Vector3::new(3.0, -1.0, 0.0),
            &Vector3::new(3.0, 1.0, 0.0),
        );
        assert!((d - 2.0).abs() < 1e-12);
    }

    #[test]
    fn cone_angles_zero_at_home_and_follow_a_tilt() {
        let t = JointTable::paper_cubic();
        for (b, p) in cone_angles_deg(&t, &t.home) {
            assert!(b.abs() < 1e-9 && p.abs() < 1e-9);
        }
        // A pure rotation about z at a fixed position: base angles change, and a platform
        // joint sees the link turn by at most the rotation plus the base angle.
        let pose = Pose::from_xyz_rpy_deg([0.0, 0.0, 410.0], [0.0, 0.0, 10.0]);
        let cones = cone_angles_deg(&t, &pose);
        assert!(cones.iter().all(|(b, _)| *b > 0.1));
        let c = Constraints::default();
        assert!(c.check_pose(&t, &t.home).is_ok());
        let tight = Constraints {
            joints: JointLimits {
                base_cone_deg: 0.05,
                platform_cone_deg: 40.0,
            },
            ..Constraints::default()
        };
        assert!(tight
            .check_pose(&t, &pose)
            .unwrap_err()
            .contains("base joint cone"));
    }

    #[test]
    fn validation_names_the_field() {
        let mut c = Constraints::default();
        c.gauge.stroke_mm = 0.0;
        assert!(c.validate().unwrap_err().to_string().contains("stroke_mm"));
        let mut c = Constraints::default();
        c.gauge.longest_mm = 200.0;
        assert!(c.validate().unwrap_err().to_string().contains("longest_mm"));
        let mut c = Constraints::default();
        c.joints.platform_cone_deg = f64::NAN;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("platform_cone_deg"));
        let mut c = Constraints::default();
        c.gauge.bars_mm = vec![-1.0];
        assert!(c.validate().unwrap_err().to_string().contains("bars_mm"));
    }

    #[test]
    fn windows_cover_the_range_within_the_gauge() {
        let g = Gauge::default();
        let w = g.windows(300.0, 650.0, 8);
        assert!(!w.is_empty());
        for (bar, lo, hi) in &w {
            assert!((hi - lo - 200.0).abs() < 1e-9);
            assert!(*lo >= g.shortest_mm - 1e-9 && *hi <= g.longest_mm + 1e-9);
            assert!((lo - g.shortest_mm - bar).abs() < 1e-9);
        }
        assert!(w.first().unwrap().1 <= 300.0 && w.last().unwrap().2 >= 650.0);
        let bars = Gauge {
            bars_mm: vec![0.0, 100.0, 5000.0],
            ..Gauge::default()
        };
        // The 5000 mm bar exceeds the longest length.
        assert_eq!(bars.windows(0.0, 2000.0, 8).len(), 2);
    }
}
