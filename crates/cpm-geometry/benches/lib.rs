//! Benchmarks of the roll-pitch-yaw conversions.
use std::hint::black_box;

use cpm_geometry::rotation::{from_quaternion, from_rpy, quaternion, rpy};
use criterion::{criterion_group, criterion_main, Criterion};

fn benches(c: &mut Criterion) {
    let r = from_rpy(0.1, -0.2, 0.3);
    let q = quaternion(&r);
    c.bench_function("rotation/from_rpy", |b| {
        b.iter(|| from_rpy(black_box(0.1), black_box(-0.2), black_box(0.3)))
    });
    c.bench_function("rotation/rpy", |b| b.iter(|| rpy(black_box(&r))));
    c.bench_function("rotation/quaternion", |b| {
        b.iter(|| quaternion(black_box(&r)))
    });
    c.bench_function("rotation/from_quaternion", |b| {
        b.iter(|| from_quaternion(black_box(q[0]), q[1], q[2], q[3]).unwrap())
    });
}

criterion_group!(rotation, benches);
criterion_main!(rotation);
