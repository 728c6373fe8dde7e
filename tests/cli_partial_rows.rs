//! Partial rows of a tracker file: an empty cell is a component not measured (a lost marker, an
//! orientation not solved). The fit uses the rest: a row left empty fits as if it were not in
//! the file, the components left out are not observations (the file still reproduces its
//! fit), and bad cells are still refused with the file, line and field named.
#[path = "common/cli.rs"]
mod cli;

use std::path::Path;

use cli::{calibrate_refused, example, ok, p, scratch, validate_json};

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text).unwrap()
}

/// A simulated tracker file (40 poses, 5 um, 10 urad, in a frame of its own).
fn tracker_file(dir: &Path) -> (String, Vec<String>) {
    let out = dir.join("tracker.csv");
    ok(&[
        "simulate",
        "--robot",
        &example("hexapod_66.toml"),
        "--truth",
        &example("hexapod_66_truth.toml"),
        "--random",
        "40",
        "--measure",
        "poses",
        "--noise",
        "gaussian:5",
        "--orientation-noise-urad",
        "10",
        "--seed",
        "3",
        "--tracker-frame",
        "800,-300,50,5,-3,40",
        "--out",
        &p(&out),
    ]);
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<String> = text.lines().map(str::to_string).collect();
    (lines[..2].join("\n"), lines[2..].to_vec())
}

/// The data rows with the cells of `columns` emptied in the rows `blank` picks.
fn blanked(header: &str, rows: &[String], blank: impl Fn(usize) -> Vec<&'static str>) -> String {
    let names: Vec<&str> = header.lines().nth(1).unwrap().split(',').collect();
    let mut out = header.to_string() + "\n";
    for (n, row) in rows.iter().enumerate() {
        let mut cells: Vec<&str> = row.split(',').collect();
        for c in blank(n) {
            let i = names.iter().position(|h| *h == c).unwrap();
            cells[i] = "";
        }
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}

/// `cpm calibrate` (tracker noise declared) on `data`; its calibration.json.
fn calibrate(dir: &Path, name: &str, data: &Path) -> serde_json::Value {
    let cal = dir.join(name);
    ok(&[
        "calibrate",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        &p(data),
        "--sigma-um",
        "5",
        "--pose-sigma-um",
        "5",
        "--orientation-sigma-urad",
        "10",
        "--out",
        &p(&cal),
    ]);
    json(&std::fs::read_to_string(cal.join("calibration.json")).unwrap())
}

const ALL: [&str; 6] = ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"];

#[test]
fn an_empty_row_fits_as_a_dropped_row_and_partial_rows_use_the_rest() {
    let dir = scratch("partial", "fit");
    let (header, rows) = tracker_file(&dir);
    let empty_rows = |n: usize| n % 9 == 4;
    // Rows with every measured cell empty ...
    let blank = dir.join("blank.csv");
    std::fs::write(
        &blank,
        blanked(&header, &rows, |n| {
            if empty_rows(n) {
                ALL.to_vec()
            } else {
                Vec::new()
            }
        }),
    )
    .unwrap();
    // ... and the same rows dropped.
    let dropped = dir.join("dropped.csv");
    let kept: Vec<String> = rows
        .iter()
        .enumerate()
        .filter(|(n, _)| !empty_rows(*n))
        .map(|(_, r)| r.clone())
        .collect();
    std::fs::write(&dropped, blanked(&header, &kept, |_| Vec::new())).unwrap();
    let (a, b) = (
        calibrate(&dir, "blank", &blank),
        calibrate(&dir, "dropped", &dropped),
    );
    let (ra, rb) = (cli::length_rms_um(&a), cli::length_rms_um(&b));
    assert!((ra - rb).abs() <= 1e-9 * rb, "{ra} vs {rb}");
    // The installation errors of the fit's point (base and platform, per link, x y z).
    let flat = |v: &serde_json::Value| -> Vec<f64> {
        ["base", "platform"]
            .iter()
            .flat_map(|side| v["minimum_norm_um"][side].as_array().unwrap().clone())
            .flat_map(|row| row.as_array().unwrap().clone())
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (ma, mb) = (flat(&a), flat(&b));
    assert_eq!(ma.len(), 36);
    for (x, y) in ma.iter().zip(&mb) {
        assert!((x - y).abs() <= 1e-6 * (1.0 + y.abs()), "{x} vs {y}");
    }
    // Partial rows: orientation not solved in every fifth row, one coordinate lost in every
    // seventh. The fit uses the rest, and its file reproduces it (calibrate checks that on
    // the same partial file: it would refuse to write otherwise).
    let partial = dir.join("partial.csv");
    std::fs::write(
        &partial,
        blanked(&header, &rows, |n| {
            let mut v = Vec::new();
            if n % 5 == 1 {
                v.extend(["roll_deg", "pitch_deg", "yaw_deg"]);
            }
            if n % 7 == 3 {
                v.push("y_mm");
            }
            v
        }),
    )
    .unwrap();
    let c = calibrate(&dir, "partial", &partial);
    let full = calibrate(&dir, "full", &dir.join("tracker.csv"));
    let rc = cli::length_rms_um(&c);
    assert!((rc - 5.0).abs() < 1.0, "{rc}");
    // Fewer observations: 8 orientations (3 each) and 6 positions (the y coordinate, or the
    // whole position where the registration's rotation mixes the coordinates) left out.
    let obs = |v: &serde_json::Value| v["identifiability"]["observations"].as_u64();
    if let (Some(o1), Some(o2)) = (obs(&c), obs(&full)) {
        assert!(o1 < o2 && o2 - o1 >= 8 * 3 + 6, "{o1} {o2}");
    }
    // validate skips the missing components: the held-out figures count only measured ones.
    let v = validate_json(&dir.join("partial").join("calibrated.toml"), &[&partial]);
    let file_rms = v["calibrated"]["rms_um"].as_f64().unwrap();
    assert!(file_rms.is_finite() && file_rms < 10.0, "{file_rms}");
}

#[test]
fn bad_cells_of_partial_rows_are_refused_with_file_line_and_field() {
    let dir = scratch("partial", "bad");
    let (header, rows) = tracker_file(&dir);
    let robot = std::path::PathBuf::from(example("hexapod_66.toml"));
    let run = |name: &str, text: String| -> String {
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        calibrate_refused(&robot, &f)
    };
    // An orientation given in part: line 4 (the second data row), the empty field named.
    let e = run(
        "half_orientation.csv",
        blanked(&header, &rows, |n| {
            if n == 1 {
                vec!["pitch_deg"]
            } else {
                Vec::new()
            }
        }),
    );
    assert!(
        e.contains("half_orientation.csv:4") && e.contains("pitch_deg"),
        "{e}"
    );
    // A cell that is not a number, in a row with an empty cell beside it.
    let mut text = blanked(&header, &rows, |n| {
        if n == 2 {
            vec!["x_mm"]
        } else {
            Vec::new()
        }
    });
    let line5 = text.lines().nth(4).unwrap().to_string();
    let names: Vec<&str> = header.lines().nth(1).unwrap().split(',').collect();
    let zi = names.iter().position(|h| *h == "z_mm").unwrap();
    let mut cells: Vec<&str> = line5.split(',').collect();
    cells[zi] = "3o7.5";
    text = text.replace(&line5, &cells.join(","));
    let e = run("not_a_number.csv", text);
    assert!(
        e.contains("not_a_number.csv:5") && e.contains("z_mm"),
        "{e}"
    );
}
