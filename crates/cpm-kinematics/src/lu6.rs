//! 6x6 LU factors with partial pivoting on plain arrays: nalgebra's `LU` and `LU::solve`
//! operation for operation (the same pivots, products, sums and quotients in the same order,
//! so the same bits), without its generic views, for forward kinematics' Newton steps.
//!
//! nalgebra's elimination step scales the column below the pivot by the pivot's reciprocal
//! (`l = a * (1 / p)`, not `a / p`) and updates each entry as `a - u * l` (its `axpy` with
//! `b = 1`: `(-u) * l * 1 + 1 * a`, the same value, written `a += -u * l`: a sum of two
//! terms is the same either way round); the pivot is the first entry of largest
//! magnitude; a column without a non-zero pivot is skipped and the solve then fails. The
//! solve permutes the right-hand side by the recorded swaps, substitutes forward through the
//! unit lower factor and backward through the upper one (`x_i = b_i / u_ii`, then
//! `b_r - x_i * u_ri` for the rows above). `tests` compares the two bit for bit.
//!
//! ```
//! use cpm_kinematics::lu6::Lu6;
//! let mut a = [[0.0; 6]; 6];
//! for i in 0..6 {
//!     a[i][i] = 2.0;
//!     a[i][(i + 1) % 6] = 1.0;
//! }
//! let x = Lu6::new(&a).solve(&[3.0; 6]).unwrap();
//! assert!(x.iter().all(|v| (v - 1.0).abs() < 1e-15));
//! ```

/// A 6x6 matrix as rows.
pub type Mat6 = [[f64; 6]; 6];

/// The LU factors of a 6x6 matrix with partial (row) pivoting, as nalgebra's `LU::new`
/// makes them (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lu6 {
    /// The unit lower factor below the diagonal, the upper factor on and above it.
    lu: Mat6,
    /// The row swaps `(i, piv)` in the order they were made (`piv != i`).
    swaps: [(u8, u8); 6],
    /// How many of `swaps` were made.
    count: u8,
}

impl Lu6 {
    /// The factors of `a`.
    pub fn new(a: &Mat6) -> Self {
        let mut lu = *a;
        let mut swaps = [(0u8, 0u8); 6];
        let mut count = 0u8;
        for i in 0..6 {
            // The first entry of largest magnitude at or below the diagonal (nalgebra's
            // `icamax`: a strictly larger one replaces it, NaN never does).
            let mut piv = i;
            let mut the_max = lu[i][i].abs();
            for r in i + 1..6 {
                let v = lu[r][i].abs();
                if v > the_max {
                    the_max = v;
                    piv = r;
                }
            }
            let diag = lu[piv][i];
            if diag == 0.0 {
                continue;
            }
            if piv != i {
                swaps[count as usize] = (i as u8, piv as u8);
                count += 1;
                lu.swap(i, piv);
            }
            let inv_diag = 1.0 / diag;
            for r in i + 1..6 {
                let l = lu[r][i] * inv_diag;
                lu[r][i] = l;
                for k in i + 1..6 {
                    lu[r][k] += -lu[i][k] * l;
                }
            }
        }
        Lu6 { lu, swaps, count }
    }

    /// The solution of `a x = b`, `None` when a pivot is zero (nalgebra's `LU::solve`).
    pub fn solve(&self, b: &[f64; 6]) -> Option<[f64; 6]> {
        let mut x = *b;
        for &(i, piv) in &self.swaps[..self.count as usize] {
            x.swap(i as usize, piv as usize);
        }
        let lu = &self.lu;
        for i in 0..5 {
            let coeff = x[i];
            for r in i + 1..6 {
                x[r] += -coeff * lu[r][i];
            }
        }
        for i in (0..6).rev() {
            let diag = lu[i][i];
            if diag == 0.0 {
                return None;
            }
            let coeff = x[i] / diag;
            x[i] = coeff;
            for r in 0..i {
                x[r] += -coeff * lu[r][i];
            }
        }
        Some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix6, Vector6};
    use proptest::prelude::*;

    fn nalgebra_solve(a: &Mat6, b: &[f64; 6]) -> Option<[f64; 6]> {
        let lu = Matrix6::from_fn(|i, j| a[i][j]).lu();
        lu.solve(&Vector6::from(*b)).map(|x| x.into())
    }

    fn same_bits(a: Option<[f64; 6]>, b: Option<[f64; 6]>) -> bool {
        match (a, b) {
            // NaN's payload and sign are not kept by the compiler's folding (`1 * x` is `x`):
            // any NaN is the same NaN here (forward kinematics refuses a non-finite step).
            (Some(a), Some(b)) => a
                .iter()
                .zip(&b)
                .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan())),
            (None, None) => true,
            _ => false,
        }
    }

    /// An entry: mostly ordinary numbers of any scale, sometimes zero, a repeat, or a
    /// non-finite value.
    fn entry() -> impl Strategy<Value = f64> {
        prop_oneof![
            8 => -1e3..1e3f64,
            2 => (-1.0..1.0f64, -30i32..30).prop_map(|(m, e)| m * 2f64.powi(e)),
            2 => Just(0.0),
            1 => Just(1.0),
            1 => Just(-0.0),
            1 => prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)],
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]
        /// The same bits as nalgebra's LU solve: general, rank-deficient (a zero or
        /// repeated row or column), and non-finite matrices.
        #[test]
        fn solves_as_nalgebra_does(
            a in proptest::array::uniform6(proptest::array::uniform6(entry())),
            b in proptest::array::uniform6(entry()),
            defect in 0usize..4,
            k in 0usize..6,
        ) {
            let mut a = a;
            match defect {
                1 => a[k] = [0.0; 6],
                2 => a[k] = a[(k + 1) % 6],
                3 => (0..6).for_each(|r| a[r][k] = 0.0),
                _ => {}
            }
            let ours = Lu6::new(&a).solve(&b);
            let theirs = nalgebra_solve(&a, &b);
            prop_assert!(same_bits(ours, theirs), "{a:?} {b:?}: {ours:?} against {theirs:?}");
        }
    }

    #[test]
    fn a_singular_matrix_has_no_solution() {
        let mut a = [[1.0; 6]; 6];
        a[0][0] = 2.0;
        assert_eq!(Lu6::new(&a).solve(&[1.0; 6]), None);
        assert_eq!(nalgebra_solve(&a, &[1.0; 6]), None);
    }
}
