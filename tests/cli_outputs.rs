//! Every output as a metrologist reads it (issue 61): each figure with its own unit, no sum
//! over mixed units.
#[path = "common/cli.rs"]
mod cli;

use cli::{example, ok};

/// `cpm identifiability` gives its Cramér-Rao bounds with their unit, and one RMS per unit
/// where the parameters mix units (link offsets in um beside link scales in ppm): it printed
/// "RMS 17.101, worst 28.647" with no unit, over offsets and scales together.
#[test]
fn identifiability_bounds_carry_their_units_and_never_mix_them() {
    let (robot, data) = (
        example("hexapod_66.toml"),
        example("hexapod_66_readings.csv"),
    );
    let bounds = |effects: &str| -> String {
        let out = ok(&[
            "identifiability",
            "--robot",
            &robot,
            "--data",
            &data,
            "--effects",
            effects,
        ]);
        out.lines()
            .find(|l| l.starts_with("Cramér-Rao bounds"))
            .unwrap_or_else(|| panic!("{out}"))
            .to_string()
    };
    let plain = bounds("none");
    assert!(
        plain.contains(" um, worst ") && plain.ends_with(" um"),
        "{plain}"
    );
    let mixed = bounds("link_offset,link_scale");
    let (um, ppm) = mixed.split_once("; ").unwrap_or_else(|| panic!("{mixed}"));
    assert!(um.ends_with("in um)"), "{mixed}");
    assert!(
        ppm.ends_with("in ppm)") && ppm.contains(" ppm, worst "),
        "{mixed}"
    );
    // 36 joint components and 6 offsets in um, 6 scales in ppm, as far as determined.
    let count = |s: &str| -> usize {
        let open = s.rfind('(').unwrap();
        s[open + 1..].split(' ').next().unwrap().parse().unwrap()
    };
    assert!(
        count(um) <= 42 && count(ppm) <= 6 && count(ppm) > 0,
        "{mixed}"
    );
}

/// The fold scheme of the tracker residuals' choice is said in words (it printed "Blocks"),
/// and each frame parameter carries its own unit (every row read "[um (translation), urad
/// (rotation)]"), in report.md and calibration.json.
#[test]
fn the_fold_scheme_is_said_in_words() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/jugglebot");
    let dir = cli::scratch("outputs", "folds");
    let o = cli::cpm(&[
        "calibrate",
        "--robot",
        &cli::p(&root.join("robot.toml")),
        "--data",
        &cli::p(&root.join("session_108.csv")),
        "--out",
        &cli::p(&dir.join("cal")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("tracker residuals:"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(
        line.contains("cross-validated, contiguous blocks in acquisition order:"),
        "{line}"
    );
    assert!(!line.contains("Blocks"), "{line}");
    let report = std::fs::read_to_string(dir.join("cal/report.md")).unwrap();
    let json = std::fs::read_to_string(dir.join("cal/calibration.json")).unwrap();
    for text in [&report, &json] {
        // A group's tolerance may name both units; a parameter has one.
        assert!(
            !text.contains("[um (translation), urad (rotation)]"),
            "a row with two units"
        );
    }
    for row in [
        "tracker_frame tx [um]",
        "tracker_frame rz [urad]",
        "marker_frame ty [um]",
        "marker_frame rx [urad]",
    ] {
        assert!(report.contains(row), "no row '{row}' in report.md");
        assert!(json.contains(row), "no '{row}' in calibration.json");
    }
}

/// The help says numbers, not rustdoc links ("Implicit from [`IMPLICIT_FROM_READINGS`]
/// readings"), and `--data` names every kind of measurement file.
#[test]
fn the_help_says_numbers_and_every_kind_of_file() {
    let help = ok(&["calibrate", "--help"]);
    assert!(!help.contains("[`"), "a rustdoc link in the help:\n{help}");
    let implicit = format!(
        "Implicit from {} readings",
        cpm::calib::fit::formulation::IMPLICIT_FROM_READINGS
    );
    assert!(help.contains(&implicit), "no '{implicit}' in:\n{help}");
    for kind in [
        "length readings",
        "tracker poses",
        "reflector points",
        "inclinometer angles",
    ] {
        assert!(help.contains(kind), "--data does not name {kind}:\n{help}");
    }
}

/// The example hexapod with an inclinometer and three reflectors.
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

/// The y axis labels of an SVG figure's panels, and how many filled data marks (circles,
/// rings, triangles, squares: plotters' `<circle`, `<polygon`, `<rect`, less the background)
/// it holds; crosses are lines and are not counted.
fn panels_and_marks(svg: &str) -> (Vec<String>, usize) {
    let labels = [
        "length residual (um)",
        "position residual (um)",
        "orientation residual (urad)",
        "point residual (um)",
        "angle residual (urad)",
    ]
    .iter()
    .filter(|l| svg.contains(*l))
    .map(|l| l.to_string())
    .collect();
    let marks = ["<circle", "<polygon", "<rect"]
        .iter()
        .map(|m| svg.matches(m).count())
        .sum::<usize>()
        - 1;
    (labels, marks)
}

/// Every residual figure is drawn for every kind of observation, in that kind's unit, one
/// panel per kind (inclinometer campaigns gave empty 0-1 axes labelled "residual (um)"):
/// the real inclinometer session (angles only), a simulated points-only campaign and a
/// simulated campaign of gauges, points and angles together.
#[test]
fn residual_figures_hold_every_kind_in_its_unit() {
    let d = cli::scratch("outputs", "figures");
    let robot = d.join("robot.toml");
    let r = std::fs::read_to_string(example("hexapod_66.toml")).unwrap();
    std::fs::write(&robot, r + INSTRUMENTS).unwrap();
    let robot = cli::p(&robot);
    let sim = |measure: &str, noise: &str| -> String {
        let out = cli::p(&d.join(format!("{measure}.csv")));
        ok(&[
            "simulate",
            "--robot",
            &robot,
            "--random",
            "30",
            "--measure",
            measure,
            "--seed",
            "3",
            "--noise",
            noise,
            "--out",
            &out,
        ]);
        out
    };
    let points = sim("points", "gaussian:5");
    let tilts = sim("tilts", "gaussian:20");
    let gauges = cli::p(&d.join("gauges.csv"));
    ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "30",
        "--seed",
        "4",
        "--noise",
        "gaussian:1",
        "--out",
        &gauges,
    ]);
    let tilt_root =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/jugglebot_tilt");
    let (tilt_robot, tilt_data) = (
        cli::p(&tilt_root.join("robot.toml")),
        cli::p(&tilt_root.join("session_1.csv")),
    );
    let cases: [(&str, &str, Vec<&str>, &[&str]); 3] = [
        (
            "tilt-only",
            &tilt_robot,
            vec![&tilt_data],
            &["angle residual (urad)"],
        ),
        (
            "points-only",
            &robot,
            vec![&points],
            &["point residual (um)"],
        ),
        (
            "mixed",
            &robot,
            vec![&gauges, &points, &tilts],
            &[
                "length residual (um)",
                "point residual (um)",
                "angle residual (urad)",
            ],
        ),
    ];
    for (name, robot, data, want) in cases {
        let out = d.join(name);
        let mut args = vec!["calibrate", "--robot", robot];
        for f in &data {
            args.extend_from_slice(&["--data", f]);
        }
        let o = cli::p(&out);
        args.extend_from_slice(&["--out", &o]);
        ok(&args);
        let svg = std::fs::read_to_string(out.join("residuals_pose.svg")).unwrap();
        let (labels, marks) = panels_and_marks(&svg);
        assert_eq!(labels, want.to_vec(), "{name}: panels");
        assert!(!svg.contains(">residual (um)<"), "{name}: a unitless panel");
        // The observations are marks (crosses aside, a quarter of the series at most).
        let observations: usize = std::fs::read_to_string(out.join("residuals.csv"))
            .unwrap()
            .lines()
            .count()
            - 1;
        assert!(
            2 * marks >= observations,
            "{name}: {marks} marks for {observations} observations"
        );
        let estimates = std::fs::read_to_string(out.join("estimates.svg")).unwrap();
        assert!(
            estimates.matches("<line").count() + estimates.matches("<polyline").count() > 2,
            "{name}: estimates.svg holds no estimate"
        );
    }
}
