//! The Schur-complement path on a calibration-shaped problem (`common/loops.rs`): exact
//! Jacobian, agreement with the sparse Cholesky solver and between damping strategies, and
//! the same answer whether the pattern is returned as a list, streamed in CSR order, or
//! given in another order (with the values permuted to match).

#[path = "common/loops.rs"]
mod loops;

use cpm_lm::{
    check_sparse_jacobian, minimize_sparse, Damping, LinearSolver, ModelError, Options, Problem,
    SparseJacobian,
};
use loops::{schur_options as options, Loops, LOCAL};

fn solve<P: SparseJacobian>(p: &mut P, o: &Options) -> (Vec<f64>, f64) {
    let mut x = vec![0.0; p.num_params()];
    let report = minimize_sparse(p, &mut x, o).unwrap();
    assert!(report.was_successful(), "{report}");
    (x, report.final_cost)
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max)
}

#[test]
fn loops_jacobian_is_exact() {
    let mut p = Loops::new(3, 5);
    let x: Vec<f64> = p.truth.iter().map(|v| v + 0.01).collect();
    // Lengths of about 500 carry rounding errors of about 1e-13: a relative step of 1e-3
    // (1e-5 on the small pose corrections) keeps the differences clear of them.
    let c = check_sparse_jacobian(&mut p, &x, 1e-3).unwrap();
    assert!(c.is_consistent(1e-6), "{c}");
}

#[test]
fn schur_agrees_with_sparse_cholesky_and_recovers_the_globals() {
    let blocks = 40;
    let mut p = Loops::new(blocks, 2);
    let (x_tr, cost_tr) = solve(&mut p, &options(blocks, Damping::TrustRegion));
    let (x_ni, cost_ni) = solve(&mut p, &options(blocks, Damping::Nielsen));
    let chol = Options {
        linear_solver: LinearSolver::SparseCholesky,
        ..options(blocks, Damping::TrustRegion)
    };
    let (x_ch, cost_ch) = solve(&mut p, &chol);
    assert!(max_diff(&x_tr, &x_ni) < 1e-6, "{}", max_diff(&x_tr, &x_ni));
    assert!(max_diff(&x_tr, &x_ch) < 1e-6, "{}", max_diff(&x_tr, &x_ch));
    assert!(
        (cost_tr - cost_ni).abs() <= 1e-9 * cost_tr && (cost_tr - cost_ch).abs() <= 1e-9 * cost_tr
    );
    // 1e-3 noise on lengths of about 500: the globals come back to well under 0.05.
    let g0 = blocks * LOCAL;
    assert!(max_diff(&x_tr[g0..], &p.truth[g0..]) < 0.05);
}

/// `Loops` with its pattern (and values) listed in reverse order.
struct Reversed(Loops);

impl Problem for Reversed {
    fn num_params(&self) -> usize {
        self.0.num_params()
    }
    fn num_residuals(&self) -> usize {
        self.0.num_residuals()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.0.residuals(x, r)
    }
}

impl SparseJacobian for Reversed {
    fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p = self.0.pattern();
        p.reverse();
        p
    }
    fn jacobian_values(&mut self, x: &[f64], values: &mut [f64]) -> Result<(), ModelError> {
        self.0.jacobian_values(x, values)?;
        values.reverse();
        Ok(())
    }
}

#[test]
fn pattern_list_stream_and_order_give_the_same_solution() {
    let blocks = 25;
    let o = options(blocks, Damping::TrustRegion);
    let mut listed = Loops::new(blocks, 3);
    let (x_list, _) = solve(&mut listed, &o);
    let mut streamed = Loops::new(blocks, 3);
    streamed.stream_pattern = true;
    let (x_stream, _) = solve(&mut streamed, &o);
    assert_eq!(x_list, x_stream);
    let mut reversed = Reversed(Loops::new(blocks, 3));
    let (x_rev, _) = solve(&mut reversed, &o);
    assert!(max_diff(&x_list, &x_rev) < 1e-9);
    // The dense solver sees the same Jacobian through either storage.
    let dense = Options {
        linear_solver: LinearSolver::DenseQr,
        ..options(blocks, Damping::TrustRegion)
    };
    let (x_dense, _) = solve(&mut reversed, &dense);
    assert!(max_diff(&x_list, &x_dense) < 1e-6);
}
