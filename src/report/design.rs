//! The report of `cpm design` (free socket choice): `design.json` and report.md (hence
//! report.html) from one [`DesignReport`].
use serde::Serialize;

use super::format::{fixed, short, sig};
use crate::calib::design::{Criterion, Design};

/// The criterion in words (`A-optimal`), never its Rust name.
pub fn criterion_text(c: Criterion) -> String {
    format!("{}-optimal", c.name())
}

/// A chosen sensor, for the text.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorRow {
    /// Its name.
    pub name: String,
    /// Base socket, mm, base frame.
    pub base_mm: [f64; 3],
    /// Platform socket, mm, platform frame.
    pub platform_mm: [f64; 3],
}

/// `design.json` (the keys cpm has always written) and what report.md adds.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct DesignReport {
    /// The robot description file.
    pub robot: String,
    /// Poses chosen.
    pub poses: usize,
    /// Sensor names.
    pub sensors: Vec<String>,
    /// Readings (poses x sensors).
    pub readings: usize,
    /// Admissible candidates.
    pub candidates: usize,
    /// The criterion's Rust name (`AOptimal`), kept for readers of older files; the text
    /// uses [`criterion_text`].
    pub criterion: String,
    /// Rank of the design.
    pub rank: usize,
    /// Parameters.
    pub parameters: usize,
    /// Sensor noise assumed, um.
    pub sigma_um: f64,
    /// RMS Cramér-Rao bound, um.
    pub crlb_rms_um: f64,
    /// Worst parameter's bound, um.
    pub crlb_max_um: f64,
    /// Worst direction's bound, um.
    pub crlb_worst_direction_um: f64,
    /// Condition number (O2).
    pub condition: f64,
    /// Gauge freedoms the socket layout leaves.
    pub gauge_freedoms_left: Option<usize>,
    /// Gauge length range per sensor, mm.
    pub sensor_lengths_mm: Vec<(f64, f64)>,
    /// How it was chosen.
    pub log: Vec<String>,
    /// The criterion, in words.
    #[serde(skip)]
    pub criterion_text: String,
    /// The sensors' sockets.
    #[serde(skip)]
    pub sensor_rows: Vec<SensorRow>,
}

impl DesignReport {
    /// From a design of the robot in `robot_file`.
    pub fn new(robot_file: &str, d: &Design) -> Self {
        Self {
            robot: robot_file.to_string(),
            poses: d.poses.len(),
            sensors: d.sensors.iter().map(|s| s.name.clone()).collect(),
            readings: d.num_readings(),
            candidates: d.candidates,
            criterion: format!("{:?}", d.criterion),
            rank: d.indices.rank,
            parameters: d.indices.num_params,
            sigma_um: d.indices.sigma_um,
            crlb_rms_um: d.indices.crlb_rms_um,
            crlb_max_um: d.indices.crlb_max_um,
            crlb_worst_direction_um: d.indices.crlb_worst_um,
            condition: d.indices.o2_condition,
            gauge_freedoms_left: d.gauge.last().map(|g| g.socket_freedoms()),
            sensor_lengths_mm: d.sensor_lengths_mm.clone(),
            log: d.log.clone(),
            criterion_text: criterion_text(d.criterion),
            sensor_rows: d
                .sensors
                .iter()
                .map(|s| SensorRow {
                    name: s.name.clone(),
                    base_mm: [s.base_mm.x, s.base_mm.y, s.base_mm.z],
                    platform_mm: [s.platform_mm.x, s.platform_mm.y, s.platform_mm.z],
                })
                .collect(),
        }
    }

    /// `design.json`, pretty-printed (keys sorted).
    pub fn to_json(&self) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&serde_json::to_value(self)?)
    }

    /// report.md.
    pub fn markdown(&self) -> String {
        let mut r = String::from("# Calibration design\n\n");
        r.push_str(&format!(
            "- Robot: `{}`; {} poses x {} socket pairs = {} readings ({} criterion, {} admissible candidates).\n- Rank {} of {}; Cramér-Rao bounds for {} um of sensor noise: RMS {} um, worst parameter {} um, worst direction {} um.\n",
            self.robot, self.poses, self.sensors.len(), self.readings, self.criterion_text, self.candidates,
            self.rank, self.parameters, short(self.sigma_um), sig(self.crlb_rms_um, 3), sig(self.crlb_max_um, 3), sig(self.crlb_worst_direction_um, 3)
        ));
        if let Some(g) = self.gauge_freedoms_left {
            r.push_str(&format!(
                "- Gauge freedoms left by the socket layout: {g}.\n"
            ));
        }
        r.push_str("\n## Sensors (gauge travel over the poses)\n\n| sensor | base socket (mm, {B}) | platform socket (mm, {P}) | length range (mm) |\n|---|---|---|---|\n");
        let xyz = |v: &[f64; 3]| {
            format!(
                "({}, {}, {})",
                fixed(v[0], 1),
                fixed(v[1], 1),
                fixed(v[2], 1)
            )
        };
        for (s, (lo, hi)) in self.sensor_rows.iter().zip(&self.sensor_lengths_mm) {
            r.push_str(&format!(
                "| {} | {} | {} | {} .. {} |\n",
                s.name,
                xyz(&s.base_mm),
                xyz(&s.platform_mm),
                fixed(*lo, 1),
                fixed(*hi, 1)
            ));
        }
        r.push_str("\n## How it was chosen\n\n");
        for l in &self.log {
            r.push_str(&format!("- {l}\n"));
        }
        r.push_str("\n## Files\n\n- `poses.csv`: the poses to drive (`--plan` of `cpm simulate` / `cpm identifiability`).\n- `sockets.csv`: the chosen socket pairs.\n- `robot.toml`: the robot description with these sensors: measure with it, then `cpm calibrate --robot robot.toml`.\n");
        r
    }
}
