//! Polynomial (Bézier-style) extraction of the rational T-spline for fast dense evaluation
//! (spec §3.2 eq. 2.7, §6.3 Alg. 6).
//!
//! Why: the PB-spline path in [`PbSpline::point`] visits every candidate control point of the
//! bucket and evaluates two basis functions each (≈ 580 flops per point on a cubic mesh). On an
//! *element* — a rectangle that no knot line of any overlapping blending function crosses —
//! every blending function is the product of two polynomials of degree ≤ K, so the numerator
//! Σ wᵢ zᵢ Nᵢ and the denominator Σ wᵢ Nᵢ are each ONE polynomial of bidegree (K, K). We
//! precompute these two (K+1)×(K+1) coefficient blocks per element, in the element's local
//! parameters u = (s − s₀)/(s₁ − s₀), v = (t − t₀)/(t₁ − t₀) (∈ [0, 1], for conditioning), so a
//! point costs: locate the element + 2 bivariate Horner evaluations + 1 division, independent of
//! how many blending functions overlap.
//!
//! Elements are the leaf cells of the T-mesh subdivided by every knot value (in s and in t) of
//! the blending functions overlapping the cell that falls strictly inside it: a leaf cell is not
//! always an element, because T-junction extensions of analysis-suitable meshes (and the knot
//! lines of any T-mesh) may cross a face of the T-mesh.
//!
//! Only z and w are extracted: the dense paths (`eval_z`, `eval_grid`, the OpenCL grid/points
//! kernels) return heights; `PbSpline::point` (x, y, z) stays on the PB-spline path.
//!
//! Spans are half-open [a, b) like the reference (A2), so an element owns its lower and left
//! edges. Everything the reference treats specially goes to the reference path
//! ([`PbSpline::point`]), so the two stay equal to rounding:
//! - points in no element half-open: outside the domain (NaN) or on an upper border (A1);
//! - points on an element's lower/left edge where that edge lies on its leaf cell's edge and is
//!   not entirely covered by leaf cells on the other side (a domain border, a hole's or notch's
//!   edge: A1 moves or flags the point there). Elsewhere on such an edge a neighbouring leaf
//!   contains the point, so the reference neither moves it nor flips spans.

use rayon::prelude::*;

use crate::eval::{BucketGrid, GridSpec, PbSpline};

/// Element flag: the left edge (s = s₀) may be a border in the A1 sense.
pub const LEFT_BORDER: u32 = 1;
/// Element flag: the lower edge (t = t₀) may be a border in the A1 sense.
pub const BOTTOM_BORDER: u32 = 2;

/// Points where the extracted denominator is below `DEN_TAU · Σ|w-block coefficients|` of
/// their element take the reference path. Why: near a cubic border (knot multiplicity 3, A1)
/// every blending function tends to 0 and the rational form to 0/0; the summed monomial blocks
/// then evaluate with an absolute error of about ε·Σ|coefficients|, i.e. a relative error of
/// ε·Σ|c|/den (measured: 1e-12 relative at den = 1.4e-2 on the test mesh, 1e-10 at 1.4e-4). With
/// τ = 2⁻⁸ the relative error stays below ~256 ε × (a cancellation factor ~1), well inside the
/// 1e-12 agreement; the band it diverts is a few percent of a border cell.
pub const DEN_TAU: f64 = 1.0 / 256.0;

/// Per-element polynomial blocks plus a bucket grid over the elements, flat and device-ready.
#[derive(Debug, Clone)]
pub struct Extraction {
    /// Polynomial degree K (1 or 3); blocks are (K+1)×(K+1).
    pub k: usize,
    /// Doubles per element record: `8 + 2 (K+1)²`.
    pub stride: usize,
    /// Per element: s₀, t₀, s₁, t₁, 1/(s₁−s₀), 1/(t₁−t₀), the denominator threshold (below:
    /// reference path, see [`DEN_TAU`]), 0, then the z·w block and the w block, each row-major
    /// in v: coefficient of uⁱ vʲ at `j (K+1) + i`.
    pub data: Vec<f64>,
    /// Per element: [`LEFT_BORDER`] | [`BOTTOM_BORDER`].
    pub flags: Vec<u32>,
    /// Uniform grid over the domain's bounding box, about one bucket per element.
    pub grid: BucketGrid,
    /// CSR: elements whose closed rectangle meets bucket b: `items[start[b]..start[b+1]]`.
    pub start: Vec<u32>,
    pub items: Vec<u32>,
}

/// Coefficients of q(x) = p(α + β x) for p(y) = Σ cₘ yᵐ (Taylor shift by α, then scaling by β).
#[inline]
fn compose(c: &mut [f64], alpha: f64, beta: f64) {
    let n = c.len();
    if alpha != 0.0 {
        for i in 0..n - 1 {
            for j in (i..n - 1).rev() {
                c[j] += alpha * c[j + 1];
            }
        }
    }
    if beta != 1.0 {
        let mut f = beta;
        for cm in c.iter_mut().skip(1) {
            *cm *= f;
            f *= beta;
        }
    }
}

/// The factor of a blending function in one direction on [a, b] (inside one span), as
/// coefficients in the element's local parameter; `kn` the K+2 local knots, `pc` the pieces
/// ([`crate::eval::basis_pieces`]: per span 1/width, c₀..c₃ in (u − knot)/width).
#[inline]
fn factor(kn: &[f64], pc: &[f64], k: usize, a: f64, b: f64, out: &mut [f64; 4]) -> bool {
    for j in 0..=k {
        if kn[j] <= a && b <= kn[j + 1] && kn[j] < kn[j + 1] {
            let p = &pc[5 * j..5 * j + 5];
            // a fixed-size copy for the cubic case: a slice copy of run-time length k + 1 was a
            // memmove call per factor (2.5 % of the BAG 0.1 fit's samples)
            if k == 3 {
                *out = [p[1], p[2], p[3], p[4]];
            } else {
                out.iter_mut().zip(&p[1..k + 2]).for_each(|(o, v)| *o = *v);
            }
            compose(&mut out[..k + 1], (a - kn[j]) * p[0], (b - a) * p[0]);
            return true;
        }
    }
    false
}

/// Value of a (N×N) block at local (u, v): Horner in u per row, then in v. The OpenCL twin
/// (`bipoly` in `tspline.cl`) uses the same order.
#[inline(always)]
fn bipoly<const N: usize>(c: &[f64], u: f64, v: f64) -> f64 {
    let mut acc = 0.0;
    for j in (0..N).rev() {
        let row = &c[j * N..j * N + N];
        let mut r = row[N - 1];
        for i in (0..N - 1).rev() {
            r = r * u + row[i];
        }
        acc = if j == N - 1 { r } else { acc * v + r };
    }
    acc
}

impl Extraction {
    /// Extracts the element polynomials of `pb` with its current geometry (rebuild after
    /// changing `pb.geom`). `parallel`: over leaf cells with rayon.
    pub fn new(pb: &PbSpline, parallel: bool) -> Extraction {
        let k = pb.degree.k();
        let stride = 8 + 2 * (k + 1) * (k + 1);
        // Chunks of cells with reused scratch buffers: one output allocation per chunk.
        const CHUNK: usize = 1024;
        let nchunks = pb.cells.len().div_ceil(CHUNK);
        let first = first_buckets(pb, parallel);
        let run = |q: usize| {
            let mut sc = Scratch { first: &first, ..Scratch::default() };
            let (mut data, mut flags) = (Vec::new(), Vec::new());
            for ci in q * CHUNK..((q + 1) * CHUNK).min(pb.cells.len()) {
                extract_cell(pb, ci, &mut sc, &mut data, &mut flags);
            }
            (data, flags)
        };
        let parts: Vec<(Vec<f64>, Vec<u32>)> =
            if parallel { (0..nchunks).into_par_iter().map(run).collect() } else { (0..nchunks).map(run).collect() };
        let ne: usize = parts.iter().map(|p| p.1.len()).sum();
        let (data, flags) = if parts.len() == 1 {
            parts.into_iter().next().unwrap_or_default()
        } else {
            let mut data = Vec::with_capacity(ne * stride);
            let mut flags = Vec::with_capacity(ne);
            for (d, f) in parts {
                data.extend_from_slice(&d);
                flags.extend_from_slice(&f);
            }
            (data, flags)
        };
        // Bucket grid over the same box, about one bucket per element.
        let g0 = pb.grid;
        let (w, h) = (g0.ds * g0.ns as f64, g0.dt * g0.nt as f64);
        let n = ne.max(1) as f64;
        let aspect = (w / h).clamp(1e-6, 1e6);
        let ns = ((n * aspect).sqrt().ceil() as u32).clamp(1, 4096);
        let nt = ((n / aspect).sqrt().ceil() as u32).clamp(1, 4096);
        let grid = BucketGrid { s0: g0.s0, t0: g0.t0, ds: w / ns as f64, dt: h / nt as f64, ns, nt };
        let nb = (ns * nt) as usize;
        let rect = |e: usize| {
            let r = &data[e * stride..e * stride + 4];
            (grid.index_range(r[0], r[2], true), grid.index_range(r[1], r[3], false))
        };
        let mut start = vec![0u32; nb + 1];
        for e in 0..ne {
            let ((i0, i1), (j0, j1)) = rect(e);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    start[(j * ns + i) as usize + 1] += 1;
                }
            }
        }
        for b in 0..nb {
            start[b + 1] += start[b];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; start[nb] as usize];
        for e in 0..ne {
            let ((i0, i1), (j0, j1)) = rect(e);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let b = (j * ns + i) as usize;
                    items[fill[b] as usize] = e as u32;
                    fill[b] += 1;
                }
            }
        }
        Extraction { k, stride, data, flags, grid, start, items }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.flags.len()
    }

    pub fn is_empty(&self) -> bool {
        self.flags.is_empty()
    }

    /// The element holding (s, t) half-open, trying `hint` first.
    #[inline]
    fn find(&self, s: f64, t: f64, hint: usize) -> Option<usize> {
        let st = self.stride;
        if hint < self.flags.len() {
            let r = &self.data[hint * st..hint * st + 4];
            if r[0] <= s && s < r[2] && r[1] <= t && t < r[3] {
                return Some(hint);
            }
        }
        let (i, _) = self.grid.index_range(s, s, true);
        let (j, _) = self.grid.index_range(t, t, false);
        let b = (j * self.grid.ns + i) as usize;
        for &e in &self.items[self.start[b] as usize..self.start[b + 1] as usize] {
            let r = &self.data[e as usize * st..e as usize * st + 4];
            if r[0] <= s && s < r[2] && r[1] <= t && t < r[3] {
                return Some(e as usize);
            }
        }
        None
    }

    /// Height at (s, t); `pb` must be the PB-spline this was extracted from (reference path for
    /// borders and outside, see the module doc). `hint`: the last element (dense grids evaluate
    /// row by row, so consecutive points mostly share it).
    #[inline]
    pub fn z(&self, pb: &PbSpline, s: f64, t: f64, hint: &mut usize) -> f64 {
        let Some(e) = self.find(s, t, *hint) else { return pb.point(s, t)[2] };
        *hint = e;
        let r = &self.data[e * self.stride..(e + 1) * self.stride];
        let f = self.flags[e];
        if f != 0 && ((f & LEFT_BORDER != 0 && s == r[0]) || (f & BOTTOM_BORDER != 0 && t == r[1])) {
            return pb.point(s, t)[2];
        }
        let u = (s - r[0]) * r[4];
        let v = (t - r[1]) * r[5];
        let (num, den) = if self.k == 3 {
            (bipoly::<4>(&r[8..24], u, v), bipoly::<4>(&r[24..40], u, v))
        } else {
            (bipoly::<2>(&r[8..12], u, v), bipoly::<2>(&r[12..16], u, v))
        };
        if den >= r[6] {
            return num / den;
        }
        // Small, zero or NaN denominators: the reference decides (NaN where Σ w N = 0).
        pb.point(s, t)[2]
    }

    /// Heights on a regular grid (as [`PbSpline::eval_grid`]), evaluated separably: along a
    /// grid row t is fixed, so per element crossed the two blocks are collapsed once to
    /// polynomials in u (Horner in v per column of the block), and every grid point inside the
    /// element costs two Horner forms in u and a division (about 15 flops instead of ~70 for
    /// [`Extraction::z`]), with no element search until the row leaves the element. Equal to
    /// [`Extraction::z`] to rounding (the sums are taken in the other order). Callers that
    /// evaluate many grids on the same geometry (the fit's row-block error pass) build the
    /// extraction once and call this per block.
    pub fn eval_grid(&self, pb: &PbSpline, g: &GridSpec, parallel: bool) -> Vec<f64> {
        let mut out = vec![0.0; g.ns * g.nt];
        let row = |(j, o): (usize, &mut [f64])| {
            let t = g.t0 + j as f64 * g.dt;
            if self.k == 3 {
                self.grid_row::<4>(pb, g, t, o)
            } else {
                self.grid_row::<2>(pb, g, t, o)
            }
        };
        if g.ns > 0 {
            if parallel {
                out.par_chunks_mut(g.ns).enumerate().for_each(row);
            } else {
                out.chunks_mut(g.ns).enumerate().for_each(row);
            }
        }
        out
    }

    /// One grid row at `t` (see [`Extraction::eval_grid`]); N = K + 1.
    #[inline]
    fn grid_row<const N: usize>(&self, pb: &PbSpline, g: &GridSpec, t: f64, o: &mut [f64]) {
        let s_at = |i: usize| g.s0 + i as f64 * g.ds;
        if !(g.ds > 0.0) {
            // a row that does not run left to right: point by point
            let mut hint = 0;
            for (i, z) in o.iter_mut().enumerate() {
                *z = self.z(pb, s_at(i), t, &mut hint);
            }
            return;
        }
        let mut i = 0;
        let mut hint = 0;
        while i < o.len() {
            let s = s_at(i);
            let Some(e) = self.find(s, t, hint) else {
                o[i] = pb.point(s, t)[2];
                i += 1;
                continue;
            };
            hint = e;
            let r = &self.data[e * self.stride..(e + 1) * self.stride];
            let f = self.flags[e];
            let bottom = f & BOTTOM_BORDER != 0 && t == r[1];
            let left = f & LEFT_BORDER != 0;
            // the blocks collapsed at v: coefficient of uⁱ = Σ_j c[j N + i] vʲ
            let v = (t - r[1]) * r[5];
            let (zb, wb) = (&r[8..8 + N * N], &r[8 + N * N..8 + 2 * N * N]);
            let (mut cz, mut cw) = ([0.0; N], [0.0; N]);
            for col in 0..N {
                let (mut a, mut b) = (zb[(N - 1) * N + col], wb[(N - 1) * N + col]);
                for jj in (0..N - 1).rev() {
                    a = a * v + zb[jj * N + col];
                    b = b * v + wb[jj * N + col];
                }
                cz[col] = a;
                cw[col] = b;
            }
            loop {
                let s = s_at(i);
                if !(s < r[2]) {
                    break;
                }
                o[i] = if bottom || (left && s == r[0]) {
                    pb.point(s, t)[2]
                } else {
                    let u = (s - r[0]) * r[4];
                    let (mut num, mut den) = (cz[N - 1], cw[N - 1]);
                    for col in (0..N - 1).rev() {
                        num = num * u + cz[col];
                        den = den * u + cw[col];
                    }
                    // small, zero or NaN denominators: the reference decides (as in `z`)
                    if den >= r[6] {
                        num / den
                    } else {
                        pb.point(s, t)[2]
                    }
                };
                i += 1;
                if i == o.len() {
                    break;
                }
            }
        }
    }

    /// Heights at many points, in chunks (each with its own element hint).
    pub fn eval_z(&self, pb: &PbSpline, st: &[[f64; 2]], parallel: bool) -> Vec<f64> {
        let mut out = vec![0.0; st.len()];
        let run = |(o, p): (&mut [f64], &[[f64; 2]])| {
            let mut hint = 0;
            for (z, q) in o.iter_mut().zip(p) {
                *z = self.z(pb, q[0], q[1], &mut hint);
            }
        };
        const CHUNK: usize = 8192;
        if parallel {
            out.par_chunks_mut(CHUNK).zip(st.par_chunks(CHUNK)).for_each(run);
        } else {
            out.chunks_mut(CHUNK).zip(st.chunks(CHUNK)).for_each(run);
        }
        out
    }

    /// Fraction of `st` that takes the element path, and the mean number of element
    /// rectangles tested per point (for [`PbSpline::flops_estimate`]), on 10 runs of 1000
    /// consecutive points centred in tenths of `st` (consecutive, so the element hint works as
    /// in [`Extraction::eval_z`]; not at its ends, which on a grid are border rows).
    pub fn path_stats(&self, st: &[[f64; 2]]) -> (f64, f64) {
        if st.is_empty() {
            return (1.0, 1.0);
        }
        let (mut fast, mut tests, mut n) = (0usize, 0usize, 0usize);
        for q in 0..10 {
            let a = ((2 * q + 1) * st.len() / 20).saturating_sub(500);
            let mut hint = usize::MAX;
            for p in &st[a..(a + 1000).min(st.len())] {
                let (s, t) = (p[0], p[1]);
                n += 1;
                tests += 1;
                let hit = hint < self.flags.len() && {
                    let r = &self.data[hint * self.stride..hint * self.stride + 4];
                    r[0] <= s && s < r[2] && r[1] <= t && t < r[3]
                };
                let found = if hit {
                    Some(hint)
                } else {
                    let (i, _) = self.grid.index_range(s, s, true);
                    let (j, _) = self.grid.index_range(t, t, false);
                    let b = (j * self.grid.ns + i) as usize;
                    tests += (self.start[b + 1] - self.start[b]) as usize;
                    self.find(s, t, usize::MAX)
                };
                if let Some(e) = found {
                    hint = e;
                    let r = &self.data[e * self.stride..];
                    let f = self.flags[e];
                    if !(f != 0 && ((f & LEFT_BORDER != 0 && s == r[0]) || (f & BOTTOM_BORDER != 0 && t == r[1]))) {
                        fast += 1;
                    }
                }
            }
        }
        (fast as f64 / n as f64, tests as f64 / n as f64)
    }
}

#[derive(Default)]
struct Scratch<'a> {
    first: &'a [[u32; 2]],
    el: CellElements,
}

/// Per blending function, the first bucket of the PB-spline's grid that its support meets (s,
/// t): [`CellElements::build`] takes a candidate from the first bucket its support shares with
/// the cell only, so no sort/dedup is needed.
pub(crate) fn first_buckets(pb: &PbSpline, parallel: bool) -> Vec<[u32; 2]> {
    let first =
        |kn: &[f64; 10]| [pb.grid.index_range(kn[0], kn[0], true).0, pb.grid.index_range(kn[5], kn[5], false).0];
    if parallel {
        pb.knots.par_iter().map(first).collect()
    } else {
        pb.knots.iter().map(first).collect()
    }
}

/// The elements of one leaf cell (shared by the extraction and the fit's per-element
/// assembly, `crate::assembly`): the element (jt, is) is [sb[is], sb[is+1]) × [tb[jt], tb[jt+1]).
#[derive(Default)]
pub(crate) struct CellElements {
    /// PB indices of the blending functions whose support meets the cell's interior, in
    /// bucket order.
    pub cand: Vec<u32>,
    /// Element breaks in s and t: the cell's edges and every knot strictly inside, sorted.
    pub sb: Vec<f64>,
    pub tb: Vec<f64>,
    /// Per element row (jt): whether its left edge may be an A1 border; per element column
    /// (is): whether its lower edge may be one.
    pub left: Vec<bool>,
    pub bottom: Vec<bool>,
    ids: Vec<u32>,
}

impl CellElements {
    /// Fills the lists for leaf cell `ci`; `first` from [`first_buckets`].
    pub(crate) fn build(&mut self, pb: &PbSpline, ci: usize, first: &[[u32; 2]]) {
        let k = pb.degree.k();
        let c = pb.cells[ci];
        let (s0, t0, s1, t1) = (c[0], c[1], c[2], c[3]);
        // Blending functions whose support meets the cell's interior.
        let cand = &mut self.cand;
        cand.clear();
        pb.for_points_in_buckets_once((s0, s1), (t0, t1), first, |p| {
            let kn = &pb.knots[p as usize];
            if kn[0] < s1 && kn[k + 1] > s0 && kn[5] < t1 && kn[5 + k + 1] > t0 {
                cand.push(p);
            }
        });
        // Element breaks: the cell's edges and every knot strictly inside.
        let (sb, tb) = (&mut self.sb, &mut self.tb);
        sb.clear();
        tb.clear();
        sb.extend([s0, s1]);
        tb.extend([t0, t1]);
        for &p in cand.iter() {
            let kn = &pb.knots[p as usize];
            for &x in &kn[..k + 2] {
                if s0 < x && x < s1 && !sb.contains(&x) {
                    sb.push(x);
                }
            }
            for &x in &kn[5..5 + k + 2] {
                if t0 < x && x < t1 && !tb.contains(&x) {
                    tb.push(x);
                }
            }
        }
        if sb.len() > 2 {
            sb.sort_by(|a, b| a.total_cmp(b));
        }
        if tb.len() > 2 {
            tb.sort_by(|a, b| a.total_cmp(b));
        }
        self.find_borders(pb, s0, t0);
    }

    /// The A1 border flags of the element edges on the cell's left (s = s0) and lower (t = t0)
    /// edges.
    fn find_borders(&mut self, pb: &PbSpline, s0: f64, t0: f64) {
        let (sb, tb) = (&self.sb, &self.tb);
        let (s1, t1) = (sb[sb.len() - 1], tb[tb.len() - 1]);
        let left_open = !edge_covered(pb, s0, t0, t1, true, &mut self.ids);
        let bottom_open = !edge_covered(pb, t0, s0, s1, false, &mut self.ids);
        self.left.clear();
        self.left.resize(tb.len() - 1, left_open);
        self.bottom.clear();
        self.bottom.resize(sb.len() - 1, bottom_open);
        // A partly covered edge: decide per element segment.
        if left_open && tb.len() > 2 {
            for q in 0..tb.len() - 1 {
                self.left[q] = !edge_covered(pb, s0, tb[q], tb[q + 1], true, &mut self.ids);
            }
        }
        if bottom_open && sb.len() > 2 {
            for q in 0..sb.len() - 1 {
                self.bottom[q] = !edge_covered(pb, t0, sb[q], sb[q + 1], false, &mut self.ids);
            }
        }
    }

    /// The flags ([`LEFT_BORDER`] | [`BOTTOM_BORDER`]) of element (jt, is).
    pub(crate) fn flags(&self, jt: usize, is: usize) -> u32 {
        let mut f = 0;
        if is == 0 && self.left[jt] {
            f |= LEFT_BORDER;
        }
        if jt == 0 && self.bottom[is] {
            f |= BOTTOM_BORDER;
        }
        f
    }
}

/// Appends the elements of leaf cell `ci` (records and flags, see [`Extraction::data`]).
fn extract_cell(pb: &PbSpline, ci: usize, sc: &mut Scratch<'_>, data: &mut Vec<f64>, flags: &mut Vec<u32>) {
    let k = pb.degree.k();
    let n1 = k + 1;
    let nc = n1 * n1;
    let stride = 8 + 2 * nc;
    sc.el.build(pb, ci, sc.first);
    let el = &sc.el;
    let (cand, sb, tb) = (&el.cand, &el.sb, &el.tb);
    for jt in 0..tb.len() - 1 {
        for is in 0..sb.len() - 1 {
            let (a, b, c_, d) = (sb[is], sb[is + 1], tb[jt], tb[jt + 1]);
            let base = data.len();
            data.resize(base + stride, 0.0);
            let r = &mut data[base..];
            r[..6].copy_from_slice(&[a, c_, b, d, 1.0 / (b - a), 1.0 / (d - c_)]);
            flags.push(el.flags(jt, is));
            let (head, blocks) = r.split_at_mut(8);
            let (zw, ww) = blocks.split_at_mut(nc);
            for &p in cand.iter() {
                let kn = &pb.knots[p as usize];
                if !(kn[0] < b && kn[k + 1] > a && kn[5] < d && kn[5 + k + 1] > c_) {
                    continue;
                }
                let (ps, pt) = pb.pieces(p as usize);
                let (mut fs, mut ft) = ([0.0; 4], [0.0; 4]);
                if !factor(&kn[0..5], ps, k, a, b, &mut fs) || !factor(&kn[5..10], pt, k, c_, d, &mut ft) {
                    continue;
                }
                let g = pb.geom[p as usize];
                let (w, wz) = (g[3], g[3] * g[2]);
                let (mut a, mut bw) = ([0.0; 4], [0.0; 4]);
                for i in 0..4 {
                    a[i] = wz * fs[i];
                    bw[i] = w * fs[i];
                }
                if n1 == 4 {
                    for j in 0..4 {
                        let (z4, w4) = (&mut zw[4 * j..4 * j + 4], &mut ww[4 * j..4 * j + 4]);
                        for i in 0..4 {
                            z4[i] += a[i] * ft[j];
                            w4[i] += bw[i] * ft[j];
                        }
                    }
                } else {
                    for j in 0..n1 {
                        for i in 0..n1 {
                            zw[j * n1 + i] += a[i] * ft[j];
                            ww[j * n1 + i] += bw[i] * ft[j];
                        }
                    }
                }
            }
            head[6] = DEN_TAU * ww.iter().map(|x| x.abs()).sum::<f64>();
        }
    }
}

/// Whether the segment {at} × [lo, hi] (horizontal = false: [lo, hi] × {at}) is covered by leaf
/// cells lying on its lower side (cells ending at `at`). Exact sums of overlaps (the cell
/// coordinates are dyadic in practice); an inexact sum reads "not covered", which only sends
/// points to the reference path.
fn edge_covered(pb: &PbSpline, at: f64, lo: f64, hi: f64, vertical_edge: bool, ids: &mut Vec<u32>) -> bool {
    let (ir, jr) = if vertical_edge {
        (pb.grid.index_range(at, at, true), pb.grid.index_range(lo, hi, false))
    } else {
        (pb.grid.index_range(lo, hi, true), pb.grid.index_range(at, at, false))
    };
    ids.clear();
    for bj in jr.0..=jr.1 {
        for bi in ir.0..=ir.1 {
            let b = (bj * pb.grid.ns + bi) as usize;
            for &ci in &pb.cell_items[pb.cell_start[b] as usize..pb.cell_start[b + 1] as usize] {
                let c = &pb.cells[ci as usize];
                let (end, plo, phi) = if vertical_edge { (c[2], c[1], c[3]) } else { (c[3], c[0], c[2]) };
                if end == at && plo < hi && phi > lo {
                    ids.push(ci);
                }
            }
        }
    }
    ids.sort_unstable();
    ids.dedup();
    let mut sum = 0.0;
    for &ci in ids.iter() {
        let c = &pb.cells[ci as usize];
        let (plo, phi) = if vertical_edge { (c[1], c[3]) } else { (c[0], c[2]) };
        sum += phi.min(hi) - plo.max(lo);
    }
    sum == hi - lo
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Degree, TMesh};

    use crate::testing::lcg;

    use crate::testing::refined_mesh as refined;

    /// z by plain Cox–de Boor (`eval::basis`), the accurate reference near zeros of the basis.
    fn cox_z(pb: &PbSpline, s: f64, t: f64) -> f64 {
        let Some((s, t, ls, lt)) = pb.locate(s, t) else { return f64::NAN };
        let k = pb.degree.k();
        let (mut z, mut den) = (0.0, 0.0);
        for (i, kn) in pb.knots.iter().enumerate() {
            let wn = pb.geom[i][3] * crate::eval::basis(&kn[0..5], k, s, ls) * crate::eval::basis(&kn[5..10], k, t, lt);
            z += wn * pb.geom[i][2];
            den += wn;
        }
        z / den
    }

    fn check(pb: &PbSpline, st: &[[f64; 2]], what: &str) -> usize {
        let ex = Extraction::new(pb, true);
        let mut hint = 0;
        let mut nan = 0;
        let bounds = [
            pb.cells.iter().map(|c| c[0]).fold(f64::INFINITY, f64::min),
            pb.cells.iter().map(|c| c[1]).fold(f64::INFINITY, f64::min),
        ];
        let upper = [
            pb.cells.iter().map(|c| c[2]).fold(f64::NEG_INFINITY, f64::max),
            pb.cells.iter().map(|c| c[3]).fold(f64::NEG_INFINITY, f64::max),
        ];
        for (n, q) in st.iter().enumerate() {
            let a = pb.point(q[0], q[1])[2];
            let b = ex.z(pb, q[0], q[1], &mut hint);
            // independent truth (plain Cox–de Boor) on a subsample, away from the 0/0 borders
            let inner = (q[0] - bounds[0]).min(upper[0] - q[0]).min(q[1] - bounds[1]).min(upper[1] - q[1]) > 0.01;
            if n % 16 == 0 && inner && b.is_finite() {
                let c = cox_z(pb, q[0], q[1]);
                assert!((c - b).abs() <= 1e-12 * c.abs().max(1.0), "{what} at {q:?}: Cox–de Boor {c}, extraction {b}");
            }
            if a.is_nan() || b.is_nan() {
                assert!(a.is_nan() && b.is_nan(), "{what} at {q:?}: reference {a}, extraction {b}");
                nan += 1;
                continue;
            }
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{what} at {q:?}: reference {a}, extraction {b}");
        }
        nan
    }

    /// The extraction equals the PB-spline (polynomial-piece / Cox–de Boor) reference to 1e-12
    /// on random points, on every integer grid point (cell edges, T-junction lines, borders) and
    /// at every vertex of refined meshes with T-junctions, and on a merged mesh with a gap.
    #[test]
    fn extraction_equals_reference() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let m = refined(degree);
            let pb = PbSpline::build(&m);
            let ex = Extraction::new(&pb, false);
            // T-junction extensions cross faces: there are more elements than leaves.
            assert!(ex.len() > pb.cells.len(), "{degree:?}: {} elements, {} cells", ex.len(), pb.cells.len());
            let b = m.bounds();
            let mut seed = 5u64;
            let mut st: Vec<[f64; 2]> = (0..200_000)
                .map(|_| {
                    [
                        b.s_min - 2.0 + (b.width() + 4.0) * lcg(&mut seed),
                        b.t_min - 2.0 + (b.height() + 4.0) * lcg(&mut seed),
                    ]
                })
                .collect();
            for j in -1..=(b.t_max as i32 + 1) {
                for i in -1..=(b.s_max as i32 + 1) {
                    st.push([i as f64, j as f64]);
                    st.push([i as f64 + 0.5, j as f64 + 0.25]);
                }
            }
            st.extend(m.points.iter().map(|p| [p.s, p.t]));
            let nan = check(&pb, &st, &format!("{degree:?}"));
            assert!(nan > 0 && nan < st.len() / 2);
            // ... and the element path is what was compared: inside the domain (away from its
            // borders) nearly every point takes it, not the reference fallback.
            let inner: Vec<[f64; 2]> = (0..20_000)
                .map(|_| {
                    [
                        b.s_min + b.width() * (0.1 + 0.8 * lcg(&mut seed)),
                        b.t_min + b.height() * (0.1 + 0.8 * lcg(&mut seed)),
                    ]
                })
                .collect();
            let (taken, _) = ex.path_stats(&inner);
            assert!(taken > 0.9, "{degree:?}: only {taken} of interior points take the element path");
            // merged meshes: a gap, notches and partial borders (A14, A1 on notch edges)
            let a = TMesh::grid(degree, 0.0, 0.0, 4.0, 5, 4);
            let mut c = TMesh::grid(degree, 20.0, 4.0, 4.0, 3, 3);
            for p in &mut c.points {
                p.z = 1.0 + 0.1 * p.s - 0.05 * p.t * p.t;
            }
            let mm = a.merge(&c).unwrap();
            let pb = PbSpline::build(&mm);
            let b = mm.bounds();
            let mut st: Vec<[f64; 2]> = (0..50_000)
                .map(|_| {
                    [
                        b.s_min - 1.0 + (b.width() + 2.0) * lcg(&mut seed),
                        b.t_min - 1.0 + (b.height() + 2.0) * lcg(&mut seed),
                    ]
                })
                .collect();
            for j in -1..=(b.t_max as i32 + 1) {
                for i in -1..=(b.s_max as i32 + 1) {
                    st.push([i as f64, j as f64]);
                }
            }
            check(&pb, &st, &format!("{degree:?} merged"));
        }
    }

    #[test]
    fn compose_is_a_change_of_variable() {
        let c = [0.3, -1.2, 2.5, 0.7];
        let p = |y: f64| ((c[3] * y + c[2]) * y + c[1]) * y + c[0];
        let mut q = c;
        compose(&mut q, 0.25, 0.5);
        for x in [0.0, 0.1, 0.5, 0.9, 1.0] {
            let v = ((q[3] * x + q[2]) * x + q[1]) * x + q[0];
            assert!((v - p(0.25 + 0.5 * x)).abs() < 1e-15);
        }
    }

    #[test]
    fn planes_and_nan_through_the_extraction() {
        let mut m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 1.0, 3, 3);
        for p in &mut m.points {
            p.z = 2.0 + p.s;
        }
        let pb = PbSpline::build(&m);
        let ex = Extraction::new(&pb, false);
        let mut h = 0;
        assert!(ex.z(&pb, -0.1, 1.0, &mut h).is_nan());
        assert!(ex.z(&pb, 1.0, 3.0001, &mut h).is_nan());
        assert!(ex.z(&pb, f64::NAN, 1.0, &mut h).is_nan());
        for (s, t) in [(3.0, 3.0), (0.0, 0.0), (3.0, 1.5), (1.5, 3.0), (1.5, 1.5)] {
            assert!(ex.z(&pb, s, t, &mut h).is_finite(), "({s},{t})");
        }
    }
}

/// Throughput probe on the benchmark's mesh shape (`benches/tspline_mesh.py`: 315² cubic cells
/// of size 10, one band split): `cargo test -p tspline --release -- --ignored --nocapture
/// throughput`. The published figures come from `benches/tspline.sh` (the CLI).
#[cfg(test)]
mod probe {
    use super::*;
    use std::time::Instant;

    #[test]
    #[ignore]
    fn throughput() {
        let n = 315;
        let (pb, st) = crate::testing::benchmark_surface(n);
        let t = Instant::now();
        let ex = Extraction::new(&pb, true);
        let tex = t.elapsed().as_secs_f64();
        eprintln!(
            "{} cells, {} elements, {} control points; extraction {:.3} s (rayon)",
            pb.cells.len(),
            ex.len(),
            pb.point_ids.len(),
            tex
        );
        let pool1 = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        // On-CPU time of this thread (/proc/thread-self/schedstat, ns): robust to a loaded machine.
        let cpu = || -> f64 {
            std::fs::read_to_string("/proc/thread-self/schedstat")
                .ok()
                .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse::<f64>().ok()))
                .unwrap_or(f64::NAN)
                * 1e-9
        };
        let (t, c) = (Instant::now(), cpu());
        let ex1 = Extraction::new(&pb, false);
        eprintln!("extraction on 1 thread {:.3} s wall, {:.3} s cpu", t.elapsed().as_secs_f64(), cpu() - c);
        let (t, c) = (Instant::now(), cpu());
        let z1 = ex1.eval_z(&pb, &st, false);
        eprintln!(
            "evaluation only, 1 thread: {:.2} M points/s wall, {:.2} per cpu-second",
            st.len() as f64 / t.elapsed().as_secs_f64() / 1e6,
            st.len() as f64 / (cpu() - c) / 1e6
        );
        let (t, c) = (Instant::now(), cpu());
        let _ = st.iter().step_by(7).map(|p| pb.point(p[0], p[1])[2]).sum::<f64>();
        eprintln!(
            "reference, 1 thread: {:.2} M points/s per cpu-second (wall {:.2})",
            st.len() as f64 / 7.0 / (cpu() - c) / 1e6,
            st.len() as f64 / 7.0 / t.elapsed().as_secs_f64() / 1e6
        );
        let t = Instant::now();
        let z2 = ex1.eval_z(&pb, &st, true);
        eprintln!("evaluation only, rayon: {:.2} M points/s", st.len() as f64 / t.elapsed().as_secs_f64() / 1e6);
        assert_eq!(z1.len(), z2.len());
        let mut res = Vec::new();
        for (name, par) in [("1 thread", false), ("rayon", true)] {
            let t = Instant::now();
            let a = if par { pb.eval_z(&st, true) } else { pool1.install(|| pb.eval_z(&st, false)) };
            let te = t.elapsed().as_secs_f64();
            let sub: Vec<[f64; 2]> = st.iter().step_by(7).copied().collect();
            let t = Instant::now();
            let b: Vec<f64> = if par {
                sub.par_iter().map(|p| pb.point(p[0], p[1])[2]).collect()
            } else {
                sub.iter().map(|p| pb.point(p[0], p[1])[2]).collect()
            };
            let tr = t.elapsed().as_secs_f64();
            eprintln!(
                "{name}: extraction path {:.2} M points/s (incl. extraction), reference {:.2} M points/s",
                st.len() as f64 / te / 1e6,
                sub.len() as f64 / tr / 1e6
            );
            res.push((a, b));
        }
        eprintln!("flops/point: extraction {:.0}, reference {:.0}", pb.flops_estimate(&st), pb.flops_reference(&st));
        for (a, b) in &res {
            for (x, y) in a.iter().step_by(7).zip(b) {
                assert!((x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-12 * x.abs().max(1.0));
            }
        }
    }
}
