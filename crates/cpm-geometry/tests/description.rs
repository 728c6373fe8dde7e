//! Robot description files: the shipped examples, round trips and every kind of error.
use cpm_geometry::description::{
    CalibrationSpec, InstallationErrorsSpec, LinkSpec, LoadSpec, RobotDescription,
};
use cpm_geometry::{GeometryError, InstallationErrors, JointTable};
use proptest::prelude::*;

fn example(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

fn err_message(r: Result<RobotDescription, GeometryError>) -> String {
    match r {
        Err(e @ GeometryError::Description { .. }) => e.to_string(),
        Err(e) => panic!("wrong error kind: {e}"),
        Ok(_) => panic!("expected an error"),
    }
}

fn paper_text() -> String {
    std::fs::read_to_string(example("paper_cubic.toml")).unwrap()
}

#[test]
fn paper_example_loads_and_equals_the_paper_table() {
    let desc = RobotDescription::load(example("paper_cubic.toml")).unwrap();
    assert_eq!(desc.joint_table().unwrap(), JointTable::paper_cubic());
    assert_eq!(desc, RobotDescription::paper_cubic());
    assert_eq!(desc.name.as_deref(), Some("paper cubic"));
    assert_eq!(desc.clearance.unwrap().radius_um, 10.0);
    let load = desc.load.unwrap();
    assert_eq!(load.platform_mass_kg, 20.0);
    assert_eq!(load.platform_com_mm, [0.0, 0.0, -100.0]);
    assert_eq!(desc.installation_errors().unwrap(), None);
}

#[test]
fn hexapod_example_loads_and_equals_the_constructor() {
    let desc = RobotDescription::load(example("hexapod_66.toml")).unwrap();
    let table = desc.joint_table().unwrap();
    assert_eq!(table, JointTable::hexapod_66());
    assert_eq!(desc, RobotDescription::hexapod_66());
    assert_eq!(table.sensors.len(), 3);
    // The stated geometry: radii, pair angles, home height.
    for (i, l) in table.links.iter().enumerate() {
        assert!((l.base_mm.norm() - 200.0).abs() < 1e-8);
        assert!((l.platform_mm.norm() - 120.0).abs() < 1e-8);
        let b = l.base_mm.y.atan2(l.base_mm.x).to_degrees();
        let p = l.platform_mm.y.atan2(l.platform_mm.x).to_degrees();
        let pair_b = [0.0, 0.0, 120.0, 120.0, 240.0, 240.0][i];
        let pair_p = [300.0, 60.0, 60.0, 180.0, 180.0, 300.0][i];
        let off = |a: f64, c: f64| ((a - c).rem_euclid(360.0) + 180.0).rem_euclid(360.0) - 180.0;
        assert!(
            (off(b, pair_b).abs() - 15.0).abs() < 1e-6,
            "link {i} base at {b}"
        );
        assert!(
            (off(p, pair_p).abs() - 15.0).abs() < 1e-6,
            "link {i} platform at {p}"
        );
    }
    assert_eq!(table.home.position_mm.z, 300.0);
}

#[test]
fn paper_home_lengths_by_hand() {
    let t = RobotDescription::paper_cubic().joint_table().unwrap();
    let home = t.home;
    let len = |i: usize| {
        let l = &t.links[i];
        (home.transform_point(&l.platform_mm) - l.base_mm).norm()
    };
    for i in 0..3 {
        assert_eq!(len(i), 354.0); // 410 - 28 - 28
    }
    assert_eq!(len(3), 354.0); // 177 + 177
    assert_eq!(len(4), 354.0);
    assert!((len(5) - (382.0f64.powi(2) + 10.0f64.powi(2)).sqrt()).abs() < 1e-12);
    let s = t.sensor("paper").unwrap().length_mm(&home);
    assert!((s - (295.0f64.powi(2) + 95.0f64.powi(2)).sqrt()).abs() < 1e-12);
}

#[test]
fn round_trip_with_every_section() {
    let mut d = RobotDescription::paper_cubic();
    d.links[2] = LinkSpec {
        length_limits_mm: Some([300.0, 420.0]),
        length_at_zero_mm: 250.0,
        mm_per_unit: 0.5e-3,
        ..d.links[2]
    };
    d.home.rpy_deg = [1.5, -2.25, 30.0];
    d.calibration = Some(CalibrationSpec {
        effects: vec!["link_offset".into(), "link_scale".into()],
        sensor_noise_um: Some(5.0),
        tracker_position_sigma_um: Some(12.5),
        tracker_orientation_sigma_urad: None,
        screw_lead_mm: Some(4.0),
        reference_temperature_c: Some(21.5),
        reference_time_s: Some(1000.0),
        nonlinearity_scale_mm: None,
        known_effects: [
            (
                "backlash".to_string(),
                vec![1.5, -2.0, 0.0, 0.25, 3.0, -1.0],
            ),
            ("sensor_offset".to_string(), vec![12.0]),
        ]
        .into_iter()
        .collect(),
        instruments: [("camera".to_string(), vec![2.0, -1.5, 0.25])]
            .into_iter()
            .collect(),
        tolerances: [("link_scale".to_string(), 20_000.0)].into_iter().collect(),
        tolerance_limit: Some(2.5),
        hold: vec!["installation_errors".into()],
        undetermined: vec!["base 1 x".into()],
        blind_directions: vec!["all base joints translated together".into()],
        calibrated_from: Some("../robot.toml".into()),
        calibrated_from_fnv1a64: Some("0123456789abcdef".into()),
        simulated: true,
        covariance: Some(cpm_geometry::description::CovarianceSpec {
            effects: vec!["link_offset".into()],
            parameters: vec!["a [um]".into(), "b [um]".into()],
            std: vec![1.5, 0.25],
            correlation: vec![vec![1.0, -0.3], vec![-0.3, 1.0]],
            unbounded: vec!["b [um]".into()],
        }),
    });
    d.installation_errors_um = Some(InstallationErrorsSpec::from_errors(
        &InstallationErrors::paper_table2(),
    ));
    d.load = Some(LoadSpec {
        payload_mass_kg: 3.5,
        payload_com_mm: [1.0, 2.0, 3.0],
        external_force_n: [0.5, 0.0, -1.0],
        external_moment_nmm: [0.0, 100.0, 0.0],
        ..LoadSpec::platform(20.0, [0.0, 0.0, -100.0])
    });
    d.clearance.as_mut().unwrap().smooth_force_n = 1.0;
    let text = d.to_toml_string().unwrap();
    let back = RobotDescription::from_toml_str(&text, "<round trip>").unwrap();
    assert_eq!(back, d);
    assert!(text.contains("[calibration.known_effects]"), "{text}");
    assert!(text.contains("[calibration.instruments]"), "{text}");
    assert_eq!(
        back.installation_errors().unwrap().unwrap(),
        InstallationErrors::paper_table2()
    );
    assert_eq!(back.lengths_from_readings(&[0.0; 6]).unwrap()[2], 250.0);
    assert!(back.lengths_from_readings(&[0.0; 5]).is_err());

    // Through a file too.
    let dir = tempfile::Builder::new()
        .prefix("cpm-geometry-test-")
        .tempdir()
        .unwrap();
    let path = dir.path().join("robot.toml");
    d.save(&path).unwrap();
    assert_eq!(RobotDescription::load(&path).unwrap(), d);
}

#[test]
fn from_joint_table_round_trip() {
    for t in [JointTable::paper_cubic(), JointTable::hexapod_66()] {
        let d = RobotDescription::from_joint_table(&t);
        assert_eq!(d.joint_table().unwrap(), t);
        let text = d.to_toml_string().unwrap();
        assert_eq!(
            RobotDescription::from_toml_str(&text, "<t>")
                .unwrap()
                .joint_table()
                .unwrap(),
            t
        );
    }
}

#[test]
fn defaults_apply_and_integers_are_accepted() {
    let text = paper_text()
        .replace("rpy_deg = [0.0, 0.0, 0.0]\n", "")
        .replace(
            "position_mm = [0.0, 0.0, 410.0]",
            "position_mm = [0, 0, 410]",
        )
        .replace("smooth_force_n = 0.0\n", "")
        .replace("payload_mass_kg = 0.0\n", "")
        .replace("payload_com_mm = [0.0, 0.0, 0.0]\n", "")
        .replace("gravity_mm_s2 = [0.0, 0.0, -9806.65] # in {B}\n", "")
        .replace("external_force_n = [0.0, 0.0, 0.0]\n", "")
        .replace("external_moment_nmm = [0.0, 0.0, 0.0]\n", "");
    let d = RobotDescription::from_toml_str(&text, "<defaults>").unwrap();
    assert_eq!(d, RobotDescription::paper_cubic());
    assert!(d
        .links
        .iter()
        .all(|l| l.mm_per_unit == 1.0 && l.length_at_zero_mm == 0.0));
}

#[test]
fn minimal_description() {
    let mut text = String::from("[home]\nposition_mm = [0.0, 0.0, 410.0]\n");
    for l in &JointTable::paper_cubic().links {
        text.push_str(&format!(
            "[[link]]\nbase_mm = [{}, {}, {}]\nplatform_mm = [{}, {}, {}]\n",
            l.base_mm.x,
            l.base_mm.y,
            l.base_mm.z,
            l.platform_mm.x,
            l.platform_mm.y,
            l.platform_mm.z
        ));
    }
    let d = RobotDescription::from_toml_str(&text, "<minimal>").unwrap();
    let t = d.joint_table().unwrap();
    assert!(t.sensors.is_empty());
    assert_eq!(t.links, JointTable::paper_cubic().links);
    assert!(d.clearance.is_none() && d.load.is_none() && d.calibration.is_none());
}

#[test]
fn unknown_keys_are_named_with_their_line() {
    let text = paper_text().replace("radius_um = 10.0", "radius_um = 10.0\nradius_mm = 0.01");
    let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
    assert!(msg.starts_with("robot.toml: "), "{msg}");
    assert!(msg.contains("unknown field `radius_mm`"), "{msg}");
    assert!(msg.contains("line"), "{msg}");

    // In an array of tables, at the top level, and a misspelt section.
    for (from, to, key) in [
        (
            "[[link]] # link 4: along x",
            "[[link]]\nbse_mm = [0.0, 0.0, 0.0]",
            "bse_mm",
        ),
        (
            "name = \"paper cubic\"",
            "name = \"paper cubic\"\nversion = 2",
            "version",
        ),
        ("[clearance]", "[clearence]", "clearence"),
        (
            "name = \"paper\"",
            "name = \"paper\"\nradius_mm = 1.0",
            "radius_mm",
        ),
    ] {
        let text = paper_text().replacen(from, to, 1);
        let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
        assert!(msg.contains(&format!("`{key}`")), "{key}: {msg}");
        assert!(msg.contains("line"), "{msg}");
    }
}

#[test]
fn missing_fields_are_named() {
    let text = paper_text().replacen("platform_mm = [-140.0, 140.0, -28.0]\n", "", 1);
    let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
    assert!(msg.contains("missing field `platform_mm`"), "{msg}");
    assert!(msg.contains("line"), "{msg}");

    let text = paper_text().replace("[home]\nposition_mm = [0.0, 0.0, 410.0]\n", "[home]\n");
    let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
    assert!(msg.contains("missing field `position_mm`"), "{msg}");

    let msg = err_message(RobotDescription::from_toml_str(
        "name = \"x\"\n",
        "robot.toml",
    ));
    assert!(msg.contains("missing field `home`"), "{msg}");
}

#[test]
fn wrong_types_and_shapes() {
    for (from, to, what) in [
        ("radius_um = 10.0", "radius_um = \"ten\"", "radius_um"),
        (
            "base_mm = [-140.0, -140.0, 28.0]",
            "base_mm = [-140.0, -140.0]",
            "expected 3 numbers, got 2",
        ),
        (
            "position_mm = [0.0, 0.0, 410.0]",
            "position_mm = [0, 0, 300, 999, 1e9]",
            "expected 3 numbers, got 5",
        ),
        (
            "base_mm = [-140.0, -140.0, 28.0]",
            "base_mm = [-140.0, -140.0, 28.0, 1.0]",
            "expected 3 numbers, got 4",
        ),
        (
            "platform_mass_kg = 20.0",
            "platform_mass_kg = [20.0]",
            "platform_mass_kg",
        ),
    ] {
        let text = paper_text().replacen(from, to, 1);
        let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
        assert!(msg.contains("line"), "{msg}");
        assert!(
            msg.contains(what)
                || (what == "radius_um" || what == "platform_mass_kg") && msg.contains("invalid"),
            "{what}: {msg}"
        );
    }
    let msg = err_message(RobotDescription::from_toml_str("[home\n", "bad.toml"));
    assert!(
        msg.starts_with("bad.toml: ") && msg.contains("line 1"),
        "{msg}"
    );
}

#[test]
fn non_finite_values_name_the_field_and_line() {
    let cases = [
        (
            "base_mm = [140.0, 0.0, 28.0]",
            "base_mm = [140.0, nan, 28.0]",
            "link[3].base_mm",
            26,
        ),
        (
            "platform_mm = [0.0, 177.0, -140.0]",
            "platform_mm = [0.0, 177.0, inf]",
            "link[6].platform_mm",
            39,
        ),
        (
            "position_mm = [0.0, 0.0, 410.0]",
            "position_mm = [0.0, 0.0, -inf]",
            "home.position_mm",
            12,
        ),
        (
            "radius_um = 10.0",
            "radius_um = nan",
            "clearance.radius_um",
            49,
        ),
        (
            "platform_com_mm = [0.0, 0.0, -100.0]",
            "platform_com_mm = [0.0, 0.0, nan]",
            "load.platform_com_mm",
            56,
        ),
        (
            "base_mm = [-200.0, 500.0, 500.0]",
            "base_mm = [-200.0, 500.0, inf]",
            "sensor[1].base_mm",
            44,
        ),
    ];
    for (from, to, field, line) in cases {
        let text = paper_text().replacen(from, to, 1);
        assert_eq!(
            text.lines()
                .position(|l| l.contains(to.split(" = ").next().unwrap())
                    && l.contains(to.split(" = ").nth(1).unwrap())),
            Some(line - 1),
            "test table: {to} is not on line {line}"
        );
        let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
        assert!(
            msg.contains(&format!("{field}: must be finite")),
            "{field}: {msg}"
        );
        assert!(
            msg.contains(&format!("(line {line}, column ")),
            "{field}: {msg}"
        );
    }
}

#[test]
fn semantic_errors_name_the_key_path() {
    let mut text = paper_text();
    text = text.replacen(
        "platform_mm = [140.0, 0.0, -28.0]",
        "platform_mm = [140.0, 0.0, -28.0]\nmm_per_unit = 0.0",
        1,
    );
    let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
    assert!(
        msg.contains(
            "link[3].mm_per_unit: must be finite and non-zero, got 0 (line 28, column 15)"
        ),
        "{msg}"
    );

    for (from, to, expect) in [
        (
            "platform_mm = [-140.0, 140.0, -28.0]",
            "platform_mm = [-140.0, 140.0, -28.0]\nlength_limits_mm = [420.0, 300.0]",
            "link[2].length_limits_mm: need finite 0 < min < max",
        ),
        (
            "platform_mm = [-140.0, 140.0, -28.0]",
            "platform_mm = [-140.0, 140.0, -28.0]\nlength_at_zero_mm = inf",
            "link[2].length_at_zero_mm: must be finite",
        ),
        ("radius_um = 10.0", "radius_um = -1.0", "clearance.radius_um: must be finite and >= 0"),
        ("platform_mass_kg = 20.0", "platform_mass_kg = -20.0", "load.platform_mass_kg"),
        (
            "[clearance]",
            "[[sensor]]\nname = \"paper\"\nbase_mm = [0.0, 0.0, 0.0]\nplatform_mm = [0.0, 0.0, 0.0]\n\n[clearance]",
            "sensor[2].name: duplicate sensor name `paper`",
        ),
        ("name = \"paper\"", "name = \"\"", "sensor[1].name: must not be empty"),
        (
            "# [calibration]\n# effects = []\n# sensor_noise_um = 2.0",
            "[calibration]\neffects = [\"link_offset\", \"link_offset\"]",
            "calibration.effects[2]: duplicate effect",
        ),
        (
            "# [calibration]\n# effects = []\n# sensor_noise_um = 2.0",
            "[calibration]\nsensor_noise_um = nan",
            "calibration.sensor_noise_um",
        ),
        (
            "# [calibration]\n# effects = []\n# sensor_noise_um = 2.0",
            "[calibration]\nscrew_lead_mm = 0.0",
            "calibration.screw_lead_mm: must be finite and > 0",
        ),
        (
            "# [calibration]\n# effects = []\n# sensor_noise_um = 2.0",
            "[calibration]\neffects = []\n\n[calibration.known_effects]\nbacklash = [1.0, nan, 0.0, 0.0, 0.0, 0.0]",
            "calibration.known_effects.backlash[2]: must be finite, got NaN",
        ),
        (
            "# [calibration]\n# effects = []\n# sensor_noise_um = 2.0",
            "[calibration]\n\n[calibration.known_effects]\nclearance = []",
            "calibration.known_effects.clearance: has no values",
        ),
        (
            "# [calibration]",
            "[installation_errors_um]\nbase = [[1.0, 2.0, 3.0]]\nplatform = []\n# [calibration]",
            "installation_errors_um.base: has 1 rows",
        ),
    ] {
        assert!(paper_text().contains(from), "test table: {from}");
        let text = paper_text().replacen(from, to, 1);
        let msg = err_message(RobotDescription::from_toml_str(&text, "robot.toml"));
        assert!(msg.contains(expect), "{expect}: {msg}");
        assert!(msg.contains("(line "), "{msg}");
    }
}

#[test]
fn installation_error_rows_are_checked() {
    let mut d = RobotDescription::paper_cubic();
    let mut e = InstallationErrorsSpec::from_errors(&InstallationErrors::paper_table3());
    e.platform[4][1] = f64::NAN;
    d.installation_errors_um = Some(e);
    let text = d.to_toml_string().unwrap();
    let msg = err_message(RobotDescription::from_toml_str(&text, "r.toml"));
    assert!(
        msg.contains("installation_errors_um.platform[5]: must be finite"),
        "{msg}"
    );
    assert!(msg.contains("(line "), "{msg}");
}

#[test]
fn too_few_links() {
    let text = paper_text();
    let cut = text.find("[[link]] # link 6").unwrap();
    let end = text.find("# The paper's length sensor").unwrap();
    let five = format!("{}{}", &text[..cut], &text[end..]);
    let msg = err_message(RobotDescription::from_toml_str(&five, "five.toml"));
    assert!(
        msg.contains("link: need at least 6 [[link]] tables, got 5"),
        "{msg}"
    );

    let mut d = RobotDescription::paper_cubic();
    d.links.truncate(3);
    match d.joint_table() {
        Err(GeometryError::Description { path, message }) => {
            assert_eq!(path, "robot description `paper cubic`");
            assert!(message.contains("got 3"), "{message}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn zero_length_link_and_missing_file() {
    let mut d = RobotDescription::paper_cubic();
    d.links[0].platform_mm = [-140.0, -140.0, 28.0 - 410.0];
    let msg = d.validate().unwrap_err().to_string();
    assert!(
        msg.contains("link[1]: zero length at the home pose"),
        "{msg}"
    );

    let msg = err_message(RobotDescription::load("/nonexistent/robot.toml"));
    assert!(
        msg.starts_with("/nonexistent/robot.toml: cannot read the file"),
        "{msg}"
    );
}

#[test]
fn joint_table_validate_still_rejects_nan() {
    let mut t = JointTable::paper_cubic();
    t.links[1].base_mm.x = f64::NAN;
    assert!(t.validate().is_err());
    // And a description built from it refuses to become a table again.
    assert!(RobotDescription::from_joint_table(&t)
        .joint_table()
        .is_err());
}

proptest! {
    /// Arbitrary text never panics the loader.
    #[test]
    fn loading_never_panics_on_arbitrary_text(s in "\\PC{0,400}") {
        let _ = RobotDescription::from_toml_str(&s, "<fuzz>");
    }

    /// Nor does a mutated example: a byte range deleted or replaced by TOML-ish noise.
    #[test]
    fn loading_never_panics_on_mutated_examples(
        hexapod in prop::bool::ANY,
        at in 0.0..1.0f64,
        len in 0usize..40,
        insert in "[\\[\\]=\"#a-z0-9_., \\n-]{0,20}|nan|inf|-inf|1e400|\\[\\]",
    ) {
        let text = std::fs::read_to_string(example(if hexapod { "hexapod_66.toml" } else { "paper_cubic.toml" })).unwrap();
        let mut start = ((text.len() as f64) * at) as usize;
        while !text.is_char_boundary(start) { start -= 1; }
        let mut end = (start + len).min(text.len());
        while !text.is_char_boundary(end) { end -= 1; }
        let mutated = format!("{}{}{}", &text[..start], insert, &text[end..]);
        if let Ok(d) = RobotDescription::from_toml_str(&mutated, "<mutated>") {
            // Whatever loads is valid and converts.
            prop_assert!(d.joint_table().is_ok());
        }
    }

    /// A description with arbitrary finite numbers round-trips exactly through TOML.
    #[test]
    fn round_trip_arbitrary_numbers(
        v in prop::collection::vec(-1e6..1e6f64, 36),
        limits in prop::option::of((1.0..100.0f64, 100.0..1000.0f64)),
        scale in prop_oneof![Just(1.0), 1e-6..10.0f64],
    ) {
        let mut d = RobotDescription::paper_cubic();
        for (i, l) in d.links.iter_mut().enumerate() {
            l.base_mm = [v[6 * i], v[6 * i + 1], v[6 * i + 2]];
            l.platform_mm = [v[6 * i + 3], v[6 * i + 4], v[6 * i + 5]];
            l.length_limits_mm = limits.map(|(a, b)| [a, b]);
            l.mm_per_unit = scale;
        }
        prop_assume!(d.validate().is_ok());
        let back = RobotDescription::from_toml_str(&d.to_toml_string().unwrap(), "<rt>").unwrap();
        prop_assert_eq!(back, d);
    }
}

/// The TOML blocks of `docs/robot-description.md` are valid.
#[test]
fn documentation_examples_load() {
    let doc = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/robot-description.md"),
    )
    .unwrap();
    let blocks: Vec<&str> = doc
        .split("```toml\n")
        .skip(1)
        .map(|b| b.split("```").next().unwrap())
        .collect();
    assert_eq!(blocks.len(), 6);
    // In the order of the document: [calibration.known_effects], [calibration.instruments],
    // [pose_map], the instruments, the paper, the encoder link.
    let known_block = blocks[0];
    let own_instruments_block = blocks[1];
    let pose_map_block = blocks[2];
    let instruments_block = blocks[3];
    let blocks = &blocks[4..];

    // The [pose_map] example, appended to the paper's description.
    let d = RobotDescription::from_toml_str(&format!("{}\n{pose_map_block}", paper_text()), "doc")
        .unwrap();
    let p = d.pose_map.unwrap();
    assert_eq!(p.fitted_min.unwrap()[1], -97.5);
    assert_eq!(p.fitted_max.unwrap()[2], 489.5);
    assert_eq!(d.calibration.unwrap().known_effects["pose_map_y2"].len(), 6);

    // The instruments example, added to the paper's cube: the gauge, the region, the limits,
    // and a setup whose window holds its length at home.
    let text = format!("{}\n{instruments_block}", paper_text());
    let d = RobotDescription::from_toml_str(&text, "doc").unwrap();
    let g = d.gauge(None).unwrap();
    assert_eq!((g.name.as_str(), g.stroke_mm), ("lg200", 200.0));
    assert_eq!(d.socket_places().len(), 25);
    let l = d.limits.unwrap();
    assert_eq!(
        (l.link_link_mm(), l.gauge_link_mm(Some(g))),
        (Some(40.0), 30.0)
    );
    let s = &d.sensors[1];
    let (lo, hi) = g.window_mm(s.bar_mm.unwrap());
    let home = d.joint_table().unwrap().sensors[1].length_mm(&d.home.pose());
    assert!(lo <= home && home <= hi, "{lo} {home} {hi}");
    assert!((home - 581.5).abs() < 0.05, "{home}");

    // The abridged paper example, with links 2 to 5 filled in.
    let middle: String = JointTable::paper_cubic().links[1..5]
        .iter()
        .map(|l| {
            format!(
                "[[link]]\nbase_mm = [{}, {}, {}]\nplatform_mm = [{}, {}, {}]\n",
                l.base_mm.x,
                l.base_mm.y,
                l.base_mm.z,
                l.platform_mm.x,
                l.platform_mm.y,
                l.platform_mm.z
            )
        })
        .collect();
    assert!(blocks[0].contains("# ... links 2 to 5 ...\n"));
    let full = blocks[0].replace("# ... links 2 to 5 ...\n", &middle);
    let d = RobotDescription::from_toml_str(&full, "doc").unwrap();
    assert_eq!(d.joint_table().unwrap(), JointTable::paper_cubic());
    assert_eq!(
        d.installation_errors().unwrap().unwrap(),
        InstallationErrors::paper_table2()
    );
    assert_eq!(
        d.calibration.unwrap().effects,
        ["link_offset", "link_scale"]
    );

    // The encoder link, as link 3 of the paper's cube.
    let text = paper_text();
    let start = text.find("[[link]] # link 3").unwrap();
    let end = text.find("[[link]] # link 4").unwrap();
    let text = format!("{}{}\n{}", &text[..start], blocks[1], &text[end..]);
    let d = RobotDescription::from_toml_str(&text, "doc").unwrap();
    let mut expected = JointTable::paper_cubic();
    expected.links[2].length_limits_mm = Some((300.0, 420.0));
    assert_eq!(d.joint_table().unwrap(), expected);
    assert_eq!(d.links[2].length_mm(208_000.0), 354.0);

    // The [calibration.known_effects] example, in place of the paper's commented table.
    let from = "# [calibration]\n# effects = []\n# sensor_noise_um = 2.0";
    assert!(paper_text().contains(from));
    let text = paper_text().replacen(from, known_block, 1);
    let d = RobotDescription::from_toml_str(&text, "doc").unwrap();
    let c = d.calibration.unwrap();
    assert_eq!(c.effects, ["backlash"]);
    assert_eq!(c.known_effects["backlash"].len(), 6);
    assert_eq!(c.known_effects["sensor_offset"], [12.5]);

    // The [calibration.instruments] example, appended to the paper's description.
    let text = format!("{}\n{own_instruments_block}", paper_text());
    let d = RobotDescription::from_toml_str(&text, "doc").unwrap();
    assert_eq!(d.calibration.unwrap().instruments["camera"].len(), 7);
}

/// The messages quoted in `docs/robot-description.md` are the real ones.
#[test]
fn documented_messages_are_real() {
    let text = paper_text();
    let cut = text.find("[[link]] # link 6").unwrap();
    let end = text.find("# The paper's length sensor").unwrap();
    let five = format!("{}{}", &text[..cut], &text[end..]);
    let msg = err_message(RobotDescription::from_toml_str(&five, "robot.toml"));
    assert_eq!(
        msg,
        "robot.toml: link: need at least 6 [[link]] tables, got 5 (line 17, column 1)"
    );
    let msg = err_message(RobotDescription::from_toml_str(
        &text.replace("radius_um = 10.0", "radius_um = nan"),
        "robot.toml",
    ));
    assert_eq!(
        msg,
        "robot.toml: clearance.radius_um: must be finite and >= 0, got NaN (line 49, column 13)"
    );
}

/// Deeply nested input is refused by the parser's recursion limit, not a stack overflow.
#[test]
fn deep_nesting_does_not_overflow() {
    for (open, close) in [("[", "]"), ("{a=", "}")] {
        let s = format!("x = {}1{}", open.repeat(100_000), close.repeat(100_000));
        assert!(RobotDescription::from_toml_str(&s, "<deep>").is_err());
    }
    let s = format!("{}= 1", "a.".repeat(100_000));
    assert!(RobotDescription::from_toml_str(&s, "<deep keys>").is_err());
}

/// `[pose_map]`: the fitted range must be finite, ordered and given whole; the degree 0 to 3.
#[test]
fn pose_map_section_is_checked() {
    let text = paper_text();
    for (table, needle) in [
        ("degree = 4", "pose_map.degree: must be 0 to 3, got 4"),
        (
            "fitted_min = [0, 0, 0, 0, 0, 0]",
            "pose_map: give both fitted_min and fitted_max, or neither",
        ),
        (
            "fitted_min = [0, 5, 0, 0, 0, 0]\nfitted_max = [1, 1, 1, 1, 1, 1]",
            "pose_map.fitted_min[2]: 5 is above fitted_max 1",
        ),
    ] {
        let msg = err_message(RobotDescription::from_toml_str(
            &format!("{text}\n[pose_map]\n{table}\n"),
            "robot.toml",
        ));
        assert!(msg.contains(needle), "{msg}");
    }
    let ok = format!("{text}\n[pose_map]\ndegree = 3\nfitted_min = [0, 0, 0, 0, 0, 0]\nfitted_max = [1, 1, 1, 1, 1, 1]\n");
    let d = RobotDescription::from_toml_str(&ok, "robot.toml").unwrap();
    assert_eq!(d.pose_map.unwrap().degree, Some(3));
    let back = RobotDescription::from_toml_str(&d.to_toml_string().unwrap(), "rt").unwrap();
    assert_eq!(back, d);
}
