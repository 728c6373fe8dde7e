//! Rust errors as the Python exceptions of `cpm.errors`: `InputError` (with `file`, `line`,
//! `field`), `UsageError`, `SolverError`, `CpmIOError`, all under `CpmError`.
//!
//! The kind follows the `cpm` command's exit codes ([`cpm_workflow::error::exit_kind`]): 2 usage, 3 bad
//! input file, 4 I/O, 1 (and anything else) the computation. The message is the command's
//! (`file:line: field name: what`, [`cpm_workflow::error::render_error`]).
use cpm_io::{InputError, ReadError};
use cpm_workflow::error::{exit_kind, render_error, ExitKind};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// Raises `cpm.errors.<class>(*args)`.
fn raise<'py, A>(py: Python<'py>, class: &str, args: A) -> PyErr
where
    A: IntoPyObject<'py, Target = PyTuple, Output = Bound<'py, PyTuple>>,
    A::Error: Into<PyErr>,
{
    let made = py
        .import("cpm.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1(args.into_pyobject(py).map_err(Into::into)?));
    match made {
        Ok(e) => PyErr::from_value(e),
        Err(e) => e,
    }
}

/// The first `InputError` in an error's chain (also inside a `ReadError`).
fn input_error(err: &anyhow::Error) -> Option<&InputError> {
    err.chain().find_map(|c| {
        c.downcast_ref::<InputError>()
            .or(match c.downcast_ref::<ReadError>() {
                Some(ReadError::Input(e)) => Some(e),
                _ => None,
            })
    })
}

/// A `cpm.errors.InputError` with where the problem is.
pub fn input(py: Python<'_>, message: String, e: Option<&InputError>) -> PyErr {
    let (file, line, field) = match e {
        Some(e) => (Some(e.file.clone()), e.line, e.field.clone()),
        None => (None, None, None),
    };
    raise(py, "InputError", (message, file, line, field))
}

/// A `cpm.errors.UsageError`.
pub fn usage(py: Python<'_>, message: impl Into<String>) -> PyErr {
    raise(py, "UsageError", (message.into(),))
}

/// A `cpm.errors.SolverError`.
pub fn solver(py: Python<'_>, message: impl Into<String>) -> PyErr {
    raise(py, "SolverError", (message.into(),))
}

/// A `cpm.errors.CpmError` (an internal failure, e.g. a panic caught on the worker).
pub fn internal(py: Python<'_>, message: impl Into<String>) -> PyErr {
    raise(py, "CpmError", (message.into(),))
}

/// Any error of the `cpm` library as the exception its exit code stands for.
pub fn to_py(py: Python<'_>, err: &anyhow::Error) -> PyErr {
    let message = render_error(err);
    match exit_kind(err) {
        ExitKind::Usage => usage(py, message),
        ExitKind::Input => input(py, message, input_error(err)),
        ExitKind::Io => raise(py, "CpmIOError", (message,)),
        ExitKind::Trouble | ExitKind::Success => solver(py, message),
    }
}

/// A reader's error as an exception (`InputError`, or `CpmIOError` when the file could not
/// be read).
pub fn read_to_py(py: Python<'_>, err: ReadError) -> PyErr {
    to_py(py, &anyhow::Error::new(err))
}
