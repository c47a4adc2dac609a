//! Sparse symmetric positive definite solves for the least-squares fit's normal equations
//! (issue 19: the solve dominated the fit once a mesh passed ~10⁴ control points).
//!
//! Why a direct factorisation: the normal equations of a T-spline fit have ~(2K+1)² entries
//! per row on a 2-D lattice, so a fill-reducing ordering (AMD) keeps the Cholesky factor near
//! O(n log n) and the factorisation is a fraction of a second at 10⁵ unknowns, while the
//! Jacobi-preconditioned conjugate gradients needed hundreds to thousands of iterations
//! (the system's condition grows with the mesh's spread of cell sizes). Measured side by side
//! in `benches/tspline_speed.sh` (BENCHMARKS.md, "T-spline speed").
//!
//! - [`solve_spd`]: faer's supernodal sparse Cholesky (the version `crates/adjust` uses), one
//!   step of iterative refinement, the relative residual reported; the symbolic factorisation
//!   (ordering + elimination tree) is re-used when the next system has the same pattern (the
//!   last one is cached per thread, compared exactly).
//! - A non-positive pivot (a system that is not numerically definite) or a factor larger than
//!   [`MAX_FACTOR_BYTES`] falls back to the warm-started Jacobi-preconditioned CG; a CG that
//!   does not reach its tolerance is an error naming the residual reached, never a silent
//!   approximate answer.
//! - `GEOFIT_TSPLINE_SOLVER=cg` selects the CG for measurements (benches); anything else or
//!   unset is the default (Cholesky).
//!
//! The module depends on nothing of the T-spline: `crates/implicit` could use it as it is.

use std::cell::RefCell;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymmetricOrdering};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use rayon::prelude::*;

/// Sparse symmetric matrix in CSR with the full pattern (both triangles), columns sorted.
#[derive(Debug, Clone)]
pub struct SymCsr {
    pub start: Vec<usize>,
    pub cols: Vec<u32>,
    pub vals: Vec<f64>,
}

impl SymCsr {
    pub fn n(&self) -> usize {
        self.start.len() - 1
    }
    /// y = A x (rows in parallel).
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
}

/// How a system was solved.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SolveInfo {
    /// "cholesky" or "cg".
    pub method: &'static str,
    /// CG iterations (0 for Cholesky).
    pub iterations: usize,
    /// ‖b − A x‖ / ‖b‖ of the returned x.
    pub relative_residual: f64,
    /// Whether the symbolic factorisation of the previous system was re-used.
    pub symbolic_reused: bool,
}

/// A solve that did not reach its tolerance.
#[derive(Debug, Clone, thiserror::Error)]
#[error("the {method} solve of {n} unknowns did not converge: relative residual {residual:e} after {iterations} iterations (tolerance {tol:e})")]
pub struct NotConverged {
    pub method: &'static str,
    pub n: usize,
    pub iterations: usize,
    pub residual: f64,
    pub tol: f64,
}

/// Relative residual a solve must reach (Cholesky after refinement; CG's stopping rule).
pub const TOLERANCE: f64 = 1e-13;
/// Largest Cholesky factor (bytes of its values) the direct path builds; bigger systems take
/// the PCG. Why: the factor's fill grows faster than the system (measured: +117 MiB of peak
/// for 3·10⁴ cubic control points on Kilauea 5 m), and at 10⁸ raster cells the per-cell
/// arrays already take most of the memory budget.
pub const MAX_FACTOR_BYTES: usize = 256 << 20;
/// Cholesky results with a residual up to this are accepted (the factorisation's rounding on
/// ill-conditioned systems); above it CG continues from the Cholesky solution.
const DIRECT_ACCEPT: f64 = 1e-10;

struct Cached {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
}

thread_local! {
    /// The last symbolic factorisation of this thread (the fit's loop runs on one thread).
    static SYMBOLIC: RefCell<Option<Cached>> = const { RefCell::new(None) };
}

fn use_cg_only() -> bool {
    std::env::var("GEOFIT_TSPLINE_SOLVER").is_ok_and(|v| v.eq_ignore_ascii_case("cg"))
}

/// Solves A x = b for a symmetric positive definite A; `x0` is the CG's warm start.
pub fn solve_spd(a: &SymCsr, b: &[f64], x0: &[f64]) -> Result<(Vec<f64>, SolveInfo), NotConverged> {
    let n = a.n();
    let bnorm = norm(b).max(1e-300);
    if !use_cg_only() {
        if let Some((x, reused)) = cholesky(a, b) {
            let res = residual(a, b, &x) / bnorm;
            if res <= DIRECT_ACCEPT {
                return Ok((x, SolveInfo { method: "cholesky", iterations: 0, relative_residual: res, symbolic_reused: reused }));
            }
            return cg(a, b, &x, TOLERANCE, 20 * n + 2000).map(|(x, mut info)| {
                info.symbolic_reused = reused;
                (x, info)
            });
        }
    }
    cg(a, b, x0, TOLERANCE, 20 * n + 2000)
}

fn norm(v: &[f64]) -> f64 {
    dot(v, v).sqrt()
}

fn residual(a: &SymCsr, b: &[f64], x: &[f64]) -> f64 {
    let mut r = vec![0.0; b.len()];
    a.mul(x, &mut r);
    r.iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
    norm(&r)
}

/// Cholesky with one step of iterative refinement; None on a non-positive pivot.
fn cholesky(a: &SymCsr, b: &[f64]) -> Option<(Vec<f64>, bool)> {
    let n = a.n();
    // The lower triangle in CSC: by symmetry column j of it is row j of the CSR from the
    // diagonal on (columns sorted, so the rows of the CSC column are sorted too).
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::with_capacity(a.cols.len() / 2 + n);
    let mut vals = Vec::with_capacity(a.cols.len() / 2 + n);
    col_ptr.push(0usize);
    for j in 0..n {
        for k in a.start[j]..a.start[j + 1] {
            let i = a.cols[k] as usize;
            if i >= j {
                row_idx.push(i);
                vals.push(a.vals[k]);
            }
        }
        col_ptr.push(row_idx.len());
    }
    SYMBOLIC.with(|cache| factor_and_solve(a, b, &col_ptr, &row_idx, &vals, &mut cache.borrow_mut()))
}

fn factor_and_solve(a: &SymCsr, b: &[f64], col_ptr: &[usize], row_idx: &[usize], vals: &[f64], cache: &mut Option<Cached>) -> Option<(Vec<f64>, bool)> {
    let n = a.n();
    let sym = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
    let mat = SparseColMatRef::new(sym, vals);
    let reused = cache.as_ref().is_some_and(|c| c.col_ptr == col_ptr && c.row_idx == row_idx);
    if !reused {
        let symbolic = factorize_symbolic_cholesky(sym, Side::Lower, SymmetricOrdering::Amd, Default::default()).ok()?;
        *cache = Some(Cached { col_ptr: col_ptr.to_vec(), row_idx: row_idx.to_vec(), symbolic });
    }
    let symbolic = &cache.as_ref()?.symbolic;
    if symbolic.len_val().saturating_mul(8) > MAX_FACTOR_BYTES {
        return None;
    }
    let par = if rayon::current_num_threads() > 1 { Par::rayon(0) } else { Par::Seq };
    let mut l = vec![0.0; symbolic.len_val()];
    let mut buf = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
    symbolic.factorize_numeric_llt::<f64>(&mut l, mat, Side::Lower, Default::default(), par, MemStack::new(&mut buf), Default::default()).ok()?;
    let llt = LltRef::<'_, usize, f64>::new(symbolic, &l);
    let mut sbuf = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(1, par));
    let mut solve = |v: &mut [f64]| {
        let m = MatMut::from_column_major_slice_mut(v, n, 1);
        llt.solve_in_place_with_conj(Conj::No, m, par, MemStack::new(&mut sbuf));
    };
    let mut x = b.to_vec();
    solve(&mut x);
    // one refinement step: x += A⁻¹ (b − A x)
    let mut r = vec![0.0; n];
    a.mul(&x, &mut r);
    r.iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
    solve(&mut r);
    x.iter_mut().zip(&r).for_each(|(xi, di)| *xi += di);
    Some((x, reused))
}

/// Dot product with a fixed summation order (deterministic under rayon).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let parts: Vec<f64> = a.par_chunks(8192).zip(b.par_chunks(8192)).map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>()).collect();
    parts.iter().sum()
}

/// Jacobi-preconditioned conjugate gradients from `x0`; Err when `tol` is not reached.
pub fn cg(a: &SymCsr, b: &[f64], x0: &[f64], tol: f64, max_iter: usize) -> Result<(Vec<f64>, SolveInfo), NotConverged> {
    let n = b.len();
    let dinv: Vec<f64> = (0..n).map(|i| a.find(i, i as u32).map_or(1.0, |k| 1.0 / a.vals[k])).collect();
    let mut x = x0.to_vec();
    let mut r = vec![0.0; n];
    a.mul(&x, &mut r);
    r.par_iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
    let bnorm = norm(b).max(1e-300);
    let mut z: Vec<f64> = r.iter().zip(&dinv).map(|(a, d)| a * d).collect();
    let mut p = z.clone();
    let mut rz: f64 = dot(&r, &z);
    let mut ap = vec![0.0; n];
    let mut it = 0;
    let mut rel = norm(&r) / bnorm;
    while rel > tol && it < max_iter {
        a.mul(&p, &mut ap);
        let pap: f64 = dot(&p, &ap);
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        x.par_iter_mut().zip(&p).for_each(|(xi, pi)| *xi += alpha * pi);
        r.par_iter_mut().zip(&ap).for_each(|(ri, api)| *ri -= alpha * api);
        z.par_iter_mut().zip(&r).zip(&dinv).for_each(|((zi, ri), d)| *zi = ri * d);
        let rz_new: f64 = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut().zip(&z).for_each(|(pi, zi)| *pi = zi + beta * *pi);
        it += 1;
        rel = norm(&r) / bnorm;
    }
    // the recurrence's residual drifts from the true one: judge the true one
    let true_rel = residual(a, b, &x) / bnorm;
    if !(true_rel <= tol.max(DIRECT_ACCEPT)) {
        return Err(NotConverged { method: "cg", n, iterations: it, residual: true_rel, tol });
    }
    Ok((x, SolveInfo { method: "cg", iterations: it, relative_residual: true_rel, symbolic_reused: false }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 2-D Laplacian plus a shift (SPD) on an m×m grid, full pattern.
    fn laplace(m: usize, shift: f64) -> SymCsr {
        let n = m * m;
        let mut start = vec![0];
        let (mut cols, mut vals) = (Vec::new(), Vec::new());
        for q in 0..n {
            let (i, j) = (q % m, q / m);
            let mut row = vec![(q as u32, 4.0 + shift)];
            if i > 0 {
                row.push(((q - 1) as u32, -1.0));
            }
            if i + 1 < m {
                row.push(((q + 1) as u32, -1.0));
            }
            if j > 0 {
                row.push(((q - m) as u32, -1.0));
            }
            if j + 1 < m {
                row.push(((q + m) as u32, -1.0));
            }
            row.sort_by_key(|e| e.0);
            for (c, v) in row {
                cols.push(c);
                vals.push(v);
            }
            start.push(cols.len());
        }
        SymCsr { start, cols, vals }
    }

    /// Cholesky and CG both solve a known system (x chosen, b = A x) to 1e-10, the second
    /// Cholesky of the same pattern re-uses the symbolic factorisation, and a CG with too few
    /// iterations says so instead of returning its approximation.
    #[test]
    fn direct_and_iterative_agree_with_the_truth() {
        let a = laplace(40, 0.01);
        let n = a.n();
        let truth: Vec<f64> = (0..n).map(|q| ((q * 7919) % 101) as f64 / 10.0 - 5.0).collect();
        let mut b = vec![0.0; n];
        a.mul(&truth, &mut b);
        let (x, info) = solve_spd(&a, &b, &vec![0.0; n]).unwrap();
        assert_eq!(info.method, "cholesky");
        assert!(x.iter().zip(&truth).all(|(p, q)| (p - q).abs() < 1e-10), "{info:?}");
        let mut a2 = a.clone();
        a2.vals.iter_mut().for_each(|v| *v *= 2.0);
        let (x2, info2) = solve_spd(&a2, &b, &vec![0.0; n]).unwrap();
        assert!(info2.symbolic_reused);
        assert!(x2.iter().zip(&truth).all(|(p, q)| (2.0 * p - q).abs() < 1e-10));
        let (xc, ic) = cg(&a, &b, &vec![0.0; n], TOLERANCE, 20 * n).unwrap();
        assert!(ic.iterations > 10);
        assert!(xc.iter().zip(&truth).all(|(p, q)| (p - q).abs() < 1e-8));
        let e = cg(&a, &b, &vec![0.0; n], TOLERANCE, 3).unwrap_err();
        assert_eq!(e.iterations, 3);
        assert!(e.residual > 1e-6 && e.to_string().contains("did not converge"), "{e}");
    }

    /// An indefinite matrix is not factorised: the CG fallback reports the failure.
    #[test]
    fn indefinite_systems_are_reported() {
        let mut a = laplace(10, 0.0);
        for k in a.start[5]..a.start[6] {
            if a.cols[k] == 5 {
                a.vals[k] = -50.0;
            }
        }
        let b = vec![1.0; a.n()];
        match solve_spd(&a, &b, &vec![0.0; a.n()]) {
            Err(e) => assert!(e.to_string().contains("did not converge")),
            Ok((x, info)) => {
                // CG may still solve an indefinite system; then the answer must be right
                let r = residual(&a, &b, &x) / norm(&b);
                assert!(r <= 1e-10, "{info:?}: residual {r}");
            }
        }
    }
}
