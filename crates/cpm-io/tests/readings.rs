//! The readings reader's fast paths (columns looked up once, rows repeating their pose's
//! cells not parsed again) read what the rows say: a pose written differently but equal is
//! the same pose, a repeated label with another pose is refused naming line and field.
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::{simulate, Plan, SimulationOptions};
use cpm_geometry::{InstallationErrors, RobotDescription};
use cpm_io::{read_data, write_readings, ReadOptions, Robot};

fn robot() -> Robot {
    let mut robot =
        Robot::from_description(RobotDescription::paper_cubic(), "cube.toml").expect("cube");
    robot.table.sensors = designed_sensors();
    robot
}

fn text(robot: &Robot) -> String {
    let plan = Plan {
        poses: random_workspace_poses(&robot.table, 5, 100.0, 25.0, 3.0, 3),
        sensors: (0..16).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(
        &robot.model(&[]),
        &truth,
        &plan,
        &SimulationOptions::default(),
    )
    .expect("simulate");
    write_readings(&data, robot, "test")
}

/// Replaces field `col` of data row `k` (0-based, after the comment and header lines).
fn edit(text: &str, k: usize, col: usize, f: impl Fn(&str) -> String) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut fields: Vec<String> = lines[k + 2].split(',').map(str::to_string).collect();
    fields[col] = f(&fields[col]);
    lines[k + 2] = fields.join(",");
    lines.join("\n") + "\n"
}

#[test]
fn repeated_rows_read_as_written() {
    let robot = robot();
    let text = text(&robot);
    let opts = ReadOptions::default();
    let base = read_data(&text, "r.csv", &robot, &opts).expect("read");
    assert_eq!(base.campaign.readings.len(), 80);
    assert_eq!(base.campaign.poses.len(), 5);
    // Row 3 (pose 1) with x written in another form: the same pose, the same campaign (and
    // row 4 after it is again written like row 1).
    let same = edit(&text, 3, 2, |x| format!("{:e}", x.parse::<f64>().unwrap()));
    assert_ne!(same, text);
    let d = read_data(&same, "r.csv", &robot, &opts).expect("read");
    assert_eq!(d.campaign.poses, base.campaign.poses);
    assert_eq!(d.campaign.readings, base.campaign.readings);
    // A row of pose 1 with another pose: refused on its line (comment, header, then rows).
    for (k, col, name) in [(5usize, 2usize, "x_mm"), (1, 7, "yaw_deg"), (15, 4, "z_mm")] {
        let bad = edit(&text, k, col, |x| {
            (x.parse::<f64>().unwrap() + 0.5).to_string()
        });
        let e = read_data(&bad, "r.csv", &robot, &opts)
            .unwrap_err()
            .to_string();
        let want = format!("r.csv:{}: field {name}: ", k + 3);
        assert!(e.starts_with(&want), "{e}");
        assert!(e.contains("given for pose \"1\" on line 3"), "{e}");
    }
    // A bad number in a repeated row is still found.
    let bad = edit(&text, 7, 3, |_| "abc".to_string());
    let e = read_data(&bad, "r.csv", &robot, &opts)
        .unwrap_err()
        .to_string();
    assert_eq!(e, "r.csv:10: field y_mm: \"abc\" is not a number");
}
