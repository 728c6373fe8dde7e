//! `cpm refine`: calibrate, then add the effects that the residual asks for, one at a time,
//! each with an F-test, its BIC change and cross-validation (cpm_calib::refine), and write
//! `refine.json`, `report.md`, `calibration.json`, figures and `calibrated.toml`. The
//! arguments and what is printed; the job is [`cpm_workflow::refine::refine`].
use clap::Args;

use super::common::{self, FitArgs};
use super::{Ctx, Outcome};
pub use cpm_workflow::refine::*;

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
    #[arg(long, value_name = "LIST", value_parser = common::candidate_list)]
    pub candidates: Option<common::EffectList>,
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

impl RefineArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> RefineOptions {
        RefineOptions {
            fit: self.fit.options(),
            candidates: self.candidates.as_ref().map(|l| l.0.clone()),
            max_steps: self.max_steps,
            alpha: self.alpha,
            folds: self.folds,
            pose_map_degree: self.pose_map_degree,
        }
    }
}

/// Runs `cpm refine`: the job, then the commit of its outputs and the summary.
pub fn run(args: &RefineArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let job = refine(&args.options(), &*ctx)?;
    let trouble = job.trouble();
    let Refined {
        inputs,
        result: r,
        set,
        report,
        last_round: last,
    } = job;
    let campaign = &inputs.merged.campaign;
    let dir = &args.fit.out;
    let cal = &r.calibration;
    let inputs_paths = args.fit.input_paths();
    let written = common::commit_dir(set, dir, &inputs_paths, "refine", ctx)?;
    ctx.finish();
    for w in cpm_workflow::fit::warnings(&r.model, cal, report.fit.residual_weighted)
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
        // Weighted figures in sigma (as report.md), never in um.
        let (u, scale) = if report.fit.residual_weighted && report.fit.scale.sigma > 0.0 {
            (" (weighted, in sigma)", report.fit.scale.sigma)
        } else {
            (" um", 1.0)
        };
        writeln!(
            ctx.out,
            "{}added {} effect(s): {}; RMS {:.3} -> {:.3}{u}, cross-validated {:.3}{u}; unexplained structure: {}",
            if campaign.simulated { "SIMULATED data: " } else { "" },
            r.steps.len(),
            if r.steps.is_empty() { "none".to_string() } else { r.steps.iter().map(|s| s.effect.name()).collect::<Vec<_>>().join(", ") },
            r.initial_rms_um / scale,
            cal.residual_rms_um / scale,
            r.final_cv_rms_um / scale,
            if r.unexplained_structure.is_empty() { "none".to_string() } else { r.unexplained_structure.join(", ") }
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(match trouble {
        Some(m) => Outcome::Trouble(m),
        None => Outcome::Done,
    })
}
