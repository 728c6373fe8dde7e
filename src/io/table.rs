//! Reading CSV tables with a header row: column checks, typed fields, line numbers, and the
//! `# simulated by cpm` comment line.
use std::collections::HashMap;

use super::InputError;

/// The first comment line of every file that `cpm` simulated.
pub const SIMULATED_MARK: &str = "# simulated by cpm";

/// What a file holds, told from its header row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// Length-sensor readings (`sensor`, `length_mm`, ...).
    Readings,
    /// Tracker pose measurements with the commanded link readings (`reading_1`, ..., a pose).
    PoseMeasurements,
    /// A list of poses (a plan or compensation targets).
    Poses,
}

impl FileKind {
    /// Words for messages.
    pub fn describe(&self) -> &'static str {
        match self {
            FileKind::Readings => "length-sensor readings",
            FileKind::PoseMeasurements => "tracker pose measurements",
            FileKind::Poses => "a list of poses",
        }
    }
}

/// One data row.
#[derive(Debug, Clone)]
pub struct Row {
    /// 1-based line of the row in the file.
    pub line: usize,
    /// Its fields, trimmed, in header order.
    pub fields: Vec<String>,
}

/// A CSV table read from text.
#[derive(Debug, Clone)]
pub struct Table {
    /// The file name used in messages.
    pub file: String,
    /// 1-based line of the header row.
    pub header_line: usize,
    /// Column names, trimmed.
    pub headers: Vec<String>,
    /// Data rows.
    pub rows: Vec<Row>,
    /// True when the first line is the `# simulated by cpm` mark.
    pub simulated_mark: bool,
    index: HashMap<String, usize>,
}

impl Table {
    /// Parses CSV text with a header row. Lines starting with `#` are comments and blank lines
    /// are skipped; every row must have as many fields as the header.
    pub fn parse(text: &str, file: &str) -> Result<Table, InputError> {
        let simulated_mark = text
            .lines()
            .next()
            .is_some_and(|l| l.trim_start().starts_with(SIMULATED_MARK));
        let header_line = text
            .lines()
            .position(|l| !l.trim().is_empty() && !l.starts_with('#'))
            .map(|i| i + 1)
            .ok_or_else(|| InputError::file(file, "no header row: the file is empty"))?;
        let mut reader = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .has_headers(true)
            .flexible(false)
            .from_reader(text.as_bytes());
        let headers: Vec<String> = reader
            .headers()
            .map_err(|e| csv_error(file, header_line, e))?
            .iter()
            .map(|h| h.trim().to_string())
            .collect();
        let mut index = HashMap::new();
        for (i, h) in headers.iter().enumerate() {
            if h.is_empty() {
                return Err(InputError::line(
                    file,
                    header_line,
                    format!("column {} of the header has no name", i + 1),
                ));
            }
            if index.insert(h.clone(), i).is_some() {
                return Err(InputError::field(
                    file,
                    header_line,
                    h,
                    "the column appears twice in the header",
                ));
            }
        }
        let mut rows = Vec::new();
        for rec in reader.records() {
            let rec = rec.map_err(|e| csv_error(file, header_line, e))?;
            let line = rec
                .position()
                .map(|p| p.line() as usize)
                .unwrap_or(header_line);
            rows.push(Row {
                line,
                fields: rec.iter().map(|f| f.trim().to_string()).collect(),
            });
        }
        Ok(Table {
            file: file.to_string(),
            header_line,
            headers,
            rows,
            simulated_mark,
            index,
        })
    }

    /// What the header says the file holds.
    pub fn kind(&self) -> Result<FileKind, InputError> {
        if self.has("sensor") || self.has("length_mm") {
            Ok(FileKind::Readings)
        } else if self.headers.iter().any(|h| reading_index(h).is_some()) {
            Ok(FileKind::PoseMeasurements)
        } else if self.has("x_mm") {
            Ok(FileKind::Poses)
        } else {
            Err(InputError::line(
                &self.file,
                self.header_line,
                format!(
                    "cannot tell what this file holds from its header ({}): expected length-sensor readings (pose,sensor,x_mm,...,length_mm), tracker pose measurements (pose,reading_1..,x_mm,...) or a list of poses (x_mm,y_mm,z_mm,...)",
                    self.headers.join(",")
                ),
            ))
        }
    }

    /// True when the header has this column.
    pub fn has(&self, name: &str) -> bool {
        self.index.contains_key(name)
    }

    /// Index of a column.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// Checks the header: every name in `required` present, every column known (in
    /// `required`, `optional`, or accepted by `also`).
    pub fn check_columns(
        &self,
        required: &[&str],
        optional: &[&str],
        also: impl Fn(&str) -> bool,
    ) -> Result<(), InputError> {
        for r in required {
            if !self.has(r) {
                return Err(InputError::field(
                    &self.file,
                    self.header_line,
                    *r,
                    format!(
                        "missing column (the header has: {})",
                        self.headers.join(",")
                    ),
                ));
            }
        }
        for h in &self.headers {
            let known = required.contains(&h.as_str()) || optional.contains(&h.as_str()) || also(h);
            if !known {
                let mut expected: Vec<&str> = required.to_vec();
                expected.extend(optional);
                return Err(InputError::field(
                    &self.file,
                    self.header_line,
                    h,
                    format!("unknown column (expected: {})", expected.join(", ")),
                ));
            }
        }
        Ok(())
    }

    /// The raw text of a field (`None` when the table has no such column).
    pub fn text<'a>(&self, row: &'a Row, name: &str) -> Option<&'a str> {
        self.column(name).map(|i| row.fields[i].as_str())
    }

    /// A required text field: present and non-empty.
    pub fn required_text<'a>(&self, row: &'a Row, name: &str) -> Result<&'a str, InputError> {
        match self.text(row, name) {
            Some(t) if !t.is_empty() => Ok(t),
            Some(_) => Err(self.err(row, name, "missing value")),
            None => Err(InputError::field(
                &self.file,
                self.header_line,
                name,
                "missing column",
            )),
        }
    }

    /// A required finite number.
    pub fn number(&self, row: &Row, name: &str) -> Result<f64, InputError> {
        let t = self.required_text(row, name)?;
        parse_number(t).map_err(|m| self.err(row, name, m))
    }

    /// An optional finite number: `None` when the column is absent or the cell empty.
    pub fn optional_number(&self, row: &Row, name: &str) -> Result<Option<f64>, InputError> {
        match self.text(row, name) {
            None | Some("") => Ok(None),
            Some(t) => parse_number(t)
                .map(Some)
                .map_err(|m| self.err(row, name, m)),
        }
    }

    /// An optional boolean (`true`/`false`, `yes`/`no`, `1`/`0`).
    pub fn optional_bool(&self, row: &Row, name: &str) -> Result<Option<bool>, InputError> {
        match self.text(row, name) {
            None | Some("") => Ok(None),
            Some(t) => match t.to_ascii_lowercase().as_str() {
                "true" | "yes" | "1" => Ok(Some(true)),
                "false" | "no" | "0" => Ok(Some(false)),
                _ => Err(self.err(
                    row,
                    name,
                    format!("{t:?} is not a boolean (true/false, yes/no, 1/0)"),
                )),
            },
        }
    }

    /// An error in one field of a row.
    pub fn err(&self, row: &Row, name: &str, message: impl Into<String>) -> InputError {
        InputError::field(&self.file, row.line, name, message)
    }

    /// Numbers `k` of the `reading_k` columns, sorted; checks they are 1..=n without gaps.
    pub fn reading_columns(&self) -> Result<Vec<usize>, InputError> {
        let mut ks: Vec<usize> = self
            .headers
            .iter()
            .filter_map(|h| reading_index(h))
            .collect();
        ks.sort_unstable();
        for (i, k) in ks.iter().enumerate() {
            if *k != i + 1 {
                return Err(InputError::field(
                    &self.file,
                    self.header_line,
                    format!("reading_{}", i + 1),
                    "missing column (reading_1, reading_2, ... must be numbered without gaps)",
                ));
            }
        }
        Ok(ks)
    }
}

/// `k` of a `reading_k` column name (k >= 1).
pub fn reading_index(name: &str) -> Option<usize> {
    name.strip_prefix("reading_")
        .and_then(|k| k.parse::<usize>().ok())
        .filter(|k| *k >= 1)
}

/// Parses a finite number; the message says what is wrong.
pub fn parse_number(t: &str) -> Result<f64, String> {
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("{t:?} is not a finite number")),
        Err(_) => Err(format!("{t:?} is not a number")),
    }
}

fn csv_error(file: &str, header_line: usize, e: csv::Error) -> InputError {
    let line = e
        .position()
        .map(|p| p.line() as usize)
        .unwrap_or(header_line);
    let message = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!(
            "{len} field{}, but the header has {expected_len}",
            if *len == 1 { "" } else { "s" }
        ),
        csv::ErrorKind::Utf8 { .. } => "not UTF-8 text".to_string(),
        _ => e.to_string(),
    };
    InputError::line(file, line, message)
}

/// Formats a number so that it reads back exactly (shortest round-trip form).
pub fn num(v: f64) -> String {
    format!("{v}")
}

/// Quotes a CSV field when needed.
pub fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) || s.starts_with('#') || s != s.trim() {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
