//! Jacobian storage shared by the linear solvers: a dense column-major faer matrix, or a
//! fixed compressed-sparse-column structure (with a row-wise index for row operations).

use faer::Mat;

use crate::error::LmError;

/// A sparse Jacobian with a fixed structure: values in compressed-sparse-row (CSR) order,
/// plus a column-wise (CSC) index into them.
#[derive(Clone, Debug)]
pub(crate) struct SparseJac {
    pub nrows: usize,
    pub ncols: usize,
    /// CSR row pointers (`nrows + 1`).
    pub row_ptr: Vec<usize>,
    /// Column of each entry, sorted and unique within each row.
    pub row_col: Vec<usize>,
    /// Values, in CSR order.
    pub values: Vec<f64>,
    /// CSC column pointers (`ncols + 1`) into `col_row` / `col_src`.
    pub col_ptr: Vec<usize>,
    /// Row of each CSC entry (sorted within a column).
    pub col_row: Vec<usize>,
    /// Position in `values` of each CSC entry.
    pub col_src: Vec<usize>,
}

impl SparseJac {
    /// Builds the structure of a user pattern; also returns, for each pattern entry, its
    /// position in `values` (duplicates share a position and are summed). Linear time;
    /// a pattern listed row by row needs no sorting at all.
    pub(crate) fn from_pattern(
        nrows: usize,
        ncols: usize,
        pattern: &[(usize, usize)],
    ) -> Result<(Self, Vec<usize>), LmError> {
        for (index, &(row, col)) in pattern.iter().enumerate() {
            if row >= nrows || col >= ncols {
                return Err(LmError::PatternOutOfBounds {
                    index,
                    row,
                    col,
                    nrows,
                    ncols,
                });
            }
        }
        // Bucket the entries by row (sequential reads of the pattern), then sort each row
        // by column if needed and merge duplicates.
        let mut count = vec![0usize; nrows + 1];
        for &(r, _) in pattern {
            count[r + 1] += 1;
        }
        for r in 0..nrows {
            count[r + 1] += count[r];
        }
        let mut next = count.clone();
        let mut bucket: Vec<(usize, usize)> = vec![(0, 0); pattern.len()];
        for (k, &(r, c)) in pattern.iter().enumerate() {
            bucket[next[r]] = (c, k);
            next[r] += 1;
        }
        drop(next);
        let mut row_ptr = vec![0usize; nrows + 1];
        let mut row_col = Vec::with_capacity(pattern.len());
        let mut user_to_csr = vec![0usize; pattern.len()];
        for r in 0..nrows {
            let seg = &mut bucket[count[r]..count[r + 1]];
            if !seg.windows(2).all(|w| w[0].0 < w[1].0) {
                seg.sort_unstable();
            }
            let mut last = usize::MAX;
            for &(c, k) in seg.iter() {
                if c != last {
                    row_col.push(c);
                    last = c;
                }
                user_to_csr[k] = row_col.len() - 1;
            }
            row_ptr[r + 1] = row_col.len();
        }
        let nnz = row_col.len();
        let mut jac = Self {
            nrows,
            ncols,
            row_ptr,
            row_col,
            values: vec![0.0; nnz],
            col_ptr: Vec::new(),
            col_row: Vec::new(),
            col_src: Vec::new(),
        };
        jac.build_cols();
        Ok((jac, user_to_csr))
    }

    /// The fully dense structure (every entry present, row-major order).
    pub(crate) fn full(nrows: usize, ncols: usize) -> Self {
        let row_ptr = (0..=nrows).map(|r| r * ncols).collect();
        let row_col = (0..nrows).flat_map(|_| 0..ncols).collect();
        let mut jac = Self {
            nrows,
            ncols,
            row_ptr,
            row_col,
            values: vec![0.0; nrows * ncols],
            col_ptr: Vec::new(),
            col_row: Vec::new(),
            col_src: Vec::new(),
        };
        jac.build_cols();
        jac
    }

    fn build_cols(&mut self) {
        let mut col_ptr = vec![0usize; self.ncols + 1];
        for &c in &self.row_col {
            col_ptr[c + 1] += 1;
        }
        for c in 0..self.ncols {
            col_ptr[c + 1] += col_ptr[c];
        }
        let nnz = self.row_col.len();
        let mut next = col_ptr.clone();
        let mut col_row = vec![0usize; nnz];
        let mut col_src = vec![0usize; nnz];
        for r in 0..self.nrows {
            for q in self.row_ptr[r]..self.row_ptr[r + 1] {
                let c = self.row_col[q];
                let p = next[c];
                col_row[p] = r;
                col_src[p] = q;
                next[c] += 1;
            }
        }
        self.col_ptr = col_ptr;
        self.col_row = col_row;
        self.col_src = col_src;
    }
}

/// The Jacobian in the form a linear solver wants.
#[derive(Clone, Debug)]
pub(crate) enum Jacobian {
    Dense(Mat<f64>),
    Sparse(SparseJac),
}

impl Jacobian {
    pub(crate) fn is_finite(&self) -> bool {
        match self {
            Jacobian::Dense(j) => {
                (0..j.ncols()).all(|c| j.col_as_slice(c).iter().all(|v| v.is_finite()))
            }
            Jacobian::Sparse(s) => s.values.iter().all(|v| v.is_finite()),
        }
    }

    /// Multiplies row `i` by `w[i]`.
    pub(crate) fn scale_rows(&mut self, w: &[f64]) {
        match self {
            Jacobian::Dense(j) => {
                for c in 0..j.ncols() {
                    for (v, s) in j.col_as_slice_mut(c).iter_mut().zip(w) {
                        *v *= s;
                    }
                }
            }
            Jacobian::Sparse(s) => {
                for r in 0..s.nrows {
                    for v in &mut s.values[s.row_ptr[r]..s.row_ptr[r + 1]] {
                        *v *= w[r];
                    }
                }
            }
        }
    }

    /// Zeroes the columns flagged in `frozen`.
    pub(crate) fn zero_cols(&mut self, frozen: &[bool]) {
        match self {
            Jacobian::Dense(j) => {
                for c in 0..j.ncols() {
                    if frozen[c] {
                        j.col_as_slice_mut(c).fill(0.0);
                    }
                }
            }
            Jacobian::Sparse(s) => {
                for c in 0..s.ncols {
                    if frozen[c] {
                        for p in s.col_ptr[c]..s.col_ptr[c + 1] {
                            s.values[s.col_src[p]] = 0.0;
                        }
                    }
                }
            }
        }
    }

    /// `g = J^T r` and `norms2[j] = ||J e_j||^2`.
    pub(crate) fn gradient_and_norms(&self, r: &[f64], g: &mut [f64], norms2: &mut [f64]) {
        match self {
            Jacobian::Dense(j) => {
                for c in 0..j.ncols() {
                    let col = j.col_as_slice(c);
                    let mut s = 0.0;
                    let mut q = 0.0;
                    for (a, b) in col.iter().zip(r) {
                        s += a * b;
                        q += a * a;
                    }
                    g[c] = s;
                    norms2[c] = q;
                }
            }
            Jacobian::Sparse(sp) => {
                g.fill(0.0);
                norms2.fill(0.0);
                for i in 0..sp.nrows {
                    let ri = r[i];
                    let range = sp.row_ptr[i]..sp.row_ptr[i + 1];
                    for (&c, &v) in sp.row_col[range.clone()].iter().zip(&sp.values[range]) {
                        g[c] += v * ri;
                        norms2[c] += v * v;
                    }
                }
            }
        }
    }

    /// `out = J h`.
    pub(crate) fn mul(&self, h: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        match self {
            Jacobian::Dense(j) => {
                for c in 0..j.ncols() {
                    let hc = h[c];
                    if hc == 0.0 {
                        continue;
                    }
                    for (o, a) in out.iter_mut().zip(j.col_as_slice(c)) {
                        *o += a * hc;
                    }
                }
            }
            Jacobian::Sparse(s) => {
                for (i, o) in out.iter_mut().enumerate() {
                    let range = s.row_ptr[i]..s.row_ptr[i + 1];
                    *o = s.row_col[range.clone()]
                        .iter()
                        .zip(&s.values[range])
                        .map(|(&c, &v)| v * h[c])
                        .sum();
                }
            }
        }
    }

    /// A dense copy.
    pub(crate) fn to_dense(&self) -> Mat<f64> {
        match self {
            Jacobian::Dense(j) => j.clone(),
            Jacobian::Sparse(s) => {
                let mut d = Mat::<f64>::zeros(s.nrows, s.ncols);
                for r in 0..s.nrows {
                    for q in s.row_ptr[r]..s.row_ptr[r + 1] {
                        d[(r, s.row_col[q])] = s.values[q];
                    }
                }
                d
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_is_compressed_with_duplicates() {
        let pat = [(2, 1), (0, 0), (1, 1), (2, 1), (0, 2)];
        let (s, map) = SparseJac::from_pattern(3, 3, &pat).unwrap();
        assert_eq!(s.row_ptr, vec![0, 2, 3, 4]);
        assert_eq!(s.row_col, vec![0, 2, 1, 1]);
        assert_eq!(map, vec![3, 0, 2, 3, 1]);
        assert_eq!(s.col_ptr, vec![0, 1, 3, 4]);
        assert_eq!(s.col_row, vec![0, 1, 2, 0]);
        assert_eq!(s.col_src, vec![0, 2, 3, 1]);
        assert!(SparseJac::from_pattern(3, 3, &[(3, 0)]).is_err());
    }

    #[test]
    fn dense_and_sparse_products_agree() {
        let d = Mat::<f64>::from_fn(4, 3, |i, j| (i * 3 + j) as f64 - 4.0);
        let mut s = SparseJac::full(4, 3);
        for c in 0..3 {
            for i in 0..4 {
                s.values[i * 3 + c] = d[(i, c)];
            }
        }
        let (jd, js) = (Jacobian::Dense(d), Jacobian::Sparse(s));
        let h = [1.0, -2.0, 0.5];
        let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
        jd.mul(&h, &mut a);
        js.mul(&h, &mut b);
        assert_eq!(a, b);
        let r = [1.0, 2.0, 3.0, 4.0];
        let (mut g1, mut g2, mut n1, mut n2) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        jd.gradient_and_norms(&r, &mut g1, &mut n1);
        js.gradient_and_norms(&r, &mut g2, &mut n2);
        assert_eq!((g1, n1), (g2, n2));
        assert_eq!(jd.to_dense(), js.to_dense());
    }
}
