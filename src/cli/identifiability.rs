//! `cpm identifiability`: what a campaign (or a plan, before measuring) can identify. The
//! arguments and what is printed; the job is
//! [`cpm_workflow::identifiability::identifiability`].
use std::path::PathBuf;

use clap::Args;

use super::common::{self, EffectsArg, PlanArgs, RobotArg};
use super::{Ctx, Outcome};
pub use cpm_workflow::identifiability::*;

/// Arguments of `cpm identifiability`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm identifiability --robot examples/paper_cubic.toml --circle\n  cpm identifiability --robot examples/hexapod_66.toml --random 40 --sensors s1,s2,s3 --json\n  cpm identifiability --robot examples/hexapod_66.toml --data data.csv --effects link_offset"
)]
pub struct IdentifiabilityArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Measurement files (readings or tracker poses); repeatable. Or give a plan.
    #[arg(long, value_name = "DATA.csv")]
    pub data: Vec<PathBuf>,
    /// The plan: where the poses come from.
    #[command(flatten)]
    pub plan: PlanArgs,
    /// The effects modelled.
    #[command(flatten)]
    pub effects: EffectsArg,
    /// Noise standard deviation for the Cramér-Rao bounds, um (default: the description's
    /// `[calibration] sensor_noise_um`, else 1: bounds per um of noise).
    #[arg(long, value_name = "UM")]
    pub sigma_um: Option<f64>,
    /// Relative rank threshold: singular values below RTOL x the largest count as zero.
    #[arg(long, value_name = "RTOL", default_value_t = 1e-4)]
    pub rank_rtol: f64,
    /// Print JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// A-priori tolerance of a group, GROUP=VALUE in its unit (as for `cpm calibrate`);
    /// repeatable. With the noise, says which directions a fit would determine and which it
    /// would hold near nominal (docs/estimation.md).
    #[arg(long = "tolerance", value_name = "GROUP=VALUE", value_parser = cpm_workflow::options::parse_tolerance)]
    pub tolerance: Vec<cpm_workflow::options::Tolerance>,
    /// Groups held at nominal (comma-separated), as for `cpm calibrate`.
    #[arg(long, value_delimiter = ',', value_name = "GROUP")]
    pub hold: Vec<cpm_workflow::options::Group>,
}

impl IdentifiabilityArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> IdentifiabilityOptions {
        IdentifiabilityOptions {
            robot: self.robot.robot.clone(),
            data: self.data.clone(),
            plan: self.plan.options(),
            effects: self.effects.given(),
            sigma_um: self.sigma_um,
            rank_rtol: self.rank_rtol,
            tolerance: self.tolerance.clone(),
            hold: self.hold.clone(),
        }
    }
}

/// Runs `cpm identifiability`: the job, then what is printed.
pub fn run(args: &IdentifiabilityArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let Identified {
        doc,
        ident,
        names,
        robot,
        model,
        sigma_um: sigma,
        sigma_declared,
    } = identifiability(&args.options(), &*ctx)?;
    ctx.finish();
    if args.json {
        // Keys sorted, as every cpm JSON file.
        let v = serde_json::to_value(&doc)?;
        writeln!(ctx.out, "{}", serde_json::to_string_pretty(&v)?)?;
        return Ok(Outcome::Done);
    }
    let source = &doc.source;
    let against = &doc.against_tolerances;
    let o = &mut ctx.out;
    writeln!(
        o,
        "Identifiability of {source} on {} ({})",
        robot.file,
        common::describe_model(&model)
    )?;
    if doc.simulated {
        writeln!(o, "(the data are SIMULATED)")?;
    }
    write!(o, "{}", ident.summary())?;
    writeln!(
        o,
        "Cramér-Rao bounds for sensor noise {sigma} um{}: {}",
        if !sigma_declared {
            " (none declared: bounds per um of noise)"
        } else {
            ""
        },
        doc.analysis.crlb_words(|v| format!("{v:.3}"))
    )?;
    if let Some(a) = &against {
        writeln!(
            o,
            "Against the tolerances at noise {sigma} um: {} directions seen by the data better than their tolerance, {} a fit holds near nominal{}",
            a.determined_dimensions,
            a.held_directions.len(),
            if a.held_directions.is_empty() { "" } else { ":" }
        )?;
        for h in a.held_directions.iter().take(12) {
            writeln!(
                o,
                "  {} (data std {:.2e} tolerances)",
                h.description, h.data_std_in_tolerances
            )?;
        }
        if a.held_directions.len() > 12 {
            writeln!(o, "  and {} more (--json)", a.held_directions.len() - 12)?;
        }
    }
    // The rank is decided on the values the threshold applies to: the block-scaled
    // Jacobian's when its columns were scaled (units differ between blocks).
    let decided = if ident.scaled_singular_values.is_empty() {
        writeln!(o, "\nsingular values:")?;
        &ident.singular_values
    } else {
        writeln!(
            o,
            "\nsingular values (of the Jacobian scaled per unit of parameters and per kind of observation, so that the rank does not depend on units or weights):"
        )?;
        &ident.scaled_singular_values
    };
    for (k, s) in decided.iter().enumerate() {
        writeln!(
            o,
            "  {:>3} {:.4e}{}",
            k + 1,
            s,
            if k == ident.rank && ident.rank < ident.num_params {
                "   <- below the rank threshold from here"
            } else {
                ""
            }
        )?;
    }
    writeln!(
        o,
        "\n{:<40} {:>10} {:>13} {:>14}",
        "parameter", "determined", "null fraction", "CRLB std"
    )?;
    for (k, n) in names.iter().enumerate() {
        writeln!(
            o,
            "{:<40} {:>10} {:>13.3e} {:>14}",
            n,
            if ident.determined[k] { "yes" } else { "no" },
            ident.null_fraction[k],
            ident.crlb_std_um[k].map_or("n.d.".to_string(), |s| format!("{s:.4}"))
        )?;
    }
    Ok(Outcome::Done)
}
