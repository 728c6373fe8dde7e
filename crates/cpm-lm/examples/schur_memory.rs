//! Peak memory and time of a Schur-complement solve shaped like the implicit-loop
//! calibration (6 local parameters per pose, 36 globals, 22 residuals and 168 Jacobian
//! entries per pose; see `tests/common/loops.rs`).
//!
//! `cargo run --release -p cpm-lm --example schur_memory -- [BLOCKS] [DAMPING] [stream]`
//! (defaults: 100000 blocks, the default damping; DAMPING is `trust-region`, `nielsen` or
//! `marquardt`; `stream` makes the problem stream its pattern through
//! `SparseJacobian::visit_pattern` instead of returning a list). Prints the report and the
//! peak resident set size (VmHWM) of the process.

#[path = "../tests/common/loops.rs"]
mod loops;

use cpm_lm::{minimize_sparse, Damping, Options};
use loops::{schur_options, Loops, LOCAL};

fn vm_hwm_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let blocks: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(100_000);
    let damping = match args.get(2).map(String::as_str) {
        Some("nielsen") => Damping::Nielsen,
        Some("marquardt") => Damping::Marquardt,
        Some("trust-region" | "default") | None => Damping::TrustRegion,
        Some(other) => panic!("unknown damping {other:?}"),
    };
    let mut problem = Loops::new(blocks, 1);
    problem.stream_pattern = args.get(3).is_some_and(|s| s == "stream");
    let setup_mb = vm_hwm_mb();
    let options = Options {
        ftol: 1e-10,
        xtol: 1e-10,
        gtol: 1e-10,
        ..schur_options(blocks, damping)
    };
    let mut x = vec![0.0; problem.truth.len()];
    let t = std::time::Instant::now();
    let report = minimize_sparse(&mut problem, &mut x, &options).expect("solve");
    let secs = t.elapsed().as_secs_f64();
    let g0 = blocks * LOCAL;
    let err = x[g0..]
        .iter()
        .zip(&problem.truth[g0..])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!("{}", report.brief());
    println!(
        "timings: residuals {:.2?}, Jacobian {:.2?}, linear solver {:.2?}",
        report.timings.residuals, report.timings.jacobian, report.timings.linear_solver
    );
    println!(
        "blocks {blocks}, nnz {}, {secs:.2} s, {:.3} s per iteration, max global error {err:.2e}",
        problem.nnz(),
        secs / report.iterations.len().max(1) as f64
    );
    println!(
        "peak RSS: {:.1} MB (after building the problem: {:.1} MB)",
        vm_hwm_mb().unwrap_or(f64::NAN),
        setup_mb.unwrap_or(f64::NAN)
    );
}
