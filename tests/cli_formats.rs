//! File formats of the `cpm` command: round trips (write -> read gives the same campaign) and
//! bad files (each error names file, line and field).
#[path = "common/ingest.rs"]
mod ingest;

use std::path::{Path, PathBuf};

use cpm::calib::campaign::{circle, PoseMeasurement};
use cpm::calib::{
    simulate_campaign, Campaign, Determination, Effect, Noise, Plan, SimulationOptions,
};
use cpm::geometry::{Pose, RobotDescription};
use cpm::io::robot::calibrated_description;
use cpm::io::{
    read_pose_list, write_pose_list, write_pose_measurements, write_readings, FileKind,
    ReadOptions, Robot,
};
use ingest::read_data;

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
}

fn cube() -> Robot {
    Robot::load(&example("paper_cubic.toml")).unwrap()
}

fn hexapod() -> Robot {
    Robot::load(&example("hexapod_66.toml")).unwrap()
}

/// A robot whose link readings are encoder counts (0.5 um, zero at 250 mm).
fn encoder_hexapod() -> Robot {
    let mut d = RobotDescription::hexapod_66();
    for l in d.links.iter_mut() {
        l.length_at_zero_mm = 250.0;
        l.mm_per_unit = 0.0005;
    }
    Robot::from_description(d, "encoder.toml").unwrap()
}

fn simulated(robot: &Robot, poses: Vec<Pose>, logged: bool, timed: bool) -> Campaign {
    let model = robot.model(&[]);
    let plan = Plan {
        sensors: (0..robot.table.sensors.len()).collect(),
        poses,
    };
    let mut skeleton = plan.skeleton();
    if logged {
        skeleton.commanded_lengths_mm = Some(
            plan.poses
                .iter()
                .map(|p| cpm::kinematics::inverse_lengths(&robot.table, p))
                .collect(),
        );
    }
    if timed {
        for (k, r) in skeleton.readings.iter_mut().enumerate() {
            r.time_s = Some(10.0 * k as f64).into();
            r.temperature_c = Some(20.0 + 0.01 * k as f64).into();
        }
    }
    let truth = cpm::geometry::InstallationErrors::paper_table2().to_vec_um();
    simulate_campaign(
        &model,
        &truth,
        &skeleton,
        &SimulationOptions {
            noise: Noise::Gaussian { sigma_um: 1.0 },
            repeats: 1,
            seed: 4,
        },
    )
    .unwrap()
}

fn assert_same(a: &Campaign, b: &Campaign) {
    assert_eq!(a.simulated, b.simulated);
    assert_eq!(a.poses.len(), b.poses.len());
    for (p, q) in a.poses.iter().zip(&b.poses) {
        let d = p.difference(q);
        assert!(d.norm() < 1e-10, "poses differ by {d}");
    }
    assert_eq!(a.readings.len(), b.readings.len());
    for (r, s) in a.readings.iter().zip(&b.readings) {
        assert_eq!((r.pose, r.sensor), (s.pose, s.sensor));
        assert_eq!(r.length_mm, s.length_mm);
        assert_eq!(r.time_s, s.time_s);
        assert_eq!(r.temperature_c, s.temperature_c);
    }
    match (&a.commanded_lengths_mm, &b.commanded_lengths_mm) {
        (None, None) => {}
        (Some(x), Some(y)) => {
            for (u, v) in x.iter().flatten().zip(y.iter().flatten()) {
                assert!((u - v).abs() < 1e-9, "{u} vs {v}");
            }
        }
        _ => panic!("commanded lengths lost"),
    }
    assert_eq!(a.pose_measurements.len(), b.pose_measurements.len());
    for (m, n) in a.pose_measurements.iter().zip(&b.pose_measurements) {
        assert_eq!(m.pose, n.pose);
        assert!(m.measured.difference(&n.measured).norm() < 1e-10);
        assert_eq!(m.time_s, n.time_s);
    }
}

#[test]
fn readings_round_trip_plain_and_logged() {
    let robot = cube();
    let poses = circle(&robot.table.home, 100.0, 12);
    for (logged, timed) in [(false, false), (true, true), (true, false), (false, true)] {
        let c = simulated(&robot, poses.clone(), logged, timed);
        let text = write_readings(&c, &robot, "round trip");
        assert!(text.starts_with("# simulated by cpm"));
        let back = read_data(&text, "data.csv", &robot, &ReadOptions::default()).unwrap();
        assert_eq!(back.kind, FileKind::Readings);
        assert_same(&c, &back.campaign);
        assert_eq!(back.reading_lines[0], 3, "comment, header, first row");
    }
}

#[test]
fn readings_round_trip_with_encoder_counts() {
    let robot = encoder_hexapod();
    let poses = cpm::calib::paper::random_workspace_poses(&robot.table, 8, 30.0, 5.0, 3.0, 2);
    let c = simulated(&robot, poses, true, false);
    let text = write_readings(&c, &robot, "");
    // The link readings are counts: (length - 250) / 0.0005, e.g. about 141 000 at home.
    let header: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let k = header.iter().position(|h| *h == "reading_1").unwrap();
    let u: f64 = text
        .lines()
        .nth(2)
        .unwrap()
        .split(',')
        .nth(k)
        .unwrap()
        .parse()
        .unwrap();
    assert!(u > 50_000.0 && u < 300_000.0, "{u}");
    let back = read_data(&text, "enc.csv", &robot, &ReadOptions::default()).unwrap();
    assert_same(&c, &back.campaign);
}

#[test]
fn simulated_flag_survives_without_the_comment_and_is_absent_for_measured_data() {
    let robot = cube();
    let c = simulated(&robot, circle(&robot.table.home, 100.0, 6), false, false);
    let text = write_readings(&c, &robot, "x");
    let no_comment: String = text.lines().skip(1).map(|l| format!("{l}\n")).collect();
    let back = read_data(&no_comment, "a.csv", &robot, &ReadOptions::default()).unwrap();
    assert!(
        back.campaign.simulated,
        "the simulated column keeps the flag"
    );
    // Measured data: neither the comment nor the column.
    let measured: String = no_comment
        .lines()
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.pop();
            format!("{}\n", f.join(","))
        })
        .collect();
    let back = read_data(&measured, "m.csv", &robot, &ReadOptions::default()).unwrap();
    assert!(!back.campaign.simulated);
    // Columns in another order read the same.
    let reordered = "length_mm,sensor,yaw_deg,pitch_deg,roll_deg,z_mm,y_mm,x_mm,pose\n309.9,paper,0,0,0,410,0,0,a\n";
    let back = read_data(reordered, "r.csv", &robot, &ReadOptions::default()).unwrap();
    assert_eq!(back.campaign.readings[0].length_mm, 309.9);
    assert_eq!(back.campaign.poses[0].position_mm.z, 410.0);
}

#[test]
fn pose_measurements_round_trip_and_quaternions() {
    let robot = hexapod();
    let poses = cpm::calib::paper::random_workspace_poses(&robot.table, 6, 30.0, 5.0, 3.0, 9);
    let c = Campaign {
        commanded_lengths_mm: Some(
            poses
                .iter()
                .map(|p| cpm::kinematics::inverse_lengths(&robot.table, p))
                .collect(),
        ),
        pose_measurements: poses
            .iter()
            .enumerate()
            .map(|(j, p)| PoseMeasurement {
                pose: j,
                measured: *p,
                time_s: Some(j as f64),
                temperature_c: None,
            })
            .collect(),
        poses,
        simulated: true,
        ..Campaign::default()
    };
    let text = write_pose_measurements(&c, &robot, "tracker");
    let back = read_data(&text, "t.csv", &robot, &ReadOptions::default()).unwrap();
    assert_eq!(back.kind, FileKind::PoseMeasurements);
    assert_same(&c, &back.campaign);
    // The same poses as quaternions.
    let mut q = String::from("pose,reading_1,reading_2,reading_3,reading_4,reading_5,reading_6,x_mm,y_mm,z_mm,qw,qx,qy,qz\n");
    for (j, p) in c.poses.iter().enumerate() {
        let l = &c.commanded_lengths_mm.as_ref().unwrap()[j];
        let w = p.quaternion();
        q.push_str(&format!(
            "{j},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            l[0],
            l[1],
            l[2],
            l[3],
            l[4],
            l[5],
            p.position_mm.x,
            p.position_mm.y,
            p.position_mm.z,
            w[0],
            w[1],
            w[2],
            w[3]
        ));
    }
    let back = read_data(&q, "q.csv", &robot, &ReadOptions::default()).unwrap();
    for (a, b) in c.poses.iter().zip(&back.campaign.poses) {
        assert!(a.difference(b).norm() < 1e-12);
    }
    assert!(!back.campaign.simulated);
}

#[test]
fn pose_lists_round_trip() {
    let robot = cube();
    let poses = circle(&robot.table.home, 50.0, 5);
    let text = write_pose_list(&poses);
    let back = read_pose_list(&text, "p.csv").unwrap();
    assert_eq!(back.len(), 5);
    assert_eq!(back[2].label, "3");
    assert_eq!(back[2].line, 4);
    for (a, b) in poses.iter().zip(&back) {
        assert!(a.difference(&b.pose).norm() < 1e-12);
    }
    // A pose list is not a measurement file, and measurements are not a pose list.
    let e = read_data(&text, "p.csv", &robot, &ReadOptions::default()).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("p.csv:1: this is a list of poses"),
        "{e}"
    );
    let data = write_readings(&simulated(&robot, poses, false, false), &robot, "");
    let e = read_pose_list(&data, "d.csv").unwrap_err();
    assert!(
        e.to_string()
            .starts_with("d.csv:2: expected a list of poses"),
        "{e}"
    );
}

const HEADER: &str = "pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm";
const ROW: &str = "1,paper,0,0,410,0,0,0,309.9";

fn bad(text: &str) -> String {
    read_data(text, "data.csv", &cube(), &ReadOptions::default())
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_readings_files_name_file_line_and_field() {
    let cases: Vec<(String, &str)> = vec![
        // Missing column.
        (
            "pose,sensor,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n1,paper,0,0,410,0,0,0\n".into(),
            "data.csv:1: field length_mm: missing column",
        ),
        // Not a number, NaN, empty.
        (format!("{HEADER}\n{ROW}\n1,paper,0,0,410,0,0,0,abc\n"), "data.csv:3: field length_mm: \"abc\" is not a number"),
        (format!("{HEADER}\n1,paper,0,0,410,NaN,0,0,309.9\n"), "data.csv:2: field roll_deg: \"NaN\" is not a finite number"),
        (format!("{HEADER}\n1,paper,0,0,,0,0,0,309.9\n"), "data.csv:2: field z_mm: missing value"),
        // Unknown sensor.
        (format!("{HEADER}\n1,gauge,0,0,410,0,0,0,309.9\n"), "data.csv:2: field sensor: unknown sensor \"gauge\" (the robot description has: paper)"),
        // The platform in metres: a hundred times closer to the base than home.
        (format!("{HEADER}\n1,paper,0,0,0.41,0,0,0,309.9\n"), "data.csv:2: field z_mm: the position (0, 0, 0.41) is 0.4100 mm from the base origin while the robot's home is 410.0 mm away: metres?"),
        // Angles in radians.
        (format!("{HEADER}\n{ROW}\n2,paper,0,0,410,0.05,0,0,309.9\n"), "data.csv:3: field roll_deg: 0.05 degrees, and every angle of the file is within +-0.2 degrees (largest 0.05): radians?"),
        // A length in metres.
        (format!("{HEADER}\n1,paper,0,0,410,0,0,0,0.3099\n"), "data.csv:2: field length_mm: 0.3099 mm is far from the nominal length"),
        // Extra column.
        (format!("{HEADER},humidity\n{ROW},40\n"), "data.csv:1: field humidity: unknown column"),
        // Rows of one pose disagree.
        (format!("{HEADER}\n{ROW}\n1,paper,0,0,411,0,0,0,309.9\n"), "data.csv:3: field z_mm: 411 differs from 410 given for pose \"1\" on line 2"),
        // Wrong number of fields.
        (format!("{HEADER}\n{ROW},5\n"), "data.csv:2: 10 fields, but the header has 9"),
        // Incomplete link readings.
        (format!("{HEADER},reading_1,reading_2\n{ROW},354,354\n"), "data.csv:1: field reading_3: missing column"),
        // Link readings in metres.
        (format!("{HEADER},reading_1,reading_2,reading_3,reading_4,reading_5,reading_6\n{ROW},0.354,0.354,0.354,0.354,0.354,0.382\n"), "data.csv:2: field reading_1: 0.354 means a link length of 0.354 mm"),
        // Both orientations.
        (format!("{HEADER},qw,qx,qy,qz\n{ROW},1,0,0,0\n"), "data.csv:1: give the orientation either as roll_deg,pitch_deg,yaw_deg or as qw,qx,qy,qz"),
        // Empty.
        ("# simulated by cpm\n".into(), "data.csv: no header row"),
        (format!("{HEADER}\n"), "data.csv: no readings"),
    ];
    for (text, want) in cases {
        let got = bad(&text);
        assert!(got.starts_with(want), "\n got: {got}\nwant: {want}");
    }
}

#[test]
fn bad_tracker_files() {
    let robot = hexapod();
    let h = "pose,reading_1,reading_2,reading_3,reading_4,reading_5,reading_6,x_mm,y_mm,z_mm,qw,qx,qy,qz";
    let l = 320.7;
    let row = |label: &str, q: &str| format!("{label},{l},{l},{l},{l},{l},{l},0,0,300,{q}");
    let cases = vec![
        (
            format!("{h}\n{}\n{}\n", row("a", "1,0,0,0"), row("a", "1,0,0,0")),
            "t.csv:3: field pose: pose \"a\" appears again (first on line 2)",
        ),
        (
            format!("{h}\n{}\n", row("a", "2,0,0,0")),
            "t.csv:2: field qw: (qw, qx, qy, qz) = (2, 0, 0, 0) is not a unit quaternion",
        ),
        (
            format!("{}\n{}\n", h.replace(",qz", ""), row("a", "1,0,0")),
            "t.csv:1: field qz: missing column",
        ),
        (
            format!(
                "{h}\n{}\n",
                row("a", "1,0,0,0").replacen("320.7", "3.207", 1)
            ),
            "t.csv:2: field reading_1: 3.207 means a link length of 3.207 mm",
        ),
    ];
    for (text, want) in cases {
        let got = read_data(&text, "t.csv", &robot, &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(got.starts_with(want), "\n got: {got}\nwant: {want}");
    }
}

#[test]
fn calibrated_description_keeps_link_offset_and_scale_as_known_effects() {
    let robot = encoder_hexapod();
    let model = robot.model(&[Effect::LinkOffset, Effect::LinkScale]);
    let mut params: Vec<f64> = vec![0.0; model.num_params()];
    let mut determined = vec![Determination::Determined; model.num_params()];
    params[0] = 10.0; // link 1 base dx, um
    params[7] = -4.0; // link 2 base dy: not determined on its own, written all the same
    determined[7] = Determination::Blind;
    let offsets = [12.0, -7.0, 0.0, 3.0, 25.0, -1.0];
    let scales = [100.0, -50.0, 0.0, 20.0, 5.0, 1.0];
    params[36..42].copy_from_slice(&offsets);
    params[42..48].copy_from_slice(&scales);
    let (d, notes) = calibrated_description(&robot, &model, &params, &determined, None);
    assert_eq!(notes.undetermined, vec!["link 2 base dy".to_string()]);
    // Named with its word in calibrated.toml's comments.
    assert_eq!(
        notes.held,
        vec![(Determination::Blind, "link 2 base dy [um]".to_string())]
    );
    // The design joints stay; the installation errors carry the fit, undetermined ones too.
    assert_eq!(
        d.links,
        robot
            .description
            .links
            .iter()
            .zip(&d.links)
            .map(|(a, b)| cpm::geometry::description::LinkSpec {
                length_at_zero_mm: b.length_at_zero_mm,
                mm_per_unit: b.mm_per_unit,
                ..*a
            })
            .collect::<Vec<_>>()
    );
    let errors = d.installation_errors_um.as_ref().unwrap();
    assert_eq!(errors.base[0][0], 10.0);
    assert_eq!(errors.base[1][1], -4.0);
    let back = Robot::from_description(d.clone(), "cal.toml").unwrap();
    assert!(
        (back.table.links[0].base_mm.x - (robot.table.links[0].base_mm.x + 0.010)).abs() < 1e-12
    );
    assert!(
        (back.table.links[1].base_mm.y - (robot.table.links[1].base_mm.y - 0.004)).abs() < 1e-12
    );
    // link_offset and link_scale are known effects; the reading models stay the robot's, and
    // their folded form (for controllers) is exact.
    let known = &d.calibration.as_ref().unwrap().known_effects;
    assert_eq!(known["link_offset"], offsets.to_vec());
    assert_eq!(known["link_scale"], scales.to_vec());
    assert_eq!(
        d.links
            .iter()
            .map(|l| (l.length_at_zero_mm, l.mm_per_unit))
            .collect::<Vec<_>>(),
        robot
            .description
            .links
            .iter()
            .map(|l| (l.length_at_zero_mm, l.mm_per_unit))
            .collect::<Vec<_>>()
    );
    for i in 0..6 {
        let (l0, k) = cpm::io::robot::folded_reading_model(&back, i);
        for u in [0.0, 120_000.0, 260_000.0] {
            let commanded = robot.length_mm(i, u);
            let effective = commanded * (1.0 + scales[i] * 1e-6) + offsets[i] * 1e-3;
            assert!((l0 + k * u - effective).abs() < 1e-9);
        }
    }
}

#[test]
fn calibrated_description_adds_effect_values_to_the_known_ones() {
    // A robot that already knows a backlash and a sensor offset, recalibrated with backlash and
    // compliance: the new description knows the sums, keeps an undetermined parameter at its
    // old value, and loads back into a model that predicts what the calibrated one did.
    let mut d = hexapod().description.clone();
    d.calibration = Some(cpm::geometry::description::CalibrationSpec {
        known_effects: [
            ("backlash".to_string(), vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]),
            ("sensor_offset".to_string(), vec![7.5, -2.0, 0.5]),
        ]
        .into_iter()
        .collect(),
        ..Default::default()
    });
    let robot = Robot::from_description(d, "known.toml").unwrap();
    let model = robot.model(&[Effect::Backlash, Effect::Compliance]);
    let mut params: Vec<f64> = vec![0.0; model.num_params()];
    let mut determined = vec![Determination::Determined; model.num_params()];
    let fit = [0.5, -1.0, 0.25, 0.0, 2.0, -3.0];
    for i in 0..6 {
        params[36 + i] = fit[i];
        params[42 + i] = 10.0 * (i as f64 + 1.0);
    }
    determined[37] = Determination::HeldByTolerance;
    let (desc, notes) = calibrated_description(
        &robot,
        &model,
        &params,
        &determined,
        Some(&[Effect::Backlash]),
    );
    assert_eq!(notes.known_effects, vec!["backlash", "compliance"]);
    assert_eq!(notes.undetermined_effects.len(), 1);
    let known = &desc.calibration.as_ref().unwrap().known_effects;
    // Link 2's backlash is not determined on its own: written at the fit's point all the same.
    assert_eq!(known["backlash"], vec![1.5, 1.0, 3.25, 4.0, 7.0, 3.0]);
    assert_eq!(
        known["compliance"],
        vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
    );
    assert_eq!(known["sensor_offset"], vec![7.5, -2.0, 0.5]);

    let text = desc.to_toml_string().unwrap();
    let back = Robot::from_toml(&text, "calibrated.toml").unwrap();
    let plan = Plan {
        poses: cpm::calib::paper::random_workspace_poses(&robot.table, 12, 40.0, 8.0, 3.0, 4),
        sensors: (0..robot.table.sensors.len()).collect(),
    };
    let c = plan.skeleton();
    let full: Vec<f64> = params.clone();
    let prepared = cpm::calib::model::Prepared::new(&model, &c).unwrap();
    let y_fit = cpm::calib::model::predict(&model, &prepared, &c, &full, None).unwrap();
    let loaded = back.model(&[]);
    let prepared = cpm::calib::model::Prepared::new(&loaded, &c).unwrap();
    let y_back = cpm::calib::model::predict(&loaded, &prepared, &c, &[0.0; 36], None).unwrap();
    let unfit = {
        let mut m = model.clone();
        m.known_effects.clear();
        let prepared = cpm::calib::model::Prepared::new(&m, &c).unwrap();
        cpm::calib::model::predict(&m, &prepared, &c, &full, None).unwrap()
    };
    let differs = y_fit.iter().zip(&unfit).any(|(a, b)| (a - b).abs() > 1e-4);
    assert!(differs, "the known values should matter");
    for (a, b) in y_fit.iter().zip(&y_back) {
        assert!((a - b).abs() < 1e-9, "fit {a} vs loaded back {b}");
    }
}

#[test]
fn robot_description_errors_are_located() {
    let text = std::fs::read_to_string(example("paper_cubic.toml")).unwrap();
    let e = Robot::from_toml(
        &text.replace("radius_um = 10.0", "radius_um = -1.0"),
        "r.toml",
    )
    .unwrap_err();
    assert_eq!(e.field.as_deref(), Some("clearance.radius_um"));
    let line = e.line.unwrap();
    assert!(
        text.lines().nth(line - 1).unwrap().contains("radius_um"),
        "{e}"
    );
    let e = Robot::from_toml(
        &text.replace("radius_um = 10.0", "radius_mm = 10.0"),
        "r.toml",
    )
    .unwrap_err();
    assert_eq!(e.line, Some(line));
    assert!(e.message.contains("unknown field `radius_mm`"), "{e}");
    let mut d = RobotDescription::paper_cubic();
    d.calibration = Some(cpm::geometry::description::CalibrationSpec {
        effects: vec!["link_offset".into(), "wobble".into()],
        sensor_noise_um: Some(2.0),
        ..Default::default()
    });
    let err = Robot::from_description(d.clone(), "r.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("r.toml: field calibration.effects[2]: unknown effect `wobble`"),
        "{err}"
    );
    d.calibration.as_mut().unwrap().effects.pop();
    let robot = Robot::from_description(d.clone(), "r.toml").unwrap();
    assert_eq!(robot.sensor_noise_um(), Some(2.0));

    // Known effect values: the name must be an effect, the count must fit the machine, and
    // the message names the line of the entry.
    let mut text = d.to_toml_string().unwrap();
    text.push_str("\n[calibration.known_effects]\nsensor_offset = [1.5]\nbacklash = [1.0, 2.0]\n");
    let line = text
        .lines()
        .position(|l| l.starts_with("backlash"))
        .unwrap()
        + 1;
    let e = Robot::from_toml(&text, "r.toml").unwrap_err();
    assert_eq!(e.line, Some(line), "{e}");
    assert_eq!(
        e.field.as_deref(),
        Some("calibration.known_effects.backlash")
    );
    assert!(
        e.message
            .contains("2 values, but backlash has 6 parameters"),
        "{e}"
    );
    let text = text.replace("backlash = [1.0, 2.0]", "wobble = [1.0]");
    let e = Robot::from_toml(&text, "r.toml").unwrap_err();
    assert_eq!(e.line, Some(line), "{e}");
    assert!(e.message.contains("unknown effect `wobble`"), "{e}");
    let text = text.replace("wobble = [1.0]\n", "");
    let robot = Robot::from_toml(&text, "r.toml").unwrap();
    let model = robot.model(&[]);
    assert_eq!(model.known_effects.len(), 1);
    assert_eq!(
        model.known(cpm::calib::Effect::SensorOffset),
        Some(&[1.5][..])
    );
}

#[test]
fn exit_codes_of_errors() {
    use cpm::cli::{exit_kind, ExitKind};
    let calib = |e: cpm::calib::CalibError| exit_kind(&anyhow::Error::new(e));
    assert_eq!(
        calib(cpm::calib::CalibError::NoInformation("x".into())),
        ExitKind::Trouble
    );
    let input = cpm::io::InputError::field("d.csv", 3, "x_mm", "bad");
    assert_eq!(exit_kind(&anyhow::Error::new(input)), ExitKind::Input);
    let io = std::io::Error::new(std::io::ErrorKind::PermissionDenied, "no");
    assert_eq!(
        exit_kind(&anyhow::Error::new(io).context("writing out/")),
        ExitKind::Io
    );
}
