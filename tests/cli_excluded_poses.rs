//! One bad row in a real log is flagged, not fatal (issue 33): `cpm calibrate` on 40
//! simulated poses of the example hexapod, one of them lifted 200 mm out of the machine's
//! reach, leaves that pose out with a warning naming its line, lists it in
//! `calibration.json`, and fits what the file without its rows gives.
use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
use cli::{cpm, example, ok, p, scratch};

/// Every number under `a` equals the one at the same place under `b` to `tol`.
fn assert_close(a: &serde_json::Value, b: &serde_json::Value, tol: f64, at: &str) {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!((x - y).abs() <= tol, "{at}: {x} vs {y}");
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (k, (u, v)) in x.iter().zip(y).enumerate() {
                assert_close(u, v, tol, &format!("{at}[{k}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (k, u) in x {
                assert_close(u, &y[k], tol, &format!("{at}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}

#[test]
fn calibrate_leaves_out_one_unreachable_pose_in_forty_with_a_warning() {
    let d = scratch("excluded", "calibrate");
    let robot = example("hexapod_66.toml");
    let data = d.join("data.csv");
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--truth",
        &example("hexapod_66_truth.toml"),
        "--random",
        "40",
        "--range-mm",
        "30",
        "--range-deg",
        "5",
        "--seed",
        "3",
        "--out",
        &p(&data),
    ]);
    let text = std::fs::read_to_string(&data).unwrap();
    assert!(text.starts_with("# simulated by cpm"));
    let header: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let (pose, z) = (
        header.iter().position(|h| *h == "pose").unwrap(),
        header.iter().position(|h| *h == "z_mm").unwrap(),
    );
    // Pose 17 lifted by 200 mm (its links far past their 400 mm limit); the same file
    // without its rows.
    let mut lifted = String::new();
    let mut without = String::new();
    let mut first = None;
    for (k, l) in text.lines().enumerate() {
        let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
        if k >= 2 && f[pose] == "17" {
            first.get_or_insert(k + 1);
            f[z] = (f[z].parse::<f64>().unwrap() + 200.0).to_string();
        } else {
            without.push_str(l);
            without.push('\n');
        }
        lifted.push_str(&f.join(","));
        lifted.push('\n');
    }
    let line = first.expect("pose 17");
    let bad = d.join("lifted.csv");
    std::fs::write(&bad, lifted).unwrap();
    let cut = d.join("without.csv");
    std::fs::write(&cut, without).unwrap();

    let out = d.join("lifted.out");
    let o = cpm(&[
        "calibrate",
        "--robot",
        &robot,
        "--data",
        &p(&bad),
        "--out",
        &p(&out),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let warning = format!("warning: {}:{line}: pose \"17\" excluded: (x ", p(&bad));
    assert!(stderr.contains(&warning), "{stderr}");
    assert!(stderr.contains("is not reachable: link"), "{stderr}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap())
            .unwrap();
    let excluded = json["excluded_poses"].as_array().expect("excluded_poses");
    assert_eq!(excluded.len(), 1);
    assert_eq!(excluded[0]["file"], p(&bad));
    assert_eq!(excluded[0]["line"], line);
    assert_eq!(excluded[0]["label"], "17");
    assert!(excluded[0]["reason"]
        .as_str()
        .unwrap()
        .contains("is not reachable"));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("## Poses left out"), "{report}");
    assert!(
        report.contains(&format!("| {}:{line} | 17 |", p(&bad))),
        "{report}"
    );

    // The fit is that of the file without pose 17's rows, and that file's outputs say
    // nothing of poses left out.
    let ref_out = d.join("without.out");
    ok(&[
        "calibrate",
        "--robot",
        &robot,
        "--data",
        &p(&cut),
        "--out",
        &p(&ref_out),
    ]);
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ref_out.join("calibration.json")).unwrap())
            .unwrap();
    assert!(reference.get("excluded_poses").is_none());
    for key in [
        "installation_errors_um",
        "std_um",
        "effects",
        "residual_rms_um",
        "poses",
        "readings",
    ] {
        assert_close(&json[key], &reference[key], 1e-9, key);
    }
    let plain = std::fs::read_to_string(ref_out.join("report.md")).unwrap();
    assert!(!plain.contains("Poses left out"));
    assert!(Path::new(&out).join("calibrated.toml").exists());
}
