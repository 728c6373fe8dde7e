//! Malformed inputs, run through the `cpm` binary: each case asserts the exit code, the exact
//! start of the message (`error: FILE:LINE: field NAME: what`), the typed error of the library
//! reader (line and field of the `InputError`) and that the output directory, which holds a
//! previous run's results, is byte for byte what it was. The files are in
//! `tests/data/malformed/` (see its README.md). Also: inputs that look odd but are fine (CRLF,
//! a byte-order mark, pose-label gaps, blank lines), streaming of huge inputs, a solver that
//! does not converge, a rank-deficient fit, an outlier reading and a failure while writing.
#[path = "common/ingest.rs"]
mod ingest;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use cpm::io::{ReadError, ReadOptions, Robot};
use ingest::{read_data_file, read_data_from};

const DIR: &str = "tests/data/malformed";
const CUBE: &str = "examples/paper_cubic.toml";
const HEXAPOD: &str = "examples/hexapod_66.toml";
const GOOD: &str = "tests/data/malformed/good.csv";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `cpm` in the package folder, so that files are named as in the table.
fn cpm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpm"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("run cpm")
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("malformed-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Every file under `dir` (recursively) with its contents.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p.clone());
                out.insert(p, Vec::new());
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// A previous run's results in a fresh folder.
fn previous_results(name: &str) -> (PathBuf, BTreeMap<PathBuf, Vec<u8>>) {
    let out = scratch(name).join("cal");
    let o = cpm(&[
        "calibrate",
        "--robot",
        CUBE,
        "--data",
        GOOD,
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let snap = snapshot(&out);
    assert!(snap.len() >= 5, "{snap:?}");
    (out, snap)
}

/// Which command a file case runs, and with what.
#[derive(Debug, Clone, Copy, PartialEq)]
enum On {
    /// `calibrate --robot paper_cubic.toml --data FILE`.
    Data,
    /// `calibrate --robot hexapod_66.toml --data FILE` (tracker files).
    Tracker,
    /// `calibrate --robot FILE --data good.csv`.
    Toml,
    /// `calibrate --robot FILE --data good.csv`, the error in good.csv.
    RobotThenData,
    /// `compensate --robot paper_cubic.toml --poses FILE --out OUT/commands.csv`.
    Poses,
}

/// One malformed file: where it goes, the exit code, the line and field the message names
/// and the start of what it says.
struct Case {
    file: &'static str,
    on: On,
    code: i32,
    line: Option<usize>,
    field: Option<&'static str>,
    what: &'static str,
}

const fn case(
    file: &'static str,
    on: On,
    line: Option<usize>,
    field: Option<&'static str>,
    what: &'static str,
) -> Case {
    Case {
        file,
        on,
        code: 3,
        line,
        field,
        what,
    }
}

use On::*;

/// The table: every case exits 3 (bad input file).
const CASES: &[Case] = &[
    // Empty and truncated files.
    case(
        "empty.csv",
        Data,
        None,
        None,
        "no header row: the file is empty",
    ),
    case("comments_only.csv", Data, None, None, "no header row"),
    case(
        "header_only.csv",
        Data,
        None,
        None,
        "no readings: the file has a header but no rows",
    ),
    case(
        "truncated_row.csv",
        Data,
        Some(3),
        None,
        "5 fields, but the header has 9",
    ),
    // Numbers: NaN, infinities, typos, a decimal comma, missing cells.
    case(
        "nan_length.csv",
        Data,
        Some(3),
        Some("length_mm"),
        "\"NaN\" is not a finite number",
    ),
    case(
        "inf_position.csv",
        Data,
        Some(2),
        Some("x_mm"),
        "\"inf\" is not a finite number",
    ),
    case(
        "neg_inf_time.csv",
        Data,
        Some(3),
        Some("time_s"),
        "\"-inf\" is not a finite number",
    ),
    case(
        "nan_temperature.csv",
        Data,
        Some(2),
        Some("temperature_c"),
        "\"nan\" is not a finite number",
    ),
    case(
        "not_a_number.csv",
        Data,
        Some(2),
        Some("length_mm"),
        "\"3O9.9\" is not a number",
    ),
    case(
        "comma_decimal.csv",
        Data,
        Some(2),
        None,
        "10 fields, but the header has 9",
    ),
    case(
        "missing_value.csv",
        Data,
        Some(2),
        Some("z_mm"),
        "missing value",
    ),
    case(
        "empty_pose_label.csv",
        Data,
        Some(3),
        Some("pose"),
        "missing value",
    ),
    case(
        "bad_boolean.csv",
        Data,
        Some(2),
        Some("simulated"),
        "\"maybe\" is not a boolean",
    ),
    // Header problems.
    case(
        "no_sensor_column.csv",
        Data,
        Some(1),
        Some("sensor"),
        "missing column",
    ),
    case(
        "unknown_column.csv",
        Data,
        Some(1),
        Some("humidity"),
        "unknown column",
    ),
    case(
        "duplicate_column.csv",
        Data,
        Some(1),
        Some("x_mm"),
        "the column appears twice",
    ),
    case(
        "unnamed_column.csv",
        Data,
        Some(1),
        None,
        "column 3 of the header has no name",
    ),
    case(
        "both_orientations.csv",
        Data,
        Some(1),
        None,
        "give the orientation either",
    ),
    case(
        "partial_quaternion.csv",
        Data,
        Some(1),
        Some("qz"),
        "missing column",
    ),
    case(
        "reading_column_gap.csv",
        Data,
        Some(1),
        Some("reading_2"),
        "missing column",
    ),
    case(
        "reading_column_extra.csv",
        Data,
        Some(1),
        Some("reading_7"),
        "unknown column",
    ),
    case(
        "pose_list_as_data.csv",
        Data,
        Some(1),
        None,
        "this is a list of poses",
    ),
    case(
        "unknown_kind.csv",
        Data,
        Some(1),
        None,
        "cannot tell what this file holds",
    ),
    // Encoding and quoting.
    case(
        "not_utf8.csv",
        Data,
        Some(3),
        Some("sensor"),
        "not UTF-8 text",
    ),
    case(
        "unclosed_quote.csv",
        Data,
        Some(2),
        Some("pose"),
        "a quote is not closed",
    ),
    case(
        "text_after_quote.csv",
        Data,
        Some(2),
        Some("pose"),
        "text after the closing quote",
    ),
    // Against the robot: sensors, poses, units.
    case(
        "unknown_sensor.csv",
        Data,
        Some(3),
        Some("sensor"),
        "unknown sensor \"ballbar\" (the robot description has: paper)",
    ),
    case(
        "duplicate_pose_id.csv",
        Data,
        Some(4),
        Some("z_mm"),
        "411 differs from 410 given for pose \"1\" on line 2",
    ),
    case(
        "link_readings_differ.csv",
        Data,
        Some(3),
        Some("reading_3"),
        "354.5 differs from 354 given for pose \"1\" on line 2",
    ),
    case(
        "unreachable_pose.csv",
        Data,
        Some(3),
        None,
        "pose \"2\" (x 0 mm, y 0 mm, z 41 mm",
    ),
    case(
        "singular_pose.csv",
        Data,
        Some(3),
        None,
        "pose \"2\" (x 0 mm, y 0 mm, z 410 mm, roll 89.0000 deg",
    ),
    case(
        "pose_in_metres.csv",
        Data,
        Some(2),
        Some("z_mm"),
        "the position (0, 0, 0.41) is 0.4100 mm from the base origin while the robot's home is 410.0 mm away: metres?",
    ),
    case(
        "length_in_metres.csv",
        Data,
        Some(2),
        Some("length_mm"),
        "0.3099 mm is far from the nominal length of sensor \"paper\"",
    ),
    case(
        "link_readings_in_metres.csv",
        Data,
        Some(2),
        Some("reading_1"),
        "0.354 means a link length of 0.354 mm",
    ),
    case(
        "angle_out_of_range.csv",
        Data,
        Some(2),
        Some("roll_deg"),
        "400 degrees",
    ),
    case(
        "implausible_position.csv",
        Data,
        Some(2),
        Some("x_mm"),
        "1e9 mm is implausibly far",
    ),
    // Tracker pose measurements (hexapod).
    case(
        "tracker_duplicate_pose.csv",
        Tracker,
        Some(4),
        Some("pose"),
        "pose \"1\" appears again (first on line 2)",
    ),
    case(
        "tracker_not_unit_quaternion.csv",
        Tracker,
        Some(2),
        Some("qw"),
        "(qw, qx, qy, qz) = (2, 0, 0, 0) is not a unit quaternion",
    ),
    case(
        "tracker_reading_in_metres.csv",
        Tracker,
        Some(3),
        Some("reading_1"),
        "0.32196873952679034 means a link length of 0.322 mm",
    ),
    case(
        "tracker_five_readings.csv",
        Tracker,
        Some(1),
        Some("reading_6"),
        "missing column",
    ),
    // Pose lists (compensate --poses).
    case(
        "pose_in_metres_targets.csv",
        Poses,
        Some(3),
        Some("z_mm"),
        "the position (0, 0, 0.41) is 0.4100 mm from the base origin while the robot's home is 410.0 mm away: metres?",
    ),
    case(
        "nan_targets.csv",
        Poses,
        Some(2),
        Some("yaw_deg"),
        "\"nan\" is not a finite number",
    ),
    // Robot descriptions.
    case(
        "robot_syntax_error.toml",
        Toml,
        Some(25),
        None,
        "unclosed array table",
    ),
    case(
        "robot_truncated.toml",
        Toml,
        Some(27),
        Some("platform_mm"),
        "unclosed array",
    ),
    case(
        "robot_no_home.toml",
        Toml,
        Some(1),
        Some("home"),
        "missing field `home`",
    ),
    case(
        "robot_unknown_key.toml",
        Toml,
        Some(49),
        Some("radius_mm"),
        "unknown field `radius_mm`",
    ),
    case(
        "robot_wrong_type.toml",
        Toml,
        Some(49),
        Some("radius_um"),
        "invalid type: string \"ten\"",
    ),
    case(
        "robot_short_array.toml",
        Toml,
        Some(38),
        Some("base_mm"),
        "expected 3 numbers, got 2",
    ),
    case(
        "robot_duplicate_key.toml",
        Toml,
        Some(51),
        Some("radius_um"),
        "duplicate key",
    ),
    case(
        "robot_nan.toml",
        Toml,
        Some(12),
        Some("home.position_mm"),
        "must be finite, but its y (2nd) component is NaN",
    ),
    case(
        "robot_inf.toml",
        Toml,
        Some(49),
        Some("clearance.radius_um"),
        "must be finite and >= 0, got inf",
    ),
    case(
        "robot_negative_clearance.toml",
        Toml,
        Some(49),
        Some("clearance.radius_um"),
        "must be finite and >= 0, got -1",
    ),
    case(
        "robot_mm_per_unit_zero.toml",
        Toml,
        Some(20),
        Some("link[1].mm_per_unit"),
        "must be finite and non-zero, got 0",
    ),
    case(
        "robot_mm_per_unit_negative.toml",
        Toml,
        Some(20),
        Some("link[1].mm_per_unit"),
        "must be > 0",
    ),
    case(
        "robot_limits_reversed.toml",
        Toml,
        Some(20),
        Some("link[1].length_limits_mm"),
        "need finite 0 < min < max, got [400, 300]",
    ),
    case(
        "robot_home_outside_limits.toml",
        Toml,
        Some(20),
        Some("link[1].length_limits_mm"),
        "the link is 354.000 mm long at the home pose, outside [400, 500] mm",
    ),
    case(
        "robot_five_links.toml",
        Toml,
        Some(17),
        Some("link"),
        "need at least 6 [[link]] tables, got 5",
    ),
    case(
        "robot_duplicate_sensor.toml",
        Toml,
        Some(75),
        Some("sensor[2].name"),
        "duplicate sensor name `paper`",
    ),
    case(
        "robot_in_metres.toml",
        Toml,
        Some(17),
        Some("link[1]"),
        "only 0.354000 mm long at the home pose: implausibly short",
    ),
    case(
        "robot_huge_coordinate.toml",
        Toml,
        Some(38),
        Some("link[6].base_mm"),
        "its z (3rd) component is 1e300 mm: implausibly far",
    ),
    // Issue 16: gauges, socket places and limits.
    case(
        "robot_gauge_stroke.toml",
        Toml,
        Some(77),
        Some("gauge[1].stroke_mm"),
        "must be finite and > 0, got 0",
    ),
    case(
        "robot_gauge_unknown_key.toml",
        Toml,
        Some(78),
        Some("travel_mm"),
        "unknown field `travel_mm`",
    ),
    case(
        "robot_gauge_bar_too_long.toml",
        Toml,
        Some(78),
        Some("gauge[1].bars_mm[2]"),
        "a 900 mm bar puts the window's end at 1250 mm, beyond longest_mm = 1000 mm",
    ),
    case(
        "robot_sensor_unknown_gauge.toml",
        Toml,
        Some(46),
        Some("sensor[1].gauge"),
        "unknown gauge `nope` (the [[gauge]] tables have: none)",
    ),
    case(
        "robot_limits_cone.toml",
        Toml,
        Some(76),
        Some("limits.base_cone_deg"),
        "must be in (0, 180] deg, got 200",
    ),
    case(
        "robot_socket_region_reversed.toml",
        Toml,
        Some(79),
        Some("socket_region[1].max_mm"),
        "its y (2nd) component -1 is below min_mm's 0",
    ),
    case(
        "robot_socket_side.toml",
        Toml,
        Some(77),
        Some("side"),
        "unknown variant `middle`, expected `base` or `platform`",
    ),
    // Issue 14: arrays longer than their fields, a load that overflows, a machine singular at
    // home, a zero declared noise (like --sigma-um 0) and a sensor name that reads as a comment.
    case(
        "robot_array_too_long.toml",
        Toml,
        Some(12),
        Some("position_mm"),
        "expected 3 numbers, got 5",
    ),
    case(
        "robot_base_four.toml",
        Toml,
        Some(22),
        Some("base_mm"),
        "expected 3 numbers, got 4",
    ),
    case(
        "robot_clearance_without_load.toml",
        Toml,
        Some(1),
        Some("load"),
        "missing: [clearance] (radius 10 um) is applied along each link's force, which only a declared load gives",
    ),
    case(
        "robot_com_far.toml",
        Toml,
        Some(56),
        Some("load.platform_com_mm"),
        "implausibly far from the platform's origin: 1.000000e6 mm, over 100 times the machine's size (347.0 mm",
    ),
    case(
        "robot_heavy_load.toml",
        Toml,
        Some(55),
        Some("load.platform_mass_kg"),
        "the load's weight or wrench at home is not a finite number",
    ),
    case(
        "robot_coincident_links.toml",
        Toml,
        Some(21),
        Some("link[2]"),
        "has the same joints as link 1 (it coincides with it): the machine is singular at its home pose",
    ),
    case(
        "robot_zero_noise.toml",
        Toml,
        Some(66),
        Some("calibration.sensor_noise_um"),
        "must be > 0, got 0",
    ),
    case(
        "robot_tolerance_limit.toml",
        Toml,
        Some(66),
        Some("calibration.tolerance_limit"),
        "must be > 0 (a number of tolerances; inf for no limit), got -1",
    ),
    case(
        "robot_sensor_name_hash.toml",
        Toml,
        Some(43),
        Some("sensor[1].name"),
        "\"#paper\": a sensor name must not start with '#'",
    ),
    case(
        "robot_error_rows.toml",
        Toml,
        Some(75),
        Some("installation_errors_um.base"),
        "has 1 rows, need one [dx, dy, dz] per link (6)",
    ),
    case(
        "robot_implausible_error.toml",
        Toml,
        Some(76),
        Some("installation_errors_um.platform[3]"),
        "its z (3rd) component is 2.5e6 um: implausibly large",
    ),
    case(
        "robot_unknown_effect.toml",
        Toml,
        Some(75),
        Some("calibration.effects[2]"),
        "unknown effect `wobble`",
    ),
    case(
        "robot_covariance_size.toml",
        Toml,
        Some(79),
        Some("calibration.covariance.std"),
        "35 values for 36 parameters",
    ),
    case(
        "robot_known_effect_count.toml",
        Toml,
        Some(79),
        Some("calibration.known_effects.backlash"),
        "3 values, but backlash has 6 parameters here",
    ),
    case(
        "robot_known_effect_nan.toml",
        Toml,
        Some(77),
        Some("calibration.known_effects.thermal_drift[3]"),
        "must be finite, got NaN",
    ),
    case("robot_not_utf8.toml", Toml, Some(6), None, "not UTF-8 text"),
    // A sensor of the data that the robot does not have.
    case(
        "robot_no_sensor.toml",
        RobotThenData,
        Some(3),
        Some("sensor"),
        "unknown sensor \"paper\" (the robot description has: none",
    ),
];

fn path(file: &str) -> String {
    format!("{DIR}/{file}")
}

fn args_of(c: &Case, out: &Path) -> Vec<String> {
    let f = path(c.file);
    let out_s = out.to_str().unwrap().to_string();
    let v: Vec<&str> = match c.on {
        Data => vec!["calibrate", "--robot", CUBE, "--data", &f, "--out", &out_s],
        Tracker => vec![
            "calibrate",
            "--robot",
            HEXAPOD,
            "--data",
            &f,
            "--out",
            &out_s,
        ],
        Toml | RobotThenData => vec!["calibrate", "--robot", &f, "--data", GOOD, "--out", &out_s],
        Poses => {
            return ["compensate", "--robot", CUBE, "--poses", &f, "--out"]
                .iter()
                .map(|s| s.to_string())
                .chain([out.join("commands.csv").display().to_string()])
                .collect()
        }
    };
    v.into_iter().map(String::from).collect()
}

/// The message the case expects, from `error: ` to the start of what it says.
fn expected(c: &Case) -> String {
    let named = if c.on == RobotThenData {
        GOOD.to_string()
    } else {
        path(c.file)
    };
    let mut s = format!("error: {named}");
    if let Some(l) = c.line {
        s.push_str(&format!(":{l}"));
    }
    if let Some(f) = c.field {
        s.push_str(&format!(": field {f}"));
    }
    s.push_str(&format!(": {}", c.what));
    s
}

/// The typed error of the library reader for a case.
fn typed(c: &Case) -> cpm::io::InputError {
    let p = root().join(path(c.file));
    let cube = || Robot::load(&root().join(CUBE)).unwrap();
    let result = match c.on {
        Data => read_data_file(&p, &cube(), &ReadOptions::default()).map(|_| ()),
        Tracker => read_data_file(
            &p,
            &Robot::load(&root().join(HEXAPOD)).unwrap(),
            &ReadOptions::default(),
        )
        .map(|_| ()),
        Toml => Robot::load(&p).map(|_| ()),
        RobotThenData => read_data_file(
            &root().join(GOOD),
            &Robot::load(&p).unwrap(),
            &ReadOptions::default(),
        )
        .map(|_| ()),
        Poses => cpm::io::read_pose_list_file(&p).and_then(|rows| {
            let robot = cube();
            cpm::io::campaign::check_pose_list_units(&rows, &p.display().to_string(), &robot)?;
            for r in &rows {
                cpm::io::campaign::check_reachable(
                    &robot.table,
                    &r.pose,
                    1e3,
                    &p.display().to_string(),
                    r.line,
                    &r.label,
                )?;
            }
            Ok(())
        }),
    };
    match result {
        Err(ReadError::Input(e)) => e,
        other => panic!("{}: expected an input error, got {other:?}", c.file),
    }
}

#[test]
fn malformed_inputs_exit_3_name_file_line_field_and_leave_earlier_results() {
    assert!(CASES.len() >= 40);
    let (out, before) = previous_results("table");
    for c in CASES {
        assert!(root().join(path(c.file)).exists(), "{} is missing", c.file);
        let args = args_of(c, &out);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = cpm(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(c.code), "{}: {err}", c.file);
        let want = expected(c);
        assert!(
            err.starts_with(&want),
            "{}\n got: {err}\nwant: {want}",
            c.file
        );
        assert!(o.stdout.is_empty(), "{}: printed results", c.file);
        assert!(
            snapshot(&out) == before,
            "{}: the output folder changed",
            c.file
        );
        // The library's typed error says the same.
        let e = typed(c);
        assert_eq!(e.line, c.line, "{}: {e}", c.file);
        assert_eq!(e.field.as_deref(), c.field, "{}: {e}", c.file);
        assert!(e.message.starts_with(c.what), "{}: {e}", c.file);
    }
}

#[test]
fn bad_options_exit_2_and_missing_files_exit_4_leaving_earlier_results() {
    let (out, before) = previous_results("options");
    let o_s = out.to_str().unwrap();
    let sim = out.join("sim.csv");
    let sim_s = sim.to_str().unwrap();
    let cal = |extra: &[&'static str]| -> Vec<String> {
        ["calibrate", "--robot", CUBE, "--data", GOOD, "--out", o_s]
            .iter()
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    let simulate = |extra: &[&'static str]| -> Vec<String> {
        ["simulate", "--robot", CUBE, "--out", sim_s]
            .iter()
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    let file = out.join("calibration.json");
    let cases: Vec<(Vec<String>, i32, &str)> = vec![
        (
            cal(&["--robust", "pink:3"]),
            2,
            "error: --robust \"pink:3\": unknown loss",
        ),
        (
            cal(&["--robust", "huber:-1"]),
            2,
            "error: --robust \"huber:-1\": K = \"-1\" must be a number of um > 0",
        ),
        (
            cal(&["--robust", "huber"]),
            2,
            "error: --robust \"huber\": expected huber:K",
        ),
        (
            cal(&["--sigma-um", "0"]),
            2,
            "error: --sigma-um must be > 0, got 0",
        ),
        (
            cal(&["--sigma-um", "NaN"]),
            2,
            "error: --sigma-um must be > 0, got NaN",
        ),
        (
            cal(&["--max-iterations", "0"]),
            2,
            "error: --max-iterations must be >= 1",
        ),
        (
            cal(&["--effects", "nosuch"]),
            2,
            "error: --effects: unknown effect `nosuch`",
        ),
        // Typed values parsed at the edge (cpm_workflow::options), refused in the same words.
        (
            cal(&["--effects", "link_offset,link_offset"]),
            2,
            "error: --effects: effect `link_offset` given twice",
        ),
        (
            cal(&["--tolerance", "x"]),
            2,
            "error: --tolerance \"x\": expected GROUP=VALUE, e.g. installation_errors=2000",
        ),
        (
            cal(&["--tolerance", "link_scale=big"]),
            2,
            "error: --tolerance \"link_scale=big\": \"big\" is not a number",
        ),
        (
            cal(&["--tolerance", "installation_errors=-1"]),
            2,
            "error: --tolerance \"installation_errors=-1\": invalid `tolerance`: installation_errors = -1: a tolerance must be > 0",
        ),
        (
            cal(&["--hold", "nosuch"]),
            2,
            "`nosuch` is not a parameter group of this fit",
        ),
        (
            cal(&["--pose-sigma-um=-1"]),
            2,
            "error: --pose-sigma-um must be > 0",
        ),
        (
            cal(&["--max-iterations=-3"]),
            2,
            "error: invalid value '-3' for '--max-iterations <N>'",
        ),
        (
            cal(&["--sigma-um", "-3"]),
            2,
            "error: unexpected argument '-3' found",
        ),
        (
            simulate(&["--circle", "--count", "1000000000000"]),
            2,
            "error: --count 1000000000000: at most 1000000 poses",
        ),
        (
            simulate(&["--random", "1000000000000"]),
            2,
            "error: --random 1000000000000: at most 1000000 poses",
        ),
        (
            simulate(&["--circle", "--noise", "gaussian:1e300"]),
            2,
            "error: --noise \"gaussian:1e300\": 1e300 um is implausibly large",
        ),
        (
            simulate(&["--random", "3", "--range-mm", "inf"]),
            2,
            "error: --random needs N >= 1 and finite",
        ),
        (
            vec![
                "calibrate".into(),
                "--robot".into(),
                CUBE.into(),
                "--data".into(),
                GOOD.into(),
                "--out".into(),
                file.display().to_string(),
            ],
            2,
            "exists and is not a directory",
        ),
        // I/O: a missing file, a folder given as a file.
        (
            vec![
                "calibrate".into(),
                "--robot".into(),
                CUBE.into(),
                "--data".into(),
                path("no_such.csv"),
                "--out".into(),
                o_s.into(),
            ],
            4,
            "error: tests/data/malformed/no_such.csv: cannot read:",
        ),
        (
            vec![
                "calibrate".into(),
                "--robot".into(),
                CUBE.into(),
                "--data".into(),
                DIR.into(),
                "--out".into(),
                o_s.into(),
            ],
            4,
            "error: tests/data/malformed: cannot read: is a directory",
        ),
        (
            vec![
                "calibrate".into(),
                "--robot".into(),
                path("no_such.toml"),
                "--data".into(),
                GOOD.into(),
                "--out".into(),
                o_s.into(),
            ],
            4,
            "error: tests/data/malformed/no_such.toml: cannot read:",
        ),
    ];
    for (args, code, want) in cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = cpm(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{a:?}: {err}");
        if want.starts_with("error: ") {
            assert!(err.starts_with(want), "{a:?}\n got: {err}\nwant: {want}");
        } else {
            assert!(err.contains(want), "{a:?}\n got: {err}\nwant: {want}");
        }
        assert!(snapshot(&out) == before, "{a:?}: the output folder changed");
    }
}

#[test]
fn odd_but_valid_inputs_are_read() {
    let cube = Robot::load(&root().join(CUBE)).unwrap();
    let read = |f: &str| read_data_file(&root().join(path(f)), &cube, &ReadOptions::default());
    for (f, lines) in [
        ("crlf.csv", [2, 3]),
        ("bom.csv", [2, 3]),
        ("bom_simulated_mark.csv", [3, 4]),
    ] {
        let d = read(f).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(d.reading_lines, lines, "{f}");
        assert_eq!(d.campaign.simulated, f == "bom_simulated_mark.csv", "{f}");
    }
    // Pose labels are names: gaps and any order are fine; poses keep the file's order.
    let d = read("pose_index_gaps.csv").unwrap();
    assert_eq!(d.pose_labels, ["1", "7", "3"]);
    // Blank lines (also spaces only) and comments are skipped; lines are the file's.
    let d = read("blank_and_comment_lines.csv").unwrap();
    assert_eq!(d.reading_lines, [5, 7]);
    // Rows repeating a pose with the same values are readings at one pose.
    let d = read("repeated_pose_rows.csv").unwrap();
    assert_eq!((d.campaign.poses.len(), d.campaign.readings.len()), (2, 3));
    for f in ["robot_bom.toml", "robot_crlf.toml"] {
        let r = Robot::load(&root().join(path(f))).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(r.table, cube.table, "{f}");
    }
    // The whole command on a CRLF file with a byte-order mark in the robot description.
    let out = scratch("odd").join("cal");
    let o = cpm(&[
        "calibrate",
        "--robot",
        &path("robot_bom.toml"),
        "--data",
        &path("crlf.csv"),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("calibration.json").exists());
}

/// A reader that repeats `row` forever after `head`.
struct Endless {
    head: Vec<u8>,
    row: Vec<u8>,
    at: usize,
}

impl std::io::Read for Endless {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut n = 0;
        while n < buf.len() {
            let byte = if self.at < self.head.len() {
                self.head[self.at]
            } else {
                self.row[(self.at - self.head.len()) % self.row.len()]
            };
            buf[n] = byte;
            n += 1;
            self.at += 1;
        }
        Ok(n)
    }
}

#[test]
fn readers_stream_and_stop_at_the_first_problem() {
    let cube = Robot::load(&root().join(CUBE)).unwrap();
    let header = "pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm\n";
    // A bad row early in an endless file: found without reading on.
    let endless = Endless {
        head: format!("{header}1,paper,0,0,410,0,0,0,309.9\n2,paper,0,0,410,0,0,0,abc\n")
            .into_bytes(),
        row: b"3,paper,0,0,410,0,0,0,309.9\n".to_vec(),
        at: 0,
    };
    let e = read_data_from(endless, "endless.csv", &cube, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert_eq!(e, "endless.csv:3: field length_mm: \"abc\" is not a number");
    // An endless file of good rows stops at the row limit.
    let endless = Endless {
        head: header.as_bytes().to_vec(),
        row: b"1,paper,0,0,410,0,0,0,309.9\n".to_vec(),
        at: 0,
    };
    let options = ReadOptions {
        max_rows: 1000,
        ..ReadOptions::default()
    };
    let e = read_data_from(endless, "endless.csv", &cube, &options)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("endless.csv:1002: more than 1000 data rows"),
        "{e}"
    );
    // An endless line (a binary file, say) stops at the line limit.
    let endless = Endless {
        head: header.as_bytes().to_vec(),
        row: b"7".to_vec(),
        at: 0,
    };
    let e = read_data_from(endless, "blob.csv", &cube, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("blob.csv:2: the line is longer than 1048576 bytes"),
        "{e}"
    );
    // The command on a file with a 2 MiB line.
    let d = scratch("long-line");
    let f = d.join("long.csv");
    let mut text = format!("{header}1,paper,0,0,410,0,0,0,309.9\n").into_bytes();
    text.extend(std::iter::repeat_n(b'9', 2 << 20));
    std::fs::write(&f, text).unwrap();
    let o = cpm(&[
        "calibrate",
        "--robot",
        CUBE,
        "--data",
        f.to_str().unwrap(),
        "--out",
        d.join("out").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&o.stderr)
        .starts_with(&format!("error: {}:3: the line is longer", f.display())));
    assert!(!d.join("out").exists());
}

/// Simulated hexapod readings (30 poses, 3 sensors, 1 um noise) with the paper's Table 2 as
/// the installation errors.
fn hexapod_data(d: &Path) -> PathBuf {
    let mut desc = cpm::geometry::RobotDescription::load(root().join(HEXAPOD)).unwrap();
    desc.installation_errors_um = Some(
        cpm::geometry::description::InstallationErrorsSpec::from_errors(
            &cpm::geometry::InstallationErrors::paper_table2(),
        ),
    );
    let truth = d.join("truth.toml");
    std::fs::write(&truth, desc.to_toml_string().unwrap()).unwrap();
    let data = d.join("data.csv");
    let o = cpm(&[
        "simulate",
        "--robot",
        HEXAPOD,
        "--random",
        "30",
        "--truth",
        truth.to_str().unwrap(),
        "--noise",
        "gaussian:1",
        "--out",
        data.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    data
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_solver_that_stops_early_exits_1_and_says_so() {
    let d = scratch("no-convergence");
    let data = hexapod_data(&d);
    let out = d.join("cal");
    let o = cpm(&[
        "calibrate",
        "--robot",
        HEXAPOD,
        "--data",
        data.to_str().unwrap(),
        "--max-iterations",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(
            "error: the solver did not converge (stopped: maximum number of iterations reached)"
        ),
        "{err}"
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("**The solver did not converge**"),
        "{report}"
    );
    assert_eq!(
        json(&out.join("calibration.json"))["solver"]["converged"],
        false
    );
    let toml = std::fs::read_to_string(out.join("calibrated.toml")).unwrap();
    assert!(toml.contains("# WARNING: the solver did not converge"));
}

#[test]
fn a_rank_deficient_fit_is_reported() {
    let out = scratch("rank").join("cal");
    let o = cpm(&[
        "calibrate",
        "--robot",
        CUBE,
        "--data",
        GOOD,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("note: Rank-deficient fit: the data determine 0 of 36 parameters on their own (rank 8 of 36)"), "{err}");
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("**Rank-deficient fit**"));
    let j = json(&out.join("calibration.json"));
    assert!(j["warnings"][0]
        .as_str()
        .unwrap()
        .starts_with("Rank-deficient fit"));
    assert_eq!(j["not_determined"].as_array().unwrap().len(), 36);
}

#[test]
fn a_5_mm_spike_is_flagged_with_its_line_and_a_robust_loss_resists_it() {
    let d = scratch("spike");
    let data = hexapod_data(&d);
    let text = std::fs::read_to_string(&data).unwrap();
    // Line 21 of the file: a reading 5 mm too long (the ballbar slipped).
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut f: Vec<String> = lines[20].split(',').map(String::from).collect();
    let length: f64 = f[8].parse().unwrap();
    f[8] = (length + 5.0).to_string();
    lines[20] = f.join(",");
    let spiked = d.join("spiked.csv");
    std::fs::write(&spiked, lines.join("\n") + "\n").unwrap();
    let truth = cpm::geometry::InstallationErrors::paper_table2().to_vec_um();
    let fit = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = d.join(name);
        let mut args = vec![
            "calibrate",
            "--robot",
            HEXAPOD,
            "--data",
            spiked.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = cpm(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert!(
            report.contains(&format!("| {}:21 | sensor ", spiked.display())),
            "{report}"
        );
        json(&out.join("calibration.json"))
    };
    let error_rms = |j: &serde_json::Value| -> f64 {
        let mut sq = 0.0;
        let mut n = 0.0;
        for (side, off) in [("base", 0), ("platform", 3)] {
            for i in 0..6 {
                for a in 0..3 {
                    // The fit's complete point: with the spike, least squares' noise estimate
                    // is so large that the prior holds some joints (not reported as measured).
                    let v = j["minimum_norm_um"][side][i][a].as_f64().unwrap();
                    sq += (v - truth[6 * i + off + a]).powi(2);
                    n += 1.0;
                }
            }
        }
        (sq / n).sqrt()
    };
    // Least squares sets the spike aside by default; `--keep-outliers` fits it.
    let plain = fit("plain", &[]);
    let kept = fit("kept", &["--keep-outliers"]);
    let robust = fit("huber", &["--robust", "huber:3"]);
    let aside = plain["outliers"].as_array().unwrap();
    assert_eq!(aside.len(), 1, "{aside:?}");
    assert_eq!(aside[0]["set_aside"], true);
    assert_eq!(kept["outliers"][0]["set_aside"], false);
    let flagged = robust["outliers"].as_array().unwrap();
    assert_eq!(flagged.len(), 1, "{flagged:?}");
    assert_eq!(flagged[0]["line"], 21);
    assert!(flagged[0]["residual_um"].as_f64().unwrap().abs() > 4000.0);
    assert_eq!(robust["robust_loss"], "Huber, K = 3 um");
    let (e_plain, e_kept, e_robust) = (error_rms(&plain), error_rms(&kept), error_rms(&robust));
    assert!(
        e_robust < 60.0 && e_plain < 60.0 && e_robust * 10.0 < e_kept && e_plain * 5.0 < e_kept,
        "error vs truth: robust {e_robust} um, set aside {e_plain} um, fitted {e_kept} um"
    );
    // Set aside, the spike leaves the noise estimate too.
    assert!(
        plain["sigma_um"].as_f64().unwrap() < 2.0,
        "{}",
        plain["sigma_um"]
    );
    // The standard deviations come from the inliers' noise (1 um), not the spike.
    assert!(
        robust["sigma_um"].as_f64().unwrap() < 2.0,
        "{}",
        robust["sigma_um"]
    );
}

#[test]
fn a_failure_while_writing_leaves_the_earlier_results() {
    let (out, _) = previous_results("write-failure");
    // A folder where a result file goes: the set cannot be written.
    std::fs::remove_file(out.join("estimates.svg")).unwrap();
    std::fs::create_dir(out.join("estimates.svg")).unwrap();
    let before = snapshot(&out);
    let o = cpm(&[
        "calibrate",
        "--robot",
        CUBE,
        "--data",
        &path("pose_index_gaps.csv"),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(
        o.status.code(),
        Some(4),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("estimates.svg: is a directory"));
    assert!(snapshot(&out) == before, "the earlier results changed");
}

#[test]
fn a_solver_error_at_a_pose_names_its_line() {
    use cpm::calib::CalibError;
    let cube = Robot::load(&root().join(CUBE)).unwrap();
    let file = read_data_file(&root().join(GOOD), &cube, &ReadOptions::default()).unwrap();
    let merged = cpm::io::merge(vec![file], &cube);
    let fk = |pose| CalibError::Kinematics {
        pose,
        source: cpm::kinematics::KinematicsError::NonConvergence {
            iterations: 50,
            residual_mm: 1.0,
            condition: 1e9,
        },
    };
    // Inside the least-squares solver (the model failed during an iteration) ...
    let err = CalibError::Solver(cpm::lm::LmError::Model {
        iteration: 3,
        stage: cpm::lm::EvalStage::Residuals,
        source: Box::new(fk(4)),
    });
    let e = cpm::cli::common::locate(err, &merged);
    let shown = cpm::cli::render_error(&e);
    let want = "good.csv:7: pose \"5\": least-squares solver: model error at iteration 3 while evaluating the residuals: pose 4: forward kinematics did not converge in 50 iterations";
    assert!(shown.contains(want), "{shown}");
    assert_eq!(shown.matches("did not converge").count(), 1, "{shown}");
    assert_eq!(cpm::cli::exit_kind(&e), cpm::cli::ExitKind::Trouble);
    // ... and outside it.
    let e = cpm::cli::common::locate(fk(0), &merged);
    let shown = cpm::cli::render_error(&e);
    assert!(
        shown.contains("good.csv:3: pose \"1\": pose 0: forward kinematics did not converge"),
        "{shown}"
    );
}

/// Options that make no sense exit 2 naming the option (issue 14), and a declared noise of 0
/// is refused like `--sigma-um 0`.
#[test]
fn options_that_make_no_sense_exit_2_naming_the_option() {
    let out = scratch("options");
    let sim = out.join("sim.csv");
    for (value, says) in [
        ("link_offset=1e300,0,0,0,0,0", "implausibly large"),
        ("link_offset=9e4,0,0,0,0,0", "cannot be simulated"),
    ] {
        let o = cpm(&[
            "simulate",
            "--robot",
            HEXAPOD,
            "--random",
            "5",
            "--truth-effect",
            value,
            "--out",
            sim.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{value}: {err}");
        assert!(err.starts_with("error: --truth-effect"), "{value}: {err}");
        assert!(err.contains(says), "{value}: {err}");
        assert!(!sim.exists());
    }
    let o = cpm(&[
        "calibrate",
        "--robot",
        CUBE,
        "--data",
        GOOD,
        "--sigma-um",
        "0",
        "--out",
        out.join("cal").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = cpm(&[
        "calibrate",
        "--robot",
        &format!("{DIR}/robot_zero_noise.toml"),
        "--data",
        GOOD,
        "--out",
        out.join("cal").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&o.stderr).contains("sensor_noise_um: must be > 0"));
    assert!(!out.join("cal").exists());
}
