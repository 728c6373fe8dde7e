//! Benchmarks of inverse and forward kinematics and the Jacobians (six links, paper cube).
//!
//! Targets (release build, 2 cores): IK of six links < 100 ns, one FK solve < 2 us; the
//! 6x6 LU and solve faster than nalgebra's (same numbers).
use std::hint::black_box;

use cpm_geometry::{JointTable, Pose};
use cpm_kinematics::{forward, inverse_lengths_into, j1, j2, ForwardOptions};
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector6;

fn benches(c: &mut Criterion) {
    let table = JointTable::paper_cubic();
    let home = table.home;
    // A measurement pose 20 mm / 5 deg away from home.
    let target = home.perturbed(&Vector6::new(12.0, -8.0, 15.0, 0.05, -0.06, 0.04));
    let mut lengths = vec![0.0; 6];
    inverse_lengths_into(&table, &target, &mut lengths);
    // A warm start 0.1 mm / 0.5 mrad from the solution (e.g. the previous measurement).
    let near: Pose = target.perturbed(&Vector6::new(0.1, -0.05, 0.07, 5e-4, -3e-4, 2e-4));
    let opts = ForwardOptions::default();

    c.bench_function("ik/inverse_lengths_into (6 links)", |b| {
        let mut out = [0.0; 6];
        b.iter(|| inverse_lengths_into(black_box(&table), black_box(&target), &mut out))
    });
    c.bench_function("fk/forward from home (20 mm, 5 deg away)", |b| {
        b.iter(|| forward(black_box(&table), black_box(&lengths), &home, &opts).unwrap())
    });
    c.bench_function("fk/forward from a nearby pose (0.1 mm away)", |b| {
        b.iter(|| forward(black_box(&table), black_box(&lengths), &near, &opts).unwrap())
    });
    c.bench_function("jacobian/j1 (6x6)", |b| {
        b.iter(|| j1(black_box(&table), black_box(&target)))
    });
    c.bench_function("jacobian/j2 (6x36)", |b| {
        b.iter(|| j2(black_box(&table), black_box(&target)))
    });
    // J1's LU and a solve: this crate's (nalgebra's operations, bit for bit) against
    // nalgebra's own.
    let a = nalgebra::Matrix6::from_iterator(j1(&table, &target).iter().copied());
    let rhs = Vector6::new(1.0, -2.0, 3.0, -4.0, 5.0, -6.0);
    c.bench_function("lu6/factor and solve (J1)", |b| {
        b.iter(|| cpm_kinematics::lu6::Lu6::new(black_box(&a)).solve(black_box(&rhs)))
    });
    c.bench_function("lu6/nalgebra factor and solve (J1)", |b| {
        b.iter(|| black_box(&a).lu().solve(black_box(&rhs)))
    });
    c.bench_function("lu6/inverse (J1)", |b| {
        b.iter(|| cpm_kinematics::lu6::try_inverse6(black_box(&a)))
    });
    c.bench_function("lu6/nalgebra inverse (J1)", |b| {
        b.iter(|| black_box(&a).try_inverse())
    });
    // The condition shortcut of the reachability judge and the forward solver: |J1|_F
    // |J1^-1|_F from the LU with reciprocal pivots, against the same bound from the full
    // inverse (what it was before session 29).
    c.bench_function("lu6/condition_at_most (J1)", |b| {
        b.iter(|| cpm_kinematics::fk::condition_at_most(black_box(&a), black_box(1e3)))
    });
    c.bench_function("lu6/condition bound from the inverse (J1)", |b| {
        b.iter(|| {
            cpm_kinematics::lu6::try_inverse6(black_box(&a))
                .is_some_and(|inv| a.norm() * inv.norm() <= black_box(1e3))
        })
    });
    // One pose judged as the readers judge each pose of a file.
    let at = cpm_kinematics::workspace::ReachableAt::new(&table);
    c.bench_function("workspace/reachable_at (20 mm, 5 deg from home)", |b| {
        b.iter(|| at.check(black_box(&target), black_box(1e3)))
    });
    // The judge's workload in a campaign: 1000 random poses within +-100 mm and +-25 deg of
    // home (as `cpm simulate --random` draws them), each judged once.
    let batch: Vec<Pose> = {
        use rand::{rngs::StdRng, Rng, SeedableRng};
        let mut rng = StdRng::seed_from_u64(5);
        (0..1000)
            .map(|_| {
                let mut u = |r: f64| rng.random_range(-r..r);
                let d = Vector6::new(u(100.0), u(100.0), u(100.0), u(0.436), u(0.436), u(0.436));
                home.perturbed(&d)
            })
            .collect()
    };
    c.bench_function(
        "workspace/reachable_at (1000 random poses, 100 mm, 25 deg)",
        |b| {
            b.iter(|| {
                batch
                    .iter()
                    .filter(|p| at.check(black_box(p), black_box(1e3)).is_ok())
                    .count()
            })
        },
    );
}

criterion_group!(kinematics, benches);
criterion_main!(kinematics);
