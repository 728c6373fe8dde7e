//! Ingesting measurement files: read with `cpm-io` (which parses, nothing else), then register
//! the tracker files among them (a frame per file, reading offsets per link shared by them: a
//! fit) and check their rows against the robot, which needs the registration first, and
//! register each point file roughly ([`register_point_files`]: the frame that takes the
//! nominal targets onto the measured points). What may read a tracker or point file reads
//! through here ([`read_data_file`], [`read_data_files`], ...); a file of another kind comes
//! out as `cpm-io` read it.
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::calib::Campaign;
use crate::geometry::{Pose, Vector3};
use crate::io::campaign::{
    check_link_readings, condition_bound, exclude_poses, unreachable_why, widened, Unusable,
    CONSISTENCY_MM,
};
use crate::io::{
    DataFile, FileKind, InputError, ReadError, ReadForTwo, ReadOptions, RegistrationReport, Robot,
    SecondReading, SessionRegistration, TrackerRow, REGISTRATION_APPLY_MM,
};

/// How tracker files are registered before their consistency checks (see
/// [`register_tracker_files`]): the fit side's settings, beside the [`ReadOptions`] of the
/// reading itself. [`Default`] gives the defaults documented here.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationOptions {
    /// Register tracker files automatically before their consistency checks. Default true.
    pub register_tracker: bool,
    /// The known `tracker_frame` of the description (tx, ty, tz um; rx, ry, rz urad), which
    /// the model applies to its predictions: registration works on the measured poses with
    /// it taken out. Default none.
    pub known_tracker_frame: Option<[f64; 6]>,
    /// Let the registration of tracker files estimate one reading offset per link (applied
    /// when large). Default true; `cpm validate` holds the machine fixed (false).
    pub register_link_offsets: bool,
}

impl Default for RegistrationOptions {
    fn default() -> Self {
        Self {
            register_tracker: true,
            known_tracker_frame: None,
            register_link_offsets: true,
        }
    }
}

/// Reads a measurement file of either kind (told from the header) from text
/// ([`io::read_data`](crate::io::read_data)), tracker files registered and checked
/// ([`register_tracker_files`]).
pub fn read_data(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<DataFile, InputError> {
    registered(
        crate::io::read_data(text, file, robot, options),
        robot,
        options,
        registration,
    )
}

/// Reads a measurement file of either kind, streaming its rows from the file at `path`
/// ([`io::read_data_file`](crate::io::read_data_file)), tracker files registered and checked
/// ([`register_tracker_files`]).
pub fn read_data_file(
    path: &Path,
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<DataFile, ReadError> {
    registered(
        crate::io::read_data_file(path, robot, options),
        robot,
        options,
        registration,
    )
}

/// Reads a measurement file of either kind from a reader, row by row
/// ([`io::read_data_from`](crate::io::read_data_from)), tracker files registered and checked
/// ([`register_tracker_files`]).
pub fn read_data_from<R: Read>(
    source: R,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<DataFile, ReadError> {
    registered(
        crate::io::read_data_from(source, file, robot, options),
        robot,
        options,
        registration,
    )
}

/// A file as read (`read`), registered and checked when it is a tracker file.
fn registered<E: From<InputError>>(
    read: Result<DataFile, E>,
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<DataFile, E> {
    let mut f = read?;
    register_files(std::slice::from_mut(&mut f), robot, options, registration)?;
    Ok(f)
}

/// Registers the files as read: each point file roughly ([`register_point_files`]), the
/// tracker files together ([`register_tracker_files`]).
pub(crate) fn register_files(
    files: &mut [DataFile],
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<(), InputError> {
    register_point_files(files, robot)?;
    register_tracker_files(files, robot, options, registration)
}

/// Registers each point file among `files` not yet registered ([`DataFile::point_frame`]
/// `None`) roughly: the rigid frame that best takes the robot's nominal targets at the
/// commanded poses onto the measured points ([`rough_frame`](crate::calib::points::rough_frame)),
/// applied to the points (so that the fit's `point_frame` of the session is a small
/// correction) and recorded in `point_frame`. The error names the file when its points do
/// not fix the frame.
pub fn register_point_files(files: &mut [DataFile], robot: &Robot) -> Result<(), InputError> {
    for f in files
        .iter_mut()
        .filter(|f| f.kind == FileKind::PointMeasurements && f.point_frame.is_none())
    {
        f.point_frame = Some(register_points(&f.file, robot, &mut f.campaign)?);
    }
    Ok(())
}

/// The rough registration of a point session: the frame that best takes the nominal targets
/// at the commanded poses onto the measured points, applied to the points; returns it.
fn register_points(file: &str, robot: &Robot, campaign: &mut Campaign) -> Result<Pose, InputError> {
    let targets = robot.target_positions_mm();
    let base: Vec<Vector3<f64>> = campaign
        .point_measurements
        .iter()
        .map(|m| campaign.poses[m.pose].transform_point(&targets[m.target]))
        .collect();
    let measured: Vec<Vector3<f64>> = campaign
        .point_measurements
        .iter()
        .map(|m| m.measured_mm)
        .collect();
    let Some((tr, rot)) = crate::calib::points::rough_frame(&base, &measured) else {
        return Err(InputError::file(
            file,
            "the measured points do not fix the tracker's frame (fewer than three points, or all on a line): measure more poses",
        ));
    };
    for m in &mut campaign.point_measurements {
        m.measured_mm = rot.inverse() * (m.measured_mm - tr);
    }
    Ok(Pose::new(tr, rot))
}

/// A measurement file read for two robots with one pass over it
/// ([`io::read_data_file_for_two`](crate::io::read_data_file_for_two)), each robot's reading
/// registered and checked with that robot ([`register_tracker_files`]): the first robot's as
/// [`read_data_file`] gives it, the second's when it can share the pass.
pub fn read_data_file_for_two(
    path: &Path,
    first: &Robot,
    second: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<(DataFile, Option<Result<SecondReading, ReadError>>), ReadError> {
    let read = crate::io::read_data_file_for_first(path, first, options)?;
    let theirs = second_reading(&read, first, second, options, registration);
    Ok((first_reading(read, first, options, registration)?, theirs))
}

/// The first robot's reading of a file read for two
/// ([`read_data_file_for_first`](crate::io::read_data_file_for_first)), registered and
/// checked with it: as [`read_data_file_for_two`] gives it.
pub fn first_reading(
    read: ReadForTwo,
    first: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<DataFile, ReadError> {
    registered::<ReadError>(Ok(read.into_file()), first, options, registration)
}

/// The second robot's reading of a file read for two, registered and checked with it: as
/// [`read_data_file_for_two`] gives it (`first`: the robot that read it).
pub fn second_reading(
    read: &ReadForTwo,
    first: &Robot,
    second: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Option<Result<SecondReading, ReadError>> {
    read.second(first, second, options).map(|r| match r {
        Ok(SecondReading::File(g)) => registered(Ok(*g), second, options, registration)
            .map(|g| SecondReading::File(Box::new(g))),
        other => other,
    })
}

/// Reads several measurement files ([`io::read_data_files`](crate::io::read_data_files));
/// the tracker files among them are registered together ([`register_tracker_files`]: a frame
/// per file, reading offsets shared) before their consistency checks.
pub fn read_data_files(
    paths: &[PathBuf],
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<Vec<DataFile>, ReadError> {
    let mut files = crate::io::read_data_files(paths, robot, options)?;
    register_files(&mut files, robot, options, registration)?;
    Ok(files)
}

/// Registers the tracker files among `files` together (a frame per file, reading offsets per
/// link shared by them; see [`cpm_calib::registration`]), applies what is large (over
/// [`REGISTRATION_APPLY_MM`]) to their measured poses and commanded lengths, then checks every
/// tracker row: the pose reachable, the link readings consistent with it. Files already
/// checked are left alone. Errors name the file, line and field, and the registration when it
/// is the likely cause.
///
/// The stages: `register_sessions` (the frames and offsets, recorded in each file's
/// `registration`), `check_tracker_rows`, then the commanded poses of the rows.
pub fn register_tracker_files(
    files: &mut [DataFile],
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> Result<(), InputError> {
    let idx: Vec<usize> = (0..files.len())
        .filter(|&k| files[k].kind == FileKind::PoseMeasurements && !files[k].checked)
        .collect();
    if idx.is_empty() {
        return Ok(());
    }
    let lengths = KnownLengths::new(robot);
    if registration.register_tracker {
        register_sessions(files, &idx, robot, registration, &lengths);
    }
    check_tracker_rows(files, &idx, robot, options, &lengths)?;
    commanded_poses_of_tracker_rows(files, &idx, robot);
    Ok(())
}

/// A tracker frame known beforehand (`[calibration] tracker_frame` of a calibrated
/// description): taken out of the measured poses before the registration, put back after.
struct KnownFrame(Option<(nalgebra::Vector3<f64>, nalgebra::Rotation3<f64>)>);

impl KnownFrame {
    fn new(registration: &RegistrationOptions) -> Self {
        KnownFrame(
            registration
                .known_tracker_frame
                .map(|q| cpm_calib::effects::tracker_registration(&q)),
        )
    }

    /// The measured pose with the known registration taken out.
    fn taken_out(&self, p: &Pose) -> Pose {
        match &self.0 {
            Some((t, r)) => Pose::new(r.inverse() * (p.position_mm - t), r.inverse() * p.rotation),
            None => *p,
        }
    }

    /// The pose with the known registration put back.
    fn put_back(&self, p: &Pose) -> Pose {
        match &self.0 {
            Some((t, r)) => Pose::new(r * p.position_mm + t, r * p.rotation),
            None => *p,
        }
    }
}

/// The lengths the registration works with: the readings through the reading models, plus
/// the robot's known link effects (a calibrated description's link offsets and scales,
/// backlash, ...), evaluated in the file's order with the link forces of the home pose (the
/// registration is rough; the fit and `cpm validate` refine the frame through the full
/// model).
struct KnownLengths<'r> {
    robot: &'r Robot,
    model: cpm_calib::MeasurementModel,
}

impl<'r> KnownLengths<'r> {
    fn new(robot: &'r Robot) -> Self {
        KnownLengths {
            robot,
            model: robot.model(&[]),
        }
    }

    /// The known link effects' shift of each row's links (mm; empty when the robot has none).
    fn shifts(&self, f: &DataFile) -> Vec<Vec<f64>> {
        let robot = self.robot;
        if self.model.known_effects.is_empty() {
            return Vec::new();
        }
        let home = robot.table.home;
        let mut previous: Option<cpm_calib::effects::PoseContext> = None;
        f.tracker_rows
            .iter()
            .map(|r| {
                let l: Vec<f64> = r
                    .readings
                    .iter()
                    .enumerate()
                    .map(|(i, v)| robot.length_mm(i, *v))
                    .collect();
                match self
                    .model
                    .pose_context(&home, l, previous.as_ref(), None, None)
                {
                    Ok(ctx) => {
                        let d = self.model.known_link_shift_at(&ctx, &home, 0.0);
                        previous = Some(ctx);
                        d
                    }
                    Err(_) => vec![0.0; robot.num_links()],
                }
            })
            .collect()
    }

    /// Each row's link lengths (mm): its readings through the reading models plus the
    /// known shifts.
    fn raw(&self, f: &DataFile) -> Vec<Vec<f64>> {
        let known = self.shifts(f);
        f.tracker_rows
            .iter()
            .enumerate()
            .map(|(q, r)| {
                r.readings
                    .iter()
                    .enumerate()
                    .map(|(i, v)| self.robot.length_mm(i, *v) + known.get(q).map_or(0.0, |k| k[i]))
                    .collect()
            })
            .collect()
    }
}

/// The registration of the tracker files `files[idx]` together (their rows measured in
/// full): each file's frame and the shared reading offsets, applied where large and recorded
/// in each file's `registration` (a failed registration is recorded too, with why).
fn register_sessions(
    files: &mut [DataFile],
    idx: &[usize],
    robot: &Robot,
    registration: &RegistrationOptions,
    lengths: &KnownLengths<'_>,
) {
    let known = KnownFrame::new(registration);
    let sessions: Vec<cpm_calib::registration::Session> = idx
        .iter()
        .map(|&k| {
            // Rows measured in full register the session.
            let f = &files[k];
            let full: Vec<bool> = f.tracker_rows.iter().map(TrackerRow::complete).collect();
            cpm_calib::registration::Session {
                lengths_mm: lengths
                    .raw(f)
                    .into_iter()
                    .zip(&full)
                    .filter(|(_, c)| **c)
                    .map(|(l, _)| l)
                    .collect(),
                measured: f
                    .tracker_rows
                    .iter()
                    .filter(|r| r.complete())
                    .map(|r| known.taken_out(&r.measured))
                    .collect(),
            }
        })
        .collect();
    let finite = sessions
        .iter()
        .all(|s| s.lengths_mm.iter().flatten().all(|v| v.is_finite()));
    // The model's joint clearance shifts the effective link lengths with the link forces:
    // the registration uses it too.
    let model = robot.model(&[]);
    let n = robot.num_links();
    let clearance = |p: &Pose| {
        model
            .clearance
            .link_corrections_mm(&model.nominal, p, &model.load)
            .unwrap_or_else(|_| vec![0.0; n])
    };
    let result = if finite {
        cpm_calib::registration::register_with_corrections(
            &robot.table,
            &sessions,
            &cpm_calib::registration::RegistrationOptions {
                estimate_link_offsets: registration.register_link_offsets,
                ..Default::default()
            },
            &clearance,
        )
        .map_err(|e| e.to_string())
    } else {
        Err("a link reading gives a length that is not a finite number".to_string())
    };
    let reg = match result {
        Ok(reg) => reg,
        Err(why) => {
            let report = failed_registration(why);
            for &k in idx {
                files[k].registration = Some(report.clone());
            }
            return;
        }
    };
    let largest_offset = reg
        .link_offset_mm
        .iter()
        .fold(0.0_f64, |a, o| a.max(o.abs()));
    let offsets_applied = reg.offsets_estimated && largest_offset > REGISTRATION_APPLY_MM;
    let mut report = RegistrationReport {
        sessions: Vec::new(),
        link_offset_mm: reg.link_offset_mm.clone(),
        link_offset_sd_mm: reg.link_offset_sd_mm.clone(),
        offsets_estimated: reg.offsets_estimated,
        offsets_applied,
        variance_factor: reg.variance_factor,
        failure: None,
    };
    for (s, (&k, frame)) in sessions.iter().zip(idx.iter().zip(&reg.frames)) {
        let largest_move_mm = s
            .measured
            .iter()
            .map(|q| (frame.to_base(q).position_mm - q.position_mm).norm())
            .fold(0.0_f64, f64::max);
        let applied = largest_move_mm > REGISTRATION_APPLY_MM;
        report.sessions.push(SessionRegistration {
            file: files[k].file.clone(),
            frame: frame.clone(),
            applied,
            largest_move_mm,
        });
    }
    let unknown = |p: &Pose| known.taken_out(p);
    let known_applied = |p: &Pose| known.put_back(p);
    for (s, &k) in report.sessions.iter().zip(idx) {
        let offsets = offsets_applied.then_some(report.link_offset_mm.as_slice());
        apply_registration(&mut files[k], s, offsets, &unknown, &known_applied);
    }
    for &k in idx {
        files[k].registration = Some(report.clone());
    }
}

/// The checks of every row of the tracker files `files[idx]`, after registration: the pose
/// reachable (else left out, or the file refused when too many are), the link readings
/// consistent with it. A measured pose is where the real machine went: the nominal inverse
/// kinematics of it misses the true link lengths by the machine's errors, so its link limits
/// are checked widened by the consistency tolerance ([`CONSISTENCY_MM`]), which only catches
/// gross errors (units, frames, link mapping).
fn check_tracker_rows(
    files: &mut [DataFile],
    idx: &[usize],
    robot: &Robot,
    options: &ReadOptions,
    lengths: &KnownLengths<'_>,
) -> Result<(), InputError> {
    let measured_table = widened(&robot.table, CONSISTENCY_MM);
    for &k in idx {
        let f = &mut files[k];
        let note = registration_note(f);
        let offsets = f
            .registration
            .as_ref()
            .filter(|r| r.offsets_applied)
            .map(|r| r.link_offset_mm.clone());
        let known = lengths.shifts(f);
        let mut unusable = Vec::new();
        for (q, row) in f.tracker_rows.iter().enumerate() {
            let pose = f.campaign.poses[f.campaign.pose_measurements[q].pose];
            // The registration's reading offsets and the robot's known link effects.
            let row_offsets: Option<Vec<f64>> = match (&offsets, known.get(q)) {
                (None, None) => None,
                (o, k) => Some(
                    (0..robot.num_links())
                        .map(|i| o.as_ref().map_or(0.0, |o| o[i]) + k.map_or(0.0, |k| k[i]))
                        .collect(),
                ),
            };
            if options.max_condition_ratio.is_finite() {
                let bound = condition_bound(
                    &measured_table,
                    options.max_condition_ratio,
                    &f.file,
                    row.line,
                )?;
                // An unreachable pose is excluded after the file's checks (its link readings
                // unchecked), or refuses the file when there are too many.
                if let Some(what) = unreachable_why(&measured_table, &pose, bound) {
                    unusable.push(Unusable {
                        pose: f.campaign.pose_measurements[q].pose,
                        what,
                        note: note.clone(),
                        field: None,
                    });
                    continue;
                }
            }
            check_link_readings(
                &f.file,
                row.line,
                robot,
                &pose,
                &row.readings,
                row_offsets.as_deref(),
                "measured pose",
                &note,
            )?;
        }
        exclude_poses(f, unusable)?;
        f.checked = true;
    }
    Ok(())
}

/// The commanded pose of each tracker row of `files[idx]` (what the link effects and a pose
/// map read, where the link forces are computed): the forward kinematics of its commanded
/// lengths on the design geometry, started from the registered measured pose. It depends on
/// the logged readings and the design only, never on the robot that registers the session,
/// so that every command that reads the file sees the same poses as the fit did.
fn commanded_poses_of_tracker_rows(files: &mut [DataFile], idx: &[usize], robot: &Robot) {
    let model = robot.model(&[]);
    let design = model.statics_table();
    let fk = cpm_kinematics::ForwardOptions::default();
    for &k in idx {
        let f = &mut files[k];
        let Some(commanded) = f.campaign.commanded_lengths_mm.clone() else {
            continue;
        };
        for q in 0..f.campaign.pose_measurements.len() {
            let j = f.campaign.pose_measurements[q].pose;
            if let Ok((p, _)) =
                cpm_kinematics::forward(design, &commanded[j], &f.campaign.poses[j], &fk)
            {
                if p.is_finite() && (p.position_mm - f.campaign.poses[j].position_mm).norm() < 1e3 {
                    f.campaign.poses[j] = p;
                }
            }
        }
    }
}

/// A session's registration applied to its file: each measured pose (the known frame
/// `unknown` taken out, put back by `known_applied`) in the base frame, the commanded pose of a
/// row measured in full moved there too, and with `offsets`, the registration's reading
/// offsets added to the commanded lengths.
fn apply_registration(
    f: &mut DataFile,
    s: &SessionRegistration,
    offsets: Option<&[f64]>,
    unknown: &dyn Fn(&Pose) -> Pose,
    known_applied: &dyn Fn(&Pose) -> Pose,
) {
    if s.applied {
        let mut unmeasured = f.campaign.unmeasured.clone();
        for (q, row) in f.tracker_rows.iter().enumerate() {
            let base = s.frame.to_base(&unknown(&row.measured));
            f.campaign.pose_measurements[q].measured = known_applied(&base);
            if row.complete() {
                f.campaign.poses[f.campaign.pose_measurements[q].pose] = base;
            } else if row.mask[..3].contains(&true) && row.mask[..3].contains(&false) {
                // The frame's rotation mixes the coordinates: a position measured in part is
                // not known in the base frame.
                unmeasured.extend((0..3).map(|a| (q, a)));
            }
        }
        unmeasured.sort_unstable();
        unmeasured.dedup();
        f.campaign.unmeasured = unmeasured;
    }
    if let Some(offsets) = offsets {
        if let Some(c) = &mut f.campaign.commanded_lengths_mm {
            for l in c.iter_mut() {
                for (a, o) in l.iter_mut().zip(offsets) {
                    *a += o;
                }
            }
        }
    }
}

/// The report of a registration that failed (`why`), with nothing estimated.
fn failed_registration(why: String) -> RegistrationReport {
    RegistrationReport {
        sessions: Vec::new(),
        link_offset_mm: Vec::new(),
        link_offset_sd_mm: Vec::new(),
        offsets_estimated: false,
        offsets_applied: false,
        variance_factor: f64::NAN,
        failure: Some(why),
    }
}

/// What a consistency error of a tracker file says about its registration.
fn registration_note(f: &DataFile) -> String {
    let Some(r) = &f.registration else {
        return " (the tracker frame was not registered automatically: the measured poses must be in the base frame)".to_string();
    };
    if let Some(why) = &r.failure {
        return format!(" (the automatic registration of the tracker frame failed: {why}; the measured poses were checked as logged)");
    }
    let Some(s) = r.sessions.iter().find(|s| s.file == f.file) else {
        return String::new();
    };
    let t = s.frame.translation_mm;
    format!(
        " (the tracker frame of this file was registered automatically{}: {:.3} mm, {:.4} deg from the base frame, RMS {:.3} mm before and {:.3} mm after{}; a wrong registration, from too few poses, poses all alike or a wrong link mapping, is the likely cause)",
        if s.applied { " and applied" } else { ", not applied (small)" },
        t.norm(),
        s.frame.rotation_angle_deg(),
        s.frame.rms_before_mm,
        s.frame.rms_after_mm,
        if r.offsets_applied {
            format!(
                ", reading offsets {} mm applied",
                r.link_offset_mm
                    .iter()
                    .map(|o| format!("{o:.3}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            String::new()
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::PointMeasurement;
    use crate::geometry::Rotation3;

    /// cpm-io returns a point file as measured (in the tracker's frame, unregistered); the
    /// ingest registers it: the frame found is the tracker's, the points come back to the
    /// base frame.
    #[test]
    fn point_files_are_registered_on_the_fit_side() {
        let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        let text = std::fs::read_to_string(examples.join("hexapod_66.toml")).unwrap()
            + "\n[[target]]\nname = \"a\"\nplatform_mm = [90.0, 10.0, 30.0]\n\
               \n[[target]]\nname = \"b\"\nplatform_mm = [-50.0, 80.0, 25.0]\n\
               \n[[target]]\nname = \"c\"\nplatform_mm = [-40.0, -85.0, 35.0]\n";
        let robot = Robot::from_toml(&text, "robot.toml").unwrap();
        let home = robot.table.home;
        // The tracker's frame: 1.2 m away, turned 30 degrees about z.
        let (t, r) = (
            Vector3::new(1200.0, -300.0, 40.0),
            Rotation3::from_euler_angles(0.0, 0.0, 30f64.to_radians()),
        );
        let mut campaign = Campaign::default();
        let offsets = [[0.0, 0.0, 0.0], [20.0, -10.0, 5.0], [-15.0, 12.0, -8.0]];
        for (j, o) in offsets.iter().enumerate() {
            let pose = Pose::new(home.position_mm + Vector3::from(*o), home.rotation);
            for (k, target) in robot.description.targets.iter().enumerate() {
                let base = pose.transform_point(&Vector3::from(target.platform_mm));
                campaign.point_measurements.push(PointMeasurement {
                    pose: j,
                    target: k,
                    session: 0,
                    measured_mm: r * base + t,
                    time_s: None,
                });
            }
            campaign.poses.push(pose);
        }
        let csv = crate::io::points::write_point_measurements(&campaign, &robot, "test");
        let options = ReadOptions::default();
        let parsed = crate::io::read_data(&csv, "points.csv", &robot, &options).unwrap();
        assert_eq!(parsed.kind, FileKind::PointMeasurements);
        assert!(parsed.point_frame.is_none());
        let first = parsed.campaign.point_measurements[0].measured_mm;
        assert!((first - campaign.point_measurements[0].measured_mm).norm() < 1e-9);
        let f = read_data(&csv, "points.csv", &robot, &options, &Default::default()).unwrap();
        let frame = f.point_frame.expect("registered");
        assert!(
            (frame.position_mm - t).norm() < 1e-6,
            "{}",
            frame.position_mm
        );
        assert!((frame.rotation.matrix() - r.matrix()).norm() < 1e-9);
        for (m, truth) in f
            .campaign
            .point_measurements
            .iter()
            .zip(&campaign.point_measurements)
        {
            let base = campaign.poses[truth.pose].transform_point(&Vector3::from(
                robot.description.targets[truth.target].platform_mm,
            ));
            assert!((m.measured_mm - base).norm() < 1e-6);
        }
        // Three points on a line do not fix a frame: the error names the file.
        campaign.point_measurements.truncate(1);
        campaign.poses.truncate(1);
        let csv = crate::io::points::write_point_measurements(&campaign, &robot, "test");
        assert!(crate::io::read_data(&csv, "one.csv", &robot, &options).is_ok());
        let e = read_data(&csv, "one.csv", &robot, &options, &Default::default()).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("one.csv: the measured points do not fix"),
            "{e}"
        );
    }
}
