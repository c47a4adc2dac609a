//! faer's supernodal sparse Cholesky with the symbolic factorisation (AMD ordering and
//! elimination tree) re-used while the pattern stays the same.

use std::cell::RefCell;

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymmetricOrdering};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::csr::SymCsr;

/// Why the direct solve was not done.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CholeskyError {
    #[error("the symbolic Cholesky factorisation failed: {0}")]
    Symbolic(String),
    #[error("the Cholesky factor would take {bytes} bytes, more than the {limit} allowed")]
    FactorTooLarge { bytes: usize, limit: usize },
    #[error("the matrix is not numerically positive definite (a non-positive pivot)")]
    NotPositiveDefinite,
}

/// Indices are u32 (a system with more entries takes the CG): half the memory of usize for
/// the lower triangle, its cached copy and the symbolic factorisation (the solve is the fit's
/// memory peak at 10⁸ raster cells).
struct Cached {
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    symbolic: SymbolicCholesky<u32>,
}

thread_local! {
    /// The last symbolic factorisation of this thread (a fit's loop runs on one thread and
    /// solves a sequence of systems whose pattern often repeats).
    static SYMBOLIC: RefCell<Option<Cached>> = const { RefCell::new(None) };
}

/// The lower triangle of `a` in CSC: by symmetry column j of it is row j of the CSR from the
/// diagonal on (columns sorted, so the rows of each CSC column are sorted too). None when its
/// entries do not fit u32 indices.
fn lower_csc(a: &SymCsr) -> Option<(Vec<u32>, Vec<u32>, Vec<f64>)> {
    let (col_ptr, row_idx) = lower_pattern(&a.start, &a.cols)?;
    let mut vals = Vec::with_capacity(row_idx.len());
    for j in 0..a.n() {
        vals.extend((a.start[j]..a.start[j + 1]).filter(|&k| a.cols[k] as usize >= j).map(|k| a.vals[k]));
    }
    Some((col_ptr, row_idx, vals))
}

/// The lower triangle's pattern (CSC) of the symmetric pattern `start`, `cols`: [`lower_csc`]
/// without the values, all a symbolic factorisation needs; None when it does not fit u32
/// indices.
fn lower_pattern(start: &[usize], cols: &[u32]) -> Option<(Vec<u32>, Vec<u32>)> {
    let n = start.len().saturating_sub(1);
    if cols.len() > u32::MAX as usize {
        return None;
    }
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::with_capacity(cols.len() / 2 + n);
    col_ptr.push(0u32);
    for j in 0..n {
        row_idx.extend(cols[start[j]..start[j + 1]].iter().copied().filter(|&i| i as usize >= j));
        col_ptr.push(row_idx.len() as u32);
    }
    Some((col_ptr, row_idx))
}

/// A symbolic factorisation (AMD ordering and elimination structure) made ahead of the solve,
/// on any thread, from the pattern alone: the caller can build it while it assembles the
/// values, then [`install_symbolic`] it on the thread that solves.
pub struct Symbolic(Cached);

/// Whether this thread's cached symbolic factorisation is that of the pattern `start`, `cols`
/// (a [`SymCsr`]'s, both triangles).
pub fn symbolic_cached(start: &[usize], cols: &[u32]) -> bool {
    let Some((col_ptr, row_idx)) = lower_pattern(start, cols) else { return false };
    SYMBOLIC.with(|c| c.borrow().as_ref().is_some_and(|c| c.col_ptr == col_ptr && c.row_idx == row_idx))
}

/// Drops this thread's cached symbolic factorisation (before one for another pattern is built:
/// two would be held at once otherwise).
pub fn clear_symbolic() {
    SYMBOLIC.with(|c| *c.borrow_mut() = None);
}

/// The symbolic factorisation of the pattern `start`, `cols` (a [`SymCsr`]'s): what
/// [`cholesky_solve`] computes when its thread's cache has another pattern; the same ordering
/// and structure, so the factor and the answer are the same bits either way.
pub fn cholesky_symbolic(start: &[usize], cols: &[u32]) -> Result<Symbolic, CholeskyError> {
    let n = start.len().saturating_sub(1);
    let Some((col_ptr, row_idx)) = lower_pattern(start, cols) else {
        return Err(CholeskyError::Symbolic("more entries than u32 indices address".into()));
    };
    let sym = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
    let symbolic = factorize_symbolic_cholesky(sym, Side::Lower, SymmetricOrdering::Amd, Default::default())
        .map_err(|e| CholeskyError::Symbolic(format!("{e:?}")))?;
    Ok(Symbolic(Cached { col_ptr, row_idx, symbolic }))
}

/// Makes `s` this thread's cached symbolic factorisation: the next [`cholesky_solve`] of a
/// matrix with its pattern re-uses it.
pub fn install_symbolic(s: Symbolic) {
    SYMBOLIC.with(|c| *c.borrow_mut() = Some(s.0));
}

/// Solves A x = b by Cholesky plus one step of iterative refinement; the bool says whether
/// the symbolic factorisation of this thread's previous call was re-used (same pattern,
/// compared exactly). A factor of more than `max_factor_bytes` is not built.
pub fn cholesky_solve(a: &SymCsr, b: &[f64], max_factor_bytes: usize) -> Result<(Vec<f64>, bool), CholeskyError> {
    let Some((col_ptr, row_idx, vals)) = lower_csc(a) else {
        return Err(CholeskyError::Symbolic("more entries than u32 indices address".into()));
    };
    SYMBOLIC
        .with(|cache| factor_and_solve(a, b, (&col_ptr, &row_idx, &vals), max_factor_bytes, &mut cache.borrow_mut()))
}

fn factor_and_solve(
    a: &SymCsr,
    b: &[f64],
    csc: (&[u32], &[u32], &[f64]),
    max_bytes: usize,
    cache: &mut Option<Cached>,
) -> Result<(Vec<f64>, bool), CholeskyError> {
    let n = a.n();
    let (col_ptr, row_idx, vals) = csc;
    let sym = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
    let mat = SparseColMatRef::new(sym, vals);
    let reused = cache.as_ref().is_some_and(|c| c.col_ptr == col_ptr && c.row_idx == row_idx);
    if !reused {
        let symbolic = factorize_symbolic_cholesky(sym, Side::Lower, SymmetricOrdering::Amd, Default::default())
            .map_err(|e| CholeskyError::Symbolic(format!("{e:?}")))?;
        *cache = Some(Cached { col_ptr: col_ptr.to_vec(), row_idx: row_idx.to_vec(), symbolic });
    }
    let Some(cached) = cache.as_ref() else { return Err(CholeskyError::Symbolic("no cached factorisation".into())) };
    let symbolic = &cached.symbolic;
    let bytes = symbolic.len_val().saturating_mul(8);
    if bytes > max_bytes {
        return Err(CholeskyError::FactorTooLarge { bytes, limit: max_bytes });
    }
    // Sequential: faer's parallel supernodal factorisation gives thread-count dependent last
    // bits (tests.rs `cholesky_bits_do_not_depend_on_the_thread_count`), which the crate's
    // promise of the same answer on any machine excludes; measured CPU-neutral on 2 cores
    // (BENCHMARKS.md "Fit CPU on the largest mesh").
    let par = Par::Seq;
    let scratch = StackReq::or(
        symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        symbolic.solve_in_place_scratch::<f64>(1, par),
    );
    WORKSPACE.with(|w| {
        let ws = &mut *w.borrow_mut();
        let (l, buf) = ws.get_or_insert_with(Workspace::default).fit(symbolic.len_val(), scratch);
        symbolic
            .factorize_numeric_llt::<f64>(
                l,
                mat,
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(buf),
                Default::default(),
            )
            .map_err(|_| CholeskyError::NotPositiveDefinite)?;
        let llt = LltRef::<'_, u32, f64>::new(symbolic, l);
        let mut solve = |v: &mut [f64]| {
            let m = MatMut::from_column_major_slice_mut(v, n, 1);
            llt.solve_in_place_with_conj(Conj::No, m, par, MemStack::new(buf));
        };
        let mut x = b.to_vec();
        solve(&mut x);
        // one refinement step: x += A⁻¹ (b − A x)
        let mut r = vec![0.0; n];
        a.mul(&x, &mut r);
        r.iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
        solve(&mut r);
        x.iter_mut().zip(&r).for_each(|(xi, di)| *xi += di);
        Ok((x, reused))
    })
}

/// The numeric factor's values and faer's scratch, kept between the solves of a thread.
/// Why: a fit solves a sequence of systems of similar size; allocated afresh, each factor
/// (~100 MB at 5·10⁴ cubic control points) came from new pages, and their first-touch page
/// faults were ~40 % of the BAG 0.1 m fit's, inside the numeric factorisation (0.19–0.20 →
/// 0.12–0.15 s per factor of 4.5·10⁴ unknowns; BENCHMARKS.md "Kept solver workspace, one final
/// check"). Callers short of memory drop it with [`release_workspace`].
#[derive(Default)]
struct Workspace {
    factor: Vec<f64>,
    scratch: Option<MemBuffer>,
}

impl Workspace {
    /// The factor's values (`len`; what they hold is overwritten: faer's numeric factorisation
    /// zeroes them itself, so zeroing them here too was a second pass over the factor per
    /// solve) and a scratch buffer that meets `req`, grown only when they are too small (the
    /// scratch: what was held is freed first, never two at once).
    ///
    /// The factor grows in place with a quarter to spare. Why: freed and allocated afresh, a
    /// grown factor faulted in all its pages again (the BAG at 0.1 m grows it from 10.2·10⁶ to
    /// 13.6·10⁶ values: ~0.07 s of faults on the fit's one thread). glibc moves a big block
    /// with `mremap`, so the pages already touched stay and only the new part faults; the
    /// spare quarter is address space, not memory, until a later factor writes it.
    fn fit(&mut self, len: usize, req: StackReq) -> (&mut [f64], &mut MemBuffer) {
        if len > self.factor.capacity() {
            let room = len + len / 4;
            self.factor.reserve_exact(room - self.factor.len());
        }
        self.factor.resize(len, 0.0);
        let fits = |b: &MemBuffer| {
            b.len() >= req.size_bytes() && (b.as_ptr() as usize).is_multiple_of(req.align_bytes().max(1))
        };
        if !self.scratch.as_ref().is_some_and(fits) {
            self.scratch = None;
            self.scratch = Some(MemBuffer::new(req));
        }
        (&mut self.factor, self.scratch.as_mut().expect("set above"))
    }
}

thread_local! {
    /// This thread's [`Workspace`] (None until its first factorisation, or after
    /// [`release_workspace`]).
    static WORKSPACE: RefCell<Option<Workspace>> = const { RefCell::new(None) };
}

/// Frees this thread's kept factor values and scratch (the symbolic factorisation stays):
/// for callers whose next steps need the memory more than the next solve needs the speed.
pub fn release_workspace() {
    WORKSPACE.with(|w| *w.borrow_mut() = None);
}
