//! `cpm validate` as library functions: a calibrated robot checked on measurements the fit
//! did not use, against a reference (the nominal robot, or any other description)
//! ([`validate`]); a compensation checked end to end on a simulated machine
//! ([`check_compensation`]); and the read-back check of every fitting command
//! ([`file_reproduces_fit`]).
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
use std::path::{Path, PathBuf};

use crate::calib::model::{predict, Prepared};
use crate::calib::{Campaign, MeasurementModel};
use crate::error::{input_error, trouble, usage_error};
use crate::ingest::RegistrationOptions;
use crate::io::{FileKind, ReadOptions, Robot};
use crate::output::OutputSet;
use crate::progress::{check_cancelled, Progress};
use crate::report::validate::{
    rms, CompensationReport, GroupErrors as Errors, PredictionErrors as RobotErrors,
    ReachedSummary, TargetError, ValidateReport,
};
pub use crate::report::validate::{SessionCheck, SessionFrame};
use crate::sources::{InMemory, Source};

/// The options of `cpm validate`. [`ValidateOptions::new`] gives the defaults.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct ValidateOptions {
    /// The calibrated robot description; not used with `commands`.
    pub robot: Option<PathBuf>,
    /// The reference robot; default `None`: the description `robot` records it was
    /// calibrated from (`[calibration] calibrated_from`).
    pub reference: Option<PathBuf>,
    /// Held-out measurement files.
    pub data: Vec<PathBuf>,
    /// Check a compensation instead: the commands file of `cpm compensate`.
    pub commands: Option<PathBuf>,
    /// The true machine for `commands`.
    pub truth: Option<PathBuf>,
    /// With `commands`: true effect values on top of `truth`'s (`EFFECT=V1,V2,..`).
    pub truth_effect: Vec<String>,
    /// With `commands`: the machine comes to the first target from its home pose.
    pub from_home: bool,
    /// With `commands`: the temperature the machine runs at, deg C.
    pub temperature_c: Option<f64>,
    /// Tracker position noise, um; default `None`: the calibrated description's, else
    /// cpm-calib's.
    pub pose_sigma_um: Option<f64>,
    /// Tracker orientation noise, urad; default `None`: as for the position.
    pub orientation_sigma_urad: Option<f64>,
    /// Stage the files of a result directory (`validation.json`, `report.md`, `report.html`,
    /// `validation.svg`, `residuals.csv`) for this directory; default `None`: none.
    pub out: Option<PathBuf>,
}

impl ValidateOptions {
    /// The options for checking the calibrated `robot` on held-out `data`, every other option
    /// at its default.
    pub fn new(robot: impl Into<PathBuf>, data: Vec<PathBuf>) -> Self {
        Self {
            robot: Some(robot.into()),
            data,
            ..Self::default()
        }
    }

    /// Every input file (an output may not replace one).
    pub fn inputs(&self) -> Vec<&Path> {
        self.robot
            .iter()
            .chain(self.reference.iter())
            .chain(self.data.iter())
            .chain(self.commands.iter())
            .chain(self.truth.iter())
            .map(|p| p.as_path())
            .collect()
    }

    /// Checks what needs no file: the output directory and the noises (usage errors).
    pub fn validate(&self) -> anyhow::Result<()> {
        if let Some(out) = &self.out {
            crate::load::check_out_dir(out)?;
        }
        Ok(())
    }
}

/// What [`validate`] gives: the report, and the files of `--out` staged when asked for.
pub struct Validated {
    /// The report (validation.json and report.md are renderings of it).
    pub report: ValidateReport,
    /// The staged result directory, with `out`.
    pub set: Option<OutputSet>,
}

/// What [`check_compensation`] gives: the report, and the files of `--out` staged when asked
/// for.
pub struct CompensationChecked {
    /// The report (compensation.json and report.md are renderings of it).
    pub report: CompensationReport,
    /// The staged result directory, with `out`.
    pub set: Option<OutputSet>,
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

/// The registration options of held-out data: the machine is held fixed (the frame is
/// registered, never the link zeros).
fn held_out_registration() -> RegistrationOptions {
    RegistrationOptions {
        register_link_offsets: false,
        ..RegistrationOptions::default()
    }
}

/// The read options of held-out data (registered with [`held_out_registration`]). Not
/// `strict` (the fit's own data read back): no reachability or sensor-length checks, which the
/// data passed when they were fitted.
fn held_out_read_options(strict: bool) -> ReadOptions {
    ReadOptions {
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
    }
}

/// The range of poses a robot's pose error map was fitted on, if it has one.
fn fitted_pose_map_range(robot: &Robot) -> Option<crate::calib::refine::PoseRange> {
    match robot.description.pose_map {
        Some(crate::geometry::description::PoseMapSpec {
            fitted_min: Some(min),
            fitted_max: Some(max),
            ..
        }) => Some(crate::calib::refine::PoseRange { min, max }),
        _ => None,
    }
}

/// One held-out file read against `robot`: commanded lengths from `controller` where the file
/// logged none, the tracker weights `tracker` (position um, orientation urad; 0: default).
fn read_held_out(
    source: &Source,
    robot: &Robot,
    controller: &Robot,
    options: &ReadOptions,
    tracker: (f64, f64),
) -> anyhow::Result<crate::io::DataFile> {
    let mut file = source.read(robot, options, &held_out_registration())?;
    held_out(&mut file, robot, controller, tracker)?;
    Ok(file)
}

/// What [`read_held_out`] makes of a file `robot` read: refused when it is a pose list,
/// commanded lengths from `controller` where it logged none, the tracker weights.
fn held_out(
    file: &mut crate::io::DataFile,
    robot: &Robot,
    controller: &Robot,
    tracker: (f64, f64),
) -> anyhow::Result<()> {
    if file.kind == FileKind::Poses {
        return Err(usage_error(format!(
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
    Ok(())
}

/// Whether `list` names the pose `e` names (the same file and label, whatever the reason).
fn same_pose_in(list: &[crate::io::ExcludedPose], e: &crate::io::ExcludedPose) -> bool {
    list.iter().any(|x| x.file == e.file && x.label == e.label)
}

/// `file` without the poses `leave_out` names (by file and label), with all their rows.
fn without_left_out(
    file: crate::io::DataFile,
    leave_out: &[crate::io::ExcludedPose],
) -> crate::io::DataFile {
    let drop: Vec<bool> = file
        .pose_labels
        .iter()
        .map(|l| {
            leave_out
                .iter()
                .any(|e| e.file == file.file && e.label == *l)
        })
        .collect();
    if drop.contains(&true) {
        file.without_poses(&drop)
    } else {
        file
    }
}

/// A file with sessions (tracker poses, points, tilts): its frame (or levelling) fitted
/// afresh with the machine held, the predictions after it, and the session's check.
fn register_held_out(
    model: &MeasurementModel,
    prepared: &Prepared,
    file: &crate::io::DataFile,
    keep_outliers: bool,
    fail: &dyn Fn(crate::calib::CalibError) -> anyhow::Error,
) -> anyhow::Result<(Vec<f64>, [f64; 6], SessionCheck)> {
    let campaign = &file.campaign;
    let s = crate::calib::session::register_session_keeping(model, campaign, keep_outliers)
        .map_err(fail)?;
    let before = predict(
        model,
        prepared,
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
            .chain(campaign.first_tilt_observation()..campaign.first_instrument_observation())
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
    let check = SessionCheck {
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
    };
    Ok((s.predicted, s.frame, check))
}

/// The errors of one robot, gathered file by file into named groups.
struct Gather {
    out: RobotErrors,
    /// The group of each sensor, once it has one.
    sensor_group: Vec<Option<usize>>,
}

impl Gather {
    /// The group named `name`, made when new.
    fn group(&mut self, name: String) -> usize {
        let out = &mut self.out;
        match out.names.iter().position(|n| *n == name) {
            Some(i) => i,
            None => {
                out.names.push(name);
                out.groups.push(Errors::default());
                out.names.len() - 1
            }
        }
    }

    /// Gauge readings: each sensor's reading errors (um).
    fn readings(
        &mut self,
        robot: &Robot,
        campaign: &Campaign,
        observed: &[f64],
        predicted: &[f64],
    ) {
        let per_sensor = readings_per_sensor(campaign, self.sensor_group.len());
        for (s, &n) in per_sensor.iter().enumerate() {
            if let Some(g) = self.sensor_group[s] {
                self.out.groups[g].values_um.reserve(n);
            }
        }
        for (k, r) in campaign.readings.iter().enumerate() {
            let g = match self.sensor_group[r.sensor] {
                Some(g) => g,
                None => {
                    let name = robot.table.sensors[r.sensor].name.clone();
                    let g = self.group(name);
                    self.out.groups[g].values_um.reserve(per_sensor[r.sensor]);
                    *self.sensor_group[r.sensor].insert(g)
                }
            };
            self.out.groups[g]
                .values_um
                .push((observed[k] - predicted[k]) * 1e3);
        }
    }

    /// Point targets (each coordinate's error, um, the session's frame fitted afresh, the
    /// targets held at the robot's) and inclinometer angles (urad, the session re-levelled,
    /// the mounts held).
    fn instruments(
        &mut self,
        file: &str,
        campaign: &Campaign,
        observed: &[f64],
        predicted: &[f64],
    ) {
        if !campaign.point_measurements.is_empty() {
            let g = self.group(format!("{file} (points)"));
            for k in campaign.first_point_observation()..campaign.first_tilt_observation() {
                self.out.groups[g]
                    .values_um
                    .push((observed[k] - predicted[k]) * 1e3);
            }
        }
        if !campaign.tilt_measurements.is_empty() {
            let g = self.group(format!("{file} (tilts)"));
            for k in campaign.first_tilt_observation()..campaign.first_instrument_observation() {
                self.out.groups[g]
                    .orientation_urad
                    .push((observed[k] - predicted[k]) * 1e3);
            }
        }
    }

    /// Tracker poses: position (um) and orientation (urad) errors, the position norm and the
    /// link lengths the model needs for each fully measured pose.
    #[allow(clippy::too_many_arguments)]
    fn tracker(
        &mut self,
        robot: &Robot,
        model: &MeasurementModel,
        prepared: &Prepared,
        file: &str,
        campaign: &Campaign,
        observed: &[f64],
        predicted: &[f64],
        frame: &[f64; 6],
        pose_map_range: Option<&crate::calib::refine::PoseRange>,
    ) {
        let g = self.group(format!("{file} (tracker)"));
        let out = &mut self.out;
        let (t, rot) = crate::calib::effects::tracker_registration(frame);
        // The body the tracker measures sits on the platform in the known marker frame.
        let (tm, rm) = crate::calib::effects::tracker_registration(
            model
                .known(crate::calib::Effect::MarkerFrame)
                .filter(|q| q.len() == 6)
                .unwrap_or(&[0.0; 6]),
        );
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
            // The link lengths the model needs for the measured pose (base frame): inverse
            // kinematics minus the shifts the model adds to a commanded length.
            let m = pm.measured;
            let platform = rot.inverse() * m.rotation * rm.inverse();
            let base = crate::geometry::Pose::new(
                rot.inverse() * (m.position_mm - t) - platform * tm,
                platform,
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
            if pose_map_range.is_some_and(|r| !r.contains(&campaign.poses[pm.pose], 1e-6)) {
                out.outside_pose_map += 1;
            }
        }
    }
}

/// The prediction errors of one robot, gathered file after file (see [`errors_of`]).
struct RobotGather<'r> {
    robot: &'r Robot,
    model: MeasurementModel,
    pose_map_range: Option<crate::calib::refine::PoseRange>,
    gather: Gather,
    /// The rows of `residuals.csv` so far, when it is asked for.
    residuals: Option<Vec<(crate::io::Merged, Vec<f64>)>>,
    /// Register each session on every observation, gross outliers included (as a fit that
    /// kept them did), instead of setting them aside by the fit's rule. Default false.
    keep_outliers: bool,
}

/// `residuals.csv` of the files one robot predicted, written when the file is (10^6 readings
/// make 80 MB of text, never held whole): each file's observations as read (where each comes
/// from) with their residuals in their own units, numbered on from file to file.
struct ResidualRows {
    robot: Robot,
    files: Vec<(crate::io::Merged, Vec<f64>)>,
}

impl ResidualRows {
    /// Writes the file (its header, then the rows of each file in turn).
    fn write(&self, mut out: &mut dyn std::io::Write) -> std::io::Result<()> {
        use crate::report::residuals::{write_residual_rows, RESIDUALS_HEADER};
        out.write_all(RESIDUALS_HEADER.as_bytes())?;
        let mut first = 1;
        for (origins, native) in &self.files {
            write_residual_rows(&mut out, &self.robot, origins, native, first)?;
            first += native.len();
        }
        Ok(())
    }
}

/// What one robot predicts on the held-out files, and `residuals.csv` of them when asked for.
type Predicted = (RobotErrors, Option<ResidualRows>);

impl<'r> RobotGather<'r> {
    fn new(robot: &'r Robot, residuals: bool) -> Self {
        RobotGather {
            robot,
            model: robot.model(&[]),
            pose_map_range: fitted_pose_map_range(robot),
            gather: Gather {
                out: RobotErrors::default(),
                sensor_group: vec![None; robot.table.sensors.len()],
            },
            residuals: residuals.then(Vec::new),
            keep_outliers: false,
        }
    }

    /// One held-out file (as [`read_held_out`] gives it) predicted and gathered; the
    /// residuals in their own units when `residuals.csv` is asked for (else none).
    fn file(&mut self, file: &crate::io::DataFile) -> anyhow::Result<Vec<f64>> {
        self.file_commanded(file, file.campaign.commanded_lengths_mm.as_deref())
    }

    /// [`file`](Self::file) with the commanded lengths `commanded` in place of the file's
    /// (a file of gauge readings alone: sessions and tracker poses read the file's own).
    fn file_commanded(
        &mut self,
        file: &crate::io::DataFile,
        commanded: Option<&[Vec<f64>]>,
    ) -> anyhow::Result<Vec<f64>> {
        let keep_outliers = self.keep_outliers;
        let (robot, model, gather) = (self.robot, &self.model, &mut self.gather);
        gather.out.excluded.extend(file.excluded.iter().cloned());
        let campaign: &Campaign = &file.campaign;
        gather.out.simulated |= campaign.simulated;
        let fail = |e: crate::calib::CalibError| {
            trouble(format!(
                "{}: predicting with {}: {e}",
                file.file, robot.file
            ))
        };
        let prepared = Prepared::with_commanded(model, campaign, commanded).map_err(fail)?;
        let (predicted, frame) = if campaign.pose_measurements.is_empty()
            && campaign.point_measurements.is_empty()
            && campaign.tilt_measurements.is_empty()
        {
            let zeros = vec![0.0; model.num_params()];
            (
                predict(model, &prepared, campaign, &zeros, None).map_err(fail)?,
                None,
            )
        } else {
            let (predicted, frame, check) =
                register_held_out(model, &prepared, file, keep_outliers, &fail)?;
            gather.out.sessions.push(check);
            (predicted, Some(frame))
        };
        let observed = campaign.observations();
        gather.readings(robot, campaign, &observed, &predicted);
        gather.instruments(&file.file, campaign, &observed, &predicted);
        if let Some(frame) = frame.filter(|_| !campaign.pose_measurements.is_empty()) {
            gather.tracker(
                robot,
                model,
                &prepared,
                &file.file,
                campaign,
                &observed,
                &predicted,
                &frame,
                self.pose_map_range.as_ref(),
            );
        }
        // The residuals in their own units, for `residuals.csv` only.
        Ok(if self.residuals.is_some() {
            observed
                .iter()
                .zip(&predicted)
                .map(|(o, p)| (o - p) * 1e3)
                .collect()
        } else {
            Vec::new()
        })
    }

    /// [`file`](Self::file), and its rows of `residuals.csv` when it is asked for.
    fn take(&mut self, file: crate::io::DataFile) -> anyhow::Result<()> {
        let native = self.file(&file)?;
        self.rows(file, native)
    }

    /// The rows of `residuals.csv` of `file` when it is asked for (kept to be written with
    /// the file), its residuals `native` (as [`file`](Self::file) gives them).
    fn rows(&mut self, file: crate::io::DataFile, native: Vec<f64>) -> anyhow::Result<()> {
        if let Some(files) = &mut self.residuals {
            // Where each observation comes from, as the file was read.
            files.push((crate::io::merge(vec![file], self.robot), native));
        }
        Ok(())
    }

    fn finish(self) -> Predicted {
        let rows = self.residuals.map(|files| ResidualRows {
            robot: self.robot.clone(),
            files,
        });
        (self.gather.out, rows)
    }
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
/// order given), to be written when the file is; without, none of it is kept.
///
/// The poses `leave_out` names (file and label) are left out of the files as read, with all
/// their rows, as the fit left them out (those the reading leaves out itself are gone already).
/// With `keep_outliers`, each session is registered on every observation (as a fit that kept
/// its gross outliers registered it), else gross outliers are set aside by the fit's rule.
fn errors_of(
    robot: &Robot,
    controller: &Robot,
    paths: &[Source],
    strict: bool,
    tracker: (f64, f64),
    residuals: bool,
    leave_out: &[crate::io::ExcludedPose],
    keep_outliers: bool,
) -> anyhow::Result<Predicted> {
    let options = held_out_read_options(strict);
    let mut g = RobotGather::new(robot, residuals);
    g.keep_outliers = keep_outliers;
    for path in paths {
        g.take(without_left_out(
            read_held_out(path, robot, controller, &options, tracker)?,
            leave_out,
        ))?;
    }
    Ok(g.finish())
}

/// [`errors_of`] `robot` and of `reference` (its own controller) on the same files, each file
/// read once for both when the readers can share it ([`crate::ingest::read_data_file_for_two`]),
/// with the results and errors of the two calls one after the other: an error of
/// `robot`'s is returned, the reference's is its result.
fn errors_of_both(
    robot: &Robot,
    reference: &Robot,
    paths: &[Source],
    tracker: (f64, f64),
    residuals: bool,
) -> anyhow::Result<(Predicted, anyhow::Result<RobotErrors>)> {
    let options = held_out_read_options(true);
    let mut g = RobotGather::new(robot, residuals);
    // The reference's gathering, until its first error (kept for after `robot`'s files).
    let mut r: anyhow::Result<RobotGather> = Ok(RobotGather::new(reference, false));
    for source in paths {
        let Source::Path(path) = source else {
            // Held in memory: each robot reads it on its own.
            let file = read_held_out(source, robot, reference, &options, tracker)?;
            if let Ok(rg) = &mut r {
                let done = read_held_out(source, reference, reference, &options, tracker)
                    .and_then(|f| rg.take(f));
                if let Err(e) = done {
                    r = Err(e);
                }
            }
            g.take(file)?;
            continue;
        };
        let (mut file, second) = crate::ingest::read_data_file_for_two(
            path,
            robot,
            reference,
            &options,
            &held_out_registration(),
        )?;
        // `robot`'s predictions, when made beside the reference's.
        let mut native = None;
        if let Ok(rg) = &mut r {
            use crate::io::SecondReading;
            let done = match second {
                None => read_held_out(source, reference, reference, &options, tracker)
                    .and_then(|f| rg.take(f)),
                Some(Err(e)) => Err(e.into()),
                Some(Ok(SecondReading::File(mut f))) => {
                    held_out(&mut f, reference, reference, tracker).and_then(|()| rg.take(*f))
                }
                Some(Ok(SecondReading::SameAsFirst)) => {
                    // Gauge readings alone, the file as `robot` read it (no logged link
                    // readings): both robots predict it side by side, each with the commanded
                    // lengths `held_out` gives it (the reference's from its own controller,
                    // `robot`'s from the reference's). Nothing else `held_out` changes is read
                    // by a prediction of gauge readings alone.
                    let poses = &file.campaign.poses;
                    let (theirs, ours) = rayon::join(
                        || commanded_lengths(reference, reference, poses),
                        || commanded_lengths(robot, reference, poses),
                    );
                    let (done, mine) = rayon::join(
                        || rg.file_commanded(&file, Some(&theirs)).map(drop),
                        || g.file_commanded(&file, Some(&ours)),
                    );
                    file.campaign.commanded_lengths_mm = Some(ours);
                    native = Some(mine);
                    done
                }
            };
            if let Err(e) = done {
                r = Err(e);
            }
        }
        held_out(&mut file, robot, reference, tracker)?;
        match native {
            Some(native) => g.rows(file, native?)?,
            None => g.take(file)?,
        }
    }
    Ok((g.finish(), r.map(|r| r.finish().0)))
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
        trouble(format!(
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
        trouble(format!(
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

/// The reference robot: `--reference`, else the description the calibrated robot records
/// it came from (`[calibration] calibrated_from`).
fn reference_path(
    reference: Option<&std::path::Path>,
    robot: &Robot,
    progress: &dyn Progress,
) -> anyhow::Result<PathBuf> {
    if let Some(r) = reference {
        return Ok(r.to_path_buf());
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
    match recorded.map(|p| tidy(here.join(p))) {
        Some(p) if p.exists() => {
            reference_changed(robot, &p, progress);
            Ok(p)
        }
        Some(p) => Err(usage_error(format!(
            "{} records that it was calibrated from {}, which does not exist here (moved, or \
             not copied with it): give the nominal description it was fitted from with --reference",
            robot.file,
            p.display()
        ))),
        None => Err(usage_error(format!(
            "--reference is required: {} does not record the description it was calibrated from",
            robot.file
        ))),
    }
}

/// `path` as printed: [`lexically_normal`] when that is the same file (a symbolic link on the
/// way keeps the path as joined).
fn tidy(path: PathBuf) -> PathBuf {
    let normal = lexically_normal(&path);
    match (normal.canonicalize(), path.canonicalize()) {
        (Ok(a), Ok(b)) if a == b => normal,
        _ => path,
    }
}

/// `path` with `a/..` pairs and `.` taken out as written, not through the file system
/// (`out/../robot.toml` reads `robot.toml`); leading `..` stay.
fn lexically_normal(path: &std::path::Path) -> PathBuf {
    use std::path::Component;
    let mut out: Vec<Component> = Vec::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            Component::ParentDir if matches!(out.last(), Some(Component::RootDir)) => {}
            _ => out.push(c),
        }
    }
    if out.is_empty() {
        PathBuf::from(".")
    } else {
        out.iter().collect()
    }
}

/// A note when the recorded reference `path` is no longer the file `robot` was calibrated
/// from (its fingerprint `[calibration] calibrated_from_fnv1a64` differs).
fn reference_changed(robot: &Robot, path: &std::path::Path, progress: &dyn Progress) {
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
            progress.note(&format!(
                "{} changed since {} was calibrated from it (fingerprint {now}, recorded {recorded}); it is the reference as it is now: give --reference to choose another",
                path.display(),
                robot.file
            ));
        }
    }
}

/// `cpm validate --commands`: a compensation checked end to end on a simulated machine.
pub fn check_compensation(
    options: &ValidateOptions,
    progress: &dyn Progress,
) -> anyhow::Result<CompensationChecked> {
    check_compensation_in(options, InMemory::none(), progress)
}

/// [`check_compensation`] with the reference robot and the truth held in memory (as loaded:
/// [`InMemory::reference`], [`InMemory::truth`]) in place of the descriptions the options
/// name.
pub fn check_compensation_in(
    options: &ValidateOptions,
    held: InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<CompensationChecked> {
    let truth_given = options.truth.is_some() || held.truth.is_some();
    let (Some(commands), true) = (&options.commands, truth_given) else {
        return Err(usage_error("--commands needs --truth"));
    };
    let load = |r: Option<Robot>, path: &Option<PathBuf>| match (r, path) {
        (Some(r), _) => Ok(Some(r)),
        (None, Some(p)) => crate::load::load_robot(p, progress).map(Some),
        (None, None) => Ok(None),
    };
    let Some(reference) = load(held.reference, &options.reference)? else {
        return Err(usage_error(
            "--commands needs --reference (the robot whose inverse kinematics commands the uncompensated machine)",
        ));
    };
    let Some(mut truth) = load(held.truth, &options.truth)? else {
        return Err(usage_error("--commands needs --truth"));
    };
    crate::truth::add_truth_effects(&mut truth, &options.truth_effect)?;
    if truth.num_links() != reference.num_links() {
        return Err(input_error(format!(
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
    check_cancelled(progress)?;
    let (pos, rot) = reached_errors(
        &truth,
        &targets,
        &compensated,
        options.from_home,
        options.temperature_c,
    )?;
    let (pos_ref, rot_ref) = reached_errors(
        &truth,
        &targets,
        &nominal,
        options.from_home,
        options.temperature_c,
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
    let set = match &options.out {
        Some(dir) => {
            let mut set = OutputSet::new();
            set.add(dir.join("compensation.json"), report.to_json()?);
            let markdown = report.markdown();
            set.add(dir.join("report.md"), markdown.as_str());
            crate::load::stage_report_html(&mut set, dir, "cpm compensation check", &markdown);
            Some(set)
        }
        None => None,
    };
    Ok(CompensationChecked { report, set })
}

/// `cpm validate`: the calibrated robot and the reference predict the held-out data; the
/// report compares them. With `options.out`, the result directory is staged (not written).
pub fn validate(options: &ValidateOptions, progress: &dyn Progress) -> anyhow::Result<Validated> {
    validate_in(options, InMemory::none(), progress)
}

/// [`validate`] with inputs held in memory (the calibrated robot, the reference, the held-out
/// measurements: see [`InMemory`]) in place of the files the options name.
pub fn validate_in(
    options: &ValidateOptions,
    mut held: InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Validated> {
    options.validate()?;
    progress.stage("reading the robot descriptions");
    let robot = match (held.robot.take(), &options.robot) {
        (Some(r), _) => r,
        (None, Some(path)) => crate::load::load_robot(path, progress)?,
        (None, None) => {
            return Err(usage_error(
                "--robot is required (unless --commands is given)",
            ))
        }
    };
    let reference = match held.reference.take() {
        Some(r) => r,
        None => {
            let reference_path = reference_path(options.reference.as_deref(), &robot, progress)?;
            crate::load::load_robot(&reference_path, progress)?
        }
    };
    if robot.num_links() != reference.num_links() {
        return Err(input_error(format!(
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
        options.pose_sigma_um.or(declared.0).unwrap_or(0.0),
        options.orientation_sigma_urad.or(declared.1).unwrap_or(0.0),
    );
    for (v, name) in [
        (options.pose_sigma_um, "--pose-sigma-um"),
        (options.orientation_sigma_urad, "--orientation-sigma-urad"),
    ] {
        if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            return Err(usage_error(format!("{name} must be > 0")));
        }
    }
    check_cancelled(progress)?;
    progress.stage("predicting the held-out measurements");
    let sources = held.sources_or(&options.data);
    let data_names: Vec<String> = sources.iter().map(Source::name).collect();
    // One's own instruments' measurements are predicted apart (`instrument_errors`).
    let (own, sources): (Vec<Source>, Vec<Source>) = sources
        .into_iter()
        .partition(|s| matches!(s, Source::Instruments(_)));
    let data = &sources;
    // Each file read once for both robots where the readers can share it.
    let ((mut cal_errors, mut cal_rows), ref_errors) =
        errors_of_both(&robot, &reference, data, tracker, options.out.is_some())?;
    check_cancelled(progress)?;
    let mut ref_errors = ref_errors.map_err(|e| {
        e.context(format!(
            "reading the held-out data against the reference {} (its sensors: {})",
            reference.file,
            sensor_names(&reference).join(", ")
        ))
    })?;
    // The poses left out are those either robot's reading leaves out (most often the same),
    // for both robots: the two are compared on the same poses. When the two left out
    // different poses, each reads the files again without the union.
    let only_reference: Vec<crate::io::ExcludedPose> = ref_errors
        .excluded
        .iter()
        .filter(|e| !same_pose_in(&cal_errors.excluded, e))
        .cloned()
        .collect();
    let only_calibrated = cal_errors
        .excluded
        .iter()
        .any(|e| !same_pose_in(&ref_errors.excluded, e));
    if !only_reference.is_empty() || only_calibrated {
        check_cancelled(progress)?;
        let mut union = cal_errors.excluded.clone();
        union.extend(only_reference.iter().cloned());
        (cal_errors, cal_rows) = errors_of(
            &robot,
            &reference,
            data,
            true,
            tracker,
            options.out.is_some(),
            &union,
            false,
        )?;
        ref_errors = errors_of(
            &reference, &reference, data, true, tracker, false, &union, false,
        )?
        .0;
    }
    let mut excluded = cal_errors.excluded.clone();
    excluded.extend(only_reference);
    crate::load::warn_excluded(progress, &excluded);
    let (names, ref_names) = (&cal_errors.names, &ref_errors.names);
    if names != ref_names {
        return Err(input_error(format!(
            "the robot and the reference name different sensors ({} / {})",
            names.join(", "),
            ref_names.join(", ")
        )));
    }
    let mut report = ValidateReport::new(
        &robot.file,
        &reference.file,
        data_names,
        &cal_errors,
        &ref_errors,
    );
    report.instruments = instrument_errors(&robot, &reference, &held.instruments, &own)?;
    report.simulated |= own
        .iter()
        .any(|s| matches!(s, Source::Instruments(r) if r.simulated));
    let set = match &options.out {
        Some(dir) => {
            let svg = report.figure().map_err(|e| trouble(e.to_string()))?;
            let mut set = OutputSet::new();
            set.add(dir.join("validation.json"), report.to_json()?);
            let markdown = report.markdown(true);
            set.add(dir.join("report.md"), markdown.as_str());
            set.add(dir.join("validation.svg"), svg);
            crate::load::stage_report_html(&mut set, dir, "cpm validation report", &markdown);
            if let Some(rows) = cal_rows {
                // Written as the file is, from the numbers.
                set.add_streamed(
                    dir.join("residuals.csv"),
                    Box::new(move |out| rows.write(out)),
                );
            }
            Some(set)
        }
        None => None,
    };
    check_cancelled(progress)?;
    Ok(Validated { report, set })
}

/// The held-out errors of one's own instruments (measured minus predicted, in each
/// instrument's unit), per instrument and source: each robot predicts with its own values of
/// the instruments' parameters ([`calibrated_model`](crate::sources::calibrated_model)), both
/// at the commands of the reference's controller (as [`errors_of`] predicts gauge readings).
fn instrument_errors(
    robot: &Robot,
    reference: &Robot,
    instruments: &[std::sync::Arc<dyn crate::calib::instruments::Instrument>],
    own: &[Source],
) -> anyhow::Result<Vec<crate::report::validate::InstrumentSummary>> {
    if own.is_empty() {
        return Ok(Vec::new());
    }
    if instruments.is_empty() {
        return Err(usage_error(
            "measurements of one's own instruments are given without their instruments (InMemory::instruments)",
        ));
    }
    let models = [
        crate::sources::calibrated_model(robot, instruments)?,
        crate::sources::calibrated_model(reference, instruments)?,
    ];
    let mut out = Vec::new();
    for s in own {
        let Source::Instruments(rows) = s else {
            continue;
        };
        let mut merged = crate::io::merge(Vec::new(), reference);
        rows.append_to(&mut merged, reference)?;
        let mut c = merged.campaign;
        let observed = c.observations();
        let mut errors = Vec::new();
        for (machine, (model, params)) in [robot, reference].into_iter().zip(&models) {
            c.commanded_lengths_mm = Some(commanded_lengths(machine, reference, &c.poses));
            let fail = |e: crate::calib::CalibError| input_error(format!("{}: {e}", rows.file));
            let prepared = Prepared::new(model, &c).map_err(fail)?;
            let predicted = predict(model, &prepared, &c, params, None).map_err(fail)?;
            let e: Vec<f64> = observed
                .iter()
                .zip(&predicted)
                .map(|(o, p)| o - p)
                .collect();
            errors.push(e);
        }
        // The values of each instrument, in the order of the measurements.
        for (i, instrument) in instruments.iter().enumerate() {
            let mut k = c.first_instrument_observation();
            let (mut cal, mut refer) = (Vec::new(), Vec::new());
            for m in &c.instrument_measurements {
                let n = m.values.len();
                if m.instrument == i {
                    cal.extend_from_slice(&errors[0][k..k + n]);
                    refer.extend_from_slice(&errors[1][k..k + n]);
                }
                k += n;
            }
            if !cal.is_empty() {
                out.push(crate::report::validate::InstrumentSummary::new(
                    instrument.name(),
                    &rows.file,
                    instrument.unit(),
                    &cal,
                    &refer,
                ));
            }
        }
    }
    Ok(out)
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
    let fail =
        |e: crate::calib::CalibError| trouble(format!("predicting with {}: {e}", robot.file));
    let prepared = Prepared::new(&model, &c).map_err(fail)?;
    let predicted =
        predict(&model, &prepared, &c, &vec![0.0; model.num_params()], None).map_err(fail)?;
    let observed = c.observations();
    let mut out = RobotErrors::default();
    let mut sensor_group: Vec<Option<usize>> = vec![None; robot.table.sensors.len()];
    let per_sensor = readings_per_sensor(&c, robot.table.sensors.len());
    for (k, r) in c.readings.iter().enumerate() {
        let g = *sensor_group[r.sensor].get_or_insert_with(|| {
            out.names.push(robot.table.sensors[r.sensor].name.clone());
            out.groups.push(Errors {
                values_um: Vec::with_capacity(per_sensor[r.sensor]),
                ..Errors::default()
            });
            out.names.len() - 1
        });
        out.groups[g]
            .values_um
            .push((observed[k] - predicted[k]) * 1e3);
    }
    Ok(Some(out))
}

/// The number of readings of each of `sensors` sensors: each sensor's list of errors is made
/// at its size once (not grown by doubling: a million readings would touch twice the memory
/// they fill).
fn readings_per_sensor(campaign: &Campaign, sensors: usize) -> Vec<usize> {
    let mut n = vec![0usize; sensors];
    for r in &campaign.readings {
        n[r.sensor] += 1;
    }
    n
}

/// The check every fitting command makes before it writes: the calibrated description it
/// staged (`text`), read back and predicted on the fit's own data files as `cpm validate`
/// predicts them (tracker sessions re-registered), gives the fit's residual RMS.
///
/// Returns `(fit RMS, file RMS)` in um (the fit's weighting: positions at
/// `sigma_ref / pose_sigma`, orientations at `sigma_ref / orientation_sigma`, points at
/// `sigma_ref / point_sigma`), or `None` when
/// the check does not apply: tracker data fitted without `tracker_frame` (the fit keeps the
/// rough registration, which a later reading improves on), or measurements other than gauge
/// readings given without files (`data` empty: gauge readings are predicted from the
/// campaign in memory, the rest read again from `data`).
///
/// `excluded` are the poses the fit left out (`Merged::excluded`): read again, the files
/// lose them too, so that the read-back predicts the fit's own data.
#[allow(clippy::too_many_arguments)]
pub fn file_reproduces_fit(
    text: &str,
    reference: &Robot,
    data: &[PathBuf],
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &crate::calib::Calibration,
    sigma_um: Option<f64>,
    excluded: &[crate::io::ExcludedPose],
) -> anyhow::Result<Option<(f64, f64)>> {
    if !campaign.pose_measurements.is_empty()
        && !model.effects.contains(&crate::calib::Effect::TrackerFrame)
    {
        return Ok(None);
    }
    let user = crate::load::user_effects_of(reference, model);
    let robot = Robot::from_toml_among(text, "calibrated.toml", &user).map_err(|e| {
        trouble(format!(
            "the calibrated description does not load back: {e}"
        ))
    })?;
    let tracker = (campaign.pose_sigma(), campaign.orientation_sigma());
    let e = match readings_in_memory(&robot, reference, campaign)? {
        Some(e) => e,
        // Measurements held in memory alone: no file to read again.
        None if data.is_empty() => return Ok(None),
        None => {
            let files: Vec<Source> = data.iter().cloned().map(Source::Path).collect();
            // Each session registered as the fit registered it: what a least-squares fit
            // set aside by its rule is set aside again by the same rule; a fit that set
            // nothing aside (outliers kept, a robust loss, leg residuals) used every one.
            let keep = cal.set_aside.is_empty();
            errors_of(
                &robot, reference, &files, false, tracker, false, excluded, keep,
            )?
            .0
        }
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

    /// Paths print as written, without `a/..` ("mocap_ref72/../mocap/robot.toml").
    #[test]
    fn paths_are_printed_normal() {
        let n = |p: &str| super::lexically_normal(std::path::Path::new(p));
        assert_eq!(
            n("mocap_ref72/../mocap/robot.toml"),
            PathBuf::from("mocap/robot.toml")
        );
        assert_eq!(n("./a/./b/../c"), PathBuf::from("a/c"));
        assert_eq!(n("../a/b/../../c"), PathBuf::from("../c"));
        assert_eq!(n("/../a"), PathBuf::from("/a"));
        assert_eq!(n("a/.."), PathBuf::from("."));
    }

    /// The read-back check predicts the fit's gauge readings from the campaign in memory as
    /// reading the files again does (the same errors, number for number), and a description
    /// with a joint moved by 2 mm predicts them worse: the check still sees it.
    #[test]
    fn the_read_back_in_memory_is_the_read_back_of_the_files() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let path = root.join("examples/hexapod_66_readings.csv");
        let text = std::fs::read_to_string(root.join("examples/hexapod_66.toml")).unwrap();
        let reference = Robot::from_toml(&text, "hexapod_66.toml").unwrap();
        let file = crate::ingest::read_data_file(
            &path,
            &reference,
            &ReadOptions::default(),
            &Default::default(),
        )
        .unwrap();
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
                &[Source::Path(path.clone())],
                false,
                (campaign.pose_sigma(), campaign.orientation_sigma()),
                false,
                &[],
                false,
            )
            .unwrap()
            .0;
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
