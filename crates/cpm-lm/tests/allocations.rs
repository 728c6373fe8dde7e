//! The dense path does not allocate per iteration: a solve that runs 60 iterations makes no
//! more heap allocations than one stopped after 4, apart from the growth of the per-iteration
//! record (a `Vec` that doubles its capacity, so a handful of reallocations). And the fixed
//! cost of a default dense QR solve is six allocations: the Jacobian, the residual buffer,
//! the QR workspace and its pivots, the parameter-sized vectors and the iteration records.
//!
//! One test in this binary: the counting allocator is global, so no other test may run
//! beside it. The allocator is the one place of the workspace with `unsafe` code.
#![allow(unsafe_code)]
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use cpm_lm::{minimize, Damping, DenseJacobian, LinearSolver, ModelError, Options, Problem};
use faer::MatMut;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A slow problem: a long curved valley (Rosenbrock in 8 dimensions, chained).
struct Chain;

const N: usize = 8;

impl Problem for Chain {
    fn num_params(&self) -> usize {
        N
    }
    fn num_residuals(&self) -> usize {
        2 * (N - 1)
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        for i in 0..N - 1 {
            r[2 * i] = 10.0 * (x[i + 1] - x[i] * x[i]);
            r[2 * i + 1] = 1.0 - x[i];
        }
        Ok(())
    }
}

impl DenseJacobian for Chain {
    fn jacobian(&mut self, x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
        for i in 0..N - 1 {
            for c in 0..N {
                j[(2 * i, c)] = 0.0;
                j[(2 * i + 1, c)] = 0.0;
            }
            j[(2 * i, i)] = -20.0 * x[i];
            j[(2 * i, i + 1)] = 10.0;
            j[(2 * i + 1, i)] = -1.0;
        }
        Ok(())
    }
}

/// Allocations and iterations of one solve from the standard start.
fn solve(options: &Options) -> (usize, usize) {
    let mut x = vec![-1.2; N];
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let report = minimize(&mut Chain, &mut x, options).unwrap();
    let after = ALLOCATIONS.load(Ordering::Relaxed);
    (after - before, report.iterations.len())
}

#[test]
fn dense_iterations_do_not_allocate() {
    for solver in [LinearSolver::DenseQr, LinearSolver::DenseCholesky] {
        for damping in [Damping::TrustRegion, Damping::Nielsen, Damping::Marquardt] {
            let base = Options {
                linear_solver: solver.clone(),
                damping,
                statistics: cpm_lm::StatisticsMode::Off,
                ftol: 1e-15,
                xtol: 1e-15,
                gtol: 1e-15,
                ..Options::default()
            };
            let short = Options {
                max_iterations: 4,
                ..base.clone()
            };
            let long = Options {
                max_iterations: 60,
                ..base
            };
            let (a_short, i_short) = solve(&short);
            let (a_long, i_long) = solve(&long);
            eprintln!("{solver:?} {damping:?}: {a_short} allocations in {i_short} iterations, {a_long} in {i_long}");
            assert!(
                i_long >= i_short + 10,
                "{solver:?} {damping:?}: {i_short} vs {i_long} iterations"
            );
            if solver == LinearSolver::DenseQr {
                assert!(
                    a_short <= 6,
                    "{damping:?}: {a_short} allocations in a dense QR solve"
                );
            }
            // Growth of the iteration records from 4 to 60: at most 5 doublings.
            assert!(
                a_long <= a_short + 5,
                "{solver:?} {damping:?}: {a_short} allocations in {i_short} iterations, {a_long} in {i_long}"
            );
        }
    }
}
