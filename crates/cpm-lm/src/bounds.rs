//! Box constraints `lower <= x <= upper`: the box itself and its elementary operations.
//!
//! A parameter sitting on a bound with the gradient pushing it outwards is frozen for the
//! step (its Jacobian column is zeroed, so the step leaves it alone), and so is one on a bound
//! that the solved step would push out (the step is then solved again); the gradient test
//! for convergence uses the projected gradient. A step that the box still cuts is replaced by
//! the best of three candidates (see `solver::boxed`), and the step actually taken is the one
//! whose predicted reduction enters the gain ratio.

/// Box bounds on the parameters (internal form: both sides present, infinite when unset).
#[derive(Clone, Debug)]
pub(crate) struct Bounds {
    lower: Vec<f64>,
    upper: Vec<f64>,
}

impl Bounds {
    /// Builds the box from the options, or `None` when there is no bound at all.
    pub(crate) fn new(n: usize, lower: Option<&[f64]>, upper: Option<&[f64]>) -> Option<Self> {
        if lower.is_none() && upper.is_none() {
            return None;
        }
        let lower = lower.map_or_else(|| vec![f64::NEG_INFINITY; n], <[f64]>::to_vec);
        let upper = upper.map_or_else(|| vec![f64::INFINITY; n], <[f64]>::to_vec);
        Some(Self { lower, upper })
    }

    /// Projects `x` onto the box in place.
    pub(crate) fn project(&self, x: &mut [f64]) {
        for ((v, lo), up) in x.iter_mut().zip(&self.lower).zip(&self.upper) {
            *v = v.max(*lo).min(*up);
        }
    }

    /// Marks parameters on a bound whose descent direction `-g` points out of the box.
    /// Returns whether any parameter is frozen.
    pub(crate) fn freeze(&self, x: &[f64], g: &[f64], frozen: &mut [bool]) -> bool {
        let mut any = false;
        for j in 0..x.len() {
            let f = (x[j] <= self.lower[j] && g[j] > 0.0) || (x[j] >= self.upper[j] && g[j] < 0.0);
            frozen[j] = f;
            any |= f;
        }
        any
    }

    /// Marks, besides those already `frozen`, the parameters on a bound that the step `h`
    /// would push out of the box. Returns whether any was newly marked.
    pub(crate) fn block(&self, x: &[f64], h: &[f64], frozen: &mut [bool]) -> bool {
        let mut any = false;
        for j in 0..x.len() {
            if !frozen[j]
                && ((x[j] <= self.lower[j] && h[j] < 0.0) || (x[j] >= self.upper[j] && h[j] > 0.0))
            {
                frozen[j] = true;
                any = true;
            }
        }
        any
    }

    /// The largest `t` in `[0, 1]` with `x + t dir` in the box (`x` in the box).
    pub(crate) fn fraction_inside(&self, x: &[f64], dir: &[f64]) -> f64 {
        let mut t = 1.0f64;
        for j in 0..x.len() {
            if dir[j] < 0.0 {
                t = t.min((self.lower[j] - x[j]) / dir[j]);
            } else if dir[j] > 0.0 {
                t = t.min((self.upper[j] - x[j]) / dir[j]);
            }
        }
        t.max(0.0)
    }

    /// Whether `x + t dir` lies in the box.
    pub(crate) fn holds(&self, x: &[f64], dir: &[f64], t: f64) -> bool {
        (0..x.len()).all(|j| {
            let v = x[j] + t * dir[j];
            v >= self.lower[j] && v <= self.upper[j]
        })
    }

    /// `P(x_j + t) - x_j`: the move `t` of parameter `j` from `x_j`, kept in the box.
    pub(crate) fn clamp_move(&self, j: usize, xj: f64, t: f64) -> f64 {
        (xj + t).max(self.lower[j]).min(self.upper[j]) - xj
    }

    /// Replaces the step `s` by `P(x + s) - x`.
    pub(crate) fn project_step(&self, x: &[f64], s: &mut [f64]) {
        for j in 0..x.len() {
            s[j] = self.clamp_move(j, x[j], s[j]);
        }
    }

    /// SciPy's `active_mask`: -1 for a parameter on its lower bound, 1 on its upper bound,
    /// 0 otherwise.
    pub(crate) fn active(&self, x: &[f64]) -> Vec<i8> {
        (0..x.len())
            .map(|j| {
                if x[j] <= self.lower[j] {
                    -1
                } else if x[j] >= self.upper[j] {
                    1
                } else {
                    0
                }
            })
            .collect()
    }

    /// Whether `x` lies inside the box.
    #[cfg(test)]
    pub(crate) fn contains(&self, x: &[f64]) -> bool {
        x.iter()
            .zip(&self.lower)
            .zip(&self.upper)
            .all(|((v, lo), up)| *v >= *lo && *v <= *up)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_and_freezing() {
        let b = Bounds::new(
            3,
            Some(&[0.0, f64::NEG_INFINITY, -1.0]),
            Some(&[1.0, 2.0, 1.0]),
        )
        .unwrap();
        let mut x = [-3.0, 5.0, 0.5];
        b.project(&mut x);
        assert_eq!(x, [0.0, 2.0, 0.5]);
        assert!(b.contains(&x));
        let mut frozen = [false; 3];
        // Gradient > 0 at the lower bound: descent goes below the bound -> frozen.
        assert!(b.freeze(&x, &[1.0, 1.0, 1.0], &mut frozen));
        assert_eq!(frozen, [true, false, false]);
        b.freeze(&x, &[-1.0, -1.0, 0.0], &mut frozen);
        assert_eq!(frozen, [false, true, false]);
        // x = [0, 2, 0.5]: a step pushing x0 down or x1 up is blocked, x2 is free.
        let mut frozen = [false; 3];
        assert!(b.block(&x, &[-1.0, 1.0, 5.0], &mut frozen));
        assert_eq!(frozen, [true, true, false]);
        assert!(!b.block(&x, &[-1.0, 1.0, 5.0], &mut frozen));
        let mut frozen = [false; 3];
        assert!(!b.block(&x, &[1.0, -1.0, 5.0], &mut frozen));
        // From x2 = 0.5 a step of 5 reaches the upper bound 1 at t = 0.1.
        assert_eq!(b.fraction_inside(&x, &[1.0, -1.0, 5.0]), 0.1);
        assert_eq!(b.fraction_inside(&x, &[0.5, -1.0, 0.1]), 1.0);
        assert_eq!(b.fraction_inside(&x, &[-0.5, 0.0, 0.0]), 0.0);
        assert!(b.holds(&x, &[1.0, -1.0, 5.0], 0.1));
        assert!(!b.holds(&x, &[1.0, -1.0, 5.0], 0.2));
        let mut s = [-1.0, 1.0, -2.0];
        b.project_step(&x, &mut s);
        assert_eq!(s, [0.0, 0.0, -1.5]);
        assert_eq!(b.active(&x), vec![-1, 1, 0]);
    }
}
