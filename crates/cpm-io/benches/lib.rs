//! Benchmarks of cpm-io: reading a robot description, and reading length-sensor readings
//! (the paper's cube with its 16 designed socket pairs, simulated) at 10^4 and 10^6 rows
//! (issue 18: 10^6 rows, 62,500 poses x 16 sensors, under a second).
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

criterion_group!(benches, description, readings);
criterion_main!(benches);
