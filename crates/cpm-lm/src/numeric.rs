//! Finite-difference Jacobians for problems without an analytic one (as SciPy's
//! `least_squares(jac="2-point" | "3-point")` and Ceres' `NumericDiffCostFunction` offer).
//!
//! [`NumericJacobian`] wraps any [`Problem`] and implements [`DenseJacobian`] by
//! differencing its residuals column by column:
//!
//! - [`Difference::Forward`]: `(r(x + h e_j) - r(x)) / h`, one extra evaluation per parameter,
//!   truncation error `O(h)`; the default step is `sqrt(eps) ~ 1.5e-8` relative, which
//!   balances truncation against rounding and leaves about half the digits.
//! - [`Difference::Central`] (the default): `(r(x + h e_j) - r(x - h e_j)) / (2 h)`, two
//!   evaluations per parameter, truncation error `O(h^2)`; the default step is
//!   `eps^(1/3) ~ 6e-6` relative, leaving about two thirds of the digits.
//!
//! The step of parameter `j` is `step * |x_j|` (`step` when `x_j = 0`), so that a parameter of
//! size 1e-5 is not moved by a third of itself (SciPy's `step * max(|x_j|, 1)` loses all but
//! two digits on NIST's Kirby2 that way); [`NumericJacobian::step`] sets `step`. It is rounded so that `x_j + h` is exactly representable (the difference then
//! divides by the step actually taken). Prefer an analytic Jacobian where one is available:
//! it is faster and exact, and [`check_jacobian`](crate::check_jacobian) tests it against
//! central differences.
//!
//! ```
//! use cpm_lm::numeric::{Difference, NumericJacobian};
//! use cpm_lm::{minimize, ModelError, Options, Problem};
//!
//! // y = a exp(-b t), residuals only: no Jacobian written by hand.
//! struct ExpDecay { t: Vec<f64>, y: Vec<f64> }
//! impl Problem for ExpDecay {
//!     fn num_params(&self) -> usize { 2 }
//!     fn num_residuals(&self) -> usize { self.t.len() }
//!     fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
//!         for i in 0..self.t.len() {
//!             r[i] = x[0] * (-x[1] * self.t[i]).exp() - self.y[i];
//!         }
//!         Ok(())
//!     }
//! }
//! let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
//! let y = t.iter().map(|t| 3.0 * (-0.7 * t).exp()).collect();
//! let mut problem = NumericJacobian::new(ExpDecay { t, y }, Difference::Central);
//! let mut x = [1.0, 0.1];
//! let report = minimize(&mut problem, &mut x, &Options::default())?;
//! assert!(report.was_successful());
//! assert!((x[0] - 3.0).abs() < 1e-8 && (x[1] - 0.7).abs() < 1e-8);
//! # Ok::<(), cpm_lm::LmError>(())
//! ```

use crate::problem::{DenseJacobian, ModelError, Problem};

/// The difference scheme of a [`NumericJacobian`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Difference {
    /// One-sided `(r(x + h) - r(x)) / h`: `n` extra residual evaluations, about 8 digits.
    Forward,
    /// Two-sided `(r(x + h) - r(x - h)) / (2 h)`: `2 n` evaluations, about 10-11 digits.
    #[default]
    Central,
}

impl Difference {
    /// The default relative step: `sqrt(eps)` for forward, `eps^(1/3)` for central
    /// differences.
    pub fn default_step(self) -> f64 {
        match self {
            Difference::Forward => f64::EPSILON.sqrt(),
            Difference::Central => f64::EPSILON.cbrt(),
        }
    }
}

/// A [`Problem`] with a [`DenseJacobian`] by finite differences of its residuals (see the
/// [module documentation](self)).
#[derive(Clone, Debug)]
pub struct NumericJacobian<P> {
    /// The wrapped problem.
    pub problem: P,
    /// The difference scheme (default [`Difference::Central`]).
    pub scheme: Difference,
    /// Relative step; `None` (the default) uses [`Difference::default_step`].
    pub step: Option<f64>,
    xs: Vec<f64>,
    r0: Vec<f64>,
    r1: Vec<f64>,
}

impl<P: Problem> NumericJacobian<P> {
    /// Wraps `problem` with the given scheme and the default step.
    pub fn new(problem: P, scheme: Difference) -> Self {
        Self {
            problem,
            scheme,
            step: None,
            xs: Vec::new(),
            r0: Vec::new(),
            r1: Vec::new(),
        }
    }

    /// The same with relative step `step` (must be finite and positive, else an evaluation
    /// error is returned by [`DenseJacobian::jacobian`]).
    pub fn with_step(mut self, step: f64) -> Self {
        self.step = Some(step);
        self
    }

    /// The wrapped problem.
    pub fn into_inner(self) -> P {
        self.problem
    }
}

impl<P: Problem> Problem for NumericJacobian<P> {
    fn num_params(&self) -> usize {
        self.problem.num_params()
    }
    fn num_residuals(&self) -> usize {
        self.problem.num_residuals()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.problem.residuals(x, r)
    }
}

impl<P: Problem> DenseJacobian for NumericJacobian<P> {
    fn jacobian(&mut self, x: &[f64], mut jac: faer::MatMut<'_, f64>) -> Result<(), ModelError> {
        let (m, n) = (self.problem.num_residuals(), self.problem.num_params());
        let rel = self.step.unwrap_or(self.scheme.default_step());
        if !(rel.is_finite() && rel > 0.0) {
            return Err(
                format!("finite differences: step must be finite and > 0, got {rel}").into(),
            );
        }
        self.xs.clear();
        self.xs.extend_from_slice(x);
        self.r0.resize(m, 0.0);
        self.r1.resize(m, 0.0);
        if self.scheme == Difference::Forward {
            self.problem.residuals(x, &mut self.r0)?;
        }
        for j in 0..n {
            let xj = x[j];
            let h = if xj == 0.0 { rel } else { rel * xj.abs() };
            // The step actually taken, exactly representable.
            let hp = (xj + h) - xj;
            self.xs[j] = xj + hp;
            self.problem.residuals(&self.xs, &mut self.r1)?;
            match self.scheme {
                Difference::Forward => {
                    for i in 0..m {
                        jac[(i, j)] = (self.r1[i] - self.r0[i]) / hp;
                    }
                }
                Difference::Central => {
                    let hm = xj - (xj - h);
                    self.xs[j] = xj - hm;
                    self.problem.residuals(&self.xs, &mut self.r0)?;
                    for i in 0..m {
                        jac[(i, j)] = (self.r1[i] - self.r0[i]) / (hp + hm);
                    }
                }
            }
            self.xs[j] = xj;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    /// r_i = sin(a t_i) + b t_i^3 with its exact Jacobian.
    struct Curve(Vec<f64>);
    impl Problem for Curve {
        fn num_params(&self) -> usize {
            2
        }
        fn num_residuals(&self) -> usize {
            self.0.len()
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
            for (ri, t) in r.iter_mut().zip(&self.0) {
                *ri = (x[0] * t).sin() + x[1] * t.powi(3);
            }
            Ok(())
        }
    }

    fn exact(t: &[f64], x: &[f64]) -> Mat<f64> {
        Mat::from_fn(t.len(), 2, |i, j| match j {
            0 => t[i] * (x[0] * t[i]).cos(),
            _ => t[i].powi(3),
        })
    }

    #[test]
    fn schemes_reach_their_accuracy_over_wide_parameter_ranges() {
        let t: Vec<f64> = (0..15).map(|i| 0.1 + 0.2 * i as f64).collect();
        for &a in &[1e-6, 0.3, 1.7, 40.0] {
            for &b in &[-1e3, 0.0, 2.5] {
                let x = [a, b];
                let e = exact(&t, &x);
                for (scheme, tol) in [(Difference::Forward, 1e-5), (Difference::Central, 3e-7)] {
                    let mut p = NumericJacobian::new(Curve(t.clone()), scheme);
                    let mut j = Mat::<f64>::zeros(t.len(), 2);
                    p.jacobian(&x, j.as_mut()).unwrap();
                    // Rounding of r (size |r|) divided by the step h_j adds up to
                    // ~eps |r| / h_j: allowed on top of the scheme's truncation error.
                    let r_max = t
                        .iter()
                        .map(|t| ((a * t).sin() + b * t.powi(3)).abs())
                        .fold(1.0, f64::max);
                    for c in 0..2 {
                        let scale = (0..t.len()).map(|i| e[(i, c)].abs()).fold(1e-300, f64::max);
                        let h = scheme.default_step() * x[c].abs().max(f64::MIN_POSITIVE);
                        let h = if x[c] == 0.0 {
                            scheme.default_step()
                        } else {
                            h
                        };
                        let rounding = 4.0 * f64::EPSILON * r_max / h / scale;
                        for i in 0..t.len() {
                            let err = (j[(i, c)] - e[(i, c)]).abs() / scale;
                            assert!(
                                err < tol + rounding,
                                "{scheme:?} a={a} b={b} ({i},{c}): {err:e} (rounding {rounding:e})"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn a_bad_step_is_an_error_not_a_panic() {
        let mut p = NumericJacobian::new(Curve(vec![1.0]), Difference::Forward).with_step(0.0);
        let mut j = Mat::<f64>::zeros(1, 2);
        assert!(p.jacobian(&[1.0, 1.0], j.as_mut()).is_err());
    }
}
