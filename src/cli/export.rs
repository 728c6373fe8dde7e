//! `cpm export`: a (calibrated) robot's joint coordinates for a machine controller.
//!
//! `linuxcnc`: HAL `setp` lines for the genhexkins kinematics module,
//! `genhexkins.base.N.x|y|z` (base joints in the base frame) and
//! `genhexkins.platform.N.x|y|z` (platform joints in the platform frame), N = 0..5.
use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::common::{self, RobotArg};
use super::{input_error, Ctx, Outcome};
use crate::io::Robot;
use crate::output::Target;

/// Export formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// LinuxCNC genhexkins HAL settings (`setp genhexkins.base.0.x ...`).
    Linuxcnc,
}

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
}

/// The genhexkins settings of a six-link robot.
pub fn linuxcnc(robot: &Robot) -> String {
    let mut s = format!(
        "# LinuxCNC genhexkins joint coordinates of {}{}, written by cpm {}.\n",
        robot.file,
        robot
            .description
            .name
            .as_ref()
            .map(|n| format!(" ({n})"))
            .unwrap_or_default(),
        env!("CARGO_PKG_VERSION")
    );
    s.push_str(
        "# Base joints in the base (world) frame, platform joints in the platform frame, mm\n",
    );
    s.push_str(
        "# (LinuxCNC machine units must be mm). Load with `loadrt genhexkins` in the HAL file.\n",
    );
    if !robot.readings_are_lengths() {
        s.push_str("# The links' reading models (length_at_zero_mm, mm_per_unit) are not genhexkins settings:\n");
        for (i, l) in robot.description.links.iter().enumerate() {
            s.push_str(&format!(
                "#   joint {i}: length = {} + {} * reading (mm); set the joint's scale and home offset to match\n",
                l.length_at_zero_mm, l.mm_per_unit
            ));
        }
    }
    // Checked when the description was loaded.
    let known: Vec<String> = robot
        .known_effects()
        .unwrap_or_default()
        .iter()
        .map(|k| k.effect.name().to_string())
        .collect();
    if !known.is_empty() {
        s.push_str(&format!(
            "# Not in genhexkins: the known effects {} of [calibration.known_effects]; `cpm compensate` applies them to target poses.\n",
            known.join(", ")
        ));
    }
    for (side, name) in [(0, "base"), (1, "platform")] {
        for (i, l) in robot.table.links.iter().enumerate() {
            let p = if side == 0 { l.base_mm } else { l.platform_mm };
            for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                s.push_str(&format!(
                    "setp genhexkins.{name}.{i}.{axis} {:.6}\n",
                    p[a] + 0.0
                ));
            }
        }
    }
    s
}

/// Runs `cpm export`.
pub fn run(args: &ExportArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let inputs: [&std::path::Path; 1] = [&args.robot.robot];
    if let Some(out) = &args.out {
        common::out_target("--out", out, &inputs)?;
    }
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    let text = match args.format {
        Format::Linuxcnc => {
            if robot.num_links() != 6 {
                return Err(input_error(format!(
                    "{}: genhexkins has six struts; this robot has {} links",
                    robot.file,
                    robot.num_links()
                )));
            }
            linuxcnc(&robot)
        }
    };
    ctx.finish();
    match &args.out {
        Some(out) => {
            if common::write_out("--out", out, &inputs, &text, ctx)? != Target::Stdout {
                writeln!(ctx.out, "wrote {}", out.display())?;
            }
        }
        None => write!(ctx.out, "{text}")?,
    }
    Ok(Outcome::Done)
}
