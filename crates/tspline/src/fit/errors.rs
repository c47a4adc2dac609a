//! The error check (decisions A7/A17): |Δz| at every valid cell, in blocks, its statistics and
//! the leaves over the tolerance.

use super::*;

/// The parameter pair of PB point i (the centre knots).
pub(super) fn pb_param(pb: &PbSpline, i: usize) -> [f64; 2] {
    let h = pb.degree.half();
    [pb.knots[i][h], pb.knots[i][5 + h]]
}

/// Streaming sums of |Δz| over a block of cells (merged in block order: deterministic).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ErrAcc {
    n: usize,
    sum: f64,
    sumsq: f64,
    max: f64,
    over: usize,
}

impl ErrAcc {
    #[inline]
    fn push(&mut self, e: f64, tol: f64) {
        self.n += 1;
        self.sum += e;
        self.sumsq += e * e;
        self.max = self.max.max(e);
        self.over += (e > tol) as usize;
    }
    fn merge(&mut self, o: &ErrAcc) {
        self.n += o.n;
        self.sum += o.sum;
        self.sumsq += o.sumsq;
        self.max = self.max.max(o.max);
        self.over += o.over;
    }
}

/// Cells per evaluation block of the error pass (fixed, so sums do not depend on the threads).
pub(super) const PASS_BLOCK: usize = 1 << 16;
/// Cells per dense evaluation call of the error pass (at least 16 per leaf cell).
pub(super) const PASS_BLOCK_EVAL: usize = 1 << 22;

/// |Δz| at every valid cell into `errs` (NaN at no-data cells; +∞ where the surface is
/// undefined), the surface evaluated in big row blocks (CPU in parallel, or the OpenCL grid
/// kernel per block): the dense evaluators amortise their per-call set-up (e.g. an element
/// extraction) over a block, and only one block of heights is held at a time.
pub fn eval_errors(pb: &PbSpline, samples: &Samples, backend: &Backend, errs: &mut [f64]) -> Result<(), TsplineError> {
    let pass = ErrorPass::new(pb, samples, backend)?;
    for (b, out) in errs.chunks_mut(pass.block_cells()).enumerate() {
        pass.block(b * pass.rows, out)?;
    }
    Ok(())
}

/// The count of valid cells over the tolerance and the leaves holding them ([`summarize`]'s
/// `over_tolerance` and leaf list), by the error pass of [`eval_errors`] into one block-sized
/// buffer instead of a per-cell array: the same errors, so the same verdict. Coarsening's global
/// tries ask this first, so a failed try leaves the kept errors as they are and needs no copy
/// of them to undo (docs/decisions.md#float32-samples).
pub(crate) fn over_tolerance(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    backend: &Backend,
    tol: &Tolerance,
) -> Result<(usize, Vec<CellId>), TsplineError> {
    let pass = ErrorPass::new(pb, samples, backend)?;
    let w = samples.width;
    let n = samples.z.len();
    let (mut count, mut over) = (0, Vec::new());
    for q0 in (0..n).step_by(pass.block_cells()) {
        // the errors in the evaluation's own array: one block-sized buffer, not two
        let out = pass.block_errors(q0 / w, pass.block_cells().min(n - q0))?;
        let (acc, o) = over_in(mesh, pb, &|q| ((q % w) as f64, (q / w) as f64), &out, q0, tol);
        count += acc.over;
        over.extend(o);
    }
    over.sort_unstable();
    over.dedup();
    Ok((count, over))
}

/// The error pass over a raster in big row blocks: the dense evaluators amortise their per-call
/// set-up (an element extraction, an OpenCL upload) over all blocks.
pub(super) struct ErrorPass<'a> {
    pb: &'a PbSpline,
    samples: &'a Samples,
    backend: &'a Backend<'a>,
    sp: Option<crate::ocl_eval::OclSpline>,
    ex: Option<crate::extraction::Extraction>,
    /// Rows per parallel chunk of the |Δz| loop and per evaluation block.
    sub: usize,
    rows: usize,
}

impl<'a> ErrorPass<'a> {
    fn new(pb: &'a PbSpline, samples: &'a Samples, backend: &'a Backend<'a>) -> Result<ErrorPass<'a>, TsplineError> {
        let w = samples.width;
        let sub = (PASS_BLOCK / w.max(1)).max(1);
        let rows = ((PASS_BLOCK_EVAL.max(16 * pb.cells.len()) / w.max(1)).max(1) / sub).max(1) * sub;
        let sp = match backend {
            Backend::OpenCl(o) => Some(o.upload(pb)?),
            Backend::Cpu => None,
        };
        // CPU: one extraction for all blocks (as the OpenCL upload above), not one per block; each
        // block still takes the path PbSpline::eval_grid would (same numbers).
        let ex = (sp.is_none() && pb.use_extraction(rows * w)).then(|| crate::extraction::Extraction::new(pb, true));
        Ok(ErrorPass { pb, samples, backend, sp, ex, sub, rows })
    }

    fn block_cells(&self) -> usize {
        self.rows * self.samples.width
    }

    /// Surface heights of the `cells` cells (whole rows) from row `j0` on.
    fn heights(&self, j0: usize, cells: usize) -> Result<Vec<f64>, TsplineError> {
        let (pb, w) = (self.pb, self.samples.width);
        let g = GridSpec { s0: 0.0, t0: j0 as f64, ds: 1.0, dt: 1.0, ns: w, nt: cells / w };
        Ok(match (self.backend, &self.sp, &self.ex) {
            (Backend::OpenCl(o), Some(sp), _) => o.eval_grid(sp, &g)?,
            (_, _, Some(ex)) if pb.use_extraction(cells) => ex.eval_grid(pb, &g, true),
            _ => pb.eval_grid(&g, true),
        })
    }

    /// |Δz| of the rows from `j0` on into `out` (whole rows).
    fn block(&self, j0: usize, out: &mut [f64]) -> Result<(), TsplineError> {
        let w = self.samples.width;
        let z = self.heights(j0, out.len())?;
        match self.samples.z.slice(j0 * w, j0 * w + out.len()) {
            HeightsSlice::F64(d) => errors_into(out, &z, d, self.sub * w),
            HeightsSlice::F32(d) => errors_into(out, &z, d, self.sub * w),
        }
        Ok(())
    }

    /// [`ErrorPass::block`] of `cells` cells written over the heights' own array.
    fn block_errors(&self, j0: usize, cells: usize) -> Result<Vec<f64>, TsplineError> {
        let w = self.samples.width;
        let mut z = self.heights(j0, cells)?;
        match self.samples.z.slice(j0 * w, j0 * w + cells) {
            HeightsSlice::F64(d) => errors_in_place(&mut z, d, self.sub * w),
            HeightsSlice::F32(d) => errors_in_place(&mut z, d, self.sub * w),
        }
        Ok(z)
    }
}

/// [`errors_into`] with the heights `z` replaced by their errors.
fn errors_in_place<T: Height>(z: &mut [f64], d: &[T], chunk: usize) {
    z.par_chunks_mut(chunk).zip(d.par_chunks(chunk)).for_each(|(zc, dc)| {
        for (e, &dk) in zc.iter_mut().zip(dc) {
            let (zk, dk) = (*e, dk.f64());
            *e = if dk.is_nan() {
                f64::NAN
            } else if zk.is_nan() {
                f64::INFINITY
            } else {
                (zk - dk).abs()
            };
        }
    });
}

/// |Δz| of the surface heights `z` against the data `d` into `out` (NaN where `d` has no data,
/// +∞ where the surface is undefined), in parallel over chunks of `chunk` cells.
pub(super) fn errors_into<T: Height>(out: &mut [f64], z: &[f64], d: &[T], chunk: usize) {
    out.par_chunks_mut(chunk).zip(z.par_chunks(chunk)).zip(d.par_chunks(chunk)).for_each(|((o, zc), dc)| {
        for ((e, &zk), &dk) in o.iter_mut().zip(zc).zip(dc) {
            let dk = dk.f64();
            *e = if dk.is_nan() {
                f64::NAN
            } else if zk.is_nan() {
                f64::INFINITY
            } else {
                (zk - dk).abs()
            };
        }
    });
}

/// [`eval_errors`] restricted to the cells of `region` (PB-spline path, point by point).
pub(crate) fn eval_errors_region(pb: &PbSpline, samples: &Samples, region: &Region, errs: &mut [f64]) {
    let w = samples.width;
    let sub = (PASS_BLOCK / w.max(1)).max(1);
    errs.par_chunks_mut(sub * w).enumerate().for_each(|(b, out)| {
        let j0 = b * sub;
        let j1 = j0 + out.len() / w;
        let mut row = crate::eval::RowCache::default();
        region.for_rows(j0, j1, |q| out[q - j0 * w] = region_error(pb, samples, q, &mut row));
    });
}

/// |Δz| at raster cell `q` on the PB-spline path ([`eval_errors_region`]'s value): the height
/// of [`PbSpline::point`], with the τ factors cached along the row in `row`.
#[inline]
pub(super) fn region_error(pb: &PbSpline, samples: &Samples, q: usize, row: &mut crate::eval::RowCache) -> f64 {
    let w = samples.width;
    let dk = samples.z.get(q);
    if dk.is_nan() {
        f64::NAN
    } else {
        let zk = pb.point_z_cached((q % w) as f64, (q / w) as f64, row);
        if zk.is_nan() {
            f64::INFINITY
        } else {
            (zk - dk).abs()
        }
    }
}

/// [`over_tolerance`] of a local try: the count of valid cells of `region` over the tolerance
/// and the leaves holding them, from the errors [`eval_errors_region`] would write, computed
/// one row block at a time into a block-sized buffer (no per-cell array). Coarsening's local
/// tries ask this first and write `errs` only once a try has passed, so a failed try needs no
/// copy of the region's old errors to undo (docs/decisions.md#coarsening-decides-before-it-writes).
/// Cells outside `region` keep errors within the tolerance (every kept state passes at every
/// cell), so the verdict and the leaves are those of [`summarize`] over the whole updated array.
/// On a raster of at most [`KEEP_VERDICT_CELLS`] cells the blocks are kept, for
/// [`RegionErrors::write`] to put into `errs` when the try passes, instead of evaluating them
/// again.
pub(crate) fn over_tolerance_region(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    region: &Region,
    tol: &Tolerance,
) -> (usize, Vec<CellId>, RegionErrors) {
    let w = samples.width;
    let sub = (PASS_BLOCK / w.max(1)).max(1);
    let blocks = samples.height.div_ceil(sub);
    let keep = samples.z.len() <= KEEP_VERDICT_CELLS;
    let pos = |q: usize| ((q % w) as f64, (q / w) as f64);
    let scan = OverScan::new(mesh, pb, &pos, tol);
    let parts: Vec<(usize, Vec<CellId>, Option<Vec<f64>>)> = (0..blocks)
        .into_par_iter()
        .map_init(
            || (Vec::new(), crate::eval::RowCache::default()),
            |(buf, row): &mut (Vec<f64>, crate::eval::RowCache), b| {
                let j0 = b * sub;
                let j1 = (j0 + sub).min(samples.height);
                buf.clear();
                buf.resize((j1 - j0) * w, f64::NAN);
                let mut any = false;
                region.for_rows(j0, j1, |q| {
                    buf[q - j0 * w] = region_error(pb, samples, q, row);
                    any = true;
                });
                if !any {
                    return (0, Vec::new(), None);
                }
                let (acc, over) = scan.chunk(buf, j0 * w);
                (acc.over, over, keep.then(|| std::mem::take(buf)))
            },
        )
        .collect();
    let mut count = 0;
    let mut over = Vec::new();
    let mut kept = Vec::with_capacity(if keep { blocks } else { 0 });
    for (c, o, k) in parts {
        count += c;
        over.extend(o);
        if keep {
            kept.push(k);
        }
    }
    over.sort_unstable();
    over.dedup();
    (count, over, RegionErrors { rows: sub, blocks: kept })
}

/// Rasters up to this many cells keep the region errors of a local try's verdict
/// ([`over_tolerance_region`]) for the check that follows a pass: at most 64 MiB, while on
/// 10⁸-cell rasters a copy of a region's errors is what the verdict exists to avoid
/// (docs/decisions.md#coarsening-decides-before-it-writes). The second evaluation of the region
/// was ~0.07 s of the BAG at 0.1 m.
pub(crate) const KEEP_VERDICT_CELLS: usize = 1 << 23;

/// A verdict's region errors by blocks of `rows` raster rows (None: no cell of the region in
/// that block); no blocks when they were not kept.
#[derive(Default)]
pub(crate) struct RegionErrors {
    rows: usize,
    blocks: Vec<Option<Vec<f64>>>,
}

impl RegionErrors {
    /// Whether the blocks were kept.
    pub(crate) fn kept(&self) -> bool {
        !self.blocks.is_empty()
    }

    /// Writes the kept errors of the cells of `region` into `errs` (a raster `w` wide): what
    /// [`eval_errors_region`] writes, without evaluating the surface again.
    pub(crate) fn write(&self, region: &Region, w: usize, errs: &mut [f64]) {
        errs.par_chunks_mut(self.rows * w).zip(&self.blocks).enumerate().for_each(|(b, (out, block))| {
            let Some(block) = block else { return };
            let j0 = b * self.rows;
            region.for_rows(j0, j0 + out.len() / w, |q| out[q - j0 * w] = block[q - j0 * w]);
        });
    }
}

/// Statistics of `errs` over the valid cells (summed over fixed blocks in order: independent of
/// the thread count) and the leaf cells whose closed box holds a cell over the tolerance.
/// The median is that of the errors rounded to f32 (`nth_smallest_f32`, no copy of the
/// errors); the maximum and the tolerance test use the f64 errors.
pub fn summarize(mesh: &TMesh, pb: &PbSpline, w: usize, errs: &[f64], tol: &Tolerance) -> (ErrorStats, Vec<CellId>) {
    summarize_at(mesh, pb, &|q| ((q % w) as f64, (q / w) as f64), errs, tol)
}

/// [`summarize`] with the parameter position of error `q` given by `pos`.
pub(crate) fn summarize_at(
    mesh: &TMesh,
    pb: &PbSpline,
    pos: &(dyn Fn(usize) -> (f64, f64) + Sync),
    errs: &[f64],
    tol: &Tolerance,
) -> (ErrorStats, Vec<CellId>) {
    let (acc, over) = over_in(mesh, pb, pos, errs, 0, tol);
    let n = acc.n;
    if n == 0 {
        return (ErrorStats::default(), over);
    }
    let mean = acc.sum / n as f64;
    let sigma = (acc.sumsq / n as f64 - mean * mean).max(0.0).sqrt();
    let mid = n / 2;
    let median = if n % 2 == 0 {
        let [m, lo] = nth_smallest_f32(errs, [mid, mid - 1]);
        0.5 * (m as f64 + lo as f64)
    } else {
        nth_smallest_f32(errs, [mid])[0] as f64
    };
    (
        ErrorStats {
            count: n,
            mean,
            sigma,
            median,
            max: acc.max,
            rms: (acc.sumsq / n as f64).sqrt(),
            over_tolerance: acc.over,
        },
        over,
    )
}

/// The statistics of `errs` (errors `offset..` of the raster or point list) and the leaf cells
/// whose closed box holds one over the tolerance (sorted, each once): the scan of [`summarize_at`]
/// without the median, summed over fixed blocks in order.
pub(super) fn over_in(
    mesh: &TMesh,
    pb: &PbSpline,
    pos: &(dyn Fn(usize) -> (f64, f64) + Sync),
    errs: &[f64],
    offset: usize,
    tol: &Tolerance,
) -> (ErrAcc, Vec<CellId>) {
    let scan = OverScan::new(mesh, pb, pos, tol);
    let parts: Vec<(ErrAcc, Vec<CellId>)> =
        errs.par_chunks(PASS_BLOCK).enumerate().map(|(b, ch)| scan.chunk(ch, offset + b * PASS_BLOCK)).collect();
    let mut acc = ErrAcc::default();
    let mut over = Vec::new();
    for (a, o) in parts {
        acc.merge(&a);
        over.extend(o);
    }
    over.sort_unstable();
    over.dedup();
    (acc, over)
}

/// The per-block scan of [`over_in`]: statistics of a run of errors and the leaves holding the
/// ones over the tolerance.
pub(super) struct OverScan<'a> {
    mesh: &'a TMesh,
    pb: &'a PbSpline,
    pos: &'a (dyn Fn(usize) -> (f64, f64) + Sync),
    tol: &'a Tolerance,
    leaf_ids: Vec<CellId>,
    same_order: bool,
}

impl<'a> OverScan<'a> {
    fn new(
        mesh: &'a TMesh,
        pb: &'a PbSpline,
        pos: &'a (dyn Fn(usize) -> (f64, f64) + Sync),
        tol: &'a Tolerance,
    ) -> OverScan<'a> {
        let leaf_ids: Vec<CellId> = mesh.leaves().collect();
        let same_order = leaf_ids.len() == pb.cells.len();
        OverScan { mesh, pb, pos, tol, leaf_ids, same_order }
    }

    /// Leaves whose closed box holds (s, t): through the PB-spline's bucket grid when its cell
    /// list is the mesh's leaves in id order (checked per hit), else through the R-tree.
    fn leaves_at(&self, s: f64, t: f64, f: &mut dyn FnMut(CellId, crate::mesh::Rect)) {
        let (mesh, pb) = (self.mesh, self.pb);
        if self.same_order {
            let (bi, _) = pb.grid.index_range(s, s, true);
            let (bj, _) = pb.grid.index_range(t, t, false);
            let b = (bj * pb.grid.ns + bi) as usize;
            let mut ok = true;
            let mut hits: [(CellId, crate::mesh::Rect); 8] = [(0, crate::mesh::Rect::new(0.0, 0.0, 0.0, 0.0)); 8];
            let mut nh = 0;
            for &ci in &pb.cell_items[pb.cell_start[b] as usize..pb.cell_start[b + 1] as usize] {
                let c = pb.cells[ci as usize];
                if s < c[0] || s > c[2] || t < c[1] || t > c[3] {
                    continue;
                }
                let id = self.leaf_ids[ci as usize];
                let r = mesh.cells[id as usize].rect;
                if nh == hits.len() || r != crate::mesh::Rect::new(c[0], c[1], c[2], c[3]) {
                    ok = false;
                    break;
                }
                hits[nh] = (id, r);
                nh += 1;
            }
            if ok && nh > 0 {
                for &(id, r) in &hits[..nh] {
                    f(id, r);
                }
                return;
            }
        }
        for c in mesh.cells_at(s, t) {
            let cell = &mesh.cells[c as usize];
            if cell.is_leaf() {
                f(c, cell.rect);
            }
        }
    }

    /// Errors `ch` of cells (points) `q0..`: their sums (NaN skipped) and the leaves holding
    /// those over the tolerance (sorted, each once).
    fn chunk(&self, ch: &[f64], q0: usize) -> (ErrAcc, Vec<CellId>) {
        let mut acc = ErrAcc::default();
        let mut over = Vec::new();
        let mut interior: Option<crate::mesh::Rect> = None;
        for (k, &e) in ch.iter().enumerate() {
            if e.is_nan() {
                continue;
            }
            let tq = self.tol.at(q0 + k);
            acc.push(e, tq);
            if e <= tq {
                continue;
            }
            let (s, t) = (self.pos)(q0 + k);
            if let Some(r) = interior {
                if r.s_min < s && s < r.s_max && r.t_min < t && t < r.t_max {
                    continue; // the only leaf holding this cell is already collected
                }
            }
            interior = None;
            let mut hits: [CellId; 4] = [0; 4];
            let mut nh = 0;
            let mut owner = None;
            self.leaves_at(s, t, &mut |c, r| {
                if nh < hits.len() {
                    hits[nh] = c;
                    nh += 1;
                } else {
                    over.push(c);
                }
                if r.s_min < s && s < r.s_max && r.t_min < t && t < r.t_max {
                    interior = Some(r);
                }
                if r.s_min <= s && s < r.s_max && r.t_min <= t && t < r.t_max && r.width().min(r.height()) >= 2.0 {
                    owner = Some(c);
                }
            });
            // A7: a cell on a shared edge or corner marks only the leaf whose half-open box
            // holds it, unless that one is at the minimum size
            match owner {
                Some(c) => over.push(c),
                None => over.extend_from_slice(&hits[..nh]),
            }
        }
        over.sort_unstable();
        over.dedup();
        (acc, over)
    }
}

/// The `k`-th smallest (0-based, in `f32::total_cmp` order) of the non-NaN `errs` rounded to
/// f32, for each `k` of `ranks`, without a copy of them: a radix selection in two counting
/// passes over 16 bits of the f32's order key each (a key whose unsigned order is
/// `total_cmp`'s), both ranks in the same passes. Equal to sorting an f32 copy and taking its
/// elements `ranks`, in a few 2¹⁶-counter histograms instead of 4 bytes per cell
/// (docs/decisions.md#float32-samples). Every rank must be below the number of non-NaN errors.
pub(crate) fn nth_smallest_f32<const N: usize>(errs: &[f64], ranks: [usize; N]) -> [f32; N] {
    fn key(e: f64) -> u32 {
        let b = (e as f32).to_bits();
        if b >> 31 == 1 {
            !b
        } else {
            b | 0x8000_0000
        }
    }
    fn from_key(k: u32) -> f32 {
        f32::from_bits(if k >> 31 == 1 { k & 0x7fff_ffff } else { !k })
    }
    const DIGITS: usize = 1 << 16;
    // `N` histograms; `count(key, histograms)` adds one error's key where it belongs
    fn counts<F: Fn(u32, &mut [Vec<u64>]) + Sync>(errs: &[f64], n: usize, count: F) -> Vec<Vec<u64>> {
        errs.par_chunks(PASS_BLOCK)
            .fold(
                || vec![vec![0u64; DIGITS]; n],
                |mut c, ch| {
                    for &e in ch.iter().filter(|e| !e.is_nan()) {
                        count(key(e), &mut c);
                    }
                    c
                },
            )
            .reduce(
                || vec![vec![0u64; DIGITS]; n],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(b) {
                        x.iter_mut().zip(y).for_each(|(p, q)| *p += q);
                    }
                    a
                },
            )
    }
    // the digit holding rank `k`, and the rank within it
    let pick = |c: &[u64], mut k: u64| -> (u32, u64) {
        for (d, &n) in c.iter().enumerate() {
            if k < n {
                return (d as u32, k);
            }
            k -= n;
        }
        (DIGITS as u32 - 1, 0) // beyond the count: the caller's contract says it is not
    };
    let high = counts(errs, 1, |key, c| c[0][(key >> 16) as usize] += 1);
    let his: [(u32, u64); N] = std::array::from_fn(|r| pick(&high[0], ranks[r] as u64));
    let low = counts(errs, N, |key, c| {
        for (r, &(hi, _)) in his.iter().enumerate() {
            if key >> 16 == hi {
                c[r][(key & 0xffff) as usize] += 1;
            }
        }
    });
    std::array::from_fn(|r| {
        let (hi, rest) = his[r];
        let (lo, _) = pick(&low[r], rest);
        from_key(hi << 16 | lo)
    })
}
