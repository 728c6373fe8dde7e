//! NIST StRD nonlinear regression datasets: parser, models with exact Jacobians, LRE.
//! Shared by the integration tests and the benchmarks (`#[path]`-included).
#![allow(dead_code)]

use cpm_lm::{DenseJacobian, ModelError, Problem};
use std::f64::consts::PI;

/// The 23 vendored datasets (of NIST's 27), in NIST's order of difficulty (lower, average, higher).
pub fn names() -> Vec<&'static str> {
    vec![
        "Misra1a", "Chwirut2", "Chwirut1", "Lanczos3", "Gauss1", "Gauss2", "DanWood", "Misra1b",
        "Kirby2", "Nelson", "MGH17", "Lanczos1", "Lanczos2", "Gauss3", "Misra1c", "Misra1d",
        "Roszman1", "ENSO", "MGH09", "Thurber", "Rat42", "Rat43", "BoxBOD",
    ]
}

/// One parsed dataset.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub name: String,
    pub start1: Vec<f64>,
    pub start2: Vec<f64>,
    pub certified: Vec<f64>,
    pub certified_sd: Vec<f64>,
    pub certified_rss: f64,
    /// Predictor columns (one for every dataset except Nelson, which has two).
    pub x: Vec<Vec<f64>>,
    pub y: Vec<f64>,
}

fn num(s: &str) -> f64 {
    s.parse::<f64>()
        .unwrap_or_else(|_| panic!("not a number: {s:?}"))
}

/// Parses the text of a `.dat` file.
pub fn parse(name: &str, text: &str) -> Dataset {
    let lines: Vec<&str> = text.lines().map(|l| l.trim_end_matches('\r')).collect();
    let (mut start1, mut start2, mut certified, mut certified_sd) =
        (vec![], vec![], vec![], vec![]);
    let mut certified_rss = f64::NAN;
    let mut data_line = None;
    for (k, line) in lines.iter().enumerate() {
        let t = line.trim();
        if t.starts_with('b') && t.contains('=') {
            let rest: Vec<&str> = t.split('=').nth(1).unwrap().split_whitespace().collect();
            if rest.len() == 4 {
                start1.push(num(rest[0]));
                start2.push(num(rest[1]));
                certified.push(num(rest[2]));
                certified_sd.push(num(rest[3]));
            }
        } else if t.starts_with("Residual Sum of Squares:") {
            certified_rss = num(t.split(':').nth(1).unwrap().trim());
        } else if line.starts_with("Data:") && t.contains('y') {
            data_line = Some(k);
        }
    }
    let start = data_line.expect("no data header") + 1;
    let (mut x, mut y) = (Vec::<Vec<f64>>::new(), Vec::new());
    for line in &lines[start..] {
        let cols: Vec<f64> = line.split_whitespace().map(num).collect();
        if cols.is_empty() {
            continue;
        }
        if x.is_empty() {
            x = vec![Vec::new(); cols.len() - 1];
        }
        y.push(cols[0]);
        for (c, v) in cols[1..].iter().enumerate() {
            x[c].push(*v);
        }
    }
    Dataset {
        name: name.to_string(),
        start1,
        start2,
        certified,
        certified_sd,
        certified_rss,
        x,
        y,
    }
}

/// Reads `tests/data/nist/<name>.dat`.
pub fn load(name: &str) -> Dataset {
    let path = format!("{}/tests/data/nist/{name}.dat", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    parse(name, &text)
}

/// Model value and gradient `df/db` at one observation (`b` = parameters, `x` = predictors).
pub type ModelFn = fn(&[f64], &[f64], &mut [f64]) -> f64;

/// Model value and gradient `df/db` at one observation (`x` = predictors).
pub fn model(name: &str, b: &[f64], x: &[f64], g: &mut [f64]) -> f64 {
    model_fn(name)(b, x, g)
}

/// The model of a dataset.
pub fn model_fn(name: &str) -> ModelFn {
    match name {
        // BoxBOD has Misra1a's model.
        "Misra1a" | "BoxBOD" => |b, x, g| {
            let t = x[0];
            let e = (-b[1] * t).exp();
            g[0] = 1.0 - e;
            g[1] = b[0] * t * e;
            b[0] * (1.0 - e)
        },
        "Misra1b" => |b, x, g| {
            let t = x[0];
            let u = 1.0 + b[1] * t / 2.0;
            g[0] = 1.0 - u.powi(-2);
            g[1] = b[0] * t * u.powi(-3);
            b[0] * (1.0 - u.powi(-2))
        },
        "Misra1c" => |b, x, g| {
            let t = x[0];
            let u = 1.0 + 2.0 * b[1] * t;
            g[0] = 1.0 - u.powf(-0.5);
            g[1] = b[0] * t * u.powf(-1.5);
            b[0] * (1.0 - u.powf(-0.5))
        },
        "Misra1d" => |b, x, g| {
            let t = x[0];
            let u = 1.0 + b[1] * t;
            g[0] = b[1] * t / u;
            g[1] = b[0] * t / (u * u);
            b[0] * b[1] * t / u
        },
        "Chwirut1" | "Chwirut2" => |b, x, g| {
            let t = x[0];
            let den = b[1] + b[2] * t;
            let f = (-b[0] * t).exp() / den;
            g[0] = -t * f;
            g[1] = -f / den;
            g[2] = -t * f / den;
            f
        },
        "DanWood" => |b, x, g| {
            let t = x[0];
            let p = t.powf(b[1]);
            g[0] = p;
            g[1] = b[0] * p * t.ln();
            b[0] * p
        },
        "Lanczos1" | "Lanczos2" | "Lanczos3" => |b, x, g| {
            let t = x[0];
            let mut f = 0.0;
            for k in 0..3 {
                let e = (-b[2 * k + 1] * t).exp();
                g[2 * k] = e;
                g[2 * k + 1] = -b[2 * k] * t * e;
                f += b[2 * k] * e;
            }
            f
        },
        "Gauss1" | "Gauss2" | "Gauss3" => |b, x, g| {
            let t = x[0];
            let e0 = (-b[1] * t).exp();
            let (d1, d2) = (t - b[3], t - b[6]);
            let e1 = (-d1 * d1 / (b[4] * b[4])).exp();
            let e2 = (-d2 * d2 / (b[7] * b[7])).exp();
            g[0] = e0;
            g[1] = -b[0] * t * e0;
            g[2] = e1;
            g[3] = b[2] * e1 * 2.0 * d1 / (b[4] * b[4]);
            g[4] = b[2] * e1 * 2.0 * d1 * d1 / b[4].powi(3);
            g[5] = e2;
            g[6] = b[5] * e2 * 2.0 * d2 / (b[7] * b[7]);
            g[7] = b[5] * e2 * 2.0 * d2 * d2 / b[7].powi(3);
            b[0] * e0 + b[2] * e1 + b[5] * e2
        },
        "Kirby2" => |b, x, g| {
            let t = x[0];
            let nu = b[0] + b[1] * t + b[2] * t * t;
            let de = 1.0 + b[3] * t + b[4] * t * t;
            g[0] = 1.0 / de;
            g[1] = t / de;
            g[2] = t * t / de;
            g[3] = -nu * t / (de * de);
            g[4] = -nu * t * t / (de * de);
            nu / de
        },
        "Thurber" => |b, x, g| {
            let t = x[0];
            let nu = b[0] + t * (b[1] + t * (b[2] + t * b[3]));
            let de = 1.0 + t * (b[4] + t * (b[5] + t * b[6]));
            g[0] = 1.0 / de;
            g[1] = t / de;
            g[2] = t * t / de;
            g[3] = t * t * t / de;
            g[4] = -nu * t / (de * de);
            g[5] = -nu * t * t / (de * de);
            g[6] = -nu * t * t * t / (de * de);
            nu / de
        },
        "MGH09" => |b, x, g| {
            let t = x[0];
            let nu = t * t + t * b[1];
            let de = t * t + t * b[2] + b[3];
            g[0] = nu / de;
            g[1] = b[0] * t / de;
            g[2] = -b[0] * nu * t / (de * de);
            g[3] = -b[0] * nu / (de * de);
            b[0] * nu / de
        },
        "MGH17" => |b, x, g| {
            let t = x[0];
            let (e1, e2) = ((-t * b[3]).exp(), (-t * b[4]).exp());
            g[0] = 1.0;
            g[1] = e1;
            g[2] = e2;
            g[3] = -b[1] * t * e1;
            g[4] = -b[2] * t * e2;
            b[0] + b[1] * e1 + b[2] * e2
        },
        "Nelson" => |b, x, g| {
            let (x1, x2) = (x[0], x[1]);
            let e = (-b[2] * x2).exp();
            g[0] = 1.0;
            g[1] = -x1 * e;
            g[2] = b[1] * x1 * x2 * e;
            b[0] - b[1] * x1 * e
        },
        "Rat42" => |b, x, g| {
            let t = x[0];
            let e = (b[1] - b[2] * t).exp();
            let u = 1.0 + e;
            g[0] = 1.0 / u;
            g[1] = -b[0] * e / (u * u);
            g[2] = b[0] * t * e / (u * u);
            b[0] / u
        },
        "Rat43" => |b, x, g| {
            let t = x[0];
            let e = (b[1] - b[2] * t).exp();
            let u = 1.0 + e;
            let p = u.powf(-1.0 / b[3]);
            g[0] = p;
            g[1] = -b[0] * p * e / (b[3] * u);
            g[2] = b[0] * p * e * t / (b[3] * u);
            g[3] = b[0] * p * u.ln() / (b[3] * b[3]);
            b[0] * p
        },
        "Roszman1" => |b, x, g| {
            let t = x[0];
            let d = t - b[3];
            let u = b[2] / d;
            let w = 1.0 / (PI * (1.0 + u * u));
            g[0] = 1.0;
            g[1] = -t;
            g[2] = -w / d;
            g[3] = -w * b[2] / (d * d);
            // NIST's arctan takes values in (0, pi) here (x - b4 < 0 for all data), the
            // branch of atan2(b3, x - b4); the plain atan would shift b1 by exactly 1.
            b[0] - b[1] * t - b[2].atan2(d) / PI
        },
        "ENSO" => |b, x, g| {
            let t = x[0];
            let w = 2.0 * PI * t;
            let (a0, s0) = ((w / 12.0).cos(), (w / 12.0).sin());
            let (a1, s1) = ((w / b[3]).cos(), (w / b[3]).sin());
            let (a2, s2) = ((w / b[6]).cos(), (w / b[6]).sin());
            g[0] = 1.0;
            g[1] = a0;
            g[2] = s0;
            g[4] = a1;
            g[5] = s1;
            g[3] = (-b[4] * s1 + b[5] * a1) * (-w / (b[3] * b[3]));
            g[7] = a2;
            g[8] = s2;
            g[6] = (-b[7] * s2 + b[8] * a2) * (-w / (b[6] * b[6]));
            b[0] + b[1] * a0 + b[2] * s0 + b[4] * a1 + b[5] * s1 + b[7] * a2 + b[8] * s2
        },
        other => panic!("unknown NIST model {other}"),
    }
}

/// A dataset as a least-squares problem: `r_i = f(b; x_i) - y_i` (`log y_i` for Nelson).
#[derive(Clone)]
pub struct NistProblem {
    pub name: String,
    pub n: usize,
    pub x: Vec<Vec<f64>>,
    pub y: Vec<f64>,
    f: ModelFn,
}

impl NistProblem {
    pub fn new(d: &Dataset) -> Self {
        let y = if d.name == "Nelson" {
            d.y.iter().map(|v| v.ln()).collect()
        } else {
            d.y.clone()
        };
        Self {
            name: d.name.clone(),
            n: d.certified.len(),
            x: d.x.clone(),
            y,
            f: model_fn(&d.name),
        }
    }

    /// Residual `i` and its gradient into `g` (length >= number of parameters).
    pub fn residual(&self, b: &[f64], i: usize, g: &mut [f64]) -> f64 {
        let mut xi = [0.0; 2];
        for (c, col) in self.x.iter().enumerate() {
            xi[c] = col[i];
        }
        (self.f)(b, &xi, g) - self.y[i]
    }

    /// All residuals.
    pub fn residuals_into(&self, b: &[f64], r: &mut [f64]) {
        let mut g = [0.0; 9];
        for (i, ri) in r.iter_mut().enumerate() {
            *ri = self.residual(b, i, &mut g);
        }
    }

    /// The Jacobian through a setter `set(i, j, value)`.
    pub fn jacobian_with(&self, b: &[f64], mut set: impl FnMut(usize, usize, f64)) {
        let mut g = [0.0; 9];
        for i in 0..self.y.len() {
            self.residual(b, i, &mut g);
            for (j, v) in g.iter().enumerate().take(self.n) {
                set(i, j, *v);
            }
        }
    }
}

impl Problem for NistProblem {
    fn num_params(&self) -> usize {
        self.n
    }
    fn num_residuals(&self) -> usize {
        self.y.len()
    }
    fn residuals(&mut self, b: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.residuals_into(b, r);
        Ok(())
    }
}

impl DenseJacobian for NistProblem {
    fn jacobian(&mut self, b: &[f64], mut jac: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
        self.jacobian_with(b, |i, j, v| jac[(i, j)] = v);
        Ok(())
    }
}

/// Log relative error `-log10(|est - cert| / |cert|)`, capped at 11 (0 when not finite).
pub fn lre(est: f64, cert: f64) -> f64 {
    if est == cert {
        return 11.0;
    }
    let v = -((est - cert).abs() / cert.abs()).log10();
    if v.is_finite() {
        v.clamp(0.0, 11.0)
    } else {
        0.0
    }
}

/// Minimum LRE over the parameters.
pub fn min_lre(est: &[f64], cert: &[f64]) -> f64 {
    est.iter()
        .zip(cert)
        .map(|(e, c)| lre(*e, *c))
        .fold(f64::INFINITY, f64::min)
}
