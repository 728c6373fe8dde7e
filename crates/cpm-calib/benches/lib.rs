//! Criterion benchmarks of cpm-calib: prediction with the analytic Jacobian, and whole
//! identifications (the paper's design and a designed campaign), and the nested and implicit
//! formulations side by side.
use std::hint::black_box;

use cpm_calib::campaign::paper_circle;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};
use criterion::{criterion_group, criterion_main, Criterion};

fn designed(poses: usize) -> (MeasurementModel, Campaign) {
    let mut model = MeasurementModel::new(JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, 1),
        sensors: (0..16).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    (model, data)
}

fn prediction(c: &mut Criterion) {
    let (model, data) = designed(125);
    let prepared = Prepared::new(&model, &data).expect("prepare");
    let e = InstallationErrors::paper_table2().to_vec_um();
    let mut j = nalgebra::DMatrix::zeros(data.len(), 36);
    c.bench_function("predict/2000_readings", |b| {
        b.iter(|| predict(&model, &prepared, &data, black_box(&e), None))
    });
    c.bench_function("predict_with_jacobian/2000_readings", |b| {
        b.iter(|| predict(&model, &prepared, &data, black_box(&e), Some(&mut j)))
    });
}

fn identification(c: &mut Criterion) {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let plan = Plan {
        poses: paper_circle(&model.nominal.home),
        sensors: vec![0],
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    let opts = IdentifyOptions::default();
    c.bench_function("identify/paper_design_36_readings", |b| {
        b.iter(|| identify(&model, black_box(&data), &opts))
    });
    let (dmodel, ddata) = designed(125);
    let mut group = c.benchmark_group("identify");
    group.sample_size(10);
    group.bench_function("designed_2000_readings", |b| {
        b.iter(|| identify(&dmodel, black_box(&ddata), &opts))
    });
    group.finish();
}

/// The two formulations side by side on the same designed campaign (125 poses x 16 sensors):
/// nested (forward kinematics in the loop, dense Jacobian) and implicit (poses as unknowns,
/// Schur complement), both returning a `Calibration`.
fn formulations(c: &mut Criterion) {
    let (model, data) = designed(125);
    let opts = IdentifyOptions::default();
    let mut group = c.benchmark_group("formulation/designed_2000_readings");
    group.sample_size(10);
    group.bench_function("nested", |b| {
        b.iter(|| identify(&model, black_box(&data), &opts))
    });
    group.bench_function("implicit", |b| {
        b.iter(|| {
            cpm_calib::implicit::identify_implicit_calibration(&model, black_box(&data), &opts)
        })
    });
    group.finish();
}

criterion_group!(benches, prediction, identification, formulations);
criterion_main!(benches);
