//! Reading CSV tables with a header row, one row at a time: column checks, typed fields, line
//! numbers, and the `# simulated by cpm` comment line.
//!
//! A [`Table`] streams its rows from any reader ([`Table::next_row`]): a file is never read
//! into memory as a whole, and the first bad row stops the reading there. Lines starting with
//! `#` are comments; blank lines (spaces only) are skipped; CRLF line endings and a UTF-8
//! byte-order mark are accepted; a line longer than [`MAX_LINE_BYTES`] is refused (a file
//! that is not CSV at all, without reading all of it). Line numbers in messages are the
//! file's physical lines, as an editor shows them.
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read};

use super::InputError;

/// The first comment line of every file that `cpm` simulated.
pub const SIMULATED_MARK: &str = "# simulated by cpm";

/// The longest line a CSV file may have, bytes (1 MiB): longer means it is not a table.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// The error of a line longer than [`MAX_LINE_BYTES`] (with its line break), on `line` of
/// `file`.
pub(crate) fn line_too_long(file: &str, line: usize) -> InputError {
    InputError::line(
        file,
        line,
        format!("the line is longer than {MAX_LINE_BYTES} bytes: this is not a CSV table of cpm"),
    )
}

/// What a file holds, told from its header row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// Length-sensor readings (`sensor`, `length_mm`, ...).
    Readings,
    /// Tracker pose measurements with the commanded link readings (`reading_1`, ..., a pose).
    PoseMeasurements,
    /// A list of poses (a plan or compensation targets).
    Poses,
    /// Point target measurements (`target`, a measured point, the commanded pose or link
    /// readings).
    PointMeasurements,
    /// Inclinometer angles (`inclinometer`, `angle_1_deg`, ..., the commanded pose or link
    /// readings).
    TiltMeasurements,
}

impl FileKind {
    /// Words for messages.
    pub fn describe(&self) -> &'static str {
        match self {
            FileKind::Readings => "length-sensor readings",
            FileKind::PoseMeasurements => "tracker pose measurements",
            FileKind::Poses => "a list of poses",
            FileKind::PointMeasurements => "point target measurements",
            FileKind::TiltMeasurements => "inclinometer angles",
        }
    }
}

/// One data row: its line, held once, and where each of its fields is in it.
#[derive(Debug, Clone, Default)]
pub struct Row {
    /// 1-based line of the row in the file.
    pub line: usize,
    /// The line's text (a plain line, taken as it was read), or its fields unquoted one
    /// after the other (a line with a quoted field).
    text: String,
    /// Where each field, trimmed, is in `text`, in header order.
    spans: Vec<(usize, usize)>,
}

impl Row {
    /// Its number of fields.
    pub fn len(&self) -> usize {
        self.spans.len()
    }

    /// True when it has no field.
    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// Field `k` (trimmed), `None` past the last.
    pub fn get(&self, k: usize) -> Option<&str> {
        self.spans.get(k).and_then(|&(a, b)| self.text.get(a..b))
    }

    /// Its fields (trimmed), in header order.
    pub fn fields(&self) -> impl Iterator<Item = &str> + '_ {
        self.spans
            .iter()
            .map(|&(a, b)| self.text.get(a..b).unwrap_or(""))
    }

    /// Its fields as owned strings.
    pub fn to_fields(&self) -> Vec<String> {
        self.fields().map(str::to_string).collect()
    }
}

/// The header of a table: file name, header line, column names; reads typed fields of rows.
#[derive(Debug, Clone)]
pub struct Header {
    /// The file name used in messages.
    pub file: String,
    /// 1-based line of the header row.
    pub header_line: usize,
    /// Column names, trimmed.
    pub headers: Vec<String>,
    /// True when the first line is the `# simulated by cpm` mark.
    pub simulated_mark: bool,
    index: HashMap<String, usize>,
}

/// A CSV table with a header row, read row by row from `R`.
///
/// The dialect: fields separated by commas and trimmed; a field may be quoted (`"a,b"`,
/// `""` for a quote inside); one record per line (a quoted field cannot span lines).
pub struct Table<R: Read> {
    /// The header.
    pub header: Header,
    source: Source<R>,
    /// The size of what is read, bytes, when known: a reader sizes its lists from it.
    size_bytes: Option<u64>,
}

/// Where a table's rows come from.
enum Source<R: Read> {
    /// Its lines, read and split here as they are asked for.
    Here(Lines<R>),
    /// A thread that reads and splits them ahead ([`Table::read_ahead`]).
    Ahead(Ahead),
}

/// The lines of a table's reader, and what splitting them reuses from line to line.
struct Lines<R: Read> {
    reader: BufReader<R>,
    buf: Vec<u8>,
    /// The unquoted bytes of the fields of the current line, and where each field ends in it.
    unquoted: Vec<u8>,
    ends: Vec<usize>,
    line: usize,
    io_error: Option<std::io::Error>,
}

/// Rows split by the reading thread, in order: `rows[..len]`, then how the reading ended
/// when it did (after the rows): at the end of the file, or with the error of the next line
/// (and the I/O error behind it).
struct Batch {
    rows: Vec<Row>,
    len: usize,
    end: Option<Result<(), (InputError, Option<std::io::Error>)>>,
}

/// The receiving end of a table read ahead by a thread: the batch being handed out (its
/// next row), the batches to come, and the way back for the rows handed in for them (their
/// strings reused).
struct Ahead {
    batch: Batch,
    next: usize,
    batches: std::sync::mpsc::Receiver<Batch>,
    spent: std::sync::mpsc::Sender<Vec<Row>>,
    io_error: Option<std::io::Error>,
}

/// Rows per batch of a table read ahead.
const BATCH_ROWS: usize = 512;

/// Batches a reading thread may be ahead of the rows asked for.
const BATCHES_AHEAD: usize = 8;

impl<R: Read> std::ops::Deref for Table<R> {
    type Target = Header;
    fn deref(&self) -> &Header {
        &self.header
    }
}

impl<'a> Table<&'a [u8]> {
    /// A table over CSV text in memory.
    pub fn parse(text: &'a str, file: &str) -> Result<Self, InputError> {
        Ok(Table::from_reader(text.as_bytes(), file)?.with_size_bytes(Some(text.len() as u64)))
    }
}

impl<R: Read> Table<R> {
    /// Opens a table: skips a byte-order mark, notes the `# simulated by cpm` line, reads the
    /// header row (the first line that is neither a comment nor blank) and checks its names.
    pub fn from_reader(source: R, file: &str) -> Result<Self, InputError> {
        let mut t = Table {
            header: Header {
                file: file.to_string(),
                header_line: 0,
                headers: Vec::new(),
                simulated_mark: false,
                index: HashMap::new(),
            },
            source: Source::Here(Lines {
                reader: BufReader::with_capacity(64 * 1024, source),
                buf: Vec::new(),
                unquoted: Vec::new(),
                ends: Vec::new(),
                line: 0,
                io_error: None,
            }),
            size_bytes: None,
        };
        let Some(first) = t.next_record()? else {
            return Err(InputError::file(
                file,
                "no header row: the file is empty (or has only comments)",
            ));
        };
        t.header.header_line = first.line;
        for (i, h) in first.fields().enumerate() {
            if h.is_empty() {
                return Err(InputError::line(
                    file,
                    first.line,
                    format!("column {} of the header has no name", i + 1),
                ));
            }
            if t.header.index.insert(h.to_string(), i).is_some() {
                return Err(InputError::field(
                    file,
                    first.line,
                    shorten(h),
                    "the column appears twice in the header",
                ));
            }
        }
        t.header.headers = first.to_fields();
        Ok(t)
    }

    /// The table, told the size of what it reads (bytes; `None`: not known).
    pub fn with_size_bytes(mut self, size_bytes: Option<u64>) -> Self {
        self.size_bytes = size_bytes;
        self
    }

    /// About how many rows like `row` the table holds, from its size when known: the size
    /// over the row's length (its line, ending included). `None` when the size is not known.
    pub fn rows_like(&self, row: &Row) -> Option<usize> {
        let size = usize::try_from(self.size_bytes?).ok()?;
        Some(size / (row.text.len() + 1))
    }

    /// The next data row, `None` at the end; every row has as many fields as the header.
    pub fn next_row(&mut self) -> Result<Option<Row>, InputError> {
        let mut row = Row::default();
        Ok(self.next_row_into(&mut row)?.then_some(row))
    }

    /// [`next_row`](Self::next_row) into a row that is reused from call to call (its
    /// strings keep their allocations): false at the end. The fast way through a large file.
    pub fn next_row_into(&mut self, row: &mut Row) -> Result<bool, InputError> {
        if !self.next_record_into(row)? {
            return Ok(false);
        }
        let (len, expected) = (row.len(), self.header.headers.len());
        if len != expected {
            return Err(InputError::line(
                &self.header.file,
                row.line,
                format!(
                    "{len} field{}, but the header has {expected}",
                    if len == 1 { "" } else { "s" }
                ),
            ));
        }
        Ok(true)
    }

    /// The I/O error that stopped the reading, if one did (the returned [`InputError`] then
    /// only says that the file could not be read there).
    pub fn take_io_error(&mut self) -> Option<std::io::Error> {
        match &mut self.source {
            Source::Here(lines) => lines.io_error.take(),
            Source::Ahead(ahead) => ahead.io_error.take(),
        }
    }

    /// The next line that is neither a comment nor blank, split into trimmed UTF-8 fields.
    fn next_record(&mut self) -> Result<Option<Row>, InputError> {
        let mut row = Row::default();
        Ok(self.next_record_into(&mut row)?.then_some(row))
    }

    /// [`next_record`](Self::next_record) into a reused row: false at the end.
    fn next_record_into(&mut self, row: &mut Row) -> Result<bool, InputError> {
        match &mut self.source {
            Source::Here(lines) => lines.next_record_into(&mut self.header, row),
            Source::Ahead(ahead) => ahead.next_record_into(&self.header, row),
        }
    }
}

impl<R: Read + Send + 'static> Table<R> {
    /// The table with its remaining lines read and split into rows by a thread of its own,
    /// a few batches ahead of the rows asked for, while the caller works on the rows it has
    /// (the same rows, errors and line numbers as read here: the reading of a large file
    /// is then about the caller's work alone). The reading stops at the first error, as the
    /// callers do: after it the table has no more rows. The table as it is when no thread
    /// can be started.
    pub fn read_ahead(self) -> Self {
        let Source::Here(lines) = self.source else {
            return self;
        };
        let (give, take) = std::sync::mpsc::channel::<Lines<R>>();
        let (batches_in, batches) = std::sync::mpsc::sync_channel(BATCHES_AHEAD);
        let (spent, spent_out) = std::sync::mpsc::channel::<Vec<Row>>();
        let mut header = self.header.clone();
        let started = std::thread::Builder::new()
            .name("cpm-csv".to_string())
            .spawn(move || {
                let Ok(mut lines) = take.recv() else {
                    return;
                };
                let mut rows = Vec::new();
                loop {
                    let (mut len, mut end) = (0, None);
                    while len < BATCH_ROWS {
                        if rows.len() == len {
                            rows.push(Row::default());
                        }
                        match lines.next_record_into(&mut header, &mut rows[len]) {
                            Ok(true) => len += 1,
                            Ok(false) => end = Some(Ok(())),
                            Err(e) => end = Some(Err((e, lines.io_error.take()))),
                        }
                        if end.is_some() {
                            break;
                        }
                    }
                    let last = end.is_some();
                    // Stops when the table is gone (the caller stopped reading).
                    if batches_in.send(Batch { rows, len, end }).is_err() || last {
                        return;
                    }
                    rows = spent_out.try_recv().unwrap_or_default();
                }
            });
        if started.is_err() {
            return Table {
                header: self.header,
                source: Source::Here(lines),
                size_bytes: self.size_bytes,
            };
        }
        match give.send(lines) {
            Ok(()) => Table {
                header: self.header,
                size_bytes: self.size_bytes,
                source: Source::Ahead(Ahead {
                    batch: Batch {
                        rows: Vec::new(),
                        len: 0,
                        end: None,
                    },
                    next: 0,
                    batches,
                    spent,
                    io_error: None,
                }),
            },
            Err(std::sync::mpsc::SendError(lines)) => Table {
                header: self.header,
                source: Source::Here(lines),
                size_bytes: self.size_bytes,
            },
        }
    }
}

impl Ahead {
    /// The next row the reading thread split, into `row` (whose strings go back to it for
    /// the rows to come): false at the end; the error where the reading stopped, once (then
    /// the end).
    fn next_record_into(&mut self, header: &Header, row: &mut Row) -> Result<bool, InputError> {
        loop {
            if self.next < self.batch.len {
                std::mem::swap(row, &mut self.batch.rows[self.next]);
                self.next += 1;
                return Ok(true);
            }
            match self.batch.end.replace(Ok(())) {
                Some(Ok(())) => return Ok(false),
                Some(Err((e, io))) => {
                    self.io_error = io;
                    return Err(e);
                }
                None => self.batch.end = None,
            }
            // The thread may be done: the rows are then dropped.
            let _ = self.spent.send(std::mem::take(&mut self.batch.rows));
            match self.batches.recv() {
                Ok(batch) => {
                    self.batch = batch;
                    self.next = 0;
                }
                Err(_) => {
                    // The thread stopped without saying how the reading ended: a panic.
                    return Err(InputError::file(
                        &header.file,
                        "cannot read: the thread reading the file stopped",
                    ));
                }
            }
        }
    }
}

impl<R: Read> Lines<R> {
    /// Reads the next physical line into `buf` (without its line ending); false at the end.
    fn read_line(&mut self, header: &mut Header) -> Result<bool, InputError> {
        self.buf.clear();
        // At most one byte past the longest line: enough to tell that it is too long, without
        // reading all of a file that is not CSV.
        let limit = MAX_LINE_BYTES as u64 + 1;
        if let Err(e) = (&mut self.reader)
            .take(limit)
            .read_until(b'\n', &mut self.buf)
        {
            let err = InputError::line(&header.file, self.line + 1, format!("cannot read: {e}"));
            self.io_error = Some(e);
            return Err(err);
        }
        if self.buf.is_empty() {
            return Ok(false);
        }
        if self.buf.len() > MAX_LINE_BYTES {
            return Err(line_too_long(&header.file, self.line + 1));
        }
        self.line += 1;
        while matches!(self.buf.last(), Some(b'\n' | b'\r')) {
            self.buf.pop();
        }
        if self.line == 1 {
            if self.buf.starts_with(b"\xEF\xBB\xBF") {
                self.buf.drain(..3);
            }
            header.simulated_mark = self
                .buf
                .trim_ascii_start()
                .starts_with(SIMULATED_MARK.as_bytes());
        }
        Ok(true)
    }

    /// The next line that is neither a comment nor blank, split into trimmed UTF-8 fields
    /// (named after `header`'s columns in errors), into a reused row: false at the end.
    fn next_record_into(&mut self, header: &mut Header, row: &mut Row) -> Result<bool, InputError> {
        loop {
            if !self.read_line(header)? {
                return Ok(false);
            }
            if self.buf.first() == Some(&b'#') || self.buf.trim_ascii().is_empty() {
                continue;
            }
            let line = self.line;
            if self.plain_fields_into(row) {
                return Ok(true);
            }
            split_fields(&self.buf, &mut self.unquoted, &mut self.ends).map_err(|(col, m)| {
                match header.headers.get(col - 1) {
                    Some(name) => InputError::field(&header.file, line, name, m),
                    None => InputError::line(&header.file, line, format!("column {col}: {m}")),
                }
            })?;
            let what = "not UTF-8 text (save the file as UTF-8)";
            row.line = line;
            row.spans.clear();
            let mut start = 0;
            for (k, &end) in self.ends.iter().enumerate() {
                if std::str::from_utf8(&self.unquoted[start..end]).is_err() {
                    return Err(match header.headers.get(k) {
                        Some(name) => InputError::field(&header.file, line, name, what),
                        None => InputError::line(&header.file, line, what),
                    });
                }
                row.spans.push((start, end));
                start = end;
            }
            // The fields are UTF-8 text one by one, so all of them together are.
            let Ok(text) = std::str::from_utf8(&self.unquoted) else {
                return Err(InputError::line(&header.file, line, what));
            };
            row.text.clear();
            row.text.push_str(text);
            return Ok(true);
        }
    }

    /// The fields of the current line into `row` when the line is the common case, UTF-8
    /// text without a quoted field: split at its commas in one pass, straight from the line's
    /// bytes. False (nothing done) otherwise: the general splitting reads it, and says what is
    /// wrong.
    fn plain_fields_into(&mut self, row: &mut Row) -> bool {
        // The line as text (no copy), given back to the buffer when it is not plain.
        let text = match String::from_utf8(std::mem::take(&mut self.buf)) {
            Ok(text) => text,
            Err(e) => {
                self.buf = e.into_bytes();
                return false;
            }
        };
        let (bytes, mut start) = (text.as_bytes(), 0);
        // Split at the commas (ASCII: the pieces of UTF-8 text between them are UTF-8 text),
        // found eight bytes at a time.
        commas(bytes, &mut self.ends);
        row.spans.clear();
        let mut next_comma = 0;
        while start <= bytes.len() {
            let end = self.ends.get(next_comma).copied().unwrap_or(bytes.len());
            next_comma += 1;
            let piece = &bytes[start..end];
            // The common field: neither its first byte (a blank, a quote) nor its last (a
            // blank) asks for more; the general way below finds the same span for it.
            if let (Some(f), Some(l)) = (piece.first(), piece.last()) {
                if !f.is_ascii_whitespace() && *f != b'"' && !l.is_ascii_whitespace() {
                    row.spans.push((start, end));
                    start = end + 1;
                    continue;
                }
            }
            // Leading blanks (spaces and tabs), then a quote: not a plain field.
            let blanks = piece
                .iter()
                .position(|b| !matches!(b, b' ' | b'\t'))
                .unwrap_or(piece.len());
            if piece.get(blanks) == Some(&b'"') {
                // The row's fields so far are made again by the general splitting.
                self.buf = text.into_bytes();
                return false;
            }
            // Trimmed as `str::trim_ascii` trims (ASCII whitespace at both ends).
            let lead = piece
                .iter()
                .position(|b| !b.is_ascii_whitespace())
                .unwrap_or(piece.len());
            let trail = piece[lead..]
                .iter()
                .rposition(|b| !b.is_ascii_whitespace())
                .map_or(lead, |p| lead + p + 1);
            row.spans.push((start + lead, start + trail));
            start = end + 1;
        }
        // The line becomes the row's text, the row's previous text the next line's buffer.
        self.buf = std::mem::replace(&mut row.text, text).into_bytes();
        row.line = self.line;
        true
    }
}

/// The positions of the commas of `bytes`, in order, into `out` (cleared first): eight bytes
/// at a time, a comma being a byte of the word equal to `,` (found exactly, without carries
/// from one byte to the next).
fn commas(bytes: &[u8], out: &mut Vec<usize>) {
    const COMMAS: u64 = 0x2c2c_2c2c_2c2c_2c2c;
    const LOW7: u64 = 0x7f7f_7f7f_7f7f_7f7f;
    out.clear();
    let mut chunks = bytes.chunks_exact(8);
    let mut base = 0;
    for c in &mut chunks {
        let mut word = [0u8; 8];
        word.copy_from_slice(c);
        let x = u64::from_le_bytes(word) ^ COMMAS;
        // The high bit of each byte of x that is zero (a comma), and nothing else.
        let mut zero = !(((x & LOW7).wrapping_add(LOW7)) | x | LOW7);
        while zero != 0 {
            out.push(base + (zero.trailing_zeros() / 8) as usize);
            zero &= zero - 1;
        }
        base += 8;
    }
    for (i, b) in chunks.remainder().iter().enumerate() {
        if *b == b',' {
            out.push(base + i);
        }
    }
}

/// The error of a quoted field that a line ends in (one record per line).
pub(crate) const QUOTE_NOT_CLOSED: &str =
    "a quote is not closed on this line (a quoted field cannot span lines)";

/// Splits one CSV line into trimmed fields: commas separate, a field that starts with `"`
/// is quoted (`""` is a quote inside it). The fields' bytes go one after the other into
/// `out`, and `ends[k]` is where field `k` ends in it (both cleared first).
fn split_fields(
    line: &[u8],
    out: &mut Vec<u8>,
    ends: &mut Vec<usize>,
) -> Result<(), (usize, &'static str)> {
    out.clear();
    ends.clear();
    let mut i = 0;
    loop {
        while i < line.len() && matches!(line[i], b' ' | b'\t') {
            i += 1;
        }
        if line.get(i) == Some(&b'"') {
            let col = ends.len() + 1;
            i += 1;
            loop {
                match line.get(i) {
                    None => return Err((col, QUOTE_NOT_CLOSED)),
                    Some(b'"') if line.get(i + 1) == Some(&b'"') => {
                        out.push(b'"');
                        i += 2;
                    }
                    Some(b'"') => {
                        i += 1;
                        break;
                    }
                    Some(b) => {
                        out.push(*b);
                        i += 1;
                    }
                }
            }
            while i < line.len() && matches!(line[i], b' ' | b'\t') {
                i += 1;
            }
            if i < line.len() && line[i] != b',' {
                return Err((col, "text after the closing quote (quote the whole field)"));
            }
        } else {
            let start = i;
            while i < line.len() && line[i] != b',' {
                i += 1;
            }
            out.extend_from_slice(line[start..i].trim_ascii());
        }
        ends.push(out.len());
        if i >= line.len() {
            return Ok(());
        }
        i += 1; // the comma
    }
}

impl Header {
    /// What the header says the file holds.
    pub fn kind(&self) -> Result<FileKind, InputError> {
        if self.has("target") {
            Ok(FileKind::PointMeasurements)
        } else if self.has("inclinometer") {
            Ok(FileKind::TiltMeasurements)
        } else if self.has("sensor") || self.has("length_mm") {
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
                    "cannot tell what this file holds from its header ({}): expected length-sensor readings (pose,sensor,x_mm,...,length_mm), tracker pose measurements (pose,reading_1..,x_mm,...), point target measurements (pose,target,x_mm,y_mm,z_mm,...), inclinometer angles (pose,inclinometer,angle_1_deg,...) or a list of poses (x_mm,y_mm,z_mm,...)",
                    shorten(&self.headers.join(","))
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
        // A few columns: comparing the names is quicker than hashing one (a reader looks up
        // a dozen columns in every row).
        if self.headers.len() <= 32 {
            self.headers.iter().position(|h| h == name)
        } else {
            self.index.get(name).copied()
        }
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
                        shorten(&self.headers.join(","))
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
                    shorten(h),
                    format!("unknown column (expected: {})", expected.join(", ")),
                ));
            }
        }
        Ok(())
    }

    /// The raw text of a field (`None` when the table has no such column).
    pub fn text<'a>(&self, row: &'a Row, name: &str) -> Option<&'a str> {
        self.column(name).and_then(|i| row.get(i))
    }

    /// A required text field: present and non-empty.
    pub fn required_text<'a>(&self, row: &'a Row, name: &str) -> Result<&'a str, InputError> {
        match self.column(name) {
            Some(col) => self.required_text_at(row, col),
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
        match self.column(name) {
            Some(col) => self.number_at(row, col),
            None => self.required_text(row, name).map(|_| f64::NAN),
        }
    }

    /// An optional finite number: `None` when the column is absent or the cell empty.
    pub fn optional_number(&self, row: &Row, name: &str) -> Result<Option<f64>, InputError> {
        self.optional_number_at(row, self.column(name))
    }

    /// An optional boolean (`true`/`false`, `yes`/`no`, `1`/`0`).
    pub fn optional_bool(&self, row: &Row, name: &str) -> Result<Option<bool>, InputError> {
        self.optional_bool_at(row, self.column(name))
    }

    /// [`required_text`](Self::required_text) of column `col` (an index from
    /// [`column`](Self::column): a reader that looks up its columns once).
    pub fn required_text_at<'a>(&self, row: &'a Row, col: usize) -> Result<&'a str, InputError> {
        match row.get(col) {
            Some(t) if !t.is_empty() => Ok(t),
            _ => Err(self.err(row, &self.headers[col], "missing value")),
        }
    }

    /// [`number`](Self::number) of column `col`.
    pub fn number_at(&self, row: &Row, col: usize) -> Result<f64, InputError> {
        let t = self.required_text_at(row, col)?;
        parse_number(t).map_err(|m| self.err(row, &self.headers[col], m))
    }

    /// [`optional_number`](Self::optional_number) of column `col` (`None`: no such column).
    pub fn optional_number_at(
        &self,
        row: &Row,
        col: Option<usize>,
    ) -> Result<Option<f64>, InputError> {
        let Some(col) = col else { return Ok(None) };
        match row.get(col) {
            None | Some("") => Ok(None),
            Some(t) => parse_number(t)
                .map(Some)
                .map_err(|m| self.err(row, &self.headers[col], m)),
        }
    }

    /// [`optional_bool`](Self::optional_bool) of column `col` (`None`: no such column).
    pub fn optional_bool_at(
        &self,
        row: &Row,
        col: Option<usize>,
    ) -> Result<Option<bool>, InputError> {
        let Some(col) = col else { return Ok(None) };
        let name = &self.headers[col];
        match row.get(col) {
            None | Some("") => Ok(None),
            // As written by cpm (every row of a simulated file), before the general cases.
            Some("true") => Ok(Some(true)),
            Some(t)
                if t.eq_ignore_ascii_case("true") || t.eq_ignore_ascii_case("yes") || t == "1" =>
            {
                Ok(Some(true))
            }
            Some(t)
                if t.eq_ignore_ascii_case("false") || t.eq_ignore_ascii_case("no") || t == "0" =>
            {
                Ok(Some(false))
            }
            Some(t) => Err(self.err(
                row,
                name,
                format!(
                    "{:?} is not a boolean (true/false, yes/no, 1/0)",
                    shorten(t)
                ),
            )),
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
        .filter(|k| k.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|k| k.parse::<usize>().ok())
        .filter(|k| *k >= 1)
}

/// At most 60 characters of a text, for messages (a whole garbage line is no help).
pub fn shorten(s: &str) -> String {
    match s.char_indices().nth(60) {
        Some((i, _)) => format!("{}...", &s[..i]),
        None => s.to_string(),
    }
}

/// Parses a finite number; the message says what is wrong.
pub fn parse_number(t: &str) -> Result<f64, String> {
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("{:?} is not a finite number", shorten(t))),
        Err(_) => Err(format!("{:?} is not a number", shorten(t))),
    }
}

/// A number for messages: as written for ordinary magnitudes, in exponent form for huge or
/// tiny ones (a 300-digit number is no help), with at most `digits` decimals when given.
pub fn show(v: f64, digits: Option<usize>) -> String {
    if v != 0.0 && !(1e-6..1e12).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        match digits {
            Some(d) => format!("{v:.d$}"),
            None => format!("{v}"),
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(text: &[u8]) -> Result<(Header, Vec<Row>), InputError> {
        let mut t = Table::from_reader(text, "t.csv")?;
        let mut v = Vec::new();
        while let Some(r) = t.next_row()? {
            v.push(r);
        }
        Ok((t.header.clone(), v))
    }

    /// What a table gives, row after row, until the end or the first error (and the I/O
    /// error behind it).
    fn all_rows<R: Read>(mut t: Table<R>) -> (Vec<(usize, Vec<String>)>, String, bool) {
        let mut rows = Vec::new();
        let mut row = Row::default();
        let end = loop {
            match t.next_row_into(&mut row) {
                Ok(true) => rows.push((row.line, row.to_fields())),
                Ok(false) => break "end".to_string(),
                Err(e) => break e.to_string(),
            }
        };
        (rows, end, t.take_io_error().is_some())
    }

    /// A reader that fails after `left` bytes.
    struct Failing {
        text: std::io::Cursor<Vec<u8>>,
        left: usize,
    }

    impl Read for Failing {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.left == 0 {
                return Err(std::io::Error::other("disk on fire"));
            }
            let n = buf.len().min(self.left);
            let n = self.text.read(&mut buf[..n])?;
            self.left -= n;
            Ok(n)
        }
    }

    /// A table knows about how many rows like its first it holds when told its size (read
    /// ahead or not), and nothing when not told.
    #[test]
    fn rows_like_counts_rows_from_the_size() {
        let mut text = String::from("a,b\n");
        for k in 0..1000 {
            text.push_str(&format!("{},x\n", 100 + k % 900));
        }
        let mut t = Table::parse(&text, "t.csv").unwrap();
        let row = t.next_row().unwrap().unwrap();
        // 1000 rows of 6 bytes and a header of 4: the size over a row's 6 bytes.
        assert_eq!(t.rows_like(&row), Some(1000));
        let mut t = Table::from_reader(text.as_bytes(), "t.csv").unwrap();
        let row = t.next_row().unwrap().unwrap();
        assert_eq!(t.rows_like(&row), None);
        let told = Table::from_reader(std::io::Cursor::new(text.clone().into_bytes()), "t.csv")
            .unwrap()
            .with_size_bytes(Some(text.len() as u64));
        let mut t = told.read_ahead();
        let row = t.next_row().unwrap().unwrap();
        assert_eq!(t.rows_like(&row), Some(1000));
    }

    /// A table read ahead by a thread gives the rows, line numbers and first error (a bad
    /// row, a line too long, an I/O error) of one read here, over many batches.
    #[test]
    fn read_ahead_changes_nothing() {
        let mut text = b"# simulated by cpm\na,b,c\n".to_vec();
        for k in 0..3 * BATCH_ROWS {
            let line = match k % 7 {
                0 => format!(" {k} ,\"x,{k}\", 2\n"),
                3 => "# a comment\n\n".to_string(),
                _ => format!("{k},{},{}\r\n", k * 2, k % 5),
            };
            text.extend(line.bytes());
        }
        let mut cases = vec![text.clone()];
        for bad in [&b"1,2\n"[..], b"1,\"2,3\n", b"1,\xff,3\n"] {
            for at in [40, BATCH_ROWS * 20 + 7, text.len()] {
                let at = text[..at].iter().rposition(|b| *b == b'\n').unwrap() + 1;
                let mut t = text[..at].to_vec();
                t.extend_from_slice(bad);
                t.extend_from_slice(&text[at..]);
                cases.push(t);
            }
        }
        let mut long = text.clone();
        long.extend(std::iter::repeat_n(b'7', MAX_LINE_BYTES + 10));
        cases.push(long);
        let mut errors = 0;
        for case in cases {
            let here = Table::from_reader(std::io::Cursor::new(case.clone()), "t.csv").unwrap();
            let ahead = Table::from_reader(std::io::Cursor::new(case), "t.csv")
                .unwrap()
                .read_ahead();
            assert!(matches!(ahead.source, Source::Ahead(_)));
            let here = all_rows(here);
            errors += usize::from(here.1.starts_with("t.csv:"));
            assert_eq!(all_rows(ahead), here);
        }
        assert_eq!(errors, 10);
        for left in [100, 5000, text.len() / 2] {
            let failing = || Failing {
                text: std::io::Cursor::new(text.clone()),
                left,
            };
            let here = all_rows(Table::from_reader(failing(), "t.csv").unwrap());
            let ahead = all_rows(Table::from_reader(failing(), "t.csv").unwrap().read_ahead());
            assert!(
                here.2 && here.1.contains("cannot read: disk on fire"),
                "{}",
                here.1
            );
            assert_eq!(ahead, here);
        }
    }

    #[test]
    fn commas_are_found_eight_bytes_at_a_time_as_one_by_one() {
        let mut out = Vec::new();
        for line in [
            "",
            ",",
            "a,b",
            "1,b1p1,-44.61366920080514,5.330690571302199,445.80590496293104,true",
            ",,,,,,,,,,,,,,,,,",
            "\u{e9}\u{2c},x\u{ac},,y,\u{12c}",
            "no commas at all in this rather long line of text",
        ] {
            commas(line.as_bytes(), &mut out);
            let expected: Vec<usize> = line
                .bytes()
                .enumerate()
                .filter(|(_, b)| *b == b',')
                .map(|(i, _)| i)
                .collect();
            assert_eq!(out, expected, "{line:?}");
        }
    }

    #[test]
    fn bom_crlf_blank_lines_and_comments() {
        let (h, r) =
            rows(b"\xEF\xBB\xBF# simulated by cpm 0.1\r\na, b\r\n\r\n  \r\n1,2\r\n# c\r\n3,4\r\n")
                .unwrap();
        assert!(h.simulated_mark);
        assert_eq!(h.headers, ["a", "b"]);
        assert_eq!(h.header_line, 2);
        assert_eq!(r.iter().map(|r| r.line).collect::<Vec<_>>(), [5, 7]);
        assert_eq!(r[1].get(1), Some("4"));
    }

    /// Plain lines (split in one pass) and lines with quoted fields (the general splitting)
    /// give the same trimmed fields, in any order, through one reused row.
    #[test]
    fn plain_and_quoted_lines_agree() {
        let (_, r) =
            rows(b"a,b,c\n 1 ,\t2\t,\n\"1\", \"2\" ,\"\"\n3,\"x,y\",z\"q\n\t4,5 ,6\n").unwrap();
        let fields: Vec<Vec<String>> = r.iter().map(Row::to_fields).collect();
        assert_eq!(fields[0], ["1", "2", ""]);
        assert_eq!(fields[1], ["1", "2", ""]);
        assert_eq!(fields[2], ["3", "x,y", "z\"q"]);
        assert_eq!(fields[3], ["4", "5", "6"]);
        assert_eq!(r.iter().map(|r| r.line).collect::<Vec<_>>(), [2, 3, 4, 5]);
    }

    #[test]
    fn located_errors() {
        let e = rows(b"").unwrap_err();
        assert!(e.to_string().starts_with("t.csv: no header row"), "{e}");
        let e = rows(b"# only\n\n").unwrap_err();
        assert!(e.to_string().starts_with("t.csv: no header row"), "{e}");
        let e = rows(b"a,b\n1,2\n1,2,3\n").unwrap_err();
        assert_eq!(e.to_string(), "t.csv:3: 3 fields, but the header has 2");
        let e = rows(b"a,b\n1,2\n1,\xff\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.csv:3: field b: not UTF-8 text (save the file as UTF-8)"
        );
        let (_, r) = rows(b"a, b\n\"x, \"\"y\"\"\" , 2\n").unwrap();
        assert_eq!(r[0].to_fields(), ["x, \"y\"", "2"]);
        let e = rows(b"a,b\n\"x,2\n").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("t.csv:2: field a: a quote is not closed"),
            "{e}"
        );
        let e = rows(b"a,a\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.csv:1: field a: the column appears twice in the header"
        );
        let mut long = b"a,b\n1,2\n".to_vec();
        long.extend(std::iter::repeat_n(b'7', MAX_LINE_BYTES + 10));
        let e = rows(&long).unwrap_err();
        assert!(
            e.to_string().starts_with("t.csv:3: the line is longer"),
            "{e}"
        );
    }
}
