//! `cpm._cpm`: the Python extension module of cpm (PyO3, abi3, rust-numpy), built by maturin
//! from `python/pyproject.toml`.
//!
//! The binding is thin: it converts and calls. The commands run the very functions of the
//! `cpm` command (`cpm::cli`): their arguments are parsed from an argument vector by the
//! command's own parser (so the options, their names, defaults and usage errors are the
//! command's), the fit of `calibrate` is [`cpm::cli::calibrate::fit_with`] and its outputs
//! (`calibration.json`, `report.md`, `report.html`, `calibrated.toml`, figures) are the staged
//! files of the command. The solver is `cpm-lm` itself ([`lm`]). The pure-Python layer
//! (`python/cpm/`) builds the argument vectors from keyword arguments and wraps the results.
//!
//! Errors become the exceptions of `cpm.errors` ([`errors`]); no panic crosses into Python
//! (work runs on a worker thread that catches panics, [`blocking`]).
// PyO3's macros (`#[pymodule]`, `#[pyfunction]`, `#[pyclass]`) expand to `unsafe` FFI code;
// the workspace denies unsafe code, and this crate, the only FFI boundary, allows what the
// macros generate. Its own code has no `unsafe` block.
#![allow(unsafe_code)]

use pyo3::prelude::*;

pub mod blocking;
pub mod commands;
pub mod data;
pub mod errors;
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
    m.add_function(wrap_pyfunction!(data::tracker_csv, m)?)?;
    m.add_function(wrap_pyfunction!(commands::run_command, m)?)?;
    m.add_function(wrap_pyfunction!(commands::main, m)?)?;
    m.add_function(wrap_pyfunction!(commands::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(commands::calibrate_memory, m)?)?;
    m.add_function(wrap_pyfunction!(commands::effect_names, m)?)?;
    m.add_function(wrap_pyfunction!(commands::render_html, m)?)?;
    m.add_function(wrap_pyfunction!(lm::least_squares, m)?)?;
    Ok(())
}
