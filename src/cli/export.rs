//! `cpm export`: a (calibrated) robot's joint coordinates for a machine controller. The
//! arguments and where the settings are written; the job is [`cpm_workflow::export::export`].
//!
//! `linuxcnc`: HAL `setp` lines for the genhexkins kinematics module,
//! `genhexkins.base.N.x|y|z` (base joints in the base frame) and
//! `genhexkins.platform.N.x|y|z` (platform joints in the platform frame), N = 0..5 (cpm's
//! link N+1), the screw-lead pins when a screw lead is declared, and an INI snippet with each
//! joint's `HOME_OFFSET`, `SCALE` and `BACKLASH`; `--units mm|inch`.
use std::path::PathBuf;

use clap::Args;

use super::common::{self, RobotArg};
use super::{Ctx, Outcome};
use crate::output::Target;
pub use cpm_workflow::export::*;

/// Arguments of `cpm export`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm export --format linuxcnc --robot cal/calibrated.toml\n  cpm export --format linuxcnc --robot cal/calibrated.toml --out hexapod-joints.hal"
)]
pub struct ExportArgs {
    /// Output format.
    #[arg(long, value_enum)]
    pub format: Format,
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Output file (default, or `-`: stdout). Never a device, FIFO or an input file.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Also write the INI snippet (`[JOINT_n]` HOME_OFFSET, SCALE, BACKLASH) to this file,
    /// uncommented (it is always in the HAL output as comments).
    #[arg(long, value_name = "FILE")]
    pub ini: Option<PathBuf>,
    /// Length units of the exported settings.
    #[arg(long, value_enum, default_value_t = Units::Mm)]
    pub units: Units,
}

impl ExportArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> ExportOptions {
        ExportOptions {
            robot: self.robot.robot.clone(),
            format: self.format,
            units: self.units,
            out: self.out.clone(),
            ini: self.ini.clone(),
        }
    }
}

/// Runs `cpm export`: the job, then the settings written where asked.
pub fn run(args: &ExportArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let options = args.options();
    let inputs = options.inputs();
    let Exported { hal: text, ini, .. } = export(&options, &*ctx)?;
    let ini = args.ini.as_ref().zip(ini);
    ctx.finish();
    // Status lines go to stderr whenever stdout carries data (`--ini F > joints.hal`).
    let data_on_stdout = match &args.out {
        None => true,
        Some(out) => common::out_target("--out", out, &inputs)? == Target::Stdout,
    } || match &args.ini {
        Some(path) => common::out_target("--ini", path, &inputs)? == Target::Stdout,
        None => false,
    };
    let wrote = |path: &std::path::Path, ctx: &mut Ctx<'_>| -> anyhow::Result<()> {
        if data_on_stdout {
            ctx.status(format!("wrote {}", path.display()));
        } else {
            writeln!(ctx.out, "wrote {}", path.display())?;
        }
        Ok(())
    };
    if let Some((path, ini)) = &ini {
        if common::write_out("--ini", path, &inputs, ini, ctx)? != Target::Stdout {
            wrote(path, ctx)?;
        }
    }
    match &args.out {
        Some(out) => {
            if common::write_out("--out", out, &inputs, &text, ctx)? != Target::Stdout {
                wrote(out, ctx)?;
            }
        }
        None => write!(ctx.out, "{text}")?,
    }
    Ok(Outcome::Done)
}
