//! Instruments and limits of a description: `[[gauge]]` (length gauges), `[[socket]]` and
//! `[[socket_region]]` (where gauge sockets can go) and `[limits]` (gauge-link clearance,
//! link radii, joint cone angles).
//!
//! These tables tell an experiment design what a technician can mount and what the machine
//! allows; `docs/robot-description.md` states every default. A `[[sensor]]` may name the
//! gauge it is read with (`gauge`) and the extension bar of its setup (`bar_mm`); readings
//! outside that setup's window are then refused by `cpm calibrate`.
//!
//! ```
//! use cpm_geometry::description::RobotDescription;
//! let mut text = RobotDescription::paper_cubic().to_toml_string().unwrap();
//! text.push_str("\n[[gauge]]\nname = \"lg\"\nstroke_mm = 200.0\n\n[limits]\nbase_cone_deg = 35.0\n");
//! let d = RobotDescription::from_toml_str(&text, "<doc>").unwrap();
//! let g = &d.gauges[0];
//! assert_eq!(g.shortest_length_mm(), 150.0); // the stated default of a telescoping gauge
//! assert_eq!(d.limits.unwrap().platform_cone_deg, 40.0); // default
//! // A stroke longer than the gauge's range is refused, naming the key and its line.
//! let bad = text.replace("stroke_mm = 200.0", "stroke_mm = 2000.0");
//! let e = RobotDescription::from_toml_str(&bad, "r.toml").unwrap_err().to_string();
//! assert!(e.contains("gauge[1].longest_mm") && e.contains("line"), "{e}");
//! ```
use std::collections::HashSet;

use serde::{Deserialize, Serialize};

use super::{exact, position3, Problem, RobotDescription, Seg};

/// Default gauge-link clearance when the description declares no link radius, mm.
pub const DEFAULT_GAUGE_LINK_CLEARANCE_MM: f64 = 30.0;
/// Default largest joint cone angle (base and platform joints), deg.
pub const DEFAULT_CONE_DEG: f64 = 40.0;
/// Default shortest length of a telescoping gauge, mm.
pub const DEFAULT_TELESCOPING_SHORTEST_MM: f64 = 150.0;
/// Default shortest length of a ballbar, mm.
pub const DEFAULT_BALLBAR_SHORTEST_MM: f64 = 100.0;
/// Default longest length of a gauge with any bar, mm.
pub const DEFAULT_LONGEST_MM: f64 = 1000.0;
/// Default grid of a `[[socket_region]]`: points per axis.
pub const DEFAULT_REGION_GRID: [usize; 3] = [3, 3, 3];
/// The most candidate sockets the `[[socket]]` and `[[socket_region]]` tables may give.
pub const MAX_DESCRIBED_SOCKETS: usize = 10_000;

/// The kind of a length gauge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GaugeKindSpec {
    /// A telescoping length gauge (stroke of tens to a couple of hundred mm). The default.
    #[default]
    Telescoping,
    /// A ballbar (stroke about 2 mm, longer with extension bars between setups).
    Ballbar,
}

impl GaugeKindSpec {
    /// `telescoping` or `ballbar`.
    pub fn name(&self) -> &'static str {
        match self {
            GaugeKindSpec::Telescoping => "telescoping",
            GaugeKindSpec::Ballbar => "ballbar",
        }
    }
}

/// `[[gauge]]`: a length gauge available for the campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaugeSpec {
    /// Name, unique among the gauges; a `[[sensor]]` names it in `gauge`.
    pub name: String,
    /// `telescoping` (default) or `ballbar`.
    #[serde(default)]
    pub kind: GaugeKindSpec,
    /// Travel within one setup (one socket pair, one bar), mm. Required.
    pub stroke_mm: f64,
    /// Shortest socket-to-socket length without a bar, mm. Default 150 (telescoping) or
    /// 100 (ballbar).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shortest_mm: Option<f64>,
    /// Longest socket-to-socket length with any bar, mm. Default 1000.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub longest_mm: Option<f64>,
    /// Extension bars available, mm (a setup uses one; its window starts at
    /// `shortest + bar`). Default: none listed, any bar length.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bars_mm: Vec<f64>,
    /// Noise of one reading (standard deviation), um. Default: `[calibration]`
    /// `sensor_noise_um`, else the paper's uniform +-10 um (10 / sqrt(3) = 5.77 um).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_um: Option<f64>,
    /// Radius of the gauge body around its axis, mm (adds to the link radius in the
    /// gauge-link clearance). Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_mm: Option<f64>,
}

impl GaugeSpec {
    /// Shortest length, mm, with the kind's default.
    pub fn shortest_length_mm(&self) -> f64 {
        self.shortest_mm.unwrap_or(match self.kind {
            GaugeKindSpec::Telescoping => DEFAULT_TELESCOPING_SHORTEST_MM,
            GaugeKindSpec::Ballbar => DEFAULT_BALLBAR_SHORTEST_MM,
        })
    }

    /// Longest length, mm, with its default.
    pub fn longest_length_mm(&self) -> f64 {
        self.longest_mm.unwrap_or(DEFAULT_LONGEST_MM)
    }

    /// The window of a setup with `bar_mm`: `[shortest + bar, shortest + bar + stroke]`, mm.
    pub fn window_mm(&self, bar_mm: f64) -> (f64, f64) {
        let lo = self.shortest_length_mm() + bar_mm;
        (lo, lo + self.stroke_mm)
    }
}

/// Which body a socket is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SocketSide {
    /// On the base, position in {B}.
    Base,
    /// On the platform, position in {P}.
    Platform,
}

/// `[[socket]]`: one candidate socket place.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SocketSpec {
    /// Name, unique on its side.
    pub name: String,
    /// `base` or `platform`.
    pub side: SocketSide,
    /// Position, mm, in {B} (base) or {P} (platform).
    #[serde(deserialize_with = "exact")]
    pub position_mm: [f64; 3],
}

/// `[[socket_region]]`: a box of candidate socket places, sampled on a grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SocketRegionSpec {
    /// Name; its places are named `NAME_1`, `NAME_2`, ...
    pub name: String,
    /// `base` or `platform`.
    pub side: SocketSide,
    /// Lowest corner, mm.
    #[serde(deserialize_with = "exact")]
    pub min_mm: [f64; 3],
    /// Highest corner, mm.
    #[serde(deserialize_with = "exact")]
    pub max_mm: [f64; 3],
    /// Points per axis (an axis of zero extent gets one). Default `[3, 3, 3]`.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "grid_opt"
    )]
    pub grid: Option<[usize; 3]>,
}

fn grid_opt<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<[usize; 3]>, D::Error> {
    Option::<Vec<usize>>::deserialize(d)?
        .map(|v| {
            <[usize; 3]>::try_from(v.as_slice()).map_err(|_| {
                serde::de::Error::custom(format!(
                    "expected 3 numbers, got {} (extra or missing values are not ignored)",
                    v.len()
                ))
            })
        })
        .transpose()
}

impl SocketRegionSpec {
    /// The grid points, in x-fastest order.
    pub fn points(&self) -> Vec<[f64; 3]> {
        let g = self.grid.unwrap_or(DEFAULT_REGION_GRID);
        let n: [usize; 3] = std::array::from_fn(|a| {
            if self.max_mm[a] > self.min_mm[a] {
                g[a]
            } else {
                1
            }
        });
        let at = |a: usize, i: usize| {
            if n[a] <= 1 {
                0.5 * (self.min_mm[a] + self.max_mm[a])
            } else {
                self.min_mm[a] + (self.max_mm[a] - self.min_mm[a]) * i as f64 / (n[a] - 1) as f64
            }
        };
        let mut out = Vec::with_capacity(n[0] * n[1] * n[2]);
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    out.push([at(0, i), at(1, j), at(2, k)]);
                }
            }
        }
        out
    }
}

/// `[limits]`: what the machine allows a design.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitsSpec {
    /// Largest angle of each link from its home direction at its base joint (in {B}), deg.
    /// Default 40.
    #[serde(default = "default_cone")]
    pub base_cone_deg: f64,
    /// Largest angle of each link from its home direction at its platform joint (in {P}),
    /// deg. Default 40.
    #[serde(default = "default_cone")]
    pub platform_cone_deg: f64,
    /// Radius of every link body around its axis, mm. Optional; when given, links must stay
    /// twice this apart (axis to axis) and the default gauge-link clearance is this plus the
    /// gauge's `radius_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_radius_mm: Option<f64>,
    /// Smallest distance between the gauge axis and any link axis, mm. Default
    /// `link_radius_mm + gauge radius_mm` when the link radius is given, else 30.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gauge_link_clearance_mm: Option<f64>,
}

fn default_cone() -> f64 {
    DEFAULT_CONE_DEG
}

impl Default for LimitsSpec {
    fn default() -> Self {
        Self {
            base_cone_deg: DEFAULT_CONE_DEG,
            platform_cone_deg: DEFAULT_CONE_DEG,
            link_radius_mm: None,
            gauge_link_clearance_mm: None,
        }
    }
}

impl LimitsSpec {
    /// The gauge-link clearance for `gauge` (see the field's doc for the defaults), mm.
    pub fn gauge_link_mm(&self, gauge: Option<&GaugeSpec>) -> f64 {
        match (self.gauge_link_clearance_mm, self.link_radius_mm) {
            (Some(c), _) => c,
            (None, Some(r)) => r + gauge.and_then(|g| g.radius_mm).unwrap_or(0.0),
            (None, None) => DEFAULT_GAUGE_LINK_CLEARANCE_MM,
        }
    }

    /// The smallest distance between two link axes, mm: twice the link radius, when given.
    pub fn link_link_mm(&self) -> Option<f64> {
        self.link_radius_mm.map(|r| 2.0 * r)
    }
}

impl RobotDescription {
    /// The gauge named `name`, or the first `[[gauge]]` when `name` is `None`.
    pub fn gauge(&self, name: Option<&str>) -> Option<&GaugeSpec> {
        match name {
            Some(n) => self.gauges.iter().find(|g| g.name == n),
            None => self.gauges.first(),
        }
    }

    /// The candidate socket places of `[[socket]]` and `[[socket_region]]`, as
    /// `(name, side, position_mm)`; regions are expanded onto their grids.
    pub fn socket_places(&self) -> Vec<(String, SocketSide, [f64; 3])> {
        let mut out: Vec<_> = self
            .sockets
            .iter()
            .map(|s| (s.name.clone(), s.side, s.position_mm))
            .collect();
        for r in &self.socket_regions {
            for (i, p) in r.points().into_iter().enumerate() {
                out.push((format!("{}_{}", r.name, i + 1), r.side, p));
            }
        }
        out
    }

    /// Checks `[[gauge]]`, `[[socket]]`, `[[socket_region]]`, `[limits]` and the sensors'
    /// `gauge` and `bar_mm` keys.
    pub(super) fn check_instruments(&self) -> Result<(), Problem> {
        use Seg::{Index, Key};
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let mut names = HashSet::new();
        for (i, g) in self.gauges.iter().enumerate() {
            let at = |k: &'static str| [Key("gauge"), Index(i), Key(k)];
            plain_name(&g.name, &at("name"))?;
            if !names.insert(g.name.as_str()) {
                return Err(Problem::new(
                    &at("name"),
                    format!("duplicate gauge name `{}`", g.name),
                ));
            }
            if !pos(g.stroke_mm) {
                return Err(Problem::new(
                    &at("stroke_mm"),
                    format!("must be finite and > 0, got {}", g.stroke_mm),
                ));
            }
            if let Some(v) = g.shortest_mm {
                if !pos(v) {
                    return Err(Problem::new(
                        &at("shortest_mm"),
                        format!("must be finite and > 0, got {v}"),
                    ));
                }
            }
            let (lo, hi) = (g.shortest_length_mm(), g.longest_length_mm());
            if !(hi.is_finite() && hi >= lo + g.stroke_mm) {
                return Err(Problem::new(
                    &at("longest_mm"),
                    format!(
                        "{hi} mm is shorter than the shortest length plus the stroke ({lo} + {} = {} mm)",
                        g.stroke_mm,
                        lo + g.stroke_mm
                    ),
                ));
            }
            for (k, b) in g.bars_mm.iter().enumerate() {
                if !(b.is_finite() && *b >= 0.0) {
                    return Err(Problem::new(
                        &[Key("gauge"), Index(i), Key("bars_mm"), Index(k)],
                        format!("must be finite and >= 0 mm, got {b}"),
                    ));
                }
                if lo + b + g.stroke_mm > hi + 1e-9 {
                    return Err(Problem::new(
                        &[Key("gauge"), Index(i), Key("bars_mm"), Index(k)],
                        format!(
                            "a {b} mm bar puts the window's end at {} mm, beyond longest_mm = {hi} mm",
                            lo + b + g.stroke_mm
                        ),
                    ));
                }
            }
            if let Some(v) = g.noise_um {
                if !pos(v) {
                    return Err(Problem::new(
                        &at("noise_um"),
                        format!("must be finite and > 0, got {v}"),
                    ));
                }
            }
            if let Some(v) = g.radius_mm {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(Problem::new(
                        &at("radius_mm"),
                        format!("must be finite and >= 0, got {v}"),
                    ));
                }
            }
        }
        for (i, s) in self.sensors.iter().enumerate() {
            let at = |k: &'static str| [Key("sensor"), Index(i), Key(k)];
            match (&s.gauge, s.bar_mm) {
                (None, Some(_)) => {
                    return Err(Problem::new(
                        &at("bar_mm"),
                        "needs `gauge` (the bar extends a gauge)",
                    ))
                }
                (Some(name), bar) => {
                    let Some(g) = self.gauge(Some(name)) else {
                        return Err(Problem::new(
                            &at("gauge"),
                            format!(
                                "unknown gauge `{name}` (the [[gauge]] tables have: {})",
                                if self.gauges.is_empty() {
                                    "none".to_string()
                                } else {
                                    self.gauges
                                        .iter()
                                        .map(|g| g.name.as_str())
                                        .collect::<Vec<_>>()
                                        .join(", ")
                                }
                            ),
                        ));
                    };
                    if let Some(b) = bar {
                        if !(b.is_finite() && b >= 0.0) {
                            return Err(Problem::new(
                                &at("bar_mm"),
                                format!("must be finite and >= 0, got {b}"),
                            ));
                        }
                        let (_, hi) = g.window_mm(b);
                        if hi > g.longest_length_mm() + 1e-9 {
                            return Err(Problem::new(
                                &at("bar_mm"),
                                format!(
                                    "the window ends at {hi} mm, beyond the gauge's longest_mm = {} mm",
                                    g.longest_length_mm()
                                ),
                            ));
                        }
                        if !g.bars_mm.is_empty() && !g.bars_mm.iter().any(|x| (x - b).abs() <= 1e-6)
                        {
                            return Err(Problem::new(
                                &at("bar_mm"),
                                format!(
                                    "{b} mm is not one of gauge `{}`'s bars_mm {:?}",
                                    g.name, g.bars_mm
                                ),
                            ));
                        }
                    }
                }
                (None, None) => {}
            }
        }
        let mut seen = HashSet::new();
        for (i, s) in self.sockets.iter().enumerate() {
            let at = |k: &'static str| [Key("socket"), Index(i), Key(k)];
            plain_name(&s.name, &at("name"))?;
            if !seen.insert((s.name.as_str(), s.side)) {
                return Err(Problem::new(
                    &at("name"),
                    format!(
                        "duplicate {} socket name `{}` (names are unique on each side)",
                        side_name(s.side),
                        s.name
                    ),
                ));
            }
            position3(&s.position_mm, &at("position_mm"))?;
        }
        let mut total = self.sockets.len();
        for (i, r) in self.socket_regions.iter().enumerate() {
            let at = |k: &'static str| [Key("socket_region"), Index(i), Key(k)];
            plain_name(&r.name, &at("name"))?;
            position3(&r.min_mm, &at("min_mm"))?;
            position3(&r.max_mm, &at("max_mm"))?;
            if let Some(a) = (0..3).find(|a| r.max_mm[*a] < r.min_mm[*a]) {
                return Err(Problem::new(
                    &at("max_mm"),
                    format!(
                        "its {} component {} is below min_mm's {}",
                        ["x (1st)", "y (2nd)", "z (3rd)"][a],
                        r.max_mm[a],
                        r.min_mm[a]
                    ),
                ));
            }
            if let Some(g) = r.grid {
                if g.iter().any(|n| *n == 0 || *n > 100) {
                    return Err(Problem::new(
                        &at("grid"),
                        format!("points per axis must be 1 to 100, got {g:?}"),
                    ));
                }
            }
            total += r.points().len();
            if total > MAX_DESCRIBED_SOCKETS {
                return Err(Problem::new(
                    &at("grid"),
                    format!(
                        "more than {MAX_DESCRIBED_SOCKETS} candidate sockets in all: use a coarser grid"
                    ),
                ));
            }
        }
        if let Some(l) = &self.limits {
            let at = |k: &'static str| [Key("limits"), Key(k)];
            for (k, v) in [
                ("base_cone_deg", l.base_cone_deg),
                ("platform_cone_deg", l.platform_cone_deg),
            ] {
                if !(v.is_finite() && v > 0.0 && v <= 180.0) {
                    return Err(Problem::new(
                        &at(k),
                        format!("must be in (0, 180] deg, got {v}"),
                    ));
                }
            }
            for (k, v) in [
                ("link_radius_mm", l.link_radius_mm),
                ("gauge_link_clearance_mm", l.gauge_link_clearance_mm),
            ] {
                if let Some(v) = v {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(Problem::new(
                            &at(k),
                            format!("must be finite and >= 0, got {v}"),
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

fn side_name(s: SocketSide) -> &'static str {
    match s {
        SocketSide::Base => "base",
        SocketSide::Platform => "platform",
    }
}

/// A name that can be a CSV value: not empty, no spaces at its ends, no comma, quote or
/// control character, not starting with '#'.
fn plain_name(name: &str, path: &[Seg]) -> Result<(), Problem> {
    super::plain_name_of(name, None, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(extra: &str) -> Result<RobotDescription, String> {
        let mut text = RobotDescription::paper_cubic().to_toml_string().unwrap();
        text.push('\n');
        text.push_str(extra);
        RobotDescription::from_toml_str(&text, "t.toml").map_err(|e| e.to_string())
    }

    #[test]
    fn instruments_round_trip_through_toml() {
        let mut d = RobotDescription::paper_cubic();
        d.gauges.push(GaugeSpec {
            name: "lg".into(),
            kind: GaugeKindSpec::Ballbar,
            stroke_mm: 2.0,
            shortest_mm: Some(100.0),
            longest_mm: Some(900.0),
            bars_mm: vec![0.0, 150.0, 300.0],
            noise_um: Some(1.5),
            radius_mm: Some(10.0),
        });
        d.sensors[0].gauge = Some("lg".into());
        d.sensors[0].bar_mm = Some(150.0);
        d.sockets.push(SocketSpec {
            name: "b1".into(),
            side: SocketSide::Base,
            position_mm: [1.0, 2.0, 3.0],
        });
        d.socket_regions.push(SocketRegionSpec {
            name: "top".into(),
            side: SocketSide::Platform,
            min_mm: [-100.0, -100.0, 0.0],
            max_mm: [100.0, 100.0, 0.0],
            grid: Some([2, 3, 4]),
        });
        d.limits = Some(LimitsSpec {
            link_radius_mm: Some(20.0),
            ..LimitsSpec::default()
        });
        let text = d.to_toml_string().unwrap();
        let back = RobotDescription::from_toml_str(&text, "x").unwrap();
        assert_eq!(back, d);
        // 1 place + a flat 2 x 3 grid (z has no extent: one layer).
        assert_eq!(back.socket_places().len(), 1 + 6);
        let l = back.limits.unwrap();
        assert_eq!(l.gauge_link_mm(back.gauge(None)), 30.0);
        assert_eq!(l.link_link_mm(), Some(40.0));
        assert_eq!(back.gauges[0].window_mm(150.0), (250.0, 252.0));
    }

    #[test]
    fn bad_instrument_values_name_the_key_and_line() {
        let g = "[[gauge]]\nname = \"g\"\nstroke_mm = 200.0\n";
        assert!(with(g).is_ok());
        for (extra, key) in [
            ("[[gauge]]\nname = \"g\"\nstroke_mm = -1.0\n", "gauge[1].stroke_mm"),
            (
                "[[gauge]]\nname = \"g\"\nstroke_mm = 200.0\nbars_mm = [0.0, 900.0]\n",
                "gauge[1].bars_mm[2]",
            ),
            (
                "[[gauge]]\nname = \"g\"\nstroke_mm = 2.0\n[[gauge]]\nname = \"g\"\nstroke_mm = 2.0\n",
                "gauge[2].name",
            ),
            ("[limits]\nbase_cone_deg = 0.0\n", "limits.base_cone_deg"),
            ("[limits]\nlink_radius_mm = -3.0\n", "limits.link_radius_mm"),
            (
                "[[socket_region]]\nname = \"r\"\nside = \"base\"\nmin_mm = [0.0, 0.0, 0.0]\nmax_mm = [1.0, -1.0, 0.0]\n",
                "socket_region[1].max_mm",
            ),
            (
                "[[socket]]\nname = \"a\"\nside = \"base\"\nposition_mm = [0.0, 0.0, 0.0]\n[[socket]]\nname = \"a\"\nside = \"base\"\nposition_mm = [1.0, 0.0, 0.0]\n",
                "socket[2].name",
            ),
        ] {
            let e = with(extra).unwrap_err();
            assert!(e.contains(key) && e.contains("line"), "{key}: {e}");
        }
        // A sensor naming an unknown gauge.
        let mut d = RobotDescription::paper_cubic();
        d.sensors[0].gauge = Some("nope".into());
        let e = d.validate().unwrap_err().to_string();
        assert!(
            e.contains("sensor[1].gauge") && e.contains("unknown gauge"),
            "{e}"
        );
    }
}
