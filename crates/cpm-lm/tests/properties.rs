//! Property tests on random problems.

use std::cell::Cell;

use cpm_lm::{
    minimize, minimize_sparse, DenseJacobian, LinearSolver, ModelError, Options, Problem,
    SparseJacobian,
};
use faer::prelude::*;
use faer::{Mat, MatMut};
use proptest::prelude::*;

/// r = A x - b.
struct Linear {
    a: Mat<f64>,
    b: Vec<f64>,
}
impl Problem for Linear {
    fn num_params(&self) -> usize {
        self.a.ncols()
    }
    fn num_residuals(&self) -> usize {
        self.a.nrows()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        for i in 0..self.a.nrows() {
            r[i] = (0..self.a.ncols())
                .map(|j| self.a[(i, j)] * x[j])
                .sum::<f64>()
                - self.b[i];
        }
        Ok(())
    }
}
impl DenseJacobian for Linear {
    fn jacobian(&mut self, _x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
        j.copy_from(&self.a);
        Ok(())
    }
}

fn matrix(m: usize, n: usize) -> impl Strategy<Value = Mat<f64>> {
    prop::collection::vec(-1.0f64..1.0, m * n)
        .prop_map(move |v| Mat::from_fn(m, n, |i, j| v[i + m * j]))
}

/// Sparse nonlinear problem: residual i depends on a few parameters through
/// `c_ik * atan(x_k) + d_ik * x_k`, plus a weak prior keeping it well posed.
/// One residual of [`RandomSparse`]: `(param, c, d)` terms and a target.
type Row = (Vec<(usize, f64, f64)>, f64);

#[derive(Clone, Debug)]
struct RandomSparse {
    n: usize,
    /// Per residual: (param, c, d) terms and a target.
    rows: Vec<Row>,
    /// Whether any evaluation fell outside these bounds.
    lower: Vec<f64>,
    upper: Vec<f64>,
    violated: Cell<bool>,
}
impl RandomSparse {
    fn check_bounds(&self, x: &[f64]) {
        for j in 0..self.n {
            if x[j] < self.lower[j] || x[j] > self.upper[j] {
                self.violated.set(true);
            }
        }
    }
}
impl Problem for RandomSparse {
    fn num_params(&self) -> usize {
        self.n
    }
    fn num_residuals(&self) -> usize {
        self.rows.len() + self.n
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.check_bounds(x);
        for (i, (terms, y)) in self.rows.iter().enumerate() {
            r[i] = terms
                .iter()
                .map(|&(k, c, d)| c * x[k].atan() + d * x[k])
                .sum::<f64>()
                - y;
        }
        for j in 0..self.n {
            r[self.rows.len() + j] = 0.1 * x[j];
        }
        Ok(())
    }
}
impl SparseJacobian for RandomSparse {
    fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p: Vec<(usize, usize)> = self
            .rows
            .iter()
            .enumerate()
            .flat_map(|(i, (terms, _))| terms.iter().map(move |t| (i, t.0)))
            .collect();
        p.extend((0..self.n).map(|j| (self.rows.len() + j, j)));
        p
    }
    fn jacobian_values(&mut self, x: &[f64], v: &mut [f64]) -> Result<(), ModelError> {
        self.check_bounds(x);
        let mut k = 0;
        for (terms, _) in &self.rows {
            for &(p, c, d) in terms {
                v[k] = c / (1.0 + x[p] * x[p]) + d;
                k += 1;
            }
        }
        for _ in 0..self.n {
            v[k] = 0.1;
            k += 1;
        }
        Ok(())
    }
}
impl DenseJacobian for RandomSparse {
    fn jacobian(&mut self, x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
        let pattern = self.pattern();
        let mut v = vec![0.0; pattern.len()];
        self.jacobian_values(x, &mut v)?;
        j.fill(0.0);
        for (&(r, c), v) in pattern.iter().zip(v) {
            j[(r, c)] += v;
        }
        Ok(())
    }
}

fn random_sparse(n: usize) -> impl Strategy<Value = RandomSparse> {
    let term = (0..n, -2.0f64..2.0, 0.2f64..1.5);
    let row = (prop::collection::vec(term, 1..4), -3.0f64..3.0);
    prop::collection::vec(row, n..3 * n).prop_map(move |rows| RandomSparse {
        n,
        rows,
        lower: vec![f64::NEG_INFINITY; n],
        upper: vec![f64::INFINITY; n],
        violated: Cell::new(false),
    })
}

/// Block problem: block k has `s` local parameters, all share `g` globals; residuals of
/// block k: `A_k [l_k; g] + 0.3 sin(l_k0 + g_0) - y_k`, and a weak prior on every parameter.
#[derive(Clone, Debug)]
struct Blocks {
    s: usize,
    g: usize,
    nb: usize,
    rows_per_block: usize,
    a: Vec<f64>,
    y: Vec<f64>,
}
impl Blocks {
    fn n(&self) -> usize {
        self.s * self.nb + self.g
    }
    fn width(&self) -> usize {
        self.s + self.g
    }
    fn cols(&self, k: usize) -> Vec<usize> {
        (0..self.s)
            .map(|a| k * self.s + a)
            .chain((0..self.g).map(|b| self.s * self.nb + b))
            .collect()
    }
}
impl Problem for Blocks {
    fn num_params(&self) -> usize {
        self.n()
    }
    fn num_residuals(&self) -> usize {
        self.nb * self.rows_per_block + self.n()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        let w = self.width();
        for k in 0..self.nb {
            let cols = self.cols(k);
            let sn = (x[cols[0]] + x[cols[self.s]]).sin();
            for i in 0..self.rows_per_block {
                let row = k * self.rows_per_block + i;
                let lin: f64 = (0..w).map(|c| self.a[row * w + c] * x[cols[c]]).sum();
                r[row] = lin + 0.3 * sn - self.y[row];
            }
        }
        let base = self.nb * self.rows_per_block;
        for j in 0..self.n() {
            r[base + j] = 0.05 * x[j];
        }
        Ok(())
    }
}
impl SparseJacobian for Blocks {
    fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p = Vec::new();
        for k in 0..self.nb {
            let cols = self.cols(k);
            for i in 0..self.rows_per_block {
                for &c in &cols {
                    p.push((k * self.rows_per_block + i, c));
                }
            }
        }
        let base = self.nb * self.rows_per_block;
        p.extend((0..self.n()).map(|j| (base + j, j)));
        p
    }
    fn jacobian_values(&mut self, x: &[f64], v: &mut [f64]) -> Result<(), ModelError> {
        let w = self.width();
        let mut q = 0;
        for k in 0..self.nb {
            let cols = self.cols(k);
            let cs = (x[cols[0]] + x[cols[self.s]]).cos();
            for i in 0..self.rows_per_block {
                let row = k * self.rows_per_block + i;
                for c in 0..w {
                    let extra = if c == 0 || c == self.s { 0.3 * cs } else { 0.0 };
                    v[q] = self.a[row * w + c] + extra;
                    q += 1;
                }
            }
        }
        for _ in 0..self.n() {
            v[q] = 0.05;
            q += 1;
        }
        Ok(())
    }
}

fn blocks() -> impl Strategy<Value = Blocks> {
    (1usize..4, 1usize..4, 2usize..8).prop_flat_map(|(s, g, nb)| {
        let rows_per_block = s + g + 2;
        let m = nb * rows_per_block;
        (
            prop::collection::vec(-1.0f64..1.0, m * (s + g)),
            prop::collection::vec(-2.0f64..2.0, m),
        )
            .prop_map(move |(a, y)| Blocks {
                s,
                g,
                nb,
                rows_per_block,
                a,
                y,
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// One LM step with (almost) no damping is the least-squares solution from QR.
    #[test]
    fn one_undamped_step_is_the_least_squares_solution(
        (a, b) in (2usize..7).prop_flat_map(|n| (n + 2..n + 12).prop_flat_map(move |m| {
            (matrix(m, n), prop::collection::vec(-5.0f64..5.0, m))
        }))
    ) {
        let (m, n) = (a.nrows(), a.ncols());
        // Skip badly conditioned draws.
        let s = a.singular_values().unwrap();
        prop_assume!(s[n - 1] > 1e-2 * s[0]);
        let bm = Mat::<f64>::from_fn(m, 1, |i, _| b[i]);
        let ls = a.qr().solve_lstsq(&bm);
        let mut p = Linear { a, b };
        let mut x = vec![0.0; n];
        let o = Options { tau: 1e-14, max_iterations: 1, ..Options::default() };
        let report = minimize(&mut p, &mut x, &o).unwrap();
        prop_assert_eq!(report.iterations.len(), 1);
        prop_assert!(report.iterations[0].accepted);
        for j in 0..n {
            prop_assert!((x[j] - ls[(j, 0)]).abs() <= 1e-9 * (1.0 + ls[(j, 0)].abs()),
                "x[{}] = {} vs {}", j, x[j], ls[(j, 0)]);
        }
    }

    /// Accepted steps never increase the cost; rejected ones leave it unchanged.
    #[test]
    fn cost_never_increases(mut p in random_sparse(6), start in prop::collection::vec(-3.0f64..3.0, 6)) {
        for solver in [LinearSolver::DenseQr, LinearSolver::SparseCholesky] {
            let mut x = start.clone();
            let o = Options { linear_solver: solver, ..Options::default() };
            let report = minimize_sparse(&mut p, &mut x, &o).unwrap();
            let mut prev = report.initial_cost;
            for rec in &report.iterations {
                if rec.accepted {
                    prop_assert!(rec.cost <= prev, "{} > {}", rec.cost, prev);
                    prop_assert_eq!(rec.cost, rec.trial_cost);
                } else {
                    prop_assert_eq!(rec.cost, prev);
                }
                prev = rec.cost;
            }
            prop_assert_eq!(report.final_cost, prev);
            prop_assert!(report.final_cost <= report.initial_cost);
        }
    }

    /// The sparse and the dense paths reach the same point.
    #[test]
    fn sparse_and_dense_agree(mut p in random_sparse(8), start in prop::collection::vec(-1.0f64..1.0, 8)) {
        let mut xd = start.clone();
        let rd = minimize(&mut p, &mut xd, &Options::default()).unwrap();
        let mut xs = start.clone();
        let o = Options { linear_solver: LinearSolver::SparseCholesky, ..Options::default() };
        let rs = minimize_sparse(&mut p, &mut xs, &o).unwrap();
        prop_assume!(rd.was_successful() && rs.was_successful());
        prop_assert!((rd.final_cost - rs.final_cost).abs() <= 1e-9 * (1.0 + rd.final_cost));
        // Same minimiser, to the accuracy the cost tolerance implies in weakly determined
        // directions (about sqrt(ftol) relative to their curvature).
        for j in 0..8 {
            prop_assert!((xd[j] - xs[j]).abs() < 1e-5, "{:?} vs {:?}", xd, xs);
        }
    }

    /// Schur complement and dense QR agree on block problems.
    #[test]
    fn schur_and_dense_agree(mut p in blocks()) {
        let n = p.n();
        let sizes = vec![p.s; p.nb];
        let mut xd = vec![0.0; n];
        let mut pd = p.clone();
        let rd = minimize_sparse(&mut pd, &mut xd, &Options::default()).unwrap();
        let mut xs = vec![0.0; n];
        let o = Options { linear_solver: LinearSolver::Schur { local_block_sizes: sizes }, ..Options::default() };
        let rs = minimize_sparse(&mut p, &mut xs, &o).unwrap();
        prop_assert!(rd.was_successful() && rs.was_successful(), "{} / {}", rd, rs);
        prop_assert!((rd.final_cost - rs.final_cost).abs() <= 1e-9 * (1.0 + rd.final_cost));
        // The first step must agree to rounding.
        prop_assert!((rd.iterations[0].trial_cost - rs.iterations[0].trial_cost).abs()
            <= 1e-10 * (1.0 + rd.iterations[0].trial_cost));
        for j in 0..n {
            prop_assert!((xd[j] - xs[j]).abs() < 1e-5, "{:?} vs {:?}", xd, xs);
        }
    }

    /// No evaluation ever happens outside the bounds, and the result is inside them.
    #[test]
    fn bounds_are_never_violated(
        mut p in random_sparse(5),
        lo in prop::collection::vec(-2.0f64..0.5, 5),
        width in prop::collection::vec(0.0f64..2.0, 5),
        start in prop::collection::vec(-4.0f64..4.0, 5),
        solver in prop::sample::select(vec![LinearSolver::DenseQr, LinearSolver::DenseCholesky, LinearSolver::SparseCholesky]),
    ) {
        let up: Vec<f64> = lo.iter().zip(&width).map(|(l, w)| l + w).collect();
        p.lower = lo.clone();
        p.upper = up.clone();
        let mut x = start.clone();
        let o = Options { lower: Some(lo.clone()), upper: Some(up.clone()), linear_solver: solver, ..Options::default() };
        let report = minimize_sparse(&mut p, &mut x, &o).unwrap();
        prop_assert!(!p.violated.get(), "an evaluation left the box");
        for j in 0..5 {
            prop_assert!(x[j] >= lo[j] && x[j] <= up[j]);
        }
        prop_assert!(report.final_cost <= report.initial_cost);
    }
}
