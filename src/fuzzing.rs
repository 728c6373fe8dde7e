//! Entry points for fuzzing: the robot description reader, the CSV readers and the
//! calibration pipeline of `cpm calibrate`, each taking arbitrary bytes.
//!
//! The cargo-fuzz targets in `fuzz/` call these, and so do the ordinary tests
//! (`tests/fuzz_corpus.rs`, replaying the corpus kept in `fuzz/corpus/` and mutating valid
//! files at random), so CI needs no fuzzer. Each function returns normally whatever the bytes
//! are, and panics only when `cpm` breaks a promise: a panic inside `cpm`, an error that does
//! not name the file, a line number outside the file, an unbounded message, a valid robot
//! description that does not survive a round trip, or a calibration whose outputs are
//! malformed.
use std::path::Path;
use std::sync::OnceLock;

use crate::calib::IdentifyOptions;
use crate::cli::calibrate::{fit, Inputs};
use crate::geometry::RobotDescription;
use crate::io::{self, InputError, Provenance, ReadError, ReadOptions, Robot};

/// The file name the fuzzed bytes go by in messages.
pub const FILE: &str = "fuzz.csv";

/// The most rows the calibration target reads (a bounded amount of work per input).
pub const CALIBRATE_MAX_ROWS: usize = 60;

fn robots() -> &'static [Robot; 2] {
    static ROBOTS: OnceLock<[Robot; 2]> = OnceLock::new();
    ROBOTS.get_or_init(|| {
        [
            Robot::from_description(RobotDescription::paper_cubic(), "paper_cubic.toml")
                .expect("the paper's cube loads"),
            Robot::from_description(RobotDescription::hexapod_66(), "hexapod_66.toml")
                .expect("the hexapod loads"),
        ]
    })
}

/// Checks the promises of an input error about `data` read as `file`.
pub fn check_input_error(e: &InputError, file: &str, data: &[u8]) {
    assert_eq!(e.file, file, "the error names another file: {e}");
    assert!(!e.message.trim().is_empty(), "an empty message: {e:?}");
    let lines = data.iter().filter(|b| **b == b'\n').count() + 1;
    if let Some(l) = e.line {
        assert!(l >= 1 && l <= lines, "line {l} of a {lines}-line file: {e}");
    }
    if let Some(f) = &e.field {
        assert!(!f.trim().is_empty(), "an empty field name: {e:?}");
    }
    let shown = e.to_string();
    assert!(
        shown.len() <= 2000,
        "a {}-byte message: {shown:.300}",
        shown.len()
    );
}

fn check_read_error(e: &ReadError, file: &str, data: &[u8]) {
    match e {
        ReadError::Input(e) => check_input_error(e, file, data),
        ReadError::Io { .. } => panic!("an I/O error reading memory: {e}"),
    }
}

/// A robot description from arbitrary bytes: either it loads, and then it survives a round
/// trip through TOML and gives a measurement model, or the error names `robot.toml`, a line
/// within the file and, where there is one, the key.
pub fn robot_toml(data: &[u8]) {
    const FILE: &str = "robot.toml";
    let Ok(text) = std::str::from_utf8(data) else {
        return; // `cpm::io::read_text` refuses it before the parser (tested elsewhere)
    };
    match Robot::from_toml(text, FILE) {
        Err(e) => check_input_error(&e, FILE, data),
        Ok(robot) => {
            let again = robot
                .description
                .to_toml_string()
                .expect("a loaded description serializes");
            let back = Robot::from_toml(&again, FILE)
                .unwrap_or_else(|e| panic!("a loaded description does not load back: {e}"));
            assert_eq!(back.description, robot.description, "round trip");
            if let Ok(effects) = robot.declared_effects() {
                let model = robot.model(&effects);
                // What the loader accepted, the calibration crate accepts too.
                model
                    .check_known_effects()
                    .unwrap_or_else(|e| panic!("loaded known effects refused by the model: {e}"));
            }
        }
    }
}

/// Every CSV reader over arbitrary bytes: measurement files against the paper's cube and the
/// hexapod, pose lists and candidate sockets. Errors must name the file and a line within it.
pub fn csv_readers(data: &[u8]) {
    for robot in robots() {
        match crate::workflow::ingest::read_data_from(
            data,
            FILE,
            robot,
            &ReadOptions::default(),
            &Default::default(),
        ) {
            Err(e) => check_read_error(&e, FILE, data),
            Ok(f) => {
                let c = &f.campaign;
                assert!(!c.is_empty(), "an empty campaign was accepted");
                assert_eq!(f.pose_lines.len(), c.poses.len());
                assert_eq!(f.reading_lines.len(), c.readings.len());
                assert!(c.poses.iter().all(|p| p.is_finite()));
                assert!(c.readings.iter().all(|r| r.length_mm.is_finite()));
            }
        }
    }
    match io::read_pose_list_from(data, FILE) {
        Err(e) => check_read_error(&e, FILE, data),
        Ok(rows) => assert!(!rows.is_empty() && rows.iter().all(|r| r.pose.is_finite())),
    }
    if let Err(e) = crate::cli::design::read_sockets_from(data, FILE) {
        check_read_error(&e, FILE, data);
    }
}

/// The calibration of `cpm calibrate` on arbitrary measurement bytes with the hexapod: read
/// (at most [`CALIBRATE_MAX_ROWS`] rows), fit (a least-squares, Huber or Cauchy loss chosen by
/// the input's length) and stage every output in memory. Either it fails with a typed error
/// whose message is not empty, or the outputs are complete and well formed.
pub fn calibrate(data: &[u8]) {
    let robot = &robots()[1];
    let options = ReadOptions {
        max_rows: CALIBRATE_MAX_ROWS,
        ..ReadOptions::default()
    };
    let file = match crate::workflow::ingest::read_data_from(
        data,
        FILE,
        robot,
        &options,
        &Default::default(),
    ) {
        Ok(f) => f,
        Err(e) => return check_read_error(&e, FILE, data),
    };
    let mut identify = IdentifyOptions::default();
    identify.lm.loss = match data.len() % 3 {
        0 => cpm_lm::Loss::Squared,
        1 => cpm_lm::Loss::Huber(3.0),
        _ => cpm_lm::Loss::Cauchy(3.0),
    };
    identify.lm.max_iterations = 50;
    let inputs = Inputs {
        model: robot.model(&[]),
        merged: io::merge(vec![file], robot).into(),
        identify,
        provenance: Provenance {
            robot: robot.file.clone(),
            data: vec![FILE.into()],
        },
        robot: robot.clone(),
        // In memory: no file to read the calibrated description back on.
        data_paths: Vec::new(),
    };
    match fit(&inputs, Path::new("out"), false) {
        Err(e) => {
            let shown = format!("{e:#}");
            assert!(!shown.trim().is_empty());
            let _ = crate::cli::exit_kind(&e);
        }
        Ok(f) => {
            let np = inputs.model.num_params();
            assert_eq!(f.cal.estimate_um.len(), np);
            assert_eq!(f.cal.std_um.len(), np);
            assert_eq!(f.cal.residuals_um.len(), inputs.merged.campaign.len());
            for k in &f.cal.outliers {
                assert!(*k < f.cal.residuals_um.len());
            }
            let names: Vec<_> = f
                .set
                .paths()
                .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
                .collect();
            for want in ["calibration.json", "report.md", "calibrated.toml"] {
                assert!(names.iter().any(|n| n == want), "{want} missing: {names:?}");
            }
            let json = f.report.json().expect("calibration.json serializes");
            let back: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
            assert_eq!(
                back["outliers"].as_array().map(Vec::len),
                Some(f.cal.outliers.len())
            );
        }
    }
}
