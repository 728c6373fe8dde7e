//! Robust losses and the Triggs correction that folds them into the least-squares step.
//!
//! With a loss `rho`, the cost is `0.5 * sum_i rho(r_i^2)`. Near zero every loss behaves
//! like the square (`rho(s) ~ s`); beyond the scale `a` the losses grow more slowly (Huber
//! linearly, Cauchy logarithmically, Tukey not at all), so outliers pull less on the fit.
//!
//! The solver keeps the Gauss-Newton machinery by rescaling each residual and Jacobian row
//! as in Ceres (Triggs et al., *Bundle adjustment: a modern synthesis*, 2000, section 4.3):
//! with `s = r^2`, `rho' = rho'(s)`, `rho'' = rho''(s)`,
//!
//! * if `rho'' <= 0` (all losses here, almost everywhere) the row is weighted by
//!   `sqrt(rho')` (iteratively reweighted least squares);
//! * otherwise `alpha = 1 - sqrt(1 + 2 s rho'' / rho')`, the residual is scaled by
//!   `sqrt(rho') / (1 - alpha)` and the Jacobian row by `sqrt(rho') (1 - alpha)`, which
//!   makes `J^T J` carry the second-order term of the loss.
//!
//! In both cases `J~^T r~ = sum_i rho'(s_i) r_i grad r_i` is the exact gradient of the cost.

use crate::error::LmError;

/// Robust loss applied to each scalar residual. The number is the scale `a > 0` where the
/// loss starts to depart from the square.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Loss {
    /// `rho(s) = s`: ordinary least squares (default).
    #[default]
    Squared,
    /// Huber: `rho(s) = s` for `s <= a^2`, `2 a sqrt(s) - a^2` beyond.
    Huber(f64),
    /// Cauchy: `rho(s) = a^2 ln(1 + s / a^2)`.
    Cauchy(f64),
    /// Tukey's biweight: `rho(s) = a^2/3 (1 - (1 - s/a^2)^3)` for `s <= a^2`, `a^2/3` beyond
    /// (residuals beyond `a` have no influence at all).
    Tukey(f64),
}

impl Loss {
    /// `[rho(s), rho'(s), rho''(s)]` at `s = r^2 >= 0`.
    pub fn evaluate(&self, s: f64) -> [f64; 3] {
        match *self {
            Loss::Squared => [s, 1.0, 0.0],
            Loss::Huber(a) => {
                let b = a * a;
                if s <= b {
                    [s, 1.0, 0.0]
                } else {
                    let r = s.sqrt();
                    [2.0 * a * r - b, a / r, -0.5 * a / (s * r)]
                }
            }
            Loss::Cauchy(a) => {
                let b = a * a;
                let t = 1.0 + s / b;
                [b * t.ln(), 1.0 / t, -1.0 / (b * t * t)]
            }
            Loss::Tukey(a) => {
                let b = a * a;
                if s <= b {
                    let t = 1.0 - s / b;
                    [b / 3.0 * (1.0 - t * t * t), t * t, -2.0 * t / b]
                } else {
                    [b / 3.0, 0.0, 0.0]
                }
            }
        }
    }

    /// Whether this is the plain square (no reweighting needed).
    pub fn is_squared(&self) -> bool {
        matches!(self, Loss::Squared)
    }

    pub(crate) fn validate(&self) -> Result<(), LmError> {
        let (name, a) = match *self {
            Loss::Squared => return Ok(()),
            Loss::Huber(a) => ("Huber", a),
            Loss::Cauchy(a) => ("Cauchy", a),
            Loss::Tukey(a) => ("Tukey", a),
        };
        if a.is_finite() && a > 0.0 {
            Ok(())
        } else {
            Err(LmError::InvalidOptions(format!(
                "{name} loss scale must be finite and > 0, got {a}"
            )))
        }
    }

    /// The cost `0.5 * sum rho(r_i^2)` of a residual vector.
    pub fn cost(&self, r: &[f64]) -> f64 {
        match self {
            Loss::Squared => 0.5 * r.iter().map(|v| v * v).sum::<f64>(),
            _ => 0.5 * r.iter().map(|v| self.evaluate(v * v)[0]).sum::<f64>(),
        }
    }

    /// Triggs/Ceres correction of one residual: `(residual scale, Jacobian row scale)`.
    pub fn correction(&self, r: f64) -> (f64, f64) {
        let s = r * r;
        let [_, d1, d2] = self.evaluate(s);
        if d1 <= 0.0 || !d1.is_finite() {
            return (0.0, 0.0);
        }
        let sq = d1.sqrt();
        if s == 0.0 || d2 <= 0.0 {
            return (sq, sq);
        }
        let alpha = 1.0 - (1.0 + 2.0 * s * d2 / d1).sqrt();
        (sq / (1.0 - alpha), sq * (1.0 - alpha))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn num_derivs(l: Loss, s: f64) -> (f64, f64) {
        let h = 1e-5 * s.max(1e-3);
        let f = |t: f64| l.evaluate(t);
        (
            (f(s + h)[0] - f(s - h)[0]) / (2.0 * h),
            (f(s + h)[1] - f(s - h)[1]) / (2.0 * h),
        )
    }

    #[test]
    fn derivatives_match_finite_differences() {
        for l in [Loss::Huber(1.3), Loss::Cauchy(0.7), Loss::Tukey(2.0)] {
            for s in [0.1, 0.5, 1.0, 3.0, 10.0] {
                let [_, d1, d2] = l.evaluate(s);
                let (n1, n2) = num_derivs(l, s);
                assert!((d1 - n1).abs() < 1e-6 * (1.0 + d1.abs()), "{l:?} {s}");
                assert!((d2 - n2).abs() < 1e-5 * (1.0 + d2.abs()), "{l:?} {s}");
            }
        }
    }

    #[test]
    fn all_losses_are_square_near_zero() {
        for l in [
            Loss::Squared,
            Loss::Huber(1.0),
            Loss::Cauchy(1.0),
            Loss::Tukey(1.0),
        ] {
            let [v, d1, _] = l.evaluate(1e-8);
            assert!((v - 1e-8).abs() < 1e-15 && (d1 - 1.0).abs() < 1e-7, "{l:?}");
        }
    }

    #[test]
    fn corrected_gradient_is_exact() {
        // (residual scale) * (jacobian scale) * r must equal rho'(r^2) * r.
        for l in [Loss::Huber(0.5), Loss::Cauchy(0.5), Loss::Tukey(3.0)] {
            for r in [-4.0, -0.2, 0.0, 0.3, 2.5] {
                let (a, b) = l.correction(r);
                let d1 = l.evaluate(r * r)[1];
                assert!((a * b * r - d1 * r).abs() < 1e-12);
            }
        }
    }
}
