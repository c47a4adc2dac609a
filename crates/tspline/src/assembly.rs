//! The normal equations of the least-squares fit (`crate::fit`, A9): the upper triangle of
//! Σ bᵢ bⱼ, the right-hand side Σ bᵢ d and the column sums Σ bᵢ over the valid raster cells,
//! bᵢ = wᵢ Nᵢ / Σ w N the rational basis at the cell.
//!
//! Why per element (issue 19): cell by cell, the assembly located every cell through the bucket
//! grid, evaluated two basis functions for each of ~40 candidates and scattered 136 products
//! into the CSR — 76 % of a fit's CPU time (`perf`, Kilauea 20 m). On a Bézier element
//! (`crate::extraction`: a leaf cell cut by the knot lines inside it) every blending function
//! is a product of a factor in s and a factor in t, so [`by_elements`] evaluates each factor
//! once per cell column and once per cell row of the element, gathers the element's cells as
//! a dense matrix B (cells × functions), forms the local block BᵀB (upper triangle, in
//! register tiles), Bᵀd and the column sums, and scatters them into the CSR once per element.
//! Measured on Kilauea 20 m (BENCHMARKS.md, "Fit assembly per element"): the fit's CPU time
//! 10.1 → ~4 s.
//!
//! Same numbers as the cell-by-cell path ([`per_cell`], kept for scattered points and the
//! OpenCL rows) up to the order of the sums: each cell's b is computed with the same
//! operations in the same order (the element's functions sorted by parameter, as the bucket
//! lists are; tested bit for bit), and only the accumulation over cells differs (tested).
//! Cells whose basis the element path does not own go cell by cell ([`CellRows`]): cells on an
//! element edge flagged as an A1 border, and cells in no leaf half-open (upper borders, outside).
//!
//! Determinism: leaves are split into [`CHUNKS`] ranges (not the thread count), each summed
//! into its own copy of the system, merged in range order: the same bits on any machine.

use rayon::prelude::*;

use crate::eval::PbSpline;
use crate::extraction::{first_buckets, CellElements, BOTTOM_BORDER, LEFT_BORDER};
use crate::fit::{Region, Samples, Scattered};
use crate::sparse::SymCsr;
use crate::TsplineError;

/// Fixed number of partial systems summed in parallel (not the thread count: the summation
/// order, and so the output bytes, must not depend on the machine).
const CHUNKS: usize = 4;

/// Index of entry (i, j), which the pattern holds by construction (every overlapping pair).
#[inline]
pub(crate) fn entry(a: &SymCsr, i: usize, j: u32) -> usize {
    a.find(i, j).expect("pattern covers every overlapping pair")
}

/// Where the upper triangle (j ≥ i) of the pattern lies in a compact array: entry k of row i,
/// at or right of its diagonal, is at k − `lower[i]`, the count of entries left of the diagonal
/// in rows 0..=i. Why: each partial sum of the assembly ([`CHUNKS`] of them, summed in
/// parallel) held the whole pattern although only the upper triangle is ever added to — half
/// of it zeros, ~60 MB at 1.5·10⁵ control points
/// (docs/decisions.md#knots-only-through-the-solve).
pub(crate) struct Upper {
    lower: Vec<usize>,
    len: usize,
}

impl Upper {
    pub(crate) fn new(a: &SymCsr) -> Upper {
        let n = a.n();
        let mut lower = Vec::with_capacity(n);
        let mut acc = 0;
        for i in 0..n {
            acc += a.cols[a.start[i]..a.start[i + 1]].partition_point(|&j| (j as usize) < i);
            lower.push(acc);
        }
        Upper { lower, len: a.cols.len() - acc }
    }

    /// The compact position of entry (i, j), j ≥ i.
    #[inline]
    fn at(&self, a: &SymCsr, i: usize, j: u32) -> usize {
        entry(a, i, j) - self.lower[i]
    }

    /// Row `i` of the pattern from its diagonal on: its columns and the compact position of
    /// the diagonal.
    #[inline]
    fn row_from_diagonal<'p>(&self, a: &'p SymCsr, i: usize) -> (&'p [u32], usize) {
        let left = self.lower[i] - if i == 0 { 0 } else { self.lower[i - 1] };
        let d = a.start[i] + left;
        (&a.cols[d..a.start[i + 1]], d - self.lower[i])
    }

    /// `upper` in the pattern's layout (entries left of the diagonal 0), blocks of rows in
    /// parallel.
    fn expand(&self, a: &SymCsr, upper: &[f64]) -> Vec<f64> {
        const ROWS: usize = 4096;
        let mut full = vec![0.0; a.cols.len()];
        let mut blocks = Vec::with_capacity(a.n().div_ceil(ROWS));
        let mut rest = &mut full[..];
        for i0 in (0..a.n()).step_by(ROWS) {
            let i1 = (i0 + ROWS).min(a.n());
            let (block, tail) = rest.split_at_mut(a.start[i1] - a.start[i0]);
            blocks.push((i0, i1, block));
            rest = tail;
        }
        blocks.into_par_iter().for_each(|(i0, i1, block)| {
            for i in i0..i1 {
                let (cols, diag) = self.row_from_diagonal(a, i);
                let end = a.start[i + 1] - a.start[i0];
                block[end - cols.len()..end].copy_from_slice(&upper[diag..diag + cols.len()]);
            }
        });
        full
    }
}

/// Partial sums of the normal equations: `vals` the upper triangle, compact ([`Upper`]) while
/// the parts are summed, in the pattern's layout once merged.
pub(crate) struct Sums {
    pub vals: Vec<f64>,
    pub rhs: Vec<f64>,
    pub support: Vec<f64>,
}

impl Sums {
    fn zero(nnz: usize, n: usize) -> Sums {
        Sums { vals: vec![0.0; nnz], rhs: vec![0.0; n], support: vec![0.0; n] }
    }

    /// Partial sums merged in order, `vals` expanded to the pattern's layout.
    fn merged(parts: Vec<Sums>, upper: &Upper, pattern: &SymCsr) -> Sums {
        let mut it = parts.into_iter();
        let mut first = it.next().expect("at least one part");
        let rest: Vec<Sums> = it.collect();
        add_in_order(&mut first.vals, rest.iter().map(|r| &r.vals[..]));
        add_in_order(&mut first.rhs, rest.iter().map(|r| &r.rhs[..]));
        add_in_order(&mut first.support, rest.iter().map(|r| &r.support[..]));
        first.vals = upper.expand(pattern, &first.vals);
        first
    }
}

/// Adds `parts` to `dst` in order: each entry is ((dst + parts[0]) + parts[1]) + ..., the bits
/// of adding one part after another, in one pass over blocks of entries in parallel (three
/// passes one after another were ~10 ms of one thread per assembly on the BAG at 0.1 m, the
/// other idle).
fn add_in_order<'p>(dst: &mut [f64], parts: impl Iterator<Item = &'p [f64]>) {
    const BLOCK: usize = 1 << 14;
    let parts: Vec<&[f64]> = parts.collect();
    dst.par_chunks_mut(BLOCK).enumerate().for_each(|(b, d)| {
        for p in &parts {
            d.iter_mut().zip(&p[b * BLOCK..]).for_each(|(x, y)| *x += y);
        }
    });
}

/// What is being assembled: the pattern, the basis, which points are free (None: all) and the
/// current heights (a held point's term moves to the right-hand side with its height).
#[derive(Clone, Copy)]
pub(crate) struct System<'a> {
    pub pattern: &'a SymCsr,
    pub pb: &'a PbSpline,
    pub free: Option<&'a [bool]>,
    pub prior: &'a [f64],
}

impl System<'_> {
    #[inline]
    fn is_free(&self, i: usize) -> bool {
        self.free.is_none_or(|f| f[i])
    }

    fn zero_sums(&self, upper: &Upper) -> Sums {
        Sums::zero(upper.len, self.pb.knots.len())
    }
}

/// Cell-by-cell accumulation of basis rows into [`Sums`]: the reference path.
pub(crate) struct CellRows<'a> {
    sys: System<'a>,
    upper: &'a Upper,
    pub sums: Sums,
    scratch: Vec<(u32, f64)>,
    row: Vec<(u32, f64)>,
    // Neighbouring cells mostly see the same basis functions in the same order (same bucket,
    // same spans): their CSR positions are looked up once and reused.
    prev: Vec<u32>,
    pos: Vec<usize>,
}

impl<'a> CellRows<'a> {
    pub(crate) fn new(sys: System<'a>, upper: &'a Upper) -> CellRows<'a> {
        CellRows {
            sys,
            upper,
            sums: sys.zero_sums(upper),
            scratch: Vec::new(),
            row: Vec::with_capacity(32),
            prev: Vec::with_capacity(32),
            pos: Vec::with_capacity(32 * 33 / 2),
        }
    }

    /// The datum `d` at parameter (s, t), its basis through the PB-spline's bucket grid
    /// (nothing outside the domain).
    pub(crate) fn add_point(&mut self, s: f64, t: f64, d: f64) {
        if d.is_nan() {
            return;
        }
        self.row.clear();
        let row = &mut self.row;
        if self.sys.pb.for_each_basis(s, t, &mut self.scratch, |q, v| row.push((q, v))) {
            self.add_row(d);
        }
    }

    /// The datum `d` with its basis row given (PB indices and values; empty: outside).
    pub(crate) fn add_given(&mut self, ix: &[u32], v: &[f64], d: f64) {
        if d.is_nan() || ix.is_empty() {
            return;
        }
        self.row.clear();
        self.row.extend(ix.iter().copied().zip(v.iter().copied()));
        self.add_row(d);
    }

    /// Adds `self.row` with datum `d`: held points' terms go to the right-hand side, the upper
    /// triangle (by PB index) of the products into the CSR.
    fn add_row(&mut self, mut d: f64) {
        let sys = self.sys;
        if sys.free.is_some() {
            self.row.retain(|&(q, v)| {
                if sys.is_free(q as usize) {
                    true
                } else {
                    d -= v * sys.prior[q as usize];
                    false
                }
            });
        }
        let row = &self.row;
        let m = row.len();
        if !(m == self.prev.len() && row.iter().zip(&self.prev).all(|(r, &q)| r.0 == q)) {
            self.prev.clear();
            self.prev.extend(row.iter().map(|r| r.0));
            self.pos.clear();
            for x in 0..m {
                for y in x..m {
                    let (p, q) = (row[x].0.min(row[y].0), row[x].0.max(row[y].0));
                    self.pos.push(self.upper.at(sys.pattern, p as usize, q));
                }
            }
        }
        let s = &mut self.sums;
        let mut k = 0;
        for x in 0..m {
            let (p, vp) = row[x];
            s.rhs[p as usize] += vp * d;
            s.support[p as usize] += vp;
            for &(_, vq) in &row[x..] {
                s.vals[self.pos[k]] += vp * vq;
                k += 1;
            }
        }
    }
}

/// The cell-by-cell assembly: raster rows (of `region` only, when given), scattered points,
/// or raster rows with their basis rows from the OpenCL kernel (`asm`).
pub(crate) fn per_cell(
    sys: System<'_>,
    samples: &Samples,
    pts: Option<&Scattered>,
    region: Option<&Region>,
    asm: Option<(&crate::ocl_fit::OclModel, &crate::ocl_fit::OclModelSpline)>,
) -> Result<Sums, TsplineError> {
    let w = samples.width;
    let upper = Upper::new(sys.pattern);
    // units: raster rows, or the scattered points
    let units = pts.map_or(samples.height, |p| p.z.len());
    let chunk = units.div_ceil(CHUNKS).max(1);
    let parts: Vec<Sums> = (0..units.div_ceil(chunk))
        .into_par_iter()
        .map(|c| -> Result<Sums, TsplineError> {
            let (j0, j1) = (c * chunk, ((c + 1) * chunk).min(units));
            let mut rows = CellRows::new(sys, &upper);
            let raster =
                |rows: &mut CellRows, q: usize| rows.add_point((q % w) as f64, (q / w) as f64, samples.z.get(q));
            match (pts, region, asm) {
                (Some(p), _, _) => (j0..j1).for_each(|q| rows.add_point(p.st[q][0], p.st[q][1], p.z[q])),
                (None, Some(r), _) => r.for_rows(j0, j1, |q| raster(&mut rows, q)),
                (None, None, Some((o, sp))) => device_rows(&mut rows, samples, o, sp, j0, j1)?,
                (None, None, None) => (j0 * w..j1 * w).for_each(|q| raster(&mut rows, q)),
            }
            Ok(rows.sums)
        })
        .collect::<Result<_, _>>()?;
    Ok(Sums::merged(parts, &upper, sys.pattern))
}

/// Raster rows j0..j1 with the OpenCL kernel's basis rows (2^16 cells of ELL at a time).
fn device_rows(
    rows: &mut CellRows<'_>,
    samples: &Samples,
    o: &crate::ocl_fit::OclModel,
    sp: &crate::ocl_fit::OclModelSpline,
    j0: usize,
    j1: usize,
) -> Result<(), TsplineError> {
    let w = samples.width;
    let br = ((1usize << 16) / w.max(1)).max(1);
    let mut jb = j0;
    while jb < j1 {
        let nr = br.min(j1 - jb);
        let g = crate::eval::GridSpec { s0: 0.0, t0: jb as f64, ds: 1.0, dt: 1.0, ns: w, nt: nr };
        let t = o.model_rows(sp, &g)?;
        for r in 0..t.len() {
            let (ix, v) = t.row(r);
            rows.add_given(ix, v, samples.z.get(jb * w + r));
        }
        jb += nr;
    }
    Ok(())
}

/// One bit per raster cell: whether a leaf cell holds it half-open (set from several threads).
struct CellBits {
    w: usize,
    h: usize,
    words: Vec<std::sync::atomic::AtomicU64>,
}

impl CellBits {
    fn new(w: usize, h: usize) -> CellBits {
        CellBits { w, h, words: (0..(w * h).div_ceil(64)).map(|_| std::sync::atomic::AtomicU64::new(0)).collect() }
    }

    /// Marks the raster cells in the half-open rectangle [s0, s1) × [t0, t1).
    fn mark(&self, c: &[f64; 4]) {
        let (i0, i1) = half_open_range(c[0], c[2], self.w);
        let (j0, j1) = half_open_range(c[1], c[3], self.h);
        for j in j0..j1 {
            let (mut q, q1) = (j * self.w + i0, j * self.w + i1);
            while q < q1 {
                let n = (64 - q % 64).min(q1 - q);
                let bits = if n == 64 { u64::MAX } else { ((1u64 << n) - 1) << (q % 64) };
                self.words[q / 64].fetch_or(bits, std::sync::atomic::Ordering::Relaxed);
                q += n;
            }
        }
    }

    fn into_words(self) -> Vec<u64> {
        self.words.into_iter().map(|a| a.into_inner()).collect()
    }
}

/// The integers i with lo ≤ i < hi, clipped to 0..n, as a range (start, end).
#[inline]
fn half_open_range(lo: f64, hi: f64, n: usize) -> (usize, usize) {
    let a = lo.ceil().max(0.0).min(n as f64) as usize;
    let b = hi.ceil().max(0.0).min(n as f64) as usize;
    (a, b.max(a))
}

/// Leaves whose closed rectangle meets the closed support of a free point (all when every
/// point is free): the others hold no cell with a free basis function.
fn touched_leaves(pb: &PbSpline, free: Option<&[bool]>) -> Vec<u32> {
    let Some(free) = free else { return (0..pb.cells.len() as u32).collect() };
    let k = pb.degree.k();
    let mut hit = vec![false; pb.cells.len()];
    for i in (0..pb.knots.len()).filter(|&i| free[i]) {
        let kn = &pb.knots[i];
        let (i0, i1) = pb.grid.index_range(kn[0], kn[k + 1], true);
        let (j0, j1) = pb.grid.index_range(kn[5], kn[5 + k + 1], false);
        for bj in j0..=j1 {
            for bi in i0..=i1 {
                let b = (bj * pb.grid.ns + bi) as usize;
                for &ci in &pb.cell_items[pb.cell_start[b] as usize..pb.cell_start[b + 1] as usize] {
                    let c = &pb.cells[ci as usize];
                    if c[0] <= kn[k + 1] && kn[0] <= c[2] && c[1] <= kn[5 + k + 1] && kn[5] <= c[3] {
                        hit[ci as usize] = true;
                    }
                }
            }
        }
    }
    (0..pb.cells.len() as u32).filter(|&c| hit[c as usize]).collect()
}

/// The per-element assembly on a raster (module doc): every valid cell, or those of `region`.
pub(crate) fn by_elements(sys: System<'_>, samples: &Samples, region: Option<&Region>) -> Sums {
    let pb = sys.pb;
    let upper = Upper::new(sys.pattern);
    let first = first_buckets(pb, true);
    let leaves = touched_leaves(pb, sys.free);
    let covered = CellBits::new(samples.width, samples.height);
    pb.cells.par_iter().with_min_len(1024).for_each(|c| covered.mark(c));
    let chunk = leaves.len().div_ceil(CHUNKS).max(1);
    let mut parts: Vec<Sums> = leaves
        .par_chunks(chunk)
        .map(|ls| {
            let mut acc = Elements::new(sys, &upper, samples, region);
            for &ci in ls {
                acc.add_leaf(ci as usize, &first);
            }
            acc.rows.sums
        })
        .collect();
    // a part with no cell would only add zeros (and cost a pass over every entry)
    match uncovered_cells(sys, &upper, samples, region, &covered.into_words()) {
        Some(rest) => parts.push(rest),
        None if parts.is_empty() => parts.push(sys.zero_sums(&upper)),
        None => {}
    }
    Sums::merged(parts, &upper, sys.pattern)
}

/// The valid cells (of `region`) that no leaf holds half-open, cell by cell: upper borders of
/// the domain (A1) and cells outside it (which add nothing).
fn uncovered_cells(
    sys: System<'_>,
    upper: &Upper,
    samples: &Samples,
    region: Option<&Region>,
    covered: &[u64],
) -> Option<Sums> {
    let mut rows: Option<CellRows<'_>> = None;
    let w = samples.width;
    for (wi, &word) in covered.iter().enumerate() {
        if word == u64::MAX {
            continue;
        }
        for b in 0..64 {
            let q = wi * 64 + b;
            if q >= samples.z.len() {
                break;
            }
            if word & (1u64 << b) == 0 && region.is_none_or(|r| r.contains(q)) && !samples.z.get(q).is_nan() {
                rows.get_or_insert_with(|| CellRows::new(sys, upper)).add_point(
                    (q % w) as f64,
                    (q / w) as f64,
                    samples.z.get(q),
                );
            }
        }
    }
    rows.map(|r| r.sums)
}

/// Scratch and partial sums of the per-element path.
struct Elements<'a> {
    sys: System<'a>,
    samples: &'a Samples,
    region: Option<&'a Region>,
    rows: CellRows<'a>,
    el: CellElements,
    /// The current element's functions (PB indices, sorted by parameter (t, s)).
    funcs: Vec<u32>,
    /// w·N in s per function and cell column, N in t per function and cell row.
    ws: Vec<f64>,
    nt: Vec<f64>,
    /// The element's valid cells: basis values (cell-major, padded to a multiple of
    /// [`TILE`] with zeros) and data.
    b: Vec<f64>,
    d: Vec<f64>,
    /// The s factors by cell column (`ws` transposed), the t factors of the current cell row
    /// and Σ w N at its cells.
    ws_by_col: Vec<f64>,
    nt_row: Vec<f64>,
    den: Vec<f64>,
    /// The element's BᵀB (upper tiles) and its Bᵀd, column sums ([`moments`]).
    gram: Vec<f64>,
    moments: Vec<f64>,
    /// The element's free functions (positions in `funcs`) in PB order ([`Elements::scatter_products`]).
    by_index: Vec<usize>,
}

/// One basis factor on the span that holds an element (the knots strictly inside a leaf cut
/// it into elements, so every element lies in one span of each of its functions): the span's
/// piece found once per element instead of per cell, evaluated with `eval::basis_poly`'s
/// operations (same bits at every cell of the element).
struct SpanPiece<'p> {
    knot: f64,
    c: &'p [f64],
}

impl<'p> SpanPiece<'p> {
    /// The piece of the span [kn[j], kn[j+1]) holding `lo` (the element's lower edge).
    #[inline]
    fn at(kn: &[f64], pc: &'p [f64], k: usize, lo: f64) -> SpanPiece<'p> {
        let j = (0..=k).find(|&j| kn[j] <= lo && lo < kn[j + 1]).unwrap_or(k);
        SpanPiece { knot: kn[j], c: &pc[5 * j..5 * j + 5] }
    }

    #[inline]
    fn value(&self, u: f64) -> f64 {
        let (c, x) = (self.c, (u - self.knot) * self.c[0]);
        ((c[4] * x + c[3]) * x + c[2]) * x + c[1]
    }
}

/// Sorts PB indices by their points' parameters (t, then s) as the bucket lists are, so that
/// Σ w N over an element's functions is summed in the reference's order.
fn sort_by_parameter(pb: &PbSpline, ids: &mut [u32]) {
    let h = pb.degree.half();
    ids.sort_unstable_by(|&a, &b| {
        let (ka, kb) = (&pb.knots[a as usize], &pb.knots[b as usize]);
        ka[5 + h].total_cmp(&kb[5 + h]).then(ka[h].total_cmp(&kb[h]))
    });
}

/// An element [s0, s1) × [t0, t1) with its A1 border flags.
#[derive(Clone, Copy)]
struct Element {
    s0: f64,
    s1: f64,
    t0: f64,
    t1: f64,
    flags: u32,
}

impl<'a> Elements<'a> {
    fn new(sys: System<'a>, upper: &'a Upper, samples: &'a Samples, region: Option<&'a Region>) -> Elements<'a> {
        Elements {
            sys,
            samples,
            region,
            rows: CellRows::new(sys, upper),
            el: CellElements::default(),
            funcs: Vec::new(),
            ws: Vec::new(),
            nt: Vec::new(),
            b: Vec::new(),
            d: Vec::new(),
            ws_by_col: Vec::new(),
            nt_row: Vec::new(),
            den: Vec::new(),
            gram: Vec::new(),
            moments: Vec::new(),
            by_index: Vec::new(),
        }
    }

    /// Every element of leaf cell `ci`.
    fn add_leaf(&mut self, ci: usize, first: &[[u32; 2]]) {
        self.el.build(self.sys.pb, ci, first);
        sort_by_parameter(self.sys.pb, &mut self.el.cand);
        let (ns, nt) = (self.el.sb.len() - 1, self.el.tb.len() - 1);
        for jt in 0..nt {
            for is in 0..ns {
                let (sb, tb) = (&self.el.sb, &self.el.tb);
                let e =
                    Element { s0: sb[is], s1: sb[is + 1], t0: tb[jt], t1: tb[jt + 1], flags: self.el.flags(jt, is) };
                self.add_element(e);
            }
        }
    }

    /// The cells of one element (module doc).
    fn add_element(&mut self, e: Element) {
        let (i0, i1) = half_open_range(e.s0, e.s1, self.samples.width);
        let (j0, j1) = half_open_range(e.t0, e.t1, self.samples.height);
        if i0 == i1 || j0 == j1 || !self.select_functions(e) {
            return;
        }
        self.factor_tables(e, i0, i1, j0, j1);
        if self.gather_cells(e, i0, i1, j0, j1) > 0 {
            self.scatter_block();
        }
    }

    /// The leaf's functions whose support meets the element's interior, in the leaf's order
    /// ([`sort_by_parameter`]); false when none of them is free.
    fn select_functions(&mut self, e: Element) -> bool {
        let pb = self.sys.pb;
        let k = pb.degree.k();
        self.funcs.clear();
        self.funcs.extend(self.el.cand.iter().copied().filter(|&p| {
            let kn = &pb.knots[p as usize];
            kn[0] < e.s1 && kn[k + 1] > e.s0 && kn[5] < e.t1 && kn[5 + k + 1] > e.t0
        }));
        self.funcs.iter().any(|&p| self.sys.is_free(p as usize))
    }

    /// w·N(s) per function and cell column i0..i1, N(t) per function and cell row j0..j1
    /// (the reference's factors: same pieces, half-open spans).
    fn factor_tables(&mut self, e: Element, i0: usize, i1: usize, j0: usize, j1: usize) {
        let pb = self.sys.pb;
        let k = pb.degree.k();
        self.ws.clear();
        self.nt.clear();
        for &p in &self.funcs {
            let (kn, (ps, pt), w) = (&pb.knots[p as usize], pb.pieces(p as usize), pb.geom[p as usize][3]);
            let fs = SpanPiece::at(&kn[0..5], ps, k, e.s0);
            let ft = SpanPiece::at(&kn[5..10], pt, k, e.t0);
            self.ws.extend((i0..i1).map(|i| w * fs.value(i as f64)));
            self.nt.extend((j0..j1).map(|j| ft.value(j as f64)));
        }
        let (m, nc) = (self.funcs.len(), i1 - i0);
        self.ws_by_col.clear();
        self.ws_by_col.extend((0..nc * m).map(|q| self.ws[(q % m) * nc + q / m]));
    }

    /// Adds the element's valid cells (of the region) to its block sums, [`BATCH_CELLS`] rows
    /// of `b` and `d` at a time; cells on a flagged border edge go cell by cell. Returns the
    /// number of cells added.
    fn gather_cells(&mut self, e: Element, i0: usize, i1: usize, j0: usize, j1: usize) -> usize {
        let (nc, nr, m) = (i1 - i0, j1 - j0, self.funcs.len());
        let m4 = m.next_multiple_of(TILE);
        let w = self.samples.width;
        self.b.clear();
        self.d.clear();
        self.gram.clear();
        self.gram.resize(m4 * m4, 0.0);
        self.moments.clear();
        self.moments.resize(2 * m4, 0.0);
        let mut count = 0;
        for y in 0..nr {
            let j = j0 + y;
            self.row_denominators(nc, nr, y);
            for x in 0..nc {
                let i = i0 + x;
                let q = j * w + i;
                let d = self.samples.z.get(q);
                if d.is_nan() || self.region.is_some_and(|r| !r.contains(q)) {
                    continue;
                }
                if (e.flags & LEFT_BORDER != 0 && i as f64 == e.s0)
                    || (e.flags & BOTTOM_BORDER != 0 && j as f64 == e.t0)
                {
                    self.rows.add_point(i as f64, j as f64, d);
                    continue;
                }
                let den = self.den[x];
                if den == 0.0 {
                    continue; // as the reference: no basis there
                }
                let ws = &self.ws_by_col[x * m..x * m + m];
                self.b.extend(ws.iter().zip(&self.nt_row).map(|(a, b)| a * b / den));
                self.b.resize(self.b.len() + m4 - m, 0.0);
                self.d.push(d);
                if self.d.len() == BATCH_CELLS {
                    count += self.add_batch();
                }
            }
        }
        count + self.add_batch()
    }

    /// The gathered rows `b`, `d` into the element's BᵀB, Bᵀd and column sums, then emptied.
    /// The sums go on from where the previous batch left them, cell by cell in order: the
    /// same operations as one pass over all the element's cells, with `b` bounded (an element
    /// of the first iterations spans millions of cells: 40 B each for degree 1).
    fn add_batch(&mut self) -> usize {
        let m4 = self.funcs.len().next_multiple_of(TILE);
        gram_upper(&self.b, m4, &mut self.gram);
        moments(&self.b, m4, &self.d, &mut self.moments);
        let n = self.d.len();
        self.b.clear();
        self.d.clear();
        n
    }

    /// Σ w N at every cell of element row `y` into `den`, each summed over the functions in
    /// order (the reference's order; the cells side by side are independent chains), and the
    /// row's t factors into `nt_row`.
    fn row_denominators(&mut self, nc: usize, nr: usize, y: usize) {
        let m = self.funcs.len();
        self.den.clear();
        self.den.resize(nc, 0.0);
        self.nt_row.clear();
        for f in 0..m {
            let t = self.nt[f * nr + y];
            self.nt_row.push(t);
            for (dx, &a) in self.den.iter_mut().zip(&self.ws[f * nc..f * nc + nc]) {
                *dx += a * t;
            }
        }
    }

    /// The element's block BᵀB (upper triangle), Bᵀd and column sums into the partial sums;
    /// held points' products go to the right-hand side with their heights.
    fn scatter_block(&mut self) {
        let sys = self.sys;
        let m = self.funcs.len();
        let m4 = m.next_multiple_of(TILE);
        let s = &mut self.rows.sums;
        for x in 0..m {
            let px = self.funcs[x] as usize;
            let x_free = sys.is_free(px);
            if x_free {
                s.rhs[px] += self.moments[x];
                s.support[px] += self.moments[m4 + x];
            }
            if sys.free.is_none() {
                continue;
            }
            for y in x..m {
                let py = self.funcs[y] as usize;
                let v = self.gram[x * m4 + y];
                match (x_free, sys.is_free(py)) {
                    (true, false) => s.rhs[px] -= v * sys.prior[py],
                    (false, true) => s.rhs[py] -= v * sys.prior[px],
                    _ => {}
                }
            }
        }
        self.scatter_products(m4);
    }

    /// The free pairs' products into the upper triangle, row by row of the pattern: the
    /// element's free functions in PB order, so that each row's columns are met in order by
    /// one forward scan. Why: a binary search per product waited on each of its dependent
    /// loads, ~6 % of the BAG 0.1 m fit's CPU time (`perf`). Every entry still receives one
    /// addition per element: the same sums.
    fn scatter_products(&mut self, m4: usize) {
        let (sys, funcs) = (self.sys, &self.funcs);
        self.by_index.clear();
        self.by_index.extend((0..funcs.len()).filter(|&x| sys.is_free(funcs[x] as usize)));
        self.by_index.sort_unstable_by_key(|&x| funcs[x]);
        let vals = &mut self.rows.sums.vals;
        for (a, &x) in self.by_index.iter().enumerate() {
            let (cols, diag) = self.rows.upper.row_from_diagonal(sys.pattern, funcs[x] as usize);
            let mut k = 0;
            for &y in &self.by_index[a..] {
                k += cols[k..].iter().position(|&j| j == funcs[y]).expect("pattern covers every overlapping pair");
                vals[diag + k] += self.gram[x.min(y) * m4 + x.max(y)];
            }
        }
    }
}

/// Register tile of the element Gram matrix (functions are padded to a multiple of it).
const TILE: usize = 4;

/// Cells of an element gathered before they are added to its sums (`Elements::add_batch`):
/// bounds the rows buffer to 2¹⁶ · (functions + d) values (docs/decisions.md#float32-samples).
const BATCH_CELLS: usize = 1 << 16;

/// The upper block triangle of BᵀB for cell-major rows `b` of `m4` values (a multiple of
/// [`TILE`]) into `out` (`m4`×`m4`, row-major; entries below the diagonal tiles are not
/// written). Why tiles: a TILE×TILE block of sums stays in registers while the cells stream
/// by, so each loaded value feeds TILE products (a dot product per entry loads two values
/// per product). Each entry is summed over the cells in order: deterministic. The sums start
/// from `out`'s values (zeros for a new element, a previous batch's sums for the next batch):
/// the same sequence of additions as one pass over all the cells.
fn gram_upper(b: &[f64], m4: usize, out: &mut [f64]) {
    for x0 in (0..m4).step_by(TILE) {
        for y0 in (x0..m4).step_by(TILE) {
            let mut acc = [[0.0f64; TILE]; TILE];
            for i in 0..TILE {
                acc[i].copy_from_slice(&out[(x0 + i) * m4 + y0..(x0 + i) * m4 + y0 + TILE]);
            }
            for row in b.chunks_exact(m4) {
                let (bx, by) = (&row[x0..x0 + TILE], &row[y0..y0 + TILE]);
                for i in 0..TILE {
                    for j in 0..TILE {
                        acc[i][j] += bx[i] * by[j];
                    }
                }
            }
            for i in 0..TILE {
                out[(x0 + i) * m4 + y0..(x0 + i) * m4 + y0 + TILE].copy_from_slice(&acc[i]);
            }
        }
    }
}

/// Bᵀd added to `out[..m4]` and the column sums of B to `out[m4..]` (cells in order, from
/// `out`'s values on, as [`gram_upper`]).
fn moments(b: &[f64], m4: usize, d: &[f64], out: &mut [f64]) {
    let (bd, sum) = out.split_at_mut(m4);
    for (row, &dc) in b.chunks_exact(m4).zip(d) {
        for ((x, s), &r) in bd.iter_mut().zip(sum.iter_mut()).zip(row) {
            *x += r * dc;
            *s += r;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Degree;
    use crate::testing::{lcg, refined_mesh};

    /// The batched sums (`Elements::add_batch`) must be the one-pass sums to the bit, and both
    /// the plain BᵀB, Bᵀd and column sums (checked against dot products written out here).
    #[test]
    fn gram_and_moments_in_batches_equal_one_pass() {
        let (m4, cells, cut) = (8, 11, 4);
        let b: Vec<f64> = (0..m4 * cells).map(|k| ((k * 37 % 23) as f64 - 11.0) / 7.0).collect();
        let d: Vec<f64> = (0..cells).map(|c| (c as f64).sin()).collect();
        let (mut g1, mut m1) = (vec![0.0; m4 * m4], vec![0.0; 2 * m4]);
        gram_upper(&b, m4, &mut g1);
        moments(&b, m4, &d, &mut m1);
        let (mut g2, mut m2) = (vec![0.0; m4 * m4], vec![0.0; 2 * m4]);
        for (rows, ds) in [(&b[..cut * m4], &d[..cut]), (&b[cut * m4..], &d[cut..])] {
            gram_upper(rows, m4, &mut g2);
            moments(rows, m4, ds, &mut m2);
        }
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&g1), bits(&g2));
        assert_eq!(bits(&m1), bits(&m2));
        let at = |c: usize, x: usize| b[c * m4 + x];
        for x in 0..m4 {
            for y in x..m4 {
                let dot: f64 = (0..cells).map(|c| at(c, x) * at(c, y)).sum();
                assert!((g1[x * m4 + y] - dot).abs() < 1e-12, "BᵀB[{x}][{y}]");
            }
            let bd: f64 = (0..cells).map(|c| at(c, x) * d[c]).sum();
            let col: f64 = (0..cells).map(|c| at(c, x)).sum();
            assert!((m1[x] - bd).abs() < 1e-12 && (m1[m4 + x] - col).abs() < 1e-12, "moments[{x}]");
        }
    }

    /// A wavy raster over `w`×`h` cells with a few no-data holes.
    fn raster(w: usize, h: usize) -> Samples {
        let mut seed = 5u64;
        let z: Vec<f64> = (0..w * h)
            .map(|q| {
                let (i, j) = ((q % w) as f64, (q / w) as f64);
                if lcg(&mut seed) < 0.05 {
                    f64::NAN
                } else {
                    (i * 0.21).sin() * 3.0 + j * 0.07 + (i * j * 0.003).cos()
                }
            })
            .collect();
        Samples { width: w, height: h, z: z.into() }
    }

    /// The upper-triangle pattern of every pair of overlapping supports.
    fn full_pattern(pb: &PbSpline) -> SymCsr {
        let k = pb.degree.k();
        let n = pb.knots.len();
        let mut start = vec![0];
        let mut cols = Vec::new();
        for i in 0..n {
            let a = &pb.knots[i];
            for j in 0..n {
                let c = &pb.knots[j];
                if a[k + 1].min(c[k + 1]) > a[0].max(c[0]) && a[5 + k + 1].min(c[5 + k + 1]) > a[5].max(c[5]) {
                    cols.push(j as u32);
                }
            }
            start.push(cols.len());
        }
        let vals = vec![0.0; cols.len()];
        SymCsr { start, cols, vals }
    }

    fn assert_close(a: &[f64], b: &[f64], what: &str) {
        let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() <= 1e-12 * scale, "{what}[{k}]: {x} vs {y}");
        }
    }

    /// Every raster cell position and its basis through the PB-spline, independently of both
    /// assemblies: Σ over cells of the products, dense.
    fn dense_normal(pb: &PbSpline, s: &Samples) -> (Vec<f64>, Vec<f64>) {
        let n = pb.knots.len();
        let (mut ata, mut atd) = (vec![0.0; n * n], vec![0.0; n]);
        let mut scratch = Vec::new();
        for (q, d) in s.z.iter().enumerate() {
            if d.is_nan() {
                continue;
            }
            let mut row = Vec::new();
            if !pb.for_each_basis((q % s.width) as f64, (q / s.width) as f64, &mut scratch, |i, v| {
                row.push((i as usize, v))
            }) {
                continue;
            }
            for &(i, vi) in &row {
                atd[i] += vi * d;
                for &(j, vj) in &row {
                    ata[i * n + j] += vi * vj;
                }
            }
        }
        (ata, atd)
    }

    /// The per-element assembly equals the cell-by-cell one and a dense AᵀA on meshes with
    /// T-junctions and non-unit weights, over rasters that reach the domain's borders (A1
    /// cells: the lower/left flagged edges and the upper borders no element holds) or stop
    /// inside it, with and without held points and a region.
    #[test]
    fn elements_equal_cell_by_cell_and_dense() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let pb = PbSpline::build(&refined_mesh(degree));
            let n = pb.knots.len();
            let a = full_pattern(&pb);
            let prior: Vec<f64> = pb.geom.iter().map(|g| g[2]).collect();
            for (w, h) in [(97, 81), (60, 45)] {
                let s = raster(w, h);
                let sys = System { pattern: &a, pb: &pb, free: None, prior: &prior };
                let old = per_cell(sys, &s, None, None, None).unwrap();
                let new = by_elements(sys, &s, None);
                assert_close(&old.vals, &new.vals, "vals");
                assert_close(&old.rhs, &new.rhs, "rhs");
                assert_close(&old.support, &new.support, "support");
                let (ata, atd) = dense_normal(&pb, &s);
                for i in 0..n {
                    for k in a.start[i]..a.start[i + 1] {
                        let j = a.cols[k] as usize;
                        if i <= j {
                            assert!(
                                (new.vals[k] - ata[i * n + j]).abs() <= 1e-11 * ata[i * n + i].max(1.0),
                                "{degree:?} ({i},{j})"
                            );
                        }
                    }
                    assert!((new.rhs[i] - atd[i]).abs() <= 1e-11 * atd[i].abs().max(1.0));
                }
                // held points and a region (the local update's shape)
                let free: Vec<bool> = (0..n).map(|i| i % 3 != 0 && pb.knots[i][0] < 40.0).collect();
                let mut region = Region::new(w, h);
                region.add_rect(0.0, 40.0, 0.0, 1e9);
                let sys = System { free: Some(&free), ..sys };
                let old = per_cell(sys, &s, None, Some(&region), None).unwrap();
                let new = by_elements(sys, &s, Some(&region));
                let on_free = |v: &[f64]| (0..n).map(|i| if free[i] { v[i] } else { 0.0 }).collect::<Vec<f64>>();
                assert_close(&on_free(&old.rhs), &on_free(&new.rhs), "held rhs");
                assert_close(&on_free(&old.support), &on_free(&new.support), "held support");
                let free_pair = |v: &[f64]| {
                    (0..n)
                        .flat_map(|i| (a.start[i]..a.start[i + 1]).map(move |k| (i, k)))
                        .map(|(i, k)| if free[i] && free[a.cols[k] as usize] { v[k] } else { 0.0 })
                        .collect::<Vec<f64>>()
                };
                assert_close(&free_pair(&old.vals), &free_pair(&new.vals), "held vals");
            }
        }
    }

    /// Each cell's basis row is the reference's to the bit (same factors, same order of the
    /// sum Σ w N): with a single valid cell, both assemblies hold exactly its products.
    #[test]
    fn one_cell_rows_are_bit_identical() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let pb = PbSpline::build(&refined_mesh(degree));
            let a = full_pattern(&pb);
            let prior: Vec<f64> = pb.geom.iter().map(|g| g[2]).collect();
            let sys = System { pattern: &a, pb: &pb, free: None, prior: &prior };
            let (w, h) = (97, 81);
            let mut seed = 11u64;
            for _ in 0..200 {
                let q = (lcg(&mut seed) * (w * h) as f64) as usize;
                let mut z = vec![f64::NAN; w * h];
                z[q] = 1.0 + lcg(&mut seed);
                let s = Samples { width: w, height: h, z: z.into() };
                let old = per_cell(sys, &s, None, None, None).unwrap();
                let new = by_elements(sys, &s, None);
                assert!(
                    old.vals == new.vals && old.rhs == new.rhs && old.support == new.support,
                    "{degree:?} cell {q}"
                );
            }
        }
    }
}
