//! What a running job tells its caller (the stage it is in, how far it is, notes) and how the
//! caller stops it: the [`Progress`] trait. The command line shows it as a spinner on a
//! terminal and notes on stderr; Python maps Ctrl-C to [`Progress::cancelled`].

/// The channel between a running job and its caller. Every method has a default that does
/// nothing, so an implementation overrides only what it shows.
///
/// A job asks [`cancelled`](Progress::cancelled) between its stages (reading, each fit,
/// staging the outputs, before committing them); when it answers `true` the job returns the
/// typed error [`Cancelled`](crate::Cancelled) and writes nothing. A progress that gives a
/// [`cancel_flag`](Progress::cancel_flag) also stops a fit inside its least-squares
/// iterations (the flag goes to [`IdentifyOptions::cancel`](crate::calib::IdentifyOptions)).
pub trait Progress {
    /// The stage the job is in now ("reading the measurements", "fitting ...").
    fn stage(&self, message: &str) {
        let _ = message;
    }
    /// How much of the current stage is done, 0 to 1, where the job knows it.
    fn fraction(&self, done: f64) {
        let _ = done;
    }
    /// A note for the user (a choice made, a warning); the command line prints it on stderr
    /// as `note: ...` unless `--quiet`.
    fn note(&self, message: &str) {
        let _ = message;
    }
    /// A warning for the user (an input row left out, ...); the command line prints it on
    /// stderr as `warning: ...` unless `--quiet`.
    fn warn(&self, message: &str) {
        let _ = message;
    }
    /// True when the caller wants the job stopped.
    fn cancelled(&self) -> bool {
        self.cancel_flag()
            .is_some_and(|f| f.load(std::sync::atomic::Ordering::Relaxed))
    }
    /// A flag the caller sets to stop the job, read inside the fits' iterations too. Default
    /// `None`: the job asks [`cancelled`](Self::cancelled) between its stages only.
    fn cancel_flag(&self) -> Option<std::sync::Arc<std::sync::atomic::AtomicBool>> {
        None
    }
}

/// Shows nothing and never cancels.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}

/// Collects the notes (and stages) in memory: for callers that show them later (Python
/// returns them as the fit's warnings) and for tests.
#[derive(Debug, Default)]
pub struct Collect {
    /// The notes, in order.
    pub notes: std::sync::Mutex<Vec<String>>,
    /// The stages, in order.
    pub stages: std::sync::Mutex<Vec<String>>,
    /// Set to cancel the job at its next check (inside a fit's iterations too).
    pub cancel: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl Progress for Collect {
    fn stage(&self, message: &str) {
        if let Ok(mut s) = self.stages.lock() {
            s.push(message.to_string());
        }
    }
    fn note(&self, message: &str) {
        if let Ok(mut n) = self.notes.lock() {
            n.push(message.to_string());
        }
    }
    fn warn(&self, message: &str) {
        self.note(&format!("warning: {message}"));
    }
    fn cancel_flag(&self) -> Option<std::sync::Arc<std::sync::atomic::AtomicBool>> {
        Some(self.cancel.clone())
    }
}

/// A job's result told as [`Cancelled`](crate::Cancelled) when it failed because `progress`
/// asked it to stop (a fit stopped inside its iterations fails with the solver's error).
pub fn unless_cancelled<T>(
    result: anyhow::Result<T>,
    progress: &dyn Progress,
) -> anyhow::Result<T> {
    match result {
        Err(_) if progress.cancelled() => Err(crate::error::Cancelled.into()),
        other => other,
    }
}

/// `Err(Cancelled)` when `progress` asks the job to stop: called between stages.
pub fn check_cancelled(progress: &dyn Progress) -> anyhow::Result<()> {
    if progress.cancelled() {
        return Err(crate::error::Cancelled.into());
    }
    Ok(())
}
