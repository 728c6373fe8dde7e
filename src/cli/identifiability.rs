//! `cpm identifiability`: what a campaign (or a plan, before measuring) can identify.
use std::path::PathBuf;

use clap::Args;

use super::common::{self, EffectsArg, PlanArgs, RobotArg};
use super::{usage_error, Ctx, Outcome};
use crate::calib::RankOptions;
use crate::report::fit::{IdentifiabilityDoc, IdentifiabilityReport};

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
    #[arg(long = "tolerance", value_name = "GROUP=VALUE")]
    pub tolerance: Vec<String>,
    /// Groups held at nominal (comma-separated), as for `cpm calibrate`.
    #[arg(long, value_delimiter = ',', value_name = "GROUP")]
    pub hold: Vec<String>,
}

/// Runs `cpm identifiability`.
pub fn run(args: &IdentifiabilityArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    ctx.stage("reading the robot description");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    common::require_six_links(&robot)?;
    let effects = args.effects.resolve(&robot)?;
    let model = robot.model(&effects);
    if !(args.rank_rtol > 0.0 && args.rank_rtol < 1.0) {
        return Err(usage_error("--rank-rtol must be in (0, 1)"));
    }
    let (campaign, source) = match (args.data.is_empty(), args.plan.given()) {
        (false, false) => {
            if !args.plan.sensors.is_empty() {
                return Err(usage_error("--sensors applies to a plan, not to --data"));
            }
            ctx.stage("reading the measurements");
            let merged = common::load_data(&args.data, &robot, &common::read_options(&model))?;
            common::warn_excluded(ctx, &merged.excluded);
            let names: Vec<String> = args.data.iter().map(|p| p.display().to_string()).collect();
            (merged.campaign, names.join(", "))
        }
        (true, true) => {
            ctx.stage("building the plan");
            let spec = common::build_plan(&args.plan, &robot, true)?;
            (spec.skeleton(), "plan".to_string())
        }
        (false, true) => {
            return Err(usage_error(
                "give either --data or a plan (--plan, --circle, --random), not both",
            ))
        }
        (true, false) => return Err(usage_error(
            "give the measurements (--data FILE) or a plan (--plan FILE, --circle or --random N)",
        )),
    };
    let model = match common::with_instruments(&robot, &model, &campaign) {
        Some(m) => {
            ctx.note(common::instruments_note(&m));
            m
        }
        None => model,
    };
    let sigma = match args.sigma_um {
        Some(s) => common::sigma(Some(s), &robot)?.unwrap_or(1.0),
        None => robot.sensor_noise_um().unwrap_or(1.0),
    };
    ctx.stage(format!(
        "analysing {} observations, {}",
        campaign.len(),
        common::describe_model(&model)
    ));
    let options = RankOptions {
        rank_rtol: args.rank_rtol,
        ..RankOptions::default()
    };
    let ident = crate::calib::identifiability(&model, &campaign, sigma, &options)?;
    // Against the tolerances at this noise: what a fit determines, what it holds.
    let tolerances = cpm_workflow::fit::tolerances_of(&robot, &args.tolerance, &args.hold, false)?;
    let prior = crate::calib::prior::prior_std(&model, &tolerances)
        .map_err(|e| usage_error(format!("tolerances: {e}")))?;
    let names = model.parameter_names();
    let against = if prior.iter().any(|p| p.is_finite()) {
        let j = crate::calib::identification_jacobian(
            &model,
            &campaign,
            &vec![0.0; model.num_params()],
        )?;
        Some(crate::report::identifiability::AgainstTolerances::new(
            &j, &prior, sigma, &names,
        ))
    } else {
        None
    };
    ctx.finish();
    if args.json {
        let doc = IdentifiabilityDoc {
            analysis: IdentifiabilityReport::new(&ident, &names),
            source: source.clone(),
            simulated: campaign.simulated && !args.data.is_empty(),
            effects: effects.iter().map(|e| e.name().to_string()).collect(),
            against_tolerances: against,
        };
        // Keys sorted, as every cpm JSON file.
        let v = serde_json::to_value(&doc)?;
        writeln!(ctx.out, "{}", serde_json::to_string_pretty(&v)?)?;
        return Ok(Outcome::Done);
    }
    let o = &mut ctx.out;
    writeln!(
        o,
        "Identifiability of {source} on {} ({})",
        robot.file,
        common::describe_model(&model)
    )?;
    if campaign.simulated && !args.data.is_empty() {
        writeln!(o, "(the data are SIMULATED)")?;
    }
    write!(o, "{}", ident.summary())?;
    writeln!(
        o,
        "Cramér-Rao bounds for sensor noise {sigma} um{}: RMS {}, worst {}",
        if args.sigma_um.is_none() && robot.sensor_noise_um().is_none() {
            " (none declared: bounds per um of noise)"
        } else {
            ""
        },
        fmt_opt(ident.crlb_rms_um()),
        fmt_opt(ident.crlb_max_um())
    )?;
    if let Some(a) = &against {
        writeln!(
            o,
            "Against the tolerances at noise {sigma} um: {} directions determined better than their tolerance, {} a fit holds near nominal{}",
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
    writeln!(o, "\nsingular values:")?;
    for (k, s) in ident.singular_values.iter().enumerate() {
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

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("n.d.".to_string(), |x| format!("{x:.3}"))
}
