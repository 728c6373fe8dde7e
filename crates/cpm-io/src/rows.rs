//! Length-sensor readings and tracker pose measurements given as values (numpy arrays, a
//! program's own log), read into a [`DataFile`] with every check of the CSV reader and the
//! same errors, without text.
//!
//! [`GaugeRows`] holds the columns of a readings file (`docs/formats.md`, "Length-sensor
//! readings") as typed values, one row per reading. [`read_gauge_rows`] gives exactly what
//! [`read_readings`](crate::read_readings) gives for the text [`GaugeRows::to_csv`] writes of
//! them: the same campaign to the last bit, the same exclusions, the same first error (row
//! `k` is line `k + 2` of that text, its header on line 1), in a fraction of the time (no
//! number is formatted or parsed).
//!
//! [`TrackerRows`] holds the columns of a tracker file ("Tracker pose measurements"), one row
//! per pose; [`read_tracker_rows`] gives what
//! [`read_pose_measurements`](crate::campaign::read_pose_measurements) gives for the text of
//! [`TrackerRows::to_csv`], in the same way (unregistered: the fit side registers tracker
//! sets, `cpm_workflow::ingest`).
//!
//! [`PoseRows`] holds the columns of a pose list (a plan, compensation targets), one row per
//! pose; [`read_pose_rows`] gives what [`read_pose_list`](crate::read_pose_list) gives for the
//! text of [`PoseRows::to_csv`], in the same way.
//!
//! A row whose line in that text would be longer than the CSV reader takes
//! ([`MAX_LINE_BYTES`]: a label or a sensor name of a megabyte)
//! is refused as that reader refuses the line.
//!
//! ```
//! use cpm_io::rows::{read_gauge_rows, GaugeRows};
//! use cpm_io::{ReadOptions, Robot};
//! let robot = Robot::from_description(cpm_geometry::RobotDescription::paper_cubic(), "cube.toml").unwrap();
//! let home = [0.0, 0.0, 410.0, 0.0, 0.0, 0.0];
//! let length = robot.table.sensors[0].length_mm(&robot.table.home);
//! let rows = GaugeRows::new("my log", vec!["a".into(); 2], vec!["paper".into(); 2],
//!                           vec![home; 2], vec![length, length + 0.001]);
//! let data = read_gauge_rows(&rows, &robot, &ReadOptions::default()).unwrap();
//! assert_eq!((data.campaign.poses.len(), data.campaign.readings.len()), (1, 2));
//! // A bad row names the name, the line of the text the rows stand for, and the field.
//! let mut bad = rows.clone();
//! bad.sensors[1] = "nosuch".into();
//! let err = read_gauge_rows(&bad, &robot, &ReadOptions::default()).unwrap_err();
//! assert!(err.to_string().starts_with("my log:3: field sensor: unknown sensor \"nosuch\""));
//! ```
use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::OnceLock;

use cpm_calib::{Campaign, Reading};
use cpm_geometry::Pose;

use crate::campaign::{
    check_angle_units, check_pose_value, exclude_poses, pose_from_raw, reading_name, robot_checks,
    same_pose_as_before, surely_valid_pose_value, too_many_rows_at, tracker_link_columns,
    unknown_sensor, DataFile, Orientation, PoseJudge, PoseRow, RawPose, ReadOptions, TrackerRead,
    TrackerRow, MAX_ROWS,
};
use crate::table::{field, line_too_long, parse_number, MAX_LINE_BYTES};
use crate::{InputError, Robot};

/// The number of rows of rows given as values (their labels': the reader, named, checks the
/// other columns against it), and the line of a row in their CSV.
macro_rules! rows_by_label {
    ($reader:literal) => {
        #[doc = concat!("The number of rows (of the labels; [`", $reader, "`] checks the other columns against it).")]
        pub fn len(&self) -> usize {
            self.pose_labels.len()
        }

        /// True without rows.
        pub fn is_empty(&self) -> bool {
            self.pose_labels.is_empty()
        }

        /// The line of row `k` (from 0) in the text of [`to_csv`](Self::to_csv): `k + 2`.
        pub fn line(k: usize) -> usize {
            row_line(k)
        }
    };
}

/// Length-sensor readings as values, one row per reading: the columns of a readings file.
#[derive(Debug, Clone, PartialEq)]
pub struct GaugeRows {
    /// The name that stands for the file in messages and outputs.
    pub file: String,
    /// Each row's pose label: rows with the same label share one commanded pose.
    pub pose_labels: Vec<String>,
    /// Each row's sensor, by its name in the robot description.
    pub sensors: Vec<String>,
    /// Each row's commanded pose: x, y, z mm; roll, pitch, yaw deg
    /// (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
    pub poses: Vec<[f64; 6]>,
    /// Each row's reading, mm.
    pub lengths_mm: Vec<f64>,
    /// Each row's time, s, when given.
    pub time_s: Option<Vec<f64>>,
    /// True for simulated readings (every result then says so).
    pub simulated: bool,
}

impl GaugeRows {
    /// Rows without times, not simulated.
    pub fn new(
        file: impl Into<String>,
        pose_labels: Vec<String>,
        sensors: Vec<String>,
        poses: Vec<[f64; 6]>,
        lengths_mm: Vec<f64>,
    ) -> GaugeRows {
        GaugeRows {
            file: file.into(),
            pose_labels,
            sensors,
            poses,
            lengths_mm,
            time_s: None,
            simulated: false,
        }
    }

    rows_by_label!("read_gauge_rows");

    /// The rows as the CSV of a readings file (header on line 1, row `k` on line `k + 2`),
    /// every number in its shortest form that reads back to the same `f64`; a `simulated`
    /// column says whether they are simulated.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm");
        end_header(&mut s, self.time_s.is_some());
        for k in 0..self.len() {
            self.write_row(&mut s, k);
        }
        s
    }

    /// Row `k` of [`to_csv`](Self::to_csv), with its line break.
    fn write_row(&self, s: &mut String, k: usize) {
        let label = self.pose_labels.get(k).map_or("", String::as_str);
        let sensor = self.sensors.get(k).map_or("", String::as_str);
        let _ = write!(s, "{},{}", field(label), field(sensor));
        for v in self.poses.get(k).copied().unwrap_or([f64::NAN; 6]) {
            let _ = write!(s, ",{v}");
        }
        let _ = write!(
            s,
            ",{}",
            self.lengths_mm.get(k).copied().unwrap_or(f64::NAN)
        );
        end_row(s, self.time_s.as_ref(), k, self.simulated);
    }

    /// Checks that every column has a value per row.
    fn check_columns(&self) -> Result<(), InputError> {
        let n = self.len();
        check_columns(
            &self.file,
            n,
            &[
                ("sensor", self.sensors.len(), 1),
                ("x_mm .. yaw_deg", self.poses.len(), 1),
                ("length_mm", self.lengths_mm.len(), 1),
                ("time_s", self.time_s.as_ref().map_or(n, Vec::len), 1),
            ],
        )
    }
}

/// Checks that each column `(name, values, per row)` has `per row` values for each of the
/// `n` rows, naming the first that has not.
fn check_columns(file: &str, n: usize, columns: &[(&str, usize, usize)]) -> Result<(), InputError> {
    for &(name, len, per_row) in columns {
        if len != n * per_row {
            let need = match per_row {
                1 => "one".to_string(),
                k => k.to_string(),
            };
            return Err(InputError::file(
                file,
                format!("{len} values of {name} for {n} pose labels: every row needs {need}"),
            ));
        }
    }
    Ok(())
}

/// The line of row `k` (from 0) in the CSV text of rows given as values: `k + 2` (the header
/// on line 1).
fn row_line(k: usize) -> usize {
    k + 2
}

/// The end of the header of the CSV of rows: the `time_s` column when they have times, then
/// `simulated`.
fn end_header(s: &mut String, times: bool) {
    if times {
        s.push_str(",time_s");
    }
    s.push_str(",simulated\n");
}

/// The end of row `k` of the CSV of rows: its time when they have times, then whether they
/// are simulated.
fn end_row(s: &mut String, time_s: Option<&Vec<f64>>, k: usize, simulated: bool) {
    if let Some(t) = time_s {
        let _ = write!(s, ",{}", t.get(k).copied().unwrap_or(f64::NAN));
    }
    let _ = writeln!(s, ",{simulated}");
}

/// The time of row `k` on `line`, when the rows have times: finite.
fn time(
    file: &str,
    line: usize,
    time_s: Option<&Vec<f64>>,
    k: usize,
) -> Result<Option<f64>, InputError> {
    time_s
        .map(|t| finite(file, line, "time_s", t[k]))
        .transpose()
}

/// The columns of a row's pose, in the order of [`GaugeRows::poses`].
const POSE_COLUMNS: [&str; 6] = ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"];

/// The numbers of a row's pose, each of the column named beside it in `columns`: finite and
/// within range (the checks of the CSV reader, cell by cell).
fn raw_pose(
    file: &str,
    line: usize,
    columns: &[&'static str],
    values: &[f64],
) -> Result<RawPose, InputError> {
    let mut raw = RawPose::default();
    for (name, &v) in columns.iter().zip(values) {
        if !surely_valid_pose_value(v) {
            let v = finite(file, line, name, v)?;
            check_pose_value(file, line, name, v)?;
        }
        raw.push(name, v);
    }
    Ok(raw)
}

/// A value of a number column: finite, else the reader's message for its text.
#[inline]
fn finite(file: &str, line: usize, name: &str, v: f64) -> Result<f64, InputError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(not_finite(file, line, name, v))
    }
}

/// The error of [`finite`]: the reader's message for the text of `v`.
#[cold]
fn not_finite(file: &str, line: usize, name: &str, v: f64) -> InputError {
    InputError::field(
        file,
        line,
        name,
        parse_number(&v.to_string()).expect_err("not finite"),
    )
}

/// Refuses the texts of a row (`(column, text)`, in the order of their columns) that its CSV
/// cannot hold on its line, as the CSV reader refuses that line: a text with a line break.
fn one_line(file: &str, line: usize, texts: &[(&str, &str)]) -> Result<(), InputError> {
    match texts.iter().find(|(_, v)| v.contains('\n')) {
        Some((name, _)) => Err(InputError::field(
            file,
            line,
            *name,
            crate::table::QUOTE_NOT_CLOSED,
        )),
        None => Ok(()),
    }
}

/// The most bytes a number takes in the CSV of rows (`{v}` of an `f64` writes every digit:
/// a subnormal number takes some 330).
const NUMBER_BYTES: usize = 400;

/// Refuses a row whose line in its CSV is longer than the CSV reader takes
/// ([`MAX_LINE_BYTES`], its line break included), as that reader refuses the line: `texts`
/// are the row's texts, `numbers` how many numbers it has, `row` writes the row as its CSV
/// does (only when the texts are long enough for the line to be too long). A text with a
/// line break ends the line there.
fn fits_line(
    file: &str,
    line: usize,
    texts: &[&str],
    numbers: usize,
    row: impl FnOnce(&mut String),
) -> Result<(), InputError> {
    // A text is at most doubled by quoting, plus its quotes and comma; the rest of the line
    // (the `simulated` column) is short.
    let most = texts.iter().map(|t| 2 * t.len() + 3).sum::<usize>() + numbers * NUMBER_BYTES + 16;
    if most < MAX_LINE_BYTES {
        return Ok(());
    }
    let mut text = String::new();
    row(&mut text);
    let first = text.find('\n').map_or(text.len(), |end| end + 1);
    if first > MAX_LINE_BYTES {
        return Err(line_too_long(file, line));
    }
    Ok(())
}

/// A required text column: non-empty.
fn required<'a>(file: &str, line: usize, name: &str, v: &'a str) -> Result<&'a str, InputError> {
    if v.is_empty() {
        Err(InputError::field(file, line, name, "missing value"))
    } else {
        Ok(v)
    }
}

/// How many new poses of gauge rows are judged together while the rows are read
/// ([`read_gauge_rows`]).
const JUDGE_CHUNK: usize = 2048;

/// Reads length-sensor readings given as values: what
/// [`read_readings`](crate::read_readings) gives for the text of
/// [`GaugeRows::to_csv`] (see the module's documentation), read directly.
pub fn read_gauge_rows(
    rows: &GaugeRows,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    rows.check_columns()?;
    let file = rows.file.as_str();
    // The lists sized once for the rows (at most `max_rows` of them are read), not grown;
    // those per pose for a pose read by every sensor (grown when there are more poses).
    let capacity = rows.len().min(options.max_rows.saturating_add(1));
    let poses = capacity / robot.table.sensors.len().max(1) + 1;
    let mut by_label: HashMap<&str, usize> = HashMap::with_capacity(poses);
    // Per pose: the numbers of its first row, its first line.
    let mut first: Vec<(RawPose, usize)> = Vec::with_capacity(poses);
    let mut labels: Vec<String> = Vec::with_capacity(poses);
    let mut campaign = Campaign {
        simulated: rows.simulated,
        readings: Vec::with_capacity(capacity),
        poses: Vec::with_capacity(poses),
        ..Campaign::default()
    };
    let mut reading_lines = Vec::with_capacity(capacity);
    let mut angles = Vec::with_capacity(3 * poses);
    // The pose and numbers of the previous row (rows of one pose usually follow each other).
    let mut previous: Option<(usize, [f64; 6])> = None;
    // The reachability of the poses (what `robot_checks` finds of them), judged on the
    // pool's other threads while the rows are read: each chunk of JUDGE_CHUNK new poses as
    // soon as it is complete, into its own slot; the rest after the rows.
    let judge = PoseJudge::new(robot, options);
    let at = judge.as_ref().map(PoseJudge::at);
    let slots: Vec<OnceLock<Vec<Option<String>>>> = (0..capacity / JUDGE_CHUNK + 1)
        .map(|_| OnceLock::new())
        .collect();
    let mut judged_upto = 0;
    let read = rayon::scope(|scope| -> Result<(), InputError> {
        for k in 0..rows.len() {
            let line = GaugeRows::line(k);
            let texts = [
                ("pose", &*rows.pose_labels[k]),
                ("sensor", &*rows.sensors[k]),
            ];
            fits_line(file, line, &[texts[0].1, texts[1].1], 8, |s| {
                rows.write_row(s, k)
            })?;
            one_line(file, line, &texts)?;
            if reading_lines.len() >= options.max_rows {
                return Err(too_many_rows_at(file, line, options.max_rows));
            }
            let label = required(file, line, "pose", &rows.pose_labels[k])?;
            let sensor_name = required(file, line, "sensor", &rows.sensors[k])?;
            let sensor = robot
                .table
                .sensor_index(sensor_name)
                .ok_or_else(|| unknown_sensor(file, line, robot, sensor_name))?;
            let values = rows.poses[k];
            // The previous row's pose when this row has its label.
            let same_label = previous.filter(|(j, _)| labels[*j] == label);
            let known = match same_label {
                Some((j, _)) => Some(j),
                None => by_label.get(label).copied(),
            };
            // The previous row's numbers exactly (the same text): its pose, whose numbers
            // were checked at its first row and agree with them (no checks again).
            let repeat = same_label.and_then(|(j, v)| {
                let same = v
                    .iter()
                    .zip(&values)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                same.then_some(j)
            });
            let seen = match repeat {
                Some(j) => Ok(j),
                None => {
                    let raw = raw_pose(file, line, &POSE_COLUMNS, &values)?;
                    let pose = match known {
                        Some(j) if raw.agrees(&first[j].0) => None,
                        _ => Some(Pose::from_xyz_rpy_deg(
                            [values[0], values[1], values[2]],
                            [values[3], values[4], values[5]],
                        )),
                    };
                    Err((raw, pose))
                }
            };
            let length_mm = finite(file, line, "length_mm", rows.lengths_mm[k])?;
            let time_s = time(file, line, rows.time_s.as_ref(), k)?;
            let j = match (seen, known) {
                (Ok(j), _) => j,
                (Err((raw, _)), Some(j)) => {
                    let (before, first_line) = &first[j];
                    same_pose_as_before(
                        file,
                        line,
                        label,
                        (&raw, &None),
                        (before, &None),
                        *first_line,
                    )?;
                    j
                }
                (Err((raw, pose)), None) => {
                    let j = first.len();
                    for (name, v) in raw.iter().filter(|(n, _)| n.ends_with("_deg")) {
                        angles.push((line, *name, *v));
                    }
                    by_label.insert(label, j);
                    first.push((raw, line));
                    labels.push(label.to_string());
                    campaign
                        .poses
                        .push(pose.expect("a new pose is made from its numbers"));
                    let complete = campaign.poses.len() - judged_upto == JUDGE_CHUNK;
                    let slot = slots.get(judged_upto / JUDGE_CHUNK);
                    if let (true, Some(judge), Some(at), Some(slot)) = (complete, &judge, &at, slot)
                    {
                        let chunk = campaign.poses[judged_upto..].to_vec();
                        scope.spawn(move |_| {
                            let why = chunk.iter().map(|p| judge.why(at, p)).collect();
                            // The slot is this chunk's alone: it cannot be full already.
                            let _ = slot.set(why);
                        });
                        judged_upto += JUDGE_CHUNK;
                    }
                    j
                }
            };
            previous = Some((j, values));
            campaign.readings.push(Reading {
                pose: j,
                sensor,
                length_mm,
                time_s: time_s.into(),
                temperature_c: cpm_calib::Logged::NONE,
            });
            reading_lines.push(line);
        }
        Ok(())
    });
    // The judgements of the chunks (all made: the scope waits for its tasks), then of the
    // poses after them.
    let judged = judge.as_ref().zip(at.as_ref()).and_then(|(judge, at)| {
        use rayon::prelude::*;
        let mut why: Vec<Option<String>> = Vec::with_capacity(campaign.poses.len());
        for slot in slots.into_iter().take(judged_upto / JUDGE_CHUNK) {
            why.extend(slot.into_inner()?);
        }
        why.par_extend(
            campaign.poses[judged_upto..]
                .par_iter()
                .map(|p| judge.why(at, p)),
        );
        Some(why)
    });
    // The robot's checks of the rows read (all, or those before the refused one) first, as
    // the CSV reader makes them.
    let unusable = robot_checks(
        file,
        robot,
        options,
        &campaign.poses,
        &campaign.readings,
        &reading_lines,
        judged,
    )?;
    read?;
    if campaign.readings.is_empty() {
        return Err(InputError::file(
            file,
            "no readings: the file has a header but no rows",
        ));
    }
    check_angle_units(file, &angles)?;
    let pose_lines = first.iter().map(|(_, line)| *line).collect();
    let mut f = DataFile::readings(
        file.to_string(),
        campaign,
        labels,
        pose_lines,
        reading_lines,
    );
    exclude_poses(&mut f, unusable)?;
    Ok(f)
}

/// The measured poses of tracker rows, one per row, in one of the two orientations of a
/// tracker file.
#[derive(Debug, Clone, PartialEq)]
pub enum TrackerPoses {
    /// x, y, z mm; roll, pitch, yaw deg (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
    Rpy(Vec<[f64; 6]>),
    /// x, y, z mm; unit quaternion qw, qx, qy, qz.
    Quaternion(Vec<[f64; 7]>),
}

/// The columns of a tracker row's pose given as a quaternion.
const QUATERNION_POSE_COLUMNS: [&str; 7] = ["x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"];

impl TrackerPoses {
    /// The number of poses.
    pub fn len(&self) -> usize {
        match self {
            TrackerPoses::Rpy(p) => p.len(),
            TrackerPoses::Quaternion(p) => p.len(),
        }
    }

    /// True without poses.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The numbers of pose `k`.
    fn row(&self, k: usize) -> Option<&[f64]> {
        match self {
            TrackerPoses::Rpy(p) => p.get(k).map(|v| v.as_slice()),
            TrackerPoses::Quaternion(p) => p.get(k).map(|v| v.as_slice()),
        }
    }

    /// The columns of a pose, in the order of its numbers.
    fn columns(&self) -> &'static [&'static str] {
        match self {
            TrackerPoses::Rpy(_) => &POSE_COLUMNS,
            TrackerPoses::Quaternion(_) => &QUATERNION_POSE_COLUMNS,
        }
    }

    fn orientation(&self) -> Orientation {
        match self {
            TrackerPoses::Rpy(_) => Orientation::Rpy,
            TrackerPoses::Quaternion(_) => Orientation::Quaternion,
        }
    }
}

/// Tracker pose measurements as values, one row per pose: the columns of a tracker file
/// (`docs/formats.md`, "Tracker pose measurements").
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerRows {
    /// The name that stands for the file in messages and outputs.
    pub file: String,
    /// Each row's pose label (one row per pose: no label twice).
    pub pose_labels: Vec<String>,
    /// The number of link readings of a row (`reading_1 .. reading_links`).
    pub links: usize,
    /// The commanded link readings (in the links' units), row after row: `links` per row.
    pub readings: Vec<f64>,
    /// Each row's measured pose, in the tracker's frame.
    pub poses: TrackerPoses,
    /// Each row's time, s, when given.
    pub time_s: Option<Vec<f64>>,
    /// True for simulated measurements (every result then says so).
    pub simulated: bool,
}

impl TrackerRows {
    /// Rows without times, not simulated.
    pub fn new(
        file: impl Into<String>,
        pose_labels: Vec<String>,
        links: usize,
        readings: Vec<f64>,
        poses: TrackerPoses,
    ) -> TrackerRows {
        TrackerRows {
            file: file.into(),
            pose_labels,
            links,
            readings,
            poses,
            time_s: None,
            simulated: false,
        }
    }

    rows_by_label!("read_tracker_rows");

    /// The link readings of row `k`.
    pub fn row_readings(&self, k: usize) -> &[f64] {
        self.readings
            .get(k * self.links..(k + 1) * self.links)
            .unwrap_or(&[])
    }

    /// The rows as the CSV of a tracker file (header on line 1, row `k` on line `k + 2`),
    /// every number in its shortest form that reads back to the same `f64`; a `simulated`
    /// column says whether they are simulated.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("pose");
        for k in 1..=self.links {
            let _ = write!(s, ",reading_{k}");
        }
        for c in self.poses.columns() {
            let _ = write!(s, ",{c}");
        }
        end_header(&mut s, self.time_s.is_some());
        for k in 0..self.len() {
            self.write_row(&mut s, k);
        }
        s
    }

    /// Row `k` of [`to_csv`](Self::to_csv), with its line break.
    fn write_row(&self, s: &mut String, k: usize) {
        s.push_str(&field(&self.pose_labels[k]));
        let readings = self.row_readings(k);
        for c in 0..self.links {
            let _ = write!(s, ",{}", readings.get(c).copied().unwrap_or(f64::NAN));
        }
        let missing = [f64::NAN; 7];
        let pose = self.poses.row(k).unwrap_or(&missing);
        for v in &pose[..self.poses.columns().len()] {
            let _ = write!(s, ",{v}");
        }
        end_row(s, self.time_s.as_ref(), k, self.simulated);
    }

    /// Checks that every column has a value per row (and `links` link readings).
    fn check_columns(&self) -> Result<(), InputError> {
        let n = self.len();
        let readings = format!("reading_1 .. reading_{}", self.links);
        let pose = match self.poses {
            TrackerPoses::Rpy(_) => "x_mm .. yaw_deg",
            TrackerPoses::Quaternion(_) => "x_mm .. qz",
        };
        check_columns(
            &self.file,
            n,
            &[
                (readings.as_str(), self.readings.len(), self.links),
                (pose, self.poses.len(), 1),
                ("time_s", self.time_s.as_ref().map_or(n, Vec::len), 1),
            ],
        )
    }
}

/// Reads tracker pose measurements given as values: what
/// [`read_pose_measurements`](crate::campaign::read_pose_measurements) gives for the text of
/// [`TrackerRows::to_csv`] (the same campaign to the last bit, the same first error: row `k`
/// is line `k + 2`), read directly. Like that reader, it leaves the rows unregistered and
/// unchecked against the robot ([`DataFile::checked`] false): the fit side registers them.
pub fn read_tracker_rows(
    rows: &TrackerRows,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    rows.check_columns()?;
    let file = rows.file.as_str();
    tracker_link_columns(file, 1, rows.links, robot.num_links())?;
    let (o, columns) = (rows.poses.orientation(), rows.poses.columns());
    let mut read = TrackerRead::new(rows.simulated);
    for k in 0..rows.len() {
        let line = row_line(k);
        let numbers = rows.links + 8;
        fits_line(file, line, &[&rows.pose_labels[k]], numbers, |s| {
            rows.write_row(s, k)
        })?;
        one_line(file, line, &[("pose", &rows.pose_labels[k])])?;
        read.check_more(file, line, options.max_rows)?;
        let label = required(file, line, "pose", &rows.pose_labels[k])?;
        read.check_label(file, line, label)?;
        let raw = raw_pose(file, line, columns, rows.poses.row(k).expect("checked"))?;
        let measured = pose_from_raw(file, line, o, &raw)?;
        let readings = rows
            .row_readings(k)
            .iter()
            .enumerate()
            .map(|(i, v)| finite(file, line, &reading_name(i), *v))
            .collect::<Result<Vec<f64>, InputError>>()?;
        let time_s = time(file, line, rows.time_s.as_ref(), k)?;
        let row = TrackerRow {
            line,
            label: label.to_string(),
            measured,
            readings,
            mask: [true; 6],
        };
        read.push(robot, row, &raw, (time_s, None), rows.simulated);
    }
    read.finish(file, robot)
}

/// A list of poses as values, one row per pose: the columns of a pose list (`docs/formats.md`,
/// "Pose lists": a plan, compensation targets) with the orientation as roll, pitch, yaw.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseRows {
    /// The name that stands for the file in messages and outputs.
    pub file: String,
    /// Each row's pose label.
    pub pose_labels: Vec<String>,
    /// Each row's pose: x, y, z mm; roll, pitch, yaw deg (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
    pub poses: Vec<[f64; 6]>,
}

impl PoseRows {
    /// The rows of `poses`, labelled by their numbers from 1 (as a pose list without a `pose`
    /// column is).
    pub fn new(file: impl Into<String>, poses: Vec<[f64; 6]>) -> PoseRows {
        PoseRows {
            file: file.into(),
            pose_labels: (1..=poses.len()).map(|k| k.to_string()).collect(),
            poses,
        }
    }

    rows_by_label!("read_pose_rows");

    /// The rows as the CSV of a pose list (header on line 1, row `k` on line `k + 2`), every
    /// number in its shortest form that reads back to the same `f64`.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n");
        for k in 0..self.len() {
            self.write_row(&mut s, k);
        }
        s
    }

    /// Row `k` of [`to_csv`](Self::to_csv), with its line break.
    fn write_row(&self, s: &mut String, k: usize) {
        s.push_str(&field(&self.pose_labels[k]));
        for v in self.poses.get(k).copied().unwrap_or([f64::NAN; 6]) {
            let _ = write!(s, ",{v}");
        }
        s.push('\n');
    }
}

/// Reads a list of poses given as values: what [`read_pose_list`](crate::read_pose_list)
/// gives for the text of [`PoseRows::to_csv`] (the same rows to the last bit, the same first
/// error: row `k` is line `k + 2`), read directly. Like that reader it checks the numbers
/// (finite, positions within 1 km, angles within 360 degrees), the labels (non-empty, on one
/// line) and the angle units (radians refused); the caller checks the positions against the
/// robot ([`check_pose_list_units`](crate::campaign::check_pose_list_units)).
pub fn read_pose_rows(rows: &PoseRows) -> Result<Vec<PoseRow>, InputError> {
    let file = rows.file.as_str();
    check_columns(
        file,
        rows.len(),
        &[("x_mm .. yaw_deg", rows.poses.len(), 1)],
    )?;
    let mut out = Vec::with_capacity(rows.len());
    let mut angles = Vec::new();
    for (k, label) in rows.pose_labels.iter().enumerate() {
        let line = row_line(k);
        fits_line(file, line, &[label], 6, |s| rows.write_row(s, k))?;
        one_line(file, line, &[("pose", label)])?;
        if out.len() >= MAX_ROWS {
            return Err(too_many_rows_at(file, line, MAX_ROWS));
        }
        let label = required(file, line, "pose", label)?;
        let v = rows.poses[k];
        let raw = raw_pose(file, line, &POSE_COLUMNS, &v)?;
        for (name, v) in raw.iter().filter(|(n, _)| n.ends_with("_deg")) {
            angles.push((line, *name, *v));
        }
        out.push(PoseRow {
            line,
            label: label.to_string(),
            pose: pose_from_raw(file, line, Orientation::Rpy, &raw)?,
            time_s: None,
            temperature_c: None,
        });
    }
    if out.is_empty() {
        return Err(InputError::file(
            file,
            "no poses: the file has a header but no rows",
        ));
    }
    check_angle_units(file, &angles)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn robot() -> Robot {
        let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        Robot::load(&examples.join("hexapod_66.toml")).unwrap()
    }

    /// What a reading gives, comparable: the file's contents, or the error's text.
    fn outcome(r: Result<DataFile, InputError>) -> String {
        match r {
            Ok(f) => format!("{f:?}"),
            Err(e) => format!("error: {e}"),
        }
    }

    /// One row: a pose label of a few (some awkward for CSV), a sensor, an offset from home
    /// of the label's pose (x, y, z mm; roll, pitch, yaw deg), noise on the nominal length,
    /// and a fault drawn now and then.
    fn row() -> impl Strategy<Value = (usize, usize, usize, f64, u8)> {
        (0..7usize, 0..3usize, 0..4usize, -0.01..0.01f64, 0..150u8)
    }

    const LABELS: [&str; 7] = ["1", "2", "3", "a,b", "#c", " d", "e\"f"];

    /// Offsets of a pose from home: x, y, z mm; roll, pitch, yaw deg.
    const OFFSETS: [[f64; 6]; 4] = [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [20.0, -10.0, 5.0, 2.0, -1.5, 3.0],
        [-15.0, 12.0, -8.0, -3.0, 1.0, -2.0],
        [5.0, 5.0, 20.0, 0.5, 4.0, 1.0],
    ];

    /// The pose `o` (x, y, z mm; roll, pitch, yaw deg) away from the robot's home.
    fn about_home(robot: &Robot, o: [f64; 6]) -> [f64; 6] {
        let home = robot.table.home;
        let [r, p, y] = home.rpy_deg();
        let x = home.position_mm;
        [
            x.x + o[0],
            x.y + o[1],
            x.z + o[2],
            r + o[3],
            p + o[4],
            y + o[5],
        ]
    }

    /// Rows of the example hexapod with faults: the reading from values and the CSV reader
    /// of their text agree on every campaign and every first error.
    fn rows_of(draw: &[(usize, usize, usize, f64, u8)], times: bool) -> GaugeRows {
        let robot = robot();
        let mut rows = GaugeRows::new("arrays", vec![], vec![], vec![], vec![]);
        let mut t = Vec::new();
        for (k, &(label, sensor, offset, noise, fault)) in draw.iter().enumerate() {
            let mut pose = about_home(&robot, OFFSETS[(offset + label) % 4]);
            let mut sensor = robot.table.sensors[sensor].name.clone();
            let p =
                Pose::from_xyz_rpy_deg([pose[0], pose[1], pose[2]], [pose[3], pose[4], pose[5]]);
            let mut length = robot.table.sensors[robot.table.sensor_index(&sensor).unwrap()]
                .length_mm(&p)
                + noise;
            let mut label = LABELS[label].to_string();
            let mut time = k as f64 * 0.5;
            match fault {
                0 => pose[k % 6] = f64::NAN,
                1 => length = f64::INFINITY,
                2 => pose[3 + k % 3] = 400.0,
                3 => pose[k % 3] = 2e6,
                4 => sensor = "zz".into(),
                5 => label.clear(),
                6 => sensor.clear(),
                7 => pose[0] += 1.0,
                8 => length += 100.0,
                9 => pose[2] += 1000.0,
                10 => time = f64::NAN,
                11 => pose[1] = -0.0,
                12 => label.insert(0, '\n'),
                13 => sensor.push_str("\nx"),
                14 => label = long_text(k),
                15 => sensor = long_text(k),
                _ => {}
            }
            rows.pose_labels.push(label);
            rows.sensors.push(sensor);
            rows.poses.push(pose);
            rows.lengths_mm.push(length);
            t.push(time);
        }
        if times {
            rows.time_s = Some(t);
        }
        rows
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn rows_read_as_their_csv_reads(
            draw in proptest::collection::vec(row(), 0..40),
            times in any::<bool>(),
            simulated in any::<bool>(),
            max_rows in prop_oneof![Just(crate::MAX_ROWS), 1..30usize],
        ) {
            let robot = robot();
            let mut rows = rows_of(&draw, times);
            rows.simulated = simulated;
            let options = ReadOptions { max_rows, ..ReadOptions::default() };
            let direct = outcome(read_gauge_rows(&rows, &robot, &options));
            let text = rows.to_csv();
            let csv = outcome(crate::read_readings(&text, "arrays", &robot, &options));
            prop_assert_eq!(direct, csv, "text:\n{}", text);
        }

        #[test]
        fn tracker_rows_read_as_their_csv_reads(
            draw in proptest::collection::vec(tracker_row(), 0..30),
            quaternion in any::<bool>(),
            times in any::<bool>(),
            simulated in any::<bool>(),
            shape in 0..12u8,
            max_rows in prop_oneof![Just(crate::MAX_ROWS), 1..30usize],
        ) {
            let robot = robot();
            let mut rows = tracker_rows_of(&draw, quaternion, times, shape);
            rows.simulated = simulated;
            let options = ReadOptions { max_rows, ..ReadOptions::default() };
            let direct = outcome(read_tracker_rows(&rows, &robot, &options));
            let text = rows.to_csv();
            let csv = outcome(crate::campaign::read_pose_measurements(
                &text, "tracker arrays", &robot, &options,
            ));
            prop_assert_eq!(direct, csv, "text:\n{}", text);
        }
    }

    /// Enough poses for several chunks of them (`JUDGE_CHUNK` each) to be judged while the
    /// rows are read, some unreachable in every chunk, read whole, refused by a row after
    /// some chunks and cut by `max_rows` within one: the same as the CSV reader of their text.
    #[test]
    fn many_poses_read_as_their_csv_reads() {
        let robot = robot();
        let n = 2 * JUDGE_CHUNK + JUDGE_CHUNK / 2 + 7;
        let mut rows = GaugeRows::new("arrays", vec![], vec![], vec![], vec![]);
        let mut unreachable = 0;
        for k in 0..n {
            let o = OFFSETS[k % 4];
            let step = (k % 13) as f64 * 0.1;
            let mut pose = about_home(&robot, [o[0] + step, o[1], o[2], o[3], o[4], o[5]]);
            if k % 397 == 5 {
                pose[2] += 1000.0; // links far beyond their limits
                unreachable += 1;
            }
            let p =
                Pose::from_xyz_rpy_deg([pose[0], pose[1], pose[2]], [pose[3], pose[4], pose[5]]);
            let s = &robot.table.sensors[k % robot.table.sensors.len()];
            rows.pose_labels.push(format!("p{k}"));
            rows.sensors.push(s.name.clone());
            rows.poses.push(pose);
            rows.lengths_mm.push(s.length_mm(&p));
        }
        assert!(unreachable >= 2 * (n / JUDGE_CHUNK));
        let broken = 2 * JUDGE_CHUNK + 3;
        for (max_rows, broken) in [
            (crate::MAX_ROWS, None),
            (crate::MAX_ROWS, Some(broken)),
            (JUDGE_CHUNK + 100, None),
        ] {
            let mut r = rows.clone();
            if let Some(b) = broken {
                r.lengths_mm[b] = f64::NAN;
            }
            let options = ReadOptions {
                max_rows,
                ..ReadOptions::default()
            };
            let read = read_gauge_rows(&r, &robot, &options);
            if max_rows == crate::MAX_ROWS && broken.is_none() {
                let f = read.as_ref().expect("read");
                assert_eq!(f.excluded.len(), unreachable, "{:?}", f.excluded);
            } else {
                assert!(read.is_err());
            }
            let csv = crate::read_readings(&r.to_csv(), "arrays", &robot, &options);
            assert_eq!(outcome(read), outcome(csv));
        }
    }

    /// A text near the CSV reader's line limit: its row's line a little shorter or longer
    /// than [`MAX_LINE_BYTES`] (by the row's numbers); some with a line break late in it.
    fn long_text(k: usize) -> String {
        let mut t = "x".repeat(MAX_LINE_BYTES - 40 - 13 * (k % 16));
        if k.is_multiple_of(5) {
            t.insert(t.len() - 3, '\n');
        }
        t
    }

    /// One pose row: a label of a few (some awkward for CSV), an offset from home, and a
    /// fault drawn now and then.
    fn pose_row() -> impl Strategy<Value = (usize, usize, u8)> {
        (0..7usize, 0..4usize, 0..60u8)
    }

    /// Pose rows about the example hexapod's home with faults; `radians` gives every angle in
    /// radians (refused for all of them).
    fn pose_rows_of(draw: &[(usize, usize, u8)], radians: bool) -> PoseRows {
        let robot = robot();
        let mut rows = PoseRows::new("poses", vec![]);
        for (k, &(label, offset, fault)) in draw.iter().enumerate() {
            let mut pose = about_home(&robot, OFFSETS[offset]);
            if radians {
                pose[3..]
                    .iter_mut()
                    .for_each(|a| *a = a.to_radians() / 10.0);
            }
            let mut label = format!("{}{}", LABELS[label], k % 3);
            match fault {
                0 => pose[k % 6] = f64::NAN,
                1 => pose[k % 6] = f64::NEG_INFINITY,
                2 => pose[3 + k % 3] = 400.0,
                3 => pose[k % 3] = 2e6,
                4 => label.clear(),
                5 => label.insert(1, '\n'),
                6 => pose[1] = -0.0,
                7 => label = long_text(k),
                8 => pose[k % 6] = 5e-324,
                _ => {}
            }
            rows.pose_labels.push(label);
            rows.poses.push(pose);
        }
        rows
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn pose_rows_read_as_their_csv_reads(
            draw in proptest::collection::vec(pose_row(), 0..30),
            radians in prop_oneof![4 => Just(false), 1 => Just(true)],
        ) {
            let rows = pose_rows_of(&draw, radians);
            let direct = format!("{:?}", read_pose_rows(&rows));
            let text = rows.to_csv();
            let csv = format!("{:?}", crate::read_pose_list(&text, "poses"));
            prop_assert_eq!(direct, csv, "text:\n{}", text);
        }
    }

    /// A label (or sensor name) that makes its row's line longer than the CSV reader takes is
    /// refused as that reader refuses the line, naming the line; one byte less is read.
    #[test]
    fn a_row_longer_than_a_line_is_refused_as_its_csv_is() {
        let robot = robot();
        let options = ReadOptions::default();
        let home = robot.table.home;
        let [r, p, y] = home.rpy_deg();
        let x = home.position_mm;
        let pose = [x.x, x.y, x.z, r, p, y];
        let length = robot.table.sensors[0].length_mm(&home);
        let sensor = robot.table.sensors[0].name.clone();
        let tracker_pose = TrackerPoses::Rpy(vec![pose; 2]);
        for over in [0, 1] {
            // Rows "a" then the long one; the long row's line with its break is
            // MAX_LINE_BYTES + over bytes (the most the reader takes, and one more).
            let mut poses = PoseRows::new("poses", vec![pose; 2]);
            let short = poses.to_csv().lines().nth(2).unwrap().len() - 1;
            poses.pose_labels[1] = "y".repeat(MAX_LINE_BYTES - 1 + over - short);
            let direct = read_pose_rows(&poses);
            let csv = crate::read_pose_list(&poses.to_csv(), "poses");
            assert_eq!(format!("{direct:?}"), format!("{csv:?}"));
            let e = direct.err().map(|e| e.to_string());
            assert_eq!(
                e.is_some(),
                over == 1,
                "{:?}",
                e.map(|e| e[..80].to_string())
            );
            if over == 1 {
                assert!(e.unwrap().starts_with("poses:3: the line is longer than"));
            }
            let mut gauge = GaugeRows::new(
                "log",
                vec!["a".into(), "b".into()],
                vec![sensor.clone(); 2],
                vec![pose; 2],
                vec![length; 2],
            );
            // The line less its sensor name, then the name made long.
            let short = gauge.to_csv().lines().nth(2).unwrap().len() - sensor.len();
            let more = MAX_LINE_BYTES - 1 + over - short - sensor.len();
            gauge.sensors[1] = format!("{sensor}{}", "z".repeat(more));
            let direct = outcome(read_gauge_rows(&gauge, &robot, &options));
            let csv = outcome(crate::read_readings(
                &gauge.to_csv(),
                "log",
                &robot,
                &options,
            ));
            assert_eq!(direct, csv);
            assert_eq!(direct.contains("log:3: the line is longer than"), over == 1);
            let links = robot.num_links();
            let readings = vec![0.0; 2 * links];
            let labels = vec!["a".into(), "b".into()];
            let mut tracker = TrackerRows::new("t", labels, links, readings, tracker_pose.clone());
            let short = tracker.to_csv().lines().nth(2).unwrap().len() - 1;
            tracker.pose_labels[1] = "w".repeat(MAX_LINE_BYTES - 1 + over - short);
            let direct = outcome(read_tracker_rows(&tracker, &robot, &options));
            let text = tracker.to_csv();
            let csv = outcome(crate::campaign::read_pose_measurements(
                &text, "t", &robot, &options,
            ));
            assert_eq!(direct, csv);
            assert_eq!(direct.contains("t:3: the line is longer than"), over == 1);
        }
    }

    /// Pose rows: the text is a pose list; columns of different lengths are refused.
    #[test]
    fn pose_rows_csv_and_columns() {
        let mut rows = PoseRows::new("targets", vec![[1.5, -0.0, 3.0, 0.0, 10.0, 0.25]]);
        assert_eq!(
            rows.to_csv(),
            "pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n1,1.5,-0,3,0,10,0.25\n"
        );
        let read = read_pose_rows(&rows).unwrap();
        assert_eq!((read[0].line, read[0].label.as_str()), (2, "1"));
        rows.pose_labels.push("2".into());
        let e = read_pose_rows(&rows).unwrap_err();
        assert_eq!(
            e.to_string(),
            "targets: 1 values of x_mm .. yaw_deg for 2 pose labels: every row needs one"
        );
    }

    /// Columns of different lengths are refused, naming the column.
    #[test]
    fn every_column_needs_a_value_per_row() {
        let mut rows = GaugeRows::new(
            "log",
            vec!["1".into(); 2],
            vec!["s1".into(); 2],
            vec![[0.0; 6]; 2],
            vec![1.0],
        );
        let e = read_gauge_rows(&rows, &robot(), &ReadOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "log: 1 values of length_mm for 2 pose labels: every row needs one"
        );
        rows.lengths_mm.push(1.0);
        rows.time_s = Some(vec![0.0; 3]);
        let e = read_gauge_rows(&rows, &robot(), &ReadOptions::default()).unwrap_err();
        assert!(e.to_string().contains("3 values of time_s"), "{e}");
    }

    /// One tracker row: a label (some awkward for CSV), an offset of the measured pose from
    /// home (x, y, z mm; roll, pitch, yaw deg), noise on the link readings, and a fault drawn
    /// now and then.
    fn tracker_row() -> impl Strategy<Value = (usize, usize, f64, u8)> {
        (0..7usize, 0..4usize, -0.01..0.01f64, 0..200u8)
    }

    /// Tracker rows of the example hexapod with faults: row faults, and faults of the whole
    /// set by `shape` (0: positions in metres, 1: angles in radians, 2: a link reading short).
    fn tracker_rows_of(
        draw: &[(usize, usize, f64, u8)],
        quaternion: bool,
        times: bool,
        shape: u8,
    ) -> TrackerRows {
        let robot = robot();
        let home = robot.table.home;
        let [r0, p0, y0] = home.rpy_deg();
        let links = robot.num_links() - usize::from(shape == 2);
        let mut labels: Vec<String> = Vec::new();
        let (mut readings, mut rpy, mut quat, mut t) = (vec![], vec![], vec![], vec![]);
        for (k, &(label, offset, noise, fault)) in draw.iter().enumerate() {
            let o = OFFSETS[(offset + label) % 4];
            let xyz = [
                home.position_mm.x + o[0],
                home.position_mm.y + o[1],
                home.position_mm.z + o[2],
            ];
            let p = Pose::from_xyz_rpy_deg(xyz, [r0 + o[3], p0 + o[4], y0 + o[5]]);
            let lengths = cpm_kinematics::inverse_lengths(&robot.table, &p);
            let mut u: Vec<f64> = (0..links)
                .map(|i| robot.reading(i, lengths[i]) + noise)
                .collect();
            // In the tracker's frame: shifted (the reader does not know the frame).
            let mut x = [xyz[0] + 1200.0, xyz[1] - 300.0, xyz[2] + 40.0];
            if shape == 0 {
                x = x.map(|v| v / 1000.0);
            }
            let mut a = [r0 + o[3], p0 + o[4], y0 + o[5]];
            if shape == 1 {
                a = a.map(f64::to_radians);
            }
            let q = p.quaternion();
            let mut pr = [x[0], x[1], x[2], a[0], a[1], a[2]];
            let mut pq = [x[0], x[1], x[2], q[0], q[1], q[2], q[3]];
            let mut label = format!("{}{k}", LABELS[label]);
            let mut time = k as f64 * 0.5;
            match fault {
                0 => {
                    pr[k % 6] = f64::NAN;
                    pq[k % 7] = f64::NAN;
                }
                1 => u[k % links] = f64::INFINITY,
                2 => {
                    pr[3 + k % 3] = 400.0;
                    pq[3] *= 1.5;
                }
                3 => {
                    pr[k % 3] = 2e6;
                    pq[k % 3] = -2e6;
                }
                4 => label = labels.last().cloned().unwrap_or_default(),
                5 => label.clear(),
                6 => time = f64::NAN,
                7 => u[links - 1] = f64::NAN,
                8 => {
                    pr[1] = -0.0;
                    pq[4] = -0.0;
                }
                9 => pq[3..].iter_mut().for_each(|v| *v = -*v),
                10 => pq[3..].iter_mut().for_each(|v| *v *= 1.0005),
                11 => label.push('\n'),
                12 => label = long_text(k),
                _ => {}
            }
            labels.push(label);
            readings.extend(u);
            rpy.push(pr);
            quat.push(pq);
            t.push(time);
        }
        let poses = match quaternion {
            true => TrackerPoses::Quaternion(quat),
            false => TrackerPoses::Rpy(rpy),
        };
        let mut rows = TrackerRows::new("tracker arrays", labels, links, readings, poses);
        if times {
            rows.time_s = Some(t);
        }
        rows
    }

    /// Tracker columns of different lengths are refused, naming the column.
    #[test]
    fn every_tracker_column_needs_a_value_per_row() {
        let poses = TrackerPoses::Rpy(vec![[0.0; 6]; 2]);
        let mut rows =
            TrackerRows::new("log", vec!["1".into(), "2".into()], 6, vec![0.0; 11], poses);
        let e = read_tracker_rows(&rows, &robot(), &ReadOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "log: 11 values of reading_1 .. reading_6 for 2 pose labels: every row needs 6"
        );
        rows.readings.push(0.0);
        rows.poses = TrackerPoses::Quaternion(vec![[0.0; 7]; 3]);
        let e = read_tracker_rows(&rows, &robot(), &ReadOptions::default()).unwrap_err();
        assert!(e.to_string().contains("3 values of x_mm .. qz"), "{e}");
    }

    /// The text of tracker rows is the tracker file format, numbers exact.
    #[test]
    fn tracker_rows_csv() {
        let poses = TrackerPoses::Quaternion(vec![[1.5, -0.0, 3.0, 1.0, 0.0, 0.0, 0.0]]);
        let mut rows = TrackerRows::new("log", vec!["a,b".into()], 2, vec![0.1, 2.0], poses);
        rows.time_s = Some(vec![0.25]);
        rows.simulated = true;
        assert_eq!(
            rows.to_csv(),
            "pose,reading_1,reading_2,x_mm,y_mm,z_mm,qw,qx,qy,qz,time_s,simulated\n\
             \"a,b\",0.1,2,1.5,-0,3,1,0,0,0,0.25,true\n"
        );
    }
}
