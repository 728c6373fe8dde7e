//! The report of `cargo xtask reproduce-paper`: `summary.json` and report.md (hence
//! report.html) rendered from one [`PaperReport`], built from a
//! [`PaperReproduction`] (`cpm_calib::paper`).
//!
//! [`PaperReport::summary`] is `summary.json` with the keys it has always had;
//! [`PaperReport::text`] carries what only the text shows (per-parameter tables, the
//! identifiable combinations, the options the text quotes).
use serde::Serialize;

use super::format::{fixed, opt_fixed, opt_with_sd, sci, with_sd};
use cpm_calib::design::{MonteCarloReport, ObservabilityIndices};
use cpm_calib::paper::{CampaignOutcome, LimitedOutcome, PaperReproduction, TradeoffRow};
use cpm_geometry::InstallationErrors;

/// `summary.json` and what report.md adds, from one reproduction.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PaperReport {
    /// `summary.json`.
    pub summary: PaperSummary,
    /// What only report.md shows.
    #[serde(skip)]
    pub text: PaperText,
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PaperSummary {
    /// Always `true`: the data are simulated.
    pub simulated: bool,
    /// What was simulated, in words.
    pub note: String,
    /// The simulation seed.
    pub seed: u64,
    /// The paper's design (one sensor, a circle).
    pub paper_design: PaperDesignSummary,
    /// Table 3 against Table 2 over the 36 parameters, um.
    pub table3_vs_table2: RmsMax,
    /// The designed campaign.
    pub designed: DesignedSummary,
    /// The campaign under an instrument's limits, when it was run.
    pub limited: Option<LimitedSummary>,
    /// The 36 installation error components, um: the truth (Table 2), the paper's estimate
    /// (Table 3), and cpm's estimate with its standard deviation on the paper's design and on
    /// the designed campaign (`null`: not determined by that campaign).
    pub components: Vec<ComponentRow>,
}

/// An RMS and a maximum, um.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct RmsMax {
    /// RMS, um.
    pub rms_um: f64,
    /// Maximum, um.
    pub max_um: f64,
}

/// One value per sign convention of the platform errors (`p + dp`, `p - dp`).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct PlusMinus {
    /// Platform errors applied as `p + dp`.
    pub plus: f64,
    /// Platform errors applied as `p - dp`.
    pub minus: f64,
}

/// The rank at one relative threshold.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct RankAt {
    /// Threshold relative to the largest singular value.
    pub rtol: f64,
    /// Rank at that threshold.
    pub rank: usize,
}

/// A blind direction group in physical terms.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct BlindDirection {
    /// What moves without changing a reading.
    pub description: String,
    /// How many dimensions of the null space it takes.
    pub dimensions: usize,
}

/// The paper's design.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PaperDesignSummary {
    /// Readings.
    pub readings: usize,
    /// Rank of the identification Jacobian.
    pub rank: usize,
    /// Relative rank threshold used.
    pub rank_threshold_rtol: f64,
    /// Rank against the threshold.
    pub rank_vs_threshold: Vec<RankAt>,
    /// Singular values, largest first.
    pub singular_values: Vec<f64>,
    /// Parameters the data determine on their own.
    pub determined_parameters: usize,
    /// Blind directions in physical terms.
    pub blind_directions: Vec<BlindDirection>,
    /// Null-space dimensions no physical description explains.
    pub unexplained_null_dimensions: usize,
    /// Residual RMS after the fit, um.
    pub residual_rms_um: f64,
    /// Residual RMS at the start, um.
    pub initial_residual_rms_um: f64,
    /// The solver, in brief (its wall time is in `timings.json`, so that this file is the same
    /// on every run).
    pub solver: String,
    /// What the paper's design determines: each identifiable combination of the 36
    /// components (a right singular vector), its estimate and Cramér-Rao standard deviation.
    pub identifiable_combinations: Vec<CombinationRow>,
    /// RMS difference of the readings predicted with Table 3 and Table 2, um.
    pub table3_sensor_rms_diff_um: PlusMinus,
    /// Share of Table 3 - Table 2 in the identifiable subspace.
    pub table3_visible_fraction: PlusMinus,
    /// Pose accuracy.
    pub accuracy: AccuracySummary,
}

/// Platform pose accuracy over the validation poses.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AccuracySummary {
    /// Validation poses.
    pub validation_poses: usize,
    /// Nominal geometry: RMS position error, um.
    pub nominal_rms_position_um: f64,
    /// Nominal geometry: largest position error, um.
    pub nominal_max_position_um: f64,
    /// Nominal geometry: RMS orientation error, urad.
    pub nominal_rms_orientation_urad: f64,
    /// Compensated: RMS position error, um.
    pub calibrated_rms_position_um: f64,
    /// Compensated: largest position error, um.
    pub calibrated_max_position_um: f64,
    /// Compensated: RMS orientation error, urad.
    pub calibrated_rms_orientation_urad: f64,
    /// What the compensation applies, in words.
    pub compensation: String,
    /// Minimum-norm solution applied: RMS position error, um.
    pub minimum_norm_rms_position_um: f64,
    /// Minimum-norm solution applied: largest position error, um.
    pub minimum_norm_max_position_um: f64,
    /// Minimum-norm solution applied: RMS orientation error, urad.
    pub minimum_norm_rms_orientation_urad: f64,
}

/// The designed campaign.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct DesignedSummary {
    /// Readings.
    pub readings: usize,
    /// Sensors (socket pairs).
    pub sensors: usize,
    /// Poses.
    pub poses: usize,
    /// Rank.
    pub rank: usize,
    /// Parameters determined.
    pub determined_parameters: usize,
    /// Estimates against Table 2, RMS, um (none when nothing is determined).
    pub rms_error_um: Option<f64>,
    /// Estimates against Table 2, max, um.
    pub max_error_um: Option<f64>,
    /// Cramér-Rao bound RMS at the nominal geometry, um.
    pub crlb_rms_um: Option<f64>,
    /// Cramér-Rao bound of the worst parameter, um.
    pub crlb_max_um: Option<f64>,
    /// Residual RMS, um.
    pub residual_rms_um: f64,
    /// The solver, in brief.
    pub solver: String,
    /// Pose accuracy.
    pub accuracy: AccuracySummary,
    /// The design.
    pub design: DesignSummary,
    /// The Monte Carlo study, when run.
    pub monte_carlo: Option<MonteCarloSummary>,
}

/// A socket place: cpm-calib's socket, serialised as it is (`name`, `position_mm`).
pub type SocketSummary = cpm_calib::design::Socket;

/// The length range of one sensor over the design.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SensorLengthRange {
    /// Sensor name.
    pub sensor: String,
    /// Shortest, mm.
    pub min: f64,
    /// Longest, mm.
    pub max: f64,
}

/// Observability indices (non-finite values are written as `null`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct IndicesSummary {
    /// Readings.
    pub readings: usize,
    /// Rank.
    pub rank: usize,
    /// O1, geometric mean of the singular values.
    pub o1_geometric_mean: f64,
    /// O1 per reading.
    pub o1_per_reading: f64,
    /// O2, condition number.
    pub o2_condition: f64,
    /// O3, smallest singular value.
    pub o3_min_singular: f64,
    /// O4, noise amplification.
    pub o4_noise_amplification: f64,
    /// Reading noise, um.
    pub sigma_um: f64,
    /// Cramér-Rao bound along the worst direction, um.
    pub crlb_worst_direction_um: f64,
    /// Cramér-Rao bound RMS, um.
    pub crlb_rms_um: f64,
    /// Cramér-Rao bound of the worst parameter, um.
    pub crlb_max_um: f64,
}

impl From<&ObservabilityIndices> for IndicesSummary {
    fn from(ix: &ObservabilityIndices) -> Self {
        Self {
            readings: ix.num_readings,
            rank: ix.rank,
            o1_geometric_mean: ix.o1_geometric_mean,
            o1_per_reading: ix.o1_per_reading,
            o2_condition: ix.o2_condition,
            o3_min_singular: ix.o3_min_singular,
            o4_noise_amplification: ix.o4_noise_amplification,
            sigma_um: ix.sigma_um,
            crlb_worst_direction_um: ix.crlb_worst_um,
            crlb_rms_um: ix.crlb_rms_um,
            crlb_max_um: ix.crlb_max_um,
        }
    }
}

/// Gauge freedoms left by a socket layout.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GaugeFreedomRow {
    /// Base sockets.
    pub base_sockets: usize,
    /// Platform sockets.
    pub platform_sockets: usize,
    /// Readings (text only).
    #[serde(skip)]
    pub readings: usize,
    /// Rank.
    pub rank: usize,
    /// Rotations of the base joints no reading sees.
    pub base_rotations_unseen: usize,
    /// Rotations of the platform joints no reading sees.
    pub platform_rotations_unseen: usize,
    /// Other blind directions.
    pub other_null_dimensions: usize,
}

/// The optimised design.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct DesignSummary {
    /// The criterion in words (`A-optimal`).
    pub criterion: String,
    /// Admissible candidate poses.
    pub candidate_poses: usize,
    /// Base sockets chosen.
    pub base_sockets: Vec<SocketSummary>,
    /// Platform sockets chosen.
    pub platform_sockets: Vec<SocketSummary>,
    /// Gauge length range per sensor, mm.
    pub sensor_length_range_mm: Vec<SensorLengthRange>,
    /// Indices of the design.
    pub indices: IndicesSummary,
    /// Indices of the hand-made campaign of the same budget.
    pub handmade_indices: IndicesSummary,
    /// Gauge freedoms per socket layout.
    pub gauge_freedoms: Vec<GaugeFreedomRow>,
    /// How it was chosen.
    pub log: Vec<String>,
}

/// A Monte Carlo study of simulated campaigns and calibrations.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MonteCarloSummary {
    /// Runs.
    pub runs: usize,
    /// Runs whose calibration failed.
    pub failed_runs: usize,
    /// Seed of the first run (the others follow).
    pub first_seed: u64,
    /// RMS error over runs and parameters, um.
    pub rms_error_um: f64,
    /// Cramér-Rao RMS, um.
    pub crlb_rms_um: f64,
    /// Efficiency (bound over error, squared).
    pub efficiency: f64,
    /// Smallest per-parameter efficiency.
    pub efficiency_min: f64,
    /// Largest per-parameter efficiency.
    pub efficiency_max: f64,
    /// Largest absolute bias, um.
    pub max_abs_bias_um: f64,
    /// Mean of the per-run RMS error, um.
    pub run_rms_error_um_mean: f64,
    /// Worst per-run RMS error, um.
    pub run_rms_error_um_worst: f64,
    /// Mean of the per-run largest error, um.
    pub max_error_um_mean: f64,
    /// 95th percentile of the per-run largest error, um.
    pub max_error_um_p95: f64,
    /// Worst per-run largest error, um.
    pub max_error_um_worst: f64,
    /// Share of runs with RMS <= 2 um and max <= 6 um.
    pub fraction_rms_le_2um_and_max_le_6um: f64,
}

impl From<&MonteCarloReport> for MonteCarloSummary {
    fn from(m: &MonteCarloReport) -> Self {
        Self {
            runs: m.runs,
            failed_runs: m.failed_runs,
            first_seed: m.first_seed,
            rms_error_um: m.rms_error_um,
            crlb_rms_um: m.crlb_rms_um,
            efficiency: m.efficiency,
            efficiency_min: m.efficiency_range.0,
            efficiency_max: m.efficiency_range.1,
            max_abs_bias_um: m.max_abs_bias_um,
            run_rms_error_um_mean: m.run_rms_error_um_mean,
            run_rms_error_um_worst: m.run_rms_error_um_worst,
            max_error_um_mean: m.max_error_um_mean,
            max_error_um_p95: m.max_error_um_p95,
            max_error_um_worst: m.max_error_um_worst,
            fraction_rms_le_2um_and_max_le_6um: m.fraction_within(2.0, 6.0),
        }
    }
}

/// The instrument's limits of the campaign under limits.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LimitedConstraints {
    /// The gauge kind, in words.
    pub gauge: String,
    /// Stroke per setup, mm.
    pub stroke_mm: f64,
    /// Shortest gauge length, mm.
    pub shortest_mm: f64,
    /// Longest gauge length, mm.
    pub longest_mm: f64,
    /// Least distance between the gauge axis and a link axis, mm.
    pub gauge_link_clearance_mm: f64,
    /// Largest base joint cone angle, deg.
    pub base_cone_deg: f64,
    /// Largest platform joint cone angle, deg.
    pub platform_cone_deg: f64,
    /// Most setups.
    pub max_setups: usize,
}

/// Socket moves and bar changes between consecutive setups.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Remounts {
    /// Socket moves.
    pub socket_moves: usize,
    /// Bar changes.
    pub bar_changes: usize,
}

/// One setup of the campaign under limits.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SetupRow {
    /// Setup name.
    pub setup: String,
    /// Base socket.
    pub base_socket: String,
    /// Platform socket.
    pub platform_socket: String,
    /// Bar length, mm.
    pub bar_mm: f64,
    /// Gauge window (shortest, longest), mm.
    pub window_mm: [f64; 2],
    /// Readings.
    pub readings: usize,
    /// Lengths used (shortest, longest), mm.
    pub length_range_mm: [f64; 2],
    /// Gauge travel, mm.
    pub travel_mm: f64,
    /// Least gauge-link clearance, mm.
    pub min_clearance_mm: f64,
}

/// The worst-error target in both readings.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct WorstError {
    /// The parameter with the largest Monte Carlo RMS error.
    pub worst_parameter: Option<String>,
    /// Its RMS error, um.
    pub worst_parameter_rms_error_um: Option<f64>,
    /// Its Cramér-Rao bound, um.
    pub worst_parameter_crlb_um: Option<f64>,
    /// Largest absolute error over all runs and parameters, um.
    pub max_abs_error_um_all_runs: f64,
    /// Share of runs whose every error is within the target.
    pub fraction_runs_max_le_6um: f64,
    /// The target, um.
    pub target_um: f64,
}

/// One gauge stroke of the trade-off: cpm-calib's row, serialised as it is.
pub type TradeoffSummary = TradeoffRow;

/// The campaign under an instrument's limits.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LimitedSummary {
    /// The limits.
    pub constraints: LimitedConstraints,
    /// Readings.
    pub readings: usize,
    /// Setups.
    pub setups: usize,
    /// Rank.
    pub rank: usize,
    /// Cramér-Rao RMS, um.
    pub crlb_rms_um: f64,
    /// Cramér-Rao bound of the worst parameter, um.
    pub crlb_max_um: f64,
    /// Largest travel in a setup, mm.
    pub max_travel_mm: f64,
    /// Least gauge-link clearance, mm.
    pub min_clearance_mm: f64,
    /// Largest base joint cone angle, deg.
    pub max_base_cone_deg: f64,
    /// Largest platform joint cone angle, deg.
    pub max_platform_cone_deg: f64,
    /// Remounts between consecutive setups.
    pub remounts: Remounts,
    /// The setups in mounting order.
    pub per_setup: Vec<SetupRow>,
    /// Estimates of this seed against Table 2, RMS, um.
    pub rms_error_um: Option<f64>,
    /// Estimates of this seed against Table 2, max, um.
    pub max_error_um: Option<f64>,
    /// The Monte Carlo study, when run.
    pub monte_carlo: Option<MonteCarloSummary>,
    /// The worst-error target, when the Monte Carlo study was run.
    pub worst_error: Option<WorstError>,
    /// Stroke against precision.
    pub tradeoff: Vec<TradeoffSummary>,
    /// How it was chosen.
    pub log: Vec<String>,
    /// The files written.
    pub files: Vec<String>,
    /// Readings budget (text only).
    #[serde(skip)]
    pub max_readings: usize,
    /// Exchanges of the trade-off searches (text only).
    #[serde(skip)]
    pub tradeoff_exchanges: usize,
    /// Exchanges of the campaign's search (text only).
    #[serde(skip)]
    pub max_exchanges: usize,
    /// Minimax rounds of the campaign's search (text only).
    #[serde(skip)]
    pub minimax_rounds: usize,
}

/// An identifiable combination of the paper's design.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CombinationRow {
    /// Its singular value.
    pub singular_value: f64,
    /// Estimate, um.
    pub estimate_um: f64,
    /// Cramér-Rao standard deviation, um.
    pub std_um: f64,
    /// Largest loadings (component name, weight), largest first.
    pub loadings: Vec<(String, f64)>,
}

/// One installation error component in the side-by-side table, um.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ComponentRow {
    /// Component name.
    pub name: String,
    /// Table 2 (true).
    #[serde(rename = "table2_um")]
    pub table2: f64,
    /// Table 3 (the paper's estimate).
    #[serde(rename = "table3_um")]
    pub table3: f64,
    /// cpm on the paper's design (none: not determined).
    #[serde(rename = "paper_design_um")]
    pub paper: Option<f64>,
    /// Its standard deviation.
    #[serde(rename = "paper_design_std_um")]
    pub paper_std: Option<f64>,
    /// cpm on the designed campaign.
    #[serde(rename = "designed_um")]
    pub designed: Option<f64>,
    /// Its standard deviation.
    #[serde(rename = "designed_std_um")]
    pub designed_std: Option<f64>,
}

/// What only report.md shows.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PaperText {
    /// The noise model, in words.
    pub noise: String,
    /// Reading noise standard deviation, um.
    pub sigma_um: f64,
    /// Blind directions of the paper's design, in words (the identifiability summary).
    pub blind_summary: String,
    /// Identifiable combinations of the paper's design.
    pub combinations: Vec<CombinationRow>,
    /// The designed campaign's readings budget.
    pub max_readings: usize,
    /// Candidate pose range, mm.
    pub designed_range_mm: f64,
    /// Candidate pose range, deg.
    pub designed_range_deg: f64,
    /// Candidate socket places (base, platform).
    pub socket_candidates: (usize, usize),
    /// Largest Cramér-Rao standard deviation of a compensated combination, um.
    pub compensation_max_std_um: f64,
    /// The 36 components side by side (in [`InstallationErrors`] order: link by link, base
    /// dx dy dz then platform dx dy dz).
    pub components: Vec<ComponentRow>,
    /// Singular values of the designed campaign's identification Jacobian.
    pub designed_singular_values: Vec<f64>,
    /// The paper design's absolute rank threshold on the singular values.
    pub rank_threshold: f64,
}

fn accuracy(o: &CampaignOutcome) -> AccuracySummary {
    AccuracySummary {
        validation_poses: o.accuracy.poses,
        nominal_rms_position_um: o.accuracy.nominal.rms_position_um,
        nominal_max_position_um: o.accuracy.nominal.max_position_um,
        nominal_rms_orientation_urad: o.accuracy.nominal.rms_orientation_urad,
        calibrated_rms_position_um: o.accuracy.calibrated.rms_position_um,
        calibrated_max_position_um: o.accuracy.calibrated.max_position_um,
        calibrated_rms_orientation_urad: o.accuracy.calibrated.rms_orientation_urad,
        compensation: format!(
            "identifiable combinations with Cramér-Rao std <= {} um",
            cpm_calib::paper::COMPENSATION_MAX_STD_UM
        ),
        minimum_norm_rms_position_um: o.accuracy_minimum_norm.calibrated.rms_position_um,
        minimum_norm_max_position_um: o.accuracy_minimum_norm.calibrated.max_position_um,
        minimum_norm_rms_orientation_urad: o.accuracy_minimum_norm.calibrated.rms_orientation_urad,
    }
}

fn limited(l: &LimitedOutcome, max_readings: usize) -> LimitedSummary {
    let d = &l.design;
    let c = &d.constraints;
    let names = cpm_calib::identifiability::parameter_names(6);
    let (socket_moves, bar_changes) = d.remounts();
    LimitedSummary {
        constraints: LimitedConstraints {
            gauge: c.gauge.kind.name().to_string(),
            stroke_mm: c.gauge.stroke_mm,
            shortest_mm: c.gauge.shortest_mm,
            longest_mm: c.gauge.longest_mm,
            gauge_link_clearance_mm: c.clearance.gauge_link_mm,
            base_cone_deg: c.joints.base_cone_deg,
            platform_cone_deg: c.joints.platform_cone_deg,
            max_setups: l.options.max_setups,
        },
        readings: d.num_readings(),
        setups: d.setups.len(),
        rank: d.indices.rank,
        crlb_rms_um: d.indices.crlb_rms_um,
        crlb_max_um: d.indices.crlb_max_um,
        max_travel_mm: d.max_travel_mm(),
        min_clearance_mm: d.min_clearance_mm(),
        max_base_cone_deg: l.max_cone_deg.0,
        max_platform_cone_deg: l.max_cone_deg.1,
        remounts: Remounts {
            socket_moves,
            bar_changes,
        },
        per_setup: d
            .setups
            .iter()
            .map(|s| SetupRow {
                setup: s.name.clone(),
                base_socket: s.base.name.clone(),
                platform_socket: s.platform.name.clone(),
                bar_mm: s.bar_mm,
                window_mm: [s.window_mm.0, s.window_mm.1],
                readings: s.poses.len(),
                length_range_mm: [s.length_range_mm().0, s.length_range_mm().1],
                travel_mm: s.travel_mm(),
                min_clearance_mm: s.min_clearance_mm(),
            })
            .collect(),
        rms_error_um: l.error_vs_truth_um.map(|x| x.0),
        max_error_um: l.error_vs_truth_um.map(|x| x.1),
        monte_carlo: l.monte_carlo.as_ref().map(MonteCarloSummary::from),
        worst_error: l.monte_carlo.as_ref().map(|m| {
            let worst = m.worst_parameter();
            WorstError {
                worst_parameter: worst.map(|(k, _)| names.get(k).cloned().unwrap_or_default()),
                worst_parameter_rms_error_um: worst.map(|(_, p)| p.rms_error_um),
                worst_parameter_crlb_um: worst.map(|(_, p)| p.crlb_um),
                max_abs_error_um_all_runs: m.max_error_um_worst,
                fraction_runs_max_le_6um: m.fraction_max_within(6.0),
                target_um: 6.0,
            }
        }),
        tradeoff: l.tradeoff.clone(),
        log: d.log.clone(),
        files: [
            "designed/robot.toml",
            "designed/readings.csv",
            "designed/setup_sheet.md",
            "designed/setup_sheet.csv",
        ]
        .map(String::from)
        .to_vec(),
        max_readings,
        tradeoff_exchanges: l.options.tradeoff_exchanges,
        max_exchanges: l.options.search.select.max_exchanges,
        minimax_rounds: l.options.search.minimax_rounds,
    }
}

impl PaperReport {
    /// The report of a reproduction.
    pub fn new(r: &PaperReproduction) -> Self {
        let p = &r.paper.calibration;
        let d = &r.designed.calibration;
        let dz = &r.design;
        let t2 = InstallationErrors::paper_table2().to_vec_um();
        let t3 = InstallationErrors::paper_table3().to_vec_um();
        let cands = cpm_calib::design::SocketCandidates::paper_cubic();
        let combinations: Vec<CombinationRow> = p
            .combinations
            .iter()
            .map(|c| CombinationRow {
                singular_value: c.singular_value,
                estimate_um: c.estimate_um,
                std_um: c.std_um,
                loadings: c
                    .loadings
                    .iter()
                    .map(|(k, w)| (InstallationErrors::component_name(*k).to_string(), *w))
                    .collect(),
            })
            .collect();
        let components: Vec<ComponentRow> = (0..36)
            .map(|k| ComponentRow {
                name: InstallationErrors::component_name(k).to_string(),
                table2: t2[k],
                table3: t3[k],
                paper: p.estimate_um[k],
                paper_std: p.std_um[k],
                designed: d.estimate_um[k],
                designed_std: d.std_um[k],
            })
            .collect();
        let summary = PaperSummary {
            simulated: true,
            note: "All readings are simulated from the paper's Table 2 with the paper's clearance and noise model.".into(),
            seed: r.options.seed,
            paper_design: PaperDesignSummary {
                readings: p.identifiability.num_readings,
                rank: p.identifiability.rank,
                rank_threshold_rtol: p.identifiability.rank_rtol,
                rank_vs_threshold: r
                    .rank_vs_threshold
                    .iter()
                    .map(|&(rtol, rank)| RankAt { rtol, rank })
                    .collect(),
                singular_values: p.identifiability.singular_values.clone(),
                determined_parameters: p.identifiability.num_determined(),
                blind_directions: p
                    .identifiability
                    .blind_directions
                    .iter()
                    .map(|b| BlindDirection {
                        description: b.description.clone(),
                        dimensions: b.dimensions,
                    })
                    .collect(),
                unexplained_null_dimensions: p.identifiability.unexplained_null_dimensions,
                residual_rms_um: p.residual_rms_um,
                initial_residual_rms_um: p.initial_rms_um,
                solver: p.solver.brief_without_time(),
                identifiable_combinations: combinations.clone(),
                table3_sensor_rms_diff_um: PlusMinus {
                    plus: r.table3.plus,
                    minus: r.table3.minus,
                },
                table3_visible_fraction: PlusMinus {
                    plus: r.table3_visible_fraction.0,
                    minus: r.table3_visible_fraction.1,
                },
                accuracy: accuracy(&r.paper),
            },
            table3_vs_table2: RmsMax {
                rms_um: r.table3_vs_table2_um.0,
                max_um: r.table3_vs_table2_um.1,
            },
            designed: DesignedSummary {
                readings: d.identifiability.num_readings,
                sensors: r.designed.plan.sensors.len(),
                poses: r.designed.plan.poses.len(),
                rank: d.identifiability.rank,
                determined_parameters: d.identifiability.num_determined(),
                rms_error_um: r.designed.error_vs_truth_um.map(|x| x.0),
                max_error_um: r.designed.error_vs_truth_um.map(|x| x.1),
                crlb_rms_um: r.designed_identifiability.crlb_rms_um(),
                crlb_max_um: r.designed_identifiability.crlb_max_um(),
                residual_rms_um: d.residual_rms_um,
                solver: d.solver.brief_without_time(),
                accuracy: accuracy(&r.designed),
                design: DesignSummary {
                    criterion: format!("{}-optimal", dz.criterion.name()),
                    candidate_poses: dz.candidates,
                    base_sockets: dz.base_sockets.clone(),
                    platform_sockets: dz.platform_sockets.clone(),
                    sensor_length_range_mm: dz
                        .sensors
                        .iter()
                        .zip(&dz.sensor_lengths_mm)
                        .map(|(s, (lo, hi))| SensorLengthRange {
                            sensor: s.name.clone(),
                            min: *lo,
                            max: *hi,
                        })
                        .collect(),
                    indices: (&dz.indices).into(),
                    handmade_indices: (&r.handmade_indices).into(),
                    gauge_freedoms: dz
                        .gauge
                        .iter()
                        .map(|g| GaugeFreedomRow {
                            base_sockets: g.base_sockets,
                            platform_sockets: g.platform_sockets,
                            readings: g.readings,
                            rank: g.rank,
                            base_rotations_unseen: g.base_freedoms,
                            platform_rotations_unseen: g.platform_freedoms,
                            other_null_dimensions: g.other_null_dimensions,
                        })
                        .collect(),
                    log: dz.log.clone(),
                },
                monte_carlo: r.monte_carlo.as_ref().map(MonteCarloSummary::from),
            },
            limited: r
                .limited
                .as_ref()
                .map(|l| limited(l, r.options.design.max_readings)),
            components: components.clone(),
        };
        let text = PaperText {
            noise: r.options.noise.to_string(),
            sigma_um: r.options.noise.sigma_um(),
            blind_summary: p.identifiability.summary(),
            combinations,
            max_readings: r.options.design.max_readings,
            designed_range_mm: r.options.designed_range_mm,
            designed_range_deg: r.options.designed_range_deg,
            socket_candidates: (cands.base.len(), cands.platform.len()),
            compensation_max_std_um: cpm_calib::paper::COMPENSATION_MAX_STD_UM,
            components,
            designed_singular_values: d.identifiability.singular_values.clone(),
            rank_threshold: p.identifiability.threshold,
        };
        Self { summary, text }
    }

    /// `summary.json` as a JSON value (keys sorted, non-finite numbers as `null`).
    pub fn summary_json(&self) -> serde_json::Value {
        serde_json::to_value(&self.summary).unwrap_or(serde_json::Value::Null)
    }
}

/// Share removed, percent: `100 (1 - a / b)`.
fn removed_pct(a: f64, b: f64) -> f64 {
    100.0 * (1.0 - a / b)
}

fn sockets_text(v: &[SocketSummary]) -> String {
    v.iter()
        .map(|x| {
            format!(
                "{} ({}, {}, {})",
                x.name,
                fixed(x.position_mm[0], 0),
                fixed(x.position_mm[1], 0),
                fixed(x.position_mm[2], 0)
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

impl PaperReport {
    /// report.md.
    pub fn report_md(&self) -> String {
        let sm = &self.summary;
        let tx = &self.text;
        let p = &sm.paper_design;
        let d = &sm.designed;
        let dz = &d.design;
        let mut s = String::new();
        s.push_str("# Reproduction of Lim et al. (2002): installation error calibration of a cubic parallel manipulator\n\n");
        s.push_str("**All data in this report are simulated** (truth: the paper's Table 2; clearance 10 um per joint from the link force directions; sensor noise ");
        s.push_str(&format!(
            "{}, seed {}). Produced by `cargo xtask reproduce-paper`.\n\n",
            tx.noise, sm.seed
        ));
        s.push_str("## 1. The paper's design: one sensor, a circle at constant orientation\n\n");
        s.push_str(&format!(
            "- Readings: {}; residual RMS after the fit {} um (start {} um); solver: {}.\n",
            p.readings,
            fixed(p.residual_rms_um, 2),
            fixed(p.initial_residual_rms_um, 2),
            p.solver
        ));
        s.push_str(&format!(
            "- **Rank of the identification Jacobian: {} of 36** (threshold {} x s_max). Rank against the threshold: {}.\n",
            p.rank,
            sci(p.rank_threshold_rtol, 2),
            p.rank_vs_threshold
                .iter()
                .map(|r| format!("{} -> {}", sci(r.rtol, 1), r.rank))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        s.push_str(&format!(
            "- Parameters the data determine on their own: {} of 36. Every entry below marked n.d. is *not determined*: the readings are exactly as consistent with any value along the blind directions.\n",
            p.determined_parameters
        ));
        s.push_str("- Singular values: ");
        s.push_str(
            &p.singular_values
                .iter()
                .map(|v| sci(*v, 4))
                .collect::<Vec<_>>()
                .join(", "),
        );
        s.push_str("\n\n### Why the rank is so low (blind directions in physical terms)\n\n");
        // Its first line is a sentence of its own (a paragraph), then the list.
        s.push_str(
            &tx.blind_summary
                .replacen('\n', ".\n\n", 1)
                .replace("\n  - ", "\n- "),
        );
        let per_link: usize = p
            .blind_directions
            .iter()
            .filter(|b| b.description.contains("moved together by the same vector"))
            .map(|b| b.dimensions)
            .sum();
        s.push_str(&format!("\nWith the orientation constant, a link's base and platform errors enter the link length only through `R dp_i - db_i`, so moving both joints of a link by the same vector changes nothing ({per_link} blind dimensions found of this kind above)."));
        s.push_str(" One length sensor cannot see the whole mechanism rotating about its base socket, nor the platform joint pattern rotating about its platform socket. What remains is probed by a single scalar per pose along a planar circle, which sees only a few smooth functions of the pose.\n\n");
        s.push_str("Identifiable combinations (estimate +- Cramér-Rao standard deviation):\n\n| # | singular value | estimate (um) | std (um) | largest loadings |\n|---|---|---|---|---|\n");
        for (i, c) in tx.combinations.iter().enumerate() {
            let (est, sd) = with_sd(c.estimate_um, c.std_um);
            s.push_str(&format!(
                "| {} | {} | {est} | {sd} | {} |\n",
                i + 1,
                sci(c.singular_value, 4),
                c.loadings
                    .iter()
                    .map(|(k, w)| {
                        let w = fixed(*w, 2);
                        let sign = if w.starts_with('-') { "" } else { "+" };
                        format!("{sign}{w} {k}")
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        s.push_str("\n### Is Table 3 what the paper's data say?\n\n");
        s.push_str(&format!(
            "- Table 3 - Table 2 over the 36 parameters: RMS {} um, max {} um (computed here from the two tables).\n",
            fixed(sm.table3_vs_table2.rms_um, 2),
            fixed(sm.table3_vs_table2.max_um, 2)
        ));
        let t3 = p.table3_sensor_rms_diff_um;
        s.push_str(&format!(
            "- RMS difference of the noise-free sensor readings on the paper's circle predicted with Table 3 and with Table 2: **{} um with platform errors applied as p + dp, {} um as p - dp**. The paper's noise has a standard deviation of {} um per reading.\n",
            fixed(t3.plus, 3),
            fixed(t3.minus, 3),
            fixed(tx.sigma_um, 2)
        ));
        s.push_str(&format!(
            "- Fraction of the difference Table 3 - Table 2 that lies in the identifiable subspace of the paper's design: {} (p + dp), {} (p - dp).\n",
            fixed(p.table3_visible_fraction.plus, 3),
            fixed(p.table3_visible_fraction.minus, 3)
        ));
        let (lo, hi) = if t3.plus < t3.minus {
            ("p + dp", "p - dp")
        } else {
            ("p - dp", "p + dp")
        };
        s.push_str(&format!(
            "\nWhat follows: under the {lo} convention Table 3 predicts almost the same readings as Table 2, so the paper's data cannot tell the two tables apart and Table 3 is one of infinitely many equally good fits; its differences from Table 2 lie along blind directions. Under {hi} the two tables predict visibly different readings. Table 3's apparent agreement with Table 2 (most components within 10 %) therefore does not show that the 36 errors were identified: it reflects a start close to the truth or the tables' construction, not information in the 36 readings.\n\n"
        ));
        s.push_str("## 2. A designed campaign that identifies all 36 errors\n\n");
        s.push_str(&format!(
            "- Chosen by `cpm_calib::design` ({}, at most {} readings): base sockets {} mm in {{B}}; platform sockets {} mm in {{P}}; every base socket paired with every platform socket: {} sensors read at {} poses = {} readings.\n",
            dz.criterion, tx.max_readings, sockets_text(&dz.base_sockets), sockets_text(&dz.platform_sockets), dz.sensor_length_range_mm.len(), d.poses, d.readings
        ));
        let (lo, hi, travel) = dz
            .sensor_length_range_mm
            .iter()
            .fold((f64::INFINITY, 0.0f64, 0.0f64), |(a, b, c), r| {
                (a.min(r.min), b.max(r.max), c.max(r.max - r.min))
            });
        s.push_str(&format!(
            "- The gauge spans {} to {} mm between its sockets over the design; one sensor's length changes by at most {} mm over the poses (`cpm_calib::design::Design::sensor_lengths_mm`).\n",
            fixed(lo, 0), fixed(hi, 0), fixed(travel, 0)
        ));
        s.push_str(&format!(
            "- Rank {} of 36, {} parameters determined. Residual RMS {} um. Solver: {}.\n",
            d.rank,
            d.determined_parameters,
            fixed(d.residual_rms_um, 2),
            d.solver
        ));
        if let (Some(rms), Some(max)) = (d.rms_error_um, d.max_error_um) {
            s.push_str(&format!(
                "- **Estimates against Table 2 (seed {}): RMS error {} um, max {} um** (the paper's Table 3: RMS {} um, max {} um, from a design that could not identify them).\n",
                sm.seed, fixed(rms, 2), fixed(max, 2), fixed(sm.table3_vs_table2.rms_um, 2), fixed(sm.table3_vs_table2.max_um, 2)
            ));
        }
        s.push_str(&format!(
            "- Cramér-Rao bound for this design: RMS {} um, worst parameter {} um.\n",
            opt_fixed(d.crlb_rms_um, 1),
            opt_fixed(d.crlb_max_um, 1)
        ));
        if let Some(m) = &d.monte_carlo {
            s.push_str(&format!(
                "- **Monte Carlo, {} simulated campaigns and calibrations (seeds {}..{}, {} failed): RMS error {} um against a Cramér-Rao RMS of {} um, efficiency {}** (per parameter {} to {}; largest |bias| {} um). Largest error per run: mean {} um, 95th percentile {} um, worst {} um; RMS error per run: mean {} um, worst {} um; {} % of the runs meet both RMS <= 2 um and max <= 6 um.\n",
                m.runs, m.first_seed, m.first_seed + m.runs as u64 - 1, m.failed_runs, fixed(m.rms_error_um, 2), fixed(m.crlb_rms_um, 2), fixed(m.efficiency, 3),
                fixed(m.efficiency_min, 2), fixed(m.efficiency_max, 2), fixed(m.max_abs_bias_um, 2), fixed(m.max_error_um_mean, 2), fixed(m.max_error_um_p95, 2), fixed(m.max_error_um_worst, 2),
                fixed(m.run_rms_error_um_mean, 2), fixed(m.run_rms_error_um_worst, 2), fixed(100.0 * m.fraction_rms_le_2um_and_max_le_6um, 0)
            ));
        }
        s.push_str("\n### How the design was chosen\n\n");
        s.push_str(&format!(
            "{} admissible candidate poses (random within +-{} mm and +-{} deg of home, plus ballbar-like circles at three heights and three tilts; tilt at most 30 deg, J1's condition number at most 3 times its home value, forward kinematics from home converging to each) and {} x {} candidate socket places. Poses are chosen greedily and improved by DETMAX exchange on the information matrix J^T J (A-optimal: the sum of the Cramér-Rao variances); sockets are chosen exhaustively for the current poses; the two alternate until the sockets settle:\n\n",
            dz.candidate_poses, super::format::short(tx.designed_range_mm), super::format::short(tx.designed_range_deg),
            tx.socket_candidates.0, tx.socket_candidates.1
        ));
        for l in &dz.log {
            s.push_str(&format!("- {l}\n"));
        }
        s.push_str("\nObservability indices (J in um of reading per um of error; noise sigma = ");
        s.push_str(&format!("{} um):\n\n| design | readings | rank | O1 geometric mean | O2 condition | O3 min singular | O4 noise amplification | CRLB worst direction (um) | CRLB RMS (um) | CRLB max (um) |\n|---|---|---|---|---|---|---|---|---|---|\n", fixed(dz.indices.sigma_um, 2)));
        for (name, ix) in [
            (
                "hand-made: 16 socket pairs, 125 random poses",
                &dz.handmade_indices,
            ),
            ("designed", &dz.indices),
        ] {
            s.push_str(&format!(
                "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                ix.readings,
                ix.rank,
                fixed(ix.o1_geometric_mean, 3),
                fixed(ix.o2_condition, 1),
                fixed(ix.o3_min_singular, 3),
                fixed(ix.o4_noise_amplification, 4),
                fixed(ix.crlb_worst_direction_um, 2),
                fixed(ix.crlb_rms_um, 2),
                fixed(ix.crlb_max_um, 2)
            ));
        }
        s.push_str("\n### Gauge freedoms: why one socket pair is not enough\n\nA length gauge between one base socket and one platform socket sees the base joints only through their distances from its base socket, and the platform joints only through distances from its platform socket: rotating all base joints about the base socket, or all platform joints about the platform socket, changes no reading at any pose (3 + 3 blind directions). A second socket on a side leaves only the rotation about the line through the two; a third socket off that line removes it. On the designed poses:\n\n| sockets (base x platform) | readings | rank | unseen base rotations | unseen platform rotations | other blind directions |\n|---|---|---|---|---|---|\n");
        for g in &dz.gauge_freedoms {
            s.push_str(&format!(
                "| {} x {} | {} | {} | {} | {} | {} |\n",
                g.base_sockets,
                g.platform_sockets,
                g.readings,
                g.rank,
                g.base_rotations_unseen,
                g.platform_rotations_unseen,
                g.other_null_dimensions
            ));
        }
        s.push('\n');
        if let Some(l) = &sm.limited {
            s.push_str(&limited_md(l));
        }
        s.push_str("## 3. The tables side by side (um)\n\nn.d. = not determined by the data (no estimate exists).\n\n| component | Table 2 (true) | Table 3 (paper) | cpm, paper design | cpm, designed | std (designed) |\n|---|---|---|---|---|---|\n");
        for c in &tx.components {
            let (pe, _) = opt_with_sd(c.paper, c.paper_std, 1);
            let (de, dsd) = opt_with_sd(c.designed, c.designed_std, 1);
            s.push_str(&format!(
                "| {} | {} | {} | {pe} | {de} | {dsd} |\n",
                c.name,
                fixed(c.table2, 1),
                fixed(c.table3, 1),
            ));
        }
        s.push_str("\n## 4. What the user of the robot gets: platform pose error\n\n");
        s.push_str(&format!(
            "Over {} random validation poses (+-60 mm, +-8 deg about home), commanding from the nominal geometry and from the calibrated one. *Compensated*: only identifiable combinations whose Cramér-Rao standard deviation is at most {} um are applied (`Calibration::compensation_um`); *minimum norm*: every identifiable combination, however weak. Blind directions stay at zero in both.\n\n| design | nominal RMS / max position (um) | compensated RMS / max position (um) | minimum-norm RMS / max position (um) | nominal / compensated / minimum-norm RMS orientation (urad) |\n|---|---|---|---|---|\n",
            p.accuracy.validation_poses,
            super::format::short(tx.compensation_max_std_um)
        ));
        for (name, a) in [("paper design", &p.accuracy), ("designed", &d.accuracy)] {
            s.push_str(&format!(
                "| {} | {} / {} | {} / {} | {} / {} | {} / {} / {} |\n",
                name,
                fixed(a.nominal_rms_position_um, 1),
                fixed(a.nominal_max_position_um, 1),
                fixed(a.calibrated_rms_position_um, 1),
                fixed(a.calibrated_max_position_um, 1),
                fixed(a.minimum_norm_rms_position_um, 1),
                fixed(a.minimum_norm_max_position_um, 1),
                fixed(a.nominal_rms_orientation_urad, 1),
                fixed(a.calibrated_rms_orientation_urad, 1),
                fixed(a.minimum_norm_rms_orientation_urad, 1)
            ));
        }
        let pa = &p.accuracy;
        s.push_str(&format!(
            "\nOn the paper's design, compensating with the well-determined combinations removes {} % of the RMS position error and {} % of the RMS orientation error; the blind directions, which the readings cannot see, still move the platform.",
            fixed(removed_pct(pa.calibrated_rms_position_um, pa.nominal_rms_position_um), 0),
            fixed(removed_pct(pa.calibrated_rms_orientation_urad, pa.nominal_rms_orientation_urad), 0),
        ));
        if pa.minimum_norm_rms_position_um > pa.nominal_rms_position_um {
            s.push_str(" Applying every identifiable combination, weak ones included, makes the machine worse than not calibrating at all.");
        }
        s.push_str(&format!(
            " The designed campaign removes {} % of it.\n",
            fixed(
                removed_pct(
                    d.accuracy.calibrated_rms_position_um,
                    d.accuracy.nominal_rms_position_um
                ),
                1
            )
        ));
        s.push_str("\n## Figures\n\n- `fig5_platform.svg`, `fig6_base.svg`: per-joint error norm, true (Table 2), paper (Table 3) and cpm's designed campaign (the paper design determines no joint, so it has no bars).\n- `singular_values.svg`: spectra of both designs with the rank threshold.\n\n");
        s.push_str("## Assumptions\n\n- Home pose (0, 0, 410) mm, R = I (the paper gives none; at this pose the z links are 354 mm long).\n- Platform mass 20 kg, centre of mass 100 mm below the platform origin (the paper gives no load); only the force directions matter.\n- Platform-side errors are applied as p + dp in cpm.\n- Length sensor kept in compression by its spring (its socket clearance is a constant -20 um, corrected as eq. 14).\n");
        s
    }
}

/// Section 2b: the campaign under an instrument's limits.
fn limited_md(l: &LimitedSummary) -> String {
    let c = &l.constraints;
    let sh = super::format::short;
    let mut s = String::from("## 2b. A campaign a real instrument can run\n\n");
    s.push_str(&format!(
        "The campaign above assumes a gauge that travels several hundred mm and passes through the links. Under an instrument's limits (`cpm_calib::design::design_setups`): a {} gauge of **{} mm stroke per setup** (lengths {} to {} mm, any bar length), **at least {} mm between the gauge axis and every link axis**, **joint cone angles at most {} deg** at the base and {} deg at the platform joints, at most {} readings and {} setups (a setup = one socket pair with one bar; it is one `[[sensor]]` of the files). Candidate poses: those of the campaign above within the cone limits, plus poses moved along each gauge axis into its window.\n\n",
        c.gauge, sh(c.stroke_mm), sh(c.shortest_mm), sh(c.longest_mm), sh(c.gauge_link_clearance_mm),
        sh(c.base_cone_deg), sh(c.platform_cone_deg), l.max_readings, c.max_setups
    ));
    s.push_str(&format!(
        "- **{} readings in {} setups; largest gauge travel in a setup {} mm; smallest gauge-link clearance {} mm; largest cone angle {} deg (base joints), {} deg (platform joints)**; {} socket moves and {} bar changes between consecutive setups.\n",
        l.readings, l.setups, fixed(l.max_travel_mm, 1), fixed(l.min_clearance_mm, 1), fixed(l.max_base_cone_deg, 1), fixed(l.max_platform_cone_deg, 1), l.remounts.socket_moves, l.remounts.bar_changes
    ));
    s.push_str(&format!(
        "- Rank {} of 36; Cramér-Rao bound RMS {} um, worst parameter {} um.\n",
        l.rank,
        fixed(l.crlb_rms_um, 2),
        fixed(l.crlb_max_um, 2)
    ));
    if let (Some(rms), Some(max)) = (l.rms_error_um, l.max_error_um) {
        s.push_str(&format!(
            "- Estimates of this seed's readings against Table 2: RMS error {} um, max {} um.\n",
            fixed(rms, 2),
            fixed(max, 2)
        ));
    }
    if let Some(m) = &l.monte_carlo {
        s.push_str(&format!(
            "- **Monte Carlo, {} simulated campaigns and calibrations (seeds {}..{}, {} failed): RMS error {} um (Cramér-Rao {} um, efficiency {}); largest error per run: mean {} um, 95th percentile {} um, worst {} um**; {} % of the runs meet both RMS <= 2 um and max <= 6 um.\n",
            m.runs, m.first_seed, m.first_seed + m.runs as u64 - 1, m.failed_runs, fixed(m.rms_error_um, 2), fixed(m.crlb_rms_um, 2), fixed(m.efficiency, 3),
            fixed(m.max_error_um_mean, 2), fixed(m.max_error_um_p95, 2), fixed(m.max_error_um_worst, 2), fixed(100.0 * m.fraction_rms_le_2um_and_max_le_6um, 0)
        ));
        if let Some(w) = &l.worst_error {
            if let (Some(name), Some(rms), Some(crlb)) = (
                &w.worst_parameter,
                w.worst_parameter_rms_error_um,
                w.worst_parameter_crlb_um,
            ) {
                s.push_str(&format!(
                    "- **Worst error, two readings of the target (at most {} um)**: (a) the largest per-parameter Monte Carlo RMS error is {} um (`{}`, Cramér-Rao {} um); (b) the largest absolute error over all {} runs and 36 parameters is {} um, and {} % of the runs have every error within {} um.\n",
                    sh(w.target_um),
                    fixed(rms, 2),
                    if name.is_empty() { "?" } else { name },
                    fixed(crlb, 2),
                    m.runs,
                    fixed(w.max_abs_error_um_all_runs, 2),
                    fixed(100.0 * w.fraction_runs_max_le_6um, 0),
                    sh(w.target_um)
                ));
            }
        }
    }
    s.push_str("- Files: `designed/robot.toml` (the cube with one `[[sensor]]` per setup, naming the gauge and its bar; the `[[gauge]]`, the candidate `[[socket]]` places and the `[limits]`, so `cpm design --robot designed/robot.toml` designs under the same limits and `cpm calibrate` refuses readings outside a setup's window), `designed/readings.csv` (the simulated readings of this seed, readings format, marked simulated), `designed/setup_sheet.md` and `designed/setup_sheet.csv` (what to mount, then which poses to drive, in order). `cpm calibrate --robot designed/robot.toml --data designed/readings.csv --out cal/` fits them.\n\n");
    s.push_str("| setup | base socket | platform socket | bar (mm) | window (mm) | readings | lengths used (mm) | travel (mm) | min clearance (mm) |\n|---|---|---|---|---|---|---|---|---|\n");
    for st in &l.per_setup {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} .. {} | {} | {} .. {} | {} | {} |\n",
            st.setup,
            st.base_socket,
            st.platform_socket,
            fixed(st.bar_mm, 1),
            fixed(st.window_mm[0], 1),
            fixed(st.window_mm[1], 1),
            st.readings,
            fixed(st.length_range_mm[0], 1),
            fixed(st.length_range_mm[1], 1),
            fixed(st.travel_mm, 1),
            fixed(st.min_clearance_mm, 1)
        ));
    }
    s.push_str("\nHow it was chosen:\n\n");
    for line in &l.log {
        s.push_str(&format!("- {line}\n"));
    }
    if !l.tradeoff.is_empty() {
        s.push_str(&format!(
            "\n### Stroke against precision\n\nThe same limits (clearance {} mm, cones {} deg, at most {} setups) and budget ({} readings) for gauges of shorter stroke (2 mm: a ballbar); Cramér-Rao bounds at the nominal geometry for the paper's noise. The other strokes' searches use at most {} exchanges (the campaign above {}) and no minimax rounds (the campaign above {}), so their worst-parameter column is the A-optimal design's; a setup's readings keep an edge margin of up to a quarter of the stroke inside its window, so a 2 mm ballbar travels at most 1 mm.\n\n| stroke (mm) | setups | readings | rank | Cramér-Rao RMS (um) | worst parameter (um) | largest travel (mm) | smallest clearance (mm) |\n|---|---|---|---|---|---|---|---|\n",
            sh(c.gauge_link_clearance_mm), sh(c.base_cone_deg), c.max_setups, l.max_readings,
            l.tradeoff_exchanges, l.max_exchanges, l.minimax_rounds
        ));
        for t in &l.tradeoff {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                sh(t.stroke_mm),
                t.setups,
                t.readings,
                t.rank,
                fixed(t.crlb_rms_um, 2),
                fixed(t.crlb_max_um, 2),
                fixed(t.max_travel_mm, 1),
                fixed(t.min_clearance_mm, 1)
            ));
        }
    }
    s.push('\n');
    s
}
