//! The `cpm` command inside the extension (feature `cli`): the `cpm` script a `pip install`
//! puts on the PATH runs it, so the command comes with the wheel, without a Rust toolchain.
use pyo3::prelude::*;

/// The `cpm` command itself: runs `argv` (the program name first) exactly as the binary
/// does, printing to the process's standard output and error, and returns the exit code
/// (`cpm._main`).
#[pyfunction]
pub fn main(py: Python<'_>, argv: Vec<String>) -> i32 {
    cpm::cli::record_stdout_at_start();
    py.allow_threads(move || cpm::cli::run(argv))
}
