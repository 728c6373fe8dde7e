//! `cpm._cpm`: the Python extension module of cpm (PyO3, abi3, rust-numpy), built by maturin
//! from `python/pyproject.toml`.
//!
//! The binding is thin: it converts and calls. The commands are the workflow's jobs
//! ([`cpm_workflow`]), as the `cpm` command runs them, with their options by name
//! ([`commands::by_name`]: the command's options, names and defaults, without the
//! command-line parser): `calibrate` on a campaign in memory ([`commands::calibrate_memory`]),
//! the others through [`jobs::job`]. The solver is `cpm-lm` itself ([`lm`]). The pure-Python
//! layer (`python/cpm/`) gathers the options from keyword arguments and wraps the results.
//! The `cpm` command itself comes with the `cli` feature (`cli::main`), which the wheel
//! turns on for its `cpm` script; without it the crate does not depend on clap.
//!
//! Errors become the exceptions of `cpm.errors` ([`errors`]); no panic crosses into Python
//! (work runs on a worker thread that catches panics, [`blocking`]).
// PyO3's macros (`#[pymodule]`, `#[pyfunction]`, `#[pyclass]`) expand to `unsafe` FFI code;
// the workspace denies unsafe code, and this crate, the only FFI boundary, allows what the
// macros generate. Its own code has no `unsafe` block.
#![allow(unsafe_code)]

use pyo3::prelude::*;

pub mod blocking;
#[cfg(feature = "cli")]
pub mod cli;
pub mod commands;
pub mod data;
pub mod errors;
pub mod jobs;
pub mod lm;
pub mod robot;

/// The module `cpm._cpm`.
#[pymodule]
fn _cpm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<robot::PyRobot>()?;
    m.add_class::<data::PyData>()?;
    m.add_class::<commands::Origins>()?;
    m.add_function(wrap_pyfunction!(robot::robot_load, m)?)?;
    m.add_function(wrap_pyfunction!(robot::robot_from_text, m)?)?;
    m.add_function(wrap_pyfunction!(data::read_file, m)?)?;
    m.add_function(wrap_pyfunction!(data::read_text, m)?)?;
    m.add_function(wrap_pyfunction!(data::gauge_rows, m)?)?;
    m.add_function(wrap_pyfunction!(data::tracker_rows, m)?)?;
    #[cfg(feature = "cli")]
    m.add_function(wrap_pyfunction!(cli::main, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::job, m)?)?;
    m.add_function(wrap_pyfunction!(commands::calibrate_memory, m)?)?;
    m.add_function(wrap_pyfunction!(commands::effect_names, m)?)?;
    m.add_function(wrap_pyfunction!(commands::calibrated_from_at, m)?)?;
    m.add_function(wrap_pyfunction!(commands::render_html, m)?)?;
    m.add_function(wrap_pyfunction!(lm::least_squares, m)?)?;
    Ok(())
}
