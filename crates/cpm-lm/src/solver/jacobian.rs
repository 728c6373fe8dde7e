//! Jacobian storage shared by the linear solvers: a dense column-major faer matrix, or a
//! fixed compressed-sparse-row structure.
//!
//! The sparse form is kept lean because it is what large problems hold for the whole solve:
//! row pointers, `u32` column indices (sorted and unique within each row) and the values.
//! When the user's pattern is already in that order (rows ascending, columns strictly
//! ascending within a row, as a pattern built row by row usually is), the user writes the
//! values straight into the storage and no map is kept; otherwise a map from pattern entries
//! to storage positions (`u32` where it fits) and a buffer for the values in the user's order
//! are kept. A column-wise index is only built by the solvers that need one.

use faer::Mat;

use crate::error::LmError;
use crate::solver::small;

/// A sparse Jacobian with a fixed structure in compressed-sparse-row (CSR) order.
#[derive(Clone, Debug)]
pub(crate) struct SparseJac {
    pub nrows: usize,
    pub ncols: usize,
    /// CSR row pointers (`nrows + 1`).
    pub row_ptr: Vec<usize>,
    /// Column of each entry, sorted and unique within each row.
    pub row_col: Vec<u32>,
    /// Values, in CSR order.
    pub values: Vec<f64>,
}

/// Where each entry of the user's pattern lives in [`SparseJac::values`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum ValueMap {
    /// The pattern is in CSR order without duplicates: entry `k` is stored at `k`.
    Identity,
    /// Entry `k` is stored at `map[k]` (duplicates share a position and are summed).
    Small(Vec<u32>),
    /// As `Small`, for patterns with more than `u32::MAX` entries.
    Large(Vec<usize>),
}

impl ValueMap {
    /// `dst = 0`, then `dst[map[k]] += src[k]`. Not used for [`ValueMap::Identity`].
    pub(crate) fn scatter(&self, src: &[f64], dst: &mut [f64]) {
        match self {
            ValueMap::Identity => dst.copy_from_slice(src),
            ValueMap::Small(map) => {
                dst.fill(0.0);
                for (&p, &v) in map.iter().zip(src) {
                    dst[p as usize] += v;
                }
            }
            ValueMap::Large(map) => {
                dst.fill(0.0);
                for (&p, &v) in map.iter().zip(src) {
                    dst[p] += v;
                }
            }
        }
    }
}

fn column_index(col: usize, ncols: usize) -> Result<u32, LmError> {
    u32::try_from(col).map_err(|_| {
        LmError::InvalidOptions(format!(
            "sparse Jacobians support at most {} parameters, the problem has {ncols}",
            u32::MAX
        ))
    })
}

impl SparseJac {
    /// Builds the structure of a user pattern and the map from pattern entries to storage
    /// positions. Linear time apart from sorting rows that are not already sorted; a
    /// pattern in CSR order is copied once and needs no map.
    #[cfg(test)]
    pub(crate) fn from_pattern(
        nrows: usize,
        ncols: usize,
        pattern: &[(usize, usize)],
    ) -> Result<(Self, ValueMap), LmError> {
        let mut builder = PatternBuilder::new(nrows, ncols)?;
        for &(r, c) in pattern {
            builder.push(r, c);
        }
        builder.finish()
    }

    /// The general case of [`Self::from_pattern`]: rows in any order, columns in any order
    /// and duplicates (all entries already checked to lie inside the matrix).
    fn from_unordered(nrows: usize, ncols: usize, pattern: &[(usize, usize)]) -> (Self, ValueMap) {
        let mut row_ptr = vec![0usize; nrows + 1];
        for &(r, _) in pattern {
            row_ptr[r + 1] += 1;
        }
        for r in 0..nrows {
            row_ptr[r + 1] += row_ptr[r];
        }
        // Bucket the pattern entries by row (stable), sort each row by column and merge
        // duplicates; `order` holds pattern indices, later reused for the map.
        let nnz_in = pattern.len();
        let small = u32::try_from(nnz_in).is_ok();
        let mut next = row_ptr.clone();
        let mut order: Vec<usize> = vec![0; nnz_in];
        for (k, &(r, _)) in pattern.iter().enumerate() {
            order[next[r]] = k;
            next[r] += 1;
        }
        drop(next);
        let mut new_ptr = vec![0usize; nrows + 1];
        let mut row_col: Vec<u32> = Vec::with_capacity(nnz_in);
        let mut map_small: Vec<u32> = if small { vec![0; nnz_in] } else { Vec::new() };
        let mut map_large: Vec<usize> = if small { Vec::new() } else { vec![0; nnz_in] };
        for r in 0..nrows {
            let seg = &mut order[row_ptr[r]..row_ptr[r + 1]];
            if !seg.windows(2).all(|w| pattern[w[0]].1 < pattern[w[1]].1) {
                seg.sort_by_key(|&k| pattern[k].1);
            }
            let mut last = usize::MAX;
            for &k in seg.iter() {
                let c = pattern[k].1;
                if c != last {
                    row_col.push(c as u32);
                    last = c;
                }
                let pos = row_col.len() - 1;
                if small {
                    map_small[k] = pos as u32;
                } else {
                    map_large[k] = pos;
                }
            }
            new_ptr[r + 1] = row_col.len();
        }
        drop(order);
        row_col.shrink_to_fit();
        let nnz = row_col.len();
        let jac = Self {
            nrows,
            ncols,
            row_ptr: new_ptr,
            row_col,
            values: vec![0.0; nnz],
        };
        let map = if small {
            ValueMap::Small(map_small)
        } else {
            ValueMap::Large(map_large)
        };
        (jac, map)
    }

    /// The fully dense structure (every entry present, row-major order).
    pub(crate) fn full(nrows: usize, ncols: usize) -> Result<Self, LmError> {
        if ncols > 0 {
            column_index(ncols - 1, ncols)?;
        }
        let row_ptr = (0..=nrows).map(|r| r * ncols).collect();
        let row_col = (0..nrows).flat_map(|_| 0..ncols as u32).collect();
        Ok(Self {
            nrows,
            ncols,
            row_ptr,
            row_col,
            values: vec![0.0; nrows * ncols],
        })
    }

    /// The entries of row `i`: columns and values.
    #[inline]
    pub(crate) fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let range = self.row_ptr[i]..self.row_ptr[i + 1];
        (&self.row_col[range.clone()], &self.values[range])
    }

    /// Writes the values into the dense `m x n` matrix `dst` (zeroed first).
    pub(crate) fn scatter_dense(&self, dst: &mut Mat<f64>) {
        dst.fill(0.0);
        for r in 0..self.nrows {
            let (cols, vals) = self.row(r);
            for (&c, &v) in cols.iter().zip(vals) {
                dst[(r, c as usize)] = v;
            }
        }
    }
}

/// Builds the CSR structure from pattern entries arriving one at a time, in one pass.
///
/// Entries in CSR order (rows ascending, columns strictly ascending within a row) go
/// straight into the structure, so a problem that streams its pattern
/// ([`SparseJacobian::visit_pattern`](crate::SparseJacobian::visit_pattern)) is never held
/// as a list. At the first entry out of that order the entries so far are turned back into
/// a list, the rest is appended, and the general construction (sorting, duplicates, a map)
/// takes over at the end.
pub(crate) struct PatternBuilder {
    nrows: usize,
    ncols: usize,
    /// Entries seen.
    count: usize,
    row_ptr: Vec<usize>,
    row_col: Vec<u32>,
    /// Row of the last entry in order, and its column.
    row: usize,
    col: Option<usize>,
    /// The entries as a list, once they came out of order.
    list: Option<Vec<(usize, usize)>>,
    error: Option<LmError>,
}

impl PatternBuilder {
    pub(crate) fn new(nrows: usize, ncols: usize) -> Result<Self, LmError> {
        if ncols > 0 {
            column_index(ncols - 1, ncols)?;
        }
        Ok(Self {
            nrows,
            ncols,
            count: 0,
            row_ptr: vec![0; nrows + 1],
            row_col: Vec::new(),
            row: 0,
            col: None,
            list: None,
            error: None,
        })
    }

    /// Adds the next pattern entry.
    pub(crate) fn push(&mut self, row: usize, col: usize) {
        let index = self.count;
        self.count += 1;
        if self.error.is_some() {
            return;
        }
        if row >= self.nrows || col >= self.ncols {
            self.error = Some(LmError::PatternOutOfBounds {
                index,
                row,
                col,
                nrows: self.nrows,
                ncols: self.ncols,
            });
            return;
        }
        if let Some(list) = &mut self.list {
            list.push((row, col));
            return;
        }
        if row > self.row {
            let len = self.row_col.len();
            self.row_ptr[self.row + 1..=row].fill(len);
            self.row = row;
        } else if row < self.row || self.col.is_some_and(|c| col <= c) {
            self.spill_to_list();
            if let Some(list) = &mut self.list {
                list.push((row, col));
            }
            return;
        }
        self.row_col.push(col as u32);
        self.col = Some(col);
    }

    /// Turns the entries so far (in CSR order) into a list.
    fn spill_to_list(&mut self) {
        let mut list = Vec::with_capacity(self.row_col.len() * 2);
        let len = self.row_col.len();
        self.row_ptr[self.row + 1] = len;
        for r in 0..=self.row {
            for q in self.row_ptr[r]..self.row_ptr[r + 1] {
                list.push((r, self.row_col[q] as usize));
            }
        }
        self.row_col = Vec::new();
        self.list = Some(list);
    }

    /// The structure and the map from entries to storage positions.
    pub(crate) fn finish(mut self) -> Result<(SparseJac, ValueMap), LmError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if let Some(list) = self.list.take() {
            return Ok(SparseJac::from_unordered(self.nrows, self.ncols, &list));
        }
        let len = self.row_col.len();
        self.row_ptr[self.row + 1..].fill(len);
        self.row_col.shrink_to_fit();
        let jac = SparseJac {
            nrows: self.nrows,
            ncols: self.ncols,
            row_ptr: self.row_ptr,
            row_col: self.row_col,
            values: vec![0.0; len],
        };
        Ok((jac, ValueMap::Identity))
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
                for (v, &c) in s.values.iter_mut().zip(&s.row_col) {
                    if frozen[c as usize] {
                        *v = 0.0;
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
                    g[c] = small::dot(col, r);
                    norms2[c] = small::norm2(col);
                }
            }
            Jacobian::Sparse(sp) => {
                g.fill(0.0);
                norms2.fill(0.0);
                for (i, &ri) in r.iter().enumerate().take(sp.nrows) {
                    let (cols, vals) = sp.row(i);
                    for (&c, &v) in cols.iter().zip(vals) {
                        g[c as usize] += v * ri;
                        norms2[c as usize] += v * v;
                    }
                }
            }
        }
    }

    /// `||J h||^2`; `scratch` (length `m`) is used by the dense form only.
    pub(crate) fn product_norm2(&self, h: &[f64], scratch: &mut [f64]) -> f64 {
        match self {
            Jacobian::Dense(_) => {
                self.mul(h, scratch);
                small::norm2(scratch)
            }
            Jacobian::Sparse(s) => (0..s.nrows)
                .map(|i| {
                    let (cols, vals) = s.row(i);
                    let v: f64 = cols
                        .iter()
                        .zip(vals)
                        .map(|(&c, &v)| v * h[c as usize])
                        .sum();
                    v * v
                })
                .sum(),
        }
    }

    /// `out = J^T v`.
    pub(crate) fn transpose_mul(&self, v: &[f64], out: &mut [f64]) {
        match self {
            Jacobian::Dense(j) => {
                for (c, o) in out.iter_mut().enumerate().take(j.ncols()) {
                    *o = small::dot(j.col_as_slice(c), v);
                }
            }
            Jacobian::Sparse(sp) => {
                out.fill(0.0);
                for (i, &vi) in v.iter().enumerate().take(sp.nrows) {
                    let (cols, vals) = sp.row(i);
                    for (&c, &a) in cols.iter().zip(vals) {
                        out[c as usize] += a * vi;
                    }
                }
            }
        }
    }

    /// `out = J h`.
    pub(crate) fn mul(&self, h: &[f64], out: &mut [f64]) {
        match self {
            Jacobian::Dense(j) => {
                out.fill(0.0);
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
                    let (cols, vals) = s.row(i);
                    *o = cols
                        .iter()
                        .zip(vals)
                        .map(|(&c, &v)| v * h[c as usize])
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
                s.scatter_dense(&mut d);
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
        assert_eq!(map, ValueMap::Small(vec![3, 0, 2, 3, 1]));
        let mut dst = vec![9.0; 4];
        map.scatter(&[1.0, 2.0, 3.0, 4.0, 5.0], &mut dst);
        assert_eq!(dst, vec![2.0, 5.0, 3.0, 5.0]);
        assert!(SparseJac::from_pattern(3, 3, &[(3, 0)]).is_err());
    }

    #[test]
    fn pattern_in_csr_order_needs_no_map() {
        let pat = [(0, 0), (0, 2), (2, 1), (2, 2)];
        let (s, map) = SparseJac::from_pattern(3, 3, &pat).unwrap();
        assert_eq!(map, ValueMap::Identity);
        assert_eq!(s.row_ptr, vec![0, 2, 2, 4]);
        assert_eq!(s.row_col, vec![0, 2, 1, 2]);
        // A repeated column, a descending column or a descending row needs the map.
        for pat in [
            vec![(0, 0), (0, 0)],
            vec![(0, 1), (0, 0)],
            vec![(1, 0), (0, 0)],
        ] {
            let (_, map) = SparseJac::from_pattern(2, 2, &pat).unwrap();
            assert_ne!(map, ValueMap::Identity, "{pat:?}");
        }
    }

    #[test]
    fn dense_and_sparse_products_agree() {
        let d = Mat::<f64>::from_fn(4, 3, |i, j| (i * 3 + j) as f64 - 4.0);
        let mut s = SparseJac::full(4, 3).unwrap();
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
        let mut scratch = [0.0; 4];
        let n2: f64 = a.iter().map(|v| v * v).sum();
        assert_eq!(jd.product_norm2(&h, &mut scratch), n2);
        assert_eq!(js.product_norm2(&h, &mut []), n2);
        let r = [1.0, 2.0, 3.0, 4.0];
        let (mut g1, mut g2, mut n1, mut n2) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        jd.gradient_and_norms(&r, &mut g1, &mut n1);
        js.gradient_and_norms(&r, &mut g2, &mut n2);
        assert_eq!((g1, n1), (g2, n2));
        assert_eq!(jd.to_dense(), js.to_dense());
    }
}
