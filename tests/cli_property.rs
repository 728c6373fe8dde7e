//! A property test over the command line (issue 14): random valid inputs go through
//! simulate -> calibrate -> compensate / export without a panic and round-trip (what one
//! command writes, the next reads); random invalid inputs (a corrupted field of a measurement
//! file, a nonsensical option value) exit 2, 3 or 4 with a located message and leave the
//! output directory byte for byte as it was. Few cases: each spawns the binary.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use proptest::prelude::*;

fn example(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
        .display()
        .to_string()
}

fn cpm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(args)
        .output()
        .expect("run cpm")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("property-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let q = e.unwrap().path();
            if q.is_dir() {
                stack.push(q);
            } else {
                out.insert(q.clone(), std::fs::read(&q).unwrap());
            }
        }
    }
    out
}

fn no_panic(o: &Output, what: &str) {
    let e = stderr(o);
    assert!(
        !e.contains("panicked") && o.status.code().is_some(),
        "{what}: {e}"
    );
}

/// A simulated campaign and its calibration in `d` (the previous result of the invalid cases).
fn simulate_and_calibrate(d: &Path, poses: usize, sigma_um: f64, seed: u64) -> (PathBuf, PathBuf) {
    let data = d.join("data.csv");
    let o = cpm(&[
        "simulate",
        "--robot",
        &example("hexapod_66.toml"),
        "--random",
        &poses.to_string(),
        "--noise",
        &format!("gaussian:{sigma_um}"),
        "--seed",
        &seed.to_string(),
        "--out",
        p(&data),
    ]);
    no_panic(&o, "simulate");
    assert_eq!(o.status.code(), Some(0), "simulate: {}", stderr(&o));
    let cal = d.join("cal");
    let o = cpm(&[
        "calibrate",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        p(&data),
        "--out",
        p(&cal),
    ]);
    no_panic(&o, "calibrate");
    assert_eq!(o.status.code(), Some(0), "calibrate: {}", stderr(&o));
    (data, cal)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 8, ..ProptestConfig::default() })]

    #[test]
    fn valid_inputs_round_trip_through_every_command(
        poses in 12usize..30,
        sigma_um in 0.1f64..3.0,
        seed in 1u64..1_000_000,
        targets in proptest::collection::vec(
            (-20.0f64..20.0, -20.0f64..20.0, -10.0f64..10.0, -3.0f64..3.0, -3.0f64..3.0, -3.0f64..3.0),
            1..6,
        ),
    ) {
        let d = scratch("valid");
        let (data, cal) = simulate_and_calibrate(&d, poses, sigma_um, seed);
        // identifiability and refine read what simulate wrote.
        let o = cpm(&["identifiability", "--robot", &example("hexapod_66.toml"), "--data", p(&data), "--json"]);
        no_panic(&o, "identifiability");
        prop_assert_eq!(o.status.code(), Some(0), "identifiability: {}", stderr(&o));
        let ident: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        prop_assert!(ident.is_object());
        let refined = d.join("refined");
        let o = cpm(&[
            "refine", "--robot", &example("hexapod_66.toml"), "--data", p(&data),
            "--candidates", "link_offset", "--max-steps", "1", "--out", p(&refined),
        ]);
        no_panic(&o, "refine");
        prop_assert_eq!(o.status.code(), Some(0), "refine: {}", stderr(&o));
        prop_assert!(refined.join("refine.json").exists());
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(cal.join("calibration.json")).unwrap()).unwrap();
        let rms = v["residual_rms_um"].as_f64().unwrap();
        prop_assert!(rms < 3.0 * sigma_um, "residual {} um for noise {} um", rms, sigma_um);
        // calibrated.toml is read back by compensate and export.
        let robot = cal.join("calibrated.toml");
        let mut list = String::from("pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n");
        for (k, (x, y, z, r, pi, ya)) in targets.iter().enumerate() {
            // About the hexapod's home (z from its description).
            list.push_str(&format!("t{k},{x},{y},{},{r},{pi},{ya}\n", z + home_z()));
        }
        let t = d.join("targets.csv");
        std::fs::write(&t, list).unwrap();
        let commands = d.join("commands.csv");
        let o = cpm(&["compensate", "--robot", p(&robot), "--poses", p(&t), "--out", p(&commands)]);
        no_panic(&o, "compensate");
        prop_assert_eq!(o.status.code(), Some(0), "compensate: {}", stderr(&o));
        let text = std::fs::read_to_string(&commands).unwrap();
        let rows = text.lines().filter(|l| !l.starts_with('#')).count();
        prop_assert_eq!(rows, 1 + targets.len());
        let o = cpm(&["export", "--format", "linuxcnc", "--robot", p(&robot)]);
        no_panic(&o, "export");
        prop_assert_eq!(o.status.code(), Some(0), "export: {}", stderr(&o));
        let hal = String::from_utf8(o.stdout).unwrap();
        prop_assert_eq!(hal.lines().filter(|l| l.starts_with("setp ")).count(), 36);
    }

    #[test]
    fn a_corrupted_field_exits_3_naming_its_line_and_leaves_the_output(
        seed in 1u64..1_000_000,
        row in 0usize..36,
        column in 2usize..9,
        junk in prop::sample::select(vec!["abc", "NaN", "inf", "-inf", "1e999", "", "1.2.3", "0x10"]),
    ) {
        let d = scratch("corrupt");
        let (data, cal) = simulate_and_calibrate(&d, 12, 0.5, seed);
        let before = snapshot(&cal);
        let text = std::fs::read_to_string(&data).unwrap();
        let mut k = 0;
        let mut line = 0;
        let bad: Vec<String> = text
            .lines()
            .enumerate()
            .map(|(n, l)| {
                if l.starts_with('#') || l.starts_with("pose") {
                    return l.to_string();
                }
                k += 1;
                if k != row + 1 {
                    return l.to_string();
                }
                line = n + 1;
                let mut f: Vec<&str> = l.split(',').collect();
                f[column] = junk;
                f.join(",")
            })
            .collect();
        let bad_file = d.join("bad.csv");
        std::fs::write(&bad_file, bad.join("\n") + "\n").unwrap();
        let o = cpm(&[
            "calibrate",
            "--robot",
            &example("hexapod_66.toml"),
            "--data",
            p(&bad_file),
            "--out",
            p(&cal),
        ]);
        no_panic(&o, "calibrate");
        let e = stderr(&o);
        prop_assert_eq!(o.status.code(), Some(3), "{}", e);
        let located = format!("error: {}:{line}:", p(&bad_file));
        prop_assert!(e.starts_with(&located), "{} does not start with {}", e, located);
        prop_assert!(snapshot(&cal) == before, "the previous result changed");
    }

    #[test]
    fn a_nonsensical_option_exits_2_naming_it_and_leaves_the_output(
        seed in 1u64..1_000_000,
        case in 0usize..8,
        value in prop::sample::select(vec!["-1", "0", "nan", "inf", "abc"]),
    ) {
        let d = scratch("options");
        let (data, cal) = simulate_and_calibrate(&d, 12, 0.5, seed);
        let before = snapshot(&cal);
        let hexapod = example("hexapod_66.toml");
        let (option, extra): (&str, String) = [
            ("--sigma-um", value.to_string()),
            ("--robust", format!("tukey:{value}")),
            ("--robust", format!("huber:{value}")),
            ("--max-iterations", value.to_string()),
            ("--pose-sigma-um", value.to_string()),
            ("--orientation-sigma-urad", value.to_string()),
            ("--effects", format!("no_such_effect_{value}")),
            ("--robust", format!("pink:{value}")),
        ][case]
            .clone();
        let o = cpm(&[
            "calibrate",
            "--robot",
            &hexapod,
            "--data",
            p(&data),
            &format!("{option}={extra}"),
            "--out",
            p(&cal),
        ]);
        no_panic(&o, "calibrate");
        let e = stderr(&o);
        prop_assert_eq!(o.status.code(), Some(2), "{} {}: {}", option, extra, e);
        prop_assert!(e.contains(option), "{} {}: {}", option, extra, e);
        prop_assert!(snapshot(&cal) == before, "the previous result changed");
    }
}

/// The hexapod's home height, mm (from its description).
fn home_z() -> f64 {
    cpm::geometry::description::RobotDescription::load(example("hexapod_66.toml"))
        .unwrap()
        .home
        .position_mm[2]
}
