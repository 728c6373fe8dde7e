//! A 6x6 LU factorisation with partial pivoting that is nalgebra 0.34's, operation for
//! operation (`LU::new`, `LU::solve`, `LU::try_inverse`, `Matrix6::try_inverse`): the same
//! numbers bit for bit, in fixed loops over arrays instead of matrix views.
//!
//! Forward kinematics factors J1 at every Newton step, and the reachability check of a data
//! file runs it at every pose. callgrind: nalgebra's `LU::new` of a 6x6 took about 900
//! instructions, this one about 470; criterion (`cargo bench -p cpm-kinematics --bench lib
//! -- lu6`): factor and solve 168 ns against nalgebra's 176 ns (both are bound by the
//! latency of their divisions), the inverse 271 ns against 345 ns. Bit-for-bit equality with
//! nalgebra (tested on random, singular, zero-column and non-finite matrices in
//! `tests/lu6.rs`) keeps every forward solve, verdict and written output as it was.
//!
//! [`Lu6::inverse_norm`] is the one exception: a bound for condition checks, not
//! nalgebra's operations (see there).
//!
//! The operations are nalgebra's, in its order: the pivot is the first entry of largest
//! absolute value at or below the diagonal (a NaN never wins); a column whose pivot is zero
//! is skipped (and the solve then fails); the multipliers are scaled by the reciprocal of the
//! pivot (`x * (1 / d)`, not `x / d`); each update is `y += (-p) * x` (nalgebra's `axpy`
//! computes `(-p) x + y`, the same sum).
//!
//! ```
//! use cpm_kinematics::lu6::Lu6;
//! use nalgebra::{Matrix6, Vector6};
//! let a = Matrix6::from_fn(|i, j| if i == j { 2.0 } else { 1.0 / (1 + i + j) as f64 });
//! let b = Vector6::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0);
//! let x = Lu6::new(&a).solve(&b).unwrap();
//! assert_eq!(x, a.lu().solve(&b).unwrap()); // the same bits as nalgebra's
//! assert!((a * x - b).norm() < 1e-12);
//! ```
use nalgebra::{Matrix6, Vector6};

/// The LU factors `P A = L U` of a 6x6 matrix (L with a unit diagonal), as nalgebra's
/// `LU::new` makes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lu6 {
    /// L below the diagonal and U on and above it, by column: `lu[column][row]`.
    lu: [[f64; 6]; 6],
    /// The row swaps, in the order made: step `i` swapped rows `i` and `swaps[i]` (itself
    /// when it did not swap).
    swaps: [usize; 6],
}

impl Lu6 {
    /// The factors of `a` (nalgebra's `a.lu()`).
    pub fn new(a: &Matrix6<f64>) -> Self {
        Self::of_columns(columns(a))
    }

    /// The factors of the matrix whose row `i` is `rows[i]`.
    pub fn from_rows(rows: &[[f64; 6]; 6]) -> Self {
        let mut c = [[0.0; 6]; 6];
        for (i, row) in rows.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                c[j][i] = *v;
            }
        }
        Self::of_columns(c)
    }

    /// Gaussian elimination with partial pivoting, nalgebra's `LU::new`: a column whose pivot
    /// is zero is skipped (its zero stays on the diagonal, and every solve fails).
    fn of_columns(mut m: [[f64; 6]; 6]) -> Self {
        let mut swaps = [0, 1, 2, 3, 4, 5];
        // One step per column, each with constant bounds (unrolled, no bounds checks).
        step::<0>(&mut m, &mut swaps);
        step::<1>(&mut m, &mut swaps);
        step::<2>(&mut m, &mut swaps);
        step::<3>(&mut m, &mut swaps);
        step::<4>(&mut m, &mut swaps);
        step::<5>(&mut m, &mut swaps);
        Lu6 { lu: m, swaps }
    }

    /// `x` with `A x = b` (nalgebra's `LU::solve`); `None` when a pivot is zero.
    pub fn solve(&self, b: &Vector6<f64>) -> Option<Vector6<f64>> {
        let mut x = [b[0], b[1], b[2], b[3], b[4], b[5]];
        self.solve_in_place(&mut x).then(|| Vector6::from(x))
    }

    /// The inverse, by solving for each column of the identity (nalgebra's
    /// `LU::try_inverse`); `None` when a pivot is zero.
    pub fn inverse(&self) -> Option<Matrix6<f64>> {
        let mut inv = Matrix6::zeros();
        for j in 0..6 {
            let mut e = [0.0; 6];
            e[j] = 1.0;
            if !self.solve_in_place(&mut e) {
                return None;
            }
            inv.set_column(j, &Vector6::from(e));
        }
        Some(inv)
    }

    /// The determinant (nalgebra's `LU::determinant`): the product of U's diagonal, in order
    /// from 1, negated for an odd number of row swaps; the same bits as nalgebra's
    /// `Matrix6::determinant`, zero when a pivot is zero.
    pub fn determinant(&self) -> f64 {
        let mut d = 1.0;
        for i in 0..6 {
            d *= self.lu[i][i];
        }
        let swaps = self
            .swaps
            .iter()
            .enumerate()
            .filter(|(i, p)| i != *p)
            .count();
        if swaps % 2 == 0 {
            d
        } else {
            -d
        }
    }

    /// The Frobenius norm of the inverse, for bounds (not nalgebra's operations): the row
    /// swaps left out (they permute the inverse's columns, which keeps its norm), each
    /// column of `L^-1` made from its first non-zero entry on, and the back substitution by
    /// the pivots' reciprocals. Within a few units in the last place of
    /// `inverse().norm()` times the condition number; `None` when a pivot is zero or not
    /// finite.
    pub fn inverse_norm(&self) -> Option<f64> {
        let mut recip = [0.0; 6];
        for (i, r) in recip.iter_mut().enumerate() {
            let d = self.lu[i][i];
            if d == 0.0 || !d.is_finite() {
                return None;
            }
            *r = 1.0 / d;
        }
        let mut sum = 0.0;
        for k in 0..6 {
            let mut x = [0.0; 6];
            x[k] = 1.0;
            for c in k..5 {
                let coeff = x[c];
                for r in c + 1..6 {
                    x[r] -= coeff * self.lu[c][r];
                }
            }
            for c in (0..6).rev() {
                let coeff = x[c] * recip[c];
                x[c] = coeff;
                for r in 0..c {
                    x[r] -= coeff * self.lu[c][r];
                }
            }
            sum += x.iter().map(|v| v * v).sum::<f64>();
        }
        Some(sum.sqrt())
    }

    /// Permutation, forward substitution (unit diagonal) and back substitution in place;
    /// false when a pivot is zero (nalgebra's `solve_mut`).
    fn solve_in_place(&self, x: &mut [f64; 6]) -> bool {
        for (i, &p) in self.swaps.iter().enumerate() {
            x.swap(i, p);
        }
        // Each substitution step with constant bounds (unrolled, no bounds checks).
        self.forward::<0>(x);
        self.forward::<1>(x);
        self.forward::<2>(x);
        self.forward::<3>(x);
        self.forward::<4>(x);
        self.back::<5>(x)
            && self.back::<4>(x)
            && self.back::<3>(x)
            && self.back::<2>(x)
            && self.back::<1>(x)
            && self.back::<0>(x)
    }

    /// Forward substitution, column `I` of L (unit diagonal: `x[I] / 1` is `x[I]`).
    #[inline(always)]
    fn forward<const I: usize>(&self, x: &mut [f64; 6]) {
        let coeff = x[I];
        for r in I + 1..6 {
            x[r] += -coeff * self.lu[I][r];
        }
    }

    /// Back substitution, column `I` of U; false when its pivot is zero.
    #[inline(always)]
    fn back<const I: usize>(&self, x: &mut [f64; 6]) -> bool {
        let diag = self.lu[I][I];
        if diag == 0.0 {
            return false;
        }
        let coeff = x[I] / diag;
        x[I] = coeff;
        for r in 0..I {
            x[r] += -coeff * self.lu[I][r];
        }
        true
    }
}

/// Step `I` of the elimination: the pivot of column `I`, the row swap, the multipliers and
/// the update of the columns to the right.
#[inline(always)]
fn step<const I: usize>(m: &mut [[f64; 6]; 6], swaps: &mut [usize; 6]) {
    // The first entry of largest magnitude at or below the diagonal (`icamax`), chosen
    // without branches (the pivot row varies from matrix to matrix: a branch would often
    // be mispredicted).
    let mut piv = I;
    let mut largest = m[I][I].abs();
    for r in I + 1..6 {
        let v = m[I][r].abs();
        let bigger = v > largest;
        largest = if bigger { v } else { largest };
        piv = if bigger { r } else { piv };
    }
    let diag = m[I][piv];
    if diag == 0.0 {
        return;
    }
    // The multipliers already made, then this column and those to its right (a swap of a
    // row with itself when the pivot is on the diagonal).
    swaps[I] = piv;
    for col in m.iter_mut() {
        col.swap(I, piv);
    }
    let inv_diag = 1.0 / diag;
    for r in I + 1..6 {
        m[I][r] *= inv_diag;
    }
    let coeffs = m[I];
    for col in m.iter_mut().skip(I + 1) {
        let p = col[I];
        for r in I + 1..6 {
            col[r] += -p * coeffs[r];
        }
    }
}

/// The inverse of `a`, as nalgebra's `a.try_inverse()` computes it; `None` when a pivot is
/// zero. (nalgebra's `try_invert_to` stops at a zero pivot where `LU::new` skips the column;
/// both then fail, and otherwise they make the same factors and the same solves.)
pub fn try_inverse6(a: &Matrix6<f64>) -> Option<Matrix6<f64>> {
    Lu6::new(a).inverse()
}

/// The columns of `a`.
fn columns(a: &Matrix6<f64>) -> [[f64; 6]; 6] {
    let mut c = [[0.0; 6]; 6];
    for (j, col) in c.iter_mut().enumerate() {
        for (i, v) in col.iter_mut().enumerate() {
            *v = a[(i, j)];
        }
    }
    c
}
