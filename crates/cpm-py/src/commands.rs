//! The commands of `cpm` for Python.
//!
//! Every command's arguments are parsed from an argument vector by the command's own parser
//! ([`cpm::cli::Cli`]): the Python layer turns keyword arguments into `--option value`, so the
//! options, their defaults and their usage errors are exactly the command's, and an option
//! added to the command is there in Python too.
//!
//! [`run_command`] runs any command as `cpm` does (its outputs go where `--out` says; the
//! Python layer gives a scratch directory when the caller gave none and reads them back).
//! [`calibrate`] runs the fit of `cpm calibrate` ([`cpm::cli::calibrate::FitArgs::load`] and
//! [`cpm::cli::calibrate::fit_with`]) and also hands back the calibration itself: estimates,
//! standard deviations, the Cramér-Rao covariance, identifiability, residuals, and every staged
//! output file (`calibration.json`, `report.md`, `report.html`, `calibrated.toml`, figures).
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use clap::Parser;
use cpm::cli::{self, calibrate as cal_cli, common, Cli, Command, Ctx, Outcome};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Parses an argument vector (without the program name) with the command's parser.
fn parse(py: Python<'_>, argv: &[String]) -> PyResult<Cli> {
    let args = std::iter::once("cpm".to_string()).chain(argv.iter().cloned());
    Cli::try_parse_from(args).map_err(|e| {
        let text = e.render().to_string();
        crate::errors::usage(py, text.trim_end().trim_start_matches("error: "))
    })
}

/// What a command gave back: what it printed, and its trouble (exit code 1 with outputs
/// written) if any.
type Ran = (String, Option<String>);

/// Runs a `cpm` command given as an argument vector (`["simulate", "--robot", ...]`),
/// exactly as the command line does, with the GIL released. Returns what it printed on
/// standard output and, when it finished but reports trouble (the command's exit code 1, its
/// outputs written), the message. `--quiet` is implied (no progress display, no notes).
#[pyfunction]
pub fn run_command(py: Python<'_>, argv: Vec<String>) -> PyResult<Ran> {
    let cli = parse(py, &argv)?;
    let r = crate::blocking::run(py, move |_| -> anyhow::Result<Ran> {
        let mut out: Vec<u8> = Vec::new();
        let outcome = {
            let mut ctx = Ctx::new(&mut out, true);
            let r = cli::execute(&cli, &mut ctx);
            ctx.finish();
            r
        }?;
        let text = String::from_utf8_lossy(&out).to_string();
        Ok(match outcome {
            Outcome::Done => (text, None),
            Outcome::Trouble(m) => (text, Some(m)),
        })
    })?;
    r.map_err(|e| crate::errors::to_py(py, &e))
}

/// The `cpm` command itself: runs `argv` (the program name first) exactly as the binary
/// does, printing to the process's standard output and error, and returns the exit code. The
/// `cpm` script a `pip install` puts on the PATH calls it (`cpm._main`), so the command comes
/// with the wheel, without a Rust toolchain.
#[pyfunction]
pub fn main(py: Python<'_>, argv: Vec<String>) -> i32 {
    cli::record_stdout_at_start();
    py.allow_threads(move || cli::run(argv))
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
            cal_cli::observation_origin(&self.robot, &self.merged, i as usize)
                .map(|o| (o.file, o.line, o.what)),
        )
    }
}

/// Puts back the names that scratch files stand for (measurements made from arrays, a robot
/// made from text) wherever the inputs name their files, so that the outputs say
/// `tracker measurements`, not a temporary path.
fn rename(inputs: &mut cal_cli::Inputs, names: &HashMap<String, String>) {
    let name = |f: &mut String| {
        if let Some(n) = names.get(f.as_str()) {
            *f = n.clone();
        }
    };
    name(&mut inputs.provenance.robot);
    name(&mut inputs.robot.file);
    inputs.provenance.data.iter_mut().for_each(name);
    let m = std::sync::Arc::make_mut(&mut inputs.merged);
    m.pose_origin.iter_mut().for_each(|o| name(&mut o.0));
    for o in m.reading_origin.iter_mut() {
        if let Some(n) = names.get(&*o.0) {
            o.0 = n.as_str().into();
        }
    }
    if let Some(r) = m.registration.as_mut() {
        r.sessions.iter_mut().for_each(|s| name(&mut s.file));
    }
}

/// Runs `cpm calibrate` from an argument vector (`["calibrate", "--robot", ...]`); when
/// `commit` is true the outputs are written to `--out` as the command writes them (all or
/// nothing), otherwise only staged in memory. `names` maps scratch files to the names they
/// stand for (measurements made from arrays, a robot made from text). Returns a dict: the calibration's numbers as numpy arrays,
/// `files` (name -> bytes of every output), `warnings`, `trouble`.
#[pyfunction]
pub fn calibrate<'py>(
    py: Python<'py>,
    argv: Vec<String>,
    commit: bool,
    names: HashMap<String, String>,
) -> PyResult<Bound<'py, PyDict>> {
    let cli = parse(py, &argv)?;
    let Command::Calibrate(args) = cli.command else {
        return Err(crate::errors::usage(
            py,
            "cpm._cpm.calibrate runs `calibrate` only",
        ));
    };
    let r = crate::blocking::run(py, move |abandoned| -> anyhow::Result<Fit> {
        let mut sink: Vec<u8> = Vec::new();
        let ctx = Ctx::new(&mut sink, true);
        let mut inputs = args.fit.load(&ctx)?;
        rename(&mut inputs, &names);
        // Ctrl-C stops the fit inside its iterations (the flag turns true when Python is
        // interrupted).
        inputs.identify.cancel = Some(abandoned.clone());
        let dir = &args.fit.out;
        let fitted = cal_cli::fit_with(&inputs, dir, args.minimum_norm, args.formulation)?;
        // The warnings of calibration.json (the fit's, the sessions', the noise's).
        let warnings = fitted.report.fit.warnings.clone();
        let cal = fitted.cal;
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
        let files: Vec<(String, Vec<u8>)> = fitted
            .set
            .paths()
            .filter_map(|p| {
                let name = p.strip_prefix(dir).unwrap_or(p).display().to_string();
                fitted.set.bytes(p).map(|b| (name, b.into_owned()))
            })
            .collect();
        // Interrupted (the caller raised KeyboardInterrupt and left): write nothing.
        if abandoned.load(std::sync::atomic::Ordering::SeqCst) {
            anyhow::bail!("interrupted");
        }
        let written = if commit {
            let inputs_paths: Vec<&Path> = std::iter::once(args.fit.robot.robot.as_path())
                .chain(args.fit.data.iter().map(|p| p.as_path()))
                .collect();
            common::commit_dir(fitted.set, dir, &inputs_paths, "calibrate", &ctx)?
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
        let timings = vec![("solver".to_string(), cal.solver.elapsed.as_secs_f64())];
        Ok(Fit {
            names: inputs.model.parameter_names(),
            cal,
            warnings,
            trouble,
            files,
            written,
            origins,
            timings,
        })
    })?;
    let fit = r.map_err(|e| crate::errors::to_py(py, &e))?;
    fit_dict(py, fit)
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
    d.set_item("residuals_um", PyArray1::from_slice(py, &cal.residuals_um))?;
    d.set_item("observation_origin", Bound::new(py, fit.origins)?)?;
    d.set_item("outliers", cal.outliers.clone())?;
    d.set_item("sigma_um", cal.sigma_um)?;
    d.set_item("sigma_estimated", cal.sigma_estimated)?;
    d.set_item("residual_rms_um", cal.residual_rms_um)?;
    d.set_item("initial_rms_um", cal.initial_rms_um)?;
    d.set_item("simulated", cal.simulated)?;
    d.set_item("converged", cal.solver.was_successful())?;
    d.set_item("termination", cal.solver.termination.to_string())?;
    d.set_item("solver", cal.solver.brief())?;
    d.set_item("iterations", cal.solver.num_iterations())?;
    d.set_item("downweighted_share", cal.downweighted_share)?;
    d.set_item("robust_failed", cal.robust_failed)?;
    d.set_item("warnings", fit.warnings)?;
    d.set_item("trouble", fit.trouble)?;
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

/// Renders Markdown as the self-contained HTML page of `report.html` ([`cpm::report::html::render`]),
/// inlining the SVG figures of `svgs` (image name -> SVG text).
#[pyfunction]
pub fn render_html(
    title: &str,
    markdown: &str,
    svgs: std::collections::HashMap<String, String>,
) -> String {
    cpm::report::html::render(title, markdown, |name| svgs.get(name).cloned())
}

/// The progress of a job run for Python: shows nothing; Ctrl-C (the caller gone) cancels,
/// inside the fit's iterations too.
struct Cancel(std::sync::Arc<std::sync::atomic::AtomicBool>);

impl cpm_workflow::Progress for Cancel {
    fn cancel_flag(&self) -> Option<std::sync::Arc<std::sync::atomic::AtomicBool>> {
        Some(self.0.clone())
    }
}

/// A value of an option given by name (`--name`), or a usage error naming the option.
fn option<'py, T: FromPyObject<'py>>(
    py: Python<'py>,
    options: &Bound<'py, PyDict>,
    key: &str,
) -> PyResult<Option<T>> {
    match options.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => v.extract().map(Some).map_err(|e| {
            crate::errors::usage(
                py,
                format!("invalid value for '--{}': {e}", key.replace('_', "-")),
            )
        }),
    }
}

/// One of `values` for the option `key` (a usage error listing them otherwise).
fn choice<T: Copy>(
    py: Python<'_>,
    options: &Bound<'_, PyDict>,
    key: &str,
    values: &[(&str, T)],
    default: T,
) -> PyResult<T> {
    let Some(v) = option::<String>(py, options, key)? else {
        return Ok(default);
    };
    values
        .iter()
        .find(|(name, _)| *name == v)
        .map(|(_, t)| *t)
        .ok_or_else(|| {
            let names: Vec<&str> = values.iter().map(|(n, _)| *n).collect();
            crate::errors::usage(
                py,
                format!(
                    "invalid value '{v}' for '--{}'\n  [possible values: {}]",
                    key.replace('_', "-"),
                    names.join(", ")
                ),
            )
        })
}

/// The options of `cpm calibrate` from a dict of the command's options by name (`sigma_um`
/// for `--sigma-um`; values already of their types), for the output directory `out`.
fn calibrate_options(
    py: Python<'_>,
    options: &Bound<'_, PyDict>,
    out: PathBuf,
) -> PyResult<cpm_workflow::fit::CalibrateOptions> {
    use cpm_workflow::fit::{NoisePerKind, TrackerResiduals};
    use cpm_workflow::formulation::FormulationArg;
    let known = [
        "effects",
        "sigma_um",
        "pose_sigma_um",
        "orientation_sigma_urad",
        "robust",
        "keep_outliers",
        "max_iterations",
        "noise_per_kind",
        "tolerance",
        "hold",
        "no_prior",
        "tolerance_limit",
        "tracker_residuals",
        "minimum_norm",
        "formulation",
        "json",
        "quiet",
    ];
    for key in options.keys() {
        let key: String = key.extract()?;
        if !known.contains(&key.as_str()) {
            return Err(crate::errors::usage(
                py,
                format!("unexpected argument '--{}' found", key.replace('_', "-")),
            ));
        }
    }
    let flag =
        |key: &str| -> PyResult<bool> { Ok(option::<bool>(py, options, key)?.unwrap_or(false)) };
    let mut o = cpm_workflow::fit::CalibrateOptions::new(PathBuf::new(), Vec::new(), out);
    let f = &mut o.fit;
    f.effects = option(py, options, "effects")?;
    f.sigma_um = option(py, options, "sigma_um")?;
    f.pose_sigma_um = option(py, options, "pose_sigma_um")?;
    f.orientation_sigma_urad = option(py, options, "orientation_sigma_urad")?;
    f.robust = option(py, options, "robust")?;
    f.keep_outliers = flag("keep_outliers")?;
    f.max_iterations = option(py, options, "max_iterations")?;
    f.noise_per_kind = choice(
        py,
        options,
        "noise_per_kind",
        &[
            ("auto", NoisePerKind::Auto),
            ("on", NoisePerKind::On),
            ("off", NoisePerKind::Off),
        ],
        NoisePerKind::Auto,
    )?;
    f.tolerance = option(py, options, "tolerance")?.unwrap_or_default();
    f.hold = option::<Vec<String>>(py, options, "hold")?
        .unwrap_or_default()
        .iter()
        .flat_map(|h| h.split(',').map(str::to_string))
        .collect();
    f.no_prior = flag("no_prior")?;
    f.tolerance_limit = option(py, options, "tolerance_limit")?;
    f.tracker_residuals = choice(
        py,
        options,
        "tracker_residuals",
        &[
            ("auto", TrackerResiduals::Auto),
            ("pose", TrackerResiduals::Pose),
            ("legs", TrackerResiduals::Legs),
        ],
        TrackerResiduals::Auto,
    )?;
    o.minimum_norm = flag("minimum_norm")?;
    o.formulation = choice(
        py,
        options,
        "formulation",
        &[
            ("auto", FormulationArg::Auto),
            ("nested", FormulationArg::Nested),
            ("implicit", FormulationArg::Implicit),
        ],
        FormulationArg::Auto,
    )?;
    Ok(o)
}

/// A directory for outputs that are only staged: its name is in `calibrated.toml` (where the
/// robot lies relative to it), as a scratch directory's was. Made empty, removed after.
struct Unwritten(PathBuf);

impl Unwritten {
    fn new() -> std::io::Result<Unwritten> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static COUNT: AtomicUsize = AtomicUsize::new(0);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let dir = std::env::temp_dir().join(format!(
            "cpm-py-{}-{}-{nanos}",
            std::process::id(),
            COUNT.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir(&dir)?;
        Ok(Unwritten(dir))
    }
}

impl Drop for Unwritten {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir(&self.0);
    }
}

/// `cpm calibrate` on a campaign in memory ([`cpm_workflow::memory::calibrate`]): `robot`
/// as loaded, `data` paths (read as `--data` reads them) or measurements read by
/// [`crate::data::read_text`] (taken as read), `options` the command's by name with values
/// of their types. With `out` and `commit` the outputs are written there as the command
/// writes them (all or nothing), otherwise only staged. Returns the dict of [`calibrate`], or
/// `None` when the campaign must be read from files (two or more tracker sets, some in
/// memory: [`cpm_workflow::memory::NeedsFiles`]).
#[pyfunction]
#[pyo3(signature = (robot, data, options, out=None, commit=false))]
pub fn calibrate_memory<'py>(
    py: Python<'py>,
    robot: &crate::robot::PyRobot,
    data: Vec<Bound<'py, PyAny>>,
    options: &Bound<'py, PyDict>,
    out: Option<PathBuf>,
    commit: bool,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    use cpm_workflow::memory::{calibrate as calibrate_in_memory, NeedsFiles, Source};
    if data.is_empty() {
        return Err(crate::errors::usage(py, "data: no measurements"));
    }
    let mut sources = Vec::with_capacity(data.len());
    for d in &data {
        sources.push(match d.downcast::<crate::data::PyData>() {
            Ok(h) => h.get().source(robot),
            Err(_) => Source::Path(d.extract()?),
        });
    }
    let staged = match out {
        Some(_) => None,
        None => Some(Unwritten::new().map_err(|e| {
            crate::errors::to_py(py, &anyhow::Error::new(e).context("a scratch directory"))
        })?),
    };
    let dir = match &staged {
        Some(s) => s.0.join("cal"),
        None => out.clone().unwrap_or_default(),
    };
    let options = calibrate_options(py, options, dir.clone())?;
    let bot = robot.robot.clone();
    let robot_path = robot.path.clone();
    let r = crate::blocking::run(py, move |abandoned| -> anyhow::Result<Option<Fit>> {
        let progress = Cancel(abandoned.clone());
        let t0 = std::time::Instant::now();
        let job = match calibrate_in_memory(&options, bot, &sources, &progress) {
            Err(e) if e.downcast_ref::<NeedsFiles>().is_some() => return Ok(None),
            r => r?,
        };
        let fitted_s = t0.elapsed().as_secs_f64();
        let cpm_workflow::fit::Calibrated { inputs, fitted } = job;
        let stages = fitted.seconds;
        let warnings = fitted.report.fit.warnings.clone();
        let cal = fitted.cal;
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
        let files: Vec<(String, Vec<u8>)> = fitted
            .set
            .paths()
            .filter_map(|p| {
                let name = p.strip_prefix(&dir).unwrap_or(p).display().to_string();
                fitted.set.bytes(p).map(|b| (name, b.into_owned()))
            })
            .collect();
        if abandoned.load(std::sync::atomic::Ordering::SeqCst) {
            anyhow::bail!("interrupted");
        }
        let written = if commit {
            let inputs_paths: Vec<&Path> = robot_path
                .iter()
                .map(|p| p.as_path())
                .chain(sources.iter().filter_map(|s| match s {
                    Source::Path(p) => Some(p.as_path()),
                    _ => None,
                }))
                .collect();
            cpm_workflow::load::commit_dir(
                fitted.set,
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
        Ok(Some(Fit {
            names: inputs.model.parameter_names(),
            cal,
            warnings,
            trouble,
            files,
            written,
            origins,
            timings,
        }))
    })?;
    drop(staged);
    match r.map_err(|e| crate::errors::to_py(py, &e))? {
        Some(fit) => fit_dict(py, fit).map(Some),
        None => Ok(None),
    }
}
