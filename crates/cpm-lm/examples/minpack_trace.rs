//! Diagnostics for the MINPACK set: per case, cpm-lm's work (evaluations, Jacobians,
//! accepted and rejected steps, restarts, termination) beside the `levenberg-marquardt`
//! crate's and MINPACK's evaluations; with a case label as argument, every iteration of
//! that case.
//!
//! `cargo run --release -p cpm-lm --example minpack_trace [-- <label substring>]`

#[path = "../tests/common/mgh.rs"]
mod mgh;

#[path = "../tests/common/nist.rs"]
mod nist;

use cpm_lm::{minimize, Options, Solver};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};
use std::cell::Cell;
use std::ops::ControlFlow;

/// A test problem in the `levenberg-marquardt` crate's interface that prints the cost at
/// every residual evaluation when `trace` is set.
struct LmMgh {
    p: mgh::Mgh,
    x: DVector<f64>,
    trace: bool,
    evals: Cell<usize>,
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
        self.evals.set(self.evals.get() + 1);
        if self.trace {
            println!(
                "  lm {:>4} cost {:>22.15e} x {:?}",
                self.evals.get(),
                0.5 * r.norm_squared(),
                self.x.as_slice()
            );
        }
        Some(r)
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let mut r = vec![0.0; self.p.m];
        let mut j = faer::Mat::<f64>::zeros(self.p.m, self.p.n);
        self.p.eval(self.x.as_slice(), &mut r, Some(j.as_mut()));
        Some(DMatrix::from_fn(self.p.m, self.p.n, |i, k| j[(i, k)]))
    }
}

fn main() {
    let filter = std::env::args().nth(1);
    // `NIST=<dataset>`: trace that NIST problem from its first start instead.
    if let Ok(name) = std::env::var("NIST") {
        let d = nist::load(&name);
        let mut p = nist::NistProblem::new(&d);
        let mut x = d.start1.clone();
        let mut solver = Solver::new(Options::default()).with_callback(|rec| {
            println!(
                "  {:>4} cost {:>22.15e} trial {:>14.8e} mu {:>10.3e} |h| {:>10.3e} rho {:>9.3e} {}",
                rec.iteration,
                rec.cost,
                rec.trial_cost,
                rec.damping,
                rec.step_norm,
                rec.gain_ratio,
                if rec.accepted { "acc" } else { "rej" }
            );
            ControlFlow::Continue(())
        });
        let r = solver.minimize(&mut p, &mut x).unwrap();
        println!("x = {x:?}\n{r:#}");
        return;
    }
    // `ACCEL=1`: geodesic acceleration from the start.
    let options = Options {
        acceleration: std::env::var("ACCEL")
            .is_ok()
            .then(cpm_lm::GeodesicAcceleration::default),
        ..Options::default()
    };
    println!(
        "{:<34} {:>6} {:>5} {:>5} {:>5} {:>3} {:>8} {:>14}  termination",
        "case", "evals", "jacs", "acc", "rej", "rst", "MINPACK", "cost"
    );
    for case in mgh::minpack_reference() {
        if let Some(f) = &filter {
            if !case.label.contains(f.as_str()) {
                continue;
            }
        }
        // `REPEAT=k`: solve k times without tracing (for a profiler).
        if let Some(k) = std::env::var("REPEAT")
            .ok()
            .and_then(|v| v.parse::<usize>().ok())
        {
            for _ in 0..k {
                let mut x = case.start.clone();
                let r = minimize(&mut case.problem.clone(), &mut x, &options).unwrap();
                std::hint::black_box((r, x));
            }
            continue;
        }
        let mut x = case.start.clone();
        let r = minimize(&mut case.problem.clone(), &mut x, &options).unwrap();
        println!(
            "{:<34} {:>6} {:>5} {:>5} {:>5} {:>3} {:>8} {:>14.8e}  {}",
            case.label,
            r.residual_evaluations,
            r.jacobian_evaluations,
            r.accepted_steps,
            r.rejected_steps,
            r.restarts,
            case.evaluations,
            r.final_cost,
            r.termination
        );
        if filter.is_some() {
            let mut x = case.start.clone();
            let mut solver = Solver::new(options.clone()).with_callback(|rec| {
                println!(
                    "  {:>4} cost {:>22.15e} trial {:>14.8e} mu {:>10.3e} |h| {:>10.3e} rho {:>9.3e} {}",
                    rec.iteration,
                    rec.cost,
                    rec.trial_cost,
                    rec.damping,
                    rec.step_norm,
                    rec.gain_ratio,
                    if rec.accepted { "acc" } else { "rej" }
                );
                ControlFlow::Continue(())
            });
            let r = solver.minimize(&mut case.problem.clone(), &mut x).unwrap();
            println!("  x = {x:?}, restarts {}", r.restarts);
            let (lm, rep) = LevenbergMarquardt::new().minimize(LmMgh {
                p: case.problem.clone(),
                x: DVector::from_vec(case.start.clone()),
                trace: true,
                evals: Cell::new(0),
            });
            println!("  lm: {:?}, x = {:?}", rep.termination, lm.x.as_slice());
        }
    }
}
