//! `cpm design` without a gauge honours the limits it is given (`--cone-deg`,
//! `--clearance-mm`, the description's `[limits]`) or refuses with exit 2 naming them: the
//! written poses, sockets and `[limits]` are read back and checked against each other.
#[path = "common/cli.rs"]
mod cli;

use std::path::{Path, PathBuf};

use cli::{cpm, example, ok, p, scratch};
use cpm::calib::design::limits::{
    cone_angles_deg, gauge_clearance_mm, link_axes, segment_distance_mm,
};
use cpm::geometry::Pose;
use cpm::io::Robot;

/// The hexapod example with `extra` appended (a `[limits]` table).
fn robot_with(dir: &Path, extra: &str) -> PathBuf {
    let text = std::fs::read_to_string(example("hexapod_66.toml")).unwrap();
    let f = dir.join("robot.toml");
    std::fs::write(&f, format!("{text}\n{extra}")).unwrap();
    f
}

/// `cpm design` of 180 readings (20 poses x 9 socket pairs) from 400 candidates.
fn design_args<'a>(robot: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "design",
        "--robot",
        robot,
        "--readings",
        "180",
        "--candidates",
        "400",
        "--out",
        out,
    ];
    a.extend_from_slice(extra);
    a
}

/// What the written design reaches: (largest base cone, largest platform cone, smallest
/// gauge-link clearance, smallest link-link distance), from the written files alone; and the
/// written description.
fn read_back(out: &Path) -> ((f64, f64, f64, f64), Robot) {
    let robot = Robot::load(&out.join("robot.toml")).unwrap();
    let poses: Vec<Pose> = cpm::io::campaign::read_pose_list_file(&out.join("poses.csv"))
        .unwrap()
        .into_iter()
        .map(|r| r.pose)
        .collect();
    assert_eq!(poses.len(), 20);
    // The sockets file names the same sockets as the description's sensors.
    let sockets = std::fs::read_to_string(out.join("sockets.csv")).unwrap();
    assert_eq!(sockets.lines().count(), 1 + robot.table.sensors.len());
    assert_eq!(robot.table.sensors.len(), 9);
    let t = &robot.table;
    let mut reached = (0.0f64, 0.0f64, f64::INFINITY, f64::INFINITY);
    for pose in &poses {
        for (b, q) in cone_angles_deg(t, pose) {
            reached.0 = reached.0.max(b);
            reached.1 = reached.1.max(q);
        }
        for s in &t.sensors {
            reached.2 = reached.2.min(gauge_clearance_mm(t, s, pose));
        }
        let axes = link_axes(t, pose);
        for i in 0..axes.len() {
            for j in i + 1..axes.len() {
                let d = segment_distance_mm(&axes[i].0, &axes[i].1, &axes[j].0, &axes[j].1);
                reached.3 = reached.3.min(d);
            }
        }
    }
    (reached, robot)
}

/// The written `[limits]` hold for the written poses and sensors.
fn assert_limits_hold(out: &Path) -> (f64, f64, f64, f64) {
    let (r, robot) = read_back(out);
    let l = robot
        .description
        .limits
        .expect("robot.toml has a [limits] table");
    assert!(
        r.0 <= l.base_cone_deg + 1e-9,
        "base cone {} > {}",
        r.0,
        l.base_cone_deg
    );
    assert!(
        r.1 <= l.platform_cone_deg + 1e-9,
        "platform cone {} > {}",
        r.1,
        l.platform_cone_deg
    );
    let gauge_link = l.gauge_link_mm(None);
    assert!(r.2 >= gauge_link, "gauge-link {} < {gauge_link}", r.2);
    if let Some(d) = l.link_link_mm() {
        assert!(r.3 >= d, "link-link {} < {d}", r.3);
    }
    r
}

#[test]
fn cone_and_clearance_options_are_honoured_without_a_gauge() {
    let d = scratch("design-limits", "options");
    let robot = example("hexapod_66.toml");
    // Small motions, where 3 deg cones leave candidates enough.
    let range = ["--range-mm", "20", "--range-deg", "3"];
    // Without limits the design goes beyond 3 deg and 10 mm (before the fix the options were
    // ignored: 16 and 27 deg cones, a gauge 0.1 mm from a link at the default range).
    let free = d.join("free");
    ok(&design_args(&robot, &p(&free), &range));
    let (r, written) = read_back(&free);
    assert!(written.description.limits.is_none());
    assert!(r.0 > 3.0 && r.1 > 3.0 && r.2 < 10.0, "{r:?}");
    // With them, the written poses honour them, and [limits] says so.
    let out = d.join("limited");
    let mut args = range.to_vec();
    args.extend(["--cone-deg", "3", "--clearance-mm", "10"]);
    let stdout = ok(&design_args(&robot, &p(&out), &args));
    assert!(stdout.contains("wrote"), "{stdout}");
    let r = assert_limits_hold(&out);
    let (_, written) = read_back(&out);
    let l = written.description.limits.unwrap();
    assert_eq!(
        (l.base_cone_deg, l.platform_cone_deg, l.gauge_link_mm(None)),
        (3.0, 3.0, 10.0)
    );
    assert!(r.0 <= 3.0 && r.1 <= 3.0 && r.2 >= 10.0, "{r:?}");
    // The report states the limits and what was reached.
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("Limits honoured: joint cones at most 3 deg"),
        "{report}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("design.json")).unwrap()).unwrap();
    assert!(json["max_base_cone_deg"].as_f64().unwrap() <= 3.0);
    assert!(json["min_clearance_mm"].as_f64().unwrap() >= 10.0);
}

#[test]
fn a_described_limits_table_is_honoured_and_written_back_true() {
    let d = scratch("design-limits", "described");
    let robot = robot_with(
        &d,
        "[limits]\nbase_cone_deg = 6.0\nplatform_cone_deg = 8.0\nlink_radius_mm = 12.0\n",
    );
    let out = d.join("out");
    ok(&design_args(&p(&robot), &p(&out), &[]));
    let r = assert_limits_hold(&out);
    let (_, written) = read_back(&out);
    let l = written.description.limits.unwrap();
    assert_eq!((l.base_cone_deg, l.platform_cone_deg), (6.0, 8.0));
    assert_eq!(l.link_radius_mm, Some(12.0));
    // The gauge clears the links by at least the link radius.
    assert!(r.2 >= 12.0, "{r:?}");
    // An option overrides the description, and the written [limits] follows the option
    // (10 deg asked, looser than the description's 6 and 8: never a table the poses break).
    let out2 = d.join("out2");
    ok(&design_args(&p(&robot), &p(&out2), &["--cone-deg", "10"]));
    assert_limits_hold(&out2);
    let (_, written) = read_back(&out2);
    let l = written.description.limits.unwrap();
    assert_eq!((l.base_cone_deg, l.platform_cone_deg), (10.0, 10.0));
}

#[test]
fn limits_no_pose_can_honour_are_refused_naming_them() {
    let d = scratch("design-limits", "refused");
    let robot = example("hexapod_66.toml");
    let refused = |args: &[&str], out: &Path, names: &[&str]| {
        let o = cpm(args);
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        for n in names {
            assert!(err.contains(n), "{args:?}: {n} not in {err}");
        }
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    };
    let out = d.join("out");
    // Cones no candidate keeps.
    refused(
        &design_args(&robot, &p(&out), &["--cone-deg", "0.001"]),
        &out,
        &["--cone-deg 0.001", "beyond the base joint cone"],
    );
    // A clearance no socket layout keeps.
    refused(
        &design_args(&robot, &p(&out), &["--clearance-mm", "5000"]),
        &out,
        &["--clearance-mm 5000", "no layout"],
    );
    // Values out of range.
    refused(
        &design_args(&robot, &p(&out), &["--cone-deg", "0"]),
        &out,
        &["--cone-deg 0: must be in (0, 180] deg"],
    );
    refused(
        &design_args(&robot, &p(&out), &["--clearance-mm=-1"]),
        &out,
        &["--clearance-mm -1: must be finite and >= 0"],
    );
    // A link radius no pose allows (it was "1629 usable of 1629" candidates).
    let impossible = robot_with(&d, "[limits]\nlink_radius_mm = 1000.0\n");
    refused(
        &design_args(&p(&impossible), &p(&out), &[]),
        &out,
        &["link_radius_mm = 1000", "closer than 2000 mm"],
    );
}
