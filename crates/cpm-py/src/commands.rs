//! The commands of `cpm` for Python, run as the workflow's jobs ([`cpm_workflow`]): no
//! argument vector, no command-line parser.
//!
//! Options come by name, as JSON text (`{"sigma_um": 2.0, "hold": ["link_scale"]}`), and
//! become the job's options struct ([`by_name`]): every option of a command is a field of its
//! options under the same name (`--sigma-um` is `sigma_um`; `tests/workflow.rs` checks that
//! fields and defaults are the command's), so a Python call takes exactly the command's
//! options with the command's defaults. The typed values are parsed there, once, by
//! [`cpm_workflow::options`] (`{"effects": ["link_offset"]}`, `{"robust": "huber:1.5"}`,
//! `{"tolerance": [{"group": "link_scale", "value": 2000}]}`). Unknown options and values of
//! the wrong type are usage errors naming the option.
//!
//! [`calibrate_memory`] runs the fit on a campaign in memory ([`cpm_workflow::memory`]) and
//! hands back the calibration itself: estimates, standard deviations, the Cramér-Rao
//! covariance, identifiability, residuals, and every staged output file.
//! [`crate::jobs::job`] runs any other command.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde::{de::DeserializeOwned, Serialize};
use serde_json::Value;

/// The options struct `T` of `command` from options given by name (`given`: a JSON object),
/// over `defaults` (the struct's `new`). A list option given one value takes it as a list of
/// one; the options `cpm` splits at commas (`hold`, `sensors`, `bars_mm`) are split alike.
/// Unknown names and values of the wrong type are usage errors naming the option by its
/// keyword (`sigma_um`, not `--sigma-um`: the Python layer names the keywords in the
/// workflow's messages too).
pub fn by_name<T: Serialize + DeserializeOwned>(
    py: Python<'_>,
    command: &str,
    defaults: &T,
    given: &str,
) -> PyResult<T> {
    let internal = |e: serde_json::Error| crate::errors::internal(py, e.to_string());
    let given: serde_json::Map<String, Value> = serde_json::from_str(given).map_err(internal)?;
    let Value::Object(base) = serde_json::to_value(defaults).map_err(internal)? else {
        return Err(crate::errors::internal(py, "options are not an object"));
    };
    let mut all = base.clone();
    for (key, value) in given {
        let flag = format!("--{}", key.replace('_', "-"));
        let Some(default) = base.get(&key) else {
            let mut known: Vec<&String> = base.keys().collect();
            known.sort();
            let known: Vec<&str> = known.iter().map(|k| k.as_str()).collect();
            return Err(crate::errors::usage(
                py,
                format!(
                    "unexpected keyword argument '{key}' ({command} takes {})",
                    known.join(", ")
                ),
            ));
        };
        let value = shaped(&key, default, value);
        let mut one = base.clone();
        one.insert(key.clone(), value.clone());
        if let Err(e) = serde_json::from_value::<T>(Value::Object(one)) {
            // A value the workflow's parsers refuse (cpm_workflow::options) is told in the
            // command's words, which name the option: `--robust "pink:3": unknown loss ...`.
            let e = e.to_string();
            return Err(crate::errors::usage(
                py,
                if e.starts_with(&flag) {
                    e
                } else {
                    format!("invalid value {value} for '{key}': {e}")
                },
            ));
        }
        all.insert(key, value);
    }
    serde_json::from_value(Value::Object(all)).map_err(|e| crate::errors::usage(py, e.to_string()))
}

/// A value given by name in the shape of the option's `default`: one value for a list
/// option is a list of one; `hold`, `sensors` and `bars_mm` split at commas as `cpm` does.
fn shaped(key: &str, default: &Value, value: Value) -> Value {
    if !default.is_array() {
        return value;
    }
    let items = match value {
        Value::Array(a) => a,
        Value::Null => Vec::new(),
        v => vec![v],
    };
    if !["hold", "sensors", "bars_mm"].contains(&key) {
        return Value::Array(items);
    }
    let mut out = Vec::with_capacity(items.len());
    for v in items {
        match v {
            Value::String(s) => {
                for part in s.split(',') {
                    let part = part.trim();
                    out.push(match (key, part.parse::<f64>()) {
                        ("bars_mm", Ok(x)) => serde_json::json!(x),
                        _ => Value::String(part.to_string()),
                    });
                }
            }
            v => out.push(v),
        }
    }
    Value::Array(out)
}

/// The names of the effects `--effects` knows (the library's, without pose map terms).
#[pyfunction]
pub fn effect_names() -> Vec<&'static str> {
    cpm_calib::Effect::ALL.iter().map(|e| e.name()).collect()
}

/// Everything a fit gives, plain data (built on the worker thread).
struct Fit {
    cal: cpm_calib::Calibration,
    names: Vec<String>,
    warnings: Vec<String>,
    trouble: Option<String>,
    files: Vec<(String, Vec<u8>)>,
    written: Vec<String>,
    origins: Origins,
    /// Seconds spent, by part (the job, its solver, and all of the work with the results).
    timings: Vec<(String, f64)>,
    /// The job's warnings (the command's `warning:` lines).
    warned: Vec<String>,
    /// The residual mixes kinds weighed differently (calibration.json's
    /// `residual_weighted`): its RMS and noise are then said in sigma, never in um.
    weighted: bool,
    /// calibration.json's `weighted_rms_in_sigma` and `initial_weighted_rms_in_sigma`.
    weighted_rms_in_sigma: (f64, f64),
    /// Every observation's residual in its own unit, measured minus predicted (as
    /// residuals.csv), its unit's index into `units`, and the units.
    native: (Vec<f64>, Vec<u8>, Vec<String>),
}

/// Every observation's residual as residuals.csv writes it (measured minus predicted, in its
/// kind's unit), with the index of each one's unit into the list of units.
fn native_residuals(
    model: &cpm_calib::MeasurementModel,
    campaign: &cpm_calib::Campaign,
    cal: &cpm_calib::Calibration,
) -> (Vec<f64>, Vec<u8>, Vec<String>) {
    use cpm_calib::noise::{measured_minus_predicted, Kind};
    let native = measured_minus_predicted(campaign, cal.sigma_ref_um, &cal.residuals_um);
    if campaign.pose_measurements.is_empty()
        && campaign.point_measurements.is_empty()
        && campaign.tilt_measurements.is_empty()
        && campaign.instrument_measurements.is_empty()
    {
        // Gauge readings alone (10^6 of them on the hot path): all in um, no kind to look up.
        let n = native.len();
        return (native, vec![0; n], vec!["um".to_string()]);
    }
    let mut units: Vec<String> = Vec::new();
    let mut by_kind: std::collections::BTreeMap<Kind, u8> = std::collections::BTreeMap::new();
    let codes = campaign
        .observation_kinds()
        .into_iter()
        .map(|k| {
            let kind = Kind::of(campaign, k);
            *by_kind.entry(kind).or_insert_with(|| {
                let unit = kind.unit(model);
                match units.iter().position(|u| *u == unit) {
                    Some(i) => i as u8,
                    None => {
                        units.push(unit);
                        (units.len() - 1) as u8
                    }
                }
            })
        })
        .collect();
    (native, codes, units)
}

/// Where each observation of a fit came from (file, line, what), told when asked: a list
/// of them for 10^5 readings would take longer to build than the rest of the results.
#[pyclass(name = "ObservationOrigins", module = "cpm._cpm", frozen)]
pub struct Origins {
    count: usize,
    robot: cpm_io::Robot,
    merged: std::sync::Arc<cpm_io::Merged>,
}

#[pymethods]
impl Origins {
    fn __len__(&self) -> usize {
        self.count
    }
    /// Observation `k`'s file, line and what it is (`None` when not known); negative `k`
    /// counts from the end.
    fn __getitem__(&self, k: isize) -> PyResult<Option<(String, usize, String)>> {
        let n = self.count as isize;
        let i = if k < 0 { k + n } else { k };
        if i < 0 || i >= n {
            return Err(pyo3::exceptions::PyIndexError::new_err(
                "observation index out of range",
            ));
        }
        Ok(
            cpm_workflow::fit::observation_origin(&self.robot, &self.merged, i as usize)
                .map(|o| (o.file, o.line, o.what)),
        )
    }
}

fn opt_array<'py>(py: Python<'py>, v: &[Option<f64>]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_iter(py, v.iter().map(|x| x.unwrap_or(f64::NAN)))
}

/// The fit as a dict for the Python layer.
fn fit_dict(py: Python<'_>, fit: Fit) -> PyResult<Bound<'_, PyDict>> {
    let cal = &fit.cal;
    let id = &cal.identifiability;
    let d = PyDict::new(py);
    let np = id.num_params;
    d.set_item("parameter_names", fit.names)?;
    d.set_item("estimates_um", opt_array(py, &cal.estimate_um))?;
    d.set_item("std_um", opt_array(py, &cal.std_um))?;
    d.set_item(
        "minimum_norm_um",
        PyArray1::from_slice(py, &cal.minimum_norm_um),
    )?;
    // The Cramér-Rao covariance the standard deviations come from:
    // sigma^2 V_r S_r^-2 V_r^T over the identifiable subspace (um^2); its diagonal is
    // std_um^2 for the determined parameters. Rows and columns of parameters the data do
    // not determine on their own are NaN (their variance is not defined).
    let mut cov = vec![vec![0.0; np]; np];
    for (i, row) in cov.iter_mut().enumerate() {
        for (j, c) in row.iter_mut().enumerate() {
            *c = if id.determined[i] && id.determined[j] {
                (0..id.rank)
                    .map(|k| id.v[(i, k)] * id.v[(j, k)] / (id.singular_values[k].powi(2)))
                    .sum::<f64>()
                    * cal.sigma_um.powi(2)
            } else {
                f64::NAN
            };
        }
    }
    d.set_item(
        "covariance",
        if np == 0 {
            PyArray2::zeros(py, [0, 0], false)
        } else {
            PyArray2::from_vec2(py, &cov).map_err(|e| crate::errors::internal(py, e.to_string()))?
        },
    )?;
    d.set_item("determined", id.determined.clone())?;
    d.set_item("rank", id.rank)?;
    d.set_item("num_params", np)?;
    d.set_item("rank_rtol", id.rank_rtol)?;
    d.set_item(
        "singular_values",
        PyArray1::from_slice(py, &id.singular_values),
    )?;
    d.set_item(
        "blind_directions",
        id.blind_directions
            .iter()
            .map(|b| (b.description.clone(), b.dimensions))
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "unexplained_null_dimensions",
        id.unexplained_null_dimensions,
    )?;
    d.set_item("identifiability_summary", id.summary())?;
    // A residual that mixes kinds weighed differently has no one unit: its figures in um
    // are None (as calibration.json's null), the weighted ones in sigma. The fit's residuals
    // (predicted minus measured, um) likewise; every observation's in its own unit always,
    // as residuals.csv.
    let um = |x: f64| (!fit.weighted).then_some(x);
    d.set_item(
        "residuals_um",
        (!fit.weighted).then(|| PyArray1::from_slice(py, &cal.residuals_um)),
    )?;
    let (native, codes, units) = fit.native;
    d.set_item("residuals", PyArray1::from_vec(py, native))?;
    d.set_item("residual_unit_codes", PyArray1::from_vec(py, codes))?;
    d.set_item("residual_unit_names", units)?;
    d.set_item("observation_origin", Bound::new(py, fit.origins)?)?;
    d.set_item("outliers", cal.outliers.clone())?;
    d.set_item("sigma_um", um(cal.sigma_um))?;
    d.set_item("sigma_estimated", cal.sigma_estimated)?;
    d.set_item("residual_rms_um", um(cal.residual_rms_um))?;
    d.set_item("initial_rms_um", um(cal.initial_rms_um))?;
    d.set_item("residual_weighted", fit.weighted)?;
    d.set_item("weighted_rms_in_sigma", fit.weighted_rms_in_sigma.0)?;
    d.set_item("initial_weighted_rms_in_sigma", fit.weighted_rms_in_sigma.1)?;
    d.set_item("simulated", cal.simulated)?;
    d.set_item("converged", cal.solver.was_successful())?;
    d.set_item("termination", cal.solver.termination.to_string())?;
    d.set_item("solver", cal.solver.brief())?;
    d.set_item("iterations", cal.solver.num_iterations())?;
    d.set_item("downweighted_share", cal.downweighted_share)?;
    d.set_item("robust_failed", cal.robust_failed)?;
    d.set_item("warnings", fit.warnings)?;
    d.set_item("trouble", fit.trouble)?;
    d.set_item("warned", fit.warned)?;
    let files = PyDict::new(py);
    for (name, bytes) in fit.files {
        files.set_item(name, pyo3::types::PyBytes::new(py, &bytes))?;
    }
    d.set_item("files", files)?;
    d.set_item("written", fit.written)?;
    d.set_item(
        "timings",
        fit.timings.into_iter().collect::<HashMap<_, _>>(),
    )?;
    Ok(d)
}

/// Renders Markdown as the self-contained HTML page of `report.html`
/// ([`cpm_workflow::report::html::render`]),
/// inlining the SVG figures of `svgs` (image name -> SVG text).
#[pyfunction]
pub fn render_html(
    title: &str,
    markdown: &str,
    svgs: std::collections::HashMap<String, String>,
) -> String {
    cpm_workflow::report::html::render(title, markdown, |name| svgs.get(name).cloned())
}

/// The progress of a job run for Python: keeps the job's warnings (the command's
/// `warning:` lines, which Python raises as `cpm.CpmWarning`), shows nothing else; Ctrl-C
/// (the caller gone) cancels, inside the fit's iterations too.
pub struct Cancel {
    flag: std::sync::Arc<std::sync::atomic::AtomicBool>,
    warned: std::sync::Mutex<Vec<String>>,
}

impl Cancel {
    /// A progress cancelled by `flag`.
    pub fn new(flag: std::sync::Arc<std::sync::atomic::AtomicBool>) -> Cancel {
        Cancel {
            flag,
            warned: std::sync::Mutex::new(Vec::new()),
        }
    }

    /// The warnings the job gave, in order.
    pub fn warned(&self) -> Vec<String> {
        self.warned.lock().map(|w| w.clone()).unwrap_or_default()
    }
}

impl cpm_workflow::Progress for Cancel {
    fn warn(&self, message: &str) {
        if let Ok(mut w) = self.warned.lock() {
            w.push(message.to_string());
        }
    }
    fn cancel_flag(&self) -> Option<std::sync::Arc<std::sync::atomic::AtomicBool>> {
        Some(self.flag.clone())
    }
}

/// `text` (a `calibrated.toml`) with `[calibration] calibrated_from`, recorded relative to
/// the folder `here` (or absolute, or relative to the working directory, when `here` is
/// `None`), recorded for the folder `there` as `cpm calibrate --out there` records it
/// ([`cpm_workflow::load::calibrated_from`]), or absolute when `there` is `None` (outputs
/// held in memory: their staging folder is gone). The rest of the text is kept as it is;
/// a text that records no origin is returned as it is.
pub fn recorded_for(text: &str, here: Option<&Path>, there: Option<&Path>) -> String {
    let Some(recorded) = text.parse::<toml::Table>().ok().and_then(|t| {
        match t.get("calibration")?.get("calibrated_from")? {
            toml::Value::String(s) => Some(s.clone()),
            _ => None,
        }
    }) else {
        return text.to_string();
    };
    let from = match here {
        Some(h) => h.join(&recorded),
        None => PathBuf::from(&recorded),
    };
    // Through `..` by name (the staging folder may be gone), then the file itself.
    let mut from = from.components().fold(PathBuf::new(), |mut p, c| {
        match c {
            std::path::Component::ParentDir if p.file_name().is_some() => {
                p.pop();
            }
            std::path::Component::CurDir => {}
            c => p.push(c),
        }
        p
    });
    if let Ok(c) = std::fs::canonicalize(&from) {
        from = c;
    }
    let new = match there {
        Some(d) => cpm_workflow::load::calibrated_from(&from, d),
        None => std::path::absolute(&from)
            .unwrap_or(from)
            .display()
            .to_string(),
    };
    let mut table = "";
    let mut out = String::with_capacity(text.len() + new.len());
    for line in text.split_inclusive('\n') {
        let t = line.trim();
        if t.starts_with('[') {
            table = t;
        }
        let key = t
            .strip_prefix("calibrated_from")
            .is_some_and(|rest| rest.trim_start().starts_with('='));
        if table == "[calibration]" && key {
            let end = if line.ends_with("\r\n") {
                "\r\n"
            } else if line.ends_with('\n') {
                "\n"
            } else {
                ""
            };
            out.push_str(&format!(
                "calibrated_from = {}{end}",
                toml::Value::String(new.clone())
            ));
        } else {
            out.push_str(line);
        }
    }
    out
}

/// [`recorded_for`] for Python (`CalibrationResult.save`): `calibrated.toml`'s text with its
/// origin recorded from `here` re-recorded for the folder `there`.
#[pyfunction]
#[pyo3(signature = (text, here, there))]
pub fn calibrated_from_at(text: &str, here: Option<PathBuf>, there: Option<PathBuf>) -> String {
    recorded_for(text, here.as_deref(), there.as_deref())
}

/// Staged outputs (nothing written) as they are handed to Python: `calibrated.toml` records
/// its origin absolute, since the staging name `dir` it was recorded from is no folder
/// ([`staging_name`]).
pub fn unstaged(files: &mut [(String, Vec<u8>)], dir: &Path) {
    for (name, bytes) in files.iter_mut() {
        if name == "calibrated.toml" {
            if let Ok(text) = std::str::from_utf8(bytes) {
                *bytes = recorded_for(text, Some(dir), None).into_bytes();
            }
        }
    }
}

/// Where outputs that are only staged are named, never made: a path in the system's
/// temporary directory that no directory takes (their names, and `calibrated.toml`'s
/// `calibrated_from` before [`unstaged`] makes it absolute, are relative to it). Nothing is
/// created there: a job without `out` writes nothing anywhere.
pub fn staging_name(what: &str) -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static COUNT: AtomicUsize = AtomicUsize::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    std::env::temp_dir().join(format!(
        "cpm-py-{}-{}-{nanos}-{what}",
        std::process::id(),
        COUNT.fetch_add(1, Ordering::Relaxed)
    ))
}

/// The measurements for a job on `robot`: read ones as read ([`crate::data::PyData`]),
/// paths as files.
pub fn sources_of(
    robot: &crate::robot::PyRobot,
    data: &[Bound<'_, PyAny>],
) -> PyResult<Vec<cpm_workflow::memory::Source>> {
    data.iter()
        .map(|d| match d.downcast::<crate::data::PyData>() {
            Ok(h) => Ok(h.get().source(robot)),
            Err(_) => Ok(cpm_workflow::memory::Source::Path(d.extract()?)),
        })
        .collect()
}

/// `cpm calibrate` on a campaign in memory ([`cpm_workflow::memory::calibrate`]): `robot`
/// as loaded, `data` paths (read as `--data` reads them) or measurements read by
/// [`crate::data`] (taken as read), `options` the command's by name (JSON text, [`by_name`]).
/// With `out` and `commit` the outputs are written there as the command writes them (all or
/// nothing), otherwise only staged. Returns the fit as a dict (numbers as numpy arrays,
/// `files`: name -> bytes of every output, `warnings`, `trouble`, `timings`).
#[pyfunction]
#[pyo3(signature = (robot, data, options, out=None, commit=false))]
pub fn calibrate_memory<'py>(
    py: Python<'py>,
    robot: &crate::robot::PyRobot,
    data: Vec<Bound<'py, PyAny>>,
    options: &str,
    out: Option<PathBuf>,
    commit: bool,
) -> PyResult<Bound<'py, PyDict>> {
    use cpm_workflow::memory::{calibrate as calibrate_in_memory, Source};
    if data.is_empty() {
        return Err(crate::errors::usage(py, "data: no measurements"));
    }
    let sources = sources_of(robot, &data)?;
    let dir = match &out {
        Some(d) => d.clone(),
        None => staging_name("cal"),
    };
    let defaults = cpm_workflow::fit::CalibrateOptions::new(PathBuf::new(), Vec::new(), &dir);
    let mut options = by_name(py, "calibrate", &defaults, options)?;
    // The robot and the data are given as objects; the output directory is `out`.
    options.fit.out = dir.clone();
    let bot = robot.robot.clone();
    let robot_path = robot.path.clone();
    let out_given = out.clone();
    let r = crate::blocking::run(py, move |abandoned| -> anyhow::Result<Fit> {
        let progress = Cancel::new(abandoned.clone());
        let t0 = std::time::Instant::now();
        let job = calibrate_in_memory(&options, bot, &sources, &progress)?;
        let fitted_s = t0.elapsed().as_secs_f64();
        let cpm_workflow::fit::Calibrated { inputs, fitted } = job;
        let stages = fitted.seconds;
        let warnings = fitted.report.fit.warnings.clone();
        let weighted = fitted.report.fit.residual_weighted;
        let weighted_rms_in_sigma = (
            fitted.report.fit.weighted_rms_in_sigma,
            fitted.report.fit.initial_weighted_rms_in_sigma,
        );
        let cal = fitted.cal;
        let native = native_residuals(&inputs.model, &inputs.merged.campaign, &cal);
        let trouble = if let Some(why) = cal.robust_failure() {
            Some(format!("the fit failed: {why}"))
        } else if !cal.solver.was_successful() {
            Some(format!(
                "the solver did not converge ({})",
                cal.solver.termination
            ))
        } else {
            None
        };
        let name_of = |p: &Path| p.strip_prefix(&dir).unwrap_or(p).display().to_string();
        // Staged only: the bytes moved out of the set, not copied (streamed ones made now).
        let (mut files, set): (Vec<(String, Vec<u8>)>, _) = if commit {
            let files = fitted
                .set
                .paths()
                .filter_map(|p| fitted.set.bytes(p).map(|b| (name_of(p), b.into_owned())))
                .collect();
            (files, Some(fitted.set))
        } else {
            let files = fitted
                .set
                .into_files()
                .into_iter()
                .map(|(p, contents)| {
                    let bytes = match contents {
                        cpm_io::write::Contents::Bytes(b) => b,
                        streamed => streamed.bytes().into_owned(),
                    };
                    (name_of(&p), bytes)
                })
                .collect();
            (files, None)
        };
        if abandoned.load(std::sync::atomic::Ordering::SeqCst) {
            anyhow::bail!("interrupted");
        }
        if out_given.is_none() {
            unstaged(&mut files, &dir);
        }
        let written = if let Some(set) = set {
            let inputs_paths: Vec<&Path> = robot_path
                .iter()
                .map(|p| p.as_path())
                .chain(sources.iter().filter_map(|s| match s {
                    Source::Path(p) => Some(p.as_path()),
                    _ => None,
                }))
                .collect();
            cpm_workflow::load::commit_dir(
                set,
                &dir,
                &inputs_paths,
                "calibrate",
                &cpm_workflow::Silent,
            )?
            .iter()
            .map(|p| p.display().to_string())
            .collect()
        } else {
            Vec::new()
        };
        let origins = Origins {
            count: cal.residuals_um.len(),
            robot: inputs.robot,
            merged: inputs.merged,
        };
        let timings = vec![
            ("job".to_string(), fitted_s),
            ("fit".to_string(), stages.fit_s),
            ("outputs".to_string(), stages.outputs_s),
            ("solver".to_string(), cal.solver.elapsed.as_secs_f64()),
            ("total".to_string(), t0.elapsed().as_secs_f64()),
        ];
        Ok(Fit {
            names: inputs.model.parameter_names(),
            cal,
            warnings,
            trouble,
            files,
            written,
            origins,
            timings,
            warned: progress.warned(),
            weighted,
            weighted_rms_in_sigma,
            native,
        })
    })?;
    fit_dict(py, r.map_err(|e| crate::errors::to_py(py, &e))?)
}
