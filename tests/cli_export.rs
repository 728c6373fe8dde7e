//! `cpm export --format linuxcnc`: joints in mm and inch, the INI snippet's HOME_OFFSET, SCALE
//! and BACKLASH from the link reading models and a known backlash, the screw-lead pins, and the
//! link-to-joint mapping; every value checked against the description it came from.
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("export-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cpm(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "cpm {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// The value of `setp NAME value` in a HAL text (commented or not).
fn setp(hal: &str, name: &str) -> f64 {
    hal.lines()
        .map(|l| l.trim_start_matches("# "))
        .find_map(|l| l.strip_prefix(&format!("setp {name} ")))
        .unwrap_or_else(|| panic!("no setp {name}"))
        .trim()
        .parse()
        .unwrap()
}

/// `KEY = value` of section `[JOINT_j]` of an INI text.
fn ini_value(ini: &str, j: usize, key: &str) -> Option<f64> {
    let section = format!("[JOINT_{j}]");
    let mut inside = false;
    for l in ini.lines() {
        let l = l.trim();
        if l.starts_with('[') {
            inside = l == section;
        } else if inside {
            if let Some(v) = l.strip_prefix(&format!("{key} = ")) {
                return Some(v.parse().unwrap());
            }
        }
    }
    None
}

/// The hexapod example with link reading models (motor revolutions of a 5 mm screw), a
/// screw lead and a known backlash (negative = lost motion, one positive value).
fn robot(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/hexapod_66.toml"),
    )
    .unwrap();
    let mut out = String::new();
    let mut link = 0;
    for line in text.lines() {
        out.push_str(line);
        out.push('\n');
        if line.starts_with("length_limits_mm") {
            link += 1;
            out.push_str(&format!(
                "length_at_zero_mm = {}\nmm_per_unit = {}\n",
                300.0 + link as f64,
                5.0 + 0.001 * link as f64
            ));
        }
    }
    out.push_str(
        "\n[calibration]\nscrew_lead_mm = 5.0\n[calibration.known_effects]\nbacklash = [-4.0, -5.0, -6.0, -7.0, -8.0, 3.0]\n",
    );
    let p = dir.join("robot.toml");
    std::fs::write(&p, out).unwrap();
    p
}

#[test]
fn linuxcnc_export_in_mm_and_inch_with_ini() {
    let dir = scratch("units");
    let robot = robot(&dir);
    let r = robot.display().to_string();
    let desc = cpm::io::Robot::load(&robot).unwrap();
    let ini_mm = dir.join("mm.ini");
    let ini_in = dir.join("in.ini");
    let hal_mm = cpm(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &r,
        "--ini",
        &ini_mm.display().to_string(),
    ]);
    let hal_in = cpm(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &r,
        "--units",
        "inch",
        "--ini",
        &ini_in.display().to_string(),
    ]);
    assert!(hal_mm.contains("cpm link N (1-based, [[link]] order) = genhexkins joint N-1"));
    for (i, l) in desc.table.links.iter().enumerate() {
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let mm = setp(&hal_mm, &format!("genhexkins.base.{i}.{axis}"));
            let inch = setp(&hal_in, &format!("genhexkins.platform.{i}.{axis}"));
            assert!((mm - l.base_mm[a]).abs() < 1e-6);
            assert!((inch - l.platform_mm[a] / 25.4).abs() < 1e-6);
        }
    }
    let (ini_mm, ini_in) = (
        std::fs::read_to_string(ini_mm).unwrap(),
        std::fs::read_to_string(ini_in).unwrap(),
    );
    let backlash = [-4.0, -5.0, -6.0, -7.0, -8.0, 3.0];
    for (j, l) in desc.description.links.iter().enumerate() {
        let home = ini_value(&ini_mm, j, "HOME_OFFSET").unwrap();
        assert!((home - l.length_at_zero_mm).abs() < 1e-9, "joint {j}");
        let scale = ini_value(&ini_mm, j, "SCALE").unwrap();
        assert!((scale * l.mm_per_unit - 1.0).abs() < 1e-8, "joint {j}");
        let scale_in = ini_value(&ini_in, j, "SCALE").unwrap();
        assert!((scale_in - 25.4 / l.mm_per_unit).abs() < 1e-8, "joint {j}");
        let home_in = ini_value(&ini_in, j, "HOME_OFFSET").unwrap();
        assert!((home_in - l.length_at_zero_mm / 25.4).abs() < 1e-6);
        // LinuxCNC's BACKLASH is the whole lost motion: -2 x cpm's half, in mm.
        match ini_value(&ini_mm, j, "BACKLASH") {
            Some(b) => assert!(
                (b + 2.0 * backlash[j] * 1e-3).abs() < 1e-9,
                "joint {j}: {b}"
            ),
            None => assert!(backlash[j] > 0.0, "joint {j} lost its BACKLASH"),
        }
    }
    assert!(ini_mm.contains("the link overshoots"));
    // The screw lead is declared: its pins are offered (commented, the axes are assumed).
    assert!((setp(&hal_mm, "genhexkins.screw-lead") - 5.0).abs() < 1e-12);
    assert!((setp(&hal_in, "genhexkins.screw-lead") - 5.0 / 25.4).abs() < 1e-6);
    for i in 0..6 {
        let n: f64 = ["x", "y", "z"]
            .iter()
            .map(|a| setp(&hal_mm, &format!("genhexkins.base-n.{i}.{a}")).powi(2))
            .sum();
        assert!((n - 1.0).abs() < 1e-5, "base-n.{i} is not a unit vector");
    }
    // The HAL text carries the INI snippet as comments.
    assert!(hal_mm.contains("# [JOINT_5]"));
}

#[test]
fn status_lines_go_to_stderr_when_stdout_carries_data() {
    let dir = scratch("status");
    let r = robot(&dir).display().to_string();
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_cpm"))
            .args(["export", "--format", "linuxcnc", "--robot", &r])
            .args(args)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            String::from_utf8(o.stdout).unwrap(),
            String::from_utf8(o.stderr).unwrap(),
        )
    };
    let ini = dir.join("j.ini").display().to_string();
    let hal = dir.join("j.hal").display().to_string();
    // `--ini F > joints.hal`: stdout is the HAL file and nothing else (it had `wrote F`).
    let (out, err) = run(&["--ini", &ini]);
    assert!(!out.contains("wrote"), "{out}");
    assert!(out.lines().all(|l| l.is_empty()
        || l.starts_with('#')
        || l.starts_with("setp ")
        || l.starts_with("loadrt ")));
    assert_eq!(err.trim(), format!("wrote {ini}"));
    // `--quiet` drops the status line there.
    let (_, err) = run(&["--ini", &ini, "--quiet"]);
    assert!(err.is_empty(), "{err}");
    // `--ini - --out F`: the INI on stdout, the status of F on stderr.
    let (out, err) = run(&["--ini", "-", "--out", &hal]);
    assert!(out.starts_with("; LinuxCNC joints of"), "{out}");
    assert!(!out.contains("wrote"), "{out}");
    assert_eq!(err.trim(), format!("wrote {hal}"));
    // Both to files: stdout carries only the status lines.
    let (out, err) = run(&["--ini", &ini, "--out", &hal]);
    assert_eq!(out, format!("wrote {ini}\nwrote {hal}\n"));
    assert!(err.is_empty(), "{err}");
}

/// A robot calibrated from simulated data (`calibrate` writes `[calibration] simulated =
/// true`): the LinuxCNC files it exports say SIMULATED; the same robot from measured data does
/// not.
#[test]
fn exports_of_a_robot_calibrated_from_simulated_data_say_so() {
    let dir = scratch("simulated");
    let r = robot(&dir);
    let text = std::fs::read_to_string(&r).unwrap();
    let marked = dir.join("simulated.toml");
    std::fs::write(
        &marked,
        if text.contains("[calibration]") {
            text.replace("[calibration]", "[calibration]\nsimulated = true")
        } else {
            format!("{text}\n[calibration]\nsimulated = true\n")
        },
    )
    .unwrap();
    for (path, simulated) in [(&marked, true), (&r, false)] {
        let hal = cpm(&[
            "export",
            "--format",
            "linuxcnc",
            "--robot",
            &path.display().to_string(),
        ]);
        let ini = cpm(&[
            "export",
            "--format",
            "linuxcnc",
            "--robot",
            &path.display().to_string(),
            "--ini",
            "-",
            "--out",
            &dir.join("j.hal").display().to_string(),
            "--quiet",
        ]);
        assert_eq!(hal.contains("SIMULATED"), simulated, "{hal}");
        assert_eq!(ini.contains("SIMULATED"), simulated, "{ini}");
    }
}
