//! The fuzz corpus, replayed without a fuzzer, and a small random-mutation fuzzer that runs
//! in the ordinary test suite.
//!
//! `fuzz/corpus/<target>/` holds the inputs of the cargo-fuzz targets (seeds, what fuzzing
//! found interesting, and `regression-*` inputs that once broke a promise); each is fed to the
//! same entry point as the target, `cpm::fuzzing::<target>`, which panics when `cpm` panics or
//! gives an error that does not name the file and a line within it. The mutation test changes
//! valid files byte-wise (seeded, so a failure reproduces) and asks the same.
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn corpus(target: &str) -> Vec<PathBuf> {
    let dir = root().join("fuzz/corpus").join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file() && p.file_name().is_some_and(|n| n != ".gitattributes"))
        .collect();
    files.sort();
    files
}

/// Runs `f` on `data`; a panic fails the test naming the input.
fn run(what: &str, f: fn(&[u8]), data: &[u8]) {
    if let Err(panic) = catch_unwind(AssertUnwindSafe(|| f(data))) {
        let msg = panic
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default();
        panic!(
            "{what}: {msg}\ninput ({} bytes): {:?}",
            data.len(),
            String::from_utf8_lossy(&data[..data.len().min(2000)])
        );
    }
}

fn replay(target: &str, f: fn(&[u8])) -> usize {
    let files = corpus(target);
    assert!(!files.is_empty(), "no corpus for {target}");
    for p in &files {
        run(&p.display().to_string(), f, &std::fs::read(p).unwrap());
    }
    files.len()
}

#[test]
fn corpus_robot_toml() {
    assert!(replay("robot_toml", cpm::fuzzing::robot_toml) >= 10);
}

#[test]
fn corpus_csv_readers() {
    assert!(replay("csv_readers", cpm::fuzzing::csv_readers) >= 10);
}

#[test]
fn corpus_calibrate() {
    assert!(replay("calibrate", cpm::fuzzing::calibrate) >= 5);
}

/// Bytes that matter to the formats: separators, quotes, comments, line ends, signs, digits,
/// exponents, the letters of nan and inf, a byte that is not UTF-8, TOML brackets.
const INTERESTING: &[u8] = b",\n\r\"#-+.0123456789eEnaifNI\xff[]=' \t";

/// Replacements for a number: what instruments and spreadsheets write.
const NUMBERS: &[&str] = &[
    "NaN", "inf", "-inf", "1e308", "-1e308", "1e-320", "0", "-0", "", "1,5", "0x10", "1e999",
    "354000", "0.354", "  7  ", "\"3\"",
];

fn mutate(rng: &mut StdRng, seed: &[u8]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        let n = v.len().max(1);
        match rng.random_range(0..8) {
            0 => {
                let i = rng.random_range(0..n);
                if i < v.len() {
                    v[i] = INTERESTING[rng.random_range(0..INTERESTING.len())];
                }
            }
            1 => {
                let i = rng.random_range(0..=v.len());
                v.insert(i, INTERESTING[rng.random_range(0..INTERESTING.len())]);
            }
            2 => {
                let i = rng.random_range(0..n);
                let j = (i + rng.random_range(1..40)).min(v.len());
                if i < j {
                    v.drain(i..j);
                }
            }
            3 => {
                let keep = rng.random_range(0..=v.len());
                v.truncate(keep);
            }
            4 => {
                // Replace a number by something an instrument or a spreadsheet writes.
                let text = String::from_utf8_lossy(&v).into_owned();
                let starts: Vec<usize> = text
                    .char_indices()
                    .filter(|(i, c)| {
                        (c.is_ascii_digit() || *c == '-')
                            && (*i == 0 || matches!(text.as_bytes()[i - 1], b',' | b' ' | b'['))
                    })
                    .map(|(i, _)| i)
                    .collect();
                if let Some(&s) = starts.get(rng.random_range(0..starts.len().max(1))) {
                    let e = text[s..]
                        .find([',', '\n', ']', ' '])
                        .map_or(text.len(), |k| s + k);
                    let r = NUMBERS[rng.random_range(0..NUMBERS.len())];
                    v = format!("{}{r}{}", &text[..s], &text[e..]).into_bytes();
                }
            }
            5 => {
                // Duplicate or drop a line.
                let text = String::from_utf8_lossy(&v).into_owned();
                let mut lines: Vec<&str> = text.split('\n').collect();
                let i = rng.random_range(0..lines.len());
                if rng.random_bool(0.5) {
                    lines.insert(i, lines[i]);
                } else {
                    lines.remove(i);
                }
                v = lines.join("\n").into_bytes();
            }
            6 => {
                // CRLF line endings, or a byte-order mark.
                if rng.random_bool(0.5) {
                    v = String::from_utf8_lossy(&v)
                        .replace('\n', "\r\n")
                        .into_bytes();
                } else {
                    v.splice(0..0, *b"\xEF\xBB\xBF");
                }
            }
            _ => {
                let i = rng.random_range(0..n);
                if i < v.len() {
                    v[i] = rng.random();
                }
            }
        }
    }
    v
}

fn fuzz(seeds: &[Vec<u8>], f: fn(&[u8]), what: &str, rounds: usize, seed: u64) {
    let mut rng = StdRng::seed_from_u64(seed);
    for k in 0..rounds {
        let s = &seeds[k % seeds.len()];
        let input = mutate(&mut rng, s);
        run(&format!("{what}, mutation {k} (seed {seed})"), f, &input);
    }
}

fn read(p: &str) -> Vec<u8> {
    std::fs::read(root().join(p)).unwrap()
}

#[test]
fn mutated_robot_descriptions_give_located_errors() {
    let seeds = vec![
        read("examples/paper_cubic.toml"),
        read("examples/hexapod_66.toml"),
        read("fuzz/corpus/robot_toml/seed-known-effects.toml"),
    ];
    fuzz(&seeds, cpm::fuzzing::robot_toml, "robot_toml", 3000, 1);
}

#[test]
fn mutated_measurement_files_give_located_errors() {
    let seeds = vec![
        read("tests/data/malformed/good.csv"),
        read("fuzz/corpus/calibrate/seed-hexapod-readings.csv"),
        read("fuzz/corpus/calibrate/seed-hexapod-tracker.csv"),
        b"pose,x_mm,y_mm,z_mm,qw,qx,qy,qz,time_s\n1,0,0,410,1,0,0,0,0\n2,10,0,410,1,0,0,0,1\n"
            .to_vec(),
    ];
    fuzz(&seeds, cpm::fuzzing::csv_readers, "csv_readers", 3000, 2);
}

#[test]
fn mutated_campaigns_calibrate_or_fail_cleanly() {
    let seeds = vec![
        read("fuzz/corpus/calibrate/seed-hexapod-readings.csv"),
        read("fuzz/corpus/calibrate/seed-hexapod-tracker.csv"),
    ];
    fuzz(&seeds, cpm::fuzzing::calibrate, "calibrate", 60, 3);
}
