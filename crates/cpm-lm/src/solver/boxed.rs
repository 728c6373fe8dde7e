//! Box constraints inside the iteration: the step to take when a bound cuts the solved
//! one, and the first-order optimality of a point in the box.
//!
//! A solved step `h` that leaves the box is not simply clipped. Three candidates are formed
//! and the one whose predicted reduction `-g.s - ||J s||^2 / 2` is largest is tried:
//!
//! - the projection `P(x + h) - x` (parameters pushed past a bound land on it and are held
//!   there by the next linearisation's active set);
//! - `h` shortened to the boundary, `tau h` with the largest `tau <= 1` that stays in the box
//!   (along a damped step the model decreases all the way to `h`, so it predicts a reduction
//!   whenever `tau > 0`);
//! - the projected Cauchy step: the model's minimiser along the scaled steepest descent
//!   `-D^-2 g`, kept within the trust region, then projected.
//!
//! The Cauchy candidate predicts a reduction whenever the gradient, with the parameters held
//! at a bound removed, is not zero, so a cut step is never one that can only go uphill (the
//! solve then ends by its tolerances only where the box allows no first-order progress).
//!
//! The optimality [`measure`] is scale-free: for each parameter, the reduction of the
//! Gauss-Newton model from moving that parameter alone to its best place in the box,
//! relative to the cost, square-rooted. In the interior it is the cosine of MINPACK's
//! gradient test, `|g_j| / (||J e_j|| ||r||)`; at a bound that the gradient pushes against
//! it is zero. At a zero residual the model still predicts the whole cost, along a move at
//! the rounding level of `x`: moves below [`STEP_TOL`] of the parameter's own value do not
//! count, and a cost at the rounding level of the start's (below `(32 eps sqrt(m))^2` times
//! it) measures zero. (Relative to each parameter's own value, not to the scaled `||D x||`
//! of the step test: after a start where one column was huge, Marquardt's running maximum
//! would make every other parameter's move look negligible.)

use crate::bounds::Bounds;
use crate::solver::jacobian::Jacobian;
use crate::solver::small::dot;

/// Relative size (of the parameter's value) below which its move does not count in
/// [`measure`].
pub(crate) const STEP_TOL: f64 = 1e-10;

/// The largest [`measure`] at which a point of the box counts as first-order optimal.
pub(crate) const OPTIMALITY_TOL: f64 = 1e-6;

/// The linear model's predicted reduction `-g.s - ||J s||^2 / 2` for the step `s`.
fn predicted(jac: &Jacobian, scratch: &mut [f64], g: &[f64], s: &[f64]) -> f64 {
    -dot(g, s) - 0.5 * jac.product_norm2(s, scratch)
}

/// What [`cut_step`] works with: the linearisation at `x` (its Jacobian with the held
/// columns zeroed, the gradient with the held entries zeroed), the scaling and the radius.
pub(crate) struct CutStep<'a> {
    pub(crate) jac: &'a Jacobian,
    /// Scratch for `J s` (may be empty: see [`Jacobian::product_norm2`]).
    pub(crate) scratch: &'a mut [f64],
    pub(crate) bounds: &'a Bounds,
    pub(crate) x: &'a [f64],
    pub(crate) g: &'a [f64],
    pub(crate) d: &'a [f64],
    /// The trust-region radius on `||D s||` (the scaled length of the solved step for the
    /// other damping schedules).
    pub(crate) radius: f64,
}

impl CutStep<'_> {
    /// Chooses the step when the box cut the solved step `dir` (`= alpha h`): on entry
    /// `step` holds the projection `P(x + dir) - x`, on return the best candidate; `cand` is
    /// scratch. Returns the candidate's predicted reduction.
    pub(crate) fn choose(&mut self, dir: &[f64], step: &mut [f64], cand: &mut [f64]) -> f64 {
        let n = self.x.len();
        let mut best = predicted(self.jac, self.scratch, self.g, step);
        // Shortened to the boundary.
        let tau = self.bounds.fraction_inside(self.x, dir);
        if tau > 0.0 {
            for j in 0..n {
                cand[j] = tau * dir[j];
            }
            let p = predicted(self.jac, self.scratch, self.g, cand);
            if p > best {
                step.copy_from_slice(cand);
                best = p;
            }
        }
        // The projected Cauchy step.
        let (mut gp, mut dp2) = (0.0, 0.0);
        for j in 0..n {
            let p = -self.g[j] / (self.d[j] * self.d[j]);
            cand[j] = p;
            gp += self.g[j] * p;
            dp2 += (self.d[j] * p).powi(2);
        }
        if !(gp < 0.0 && dp2 > 0.0) {
            return best;
        }
        let jp2 = self.jac.product_norm2(cand, self.scratch);
        let t_model = if jp2 > 0.0 { -gp / jp2 } else { f64::INFINITY };
        let t = t_model.min(self.radius / dp2.sqrt());
        if !(t > 0.0 && t.is_finite()) {
            return best;
        }
        for j in 0..n {
            cand[j] *= t;
        }
        self.bounds.project_step(self.x, cand);
        let p = predicted(self.jac, self.scratch, self.g, cand);
        if p > best {
            step.copy_from_slice(cand);
            best = p;
        }
        best
    }
}

/// The first-order optimality measure at `x` (see the module documentation) from the
/// gradient `g` and the squared column norms `norms2` there, and the cost. Zero at a cost
/// not above `zero_cost` (the rounding level of the start's).
pub(crate) fn measure(
    x: &[f64],
    g: &[f64],
    norms2: &[f64],
    bounds: &Bounds,
    cost: f64,
    zero_cost: f64,
) -> f64 {
    if !(cost > zero_cost) {
        return 0.0;
    }
    let mut worst = 0.0f64;
    for j in 0..x.len() {
        if !(norms2[j] > 0.0) {
            continue;
        }
        let t = bounds.clamp_move(j, x[j], -g[j] / norms2[j]);
        if !(t.abs() > STEP_TOL * x[j].abs()) {
            continue;
        }
        let red = -g[j] * t - 0.5 * norms2[j] * t * t;
        worst = worst.max((red.max(0.0) / cost).sqrt());
    }
    worst
}

/// `||x - P(x - g)||_inf`, the projected gradient's infinity norm.
pub(crate) fn projected_gradient(x: &[f64], g: &[f64], bounds: &Bounds) -> f64 {
    (0..x.len())
        .map(|j| bounds.clamp_move(j, x[j], -g[j]).abs())
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    /// r = [10 (x1 - x0^2), 1 - x0] (Rosenbrock): its Jacobian and gradient at `x`.
    fn rosenbrock(x: &[f64]) -> (Jacobian, Vec<f64>, Vec<f64>, f64) {
        let r = [10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]];
        let j = Mat::from_fn(2, 2, |i, c| match (i, c) {
            (0, 0) => -20.0 * x[0],
            (0, 1) => 10.0,
            (1, 0) => -1.0,
            _ => 0.0,
        });
        let g: Vec<f64> = (0..2)
            .map(|c| j[(0, c)] * r[0] + j[(1, c)] * r[1])
            .collect();
        let n2: Vec<f64> = (0..2)
            .map(|c| j[(0, c)].powi(2) + j[(1, c)].powi(2))
            .collect();
        let cost = 0.5 * (r[0] * r[0] + r[1] * r[1]);
        (Jacobian::Dense(j), g, n2, cost)
    }

    #[test]
    fn a_cut_step_that_goes_uphill_is_replaced_by_one_that_descends() {
        // From Rosenbrock's start the Gauss-Newton step goes to (1, -3.84); the box
        // [-2, 2]^2 cuts it to (1, -2), uphill for the model. The chosen step must descend.
        let b = Bounds::new(2, Some(&[-2.0, -2.0]), Some(&[2.0, 2.0])).unwrap();
        let x = [-1.2, 1.0];
        let (jac, g, n2, _) = rosenbrock(&x);
        let dir = [2.2, -4.84];
        let mut step = [0.0; 2];
        for j in 0..2 {
            step[j] = (x[j] + dir[j]).clamp(-2.0, 2.0) - x[j];
        }
        let mut scratch = [0.0; 2];
        let projected = predicted(&jac, &mut scratch, &g, &step);
        assert!(projected <= 0.0, "{projected}");
        let d: Vec<f64> = n2.iter().map(|v| v.sqrt()).collect();
        let mut cut = CutStep {
            jac: &jac,
            scratch: &mut scratch,
            bounds: &b,
            x: &x,
            g: &g,
            d: &d,
            radius: 100.0,
        };
        let mut cand = [0.0; 2];
        let pred = cut.choose(&dir, &mut step, &mut cand);
        assert!(pred > 0.0, "{pred}");
        for j in 0..2 {
            assert!((-2.0..=2.0).contains(&(x[j] + step[j])), "{step:?}");
        }
        assert!((predicted(&jac, &mut scratch, &g, &step) - pred).abs() <= 1e-12 * pred);
    }

    #[test]
    fn the_measure_is_the_gradient_cosine_inside_and_zero_against_a_bound() {
        let x = [-1.2, 1.0];
        let (_, g, n2, cost) = rosenbrock(&x);
        let wide = Bounds::new(2, Some(&[-1e9, -1e9]), Some(&[1e9, 1e9])).unwrap();
        let m = measure(&x, &g, &n2, &wide, cost, 0.0);
        let cosine = (0..2)
            .map(|j| g[j].abs() / (n2[j].sqrt() * (2.0 * cost).sqrt()))
            .fold(0.0, f64::max);
        assert!((m - cosine).abs() < 1e-12, "{m} {cosine}");
        // At (0.5, 0.25) in x0 <= 0.5: the gradient pushes x0 up against its bound and
        // r0 = 0, so nothing can be gained.
        let x = [0.5, 0.25];
        let (_, g, n2, cost) = rosenbrock(&x);
        assert!(g[0] < 0.0);
        let cut = Bounds::new(2, Some(&[-2.0, -2.0]), Some(&[0.5, 2.0])).unwrap();
        assert_eq!(measure(&x, &g, &n2, &cut, cost, 0.0), 0.0);
        assert!(measure(&x, &g, &n2, &wide, cost, 0.0) > 0.05);
        assert_eq!(projected_gradient(&x, &g, &cut), 0.0);
        assert!(projected_gradient(&x, &g, &wide) > 0.1);
        // At a cost below the zero level, and for a move negligible beside x.
        assert_eq!(measure(&x, &g, &n2, &wide, cost, cost), 0.0);
        let (_, g, n2, cost) = rosenbrock(&[1.0 + 1e-13, 1.0 + 2e-13]);
        assert!(cost > 0.0);
        assert_eq!(measure(&[1.0, 1.0], &g, &n2, &wide, cost, 0.0), 0.0);
    }
}
