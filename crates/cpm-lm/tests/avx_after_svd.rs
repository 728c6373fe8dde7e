//! Does ordinary scalar floating-point code run slower after a faer SVD? On processors with
//! AVX-512, faer's larger matrix products run hand-written AVX-512 kernels that do not
//! clear the upper halves of the vector registers (`vzeroupper`); on some processors the
//! SSE code that runs next then pays for that.
//!
//! Measured, not asserted (timings depend on the machine and its load): run
//! `cargo test -p cpm-lm --release --test avx_after_svd -- --ignored --nocapture`.
use std::hint::black_box;
use std::time::Instant;

use cpm_lm::stats::Statistics;
use faer::Mat;

/// 10^6 scalar multiply-adds in four independent chains (black_box keeps them scalar).
fn scalar_work(x: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    for i in 0..1_000_000 {
        let v = black_box(x[i & 1023]);
        let a = &mut acc[i & 3];
        *a = *a * 0.999_999 + v * 1.000_001;
    }
    acc.iter().sum()
}

fn time_ms(f: impl FnOnce() -> f64) -> f64 {
    let t = Instant::now();
    black_box(f());
    t.elapsed().as_secs_f64() * 1e3
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median time of the scalar loop right after `before` ran, over `rounds` rounds.
fn after(rounds: usize, x: &[f64], mut before: impl FnMut()) -> f64 {
    let mut t = Vec::with_capacity(rounds);
    for _ in 0..rounds {
        before();
        t.push(time_ms(|| scalar_work(x)));
    }
    median(t)
}

#[test]
#[ignore]
fn scalar_code_after_a_faer_svd() {
    let x: Vec<f64> = (0..1024).map(|i| (i as f64 * 0.37).sin()).collect();
    let a60 = Mat::<f64>::from_fn(60, 60, |i, j| {
        ((i * 31 + j * 17) % 23) as f64 - 11.0 + 0.01 * (i + j) as f64
    });
    let a40 = Mat::<f64>::from_fn(40, 40, |i, j| {
        ((i * 31 + j * 17) % 23) as f64 - 11.0 + 0.01 * (i + j) as f64
    });
    let j = Mat::<f64>::from_fn(2000, 60, |i, k| {
        ((i * 13 + k * 7) % 29) as f64 - 14.0 + 0.001 * i as f64
    });
    let r = vec![0.01; 2000];
    for _ in 0..20 {
        black_box(scalar_work(&x));
    }
    let rounds = 41;
    let control = after(rounds, &x, || {
        black_box(scalar_work(&x));
    });
    let svd60 = after(rounds, &x, || {
        black_box(a60.svd().unwrap());
    });
    let svd40 = after(rounds, &x, || {
        black_box(a40.svd().unwrap());
    });
    let stats = after(rounds, &x, || {
        black_box(Statistics::from_jacobian(j.as_ref(), &r, None));
    });
    let svd60_cleared = after(rounds, &x, || {
        black_box(a60.svd().unwrap());
        cpm_lm::stats::clear_upper_vector_registers();
    });
    let a6 = Mat::<f64>::from_fn(6, 6, |i, j| ((i * 31 + j * 17) % 23) as f64 - 11.0);
    let svd6 = after(rounds, &x, || {
        black_box(a6.svd().unwrap());
    });
    let control2 = after(rounds, &x, || {
        black_box(scalar_work(&x));
        cpm_lm::stats::clear_upper_vector_registers();
    });
    println!(
        "avx512f detected: {}",
        std::arch::is_x86_feature_detected!("avx512f")
    );
    println!("10^6 scalar mul-adds, median of {rounds}: after scalar code {control:.3} ms (and {control2:.3} ms at the end, registers cleared); after faer SVD 60x60 {svd60:.3} ms ({:.2}x); after SVD 40x40 {svd40:.3} ms ({:.2}x); after SVD 60x60 then clear_upper_vector_registers {svd60_cleared:.3} ms ({:.2}x); after SVD 6x6 {svd6:.3} ms ({:.2}x); after Statistics of a 2000x60 Jacobian (which clears) {stats:.3} ms ({:.2}x)",
        svd60 / control, svd40 / control, svd60_cleared / control, svd6 / control, stats / control);
    assert!(control > 0.0);
}
