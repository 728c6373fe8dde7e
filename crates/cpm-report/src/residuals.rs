//! `residuals.csv` of `cpm calibrate`, `cpm refine` and `cpm validate`: every observation's
//! residual in its own unit, with the file, line and what was observed.
//!
//! The rows are written one after the other into any writer ([`write_residual_rows`]): the
//! texts of an observation (file, line, what) exist only while its row is written, in
//! buffers reused from row to row; the residuals stay numbers until then.

use cpm_io::{Merged, Robot};

use crate::fit::write_observation_origin;

/// The header row of `residuals.csv`.
pub const RESIDUALS_HEADER: &str = "observation,file,line,what,unit,residual\n";

/// `residuals.csv`: every observation's residual (measured minus predicted, in its own unit:
/// um for lengths, positions and points, urad for orientations and angles) with the file,
/// line and what it is. `residuals` are the native residuals in observation order.
///
/// Tracker positions and orientations, and point coordinates, are given in the tracker's own
/// axes (the rough registration the reader applied undone): the same whatever registration a
/// command started from.
pub fn residuals_csv(robot: &Robot, merged: &Merged, residuals: &[f64]) -> String {
    let mut out = Vec::with_capacity(RESIDUALS_HEADER.len() + 64 * residuals.len());
    out.extend_from_slice(RESIDUALS_HEADER.as_bytes());
    write_residual_rows(&mut out, robot, merged, residuals, 1).expect("writing to memory");
    String::from_utf8(out).expect("UTF-8 rows")
}

/// The rows of [`residuals_csv`] (no header), numbered from `first`, written to `out` as they
/// are made (several campaigns' rows follow each other in one file with `first` continuing
/// the numbering).
pub fn write_residual_rows<W: std::io::Write>(
    out: &mut W,
    robot: &Robot,
    merged: &Merged,
    residuals: &[f64],
    first: usize,
) -> std::io::Result<()> {
    write_residual_rows_with(out, robot, merged, residuals, first, &[])
}

/// [`write_residual_rows`] of a campaign with measurements of one's own instruments:
/// `instrument_units` is the unit of each (the model's
/// [`instruments`](cpm_calib::MeasurementModel::instruments), in order), written in their rows.
pub fn write_residual_rows_with<W: std::io::Write>(
    out: &mut W,
    robot: &Robot,
    merged: &Merged,
    residuals: &[f64],
    first: usize,
    instrument_units: &[String],
) -> std::io::Result<()> {
    use rayon::prelude::*;
    let residuals = merged.in_tracker_axes(residuals);
    // Blocks of rows made in parallel, a batch of them at a time (so that at most two
    // batches' text is held beside what `out` keeps), written in order: each batch is made
    // while the one before it is written (`out` may take its time: a file, fingerprinted as it
    // is written).
    const ROWS: usize = 1 << 13;
    const BATCH: usize = 16;
    let blocks: Vec<(usize, &[f64])> = residuals
        .chunks(ROWS)
        .enumerate()
        .map(|(b, r)| (b * ROWS, r))
        .collect();
    let make = |batch: &[(usize, &[f64])]| -> Vec<String> {
        batch
            .par_iter()
            .map(|(start, r)| residual_rows(robot, merged, r, *start, first, instrument_units))
            .collect()
    };
    let mut made: Vec<String> = Vec::new();
    for batch in blocks.chunks(BATCH) {
        let mut next = Vec::new();
        let written = rayon::in_place_scope(|s| {
            s.spawn(|_| next = make(batch));
            made.iter().try_for_each(|t| out.write_all(t.as_bytes()))
        });
        written?;
        made = next;
    }
    made.iter().try_for_each(|t| out.write_all(t.as_bytes()))
}

/// The rows of observations `start..start + residuals.len()` (see [`write_residual_rows`]).
fn residual_rows(
    robot: &Robot,
    merged: &Merged,
    residuals: &[f64],
    start: usize,
    first: usize,
    instrument_units: &[String],
) -> String {
    let c = &merged.campaign;
    let (mut what, mut field) = (String::new(), String::new());
    // Sized after the first row, for rows like it (and a few bytes more): a fixed guess
    // below the rows' length (64 bytes for ~70) made every block grow once, copying half a
    // megabyte each (60 MB over 10^6 rows).
    let mut chunk = String::new();
    // The file field of the previous row, as written (rows of one file follow each other).
    let (mut file_of_field, mut file_field) = (None::<&str>, String::new());
    // Which sensors have a plain name (see `plain`), for the gauge readings' rows.
    let plain_sensor: Vec<bool> = robot.table.sensors.iter().map(|s| plain(&s.name)).collect();
    for (i, r) in residuals.iter().enumerate() {
        let k = start + i;
        // A gauge reading of a sensor and a pose with plain names: its `what` written
        // quoted as it is (see `push_reading_what`), without the general formatting.
        let reading = c.readings.get(k).and_then(|rd| {
            let label = &merged.pose_origin.get(rd.pose)?.2;
            let sensor = &robot.table.sensors.get(rd.sensor)?.name;
            let origin = merged.reading_origin.get(k)?;
            (plain_sensor[rd.sensor] && plain(label)).then_some((origin, sensor, label))
        });
        let (file, line) = match reading {
            Some((origin, _, _)) => origin,
            None => write_observation_origin(robot, merged, k, &mut what).unwrap_or(("", 0)),
        };
        if file_of_field != Some(file) {
            file_field.clear();
            push_tidy_quoted(&mut file_field, file, &mut field);
            file_of_field = Some(file);
        }
        let unit = match c.observation_kind(k) {
            cpm_calib::ObservationKind::TrackerOrientation(..)
            | cpm_calib::ObservationKind::Tilt(..) => "urad",
            cpm_calib::ObservationKind::Instrument(q, _) => c
                .instrument_measurements
                .get(q)
                .and_then(|m| instrument_units.get(m.instrument))
                .map_or("", String::as_str),
            _ => "um",
        };
        // The row as `tidy_csv` would leave it: the numbering, the line and the unit are
        // left as they are, the residual is rounded to 12 significant digits.
        // Writing into a String cannot fail.
        push_integer(&mut chunk, k + first);
        chunk.push(',');
        chunk.push_str(&file_field);
        chunk.push(',');
        push_integer(&mut chunk, line);
        chunk.push(',');
        match reading {
            Some((_, sensor, label)) => push_reading_what(&mut chunk, sensor, label),
            None => push_tidy_quoted(&mut chunk, &what, &mut field),
        }
        chunk.push(',');
        chunk.push_str(unit);
        chunk.push(',');
        crate::format::push_tidy_number(&mut chunk, *r);
        chunk.push('\n');
        if i == 0 {
            chunk.reserve((chunk.len() + 8) * (residuals.len() - 1));
        }
    }
    chunk
}

/// Whether `s` is printable ASCII without a quote, a backslash or a comma: written as it is
/// by `{:?}` between its quotes, and by CSV quoting and tidying.
fn plain(s: &str) -> bool {
    s.bytes()
        .all(|b| (b' '..=b'~').contains(&b) && !matches!(b, b'"' | b'\\' | b','))
}

/// The `what` field of a gauge reading (`sensor NAME at pose "LABEL"`, as
/// `write_reading_what` writes it) quoted as [`push_tidy_quoted`] quotes it, for a
/// sensor and a label that are [`plain`]: the text has no comma, so tidying leaves it, and
/// its only quotes are the label's two, doubled.
fn push_reading_what(out: &mut String, sensor: &str, label: &str) {
    out.push_str("\"sensor ");
    out.push_str(sensor);
    out.push_str(" at pose \"\"");
    out.push_str(label);
    out.push_str("\"\"\"");
}

/// `n` in decimal digits (as `{n}` writes it), appended to `out`.
fn push_integer(out: &mut String, n: usize) {
    out.push_str(itoa::Buffer::new().format(n));
}

/// `s` as a quoted CSV field, tidied as [`crate::format::tidy_csv`] tidies it in its line
/// (which splits at every comma, quoted or not), appended to `out`; `work` is scratch.
fn push_tidy_quoted(out: &mut String, s: &str, work: &mut String) {
    if s.contains(',') {
        work.clear();
        push_quoted(work, s);
        crate::format::tidy_csv_line_into(work, out);
    } else {
        // One piece that starts with a quote: not a number, kept.
        push_quoted(out, s);
    }
}

/// `s` as a quoted CSV field (`"` doubled inside), appended to `out`.
fn push_quoted(out: &mut String, s: &str) {
    out.push('"');
    for (i, part) in s.split('"').enumerate() {
        if i > 0 {
            out.push_str("\"\"");
        }
        out.push_str(part);
    }
    out.push('"');
}

#[cfg(test)]
mod tests {
    use super::push_quoted;
    use proptest::prelude::*;

    /// A name: mostly plain ASCII, sometimes with what `{:?}`, CSV quoting or tidying
    /// change (quotes, backslashes, commas, control characters, non-ASCII, blanks).
    fn name() -> impl Strategy<Value = String> {
        prop_oneof![
            4 => "[a-zA-Z0-9 _.:;#()+-]{0,12}",
            1 => "[a-z0-9\"\\\\, \t\n\u{7f}\u{e9}\u{301}\u{1f600}]{0,8}",
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// A gauge reading's `what` written the short way is what the general way writes
        /// (`write_observation_origin`'s text, `write_reading_what`, quoted and tidied),
        /// whenever the short way is
        /// taken; it is taken for plain names only.
        #[test]
        fn a_reading_s_what_is_written_as_the_general_way_writes_it(
            sensor in name(),
            label in name(),
        ) {
            let (mut what, mut work, mut general) = (String::new(), String::new(), String::new());
            crate::fit::write_reading_what(&mut what, &sensor, &label);
            super::push_tidy_quoted(&mut general, &what, &mut work);
            if super::plain(&sensor) && super::plain(&label) {
                let mut short = String::new();
                super::push_reading_what(&mut short, &sensor, &label);
                prop_assert_eq!(short, general);
            } else {
                let odd = |s: &str| {
                    s.contains([',', '"', '\\']) || !s.bytes().all(|b| (b' '..=b'~').contains(&b))
                };
                prop_assert!(odd(&sensor) || odd(&label));
            }
        }
    }

    /// A row written field by field is the row `tidy_csv` makes of the plain row, even when
    /// a quoted text holds commas and pieces that look like numbers.
    #[test]
    fn fields_are_tidied_as_the_whole_line_would_be() {
        for v in [
            0.1 + 0.2,
            -0.0,
            0.0,
            331.739672003852,
            1e-7 / 3.0,
            -2.5e13 / 3.0,
            f64::NAN,
        ] {
            let mut direct = String::new();
            crate::format::push_tidy_number(&mut direct, v);
            assert_eq!(direct, crate::format::tidy_csv(&format!("{v}")), "{v}");
        }
        for s in [
            "m.csv",
            "a,-0,b",
            "x,1.0000000000000002,\"q\"",
            ",",
            "plain",
        ] {
            let (mut direct, mut work) = (String::new(), String::new());
            super::push_tidy_quoted(&mut direct, s, &mut work);
            let mut quoted = String::new();
            push_quoted(&mut quoted, s);
            assert_eq!(direct, crate::format::tidy_csv(&quoted), "{s}");
        }
        let mut s = String::new();
        super::push_tidy_quoted(&mut s, "a,-0,b", &mut String::new());
        assert_eq!(s, "\"a,0,b\"");
    }

    #[test]
    fn integers_are_written_as_display_writes_them() {
        for n in [0usize, 1, 9, 10, 99, 100, 12_345, 1_000_000, usize::MAX] {
            let mut s = String::new();
            super::push_integer(&mut s, n);
            assert_eq!(s, n.to_string());
        }
    }

    #[test]
    fn quotes_are_doubled_inside_a_quoted_field() {
        let mut s = String::new();
        push_quoted(&mut s, r#"sensor s1 at pose "3""#);
        assert_eq!(s, r#""sensor s1 at pose ""3""""#);
        s.clear();
        push_quoted(&mut s, "m.csv");
        assert_eq!(s, "\"m.csv\"");
    }
}
