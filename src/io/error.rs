//! Errors of the file formats: where (file, line, field) and what.
use std::fmt;

/// A problem with the contents of an input file.
///
/// Displays as `file:line: field name: what` (the line and field when known), e.g.
/// `data.csv:17: field length_mm: "abc" is not a number`. Lines are counted from 1, as an
/// editor shows them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputError {
    /// The file (as given on the command line).
    pub file: String,
    /// 1-based line, when the problem is on one line.
    pub line: Option<usize>,
    /// Column or key, when the problem is in one field.
    pub field: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl InputError {
    /// A problem with the file as a whole.
    pub fn file(file: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            file: file.into(),
            line: None,
            field: None,
            message: message.into(),
        }
    }

    /// A problem on one line.
    pub fn line(file: impl Into<String>, line: usize, message: impl Into<String>) -> Self {
        Self {
            line: Some(line),
            ..Self::file(file, message)
        }
    }

    /// A problem in one field of one line.
    pub fn field(
        file: impl Into<String>,
        line: usize,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self {
            line: Some(line),
            field: Some(field.into()),
            ..Self::file(file, message)
        }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        if let Some(c) = &self.field {
            write!(f, ": field {c}")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for InputError {}

/// Reading a file failed: it could not be read at all, or its contents are wrong.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The contents are wrong.
    #[error(transparent)]
    Input(#[from] InputError),
    /// The file could not be read (missing, no permission, not UTF-8 text).
    #[error("{file}: cannot read: {source}")]
    Io {
        /// The file.
        file: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

/// Reads a text file; failures are [`ReadError::Io`] (a file that is not UTF-8 text is bad
/// input).
pub fn read_text(path: &std::path::Path) -> Result<String, ReadError> {
    let file = path.display().to_string();
    std::fs::read_to_string(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::InvalidData {
            ReadError::Input(InputError::file(file, "not UTF-8 text"))
        } else {
            ReadError::Io { file, source }
        }
    })
}
