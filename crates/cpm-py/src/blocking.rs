//! Long work off the Python thread: the GIL is released while it runs, Ctrl-C is honoured,
//! and a panic comes back as an exception rather than crossing into Python.
//!
//! The work runs on a worker thread; the calling thread waits for it with the GIL released
//! and checks for signals every 50 ms. On Ctrl-C (or any signal handler that raises) the
//! exception is raised at once and the work is told (the flag it gets turns true): the
//! binding's jobs hand that flag to the workflow as their progress's cancel flag
//! ([`cpm_workflow::Progress::cancel_flag`]; the fit checks it at each evaluation,
//! [`cpm_workflow::calib::IdentifyOptions::cancel`]), stop at the next check, and write
//! nothing; a job that has no check left finishes in the background, its result dropped and
//! its outputs not committed.
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use pyo3::prelude::*;

/// How often the waiting thread looks for signals.
const POLL: Duration = Duration::from_millis(50);

/// Runs `work` on a worker thread with the GIL released; returns its result, raises
/// `KeyboardInterrupt` (or what a signal handler raised) when interrupted, and a
/// `cpm.CpmError` when the work panicked. `work` gets a flag that turns true when the caller
/// was interrupted and no longer waits.
pub fn run<T, F>(py: Python<'_>, work: F) -> PyResult<T>
where
    T: Send + 'static,
    F: FnOnce(Arc<AtomicBool>) -> T + Send + 'static,
{
    let abandoned = Arc::new(AtomicBool::new(false));
    let flag = abandoned.clone();
    let work = move || work(flag);
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("cpm-work".into())
        .spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
            let _ = tx.send(r);
        })
        .map_err(|e| crate::errors::internal(py, format!("cannot start a worker thread: {e}")))?;
    let mut rx = rx;
    loop {
        // The receiver goes to the GIL-free closure and comes back (it is not Sync).
        let (got, back) = py.allow_threads(move || (rx.recv_timeout(POLL), rx));
        rx = back;
        match got {
            Ok(Ok(v)) => return Ok(v),
            Ok(Err(panic)) => {
                let what = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "unknown panic".into());
                return Err(crate::errors::internal(
                    py,
                    format!("internal error in cpm (a bug, please report it): {what}"),
                ));
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if let Err(e) = py.check_signals() {
                    abandoned.store(true, Ordering::SeqCst);
                    return Err(e);
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return Err(crate::errors::internal(
                    py,
                    "internal error in cpm: the worker thread ended without a result",
                ))
            }
        }
    }
}
