//! Length-sensor readings given as values (numpy arrays, a program's own log), read into a
//! [`DataFile`] with every check of the CSV reader and the same errors, without text.
//!
//! [`GaugeRows`] holds the columns of a readings file (`docs/formats.md`, "Length-sensor
//! readings") as typed values, one row per reading. [`read_gauge_rows`] gives exactly what
//! [`read_readings`](crate::read_readings) gives for the text [`GaugeRows::to_csv`] writes of
//! them: the same campaign to the last bit, the same exclusions, the same first error (row
//! `k` is line `k + 2` of that text, its header on line 1), in a fraction of the time (no
//! number is formatted or parsed).
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

use cpm_calib::{Campaign, Reading};
use cpm_geometry::Pose;

use crate::campaign::{
    check_angle_units, check_pose_value, exclude_poses, robot_checks, same_pose_as_before,
    too_many_rows_at, unknown_sensor, DataFile, RawPose, ReadOptions,
};
use crate::table::{field, parse_number};
use crate::{InputError, Robot};

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

    /// The number of rows (of the labels; [`read_gauge_rows`] checks the other columns
    /// against it).
    pub fn len(&self) -> usize {
        self.pose_labels.len()
    }

    /// True without rows.
    pub fn is_empty(&self) -> bool {
        self.pose_labels.is_empty()
    }

    /// The line of row `k` (from 0) in the text of [`to_csv`](Self::to_csv): `k + 2`.
    pub fn line(k: usize) -> usize {
        k + 2
    }

    /// The rows as the CSV of a readings file (header on line 1, row `k` on line `k + 2`),
    /// every number in its shortest form that reads back to the same `f64`; a `simulated`
    /// column says whether they are simulated.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm");
        if self.time_s.is_some() {
            s.push_str(",time_s");
        }
        s.push_str(",simulated\n");
        for k in 0..self.len() {
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
            if let Some(t) = &self.time_s {
                let _ = write!(s, ",{}", t.get(k).copied().unwrap_or(f64::NAN));
            }
            let _ = writeln!(s, ",{}", self.simulated);
        }
        s
    }

    /// Checks that every column has a value per row.
    fn check_columns(&self) -> Result<(), InputError> {
        let n = self.len();
        let columns = [
            ("sensor", self.sensors.len()),
            ("x_mm .. yaw_deg", self.poses.len()),
            ("length_mm", self.lengths_mm.len()),
            ("time_s", self.time_s.as_ref().map_or(n, Vec::len)),
        ];
        for (name, len) in columns {
            if len != n {
                return Err(InputError::file(
                    &self.file,
                    format!("{len} values of {name} for {n} pose labels: every row needs one"),
                ));
            }
        }
        Ok(())
    }
}

/// The columns of a row's pose, in the order of [`GaugeRows::poses`].
const POSE_COLUMNS: [&str; 6] = ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"];

/// A value of a number column: finite, else the reader's message for its text.
fn finite(file: &str, line: usize, name: &str, v: f64) -> Result<f64, InputError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(InputError::field(
            file,
            line,
            name,
            parse_number(&v.to_string()).expect_err("not finite"),
        ))
    }
}

/// A required text column: non-empty.
fn required<'a>(file: &str, line: usize, name: &str, v: &'a str) -> Result<&'a str, InputError> {
    if v.is_empty() {
        Err(InputError::field(file, line, name, "missing value"))
    } else {
        Ok(v)
    }
}

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
    let mut by_label: HashMap<&str, usize> = HashMap::new();
    // Per pose: the numbers of its first row, its first line.
    let mut first: Vec<(RawPose, usize)> = Vec::new();
    let mut labels: Vec<String> = Vec::new();
    let mut campaign = Campaign {
        simulated: rows.simulated,
        ..Campaign::default()
    };
    let mut reading_lines = Vec::new();
    let mut angles = Vec::new();
    // The pose and numbers of the previous row (rows of one pose usually follow each other).
    let mut previous: Option<(usize, [f64; 6])> = None;
    let mut read = || -> Result<(), InputError> {
        for k in 0..rows.len() {
            let line = GaugeRows::line(k);
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
            let known = match previous {
                Some((j, _)) if labels[j] == label => Some(j),
                _ => by_label.get(label).copied(),
            };
            // The previous row's numbers exactly (the same text): its pose's first row's.
            let same_as_previous = previous.is_some_and(|(j, v)| {
                labels[j] == label
                    && v.iter()
                        .zip(&values)
                        .all(|(a, b)| a.to_bits() == b.to_bits())
            });
            let (raw, pose) = if same_as_previous {
                (first[known.expect("the previous row's pose")].0, None)
            } else {
                let mut raw = RawPose::default();
                for (name, v) in POSE_COLUMNS.iter().zip(values) {
                    let v = finite(file, line, name, v)?;
                    check_pose_value(file, line, name, v)?;
                    raw.push(name, v);
                }
                let pose = match known {
                    Some(j) if raw.agrees(&first[j].0) => None,
                    _ => Some(Pose::from_xyz_rpy_deg(
                        [values[0], values[1], values[2]],
                        [values[3], values[4], values[5]],
                    )),
                };
                (raw, pose)
            };
            let length_mm = finite(file, line, "length_mm", rows.lengths_mm[k])?;
            let time_s = match &rows.time_s {
                Some(t) => Some(finite(file, line, "time_s", t[k])?),
                None => None,
            };
            let j = match known {
                Some(j) => {
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
                None => {
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
                    j
                }
            };
            previous = Some((j, values));
            campaign.readings.push(Reading {
                pose: j,
                sensor,
                length_mm,
                time_s,
                temperature_c: None,
            });
            reading_lines.push(line);
        }
        Ok(())
    };
    let read = read();
    // The robot's checks of the rows read (all, or those before the refused one) first, as
    // the CSV reader makes them.
    let unusable = robot_checks(
        file,
        robot,
        options,
        &campaign.poses,
        &campaign.readings,
        &reading_lines,
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

    /// Rows of the example hexapod with faults: the reading from values and the CSV reader
    /// of their text agree on every campaign and every first error.
    fn rows_of(draw: &[(usize, usize, usize, f64, u8)], times: bool) -> GaugeRows {
        let robot = robot();
        let home = robot.table.home;
        let [r0, p0, y0] = home.rpy_deg();
        let offsets = [
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [20.0, -10.0, 5.0, 2.0, -1.5, 3.0],
            [-15.0, 12.0, -8.0, -3.0, 1.0, -2.0],
            [5.0, 5.0, 20.0, 0.5, 4.0, 1.0],
        ];
        let mut rows = GaugeRows::new("arrays", vec![], vec![], vec![], vec![]);
        let mut t = Vec::new();
        for (k, &(label, sensor, offset, noise, fault)) in draw.iter().enumerate() {
            let o = offsets[(offset + label) % 4];
            let mut pose = [
                home.position_mm.x + o[0],
                home.position_mm.y + o[1],
                home.position_mm.z + o[2],
                r0 + o[3],
                p0 + o[4],
                y0 + o[5],
            ];
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
}
