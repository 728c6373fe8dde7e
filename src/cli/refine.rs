//! `cpm refine`: calibrate, then add the effects that the residual asks for, one at a time,
//! each with an F-test, its BIC change and cross-validation (cpm_calib::refine), and write
//! `refine.json`, `report.md`, `calibration.json`, figures and `calibrated.toml`.
use clap::Args;

use super::calibrate::{self, provenance_lines, stage_calibrated, stage_figures, FitArgs};
use super::common;
use super::{plots, usage_error, Ctx, Outcome};
use crate::calib::{refine, Effect, RefineOptions};
use crate::io::parse_effects;
use crate::output::OutputSet;
use crate::report::calibrate::CalibratedFile;
use crate::report::fit::FitReport;
use crate::report::refine::{RefineDoc, RefineReport};

/// Arguments of `cpm refine`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm refine --robot examples/hexapod_66.toml --data data.csv --out refined/\n  cpm refine --robot examples/hexapod_66.toml --data data.csv --candidates link_offset,link_scale,backlash --max-steps 2 --out refined/ --json"
)]
pub struct RefineArgs {
    /// Robot, data, effects, noise, solver and output: as for `cpm calibrate`.
    #[command(flatten)]
    pub fit: FitArgs,
    /// Candidate effects, comma-separated (default: the whole library).
    #[arg(long, value_name = "LIST")]
    pub candidates: Option<String>,
    /// Most effects added.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub max_steps: usize,
    /// Significance level of the F-test (before the Bonferroni correction).
    #[arg(long, value_name = "P", default_value_t = 0.01)]
    pub alpha: f64,
    /// Folds of the cross-validation over poses.
    #[arg(long, value_name = "K", default_value_t = 5)]
    pub folds: usize,
    /// Highest degree of the pose error map terms scanned and proposed (0: none, at most 3;
    /// default: 0 with `--candidates`, else `[pose_map] degree` of the description, else 2).
    #[arg(long, value_name = "D")]
    pub pose_map_degree: Option<u8>,
}

/// Runs `cpm refine`.
pub fn run(args: &RefineArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    common::check_out_dir(&args.fit.out)?;
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(usage_error("--alpha must be in (0, 1)"));
    }
    if args.folds < 2 || args.folds > 1000 {
        return Err(usage_error("--folds must be between 2 and 1000"));
    }
    let inputs = args.fit.load(ctx)?;
    let campaign = &inputs.merged.campaign;
    // The library's effects that can act on these data (an explicit list is taken as given).
    let (candidates, not_applicable) = match &args.candidates {
        Some(list) => (
            parse_effects(list).map_err(|m| usage_error(format!("--candidates: {m}")))?,
            Vec::new(),
        ),
        None => applicable(campaign),
    };
    // No hidden load: without a declared [load], the effects whose direction the link
    // forces set are not candidates (an explicit --candidates naming one is an error).
    let (candidates, not_applicable) = if inputs.robot.description.load.is_none() {
        let (skip, keep): (Vec<Effect>, Vec<Effect>) = candidates
            .into_iter()
            .partition(|e| calibrate::needs_load(*e));
        if !skip.is_empty() && args.candidates.is_some() {
            return Err(super::input_error(format!(
                "{}: --candidates names {}, which needs the platform's load, and the description declares none: add a [load] table (docs/formats.md) or leave it out",
                inputs.robot.file,
                skip.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")
            )));
        }
        let mut not_applicable = not_applicable;
        not_applicable.extend(skip.into_iter().map(|e| {
            (
                e,
                "no [load] declared (the link forces that give it its direction need one)",
            )
        }));
        (keep, not_applicable)
    } else {
        (candidates, not_applicable)
    };
    // An explicit --candidates list is the whole candidate set: the pose map scan joins it
    // only when --pose-map-degree asks for it.
    let pose_map_degree = match (args.pose_map_degree, &args.candidates) {
        (Some(d), _) => d,
        (None, Some(_)) => 0,
        (None, None) => inputs
            .robot
            .description
            .pose_map
            .and_then(|p| p.degree)
            .unwrap_or(2),
    };
    if pose_map_degree > 3 {
        return Err(usage_error("--pose-map-degree must be 0 to 3"));
    }
    ctx.stage(format!(
        "refining: {} to {} observations, up to {} effects from {} candidates (each round fits every candidate)",
        common::describe_model(&inputs.model),
        campaign.len(),
        args.max_steps,
        candidates.len()
    ));
    let options = RefineOptions {
        candidates,
        alpha: args.alpha,
        max_steps: args.max_steps,
        folds: args.folds,
        pose_map_degree,
        identify: inputs.identify.clone(),
        ..RefineOptions::default()
    };
    // A pose where the fit cannot start is left out (see `calibrate::leaving_out`).
    let (r, excluded) = calibrate::leaving_out(&inputs, |merged| {
        refine(&inputs.model, &merged.campaign, &options)
    })?;
    common::warn_excluded(
        ctx,
        &excluded.iter().map(|(_, e)| e.clone()).collect::<Vec<_>>(),
    );
    let inputs = if excluded.is_empty() {
        inputs
    } else {
        inputs.without_poses(&excluded)
    };
    let campaign = &inputs.merged.campaign;
    // Never worse than plain calibration on data the fits did not see: otherwise an error,
    // and nothing written.
    if let Some(why) = r.against_calibrate.refusal() {
        return Err(super::trouble(format!("{why}; nothing was written")));
    }
    ctx.stage("writing the results");
    let dir = &args.fit.out;
    let cal = &r.calibration;
    let mut set = OutputSet::new();
    let mut doc = RefineDoc::new(&r, campaign.simulated, options.min_novelty);
    doc.not_applicable = not_applicable
        .iter()
        .map(|(e, why)| crate::report::refine::NotApplicable {
            effect: e.name().to_string(),
            why: why.to_string(),
        })
        .collect();
    set.add(dir.join("refine.json"), doc.to_json()?);
    let mut fit = FitReport::new(&inputs.report_inputs(), &r.model, cal, None);
    calibrate::add_session_warnings(&mut fit, &inputs, &r.model)?;
    set.add(dir.join("calibration.json"), fit.to_json()?);
    calibrate::stage_residuals(&mut set, dir, &inputs, cal);
    let mut figures = stage_figures(&mut set, dir, &inputs.robot, &r.model, campaign, cal)?;
    set.add(
        dir.join("residuals_before_after.svg"),
        plots::residuals_before_after(
            &format!(
                "Residual before and after refinement{}",
                if campaign.simulated {
                    " (SIMULATED)"
                } else {
                    ""
                }
            ),
            campaign,
            &r.initial_residuals_um,
            &cal.residuals_um,
        )?,
    );
    figures.push("residuals_before_after.svg");
    let notes = stage_calibrated(
        &mut set,
        dir,
        &inputs,
        &r.model,
        cal,
        false,
        Some(&r.model.effects),
        "Refined",
        true,
    )?;
    let last = doc.last_round_message();
    let report = RefineReport {
        provenance: provenance_lines(&inputs.provenance, campaign.simulated, "Refined"),
        starting_model: common::describe_model(&inputs.model),
        final_effects: common::effect_list(&r.model.effects),
        calibrated: CalibratedFile {
            minimum_norm: false,
            undetermined: notes.undetermined.len(),
            known_effects: notes.known_effects.clone(),
        },
        figures: figures.iter().map(|f| f.to_string()).collect(),
        significant_pose_structure: {
            let alpha_scan = options.alpha / r.initial_pose_structure.len().max(1) as f64;
            doc.pose_structure
                .iter()
                .filter(|p| p.p_value < alpha_scan)
                .take(3)
                .cloned()
                .collect()
        },
        fit,
        doc,
    };
    let markdown = report.markdown();
    set.add(dir.join("report.md"), markdown.as_str());
    common::stage_report_html(&mut set, dir, "cpm refinement report", &markdown);
    let inputs_paths: Vec<&std::path::Path> = std::iter::once(args.fit.robot.robot.as_path())
        .chain(args.fit.data.iter().map(std::path::PathBuf::as_path))
        .collect();
    let written = common::commit_dir(set, dir, &inputs_paths, "refine", ctx)?;
    ctx.finish();
    for w in calibrate::warnings(&r.model, cal)
        .iter()
        .skip(usize::from(!cal.solver.was_successful()))
    {
        ctx.note(w.replace("**", ""));
    }
    if let Some(m) = &last {
        ctx.note(m.replace('`', ""));
    }
    if args.fit.json {
        writeln!(ctx.out, "{}", report.doc.to_json()?)?;
    } else {
        let u = if report.fit.residual_weighted {
            " (weighted, um of the reference noise)"
        } else {
            " um"
        };
        writeln!(
            ctx.out,
            "{}added {} effect(s): {}; RMS {:.3} -> {:.3}{u}, cross-validated {:.3}{u}; unexplained structure: {}",
            if campaign.simulated { "SIMULATED data: " } else { "" },
            r.steps.len(),
            if r.steps.is_empty() { "none".to_string() } else { r.steps.iter().map(|s| s.effect.name()).collect::<Vec<_>>().join(", ") },
            r.initial_diagnostics.rms_um,
            cal.residual_rms_um,
            r.final_cv_rms_um,
            if r.unexplained_structure.is_empty() { "none".to_string() } else { r.unexplained_structure.join(", ") }
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    if let Some(why) = cal.robust_failure() {
        Ok(Outcome::Trouble(format!(
            "the final fit failed: {why}; the outputs were written and say so"
        )))
    } else if cal.solver.was_successful() {
        Ok(Outcome::Done)
    } else {
        Ok(Outcome::Trouble(format!(
            "the final fit did not converge ({})",
            cal.solver.termination
        )))
    }
}

/// The library's effects split into those that can act on `campaign` and those that cannot,
/// with why: a tracker frame without tracker poses, a thermal drift without a logged
/// temperature, the sensors' effects without gauge readings.
fn applicable(campaign: &crate::calib::Campaign) -> (Vec<Effect>, Vec<(Effect, &'static str)>) {
    let temperatures = campaign.readings.iter().any(|r| r.temperature_c.is_some())
        || campaign
            .pose_measurements
            .iter()
            .any(|p| p.temperature_c.is_some());
    let (mut yes, mut no) = (Vec::new(), Vec::new());
    for e in Effect::ALL {
        let why = match e {
            Effect::TrackerFrame if campaign.pose_measurements.is_empty() => {
                Some("no tracker poses in the data")
            }
            Effect::ThermalDrift if !temperatures => Some("no temperature logged"),
            Effect::SensorOffset | Effect::SensorScale | Effect::SocketError
                if campaign.readings.is_empty() =>
            {
                Some("no gauge readings")
            }
            _ => None,
        };
        match why {
            Some(w) => no.push((e, w)),
            None => yes.push(e),
        }
    }
    (yes, no)
}
