//! Benchmarks of cpm-io: reading a robot description, and reading length-sensor readings
//! (the paper's cube with its 16 designed socket pairs, simulated) at 10^4 and 10^6 rows
//! (issue 18: 10^6 rows, 62,500 poses x 16 sensors, under a second); the same readings given
//! as values (`rows`, numpy arrays from Python) against the text of those values.
use std::hint::black_box;

use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::{simulate, Plan, SimulationOptions};
use cpm_geometry::{InstallationErrors, RobotDescription};
use cpm_io::{read_data, write_readings, ReadOptions, Robot};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

/// The paper's cube with the 16 designed sensors.
fn robot() -> Robot {
    let mut robot = Robot::from_description(RobotDescription::paper_cubic(), "cube.toml")
        .expect("the paper's cube");
    robot.table.sensors = designed_sensors();
    robot
}

/// A simulated readings file of `poses` x 16 rows.
fn readings_text(robot: &Robot, poses: usize) -> String {
    let model = robot.model(&[]);
    let plan = Plan {
        poses: random_workspace_poses(&robot.table, poses, 100.0, 25.0, 3.0, 1),
        sensors: (0..16).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    write_readings(&data, robot, "benchmark")
}

fn description(c: &mut Criterion) {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/hexapod_66_truth.toml"
    ))
    .expect("examples/hexapod_66_truth.toml");
    c.bench_function("robot_from_toml", |b| {
        b.iter(|| Robot::from_toml(black_box(&text), "robot.toml").expect("robot"))
    });
}

fn readings(c: &mut Criterion) {
    let robot = robot();
    let mut group = c.benchmark_group("read_readings");
    group.sample_size(10);
    for poses in [625usize, 62_500] {
        let text = readings_text(&robot, poses);
        let rows = poses * 16;
        group.bench_with_input(BenchmarkId::from_parameter(rows), &text, |b, text| {
            b.iter(|| {
                let d = read_data(
                    black_box(text),
                    "readings.csv",
                    &robot,
                    &ReadOptions::default(),
                )
                .expect("read");
                assert_eq!(d.campaign.readings.len(), rows);
                d
            })
        });
    }
    group.finish();
}

/// Readings given as values (`cpm_io::rows`: what numpy arrays from Python become) and the
/// CSV text of the same values read by the file reader: the same checks, with and without
/// text.
fn rows(c: &mut Criterion) {
    use cpm_io::rows::{read_gauge_rows, GaugeRows};
    let robot = robot();
    let mut group = c.benchmark_group("read_gauge_rows");
    group.sample_size(10);
    for poses in [625usize, 62_500] {
        let model = robot.model(&[]);
        let plan = Plan {
            poses: random_workspace_poses(&robot.table, poses, 100.0, 25.0, 3.0, 1),
            sensors: (0..16).collect(),
        };
        let truth = InstallationErrors::paper_table2().to_vec_um();
        let data =
            simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
        let mut rows = GaugeRows::new("rows", vec![], vec![], vec![], vec![]);
        for r in &data.readings {
            let p = &data.poses[r.pose];
            let [roll, pitch, yaw] = p.rpy_deg();
            let x = p.position_mm;
            rows.pose_labels.push((r.pose + 1).to_string());
            rows.sensors
                .push(robot.table.sensors[r.sensor].name.clone());
            rows.poses.push([x.x, x.y, x.z, roll, pitch, yaw]);
            rows.lengths_mm.push(r.length_mm);
        }
        let n = rows.len();
        let text = rows.to_csv();
        group.bench_with_input(BenchmarkId::new("values", n), &rows, |b, rows| {
            b.iter(|| {
                let d = read_gauge_rows(black_box(rows), &robot, &ReadOptions::default())
                    .expect("read");
                assert_eq!(d.campaign.readings.len(), n);
                d
            })
        });
        group.bench_with_input(BenchmarkId::new("text", n), &text, |b, text| {
            b.iter(|| read_data(black_box(text), "rows.csv", &robot, &ReadOptions::default()))
        });
    }
    group.finish();
}

criterion_group!(benches, description, readings, rows);
criterion_main!(benches);
