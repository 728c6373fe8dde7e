//! The commands other than `calibrate` for Python: each the workflow's job
//! ([`cpm_workflow`]) with its options by name ([`crate::commands::by_name`]), run with the
//! GIL released, Ctrl-C cancelling it ([`crate::commands::Cancel`]).
//!
//! What a job gives back is what the command prints with `--json` (`summary`), the files it
//! stages (`files`: name -> bytes, committed to `out` only when asked, all or nothing, as
//! the command commits them) and the data it writes to a single file (`text`: simulated
//! measurements, compensation commands, the controller's settings). A job interrupted from
//! Python writes nothing.
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use cpm_workflow::memory::{InMemory, Source};
use cpm_workflow::output::OutputSet;
use cpm_workflow::{compensate, design, export, identifiability, load, refine, simulate};
use cpm_workflow::{validate, Progress};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use crate::commands::{by_name, staging_name, Cancel};

/// What a job gave back (plain data, built on the worker thread).
#[derive(Default)]
struct Ran {
    /// What the command prints with `--json` (JSON text), or its line of text.
    summary: String,
    /// The command's trouble (its exit code 1, outputs written), if any.
    trouble: Option<String>,
    /// The staged files by their names in the output directory.
    files: Vec<(String, Vec<u8>)>,
    /// The single-file output (`simulate`, `compensate`, `export`).
    text: Option<String>,
    /// `export`'s INI settings, when asked for.
    ini: Option<String>,
    /// The paths written.
    written: Vec<String>,
    /// The job's warnings (the command's `warning:` lines).
    warned: Vec<String>,
}

/// Where a job stages its outputs: `out` when given (and committed there when asked), else a
/// name in the temporary directory that no directory takes ([`staging_name`]: nothing is
/// made there); true when only staged.
fn out_dir(out: Option<&Path>, name: &str) -> (PathBuf, bool) {
    match out {
        Some(d) => (d.to_path_buf(), false),
        None => (staging_name(name), true),
    }
}

/// The files of a staged set by their names relative to `dir`.
fn files_of(set: &OutputSet, dir: &Path) -> Vec<(String, Vec<u8>)> {
    set.paths()
        .filter_map(|p| {
            let name = p.strip_prefix(dir).unwrap_or(p).display().to_string();
            set.bytes(p).map(|b| (name, b.into_owned()))
        })
        .collect()
}

/// The input files that have a path (a robot held in memory may have none).
fn named_files<'a>(inputs: &[&'a Path]) -> Vec<&'a Path> {
    inputs
        .iter()
        .copied()
        .filter(|p| !p.as_os_str().is_empty())
        .collect()
}

/// Commits `set` to `dir` (all or nothing, as the command does) unless the caller left.
fn commit(
    set: OutputSet,
    dir: &Path,
    inputs: &[&Path],
    command: &str,
    abandoned: &AtomicBool,
) -> anyhow::Result<Vec<String>> {
    if abandoned.load(Ordering::SeqCst) {
        anyhow::bail!("interrupted");
    }
    let inputs = named_files(inputs);
    Ok(
        load::commit_dir(set, dir, &inputs, command, &cpm_workflow::Silent)?
            .iter()
            .map(|p| p.display().to_string())
            .collect(),
    )
}

/// The robot option of a job given the robot in memory: the path of its file when it has one
/// (an output may not replace it), else left empty (the robot is never read from it).
fn given_robot(option: &mut PathBuf, path: &Option<PathBuf>) {
    if let (true, Some(p)) = (option.as_os_str().is_empty(), path) {
        *option = p.clone();
    }
}

/// Writes a single-file output as the command does (never over an input), unless the
/// caller left.
fn write_one(
    path: &Path,
    option: &str,
    inputs: &[&Path],
    text: &str,
    abandoned: &AtomicBool,
) -> anyhow::Result<String> {
    if abandoned.load(Ordering::SeqCst) {
        anyhow::bail!("interrupted");
    }
    let inputs = named_files(inputs);
    load::out_target(option, path, &inputs)?;
    cpm_workflow::output::write_file(path, text.as_bytes())
        .map_err(|e| anyhow::Error::new(e).context(format!("writing {}", path.display())))?;
    Ok(path.display().to_string())
}

/// Runs `cpm COMMAND` as the workflow's job: `options` by name (JSON text; paths for the
/// robot, the data and the other files), `out` where the outputs go (committed there when
/// `commit`, else only staged). The jobs also take the robot as loaded (for their `robot`
/// option), `validate` its reference too (for `reference`), and `refine`, `identifiability`
/// and `validate` the measurements in memory (read, or paths) for their `data`; `simulate`
/// and `identifiability` a plan's poses (`poses`, an array `(n, 6)`: x, y, z mm; roll,
/// pitch, yaw deg; named "poses", row `k` on line `k + 2`) for their `plan`, `compensate`
/// its targets for its `poses`; `simulate` and `validate` (a compensation check) the true
/// machine as loaded (`truth`) for their `truth`.
/// Returns a dict: `summary` (what the command prints with `--json`), `trouble`, `files`
/// (name -> bytes), `text` (the single-file output), `ini`, `written`.
#[pyfunction]
#[pyo3(signature = (command, options, out=None, commit=false, robot=None, data=None, reference=None, poses=None, truth=None))]
#[allow(clippy::too_many_arguments)]
pub fn job<'py>(
    py: Python<'py>,
    command: &str,
    options: &str,
    out: Option<PathBuf>,
    commit: bool,
    robot: Option<&crate::robot::PyRobot>,
    data: Option<Vec<Bound<'py, PyAny>>>,
    reference: Option<&crate::robot::PyRobot>,
    poses: Option<numpy::PyReadonlyArray2<'py, f64>>,
    truth: Option<&crate::robot::PyRobot>,
) -> PyResult<Bound<'py, PyDict>> {
    let commit = commit && out.is_some();
    let mut held = InMemory::none();
    held.truth = truth.map(|r| r.robot.clone());
    if let Some(p) = poses {
        held.poses = Some(Arc::new(crate::data::pose_rows(py, p, "poses")?));
    }
    let reference_path = reference.and_then(|r| r.path.clone());
    held.reference = reference.map(|r| r.robot.clone());
    // Paths of inputs an output may not replace (the robot's file, when it has one).
    let mut robot_path = None;
    if let Some(r) = robot {
        held.robot = Some(r.robot.clone());
        robot_path = r.path.clone();
        if let Some(d) = &data {
            held.data = Some(crate::commands::sources_of(r, d)?);
        }
    }
    let r = match command {
        "validate" => {
            let (dir, _) = out_dir(out.as_deref(), "validation");
            let mut o = by_name(py, command, &validate::ValidateOptions::default(), options)?;
            o.out = Some(dir.clone());
            // The files of robots held in memory, when they have one (an output may not
            // replace them).
            o.robot = o.robot.or(robot_path);
            o.reference = o.reference.or(reference_path);
            run(py, move |a, p| run_validate(&o, held, &dir, commit, a, p))?
        }
        "refine" => {
            let (dir, staged_only) = out_dir(out.as_deref(), "refined");
            let d = refine::RefineOptions::new(PathBuf::new(), Vec::new(), &dir);
            let mut o = by_name(py, command, &d, options)?;
            o.fit.out = dir.clone();
            run(py, move |a, p| {
                run_refine(&o, held, robot_path, &dir, commit, a, p).map(|mut r| {
                    // Staged only: calibrated.toml records its origin absolute (the
                    // staging name it was recorded from is no folder).
                    if staged_only {
                        crate::commands::unstaged(&mut r.files, &dir);
                    }
                    r
                })
            })?
        }
        "design" => {
            let (dir, _) = out_dir(out.as_deref(), "design");
            let d = design::DesignJobOptions::new(PathBuf::new(), &dir);
            let mut o = by_name(py, command, &d, options)?;
            o.out = dir.clone();
            given_robot(&mut o.robot, &robot_path);
            run(py, move |a, p| run_design(&o, held, &dir, commit, a, p))?
        }
        "identifiability" => {
            let d = identifiability::IdentifiabilityOptions::new(PathBuf::new());
            let o = by_name(py, command, &d, options)?;
            run(py, move |_, p| run_identifiability(&o, held, p))?
        }
        "simulate" => {
            let mut o = by_name(
                py,
                command,
                &simulate::SimulateOptions::new(PathBuf::new()),
                options,
            )?;
            o.out = out.clone().filter(|_| commit);
            given_robot(&mut o.robot, &robot_path);
            run(py, move |a, p| run_simulate(&o, held, a, p))?
        }
        "compensate" => {
            let d = compensate::CompensateOptions::new(PathBuf::new(), PathBuf::new());
            let mut o = by_name(py, command, &d, options)?;
            o.out = out.clone().filter(|_| commit);
            given_robot(&mut o.robot, &robot_path);
            run(py, move |a, p| run_compensate(&o, held, a, p))?
        }
        "export" => {
            let mut o = by_name(
                py,
                command,
                &export::ExportOptions::new(PathBuf::new()),
                options,
            )?;
            o.out = out.clone().filter(|_| commit);
            given_robot(&mut o.robot, &robot_path);
            run(py, move |a, p| run_export(&o, held, a, p))?
        }
        other => {
            return Err(crate::errors::usage(
                py,
                format!("cpm has no command `{other}` that runs as a job"),
            ))
        }
    };
    let d = PyDict::new(py);
    d.set_item("summary", r.summary)?;
    d.set_item("trouble", r.trouble)?;
    let files = PyDict::new(py);
    for (name, bytes) in r.files {
        files.set_item(name, PyBytes::new(py, &bytes))?;
    }
    d.set_item("files", files)?;
    d.set_item("text", r.text)?;
    d.set_item("ini", r.ini)?;
    d.set_item("written", r.written)?;
    d.set_item("warned", r.warned)?;
    Ok(d)
}

/// Runs `work` on the worker thread ([`crate::blocking::run`]) with a progress that shows
/// nothing and cancels when the caller leaves.
fn run<F>(py: Python<'_>, work: F) -> PyResult<Ran>
where
    F: FnOnce(&AtomicBool, &dyn Progress) -> anyhow::Result<Ran> + Send + 'static,
{
    let r = crate::blocking::run(py, move |abandoned: Arc<AtomicBool>| {
        let progress = Cancel::new(abandoned.clone());
        work(&abandoned, &progress).map(|mut r| {
            r.warned = progress.warned();
            r
        })
    })?;
    r.map_err(|e| crate::errors::to_py(py, &e))
}

fn run_validate(
    o: &validate::ValidateOptions,
    held: InMemory,
    dir: &Path,
    commit_to_dir: bool,
    abandoned: &AtomicBool,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    o.validate()?;
    let (summary, set) = if o.commands.is_some() {
        let c = validate::check_compensation_in(o, held, progress)?;
        (c.report.to_json()?, c.set)
    } else {
        let v = validate::validate_in(o, held, progress)?;
        (v.report.to_json()?, v.set)
    };
    let mut r = Ran {
        summary,
        ..Ran::default()
    };
    if let Some(set) = set {
        r.files = files_of(&set, dir);
        if commit_to_dir {
            r.written = commit(set, dir, &o.inputs(), "validate", abandoned)?;
        }
    }
    Ok(r)
}

fn run_refine(
    o: &refine::RefineOptions,
    held: InMemory,
    robot_path: Option<PathBuf>,
    dir: &Path,
    commit_to_dir: bool,
    abandoned: &AtomicBool,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    let data_paths: Vec<PathBuf> = match &held.data {
        Some(sources) => sources
            .iter()
            .filter_map(|s| match s {
                Source::Path(p) => Some(p.clone()),
                _ => None,
            })
            .collect(),
        None => o.fit.data.clone(),
    };
    let robot_path = robot_path.or_else(|| held.robot.is_none().then(|| o.fit.robot.clone()));
    let job = refine::refine_in(o, held, progress)?;
    let mut r = Ran {
        trouble: job.trouble(),
        summary: job.report.doc.to_json()?,
        files: files_of(&job.set, dir),
        ..Ran::default()
    };
    if commit_to_dir {
        let inputs: Vec<&Path> = robot_path
            .iter()
            .chain(data_paths.iter())
            .map(PathBuf::as_path)
            .collect();
        r.written = commit(job.set, dir, &inputs, "refine", abandoned)?;
    }
    Ok(r)
}

fn run_design(
    o: &design::DesignJobOptions,
    held: InMemory,
    dir: &Path,
    commit_to_dir: bool,
    abandoned: &AtomicBool,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    let d = design::design_in(o, held, progress)?;
    let mut r = Ran {
        files: files_of(&d.outputs, dir),
        summary: d.json,
        ..Ran::default()
    };
    if commit_to_dir {
        let inputs: Vec<&Path> = d.inputs.iter().map(PathBuf::as_path).collect();
        r.written = commit(d.outputs, dir, &inputs, "design", abandoned)?;
    }
    Ok(r)
}

fn run_identifiability(
    o: &identifiability::IdentifiabilityOptions,
    held: InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    let job = identifiability::identifiability_in(o, held, progress)?;
    // Keys sorted, as every cpm JSON file (and `cpm identifiability --json`).
    let v = serde_json::to_value(&job.doc)?;
    Ok(Ran {
        summary: serde_json::to_string_pretty(&v)?,
        ..Ran::default()
    })
}

fn run_simulate(
    o: &simulate::SimulateOptions,
    held: InMemory,
    abandoned: &AtomicBool,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    let job = simulate::simulate_in(o, held, progress)?;
    let named = o.out.as_deref().unwrap_or(Path::new("simulated.csv"));
    let summary = job.summary(named).to_json();
    one_file(o.out.as_deref(), &o.inputs(), job.text, summary, abandoned)
}

fn run_compensate(
    o: &compensate::CompensateOptions,
    held: InMemory,
    abandoned: &AtomicBool,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    let job = compensate::compensate_in(o, held, progress)?;
    let named = o.out.as_deref().unwrap_or(Path::new("commands.csv"));
    let summary = job.summary(named).to_json();
    one_file(o.out.as_deref(), &o.inputs(), job.csv, summary, abandoned)
}

/// What a job with a single-file output gives: `text` (written to `out` when given) and its
/// `summary`.
fn one_file(
    out: Option<&Path>,
    inputs: &[&Path],
    text: String,
    summary: String,
    abandoned: &AtomicBool,
) -> anyhow::Result<Ran> {
    let written = match out {
        Some(out) => vec![write_one(out, "--out", inputs, &text, abandoned)?],
        None => Vec::new(),
    };
    Ok(Ran {
        summary,
        text: Some(text),
        written,
        ..Ran::default()
    })
}

fn run_export(
    o: &export::ExportOptions,
    held: InMemory,
    abandoned: &AtomicBool,
    progress: &dyn Progress,
) -> anyhow::Result<Ran> {
    let job = export::export_in(o, held, progress)?;
    let inputs = o.inputs();
    let mut r = Ran::default();
    if let (Some(path), Some(ini)) = (&o.ini, &job.ini) {
        r.written
            .push(write_one(path, "--ini", &inputs, ini, abandoned)?);
    }
    if let Some(out) = &o.out {
        r.written
            .push(write_one(out, "--out", &inputs, &job.hal, abandoned)?);
    }
    r.text = Some(job.hal);
    r.ini = job.ini;
    Ok(r)
}
