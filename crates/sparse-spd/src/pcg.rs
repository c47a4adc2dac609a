//! Preconditioned conjugate gradients (Hestenes & Stiefel 1952) with a Jacobi or IC(0)
//! preconditioner; a solve that does not reach its tolerance is an error, never a silent
//! approximate answer.

use rayon::prelude::*;

use crate::csr::{det_dot, SymCsr};
use crate::NotConverged;

/// The summation chunk of the dot products when a caller has no reason to choose another.
pub const DEFAULT_DOT_CHUNK: usize = 4096;

/// What a CG solve aims at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcgOptions {
    /// Stopping rule: the iteration stops once the recurrence's ‖r‖ ≤ tol·‖b‖.
    pub tol: f64,
    /// Iteration cap.
    pub max_iter: usize,
    /// The true relative residual ‖b − A x‖/‖b‖ the answer must have to be returned (judged
    /// against `accept.max(tol)`); the recurrence's residual drifts from the true one, so the
    /// true one decides.
    pub accept: f64,
    /// Summation chunk of the dot products ([`det_dot`]): it fixes the last bits of every
    /// iterate, so a caller keeps the one its outputs were made with.
    pub dot_chunk: usize,
}

impl PcgOptions {
    /// Stop and accept at `tol`, at most `max_iter` iterations, default dot chunk.
    pub fn new(tol: f64, max_iter: usize) -> PcgOptions {
        PcgOptions { tol, max_iter, accept: tol, dot_chunk: DEFAULT_DOT_CHUNK }
    }
}

/// What one CG solve did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CgStats {
    pub iterations: usize,
    /// The recurrence's relative residual when the iteration stopped.
    pub residual: f64,
    /// ‖b − A x‖/‖b‖ of the returned x.
    pub true_residual: f64,
    /// The checkpoint's `go_on` said stop: the answer meets the checkpoint's loose tolerance.
    pub stopped_at_checkpoint: bool,
}

/// A look at the iterate when the residual first reaches `loose`·‖b‖: `go_on(x)` decides
/// whether to keep iterating to the tolerance within the same Krylov sequence (true) or to
/// stop there (false). Continuing instead of restarting keeps CG's superlinear phase.
pub struct Checkpoint<'a> {
    pub loose: f64,
    pub go_on: &'a mut dyn FnMut(&[f64]) -> bool,
}

/// M ≈ A whose inverse is cheap to apply.
pub enum Preconditioner {
    /// M = diag(A), stored as its inverse (1 where a diagonal entry is missing or zero).
    Jacobi(Vec<f64>),
    /// Incomplete Cholesky with A's own pattern.
    Ic0(Ic0),
}

impl Preconditioner {
    /// diag(A)⁻¹.
    pub fn jacobi(a: &SymCsr) -> Preconditioner {
        Preconditioner::Jacobi((0..a.n()).map(|i| a.find(i, i as u32).map_or(1.0, |k| 1.0 / a.vals[k])).collect())
    }
    /// IC(0) of A.
    pub fn ic0(a: &SymCsr) -> Preconditioner {
        Preconditioner::Ic0(Ic0::new(a))
    }
    /// z = M⁻¹ r.
    pub fn apply(&self, r: &[f64], z: &mut [f64]) {
        match self {
            Preconditioner::Jacobi(dinv) => z.par_iter_mut().zip(r).zip(dinv).for_each(|((zi, ri), d)| *zi = ri * d),
            Preconditioner::Ic0(ic) => ic.apply(r, z),
        }
    }
}

/// Diagonal shifts [`Ic0::new`] tries before it falls back to the diagonal of A.
pub const IC0_SHIFTS: usize = 30;

/// Incomplete Cholesky IC(0) factor: L with the pattern of A's lower triangle, A ≈ L·Lᵀ.
/// A non-positive pivot (A is not an M-matrix) restarts with a diagonal shift (Manteuffel).
pub struct Ic0 {
    ptr: Vec<usize>,
    idx: Vec<u32>,
    val: Vec<f64>,
}

impl Ic0 {
    pub fn new(a: &SymCsr) -> Ic0 {
        let n = a.n();
        let mut ptr = vec![0usize; n + 1];
        let mut idx = Vec::new();
        let mut base = Vec::new();
        for r in 0..n {
            for k in a.start[r]..a.start[r + 1] {
                if a.cols[k] as usize <= r {
                    idx.push(a.cols[k]);
                    base.push(a.vals[k]);
                }
            }
            ptr[r + 1] = idx.len();
        }
        // At most IC0_SHIFTS tries (a shift of 1e-3 up to 1e26): a matrix with a non-finite
        // entry never factors, and an unbounded `alpha *= 10` ran forever on one
        // (docs/decisions.md#crashes-and-hangs-of-issue-40). Beyond that, the diagonal.
        let mut alpha = 0.0;
        if base.iter().all(|v| v.is_finite()) {
            for _ in 0..IC0_SHIFTS {
                let mut val = base.clone();
                if factor_in_place(&ptr, &idx, &mut val, alpha) {
                    return Ic0 { ptr, idx, val };
                }
                alpha = if alpha == 0.0 { 1e-3 } else { alpha * 10.0 };
            }
        }
        let mut val = vec![0.0; base.len()];
        for i in 0..n {
            let d = base[ptr[i + 1] - 1];
            val[ptr[i + 1] - 1] = if d > 0.0 && d.is_finite() { d.sqrt() } else { 1.0 };
        }
        Ic0 { ptr, idx, val }
    }

    /// z = (L·Lᵀ)⁻¹ r.
    pub fn apply(&self, r: &[f64], z: &mut [f64]) {
        let n = r.len();
        for i in 0..n {
            let (s, e) = (self.ptr[i], self.ptr[i + 1]);
            let mut v = r[i];
            for k in s..e - 1 {
                v -= self.val[k] * z[self.idx[k] as usize];
            }
            z[i] = v / self.val[e - 1];
        }
        for i in (0..n).rev() {
            let (s, e) = (self.ptr[i], self.ptr[i + 1]);
            z[i] /= self.val[e - 1];
            let zi = z[i];
            for k in s..e - 1 {
                z[self.idx[k] as usize] -= self.val[k] * zi;
            }
        }
    }
}

/// The IC(0) elimination of the lower triangle (`ptr`, `idx`, `val`: rows, diagonal last) with
/// the diagonal scaled by 1 + `alpha`; false on a non-positive pivot.
fn factor_in_place(ptr: &[usize], idx: &[u32], val: &mut [f64], alpha: f64) -> bool {
    for i in 0..ptr.len() - 1 {
        let (s, e) = (ptr[i], ptr[i + 1]);
        if alpha > 0.0 {
            val[e - 1] *= 1.0 + alpha;
        }
        for kk in s..e {
            let k = idx[kk] as usize;
            // dot of rows i and k over columns j < k
            let (mut p, mut q) = (s, ptr[k]);
            let mut sum = 0.0;
            while p < kk && q < ptr[k + 1] - 1 {
                let (cp, cq) = (idx[p], idx[q]);
                if cp == cq {
                    sum += val[p] * val[q];
                    p += 1;
                    q += 1;
                } else if cp < cq {
                    p += 1;
                } else {
                    q += 1;
                }
            }
            if k == i {
                let d = val[kk] - sum;
                if !(d > 0.0) {
                    return false;
                }
                val[kk] = d.sqrt();
            } else {
                val[kk] = (val[kk] - sum) / val[ptr[k + 1] - 1];
            }
        }
    }
    true
}

/// Preconditioned conjugate gradients on A x = b from the start value in `x`; `x` holds the
/// last iterate either way. Err when the true relative residual misses `opts.accept.max(tol)`
/// (tol: the checkpoint's loose one where `go_on` stopped there). b = 0 gives x = 0.
pub fn pcg(
    a: &SymCsr,
    b: &[f64],
    x: &mut [f64],
    pre: &Preconditioner,
    opts: &PcgOptions,
    mut check: Option<Checkpoint<'_>>,
) -> Result<CgStats, NotConverged> {
    let n = b.len();
    let dot = |u: &[f64], v: &[f64]| det_dot(u, v, opts.dot_chunk);
    // Non-finite input is refused before the first iteration: no answer can come of it
    // (docs/decisions.md#crashes-and-hangs-of-issue-40).
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !(finite(&a.vals) && finite(b) && finite(x)) {
        return Err(NotConverged {
            method: "cg",
            n,
            iterations: 0,
            residual: f64::NAN,
            tol: opts.accept.max(opts.tol),
        });
    }
    let bn = dot(b, b).sqrt();
    if !bn.is_finite() {
        return Err(NotConverged {
            method: "cg",
            n,
            iterations: 0,
            residual: f64::NAN,
            tol: opts.accept.max(opts.tol),
        });
    }
    if bn == 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return Ok(CgStats::default());
    }
    let mut r = vec![0.0; n];
    a.mul(x, &mut r);
    r.par_iter_mut().zip(b.par_iter()).for_each(|(r, b)| *r = b - *r);
    let mut z = vec![0.0; n];
    pre.apply(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut q = vec![0.0; n];
    let mut res = dot(&r, &r).sqrt() / bn;
    let mut it = 0;
    let mut tol = opts.tol;
    let mut stopped_at_checkpoint = false;
    loop {
        if let Some(c) = check.as_mut() {
            if res <= c.loose {
                let cont = (c.go_on)(x);
                if !cont {
                    (tol, stopped_at_checkpoint) = (c.loose, true);
                    break;
                }
                check = None;
            }
        }
        if res <= tol || it >= opts.max_iter {
            break;
        }
        a.mul(&p, &mut q);
        let pq = dot(&p, &q);
        if !(pq > 0.0) {
            break;
        }
        let alpha = rz / pq;
        x.par_iter_mut().zip(p.par_iter()).for_each(|(x, p)| *x += alpha * p);
        r.par_iter_mut().zip(q.par_iter()).for_each(|(r, q)| *r -= alpha * q);
        pre.apply(&r, &mut z);
        let rz2 = dot(&r, &z);
        let beta = rz2 / rz;
        rz = rz2;
        p.par_iter_mut().zip(z.par_iter()).for_each(|(p, z)| *p = z + beta * *p);
        res = dot(&r, &r).sqrt() / bn;
        it += 1;
    }
    let true_residual = true_residual(a, b, x, bn, opts.dot_chunk);
    let limit = opts.accept.max(tol);
    if !(true_residual <= limit) {
        return Err(NotConverged { method: "cg", n, iterations: it, residual: true_residual, tol: limit });
    }
    Ok(CgStats { iterations: it, residual: res, true_residual, stopped_at_checkpoint })
}

/// ‖b − A x‖ / `bnorm`.
pub(crate) fn true_residual(a: &SymCsr, b: &[f64], x: &[f64], bnorm: f64, chunk: usize) -> f64 {
    let mut r = vec![0.0; b.len()];
    a.mul(x, &mut r);
    r.iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
    det_dot(&r, &r, chunk).sqrt() / bnorm
}
