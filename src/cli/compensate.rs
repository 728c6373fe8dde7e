//! `cpm compensate`: the actuator commands that bring a calibrated machine to target poses.
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
use crate::calib::effects::{is_link_effect, PoseContext};
use crate::calib::MeasurementModel;
use crate::io::{self, campaign::check_reachable, ReadOptions};
use crate::output::Target;

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

/// Fixed-point iterations of the commanded lengths against the known link effects.
const COMMAND_ITERATIONS: usize = 8;

/// What the commands of one target came out as.
#[derive(Debug, Clone)]
pub struct Commands {
    /// Commanded link lengths, mm.
    pub lengths_mm: Vec<f64>,
    /// Readings to command, in each link's reading units.
    pub readings: Vec<f64>,
    /// The pose context of this target (the next target's `previous`).
    pub context: PoseContext,
    /// The largest change of a commanded length in the last fixed-point iteration, mm.
    pub last_change_mm: f64,
}

/// Link lengths (mm) and readings that a machine described by `robot` (its measurement model
/// `model`, with the known effect values) needs to reach `pose`, coming from the target whose
/// context is `previous`.
pub fn commands_for(
    robot: &io::Robot,
    model: &MeasurementModel,
    pose: &crate::geometry::Pose,
    previous: Option<&PoseContext>,
    temperature_c: Option<f64>,
) -> Result<Commands, cpm_clearance::ClearanceError> {
    // A known pose error map moves the platform by `twist` from where the lengths put it:
    // aim at the target moved back (the map's variable is the commanded pose; the twist is
    // micrometres, so evaluating it at the target rather than the aim is second order).
    let pose = &pose_map_aim(robot, model, pose, previous, temperature_c)?;
    let mut target = cpm_kinematics::inverse_lengths(&robot.table, pose);
    if model.clearance.radius_um > 0.0 {
        let shift =
            model
                .clearance
                .link_corrections_mm(model.statics_table(), pose, &model.load)?;
        for (l, s) in target.iter_mut().zip(shift) {
            *l -= s;
        }
    }
    let mut lengths = target.clone();
    let mut context = model.pose_context(pose, lengths.clone(), previous, temperature_c, None)?;
    let mut last_change_mm = 0.0;
    if model.known_effects.iter().any(|k| is_link_effect(k.effect)) {
        for _ in 0..COMMAND_ITERATIONS {
            let shift = model.known_link_shift_mm(&context, 0.0);
            let next: Vec<f64> = target.iter().zip(&shift).map(|(t, s)| t - s).collect();
            last_change_mm = next
                .iter()
                .zip(&lengths)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            lengths = next;
            context = model.pose_context(pose, lengths.clone(), previous, temperature_c, None)?;
            if last_change_mm < 1e-9 {
                break;
            }
        }
    }
    let readings = lengths
        .iter()
        .enumerate()
        .map(|(i, l)| robot.reading(i, *l))
        .collect();
    Ok(Commands {
        lengths_mm: lengths,
        readings,
        context,
        last_change_mm,
    })
}

/// The pose to command so that a known pose error map puts the platform at `pose`.
fn pose_map_aim(
    robot: &io::Robot,
    model: &MeasurementModel,
    pose: &crate::geometry::Pose,
    previous: Option<&PoseContext>,
    temperature_c: Option<f64>,
) -> Result<crate::geometry::Pose, cpm_clearance::ClearanceError> {
    if !model
        .known_effects
        .iter()
        .any(|k| k.effect.acts_through(crate::calib::Channel::PlatformPose))
    {
        return Ok(*pose);
    }
    let lengths = cpm_kinematics::inverse_lengths(&robot.table, pose);
    let context = model.pose_context(pose, lengths, previous, temperature_c, None)?;
    Ok(pose.perturbed(&-model.known_pose_twist(&context, pose, 0.0)))
}

/// True when `pose` lies outside the range `[pose_map]` says the known pose map was fitted on.
fn outside_pose_map_range(robot: &io::Robot, pose: &crate::geometry::Pose) -> bool {
    match robot.description.pose_map {
        Some(crate::geometry::description::PoseMapSpec {
            fitted_min: Some(min),
            fitted_max: Some(max),
            ..
        }) => !crate::calib::refine::PoseRange { min, max }.contains(pose, 1e-6),
        _ => false,
    }
}

/// The warning of a compensation with a calibration that left `undetermined` parameters
/// (and could not see `blind`, in words): the commands cannot correct them.
pub fn undetermined_warning(file: &str, undetermined: &[String], blind: &[String]) -> String {
    let shown: Vec<&str> = undetermined.iter().take(8).map(String::as_str).collect();
    let more = undetermined.len().saturating_sub(shown.len());
    format!(
        "the calibration in {file} left {} parameter(s) undetermined by its data ({}{}){}: they stay at the fit's minimum-norm point, not measured values, and the commands cannot correct the machine's errors along them",
        undetermined.len(),
        shown.join(", "),
        if more > 0 {
            format!(", and {more} more")
        } else {
            String::new()
        },
        if blind.is_empty() {
            String::new()
        } else {
            format!("; the data could not see: {}", blind.join("; "))
        }
    )
}

/// Runs `cpm compensate`.
pub fn run(args: &CompensateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    if args.json && args.out.as_deref().is_none_or(|o| o.as_os_str() == "-") {
        return Err(usage_error(
            "--json needs --out FILE (the commands would share stdout)",
        ));
    }
    let inputs: [&std::path::Path; 2] = [&args.robot.robot, &args.poses];
    if let Some(out) = &args.out {
        common::out_target("--out", out, &inputs)?;
    }
    ctx.stage("reading the robot description");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    let file = args.poses.display().to_string();
    let targets = io::read_pose_list_file(&args.poses)?;
    io::campaign::check_pose_list_units(&targets, &file, &robot)?;
    ctx.stage(format!("computing commands for {} targets", targets.len()));
    let ratio = ReadOptions::default().max_condition_ratio;
    if let Some(t) = args.temperature_c {
        if !(t.is_finite() && (-273.15..=1000.0).contains(&t)) {
            return Err(usage_error(format!(
                "--temperature-c {t}: not a temperature between -273.15 and 1000 deg C"
            )));
        }
    }
    let model = robot.model(&[]);
    let mut previous = if args.from_home {
        let home = robot.table.home;
        let l = cpm_kinematics::inverse_lengths(&robot.table, &home);
        Some(
            model
                .pose_context(&home, l, None, args.temperature_c, None)
                .map_err(|e| io::InputError::file(&robot.file, format!("home pose: {e}")))?,
        )
    } else {
        None
    };
    let mut readings = Vec::with_capacity(targets.len());
    let mut lengths = Vec::with_capacity(targets.len());
    for t in &targets {
        check_reachable(&robot.table, &t.pose, ratio, &file, t.line, &t.label)?;
        let c = commands_for(
            &robot,
            &model,
            &t.pose,
            previous.as_ref(),
            args.temperature_c,
        )
        .map_err(|e| io::InputError::line(&file, t.line, format!("pose {:?}: {e}", t.label)))?;
        if c.last_change_mm > 1e-6 {
            return Err(super::trouble(format!(
                "pose {:?} (line {}): the commands did not settle against the known link effects (last change {:.2e} mm after {COMMAND_ITERATIONS} iterations)",
                t.label, t.line, c.last_change_mm
            )));
        }
        let (l, u) = (c.lengths_mm, c.readings);
        previous = Some(c.context);
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
    let outside: Vec<&str> = targets
        .iter()
        .filter(|t| outside_pose_map_range(&robot, &t.pose))
        .map(|t| t.label.as_str())
        .collect();
    let note = format!(
        "{}robot {}, targets {}; readings to command (length = length_at_zero_mm + mm_per_unit * reading)",
        if common::simulated(&robot) {
            "SIMULATED calibration (fitted to simulated data), "
        } else {
            ""
        },
        robot.file,
        file
    );
    let csv =
        crate::report::format::tidy_csv(&io::write_commands(&targets, &readings, &lengths, &note));
    ctx.finish();
    let (undetermined, blind) = robot
        .description
        .calibration
        .as_ref()
        .map_or((Vec::new(), Vec::new()), |c| {
            (c.undetermined.clone(), c.blind_directions.clone())
        });
    if !undetermined.is_empty() {
        ctx.note(undetermined_warning(&robot.file, &undetermined, &blind));
    }
    if !outside.is_empty() {
        ctx.note(format!(
            "{} target(s) lie outside the pose range the pose error map of {} was fitted on ([pose_map]); the map does not extrapolate, so their commands carry its error unknown: {}",
            outside.len(),
            robot.file,
            outside.join(", ")
        ));
    }
    match &args.out {
        Some(out) => {
            if common::write_out("--out", out, &inputs, &csv, ctx)? == Target::Stdout {
                return Ok(Outcome::Done);
            }
            if args.json {
                let summary = crate::report::commands::CompensateSummary {
                    clearance_um: robot.clearance().radius_um,
                    known_effects: model
                        .known_effects
                        .iter()
                        .map(|k| k.effect.name().to_string())
                        .collect(),
                    out: out.display().to_string(),
                    outside_pose_map_range: outside.iter().map(|s| s.to_string()).collect(),
                    robot: robot.file.clone(),
                    targets: targets.len(),
                    undetermined: undetermined.clone(),
                    blind_directions: blind.clone(),
                };
                writeln!(ctx.out, "{}", summary.to_json())?;
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
