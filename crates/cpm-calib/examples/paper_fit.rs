//! Times the paper's 36-reading identification (simulated data, the paper's circle design),
//! the figure behind issue 18's "< 1 ms" target: `cargo run --release -p cpm-calib --example
//! paper_fit -- [repetitions]`. Prints wall and CPU time per fit.
use std::time::Instant;

use cpm_calib::campaign::paper_circle;
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};

fn cpu_seconds() -> f64 {
    // utime + stime of this process (Linux), in clock ticks of 1/100 s.
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let Some(p) = stat.rfind(')') else {
        return f64::NAN;
    };
    let f: Vec<&str> = stat[p + 2..].split_whitespace().collect();
    let t = |i: usize| {
        f.get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    (t(11) + t(12)) / 100.0
}

fn main() {
    let reps: usize = std::env::args()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000);
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let plan = Plan {
        poses: paper_circle(&model.nominal.home),
        sensors: vec![0],
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    let opts = IdentifyOptions::default();
    let c = identify(&model, &data, &opts).expect("identify");
    let (c0, t0) = (cpu_seconds(), Instant::now());
    for _ in 0..reps {
        std::hint::black_box(identify(&model, std::hint::black_box(&data), &opts).expect("fit"));
    }
    let wall = t0.elapsed().as_secs_f64() / reps as f64;
    let cpu = (cpu_seconds() - c0) / reps as f64;
    println!(
        "{{\"simulated\": true, \"readings\": {}, \"rank\": {}, \"iterations\": {}, \"wall_ms\": {:.4}, \"cpu_ms\": {:.4}}}",
        data.len(),
        c.identifiability.rank,
        c.solver.num_iterations(),
        wall * 1e3,
        cpu * 1e3
    );
}
