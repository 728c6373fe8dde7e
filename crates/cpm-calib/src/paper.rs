//! The paper's numerical example (Lim et al. 2002, section 6) and a campaign that does
//! identify all 36 errors: the computations behind `cargo xtask reproduce-paper`.
//!
//! Everything here is simulation: the readings are made from the paper's Table 2 through the
//! measurement model, with the paper's clearance and noise.
use cpm_geometry::{InstallationErrors, JointTable, Pose};
use serde::{Deserialize, Serialize};

use crate::analysis::identifiability::{Identifiability, RankOptions};
use crate::data::campaign::{paper_circle, Plan};
use crate::design::candidates::Workspace;
use crate::design::{
    Design, DesignOptions, MonteCarloOptions, MonteCarloReport, ObservabilityIndices,
    SocketCandidates,
};
use crate::model::{predict, Prepared};
use crate::{
    accuracy, identify, simulate, AccuracyReport, CalibError, Calibration, IdentifyOptions,
    MeasurementModel, Noise, SimulationOptions,
};

/// RMS and max of a difference of two error sets, um.
pub fn rms_max_diff(a: &[f64], b: &[f64]) -> (f64, f64) {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt();
    let max = d.iter().map(|x| x.abs()).fold(0.0, f64::max);
    (rms, max)
}

/// Flips the sign of the platform-side components (the `p - dp` convention expressed in
/// `p + dp` terms).
pub fn platform_negated(errors_um: &[f64]) -> Vec<f64> {
    errors_um
        .iter()
        .enumerate()
        .map(|(k, v)| if (k % 6) >= 3 { -v } else { *v })
        .collect()
}

/// Noise-free readings of a campaign plan for installation errors `errors_um`, mm.
pub fn noise_free_readings(
    model: &MeasurementModel,
    plan: &Plan,
    errors_um: &[f64],
) -> Result<Vec<f64>, CalibError> {
    let c = plan.skeleton();
    let prepared = Prepared::new(model, &c)?;
    predict(model, &prepared, &c, errors_um, None)
}

/// RMS difference (um) between the readings predicted with Table 3 and with Table 2 on the
/// paper's circle, with platform errors applied as `p + dp` (`plus`) and `p - dp` (`minus`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Table3Check {
    /// Platform side as `p + dp`.
    pub plus: f64,
    /// Platform side as `p - dp`.
    pub minus: f64,
}

/// Computes [`Table3Check`] for a plan.
pub fn table3_check(model: &MeasurementModel, plan: &Plan) -> Result<Table3Check, CalibError> {
    let t2 = InstallationErrors::paper_table2().to_vec_um();
    let t3 = InstallationErrors::paper_table3().to_vec_um();
    let diff = |a: &[f64], b: &[f64]| -> Result<f64, CalibError> {
        let ya = noise_free_readings(model, plan, a)?;
        let yb = noise_free_readings(model, plan, b)?;
        Ok(rms_max_diff(&ya, &yb).0 * 1e3)
    };
    Ok(Table3Check {
        plus: diff(&t3, &t2)?,
        minus: diff(&platform_negated(&t3), &platform_negated(&t2))?,
    })
}

// The general generators once lived here; their paths are kept.
pub use crate::data::poses::{j1_condition, random_poses, random_workspace_poses};
pub use crate::data::sensors::designed_sensors;

/// Settings of the reproduction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperOptions {
    /// Seed of the simulated noise. Default 2002.
    pub seed: u64,
    /// Noise, default the paper's uniform +-10 um.
    pub noise: Noise,
    /// The optimised design: reading budget (default 2000), sockets (default 4 base x 4
    /// platform from [`SocketCandidates::paper_cubic`], hence 125 poses), criterion (default
    /// A-optimal). Its `sigma_um` is replaced by the noise's.
    pub design: DesignOptions,
    /// Random candidate poses for the design (ballbar circles are added). Default 3000.
    pub design_candidates: usize,
    /// Half range of the candidate poses' positions about home, mm. Default 100.
    pub designed_range_mm: f64,
    /// Half range of the candidate poses' roll, pitch and yaw, deg. Default 25 (with a tilt
    /// limit of 30 deg and J1's condition number at most 3 times its value at home).
    pub designed_range_deg: f64,
    /// Monte Carlo runs of the designed campaign (seeds `seed + 1000 ..`); 0 for none.
    /// Default 100.
    pub monte_carlo_runs: usize,
    /// Validation poses for the accuracy figures. Default 200.
    pub validation_poses: usize,
    /// Damping of the paper-design fit. Default: the paper's cubic-interpolation rule.
    pub paper_damping: cpm_lm::Damping,
    /// The campaign under an instrument's limits (and its stroke trade-off); `None` to skip.
    /// Default [`LimitedOptions::default`].
    pub limited: Option<LimitedOptions>,
}

/// Settings of the campaign under limits (issue: experiments a real instrument can run).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimitedOptions {
    /// Gauge stroke per setup, mm. Default 200.
    pub stroke_mm: f64,
    /// Smallest gauge-link clearance, mm. Default 30.
    pub clearance_mm: f64,
    /// Largest joint cone angle (base and platform), deg. Default 40.
    pub cone_deg: f64,
    /// Most setups. Default 24 (more setups, more socket pairs: a flatter spread of the 36
    /// errors' variances than 16 for the same 2000 readings).
    pub max_setups: usize,
    /// Monte Carlo runs (seeds `seed + 3000 ..`). Default 100.
    pub monte_carlo_runs: usize,
    /// The stroke trade-off: designs for 2 (a ballbar), 20, 50, 100 and 200 mm and their
    /// Cramér-Rao bounds. Default true.
    pub tradeoff: bool,
    /// The search (its reading budget and seed are replaced by the reproduction's).
    /// Default [`crate::design::SetupOptions::default`].
    pub search: crate::design::SetupOptions,
    /// Most exchanges of the trade-off's other strokes (lighter searches). Default 60.
    pub tradeoff_exchanges: usize,
}

impl Default for LimitedOptions {
    fn default() -> Self {
        Self {
            stroke_mm: 200.0,
            clearance_mm: 30.0,
            cone_deg: 40.0,
            max_setups: 24,
            monte_carlo_runs: 100,
            tradeoff: true,
            search: crate::design::SetupOptions::default(),
            tradeoff_exchanges: 60,
        }
    }
}

/// Strokes of the trade-off table, mm.
pub const TRADEOFF_STROKES_MM: [f64; 5] = [2.0, 20.0, 50.0, 100.0, 200.0];

/// One row of the stroke trade-off.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TradeoffRow {
    /// Gauge stroke per setup, mm.
    pub stroke_mm: f64,
    /// Setups used.
    pub setups: usize,
    /// Readings used.
    pub readings: usize,
    /// Rank of the design (of 36).
    pub rank: usize,
    /// Cramér-Rao RMS over the 36 errors, um.
    pub crlb_rms_um: f64,
    /// Largest per-parameter Cramér-Rao standard deviation, um.
    pub crlb_max_um: f64,
    /// Largest gauge travel used in a setup, mm.
    pub max_travel_mm: f64,
    /// Smallest gauge-link clearance met, mm.
    pub min_clearance_mm: f64,
}

/// The campaign under limits.
#[derive(Debug, Clone)]
pub struct LimitedOutcome {
    /// Options used.
    pub options: LimitedOptions,
    /// The design (setups, their poses, figures).
    pub design: crate::design::SetupDesign,
    /// Largest base and platform joint cone angles over the readings, deg.
    pub max_cone_deg: (f64, f64),
    /// The simulated readings of this seed (setup after setup).
    pub data: crate::Campaign,
    /// Estimates of this seed against Table 2: (RMS, max), um.
    pub error_vs_truth_um: Option<(f64, f64)>,
    /// Monte Carlo study, when asked for.
    pub monte_carlo: Option<MonteCarloReport>,
    /// The stroke trade-off, when asked for.
    pub tradeoff: Vec<TradeoffRow>,
}

fn limited_campaign(
    model: &MeasurementModel,
    candidates: &[Pose],
    options: &PaperOptions,
    limited: &LimitedOptions,
    truth: &[f64],
    ident: &IdentifyOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<LimitedOutcome, CalibError> {
    use crate::design::limits::{Clearance, Constraints, Gauge, JointLimits};
    use crate::design::{design_setups, SetupOptions};
    let sigma = options.noise.sigma_um();
    let constraints = |stroke: f64| Constraints {
        gauge: Gauge {
            stroke_mm: stroke,
            sigma_um: sigma,
            ..if stroke <= 2.0 {
                Gauge::ballbar()
            } else {
                Gauge::default()
            }
        },
        clearance: Clearance {
            gauge_link_mm: limited.clearance_mm,
            link_link_mm: None,
        },
        joints: JointLimits {
            base_cone_deg: limited.cone_deg,
            platform_cone_deg: limited.cone_deg,
        },
    };
    let setup_options = SetupOptions {
        max_readings: options.design.max_readings,
        max_setups: limited.max_setups,
        seed: options.seed.wrapping_add(2),
        ..limited.search
    };
    let sockets = SocketCandidates::paper_cubic();
    let run = |stroke: f64, opts: &SetupOptions, progress: &mut dyn FnMut(&str)| {
        let cell = std::cell::RefCell::new(progress);
        design_setups(
            model,
            &sockets,
            candidates,
            &constraints(stroke),
            opts,
            &|stage: &str| (cell.borrow_mut())(stage),
        )
    };
    progress(&format!(
        "campaign under limits: stroke {} mm, clearance {} mm, cones {} deg",
        limited.stroke_mm, limited.clearance_mm, limited.cone_deg
    ));
    let design = run(limited.stroke_mm, &setup_options, progress)?;
    let dmodel = design.model(model);
    let skeleton = design.campaign();
    let sim = SimulationOptions {
        noise: options.noise,
        repeats: 1,
        seed: options.seed,
    };
    let data = crate::simulate_campaign(&dmodel, truth, &skeleton, &sim)?;
    let cal = identify(&dmodel, &data, ident)?;
    let det: Vec<(f64, f64)> = cal
        .estimate_um
        .iter()
        .zip(truth)
        .filter_map(|(e, t)| e.map(|e| (e, *t)))
        .collect();
    let error_vs_truth_um = (!det.is_empty()).then(|| {
        let (a, b): (Vec<f64>, Vec<f64>) = det.into_iter().unzip();
        rms_max_diff(&a, &b)
    });
    let monte_carlo = if limited.monte_carlo_runs > 0 {
        progress(&format!(
            "campaign under limits: Monte Carlo, {} simulated calibrations",
            limited.monte_carlo_runs
        ));
        Some(crate::design::monte_carlo_campaign(
            &dmodel,
            truth,
            &skeleton,
            ident,
            &MonteCarloOptions {
                runs: limited.monte_carlo_runs,
                seed: options.seed.wrapping_add(3000),
                noise: options.noise,
            },
            &|_, _| {},
        )?)
    } else {
        None
    };
    let mut tradeoff = Vec::new();
    if limited.tradeoff {
        // Lighter searches for the table: fewer exchanges, no minimax rounds (the table
        // compares the A-optimal RMS bounds).
        let quick = SetupOptions {
            select: crate::design::SelectOptions {
                max_exchanges: limited.tradeoff_exchanges,
                ..setup_options.select
            },
            minimax_rounds: 0,
            ..setup_options
        };
        for stroke in TRADEOFF_STROKES_MM {
            progress(&format!("stroke trade-off: {stroke} mm"));
            let d = if stroke == limited.stroke_mm {
                design.clone()
            } else {
                run(stroke, &quick, progress)?
            };
            tradeoff.push(TradeoffRow {
                stroke_mm: stroke,
                setups: d.setups.len(),
                readings: d.num_readings(),
                rank: d.indices.rank,
                crlb_rms_um: d.indices.crlb_rms_um,
                crlb_max_um: d.indices.crlb_max_um,
                max_travel_mm: d.max_travel_mm(),
                min_clearance_mm: d.min_clearance_mm(),
            });
        }
    }
    let max_cone_deg = design.max_cone_deg(&model.nominal);
    Ok(LimitedOutcome {
        options: *limited,
        design,
        max_cone_deg,
        data,
        error_vs_truth_um,
        monte_carlo,
        tradeoff,
    })
}

impl Default for PaperOptions {
    fn default() -> Self {
        Self {
            seed: 2002,
            noise: Noise::Uniform {
                half_width_um: 10.0,
            },
            design: DesignOptions::default(),
            design_candidates: 3000,
            designed_range_mm: 100.0,
            designed_range_deg: 25.0,
            monte_carlo_runs: 100,
            validation_poses: 200,
            paper_damping: cpm_lm::Damping::CubicInterpolation,
            limited: Some(LimitedOptions::default()),
        }
    }
}

/// One campaign's outcome.
#[derive(Debug, Clone)]
pub struct CampaignOutcome {
    /// The plan (poses and sensors).
    pub plan: Plan,
    /// The calibration.
    pub calibration: Calibration,
    /// Estimates against Table 2 over determined parameters: (RMS, max), um.
    pub error_vs_truth_um: Option<(f64, f64)>,
    /// Pose accuracy, nominal against calibrated with the well-determined combinations only
    /// ([`Calibration::compensation_um`] with [`COMPENSATION_MAX_STD_UM`]).
    pub accuracy: AccuracyReport,
    /// Pose accuracy with the whole minimum-norm solution (weak combinations included).
    pub accuracy_minimum_norm: AccuracyReport,
}

/// Largest Cramér-Rao standard deviation (um) of a combination used for compensation in the
/// reproduction.
pub const COMPENSATION_MAX_STD_UM: f64 = 10.0;

/// Everything the reproduction reports.
#[derive(Debug, Clone)]
pub struct PaperReproduction {
    /// Options used.
    pub options: PaperOptions,
    /// The paper's design: its circle, one sensor.
    pub paper: CampaignOutcome,
    /// Identifiability of the paper's design at a range of rank thresholds (rtol, rank).
    pub rank_vs_threshold: Vec<(f64, usize)>,
    /// Table 3 against Table 2 through the paper's own readings.
    pub table3: Table3Check,
    /// Table 3 minus Table 2 on the parameters: (RMS, max), um.
    pub table3_vs_table2_um: (f64, f64),
    /// The same as seen in the identifiable subspace of the paper's design: norm of the
    /// projection of Table 3 - Table 2 on that subspace, over the norm of the difference,
    /// for `plus` and `minus`.
    pub table3_visible_fraction: (f64, f64),
    /// The designed campaign.
    pub designed: CampaignOutcome,
    /// Identifiability of the designed plan at the nominal geometry (for the bounds).
    pub designed_identifiability: Identifiability,
    /// The optimised design (sockets, poses, indices, gauge freedoms, how it was found).
    pub design: Design,
    /// Indices of the hand-made campaign of the same budget for comparison: the 16 socket
    /// pairs of [`designed_sensors`] at 125 random poses (+-100 mm, +-25 deg).
    pub handmade_indices: ObservabilityIndices,
    /// Monte Carlo study of the designed campaign, when asked for.
    pub monte_carlo: Option<MonteCarloReport>,
    /// The campaign under an instrument's limits, when asked for.
    pub limited: Option<LimitedOutcome>,
}

fn outcome(
    model: &MeasurementModel,
    plan: Plan,
    truth: &[f64],
    sim: &SimulationOptions,
    ident: &IdentifyOptions,
    validation: &[Pose],
) -> Result<CampaignOutcome, CalibError> {
    let data = simulate(model, truth, &plan, sim)?;
    let calibration = identify(model, &data, ident)?;
    let det: Vec<(f64, f64)> = calibration
        .estimate_um
        .iter()
        .zip(truth)
        .filter_map(|(e, t)| e.map(|e| (e, *t)))
        .collect();
    let error_vs_truth_um = if det.is_empty() {
        None
    } else {
        let (a, b): (Vec<f64>, Vec<f64>) = det.into_iter().unzip();
        Some(rms_max_diff(&a, &b))
    };
    let accuracy_minimum_norm = accuracy(model, truth, &calibration.minimum_norm_um, validation)?;
    let compensation =
        calibration.compensation_um(&vec![0.0; truth.len()], COMPENSATION_MAX_STD_UM);
    let accuracy = accuracy(model, truth, &compensation, validation)?;
    Ok(CampaignOutcome {
        plan,
        calibration,
        error_vs_truth_um,
        accuracy,
        accuracy_minimum_norm,
    })
}

/// Runs the paper's example and the designed campaign. `progress` is told each stage.
pub fn reproduce(
    options: &PaperOptions,
    mut progress: impl FnMut(&str),
) -> Result<PaperReproduction, CalibError> {
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let t3 = InstallationErrors::paper_table3().to_vec_um();
    let sim = SimulationOptions {
        noise: options.noise,
        repeats: 1,
        seed: options.seed,
    };
    let sigma = sim.reading_sigma_um();
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let home = model.nominal.home;
    let validation = random_poses(
        &home,
        options.validation_poses,
        60.0,
        8.0,
        options.seed.wrapping_add(7),
    );

    progress("paper design: the circle, one sensor");
    let paper_plan = Plan {
        poses: paper_circle(&home),
        sensors: vec![0],
    };
    let mut ident = IdentifyOptions {
        sigma_um: Some(sigma),
        ..IdentifyOptions::default()
    };
    ident.lm.damping = options.paper_damping;
    let paper = outcome(
        &model,
        paper_plan.clone(),
        &truth,
        &sim,
        &ident,
        &validation,
    )?;
    let j = crate::identification_jacobian(&model, &paper_plan.skeleton(), &vec![0.0; 36])?;
    let rank_vs_threshold = [1e-3, 3e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 1e-6, 1e-8]
        .iter()
        .map(|&rtol| {
            let a = crate::analyze(
                &j,
                sigma,
                &RankOptions {
                    rank_rtol: rtol,
                    ..RankOptions::default()
                },
                &[],
            );
            (rtol, a.rank)
        })
        .collect();
    let table3 = table3_check(&model, &paper_plan)?;
    let table3_vs_table2_um = rms_max_diff(&t3, &truth);
    let a = crate::analyze(&j, sigma, &RankOptions::default(), &[]);
    let vis = |d: Vec<f64>| {
        let d = nalgebra::DVector::from_vec(d);
        let proj = a.row_space().transpose() * &d;
        proj.norm() / d.norm()
    };
    let d_plus: Vec<f64> = t3.iter().zip(&truth).map(|(a, b)| a - b).collect();
    let table3_visible_fraction = (vis(d_plus.clone()), vis(platform_negated(&d_plus)));

    progress("designed campaign: candidate poses in the workspace");
    let workspace = Workspace::default();
    let (candidates, _) = crate::design::candidates::default_candidates(
        &model.nominal,
        &workspace,
        options.design_candidates,
        options.designed_range_mm,
        options.designed_range_deg,
        options.seed.wrapping_add(1),
    );
    let design_options = DesignOptions {
        sigma_um: sigma,
        ..options.design
    };
    let design = {
        let cell = std::cell::RefCell::new(&mut progress);
        crate::design::design(
            &model,
            &SocketCandidates::paper_cubic(),
            &candidates,
            &design_options,
            &|stage: &str| (cell.borrow_mut())(stage),
        )?
    };
    let handmade_indices = {
        let mut hand = model.clone();
        hand.nominal.sensors = designed_sensors();
        let plan = Plan {
            poses: random_workspace_poses(
                &hand.nominal,
                125,
                options.designed_range_mm,
                options.designed_range_deg,
                3.0,
                options.seed.wrapping_add(1),
            ),
            sensors: (0..hand.nominal.sensors.len()).collect(),
        };
        let j = crate::identification_jacobian(&hand, &plan.skeleton(), &vec![0.0; 36])?;
        crate::design::observability_indices(&j, sigma)
    };
    let dmodel = design.model(&model);
    let dplan = design.plan();
    let mut dident = IdentifyOptions {
        sigma_um: Some(sigma),
        ..IdentifyOptions::default()
    };
    dident.lm.damping = cpm_lm::Damping::Nielsen;
    let designed_identifiability =
        crate::identifiability(&dmodel, &dplan.skeleton(), sigma, &RankOptions::default())?;
    let monte_carlo = if options.monte_carlo_runs > 0 {
        progress(&format!(
            "designed campaign: Monte Carlo, {} simulated calibrations",
            options.monte_carlo_runs
        ));
        Some(crate::design::monte_carlo(
            &dmodel,
            &truth,
            &dplan,
            &dident,
            &MonteCarloOptions {
                runs: options.monte_carlo_runs,
                seed: options.seed.wrapping_add(1000),
                noise: options.noise,
            },
            &|_, _| {},
        )?)
    } else {
        None
    };
    progress("designed campaign: the calibration of this seed");
    let designed = outcome(&dmodel, dplan, &truth, &sim, &dident, &validation)?;
    let limited = match &options.limited {
        Some(l) => Some(limited_campaign(
            &model,
            &candidates,
            options,
            l,
            &truth,
            &dident,
            &mut progress,
        )?),
        None => None,
    };
    Ok(PaperReproduction {
        options: *options,
        paper,
        rank_vs_threshold,
        table3,
        table3_vs_table2_um,
        table3_visible_fraction,
        designed,
        designed_identifiability,
        design,
        handmade_indices,
        monte_carlo,
        limited,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_workspace_poses_take_every_seed() {
        // The batches are seeded `seed, seed + 1, ...`: near u64::MAX they wrap around
        // instead of ending at once (found 0 of 5 before) or overflowing.
        let t = JointTable::paper_cubic();
        for seed in [0, 1, u64::MAX - 1, u64::MAX] {
            let poses = random_workspace_poses(&t, 5, 50.0, 10.0, 3.0, seed);
            assert_eq!(poses.len(), 5, "seed {seed}");
        }
        // Seeds far from the wrap are unchanged: the same poses as before the fix.
        let a = random_workspace_poses(&t, 5, 50.0, 10.0, 3.0, 7);
        let b = random_poses(&t.home, 5, 50.0, 10.0, 7u64.wrapping_mul(7919));
        let kept: Vec<Pose> = b
            .into_iter()
            .filter(|p| {
                cpm_kinematics::reachable_at(&t, p, 3.0 * j1_condition(&t, &t.home)).is_ok()
            })
            .collect();
        assert_eq!(a[..kept.len()], kept[..]);
    }
}
