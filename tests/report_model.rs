//! The typed reports of `cpm calibrate` and `cpm refine`: every JSON key the files had before
//! the reports were typed is still there (key sets recorded from the untyped code in
//! tests/data/report_keys, one per run below), and no report.md or CSV file shows a
//! formatting artefact (`-0.000`, `3.0000000000000004`, `NaN`, a Debug name).
//!
//! The data are SIMULATED (`cpm simulate`, seeded), one reading spiked to give an outlier.
#[path = "common/cli.rs"]
mod cli;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use cli::{example, ok, p, scratch};

/// Every key path of a JSON value (`/a/b`, arrays as `[]`).
fn key_paths(v: &serde_json::Value, prefix: &str, out: &mut BTreeSet<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                let q = format!("{prefix}/{k}");
                out.insert(q.clone());
                key_paths(x, &q, out);
            }
        }
        serde_json::Value::Array(a) => {
            for x in a {
                key_paths(x, &format!("{prefix}[]"), out);
            }
        }
        _ => {}
    }
}

fn keys_of(path: &Path) -> BTreeSet<String> {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut out = BTreeSet::new();
    key_paths(&v, "", &mut out);
    out
}

fn recorded(name: &str) -> BTreeSet<String> {
    let f = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/report_keys")
        .join(format!("{name}.txt"));
    std::fs::read_to_string(f)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

fn assert_keeps(name: &str, file: &Path) {
    let old = recorded(name);
    assert!(old.len() > 10, "{name}: fixture too small");
    let new = keys_of(file);
    let missing: Vec<_> = old.difference(&new).collect();
    assert!(
        missing.is_empty(),
        "{}: keys lost: {missing:?}",
        file.display()
    );
}

/// Simulated length readings (40 poses, the paper's Table 2, seed 4) with reading 21 spiked
/// by 0.5 mm.
fn lengths(dir: &Path) -> PathBuf {
    let f = dir.join("len.csv");
    ok(&[
        "simulate",
        "--robot",
        &example("hexapod_66.toml"),
        "--random",
        "40",
        "--paper-table2",
        "--seed",
        "4",
        "--out",
        &p(&f),
    ]);
    let text = std::fs::read_to_string(&f).unwrap();
    let mut n = 0;
    let lines: Vec<String> = text
        .lines()
        .map(|l| {
            if l.starts_with(|c: char| c.is_ascii_digit()) {
                n += 1;
                if n == 21 {
                    let mut v: Vec<String> = l.split(',').map(str::to_string).collect();
                    v[8] = format!("{}", v[8].parse::<f64>().unwrap() + 0.5);
                    return v.join(",");
                }
            }
            l.to_string()
        })
        .collect();
    std::fs::write(&f, lines.join("\n") + "\n").unwrap();
    f
}

/// Every report.md and .csv file under `dir` (recursively), checked for artefacts.
fn assert_clean_text(dir: &Path) -> usize {
    let mut checked = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let path = e.unwrap().path();
        if path.is_dir() {
            checked += assert_clean_text(&path);
            continue;
        }
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if !(name.ends_with(".md") || name.ends_with(".csv"))
            || name == "len.csv"
            || name == "bl.csv"
            || name == "poses_in.csv"
            || name == "sockets_in.csv"
        {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        if let Some(a) = cpm::report::format::find_artefact(&text) {
            panic!("{}: formatting artefact {a:?}", path.display());
        }
        for debug in [
            "AOptimal", "DOptimal", "EOptimal", "Some(", "None", ": true", ": false", "| true",
            "| false",
        ] {
            if name.ends_with(".md") {
                assert!(
                    !text.contains(debug),
                    "{}: Debug text {debug:?}",
                    path.display()
                );
            }
        }
        checked += 1;
    }
    checked
}

#[test]
fn calibrate_keeps_every_json_key_and_writes_clean_text() {
    let d = scratch("report-model", "calibrate");
    let len = lengths(&d);
    let cal = d.join("cal");
    // Declared noise 1 um: the misfit object is filled; the spike is flagged as an outlier.
    let o = cli::cpm(&[
        "calibrate",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        &p(&len),
        "--sigma-um",
        "1",
        "--out",
        &p(&cal),
    ]);
    assert!(cal.join("calibration.json").exists(), "{o:?}");
    assert_keeps("calibrate_lengths", &cal.join("calibration.json"));
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cal.join("calibration.json")).unwrap())
            .unwrap();
    assert!(
        !j["outliers"].as_array().unwrap().is_empty(),
        "{}",
        j["outliers"]
    );
    assert!(j["misfit"].is_object());

    let poses = d.join("poses_in.csv");
    ok(&[
        "simulate",
        "--robot",
        &example("hexapod_66.toml"),
        "--random",
        "30",
        "--range-deg",
        "12",
        "--measure",
        "poses",
        "--noise",
        "gaussian:10",
        "--orientation-noise-urad",
        "20",
        "--seed",
        "3",
        "--paper-table2",
        "--out",
        &p(&poses),
    ]);
    let calp = d.join("calp");
    ok(&[
        "calibrate",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        &p(&poses),
        "--effects",
        "link_offset,tracker_frame",
        "--out",
        &p(&calp),
    ]);
    assert_keeps("calibrate_tracker", &calp.join("calibration.json"));
    let report = std::fs::read_to_string(calp.join("report.md")).unwrap();
    assert!(report.contains("## Tracker registration"), "{report}");
    // The commands compensate writes from the calibrated description: no float noise.
    ok(&[
        "compensate",
        "--robot",
        &p(&cal.join("calibrated.toml")),
        "--poses",
        &example("targets.csv"),
        "--out",
        &p(&d.join("commands.csv")),
    ]);
    assert!(assert_clean_text(&d) >= 2);
}

#[test]
fn refine_keeps_every_json_key_and_writes_clean_text() {
    let d = scratch("report-model", "refine");
    let len = lengths(&d);
    let r = d.join("ref");
    let _ = cli::cpm(&[
        "refine",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        &p(&len),
        "--max-steps",
        "1",
        "--candidates",
        "link_offset,backlash",
        "--out",
        &p(&r),
    ]);
    assert_keeps("refine_no_step", &r.join("refine.json"));

    let bl = d.join("bl.csv");
    ok(&[
        "simulate",
        "--robot",
        &example("hexapod_66.toml"),
        "--random",
        "60",
        "--paper-table2",
        "--truth-effect",
        "backlash=8,8,8,8,8,8",
        "--noise",
        "gaussian:1",
        "--seed",
        "5",
        "--out",
        &p(&bl),
    ]);
    let rb = d.join("refb");
    ok(&[
        "refine",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        &p(&bl),
        "--sigma-um",
        "1",
        "--max-steps",
        "2",
        "--candidates",
        "link_offset,backlash",
        "--out",
        &p(&rb),
    ]);
    assert_keeps("refine_step", &rb.join("refine.json"));
    assert_keeps("refine_calibration", &rb.join("calibration.json"));
    // The text says what refine.json says, rounded to the deviation: 8 um of backlash, found.
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rb.join("refine.json")).unwrap()).unwrap();
    let step = &j["steps"][0];
    assert_eq!(step["effect"], "backlash");
    let report = std::fs::read_to_string(rb.join("report.md")).unwrap();
    for par in step["parameters"].as_array().unwrap() {
        let (v, sd) = cpm::report::format::with_sd(
            par["value"].as_f64().unwrap(),
            par["std"].as_f64().unwrap(),
        );
        let row = format!("| {} | {v} | {sd} |", par["name"].as_str().unwrap());
        assert!(report.contains(&row), "{row} not in\n{report}");
        assert!((par["value"].as_f64().unwrap() - 8.0).abs() < 1.5, "{par}");
    }
    // The estimates figure has one panel per physical group, its unit on the axis.
    let svg = std::fs::read_to_string(rb.join("estimates.svg")).unwrap();
    for axis in ["installation errors, um", "backlash, um"] {
        assert!(svg.contains(axis), "estimates.svg lacks the axis {axis:?}");
    }
    assert!(!svg.contains("unit in report.md"));
    assert!(assert_clean_text(&d) >= 2);
}

#[test]
fn design_keeps_every_json_key_and_names_its_criterion() {
    let d = scratch("report-model", "design");
    let out = d.join("des");
    ok(&[
        "design",
        "--robot",
        &example("hexapod_66.toml"),
        "--base-sockets",
        "3",
        "--platform-sockets",
        "3",
        "--readings",
        "120",
        "--out",
        &p(&out),
    ]);
    assert_keeps("design", &out.join("design.json"));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("(A-optimal criterion"), "{report}");
    assert!(assert_clean_text(&d) >= 3);
}

/// Under an instrument's limits: design.json's keys, the criterion in words, and setup
/// sheets and plans without `-0.000000000` (which the library's CSV writers print).
#[test]
fn limited_design_keeps_every_json_key_and_writes_clean_csv() {
    let d = scratch("report-model", "limited");
    let sockets = d.join("sockets_in.csv");
    let c = cpm::calib::design::SocketCandidates::paper_cubic();
    let mut text = String::from("name,side,x_mm,y_mm,z_mm\n");
    for (side, list) in [("base", &c.base), ("platform", &c.platform)] {
        for s in list.iter() {
            let v = s.position_mm;
            text.push_str(&format!("{},{side},{},{},{}\n", s.name, v.x, v.y, v.z));
        }
    }
    std::fs::write(&sockets, text).unwrap();
    let out = d.join("lim");
    ok(&[
        "design",
        "--robot",
        &example("paper_cubic.toml"),
        "--sockets",
        &p(&sockets),
        "--readings",
        "240",
        "--candidates",
        "200",
        "--range-mm",
        "100",
        "--range-deg",
        "20",
        "--stroke-mm",
        "80",
        "--setups",
        "8",
        "--out",
        &p(&out),
    ]);
    assert_keeps("design_limited", &out.join("design.json"));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("(A-optimal criterion;"), "{report}");
    std::fs::remove_file(&sockets).unwrap();
    // report.md, setup_sheet.md, setup_sheet.csv and one plan per setup.
    assert!(assert_clean_text(&d) >= 5);
}

/// `cargo xtask reproduce-paper`'s summary.json, from the typed `PaperReport`: every key the
/// untyped `json!` value had (recorded from a full run of it in
/// tests/data/report_keys/reproduce_paper.txt) is still written, report.md shows no
/// formatting artefact, and its text quotes the numbers the JSON holds. The reproduction is
/// SIMULATED, here with small budgets so the test stays fast (the key set does not depend on
/// the budgets as long as every study runs at least once).
#[test]
fn reproduce_paper_summary_keeps_its_keys() {
    use cpm::calib::paper::{reproduce, LimitedOptions, PaperOptions};
    let mut options = PaperOptions {
        design_candidates: 150,
        monte_carlo_runs: 2,
        validation_poses: 10,
        ..PaperOptions::default()
    };
    options.design.max_readings = 320;
    let mut limited = LimitedOptions {
        max_setups: 6,
        monte_carlo_runs: 2,
        tradeoff: true,
        tradeoff_exchanges: 2,
        ..LimitedOptions::default()
    };
    limited.search.minimax_rounds = 0;
    limited.search.select.max_exchanges = 4;
    limited.search.projections = 40;
    limited.search.windows_per_pair = 2;
    options.limited = Some(limited);
    let r = reproduce(&options, |_| {}).unwrap();
    let dir = scratch("report_model", "reproduce_paper");
    let mut files = cpm::output::OutputSet::new();
    cpm::paper_report::render(&r, &dir, &mut files).unwrap();
    cpm::paper_report::render_limited(&r, &dir, &mut files).unwrap();
    files.commit().unwrap();
    assert_keeps("reproduce_paper", &dir.join("summary.json"));
    let report = cpm::report::paper::PaperReport::new(&r);
    // The JSON written is the typed summary, and the free functions agree with it.
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(written["seed"], serde_json::json!(options.seed));
    assert_eq!(
        written["paper_design"]["rank"],
        serde_json::json!(r.paper.calibration.identifiability.rank)
    );
    assert_eq!(
        written["designed"]["monte_carlo"]["runs"],
        serde_json::json!(2)
    );
    // The whole result is in the JSON: the 36 estimates with their standard deviations on
    // both campaigns, and what the paper's design identifies.
    let comps = written["components"].as_array().unwrap();
    assert_eq!(comps.len(), 36);
    // (serde_json reads a float back to within an ulp or so.)
    let same = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() <= 1e-12 * b.abs().max(1e-300),
        (a, b) => a.is_none() && b.is_none(),
    };
    for (k, c) in comps.iter().enumerate() {
        let (d, p) = (&r.designed.calibration, &r.paper.calibration);
        assert!(same(c["designed_um"].as_f64(), d.estimate_um[k]), "{c}");
        assert!(same(c["designed_std_um"].as_f64(), d.std_um[k]), "{c}");
        assert!(same(c["paper_design_um"].as_f64(), p.estimate_um[k]), "{c}");
        assert!(c["table2_um"].is_f64() && c["name"].is_string(), "{c}");
    }
    let combos = written["paper_design"]["identifiable_combinations"]
        .as_array()
        .unwrap();
    assert_eq!(combos.len(), r.paper.calibration.combinations.len());
    assert!(
        !combos.is_empty() && combos[0]["std_um"].is_f64(),
        "{}",
        combos[0]
    );
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    // No wall time in the results (they are the same on every run; xtask writes the times
    // to timings.json).
    for solver in [&r.paper.calibration.solver, &r.designed.calibration.solver] {
        let elapsed = format!("{:.3?}", solver.elapsed);
        let json = std::fs::read_to_string(dir.join("summary.json")).unwrap();
        assert!(
            !json.contains(&elapsed) && !md.contains(&elapsed),
            "{elapsed}"
        );
    }
    // The blind-direction summary's first line does not run into the next in HTML.
    assert!(!md.contains("determined on their own\n"), "{md}");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert_eq!(
        html.matches(">Figures</h2>").count(),
        1,
        "two Figures sections"
    );
    assert_eq!(md, report.report_md());
    assert_eq!(md, cpm::paper_report::report_md(&r));
    assert!(
        md.contains(&format!(
            "**Rank of the identification Jacobian: {} of 36**",
            report.summary.paper_design.rank
        )),
        "{md}"
    );
    let l = report.summary.limited.as_ref().unwrap();
    assert_eq!(
        l.tradeoff.len(),
        cpm::calib::paper::TRADEOFF_STROKES_MM.len()
    );
    assert!(md.contains(&format!(
        "**{} readings in {} setups;",
        l.readings, l.setups
    )));
    // report.md and the setup sheet are for people; designed/readings.csv is simulated
    // input data at full precision, as `cpm simulate` writes it.
    for name in [
        "report.md",
        "designed/setup_sheet.md",
        "designed/setup_sheet.csv",
    ] {
        let text = std::fs::read_to_string(dir.join(name)).unwrap();
        assert_eq!(cpm::report::format::find_artefact(&text), None, "{name}");
        assert!(
            !text.contains("AOptimal") && !text.contains("Some("),
            "{name}"
        );
    }
}
