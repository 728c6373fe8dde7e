//! The bound-constrained test set: the cases and SciPy's references of
//! `tests/data/bounded_reference.tsv` (written by `tests/data/bounded_reference.py`), their
//! problems (Moré-Garbow-Hillstrom and NIST), and a first-order optimality measure computed
//! from the problem alone. Shared by `tests/bounded.rs` and the benchmarks; needs the `mgh`
//! and `nist` modules beside it.
#![allow(dead_code)]

use cpm_lm::{DenseJacobian, ModelError, Problem};
use faer::{Mat, MatMut};

use super::mgh::{Kind, Mgh};
use super::nist::{load, NistProblem};

/// One case of the set.
#[derive(Clone, Debug)]
pub struct Case {
    pub name: String,
    /// `mgh:<Kind>:<n>:<m>` or `nist:<dataset>`.
    pub problem: String,
    pub x0: Vec<f64>,
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
    /// The best cost of SciPy's trf (x_scale 1 and 'jac') and dogbox runs.
    pub reference_cost: f64,
    /// SciPy's runs: (method, cost, evaluations).
    pub scipy: Vec<(&'static str, f64, usize)>,
    pub reference_x: Vec<f64>,
    /// Whether the box cuts the first Gauss-Newton step.
    pub cuts_gn: bool,
}

fn floats(s: &str) -> Vec<f64> {
    s.split(',')
        .map(|v| {
            v.parse::<f64>()
                .unwrap_or_else(|_| panic!("not a number: {v:?}"))
        })
        .collect()
}

/// The cases of `tests/data/bounded_reference.tsv`.
pub fn cases() -> Vec<Case> {
    let path = format!(
        "{}/tests/data/bounded_reference.tsv",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let c: Vec<&str> = l.split('\t').collect();
            assert_eq!(c.len(), 14, "{l}");
            let num = |s: &str| s.parse::<f64>().unwrap();
            let count = |s: &str| s.parse::<usize>().unwrap();
            Case {
                name: c[0].to_string(),
                problem: c[1].to_string(),
                x0: floats(c[2]),
                lower: floats(c[3]),
                upper: floats(c[4]),
                reference_cost: num(c[5]),
                scipy: vec![
                    ("trf", num(c[6]), count(c[7])),
                    ("trf-jac", num(c[8]), count(c[9])),
                    ("dogbox", num(c[10]), count(c[11])),
                ],
                reference_x: floats(c[12]),
                cuts_gn: c[13] == "cut",
            }
        })
        .collect()
}

/// A problem of the set.
pub enum Bounded {
    Mgh(Mgh),
    Nist(NistProblem),
}

impl Bounded {
    pub fn new(spec: &str) -> Self {
        let p: Vec<&str> = spec.split(':').collect();
        match p[0] {
            "mgh" => {
                let kind = match p[1] {
                    "Rosenbrock" => Kind::Rosenbrock,
                    "HelicalValley" => Kind::HelicalValley,
                    "PowellSingular" => Kind::PowellSingular,
                    "FreudensteinRoth" => Kind::FreudensteinRoth,
                    "Bard" => Kind::Bard,
                    "KowalikOsborne" => Kind::KowalikOsborne,
                    "Box3d" => Kind::Box3d,
                    "JennrichSampson" => Kind::JennrichSampson,
                    "BrownDennis" => Kind::BrownDennis,
                    "Osborne1" => Kind::Osborne1,
                    other => panic!("unknown MGH problem {other}"),
                };
                Bounded::Mgh(Mgh::new(kind, p[2].parse().unwrap(), p[3].parse().unwrap()))
            }
            "nist" => Bounded::Nist(NistProblem::new(&load(p[1]))),
            other => panic!("unknown problem family {other}"),
        }
    }
}

impl Problem for Bounded {
    fn num_params(&self) -> usize {
        match self {
            Bounded::Mgh(p) => p.num_params(),
            Bounded::Nist(p) => p.num_params(),
        }
    }
    fn num_residuals(&self) -> usize {
        match self {
            Bounded::Mgh(p) => p.num_residuals(),
            Bounded::Nist(p) => p.num_residuals(),
        }
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        match self {
            Bounded::Mgh(p) => p.residuals(x, r),
            Bounded::Nist(p) => p.residuals(x, r),
        }
    }
}

impl DenseJacobian for Bounded {
    fn jacobian(&mut self, x: &[f64], jac: MatMut<'_, f64>) -> Result<(), ModelError> {
        match self {
            Bounded::Mgh(p) => p.jacobian(x, jac),
            Bounded::Nist(p) => p.jacobian(x, jac),
        }
    }
}

/// First-order optimality at `x` in the box, from the problem alone.
#[derive(Clone, Copy, Debug)]
pub struct FirstOrder {
    pub cost: f64,
    /// `||x - P(x - g)||_inf`, `g = J^T r`.
    pub projected_gradient: f64,
    /// The largest over the parameters of `sqrt(red_j / cost)`, where `red_j` is the
    /// reduction of the Gauss-Newton model from moving parameter `j` alone to its best
    /// place in the box, counting only moves above `1e-10` relative to `x` (a zero-residual
    /// point after quadratic convergence has `red_j ~ cost` with a negligible move). Without
    /// bounds this is the cosine of MINPACK's gradient test.
    pub measure: f64,
}

/// [`FirstOrder`] at `x` of `problem` in `[lower, upper]`.
pub fn first_order<P: DenseJacobian>(
    problem: &mut P,
    x: &[f64],
    lower: &[f64],
    upper: &[f64],
) -> FirstOrder {
    let (n, m) = (problem.num_params(), problem.num_residuals());
    let mut r = vec![0.0; m];
    problem.residuals(x, &mut r).unwrap();
    let mut j = Mat::<f64>::zeros(m, n);
    problem.jacobian(x, j.as_mut()).unwrap();
    let cost = 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    let xnorm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
    let (mut pg, mut measure) = (0.0f64, 0.0f64);
    for c in 0..n {
        let g: f64 = (0..m).map(|i| j[(i, c)] * r[i]).sum();
        let n2: f64 = (0..m).map(|i| j[(i, c)].powi(2)).sum();
        pg = pg.max((x[c] - (x[c] - g).clamp(lower[c], upper[c])).abs());
        if n2 == 0.0 || cost == 0.0 {
            continue;
        }
        let t = (-g / n2).clamp(lower[c] - x[c], upper[c] - x[c]);
        let red = -g * t - 0.5 * n2 * t * t;
        if t.abs() > 1e-10 * (xnorm + 1e-10) {
            measure = measure.max((red.max(0.0) / cost).sqrt());
        }
    }
    FirstOrder {
        cost,
        projected_gradient: pg,
        measure,
    }
}
