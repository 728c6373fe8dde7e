//! One unreachable pose in a long log is left out and recorded, not fatal: a readings file of
//! 40 poses loses the pose (all its rows) and says which (file, line, label); a file with more
//! such poses than one in 20 is refused naming the first; `Merged::without_pose` keeps every
//! origin aligned with what is left.
use std::path::Path;

use cpm_calib::paper::random_workspace_poses;
use cpm_calib::{simulate, Plan, SimulationOptions};
use cpm_io::{merge, read_data, write_readings, ReadOptions, Robot, POSES_PER_EXCLUDED_POSE};

fn robot() -> Robot {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    Robot::load(&examples.join("hexapod_66.toml")).expect("example robot")
}

/// 40 simulated poses of the example hexapod, every sensor at each.
fn text(robot: &Robot) -> String {
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
    write_readings(&data, robot, "test")
}

/// `text` with every row of pose `label` lifted 200 mm (its links far past their 400 mm
/// limit): the lines it is on (1-based).
fn lift(text: &str, label: &str) -> (String, Vec<usize>) {
    let mut lines = Vec::new();
    let out: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(k, l)| {
            let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
            if k >= 2 && f[0] == label {
                let z: f64 = f[4].parse().unwrap();
                f[4] = (z + 200.0).to_string();
                lines.push(k + 1);
            }
            f.join(",")
        })
        .collect();
    (out.join("\n") + "\n", lines)
}

#[test]
fn one_unreachable_pose_in_forty_is_excluded_and_recorded() {
    let robot = robot();
    let text = text(&robot);
    let opts = ReadOptions::default();
    let base = read_data(&text, "log.csv", &robot, &opts).expect("read");
    assert_eq!(base.campaign.poses.len(), 40);
    assert!(base.excluded.is_empty());
    let (bad, lines) = lift(&text, "17");
    let d = read_data(&bad, "log.csv", &robot, &opts).expect("one pose in 40 is left out");
    assert_eq!(d.excluded.len(), 1, "{:?}", d.excluded);
    let e = &d.excluded[0];
    assert_eq!(
        (e.file.as_str(), e.line, e.label.as_str()),
        ("log.csv", lines[0], "17")
    );
    assert!(e.reason.contains("is not reachable: link"), "{}", e.reason);
    assert!(e
        .to_string()
        .starts_with(&format!("log.csv:{}: pose \"17\" excluded: (x ", lines[0])));
    // The campaign is the file's without pose 17's rows.
    let without: String = text
        .lines()
        .filter(|l| !l.starts_with("17,"))
        .map(|l| format!("{l}\n"))
        .collect();
    let w = read_data(&without, "log.csv", &robot, &opts).expect("read");
    assert_eq!(d.campaign, w.campaign);
    assert_eq!(d.pose_labels, w.pose_labels);
    assert!(!d.pose_labels.contains(&"17".to_string()));
    assert!(d.reading_lines.iter().all(|l| !lines.contains(l)));
    assert_eq!(d.reading_lines.len(), d.campaign.readings.len());
    // A pose after it keeps its own first line.
    let k = d.pose_labels.iter().position(|l| l == "18").unwrap();
    assert_eq!(d.pose_lines[k], base.pose_lines[17]);
}

#[test]
fn more_unreachable_poses_than_one_in_twenty_refuse_the_file_naming_the_first() {
    let robot = robot();
    let text = text(&robot);
    assert_eq!(40 / POSES_PER_EXCLUDED_POSE, 2);
    let (two, _) = lift(&text, "30");
    let (two, _) = lift(&two, "9");
    let d = read_data(&two, "log.csv", &robot, &ReadOptions::default()).expect("two of 40");
    let labels: Vec<&str> = d.excluded.iter().map(|e| e.label.as_str()).collect();
    assert_eq!(labels, ["9", "30"]);
    let (three, _) = lift(&two, "35");
    let (_, first) = lift(&text, "9");
    let err = read_data(&three, "log.csv", &robot, &ReadOptions::default()).unwrap_err();
    let s = err.to_string();
    assert!(
        s.starts_with(&format!("log.csv:{}: pose \"9\" (x ", first[0])),
        "{s}"
    );
    assert!(s.contains("is not reachable"), "{s}");
    assert!(s.contains("3 of the file's 40 poses"), "{s}");
}

#[test]
fn without_pose_keeps_the_origins_aligned() {
    let robot = robot();
    let text = text(&robot);
    let (bad, _) = lift(&text, "5");
    let f = read_data(&bad, "log.csv", &robot, &ReadOptions::default()).expect("read");
    let m = merge(vec![f], &robot);
    assert_eq!(m.excluded.len(), 1);
    let label_on = |line: usize| {
        text.lines()
            .nth(line - 1)
            .unwrap()
            .split(',')
            .next()
            .unwrap()
    };
    let aligned = |m: &cpm_io::Merged| {
        assert_eq!(m.pose_origin.len(), m.campaign.poses.len());
        assert_eq!(m.reading_origin.len(), m.campaign.readings.len());
        for (r, (_, line)) in m.campaign.readings.iter().zip(m.reading_origin.iter()) {
            assert_eq!(label_on(line), m.pose_origin[r.pose].2);
        }
        for (_, line, label) in &m.pose_origin {
            assert_eq!(label_on(*line), label);
        }
    };
    aligned(&m);
    let k = m.pose_origin.iter().position(|o| o.2 == "20").unwrap();
    let w = m.without_pose(k);
    aligned(&w);
    assert_eq!(w.campaign.poses.len(), m.campaign.poses.len() - 1);
    let mut expected = m.pose_origin.clone();
    expected.remove(k);
    assert_eq!(w.pose_origin, expected);
    assert_eq!(w.excluded, m.excluded);
    assert!(w.campaign.readings.len() < m.campaign.readings.len());
}
