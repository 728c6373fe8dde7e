//! Measurement files: length-sensor readings and tracker pose measurements (CSV), read into a
//! [`Campaign`] and written back; lists of poses (plans, compensation targets).
//!
//! The formats are documented in `docs/formats.md`. Reading checks every field (numbers
//! finite, sensor names known, rows of one pose agreeing) and every pose (reachable from home
//! without crossing a singularity, link readings and sensor lengths consistent with it, which
//! catches a file in the wrong units); each failure names the file, the line and the field.
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

use cpm_calib::campaign::PoseMeasurement;
use cpm_calib::{Campaign, Reading};
use cpm_geometry::{JointTable, Pose, Vector3};
use cpm_kinematics::workspace::{reachable_from_home, Unreachable};

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

/// How strictly measurement files are checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReadOptions {
    /// Check each length reading against the nominal sensor length at its pose. Turn off for
    /// sensors whose zero is unknown (`sensor_offset` modelled). Default true.
    pub check_sensor_lengths: bool,
    /// A pose is refused when J1's condition number on the way from home exceeds this factor
    /// times its value at home. Default 1000.
    pub max_condition_ratio: f64,
    /// The most data rows a file may have (the reading stops with an error at the next one).
    /// Default [`MAX_ROWS`].
    pub max_rows: usize,
}

/// The most data rows of a measurement file or pose list by default: ten million.
pub const MAX_ROWS: usize = 10_000_000;

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            check_sensor_lengths: true,
            max_condition_ratio: 1e3,
            max_rows: MAX_ROWS,
        }
    }
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
enum Orientation {
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

fn orientation_columns(o: Orientation) -> &'static [&'static str] {
    match o {
        Orientation::Rpy => &RPY_COLUMNS,
        Orientation::Quaternion => &QUATERNION_COLUMNS,
    }
}

/// The numbers a pose was made of, by column (for agreement checks).
type RawPose = Vec<(&'static str, f64)>;

/// The pose of a row, and the raw numbers it was made of (for agreement checks).
fn parse_pose(t: &Header, row: &Row, o: Orientation) -> Result<(Pose, RawPose), InputError> {
    let mut raw = Vec::with_capacity(7);
    for c in ["x_mm", "y_mm", "z_mm"]
        .iter()
        .chain(orientation_columns(o))
    {
        let v = t.number(row, c)?;
        if c.ends_with("_mm") && v.abs() > MAX_POSITION_MM {
            return Err(t.err(
                row,
                c,
                format!("{v:e} mm is implausibly far (over 1 km): positions are in mm"),
            ));
        }
        if c.ends_with("_deg") && v.abs() > 360.0 {
            return Err(t.err(
                row,
                c,
                format!("{v} degrees: an angle is within [-360, 360] (angles are in degrees)"),
            ));
        }
        raw.push((*c, v));
    }
    let p = [raw[0].1, raw[1].1, raw[2].1];
    let pose = match o {
        Orientation::Rpy => Pose::from_xyz_rpy_deg(p, [raw[3].1, raw[4].1, raw[5].1]),
        Orientation::Quaternion => {
            let q = [raw[3].1, raw[4].1, raw[5].1, raw[6].1];
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-3 {
                return Err(t.err(
                    row,
                    "qw",
                    format!("(qw, qx, qy, qz) = ({}, {}, {}, {}) is not a unit quaternion (norm {norm})", q[0], q[1], q[2], q[3]),
                ));
            }
            Pose::try_from_quaternion(Vector3::from(p), q)
                .map_err(|e| t.err(row, "qw", e.to_string()))?
        }
    };
    Ok((pose, raw))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 + 1e-9 * a.abs().max(b.abs())
}

fn tolerance_mm(length_mm: f64) -> f64 {
    CONSISTENCY_MM + CONSISTENCY_REL * length_mm.abs()
}

/// Checks that a pose can be reached from home; the error names the pose's first line.
pub fn check_reachable(
    table: &JointTable,
    pose: &Pose,
    max_condition_ratio: f64,
    file: &str,
    line: usize,
    label: &str,
) -> Result<(), InputError> {
    let c0 = cpm_kinematics::workspace::j1_condition(table, &table.home);
    let bound = if c0.is_finite() {
        (max_condition_ratio * c0).max(10.0)
    } else {
        f64::INFINITY
    };
    let why = match reachable_from_home(table, pose, bound) {
        Ok(()) => return Ok(()),
        Err(Unreachable::LengthLimit {
            link,
            length_mm,
            limits_mm,
        }) => format!(
            "link {} would be {length_mm:.3} mm long, outside its limits [{}, {}] mm",
            link + 1,
            limits_mm.0,
            limits_mm.1
        ),
        Err(Unreachable::NearSingular { condition }) => format!(
            "the machine is (near) singular there or on the way from home (J1 condition number {condition:.3e}, {c0:.3e} at home)"
        ),
        Err(Unreachable::AssemblyModeChange { at }) => format!(
            "the way from home crosses a singularity ({:.0} % of the way): the pose belongs to another assembly mode",
            at * 100.0
        ),
        Err(Unreachable::Invalid) => {
            "its link lengths are not finite numbers (an implausible pose or robot)".to_string()
        }
    };
    let [x, y, z] =
        [pose.position_mm.x, pose.position_mm.y, pose.position_mm.z].map(|v| show(v, None));
    let [r, p, w] = pose.rpy_deg();
    let label = shorten(label);
    Err(InputError::line(
        file,
        line,
        format!(
            "pose {label:?} (x {x} mm, y {y} mm, z {z} mm, roll {r:.4} deg, pitch {p:.4} deg, yaw {w:.4} deg) is not reachable from home: {why} (positions are in mm, angles in degrees)"
        ),
    ))
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
fn finish<R: Read>(t: &mut Table<R>, e: InputError) -> ReadError {
    match t.take_io_error() {
        Some(source) => ReadError::Io {
            file: t.file.clone(),
            source,
        },
        None => ReadError::Input(e),
    }
}

/// Reads a measurement file of either kind (told from the header) from text.
pub fn read_data(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    read_data_from(text.as_bytes(), file, robot, options).map_err(ReadError::into_input)
}

/// Reads a measurement file of either kind, streaming its rows from the file at `path`.
pub fn read_data_file(
    path: &Path,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    read_data_from(open(path)?, &path.display().to_string(), robot, options)
}

/// Reads a measurement file of either kind (told from the header) from a reader, row by row:
/// the first problem stops the reading there.
pub fn read_data_from<R: Read>(
    source: R,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    let mut t = Table::from_reader(source, file)?;
    let r = match t.kind() {
        Ok(FileKind::Readings) => read_readings_table(&mut t, robot, options),
        Ok(FileKind::PoseMeasurements) => read_pose_measurements_table(&mut t, robot, options),
        Ok(FileKind::Poses) => Err(InputError::line(
            file,
            t.header_line,
            "this is a list of poses (no sensor readings and no link readings): measurements need `sensor` and `length_mm` columns, or `reading_1`.. columns with a measured pose",
        )),
        Err(e) => Err(e),
    };
    r.map_err(|e| finish(&mut t, e))
}

/// Checks the `reading_k` columns: none, or exactly `reading_1..reading_n`.
fn link_reading_columns(t: &Header, n: usize) -> Result<bool, InputError> {
    let ks = t.reading_columns()?;
    if ks.is_empty() {
        return Ok(false);
    }
    if ks.len() != n {
        let name = if ks.len() < n {
            format!("reading_{}", ks.len() + 1)
        } else {
            format!("reading_{}", n + 1)
        };
        let what = if ks.len() < n {
            "missing column"
        } else {
            "unknown column"
        };
        return Err(InputError::field(
            &t.file,
            t.header_line,
            name,
            format!("{what}: the robot has {n} links, so a file with link readings has reading_1 to reading_{n}"),
        ));
    }
    Ok(true)
}

fn link_readings(t: &Header, row: &Row, n: usize) -> Result<Vec<f64>, InputError> {
    (1..=n)
        .map(|k| t.number(row, &format!("reading_{k}")))
        .collect()
}

/// Checks logged link readings against the pose's inverse kinematics.
fn check_link_readings(
    t: &Header,
    row: &Row,
    robot: &Robot,
    pose: &Pose,
    readings: &[f64],
    what: &str,
) -> Result<Vec<f64>, InputError> {
    let ik = cpm_kinematics::inverse_lengths(&robot.table, pose);
    let mut lengths = Vec::with_capacity(readings.len());
    for (i, (u, l_ik)) in readings.iter().zip(&ik).enumerate() {
        let l = robot.length_mm(i, *u);
        if !l.is_finite() || !((l - l_ik).abs() <= tolerance_mm(*l_ik)) {
            return Err(t.err(
                row,
                &format!("reading_{}", i + 1),
                format!(
                    "{} means a link length of {} mm (length_at_zero_mm + mm_per_unit * reading), but the {what} needs {l_ik:.3} mm: wrong units, a wrong link mapping in the robot description, or a wrong pose?",
                    show(*u, None),
                    show(l, Some(3))
                ),
            ));
        }
        lengths.push(l);
    }
    Ok(lengths)
}

/// The error of a file with more rows than allowed.
fn too_many_rows(t: &Header, row: &Row, max: usize) -> InputError {
    InputError::line(
        &t.file,
        row.line,
        format!("more than {max} data rows: cpm reads at most {max} (average repeated readings, or split the campaign)"),
    )
}

/// Reads length-sensor readings (see `docs/formats.md`).
pub fn read_readings(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let mut t = Table::parse(text, file)?;
    read_readings_table(&mut t, robot, options)
}

fn read_readings_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
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
    while let Some(row) = t.next_row()? {
        let t: &Header = t;
        if reading_lines.len() >= options.max_rows {
            return Err(too_many_rows(t, &row, options.max_rows));
        }
        let label = t.required_text(&row, "pose")?.to_string();
        let sensor_name = t.required_text(&row, "sensor")?;
        let sensor = robot.table.sensor_index(sensor_name).ok_or_else(|| {
            t.err(
                &row,
                "sensor",
                format!(
                    "unknown sensor {:?} (the robot description has: {})",
                    shorten(sensor_name),
                    robot.sensor_names()
                ),
            )
        })?;
        let (pose, raw) = parse_pose(t, &row, o)?;
        let length_mm = t.number(&row, "length_mm")?;
        let time_s = t.optional_number(&row, "time_s")?;
        let temperature_c = t.optional_number(&row, "temperature_c")?;
        if t.optional_bool(&row, "simulated")? == Some(true) {
            campaign.simulated = true;
        }
        let link = if logged {
            Some(link_readings(t, &row, n)?)
        } else {
            None
        };
        let j = match by_label.get(&label) {
            Some(&j) => {
                let e = &entries[j];
                for ((name, a), (_, b)) in raw.iter().zip(&e.raw) {
                    if !close(*a, *b) {
                        return Err(t.err(
                            &row,
                            name,
                            format!("{} differs from {} given for pose {:?} on line {}: rows of one pose share one commanded pose (a repeated pose label?)", show(*a, None), show(*b, None), shorten(&label), e.line),
                        ));
                    }
                }
                if let (Some(a), Some(b)) = (&link, &e.readings) {
                    for (k, (x, y)) in a.iter().zip(b).enumerate() {
                        if !close(*x, *y) {
                            return Err(t.err(
                                &row,
                                &format!("reading_{}", k + 1),
                                format!("{x} differs from {y} given for pose {:?} on line {}: rows of one pose share one command", shorten(&label), e.line),
                            ));
                        }
                    }
                }
                j
            }
            None => {
                let j = entries.len();
                if options.max_condition_ratio.is_finite() {
                    check_reachable(
                        &robot.table,
                        &pose,
                        options.max_condition_ratio,
                        &t.file,
                        row.line,
                        &label,
                    )?;
                }
                if let Some(u) = &link {
                    commanded.push(check_link_readings(
                        t,
                        &row,
                        robot,
                        &pose,
                        u,
                        "commanded pose",
                    )?);
                }
                by_label.insert(label.clone(), j);
                entries.push(PoseEntry {
                    raw,
                    readings: link,
                    line: row.line,
                });
                labels.push(label);
                campaign.poses.push(pose);
                j
            }
        };
        if options.check_sensor_lengths {
            let s = &robot.table.sensors[sensor];
            let nominal = s.length_mm(&campaign.poses[j]);
            if !((length_mm - nominal).abs() <= tolerance_mm(nominal)) {
                return Err(t.err(
                    &row,
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
            time_s,
            temperature_c,
        });
        reading_lines.push(row.line);
    }
    if campaign.readings.is_empty() {
        return Err(InputError::file(
            &t.file,
            "no readings: the file has a header but no rows",
        ));
    }
    if logged {
        campaign.commanded_lengths_mm = Some(commanded);
    }
    Ok(DataFile {
        file: t.file.clone(),
        kind: FileKind::Readings,
        pose_lines: entries.iter().map(|e| e.line).collect(),
        campaign,
        pose_labels: labels,
        reading_lines,
    })
}

/// Reads tracker pose measurements (see `docs/formats.md`).
pub fn read_pose_measurements(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let mut t = Table::parse(text, file)?;
    read_pose_measurements_table(&mut t, robot, options)
}

fn read_pose_measurements_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let n = robot.num_links();
    let o = orientation(t)?;
    t.check_columns(
        &["pose", "x_mm", "y_mm", "z_mm"],
        &["time_s", "simulated"],
        |h| {
            RPY_COLUMNS.contains(&h)
                || QUATERNION_COLUMNS.contains(&h)
                || super::table::reading_index(h).is_some()
        },
    )?;
    if !link_reading_columns(t, n)? {
        return Err(InputError::field(
            &t.file,
            t.header_line,
            "reading_1",
            "missing column",
        ));
    }
    let mut campaign = Campaign {
        simulated: t.simulated_mark,
        ..Campaign::default()
    };
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut labels = Vec::new();
    let mut lines = Vec::new();
    let mut commanded = Vec::new();
    while let Some(row) = t.next_row()? {
        let t: &Header = t;
        if lines.len() >= options.max_rows {
            return Err(too_many_rows(t, &row, options.max_rows));
        }
        let label = t.required_text(&row, "pose")?.to_string();
        if let Some(first) = seen.get(&label) {
            return Err(t.err(
                &row,
                "pose",
                format!("pose {:?} appears again (first on line {first}): a tracker file has one row per pose", shorten(&label)),
            ));
        }
        let (measured, _) = parse_pose(t, &row, o)?;
        let u = link_readings(t, &row, n)?;
        let time_s = t.optional_number(&row, "time_s")?;
        if t.optional_bool(&row, "simulated")? == Some(true) {
            campaign.simulated = true;
        }
        if options.max_condition_ratio.is_finite() {
            check_reachable(
                &robot.table,
                &measured,
                options.max_condition_ratio,
                &t.file,
                row.line,
                &label,
            )?;
        }
        commanded.push(check_link_readings(
            t,
            &row,
            robot,
            &measured,
            &u,
            "measured pose",
        )?);
        seen.insert(label.clone(), row.line);
        let j = campaign.poses.len();
        campaign.poses.push(measured);
        campaign.pose_measurements.push(PoseMeasurement {
            pose: j,
            measured,
            time_s,
        });
        labels.push(label);
        lines.push(row.line);
    }
    if campaign.pose_measurements.is_empty() {
        return Err(InputError::file(
            &t.file,
            "no pose measurements: the file has a header but no rows",
        ));
    }
    campaign.commanded_lengths_mm = Some(commanded);
    Ok(DataFile {
        file: t.file.clone(),
        kind: FileKind::PoseMeasurements,
        campaign,
        pose_labels: labels,
        pose_lines: lines,
        reading_lines: Vec::new(),
    })
}

/// Several measurement files merged into one campaign, with where each pose came from.
#[derive(Debug, Clone)]
pub struct Merged {
    /// The campaign (poses of the files one after the other).
    pub campaign: Campaign,
    /// Per campaign pose: (file, first line, label).
    pub pose_origin: Vec<(String, usize, String)>,
    /// Per reading: (file, line).
    pub reading_origin: Vec<(String, usize)>,
}

impl Merged {
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
    let mut reading_origin = Vec::new();
    for f in files {
        let c = f.campaign;
        let base = out.poses.len();
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
        out.readings.extend(c.readings.iter().map(|r| Reading {
            pose: r.pose + base,
            ..*r
        }));
        out.pose_measurements
            .extend(c.pose_measurements.iter().map(|m| PoseMeasurement {
                pose: m.pose + base,
                ..*m
            }));
        for (line, label) in f.pose_lines.iter().zip(&f.pose_labels) {
            pose_origin.push((f.file.clone(), *line, label.clone()));
        }
        reading_origin.extend(f.reading_lines.iter().map(|l| (f.file.clone(), *l)));
    }
    if any_commanded {
        out.commanded_lengths_mm = Some(commanded);
    }
    Merged {
        campaign: out,
        pose_origin,
        reading_origin,
    }
}

fn simulated_header(note: &str) -> String {
    format!(
        "{SIMULATED_MARK} {}{}{}\n",
        env!("CARGO_PKG_VERSION"),
        if note.is_empty() { "" } else { ": " },
        note.replace(['\n', '\r'], " ")
    )
}

fn pose_fields(p: &Pose) -> String {
    let [r, pi, y] = p.rpy_deg();
    format!(
        "{},{},{},{},{},{}",
        num(p.position_mm.x),
        num(p.position_mm.y),
        num(p.position_mm.z),
        num(r + 0.0),
        num(pi + 0.0),
        num(y + 0.0)
    )
}

fn opt(v: Option<f64>) -> String {
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
            s.push_str(&format!(",{}", opt(r.time_s)));
        }
        if has_temp {
            s.push_str(&format!(",{}", opt(r.temperature_c)));
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
    if campaign.simulated {
        s.push_str(",simulated");
    }
    s.push('\n');
    for m in &campaign.pose_measurements {
        let lengths = match &campaign.commanded_lengths_mm {
            Some(l) => l[m.pose].clone(),
            None => cpm_kinematics::inverse_lengths(&robot.table, &campaign.poses[m.pose]),
        };
        s.push_str(&format!("{}", m.pose + 1));
        for (i, len) in lengths.iter().enumerate() {
            s.push_str(&format!(",{}", num(robot.reading(i, *len))));
        }
        s.push_str(&format!(",{}", pose_fields(&m.measured)));
        if has_time {
            s.push_str(&format!(",{}", opt(m.time_s)));
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
