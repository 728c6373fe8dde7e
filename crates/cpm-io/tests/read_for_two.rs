//! A readings file read once for two robots (`read_data_file_for_two`, what `cpm validate`
//! does with the calibrated robot and the reference) gives each robot what reading the file
//! for it alone gives: the same poses left out, the same error, or no sharing at all when the
//! robots name their sensors otherwise.
use std::path::{Path, PathBuf};

use cpm_calib::paper::random_workspace_poses;
use cpm_calib::{simulate, Plan, SimulationOptions};
use cpm_io::{read_data_file, read_data_file_for_two, write_readings, DataFile};
use cpm_io::{ReadOptions, Robot, SecondReading};

fn example_text() -> String {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    std::fs::read_to_string(examples.join("hexapod_66.toml")).expect("example robot")
}

fn robot(text: &str) -> Robot {
    Robot::from_toml(text, "hexapod_66.toml").expect("robot")
}

/// 40 simulated poses of the example hexapod, every sensor at each, written to a file.
fn data_file(robot: &Robot, name: &str) -> PathBuf {
    let plan = Plan {
        poses: random_workspace_poses(&robot.table, 40, 30.0, 5.0, 3.0, 11),
        sensors: (0..robot.table.sensors.len()).collect(),
    };
    let truth = vec![0.0; robot.model(&[]).num_params()];
    let data = simulate(
        &robot.model(&[]),
        &truth,
        &plan,
        &SimulationOptions::default(),
    )
    .expect("simulate");
    // Under the target directory, not the system's temporary one (nothing is left there).
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cpm-io-read-for-two");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, write_readings(&data, robot, "test")).unwrap();
    path
}

fn assert_same(a: &DataFile, b: &DataFile) {
    assert_eq!(a.file, b.file);
    assert_eq!(a.kind, b.kind);
    assert_eq!(a.campaign, b.campaign);
    assert_eq!(a.pose_labels, b.pose_labels);
    assert_eq!(a.pose_lines, b.pose_lines);
    assert_eq!(a.reading_lines, b.reading_lines);
    assert_eq!(a.excluded, b.excluded);
}

#[test]
fn the_same_robot_twice_shares_the_reading() {
    let r = robot(&example_text());
    let path = data_file(&r, "same.csv");
    let options = ReadOptions::default();
    let (first, second) = read_data_file_for_two(&path, &r, &r, &options).unwrap();
    assert_same(&first, &read_data_file(&path, &r, &options).unwrap());
    assert!(matches!(second, Some(Ok(SecondReading::SameAsFirst))));
}

/// A second robot whose links are shorter at most: the pose that needs the longest link is
/// left out for it alone, as its own reading leaves it out.
#[test]
fn a_pose_only_the_second_robot_cannot_reach_is_left_out_for_it_alone() {
    let text = example_text();
    let r = robot(&text);
    let path = data_file(&r, "limits.csv");
    let options = ReadOptions::default();
    let first = read_data_file(&path, &r, &options).unwrap();
    // The longest link of each pose; the limit between the two longest.
    let mut longest: Vec<f64> = first
        .campaign
        .poses
        .iter()
        .map(|p| {
            cpm_kinematics::ik::inverse_lengths(&r.table, p)
                .into_iter()
                .fold(f64::MIN, f64::max)
        })
        .collect();
    longest.sort_by(f64::total_cmp);
    let limit = (longest[longest.len() - 1] + longest[longest.len() - 2]) / 2.0;
    let old = "length_limits_mm = [250.0, 400.0]";
    assert!(text.contains(old));
    let shorter = robot(&text.replace(old, &format!("length_limits_mm = [250.0, {limit}]")));
    let alone = read_data_file(&path, &shorter, &options).unwrap();
    assert_eq!(alone.excluded.len(), 1);
    let (shared_first, second) = read_data_file_for_two(&path, &r, &shorter, &options).unwrap();
    assert_same(&shared_first, &first);
    match second {
        Some(Ok(SecondReading::File(f))) => assert_same(&f, &alone),
        other => panic!("expected the second robot's own reading, got {other:?}"),
    }
}

/// A second robot whose gauge is 100 mm off refuses the file with the error its own reading
/// gives (the first robot's reading is unaffected).
#[test]
fn the_second_robot_refuses_the_file_as_its_own_reading_does() {
    let text = example_text();
    let r = robot(&text);
    let path = data_file(&r, "sensor.csv");
    let options = ReadOptions::default();
    let old = "platform_mm = [120.0, 0.0, 0.0]";
    assert!(text.contains(old));
    let moved = robot(&text.replace(old, "platform_mm = [20.0, 0.0, 0.0]"));
    let alone = read_data_file(&path, &moved, &options).unwrap_err();
    let (first, second) = read_data_file_for_two(&path, &r, &moved, &options).unwrap();
    assert_same(&first, &read_data_file(&path, &r, &options).unwrap());
    match second {
        Some(Err(e)) => assert_eq!(e.to_string(), alone.to_string()),
        other => panic!("expected the second robot's error, got {other:?}"),
    }
    // And the other way round: the first robot's error is the error.
    let e = read_data_file_for_two(&path, &moved, &r, &options).unwrap_err();
    assert_eq!(e.to_string(), alone.to_string());
}

/// Sensors named otherwise: the rows name them, nothing is shared.
#[test]
fn sensors_named_otherwise_share_nothing() {
    let text = example_text();
    let r = robot(&text);
    let path = data_file(&r, "names.csv");
    let renamed = robot(&text.replace("name = \"s3\"", "name = \"s3b\""));
    let (_, second) = read_data_file_for_two(&path, &r, &renamed, &ReadOptions::default()).unwrap();
    assert!(second.is_none());
}
