//! One bad row in a real log is flagged, not fatal (issue 33): `cpm calibrate` on 40
//! simulated poses of the example hexapod, one of them lifted 200 mm out of the machine's
//! reach, leaves that pose out with a warning naming its line, lists it in
//! `calibration.json`, and fits what the file without its rows gives.
use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
use cli::{calibrate_json, cpm, example, ok, p, scratch};

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

const INSTRUMENTS: &str = "
[[inclinometer]]
name = \"scl3300\"
axes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]

[[target]]
name = \"smr1\"
platform_mm = [90.0, 10.0, 30.0]

[[target]]
name = \"smr2\"
platform_mm = [-50.0, 80.0, 25.0]

[[target]]
name = \"smr3\"
platform_mm = [-40.0, -85.0, 35.0]
";

/// The example hexapod with an inclinometer and three reflectors, and its truth (the
/// inclinometer mounted 0.1-0.3 deg off).
fn instrument_robots(d: &Path) -> (String, String) {
    let (robot, truth) = (d.join("robot.toml"), d.join("truth.toml"));
    let r = std::fs::read_to_string(example("hexapod_66.toml")).unwrap();
    std::fs::write(&robot, r + INSTRUMENTS).unwrap();
    let t = std::fs::read_to_string(example("hexapod_66_truth.toml")).unwrap();
    let mounted = INSTRUMENTS.replacen(
        "axes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\n",
        "axes = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\nmount_rpy_deg = [0.15, -0.1, 0.3]\n",
        1,
    );
    std::fs::write(&truth, t + &mounted).unwrap();
    (p(&robot), p(&truth))
}

/// The commanded pose columns of an instrument file.
const COMMANDED: [&str; 6] = [
    "cmd_x_mm",
    "cmd_y_mm",
    "cmd_z_mm",
    "cmd_roll_deg",
    "cmd_pitch_deg",
    "cmd_yaw_deg",
];

/// `text` (a file as `cpm simulate` writes it: the simulated line, then the header) without
/// the columns `drop`.
fn without_columns(text: &str, drop: &[&str]) -> String {
    let header: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let mut out = String::new();
    for (k, l) in text.lines().enumerate() {
        if k == 0 {
            out.push_str(l);
        } else {
            let f: Vec<&str> = l.split(',').collect();
            let keep: Vec<&str> = (0..f.len())
                .filter(|&i| !drop.contains(&header[i]))
                .map(|i| f[i])
                .collect();
            out.push_str(&keep.join(","));
        }
        out.push('\n');
    }
    out
}

/// `text` (an instrument file as `cpm simulate` writes it) with pose `label`'s `reading_1`
/// 1000 mm longer on each of its rows (no pose of the machine has such link lengths), and
/// the same file without that pose's rows; the columns `drop` left out of both. Returns the
/// two texts and the pose's first line (1-based).
fn glitch(text: &str, label: &str, drop: &[&str]) -> (String, String, usize) {
    let header: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (pose, reading) = (col("pose"), col("reading_1"));
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !drop.contains(&header[i]))
        .collect();
    let (mut bad, mut without, mut first) = (String::new(), String::new(), None);
    for (k, l) in text.lines().enumerate() {
        let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
        if k >= 1 {
            let this = k >= 2 && f[pose] == label;
            if this {
                first.get_or_insert(k + 1);
                f[reading] = (f[reading].parse::<f64>().unwrap() + 1000.0).to_string();
            }
            f = keep.iter().map(|&i| f[i].clone()).collect();
            if !this {
                without.push_str(&f.join(","));
                without.push('\n');
            }
        } else {
            without.push_str(l);
            without.push('\n');
        }
        bad.push_str(&f.join(","));
        bad.push('\n');
    }
    (bad, without, first.expect("the pose"))
}

/// `cpm calibrate` of a tilt or point file with one pose whose link readings give no pose
/// (40 poses): exit 0, the warning `FILE:LINE: pose "17" excluded: ...` on stderr, the pose in
/// `calibration.json`'s `excluded_poses`, and the estimates of the file without its rows.
/// `why`: the start of the reason (after `excluded: `).
fn instrument_pose_left_out(
    d: &Path,
    robot: &str,
    text: &str,
    name: &str,
    drop: &[&str],
    why: &str,
) -> serde_json::Value {
    let (bad, without, line) = glitch(text, "17", drop);
    let (bad_path, cut) = (
        d.join(format!("{name}.csv")),
        d.join(format!("{name}-cut.csv")),
    );
    std::fs::write(&bad_path, bad).unwrap();
    std::fs::write(&cut, without).unwrap();
    let out = d.join(format!("{name}.out"));
    let o = cpm(&[
        "calibrate",
        "--robot",
        robot,
        "--data",
        &p(&bad_path),
        "--out",
        &p(&out),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{name}: {stderr}");
    let warning = format!(
        "warning: {}:{line}: pose \"17\" excluded: {why}",
        p(&bad_path)
    );
    assert!(stderr.contains(&warning), "{name}: {stderr}");
    assert!(
        stderr.contains("forward kinematics did not converge"),
        "{stderr}"
    );
    let read = |dir: &Path, file: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(file)).unwrap()).unwrap()
    };
    let json = read(&out, "calibration.json");
    let excluded = json["excluded_poses"].as_array().expect("excluded_poses");
    assert_eq!(excluded.len(), 1, "{name}");
    assert_eq!(excluded[0]["file"], p(&bad_path));
    assert_eq!(excluded[0]["line"], line);
    assert_eq!(excluded[0]["label"], "17");
    assert!(excluded[0]["reason"].as_str().unwrap().starts_with(why));
    let cut_out = d.join(format!("{name}-cut.out"));
    ok(&[
        "calibrate",
        "--robot",
        robot,
        "--data",
        &p(&cut),
        "--out",
        &p(&cut_out),
    ]);
    let reference = read(&cut_out, "calibration.json");
    assert!(reference.get("excluded_poses").is_none());
    for key in [
        "installation_errors_um",
        "std_um",
        "effects",
        "residual_rms_um",
        "poses",
        "readings",
        "noise_by_kind",
    ] {
        assert_close(&json[key], &reference[key], 1e-9, &format!("{name}: {key}"));
    }
    json
}

#[test]
fn calibrate_leaves_out_a_tilt_or_point_pose_whose_link_readings_give_no_pose() {
    let d = scratch("excluded", "instruments");
    let (robot, truth) = instrument_robots(&d);
    let sim = |measure: &str, extra: &[&str]| -> String {
        let out = d.join(format!("{measure}.csv"));
        let mut args = vec![
            "simulate",
            "--robot",
            &robot,
            "--truth",
            &truth,
            "--random",
            "40",
            "--measure",
            measure,
            "--seed",
            "1",
        ];
        args.extend_from_slice(extra);
        let o = p(&out);
        args.extend_from_slice(&["--out", &o]);
        ok(&args);
        std::fs::read_to_string(&out).unwrap()
    };
    let tilts = sim(
        "tilts",
        &[
            "--range-deg",
            "10",
            "--noise",
            "gaussian:20",
            "--base-tilt-deg",
            "0.04,-0.02",
        ],
    );
    let points = sim(
        "points",
        &[
            "--noise",
            "gaussian:5",
            "--tracker-frame",
            "1500,200,-100,0,0,30",
        ],
    );
    // Files with the commanded pose beside the link readings (as `cpm simulate` writes them):
    // the reader takes the commanded pose, and the fit, which starts forward kinematics of
    // the logged lengths there, cannot start at pose 17; it leaves it out and fits again.
    let fit = "the fit cannot start there: forward kinematics did not converge";
    let t = instrument_pose_left_out(&d, &robot, &tilts, "tilts-commanded", &[], fit);
    // 39 poses of two angles each are fitted.
    assert_eq!(t["poses"], 39);
    assert_eq!(
        t["noise_by_kind"][0]["observations"], 78,
        "{}",
        t["noise_by_kind"]
    );
    instrument_pose_left_out(&d, &robot, &points, "points-commanded", &[], fit);
    // Files with the link readings alone: the reader's forward kinematics (its commanded
    // pose) gives no pose at pose 17; the reader leaves it out.
    let read = "gives no pose: forward kinematics of its link readings: ";
    let t = instrument_pose_left_out(&d, &robot, &tilts, "tilts-readings", &COMMANDED, read);
    assert_eq!(t["poses"], 39);
    instrument_pose_left_out(&d, &robot, &points, "points-readings", &COMMANDED, read);

    // `cpm refine` lists the poses left out in refine.json as calibrate does in
    // calibration.json (the fit's and the reader's alike); for a clean file, not at all.
    for name in ["tilts-commanded", "points-commanded"] {
        let refine = |data: &Path| -> serde_json::Value {
            let out = data.with_extension("refine");
            ok(&[
                "refine",
                "--robot",
                &robot,
                "--data",
                &p(data),
                "--out",
                &p(&out),
            ]);
            serde_json::from_str(&std::fs::read_to_string(out.join("refine.json")).unwrap())
                .unwrap()
        };
        let bad = d.join(format!("{name}.csv"));
        let doc = refine(&bad);
        let calibration: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.join(format!("{name}.out/calibration.json"))).unwrap(),
        )
        .unwrap();
        let excluded = doc["excluded_poses"].as_array().expect("excluded_poses");
        assert_eq!(excluded.len(), 1, "{name}");
        assert_eq!(excluded[0]["file"], p(&bad));
        assert_eq!(excluded[0]["label"], "17");
        assert!(excluded[0]["reason"].as_str().unwrap().starts_with(fit));
        assert_eq!(
            doc["excluded_poses"], calibration["excluded_poses"],
            "{name}"
        );
        let clean = refine(&d.join(format!("{name}-cut.csv")));
        assert!(clean.get("excluded_poses").is_none(), "{name}");
    }
}

/// A tilt file and a point file that log the link readings alone (no commanded pose): the
/// reader's commanded poses are the forward kinematics of the logged lengths on the design
/// geometry, whichever robot reads them, so `cpm calibrate` passes its own read-back check
/// (exit 0) and `cpm validate` of `calibrated.toml` (whose joints carry the fitted installation
/// errors) on the same file reproduces the fit's residual RMS. Before the design geometry was
/// used, the read-back took the calibrated geometry and both files failed ("does not
/// reproduce the fit": 8.34 vs 9.97, 4.93 vs 6.51).
#[test]
fn calibrate_and_validate_agree_on_tilt_and_point_files_of_link_readings_alone() {
    let d = scratch("excluded", "readings-alone");
    let (robot, truth) = instrument_robots(&d);
    let cases: [(&str, &[&str], &[&str]); 2] = [
        (
            "tilts",
            &[
                "--range-deg",
                "10",
                "--noise",
                "gaussian:20",
                "--base-tilt-deg",
                "0.04,-0.02",
            ],
            // The reference noise of the weighting equal to the angle noise: the residual RMS
            // in urad.
            &["--sigma-um", "20", "--orientation-sigma-urad", "20"],
        ),
        (
            "points",
            &[
                "--noise",
                "gaussian:5",
                "--tracker-frame",
                "1500,200,-100,0,0,30",
            ],
            &[],
        ),
    ];
    for (measure, sim, fit) in cases {
        let full = d.join(format!("{measure}-full.csv"));
        let mut args = vec![
            "simulate",
            "--robot",
            &robot,
            "--truth",
            &truth,
            "--random",
            "40",
            "--measure",
            measure,
            "--seed",
            "1",
        ];
        args.extend_from_slice(sim);
        let o = p(&full);
        args.extend_from_slice(&["--out", &o]);
        ok(&args);
        // The file without its commanded pose columns.
        let text = std::fs::read_to_string(&full).unwrap();
        let alone = without_columns(&text, &COMMANDED);
        let header = alone.lines().nth(1).unwrap();
        assert!(
            header.contains("reading_6") && !header.contains("cmd_"),
            "{header}"
        );
        let data = d.join(format!("{measure}.csv"));
        std::fs::write(&data, &alone).unwrap();
        let out = d.join(format!("{measure}.out"));
        let json = calibrate_json(Path::new(&robot), &[&data], fit, &out);
        // Angles alone have no RMS in um (calibration.json's residual_rms_um is null): theirs
        // is in urad, per kind.
        let fitted = if measure == "tilts" {
            assert!(
                json["residual_rms_um"].is_null(),
                "{}",
                json["residual_rms_um"]
            );
            cli::kind_rms(&json, "inclinometer angles")
        } else {
            json["residual_rms_um"].as_f64().unwrap()
        };
        let calibrated = out.join("calibrated.toml");
        let toml = std::fs::read_to_string(&calibrated).unwrap();
        // The calibrated geometry is not the design: the two robots' forward kinematics of
        // the readings differ.
        assert!(toml.contains("[installation_errors_um]"), "{toml}");
        let v: serde_json::Value = serde_json::from_str(&ok(&[
            "validate",
            "--robot",
            &p(&calibrated),
            "--reference",
            &robot,
            "--data",
            &p(&data),
            "--json",
        ]))
        .unwrap();
        let c = &v["calibrated"];
        let (back, by_kind) = if measure == "tilts" {
            (
                c["orientation_rms_urad"].as_f64().unwrap(),
                json["noise_by_kind"][0]["rms"].as_f64().unwrap(),
            )
        } else {
            (c["rms_um"].as_f64().unwrap(), fitted)
        };
        eprintln!("{measure} read alone: fit RMS {fitted}, validate {back}");
        assert!(
            (back - fitted).abs() <= 1e-9 * fitted,
            "{measure}: fit {fitted}, validate {back}"
        );
        assert!(
            (back - by_kind).abs() <= 1e-9 * by_kind,
            "{measure}: {by_kind} vs {back}"
        );
    }
}

/// `cpm validate` compares the two robots on the same poses: a pose that one robot's reading
/// leaves out (here: a description whose links are 5 mm shorter than the one pose of 40 that
/// needs the longest link, the other robot the example hexapod) is left out for both, and
/// each robot's figures are those of the file without that pose's rows; so whichever of the
/// two is `--robot` and which `--reference`. The pose is warned of once.
#[test]
fn validate_leaves_out_for_both_robots_a_pose_either_robot_leaves_out() {
    let d = scratch("excluded", "validate-union");
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
    // The longest link of each pose; the pose that needs the longest of all.
    let example_robot = cpm_io::Robot::load(Path::new(&robot)).unwrap();
    let file = cpm::workflow::ingest::read_data_file(
        &data,
        &example_robot,
        &cpm_io::ReadOptions::default(),
        &Default::default(),
    )
    .unwrap();
    let longest: Vec<f64> = file
        .campaign
        .poses
        .iter()
        .map(|q| {
            cpm_kinematics::inverse_lengths(&example_robot.table, q)
                .into_iter()
                .fold(f64::MIN, f64::max)
        })
        .collect();
    let far = (0..longest.len())
        .max_by(|a, b| longest[*a].total_cmp(&longest[*b]))
        .unwrap();
    let next = (0..longest.len())
        .filter(|&j| j != far)
        .map(|j| longest[j])
        .fold(f64::MIN, f64::max);
    assert!(longest[far] > next + 0.2, "{} vs {next}", longest[far]);
    let label = file.pose_labels[far].clone();
    // Held-out data are read with 5 mm of margin on the link limits
    // (`cpm_io::campaign::CONSISTENCY_MM`): this limit leaves out that pose alone.
    let limit = (longest[far] + next) / 2.0 - cpm_io::campaign::CONSISTENCY_MM;
    let text = std::fs::read_to_string(&robot).unwrap();
    assert_eq!(text.matches("length_limits_mm = [250.0, 400.0]").count(), 6);
    let short = d.join("short.toml");
    std::fs::write(
        &short,
        text.replace(
            "length_limits_mm = [250.0, 400.0]",
            &format!("length_limits_mm = [250.0, {limit}]"),
        ),
    )
    .unwrap();
    // The file without that pose's rows.
    let all = std::fs::read_to_string(&data).unwrap();
    let header: Vec<&str> = all.lines().nth(1).unwrap().split(',').collect();
    let pose = header.iter().position(|h| *h == "pose").unwrap();
    let cut = d.join("cut.csv");
    let kept: Vec<&str> = all
        .lines()
        .enumerate()
        .filter(|(k, l)| *k < 2 || l.split(',').nth(pose) != Some(label.as_str()))
        .map(|(_, l)| l)
        .collect();
    assert!(kept.len() < all.lines().count());
    std::fs::write(&cut, kept.join("\n") + "\n").unwrap();
    let short = p(&short);
    for (calibrated, reference) in [(&short, &robot), (&robot, &short)] {
        let validate = |data: &Path| {
            let o = cpm(&[
                "validate",
                "--robot",
                calibrated,
                "--reference",
                reference,
                "--data",
                &p(data),
                "--json",
            ]);
            let stderr = String::from_utf8_lossy(&o.stderr).to_string();
            assert_eq!(o.status.code(), Some(0), "{stderr}");
            let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            (json, stderr)
        };
        let (json, stderr) = validate(&data);
        let warning = format!("{}:", p(&data));
        let warned: Vec<&str> = stderr.lines().filter(|l| l.contains(&warning)).collect();
        assert_eq!(warned.len(), 1, "{stderr}");
        assert!(
            warned[0].contains(&format!("pose {label:?} excluded: ")),
            "{stderr}"
        );
        assert!(warned[0].contains("is not reachable: link"), "{stderr}");
        let (without, plain) = validate(&cut);
        assert!(!plain.contains("excluded"), "{plain}");
        for side in ["calibrated", "reference"] {
            assert_close(&json[side], &without[side], 1e-9, side);
        }
    }
}
