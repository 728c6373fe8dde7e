//! Box constraints `lower <= x <= upper`, handled by projection.
//!
//! Each trial point is projected onto the box, and the step that is actually taken (the
//! projected one) is the one whose predicted reduction enters the gain ratio. A parameter
//! sitting on a bound with the gradient pushing it outwards is frozen for the step (its
//! Jacobian column is zeroed, so the step leaves it alone), and the gradient test for
//! convergence uses the projected gradient.

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
    }
}
