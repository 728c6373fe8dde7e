//! `cpm calibrate`: fit the installation errors and declared effects to measurements, and
//! write `calibration.json`, `report.md`, SVG figures and `calibrated.toml`. The arguments and
//! what is printed; the job is [`cpm_workflow::fit::calibrate`].
use clap::Args;

use super::common;
pub use super::common::FitArgs;
use super::{Ctx, Outcome};
pub use cpm_workflow::fit::*;

/// Arguments of `cpm calibrate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm calibrate --robot examples/hexapod_66.toml --data data.csv --out cal/\n  cpm calibrate --robot examples/hexapod_66.toml --data data.csv --data tracker.csv --effects link_offset,link_scale,tracker_frame --out cal_both/ --json"
)]
pub struct CalibrateArgs {
    /// Robot, data, effects, noise, solver and output: as for `cpm refine`.
    #[command(flatten)]
    pub fit: FitArgs,
    /// Kept for compatibility: calibrated.toml always holds the fit's complete point (the
    /// minimum-norm solution when the data do not determine every parameter), which
    /// reproduces the fit; the undetermined components are named in its header.
    #[arg(long)]
    pub minimum_norm: bool,
    /// Formulation of the fit: `auto` (nested below 100,000 readings, implicit from there
    /// when the campaign has length readings only and the fit is plain least squares),
    /// `nested` or `implicit`. The report and calibration.json say which was used.
    #[arg(long, value_enum, default_value_t = super::formulation::FormulationArg::Auto)]
    pub formulation: super::formulation::FormulationArg,
}

impl CalibrateArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> CalibrateOptions {
        CalibrateOptions {
            fit: self.fit.options(),
            minimum_norm: self.minimum_norm,
            formulation: self.formulation,
        }
    }
}

/// Runs `cpm calibrate`: the job, then the commit of its outputs and the summary.
pub fn run(args: &CalibrateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let job = cpm_workflow::fit::calibrate(&args.options(), &*ctx)?;
    let trouble = job.trouble();
    let Calibrated { inputs, fitted } = job;
    let Fitted {
        cal, set, report, ..
    } = fitted;
    let model = &inputs.model;
    ctx.stage("writing the results");
    let dir = &args.fit.out;
    let written = common::commit_dir(set, dir, &args.fit.input_paths(), "calibrate", ctx)?;
    ctx.finish();
    for w in warnings(model, &cal, report.fit.residual_weighted)
        .iter()
        .skip(usize::from(!cal.succeeded()))
    {
        ctx.note(w.replace("**", ""));
    }
    for w in report.fit.warnings.iter().filter(|w| {
        w.starts_with("Estimates move between sessions")
            || w.starts_with("Tracker frame held fixed")
            || w.starts_with("Noise not as weighed")
            || w.starts_with("Noise estimated, none declared")
            || w.starts_with("Held near nominal")
            || w.starts_with("Beyond tolerance")
            || w.starts_with("Held at tolerance")
            || w.starts_with(&NOT_WHITE.replace("**", ""))
    }) {
        ctx.note(w);
    }
    if args.fit.json {
        let files = written.iter().map(|p| p.display().to_string()).collect();
        let summary = report.summary(dir.display().to_string(), files);
        writeln!(ctx.out, "{}", summary.to_json()?)?;
    } else {
        let residual = if report.fit.residual_weighted {
            let kinds: Vec<String> = report
                .fit
                .noise_by_kind
                .iter()
                .map(|k| format!("{} {:.3} {}", k.kind, k.rms, k.unit))
                .collect();
            format!(
                "weighted residual RMS {} in sigma (RMS per kind: {})",
                if report.fit.scale.residual_rms
                    < cpm_workflow::calib::diagnostics::NUMERICAL_RESIDUAL_UM
                {
                    report.fit.weighted_rms_words()
                } else {
                    format!("{:.3}", report.fit.weighted_rms_in_sigma)
                },
                kinds.join(", ")
            )
        } else {
            format!("residual RMS {:.3} um", cal.residual_rms_um)
        };
        writeln!(
            ctx.out,
            "{}rank {} of {}, parameters: {}; {residual}; solver: {}",
            if cal.simulated {
                "SIMULATED data: "
            } else {
                ""
            },
            cal.identifiability.rank,
            cal.identifiability.num_params,
            report.fit.determination.words(),
            cal.solver.termination
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
