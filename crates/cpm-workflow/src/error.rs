//! Errors of the jobs and the exit code each gives: a job returns `anyhow::Error`s whose
//! chain holds a typed cause ([`JobError`], [`OptionError`], [`Cancelled`], cpm-io's
//! [`ReadError`] and [`InputError`], cpm-calib's [`CalibError`], [`OutputError`], I/O);
//! [`exit_kind`] reads the first cause that says what kind of failure it is.
//!
//! [`ReadError`]: crate::io::ReadError
//! [`InputError`]: crate::io::InputError
//! [`CalibError`]: crate::calib::CalibError
//! [`OutputError`]: crate::output::OutputError
//! [`OptionError`]: crate::options::OptionError

/// Exit codes of `cpm` (`docs/cli.md`), and the kinds of failure of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitKind {
    /// 0: success.
    Success = 0,
    /// 1: the computation failed or reported trouble.
    Trouble = 1,
    /// 2: usage error.
    Usage = 2,
    /// 3: bad input file.
    Input = 3,
    /// 4: I/O error.
    Io = 4,
}

/// An error of a job with its kind (the exit code it gives on the command line).
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct JobError {
    /// Which exit code it gives.
    pub kind: ExitKind,
    /// What went wrong.
    pub message: String,
}

/// The job was cancelled through its [`Progress`](crate::Progress) before it finished;
/// nothing was written (exit code 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("cancelled before it finished; nothing was written")]
pub struct Cancelled;

/// A usage error (exit code 2): options that contradict each other or are out of range.
pub fn usage_error(message: impl Into<String>) -> anyhow::Error {
    JobError {
        kind: ExitKind::Usage,
        message: message.into(),
    }
    .into()
}

/// A bad-input error without a file position (exit code 3).
pub fn input_error(message: impl Into<String>) -> anyhow::Error {
    JobError {
        kind: ExitKind::Input,
        message: message.into(),
    }
    .into()
}

/// A computation error (exit code 1).
pub fn trouble(message: impl Into<String>) -> anyhow::Error {
    JobError {
        kind: ExitKind::Trouble,
        message: message.into(),
    }
    .into()
}

/// The exit code an error gives: the first cause in its chain that says.
pub fn exit_kind(err: &anyhow::Error) -> ExitKind {
    use crate::calib::CalibError;
    use crate::io::{InputError, ReadError};
    for cause in err.chain() {
        if let Some(c) = cause.downcast_ref::<JobError>() {
            return c.kind;
        }
        if cause.is::<crate::options::OptionError>() {
            return ExitKind::Usage;
        }
        if cause.is::<Cancelled>() {
            return ExitKind::Trouble;
        }
        if let Some(o) = cause.downcast_ref::<crate::output::OutputError>() {
            return match o {
                crate::output::OutputError::Refused(_) => ExitKind::Usage,
                crate::output::OutputError::Io { .. } => ExitKind::Io,
            };
        }
        if cause.is::<InputError>() || cause.is::<crate::geometry::GeometryError>() {
            return ExitKind::Input;
        }
        if let Some(r) = cause.downcast_ref::<ReadError>() {
            return match r {
                ReadError::Input(_) => ExitKind::Input,
                ReadError::Io { .. } => ExitKind::Io,
            };
        }
        if cause.is::<std::io::Error>() {
            return ExitKind::Io;
        }
        if let Some(c) = cause.downcast_ref::<CalibError>() {
            return match c {
                CalibError::Invalid { .. } | CalibError::Geometry(_) => ExitKind::Input,
                _ => ExitKind::Trouble,
            };
        }
    }
    ExitKind::Trouble
}

/// An error and its causes on one line, `outer: inner: ...`, leaving out a cause whose text
/// the message before it already shows (many errors quote their source).
pub fn render_error(err: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in err.chain() {
        let s = cause.to_string();
        if !parts.iter().any(|p| p.contains(&s)) {
            parts.push(s);
        }
    }
    parts.join(": ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_cause_gives_its_exit_code() {
        assert_eq!(exit_kind(&usage_error("x")), ExitKind::Usage);
        assert_eq!(exit_kind(&input_error("x")), ExitKind::Input);
        assert_eq!(exit_kind(&trouble("x")), ExitKind::Trouble);
        assert_eq!(exit_kind(&anyhow::Error::new(Cancelled)), ExitKind::Trouble);
        let io = anyhow::Error::new(std::io::Error::other("disk")).context("writing");
        assert_eq!(exit_kind(&io), ExitKind::Io);
        let nested = usage_error("--alpha must be in (0, 1)").context("refine");
        assert_eq!(exit_kind(&nested), ExitKind::Usage);
        assert_eq!(render_error(&nested), "refine: --alpha must be in (0, 1)");
    }
}
