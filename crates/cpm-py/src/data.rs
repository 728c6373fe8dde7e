//! Measurements for Python: files read by the readers of `cpm` (same checks, same
//! `file:line: field` errors); gauge readings and tracker measurements from numpy arrays
//! read as values by [`cpm_io::rows`] (the checks and errors of the CSV reader, no text;
//! tracker sets registered as tracker files are).
//!
//! A command that reads files gets the arrays' CSV ([`PyData`]'s `csv`), every number in
//! Rust's shortest round-trip form, so its reader gets back every `f64` exactly.
use std::path::PathBuf;

use cpm_io::{DataFile, FileKind, ReadOptions};
use cpm_workflow::ingest::RegistrationOptions;
use cpm_workflow::memory::Given;
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::robot::PyRobot;

/// Measurements as read, kept for the jobs that take them from memory
/// ([`cpm_workflow::memory`]): the file as read, the read options, its text (read again when a
/// job needs other options) and the robot they were read against.
#[pyclass(name = "DataHandle", module = "cpm._cpm", frozen)]
pub struct PyData {
    /// The measurements as read.
    pub data: std::sync::Arc<DataFile>,
    /// The read options they were read with.
    pub options: ReadOptions,
    /// The registration options they were read with (tracker files).
    pub registration: RegistrationOptions,
    /// What they were read from (a file's text, or readings as values).
    pub given: Given,
    /// The robot's description text and name they were read against.
    pub robot: (String, String),
    /// What the summary of these measurements needs of that robot: its sensors' names and
    /// number of links.
    pub names: Names,
}

/// What a summary of measurements needs of the robot they were read against: its sensors'
/// names (readings name their sensor by index) and its number of links.
#[derive(Debug, Clone)]
pub struct Names {
    sensors: Vec<String>,
    links: usize,
}

impl Names {
    fn of(robot: &PyRobot) -> Names {
        Names {
            sensors: robot
                .robot
                .table
                .sensors
                .iter()
                .map(|s| s.name.clone())
                .collect(),
            links: robot.robot.num_links(),
        }
    }
}

impl PyData {
    /// The measurements as a source of a job on `robot`: as read when read against it,
    /// else their text to read again.
    pub fn source(&self, robot: &PyRobot) -> cpm_workflow::memory::Source {
        use cpm_workflow::memory::{ReadData, Source};
        if self.robot.0 == robot.text && self.robot.1 == robot.robot.file {
            Source::Read(ReadData {
                data: self.data.clone(),
                options: self.options,
                registration: self.registration,
                given: self.given.clone(),
            })
        } else {
            match &self.given {
                Given::Text(text) => Source::Text {
                    name: self.data.file.clone(),
                    text: text.clone(),
                },
                Given::GaugeRows(rows) => Source::GaugeRows(rows.clone()),
                Given::TrackerRows(rows) => Source::TrackerRows(rows.clone()),
            }
        }
    }
}

#[pymethods]
impl PyData {
    /// The measurements as the text of a measurement file (for a command that reads files):
    /// the text read, or the CSV of readings given as values (every number exact).
    fn csv(&self) -> String {
        match &self.given {
            Given::Text(text) => text.to_string(),
            Given::GaugeRows(rows) => rows.to_csv(),
            Given::TrackerRows(rows) => rows.to_csv(),
        }
    }

    /// What the measurements hold, as a dict of plain values and numpy arrays (made when
    /// asked: the dict of `read_text` and of the readers of arrays holds only `file`,
    /// `kind`, `simulated` and `handle`).
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        summary(py, &self.data, &self.names)
    }
}

/// The read and registration options of `cpm calibrate` for a robot and its declared effects.
fn options(py: Python<'_>, robot: &PyRobot) -> PyResult<(ReadOptions, RegistrationOptions)> {
    let effects = robot
        .robot
        .declared_effects()
        .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))?;
    let model = robot.robot.model(&effects);
    Ok((
        cpm_workflow::load::read_options(&model),
        cpm_workflow::load::registration_options(&model),
    ))
}

/// What a measurement file is: its `file` name, `kind`, whether `simulated`, and the poses
/// left out while reading it (`excluded`).
fn brief<'py>(py: Python<'py>, f: &DataFile) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("file", &f.file)?;
    d.set_item(
        "kind",
        match f.kind {
            FileKind::Readings => "gauge",
            FileKind::PoseMeasurements => "tracker",
            FileKind::Poses => "poses",
            FileKind::PointMeasurements => "points",
            FileKind::TiltMeasurements => "tilts",
        },
    )?;
    d.set_item("simulated", f.campaign.simulated)?;
    // The poses left out while reading (unreachable), in the words the commands warn with.
    d.set_item(
        "excluded",
        f.excluded.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
    )?;
    Ok(d)
}

/// What a measurement file holds, as a dict of plain values and numpy arrays: [`brief`]
/// and every array.
fn summary<'py>(py: Python<'py>, f: &DataFile, names: &Names) -> PyResult<Bound<'py, PyDict>> {
    let d = brief(py, f)?;
    let c = &f.campaign;
    // One flat list of numbers per array (no list per pose).
    let mut poses = Vec::with_capacity(6 * c.poses.len());
    for p in &c.poses {
        let r = p.rpy_deg();
        poses.extend([
            p.position_mm.x,
            p.position_mm.y,
            p.position_mm.z,
            r[0],
            r[1],
            r[2],
        ]);
    }
    d.set_item("poses", flat_array2(py, poses, 6)?)?;
    d.set_item("pose_labels", f.pose_labels.clone())?;
    d.set_item("pose_lines", f.pose_lines.clone())?;
    d.set_item(
        "reading_pose",
        PyArray1::from_iter(py, c.readings.iter().map(|r| r.pose as i64)),
    )?;
    // Each sensor's name made once as a Python string, shared by its readings.
    let name_objects: Vec<Bound<'py, PyString>> =
        names.sensors.iter().map(|s| PyString::new(py, s)).collect();
    let unknown = PyString::new(py, "?");
    d.set_item(
        "reading_sensor",
        PyList::new(
            py,
            c.readings
                .iter()
                .map(|r| name_objects.get(r.sensor).unwrap_or(&unknown)),
        )?,
    )?;
    d.set_item(
        "lengths_mm",
        PyArray1::from_iter(py, c.readings.iter().map(|r| r.length_mm)),
    )?;
    d.set_item("reading_lines", f.reading_lines.clone())?;
    d.set_item(
        "time_s",
        PyArray1::from_iter(
            py,
            c.readings
                .iter()
                .map(|r| r.time_s.get().unwrap_or(f64::NAN)),
        ),
    )?;
    d.set_item(
        "temperature_c",
        PyArray1::from_iter(
            py,
            c.readings
                .iter()
                .map(|r| r.temperature_c.get().unwrap_or(f64::NAN)),
        ),
    )?;
    match &c.commanded_lengths_mm {
        Some(l) => d.set_item("commanded_lengths_mm", array2(py, l, names.links)?)?,
        None => d.set_item("commanded_lengths_mm", py.None())?,
    }
    let mut measured = Vec::with_capacity(7 * c.pose_measurements.len());
    for m in &c.pose_measurements {
        let q = m.measured.quaternion();
        let p = m.measured.position_mm;
        measured.extend([p.x, p.y, p.z, q[0], q[1], q[2], q[3]]);
    }
    d.set_item("measured_poses", flat_array2(py, measured, 7)?)?;
    d.set_item(
        "measured_pose_index",
        PyArray1::from_iter(py, c.pose_measurements.iter().map(|m| m.pose as i64)),
    )?;
    d.set_item(
        "registration_failure",
        f.registration.as_ref().and_then(|r| r.failure.clone()),
    )?;
    Ok(d)
}

/// `values`, `width` numbers per row one row after the other, as an `(n, width)` array.
fn flat_array2(
    py: Python<'_>,
    values: Vec<f64>,
    width: usize,
) -> PyResult<Bound<'_, PyArray2<f64>>> {
    let rows = values.len() / width;
    PyArray1::from_vec(py, values)
        .reshape([rows, width])
        .map_err(|e| crate::errors::internal(py, e.to_string()))
}

/// Rows of `width` numbers as an `(n, width)` array (`(0, width)` when empty).
fn array2<'py>(
    py: Python<'py>,
    rows: &[Vec<f64>],
    width: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    if rows.is_empty() {
        return Ok(PyArray2::zeros(py, [0, width], false));
    }
    PyArray2::from_vec2(py, rows).map_err(|e| crate::errors::internal(py, e.to_string()))
}

/// Reads a measurement file (gauge readings or tracker poses) against a robot, with the
/// checks of `cpm calibrate --data` for the robot's declared effects.
#[pyfunction]
pub fn read_file<'py>(
    py: Python<'py>,
    path: PathBuf,
    robot: &PyRobot,
) -> PyResult<Bound<'py, PyDict>> {
    let (options, registration) = options(py, robot)?;
    let f = cpm_workflow::ingest::read_data_file(&path, &robot.robot, &options, &registration)
        .map_err(|e| crate::errors::read_to_py(py, e))?;
    if f.kind == FileKind::Poses {
        return Err(crate::errors::input(
            py,
            format!("{}: a pose list has no measurements", f.file),
            None,
        ));
    }
    summary(py, &f, &Names::of(robot))
}

/// The dict of [`brief`] with its `handle`: the measurements as read, how, and from what
/// (the handle's `summary()` gives the rest of [`summary`], when asked).
fn with_handle<'py>(
    py: Python<'py>,
    f: DataFile,
    (options, registration): (ReadOptions, RegistrationOptions),
    given: Given,
    robot: &PyRobot,
) -> PyResult<Bound<'py, PyDict>> {
    let d = brief(py, &f)?;
    let handle = PyData {
        data: std::sync::Arc::new(f),
        options,
        registration,
        given,
        robot: (robot.text.clone(), robot.robot.file.clone()),
        names: Names::of(robot),
    };
    d.set_item("handle", Bound::new(py, handle)?)?;
    Ok(d)
}

/// Reads measurements from CSV text; `name` stands for the file in messages. The dict's
/// `handle` keeps them as read, for the jobs that take measurements from memory.
#[pyfunction]
pub fn read_text<'py>(
    py: Python<'py>,
    text: &str,
    name: &str,
    robot: &PyRobot,
) -> PyResult<Bound<'py, PyDict>> {
    let (options, registration) = options(py, robot)?;
    let f = cpm_workflow::ingest::read_data(text, name, &robot.robot, &options, &registration)
        .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))?;
    let given = Given::Text(text.into());
    with_handle(py, f, (options, registration), given, robot)
}

/// A list of poses given as an array `(n, 6)` (x, y, z mm; roll, pitch, yaw deg), labelled
/// from 1, named `name` (read by the job with the checks of a pose list file:
/// [`cpm_io::rows::read_pose_rows`], row `k` on line `k + 2`).
pub fn pose_rows(
    py: Python<'_>,
    poses: PyReadonlyArray2<'_, f64>,
    name: &str,
) -> PyResult<cpm_io::rows::PoseRows> {
    let poses = poses.as_array();
    check_shape(py, "poses", poses.shape(), poses.shape()[0], Some(6))?;
    let values = poses
        .rows()
        .into_iter()
        .map(|r| std::array::from_fn(|c| r[c]))
        .collect();
    Ok(cpm_io::rows::PoseRows::new(name, values))
}

/// Checks that an array has `n` rows (and `cols` columns); a usage error naming it otherwise.
fn check_shape(
    py: Python<'_>,
    what: &str,
    shape: &[usize],
    n: usize,
    cols: Option<usize>,
) -> PyResult<()> {
    let ok = shape[0] == n && cols.is_none_or(|c| shape.get(1) == Some(&c));
    if ok {
        return Ok(());
    }
    let want = match cols {
        Some(c) => format!("({n}, {c})"),
        None => format!("({n},)"),
    };
    Err(crate::errors::usage(
        py,
        format!("{what} has shape {shape:?}, expected {want}"),
    ))
}

/// The texts of a sequence as Python's `str()` gives them (an exact `str` as it is,
/// anything else, a subclass of `str` too, through `str()`), converted here rather than by a list comprehension in Python: a run of
/// the same object (a label shared by the rows of a pose) is converted once.
fn texts(items: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
    let mut out = Vec::with_capacity(items.len().unwrap_or(0));
    // The previous item, held (so its address cannot be taken by another object), and its text.
    let mut previous: Option<Bound<'_, PyAny>> = None;
    for item in items.try_iter()? {
        let item = item?;
        if let (Some(p), Some(last)) = (&previous, out.last()) {
            if p.is(&item) {
                let again = String::clone(last);
                out.push(again);
                continue;
            }
        }
        let text = match item.downcast_exact::<PyString>() {
            Ok(s) => s.to_str()?.to_owned(),
            Err(_) => item.str()?.to_str()?.to_owned(),
        };
        out.push(text);
        previous = Some(item);
    }
    Ok(out)
}

/// Optional labels (any values, as their `str()`) and times, checked against `n` rows.
fn labels_and_times(
    py: Python<'_>,
    n: usize,
    labels: Option<&Bound<'_, PyAny>>,
    time_s: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<(Vec<String>, Option<Vec<f64>>)> {
    let labels = match labels.map(texts).transpose()? {
        Some(l) => {
            check_shape(py, "pose_labels", &[l.len()], n, None)?;
            l
        }
        None => (1..=n).map(|k| k.to_string()).collect(),
    };
    let times = match time_s {
        Some(t) => {
            check_shape(py, "time_s", t.shape(), n, None)?;
            Some(t.as_array().iter().copied().collect())
        }
        None => None,
    };
    Ok((labels, times))
}

/// Reads gauge readings given as arrays (no text: [`cpm_io::rows::read_gauge_rows`], the
/// checks and errors of the CSV reader, row `k` on line `k + 2`): `poses` `(n, 6)` (x, y,
/// z mm; roll, pitch, yaw deg), `sensors` `n` names (any sequence, its items' `str()`),
/// `lengths_mm` `(n,)`; rows with the same label (any sequence, as `str()`) share a pose
/// (default: every row its own pose, labelled from 1). `name` stands for the file in
/// messages and outputs. Returns the dict of [`read_text`], with its `handle`.
#[pyfunction]
#[pyo3(signature = (poses, sensors, lengths_mm, robot, name, pose_labels=None, time_s=None, simulated=false))]
#[allow(clippy::too_many_arguments)]
pub fn gauge_rows<'py>(
    py: Python<'py>,
    poses: PyReadonlyArray2<'py, f64>,
    sensors: &Bound<'py, PyAny>,
    lengths_mm: PyReadonlyArray1<'py, f64>,
    robot: &PyRobot,
    name: &str,
    pose_labels: Option<&Bound<'py, PyAny>>,
    time_s: Option<PyReadonlyArray1<'py, f64>>,
    simulated: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let poses = poses.as_array();
    let n = poses.shape()[0];
    check_shape(py, "poses", poses.shape(), n, Some(6))?;
    let sensors = texts(sensors)?;
    check_shape(py, "sensors", &[sensors.len()], n, None)?;
    check_shape(py, "lengths_mm", lengths_mm.shape(), n, None)?;
    let (pose_labels, time_s) = labels_and_times(py, n, pose_labels, time_s)?;
    let rows = cpm_io::rows::GaugeRows {
        file: name.to_string(),
        pose_labels,
        sensors,
        poses: poses
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2], r[3], r[4], r[5]])
            .collect(),
        lengths_mm: lengths_mm.as_array().iter().copied().collect(),
        time_s,
        simulated,
    };
    let (options, registration) = options(py, robot)?;
    let f = py
        .allow_threads(|| cpm_io::rows::read_gauge_rows(&rows, &robot.robot, &options))
        .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))?;
    let given = Given::GaugeRows(std::sync::Arc::new(rows));
    with_handle(py, f, (options, registration), given, robot)
}

/// Reads tracker measurements given as arrays (no text: [`cpm_io::rows::read_tracker_rows`],
/// the checks and errors of the CSV reader, row `k` on line `k + 2`; then registered as a
/// tracker file is): one row per pose, `readings` `(n, links)` (commanded link readings, the
/// links' units), `poses` `(n, 7)` (measured x, y, z mm; quaternion qw, qx, qy, qz) or
/// `(n, 6)` (x, y, z mm; roll, pitch, yaw deg, the file format's other orientation); labels
/// default to the row numbers from 1. `name` stands for the file in messages and outputs.
/// Returns the dict of [`read_text`], with its `handle`.
#[pyfunction]
#[pyo3(signature = (readings, poses, robot, name, pose_labels=None, time_s=None, simulated=false))]
#[allow(clippy::too_many_arguments)]
pub fn tracker_rows<'py>(
    py: Python<'py>,
    readings: PyReadonlyArray2<'py, f64>,
    poses: PyReadonlyArray2<'py, f64>,
    robot: &PyRobot,
    name: &str,
    pose_labels: Option<&Bound<'py, PyAny>>,
    time_s: Option<PyReadonlyArray1<'py, f64>>,
    simulated: bool,
) -> PyResult<Bound<'py, PyDict>> {
    use cpm_io::rows::{TrackerPoses, TrackerRows};
    let readings = readings.as_array();
    let poses = poses.as_array();
    let (n, links) = (readings.shape()[0], readings.shape()[1]);
    let cols = if poses.shape().get(1) == Some(&6) {
        6
    } else {
        7
    };
    if check_shape(py, "poses", poses.shape(), n, Some(cols)).is_err() {
        return Err(crate::errors::usage(
            py,
            format!(
                "poses has shape {:?}, expected ({n}, 7) (x, y, z mm, qw, qx, qy, qz) or ({n}, 6) (x, y, z mm, roll, pitch, yaw deg)",
                poses.shape()
            ),
        ));
    }
    let (pose_labels, time_s) = labels_and_times(py, n, pose_labels, time_s)?;
    let rows = poses.rows().into_iter();
    let poses = if cols == 6 {
        TrackerPoses::Rpy(rows.map(|r| std::array::from_fn(|c| r[c])).collect())
    } else {
        TrackerPoses::Quaternion(rows.map(|r| std::array::from_fn(|c| r[c])).collect())
    };
    let rows = TrackerRows {
        file: name.to_string(),
        pose_labels,
        links,
        readings: readings.iter().copied().collect(),
        poses,
        time_s,
        simulated,
    };
    let (options, registration) = options(py, robot)?;
    let given = Given::TrackerRows(std::sync::Arc::new(rows));
    let f = py
        .allow_threads(|| given.read(name, &robot.robot, &options, &registration))
        .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))?;
    with_handle(py, f, (options, registration), given, robot)
}
