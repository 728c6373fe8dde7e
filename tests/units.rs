//! Files in the wrong units: angles in radians, positions in metres. Every reader (length
//! readings, tracker poses, pose lists) asks "radians?" / "metres?" at the first such row,
//! with file, line and field, exit code 3, no output; ordinary files, small-angle campaigns
//! in degrees and constant orientations are read. Files are SIMULATED by `cpm simulate` and
//! converted here.
#[path = "common/ingest.rs"]
mod ingest;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use cpm::io::{read_pose_list_file, ReadError, ReadOptions, Robot};
use ingest::read_data_file;

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/hexapod_66.toml")
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("units-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cpm(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpm"))
        .current_dir(dir)
        .arg(args[0])
        .arg("--robot")
        .arg(example())
        .args(&args[1..])
        .output()
        .unwrap()
}

fn simulate(dir: &Path, out: &str, extra: &[&str]) -> String {
    let mut a = vec!["simulate", "--random", "12", "--seed", "2"];
    if !extra.contains(&"--range-deg") {
        a.extend(["--range-deg", "8"]);
    }
    a.extend(extra);
    a.extend(["--out", out]);
    let o = cpm(dir, &a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read_to_string(dir.join(out)).unwrap()
}

/// The file with the columns named in `cols` mapped by `f` (header and comments kept).
fn map_columns(text: &str, cols: &[&str], f: impl Fn(f64) -> f64) -> String {
    let mut idx = Vec::new();
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if idx.is_empty() {
            let h: Vec<&str> = line.split(',').collect();
            idx = cols
                .iter()
                .map(|c| h.iter().position(|x| x == c).unwrap())
                .collect();
            out.push_str(line);
        } else {
            let mut v: Vec<String> = line.split(',').map(str::to_string).collect();
            for &k in &idx {
                v[k] = format!("{}", f(v[k].parse().unwrap()));
            }
            out.push_str(&v.join(","));
        }
        out.push('\n');
    }
    out
}

const ANGLES: [&str; 3] = ["roll_deg", "pitch_deg", "yaw_deg"];
const POSITIONS: [&str; 3] = ["x_mm", "y_mm", "z_mm"];

/// `cpm calibrate` (or `args`) refuses `file` with exit code 3, a message naming the file,
/// line 3 (the first data row after the simulated mark) or `line`, a field among `fields`,
/// and `what`; the library reader gives the same line and field.
fn refused(dir: &Path, args: &[&str], file: &str, line: usize, fields: &[&str], what: &str) {
    let out = dir.join("out");
    let o = cpm(dir, args);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{stderr}");
    let start = format!("error: {file}:{line}: field ");
    assert!(stderr.starts_with(&start), "{stderr}");
    assert!(
        fields
            .iter()
            .any(|f| stderr.starts_with(&format!("{start}{f}:"))),
        "{stderr}"
    );
    assert!(stderr.contains(what), "{stderr}");
    assert!(!out.exists(), "no output after an input error");
}

fn typed(e: ReadError) -> cpm::io::InputError {
    match e {
        ReadError::Input(e) => e,
        other => panic!("{other}"),
    }
}

#[test]
fn readings_in_radians_or_metres_are_refused_at_the_first_row() {
    let d = scratch("readings");
    let text = simulate(&d, "deg.csv", &[]);
    std::fs::write(
        d.join("rad.csv"),
        map_columns(&text, &ANGLES, f64::to_radians),
    )
    .unwrap();
    std::fs::write(
        d.join("m.csv"),
        map_columns(&text, &POSITIONS, |v| v / 1000.0),
    )
    .unwrap();
    let args = |f: &'static str| ["calibrate", "--data", f, "--out", "out"];
    refused(&d, &args("rad.csv"), "rad.csv", 3, &ANGLES, "radians?");
    refused(&d, &args("m.csv"), "m.csv", 3, &POSITIONS, "metres?");
    let robot = Robot::load(&example()).unwrap();
    let e = typed(read_data_file(&d.join("rad.csv"), &robot, &ReadOptions::default()).unwrap_err());
    assert_eq!(e.line, Some(3));
    assert!(ANGLES.contains(&e.field.as_deref().unwrap()));
    // The same file in degrees is read.
    read_data_file(&d.join("deg.csv"), &robot, &ReadOptions::default()).unwrap();
}

#[test]
fn tracker_poses_in_radians_or_metres_are_refused() {
    let d = scratch("tracker");
    let text = simulate(&d, "deg.csv", &["--measure", "poses"]);
    std::fs::write(
        d.join("rad.csv"),
        map_columns(&text, &ANGLES, f64::to_radians),
    )
    .unwrap();
    std::fs::write(
        d.join("m.csv"),
        map_columns(&text, &POSITIONS, |v| v / 1000.0),
    )
    .unwrap();
    let args = |f: &'static str| ["calibrate", "--data", f, "--out", "out"];
    refused(&d, &args("rad.csv"), "rad.csv", 3, &ANGLES, "radians?");
    // Tracker positions may be anywhere (the tracker's frame): their spread against the
    // links' travel tells metres; the row named is the one furthest from the first.
    let o = cpm(&d, &args("m.csv"));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{stderr}");
    assert!(stderr.starts_with("error: m.csv:"), "{stderr}");
    assert!(stderr.contains("metres?"), "{stderr}");
    let robot = Robot::load(&example()).unwrap();
    let e = typed(read_data_file(&d.join("m.csv"), &robot, &ReadOptions::default()).unwrap_err());
    assert!(POSITIONS.contains(&e.field.as_deref().unwrap()));
    assert!(e.line.unwrap() >= 3);
}

#[test]
fn pose_lists_in_radians_or_metres_are_refused() {
    let d = scratch("poses");
    let list = "pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n1,10,20,300,0,0,0\n2,12,18,305,0.08,-0.05,0.1\n3,8,25,295,-0.1,0.03,0.02\n";
    std::fs::write(d.join("rad.csv"), list).unwrap();
    let m = "pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n1,0.01,0.02,0.3,0,0,0\n2,0.012,0.018,0.305,3,-2,1\n";
    std::fs::write(d.join("m.csv"), m).unwrap();
    refused(
        &d,
        &["compensate", "--poses", "rad.csv", "--out", "out"],
        "rad.csv",
        3,
        &ANGLES,
        "radians?",
    );
    refused(
        &d,
        &["compensate", "--poses", "m.csv", "--out", "out"],
        "m.csv",
        2,
        &POSITIONS,
        "metres?",
    );
    refused(
        &d,
        &["simulate", "--plan", "m.csv", "--out", "out"],
        "m.csv",
        2,
        &POSITIONS,
        "metres?",
    );
    let e = typed(read_pose_list_file(&d.join("rad.csv")).unwrap_err());
    assert_eq!((e.line, e.field.as_deref()), (Some(3), Some("roll_deg")));
}

#[test]
fn small_angle_campaigns_in_degrees_are_read() {
    let d = scratch("fine");
    let robot = Robot::load(&example()).unwrap();
    // Tilts of about one degree: beyond 0.2, read as degrees.
    simulate(&d, "one.csv", &["--range-deg", "1"]);
    read_data_file(&d.join("one.csv"), &robot, &ReadOptions::default()).unwrap();
    // Constant orientation (all angles zero) and tiny angles under 0.02 are left alone.
    for (name, a) in [("zero.csv", 0.0), ("tiny.csv", 0.01)] {
        let list = format!(
            "x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n10,20,300,0,0,0\n12,18,305,{a},0,{a}\n"
        );
        std::fs::write(d.join(name), list).unwrap();
        read_pose_list_file(&d.join(name)).unwrap();
        let o = cpm(&d, &["compensate", "--poses", name]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // Truly tiny tilts in degrees given as a quaternion are read.
    let h = (0.1_f64.to_radians() / 2.0).sin();
    let c = (0.1_f64.to_radians() / 2.0).cos();
    let q = format!("x_mm,y_mm,z_mm,qw,qx,qy,qz\n10,20,300,1,0,0,0\n12,18,305,{c},{h},0,0\n");
    std::fs::write(d.join("q.csv"), q).unwrap();
    read_pose_list_file(&d.join("q.csv")).unwrap();
}
