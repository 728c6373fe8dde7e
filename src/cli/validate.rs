//! `cpm validate`: a calibrated robot checked on measurements the fit did not use, against a
//! reference (the nominal robot, or any other description). The arguments and what is
//! printed; the jobs are [`cpm_workflow::validate`]'s.
//!
//! Each held-out file is read against each robot (logged link readings become lengths through
//! that robot's reading models), predicted by that robot's measurement model with every known
//! effect applied and nothing estimated, and compared with what was measured: gauge readings
//! as reading errors (um), tracker poses as position errors (um) and orientation errors
//! (urad), point targets as coordinate errors (um) with each file's session frame fitted
//! afresh, inclinometer angles as angle errors (urad) with each file's base re-levelled. The
//! figures are given per sensor (gauge) or per file (tracker, points, tilts), and in all.
//!
//! A file without logged link readings (`reading_k`) was driven by the controller's inverse
//! kinematics of its commanded poses; `cpm validate` takes that controller to be the
//! reference robot's (the nominal description the machine ran with), for both predictions.
use std::path::PathBuf;

use clap::Args;

use super::common;
use super::{Ctx, Outcome};
pub use cpm_workflow::validate::*;

/// Arguments of `cpm validate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm validate --robot cal/calibrated.toml --reference examples/hexapod_66.toml --data held_out.csv\n  cpm validate --robot cal/calibrated.toml --reference examples/hexapod_66.toml --data held_out.csv --data tracker.csv --out validation/ --json\n  cpm validate --reference examples/hexapod_66.toml --commands commands.csv --truth examples/hexapod_66_truth.toml --out compensation/"
)]
pub struct ValidateArgs {
    /// The calibrated robot description (`calibrated.toml` of `cpm calibrate` or `cpm refine`);
    /// not used with `--commands`.
    #[arg(long, value_name = "ROBOT.toml", required_unless_present = "commands")]
    pub robot: Option<PathBuf>,
    /// The reference robot the calibration is judged against, usually the nominal description
    /// the fit started from.
    /// Default: the description `--robot` records it was calibrated from
    /// (`[calibration] calibrated_from`, written by `cpm calibrate` and `cpm refine`).
    #[arg(long, value_name = "REFERENCE.toml")]
    pub reference: Option<PathBuf>,
    /// Held-out measurement files (gauge readings or tracker poses); repeatable.
    #[arg(long, value_name = "DATA.csv", required_unless_present = "commands")]
    pub data: Vec<PathBuf>,
    /// Check a compensation end to end in simulation instead: the machine `--truth` executes
    /// these commands (`cpm compensate`'s output), and the pose it reaches is compared with
    /// each target; the reference is the same machine commanded with the reference robot's
    /// inverse kinematics (no compensation).
    #[arg(
        long,
        value_name = "COMMANDS.csv",
        requires = "truth",
        conflicts_with = "data"
    )]
    pub commands: Option<PathBuf>,
    /// The true machine for `--commands`: a robot description (geometry, link reading models
    /// and `[calibration.known_effects]`), e.g. the `--truth` of `cpm simulate`.
    #[arg(long, value_name = "TRUTH.toml", requires = "commands")]
    pub truth: Option<PathBuf>,
    /// With `--commands`: true values of an effect of the machine, on top of `--truth`'s
    /// `[calibration.known_effects]`, as `cpm simulate --truth-effect` takes them (e.g.
    /// backlash=-8,6,-10,5,-7,9); repeatable.
    #[arg(long, value_name = "EFFECT=V1,V2,..", requires = "commands")]
    pub truth_effect: Vec<String>,
    /// With `--commands`: the machine comes to the first target from its home pose (as
    /// `cpm compensate --from-home` assumed), so the first target's backlash is known.
    #[arg(long, requires = "commands")]
    pub from_home: bool,
    /// With `--commands`: the temperature the machine runs at, deg C (as given to
    /// `cpm compensate --temperature-c`; a known `thermal_drift` acts at it).
    #[arg(long, value_name = "DEG_C", requires = "commands")]
    pub temperature_c: Option<f64>,
    /// Tracker position noise, um: the weight of positions when each held-out tracker session
    /// is registered (default: `[calibration] tracker_position_sigma_um` of `--robot`, which
    /// `cpm calibrate` writes, else cpm-calib's 10 um). The reference is registered alike.
    #[arg(long, value_name = "UM")]
    pub pose_sigma_um: Option<f64>,
    /// Tracker orientation noise, urad (default: `[calibration]
    /// tracker_orientation_sigma_urad` of `--robot`, else cpm-calib's 20 urad).
    #[arg(long, value_name = "URAD")]
    pub orientation_sigma_urad: Option<f64>,
    /// Also write validation.json, report.md, report.html (figure inline), validation.svg
    /// and residuals.csv into this directory (with `--commands`: compensation.json,
    /// report.md and report.html).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

impl ValidateArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> ValidateOptions {
        ValidateOptions {
            robot: self.robot.clone(),
            reference: self.reference.clone(),
            data: self.data.clone(),
            commands: self.commands.clone(),
            truth: self.truth.clone(),
            truth_effect: self.truth_effect.clone(),
            from_home: self.from_home,
            temperature_c: self.temperature_c,
            pose_sigma_um: self.pose_sigma_um,
            orientation_sigma_urad: self.orientation_sigma_urad,
            out: self.out.clone(),
        }
    }
}

/// Runs `cpm validate`.
pub fn run(args: &ValidateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let options = args.options();
    options.validate()?;
    let (json, line, set) = if args.commands.is_some() {
        let c = check_compensation(&options, &*ctx)?;
        (c.report.to_json()?, c.report.console_line(), c.set)
    } else {
        let v = validate(&options, &*ctx)?;
        (v.report.to_json()?, v.report.console_line(), v.set)
    };
    ctx.finish();
    let mut written = Vec::new();
    if let (Some(dir), Some(set)) = (&args.out, set) {
        written = common::commit_dir(set, dir, &options.inputs(), "validate", ctx)?;
    }
    if args.json {
        writeln!(ctx.out, "{json}")?;
    } else {
        writeln!(ctx.out, "{line}")?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}
