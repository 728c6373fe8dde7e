//! Robot descriptions (`cpm_io::Robot`) for Python: loaded from a file or from TOML text with
//! the command's checks and errors; the joints, links and sensors as numpy arrays.
use std::path::PathBuf;

use cpm_io::Robot;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;

/// A robot description as read by `cpm`: its TOML text, where it came from, and the parsed
/// robot.
#[pyclass(name = "RobotHandle", module = "cpm._cpm", frozen)]
pub struct PyRobot {
    /// The description as written.
    pub text: String,
    /// The file it was read from, when it was.
    pub path: Option<PathBuf>,
    /// The robot.
    pub robot: Robot,
}

/// Reads a robot description file (the checks and errors of `cpm --robot`).
#[pyfunction]
pub fn robot_load(py: Python<'_>, path: PathBuf) -> PyResult<PyRobot> {
    let text = cpm_io::read_text(&path).map_err(|e| crate::errors::read_to_py(py, e))?;
    let robot = Robot::from_toml(&text, &path.display().to_string())
        .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))?;
    Ok(PyRobot {
        text,
        path: Some(path),
        robot,
    })
}

/// Reads a robot description from TOML text; `name` stands for the file in messages.
#[pyfunction]
pub fn robot_from_text(py: Python<'_>, text: String, name: String) -> PyResult<PyRobot> {
    let robot = Robot::from_toml(&text, &name)
        .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))?;
    Ok(PyRobot {
        text,
        path: None,
        robot,
    })
}

/// Points as an `(n, 3)` array.
fn rows3<'py>(py: Python<'py>, rows: impl Iterator<Item = [f64; 3]>) -> Bound<'py, PyArray2<f64>> {
    let v: Vec<Vec<f64>> = rows.map(|r| r.to_vec()).collect();
    if v.is_empty() {
        return PyArray2::zeros(py, [0, 3], false);
    }
    // Every row has three entries: the conversion cannot fail.
    PyArray2::from_vec2(py, &v).unwrap_or_else(|_| PyArray2::zeros(py, [0, 3], false))
}

#[pymethods]
impl PyRobot {
    /// The description's TOML text.
    #[getter]
    fn text(&self) -> &str {
        &self.text
    }
    /// The file it was read from (`None` when made from text).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }
    /// The name it goes by in messages (the file as given).
    #[getter]
    fn file(&self) -> &str {
        &self.robot.file
    }
    /// The description's `name`.
    #[getter]
    fn name(&self) -> Option<String> {
        self.robot.description.name.clone()
    }
    /// Number of links.
    #[getter]
    fn num_links(&self) -> usize {
        self.robot.num_links()
    }
    /// Base joints in {B}, mm, `(links, 3)` (with `[installation_errors_um]` applied).
    #[getter]
    fn base_joints_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows3(py, self.robot.table.links.iter().map(|l| l.base_mm.into()))
    }
    /// Platform joints in {P}, mm, `(links, 3)`.
    #[getter]
    fn platform_joints_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows3(
            py,
            self.robot.table.links.iter().map(|l| l.platform_mm.into()),
        )
    }
    /// Each link's length at reading 0, mm.
    #[getter]
    fn length_at_zero_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_iter(
            py,
            self.robot
                .description
                .links
                .iter()
                .map(|l| l.length_at_zero_mm),
        )
    }
    /// Each link's mm per reading unit.
    #[getter]
    fn mm_per_unit<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_iter(
            py,
            self.robot.description.links.iter().map(|l| l.mm_per_unit),
        )
    }
    /// Sensor names, in the order of `[[sensor]]`.
    #[getter]
    fn sensor_names(&self) -> Vec<String> {
        self.robot
            .table
            .sensors
            .iter()
            .map(|s| s.name.clone())
            .collect()
    }
    /// Sensor sockets on the base, {B}, mm, `(sensors, 3)`.
    #[getter]
    fn sensor_base_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows3(
            py,
            self.robot.table.sensors.iter().map(|s| s.base_mm.into()),
        )
    }
    /// Sensor sockets on the platform, {P}, mm, `(sensors, 3)`.
    #[getter]
    fn sensor_platform_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows3(
            py,
            self.robot
                .table
                .sensors
                .iter()
                .map(|s| s.platform_mm.into()),
        )
    }
    /// The home pose: x, y, z (mm), roll, pitch, yaw (deg).
    #[getter]
    fn home<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let h = &self.robot.table.home;
        let rpy = h.rpy_deg();
        PyArray1::from_vec(
            py,
            vec![
                h.position_mm.x,
                h.position_mm.y,
                h.position_mm.z,
                rpy[0],
                rpy[1],
                rpy[2],
            ],
        )
    }
    /// The effects declared in `[calibration] effects`.
    #[getter]
    fn declared_effects(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        self.robot
            .declared_effects()
            .map(|v| v.iter().map(|e| e.name().to_string()).collect())
            .map_err(|e| crate::errors::input(py, e.to_string(), Some(&e)))
    }
    /// `[calibration] sensor_noise_um`.
    #[getter]
    fn sensor_noise_um(&self) -> Option<f64> {
        self.robot.sensor_noise_um()
    }
    /// True when `[installation_errors_um]` moved the joints.
    #[getter]
    fn errors_applied(&self) -> bool {
        self.robot.errors_applied
    }
    /// The whole description as JSON text (every table and key of the TOML).
    fn description_json(&self, py: Python<'_>) -> PyResult<String> {
        serde_json::to_string(&self.robot.description)
            .map_err(|e| crate::errors::internal(py, e.to_string()))
    }
}
