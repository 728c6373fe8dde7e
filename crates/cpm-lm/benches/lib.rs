//! Benchmarks of cpm-lm.
//!
//! * `nist/<dataset>`: one solve of a NIST StRD problem from its second start, cpm-lm
//!   (default options, with and without the end-of-solve statistics, and with Nielsen's
//!   damping) next to the `levenberg-marquardt` crate (MINPACK port on nalgebra, default
//!   options, dynamic sizes).
//! * `nist/BoxBOD-start1`: BoxBOD from its first start, cpm-lm plain (stops on the plateau)
//!   and with geodesic acceleration (reaches the certified minimum), and the
//!   levenberg-marquardt crate.
//! * `minpack/<case>`: the 35 runs of MINPACK's reference set (`tests/common/mgh.rs`, MINPACK's
//!   results vendored in `tests/data/minpack`), cpm-lm with default options next to the
//!   `levenberg-marquardt` crate with default options, on the same problem code (the crate
//!   through a dynamic-size adapter). `benches/ratios.py` reads criterion's estimates and
//!   prints the time ratio per case and their geometric mean.
//! * `bounded/<case>`: the bound-constrained set of `tests/bounded.rs` (Rosenbrock boxes,
//!   Moré-Garbow-Hillstrom problems with boxes active and inactive at the solution, NIST fits
//!   with positivity bounds; `tests/data/bounded_reference.tsv`), each case one solve with
//!   default options and its box. `cargo bench -p cpm-lm --bench lib -- bounded/` runs it.
//! * `bundle/<solver>/<N>`: a bundle-shaped sparse problem, N blocks of 6 local parameters
//!   sharing 40 global ones, 12 residuals per block, solved with the Schur complement and
//!   with the sparse Cholesky solver.
//! * `loops/<damping>/<N>`: the shape of an implicit-loop calibration (`tests/common/loops.rs`:
//!   N poses of 6 local parameters, 36 globals, 22 residuals and 168 Jacobian entries per
//!   pose) solved from zero with the Schur complement. `examples/schur_memory.rs` runs the
//!   same problem at 10^5 poses and reports the peak memory.
//!
//! Inputs are built from fixed seeds. Run briefly with
//! `cargo bench -p cpm-lm -- --warm-up-time 1 --measurement-time 2`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

#[path = "../tests/common/nist.rs"]
mod nist;

#[path = "../tests/common/loops.rs"]
mod loops;

#[path = "../tests/common/mgh.rs"]
mod mgh;

#[path = "../tests/common/bounded.rs"]
mod bounded;

/// NIST problems: cpm-lm against the `levenberg-marquardt` crate.
mod nist_vs_lm {
    use super::*;
    use cpm_lm::{minimize, Damping, GeodesicAcceleration, Options};
    use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
    use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};
    use nist::{load, min_lre, NistProblem};

    /// A NIST problem in the `levenberg-marquardt` crate's interface.
    pub struct LmNist {
        pub p: NistProblem,
        pub x: DVector<f64>,
    }

    impl LeastSquaresProblem<f64, Dyn, Dyn> for LmNist {
        type ResidualStorage = Owned<f64, Dyn>;
        type JacobianStorage = Owned<f64, Dyn, Dyn>;
        type ParameterStorage = Owned<f64, Dyn>;

        fn set_params(&mut self, x: &DVector<f64>) {
            self.x.copy_from(x);
        }
        fn params(&self) -> DVector<f64> {
            self.x.clone()
        }
        fn residuals(&self) -> Option<DVector<f64>> {
            let mut r = DVector::zeros(self.p.y.len());
            self.p.residuals_into(self.x.as_slice(), r.as_mut_slice());
            Some(r)
        }
        fn jacobian(&self) -> Option<DMatrix<f64>> {
            let mut j = DMatrix::zeros(self.p.y.len(), self.p.n);
            self.p
                .jacobian_with(self.x.as_slice(), |i, k, v| j[(i, k)] = v);
            Some(j)
        }
    }

    pub const DATASETS: [&str; 6] = ["Misra1a", "Thurber", "MGH09", "Lanczos3", "Gauss1", "Rat43"];

    pub fn bench(c: &mut Criterion) {
        let no_stats = Options {
            statistics: cpm_lm::StatisticsMode::Off,
            ..Options::default()
        };
        let nielsen = Options {
            damping: Damping::Nielsen,
            ..Options::default()
        };
        println!(
            "{:<9} {:>26} {:>26}",
            "dataset", "cpm-lm: evals / LRE", "levenberg-marquardt: evals / LRE"
        );
        for name in DATASETS {
            let d = load(name);
            let problem = NistProblem::new(&d);
            // Accuracy and work of one solve of each, for the record.
            let mut x = d.start2.clone();
            let r = minimize(&mut problem.clone(), &mut x, &Options::default()).unwrap();
            let ours = (
                r.residual_evaluations,
                r.jacobian_evaluations,
                min_lre(&x, &d.certified),
            );
            let lm = LmNist {
                p: problem.clone(),
                x: DVector::from_vec(d.start2.clone()),
            };
            let (lm, rep) = LevenbergMarquardt::new().minimize(lm);
            let theirs = (
                rep.number_of_evaluations,
                min_lre(lm.x.as_slice(), &d.certified),
            );
            println!(
                "{name:<9} {:>12} / {:>4} / {:>5.2} {:>15} / {:>5.2}",
                ours.0, ours.1, ours.2, theirs.0, theirs.1
            );

            let mut group = c.benchmark_group(format!("nist/{name}"));
            group.bench_function("cpm-lm", |b| {
                b.iter(|| {
                    let mut p = problem.clone();
                    let mut x = d.start2.clone();
                    black_box(minimize(&mut p, &mut x, &Options::default()).unwrap());
                    x
                })
            });
            group.bench_function("cpm-lm (no statistics)", |b| {
                b.iter(|| {
                    let mut p = problem.clone();
                    let mut x = d.start2.clone();
                    black_box(minimize(&mut p, &mut x, &no_stats).unwrap());
                    x
                })
            });
            group.bench_function("cpm-lm (Nielsen)", |b| {
                b.iter(|| {
                    let mut p = problem.clone();
                    let mut x = d.start2.clone();
                    black_box(minimize(&mut p, &mut x, &nielsen).unwrap());
                    x
                })
            });
            group.bench_function("levenberg-marquardt", |b| {
                b.iter(|| {
                    let lm = LmNist {
                        p: problem.clone(),
                        x: DVector::from_vec(d.start2.clone()),
                    };
                    let (lm, rep) = LevenbergMarquardt::new().minimize(lm);
                    black_box(rep);
                    lm.x
                })
            });
            group.finish();
        }
    }

    /// BoxBOD from NIST's first start: the plain solve stops on the plateau, the
    /// geodesic-accelerated one reaches the certified minimum; the levenberg-marquardt crate
    /// beside them. The residual sums of squares are printed.
    pub fn boxbod(c: &mut Criterion) {
        let d = load("BoxBOD");
        let problem = NistProblem::new(&d);
        let accel = Options {
            acceleration: Some(GeodesicAcceleration::default()),
            ..Options::default()
        };
        for (label, options) in [
            ("plain", Options::default()),
            ("accelerated", accel.clone()),
        ] {
            let mut x = d.start1.clone();
            let r = minimize(&mut problem.clone(), &mut x, &options).unwrap();
            println!(
                "BoxBOD start 1, cpm-lm {label}: RSS {:.4} (certified {:.4}), {} evaluations",
                2.0 * r.final_cost,
                d.certified_rss,
                r.residual_evaluations
            );
        }
        let lm = LmNist {
            p: problem.clone(),
            x: DVector::from_vec(d.start1.clone()),
        };
        let (lm, rep) = LevenbergMarquardt::new().minimize(lm);
        println!(
            "BoxBOD start 1, levenberg-marquardt: RSS {:.4}, {} evaluations",
            2.0 * rep.objective_function,
            rep.number_of_evaluations
        );
        drop(lm);
        let mut group = c.benchmark_group("nist/BoxBOD-start1");
        group.bench_function("cpm-lm", |b| {
            b.iter(|| {
                let mut x = d.start1.clone();
                black_box(minimize(&mut problem.clone(), &mut x, &Options::default()).unwrap());
                x
            })
        });
        group.bench_function("cpm-lm (geodesic acceleration)", |b| {
            b.iter(|| {
                let mut x = d.start1.clone();
                black_box(minimize(&mut problem.clone(), &mut x, &accel).unwrap());
                x
            })
        });
        group.bench_function("levenberg-marquardt", |b| {
            b.iter(|| {
                let lm = LmNist {
                    p: problem.clone(),
                    x: DVector::from_vec(d.start1.clone()),
                };
                let (lm, rep) = LevenbergMarquardt::new().minimize(lm);
                black_box(rep);
                lm.x
            })
        });
        group.finish();
    }
}

/// MINPACK's reference set: cpm-lm against the `levenberg-marquardt` crate.
mod minpack_vs_lm {
    use super::*;
    use cpm_lm::{minimize, Options};
    use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
    use mgh::{minpack_reference, Mgh};
    use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};

    /// A test problem in the `levenberg-marquardt` crate's interface (the same `eval`).
    pub struct LmMgh {
        pub p: Mgh,
        pub x: DVector<f64>,
    }

    impl LeastSquaresProblem<f64, Dyn, Dyn> for LmMgh {
        type ResidualStorage = Owned<f64, Dyn>;
        type JacobianStorage = Owned<f64, Dyn, Dyn>;
        type ParameterStorage = Owned<f64, Dyn>;

        fn set_params(&mut self, x: &DVector<f64>) {
            self.x.copy_from(x);
        }
        fn params(&self) -> DVector<f64> {
            self.x.clone()
        }
        fn residuals(&self) -> Option<DVector<f64>> {
            let mut r = DVector::zeros(self.p.m);
            self.p.eval(self.x.as_slice(), r.as_mut_slice(), None);
            Some(r)
        }
        fn jacobian(&self) -> Option<DMatrix<f64>> {
            let mut r = vec![0.0; self.p.m];
            let mut j = faer::Mat::<f64>::zeros(self.p.m, self.p.n);
            self.p.eval(self.x.as_slice(), &mut r, Some(j.as_mut()));
            Some(DMatrix::from_fn(self.p.m, self.p.n, |i, k| j[(i, k)]))
        }
    }

    pub fn bench(c: &mut Criterion) {
        let mut group = c.benchmark_group("minpack");
        for case in minpack_reference() {
            let mut x = case.start.clone();
            let r = minimize(&mut case.problem.clone(), &mut x, &Options::default()).unwrap();
            let (_, rep) = LevenbergMarquardt::new().minimize(LmMgh {
                p: case.problem.clone(),
                x: DVector::from_vec(case.start.clone()),
            });
            println!(
                "{:<34} cost cpm-lm {:.8e} ({} evaluations), levenberg-marquardt {:.8e} ({}), MINPACK {:.8e} ({})",
                case.label,
                r.final_cost,
                r.residual_evaluations,
                rep.objective_function,
                rep.number_of_evaluations,
                case.cost,
                case.evaluations
            );
            group.bench_function(BenchmarkId::new("cpm-lm", &case.label), |b| {
                b.iter(|| {
                    let mut p = case.problem.clone();
                    let mut x = case.start.clone();
                    black_box(minimize(&mut p, &mut x, &Options::default()).unwrap());
                    x
                })
            });
            group.bench_function(BenchmarkId::new("levenberg-marquardt", &case.label), |b| {
                b.iter(|| {
                    let (lm, rep) = LevenbergMarquardt::new().minimize(LmMgh {
                        p: case.problem.clone(),
                        x: DVector::from_vec(case.start.clone()),
                    });
                    black_box(rep);
                    lm.x
                })
            });
        }
        group.finish();
    }
}

/// A bundle-shaped sparse problem solved with the Schur complement and sparse Cholesky.
mod bundle {
    use super::*;
    use cpm_lm::{minimize_sparse, LinearSolver, ModelError, Options, Problem, SparseJacobian};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    pub const LOCAL: usize = 6;
    pub const GLOBAL: usize = 40;
    pub const ROWS: usize = 12;

    /// Block k, residual i: `a_ki . l_k + b_i . g + 0.2 sin(l_k[i % 6] + g[(7i + k) % 40]) - y_ki`.
    pub struct Bundle {
        pub blocks: usize,
        a: Vec<f64>,
        b: Vec<f64>,
        y: Vec<f64>,
        pub start: Vec<f64>,
    }

    impl Bundle {
        /// Seeded random instance with `blocks` local blocks.
        pub fn new(blocks: usize, seed: u64) -> Self {
            let mut rng = StdRng::seed_from_u64(seed);
            let n = blocks * LOCAL + GLOBAL;
            let a: Vec<f64> = (0..blocks * ROWS * LOCAL)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let b: Vec<f64> = (0..ROWS * GLOBAL)
                .map(|_| rng.random_range(-0.3..0.3))
                .collect();
            let truth: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut p = Self {
                blocks,
                a,
                b,
                y: vec![0.0; blocks * ROWS],
                start: Vec::new(),
            };
            let mut y = vec![0.0; blocks * ROWS];
            p.eval(&truth, &mut y);
            for v in &mut y {
                *v += rng.random_range(-0.01..0.01);
            }
            p.y = y;
            p.start = truth
                .iter()
                .map(|v| v + rng.random_range(-0.3..0.3))
                .collect();
            p
        }

        fn n(&self) -> usize {
            self.blocks * LOCAL + GLOBAL
        }

        fn idx(&self, k: usize, i: usize) -> (usize, usize) {
            (
                k * LOCAL + i % LOCAL,
                self.blocks * LOCAL + (7 * i + k) % GLOBAL,
            )
        }

        fn eval(&self, x: &[f64], r: &mut [f64]) {
            let g = &x[self.blocks * LOCAL..];
            for k in 0..self.blocks {
                let l = &x[k * LOCAL..(k + 1) * LOCAL];
                for i in 0..ROWS {
                    let row = k * ROWS + i;
                    let a = &self.a[row * LOCAL..(row + 1) * LOCAL];
                    let b = &self.b[i * GLOBAL..(i + 1) * GLOBAL];
                    let lin: f64 = a.iter().zip(l).map(|(p, q)| p * q).sum::<f64>()
                        + b.iter().zip(g).map(|(p, q)| p * q).sum::<f64>();
                    let (p, q) = self.idx(k, i);
                    r[row] = lin + 0.2 * (x[p] + x[q]).sin() - self.y[row];
                }
            }
        }
    }

    impl Problem for Bundle {
        fn num_params(&self) -> usize {
            self.n()
        }
        fn num_residuals(&self) -> usize {
            self.blocks * ROWS
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
            self.eval(x, r);
            Ok(())
        }
    }

    impl SparseJacobian for Bundle {
        fn pattern(&self) -> Vec<(usize, usize)> {
            let mut p = Vec::with_capacity(self.blocks * ROWS * (LOCAL + GLOBAL));
            for k in 0..self.blocks {
                for i in 0..ROWS {
                    let row = k * ROWS + i;
                    p.extend((0..LOCAL).map(|a| (row, k * LOCAL + a)));
                    p.extend((0..GLOBAL).map(|b| (row, self.blocks * LOCAL + b)));
                }
            }
            p
        }
        fn jacobian_values(&mut self, x: &[f64], v: &mut [f64]) -> Result<(), ModelError> {
            let w = LOCAL + GLOBAL;
            for k in 0..self.blocks {
                for i in 0..ROWS {
                    let row = k * ROWS + i;
                    let out = &mut v[row * w..(row + 1) * w];
                    out[..LOCAL].copy_from_slice(&self.a[row * LOCAL..(row + 1) * LOCAL]);
                    out[LOCAL..].copy_from_slice(&self.b[i * GLOBAL..(i + 1) * GLOBAL]);
                    let (p, q) = self.idx(k, i);
                    let c = 0.2 * (x[p] + x[q]).cos();
                    out[p - k * LOCAL] += c;
                    out[LOCAL + q - self.blocks * LOCAL] += c;
                }
            }
            Ok(())
        }
    }

    pub fn bench(c: &mut Criterion) {
        let mut group = c.benchmark_group("bundle");
        group.sample_size(10);
        for blocks in [1000usize, 10_000] {
            let mut problem = Bundle::new(blocks, 7);
            let solvers = [
                (
                    "schur",
                    LinearSolver::Schur {
                        local_block_sizes: vec![LOCAL; blocks],
                    },
                ),
                ("sparse-cholesky", LinearSolver::SparseCholesky),
            ];
            for (label, solver) in solvers {
                let options = Options {
                    linear_solver: solver,
                    ..Options::default()
                };
                let mut x = problem.start.clone();
                let r = minimize_sparse(&mut problem, &mut x, &options).unwrap();
                println!("bundle {label} N={blocks}: {}", r.brief());
                group.bench_function(format!("{label}/{blocks}"), |b| {
                    b.iter(|| {
                        let mut x = problem.start.clone();
                        black_box(minimize_sparse(&mut problem, &mut x, &options).unwrap());
                        x
                    })
                });
            }
        }
        group.finish();
    }
}

/// The bound-constrained set, one solve per case.
mod bounded_set {
    use super::*;
    use bounded::{cases, Bounded};
    use cpm_lm::{minimize, Options};

    pub fn bench(c: &mut Criterion) {
        let mut group = c.benchmark_group("bounded");
        for case in cases() {
            let mut problem = Bounded::new(&case.problem);
            let options = Options {
                lower: Some(case.lower.clone()),
                upper: Some(case.upper.clone()),
                ..Options::default()
            };
            group.bench_function(case.name.as_str(), |b| {
                b.iter(|| {
                    let mut x = case.x0.clone();
                    black_box(minimize(&mut problem, &mut x, &options).unwrap());
                    x
                })
            });
        }
        group.finish();
    }
}

/// The calibration-shaped problem (Schur complement), both damping strategies.
mod calibration_shape {
    use super::*;
    use cpm_lm::{minimize_sparse, Damping, Options};
    use loops::{schur_options, Loops};

    pub fn bench(c: &mut Criterion) {
        let mut group = c.benchmark_group("loops");
        group.sample_size(10);
        let blocks = 10_000;
        let mut problem = Loops::new(blocks, 1);
        problem.stream_pattern = true;
        for (label, damping) in [
            ("trust-region", Damping::TrustRegion),
            ("nielsen", Damping::Nielsen),
        ] {
            let options = Options {
                ftol: 1e-10,
                xtol: 1e-10,
                gtol: 1e-10,
                ..schur_options(blocks, damping)
            };
            let mut x = vec![0.0; problem.truth.len()];
            let r = minimize_sparse(&mut problem, &mut x, &options).unwrap();
            println!("loops {label} N={blocks}: {}", r.brief());
            group.bench_function(format!("{label}/{blocks}"), |b| {
                b.iter(|| {
                    let mut x = vec![0.0; problem.truth.len()];
                    black_box(minimize_sparse(&mut problem, &mut x, &options).unwrap());
                    x
                })
            });
        }
        group.finish();
    }
}

criterion_group!(
    benches,
    minpack_vs_lm::bench,
    nist_vs_lm::bench,
    nist_vs_lm::boxbod,
    bounded_set::bench,
    bundle::bench,
    calibration_shape::bench
);
criterion_main!(benches);
