//! `cpm validate`: a calibrated robot checked on measurements the fit did not use, against a
//! reference (the nominal robot, or any other description).
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
use crate::calib::model::{predict, Prepared};
use crate::calib::{Campaign, MeasurementModel};
use crate::io::{FileKind, ReadOptions, Robot};
use crate::output::OutputSet;
use crate::report::validate::{
    rms, CompensationReport, GroupErrors as Errors, PredictionErrors as RobotErrors,
    ReachedSummary, TargetError, ValidateReport,
};
pub use crate::report::validate::{SessionCheck, SessionFrame};

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
    /// Every input file (an output may not replace one).
    fn inputs(&self) -> Vec<&std::path::Path> {
        self.robot
            .iter()
            .chain(self.reference.iter())
            .chain(self.data.iter())
            .chain(self.commands.iter())
            .chain(self.truth.iter())
            .map(|p| p.as_path())
            .collect()
    }
}

/// The readings a controller sent for a file without logged link readings: its own inverse
/// kinematics of the commanded poses through its own reading models. The machine `robot`
/// turns them into lengths through *its* reading models, as the real machine does.
fn commanded_lengths(
    robot: &Robot,
    controller: &Robot,
    poses: &[crate::geometry::Pose],
) -> Vec<Vec<f64>> {
    poses
        .iter()
        .map(|p| {
            crate::kinematics::ik::inverse_lengths(&controller.table, p)
                .iter()
                .enumerate()
                .map(|(i, l)| robot.length_mm(i, controller.reading(i, *l)))
                .collect()
        })
        .collect()
}

/// The groups (sensor names, or `file (tracker)`) and their errors for one robot.
///
/// A file without logged link readings was driven by the controller's inverse kinematics of
/// the commanded poses: that of `controller` (the reference robot), whichever robot predicts.
/// Each tracker file is a session: its frame is fitted afresh with the robot held fixed.
/// `tracker` is the tracker's noise (position um, orientation urad; 0: cpm-calib's default),
/// the weights with which each tracker session is registered.
///
/// With `residuals`, `residuals.csv` of the files too (one numbering over the files, in the
/// order given), its rows written as they are made; without, none of its text is made.
fn errors_of(
    robot: &Robot,
    controller: &Robot,
    paths: &[PathBuf],
    strict: bool,
    tracker: (f64, f64),
    residuals: bool,
) -> anyhow::Result<RobotErrors> {
    let model: MeasurementModel = robot.model(&[]);
    // The machine is held fixed: the readers register the frame, never the link zeros. Not
    // strict (the fit's own data read back): no reachability or sensor-length checks, which
    // the data passed when they were fitted.
    let options = ReadOptions {
        register_link_offsets: false,
        max_condition_ratio: if strict {
            ReadOptions::default().max_condition_ratio
        } else {
            f64::INFINITY
        },
        check_sensor_lengths: strict,
        // Held-out data were commanded by the reference: a calibrated robot whose joints
        // would need a link a few microns past its limit at such a pose still predicts it.
        link_limit_margin_mm: crate::io::campaign::CONSISTENCY_MM,
        ..ReadOptions::default()
    };
    let mut out = RobotErrors::default();
    let group_of =
        |name: String, out: &mut RobotErrors| match out.names.iter().position(|n| *n == name) {
            Some(i) => i,
            None => {
                out.names.push(name);
                out.groups.push(Errors::default());
                out.names.len() - 1
            }
        };
    let pose_map_range = match robot.description.pose_map {
        Some(crate::geometry::description::PoseMapSpec {
            fitted_min: Some(min),
            fitted_max: Some(max),
            ..
        }) => Some(crate::calib::refine::PoseRange { min, max }),
        _ => None,
    };
    let mut residuals_csv: Vec<u8> = Vec::new();
    if residuals {
        residuals_csv.extend_from_slice(crate::report::residuals::RESIDUALS_HEADER.as_bytes());
    }
    let mut written = 0;
    // The group of each sensor, once it has one.
    let mut sensor_group: Vec<Option<usize>> = vec![None; robot.table.sensors.len()];
    for path in paths {
        let mut file = crate::io::read_data_file(path, robot, &options)?;
        out.excluded.extend(file.excluded.iter().cloned());
        if file.kind == FileKind::Poses {
            return Err(super::usage_error(format!(
                "{}: a pose list has no measurements to validate against",
                file.file
            )));
        }
        if file.campaign.commanded_lengths_mm.is_none() {
            file.campaign.commanded_lengths_mm =
                Some(commanded_lengths(robot, controller, &file.campaign.poses));
        }
        (
            file.campaign.pose_sigma_um,
            file.campaign.orientation_sigma_urad,
        ) = tracker;
        let campaign: &Campaign = &file.campaign;
        out.simulated |= campaign.simulated;
        let fail = |e: crate::calib::CalibError| {
            super::trouble(format!(
                "{}: predicting with {}: {e}",
                file.file, robot.file
            ))
        };
        let prepared = Prepared::new(&model, campaign).map_err(fail)?;
        let (predicted, frame) = if campaign.pose_measurements.is_empty()
            && campaign.point_measurements.is_empty()
            && campaign.tilt_measurements.is_empty()
        {
            let zeros = vec![0.0; model.num_params()];
            (
                predict(&model, &prepared, campaign, &zeros, None).map_err(fail)?,
                None,
            )
        } else {
            let s = crate::calib::session::register_session(&model, campaign).map_err(fail)?;
            let before = predict(
                &model,
                &prepared,
                campaign,
                &vec![0.0; model.num_params()],
                None,
            )
            .map_err(fail)?;
            let observed = campaign.observations();
            let p0 = campaign.first_point_observation();
            let pose_rows = campaign.pose_observation_rows();
            let positions = |y: &[f64]| -> Vec<f64> {
                pose_rows
                    .iter()
                    .flat_map(|rows| rows[..3].iter().flatten().copied())
                    .chain(p0..campaign.first_tilt_observation())
                    .map(|k| (observed[k] - y[k]) * 1e3)
                    .collect()
            };
            let angles = |y: &[f64]| -> Vec<f64> {
                pose_rows
                    .iter()
                    .flat_map(|rows| rows[3..].iter().flatten().copied())
                    .chain(
                        campaign.first_tilt_observation()..campaign.first_instrument_observation(),
                    )
                    .map(|k| (observed[k] - y[k]) * 1e3)
                    .collect()
            };
            let some = |v: Vec<f64>| (!v.is_empty()).then(|| rms(&v));
            let rough = file
                .registration
                .as_ref()
                .and_then(|r| r.sessions.iter().find(|x| x.file == file.file))
                .filter(|x| x.applied);
            // A point file's rough registration: the frame its reader applied.
            let (rough_t, rough_r) = match (&file.point_frame, rough) {
                (Some(f), _) => (f.position_mm, f.rotation),
                (None, Some(x)) => (x.frame.translation_mm, x.frame.rotation),
                (None, None) => (
                    crate::geometry::Vector3::zeros(),
                    crate::geometry::Rotation3::identity(),
                ),
            };
            let tilts_only =
                campaign.pose_measurements.is_empty() && campaign.point_measurements.is_empty();
            let (kind, full_frame) = if tilts_only {
                ("tilts", SessionFrame::tilt(&s.frame, &s.frame_sd))
            } else {
                let kind = if campaign.pose_measurements.is_empty() {
                    "points"
                } else {
                    "tracker"
                };
                (
                    kind,
                    SessionFrame::rigid((rough_t, rough_r), &s.frame, &s.frame_sd),
                )
            };
            // The frame fit weighs every kind against the tracker position noise.
            let sigma_ref = campaign.pose_sigma();
            out.sessions.push(SessionCheck {
                file: file.file.clone(),
                kind: kind.to_string(),
                rough_translation_mm: rough_t.into(),
                rough_rotation_deg: rough_r.angle().to_degrees(),
                frame: s.frame,
                frame_sd: s.frame_sd,
                full_frame,
                weighted_rms_before: s.rms_before_um / sigma_ref,
                weighted_rms_after: s.rms_after_um / sigma_ref,
                position_rms_before_um: some(positions(&before)),
                position_rms_after_um: some(positions(&s.predicted)),
                angle_rms_before_urad: some(angles(&before)),
                angle_rms_after_urad: some(angles(&s.predicted)),
            });
            (s.predicted, Some(s.frame))
        };
        let observed = campaign.observations();
        for (k, r) in campaign.readings.iter().enumerate() {
            let g = match sensor_group[r.sensor] {
                Some(g) => g,
                None => {
                    let name = robot.table.sensors[r.sensor].name.clone();
                    *sensor_group[r.sensor].insert(group_of(name, &mut out))
                }
            };
            out.groups[g]
                .values_um
                .push((observed[k] - predicted[k]) * 1e3);
        }
        if !campaign.point_measurements.is_empty() {
            // Point targets: the error of each measured coordinate with the session's frame
            // fitted afresh (the targets held at the robot's).
            let g = group_of(format!("{} (points)", file.file), &mut out);
            for k in campaign.first_point_observation()..campaign.first_tilt_observation() {
                out.groups[g]
                    .values_um
                    .push((observed[k] - predicted[k]) * 1e3);
            }
        }
        if !campaign.tilt_measurements.is_empty() {
            // Inclinometers: the error of each angle (urad) with the session re-levelled (its
            // base tilt fitted afresh, the mounts held at the robot's).
            let g = group_of(format!("{} (tilts)", file.file), &mut out);
            for k in campaign.first_tilt_observation()..campaign.first_instrument_observation() {
                out.groups[g]
                    .orientation_urad
                    .push((observed[k] - predicted[k]) * 1e3);
            }
        }
        if let Some(frame) = frame.filter(|_| !campaign.pose_measurements.is_empty()) {
            let g = group_of(format!("{} (tracker)", file.file), &mut out);
            let (t, rot) = crate::calib::effects::tracker_registration(&frame);
            let commanded = campaign.commanded_lengths_mm.as_ref();
            let pose_rows = campaign.pose_observation_rows();
            for (pm, rows) in campaign.pose_measurements.iter().zip(&pose_rows) {
                // Components not measured are skipped.
                let d: Vec<f64> = rows[..3]
                    .iter()
                    .flatten()
                    .map(|&k| (observed[k] - predicted[k]) * 1e3)
                    .collect();
                out.groups[g].values_um.extend(&d);
                for &k in rows[3..].iter().flatten() {
                    // Orientation observations are mrad.
                    out.groups[g]
                        .orientation_urad
                        .push((observed[k] - predicted[k]) * 1e3);
                }
                if rows.iter().any(Option::is_none) {
                    // A pose not measured in full: no position norm, no link lengths.
                    continue;
                }
                out.position_norm_um
                    .push((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
                // The link lengths the model needs for the measured pose (base frame):
                // inverse kinematics minus the shifts the model adds to a commanded length.
                let m = pm.measured;
                let base = crate::geometry::Pose::new(
                    rot.inverse() * (m.position_mm - t),
                    rot.inverse() * m.rotation,
                );
                if let Some(c) = commanded {
                    let j = pm.pose;
                    // A pose map moves the platform after forward kinematics: the lengths are
                    // those of the pose before it.
                    let map = model.known_pose_twist(
                        &prepared.contexts[j],
                        &campaign.poses[j],
                        prepared.t0_s,
                    );
                    let base = base.perturbed(&-map);
                    let needed = crate::kinematics::ik::inverse_lengths(&robot.table, &base);
                    for i in 0..needed.len() {
                        let shift = prepared.lengths_mm[j][i] - c[j][i];
                        out.link_mm.push(c[j][i] - (needed[i] - shift));
                    }
                }
                out.tracker_poses += 1;
                if pose_map_range
                    .as_ref()
                    .is_some_and(|r| !r.contains(&campaign.poses[pm.pose], 1e-6))
                {
                    out.outside_pose_map += 1;
                }
            }
        }
        if residuals {
            let native: Vec<f64> = observed
                .iter()
                .zip(&predicted)
                .map(|(o, p)| (o - p) * 1e3)
                .collect();
            // Where each observation comes from, as the file was read.
            let origins = crate::io::merge(vec![file], robot);
            crate::report::residuals::write_residual_rows(
                &mut residuals_csv,
                robot,
                &origins,
                &native,
                written + 1,
            )?;
            written += native.len();
        }
    }
    out.residuals_csv = String::from_utf8(residuals_csv).expect("UTF-8 rows");
    Ok(out)
}

/// Pose errors (position um per target, orientation urad per target) the machine `truth`
/// reaches when it executes link `readings` (its own reading models turn them into lengths,
/// its known effects apply) aiming at `targets`.
///
/// `from_home`: the machine comes to the first target from its home pose (commanded with its
/// own inverse kinematics there), so each link's last motion direction is known;
/// `temperature_c`: the temperature the machine runs at (for a known `thermal_drift`).
fn reached_errors(
    truth: &Robot,
    targets: &[crate::io::PoseRow],
    readings: &[Vec<f64>],
    from_home: bool,
    temperature_c: Option<f64>,
) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let links = &truth.description.links;
    let home = usize::from(from_home);
    let mut poses: Vec<crate::geometry::Pose> = Vec::new();
    let mut lengths: Vec<Vec<f64>> = Vec::new();
    if from_home {
        poses.push(truth.table.home);
        lengths.push(crate::kinematics::ik::inverse_lengths(
            &truth.table,
            &truth.table.home,
        ));
    }
    poses.extend(targets.iter().map(|t| t.pose));
    lengths.extend(readings.iter().map(|u| {
        u.iter()
            .zip(links)
            .map(|(u, l)| l.length_at_zero_mm + l.mm_per_unit * u)
            .collect::<Vec<f64>>()
    }));
    let campaign = Campaign {
        poses,
        commanded_lengths_mm: Some(lengths),
        pose_measurements: targets
            .iter()
            .enumerate()
            .map(|(j, t)| crate::calib::campaign::PoseMeasurement {
                pose: j + home,
                measured: t.pose,
                time_s: t.time_s,
                temperature_c,
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
    let Some(reference) = &args.reference else {
        return Err(super::usage_error(
            "--commands needs --reference (the robot whose inverse kinematics commands the uncompensated machine)",
        ));
    };
    let reference = common::load_robot(reference, ctx)?;
    let mut truth = common::load_robot(truth, ctx)?;
    super::simulate::add_truth_effects(&mut truth, &args.truth_effect)?;
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
    let (pos, rot) = reached_errors(
        &truth,
        &targets,
        &compensated,
        args.from_home,
        args.temperature_c,
    )?;
    let (pos_ref, rot_ref) = reached_errors(
        &truth,
        &targets,
        &nominal,
        args.from_home,
        args.temperature_c,
    )?;
    let report = CompensationReport {
        simulated: true,
        truth: truth.file.clone(),
        reference_robot: reference.file.clone(),
        commands: commands.display().to_string(),
        targets: targets.len(),
        compensated: ReachedSummary::new(&pos, &rot),
        reference: ReachedSummary::new(&pos_ref, &rot_ref),
        per_target: targets
            .iter()
            .enumerate()
            .map(|(j, t)| TargetError {
                pose: t.label.clone(),
                position_um: pos[j],
                orientation_urad: rot[j],
                reference_position_um: pos_ref[j],
            })
            .collect(),
    };
    ctx.finish();
    let mut written = Vec::new();
    if let Some(dir) = &args.out {
        let mut set = OutputSet::new();
        set.add(dir.join("compensation.json"), report.to_json()?);
        let markdown = report.markdown();
        set.add(dir.join("report.md"), markdown.as_str());
        common::stage_report_html(&mut set, dir, "cpm compensation check", &markdown);
        written = common::commit_dir(set, dir, &args.inputs(), "validate", ctx)?;
    }
    if args.json {
        writeln!(ctx.out, "{}", report.to_json()?)?;
    } else {
        writeln!(ctx.out, "{}", report.console_line())?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}

/// The reference robot: `--reference`, else the description the calibrated robot records
/// it came from (`[calibration] calibrated_from`).
fn reference_path(args: &ValidateArgs, robot: &Robot, ctx: &Ctx<'_>) -> anyhow::Result<PathBuf> {
    if let Some(r) = &args.reference {
        return Ok(r.clone());
    }
    let recorded = robot
        .description
        .calibration
        .as_ref()
        .and_then(|c| c.calibrated_from.clone());
    // Recorded relative to the calibrated file's folder (older files: an absolute path).
    let here = std::path::Path::new(&robot.file)
        .parent()
        .unwrap_or(std::path::Path::new(""));
    match recorded.map(|p| here.join(p)) {
        Some(p) if p.exists() => {
            reference_changed(robot, &p, ctx);
            Ok(p)
        }
        Some(p) => Err(super::usage_error(format!(
            "{} records that it was calibrated from {}, which does not exist here (moved, or \
             not copied with it): give the nominal description it was fitted from with --reference",
            robot.file,
            p.display()
        ))),
        None => Err(super::usage_error(format!(
            "--reference is required: {} does not record the description it was calibrated from",
            robot.file
        ))),
    }
}

/// A note when the recorded reference `path` is no longer the file `robot` was calibrated
/// from (its fingerprint `[calibration] calibrated_from_fnv1a64` differs).
fn reference_changed(robot: &Robot, path: &std::path::Path, ctx: &Ctx<'_>) {
    let recorded = robot
        .description
        .calibration
        .as_ref()
        .and_then(|c| c.calibrated_from_fnv1a64.clone());
    let now = std::fs::read(path)
        .ok()
        .map(|b| format!("{:016x}", crate::output::fingerprint(&b)));
    if let (Some(recorded), Some(now)) = (recorded, now) {
        if recorded != now {
            ctx.note(format!(
                "{} changed since {} was calibrated from it (fingerprint {now}, recorded {recorded}); it is the reference as it is now: give --reference to choose another",
                path.display(),
                robot.file
            ));
        }
    }
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
    let reference_path = reference_path(args, &robot, ctx)?;
    let reference = common::load_robot(&reference_path, ctx)?;
    let sensors = sensor_names;
    if robot.num_links() != reference.num_links() {
        return Err(super::input_error(format!(
            "{} has {} links, the reference {} has {}",
            robot.file,
            robot.num_links(),
            reference.file,
            reference.num_links()
        )));
    }
    // The tracker's noise: the options, else what the calibrated description declares (the
    // weights its fit used), else cpm-calib's defaults; both robots are registered alike.
    let declared = robot.tracker_sigmas();
    let tracker = (
        args.pose_sigma_um.or(declared.0).unwrap_or(0.0),
        args.orientation_sigma_urad.or(declared.1).unwrap_or(0.0),
    );
    for (v, name) in [
        (args.pose_sigma_um, "--pose-sigma-um"),
        (args.orientation_sigma_urad, "--orientation-sigma-urad"),
    ] {
        if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            return Err(super::usage_error(format!("{name} must be > 0")));
        }
    }
    ctx.stage("predicting the held-out measurements");
    let cal_errors = errors_of(
        &robot,
        &reference,
        &args.data,
        true,
        tracker,
        args.out.is_some(),
    )?;
    let ref_errors =
        errors_of(&reference, &reference, &args.data, true, tracker, false).map_err(|e| {
            e.context(format!(
                "reading the held-out data against the reference {} (its sensors: {})",
                reference.file,
                sensors(&reference).join(", ")
            ))
        })?;
    // The poses left out by either robot's reading (most often the same).
    let mut excluded = cal_errors.excluded.clone();
    excluded.extend(
        ref_errors
            .excluded
            .iter()
            .filter(|e| !cal_errors.excluded.contains(e))
            .cloned(),
    );
    common::warn_excluded(ctx, &excluded);
    let (names, ref_names) = (&cal_errors.names, &ref_errors.names);
    if names != ref_names {
        return Err(super::input_error(format!(
            "the robot and the reference name different sensors ({} / {})",
            names.join(", "),
            ref_names.join(", ")
        )));
    }
    let report = ValidateReport::new(
        &robot.file,
        &reference.file,
        args.data.iter().map(|p| p.display().to_string()).collect(),
        &cal_errors,
        &ref_errors,
    );
    ctx.finish();
    let mut written = Vec::new();
    if let Some(dir) = &args.out {
        let svg = report.figure().map_err(|e| super::trouble(e.to_string()))?;
        let mut set = OutputSet::new();
        set.add(dir.join("validation.json"), report.to_json()?);
        let markdown = report.markdown(true);
        set.add(dir.join("report.md"), markdown.as_str());
        set.add(dir.join("validation.svg"), svg);
        common::stage_report_html(&mut set, dir, "cpm validation report", &markdown);
        set.add(dir.join("residuals.csv"), cal_errors.residuals_csv.clone());
        written = common::commit_dir(set, dir, &args.inputs(), "validate", ctx)?;
    }
    if args.json {
        writeln!(ctx.out, "{}", report.to_json()?)?;
    } else {
        writeln!(ctx.out, "{}", report.console_line())?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}

/// The names of a robot's sensors, in its order.
fn sensor_names(r: &Robot) -> Vec<String> {
    r.table.sensors.iter().map(|s| s.name.clone()).collect()
}

/// [`errors_of`] the fit's own data for the read-back check, predicted from the campaign in
/// memory instead of the files read again, when nothing of the campaign depends on the robot
/// that reads it: gauge readings alone (no sessions to register), without logged link
/// readings (the commanded lengths are the controller's, made here as [`errors_of`] makes
/// them). `None` otherwise (the files are read again).
fn readings_in_memory(
    robot: &Robot,
    controller: &Robot,
    campaign: &Campaign,
) -> anyhow::Result<Option<RobotErrors>> {
    let readings_alone = campaign.pose_measurements.is_empty()
        && campaign.point_measurements.is_empty()
        && campaign.tilt_measurements.is_empty()
        && campaign.instrument_measurements.is_empty();
    // The readings name their sensors by index: the same sensors in the same order, else
    // the files are read again (by name), as before.
    if !readings_alone
        || campaign.commanded_lengths_mm.is_some()
        || sensor_names(robot) != sensor_names(controller)
    {
        return Ok(None);
    }
    let model: MeasurementModel = robot.model(&[]);
    let mut c = Campaign {
        poses: campaign.poses.clone(),
        readings: campaign.readings.clone(),
        session_starts: campaign.session_starts.clone(),
        simulated: campaign.simulated,
        ..Campaign::default()
    };
    c.commanded_lengths_mm = Some(commanded_lengths(robot, controller, &c.poses));
    let fail = |e: crate::calib::CalibError| {
        super::trouble(format!("predicting with {}: {e}", robot.file))
    };
    let prepared = Prepared::new(&model, &c).map_err(fail)?;
    let predicted =
        predict(&model, &prepared, &c, &vec![0.0; model.num_params()], None).map_err(fail)?;
    let observed = c.observations();
    let mut out = RobotErrors::default();
    let mut sensor_group: Vec<Option<usize>> = vec![None; robot.table.sensors.len()];
    for (k, r) in c.readings.iter().enumerate() {
        let g = *sensor_group[r.sensor].get_or_insert_with(|| {
            out.names.push(robot.table.sensors[r.sensor].name.clone());
            out.groups.push(Errors::default());
            out.names.len() - 1
        });
        out.groups[g]
            .values_um
            .push((observed[k] - predicted[k]) * 1e3);
    }
    Ok(Some(out))
}

/// The check every fitting command makes before it writes: the calibrated description it
/// staged (`text`), read back and predicted on the fit's own data files as `cpm validate`
/// predicts them (tracker sessions re-registered), gives the fit's residual RMS.
///
/// Returns `(fit RMS, file RMS)` in um (the fit's weighting: positions at
/// `sigma_ref / pose_sigma`, orientations at `sigma_ref / orientation_sigma`, points at
/// `sigma_ref / point_sigma`), or `None` when
/// the check does not apply: tracker data fitted without `tracker_frame` (the fit keeps the
/// rough registration, which a later reading improves on).
pub fn file_reproduces_fit(
    text: &str,
    reference: &Robot,
    data: &[PathBuf],
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &crate::calib::Calibration,
    sigma_um: Option<f64>,
) -> anyhow::Result<Option<(f64, f64)>> {
    if !campaign.pose_measurements.is_empty()
        && !model.effects.contains(&crate::calib::Effect::TrackerFrame)
    {
        return Ok(None);
    }
    let robot = Robot::from_toml(text, "calibrated.toml").map_err(|e| {
        super::trouble(format!(
            "the calibrated description does not load back: {e}"
        ))
    })?;
    let tracker = (campaign.pose_sigma(), campaign.orientation_sigma());
    let e = match readings_in_memory(&robot, reference, campaign)? {
        Some(e) => e,
        None => errors_of(&robot, reference, data, false, tracker, false)?,
    };
    // The fit's own reference and weights (each kind by its own noise, gauges included).
    let _ = sigma_um;
    let sigma_ref = cal.sigma_ref_um;
    let (wp, wr) = (
        sigma_ref / campaign.pose_sigma(),
        sigma_ref / campaign.orientation_sigma(),
    );
    let wg = campaign.reading_sigma().map_or(1.0, |s| sigma_ref / s);
    let (mut sum, mut n) = (0.0, 0usize);
    for (name, g) in e.names.iter().zip(&e.groups) {
        let w = if name.ends_with("(tracker)") {
            wp
        } else if name.ends_with("(points)") {
            sigma_ref / campaign.point_sigma()
        } else {
            wg
        };
        sum += g.values_um.iter().map(|v| (w * v).powi(2)).sum::<f64>();
        // Orientations are a tracker's or, in a tilt file, an inclinometer's angles.
        let wo = if name.ends_with("(tilts)") {
            sigma_ref / campaign.tilt_sigma()
        } else {
            wr
        };
        sum += g
            .orientation_urad
            .iter()
            .map(|v| (wo * v).powi(2))
            .sum::<f64>();
        n += g.values_um.len() + g.orientation_urad.len();
    }
    Ok(Some((cal.residual_rms_um, (sum / n.max(1) as f64).sqrt())))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The read-back check predicts the fit's gauge readings from the campaign in memory as
    /// reading the files again does (the same errors, number for number), and a description
    /// with a joint moved by 2 mm predicts them worse: the check still sees it.
    #[test]
    fn the_read_back_in_memory_is_the_read_back_of_the_files() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let path = root.join("examples/hexapod_66_readings.csv");
        let text = std::fs::read_to_string(root.join("examples/hexapod_66.toml")).unwrap();
        let reference = Robot::from_toml(&text, "hexapod_66.toml").unwrap();
        let file = crate::io::read_data_file(&path, &reference, &ReadOptions::default()).unwrap();
        let campaign = crate::io::merge(vec![file], &reference).campaign;
        let joint = "base_mm = [193.185165258, -51.763809021, 0.0]";
        assert!(text.contains(joint));
        let moved = text.replacen(joint, "base_mm = [195.185165258, -51.763809021, 0.0]", 1);
        let mut rms = Vec::new();
        for t in [&text, &moved] {
            let robot = Robot::from_toml(t, "calibrated.toml").unwrap();
            let memory = readings_in_memory(&robot, &reference, &campaign)
                .unwrap()
                .expect("gauge readings alone are predicted in memory");
            let files = errors_of(
                &robot,
                &reference,
                std::slice::from_ref(&path),
                false,
                (campaign.pose_sigma(), campaign.orientation_sigma()),
                false,
            )
            .unwrap();
            assert_eq!(memory.names, files.names);
            let values = |e: &RobotErrors| -> Vec<f64> {
                e.groups.iter().flat_map(|g| g.values_um.clone()).collect()
            };
            assert_eq!(values(&memory), values(&files));
            rms.push(crate::report::validate::rms(&values(&memory)));
        }
        assert!(rms[1] > rms[0] + 1.0, "{rms:?}");
    }
}
