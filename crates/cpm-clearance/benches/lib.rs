//! Criterion benchmarks of cpm-clearance: link forces and clearance corrections.
use std::hint::black_box;

use cpm_clearance::{link_forces_n, ClearanceModel, Load};
use cpm_geometry::{JointTable, Pose};
use criterion::{criterion_group, criterion_main, Criterion};

fn statics(c: &mut Criterion) {
    let table = JointTable::paper_cubic();
    let pose = Pose::from_xyz_rpy(30.0, -20.0, 420.0, 0.05, -0.03, 0.1);
    let load = Load::default();
    c.bench_function("link_forces_n/paper_cubic", |b| {
        b.iter(|| link_forces_n(black_box(&table), black_box(&pose), black_box(&load)))
    });
    let model = ClearanceModel::default();
    c.bench_function("link_corrections_mm/paper_cubic", |b| {
        b.iter(|| model.link_corrections_mm(black_box(&table), black_box(&pose), black_box(&load)))
    });
}

criterion_group!(benches, statics);
criterion_main!(benches);
