//! `cpm compensate`: the actuator commands that bring a calibrated machine to target poses.
//! The arguments and where the commands are written; the job is
//! [`cpm_workflow::compensate::compensate`].
//!
//! For each target the link lengths are the inverse kinematics with the calibrated joints,
//! minus the joint clearance shift the description's `[clearance]` and `[load]` predict and
//! minus the length changes of the link effects in `[calibration.known_effects]` (the
//! machine adds both back), turned into readings with each link's reading model (where a
//! calibrated description carries `link_offset` and `link_scale`).
//!
//! The known link effects depend on the commanded lengths (scale-like terms, screw error),
//! so the commands are found by a fixed-point iteration. Backlash depends on the direction
//! each link last moved: the targets are visited in file order, and the first target gets no
//! backlash correction (its approach is unknown) unless `--from-home` says the machine starts
//! at home. `thermal_drift` needs `--temperature-c`; without it no drift is corrected.
//!
//! A known pose error map (`pose_map_*` terms) moves the platform from where the lengths put
//! it: each target is aimed at the target moved back by the map. The map describes the poses
//! it was fitted on only (`[pose_map]` of the description): targets outside are flagged.
use std::path::PathBuf;

use clap::Args;

use super::common::{self, RobotArg};
use super::{usage_error, Ctx, Outcome};
use crate::output::Target;
pub use cpm_workflow::compensate::*;

/// Arguments of `cpm compensate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm compensate --robot cal/calibrated.toml --poses examples/targets.csv --out commands.csv\n  cpm compensate --robot cal/calibrated.toml --poses examples/targets.csv   # CSV on stdout"
)]
pub struct CompensateArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Target poses (a list of poses, docs/formats.md).
    #[arg(long, value_name = "TARGETS.csv")]
    pub poses: PathBuf,
    /// Output CSV file (default, or `-`: stdout). Never a device, FIFO or an input file.
    #[arg(long, value_name = "COMMANDS.csv")]
    pub out: Option<PathBuf>,
    /// Print a JSON summary on stdout (needs --out).
    #[arg(long)]
    pub json: bool,
    /// Temperature of the machine, deg C, for a known `thermal_drift`.
    #[arg(long, value_name = "DEG_C")]
    pub temperature_c: Option<f64>,
    /// The machine comes to the first target from its home pose (sets the first target's
    /// direction of motion for a known `backlash`).
    #[arg(long)]
    pub from_home: bool,
}

impl CompensateArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> CompensateOptions {
        CompensateOptions {
            robot: self.robot.robot.clone(),
            poses: self.poses.clone(),
            out: self.out.clone(),
            temperature_c: self.temperature_c,
            from_home: self.from_home,
        }
    }
}

/// Runs `cpm compensate`: the job, then the commands written where asked.
pub fn run(args: &CompensateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    if args.json && args.out.as_deref().is_none_or(|o| o.as_os_str() == "-") {
        return Err(usage_error(
            "--json needs --out FILE (the commands would share stdout)",
        ));
    }
    let options = args.options();
    let job = compensate(&options, &*ctx)?;
    ctx.finish();
    for w in job.warnings() {
        ctx.note(w);
    }
    if let Some(p) = &job.predicted {
        ctx.note(p.line());
    }
    match &args.out {
        Some(out) => {
            if common::write_out("--out", out, &options.inputs(), &job.csv, ctx)? == Target::Stdout
            {
                return Ok(Outcome::Done);
            }
            if args.json {
                writeln!(ctx.out, "{}", job.summary(out).to_json())?;
            } else {
                writeln!(
                    ctx.out,
                    "{} commands from {} -> {}",
                    job.targets.len(),
                    job.robot.file,
                    out.display()
                )?;
            }
        }
        None => write!(ctx.out, "{}", job.csv)?,
    }
    Ok(Outcome::Done)
}
