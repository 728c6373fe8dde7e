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

impl ReadError {
    /// The error as an [`InputError`] (an I/O error becomes a whole-file one).
    pub fn into_input(self) -> InputError {
        match self {
            ReadError::Input(e) => e,
            ReadError::Io { file, source } => {
                InputError::file(file, format!("cannot read: {source}"))
            }
        }
    }
}

/// The largest text file [`read_text`] reads (robot descriptions): 16 MiB.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Reads a text file of at most [`MAX_TEXT_BYTES`]; failures are [`ReadError::Io`] (a file
/// that is not UTF-8 text, or far too large, is bad input).
pub fn read_text(path: &std::path::Path) -> Result<String, ReadError> {
    use std::io::Read;
    let file = path.display().to_string();
    let io = |source| ReadError::Io {
        file: file.clone(),
        source,
    };
    let f = super::campaign::open(path)?;
    let mut bytes = Vec::new();
    f.take(MAX_TEXT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_TEXT_BYTES {
        return Err(ReadError::Input(InputError::file(
            file,
            format!(
                "larger than {} MiB: not a robot description",
                MAX_TEXT_BYTES >> 20
            ),
        )));
    }
    let bytes = match bytes.strip_prefix(b"\xEF\xBB\xBF") {
        Some(rest) => rest.to_vec(),
        None => bytes,
    };
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = e.as_bytes()[..at].iter().filter(|b| **b == b'\n').count() + 1;
        ReadError::Input(InputError::line(
            file.clone(),
            line,
            "not UTF-8 text (save the file as UTF-8)",
        ))
    })
}
