//! Numbers for people: every number in report.md, report.html and the CSV files cpm writes
//! goes through here, so none shows more digits than its uncertainty supports, and none
//! shows as `-0.000`, `3.0000000000000004` or `NaN`.
//!
//! ```
//! use cpm_report::format::{fixed, with_sd};
//! assert_eq!(fixed(-0.00001, 3), "0.000");
//! assert_eq!(fixed(0.1 + 0.2, 3), "0.300");
//! assert_eq!(with_sd(12.34567, 0.0123), ("12.346".to_string(), "0.012".to_string()));
//! ```

/// What is printed for a number that does not exist (not determined, not finite).
pub const NOT_DETERMINED: &str = "n.d.";

/// Most decimals ever printed (beyond this an `f64` has nothing left to say at report scale).
pub const MAX_DECIMALS: usize = 12;

/// `x` with `decimals` decimals; a value that rounds to zero is printed without a sign;
/// a non-finite value as [`NOT_DETERMINED`].
pub fn fixed(x: f64, decimals: usize) -> String {
    if !x.is_finite() {
        return NOT_DETERMINED.to_string();
    }
    let decimals = decimals.min(MAX_DECIMALS);
    let s = format!("{x:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

/// [`fixed`] of an optional value ([`NOT_DETERMINED`] when `None`).
pub fn opt_fixed(x: Option<f64>, decimals: usize) -> String {
    x.map_or_else(|| NOT_DETERMINED.to_string(), |x| fixed(x, decimals))
}

/// The decimals that show a standard deviation `sd` with two significant digits (`None`
/// when `sd` is not a positive finite number).
pub fn decimals_for(sd: f64) -> Option<usize> {
    if !(sd.is_finite() && sd > 0.0) {
        return None;
    }
    let e = sd.log10().floor() as i64;
    // Rounding may carry into the next decade (0.0996 -> 0.10): two digits either way.
    Some((1 - e).clamp(0, MAX_DECIMALS as i64) as usize)
}

/// An estimate and its standard deviation, both rounded to two significant digits of the
/// standard deviation; `fallback` decimals when the deviation is unknown or zero.
pub fn with_sd_or(x: f64, sd: f64, fallback: usize) -> (String, String) {
    let d = decimals_for(sd).unwrap_or(fallback);
    (fixed(x, d), fixed(sd, d))
}

/// [`with_sd_or`] with 3 decimals as the fallback.
pub fn with_sd(x: f64, sd: f64) -> (String, String) {
    with_sd_or(x, sd, 3)
}

/// An optional estimate and optional deviation as table cells ([`NOT_DETERMINED`] for what is
/// missing), rounded as [`with_sd_or`].
pub fn opt_with_sd(x: Option<f64>, sd: Option<f64>, fallback: usize) -> (String, String) {
    let d = sd.and_then(decimals_for).unwrap_or(fallback);
    (opt_fixed(x, d), opt_fixed(sd, d))
}

/// `x` with `digits` significant digits in plain notation (for numbers without a stated
/// uncertainty: residuals, ratios); exponent notation outside 1e-4..1e9.
pub fn sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return NOT_DETERMINED.to_string();
    }
    let digits = digits.clamp(1, 15);
    if x == 0.0 {
        return fixed(0.0, digits - 1);
    }
    let a = x.abs();
    if !(1e-4..1e9).contains(&a) {
        return sci(x, digits);
    }
    let e = a.log10().floor() as i64;
    let d = (digits as i64 - 1 - e).clamp(0, MAX_DECIMALS as i64) as usize;
    fixed(x, d)
}

/// A stated constant (a threshold, a declared clearance) as short as it reads: at most 6
/// significant digits, trailing zeros dropped (`0.02`, `10`, `2.5`).
pub fn short(x: f64) -> String {
    let s = sig(x, 6);
    let (mantissa, exponent) = match s.split_once('e') {
        Some((m, e)) => (m, format!("e{e}")),
        None => (s.as_str(), String::new()),
    };
    let mantissa = if mantissa.contains('.') {
        mantissa.trim_end_matches('0').trim_end_matches('.')
    } else {
        mantissa
    };
    format!("{mantissa}{exponent}")
}

/// `x` in exponent notation with `digits` significant digits (`1.2e-5`); no negative zero.
pub fn sci(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return NOT_DETERMINED.to_string();
    }
    let d = digits.clamp(1, 15) - 1;
    let s = format!("{:.d$e}", if x == 0.0 { 0.0 } else { x });
    s
}

/// A p-value: two significant digits in exponent notation, `< 1e-300` below that.
pub fn p_value(p: f64) -> String {
    if !p.is_finite() {
        NOT_DETERMINED.to_string()
    } else if p < 1e-300 {
        "< 1e-300".to_string()
    } else {
        sci(p, 2)
    }
}

/// `yes` / `no` for a flag in user text (never `true`/`false`).
pub fn yes_no(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}

/// A CSV text as cpm writes it for people and controllers: a numeric field that is a
/// negative zero (`-0.000`) loses its sign, and one with more than 12 significant digits
/// (`3.0000000000000004`, `331.739672003852`) is rounded to 12 significant digits (1e-9 mm
/// on a length of 1 m, far below any uncertainty of a length in mm or an angle in deg). Other fields,
/// comments (`#` lines) and the line structure are kept.
pub fn tidy_csv(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.split_inclusive('\n') {
        tidy_csv_line_into(line, &mut out);
    }
    out
}

/// [`tidy_csv`] of one line (with or without its `\n`), appended to `out`: the way to tidy a
/// CSV text while it is written, without a copy of it or a string per field.
pub fn tidy_csv_line_into(line: &str, out: &mut String) {
    let (body, end) = match line.strip_suffix('\n') {
        Some(b) => (b, "\n"),
        None => (line, ""),
    };
    if body.starts_with('#') {
        out.push_str(line);
        return;
    }
    for (i, f) in body.split(',').enumerate() {
        if i > 0 {
            out.push(',');
        }
        tidy_field_into(f, out);
    }
    out.push_str(end);
}

/// One field of [`tidy_csv`] (a piece of a line between commas), appended to `out`.
fn tidy_field_into(f: &str, out: &mut String) {
    let t = f.trim_end_matches('\r');
    let cr = &f[t.len()..];
    let numeric = !t.is_empty()
        && t.bytes()
            .all(|b| b.is_ascii_digit() || matches!(b, b'-' | b'+' | b'.' | b'e' | b'E'));
    let Some(v) = numeric.then(|| t.parse::<f64>().ok()).flatten() else {
        out.push_str(f);
        return;
    };
    if v == 0.0 && t.starts_with('-') {
        out.push_str(&t[1..]);
        out.push_str(cr);
        return;
    }
    if significant_digits(t) > 12 && v.is_finite() {
        push_twelve_digits(out, v);
        out.push_str(cr);
        return;
    }
    out.push_str(f);
}

/// The significant digits of a number as written (its mantissa without leading zeros).
fn significant_digits(t: &str) -> usize {
    t.split(['e', 'E'])
        .next()
        .unwrap_or("")
        .trim_start_matches(['-', '+', '0', '.'])
        .bytes()
        .filter(u8::is_ascii_digit)
        .count()
}

/// A finite `v` rounded to 12 significant digits, as [`tidy_csv`] writes it, appended.
fn push_twelve_digits(out: &mut String, v: f64) {
    use std::fmt::Write as _;
    let a = v.abs();
    // Writing into a String cannot fail.
    if (1e-4..1e12).contains(&a) {
        let e = a.log10().floor() as i64;
        let d = (11 - e).clamp(0, 17) as usize;
        let start = out.len();
        let _ = write!(out, "{v:.d$}");
        if out[start..].contains('.') {
            let kept = out[start..]
                .trim_end_matches('0')
                .trim_end_matches('.')
                .len();
            out.truncate(start + kept);
        }
    } else {
        let _ = write!(out, "{v:.11e}");
    }
}

/// The field `{v}` as [`tidy_csv`] leaves it (negative zero unsigned, more than 12
/// significant digits rounded), appended to `out`, without reading the number back.
pub(crate) fn push_tidy_number(out: &mut String, v: f64) {
    use std::fmt::Write as _;
    if push_rounded_twelve(out, v) {
        return;
    }
    let start = out.len();
    // Writing into a String cannot fail; a finite f64 is written in digits, `-` and `.`.
    let _ = write!(out, "{v}");
    if !v.is_finite() {
        return;
    }
    if v == 0.0 {
        if out[start..].starts_with('-') {
            out.remove(start);
        }
    } else if significant_digits(&out[start..]) > 12 {
        out.truncate(start);
        push_twelve_digits(out, v);
    }
}

/// [`push_tidy_number`] of the common case made without formatting the number twice: a
/// number of [1e-4, 1e12) in magnitude whose shortest form has more than 12 significant
/// digits, rounded to 12 as [`push_twelve_digits`] rounds it (the decimals it gives, trailing
/// zeros left out) from the integer of its 12 digits. False (nothing written) for any other
/// number, and when the rounding is not certain in binary (within 1e-3 of a tie): the general
/// way writes it.
fn push_rounded_twelve(out: &mut String, v: f64) -> bool {
    const POW10: [f64; 16] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
    ];
    let a = v.abs();
    if !(1e-4..1e12).contains(&a) {
        return false;
    }
    // The decimals of `push_twelve_digits` (at most 15 in this range).
    let e = a.log10().floor() as i64;
    let d = (11 - e).clamp(0, 17) as usize;
    let Some(&scale) = POW10.get(d) else {
        return false;
    };
    // a * 10^d is below 1e13: its one rounding error is below 1e-3.
    let x = a * scale;
    let r = x.round();
    if ((x - x.floor()) - 0.5).abs() < 1e-3 || !(1e10..=1e13).contains(&r) {
        return false;
    }
    let n = r as u64;
    // Its 12 digits read back as the number: the shortest form has 12 digits or fewer, and
    // the number is written as it is (the general way).
    if n as f64 / scale == a {
        return false;
    }
    let mut buf = itoa::Buffer::new();
    let digits: &str = buf.format(n);
    let len = digits.len();
    if v < 0.0 {
        out.push('-');
    }
    // Integer part, then the `d` decimals without their trailing zeros.
    if len > d {
        out.push_str(&digits[..len - d]);
        let decimals = digits[len - d..].trim_end_matches('0');
        if !decimals.is_empty() {
            out.push('.');
            out.push_str(decimals);
        }
    } else {
        out.push('0');
        // The decimals are `d - len` zeros, then the digits.
        let decimals = digits.trim_end_matches('0');
        if !decimals.is_empty() {
            out.push('.');
            out.extend(std::iter::repeat_n('0', d - len));
            out.push_str(decimals);
        }
    }
    true
}

/// The artefacts no user text may contain: a negative zero, a float printed at full
/// precision (`3.0000000000000004`, `0.30000000000000004`), `NaN`/`inf`. Returns the first
/// offending token found in `text`, for tests and checks.
pub fn find_artefact(text: &str) -> Option<String> {
    for raw in text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '-')) {
        let tok = raw.trim_end_matches('.');
        if tok.is_empty() {
            continue;
        }
        if tok == "NaN" || tok == "inf" || tok == "-inf" {
            return Some(tok.to_string());
        }
        let Ok(v) = tok.parse::<f64>() else {
            continue;
        };
        if tok.starts_with('-') && v == 0.0 {
            return Some(tok.to_string());
        }
        // Significant digits: leading zeros do not count.
        let digits = tok
            .split(['e', 'E'])
            .next()
            .unwrap_or("")
            .trim_start_matches(['-', '+', '0', '.'])
            .chars()
            .filter(char::is_ascii_digit)
            .count();
        if digits >= 16 && tok.contains('.') {
            return Some(tok.to_string());
        }
    }
    None
}

/// The value when it is finite (`None` for NaN and infinities: written `null` in JSON).
pub(crate) fn finite(v: Option<f64>) -> Option<f64> {
    v.filter(|x| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The tidy number written the general way (shortest form, then rounded to 12 digits
    /// when longer), for comparison with the direct rounding.
    fn tidy_the_general_way(v: f64) -> String {
        use std::fmt::Write as _;
        let mut out = String::new();
        let _ = write!(out, "{v}");
        if v.is_finite() && v != 0.0 && significant_digits(&out) > 12 {
            out.clear();
            push_twelve_digits(&mut out, v);
        }
        out
    }

    proptest! {
        /// The direct rounding of 12 digits writes what formatting twice writes.
        #[test]
        fn rounding_twelve_digits_directly_is_formatting_twice(
            m in -1.0f64..1.0,
            e in -6i32..14,
        ) {
            let v = m * 10f64.powi(e);
            let mut direct = String::new();
            push_tidy_number(&mut direct, v);
            prop_assert_eq!(direct, tidy_the_general_way(v));
        }
    }

    #[test]
    fn rounding_twelve_digits_directly_at_the_edges() {
        let mut cases = vec![
            0.1 + 0.2,
            1.0 / 3.0,
            -2.0 / 3.0,
            999_999_999_999.9,
            99.999_999_999_999,
            9.999_999_999_995,
            0.000_100_000_000_000_01,
            0.000_099_999_999_999_999,
            123_456_789_012.345,
            1e-4,
            1e12 - 0.5,
            -331.739_672_003_852_1,
        ];
        let mut x = 0.123_456_789_012_345_6f64;
        for _ in 0..20_000 {
            x = (x * 7.3 + 0.1).fract();
            cases.push((x - 0.5) * 10f64.powi((x * 1e6) as i32 % 17 - 5));
        }
        for v in cases {
            let mut direct = String::new();
            push_tidy_number(&mut direct, v);
            assert_eq!(direct, tidy_the_general_way(v), "{v:e}");
        }
    }

    #[test]
    fn negative_zero_is_unsigned() {
        assert_eq!(fixed(-0.0, 3), "0.000");
        assert_eq!(fixed(-0.0004, 3), "0.000");
        assert_eq!(fixed(-0.0005001, 3), "-0.001");
        assert_eq!(fixed(-0.4, 0), "0");
        assert_eq!(sig(-0.0, 3), "0.00");
        assert_eq!(sci(-0.0, 2), "0.0e0");
    }

    #[test]
    fn float_noise_is_rounded_away() {
        assert_eq!(fixed(0.1 + 0.2, 3), "0.300");
        assert_eq!(sig(3.0000000000000004, 3), "3.00");
        assert_eq!(sig(0.000123456, 2), "0.00012");
        assert_eq!(sig(1234.6, 3), "1235");
        assert_eq!(sig(2.5e-7, 2), "2.5e-7");
        assert_eq!(fixed(f64::NAN, 3), NOT_DETERMINED);
        assert_eq!(opt_fixed(None, 3), NOT_DETERMINED);
    }

    #[test]
    fn estimates_are_rounded_to_their_deviation() {
        assert_eq!(with_sd(12.34567, 0.0123), ("12.346".into(), "0.012".into()));
        assert_eq!(with_sd(12.34567, 1.5), ("12.3".into(), "1.5".into()));
        assert_eq!(with_sd(1234.5, 23.0), ("1234".into(), "23".into()));
        assert_eq!(with_sd(-0.0001, 0.02), ("0.000".into(), "0.020".into()));
        assert_eq!(with_sd_or(1.23456, 0.0, 2), ("1.23".into(), "0.00".into()));
        assert_eq!(
            opt_with_sd(Some(1.0), None, 1),
            ("1.0".into(), NOT_DETERMINED.into())
        );
        assert_eq!(decimals_for(0.0996), Some(3));
        assert_eq!(decimals_for(-1.0), None);
    }

    #[test]
    fn constants_read_short() {
        assert_eq!(short(0.02), "0.02");
        assert_eq!(short(10.0), "10");
        assert_eq!(short(0.1 + 0.2), "0.3");
        assert_eq!(short(-0.0), "0");
        assert_eq!(short(1.5e-7), "1.5e-7");
    }

    #[test]
    fn p_values() {
        assert_eq!(p_value(0.0), "< 1e-300");
        assert_eq!(p_value(0.01234), "1.2e-2");
        assert_eq!(yes_no(true), "yes");
    }

    #[test]
    fn artefacts_are_found() {
        assert_eq!(find_artefact("rms -0.000 um"), Some("-0.000".into()));
        assert_eq!(
            find_artefact("x = 3.0000000000000004."),
            Some("3.0000000000000004".into())
        );
        assert_eq!(find_artefact("| NaN |"), Some("NaN".into()));
        assert_eq!(find_artefact("link-0 at -0.5 um, p 1.2e-5, s1"), None);
        assert_eq!(find_artefact("2026-11-23 file_0.csv"), None);
    }

    #[test]
    fn csv_is_tidied_field_by_field() {
        let t = "# note -0.000 kept\npose,x_mm,s1\n1,-0.000000000,3.0000000000000004\n2,-0.5,s-0\n3,320.27761321306946,0.1\r\n";
        assert_eq!(
            tidy_csv(t),
            "# note -0.000 kept\npose,x_mm,s1\n1,0.000000000,3\n2,-0.5,s-0\n3,320.277613213,0.1\r\n"
        );
        assert_eq!(tidy_csv("a,b"), "a,b");
    }

    proptest! {
        #[test]
        fn tidy_csv_keeps_values_to_twelve_digits(x in prop_oneof![-1e6f64..1e6, -1e-3f64..1e-3]) {
            let field = format!("{x}");
            let t = tidy_csv(&format!("{field},{field}\n"));
            let back: f64 = t.trim_end().split(',').next().unwrap().parse().unwrap();
            prop_assert!((back - x).abs() <= x.abs() * 1e-11, "{x} -> {t}");
            prop_assert!(find_artefact(&t).is_none(), "{t}");
        }

        #[test]
        fn fixed_never_prints_negative_zero_and_round_trips(
            x in prop_oneof![-1e6f64..1e6, -1e-3f64..1e-3, Just(-0.0)],
            d in 0usize..10,
        ) {
            let s = fixed(x, d);
            let back: f64 = s.parse().unwrap();
            prop_assert!(!(s.starts_with('-') && back == 0.0), "{s}");
            prop_assert!(find_artefact(&s).is_none(), "{s}");
            let tol = 0.5 * 10f64.powi(-(d as i32)) + x.abs() * 1e-15;
            prop_assert!((back - x).abs() <= tol, "{x} -> {s}");
        }

        #[test]
        fn estimates_round_trip_within_a_twentieth_of_their_deviation(
            x in -1e6f64..1e6,
            sd in prop_oneof![1e-6f64..1e-3, 1e-3f64..1e3],
        ) {
            let (v, s) = with_sd(x, sd);
            let (bv, bs): (f64, f64) = (v.parse().unwrap(), s.parse().unwrap());
            prop_assert!(!(v.starts_with('-') && bv == 0.0), "{v}");
            prop_assert!((bv - x).abs() <= sd / 20.0 + x.abs() * 1e-15, "{x} +- {sd} -> {v}");
            prop_assert!((bs - sd).abs() <= sd / 20.0 + 1e-12, "{sd} -> {s}");
            // Two significant digits of the deviation (three when rounding carried).
            let sig_digits = s.trim_start_matches(['0', '.']).chars().filter(char::is_ascii_digit).count();
            prop_assert!((2..=3).contains(&sig_digits) || bs >= 10.0, "{sd} -> {s}");
        }

        #[test]
        fn sig_round_trips_relatively(x in prop_oneof![-1e8f64..1e8, -1e-2f64..1e-2], n in 1usize..8) {
            let s = sig(x, n);
            let back: f64 = s.parse().unwrap();
            prop_assert!(!(s.starts_with('-') && back == 0.0), "{s}");
            prop_assert!((back - x).abs() <= x.abs() * 0.5 * 10f64.powi(1 - n as i32) + 1e-12, "{x} -> {s}");
        }
    }
}
