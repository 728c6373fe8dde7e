//! Helpers shared by the command-line tests: example paths, scratch directories, running the
//! `cpm` under test. Each test binary uses what it needs.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The path of a shipped example, `examples/<name>`.
pub fn example(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
        .display()
        .to_string()
}

/// A fresh scratch directory `<prefix>-<name>` for one test.
pub fn scratch(prefix: &str, name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{prefix}-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `cpm args`.
pub fn cpm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cpm"))
        .args(args)
        .output()
        .expect("run cpm")
}

/// Runs `cpm args`, which must succeed; its standard output.
pub fn ok(args: &[&str]) -> String {
    let o = cpm(args);
    assert!(
        o.status.success(),
        "cpm {args:?} failed ({:?}):\n{}{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// A path as an argument.
pub fn p(path: &Path) -> String {
    path.display().to_string()
}

/// `cpm validate --robot calibrated --data d1 --data d2 .. --json` (reference from the file),
/// which must succeed: its JSON.
pub fn validate_json(calibrated: &Path, data: &[&Path]) -> serde_json::Value {
    let mut args = vec!["validate".to_string(), "--robot".into(), p(calibrated)];
    for d in data {
        args.extend(["--data".to_string(), p(d)]);
    }
    args.push("--json".into());
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    serde_json::from_str(&ok(&args)).unwrap()
}

/// `cpm calibrate --robot robot --data data --out DATA.out`, which must fail without a panic
/// and without writing its output directory: its standard error.
pub fn calibrate_refused(robot: &Path, data: &Path) -> String {
    let out = data.with_extension("out");
    let o = cpm(&[
        "calibrate",
        "--robot",
        &p(robot),
        "--data",
        &p(data),
        "--out",
        &p(&out),
    ]);
    assert!(!o.status.success(), "{} was accepted", data.display());
    assert!(!out.exists(), "nothing written");
    let e = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!e.contains("panicked"), "{e}");
    e
}

/// `cpm calibrate --robot robot --data d1 --data d2 .. <extra> --out out`, which must succeed:
/// its calibration.json.
pub fn calibrate_json(
    robot: &Path,
    data: &[&Path],
    extra: &[&str],
    out: &Path,
) -> serde_json::Value {
    let mut args = vec!["calibrate".to_string(), "--robot".into(), p(robot)];
    for d in data {
        args.extend(["--data".to_string(), p(d)]);
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    args.extend(["--out".to_string(), p(out)]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(&args);
    serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap()
}

/// A `calibration.json`'s residual RMS in um: `residual_rms_um`, or, when that is `null`
/// (`residual_weighted`: kinds of different units or noise), the RMS over the observations
/// of its kinds in um (lengths, points, tracker positions; `noise_by_kind`, each kind's
/// set-aside observations left out). Panics when no kind is in um.
pub fn length_rms_um(json: &serde_json::Value) -> f64 {
    if let Some(r) = json["residual_rms_um"].as_f64() {
        assert_eq!(
            json["residual_weighted"], false,
            "a figure in um beside weighting"
        );
        return r;
    }
    assert_eq!(json["residual_weighted"], true, "{json}");
    let (mut ss, mut n) = (0.0, 0.0);
    for k in json["noise_by_kind"].as_array().unwrap() {
        if k["unit"] == "um" {
            let used =
                (k["observations"].as_u64().unwrap() - k["set_aside"].as_u64().unwrap()) as f64;
            ss += used * k["rms"].as_f64().unwrap().powi(2);
            n += used;
        }
    }
    assert!(n > 0.0, "no kind in um: {}", json["noise_by_kind"]);
    (ss / n).sqrt()
}

/// The RMS of one kind of observation of a `calibration.json` (`noise_by_kind[].rms`, in
/// its own unit), by name (`inclinometer angles`, `tracker orientations`, `gauge s1`, ...).
pub fn kind_rms(json: &serde_json::Value, kind: &str) -> f64 {
    json["noise_by_kind"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["kind"] == kind)
        .unwrap_or_else(|| panic!("no kind {kind}: {}", json["noise_by_kind"]))["rms"]
        .as_f64()
        .unwrap()
}
