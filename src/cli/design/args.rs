//! The arguments of `cpm design` and the workflow's options they make
//! ([`cpm_workflow::design::DesignJobOptions`]).
use std::path::PathBuf;

use clap::{Args, ValueEnum};

use crate::calib::design::{Criterion, GaugeKind};
use crate::cli::common::RobotArg;
use cpm_workflow::design::DesignJobOptions;

/// Optimality criterion of the pose selection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CriterionArg {
    /// A-optimal: smallest sum of Cramér-Rao variances (RMS bound).
    A,
    /// D-optimal: largest determinant of the information matrix.
    D,
    /// E-optimal: best worst direction (slow).
    E,
}

impl CriterionArg {
    /// The criterion of cpm-calib's selection.
    pub fn criterion(self) -> Criterion {
        match self {
            CriterionArg::A => Criterion::AOptimal,
            CriterionArg::D => Criterion::DOptimal,
            CriterionArg::E => Criterion::EOptimal,
        }
    }
}

/// Kind of gauge of a design under limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum GaugeArg {
    /// Telescoping length gauge.
    Telescoping,
    /// Ballbar.
    Ballbar,
}

/// Arguments of `cpm design`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm design --robot examples/hexapod_66.toml --base-sockets 3 --platform-sockets 3 --readings 360 --out design/\n  cpm design --robot examples/hexapod_66.toml --sockets design/sockets.csv --readings 600 --criterion d --out design_d/"
)]
pub struct DesignArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Candidate socket places, CSV `name,side,x_mm,y_mm,z_mm` (side `base` in {B} or
    /// `platform` in {P}), or socket pairs as `cpm design` writes them in `sockets.csv`;
    /// default: the description's `[[socket]]` and `[[socket_region]]` places, else the
    /// sockets of its `[[sensor]]` tables.
    #[arg(long, value_name = "SOCKETS.csv")]
    pub sockets: Option<PathBuf>,
    /// Reading budget (poses x socket pairs).
    #[arg(long, value_name = "N", default_value_t = 2000)]
    pub readings: usize,
    /// Base sockets to use (each paired with every platform socket).
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub base_sockets: usize,
    /// Platform sockets to use.
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub platform_sockets: usize,
    /// Poses to drive (default: as many as the budget allows).
    #[arg(long, value_name = "N")]
    pub poses: Option<usize>,
    /// Random candidate poses (plus circles) to choose from.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub candidates: usize,
    /// Half range of candidate positions about home, mm.
    #[arg(long, value_name = "MM", default_value_t = 50.0)]
    pub range_mm: f64,
    /// Half range of candidate roll, pitch, yaw about home, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 10.0)]
    pub range_deg: f64,
    /// Selection criterion.
    #[arg(long, value_enum, default_value_t = CriterionArg::A)]
    pub criterion: CriterionArg,
    /// Sensor noise for the reported bounds, um (default: the description's, else 1).
    #[arg(long, value_name = "UM")]
    pub sigma_um: Option<f64>,
    /// Random seed of the candidates.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// Design under an instrument's limits: the gauge's stroke per setup, mm. Turns the
    /// setup design on (one socket pair with one bar per setup; readings only within the
    /// stroke, the clearance and the joint cones); writes setup_sheet.md/.csv and plans/.
    /// The setup design is also on when the description declares a `[[gauge]]`: its
    /// `[[gauge]]` and `[limits]` give the limits, and the flags below override them.
    #[arg(long, value_name = "MM")]
    pub stroke_mm: Option<f64>,
    /// The description's `[[gauge]]` to design for (default: its first).
    #[arg(long, value_name = "NAME")]
    pub gauge_name: Option<String>,
    /// Kind of gauge (default: the description's gauge, else telescoping).
    #[arg(long, value_enum)]
    pub gauge: Option<GaugeArg>,
    /// Shortest socket-to-socket length the gauge reads, mm (default: the description's
    /// gauge, else 150; 100 for a ballbar).
    #[arg(long, value_name = "MM")]
    pub shortest_mm: Option<f64>,
    /// Longest socket-to-socket length the gauge reads with any bar, mm (default: the
    /// description's gauge, else 1000).
    #[arg(long, value_name = "MM")]
    pub longest_mm: Option<f64>,
    /// Extension bars available, mm, comma-separated (default: the description's gauge's
    /// `bars_mm`, else any length).
    #[arg(long, value_name = "MM,..", value_delimiter = ',')]
    pub bars_mm: Vec<f64>,
    /// Smallest distance between the gauge axis and any link axis, mm (default: the
    /// description's `[limits]`, else 30). Without a gauge, the limits apply when this,
    /// --cone-deg or the description's `[limits]` is given.
    #[arg(long, value_name = "MM")]
    pub clearance_mm: Option<f64>,
    /// Largest cone angle of every base and platform joint from home, deg (default: the
    /// description's `[limits]`, else 40). Without a gauge, the limits apply when this,
    /// --clearance-mm or the description's `[limits]` is given.
    #[arg(long, value_name = "DEG")]
    pub cone_deg: Option<f64>,
    /// Most setups (gauge mounts) (with --stroke-mm).
    #[arg(long, value_name = "N", default_value_t = 16)]
    pub setups: usize,
    /// Output directory: poses.csv, sockets.csv, robot.toml, design.json, report.md (with
    /// --stroke-mm: robot.toml, setup_sheet.md, setup_sheet.csv, plans/SETUP.csv,
    /// design.json, report.md).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
    /// Choose the poses for these instruments instead of designing gauge sockets: a
    /// comma-separated mix of `gauges` (the description's `[[sensor]]`s), `tracker` (6-D poses),
    /// `points` (every `[[target]]`) and `tilts` (every `[[inclinometer]]`). --readings is then
    /// the budget of scalar observations; writes poses.csv, design.json and report.md with the
    /// Cramér-Rao bounds of the mix and of each instrument alone.
    #[arg(long, value_name = "LIST")]
    pub instruments: Option<String>,
}

impl GaugeArg {
    /// The gauge kind of cpm-calib's design.
    pub fn kind(self) -> GaugeKind {
        match self {
            GaugeArg::Telescoping => GaugeKind::Telescoping,
            GaugeArg::Ballbar => GaugeKind::Ballbar,
        }
    }
}

impl DesignArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> DesignJobOptions {
        DesignJobOptions {
            robot: self.robot.robot.clone(),
            sockets: self.sockets.clone(),
            readings: self.readings,
            base_sockets: self.base_sockets,
            platform_sockets: self.platform_sockets,
            poses: self.poses,
            candidates: self.candidates,
            range_mm: self.range_mm,
            range_deg: self.range_deg,
            criterion: self.criterion.criterion(),
            sigma_um: self.sigma_um,
            seed: self.seed,
            stroke_mm: self.stroke_mm,
            gauge_name: self.gauge_name.clone(),
            gauge: self.gauge.map(GaugeArg::kind),
            shortest_mm: self.shortest_mm,
            longest_mm: self.longest_mm,
            bars_mm: self.bars_mm.clone(),
            clearance_mm: self.clearance_mm,
            cone_deg: self.cone_deg,
            setups: self.setups,
            out: self.out.clone(),
            instruments: self.instruments.clone(),
        }
    }
}
