//! Dense QR solver (default): the damped step from a pivoted QR of `J`, as in MINPACK.
//!
//! The step solves the augmented least-squares problem
//! `min || [J; sqrt(mu) D] h + [r; 0] ||`, which is the damped normal equations
//! `(J^T J + mu D^2) h = -J^T r` without ever forming `J^T J` (so without squaring the
//! condition number). `J P = Q R` is computed once per Jacobian (Householder with column
//! pivoting, MINPACK's `qrfac`); each damping value then only costs an `O(n^2)` Givens
//! elimination of `sqrt(mu) D` against `R` (MINPACK's `qrsolv`), so rejected steps are
//! cheap. All storage is allocated once, when the solver is built.

use crate::solver::jacobian::Jacobian;
use crate::solver::small;
use crate::solver::LinearSystem;

/// Workspace of the dense QR solver.
pub(crate) struct DenseQr {
    n: usize,
    m: usize,
    /// Rows of the factored matrix: `max(m, n)` (zero rows pad a wide Jacobian).
    rows: usize,
    /// The matrix and the vectors, in one allocation (see [`DenseQr::parts`]).
    store: Vec<f64>,
    ipvt: Vec<usize>,
    /// Whether the strict lower triangle and `sdiag` hold the factor `S` of the last solve
    /// (`P^T (J^T J + mu D^2) P = S^T S`).
    factored: bool,
}

/// The vectors of [`DenseQr`], borrowed from its buffer.
struct Vectors<'a> {
    rdiag: &'a mut [f64],
    acnorm: &'a mut [f64],
    wa: &'a mut [f64],
    sdiag: &'a mut [f64],
    xdiag: &'a mut [f64],
    diag: &'a mut [f64],
    z: &'a mut [f64],
    /// `Q^T r` (first `n` entries used).
    qtf: &'a mut [f64],
    /// Scratch of length `rows`.
    wb: &'a mut [f64],
}

impl DenseQr {
    pub(crate) fn new(m: usize, n: usize) -> Self {
        let rows = m.max(n);
        Self {
            n,
            m,
            rows,
            store: vec![0.0; rows * n + 7 * n + 2 * rows],
            ipvt: vec![0; n],
            factored: false,
        }
    }

    /// The `rows x n` column-major matrix (Householder vectors, then `R`: upper triangle
    /// with diagonal; the strict lower triangle of the top `n x n` block is scratch for
    /// `qrsolv`) and the vectors.
    fn parts(store: &mut [f64], rows: usize, n: usize) -> (&mut [f64], Vectors<'_>) {
        let (a, buf) = store.split_at_mut(rows * n);
        (a, Self::split(buf, n))
    }

    fn split(buf: &mut [f64], n: usize) -> Vectors<'_> {
        let (rdiag, rest) = buf.split_at_mut(n);
        let (acnorm, rest) = rest.split_at_mut(n);
        let (wa, rest) = rest.split_at_mut(n);
        let (sdiag, rest) = rest.split_at_mut(n);
        let (xdiag, rest) = rest.split_at_mut(n);
        let (diag, rest) = rest.split_at_mut(n);
        let (z, rest) = rest.split_at_mut(n);
        let (qtf, wb) = rest.split_at_mut(rest.len() / 2);
        Vectors {
            rdiag,
            acnorm,
            wa,
            sdiag,
            xdiag,
            diag,
            z,
            qtf,
            wb,
        }
    }
}

fn norm(v: &[f64]) -> f64 {
    small::norm2(v).sqrt()
}

/// Householder QR with column pivoting of the `rows x n` column-major `a` (MINPACK qrfac).
fn qrfac(
    rows: usize,
    n: usize,
    a: &mut [f64],
    ipvt: &mut [usize],
    rdiag: &mut [f64],
    acnorm: &mut [f64],
    wa: &mut [f64],
) {
    for j in 0..n {
        let nrm = norm(&a[j * rows..(j + 1) * rows]);
        acnorm[j] = nrm;
        rdiag[j] = nrm;
        wa[j] = nrm;
        ipvt[j] = j;
    }
    for j in 0..n.min(rows) {
        // Bring the column of largest remaining norm into the pivot position.
        let mut kmax = j;
        for k in j..n {
            if rdiag[k] > rdiag[kmax] {
                kmax = k;
            }
        }
        if kmax != j {
            let (left, right) = a.split_at_mut(kmax * rows);
            left[j * rows..(j + 1) * rows].swap_with_slice(&mut right[..rows]);
            rdiag[kmax] = rdiag[j];
            wa[kmax] = wa[j];
            ipvt.swap(j, kmax);
        }
        // Householder reflection zeroing column j below the diagonal.
        let (left, right) = a.split_at_mut((j + 1) * rows);
        let colj = &mut left[j * rows + j..];
        let mut ajnorm = norm(colj);
        if ajnorm != 0.0 {
            if colj[0] < 0.0 {
                ajnorm = -ajnorm;
            }
            for v in colj.iter_mut() {
                *v /= ajnorm;
            }
            colj[0] += 1.0;
            let ajj = colj[0];
            for k in j + 1..n {
                let colk = &mut right[(k - j - 1) * rows + j..(k - j) * rows];
                let sum = small::dot(colj, colk);
                let temp = sum / ajj;
                for (q, p) in colk.iter_mut().zip(colj.iter()) {
                    *q -= temp * p;
                }
                if rdiag[k] != 0.0 {
                    let t = colk[0] / rdiag[k];
                    rdiag[k] *= (1.0 - t * t).max(0.0).sqrt();
                    let t2 = rdiag[k] / wa[k];
                    if 0.05 * t2 * t2 <= f64::EPSILON {
                        rdiag[k] = norm(&colk[1..]);
                        wa[k] = rdiag[k];
                    }
                }
            }
        }
        rdiag[j] = -ajnorm;
    }
}

/// Solves `min || [R P^T; diag] x - [qtb; 0] ||` for `x` (MINPACK qrsolv). `r` holds `R` in
/// its upper triangle (leading dimension `ldr`); its strict lower triangle is overwritten.
#[allow(clippy::too_many_arguments)]
fn qrsolv(
    n: usize,
    r: &mut [f64],
    ldr: usize,
    ipvt: &[usize],
    diag: &[f64],
    qtb: &[f64],
    x: &mut [f64],
    sdiag: &mut [f64],
    wa: &mut [f64],
    xdiag: &mut [f64],
) {
    for j in 0..n {
        for i in j..n {
            r[i + j * ldr] = r[j + i * ldr];
        }
        xdiag[j] = r[j + j * ldr];
        wa[j] = qtb[j];
    }
    for j in 0..n {
        let l = ipvt[j];
        if diag[l] != 0.0 {
            sdiag[j..n].fill(0.0);
            sdiag[j] = diag[l];
            let mut qtbpj = 0.0;
            for k in j..n {
                if sdiag[k] == 0.0 {
                    continue;
                }
                let rkk = r[k + k * ldr];
                let (cos, sin) = if rkk.abs() < sdiag[k].abs() {
                    let cotan = rkk / sdiag[k];
                    let sin = 0.5 / (0.25 + 0.25 * cotan * cotan).sqrt();
                    (sin * cotan, sin)
                } else {
                    let tan = sdiag[k] / rkk;
                    let cos = 0.5 / (0.25 + 0.25 * tan * tan).sqrt();
                    (cos, cos * tan)
                };
                r[k + k * ldr] = cos * rkk + sin * sdiag[k];
                let temp = cos * wa[k] + sin * qtbpj;
                qtbpj = -sin * wa[k] + cos * qtbpj;
                wa[k] = temp;
                let col = &mut r[k * ldr + k + 1..k * ldr + n];
                for (rik, sd) in col.iter_mut().zip(sdiag[k + 1..n].iter_mut()) {
                    let temp = cos * *rik + sin * *sd;
                    *sd = -sin * *rik + cos * *sd;
                    *rik = temp;
                }
            }
        }
        sdiag[j] = r[j + j * ldr];
        r[j + j * ldr] = xdiag[j];
    }
    // Back substitution; a singular triangle gets a least-squares solution.
    let mut nsing = n;
    for j in 0..n {
        if sdiag[j] == 0.0 && nsing == n {
            nsing = j;
        }
        if nsing < n {
            wa[j] = 0.0;
        }
    }
    for j in (0..nsing).rev() {
        let col = &r[j * ldr + j + 1..j * ldr + nsing];
        let sum = small::dot(col, &wa[j + 1..nsing]);
        wa[j] = (wa[j] - sum) / sdiag[j];
    }
    for j in 0..n {
        x[ipvt[j]] = wa[j];
    }
}

impl LinearSystem for DenseQr {
    fn prepare(&mut self, jac: &Jacobian, r: &[f64]) -> Result<(), String> {
        let Jacobian::Dense(j) = jac else {
            return Err("dense QR needs a dense Jacobian".into());
        };
        let (m, n, rows) = (self.m, self.n, self.rows);
        self.factored = false;
        let (a, v) = Self::parts(&mut self.store, rows, n);
        for c in 0..n {
            let dst = &mut a[c * rows..(c + 1) * rows];
            dst[..m].copy_from_slice(j.col_as_slice(c));
            dst[m..].fill(0.0);
        }
        qrfac(rows, n, a, &mut self.ipvt, v.rdiag, v.acnorm, v.wa);
        // Q^T r, then store R's diagonal in place.
        v.wb[..m].copy_from_slice(r);
        v.wb[m..].fill(0.0);
        for jj in 0..n {
            let col = &mut a[jj * rows..(jj + 1) * rows];
            let ajj = col[jj];
            if ajj != 0.0 {
                let sum = small::dot(&col[jj..], &v.wb[jj..]);
                let temp = -sum / ajj;
                for (w, p) in v.wb[jj..].iter_mut().zip(&col[jj..]) {
                    *w += p * temp;
                }
            }
            col[jj] = v.rdiag[jj];
            v.qtf[jj] = v.wb[jj];
        }
        Ok(())
    }

    fn solve(&mut self, _jac: &Jacobian, mu: f64, d: &[f64], _g: &[f64], h: &mut [f64]) -> bool {
        let (a, v) = Self::parts(&mut self.store, self.rows, self.n);
        let s = mu.sqrt();
        for (dd, &dv) in v.diag.iter_mut().zip(d) {
            *dd = s * dv;
        }
        qrsolv(
            self.n, a, self.rows, &self.ipvt, v.diag, v.qtf, v.z, v.sdiag, v.wa, v.xdiag,
        );
        let mut ok = true;
        for (hh, &z) in h.iter_mut().zip(v.z.iter()) {
            *hh = -z;
            ok &= z.is_finite();
        }
        self.factored = ok;
        ok
    }

    fn resolve(&mut self, _jac: &Jacobian, _mu: f64, _d: &[f64], g: &[f64], h: &mut [f64]) -> bool {
        if !self.factored {
            return false;
        }
        // h = -P S^-1 S^-T P^T g with the factor S of the last solve.
        let (n, ldr) = (self.n, self.rows);
        let (a, v) = Self::parts(&mut self.store, ldr, n);
        for j in 0..n {
            v.wa[j] = g[self.ipvt[j]];
        }
        for j in 0..n {
            if v.sdiag[j] == 0.0 {
                return false;
            }
            v.wa[j] /= v.sdiag[j];
            let t = v.wa[j];
            let col = &a[j * ldr + j + 1..j * ldr + n];
            for (wi, &r) in v.wa[j + 1..n].iter_mut().zip(col) {
                *wi -= r * t;
            }
        }
        for j in (0..n).rev() {
            let col = &a[j * ldr + j + 1..j * ldr + n];
            let sum = small::dot(col, &v.wa[j + 1..n]);
            v.wa[j] = (v.wa[j] - sum) / v.sdiag[j];
        }
        let mut ok = true;
        for j in 0..n {
            h[self.ipvt[j]] = -v.wa[j];
            ok &= v.wa[j].is_finite();
        }
        ok
    }

    fn inverse_quadratic(&mut self, _jac: &Jacobian, w: &[f64]) -> Option<f64> {
        if !self.factored {
            return None;
        }
        // ||S^-T P^T w||^2 (MINPACK lmpar's Newton correction): S^T is the lower triangle
        // left by qrsolv, with diagonal sdiag.
        let (n, ldr) = (self.n, self.rows);
        let (a, v) = Self::parts(&mut self.store, ldr, n);
        for j in 0..n {
            v.wa[j] = w[self.ipvt[j]];
        }
        for j in 0..n {
            if v.sdiag[j] == 0.0 {
                return None;
            }
            v.wa[j] /= v.sdiag[j];
            let t = v.wa[j];
            let col = &a[j * ldr + j + 1..j * ldr + n];
            for (wi, &r) in v.wa[j + 1..n].iter_mut().zip(col) {
                *wi -= r * t;
            }
        }
        let q = small::norm2(&v.wa[..n]);
        q.is_finite().then_some(q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::prelude::*;
    use faer::Mat;

    /// Solves the damped normal equations densely for comparison.
    fn reference(j: &Mat<f64>, r: &[f64], mu: f64, d: &[f64]) -> Vec<f64> {
        let n = j.ncols();
        let mut a = j.transpose() * j;
        for k in 0..n {
            a[(k, k)] += mu * d[k] * d[k];
        }
        let g = Mat::<f64>::from_fn(n, 1, |k, _| {
            -(0..j.nrows()).map(|i| j[(i, k)] * r[i]).sum::<f64>()
        });
        let x = a.partial_piv_lu().solve(&g);
        (0..n).map(|k| x[(k, 0)]).collect()
    }

    /// `w^T (J^T J + mu D^2)^-1 w` densely.
    fn quad_reference(j: &Mat<f64>, mu: f64, d: &[f64], w: &[f64]) -> f64 {
        let n = j.ncols();
        let mut a = j.transpose() * j;
        for k in 0..n {
            a[(k, k)] += mu * d[k] * d[k];
        }
        let b = Mat::<f64>::from_fn(n, 1, |k, _| w[k]);
        let x = a.partial_piv_lu().solve(&b);
        (0..n).map(|k| w[k] * x[(k, 0)]).sum()
    }

    #[test]
    fn damped_steps_match_normal_equations() {
        for (m, n) in [(7, 4), (4, 4), (2, 5), (30, 6)] {
            let j = Mat::<f64>::from_fn(m, n, |i, k| {
                ((i * 7 + k * 13) % 11) as f64 - 5.0 + 0.1 * k as f64
            });
            let r: Vec<f64> = (0..m).map(|i| (i as f64 * 0.7).sin()).collect();
            let d: Vec<f64> = (0..n).map(|k| 1.0 + k as f64).collect();
            let mut qr = DenseQr::new(m, n);
            let jac = Jacobian::Dense(j.clone());
            qr.prepare(&jac, &r).unwrap();
            for mu in [1e-6, 1e-2, 1.0, 100.0] {
                let mut h = vec![0.0; n];
                assert!(qr.solve(&jac, mu, &d, &[], &mut h));
                let want = reference(&j, &r, mu, &d);
                for k in 0..n {
                    assert!(
                        (h[k] - want[k]).abs() < 1e-8 * (1.0 + want[k].abs()),
                        "{m}x{n} mu={mu}: {h:?} vs {want:?}"
                    );
                }
                let w: Vec<f64> = (0..n).map(|k| 0.5 + k as f64).collect();
                let q = qr.inverse_quadratic(&jac, &w).unwrap();
                let q_ref = quad_reference(&j, mu, &d, &w);
                assert!(
                    (q - q_ref).abs() < 1e-8 * q_ref,
                    "{m}x{n} mu={mu}: {q} vs {q_ref}"
                );
            }
        }
    }

    #[test]
    fn rank_deficient_jacobian_is_handled() {
        // Two identical columns and a zero column.
        let j = Mat::<f64>::from_fn(5, 3, |i, k| if k == 2 { 0.0 } else { i as f64 + 1.0 });
        let r = [1.0, 0.0, -1.0, 2.0, 0.5];
        let mut qr = DenseQr::new(5, 3);
        let jac = Jacobian::Dense(j.clone());
        qr.prepare(&jac, &r).unwrap();
        let mut h = vec![0.0; 3];
        assert!(qr.solve(&jac, 1e-3, &[1.0, 1.0, 1.0], &[], &mut h));
        let want = reference(&j, &r, 1e-3, &[1.0, 1.0, 1.0]);
        for k in 0..3 {
            assert!((h[k] - want[k]).abs() < 1e-8);
        }
    }
}
