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

use super::common::{self, RobotArg};
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
    /// The calibrated robot description (`calibrated.toml` of `cpm calibrate` or `cpm refine`).
    #[command(flatten)]
    pub robot: RobotArg,
    /// The reference robot the calibration is judged against, usually the nominal description
    /// the fit started from.
    #[arg(long, value_name = "REFERENCE.toml")]
    pub reference: PathBuf,
    /// Held-out measurement files (gauge readings or tracker poses); repeatable.
    #[arg(long, value_name = "DATA.csv", required = true)]
    pub data: Vec<PathBuf>,
    /// Also write validation.json, validation.md and validation.svg into this directory.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
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

/// Runs `cpm validate`.
pub fn run(args: &ValidateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    if let Some(out) = &args.out {
        common::check_out_dir(out)?;
    }
    ctx.stage("reading the robot descriptions");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
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
        written = common::commit(set, &dir.display().to_string())?;
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
