//! `cpm compensate`: the actuator commands that bring a calibrated machine to target poses.
//!
//! For each target the link lengths are the inverse kinematics with the calibrated joints,
//! minus the joint clearance shift the description's `[clearance]` and `[load]` predict (the
//! machine adds it back), turned into readings with each link's reading model (where a
//! calibrated description carries `link_offset` and `link_scale`).
use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use super::common::{self, RobotArg};
use super::{usage_error, Ctx, Outcome};
use crate::io::{self, campaign::check_reachable, ReadOptions};
use crate::output::OutputSet;

/// Arguments of `cpm compensate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm compensate --robot cal/calibrated.toml --poses targets.csv --out commands.csv\n  cpm compensate --robot cal/calibrated.toml --poses targets.csv   # CSV on stdout"
)]
pub struct CompensateArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Target poses (a list of poses, docs/formats.md).
    #[arg(long, value_name = "TARGETS.csv")]
    pub poses: PathBuf,
    /// Output CSV file (default: stdout).
    #[arg(long, value_name = "COMMANDS.csv")]
    pub out: Option<PathBuf>,
    /// Print a JSON summary on stdout (needs --out).
    #[arg(long)]
    pub json: bool,
}

/// Link lengths (mm) and readings that a machine described by `robot` needs to reach `pose`.
pub fn commands_for(
    robot: &io::Robot,
    pose: &crate::geometry::Pose,
) -> Result<(Vec<f64>, Vec<f64>), cpm_clearance::ClearanceError> {
    let mut lengths = cpm_kinematics::inverse_lengths(&robot.table, pose);
    let clearance = robot.clearance();
    if clearance.radius_um > 0.0 {
        let shift = clearance.link_corrections_mm(&robot.table, pose, &robot.platform_load())?;
        for (l, s) in lengths.iter_mut().zip(shift) {
            *l -= s;
        }
    }
    let readings = lengths
        .iter()
        .enumerate()
        .map(|(i, l)| robot.reading(i, *l))
        .collect();
    Ok((lengths, readings))
}

/// Runs `cpm compensate`.
pub fn run(args: &CompensateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    if args.json && args.out.is_none() {
        return Err(usage_error(
            "--json needs --out (the commands would share stdout)",
        ));
    }
    ctx.stage("reading the robot description");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    let file = args.poses.display().to_string();
    let targets = io::read_pose_list_file(&args.poses)?;
    ctx.stage(format!("computing commands for {} targets", targets.len()));
    let ratio = ReadOptions::default().max_condition_ratio;
    let mut readings = Vec::with_capacity(targets.len());
    let mut lengths = Vec::with_capacity(targets.len());
    for t in &targets {
        check_reachable(&robot.table, &t.pose, ratio, &file, t.line, &t.label)?;
        let (l, u) = commands_for(&robot, &t.pose)
            .map_err(|e| io::InputError::line(&file, t.line, format!("pose {:?}: {e}", t.label)))?;
        for (i, li) in l.iter().enumerate() {
            if let Some((lo, hi)) = robot.table.links[i].length_limits_mm {
                if *li < lo || *li > hi {
                    return Err(io::InputError::line(
                        &file,
                        t.line,
                        format!(
                            "pose {:?}: link {} would be commanded to {li:.3} mm, outside its limits [{lo}, {hi}] mm",
                            t.label,
                            i + 1
                        ),
                    )
                    .into());
                }
            }
        }
        lengths.push(l);
        readings.push(u);
    }
    let note = format!(
        "robot {}, targets {}; readings to command (length = length_at_zero_mm + mm_per_unit * reading)",
        robot.file, file
    );
    let csv = io::write_commands(&targets, &readings, &lengths, &note);
    ctx.finish();
    match &args.out {
        Some(out) => {
            let mut set = OutputSet::new();
            set.add(out, csv);
            common::commit(set, &out.display().to_string())?;
            if args.json {
                let v = json!({
                    "out": out.display().to_string(),
                    "targets": targets.len(),
                    "robot": robot.file,
                    "clearance_um": robot.clearance().radius_um,
                });
                writeln!(ctx.out, "{}", serde_json::to_string_pretty(&v)?)?;
            } else {
                writeln!(
                    ctx.out,
                    "{} commands from {} -> {}",
                    targets.len(),
                    robot.file,
                    out.display()
                )?;
            }
        }
        None => write!(ctx.out, "{csv}")?,
    }
    Ok(Outcome::Done)
}
