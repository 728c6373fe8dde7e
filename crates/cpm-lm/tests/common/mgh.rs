//! The Moré-Garbow-Hillstrom test problems of MINPACK's `lmder` driver (Moré, Garbow and
//! Hillstrom, "Testing unconstrained optimization software", ACM TOMS 7, 1981), shared by
//! `tests/mgh.rs` and the benchmarks (`benches/lib.rs`), and MINPACK's own results on the
//! set of the `levenberg-marquardt` crate's comparison (`tests/data/minpack`).
#![allow(dead_code)]

use cpm_lm::{DenseJacobian, ModelError, Problem};
use faer::MatMut;
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    LinearFullRank,
    LinearRank1,
    LinearRank1Zero,
    Rosenbrock,
    HelicalValley,
    PowellSingular,
    FreudensteinRoth,
    Bard,
    KowalikOsborne,
    Meyer,
    Watson,
    Box3d,
    JennrichSampson,
    BrownDennis,
    Chebyquad,
    BrownAlmostLinear,
    Osborne1,
    Osborne2,
}

#[derive(Clone, Debug)]
pub struct Mgh {
    pub kind: Kind,
    pub n: usize,
    pub m: usize,
}

const BARD_Y: [f64; 15] = [
    0.14, 0.18, 0.22, 0.25, 0.29, 0.32, 0.35, 0.39, 0.37, 0.58, 0.73, 0.96, 1.34, 2.10, 4.39,
];
const KO_Y: [f64; 11] = [
    0.1957, 0.1947, 0.1735, 0.1600, 0.0844, 0.0627, 0.0456, 0.0342, 0.0323, 0.0235, 0.0246,
];
const KO_U: [f64; 11] = [
    4.0, 2.0, 1.0, 0.5, 0.25, 0.167, 0.125, 0.1, 0.0833, 0.0714, 0.0625,
];
const MEYER_Y: [f64; 16] = [
    34780.0, 28610.0, 23650.0, 19630.0, 16370.0, 13720.0, 11540.0, 9744.0, 8261.0, 7030.0, 6005.0,
    5147.0, 4427.0, 3820.0, 3307.0, 2872.0,
];
const OSB1_Y: [f64; 33] = [
    0.844, 0.908, 0.932, 0.936, 0.925, 0.908, 0.881, 0.850, 0.818, 0.784, 0.751, 0.718, 0.685,
    0.658, 0.628, 0.603, 0.580, 0.558, 0.538, 0.522, 0.506, 0.490, 0.478, 0.467, 0.457, 0.448,
    0.438, 0.431, 0.424, 0.420, 0.414, 0.411, 0.406,
];
const OSB2_Y: [f64; 65] = [
    1.366, 1.191, 1.112, 1.013, 0.991, 0.885, 0.831, 0.847, 0.786, 0.725, 0.746, 0.679, 0.608,
    0.655, 0.616, 0.606, 0.602, 0.626, 0.651, 0.724, 0.649, 0.649, 0.694, 0.644, 0.624, 0.661,
    0.612, 0.558, 0.533, 0.495, 0.500, 0.423, 0.395, 0.375, 0.372, 0.391, 0.396, 0.405, 0.428,
    0.429, 0.523, 0.562, 0.607, 0.653, 0.672, 0.708, 0.633, 0.668, 0.645, 0.632, 0.591, 0.559,
    0.597, 0.625, 0.739, 0.710, 0.729, 0.720, 0.636, 0.581, 0.428, 0.292, 0.162, 0.098, 0.054,
];

impl Mgh {
    pub fn new(kind: Kind, n: usize, m: usize) -> Self {
        Self { kind, n, m }
    }

    pub fn start(&self, factor: f64) -> Vec<f64> {
        let n = self.n;
        let x: Vec<f64> = match self.kind {
            Kind::LinearFullRank | Kind::LinearRank1 | Kind::LinearRank1Zero => vec![1.0; n],
            Kind::Rosenbrock => vec![-1.2, 1.0],
            Kind::HelicalValley => vec![-1.0, 0.0, 0.0],
            Kind::PowellSingular => vec![3.0, -1.0, 0.0, 1.0],
            Kind::FreudensteinRoth => vec![0.5, -2.0],
            Kind::Bard => vec![1.0, 1.0, 1.0],
            Kind::KowalikOsborne => vec![0.25, 0.39, 0.415, 0.39],
            Kind::Meyer => vec![0.02, 4000.0, 250.0],
            Kind::Watson => {
                return vec![if factor == 1.0 { 0.0 } else { factor }; n];
            }
            Kind::Box3d => vec![0.0, 10.0, 20.0],
            Kind::JennrichSampson => vec![0.3, 0.4],
            Kind::BrownDennis => vec![25.0, 5.0, -5.0, -1.0],
            Kind::Chebyquad => (1..=n).map(|j| j as f64 / (n + 1) as f64).collect(),
            Kind::BrownAlmostLinear => vec![0.5; n],
            Kind::Osborne1 => vec![0.5, 1.5, -1.0, 0.01, 0.02],
            Kind::Osborne2 => vec![1.3, 0.65, 0.65, 0.7, 0.6, 3.0, 5.0, 7.0, 2.0, 4.5, 5.5],
        };
        x.into_iter().map(|v| v * factor).collect()
    }

    /// Residuals and (when `jac` is given) the Jacobian.
    pub fn eval(&self, x: &[f64], r: &mut [f64], mut jac: Option<MatMut<'_, f64>>) {
        let (n, m) = (self.n, self.m);
        if let Some(j) = jac.as_mut() {
            j.fill(0.0);
        }
        macro_rules! set {
            ($i:expr, $j:expr, $v:expr) => {
                if let Some(jm) = jac.as_mut() {
                    jm[($i, $j)] = $v;
                }
            };
        }
        match self.kind {
            Kind::LinearFullRank => {
                let s: f64 = x.iter().sum();
                let t = 2.0 * s / m as f64 + 1.0;
                for i in 0..m {
                    r[i] = -t + if i < n { x[i] } else { 0.0 };
                    for j in 0..n {
                        set!(i, j, -2.0 / m as f64 + if i == j { 1.0 } else { 0.0 });
                    }
                }
            }
            Kind::LinearRank1 => {
                let s: f64 = (0..n).map(|j| (j + 1) as f64 * x[j]).sum();
                for i in 0..m {
                    r[i] = (i + 1) as f64 * s - 1.0;
                    for j in 0..n {
                        set!(i, j, ((i + 1) * (j + 1)) as f64);
                    }
                }
            }
            Kind::LinearRank1Zero => {
                let s: f64 = (1..n - 1).map(|j| (j + 1) as f64 * x[j]).sum();
                for i in 0..m {
                    r[i] = i as f64 * s - 1.0;
                    if i > 0 && i < m - 1 {
                        for j in 1..n - 1 {
                            set!(i, j, (i * (j + 1)) as f64);
                        }
                    }
                }
                r[m - 1] = -1.0;
            }
            Kind::Rosenbrock => {
                r[0] = 10.0 * (x[1] - x[0] * x[0]);
                r[1] = 1.0 - x[0];
                set!(0, 0, -20.0 * x[0]);
                set!(0, 1, 10.0);
                set!(1, 0, -1.0);
            }
            Kind::HelicalValley => {
                let th = if x[0] > 0.0 {
                    (x[1] / x[0]).atan() / (2.0 * PI)
                } else if x[0] < 0.0 {
                    (x[1] / x[0]).atan() / (2.0 * PI) + 0.5
                } else {
                    0.25f64.copysign(x[1])
                };
                let rr = (x[0] * x[0] + x[1] * x[1]).sqrt();
                r[0] = 10.0 * (x[2] - 10.0 * th);
                r[1] = 10.0 * (rr - 1.0);
                r[2] = x[2];
                let q = 2.0 * PI * rr * rr;
                set!(0, 0, 100.0 * x[1] / q);
                set!(0, 1, -100.0 * x[0] / q);
                set!(0, 2, 10.0);
                set!(1, 0, 10.0 * x[0] / rr);
                set!(1, 1, 10.0 * x[1] / rr);
                set!(2, 2, 1.0);
            }
            Kind::PowellSingular => {
                let (s5, s10) = (5f64.sqrt(), 10f64.sqrt());
                r[0] = x[0] + 10.0 * x[1];
                r[1] = s5 * (x[2] - x[3]);
                r[2] = (x[1] - 2.0 * x[2]).powi(2);
                r[3] = s10 * (x[0] - x[3]).powi(2);
                set!(0, 0, 1.0);
                set!(0, 1, 10.0);
                set!(1, 2, s5);
                set!(1, 3, -s5);
                set!(2, 1, 2.0 * (x[1] - 2.0 * x[2]));
                set!(2, 2, -4.0 * (x[1] - 2.0 * x[2]));
                set!(3, 0, 2.0 * s10 * (x[0] - x[3]));
                set!(3, 3, -2.0 * s10 * (x[0] - x[3]));
            }
            Kind::FreudensteinRoth => {
                r[0] = -13.0 + x[0] + ((5.0 - x[1]) * x[1] - 2.0) * x[1];
                r[1] = -29.0 + x[0] + ((x[1] + 1.0) * x[1] - 14.0) * x[1];
                set!(0, 0, 1.0);
                set!(0, 1, x[1] * (10.0 - 3.0 * x[1]) - 2.0);
                set!(1, 0, 1.0);
                set!(1, 1, x[1] * (2.0 + 3.0 * x[1]) - 14.0);
            }
            Kind::Bard => {
                for i in 0..15 {
                    let u = (i + 1) as f64;
                    let v = (15 - i) as f64;
                    let w = u.min(v);
                    let den = v * x[1] + w * x[2];
                    r[i] = BARD_Y[i] - (x[0] + u / den);
                    set!(i, 0, -1.0);
                    set!(i, 1, u * v / (den * den));
                    set!(i, 2, u * w / (den * den));
                }
            }
            Kind::KowalikOsborne => {
                for i in 0..11 {
                    let u = KO_U[i];
                    let nu = u * (u + x[1]);
                    let de = u * (u + x[2]) + x[3];
                    r[i] = KO_Y[i] - x[0] * nu / de;
                    set!(i, 0, -nu / de);
                    set!(i, 1, -u * x[0] / de);
                    set!(i, 2, x[0] * nu * u / (de * de));
                    set!(i, 3, x[0] * nu / (de * de));
                }
            }
            Kind::Meyer => {
                for i in 0..16 {
                    let t = 45.0 + 5.0 * (i + 1) as f64;
                    let den = t + x[2];
                    let e = (x[1] / den).exp();
                    r[i] = x[0] * e - MEYER_Y[i];
                    set!(i, 0, e);
                    set!(i, 1, x[0] * e / den);
                    set!(i, 2, -x[0] * e * x[1] / (den * den));
                }
            }
            Kind::Watson => {
                for i in 0..29 {
                    let t = (i + 1) as f64 / 29.0;
                    let (mut s1, mut s2, mut p) = (0.0, 0.0, 1.0);
                    for j in 0..n {
                        if j >= 1 {
                            s1 += j as f64 * p / t * x[j];
                        }
                        s2 += p * x[j];
                        p *= t;
                    }
                    r[i] = s1 - s2 * s2 - 1.0;
                    let mut p = 1.0;
                    for j in 0..n {
                        let ds1 = if j >= 1 { j as f64 * p / t } else { 0.0 };
                        set!(i, j, ds1 - 2.0 * s2 * p);
                        p *= t;
                    }
                }
                r[29] = x[0];
                r[30] = x[1] - x[0] * x[0] - 1.0;
                set!(29, 0, 1.0);
                set!(30, 0, -2.0 * x[0]);
                set!(30, 1, 1.0);
            }
            Kind::Box3d => {
                for i in 0..m {
                    let t = (i + 1) as f64 / 10.0;
                    let c = (-t).exp() - (-10.0 * t).exp();
                    r[i] = (-t * x[0]).exp() - (-t * x[1]).exp() - x[2] * c;
                    set!(i, 0, -t * (-t * x[0]).exp());
                    set!(i, 1, t * (-t * x[1]).exp());
                    set!(i, 2, -c);
                }
            }
            Kind::JennrichSampson => {
                for i in 0..m {
                    let k = (i + 1) as f64;
                    r[i] = 2.0 + 2.0 * k - (k * x[0]).exp() - (k * x[1]).exp();
                    set!(i, 0, -k * (k * x[0]).exp());
                    set!(i, 1, -k * (k * x[1]).exp());
                }
            }
            Kind::BrownDennis => {
                for i in 0..m {
                    let t = (i + 1) as f64 / 5.0;
                    let a = x[0] + t * x[1] - t.exp();
                    let b = x[2] + t.sin() * x[3] - t.cos();
                    r[i] = a * a + b * b;
                    set!(i, 0, 2.0 * a);
                    set!(i, 1, 2.0 * a * t);
                    set!(i, 2, 2.0 * b);
                    set!(i, 3, 2.0 * b * t.sin());
                }
            }
            Kind::Chebyquad => {
                // r_i = (1/n) sum_j T_i(2 x_j - 1) - integral_0^1 T_i(2t - 1) dt
                for (i, ri) in r.iter_mut().enumerate().take(m) {
                    let k = i + 1;
                    *ri = if k % 2 == 0 {
                        1.0 / ((k * k) as f64 - 1.0)
                    } else {
                        0.0
                    };
                }
                for j in 0..n {
                    let y = 2.0 * x[j] - 1.0;
                    // T_k and U_{k-1} by recurrence.
                    let (mut t_prev, mut t_cur) = (1.0, y); // T_0, T_1
                    let (mut u_prev, mut u_cur) = (0.0, 1.0); // U_{-1}, U_0
                    for i in 0..m {
                        let k = (i + 1) as f64;
                        r[i] += t_cur / n as f64;
                        set!(i, j, 2.0 * k * u_cur / n as f64);
                        let t_next = 2.0 * y * t_cur - t_prev;
                        t_prev = t_cur;
                        t_cur = t_next;
                        let u_next = 2.0 * y * u_cur - u_prev;
                        u_prev = u_cur;
                        u_cur = u_next;
                    }
                }
            }
            Kind::BrownAlmostLinear => {
                let s: f64 = x.iter().sum::<f64>() - (n + 1) as f64;
                for i in 0..n - 1 {
                    r[i] = x[i] + s;
                    for j in 0..n {
                        set!(i, j, if i == j { 2.0 } else { 1.0 });
                    }
                }
                r[n - 1] = x.iter().product::<f64>() - 1.0;
                for j in 0..n {
                    let p: f64 = (0..n).filter(|&k| k != j).map(|k| x[k]).product();
                    set!(n - 1, j, p);
                }
            }
            Kind::Osborne1 => {
                for i in 0..33 {
                    let t = 10.0 * i as f64;
                    let (e1, e2) = ((-x[3] * t).exp(), (-x[4] * t).exp());
                    r[i] = OSB1_Y[i] - (x[0] + x[1] * e1 + x[2] * e2);
                    set!(i, 0, -1.0);
                    set!(i, 1, -e1);
                    set!(i, 2, -e2);
                    set!(i, 3, t * x[1] * e1);
                    set!(i, 4, t * x[2] * e2);
                }
            }
            Kind::Osborne2 => {
                for i in 0..65 {
                    let t = i as f64 / 10.0;
                    let e1 = (-x[4] * t).exp();
                    let (d2, d3, d4) = (t - x[8], t - x[9], t - x[10]);
                    let e2 = (-x[5] * d2 * d2).exp();
                    let e3 = (-x[6] * d3 * d3).exp();
                    let e4 = (-x[7] * d4 * d4).exp();
                    r[i] = OSB2_Y[i] - (x[0] * e1 + x[1] * e2 + x[2] * e3 + x[3] * e4);
                    set!(i, 0, -e1);
                    set!(i, 1, -e2);
                    set!(i, 2, -e3);
                    set!(i, 3, -e4);
                    set!(i, 4, t * x[0] * e1);
                    set!(i, 5, x[1] * d2 * d2 * e2);
                    set!(i, 6, x[2] * d3 * d3 * e3);
                    set!(i, 7, x[3] * d4 * d4 * e4);
                    set!(i, 8, -2.0 * x[1] * x[5] * d2 * e2);
                    set!(i, 9, -2.0 * x[2] * x[6] * d3 * e3);
                    set!(i, 10, -2.0 * x[3] * x[7] * d4 * e4);
                }
            }
        }
    }
}

impl Problem for Mgh {
    fn num_params(&self) -> usize {
        self.n
    }
    fn num_residuals(&self) -> usize {
        self.m
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.eval(x, r, None);
        Ok(())
    }
}

impl DenseJacobian for Mgh {
    fn jacobian(&mut self, x: &[f64], jac: MatMut<'_, f64>) -> Result<(), ModelError> {
        let mut r = vec![0.0; self.m];
        self.eval(x, &mut r, Some(jac));
        Ok(())
    }
}

/// One case of MINPACK's reference set: MINPACK's `lmder` (through SciPy's `leastsq`,
/// `ftol = xtol = 1.49012e-8`, `gtol = 0`, the default `maxfev = 100 (n + 1)`) from a start,
/// with its final cost `0.5 ||f||^2` and its number of function evaluations.
#[derive(Clone, Debug)]
pub struct MinpackCase {
    pub label: String,
    pub problem: Mgh,
    pub start: Vec<f64>,
    pub cost: f64,
    pub evaluations: usize,
}

/// The vendored reference results (`tests/data/minpack/lmder_reference.csv`; its source is in
/// the README beside it).
pub fn minpack_reference() -> Vec<MinpackCase> {
    let text = include_str!("../data/minpack/lmder_reference.csv");
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .skip(1)
        .map(|line| {
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            let kind = match f[0] {
                "linear_full_rank" => Kind::LinearFullRank,
                "linear_rank1" => Kind::LinearRank1,
                "linear_rank1_zero_columns" => Kind::LinearRank1Zero,
                "rosenbrock" => Kind::Rosenbrock,
                "helical_valley" => Kind::HelicalValley,
                "powell_singular" => Kind::PowellSingular,
                "freudenstein_roth" => Kind::FreudensteinRoth,
                "bard" => Kind::Bard,
                "kowalik_osborne" => Kind::KowalikOsborne,
                "meyer" => Kind::Meyer,
                "watson" => Kind::Watson,
                other => panic!("unknown MINPACK problem {other}"),
            };
            let n: usize = f[1].parse().unwrap();
            let m: usize = f[2].parse().unwrap();
            let problem = Mgh::new(kind, n, m);
            // "x10" scales the standard start; Watson's "+10" adds to its zero start.
            let start = match f[3] {
                "x1" => problem.start(1.0),
                "x10" => problem.start(10.0),
                "x100" => problem.start(100.0),
                "+10" => vec![10.0; n],
                "+100" => vec![100.0; n],
                other => panic!("unknown start {other}"),
            };
            MinpackCase {
                label: format!("{}-{n}x{m}-{}", f[0], f[3]),
                problem,
                start,
                cost: f[4].parse().unwrap(),
                evaluations: f[5].parse().unwrap(),
            }
        })
        .collect()
}
