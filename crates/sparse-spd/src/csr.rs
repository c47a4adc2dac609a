//! The symmetric sparse matrix both solvers take.

use rayon::prelude::*;

/// Sparse symmetric matrix in CSR with the full pattern (both triangles), columns of each row
/// sorted ascending. Why both triangles: the matrix–vector product of CG then runs row by row
/// in parallel without scatter, and the Cholesky reads its lower triangle as CSC for free.
#[derive(Debug, Clone, PartialEq)]
pub struct SymCsr {
    /// Row r holds entries `start[r]..start[r + 1]`; `start.len()` is n + 1.
    pub start: Vec<usize>,
    pub cols: Vec<u32>,
    pub vals: Vec<f64>,
}

impl Default for SymCsr {
    /// The 0 × 0 matrix.
    fn default() -> Self {
        SymCsr { start: vec![0], cols: Vec::new(), vals: Vec::new() }
    }
}

impl SymCsr {
    /// Number of rows (= columns).
    pub fn n(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.vals.len()
    }

    /// y = A x, rows in parallel, each row summed in column order (bit-identical on any
    /// thread count).
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        y.par_iter_mut().enumerate().with_min_len(1024).for_each(|(i, yi)| {
            let mut acc = 0.0;
            for k in self.start[i]..self.start[i + 1] {
                acc += self.vals[k] * x[self.cols[k] as usize];
            }
            *yi = acc;
        });
    }

    /// Index of entry (i, j) in `vals`; None when (i, j) is outside the pattern.
    pub fn find(&self, i: usize, j: u32) -> Option<usize> {
        let row = &self.cols[self.start[i]..self.start[i + 1]];
        row.binary_search(&j).ok().map(|k| self.start[i] + k)
    }

    /// The diagonal (0 where a diagonal entry is outside the pattern).
    pub fn diag(&self) -> Vec<f64> {
        (0..self.n()).map(|i| self.find(i, i as u32).map_or(0.0, |k| self.vals[k])).collect()
    }

    /// Σ `mats` + `shift`·I on the union of their patterns. Each entry is summed in the order
    /// of `mats`, the shift last (deterministic sums).
    pub fn sum(mats: &[&SymCsr], shift: f64) -> SymCsr {
        let n = mats.first().map_or(0, |m| m.n());
        let mut out = SymCsr { start: vec![0; n + 1], cols: Vec::new(), vals: Vec::new() };
        let mut acc: Vec<(u32, f64)> = Vec::new();
        for r in 0..n {
            acc.clear();
            for m in mats {
                acc.extend((m.start[r]..m.start[r + 1]).map(|k| (m.cols[k], m.vals[k])));
            }
            acc.push((r as u32, shift));
            acc.sort_by_key(|e| e.0); // stable: the order of `mats` within one column
            push_merged(&acc, &mut out);
            out.start[r + 1] = out.cols.len();
        }
        out
    }
}

/// Appends one row of column-sorted (column, value) pairs, equal columns summed in order.
fn push_merged(acc: &[(u32, f64)], out: &mut SymCsr) {
    let mut i = 0;
    while i < acc.len() {
        let c = acc[i].0;
        let mut s = 0.0;
        while i < acc.len() && acc[i].0 == c {
            s += acc[i].1;
            i += 1;
        }
        out.cols.push(c);
        out.vals.push(s);
    }
}

/// Dot product with a fixed summation order: chunks of `chunk` entries summed in parallel,
/// then the chunk sums in order, so identical input gives bit-identical iterates on any
/// thread count. The chunk is part of the result's last bits, which is why callers fix it.
pub fn det_dot(a: &[f64], b: &[f64], chunk: usize) -> f64 {
    let parts: Vec<f64> = a
        .par_chunks(chunk)
        .zip(b.par_chunks(chunk))
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>())
        .collect();
    parts.iter().sum()
}

/// The 1-D Laplacian tridiag(−1, 2 + shift, −1) of order n (test and example matrix).
pub fn laplacian_1d(n: usize, shift: f64) -> SymCsr {
    let mut a = SymCsr::default();
    for i in 0..n {
        if i > 0 {
            a.cols.push(i as u32 - 1);
            a.vals.push(-1.0);
        }
        a.cols.push(i as u32);
        a.vals.push(2.0 + shift);
        if i + 1 < n {
            a.cols.push(i as u32 + 1);
            a.vals.push(-1.0);
        }
        a.start.push(a.cols.len());
    }
    a
}
