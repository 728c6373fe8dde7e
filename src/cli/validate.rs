//! `cpm validate`: a calibrated robot checked on measurements the fit did not use, against a
//! reference (the nominal robot, or any other description).
//!
//! Each held-out file is read against each robot (logged link readings become lengths through
//! that robot's reading models), predicted by that robot's measurement model with every known
//! effect applied and nothing estimated, and compared with what was measured: gauge readings
//! as reading errors (um), tracker poses as position errors (um) and orientation errors
//! (urad). The figures are given per sensor (gauge) or per file (tracker), and in all.
//!
//! A file without logged link readings (`reading_k`) was driven by the controller's inverse
//! kinematics of its commanded poses; `cpm validate` takes that controller to be the
//! reference robot's (the nominal description the machine ran with), for both predictions.
use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use super::common;
use super::{Ctx, Outcome};
use crate::calib::model::{predict, Prepared};
use crate::calib::{Campaign, MeasurementModel};
use crate::io::{FileKind, ReadOptions, Robot};
use crate::output::OutputSet;

/// Arguments of `cpm validate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm validate --robot cal/calibrated.toml --reference examples/hexapod_66.toml --data held_out.csv\n  cpm validate --robot cal/calibrated.toml --reference robot.toml --data a.csv --data b.csv --out validation/ --json"
)]
pub struct ValidateArgs {
    /// The calibrated robot description (`calibrated.toml` of `cpm calibrate` or `cpm refine`);
    /// not used with `--commands`.
    #[arg(long, value_name = "ROBOT.toml", required_unless_present = "commands")]
    pub robot: Option<PathBuf>,
    /// The reference robot the calibration is judged against, usually the nominal description
    /// the fit started from.
    #[arg(long, value_name = "REFERENCE.toml")]
    pub reference: PathBuf,
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
    /// Also write validation.json, validation.md and validation.svg into this directory.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

impl ValidateArgs {
    /// Every input file (an output may not replace one).
    fn inputs(&self) -> Vec<&std::path::Path> {
        self.robot
            .iter()
            .chain(std::iter::once(&self.reference))
            .chain(self.data.iter())
            .chain(self.commands.iter())
            .chain(self.truth.iter())
            .map(|p| p.as_path())
            .collect()
    }
}

/// Prediction errors of one robot on one group of observations.
#[derive(Debug, Clone, Default)]
struct Errors {
    /// Reading or position errors, um (per coordinate for positions).
    values_um: Vec<f64>,
    /// Orientation errors, urad (per component).
    orientation_urad: Vec<f64>,
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(
        f64::NAN,
        |m, x| if m.is_nan() { x.abs() } else { m.max(x.abs()) },
    )
}

/// The groups (sensor names, or `file (tracker)`) and their errors for one robot.
///
/// A file without logged link readings was driven by the controller's inverse kinematics of
/// the commanded poses: that of `controller` (the reference robot), whichever robot predicts.
fn errors_of(
    robot: &Robot,
    controller: &Robot,
    paths: &[PathBuf],
) -> anyhow::Result<(Vec<String>, Vec<Errors>, bool)> {
    let model: MeasurementModel = robot.model(&[]);
    let options = ReadOptions::default();
    let mut names: Vec<String> = Vec::new();
    let mut groups: Vec<Errors> = Vec::new();
    let mut simulated = false;
    let group_of = |name: String, names: &mut Vec<String>, groups: &mut Vec<Errors>| match names
        .iter()
        .position(|n| *n == name)
    {
        Some(i) => i,
        None => {
            names.push(name);
            groups.push(Errors::default());
            names.len() - 1
        }
    };
    for path in paths {
        let mut file = crate::io::read_data_file(path, robot, &options)?;
        if file.campaign.commanded_lengths_mm.is_none() {
            let lengths = file
                .campaign
                .poses
                .iter()
                .map(|p| crate::kinematics::ik::inverse_lengths(&controller.table, p))
                .collect();
            file.campaign.commanded_lengths_mm = Some(lengths);
        }
        let campaign: &Campaign = &file.campaign;
        simulated |= campaign.simulated;
        let prepared = Prepared::new(&model, campaign).map_err(|e| {
            super::trouble(format!(
                "{}: predicting with {}: {e}",
                file.file, robot.file
            ))
        })?;
        let zeros = vec![0.0; model.num_params()];
        let predicted = predict(&model, &prepared, campaign, &zeros, None).map_err(|e| {
            super::trouble(format!(
                "{}: predicting with {}: {e}",
                file.file, robot.file
            ))
        })?;
        let observed = campaign.observations();
        let nr = campaign.readings.len();
        for (k, r) in campaign.readings.iter().enumerate() {
            let name = robot.table.sensors[r.sensor].name.clone();
            let g = group_of(name, &mut names, &mut groups);
            groups[g].values_um.push((observed[k] - predicted[k]) * 1e3);
        }
        if !campaign.pose_measurements.is_empty() {
            let g = group_of(format!("{} (tracker)", file.file), &mut names, &mut groups);
            for q in 0..campaign.pose_measurements.len() {
                for a in 0..3 {
                    let k = nr + 6 * q + a;
                    groups[g].values_um.push((observed[k] - predicted[k]) * 1e3);
                }
                for a in 3..6 {
                    let k = nr + 6 * q + a;
                    // Orientation observations are mrad.
                    groups[g]
                        .orientation_urad
                        .push((observed[k] - predicted[k]) * 1e3);
                }
            }
        }
        if file.kind == FileKind::Poses {
            return Err(super::usage_error(format!(
                "{}: a pose list has no measurements to validate against",
                file.file
            )));
        }
    }
    Ok((names, groups, simulated))
}

/// Pose errors (position um per target, orientation urad per target) the machine `truth`
/// reaches when it executes link `readings` (its own reading models turn them into lengths,
/// its known effects apply) aiming at `targets`.
fn reached_errors(
    truth: &Robot,
    targets: &[crate::io::PoseRow],
    readings: &[Vec<f64>],
) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let links = &truth.description.links;
    let campaign = Campaign {
        poses: targets.iter().map(|t| t.pose).collect(),
        commanded_lengths_mm: Some(
            readings
                .iter()
                .map(|u| {
                    u.iter()
                        .zip(links)
                        .map(|(u, l)| l.length_at_zero_mm + l.mm_per_unit * u)
                        .collect()
                })
                .collect(),
        ),
        pose_measurements: targets
            .iter()
            .enumerate()
            .map(|(j, t)| crate::calib::campaign::PoseMeasurement {
                pose: j,
                measured: t.pose,
                time_s: t.time_s,
                temperature_c: None,
            })
            .collect(),
        simulated: true,
        ..Campaign::default()
    };
    let model = truth.model(&[]);
    let prepared = Prepared::new(&model, &campaign).map_err(|e| {
        super::trouble(format!(
            "the machine {} executing the commands: {e}",
            truth.file
        ))
    })?;
    let predicted = predict(
        &model,
        &prepared,
        &campaign,
        &vec![0.0; model.num_params()],
        None,
    )
    .map_err(|e| {
        super::trouble(format!(
            "the machine {} executing the commands: {e}",
            truth.file
        ))
    })?;
    let observed = campaign.observations();
    let (mut position_um, mut orientation_urad) = (Vec::new(), Vec::new());
    for q in 0..targets.len() {
        let d = |a: usize| (predicted[6 * q + a] - observed[6 * q + a]) * 1e3;
        position_um.push((d(0).powi(2) + d(1).powi(2) + d(2).powi(2)).sqrt());
        orientation_urad.push((d(3).powi(2) + d(4).powi(2) + d(5).powi(2)).sqrt());
    }
    Ok((position_um, orientation_urad))
}

/// `cpm validate --commands`: a compensation checked end to end on a simulated machine.
fn run_commands(args: &ValidateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let (Some(commands), Some(truth)) = (&args.commands, &args.truth) else {
        return Err(super::usage_error("--commands needs --truth"));
    };
    let reference = common::load_robot(&args.reference, ctx)?;
    let truth = common::load_robot(truth, ctx)?;
    if truth.num_links() != reference.num_links() {
        return Err(super::input_error(format!(
            "{} has {} links, the reference {} has {}",
            truth.file,
            truth.num_links(),
            reference.file,
            reference.num_links()
        )));
    }
    let rows = crate::io::read_commands_file(commands, truth.num_links())?;
    let targets: Vec<crate::io::PoseRow> = rows.iter().map(|r| r.0.clone()).collect();
    let compensated: Vec<Vec<f64>> = rows.iter().map(|r| r.1.clone()).collect();
    // The same targets commanded with the reference robot's inverse kinematics.
    let nominal: Vec<Vec<f64>> = targets
        .iter()
        .map(|t| {
            crate::kinematics::ik::inverse_lengths(&reference.table, &t.pose)
                .iter()
                .zip(&reference.description.links)
                .map(|(l, m)| (l - m.length_at_zero_mm) / m.mm_per_unit)
                .collect()
        })
        .collect();
    let (pos, rot) = reached_errors(&truth, &targets, &compensated)?;
    let (pos_ref, rot_ref) = reached_errors(&truth, &targets, &nominal)?;
    let summary = |p: &[f64], r: &[f64]| {
        json!({
            "position_rms_um": rms(p),
            "position_max_um": max_abs(p),
            "orientation_rms_urad": rms(r),
            "orientation_max_urad": max_abs(r),
        })
    };
    let value = json!({
        "simulated": true,
        "truth": truth.file,
        "reference_robot": reference.file,
        "commands": commands.display().to_string(),
        "targets": targets.len(),
        "compensated": summary(&pos, &rot),
        "reference": summary(&pos_ref, &rot_ref),
        "per_target": targets.iter().enumerate().map(|(j, t)| json!({
            "pose": t.label,
            "position_um": pos[j],
            "orientation_urad": rot[j],
            "reference_position_um": pos_ref[j],
        })).collect::<Vec<_>>(),
    });
    let mut md = String::from("# Compensation checked on a simulated machine\n\n**SIMULATED: the machine is the description ");
    md.push_str(&format!(
        "`{}`, not a measurement.**\n\nIt executes `{}` (compensated) and, for reference, the inverse kinematics of `{}` (uncompensated), aiming at the same {} targets.\n\n| commands | position RMS (um) | position max (um) | orientation RMS (urad) | orientation max (urad) |\n|---|---|---|---|---|\n| compensated | {:.3} | {:.3} | {:.2} | {:.2} |\n| uncompensated | {:.3} | {:.3} | {:.2} | {:.2} |\n",
        truth.file,
        commands.display(),
        reference.file,
        targets.len(),
        rms(&pos), max_abs(&pos), rms(&rot), max_abs(&rot),
        rms(&pos_ref), max_abs(&pos_ref), rms(&rot_ref), max_abs(&rot_ref),
    ));
    ctx.finish();
    let mut written = Vec::new();
    if let Some(dir) = &args.out {
        let mut set = OutputSet::new();
        set.add(
            dir.join("compensation.json"),
            serde_json::to_string_pretty(&value)?,
        );
        set.add(dir.join("compensation.md"), md);
        written = common::commit_dir(set, dir, &args.inputs(), "validate", ctx)?;
    }
    if args.json {
        writeln!(ctx.out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else {
        writeln!(
            ctx.out,
            "SIMULATED machine {}: compensated position error RMS {:.3} um (max {:.3}), uncompensated {:.3} um (max {:.3}) over {} targets",
            truth.file,
            rms(&pos),
            max_abs(&pos),
            rms(&pos_ref),
            max_abs(&pos_ref),
            targets.len()
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}

/// Runs `cpm validate`.
pub fn run(args: &ValidateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    if let Some(out) = &args.out {
        common::check_out_dir(out)?;
    }
    if args.commands.is_some() {
        return run_commands(args, ctx);
    }
    ctx.stage("reading the robot descriptions");
    let Some(robot) = &args.robot else {
        return Err(super::usage_error(
            "--robot is required (unless --commands is given)",
        ));
    };
    let robot = common::load_robot(robot, ctx)?;
    let reference = common::load_robot(&args.reference, ctx)?;
    let sensors = |r: &Robot| {
        r.table
            .sensors
            .iter()
            .map(|s| s.name.clone())
            .collect::<Vec<_>>()
    };
    if robot.num_links() != reference.num_links() {
        return Err(super::input_error(format!(
            "{} has {} links, the reference {} has {}",
            robot.file,
            robot.num_links(),
            reference.file,
            reference.num_links()
        )));
    }
    ctx.stage("predicting the held-out measurements");
    let (names, cal, simulated) = errors_of(&robot, &reference, &args.data)?;
    let (ref_names, reference_errors, _) =
        errors_of(&reference, &reference, &args.data).map_err(|e| {
            e.context(format!(
                "reading the held-out data against the reference {} (its sensors: {})",
                reference.file,
                sensors(&reference).join(", ")
            ))
        })?;
    if names != ref_names {
        return Err(super::input_error(format!(
            "the robot and the reference name different sensors ({} / {})",
            names.join(", "),
            ref_names.join(", ")
        )));
    }
    let all = |g: &[Errors]| -> (Vec<f64>, Vec<f64>) {
        (
            g.iter().flat_map(|e| e.values_um.iter().copied()).collect(),
            g.iter()
                .flat_map(|e| e.orientation_urad.iter().copied())
                .collect(),
        )
    };
    let (cal_all, cal_rot) = all(&cal);
    let (ref_all, ref_rot) = all(&reference_errors);
    let summary = |v: &[f64], rot: &[f64]| {
        json!({
            "rms_um": rms(v),
            "max_um": max_abs(v),
            "orientation_rms_urad": if rot.is_empty() { serde_json::Value::Null } else { json!(rms(rot)) },
        })
    };
    let groups_json: Vec<serde_json::Value> = names
        .iter()
        .zip(cal.iter().zip(&reference_errors))
        .map(|(n, (c, r))| {
            json!({
                "name": n,
                "count": c.values_um.len(),
                "calibrated": summary(&c.values_um, &c.orientation_urad),
                "reference": summary(&r.values_um, &r.orientation_urad),
            })
        })
        .collect();
    let value = json!({
        "simulated": simulated,
        "robot": robot.file,
        "reference_robot": reference.file,
        "data": args.data.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "calibrated": summary(&cal_all, &cal_rot),
        "reference": summary(&ref_all, &ref_rot),
        "groups": groups_json,
    });
    let mut md = String::from("# Validation on held-out data\n\n");
    if simulated {
        md.push_str("**The measurements are SIMULATED.**\n\n");
    }
    md.push_str(&format!(
        "Calibrated robot `{}` against the reference `{}`, on {}; predictions with every known effect applied, nothing estimated. Gauge rows: reading errors; tracker rows: position errors per coordinate.\n\n",
        robot.file,
        reference.file,
        args.data
            .iter()
            .map(|p| format!("`{}`", p.display()))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    md.push_str("| group | observations | calibrated RMS (um) | calibrated max (um) | reference RMS (um) | reference max (um) |\n|---|---|---|---|---|---|\n");
    let row = |md: &mut String, name: &str, n: usize, c: &[f64], r: &[f64]| {
        md.push_str(&format!(
            "| {name} | {n} | {:.3} | {:.3} | {:.3} | {:.3} |\n",
            rms(c),
            max_abs(c),
            rms(r),
            max_abs(r)
        ));
    };
    for (n, (c, r)) in names.iter().zip(cal.iter().zip(&reference_errors)) {
        row(&mut md, n, c.values_um.len(), &c.values_um, &r.values_um);
    }
    row(&mut md, "**all**", cal_all.len(), &cal_all, &ref_all);
    if !cal_rot.is_empty() {
        md.push_str(&format!(
            "\nTracker orientation error RMS: calibrated {:.2} urad, reference {:.2} urad.\n",
            rms(&cal_rot),
            rms(&ref_rot)
        ));
    }
    ctx.finish();
    let mut written = Vec::new();
    if let Some(dir) = &args.out {
        let svg = crate::plot::grouped_bars(
            &format!(
                "Held-out prediction error{}",
                if simulated { " (SIMULATED data)" } else { "" }
            ),
            "RMS error (um)",
            &names,
            &[
                (
                    "calibrated".to_string(),
                    cal.iter().map(|e| rms(&e.values_um)).collect(),
                ),
                (
                    "reference".to_string(),
                    reference_errors.iter().map(|e| rms(&e.values_um)).collect(),
                ),
            ],
        )
        .map_err(|e| super::trouble(e.to_string()))?;
        md.push_str("\n![held-out RMS per group](validation.svg)\n");
        let mut set = OutputSet::new();
        set.add(
            dir.join("validation.json"),
            serde_json::to_string_pretty(&value)?,
        );
        set.add(dir.join("validation.md"), md.clone());
        set.add(dir.join("validation.svg"), svg);
        written = common::commit_dir(set, dir, &args.inputs(), "validate", ctx)?;
    }
    if args.json {
        writeln!(ctx.out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else {
        writeln!(
            ctx.out,
            "{}held-out: calibrated RMS {:.3} um (max {:.3}), reference RMS {:.3} um (max {:.3}) over {} observations",
            if simulated { "SIMULATED data: " } else { "" },
            rms(&cal_all),
            max_abs(&cal_all),
            rms(&ref_all),
            max_abs(&ref_all),
            cal_all.len()
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}
