//! Measurement files: length-sensor readings and tracker pose measurements (CSV), read into a
//! [`Campaign`] and written back; lists of poses (plans, compensation targets).
//!
//! The formats are documented in `docs/formats.md`. Reading checks every field (numbers
//! finite, sensor names known, rows of one pose agreeing) and every pose of a readings file
//! (reachable where it is: length limits, J1's condition, forward kinematics returning it;
//! link readings and sensor lengths consistent with it, which catches a file in the wrong
//! units); each failure names the file, the line and the field. The one exception: a long
//! file may lose one pose in [`POSES_PER_EXCLUDED_POSE`] that is not reachable where it is;
//! such a pose is left out with all its rows and recorded ([`DataFile::excluded`],
//! [`ExcludedPose`]) instead of refusing the file.
//!
//! This module parses and writes, nothing else: a tracker file is read as logged, its poses
//! checked against the robot only after the registration of its frame, which is a fit and
//! belongs to the fit side (`cpm_workflow::ingest`). The checks it uses ([`unreachable_why`],
//! [`check_link_readings`], [`exclude_poses`]) are public for it.
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

use cpm_calib::campaign::{PointMeasurement, PoseMeasurement, TiltMeasurement};
use cpm_calib::{Campaign, Reading};
use cpm_geometry::{JointTable, Pose, Vector3};
use cpm_kinematics::workspace::{reachable_at, ReachableAt, Unreachable};

use super::table::{field, num, shorten, show, FileKind, Header, Row, Table, SIMULATED_MARK};
use super::{InputError, ReadError, Robot};

/// Columns of a length-sensor readings file that must be present.
pub const READINGS_REQUIRED: [&str; 6] = ["pose", "sensor", "x_mm", "y_mm", "z_mm", "length_mm"];
/// Orientation as roll, pitch, yaw in degrees (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
pub const RPY_COLUMNS: [&str; 3] = ["roll_deg", "pitch_deg", "yaw_deg"];
/// Orientation as a unit quaternion.
pub const QUATERNION_COLUMNS: [&str; 4] = ["qw", "qx", "qy", "qz"];

/// A link length or sensor reading further than `CONSISTENCY_MM + CONSISTENCY_REL * length`
/// from what the pose implies is refused as inconsistent (wrong units, wrong link mapping,
/// wrong sensor).
pub const CONSISTENCY_MM: f64 = 5.0;
/// Relative part of the consistency tolerance.
pub const CONSISTENCY_REL: f64 = 0.05;

/// The largest plausible position coordinate, mm (1 km).
pub const MAX_POSITION_MM: f64 = 1e6;

/// How strictly measurement files are checked. (How tracker files are registered is the fit
/// side's: `cpm_workflow::ingest::RegistrationOptions`.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReadOptions {
    /// Check each length reading against the nominal sensor length at its pose. Turn off for
    /// sensors whose zero is unknown (`sensor_offset` modelled). Default true.
    pub check_sensor_lengths: bool,
    /// A pose is refused when J1's condition number at it exceeds this factor times its
    /// value at home (and at least 10). Default 1000.
    pub max_condition_ratio: f64,
    /// The most data rows a file may have (the reading stops with an error at the next one).
    /// Default [`MAX_ROWS`].
    pub max_rows: usize,
    /// Widens every link's length limits by this much (mm) when checking that a commanded
    /// pose is reachable. Default 0 (the limits as declared); `cpm validate` reads held-out
    /// data, commanded by another model of the machine (the reference's inverse kinematics),
    /// with [`CONSISTENCY_MM`]: a pose the controller reached is not refused because the
    /// calibrated joints would need a link a few microns past its limit there.
    pub link_limit_margin_mm: f64,
}

/// The most data rows of a measurement file or pose list by default: ten million.
pub const MAX_ROWS: usize = 10_000_000;

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            check_sensor_lengths: true,
            max_condition_ratio: 1e3,
            max_rows: MAX_ROWS,
            link_limit_margin_mm: 0.0,
        }
    }
}

/// `table` with every link's length limits widened by `margin_mm`.
pub fn widened(table: &JointTable, margin_mm: f64) -> JointTable {
    let mut t = table.clone();
    for l in t.links.iter_mut() {
        if let Some((lo, hi)) = l.length_limits_mm {
            l.length_limits_mm = Some((lo - margin_mm, hi + margin_mm));
        }
    }
    t
}

/// A measurement file read into a campaign, with where everything came from.
#[derive(Debug, Clone)]
pub struct DataFile {
    /// The file.
    pub file: String,
    /// Its kind (readings or pose measurements).
    pub kind: FileKind,
    /// The campaign it holds.
    pub campaign: Campaign,
    /// The `pose` label of each campaign pose.
    pub pose_labels: Vec<String>,
    /// The first line of each campaign pose.
    pub pose_lines: Vec<usize>,
    /// The line of each reading.
    pub reading_lines: Vec<usize>,
    /// Tracker files: the automatic registration of this file's frame (and the reading
    /// offsets shared by all tracker files read together), when it was attempted (by the fit
    /// side, `cpm_workflow::ingest`; the readers leave it `None`).
    pub registration: Option<RegistrationReport>,
    /// Tracker files: each row as logged (before registration), for the checks that follow it.
    pub tracker_rows: Vec<TrackerRow>,
    /// Tracker files: whether the rows passed the consistency checks (they are checked after
    /// registration, which may involve several files, by `cpm_workflow::ingest`; the readers
    /// return tracker files unchecked).
    pub checked: bool,
    /// Point files: the line of each point measurement; inclinometer files: of each tilt
    /// measurement.
    pub point_lines: Vec<usize>,
    /// Point files: the rough registration applied to the measured points (the base frame's
    /// pose in the tracker's coordinates, `p_tracker = R p_base + t`); `None` as read (the
    /// points in the tracker's frame): the fit side registers the file
    /// (`cpm_workflow::ingest::register_point_files`).
    pub point_frame: Option<Pose>,
    /// The poses left out of the campaign, with all their rows, because the machine cannot
    /// be there (at most one in [`POSES_PER_EXCLUDED_POSE`]; more refuse the file).
    pub excluded: Vec<ExcludedPose>,
}

/// One row of a tracker file as logged.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerRow {
    /// 1-based line.
    pub line: usize,
    /// The `pose` label.
    pub label: String,
    /// The measured pose, tracker frame.
    pub measured: Pose,
    /// The link readings (`reading_k`), in the link's units.
    pub readings: Vec<f64>,
    /// Which components were measured (position x y z, orientation as three): an empty cell
    /// is a component not measured; `measured` holds a placeholder there.
    pub mask: [bool; 6],
}

impl TrackerRow {
    /// True when every component was measured.
    pub fn complete(&self) -> bool {
        self.mask.iter().all(|m| *m)
    }
}

/// The pose of a tracker row whose cells may be empty (not measured): `None` when every cell
/// is given (parse it as usual), else the placeholder pose (0 or identity where not measured)
/// and the mask. The orientation is measured or not as a whole: its cells are all given or all
/// empty.
fn partial_pose(
    t: &Header,
    row: &Row,
    o: Orientation,
) -> Result<Option<(Pose, [bool; 6], RawPose)>, InputError> {
    let empty = |c: &str| t.text(row, c).is_some_and(|v| v.trim().is_empty());
    let ocols = orientation_columns(o);
    let position_empty: Vec<bool> = ["x_mm", "y_mm", "z_mm"].iter().map(|c| empty(c)).collect();
    let orientation_empty = ocols.iter().filter(|c| empty(c)).count();
    if !position_empty.iter().any(|e| *e) && orientation_empty == 0 {
        return Ok(None);
    }
    if orientation_empty != 0 && orientation_empty != ocols.len() {
        let c = ocols.iter().find(|c| empty(c)).expect("an empty cell");
        return Err(t.err(
            row,
            c,
            format!(
                "missing value: the orientation ({}) is measured as a whole: give every cell or leave them all empty (not measured)",
                ocols.join(", ")
            ),
        ));
    }
    let mut raw = RawPose {
        cells: [("", 0.0); 7],
        len: 0,
    };
    let mut mask = [true; 6];
    let mut p = Vector3::zeros();
    for (a, c) in ["x_mm", "y_mm", "z_mm"].iter().enumerate() {
        if position_empty[a] {
            mask[a] = false;
            continue;
        }
        p[a] = t.number(row, c)?;
        check_pose_cell(t, row, c, p[a])?;
    }
    let rotation = if orientation_empty == 0 {
        for c in ["x_mm", "y_mm", "z_mm"] {
            raw.cells[raw.len] = (c, 0.0);
            raw.len += 1;
        }
        for c in ocols {
            let v = t.number(row, c)?;
            check_pose_cell(t, row, c, v)?;
            raw.cells[raw.len] = (c, v);
            raw.len += 1;
        }
        pose_of(t, row, o, &raw)?.rotation
    } else {
        mask[3..].fill(false);
        cpm_geometry::Rotation3::identity()
    };
    Ok(Some((Pose::new(p, rotation), mask, raw)))
}

/// A measured position is moved by more than this (mm) by a session's registration, or a
/// link reading offset is larger than this: the registration (or the offsets) is applied to
/// the data before the fit. Smaller ones are left to the fit (`tracker_frame`, `link_offset`).
pub const REGISTRATION_APPLY_MM: f64 = 1.0;

/// The registration of one tracker file (session).
#[derive(Debug, Clone, PartialEq)]
pub struct SessionRegistration {
    /// The file.
    pub file: String,
    /// The frame: base coordinates to tracker coordinates (with any known `tracker_frame`
    /// taken out first).
    pub frame: cpm_calib::registration::Frame,
    /// Whether the frame was applied to the measured poses (it moves some measured position
    /// by more than [`REGISTRATION_APPLY_MM`]).
    pub applied: bool,
    /// The largest move of a measured position by the registration, mm.
    pub largest_move_mm: f64,
}

/// The automatic registration of tracker files: a frame per file and reading offsets per
/// link shared by them.
#[derive(Debug, Clone, PartialEq)]
pub struct RegistrationReport {
    /// One per tracker file.
    pub sessions: Vec<SessionRegistration>,
    /// Link reading offset per link, mm (true length = reading's length + offset).
    pub link_offset_mm: Vec<f64>,
    /// Their standard deviations, mm.
    pub link_offset_sd_mm: Vec<f64>,
    /// Whether the offsets were estimated.
    pub offsets_estimated: bool,
    /// Whether they were applied to the commanded lengths (the largest is over
    /// [`REGISTRATION_APPLY_MM`]).
    pub offsets_applied: bool,
    /// A-posteriori variance factor of the registration.
    pub variance_factor: f64,
    /// Why the registration failed, when it did (the data are then checked as logged).
    pub failure: Option<String>,
}

/// One pose of a pose list.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseRow {
    /// 1-based line in the file.
    pub line: usize,
    /// The `pose` label (the row number from 1 when the file has no `pose` column).
    pub label: String,
    /// The pose.
    pub pose: Pose,
    /// Time, s, if given.
    pub time_s: Option<f64>,
    /// Temperature, deg C, if given.
    pub temperature_c: Option<f64>,
}

/// Which orientation columns a file uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Orientation {
    Rpy,
    Quaternion,
}

fn orientation(t: &Header) -> Result<Orientation, InputError> {
    let rpy = RPY_COLUMNS.iter().any(|c| t.has(c));
    let quat = QUATERNION_COLUMNS.iter().any(|c| t.has(c));
    let need = |cols: &[&str]| -> Result<(), InputError> {
        for c in cols {
            if !t.has(c) {
                return Err(InputError::field(
                    &t.file,
                    t.header_line,
                    *c,
                    "missing column",
                ));
            }
        }
        Ok(())
    };
    match (rpy, quat) {
        (true, true) => Err(InputError::line(
            &t.file,
            t.header_line,
            "give the orientation either as roll_deg,pitch_deg,yaw_deg or as qw,qx,qy,qz, not both",
        )),
        (false, true) => need(&QUATERNION_COLUMNS).map(|_| Orientation::Quaternion),
        _ => need(&RPY_COLUMNS).map(|_| Orientation::Rpy),
    }
}

pub(crate) fn orientation_columns(o: Orientation) -> &'static [&'static str] {
    match o {
        Orientation::Rpy => &RPY_COLUMNS,
        Orientation::Quaternion => &QUATERNION_COLUMNS,
    }
}

/// The numbers a pose was made of, by column (for agreement checks): position, then three
/// angles or four quaternion components.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RawPose {
    cells: [(&'static str, f64); 7],
    len: usize,
}

impl Default for RawPose {
    fn default() -> Self {
        RawPose {
            cells: [("", 0.0); 7],
            len: 0,
        }
    }
}

impl RawPose {
    /// Adds the number of column `name`.
    pub(crate) fn push(&mut self, name: &'static str, v: f64) {
        self.cells[self.len] = (name, v);
        self.len += 1;
    }

    pub(crate) fn iter(&self) -> std::slice::Iter<'_, (&'static str, f64)> {
        self.cells[..self.len].iter()
    }

    fn value(&self, k: usize) -> f64 {
        self.cells[k].1
    }

    /// True when every number agrees with `other`'s ([`close`]).
    pub(crate) fn agrees(&self, other: &RawPose) -> bool {
        self.len == other.len && self.iter().zip(other.iter()).all(|(a, b)| close(a.1, b.1))
    }
}

/// The pose of a row, and the raw numbers it was made of (for agreement checks).
fn parse_pose(t: &Header, row: &Row, o: Orientation) -> Result<(Pose, RawPose), InputError> {
    let raw = raw_pose(t, row, o)?;
    Ok((pose_of(t, row, o, &raw)?, raw))
}

/// The numbers of a row's pose columns, each checked for its range.
fn raw_pose(t: &Header, row: &Row, o: Orientation) -> Result<RawPose, InputError> {
    let mut raw = RawPose {
        cells: [("", 0.0); 7],
        len: 0,
    };
    for c in ["x_mm", "y_mm", "z_mm"]
        .iter()
        .chain(orientation_columns(o))
    {
        let v = t.number(row, c)?;
        check_pose_cell(t, row, c, v)?;
        raw.cells[raw.len] = (*c, v);
        raw.len += 1;
    }
    Ok(raw)
}

/// [`raw_pose`] with the columns looked up once: `(name, column)` of each pose column.
fn raw_pose_at(
    t: &Header,
    row: &Row,
    columns: &[(&'static str, usize)],
) -> Result<RawPose, InputError> {
    let mut raw = RawPose {
        cells: [("", 0.0); 7],
        len: 0,
    };
    for &(c, col) in columns {
        let v = t.number_at(row, col)?;
        check_pose_cell(t, row, c, v)?;
        raw.cells[raw.len] = (c, v);
        raw.len += 1;
    }
    Ok(raw)
}

/// Positions within 1 km, angles within [-360, 360] degrees.
pub(crate) fn check_pose_cell(t: &Header, row: &Row, c: &str, v: f64) -> Result<(), InputError> {
    check_pose_value(&t.file, row.line, c, v)
}

/// The largest angle of a pose cell, degrees (either sign).
const MAX_ANGLE_DEG: f64 = 360.0;

/// Whether pose value `v` passes [`check_pose_value`] (and is finite) whatever its column:
/// within both limits. The common case, told without the column's name.
#[inline]
pub(crate) fn surely_valid_pose_value(v: f64) -> bool {
    const _: () = assert!(MAX_POSITION_MM >= MAX_ANGLE_DEG);
    v.abs() <= MAX_ANGLE_DEG // false for NaN
}

/// [`check_pose_cell`] of a value of column `c` on `line` of `file`.
pub(crate) fn check_pose_value(file: &str, line: usize, c: &str, v: f64) -> Result<(), InputError> {
    if surely_valid_pose_value(v) {
        return Ok(());
    }
    if c.ends_with("_mm") && v.abs() > MAX_POSITION_MM {
        return Err(InputError::field(
            file,
            line,
            c,
            format!("{v:e} mm is implausibly far (over 1 km): positions are in mm"),
        ));
    }
    if c.ends_with("_deg") && v.abs() > MAX_ANGLE_DEG {
        return Err(InputError::field(
            file,
            line,
            c,
            format!("{v} degrees: an angle is within [-360, 360] (angles are in degrees)"),
        ));
    }
    Ok(())
}

/// The pose the numbers of a row make (a quaternion must have unit norm).
fn pose_of(t: &Header, row: &Row, o: Orientation, raw: &RawPose) -> Result<Pose, InputError> {
    pose_from_raw(&t.file, row.line, o, raw)
}

/// [`pose_of`] the numbers of a row on `line` of `file`.
pub(crate) fn pose_from_raw(
    file: &str,
    line: usize,
    o: Orientation,
    raw: &RawPose,
) -> Result<Pose, InputError> {
    let v = |k| raw.value(k);
    let p = [v(0), v(1), v(2)];
    Ok(match o {
        Orientation::Rpy => Pose::from_xyz_rpy_deg(p, [v(3), v(4), v(5)]),
        Orientation::Quaternion => {
            let q = [v(3), v(4), v(5), v(6)];
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-3 {
                return Err(InputError::field(
                    file,
                    line,
                    "qw",
                    format!("(qw, qx, qy, qz) = ({}, {}, {}, {}) is not a unit quaternion (norm {norm})", q[0], q[1], q[2], q[3]),
                ));
            }
            Pose::try_from_quaternion(Vector3::from(p), q)
                .map_err(|e| InputError::field(file, line, "qw", e.to_string()))?
        }
    })
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 + 1e-9 * a.abs().max(b.abs())
}

fn tolerance_mm(length_mm: f64) -> f64 {
    CONSISTENCY_MM + CONSISTENCY_REL * length_mm.abs()
}

/// Angles all within this (in the file's unit, degrees expected) while some is at least
/// [`RADIANS_MIN`]: the file is taken for radians (docs/formats.md, "Checks beyond the syntax").
pub const RADIANS_MAX: f64 = 0.2;
/// The largest angle of a file must reach this for [`RADIANS_MAX`] to apply (0.02 rad is
/// 1.1 deg; a campaign in degrees that never tilts more than 0.2 deg is implausible for
/// calibration, and a file of constant orientation is left alone).
pub const RADIANS_MIN: f64 = 0.02;

/// Angle values of a file: (line, column, value) for every `_deg` column of every row.
pub(crate) type AngleCells = Vec<(usize, &'static str, f64)>;

/// Refuses a file whose `roll_deg`, `pitch_deg`, `yaw_deg` values all lie within
/// +-[`RADIANS_MAX`] while the largest reaches [`RADIANS_MIN`]: angles in radians, most
/// likely. The error names the first row with such an angle, and says how to keep truly tiny
/// angles (a quaternion).
pub(crate) fn check_angle_units(file: &str, cells: &AngleCells) -> Result<(), InputError> {
    let largest = cells.iter().fold(0.0_f64, |a, c| a.max(c.2.abs()));
    if cells.is_empty() || !(RADIANS_MIN..=RADIANS_MAX).contains(&largest) {
        return Ok(());
    }
    let (line, col, v) = cells
        .iter()
        .find(|c| c.2.abs() >= RADIANS_MIN)
        .copied()
        .expect("the largest angle");
    Err(InputError::field(
        file,
        line,
        col,
        format!(
            "{} degrees, and every angle of the file is within +-{RADIANS_MAX} degrees (largest {largest}): radians? Angles are in degrees ({v} rad would be {:.3} deg). If the campaign really tilts less than {RADIANS_MAX} deg, give the orientation as a quaternion (qw,qx,qy,qz)",
            show(v, None),
            v.to_degrees()
        ),
    ))
}

/// The distance of the robot's home from the base origin, mm, when it is large enough
/// (10 mm) for positions a hundred times smaller to be implausible.
fn home_distance_mm(robot: &Robot) -> Option<f64> {
    let h = robot.table.home.position_mm.norm();
    (h >= 10.0).then_some(h)
}

/// Refuses a base-frame position a hundred times closer to the base origin than the robot's
/// home: metres, most likely. `row` names the line.
fn check_position_units(
    file: &str,
    line: usize,
    p: &Vector3<f64>,
    robot: &Robot,
) -> Result<(), InputError> {
    let Some(h) = home_distance_mm(robot) else {
        return Ok(());
    };
    if p.norm() > h / 100.0 {
        return Ok(());
    }
    let col = ["x_mm", "y_mm", "z_mm"][p.iamax()];
    Err(InputError::field(
        file,
        line,
        col,
        format!(
            "the position ({}, {}, {}) is {:.4} mm from the base origin while the robot's home is {h:.1} mm away: metres? Positions are in mm",
            show(p.x, None),
            show(p.y, None),
            show(p.z, None),
            p.norm()
        ),
    ))
}

/// Checks a pose list's positions against the robot (see [`read_pose_list`]): a position a
/// hundred times closer to the base origin than the robot's home is refused as metres, at the
/// first such row.
pub fn check_pose_list_units(
    rows: &[PoseRow],
    file: &str,
    robot: &Robot,
) -> Result<(), InputError> {
    for r in rows {
        check_position_units(file, r.line, &r.pose.position_mm, robot)?;
    }
    Ok(())
}

/// Checks a pose where the machine is (see [`reachable_at`]): link lengths within their
/// limits there, J1's condition number there at most `max_condition_ratio` times its home
/// value (at least 10), forward kinematics from the pose's link lengths returning it. The
/// error names the pose's first line.
pub fn check_reachable(
    table: &JointTable,
    pose: &Pose,
    max_condition_ratio: f64,
    file: &str,
    line: usize,
    label: &str,
) -> Result<(), InputError> {
    let bound = condition_bound(table, max_condition_ratio, file, line)?;
    check_reachable_within(table, pose, bound, file, line, label)
}

/// The largest J1 condition number [`check_reachable`] accepts (`max_condition_ratio` times
/// home's, at least 10), and home's; the error names `line`.
pub fn condition_bound(
    table: &JointTable,
    max_condition_ratio: f64,
    file: &str,
    line: usize,
) -> Result<(f64, f64), InputError> {
    match cpm_kinematics::workspace::j1_condition(table, &table.home) {
        Ok(c0) if c0.is_finite() => Ok(((max_condition_ratio * c0).max(10.0), c0)),
        Ok(c0) => Ok((f64::INFINITY, c0)),
        Err(e) => Err(InputError::line(
            file,
            line,
            format!("J1's condition number at the robot's home pose: {e}"),
        )),
    }
}

/// [`check_reachable`] with the bound of [`condition_bound`] computed once (for the many
/// poses of one file).
fn check_reachable_within(
    table: &JointTable,
    pose: &Pose,
    bound: (f64, f64),
    file: &str,
    line: usize,
    label: &str,
) -> Result<(), InputError> {
    match unreachable_why(table, pose, bound) {
        None => Ok(()),
        Some(what) => Err(unreachable_error(file, line, label, &what)),
    }
}

/// The error of an unreachable pose: `pose "LABEL" ` then what [`unreachable_why`] says.
fn unreachable_error(file: &str, line: usize, label: &str, what: &str) -> InputError {
    InputError::line(file, line, format!("pose {:?} {what}", shorten(label)))
}

/// Why `pose` is not reachable (see [`check_reachable`]), `None` when it is: where it is and
/// the reason, e.g. `(x 1 mm, ..., yaw 0.0000 deg) is not reachable: link 3 would be ...`.
/// `bound` is what [`condition_bound`] gives.
pub fn unreachable_why(table: &JointTable, pose: &Pose, bound: (f64, f64)) -> Option<String> {
    why_unreachable(reachable_at(table, pose, bound.0), pose, bound)
}

/// What [`unreachable_why`] says of `pose` given what [`reachable_at`] found there.
fn why_unreachable(
    found: Result<(), Unreachable>,
    pose: &Pose,
    (bound, c0): (f64, f64),
) -> Option<String> {
    let why = match found {
        Ok(()) => return None,
        Err(Unreachable::LengthLimit {
            link,
            length_mm,
            limits_mm,
        }) => format!(
            "link {} would be {length_mm:.3} mm long there, outside its limits [{}, {}] mm",
            link + 1,
            limits_mm.0,
            limits_mm.1
        ),
        Err(Unreachable::NearSingular { condition }) => format!(
            "the machine is (near) singular there (J1 condition number {condition:.3e}, {c0:.3e} at home, at most {bound:.3e} accepted)"
        ),
        Err(Unreachable::AssemblyModeChange { .. }) => "det J1 there has the opposite sign to home's and forward kinematics from home does not return it: the pose belongs to another assembly mode (or is in other units)".to_string(),
        Err(Unreachable::ForwardMismatch {
            from_home_mm,
            from_near_mm,
        }) => format!(
            "forward kinematics from its own link lengths does not return it (lands {from_home_mm:.3e} mm away started from home, {from_near_mm:.3e} mm started near the pose): another assembly mode or a degenerate configuration"
        ),
        Err(Unreachable::Svd(e)) => {
            format!("J1's condition number there could not be computed: {e}")
        }
        Err(Unreachable::Invalid) => {
            "its link lengths are not finite numbers (an implausible pose or robot)".to_string()
        }
    };
    let [x, y, z] =
        [pose.position_mm.x, pose.position_mm.y, pose.position_mm.z].map(|v| show(v, None));
    let [r, p, w] = pose.rpy_deg();
    Some(format!(
        "(x {x} mm, y {y} mm, z {z} mm, roll {r:.4} deg, pitch {p:.4} deg, yaw {w:.4} deg) is not reachable: {why} (positions are in mm, angles in degrees)"
    ))
}

/// A file may lose one pose in this many (5 %) to exclusion: a pose the machine cannot be
/// at (see [`check_reachable`]), or whose logged link readings give no pose (forward
/// kinematics does not converge), is then left out with all its rows and recorded
/// ([`ExcludedPose`], [`DataFile::excluded`]) rather than refusing the file. A file with more
/// such poses than [`max_excluded_poses`] allows is refused with the first one's error: so a
/// file of fewer than 20 poses loses none, one of 40 poses at most two.
pub const POSES_PER_EXCLUDED_POSE: usize = 20;

/// The most poses a file of `poses` poses may lose to exclusion: `poses /`
/// [`POSES_PER_EXCLUDED_POSE`], rounded down (so at least one pose is always left).
pub fn max_excluded_poses(poses: usize) -> usize {
    poses / POSES_PER_EXCLUDED_POSE
}

/// A pose left out of a measurement file because the machine cannot be there (see
/// [`POSES_PER_EXCLUDED_POSE`]), or of a fit because forward kinematics did not converge at
/// it: its rows were not used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExcludedPose {
    /// The file.
    pub file: String,
    /// The pose's first line (1-based).
    pub line: usize,
    /// Its `pose` label.
    pub label: String,
    /// Why (the words of the error that refuses it in a smaller file).
    pub reason: String,
}

impl std::fmt::Display for ExcludedPose {
    /// `FILE:LINE: pose "LABEL" excluded: REASON` (what the commands warn with).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}:{}: pose {:?} excluded: {}",
            self.file,
            self.line,
            shorten(&self.label),
            self.reason
        )
    }
}

/// A pose of a file found unreachable while reading it, to exclude (or to refuse the file
/// with, see [`exclude_poses`]).
pub struct Unusable {
    /// Its index among the file's campaign poses.
    pub pose: usize,
    /// What is wrong, after `pose "LABEL" ` ([`unreachable_why`]).
    pub what: String,
    /// Appended to the error only (not to the exclusion's reason).
    pub note: String,
    /// The error's field, if any.
    pub field: Option<String>,
}

/// Excludes the poses `unusable` from `f` (see [`POSES_PER_EXCLUDED_POSE`]) and records them
/// in [`DataFile::excluded`], or, when they are too many, returns the first one's error.
pub fn exclude_poses(f: &mut DataFile, unusable: Vec<Unusable>) -> Result<(), InputError> {
    let Some(first) = unusable.first() else {
        return Ok(());
    };
    let poses = f.campaign.poses.len();
    let label = |j: usize| f.pose_labels.get(j).map_or("", String::as_str);
    let line = |j: usize| f.pose_lines.get(j).copied().unwrap_or(0);
    if unusable.len() > max_excluded_poses(poses) {
        let mut e = unreachable_error(&f.file, line(first.pose), label(first.pose), &first.what);
        e.field.clone_from(&first.field);
        if max_excluded_poses(poses) > 0 {
            e.message.push_str(&format!(
                " ({} of the file's {poses} poses are so: more than one in {POSES_PER_EXCLUDED_POSE}, which would be left out, so the file is refused)",
                unusable.len()
            ));
        }
        e.message.push_str(&first.note);
        return Err(e);
    }
    let mut drop = vec![false; poses];
    for u in &unusable {
        if let Some(d) = drop.get_mut(u.pose) {
            *d = true;
        }
        f.excluded.push(ExcludedPose {
            file: f.file.clone(),
            line: line(u.pose),
            label: label(u.pose).to_string(),
            reason: u.what.clone(),
        });
    }
    *f = f.without_poses(&drop);
    Ok(())
}

impl DataFile {
    /// A readings file as read (checked, nothing excluded yet): its campaign with the label
    /// and first line of each pose and the line of each reading.
    pub(crate) fn readings(
        file: String,
        campaign: Campaign,
        pose_labels: Vec<String>,
        pose_lines: Vec<usize>,
        reading_lines: Vec<usize>,
    ) -> DataFile {
        DataFile {
            file,
            kind: FileKind::Readings,
            pose_lines,
            campaign,
            pose_labels,
            reading_lines,
            registration: None,
            tracker_rows: Vec::new(),
            checked: true,
            point_lines: Vec::new(),
            point_frame: None,
            excluded: Vec::new(),
        }
    }

    /// The file without the campaign poses `j` with `drop[j]`, all their rows (readings,
    /// tracker rows, points, angles) and their lines left out, the poses left renumbered
    /// ([`Campaign::without_poses`]).
    pub fn without_poses(&self, drop: &[bool]) -> DataFile {
        let dropped = |j: usize| drop.get(j).copied().unwrap_or(false);
        let keep_lines = |lines: &[usize], poses: &mut dyn Iterator<Item = usize>| -> Vec<usize> {
            lines
                .iter()
                .zip(poses)
                .filter(|(_, j)| !dropped(*j))
                .map(|(l, _)| *l)
                .collect()
        };
        let c = &self.campaign;
        let point_lines = if self.kind == FileKind::TiltMeasurements {
            keep_lines(
                &self.point_lines,
                &mut c.tilt_measurements.iter().map(|m| m.pose),
            )
        } else {
            keep_lines(
                &self.point_lines,
                &mut c.point_measurements.iter().map(|m| m.pose),
            )
        };
        DataFile {
            file: self.file.clone(),
            kind: self.kind,
            campaign: c.without_poses(dropped),
            pose_labels: self
                .pose_labels
                .iter()
                .enumerate()
                .filter(|(j, _)| !dropped(*j))
                .map(|(_, l)| l.clone())
                .collect(),
            pose_lines: keep_lines(&self.pose_lines, &mut (0..self.pose_lines.len())),
            reading_lines: keep_lines(&self.reading_lines, &mut c.readings.iter().map(|r| r.pose)),
            registration: self.registration.clone(),
            tracker_rows: self
                .tracker_rows
                .iter()
                .zip(&c.pose_measurements)
                .filter(|(_, m)| !dropped(m.pose))
                .map(|(r, _)| r.clone())
                .collect(),
            checked: self.checked,
            point_lines,
            point_frame: self.point_frame,
            excluded: self.excluded.clone(),
        }
    }
}

/// Opens a file for reading; failures are [`ReadError::Io`].
pub fn open(path: &Path) -> Result<std::fs::File, ReadError> {
    let file = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|source| ReadError::Io {
        file: file.clone(),
        source,
    })?;
    match f.metadata() {
        Ok(m) if m.is_dir() => Err(ReadError::Io {
            file,
            source: std::io::Error::other("is a directory, not a file"),
        }),
        _ => Ok(f),
    }
}

/// The error of a reader: an I/O error when the table met one, else the input error.
pub(crate) fn finish<R: Read>(t: &mut Table<R>, e: InputError) -> ReadError {
    match t.take_io_error() {
        Some(source) => ReadError::Io {
            file: t.file.clone(),
            source,
        },
        None => ReadError::Input(e),
    }
}

/// Checks the `reading_k` columns: none, or exactly `reading_1..reading_n`.
pub(crate) fn link_reading_columns(t: &Header, n: usize) -> Result<bool, InputError> {
    let ks = t.reading_columns()?;
    link_reading_count(&t.file, t.header_line, ks.len(), n)
}

/// [`link_reading_columns`] of `count` columns `reading_1..reading_count` in the header (on
/// `header_line` of `file`).
pub(crate) fn link_reading_count(
    file: &str,
    header_line: usize,
    count: usize,
    n: usize,
) -> Result<bool, InputError> {
    if count == 0 {
        return Ok(false);
    }
    if count != n {
        let name = if count < n {
            format!("reading_{}", count + 1)
        } else {
            format!("reading_{}", n + 1)
        };
        let what = if count < n {
            "missing column"
        } else {
            "unknown column"
        };
        return Err(InputError::field(
            file,
            header_line,
            name,
            format!("{what}: the robot has {n} links, so a file with link readings has reading_1 to reading_{n}"),
        ));
    }
    Ok(true)
}

/// A tracker file's link reading columns (`count` of them, `reading_1..reading_count`):
/// exactly `reading_1..reading_n` ([`link_reading_count`]), none refused.
pub(crate) fn tracker_link_columns(
    file: &str,
    header_line: usize,
    count: usize,
    n: usize,
) -> Result<(), InputError> {
    if link_reading_count(file, header_line, count, n)? {
        Ok(())
    } else {
        Err(InputError::field(
            file,
            header_line,
            "reading_1",
            "missing column",
        ))
    }
}

/// The names of the first `reading_k` columns (no name made for every row).
const READING_NAMES: [&str; 12] = [
    "reading_1",
    "reading_2",
    "reading_3",
    "reading_4",
    "reading_5",
    "reading_6",
    "reading_7",
    "reading_8",
    "reading_9",
    "reading_10",
    "reading_11",
    "reading_12",
];

/// The name of the column of link `i`'s reading (from 0): `reading_{i + 1}`.
pub(crate) fn reading_name(i: usize) -> std::borrow::Cow<'static, str> {
    match READING_NAMES.get(i) {
        Some(name) => (*name).into(),
        None => format!("reading_{}", i + 1).into(),
    }
}

pub(crate) fn link_readings(t: &Header, row: &Row, n: usize) -> Result<Vec<f64>, InputError> {
    (0..n).map(|i| t.number(row, &reading_name(i))).collect()
}

/// Checks link lengths (from the logged readings `readings`, plus `offset_mm` per link when the
/// registration found reading offsets) against the pose's inverse kinematics; errors name
/// `file`, `line` and the `reading_k` field, with `note` appended.
#[allow(clippy::too_many_arguments)]
pub fn check_link_readings(
    file: &str,
    line: usize,
    robot: &Robot,
    pose: &Pose,
    readings: &[f64],
    offset_mm: Option<&[f64]>,
    what: &str,
    note: &str,
) -> Result<Vec<f64>, InputError> {
    let ik = cpm_kinematics::inverse_lengths(&robot.table, pose);
    let mut lengths = Vec::with_capacity(readings.len());
    for (i, (u, l_ik)) in readings.iter().zip(&ik).enumerate() {
        let l = robot.length_mm(i, *u) + offset_mm.map_or(0.0, |o| o[i]);
        if !l.is_finite() || !((l - l_ik).abs() <= tolerance_mm(*l_ik)) {
            let offset = match offset_mm {
                Some(o) => format!(" + the registration's reading offset {:.3} mm", o[i]),
                None => String::new(),
            };
            return Err(InputError::field(
                file,
                line,
                format!("reading_{}", i + 1),
                format!(
                    "{} means a link length of {} mm (length_at_zero_mm + mm_per_unit * reading{offset}), but the {what} needs {l_ik:.3} mm: wrong units, a wrong link mapping in the robot description, or a wrong pose?{note}",
                    show(*u, None),
                    show(l, Some(3))
                ),
            ));
        }
        lengths.push(l);
    }
    Ok(lengths)
}

/// The error of a row naming a sensor the robot does not have.
pub(crate) fn unknown_sensor(file: &str, line: usize, robot: &Robot, name: &str) -> InputError {
    InputError::field(
        file,
        line,
        "sensor",
        format!(
            "unknown sensor {:?} (the robot description has: {})",
            shorten(name),
            robot.sensor_names()
        ),
    )
}

/// The error of a file with more rows than allowed.
pub(crate) fn too_many_rows(t: &Header, row: &Row, max: usize) -> InputError {
    too_many_rows_at(&t.file, row.line, max)
}

/// [`too_many_rows`] on `line` of `file`.
pub(crate) fn too_many_rows_at(file: &str, line: usize, max: usize) -> InputError {
    InputError::line(
        file,
        line,
        format!("more than {max} data rows: cpm reads at most {max} (average repeated readings, or split the campaign)"),
    )
}

/// Reads length-sensor readings (see `docs/formats.md`). A pose that is not reachable where
/// it is ([`check_reachable`]) is left out with all its rows and recorded in
/// [`DataFile::excluded`], for at most one pose in [`POSES_PER_EXCLUDED_POSE`] of the file
/// ([`max_excluded_poses`]); more refuse the file with the first one's error.
pub fn read_readings(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let mut t = Table::parse(text, file)?;
    read_readings_table(&mut t, robot, options)
}

pub(crate) fn read_readings_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let (mut f, unusable, _) = read_readings_unexcluded(t, robot, None, options)?;
    exclude_poses(&mut f, unusable)?;
    Ok(f)
}

/// [`read_readings_table`] without the exclusion of the unusable poses: the file with all
/// its poses, and the poses to exclude.
///
/// Without logged link readings, the checks that depend on the robot (positions in mm,
/// reachability, sensor lengths: [`robot_checks`]) are made after the rows are read, the
/// reachability of the poses in parallel, with the errors they would have given row by row:
/// when a row is refused, the checks of the rows before it come first.
///
/// With a `second` robot, its checks of the same rows too when they can be made on the rows
/// `robot` read (see [`SecondChecks`]), beside `robot`'s.
pub(crate) fn read_readings_unexcluded<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    second: Option<&Robot>,
    options: &ReadOptions,
) -> Result<(DataFile, Vec<Unusable>, SecondChecks), InputError> {
    let n = robot.num_links();
    let o = orientation(t)?;
    t.check_columns(
        &READINGS_REQUIRED,
        &["time_s", "temperature_c", "simulated"],
        |h| {
            RPY_COLUMNS.contains(&h)
                || QUATERNION_COLUMNS.contains(&h)
                || super::table::reading_index(h).is_some()
        },
    )?;
    let logged = link_reading_columns(t, n)?;
    struct PoseEntry {
        raw: RawPose,
        readings: Option<Vec<f64>>,
        line: usize,
    }
    let mut by_label: HashMap<String, usize> = HashMap::new();
    let mut entries: Vec<PoseEntry> = Vec::new();
    let mut labels = Vec::new();
    let mut campaign = Campaign {
        simulated: t.simulated_mark,
        ..Campaign::default()
    };
    let mut commanded = Vec::new();
    let mut reading_lines = Vec::new();
    let mut angles: AngleCells = Vec::new();
    // The robot's checks of each new pose made as it is read (logged link readings).
    let mut pose_checks = PoseChecks::default();
    // The pose of the previous row (rows of one pose usually follow each other).
    let mut previous: Option<usize> = None;
    // The poses found unreachable, and per pose whether it is one of them.
    let mut unusable: Vec<Unusable> = Vec::new();
    let mut excluding: Vec<bool> = Vec::new();
    // One row after the other, its strings reused.
    let mut next = Row::default();
    // The columns, looked up once (check_columns and orientation made sure they exist).
    let col = |name: &str| t.column(name).expect("a checked column");
    let (pose_col, sensor_col, length_col) = (col("pose"), col("sensor"), col("length_mm"));
    let (time_col, temperature_col, simulated_col) = (
        t.column("time_s"),
        t.column("temperature_c"),
        t.column("simulated"),
    );
    let pose_columns: Vec<(&'static str, usize)> = ["x_mm", "y_mm", "z_mm"]
        .iter()
        .chain(orientation_columns(o))
        .map(|c| (*c, col(c)))
        .collect();
    // The pose cells of the previous row as written: a row of the same pose that repeats
    // them exactly has the same numbers, already checked.
    let mut previous_cells: Vec<String> = Vec::new();
    // Without logged link readings, the robot's checks come after the rows (see above).
    let deferred = !logged;
    // The sensor of the previous row; whether the robot's sensor names are all different
    // (then a name matches one sensor only, the one `sensor_index` finds).
    let sensors = &robot.table.sensors;
    let mut previous_sensor: Option<usize> = None;
    let names_unique = {
        let mut seen = std::collections::HashSet::new();
        sensors.iter().all(|s| seen.insert(s.name.as_str()))
    };
    let mut rows = || -> Result<(), InputError> {
        while t.next_row_into(&mut next)? {
            if reading_lines.is_empty() {
                // The lists sized once for about the rows the file holds (its size over the
                // first row's length), not grown row by row.
                let rows = t.rows_like(&next).unwrap_or(0).min(options.max_rows);
                campaign.readings.reserve(rows);
                reading_lines.reserve(rows);
                // The largest per-pose lists for poses read by every sensor (not doubled).
                let poses = rows / sensors.len().max(1) + 1;
                entries.reserve(poses);
                campaign.poses.reserve(poses);
                by_label.reserve(poses);
                angles.reserve(if o == Orientation::Rpy { 3 * poses } else { 0 });
            }
            let row = &next;
            let t: &Header = t;
            if reading_lines.len() >= options.max_rows {
                return Err(too_many_rows(t, row, options.max_rows));
            }
            let label = t.required_text_at(row, pose_col)?;
            let sensor_name = t.required_text_at(row, sensor_col)?;
            // Rows usually name the sensors in turn: the one after the previous row's first.
            let next_sensor = previous_sensor
                .map(|s| (s + 1) % sensors.len())
                .filter(|&s| names_unique && sensors[s].name == sensor_name);
            let sensor = next_sensor
                .or_else(|| robot.table.sensor_index(sensor_name))
                .ok_or_else(|| unknown_sensor(&t.file, row.line, robot, sensor_name))?;
            let same_as_previous = previous.is_some_and(|j| labels[j] == label)
                && pose_columns
                    .iter()
                    .zip(&previous_cells)
                    .all(|((_, c), p)| row.get(*c) == Some(p.as_str()));
            let known = match previous {
                Some(j) if labels[j] == label => Some(j),
                _ => by_label.get(label).copied(),
            };
            let (raw, pose) = if same_as_previous {
                // The previous row's pose, cell for cell: it agreed with its pose's first row.
                let j = known.expect("the previous row's pose");
                (entries[j].raw, None)
            } else {
                let raw = raw_pose_at(t, row, &pose_columns)?;
                // A repeated pose that agrees with its first row is that row's pose: not made
                // again.
                let pose = match known {
                    Some(j) if raw.agrees(&entries[j].raw) => None,
                    _ => Some(pose_of(t, row, o, &raw)?),
                };
                // The previous cells' strings reused (one row after the other).
                previous_cells.resize_with(pose_columns.len(), String::new);
                for (p, (_, c)) in previous_cells.iter_mut().zip(&pose_columns) {
                    p.clear();
                    p.push_str(row.get(*c).unwrap_or(""));
                }
                (raw, pose)
            };
            let length_mm = t.number_at(row, length_col)?;
            let time_s = t.optional_number_at(row, time_col)?;
            let temperature_c = t.optional_number_at(row, temperature_col)?;
            if t.optional_bool_at(row, simulated_col)? == Some(true) {
                campaign.simulated = true;
            }
            let link = if logged {
                Some(link_readings(t, row, n)?)
            } else {
                None
            };
            let j = match known {
                // The previous row's pose cell for cell, no link readings: the same pose.
                Some(j) if same_as_previous && link.is_none() => j,
                Some(j) => {
                    let e = &entries[j];
                    same_pose_as_before(
                        &t.file,
                        row.line,
                        label,
                        (&raw, &link),
                        (&e.raw, &e.readings),
                        e.line,
                    )?;
                    j
                }
                None => {
                    let pose = pose.expect("a new pose is made");
                    let j = entries.len();
                    // An unreachable pose is excluded at the end (its rows unchecked), or
                    // refuses the file when there are too many.
                    if !deferred {
                        if let Some(what) =
                            pose_checks.check(&t.file, row.line, robot, options, &pose)?
                        {
                            unusable.push(Unusable {
                                pose: j,
                                what,
                                note: String::new(),
                                field: None,
                            });
                        }
                    }
                    if o == Orientation::Rpy {
                        for (name, v) in raw.iter().filter(|(n, _)| n.ends_with("_deg")) {
                            angles.push((row.line, *name, *v));
                        }
                    }
                    let usable = unusable.last().is_none_or(|u| u.pose != j);
                    if let Some(u) = &link {
                        commanded.push(commanded_lengths(
                            &t.file, row.line, robot, &pose, u, usable,
                        )?);
                    }
                    excluding.push(!usable);
                    by_label.insert(label.to_string(), j);
                    entries.push(PoseEntry {
                        raw,
                        readings: link,
                        line: row.line,
                    });
                    labels.push(label.to_string());
                    campaign.poses.push(pose);
                    j
                }
            };
            previous = Some(j);
            previous_sensor = Some(sensor);
            if options.check_sensor_lengths && !deferred && !excluding[j] {
                let s = &robot.table.sensors[sensor];
                let nominal = s.length_mm(&campaign.poses[j]);
                if !((length_mm - nominal).abs() <= tolerance_mm(nominal)) {
                    return Err(t.err(
                    row,
                    "length_mm",
                    format!(
                        "{} mm is far from the nominal length of sensor {sensor_name:?} at this pose ({nominal:.3} mm): wrong units (mm expected), wrong sensor, or a pose in other units?",
                        show(length_mm, None)
                    ),
                ));
                }
            }
            campaign.readings.push(Reading {
                pose: j,
                sensor,
                length_mm,
                time_s: time_s.into(),
                temperature_c: temperature_c.into(),
            });
            reading_lines.push(row.line);
        }
        Ok(())
    };
    let read = rows();
    let mut theirs = None;
    if deferred {
        // The robot's checks of the rows read (all, or those before the refused one) first;
        // the second robot's beside them (used only when the rows are all read).
        let (c, lines, file) = (&campaign, &reading_lines, t.file.as_str());
        let checks = |r: &Robot| robot_checks(file, r, options, &c.poses, &c.readings, lines, None);
        unusable = match second.filter(|s| same_sensor_names(robot, s)) {
            Some(s) => {
                let (mine, second) = rayon::join(|| checks(robot), || checks(s));
                theirs = Some(second);
                mine
            }
            None => checks(robot),
        }?;
    }
    read?;
    if campaign.readings.is_empty() {
        return Err(InputError::file(
            &t.file,
            "no readings: the file has a header but no rows",
        ));
    }
    check_angle_units(&t.file, &angles)?;
    if logged {
        campaign.commanded_lengths_mm = Some(commanded);
    }
    let pose_lines = entries.iter().map(|e| e.line).collect();
    let f = DataFile::readings(t.file.clone(), campaign, labels, pose_lines, reading_lines);
    Ok((f, unusable, theirs))
}

/// The commanded lengths of a pose from its logged link readings `u` (its first row, on
/// `line`): checked against the pose when it is `usable` (kept), else only converted.
fn commanded_lengths(
    file: &str,
    line: usize,
    robot: &Robot,
    pose: &Pose,
    u: &[f64],
    usable: bool,
) -> Result<Vec<f64>, InputError> {
    if usable {
        check_link_readings(file, line, robot, pose, u, None, "commanded pose", "")
    } else {
        Ok(u.iter()
            .enumerate()
            .map(|(i, v)| robot.length_mm(i, *v))
            .collect())
    }
}

/// The robot's checks of a new pose of a readings file made at its first row (with logged
/// link readings, whose check needs to know whether the pose is kept): its position (mm, not
/// metres), J1's condition number at home (computed at the first pose), its reachability.
#[derive(Default)]
struct PoseChecks {
    bound: Option<(f64, f64)>,
    table: Option<JointTable>,
}

impl PoseChecks {
    /// Why the pose is unreachable (to exclude), `None` when it is reachable; the error of
    /// a refused position or of the condition number at home.
    fn check(
        &mut self,
        file: &str,
        line: usize,
        robot: &Robot,
        options: &ReadOptions,
        pose: &Pose,
    ) -> Result<Option<String>, InputError> {
        check_position_units(file, line, &pose.position_mm, robot)?;
        if !options.max_condition_ratio.is_finite() {
            return Ok(None);
        }
        let b = match self.bound {
            Some(b) => b,
            None => *self.bound.insert(condition_bound(
                &robot.table,
                options.max_condition_ratio,
                file,
                line,
            )?),
        };
        let table = self
            .table
            .get_or_insert_with(|| widened(&robot.table, options.link_limit_margin_mm));
        Ok(unreachable_why(table, pose, b))
    }
}

/// How a robot judges the reachability of poses for a reader ([`robot_checks`]): its table
/// with the link limits widened by the read options' margin, and the condition bound.
pub(crate) struct PoseJudge {
    table: JointTable,
    bound: (f64, f64),
}

impl PoseJudge {
    /// The judge of `robot` with `options`; `None` when the options judge no pose (no
    /// condition limit) or the bound cannot be found (then [`robot_checks`] refuses the file
    /// at its first row).
    pub(crate) fn new(robot: &Robot, options: &ReadOptions) -> Option<PoseJudge> {
        if !options.max_condition_ratio.is_finite() {
            return None;
        }
        let bound = condition_bound(&robot.table, options.max_condition_ratio, "", 0).ok()?;
        Some(PoseJudge {
            table: widened(&robot.table, options.link_limit_margin_mm),
            bound,
        })
    }

    /// A judge of many poses (see [`ReachableAt`]).
    pub(crate) fn at(&self) -> ReachableAt<'_> {
        ReachableAt::new(&self.table)
    }

    /// Why `pose` is to be excluded, if it is: what [`robot_checks`] finds of it.
    pub(crate) fn why(&self, at: &ReachableAt<'_>, pose: &Pose) -> Option<String> {
        why_unreachable(at.check(pose, self.bound.0), pose, self.bound)
    }
}

/// The checks of a readings file read without logged link readings that depend on the
/// robot, in the order the rows give them: at each pose's first row its position (mm, not
/// metres), J1's condition number at home (at the first pose) and its reachability (an
/// unreachable pose is to be excluded: returned), then at every row of a pose kept the
/// sensor's length against the nominal. The reachability of all the poses is found first,
/// in parallel (it depends on the pose alone), then the first row whose sensor length is
/// refused, in parallel too (whether its pose is kept depends on the pose alone).
///
/// The poses' judgements ([`PoseJudge::why`] of each pose, in order; at least those of the
/// poses read) are taken from `judged` when it holds them, else made here.
pub(crate) fn robot_checks(
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
    poses: &[Pose],
    readings: &[Reading],
    reading_lines: &[usize],
    judged: Option<Vec<Option<String>>>,
) -> Result<Vec<Unusable>, InputError> {
    use rayon::prelude::*;
    // Poses are numbered in the order of their first rows.
    let met = readings.iter().map(|r| r.pose + 1).max().unwrap_or(0);
    let reach = options.max_condition_ratio.is_finite() && met > 0;
    let mut bound = reach.then(|| {
        condition_bound(
            &robot.table,
            options.max_condition_ratio,
            file,
            reading_lines[0],
        )
    });
    let why: Vec<Option<String>> = match (&bound, judged) {
        (Some(Ok(_)), Some(why)) if why.len() >= met => why,
        (Some(Ok(b)), _) => {
            let judge = PoseJudge {
                table: widened(&robot.table, options.link_limit_margin_mm),
                bound: *b,
            };
            let at = judge.at();
            poses[..met].par_iter().map(|p| judge.why(&at, p)).collect()
        }
        _ => Vec::new(),
    };
    // A pose is left out at its first row, before the rows of its own are checked.
    let excluded = |j: usize| why.get(j).is_some_and(Option::is_some);
    let far = |r: &Reading| {
        let nominal = robot.table.sensors[r.sensor].length_mm(&poses[r.pose]);
        !((r.length_mm - nominal).abs() <= tolerance_mm(nominal))
    };
    let first_far = if options.check_sensor_lengths {
        readings
            .par_iter()
            .with_min_len(1 << 12)
            .position_first(|r| !excluded(r.pose) && far(r))
    } else {
        None
    };
    let mut unusable = Vec::new();
    let mut next_pose = 0;
    for (k, (r, &line)) in readings.iter().zip(reading_lines).enumerate() {
        let j = r.pose;
        if j == next_pose {
            next_pose += 1;
            check_position_units(file, line, &poses[j].position_mm, robot)?;
            if let Some(b) = bound.take() {
                b?;
            }
            if let Some(what) = why.get(j).cloned().flatten() {
                unusable.push(Unusable {
                    pose: j,
                    what,
                    note: String::new(),
                    field: None,
                });
            }
        }
        if first_far == Some(k) {
            let s = &robot.table.sensors[r.sensor];
            let nominal = s.length_mm(&poses[j]);
            return Err(InputError::field(
                file,
                line,
                "length_mm",
                format!(
                    "{} mm is far from the nominal length of sensor {:?} at this pose ({nominal:.3} mm): wrong units (mm expected), wrong sensor, or a pose in other units?",
                    show(r.length_mm, None),
                    s.name
                ),
            ));
        }
    }
    Ok(unusable)
}

/// The second robot's checks of a readings file (see [`read_readings_unexcluded`]): the
/// poses to exclude for it, or the error [`read_readings_table`] would give it; `None` when
/// they cannot be made on the rows the first robot read (the file logged link readings,
/// or the robots do not name the same sensors in the same order): read the file for it on
/// its own.
pub(crate) type SecondChecks = Option<Result<Vec<Unusable>, InputError>>;

/// Whether robots `a` and `b` name the same sensors in the same order.
fn same_sensor_names(a: &Robot, b: &Robot) -> bool {
    let (a, b) = (&a.table.sensors, &b.table.sensors);
    a.len() == b.len() && a.iter().zip(b).all(|(a, b)| a.name == b.name)
}

/// Checks that a row of a pose already given (on line `line`) repeats its commanded pose and
/// link readings (`now` against `before`), naming the field that differs.
pub(crate) fn same_pose_as_before(
    file: &str,
    line_now: usize,
    label: &str,
    now: (&RawPose, &Option<Vec<f64>>),
    before: (&RawPose, &Option<Vec<f64>>),
    line: usize,
) -> Result<(), InputError> {
    for ((name, a), (_, b)) in now.0.iter().zip(before.0.iter()) {
        if !close(*a, *b) {
            return Err(InputError::field(
                file,
                line_now,
                *name,
                format!("{} differs from {} given for pose {:?} on line {}: rows of one pose share one commanded pose (a repeated pose label?)", show(*a, None), show(*b, None), shorten(label), line),
            ));
        }
    }
    if let (Some(a), Some(b)) = (now.1, before.1) {
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            if !close(*x, *y) {
                return Err(InputError::field(
                    file,
                    line_now,
                    format!("reading_{}", k + 1),
                    format!("{x} differs from {y} given for pose {:?} on line {}: rows of one pose share one command", shorten(label), line),
                ));
            }
        }
    }
    Ok(())
}

/// Reads tracker pose measurements (see `docs/formats.md`), parsed and unregistered: the rows
/// are checked field by field and for units, not yet against the robot (reachability, link
/// readings consistent), which follows the registration of the tracker frame on the fit side
/// (`cpm_workflow::ingest::register_tracker_files`); the file is returned with
/// [`DataFile::checked`] false.
pub fn read_pose_measurements(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let mut t = Table::parse(text, file)?;
    read_pose_measurements_table(&mut t, robot, options)
}

pub(crate) fn read_pose_measurements_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let n = robot.num_links();
    let o = orientation(t)?;
    t.check_columns(
        &["pose", "x_mm", "y_mm", "z_mm"],
        &["time_s", "temperature_c", "simulated"],
        |h| {
            RPY_COLUMNS.contains(&h)
                || QUATERNION_COLUMNS.contains(&h)
                || super::table::reading_index(h).is_some()
        },
    )?;
    let links = t.reading_columns()?.len();
    tracker_link_columns(&t.file, t.header_line, links, n)?;
    let mut read = TrackerRead::new(t.simulated_mark);
    while let Some(row) = t.next_row()? {
        let t: &Header = t;
        read.check_more(&t.file, row.line, options.max_rows)?;
        let label = t.required_text(&row, "pose")?;
        read.check_label(&t.file, row.line, label)?;
        let (measured, raw, mask) = match partial_pose(t, &row, o)? {
            None => {
                let (m, raw) = parse_pose(t, &row, o)?;
                (m, raw, [true; 6])
            }
            Some((m, mask, raw)) => (m, raw, mask),
        };
        let readings = link_readings(t, &row, n)?;
        let time_s = t.optional_number(&row, "time_s")?;
        let temperature_c = t.optional_number(&row, "temperature_c")?;
        let simulated = t.optional_bool(&row, "simulated")? == Some(true);
        let row = TrackerRow {
            line: row.line,
            label: label.to_string(),
            measured,
            readings,
            mask,
        };
        read.push(robot, row, &raw, (time_s, temperature_c), simulated);
    }
    read.finish(&t.file, robot)
}

/// A tracker file being read, one row (pose) after the other, by the CSV reader
/// ([`read_pose_measurements`]) and the reader of values ([`crate::rows`]): what the rows
/// make, and the checks of a row against those before it and of the whole file.
pub(crate) struct TrackerRead {
    campaign: Campaign,
    /// The first line of each label.
    seen: HashMap<String, usize>,
    labels: Vec<String>,
    lines: Vec<usize>,
    /// Each row's commanded link lengths, mm.
    commanded: Vec<Vec<f64>>,
    rows: Vec<TrackerRow>,
    angles: AngleCells,
}

impl TrackerRead {
    /// Nothing read yet; `simulated` when the file says so before its rows.
    pub(crate) fn new(simulated: bool) -> Self {
        TrackerRead {
            campaign: Campaign {
                simulated,
                ..Campaign::default()
            },
            seen: HashMap::new(),
            labels: Vec::new(),
            lines: Vec::new(),
            commanded: Vec::new(),
            rows: Vec::new(),
            angles: Vec::new(),
        }
    }

    /// Refuses a row on `line` beyond the `max` rows allowed.
    pub(crate) fn check_more(&self, file: &str, line: usize, max: usize) -> Result<(), InputError> {
        if self.lines.len() >= max {
            return Err(too_many_rows_at(file, line, max));
        }
        Ok(())
    }

    /// Refuses the label of a row on `line` given to a row before: one row per pose.
    pub(crate) fn check_label(
        &self,
        file: &str,
        line: usize,
        label: &str,
    ) -> Result<(), InputError> {
        match self.seen.get(label) {
            Some(first) => Err(InputError::field(
                file,
                line,
                "pose",
                format!("pose {:?} appears again (first on line {first}): a tracker file has one row per pose", shorten(label)),
            )),
            None => Ok(()),
        }
    }

    /// Adds a row checked field by field: its pose made of the numbers `raw`, its time and
    /// temperature, whether it is simulated.
    pub(crate) fn push(
        &mut self,
        robot: &Robot,
        row: TrackerRow,
        raw: &RawPose,
        (time_s, temperature_c): (Option<f64>, Option<f64>),
        simulated: bool,
    ) {
        for (name, v) in raw.iter().filter(|(n, _)| n.ends_with("_deg")) {
            self.angles.push((row.line, *name, *v));
        }
        let q = self.campaign.pose_measurements.len();
        for (a, m) in row.mask.iter().enumerate() {
            if !m {
                self.campaign.unmeasured.push((q, a));
            }
        }
        if simulated {
            self.campaign.simulated = true;
        }
        self.commanded.push(
            row.readings
                .iter()
                .enumerate()
                .map(|(i, v)| robot.length_mm(i, *v))
                .collect(),
        );
        self.seen.insert(row.label.clone(), row.line);
        let j = self.campaign.poses.len();
        self.campaign.poses.push(row.measured);
        self.campaign.pose_measurements.push(PoseMeasurement {
            pose: j,
            measured: row.measured,
            time_s,
            temperature_c,
        });
        self.labels.push(row.label.clone());
        self.lines.push(row.line);
        self.rows.push(row);
    }

    /// The file of the rows read, after the checks of the whole file (some rows, units).
    pub(crate) fn finish(self, file: &str, robot: &Robot) -> Result<DataFile, InputError> {
        let TrackerRead {
            mut campaign,
            labels,
            lines,
            commanded,
            rows,
            angles,
            ..
        } = self;
        if campaign.pose_measurements.is_empty() {
            return Err(InputError::file(
                file,
                "no pose measurements: the file has a header but no rows",
            ));
        }
        check_angle_units(file, &angles)?;
        check_tracker_position_units(file, &rows, &commanded)?;
        // A row not measured in full: its pose (the start of forward kinematics) is the
        // nominal forward kinematics of its commanded lengths.
        for (q, r) in rows.iter().enumerate().filter(|(_, r)| !r.complete()) {
            let (p, _) = cpm_kinematics::forward(
                &robot.table,
                &commanded[q],
                &robot.table.home,
                &cpm_kinematics::ForwardOptions::default(),
            )
            .map_err(|e| {
                InputError::field(
                    file,
                    r.line,
                    "reading_1",
                    format!("the link readings give no pose (forward kinematics: {e}): wrong units or link mapping?"),
                )
            })?;
            campaign.poses[q] = p;
        }
        campaign.commanded_lengths_mm = Some(commanded);
        Ok(DataFile {
            file: file.to_string(),
            kind: FileKind::PoseMeasurements,
            campaign,
            pose_labels: labels,
            pose_lines: lines,
            reading_lines: Vec::new(),
            registration: None,
            tracker_rows: rows,
            checked: false,
            point_lines: Vec::new(),
            point_frame: None,
            excluded: Vec::new(),
        })
    }
}

/// Refuses a tracker file whose measured positions spread a hundred times less than the
/// commanded link lengths (over more than 1 mm of link travel): metres, most likely. The
/// tracker frame may be anywhere, so only spreads are compared. The error names the row of
/// the largest position move from the first row.
fn check_tracker_position_units(
    file: &str,
    rows: &[TrackerRow],
    lengths_mm: &[Vec<f64>],
) -> Result<(), InputError> {
    let spread = |vals: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        hi - lo
    };
    let n = lengths_mm.first().map_or(0, Vec::len);
    let travel = (0..n)
        .map(|i| spread(&mut lengths_mm.iter().map(|l| l[i])))
        .fold(0.0_f64, f64::max);
    let moved = (0..3)
        .map(|a| {
            spread(
                &mut rows
                    .iter()
                    .filter(|r| r.mask[a])
                    .map(|r| r.measured.position_mm[a]),
            )
        })
        .fold(0.0_f64, f64::max);
    if !(travel > 1.0 && moved * 100.0 < travel) {
        return Ok(());
    }
    let full: Vec<&TrackerRow> = rows.iter().filter(|r| r.mask[..3] == [true; 3]).collect();
    let Some(first) = full.first().map(|r| r.measured.position_mm) else {
        return Ok(());
    };
    let row = full
        .iter()
        .max_by(|a, b| {
            (a.measured.position_mm - first)
                .norm()
                .total_cmp(&(b.measured.position_mm - first).norm())
        })
        .expect("rows");
    let k = (row.measured.position_mm - first).iamax();
    Err(InputError::field(
        file,
        row.line,
        ["x_mm", "y_mm", "z_mm"][k],
        format!(
            "the measured positions move by {moved:.4} mm over the file while the links travel {travel:.3} mm: metres? Positions are in mm"
        ),
    ))
}

/// Where each reading of a merged campaign comes from: its file, named once for all its
/// readings (the files' readings follow each other), and its line.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReadingOrigins {
    /// Each file and the index of its first reading, in reading order (a file without
    /// readings is not listed).
    files: Vec<(std::sync::Arc<str>, usize)>,
    /// Per reading, its line.
    lines: Vec<usize>,
}

impl ReadingOrigins {
    /// The readings of one more file, on `lines` (moved in when they are the first).
    pub fn push_file(&mut self, file: std::sync::Arc<str>, lines: Vec<usize>) {
        if lines.is_empty() {
            return;
        }
        self.files.push((file, self.lines.len()));
        if self.lines.is_empty() {
            self.lines = lines;
        } else {
            self.lines.extend(lines);
        }
    }

    /// How many readings.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// True without readings.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// File and line of reading `k`, `None` past the last.
    pub fn get(&self, k: usize) -> Option<(&str, usize)> {
        let line = *self.lines.get(k)?;
        let f = self.files.partition_point(|(_, first)| *first <= k);
        Some((&*self.files[f - 1].0, line))
    }

    /// File and line of every reading, in order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, usize)> + '_ {
        self.files
            .iter()
            .enumerate()
            .flat_map(move |(i, (file, first))| {
                let end = self.files.get(i + 1).map_or(self.lines.len(), |f| f.1);
                self.lines[*first..end].iter().map(move |l| (&**file, *l))
            })
    }

    /// The origins of the readings `keep` says to keep (given each reading's index).
    fn kept(&self, mut keep: impl FnMut(usize) -> bool) -> Self {
        let mut o = ReadingOrigins::default();
        for (i, (file, first)) in self.files.iter().enumerate() {
            let end = self.files.get(i + 1).map_or(self.lines.len(), |f| f.1);
            let lines: Vec<usize> = (*first..end)
                .filter(|&k| keep(k))
                .map(|k| self.lines[k])
                .collect();
            o.push_file(file.clone(), lines);
        }
        o
    }
}

/// Several measurement files merged into one campaign, with where each pose came from.
#[derive(Debug, Clone)]
pub struct Merged {
    /// The campaign (poses of the files one after the other).
    pub campaign: Campaign,
    /// Per campaign pose: (file, first line, label).
    pub pose_origin: Vec<(String, usize, String)>,
    /// Per reading: file and line ([`ReadingOrigins`]: the file's name once per file, the
    /// lines as the reader gave them).
    pub reading_origin: ReadingOrigins,
    /// Per point measurement: (file, line).
    pub point_origin: Vec<(String, usize)>,
    /// Per tilt measurement: (file, line).
    pub tilt_origin: Vec<(String, usize)>,
    /// The automatic registration of the tracker files, if any.
    pub registration: Option<RegistrationReport>,
    /// Per point file: (file, the rough frame its reader applied, `p_tracker = R p_base + t`).
    pub point_frames: Vec<(String, Pose)>,
    /// The poses left out (with all their rows), file after file: by the readers because
    /// the machine cannot be there ([`POSES_PER_EXCLUDED_POSE`]), and those a command left
    /// out after (see [`Merged::without_pose`]).
    pub excluded: Vec<ExcludedPose>,
}

impl Merged {
    /// The rotation from the campaign's base axes to the tracker's own axes of the file
    /// `file` (the rough registration its reader applied to its tracker poses or points), or
    /// `None` when its measurements were taken as they are.
    pub fn tracker_axes(&self, file: &str) -> Option<cpm_geometry::Rotation3<f64>> {
        let tracker = self.registration.as_ref().and_then(|r| {
            r.sessions
                .iter()
                .find(|s| s.file == file && s.applied)
                .map(|s| s.frame.rotation)
        });
        tracker.or_else(|| {
            self.point_frames
                .iter()
                .find(|(f, _)| f == file)
                .map(|(_, p)| p.rotation)
        })
    }

    /// Residuals in observation order with tracker positions, orientations and point
    /// coordinates turned into the tracker's own axes (borrowed as they are when nothing
    /// turns): what `residuals.csv` and the outlier table give.
    pub fn in_tracker_axes<'a>(&self, residuals: &'a [f64]) -> std::borrow::Cow<'a, [f64]> {
        let merged = self;
        let c = &merged.campaign;
        if c.pose_measurements.is_empty() && c.point_measurements.is_empty() {
            return std::borrow::Cow::Borrowed(residuals);
        }
        let mut residuals = residuals.to_vec();
        let mut to_tracker = |rows: &[Option<usize>], file: &str| {
            let Some(r) = merged.tracker_axes(file) else {
                return;
            };
            if let [Some(a), Some(b), Some(k)] = *rows {
                let v = r * cpm_geometry::Vector3::new(residuals[a], residuals[b], residuals[k]);
                (residuals[a], residuals[b], residuals[k]) = (v.x, v.y, v.z);
            }
        };
        for (q, rows) in c.pose_observation_rows().iter().enumerate() {
            let pose = c.pose_measurements[q].pose;
            let Some((file, ..)) = merged.pose_origin.get(pose) else {
                continue;
            };
            to_tracker(&rows[..3], file);
            to_tracker(&rows[3..], file);
        }
        let p0 = c.first_point_observation();
        for (q, pm) in c.point_measurements.iter().enumerate() {
            let Some((file, ..)) = merged.pose_origin.get(pm.pose) else {
                continue;
            };
            let o = p0 + 3 * q;
            to_tracker(&[Some(o), Some(o + 1), Some(o + 2)], file);
        }
        std::borrow::Cow::Owned(residuals)
    }

    /// The merged data without campaign pose `pose` and every observation taken at it, the
    /// poses after it renumbered: the campaign ([`Campaign::without_poses`]) and the origins
    /// of what is left stay aligned (each remaining pose keeps its file, line and label).
    /// [`excluded`](Self::excluded) is unchanged: record why the pose was left out there.
    pub fn without_pose(&self, pose: usize) -> Merged {
        let c = &self.campaign;
        fn kept<T: Clone>(origin: &[T], poses: impl Iterator<Item = usize>, pose: usize) -> Vec<T> {
            origin
                .iter()
                .zip(poses)
                .filter(|(_, p)| *p != pose)
                .map(|(o, _)| o.clone())
                .collect()
        }
        Merged {
            campaign: c.without_poses(|j| j == pose),
            pose_origin: kept(&self.pose_origin, 0..c.poses.len(), pose),
            reading_origin: self.reading_origin.kept(|k| c.readings[k].pose != pose),
            point_origin: kept(
                &self.point_origin,
                c.point_measurements.iter().map(|m| m.pose),
                pose,
            ),
            tilt_origin: kept(
                &self.tilt_origin,
                c.tilt_measurements.iter().map(|m| m.pose),
                pose,
            ),
            registration: self.registration.clone(),
            point_frames: self.point_frames.clone(),
            excluded: self.excluded.clone(),
        }
    }

    /// `file:line` of a campaign pose, for messages.
    pub fn pose_location(&self, pose: usize) -> Option<String> {
        self.pose_origin
            .get(pose)
            .map(|(f, l, label)| format!("{f}:{l}: pose {label:?}"))
    }
}

/// Merges measurement files: poses are appended file after file; when some files log the
/// commanded link readings and others do not, the others get their poses' nominal inverse
/// kinematics (what the model would use anyway).
pub fn merge(files: Vec<DataFile>, robot: &Robot) -> Merged {
    let any_commanded = files
        .iter()
        .any(|f| f.campaign.commanded_lengths_mm.is_some());
    let mut out = Campaign::default();
    let mut commanded = Vec::new();
    let mut pose_origin = Vec::new();
    let mut reading_origin = ReadingOrigins::default();
    let mut point_origin = Vec::new();
    let mut tilt_origin = Vec::new();
    let mut tilt_sessions = 0;
    let mut excluded = Vec::new();
    let mut registration: Option<RegistrationReport> = None;
    let point_frames: Vec<(String, Pose)> = files
        .iter()
        .filter_map(|f| f.point_frame.map(|p| (f.file.clone(), p)))
        .collect();
    // Each point file is a session with its own frame.
    let mut point_sessions = 0;
    for f in files {
        if let Some(r) = &f.registration {
            match &mut registration {
                Some(acc) => {
                    for s in &r.sessions {
                        if !acc.sessions.iter().any(|a| a.file == s.file) {
                            acc.sessions.push(s.clone());
                        }
                    }
                }
                None => registration = Some(r.clone()),
            }
        }
        let mut c = f.campaign;
        let base = out.poses.len();
        // Each file is a session: its motion history starts afresh.
        if base > 0 && !c.poses.is_empty() {
            out.session_starts.push(base);
        }
        out.session_starts
            .extend(c.session_starts.iter().map(|s| s + base));
        out.simulated |= c.simulated;
        if any_commanded {
            match &c.commanded_lengths_mm {
                Some(l) => commanded.extend(l.iter().cloned()),
                None => commanded.extend(
                    c.poses
                        .iter()
                        .map(|p| cpm_kinematics::inverse_lengths(&robot.table, p)),
                ),
            }
        }
        out.poses.extend(c.poses.iter().copied());
        if out.readings.is_empty() && base == 0 {
            // The first file's readings as they are (numbered from its first pose): moved,
            // not copied (10^6 readings are 56 MB).
            out.readings = std::mem::take(&mut c.readings);
        } else {
            out.readings.extend(c.readings.iter().map(|r| Reading {
                pose: r.pose + base,
                ..*r
            }));
        }
        let q0 = out.pose_measurements.len();
        out.unmeasured
            .extend(c.unmeasured.iter().map(|(q, a)| (q + q0, *a)));
        out.pose_measurements
            .extend(c.pose_measurements.iter().map(|m| PoseMeasurement {
                pose: m.pose + base,
                ..*m
            }));
        let sessions = c.point_sessions();
        out.point_measurements
            .extend(c.point_measurements.iter().map(|m| PointMeasurement {
                pose: m.pose + base,
                session: m.session + point_sessions,
                ..*m
            }));
        point_sessions += sessions;
        if c.point_sigma_um > 0.0 {
            out.point_sigma_um = c.point_sigma_um;
        }
        if f.kind == FileKind::TiltMeasurements {
            tilt_origin.extend(f.point_lines.iter().map(|l| (f.file.clone(), *l)));
        } else {
            point_origin.extend(f.point_lines.iter().map(|l| (f.file.clone(), *l)));
        }
        let sessions = c.tilt_sessions();
        out.tilt_measurements
            .extend(c.tilt_measurements.iter().map(|m| TiltMeasurement {
                pose: m.pose + base,
                session: m.session + tilt_sessions,
                ..*m
            }));
        tilt_sessions += sessions;
        for (line, label) in f.pose_lines.iter().zip(f.pose_labels) {
            pose_origin.push((f.file.clone(), *line, label));
        }
        reading_origin.push_file(f.file.as_str().into(), f.reading_lines);
        excluded.extend(f.excluded);
    }
    if any_commanded {
        out.commanded_lengths_mm = Some(commanded);
    }
    Merged {
        campaign: out,
        pose_origin,
        reading_origin,
        point_origin,
        tilt_origin,
        registration,
        point_frames,
        excluded,
    }
}

pub(crate) fn simulated_header(note: &str) -> String {
    format!(
        "{SIMULATED_MARK} {}{}{}\n",
        env!("CARGO_PKG_VERSION"),
        if note.is_empty() { "" } else { ": " },
        note.replace(['\n', '\r'], " ")
    )
}

pub(crate) fn pose_fields(p: &Pose) -> String {
    let [r, pi, y] = p.rpy_deg();
    // The angles come back from radians: 15 significant digits drop the conversion's last
    // bits (a plan's 3.30054776056 deg is written as such, not 3.3005477605599998).
    let deg = |a: f64| num(round15(a) + 0.0);
    format!(
        "{},{},{},{},{},{}",
        num(p.position_mm.x),
        num(p.position_mm.y),
        num(p.position_mm.z),
        deg(r),
        deg(pi),
        deg(y)
    )
}

/// `v` rounded to 15 significant digits (the nearest `f64` to its 15-digit decimal).
fn round15(v: f64) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return v;
    }
    format!("{v:.14e}").parse().unwrap_or(v)
}

pub(crate) fn opt(v: Option<f64>) -> String {
    v.map(num).unwrap_or_default()
}

/// Writes the length readings of a campaign (the format [`read_readings`] reads). Pose labels
/// are the pose numbers from 1; link readings are written when the campaign logs commanded
/// lengths (converted with the robot's link mapping); simulated campaigns get the
/// `# simulated by cpm` line and a `simulated` column. `note` goes on the simulated line.
pub fn write_readings(campaign: &Campaign, robot: &Robot, note: &str) -> String {
    let n = robot.num_links();
    let has_time = campaign.readings.iter().any(|r| r.time_s.is_some());
    let has_temp = campaign.readings.iter().any(|r| r.temperature_c.is_some());
    let logged = campaign.commanded_lengths_mm.as_ref();
    let mut s = String::new();
    if campaign.simulated {
        s.push_str(&simulated_header(note));
    }
    s.push_str("pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm");
    if has_time {
        s.push_str(",time_s");
    }
    if has_temp {
        s.push_str(",temperature_c");
    }
    if logged.is_some() {
        for k in 1..=n {
            s.push_str(&format!(",reading_{k}"));
        }
    }
    if campaign.simulated {
        s.push_str(",simulated");
    }
    s.push('\n');
    for r in &campaign.readings {
        let pose = &campaign.poses[r.pose];
        s.push_str(&format!(
            "{},{},{},{}",
            r.pose + 1,
            field(&robot.table.sensors[r.sensor].name),
            pose_fields(pose),
            num(r.length_mm)
        ));
        if has_time {
            s.push_str(&format!(",{}", opt(r.time_s.get())));
        }
        if has_temp {
            s.push_str(&format!(",{}", opt(r.temperature_c.get())));
        }
        if let Some(l) = logged {
            for (i, len) in l[r.pose].iter().enumerate() {
                s.push_str(&format!(",{}", num(robot.reading(i, *len))));
            }
        }
        if campaign.simulated {
            s.push_str(",true");
        }
        s.push('\n');
    }
    s
}

/// Writes the pose measurements of a campaign (the format [`read_pose_measurements`] reads):
/// one row per measurement with the commanded link readings (from the campaign's commanded
/// lengths, or the nominal inverse kinematics of the pose) and the measured pose.
pub fn write_pose_measurements(campaign: &Campaign, robot: &Robot, note: &str) -> String {
    let n = robot.num_links();
    let has_time = campaign
        .pose_measurements
        .iter()
        .any(|m| m.time_s.is_some());
    let has_temp = campaign
        .pose_measurements
        .iter()
        .any(|m| m.temperature_c.is_some());
    let mut s = String::new();
    if campaign.simulated {
        s.push_str(&simulated_header(note));
    }
    s.push_str("pose");
    for k in 1..=n {
        s.push_str(&format!(",reading_{k}"));
    }
    s.push_str(",x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg");
    if has_time {
        s.push_str(",time_s");
    }
    if has_temp {
        s.push_str(",temperature_c");
    }
    if campaign.simulated {
        s.push_str(",simulated");
    }
    s.push('\n');
    for (q, m) in campaign.pose_measurements.iter().enumerate() {
        let lengths = match &campaign.commanded_lengths_mm {
            Some(l) => l[m.pose].clone(),
            None => cpm_kinematics::inverse_lengths(&robot.table, &campaign.poses[m.pose]),
        };
        s.push_str(&format!("{}", m.pose + 1));
        for (i, len) in lengths.iter().enumerate() {
            s.push_str(&format!(",{}", num(robot.reading(i, *len))));
        }
        let fields = pose_fields(&m.measured);
        if campaign.unmeasured.is_empty() {
            s.push_str(&format!(",{fields}"));
        } else {
            // Components not measured are empty cells (the orientation as a whole).
            for (c, v) in fields.split(',').enumerate() {
                let measured = campaign.is_measured(q, c.min(3));
                s.push(',');
                if measured {
                    s.push_str(v);
                }
            }
        }
        if has_time {
            s.push_str(&format!(",{}", opt(m.time_s)));
        }
        if has_temp {
            s.push_str(&format!(",{}", opt(m.temperature_c)));
        }
        if campaign.simulated {
            s.push_str(",true");
        }
        s.push('\n');
    }
    s
}

/// Reads a list of poses: `x_mm,y_mm,z_mm` and `roll_deg,pitch_deg,yaw_deg` (or
/// `qw,qx,qy,qz`), optional `pose` label, `time_s`, `temperature_c`. Measurement files are
/// refused (use them as `--data`).
pub fn read_pose_list(text: &str, file: &str) -> Result<Vec<PoseRow>, InputError> {
    read_pose_list_from(text.as_bytes(), file).map_err(ReadError::into_input)
}

/// Reads a list of poses from the file at `path`, streaming its rows.
pub fn read_pose_list_file(path: &Path) -> Result<Vec<PoseRow>, ReadError> {
    read_pose_list_from(open(path)?, &path.display().to_string())
}

/// Reads a list of poses from a reader (see [`read_pose_list`]).
pub fn read_pose_list_from<R: Read>(source: R, file: &str) -> Result<Vec<PoseRow>, ReadError> {
    let mut t = Table::from_reader(source, file)?;
    pose_list_table(&mut t).map_err(|e| finish(&mut t, e))
}

fn pose_list_table<R: Read>(t: &mut Table<R>) -> Result<Vec<PoseRow>, InputError> {
    let kind = t.kind()?;
    if kind != FileKind::Poses {
        return Err(InputError::line(
            &t.file,
            t.header_line,
            format!(
                "expected a list of poses (x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg), but the header says {}",
                kind.describe()
            ),
        ));
    }
    let o = orientation(t)?;
    t.check_columns(
        &["x_mm", "y_mm", "z_mm"],
        &["pose", "time_s", "temperature_c"],
        |h| RPY_COLUMNS.contains(&h) || QUATERNION_COLUMNS.contains(&h),
    )?;
    let mut out = Vec::new();
    let mut angles: AngleCells = Vec::new();
    while let Some(row) = t.next_row()? {
        let t: &Header = t;
        if out.len() >= MAX_ROWS {
            return Err(too_many_rows(t, &row, MAX_ROWS));
        }
        let label = match t.text(&row, "pose") {
            Some(l) if !l.is_empty() => l.to_string(),
            Some(_) => return Err(t.err(&row, "pose", "missing value")),
            None => (out.len() + 1).to_string(),
        };
        let (pose, raw) = parse_pose(t, &row, o)?;
        for (name, v) in raw.iter().filter(|(n, _)| n.ends_with("_deg")) {
            angles.push((row.line, *name, *v));
        }
        out.push(PoseRow {
            line: row.line,
            label,
            pose,
            time_s: t.optional_number(&row, "time_s")?,
            temperature_c: t.optional_number(&row, "temperature_c")?,
        });
    }
    if out.is_empty() {
        return Err(InputError::file(
            &t.file,
            "no poses: the file has a header but no rows",
        ));
    }
    check_angle_units(&t.file, &angles)?;
    Ok(out)
}

/// Writes a list of poses (the format [`read_pose_list`] reads), labelled from 1.
pub fn write_pose_list(poses: &[Pose]) -> String {
    let mut s = String::from("pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n");
    for (j, p) in poses.iter().enumerate() {
        s.push_str(&format!("{},{}\n", j + 1, pose_fields(p)));
    }
    s
}

/// Reads compensated commands (what [`write_commands`] writes, `cpm compensate`'s output):
/// per row the target pose and the `reading_1..reading_N` to command, `N = num_links`;
/// the `length_k_mm` columns are accepted and ignored (they follow from the readings).
pub fn read_commands_file(
    path: &Path,
    num_links: usize,
) -> Result<Vec<(PoseRow, Vec<f64>)>, ReadError> {
    let file = path.display().to_string();
    let mut t = Table::from_reader(open(path)?, &file)?;
    commands_table(&mut t, num_links).map_err(|e| finish(&mut t, e))
}

fn commands_table<R: Read>(
    t: &mut Table<R>,
    num_links: usize,
) -> Result<Vec<(PoseRow, Vec<f64>)>, InputError> {
    let o = orientation(t)?;
    let ks = t.reading_columns()?;
    if ks.len() != num_links {
        return Err(InputError::field(
            &t.file,
            t.header_line,
            format!("reading_{}", ks.len().min(num_links) + 1),
            format!(
                "{} reading columns for a robot with {num_links} links",
                ks.len()
            ),
        ));
    }
    t.check_columns(
        &["x_mm", "y_mm", "z_mm"],
        &["pose", "time_s", "temperature_c"],
        |h| {
            RPY_COLUMNS.contains(&h)
                || QUATERNION_COLUMNS.contains(&h)
                || super::table::reading_index(h).is_some()
                || h.strip_prefix("length_")
                    .and_then(|r| r.strip_suffix("_mm"))
                    .is_some_and(|k| {
                        k.parse::<usize>()
                            .is_ok_and(|k| (1..=num_links).contains(&k))
                    })
        },
    )?;
    let mut out = Vec::new();
    while let Some(row) = t.next_row()? {
        let t: &Header = t;
        if out.len() >= MAX_ROWS {
            return Err(too_many_rows(t, &row, MAX_ROWS));
        }
        let label = match t.text(&row, "pose") {
            Some(l) if !l.is_empty() => l.to_string(),
            Some(_) => return Err(t.err(&row, "pose", "missing value")),
            None => (out.len() + 1).to_string(),
        };
        let (pose, _) = parse_pose(t, &row, o)?;
        let mut readings = Vec::with_capacity(num_links);
        for k in 1..=num_links {
            readings.push(t.number(&row, &format!("reading_{k}"))?);
        }
        out.push((
            PoseRow {
                line: row.line,
                label,
                pose,
                time_s: t.optional_number(&row, "time_s")?,
                temperature_c: t.optional_number(&row, "temperature_c")?,
            },
            readings,
        ));
    }
    if out.is_empty() {
        return Err(InputError::file(
            &t.file,
            "no commands: the file has a header but no rows",
        ));
    }
    Ok(out)
}

/// Writes compensated commands: per target its pose, the link readings to command and the
/// link lengths they mean.
pub fn write_commands(
    targets: &[PoseRow],
    readings: &[Vec<f64>],
    lengths_mm: &[Vec<f64>],
    note: &str,
) -> String {
    let n = readings.first().map_or(0, Vec::len);
    let mut s = format!(
        "# commands by cpm {}: {}\n",
        env!("CARGO_PKG_VERSION"),
        note.replace(['\n', '\r'], " ")
    );
    s.push_str("pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg");
    for k in 1..=n {
        s.push_str(&format!(",reading_{k}"));
    }
    for k in 1..=n {
        s.push_str(&format!(",length_{k}_mm"));
    }
    s.push('\n');
    for ((t, u), l) in targets.iter().zip(readings).zip(lengths_mm) {
        s.push_str(&format!("{},{}", field(&t.label), pose_fields(&t.pose)));
        for v in u.iter().chain(l) {
            s.push_str(&format!(",{}", num(*v)));
        }
        s.push('\n');
    }
    s
}
