//! The report of `cpm design` (free socket choice): `design.json` and report.md (hence
//! report.html) from one [`DesignReport`].
use serde::Serialize;

use super::format::{fixed, short, sig};
use cpm_calib::design::{Criterion, Design};

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
    /// The limits honoured (joint cones, clearances), `null` when none were given.
    pub limits: Option<cpm_calib::design::DesignLimits>,
    /// Largest base joint cone angle over the poses, deg.
    pub max_base_cone_deg: f64,
    /// Largest platform joint cone angle over the poses, deg.
    pub max_platform_cone_deg: f64,
    /// Smallest distance between a sensor axis and a link axis over the poses, mm.
    pub min_clearance_mm: f64,
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
            limits: d.limits,
            max_base_cone_deg: d.max_cone_deg.0,
            max_platform_cone_deg: d.max_cone_deg.1,
            min_clearance_mm: d.min_clearance_mm,
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
        let reached = format!(
            "largest joint cones {} deg (base) and {} deg (platform), smallest sensor-link clearance {} mm",
            fixed(self.max_base_cone_deg, 1),
            fixed(self.max_platform_cone_deg, 1),
            fixed(self.min_clearance_mm, 1)
        );
        match &self.limits {
            Some(l) => r.push_str(&format!(
                "- Limits honoured: joint cones at most {} deg (base) and {} deg (platform), sensor axes at least {} mm from the link axes{}; {reached}.\n",
                short(l.joints.base_cone_deg),
                short(l.joints.platform_cone_deg),
                short(l.clearance.gauge_link_mm),
                l.clearance
                    .link_link_mm
                    .map_or(String::new(), |d| format!(", link axes at least {} mm apart", short(d)))
            )),
            None => r.push_str(&format!(
                "- No joint or clearance limits given (`--cone-deg`, `--clearance-mm`, `[limits]`): {reached}.\n"
            )),
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

/// One setup of a design under an instrument's limits.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SetupRow {
    /// The sensor (setup) name.
    pub sensor: String,
    /// Its base socket.
    pub base_socket: String,
    /// Its platform socket.
    pub platform_socket: String,
    /// Bar length (ball bar), mm.
    pub bar_mm: f64,
    /// Measuring window, mm.
    pub window_mm: [f64; 2],
    /// Poses driven in it.
    pub poses: usize,
    /// Gauge travel over them, mm.
    pub travel_mm: f64,
    /// Smallest gauge-link clearance, mm.
    pub min_clearance_mm: f64,
    /// Its plan file.
    pub plan: String,
}

/// The instrument's limits as given.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LimitsRow {
    /// Gauge kind.
    pub gauge: String,
    /// The gauge's name in the written description.
    pub gauge_name: String,
    /// Stroke, mm.
    pub stroke_mm: f64,
    /// Shortest gauge, mm.
    pub shortest_mm: f64,
    /// Longest gauge, mm.
    pub longest_mm: f64,
    /// Bar lengths, mm.
    pub bars_mm: Vec<f64>,
    /// Least gauge-link clearance, mm.
    pub clearance_mm: f64,
    /// Largest joint cone angle (the base joints'; kept for older readers), deg.
    pub cone_deg: f64,
    /// Largest base joint cone angle, deg.
    pub base_cone_deg: f64,
    /// Largest platform joint cone angle, deg.
    pub platform_cone_deg: f64,
    /// Least link-link clearance (when link radii are declared), mm.
    pub link_link_clearance_mm: Option<f64>,
}

/// `design.json` of `cpm design --stroke-mm` (the keys cpm has always written) and its
/// report.md.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LimitedDesignReport {
    /// The robot description file.
    pub robot: String,
    /// Always true: a design under limits.
    pub limited: bool,
    /// The setups.
    pub setups: Vec<SetupRow>,
    /// Readings.
    pub readings: usize,
    /// Candidate poses within the joint limits.
    pub candidate_poses: usize,
    /// Candidate readings.
    pub candidate_readings: usize,
    /// The criterion's Rust name (`AOptimal`), kept for readers of older files.
    pub criterion: String,
    /// Rank.
    pub rank: usize,
    /// Parameters.
    pub parameters: usize,
    /// Sensor noise assumed, um.
    pub sigma_um: f64,
    /// RMS Cramér-Rao bound, um.
    pub crlb_rms_um: f64,
    /// Worst parameter's bound, um.
    pub crlb_max_um: f64,
    /// Largest gauge travel in a setup, mm.
    pub max_travel_mm: f64,
    /// Smallest gauge-link clearance, mm.
    pub min_clearance_mm: f64,
    /// Largest base cone angle, deg.
    pub max_base_cone_deg: f64,
    /// Largest platform cone angle, deg.
    pub max_platform_cone_deg: f64,
    /// Socket moves between setups.
    pub socket_moves: usize,
    /// Bar changes between setups.
    pub bar_changes: usize,
    /// The limits.
    pub constraints: LimitsRow,
    /// How it was chosen.
    pub log: Vec<String>,
    /// The criterion, in words.
    #[serde(skip)]
    pub criterion_text: String,
}

impl LimitedDesignReport {
    /// From a design under `constraints` of the robot `robot`, with the gauge named
    /// `gauge_name`.
    pub fn new(
        robot: &cpm_io::Robot,
        d: &cpm_calib::design::SetupDesign,
        constraints: &cpm_calib::design::Constraints,
        gauge_name: &str,
    ) -> Self {
        let (max_base, max_platform) = d.max_cone_deg(&robot.table);
        let (moves, bars) = d.remounts();
        Self {
            robot: robot.file.clone(),
            limited: true,
            setups: d
                .setups
                .iter()
                .map(|s| SetupRow {
                    sensor: s.name.clone(),
                    base_socket: s.base.name.clone(),
                    platform_socket: s.platform.name.clone(),
                    bar_mm: s.bar_mm,
                    window_mm: [s.window_mm.0, s.window_mm.1],
                    poses: s.poses.len(),
                    travel_mm: s.travel_mm(),
                    min_clearance_mm: s.min_clearance_mm(),
                    plan: format!("plans/{}.csv", s.name),
                })
                .collect(),
            readings: d.num_readings(),
            candidate_poses: d.candidate_poses,
            candidate_readings: d.candidate_readings,
            criterion: format!("{:?}", d.criterion),
            rank: d.indices.rank,
            parameters: d.indices.num_params,
            sigma_um: d.indices.sigma_um,
            crlb_rms_um: d.indices.crlb_rms_um,
            crlb_max_um: d.indices.crlb_max_um,
            max_travel_mm: d.max_travel_mm(),
            min_clearance_mm: d.min_clearance_mm(),
            max_base_cone_deg: max_base,
            max_platform_cone_deg: max_platform,
            socket_moves: moves,
            bar_changes: bars,
            constraints: LimitsRow {
                gauge: constraints.gauge.kind.name().to_string(),
                gauge_name: gauge_name.to_string(),
                stroke_mm: constraints.gauge.stroke_mm,
                shortest_mm: constraints.gauge.shortest_mm,
                longest_mm: constraints.gauge.longest_mm,
                bars_mm: constraints.gauge.bars_mm.clone(),
                clearance_mm: constraints.clearance.gauge_link_mm,
                cone_deg: constraints.joints.base_cone_deg,
                base_cone_deg: constraints.joints.base_cone_deg,
                platform_cone_deg: constraints.joints.platform_cone_deg,
                link_link_clearance_mm: constraints.clearance.link_link_mm,
            },
            log: d.log.clone(),
            criterion_text: criterion_text(d.criterion),
        }
    }

    /// `design.json`, pretty-printed (keys sorted).
    pub fn to_json(&self) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&serde_json::to_value(self)?)
    }

    /// report.md.
    pub fn markdown(&self) -> String {
        let c = &self.constraints;
        let mut r = String::from("# Calibration design under an instrument's limits\n\n");
        r.push_str(&format!(
            "- Robot: `{}`; {} setups, {} readings ({} criterion; {} candidate poses within the joint limits, {} candidate readings).\n- Rank {} of {}; Cramér-Rao bounds for {} um of sensor noise: RMS {} um, worst parameter {} um.\n- Largest gauge travel in a setup {} mm (stroke {} mm); smallest gauge-link clearance {} mm (at least {} mm); largest cone angle {} deg (base), {} deg (platform), at most {} deg.\n\n",
            self.robot, self.setups.len(), self.readings, self.criterion_text, self.candidate_poses, self.candidate_readings,
            self.rank, self.parameters, short(self.sigma_um), sig(self.crlb_rms_um, 3), sig(self.crlb_max_um, 3),
            fixed(self.max_travel_mm, 1), short(c.stroke_mm), fixed(self.min_clearance_mm, 1), short(c.clearance_mm),
            fixed(self.max_base_cone_deg, 1), fixed(self.max_platform_cone_deg, 1), short(c.base_cone_deg.max(c.platform_cone_deg))
        ));
        r.push_str("## How it was chosen\n\n");
        for l in &self.log {
            r.push_str(&format!("- {l}\n"));
        }
        r.push_str("\n## Files\n\n- `setup_sheet.md`, `setup_sheet.csv`: what to mount, then which poses to drive, setup by setup.\n- `plans/<setup>.csv`: each setup's poses (`cpm simulate --plan plans/<setup>.csv --sensors <setup>`).\n- `robot.toml`: the robot description with one sensor per setup: measure each setup into its own readings file, then `cpm calibrate --robot robot.toml --data s01.csv --data s02.csv ...`.\n");
        r
    }
}
