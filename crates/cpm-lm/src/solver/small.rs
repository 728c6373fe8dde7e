//! Small dense kernels (column-major slices) for the per-block work of the Schur solver,
//! where a call into a general library would cost more than the arithmetic.

/// Dot product with four partial sums (which the compiler can vectorise, unlike one
/// running sum).
#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0f64; 4];
    let (ac, bc) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        s[0] += x[0] * y[0];
        s[1] += x[1] * y[1];
        s[2] += x[2] * y[2];
        s[3] += x[3] * y[3];
    }
    let mut t = (s[0] + s[1]) + (s[2] + s[3]);
    for (x, y) in ar.iter().zip(br) {
        t += x * y;
    }
    t
}

/// `||a||^2`, as [`dot`].
#[inline]
pub(crate) fn norm2(a: &[f64]) -> f64 {
    dot(a, a)
}

/// In-place Cholesky `A = L L^T` of the `k x k` column-major `a` (lower triangle read and
/// overwritten with `L`). Returns `false` if `A` is not numerically positive definite.
pub(crate) fn cholesky(a: &mut [f64], k: usize) -> bool {
    for j in 0..k {
        let mut s = a[j + j * k];
        for p in 0..j {
            s -= a[j + p * k] * a[j + p * k];
        }
        if !(s > 0.0 && s.is_finite()) {
            return false;
        }
        let ljj = s.sqrt();
        a[j + j * k] = ljj;
        for i in j + 1..k {
            let mut t = a[i + j * k];
            for p in 0..j {
                t -= a[i + p * k] * a[j + p * k];
            }
            a[i + j * k] = t / ljj;
        }
    }
    true
}

/// Solves `L x = b` in place, `l` from [`cholesky`].
pub(crate) fn forward_solve(l: &[f64], k: usize, b: &mut [f64]) {
    for i in 0..k {
        let mut t = b[i];
        for p in 0..i {
            t -= l[i + p * k] * b[p];
        }
        b[i] = t / l[i + i * k];
    }
}

/// Solves `L^T x = b` in place, `l` from [`cholesky`].
pub(crate) fn backward_solve(l: &[f64], k: usize, b: &mut [f64]) {
    for i in (0..k).rev() {
        let mut t = b[i];
        for p in i + 1..k {
            t -= l[p + i * k] * b[p];
        }
        b[i] = t / l[i + i * k];
    }
}

/// Solves `L L^T x = b` in place, `l` from [`cholesky`].
/// Writes `-g` into the single column `rhs` (the right-hand side of the damped normal
/// equations).
#[inline]
pub(crate) fn load_negated(rhs: &mut faer::Mat<f64>, g: &[f64]) {
    for (k, v) in g.iter().enumerate() {
        rhs[(k, 0)] = -v;
    }
}

/// Copies the single column `rhs` into `h`; true when every entry is finite.
#[inline]
pub(crate) fn store_finite(rhs: &faer::Mat<f64>, h: &mut [f64]) -> bool {
    let mut ok = true;
    for (k, v) in h.iter_mut().enumerate() {
        *v = rhs[(k, 0)];
        ok &= v.is_finite();
    }
    ok
}

#[cfg(test)]
pub(crate) fn cholesky_solve(l: &[f64], k: usize, b: &mut [f64]) {
    forward_solve(l, k, b);
    backward_solve(l, k, b);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_matches_the_plain_sum() {
        for n in [0usize, 1, 3, 4, 7, 9, 33] {
            let a: Vec<f64> = (0..n).map(|i| i as f64 * 0.5 - 2.0).collect();
            let b: Vec<f64> = (0..n).map(|i| 1.0 + (i % 3) as f64).collect();
            let want: f64 = a.iter().zip(&b).map(|(p, q)| p * q).sum();
            assert!((dot(&a, &b) - want).abs() <= 1e-12 * (1.0 + want.abs()));
            assert_eq!(norm2(&a), dot(&a, &a));
        }
    }

    #[test]
    fn solves_spd_system() {
        let a = [4.0, 2.0, 0.4, 2.0, 5.0, 1.0, 0.4, 1.0, 3.0];
        let mut l = a;
        assert!(cholesky(&mut l, 3));
        let mut b = [1.0, 2.0, 3.0];
        cholesky_solve(&l, 3, &mut b);
        for i in 0..3 {
            let ax: f64 = (0..3).map(|j| a[i + 3 * j] * b[j]).sum();
            assert!((ax - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
        let mut bad = [1.0, 2.0, 2.0, 1.0];
        assert!(!cholesky(&mut bad, 2));
    }
}
