//! Evaluation of the rational T-spline (spec §3.2, eq. 2.7) through its PB-spline form
//! (control points + local knots, spec §6.3), with a uniform bucket grid as the search
//! structure. The same flat arrays feed the OpenCL kernels (`ocl_eval.rs`), so CPU and GPU run
//! the same algorithm in the same operation order.
//!
//! Two paths give the same numbers (to 1e-12, tested): [`PbSpline::point`] sums the candidate
//! blending functions (the reference; fit, dragging and single points use it), and the dense
//! paths [`PbSpline::eval_z`] / [`PbSpline::eval_grid`] go through the per-element polynomial
//! extraction of `extraction.rs` (spec §6.3 Alg. 6 evaluated per element: 2 bicubic Horner forms
//! and a division per point instead of ~16 pairs of basis functions), falling back to the
//! reference at A1 borders, outside the domain and where the 0/0 limit at cubic borders makes
//! the summed polynomials ill-conditioned.
//!
//! Decisions:
//! - **A1** upper border: spans are half-open [a, b). A point on the upper s (or t) border of the
//!   domain — no leaf cell holds it half-open in that direction — is evaluated as the limit from
//!   inside, i.e. with spans (a, b] in that direction. The same rule gives the inside limit on
//!   the upper edge of a hole or a merged mesh's notch.
//! - **A2** the standard Cox–de Boor recursion (terms with a zero denominator are 0).
//! - **A15** device encoding: we do not port the thesis' int8 R-tree pages to the device; a
//!   uniform bucket grid (CSR lists of control points whose closed support meets the bucket, and
//!   of leaf cells for the domain test) needs no queue and no integer rounding, so A15's rounding
//!   caveat disappears. The thesis' int8 page encoding is kept for reference in `rtree_pages.rs`.
//! - Outside the domain (no leaf cell holds the point) the result is NaN (spec §6.3, Alg. 6).

use rayon::prelude::*;

use crate::extraction::Extraction;
use crate::knots::{self, LocalKnots};
use crate::mesh::{Degree, TMesh};

/// One degree-K B-spline basis function on its K+2 local knots (spec eqs. 2.3/2.4 in standard
/// form, A2), evaluated with half-open spans [a,b) or, when `left` is set, (a,b] (A1).
#[inline]
pub fn basis(kn: &[f64], k: usize, u: f64, left: bool) -> f64 {
    if u < kn[0] || u > kn[k + 1] {
        return 0.0;
    }
    let mut n = [0.0f64; 4];
    for j in 0..=k {
        let (a, b) = (kn[j], kn[j + 1]);
        let inside = if left { a < u && u <= b } else { a <= u && u < b };
        n[j] = if inside { 1.0 } else { 0.0 };
    }
    for r in 1..=k {
        for j in 0..=(k - r) {
            let d1 = kn[j + r] - kn[j];
            let d2 = kn[j + r + 1] - kn[j + 1];
            let mut v = 0.0;
            if d1 > 0.0 {
                v += (u - kn[j]) / d1 * n[j];
            }
            if d2 > 0.0 {
                v += (kn[j + r + 1] - u) / d2 * n[j + 1];
            }
            n[j] = v;
        }
    }
    n[0]
}

/// Polynomial pieces of one basis function (see [`PbSpline::poly`]): sampled at x = 0, ⅓, ⅔, 1
/// of every non-empty span with the Cox–de Boor form and interpolated (exact up to rounding:
/// each piece is a polynomial of degree ≤ 3).
pub fn basis_pieces(kn: &[f64], k: usize) -> [f64; 20] {
    let mut out = [0.0; 20];
    for j in 0..=k {
        let (a, b) = (kn[j], kn[j + 1]);
        if b <= a {
            continue;
        }
        let h = b - a;
        let xs = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
        let v: [f64; 4] = std::array::from_fn(|m| basis(kn, k, if m == 3 { b } else { a + xs[m] * h }, m == 3));
        // Newton divided differences on the nodes, then expand to monomials.
        let mut d = [v[0], v[1], v[2], v[3]];
        for lvl in 1..4 {
            for i in (lvl..4).rev() {
                d[i] = (d[i] - d[i - 1]) / (xs[i] - xs[i - lvl]);
            }
        }
        // p(x) = d0 + d1 x + d2 x(x−x1) + d3 x(x−x1)(x−x2)
        let (x1, x2) = (xs[1], xs[2]);
        let c0 = d[0];
        let c1 = d[1] - d[2] * x1 + d[3] * x1 * x2;
        let c2 = d[2] - d[3] * (x1 + x2);
        let c3 = d[3];
        out[5 * j..5 * j + 5].copy_from_slice(&[1.0 / h, c0, c1, c2, c3]);
    }
    out
}

/// One basis function from its polynomial pieces (same span rule as [`basis`]).
#[inline]
pub fn basis_poly(kn: &[f64], pc: &[f64], k: usize, u: f64, left: bool) -> f64 {
    if u < kn[0] || u > kn[k + 1] {
        return 0.0;
    }
    for j in 0..=k {
        let (a, b) = (kn[j], kn[j + 1]);
        let inside = if left { a < u && u <= b } else { a <= u && u < b };
        if inside {
            let c = &pc[5 * j..5 * j + 5];
            let x = (u - a) * c[0];
            return ((c[4] * x + c[3]) * x + c[2]) * x + c[1];
        }
    }
    0.0
}

/// The PB-spline form of a T-mesh plus the bucket grids, flat and device-ready.
#[derive(Debug, Clone)]
pub struct PbSpline {
    pub degree: Degree,
    /// Mesh point id of each PB point (inactive mesh points are skipped).
    pub point_ids: Vec<u32>,
    /// Per point: σ (5) then τ (5); K=1 uses the first 3 of each.
    pub knots: Vec<[f64; 10]>,
    /// Per point, [`PbSpline::poly_stride`] values: the basis as polynomial pieces, for fast
    /// evaluation: for σ then τ, for each of the K+1 spans: 1/width and the monomial
    /// coefficients c0..c3 in x = (u − a)/width ([`PbSpline::pieces`]). Only the K+1 spans of
    /// the degree are stored (degree 1: 20 values a point, not 40: a PB-spline of 1.5·10⁵
    /// points is 24 MB smaller, BENCHMARKS.md "Peak memory per cell without the copies").
    pub poly: Vec<f64>,
    /// Per point: x, y, z, w.
    pub geom: Vec<[f64; 4]>,
    /// Leaf cell rectangles (s_min, t_min, s_max, t_max).
    pub cells: Vec<[f64; 4]>,
    pub grid: BucketGrid,
    /// CSR: points whose closed support meets bucket b: `pt_items[pt_start[b]..pt_start[b+1]]`.
    pub pt_start: Vec<u32>,
    pub pt_items: Vec<u32>,
    /// CSR: leaf cells meeting bucket b.
    pub cell_start: Vec<u32>,
    pub cell_items: Vec<u32>,
}

/// [`PbSpline::point_z_cached`]'s cache: the non-zero τ factors (PB index, N(t)) of the buckets
/// met at one located t, per bucket column (a stamp marks the entries of the current t).
#[derive(Debug, Default)]
pub(crate) struct RowCache {
    key: Option<(u64, bool)>,
    stamp: u32,
    /// Per bucket column: (stamp, bucket, range in `terms`).
    slots: Vec<(u32, u32, u32, u32)>,
    terms: Vec<(u32, f64)>,
}

/// A PB-spline reduced to its points and knots ([`PbSpline::into_knots`]); [`PbSpline::from_knots`]
/// compiles the rest again.
#[derive(Default)]
pub(crate) struct PbKnots {
    point_ids: Vec<u32>,
    /// Per point: the K+2 knots in s, then the K+2 in t.
    knots: Vec<f64>,
}

/// A uniform grid over the domain's bounding box.
#[derive(Debug, Clone, Copy)]
pub struct BucketGrid {
    pub s0: f64,
    pub t0: f64,
    pub ds: f64,
    pub dt: f64,
    pub ns: u32,
    pub nt: u32,
}

impl BucketGrid {
    #[inline]
    pub fn index_range(&self, lo: f64, hi: f64, horizontal: bool) -> (u32, u32) {
        let (o, d, n) = if horizontal { (self.s0, self.ds, self.ns) } else { (self.t0, self.dt, self.nt) };
        let a = ((lo - o) / d).floor().max(0.0).min((n - 1) as f64) as u32;
        let b = ((hi - o) / d).floor().max(0.0).min((n - 1) as f64) as u32;
        (a, b)
    }
}

fn csr(nb: usize, lists: impl Iterator<Item = (u32, (u32, u32), (u32, u32))>, ns: u32) -> (Vec<u32>, Vec<u32>) {
    let lists: Vec<_> = lists.collect();
    let mut count = vec![0u32; nb + 1];
    for &(_, (i0, i1), (j0, j1)) in &lists {
        for j in j0..=j1 {
            for i in i0..=i1 {
                count[(j * ns + i) as usize + 1] += 1;
            }
        }
    }
    for b in 0..nb {
        count[b + 1] += count[b];
    }
    let mut fill = count.clone();
    let mut items = vec![0u32; count[nb] as usize];
    for &(id, (i0, i1), (j0, j1)) in &lists {
        for j in j0..=j1 {
            for i in i0..=i1 {
                let b = (j * ns + i) as usize;
                items[fill[b] as usize] = id;
                fill[b] += 1;
            }
        }
    }
    (count, items)
}

impl PbSpline {
    /// Compiles a mesh: knot inference for every active point (in parallel), then the bucket
    /// grids (about one bucket per leaf cell, capped).
    pub fn build(mesh: &TMesh) -> PbSpline {
        let active = mesh.active_points();
        let point_ids: Vec<u32> = (0..mesh.points.len() as u32).filter(|&i| active[i as usize]).collect();
        let params: Vec<(f64, f64)> =
            point_ids.iter().map(|&i| (mesh.points[i as usize].s, mesh.points[i as usize].t)).collect();
        let knots = knots::infer_batch(mesh, &params);
        PbSpline::from_parts(mesh, point_ids, knots)
    }

    /// Compiles with knots computed elsewhere (the OpenCL knot kernel).
    pub fn from_parts(mesh: &TMesh, point_ids: Vec<u32>, knots: Vec<LocalKnots>) -> PbSpline {
        PbSpline::from_parts_reusing(mesh, point_ids, knots, None)
    }

    /// [`PbSpline::from_parts`] taking the polynomial pieces of point i from `old`'s point
    /// `reuse[i]` (u32::MAX: computed) — callers pass only points whose knots are `old`'s
    /// knots of that point, and the pieces are a function of the knots alone, so they are the
    /// bits `basis_pieces` would give (the incremental build after a refinement: most points
    /// keep their knots).
    pub(crate) fn from_parts_reusing(
        mesh: &TMesh,
        point_ids: Vec<u32>,
        knots: Vec<LocalKnots>,
        reuse: Option<(&PbSpline, &[u32])>,
    ) -> PbSpline {
        let k = mesh.degree.k();
        let knots: Vec<[f64; 10]> = knots
            .iter()
            .map(|kn| {
                let mut a = [0.0; 10];
                a[..k + 2].copy_from_slice(&kn.s[..k + 2]);
                a[5..5 + k + 2].copy_from_slice(&kn.t[..k + 2]);
                a
            })
            .collect();
        PbSpline::from_knot_rows(mesh, point_ids, knots, reuse)
    }

    /// What [`PbSpline::from_knots`] compiles the rest from: its points and their knots (a
    /// tenth of a degree-1 PB-spline's memory; the polynomial pieces, geometry, leaf cells and
    /// bucket lists are derived from them and the mesh).
    pub(crate) fn into_knots(self) -> PbKnots {
        // the K+2 knots of each direction (the rows hold zeros beyond them): degree 1 in 48
        // bytes a point, not 80
        let k = self.degree.k();
        let mut knots = Vec::with_capacity(self.knots.len() * 2 * (k + 2));
        for a in &self.knots {
            knots.extend_from_slice(&a[..k + 2]);
            knots.extend_from_slice(&a[5..5 + k + 2]);
        }
        PbKnots { point_ids: self.point_ids, knots }
    }

    /// Compiles [`PbSpline::into_knots`]'s parts again on the mesh they were built on (its
    /// points and leaves unchanged since): the same PB-spline, bit for bit.
    pub(crate) fn from_knots(mesh: &TMesh, parts: PbKnots) -> PbSpline {
        let k = mesh.degree.k();
        let rows = parts
            .knots
            .chunks_exact(2 * (k + 2))
            .map(|c| {
                let mut a = [0.0; 10];
                a[..k + 2].copy_from_slice(&c[..k + 2]);
                a[5..5 + k + 2].copy_from_slice(&c[k + 2..]);
                a
            })
            .collect();
        drop(parts.knots);
        PbSpline::from_knot_rows(mesh, parts.point_ids, rows, None)
    }

    fn from_knot_rows(
        mesh: &TMesh,
        point_ids: Vec<u32>,
        knots: Vec<[f64; 10]>,
        reuse: Option<(&PbSpline, &[u32])>,
    ) -> PbSpline {
        let k = mesh.degree.k();
        let geom = point_ids.iter().map(|&i| mesh.points[i as usize]).map(|p| [p.x, p.y, p.z, p.w]).collect();
        let half = 5 * (k + 1);
        let mut poly = vec![0.0; knots.len() * 2 * half];
        poly.par_chunks_mut(2 * half).zip(&knots).enumerate().for_each(|(i, (a, kn))| {
            if let Some((old, of)) = reuse {
                let o = of[i];
                if o != u32::MAX {
                    debug_assert_eq!(&old.knots[o as usize], kn, "reused pieces need the same knots");
                    a.copy_from_slice(&old.poly[o as usize * 2 * half..(o as usize + 1) * 2 * half]);
                    return;
                }
            }
            a[..half].copy_from_slice(&basis_pieces(&kn[0..5], k)[..half]);
            a[half..].copy_from_slice(&basis_pieces(&kn[5..10], k)[..half]);
        });
        let cells: Vec<[f64; 4]> = mesh
            .cells
            .iter()
            .filter(|c| c.is_leaf())
            .map(|c| [c.rect.s_min, c.rect.t_min, c.rect.s_max, c.rect.t_max])
            .collect();
        let b = mesh.bounds();
        let n = cells.len().max(1) as f64;
        let aspect = (b.width() / b.height()).clamp(1e-6, 1e6);
        let ns = ((n * aspect).sqrt().ceil() as u32).clamp(1, 4096);
        let nt = ((n / aspect).sqrt().ceil() as u32).clamp(1, 4096);
        let grid =
            BucketGrid { s0: b.s_min, t0: b.t_min, ds: b.width() / ns as f64, dt: b.height() / nt as f64, ns, nt };
        let nb = (ns * nt) as usize;
        // Bucket lists in the order of the points' parameters (t, then s), not of their ids:
        // every sum over a bucket's points (here, in the extraction and in the kernels) then
        // runs in an order fixed by the mesh's geometry, so a mesh evaluates to the same bits
        // however its points are numbered (the XML keeps the fit's numbering, the binary
        // `.tmb` stores a canonical one: both give the same surface, bit for bit).
        let mut order: Vec<u32> = (0..point_ids.len() as u32).collect();
        let st = |i: u32| {
            let p = &mesh.points[point_ids[i as usize] as usize];
            (p.t, p.s)
        };
        order.sort_by(|&a, &b| {
            let (p, q) = (st(a), st(b));
            p.0.total_cmp(&q.0).then(p.1.total_cmp(&q.1))
        });
        let (pt_start, pt_items) = csr(
            nb,
            order.iter().map(|&i| {
                let kn = &knots[i as usize];
                (i, grid.index_range(kn[0], kn[k + 1], true), grid.index_range(kn[5], kn[5 + k + 1], false))
            }),
            ns,
        );
        let (cell_start, cell_items) = csr(
            nb,
            cells
                .iter()
                .enumerate()
                .map(|(i, c)| (i as u32, grid.index_range(c[0], c[2], true), grid.index_range(c[1], c[3], false))),
            ns,
        );
        PbSpline {
            degree: mesh.degree,
            point_ids,
            knots,
            poly,
            geom,
            cells,
            grid,
            pt_start,
            pt_items,
            cell_start,
            cell_items,
        }
    }

    /// Values per point in [`PbSpline::poly`]: 5 (K+1) for σ, as many for τ.
    #[inline]
    pub fn poly_stride(&self) -> usize {
        10 * (self.degree.k() + 1)
    }

    /// The polynomial pieces of point `p`'s basis: (σ, τ), 5 values per span.
    #[inline]
    pub fn pieces(&self, p: usize) -> (&[f64], &[f64]) {
        let st = self.poly_stride();
        self.poly[p * st..(p + 1) * st].split_at(st / 2)
    }

    /// [`PbSpline::poly`] laid out with 40 values a point (σ at 0, τ at 20), as the OpenCL
    /// kernels read it.
    pub fn poly_40(&self) -> Vec<f64> {
        let mut out = vec![0.0; 40 * self.knots.len()];
        for (p, o) in out.chunks_exact_mut(40).enumerate() {
            let (ps, pt) = self.pieces(p);
            o[..ps.len()].copy_from_slice(ps);
            o[20..20 + pt.len()].copy_from_slice(pt);
        }
        out
    }

    #[inline]
    fn bucket(&self, s: f64, t: f64) -> usize {
        let (i, _) = self.grid.index_range(s, s, true);
        let (j, _) = self.grid.index_range(t, t, false);
        (j * self.grid.ns + i) as usize
    }

    /// Domain test with the border rule of A1. Returns the (possibly adjusted) evaluation point
    /// and the left-limit flags, or None outside the domain.
    ///
    /// A point is on an upper (lower) border in s when every leaf cell holding it ends (starts)
    /// at s. Degree 1: upper borders use (a,b] spans, which is exact. Degree 3: the thesis'
    /// border padding gives the border knot multiplicity 3, so every cubic basis function is C0
    /// and 0 there and the rational form is 0/0 on all four borders; we evaluate the limit from
    /// inside by moving the point 2^-30 cell widths inwards (the fit never samples the mesh
    /// border: the data lies strictly inside the overhang).
    #[inline]
    pub fn locate(&self, s: f64, t: f64) -> Option<(f64, f64, bool, bool)> {
        let b = self.bucket(s, t);
        let (mut found, mut up_s, mut lo_s, mut up_t, mut lo_t) = (false, true, true, true, true);
        let (mut ws, mut wt) = (f64::INFINITY, f64::INFINITY);
        for &ci in &self.cell_items[self.cell_start[b] as usize..self.cell_start[b + 1] as usize] {
            let c = &self.cells[ci as usize];
            if s < c[0] || s > c[2] || t < c[1] || t > c[3] {
                continue;
            }
            found = true;
            up_s &= s == c[2];
            lo_s &= s == c[0];
            up_t &= t == c[3];
            lo_t &= t == c[1];
            ws = ws.min(c[2] - c[0]);
            wt = wt.min(c[3] - c[1]);
        }
        if !found {
            return None;
        }
        if self.degree == Degree::Linear {
            return Some((s, t, up_s, up_t));
        }
        const EPS: f64 = 1.0 / (1u64 << 30) as f64;
        let s = if up_s {
            s - EPS * ws
        } else if lo_s {
            s + EPS * ws
        } else {
            s
        };
        let t = if up_t {
            t - EPS * wt
        } else if lo_t {
            t + EPS * wt
        } else {
            t
        };
        Some((s, t, false, false))
    }

    /// Visits the non-zero rational basis values w_i N_i / Σ w N at (s, t); returns false outside
    /// the domain (or where Σ w N = 0). `f(index, value)` gets the PB index.
    pub fn for_each_basis(&self, s: f64, t: f64, scratch: &mut Vec<(u32, f64)>, mut f: impl FnMut(u32, f64)) -> bool {
        scratch.clear();
        let Some((s, t, ls, lt)) = self.locate(s, t) else { return false };
        let mut den = 0.0;
        for (pi, wn) in self.weighted_bases(s, t, ls, lt) {
            den += wn;
            scratch.push((pi, wn));
        }
        if den == 0.0 {
            return false;
        }
        for &(i, v) in scratch.iter() {
            f(i, v / den);
        }
        true
    }

    /// Surface point (x, y, z) at (s, t), NaN outside the domain (spec §6.3 Alg. 6).
    #[inline]
    pub fn point(&self, s: f64, t: f64) -> [f64; 3] {
        let nan = [f64::NAN; 3];
        let Some((s, t, ls, lt)) = self.locate(s, t) else { return nan };
        let (mut x, mut y, mut z, mut den) = (0.0, 0.0, 0.0, 0.0);
        for (pi, wn) in self.weighted_bases(s, t, ls, lt) {
            let g = &self.geom[pi as usize];
            x += wn * g[0];
            y += wn * g[1];
            z += wn * g[2];
            den += wn;
        }
        if den == 0.0 {
            return nan;
        }
        [x / den, y / den, z / den]
    }

    /// The height [`PbSpline::point`] gives at (s, t), to the bit, with the τ factors of a
    /// bucket's points cached in `row` for as long as the (located) t stays the same: cells of
    /// a raster row then evaluate each point's τ piece once per bucket instead of once per cell
    /// (the local error checks evaluate a region's cells row by row; BENCHMARKS.md "Fit CPU on
    /// the largest mesh, again: bit-identical levers"). Same terms (a point counts where its
    /// support holds (s, t) and both factors are non-zero), same products w·N(s)·N(t), summed
    /// in the bucket's order.
    #[inline]
    pub(crate) fn point_z_cached(&self, s: f64, t: f64, row: &mut RowCache) -> f64 {
        let Some((s, t, ls, lt)) = self.locate(s, t) else { return f64::NAN };
        let k = self.degree.k();
        let b = self.bucket(s, t);
        let key = (t.to_bits(), lt);
        if row.key != Some(key) {
            row.key = Some(key);
            row.stamp = row.stamp.wrapping_add(1);
            row.terms.clear();
            if row.slots.len() != self.grid.ns as usize {
                row.slots = vec![(u32::MAX, 0, 0, 0); self.grid.ns as usize];
            }
        }
        let slot = b % self.grid.ns as usize;
        let (stamp, sb, from, to) = row.slots[slot];
        let (from, to) = if stamp == row.stamp && sb == b as u32 {
            (from as usize, to as usize)
        } else {
            let from = row.terms.len();
            for &pi in &self.pt_items[self.pt_start[b] as usize..self.pt_start[b + 1] as usize] {
                let kn = &self.knots[pi as usize];
                if t < kn[5] || t > kn[5 + k + 1] {
                    continue;
                }
                let bt = basis_poly(&kn[5..10], self.pieces(pi as usize).1, k, t, lt);
                if bt != 0.0 {
                    row.terms.push((pi, bt));
                }
            }
            row.slots[slot] = (row.stamp, b as u32, from as u32, row.terms.len() as u32);
            (from, row.terms.len())
        };
        let (mut z, mut den) = (0.0, 0.0);
        for &(pi, bt) in &row.terms[from..to] {
            let kn = &self.knots[pi as usize];
            if s < kn[0] || s > kn[k + 1] {
                continue;
            }
            let bs = basis_poly(&kn[0..5], self.pieces(pi as usize).0, k, s, ls);
            if bs == 0.0 {
                continue;
            }
            let g = &self.geom[pi as usize];
            let wn = g[3] * bs * bt;
            z += wn * g[2];
            den += wn;
        }
        if den == 0.0 {
            return f64::NAN;
        }
        z / den
    }

    /// The unnormalised Σ w_i N_i at (s, t) (partition-of-unity checks), NaN outside.
    pub fn weight_sum(&self, s: f64, t: f64) -> f64 {
        let Some((s, t, ls, lt)) = self.locate(s, t) else { return f64::NAN };
        self.weighted_bases(s, t, ls, lt).fold(0.0, |den, (_, wn)| den + wn)
    }

    /// The points listed in the buckets that the rectangle `s` × `t` (lo, hi) meets, each once:
    /// a point is taken in the first bucket its support shares with the rectangle (`first`
    /// from `extraction::first_buckets`), so no sort or dedup is needed afterwards. A superset
    /// of the points whose support meets the rectangle; callers test the overlap they need.
    /// Plain loops calling `f` with each point: a nested `flat_map` iterator was ~4 % of a fit's
    /// samples in its own bookkeeping (`and_then_or_clear`), in the pattern and the cells'
    /// element lists.
    #[inline]
    pub(crate) fn for_points_in_buckets_once(
        &self,
        s: (f64, f64),
        t: (f64, f64),
        first: &[[u32; 2]],
        mut f: impl FnMut(u32),
    ) {
        let (i0, i1) = self.grid.index_range(s.0, s.1, true);
        let (j0, j1) = self.grid.index_range(t.0, t.1, false);
        for bj in j0..=j1 {
            for bi in i0..=i1 {
                let b = (bj * self.grid.ns + bi) as usize;
                for &p in &self.pt_items[self.pt_start[b] as usize..self.pt_start[b + 1] as usize] {
                    let fb = first[p as usize];
                    if bi == i0.max(fb[0]) && bj == j0.max(fb[1]) {
                        f(p);
                    }
                }
            }
        }
    }

    /// (PB index, w_i N_i(s, t)) of the points of the bucket of (s, t) whose blending function
    /// is non-zero there ((s, t) as [`PbSpline::locate`] returned it): the one loop behind
    /// [`PbSpline::point`], [`PbSpline::weight_sum`] and [`PbSpline::for_each_basis`], mirrored
    /// by `weighted_basis` in common.cl (same tests, same operation order). Zero terms are
    /// left out: adding them changes no sum.
    #[inline]
    fn weighted_bases(&self, s: f64, t: f64, ls: bool, lt: bool) -> impl Iterator<Item = (u32, f64)> + '_ {
        let k = self.degree.k();
        let b = self.bucket(s, t);
        self.pt_items[self.pt_start[b] as usize..self.pt_start[b + 1] as usize].iter().filter_map(move |&pi| {
            let kn = &self.knots[pi as usize];
            if s < kn[0] || s > kn[k + 1] || t < kn[5] || t > kn[5 + k + 1] {
                return None;
            }
            let (ps, pt) = self.pieces(pi as usize);
            let bs = basis_poly(&kn[0..5], ps, k, s, ls);
            if bs == 0.0 {
                return None;
            }
            let bt = basis_poly(&kn[5..10], pt, k, t, lt);
            if bt == 0.0 {
                return None;
            }
            Some((pi, self.geom[pi as usize][3] * bs * bt))
        })
    }

    /// Whether dense evaluation of `n` points goes through the element extraction: building it
    /// costs about as much as evaluating a few points per element, so small batches (the
    /// fit's per-control-point evaluations) stay on the PB-spline path.
    /// The OpenCL side applies the same rule ([`use_extraction`]), so both devices take the
    /// same path for the same batch and give identical numbers (the kernels mirror the CPU
    /// operation order), which keeps fits device-independent.
    #[inline]
    pub fn use_extraction(&self, n: usize) -> bool {
        use_extraction(n, self.cells.len())
    }

    /// Heights at many parameter points, in parallel (rayon) or on one thread. Large batches go
    /// through the per-element polynomial extraction ([`Extraction`], rebuilt from the current
    /// `geom` on every call), equal to [`PbSpline::point`] to rounding (tested to 1e-12).
    pub fn eval_z(&self, st: &[[f64; 2]], parallel: bool) -> Vec<f64> {
        if self.use_extraction(st.len()) {
            return Extraction::new(self, parallel).eval_z(self, st, parallel);
        }
        if parallel {
            st.par_iter().with_min_len(4096).map(|p| self.point(p[0], p[1])[2]).collect()
        } else {
            st.iter().map(|p| self.point(p[0], p[1])[2]).collect()
        }
    }

    /// Heights on a regular grid: point (i, j) at (s0 + i·ds, t0 + j·dt), row-major in j.
    pub fn eval_grid(&self, g: &GridSpec, parallel: bool) -> Vec<f64> {
        let n = g.ns * g.nt;
        if self.use_extraction(n) {
            return Extraction::new(self, parallel).eval_grid(self, g, parallel);
        }
        let f = |idx: usize| {
            let i = idx % g.ns;
            let j = idx / g.ns;
            self.point(g.s0 + i as f64 * g.ds, g.t0 + j as f64 * g.dt)[2]
        };
        if parallel {
            (0..g.ns * g.nt).into_par_iter().with_min_len(4096).map(f).collect()
        } else {
            (0..g.ns * g.nt).map(f).collect()
        }
    }

    /// Floating-point operations per evaluated point of [`PbSpline::eval_z`] on `st`, counted
    /// on a sample of it (for the benchmark; compares count as one flop each, as before).
    ///
    /// Element path (cubic): 4 compares of the element test per candidate, 2 subtractions + 2
    /// multiplications for (u, v), 2 bicubic Horner forms (4 rows × 6 + 6 = 30 each), 1
    /// division, 1 compare (den = 0): 66 + 4 × candidates; degree 1: 2 × (2·2 + 2) = 12 → 18 +
    /// 4 × candidates. The sample is every ⌈n/10⁴⌉-th point (not the first rows of a grid,
    /// which would over-weight its lower border). Points on the reference path cost [`PbSpline::flops_reference`].
    pub fn flops_estimate(&self, st: &[[f64; 2]]) -> f64 {
        if !self.use_extraction(st.len()) {
            return self.flops_reference(st);
        }
        let ex = Extraction::new(self, true);
        let (fast, tests) = ex.path_stats(st);
        let k = self.degree.k();
        let horner = if k == 3 { 30.0 } else { 6.0 };
        let elem = 4.0 + 2.0 * horner + 2.0;
        // reference points: restricted to the sample's slow ones would need their list; the
        // mean over the sample is a fair upper bound for them.
        tests * 4.0 + fast * elem + (1.0 - fast) * self.flops_reference(st)
    }

    /// Flops per point of the PB-spline path ([`PbSpline::point`]), from the average number of
    /// candidates and non-zero basis functions at the given sample.
    pub fn flops_reference(&self, st: &[[f64; 2]]) -> f64 {
        let k = self.degree.k() as f64;
        // One basis function: (K+1) indicator tests + Σ_{r=1..K} (K+1−r) · 8 flops.
        // polynomial pieces: span search (≤ K+1 double compares), (u − a)·(1/h), Horner (2K flops)
        let basis_flops = 2.0 * (k + 1.0) + 2.0 + 2.0 * k;
        let mut cand = 0usize;
        let mut hit = 0usize;
        let step = st.len().div_ceil(10000).max(1);
        for p in st.iter().step_by(step) {
            let b = self.bucket(p[0], p[1]);
            let items = &self.pt_items[self.pt_start[b] as usize..self.pt_start[b + 1] as usize];
            cand += items.len();
            hit += items
                .iter()
                .filter(|&&i| {
                    let kn = &self.knots[i as usize];
                    kn[0] <= p[0]
                        && p[0] <= kn[self.degree.k() + 1]
                        && kn[5] <= p[1]
                        && p[1] <= kn[5 + self.degree.k() + 1]
                })
                .count();
        }
        let n = st.len().div_ceil(step).max(1) as f64;
        // 4 compares per candidate; per hit 2 basis evaluations + 2 mul + 4 fma (8 flops) ; final 3 divisions.
        (cand as f64 * 4.0 + hit as f64 * (2.0 * basis_flops + 10.0)) / n + 3.0
    }
}

/// Dense batches of at least this many points per leaf cell use the element extraction.
pub const EXTRACTION_POINTS_PER_CELL: usize = 4;

/// Whether a batch of `n` points on a mesh with `cells` leaf cells uses the extraction.
#[inline]
pub fn use_extraction(n: usize, cells: usize) -> bool {
    n >= EXTRACTION_POINTS_PER_CELL * cells.max(1)
}

/// A regular evaluation grid in parameter space.
#[derive(Debug, Clone, Copy)]
pub struct GridSpec {
    pub s0: f64,
    pub t0: f64,
    pub ds: f64,
    pub dt: f64,
    pub ns: usize,
    pub nt: usize,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{ControlPoint, Degree, TMesh};

    use crate::testing::lcg;

    /// The row-cached height is [`PbSpline::point`]'s to the bit (NaN where it is NaN), on
    /// meshes with T-junctions and non-unit weights, at cells on and between mesh lines,
    /// outside the domain and on its borders; one cache over many rows and also one per row.
    #[test]
    fn row_cached_heights_equal_point() {
        let mut seed = 7u64;
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut pb = PbSpline::build(&crate::testing::refined_mesh(degree));
            for g in &mut pb.geom {
                g[2] = 10.0 * lcg(&mut seed) - 5.0;
                g[3] = 0.5 + lcg(&mut seed);
            }
            let (mut shared, mut checked) = (RowCache::default(), 0);
            for j in -3..110 {
                let mut row = RowCache::default();
                for i in -3..110 {
                    for (s, t) in [(i as f64, j as f64), (i as f64 + 0.25, j as f64 * 0.5)] {
                        let want = self::PbSpline::point(&pb, s, t)[2];
                        for cache in [&mut row, &mut shared] {
                            let got = pb.point_z_cached(s, t, cache);
                            assert!(
                                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                                "{degree:?} ({s}, {t}): {got} vs {want}"
                            );
                        }
                        checked += want.is_finite() as usize;
                    }
                }
            }
            assert!(checked > 5000, "{checked} finite heights");
        }
    }

    /// A PB-spline reduced to its points and knots and compiled again is the same, bit for
    /// bit (coarsening and the large-raster solves rely on it).
    #[test]
    fn knots_only_round_trip_is_exact() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut m = crate::testing::aniso_mesh(degree, 7, 3);
            let mut seed = 3u64;
            for p in &mut m.points {
                p.z = 10.0 * lcg(&mut seed) - 5.0;
            }
            let a = PbSpline::build(&m);
            let b = PbSpline::from_knots(&m, a.clone().into_knots());
            assert_eq!(a.point_ids, b.point_ids);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a.knots.as_flattened()), bits(b.knots.as_flattened()), "{degree:?}");
            assert_eq!(bits(&a.poly), bits(&b.poly));
            assert_eq!(bits(a.geom.as_flattened()), bits(b.geom.as_flattened()));
            assert_eq!(bits(a.cells.as_flattened()), bits(b.cells.as_flattened()));
            assert_eq!(
                (a.pt_start, a.pt_items, a.cell_start, a.cell_items),
                (b.pt_start, b.pt_items, b.cell_start, b.cell_items)
            );
        }
    }

    #[test]
    fn polynomial_pieces_equal_cox_de_boor() {
        let mut seed = 1u64;
        for kn in [
            [0., 1., 2., 3., 4.],
            [0., 0., 0., 1., 2.],
            [0., 0., 1., 2., 2.],
            [1., 3., 3.5, 8., 9.],
            [2., 2., 2., 2.5, 2.5],
        ] {
            for k in [1usize, 3] {
                let pc = basis_pieces(&kn, k);
                for _ in 0..500 {
                    let u = kn[0] - 0.5 + (kn[k + 1] - kn[0] + 1.0) * lcg(&mut seed);
                    for left in [false, true] {
                        let a = basis(&kn, k, u, left);
                        let b = basis_poly(&kn, &pc, k, u, left);
                        assert!((a - b).abs() < 1e-14, "{kn:?} k={k} u={u}: {a} vs {b}");
                    }
                }
                for &u in &kn[..k + 2] {
                    for left in [false, true] {
                        assert!((basis(&kn, k, u, left) - basis_poly(&kn, &pc, k, u, left)).abs() < 1e-14);
                    }
                }
            }
        }
    }

    #[test]
    fn basis_known_values() {
        // uniform cubic B-spline on [0,1,2,3,4]: 1/6, 2/3, 1/6 at 1, 2, 3
        let kn = [0., 1., 2., 3., 4.];
        assert!((basis(&kn, 3, 1.0, false) - 1.0 / 6.0).abs() < 1e-15);
        assert!((basis(&kn, 3, 2.0, false) - 2.0 / 3.0).abs() < 1e-15);
        assert!((basis(&kn, 3, 3.0, false) - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(basis(&kn, 3, 4.0, false), 0.0);
        // hat function
        assert!((basis(&[0., 1., 2.], 1, 0.5, false) - 0.5).abs() < 1e-15);
        // A1: the upper border value is the inside limit
        assert_eq!(basis(&[1., 2., 2.], 1, 2.0, false), 0.0);
        assert_eq!(basis(&[1., 2., 2.], 1, 2.0, true), 1.0);
    }

    /// A refined mesh that stays analysis-suitable: linear with one 4-split; cubic with a whole
    /// band of cells split (T-junction extensions are parallel). A single 4-split in a cubic mesh
    /// is NOT analysis-suitable (the edge extensions meet at the centre) and Σ N ≠ 1 there —
    /// which is why evaluation always normalises (rational form).
    pub(crate) fn standard_refined(degree: Degree) -> TMesh {
        let mut m = TMesh::grid(degree, 0.0, 0.0, 4.0, 8, 8);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        if degree == Degree::Linear {
            let c = m.leaves_in(crate::mesh::Rect::new(15.0, 15.0, 15.5, 15.5))[0];
            m.split(c, &mut g);
        } else {
            for c in m.leaves_in(crate::mesh::Rect::new(0.5, 13.0, 31.5, 15.0)) {
                m.split(c, &mut g);
            }
        }
        m
    }

    #[test]
    fn partition_of_unity_in_the_interior_of_a_refined_standard_mesh() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let m = standard_refined(degree);
            let pb = PbSpline::build(&m);
            let mut seed = 7u64;
            // interior: two cells away from the border
            for _ in 0..5000 {
                let s = 8.0 + 16.0 * lcg(&mut seed);
                let t = 8.0 + 16.0 * lcg(&mut seed);
                let sum = pb.weight_sum(s, t);
                assert!((sum - 1.0).abs() < 1e-12, "{degree:?} Σ N = {sum} at ({s},{t})");
            }
        }
        // the counter-example: a single split in a cubic mesh
        let mut m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 4.0, 6, 6);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        let c = m.leaves_in(crate::mesh::Rect::new(11.0, 11.0, 11.5, 11.5))[0];
        m.split(c, &mut g);
        let pb = PbSpline::build(&m);
        assert!((pb.weight_sum(11.945698134713837, 15.645276307242288) - 1.0).abs() > 1e-3);
    }

    #[test]
    fn nan_outside_and_border_handled() {
        let mut m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 1.0, 3, 3);
        for p in &mut m.points {
            p.z = 2.0 + p.s;
        }
        let pb = PbSpline::build(&m);
        assert!(pb.point(-0.1, 1.0)[2].is_nan());
        assert!(pb.point(1.0, 3.0001)[2].is_nan());
        // corners and upper borders are finite (A1)
        for (s, t) in [(3.0, 3.0), (0.0, 0.0), (3.0, 1.5), (1.5, 3.0)] {
            assert!(pb.point(s, t)[2].is_finite(), "({s},{t})");
        }
        // the upper border equals the limit from inside
        let a = pb.point(3.0, 1.5)[2];
        let b = pb.point(3.0 - 1e-9, 1.5)[2];
        assert!((a - b).abs() < 1e-7);
    }

    /// Planes are reproduced exactly by the linear T-spline on a refined mesh (control points on
    /// the plane), and by the cubic one where Σ N = 1 with control points at the Greville
    /// abscissae of their local knots.
    #[test]
    fn planes_reproduced_on_refined_meshes() {
        let plane = |x: f64, y: f64| 3.0 + 0.25 * x - 0.5 * y;
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut m = standard_refined(degree);
            let pb0 = PbSpline::build(&m);
            let k = degree.k();
            for (i, &pid) in pb0.point_ids.iter().enumerate() {
                let kn = pb0.knots[i];
                let gs = kn[1..=k].iter().sum::<f64>() / k as f64;
                let gt = kn[6..=5 + k].iter().sum::<f64>() / k as f64;
                let p: &mut ControlPoint = &mut m.points[pid as usize];
                p.x = gs;
                p.y = gt;
                p.z = plane(gs, gt);
            }
            let pb = PbSpline::build(&m);
            let mut seed = 3u64;
            let (a, b) = if degree == Degree::Linear { (0.0, 32.0) } else { (8.0, 24.0) };
            for _ in 0..3000 {
                let s = a + (b - a) * lcg(&mut seed);
                let t = a + (b - a) * lcg(&mut seed);
                let p = pb.point(s, t);
                assert!((p[2] - plane(p[0], p[1])).abs() < 1e-12, "{degree:?} at ({s},{t})");
                assert!((p[0] - s).abs() < 1e-12 && (p[1] - t).abs() < 1e-12);
            }
        }
    }
}
