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

/// The fold scheme of the tracker residuals' choice is said in words (it printed "Blocks").
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
}
