//! Adaptive approximation of a raster by a T-spline (spec §4.1, Alg. 3): initial mesh with
//! overhang, optimise, check every cell, refine, repair, repeat, then coarsen.
//!
//! Decisions:
//! - **A7/A17** the error is |Δz| at every valid raster cell centre (no sampling): the loop stops
//!   with "tolerance reached" only when EVERY valid cell has |Δz| ≤ e_max. Refinement marks the
//!   leaves holding a valid cell over the tolerance. The thesis' 3×3 probes (corners, edge
//!   mid-points, centre against the bilinear raster) are not evaluated separately: cells are
//!   squares of power-of-two size on the integer lattice, so every probe of a splittable cell
//!   (size ≥ 2) IS a raster cell, which the full check already covers. What differs is
//!   ownership: a probe on a shared corner marks all four leaves around it, while here a cell
//!   on a shared edge or corner marks only the leaf whose half-open box holds it (unless that
//!   leaf is at the minimum size: then all of them). Measured on the terrain fixtures, degree 1:
//!   4–8 % fewer control points for the same guarantee (tut_bathy 10 m 5069 → 4873, Kilauea 5 m
//!   35454 → 33702).
//! - **A8** initial mesh: square cells of a power-of-two size c0 (so every split lands on integer
//!   parameters down to the sample spacing 1), about `initial_cells` cells along the longer side of
//!   the data extent grown by `overhang` (default 25 %, thesis §3.2.5, spec §2.2) on every side; the mesh border lies
//!   strictly outside the data.
//! - **A9** least squares on all valid cells (streamed into the sparse normal equations, never the
//!   model matrix), solved by a sparse Cholesky factorisation (`crate::sparse`; Jacobi-PCG as the
//!   fallback, its non-convergence an error). Control points with little
//!   data (column sum of the model matrix below 0.5 samples) get a regulariser whose weight fades
//!   in as the support vanishes: second divided differences along the mesh lines (zero on planes,
//!   so planes stay exact) plus a weak pull to the current surface; a 1e-12 ridge keeps the system
//!   definite. Well-supported points are not biased.
//! - **A10** raster outside its extent or next to a no-data corner is NaN (no-data cells do not
//!   count; dragging clamps such points to the raster's edge, see `fit_drag`).
//! - **A11** refinement and least squares compare at the parameter pair (s, t) = raster cell; the
//!   surface is a height field z(s, t) over the parameter plane, x, y of control points are kept
//!   at their parameters (direct) and only matter for export/indirect back-mapping.
//! - **A12** dragging step limit: each |δ_i| is clamped to half the previous step's max |δ|.
//! - **A19** weights are not fitted (the thesis found them within a tight interval around 1);
//!   all w = 1.
//! - Minimum cell edge = 1 = sample spacing (§2.2 rule): cells of edge < 2 are never split.
//! - **Memory / scale** (10⁸ cells): neither the model matrix nor a full-raster surface is held.
//!   The normal equations are accumulated per Bézier element on rasters (`crate::assembly`:
//!   a dense local block per element, scattered once into the CSR, upper triangle only) and
//!   cell by cell for scattered points; the error check evaluates the surface in row blocks into one
//!   f64 |Δz| per cell, kept across iterations. After a refinement that changes at most 20 % of
//!   the blending functions (new points, changed knots), only those points and the points whose
//!   supports overlap theirs are re-solved (the others held, their terms on the right-hand side)
//!   and only the cells inside the re-solved supports — the only cells whose surface value can
//!   change — are re-evaluated; "tolerance reached" is declared only after a fresh check of
//!   every cell. Knots are re-inferred only for points whose support meets a split cell.
//!   The OpenCL model-matrix rows (T29) are in `ocl_fit` (kernel + CPU twin).
//! - **Coarsening** (`crate::coarsen`, our extension of §3.9): after the tolerance is reached
//!   (least squares on a raster), splits that were not needed are merged back in rounds, each
//!   kept only when every valid cell stays within the tolerance; `coarsen: false` keeps the
//!   loop's mesh. The local update also handles points removed since the previous state.
//! - **Indirect reduction** ([`fit_points`]): the original raster cells mapped forward into the
//!   warped frame are the data (scattered least squares, the tolerance checked at every point,
//!   no 3×3 probes against the resampled raster), so the splat's resampling error and the
//!   dilation-filled cells never enter the fit, and the tolerance holds where the indirect
//!   mesh is evaluated on the original grid.

use std::time::Instant;

use rayon::prelude::*;

use crate::eval::{GridSpec, PbSpline};
use crate::mesh::{CellId, Degree, Rect, SplitDir, SplitRule, TMesh};
use crate::ocl_eval::OclEvaluator;
use crate::tolerance::{CellTolerance, Tolerance};
use crate::TsplineError;

/// A raster in parameter layout: value (i, j) at (s = i, t = j), row-major from the bottom row,
/// NaN = no data (docs/decisions.md#nan-is-no-data).
#[derive(Debug, Clone)]
pub struct Samples {
    pub width: usize,
    pub height: usize,
    pub z: Heights,
}

/// The heights of [`Samples`] at the precision the raster holds them: 4 bytes a cell when every
/// height is exactly an f32 (a float32 raster), else 8 (docs/decisions.md#float32-samples).
/// Every f32 is an f64 exactly, so the fit reads the same numbers either way.
#[derive(Debug, Clone, PartialEq)]
pub enum Heights {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

/// A block of [`Heights`], for the loops that run over many cells: they are written once,
/// generic over the element type ([`Height`]), and dispatched per block.
pub enum HeightsSlice<'a> {
    F64(&'a [f64]),
    F32(&'a [f32]),
}

/// A stored height: f32 or f64, read as f64.
pub trait Height: Copy + Send + Sync {
    fn f64(self) -> f64;
}

impl Height for f64 {
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

impl Height for f32 {
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

impl From<Vec<f64>> for Heights {
    fn from(z: Vec<f64>) -> Heights {
        Heights::F64(z)
    }
}

impl Heights {
    /// f32 storage when every value (NaN included) survives the round trip f64 → f32 → f64,
    /// else the f64 values as they are.
    pub fn compact(z: Vec<f64>) -> Heights {
        if z.iter().all(|&v| v.is_nan() || (v as f32) as f64 == v) {
            Heights::F32(z.iter().map(|&v| v as f32).collect())
        } else {
            Heights::F64(z)
        }
    }

    #[inline]
    pub fn get(&self, q: usize) -> f64 {
        match self {
            Heights::F64(v) => v[q],
            Heights::F32(v) => v[q] as f64,
        }
    }

    /// Makes cell `q` no data.
    pub fn set_nan(&mut self, q: usize) {
        match self {
            Heights::F64(v) => v[q] = f64::NAN,
            Heights::F32(v) => v[q] = f32::NAN,
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Heights::F64(v) => v.len(),
            Heights::F32(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes per cell as stored (8 or 4).
    pub fn bytes_per_cell(&self) -> usize {
        match self {
            Heights::F64(_) => 8,
            Heights::F32(_) => 4,
        }
    }

    /// Every value as f64, in order.
    pub fn iter(&self) -> impl Iterator<Item = f64> + '_ {
        (0..self.len()).map(|q| self.get(q))
    }

    /// The cells `start..end`.
    pub fn slice(&self, start: usize, end: usize) -> HeightsSlice<'_> {
        match self {
            Heights::F64(v) => HeightsSlice::F64(&v[start..end]),
            Heights::F32(v) => HeightsSlice::F32(&v[start..end]),
        }
    }

    /// An f64 copy of every value.
    pub fn to_f64(&self) -> Vec<f64> {
        match self {
            Heights::F64(v) => v.clone(),
            Heights::F32(v) => v.iter().map(|&x| x as f64).collect(),
        }
    }
}

impl Samples {
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.z.get(j * self.width + i)
    }

    /// Standard bilinear interpolation (spec eq. 4.1 in the corrected form of §2.1 / A2); NaN
    /// when outside or when any of the four corners has no data.
    pub fn bilinear(&self, s: f64, t: f64) -> f64 {
        if !(s >= 0.0 && t >= 0.0 && s <= (self.width - 1) as f64 && t <= (self.height - 1) as f64) {
            return f64::NAN;
        }
        let i = (s.floor() as usize).min(self.width.saturating_sub(2));
        let j = (t.floor() as usize).min(self.height.saturating_sub(2));
        let fs = s - i as f64;
        let ft = t - j as f64;
        let i1 = (i + 1).min(self.width - 1);
        let j1 = (j + 1).min(self.height - 1);
        let (a, b, c, d) = (self.get(i, j), self.get(i1, j), self.get(i, j1), self.get(i1, j1));
        // corners with zero weight do not matter (exact integer positions next to no data)
        let w = [(1.0 - fs) * (1.0 - ft), fs * (1.0 - ft), (1.0 - fs) * ft, fs * ft];
        let mut v = 0.0;
        for (wk, zk) in w.iter().zip([a, b, c, d]) {
            if *wk != 0.0 {
                if zk.is_nan() {
                    return f64::NAN;
                }
                v += wk * zk;
            }
        }
        v
    }

    pub fn valid_count(&self) -> usize {
        self.z.iter().filter(|v| !v.is_nan()).count()
    }
}

/// Geometry optimiser (spec §4.3–4.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Lsq,
    Drag,
}

/// Where dense evaluations and dragging run.
pub enum Backend<'a> {
    Cpu,
    OpenCl(&'a OclEvaluator),
}

#[derive(Debug, Clone)]
pub struct FitOptions {
    pub degree: Degree,
    pub max_error: f64,
    pub max_points: Option<usize>,
    pub max_iterations: usize,
    pub method: Method,
    /// Overhang on every side as a fraction of the data extent (A8).
    pub overhang: f64,
    /// Initial cells along the longer side.
    pub initial_cells: usize,
    /// Dragging: steps per iteration.
    pub drag_steps: usize,
    /// Least squares: after a small refinement re-solve only the points it affects and re-check
    /// only the cells they influence (see `local_update`); the tolerance is still declared on a
    /// check of every valid cell.
    pub local_updates: bool,
    /// Least squares: compute the model-matrix rows of global assemblies with the OpenCL kernel
    /// (`ocl_fit`, spec T29) instead of the CPU twin.
    pub opencl_assembly: bool,
    /// Least squares on a raster: after the tolerance is reached, merge back the splits it did
    /// not need (`crate::coarsen`).
    pub coarsen: bool,
    /// A tolerance per raster cell (from the survey's uncertainty) instead of `max_error`
    /// everywhere; `max_error` should then be the smallest of them (it scales the dragging
    /// threshold, the margin and the coarsening pre-filter). Rasters only.
    pub cell_tolerance: Option<CellTolerance>,
    /// A fixed initial mesh instead of the overhang rule (A8): a tile of a plan, whose domain
    /// must meet its neighbours' exactly along the seams (docs/decisions.md#raster-tiles-and-seams).
    pub domain: Option<Domain>,
    /// 4-splits only (A13), or 2-splits across the direction the residual needs
    /// (docs/decisions.md#anisotropic-splits-issue-19). Not with `domain` (tiles need squares).
    pub split: SplitRule,
}

/// The initial mesh of a tile: `ns × nt` square cells of side `cell` from (s0, t0). Square
/// cells of one size across a plan keep every later cell square (4-splits), which the seam
/// stitch needs (`crate::seams`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Domain {
    pub s0: f64,
    pub t0: f64,
    pub cell: f64,
    pub ns: usize,
    pub nt: usize,
}

impl Domain {
    /// The domain of a `w` × `h` pixel window (cell centres at s = 0..w−1, t = 0..h−1)
    /// anchored at the window's first pixel edge in s (s = −½) and, in t, at the edge of its
    /// first raster row (`north_up`: the top, t = h − ½; else t = −½), reaching over the other
    /// sides by whole cells: tiles of one plan then share their seams exactly (the last row and
    /// column of a plan, shorter than the others, overhang the raster instead).
    pub fn anchored(w: usize, h: usize, cell: f64, north_up: bool) -> Domain {
        let ns = ((w as f64 / cell).ceil() as usize).max(1);
        let nt = ((h as f64 / cell).ceil() as usize).max(1);
        let t0 = if north_up { h as f64 - 0.5 - nt as f64 * cell } else { -0.5 };
        Domain { s0: -0.5, t0, cell, ns, nt }
    }
}

impl FitOptions {
    pub fn new(degree: Degree, max_error: f64) -> FitOptions {
        FitOptions { degree, max_error, max_points: None, max_iterations: 100, method: Method::Lsq, overhang: 0.25, initial_cells: 4, drag_steps: 40, local_updates: true, opencl_assembly: false, coarsen: true, cell_tolerance: None, domain: None, split: SplitRule::Quad }
    }
}

/// Error statistics of |Δz| over all valid cells (spec §4.2, A17).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ErrorStats {
    pub count: usize,
    pub mean: f64,
    pub sigma: f64,
    pub median: f64,
    pub max: f64,
    pub rms: f64,
    pub over_tolerance: usize,
}

/// One row of the per-iteration table (thesis Tables 7.1/7.2 plus max, RMS, time).
#[derive(Debug, Clone, serde::Serialize)]
pub struct IterationStats {
    pub iteration: usize,
    pub control_points: usize,
    pub cells: usize,
    pub refined_cells: usize,
    /// Cells merged back by a coarsening round (0 in the refinement iterations).
    pub merged_cells: usize,
    #[serde(flatten)]
    pub error: ErrorStats,
    pub seconds: f64,
    /// Of `seconds`: knot inference + PB-spline build, the geometry optimisation (assembly and
    /// solve, or dragging), and the error check over every valid cell.
    pub seconds_build: f64,
    pub seconds_optimise: f64,
    pub seconds_check: f64,
}

/// Why the loop ended.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum StopReason {
    /// Every valid cell is within the tolerance.
    ToleranceReached,
    /// The next refinement would exceed the control-point cap.
    MaxPoints { cap: usize },
    MaxIterations,
    /// Cells over the tolerance remain, but their mesh cells are at the minimum size.
    MinCellSize { cells_over: usize },
}

pub struct FitResult {
    pub mesh: TMesh,
    pub iterations: Vec<IterationStats>,
    pub stop: StopReason,
}

/// Builds the PB-spline on the backend (device knot kernel or CPU ray casting).
pub fn build_pb(mesh: &TMesh, backend: &Backend) -> Result<PbSpline, TsplineError> {
    match backend {
        Backend::Cpu => Ok(PbSpline::build(mesh)),
        Backend::OpenCl(o) => o.build_pbspline(mesh),
    }
}

/// [`build_pb`] after a refinement, re-inferring only the knots that can have changed: a
/// point's knots are the nearest edges along its four rays, all inside its closed support, so
/// they change only if a cell split since `old` (`split`: the split cells' rectangles) meets
/// that support, or the point is new. The others keep their old knots (equal to a full
/// inference: tested).
pub fn build_pb_incremental(mesh: &TMesh, old: &PbSpline, split: &[crate::mesh::Rect]) -> PbSpline {
    use rstar::{primitives::Rectangle, RTree, AABB};
    let tree: RTree<Rectangle<[f64; 2]>> = RTree::bulk_load(split.iter().map(|r| Rectangle::from_corners([r.s_min, r.t_min], [r.s_max, r.t_max])).collect());
    let mut old_of = vec![u32::MAX; mesh.points.len()];
    for (i, &pid) in old.point_ids.iter().enumerate() {
        old_of[pid as usize] = i as u32;
    }
    let k = old.degree.k();
    let active = mesh.active_points();
    let point_ids: Vec<u32> = (0..mesh.points.len() as u32).filter(|&i| active[i as usize]).collect();
    let knots: Vec<Option<crate::knots::LocalKnots>> = point_ids
        .par_iter()
        .map(|&i| {
            let o = old_of[i as usize];
            if o != u32::MAX {
                let a = &old.knots[o as usize];
                let env = AABB::from_corners([a[0], a[5]], [a[k + 1], a[5 + k + 1]]);
                if tree.locate_in_envelope_intersecting(&env).next().is_none() {
                    let mut kn = crate::knots::LocalKnots { s: [0.0; 5], t: [0.0; 5] };
                    kn.s[..k + 2].copy_from_slice(&a[..k + 2]);
                    kn.t[..k + 2].copy_from_slice(&a[5..5 + k + 2]);
                    return Some(kn);
                }
            }
            None
        })
        .collect();
    let knots = crate::knots::infer_missing(mesh, &point_ids, knots);
    PbSpline::from_parts(mesh, point_ids, knots)
}

/// The initial mesh (A8): returns it with x = s, y = t, z = mean of the data.
pub fn initial_mesh(samples: &Samples, opts: &FitOptions) -> TMesh {
    if let Some(d) = opts.domain {
        let mut m = TMesh::grid(opts.degree, d.s0, d.t0, d.cell, d.ns, d.nt);
        let mean = mean_of(samples);
        for p in &mut m.points {
            p.z = mean;
        }
        return m;
    }
    let (w, h) = ((samples.width - 1).max(1) as f64, (samples.height - 1).max(1) as f64);
    let ext = w.max(h) * (1.0 + 2.0 * opts.overhang);
    let mut c0 = 1.0f64;
    while c0 * (opts.initial_cells.max(1) as f64) < ext {
        c0 *= 2.0;
    }
    let n_for = |len: f64| -> usize {
        let need = len * (1.0 + 2.0 * opts.overhang);
        ((need / c0).ceil() as usize).max(1)
    };
    let mut ns = n_for(w);
    let mut nt = n_for(h);
    // strictly outside the data when there is an overhang: one more cell if needed
    let place = |len: f64, n: &mut usize| -> f64 {
        loop {
            let o = ((len - *n as f64 * c0) * 0.5).floor();
            let covers = if opts.overhang > 0.0 { o < 0.0 && o + *n as f64 * c0 > len } else { o <= 0.0 && o + *n as f64 * c0 >= len };
            if covers {
                return o;
            }
            *n += 1;
        }
    };
    let s0 = place((samples.width - 1) as f64, &mut ns);
    let t0 = place((samples.height - 1) as f64, &mut nt);
    let mut m = TMesh::grid(opts.degree, s0, t0, c0, ns, nt);
    let mean = mean_of(samples);
    for p in &mut m.points {
        p.z = mean;
    }
    m
}

fn mean_of(samples: &Samples) -> f64 {
    let (sum, cnt) = samples.z.iter().filter(|v| !v.is_nan()).fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if cnt == 0 { 0.0 } else { sum / cnt as f64 }
}

/// The normal equations' storage: `crate::sparse`'s symmetric CSR.
type Csr = crate::sparse::SymCsr;

use crate::assembly::entry;

/// Pattern: pairs of PB points whose supports overlap with positive area, plus mesh-line
/// neighbours used by the regulariser.
fn pattern(pb: &PbSpline, extra: &[Vec<u32>], free: Option<&[bool]>) -> Csr {
    let k = pb.degree.k();
    let n = pb.knots.len();
    let is_free = |i: usize| free.is_none_or(|f| f[i]);
    let first = crate::extraction::first_buckets(pb, true);
    let rows: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if !is_free(i) {
                return vec![i as u32]; // held: z_i = current value
            }
            let a = &pb.knots[i];
            let mut v = Vec::new();
            for q in pb.points_in_buckets_once((a[0], a[k + 1]), (a[5], a[5 + k + 1]), &first) {
                let c = &pb.knots[q as usize];
                let ow = a[k + 1].min(c[k + 1]) - a[0].max(c[0]);
                let oh = a[5 + k + 1].min(c[5 + k + 1]) - a[5].max(c[5]);
                if ow > 0.0 && oh > 0.0 {
                    v.push(q);
                }
            }
            v.push(i as u32);
            v.extend_from_slice(&extra[i]);
            v.retain(|&q| is_free(q as usize));
            v.sort_unstable();
            v.dedup();
            v
        })
        .collect();
    let mut start = Vec::with_capacity(n + 1);
    start.push(0);
    for r in &rows {
        start.push(start.last().unwrap() + r.len());
    }
    let cols: Vec<u32> = rows.into_iter().flatten().collect();
    let vals = vec![0.0; cols.len()];
    Csr { start, cols, vals }
}

/// Mesh-line neighbour triples for the regulariser: (left, right, weight_left, weight_right) so
/// that z_i − (wl·z_l + wr·z_r) is the second divided difference (zero on planes).
fn line_triples(mesh: &TMesh, pb: &PbSpline) -> Vec<Vec<(u32, u32, f64, f64)>> {
    let h = pb.degree.half();
    let mut pb_of = std::collections::HashMap::with_capacity(pb.point_ids.len());
    for (i, &pid) in pb.point_ids.iter().enumerate() {
        pb_of.insert(pid, i as u32);
    }
    (0..pb.knots.len())
        .map(|i| {
            let kn = &pb.knots[i];
            let p = mesh.points[pb.point_ids[i] as usize];
            let mut v = Vec::new();
            for dim in 0..2 {
                let o = 5 * dim;
                let (lo, c, hi) = (kn[o + h - 1], kn[o + h], kn[o + h + 1]);
                if lo == c || hi == c {
                    continue;
                }
                let (a, b) = if dim == 0 { ((lo, p.t), (hi, p.t)) } else { ((p.s, lo), (p.s, hi)) };
                let (Some(pa), Some(pbb)) = (mesh.point_id_at(a.0, a.1), mesh.point_id_at(b.0, b.1)) else { continue };
                let (Some(&ia), Some(&ib)) = (pb_of.get(&pa), pb_of.get(&pbb)) else { continue };
                let wl = (hi - c) / (hi - lo);
                let wr = (c - lo) / (hi - lo);
                v.push((ia, ib, wl, wr));
            }
            v
        })
        .collect()
}

/// Least-squares geometry fit (spec §4.5, eq. 4.35 with W = 1 ⇒ ordinary least squares with the
/// rational basis): z of every PB point; the current z are the warm start and the regulariser's
/// prior. Returns the new z per PB point.
pub fn fit_lsq(mesh: &TMesh, pb: &PbSpline, samples: &Samples) -> Result<Vec<f64>, TsplineError> {
    fit_lsq_local(mesh, pb, samples, None, None, None, None)
}

/// [`fit_lsq`] with the rows of the model matrix computed by the OpenCL kernel (spec T29,
/// [`crate::ocl_fit`]) block by block when `asm` is given; the host accumulates the normal
/// equations from them (the matrix is never stored whole).
pub fn fit_lsq_with(mesh: &TMesh, pb: &PbSpline, samples: &Samples, asm: Option<&crate::ocl_fit::OclModel>) -> Result<Vec<f64>, TsplineError> {
    fit_lsq_local(mesh, pb, samples, None, None, None, asm)
}

/// [`fit_lsq`] of the points marked `free` (the others held) on the cells of `region`.
pub(crate) fn fit_lsq_region(mesh: &TMesh, pb: &PbSpline, samples: &Samples, free: &[bool], region: &Region) -> Result<Vec<f64>, TsplineError> {
    fit_lsq_local(mesh, pb, samples, None, Some(free), Some(region), None)
}

/// Writes fitted heights (PB order) into the mesh and the PB-spline.
pub(crate) fn set_z(mesh: &mut TMesh, pb: &mut PbSpline, z: &[f64]) {
    for (i, &pid) in pb.point_ids.iter().enumerate() {
        mesh.points[pid as usize].z = z[i];
        pb.geom[i][2] = z[i];
    }
}

/// Scattered data in parameter units: positions and values (indirect reduction: the ORIGINAL
/// raster cells mapped forward into the warped frame, so the fit and its tolerance check work
/// on the original values at their warped positions, not on a resampled and dilated raster).
#[derive(Debug, Clone, Default)]
pub struct Scattered {
    pub st: Vec<[f64; 2]>,
    pub z: Vec<f64>,
}

/// A set of raster cells (bit per cell, row-major from t = 0).
#[derive(Debug, Clone)]
pub struct Region {
    w: usize,
    h: usize,
    bits: Vec<u64>,
    count: usize,
}

impl Region {
    pub fn new(w: usize, h: usize) -> Region {
        Region { w, h, bits: vec![0; (w * h).div_ceil(64)], count: 0 }
    }
    /// Adds the cells with s ∈ [s0, s1], t ∈ [t0, t1] (closed, clipped to the raster).
    pub fn add_rect(&mut self, s0: f64, s1: f64, t0: f64, t1: f64) {
        let i0 = s0.ceil().max(0.0);
        let i1 = s1.floor().min(self.w as f64 - 1.0);
        let j0 = t0.ceil().max(0.0);
        let j1 = t1.floor().min(self.h as f64 - 1.0);
        if i0 > i1 || j0 > j1 {
            return;
        }
        for j in j0 as usize..=j1 as usize {
            for i in i0 as usize..=i1 as usize {
                let q = j * self.w + i;
                let (wd, b) = (q / 64, 1u64 << (q % 64));
                if self.bits[wd] & b == 0 {
                    self.bits[wd] |= b;
                    self.count += 1;
                }
            }
        }
    }
    #[inline]
    pub fn contains(&self, q: usize) -> bool {
        self.bits[q / 64] & (1u64 << (q % 64)) != 0
    }
    pub fn len(&self) -> usize {
        self.count
    }
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// Calls `f(q)` for the cells of rows j0..j1 in the set, in order (skips empty words).
    pub(crate) fn for_rows(&self, j0: usize, j1: usize, mut f: impl FnMut(usize)) {
        let (q0, q1) = (j0 * self.w, j1 * self.w);
        let mut q = q0;
        while q < q1 {
            let wd = self.bits[q / 64];
            if wd == 0 && q % 64 == 0 {
                q += 64;
                continue;
            }
            if wd & (1u64 << (q % 64)) != 0 {
                f(q);
            }
            q += 1;
        }
    }
}

/// [`fit_lsq`] with some control points held (`free[i] == false`: z_i stays at its current
/// value, its data terms move to the right-hand side) and the data restricted to `region` (the
/// supports of the free points; cells outside do not depend on them).
pub(crate) fn fit_lsq_local(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    pts: Option<&Scattered>,
    free: Option<&[bool]>,
    region: Option<&Region>,
    asm: Option<&crate::ocl_fit::OclModel>,
) -> Result<Vec<f64>, TsplineError> {
    let n = pb.knots.len();
    // device rows only for the global raster assembly
    let asm = match (pts, region, asm) {
        (None, None, Some(o)) => Some((o, o.upload(pb)?)),
        _ => None,
    };
    let is_free = |i: usize| free.is_none_or(|f| f[i]);
    let triples = line_triples(mesh, pb);
    // The regulariser couples i, l and r of each triple: all pairs enter the pattern.
    let mut extra: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (i, ts) in triples.iter().enumerate() {
        for &(l, r, _, _) in ts {
            let ids = [i as u32, l, r];
            for &x in &ids {
                for &y in &ids {
                    if x != y {
                        extra[x as usize].push(y);
                    }
                }
            }
        }
    }
    let mut a = pattern(pb, &extra, free);
    drop(extra);
    let prior: Vec<f64> = pb.geom.iter().map(|g| g[2]).collect();
    let sys = crate::assembly::System { pattern: &a, pb, free, prior: &prior };
    let sums = match (pts, &asm) {
        (None, None) => crate::assembly::by_elements(sys, samples, region),
        _ => crate::assembly::per_cell(sys, samples, pts, region, asm.as_ref().map(|(o, sp)| (*o, sp)))?,
    };
    let crate::assembly::Sums { vals, mut rhs, support } = sums;
    a.vals = vals;
    mirror_upper(&mut a);
    let diag: Vec<f64> = (0..n).map(|i| a.vals[entry(&a, i, i as u32)]).collect();
    let supported: Vec<f64> = (0..n).filter(|&i| is_free(i) && diag[i] > 0.0).map(|i| diag[i]).collect();
    if supported.is_empty() {
        return Err(TsplineError::Fit("no valid raster cell lies inside the mesh".into()));
    }
    let mean_diag = supported.iter().sum::<f64>() / supported.len() as f64;
    drop(supported);
    // A9 regulariser
    for i in 0..n {
        if !is_free(i) {
            let pii = entry(&a, i, i as u32);
            a.vals[pii] = 1.0;
            rhs[i] = prior[i];
            continue;
        }
        let lack = (1.0 - support[i] / 0.5).max(0.0);
        let lam = 1e-3 * mean_diag * lack * lack;
        // ridge: tiny everywhere, stronger where data is lacking
        let ridge = 1e-12 * diag[i].max(mean_diag * 1e-6) + 1e-6 * lam;
        let pii = entry(&a, i, i as u32);
        a.vals[pii] += ridge;
        rhs[i] += ridge * prior[i];
        if lam == 0.0 {
            continue;
        }
        for &(l, r, wl, wr) in &triples[i] {
            // λ (z_i − wl z_l − wr z_r)²
            let idx = [i as u32, l, r];
            let c = [1.0, -wl, -wr];
            for x in 0..3 {
                if !is_free(idx[x] as usize) {
                    continue;
                }
                for y in 0..3 {
                    if is_free(idx[y] as usize) {
                        let p = entry(&a, idx[x] as usize, idx[y]);
                        a.vals[p] += lam * c[x] * c[y];
                    } else {
                        rhs[idx[x] as usize] -= lam * c[x] * c[y] * prior[idx[y] as usize];
                    }
                }
            }
        }
    }
    // what the solve does not read goes before the factor is built (the solve's memory is the
    // fit's peak at 10⁸ cells: BENCHMARKS.md "Peak memory per cell without the copies")
    drop((triples, diag, support));
    release_free_memory(samples.z.len());
    match free {
        Some(f) => solve_free(&a, &rhs, &prior, f),
        None => solve(&a, &rhs, &prior),
    }
}

/// The sparse solve; the current heights are the iterative fallback's warm start.
fn solve(a: &Csr, rhs: &[f64], prior: &[f64]) -> Result<Vec<f64>, TsplineError> {
    let (z, _info) = crate::sparse::solve_spd(a, rhs, prior).map_err(|e| TsplineError::Fit(format!("least squares: {e}")))?;
    Ok(z)
}

/// Copies the accumulated upper triangle onto the lower one. The pattern is symmetric, so
/// visiting rows in order meets the lower entries of each row j in column order: a cursor per
/// row finds the mirror position without a search.
fn mirror_upper(a: &mut Csr) {
    let n = a.n();
    let mut cursor: Vec<usize> = a.start[..n].to_vec();
    for i in 0..n {
        for k in a.start[i]..a.start[i + 1] {
            let j = a.cols[k] as usize;
            if j > i {
                let m = cursor[j];
                debug_assert_eq!(a.cols[m] as usize, i, "symmetric pattern");
                a.vals[m] = a.vals[k];
                cursor[j] += 1;
            }
        }
    }
}

/// The solve of a local update: the held points' rows are identities (z = prior) and no free
/// row refers to a held point, so only the free block is factorised. Why: a local update holds
/// most points, and the ordering, symbolic and numeric factorisation of the whole system cost
/// in proportion to all of them (the held rows were 0.8 of a Kilauea 5 m solve's unknowns).
fn solve_free(a: &Csr, rhs: &[f64], prior: &[f64], free: &[bool]) -> Result<Vec<f64>, TsplineError> {
    let n = a.n();
    let mut new_of = vec![u32::MAX; n];
    let ids: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
    for (q, &i) in ids.iter().enumerate() {
        new_of[i] = q as u32;
    }
    let mut sub = Csr { start: Vec::with_capacity(ids.len() + 1), cols: Vec::new(), vals: Vec::new() };
    sub.start.push(0);
    for &i in &ids {
        for k in a.start[i]..a.start[i + 1] {
            sub.cols.push(new_of[a.cols[k] as usize]);
            sub.vals.push(a.vals[k]);
        }
        sub.start.push(sub.cols.len());
    }
    let pick = |v: &[f64]| ids.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let zf = solve(&sub, &pick(rhs), &pick(prior))?;
    let mut z = prior.to_vec();
    for (&i, v) in ids.iter().zip(zf) {
        z[i] = v;
    }
    Ok(z)
}

/// Dragging (spec §4.6, Alg. 4): z-only, Jacobi-style simultaneous update, step limit A12.
/// Returns the new z per PB point.
pub fn fit_drag(pb: &PbSpline, samples: &Samples, steps: usize, threshold: f64, backend: &Backend) -> Result<Vec<f64>, TsplineError> {
    let params: Vec<[f64; 2]> = pb.point_ids.iter().enumerate().map(|(i, _)| pb_param(pb, i)).collect();
    // Dragging needs a continuous reference (spec §4.6): holes are filled by dilation and
    // points outside the raster take the nearest edge value (A10: clamp to edge).
    let filled = mean_dilation_fill(samples);
    let (wm, hm) = ((samples.width - 1) as f64, (samples.height - 1) as f64);
    let refz: Vec<f64> = params.iter().map(|p| filled.bilinear(p[0].clamp(0.0, wm), p[1].clamp(0.0, hm))).collect();
    let mut pb = pb.clone();
    // the PB-spline buffers only: every step replaces the geometry, which would drop an
    // element extraction before its first use
    let mut dev = match backend {
        Backend::OpenCl(o) => Some((o, o.upload_pb(&pb)?)),
        Backend::Cpu => None,
    };
    let mut prev_max = f64::INFINITY;
    for _ in 0..steps {
        let delta: Vec<f64> = match &mut dev {
            Some((o, sp)) => {
                o.update_geometry(sp, &pb)?;
                o.drag_vectors(sp, &params, &refz)?
            }
            None => params.par_iter().zip(&refz).map(|(p, r)| r - pb.point(p[0], p[1])[2]).collect(),
        };
        let max = delta.iter().filter(|d| d.is_finite()).fold(0.0f64, |m, d| m.max(d.abs()));
        let limit = 0.5 * prev_max;
        for (g, d) in pb.geom.iter_mut().zip(&delta) {
            if d.is_finite() {
                g[2] += d.clamp(-limit, limit);
            }
        }
        prev_max = max.min(prev_max * 2.0);
        if max < threshold {
            break;
        }
    }
    Ok(pb.geom.iter().map(|g| g[2]).collect())
}

/// Fills every no-data cell by wave-front dilation (spec §2.3.5, Alg. 2): each pass gives the
/// cells next to valued ones the mean of their valued 8-neighbours from the previous pass, so the
/// result does not depend on scan order.
///
/// Not `raster_proc::dilate::extrapolating_dilation_fill` on purpose: that one (the warp's, A6)
/// continues slopes by linear extrapolation and must clamp the result; dragging only needs a
/// continuous reference surface, and a mean of known values never leaves their range. It also
/// works on [`Samples`] in the parameter layout rather than on a `Raster`. The result is f64
/// (the means are not f32 values).
pub fn mean_dilation_fill(samples: &Samples) -> Samples {
    let (w, h) = (samples.width, samples.height);
    let mut z = samples.z.to_f64();
    if z.iter().all(|v| v.is_nan()) {
        return Samples { width: w, height: h, z: z.into() };
    }
    let nbrs = |q: usize| {
        let (i, j) = ((q % w) as isize, (q / w) as isize);
        let mut v = Vec::with_capacity(8);
        for dj in -1..=1 {
            for di in -1..=1 {
                let (a, b) = (i + di, j + dj);
                if (di, dj) != (0, 0) && a >= 0 && b >= 0 && (a as usize) < w && (b as usize) < h {
                    v.push(b as usize * w + a as usize);
                }
            }
        }
        v
    };
    let mut front: Vec<usize> = (0..z.len()).filter(|&q| z[q].is_nan() && nbrs(q).iter().any(|&n| !z[n].is_nan())).collect();
    while !front.is_empty() {
        let vals: Vec<f64> = front
            .iter()
            .map(|&q| {
                let v: Vec<f64> = nbrs(q).into_iter().map(|n| z[n]).filter(|x| !x.is_nan()).collect();
                v.iter().sum::<f64>() / v.len() as f64
            })
            .collect();
        for (&q, v) in front.iter().zip(vals) {
            z[q] = v;
        }
        let mut next: Vec<usize> = front.iter().flat_map(|&q| nbrs(q)).filter(|&n| z[n].is_nan()).collect();
        next.sort_unstable();
        next.dedup();
        front = next;
    }
    Samples { width: w, height: h, z: z.into() }
}

/// The parameter pair of PB point i (the centre knots).
fn pb_param(pb: &PbSpline, i: usize) -> [f64; 2] {
    let h = pb.degree.half();
    [pb.knots[i][h], pb.knots[i][5 + h]]
}

/// Streaming sums of |Δz| over a block of cells (merged in block order: deterministic).
#[derive(Debug, Clone, Copy, Default)]
struct ErrAcc {
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
const PASS_BLOCK: usize = 1 << 16;
/// Cells per dense evaluation call of the error pass (at least 16 per leaf cell).
const PASS_BLOCK_EVAL: usize = 1 << 22;

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
pub(crate) fn over_tolerance(mesh: &TMesh, pb: &PbSpline, samples: &Samples, backend: &Backend, tol: &Tolerance) -> Result<(usize, Vec<CellId>), TsplineError> {
    let pass = ErrorPass::new(pb, samples, backend)?;
    let w = samples.width;
    let n = samples.z.len();
    let mut buf = vec![0.0; pass.block_cells().min(n)];
    let (mut count, mut over) = (0, Vec::new());
    for q0 in (0..n).step_by(pass.block_cells()) {
        let out = &mut buf[..pass.block_cells().min(n - q0)];
        pass.block(q0 / w, out)?;
        let (acc, o) = over_in(mesh, pb, &|q| ((q % w) as f64, (q / w) as f64), out, q0, tol);
        count += acc.over;
        over.extend(o);
    }
    over.sort_unstable();
    over.dedup();
    Ok((count, over))
}

/// The error pass over a raster in big row blocks: the dense evaluators amortise their per-call
/// set-up (an element extraction, an OpenCL upload) over all blocks.
struct ErrorPass<'a> {
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

    /// |Δz| of the rows from `j0` on into `out` (whole rows).
    fn block(&self, j0: usize, out: &mut [f64]) -> Result<(), TsplineError> {
        let (pb, w) = (self.pb, self.samples.width);
        let g = GridSpec { s0: 0.0, t0: j0 as f64, ds: 1.0, dt: 1.0, ns: w, nt: out.len() / w };
        let z = match (self.backend, &self.sp, &self.ex) {
            (Backend::OpenCl(o), Some(sp), _) => o.eval_grid(sp, &g)?,
            (_, _, Some(ex)) if pb.use_extraction(out.len()) => ex.eval_grid(pb, &g, true),
            _ => pb.eval_grid(&g, true),
        };
        match self.samples.z.slice(j0 * w, j0 * w + out.len()) {
            HeightsSlice::F64(d) => errors_into(out, &z, d, self.sub * w),
            HeightsSlice::F32(d) => errors_into(out, &z, d, self.sub * w),
        }
        Ok(())
    }
}

/// |Δz| of the surface heights `z` against the data `d` into `out` (NaN where `d` has no data,
/// +∞ where the surface is undefined), in parallel over chunks of `chunk` cells.
fn errors_into<T: Height>(out: &mut [f64], z: &[f64], d: &[T], chunk: usize) {
    out.par_chunks_mut(chunk).zip(z.par_chunks(chunk)).zip(d.par_chunks(chunk)).for_each(|((o, zc), dc)| {
        for ((e, &zk), &dk) in o.iter_mut().zip(zc).zip(dc) {
            let dk = dk.f64();
            *e = if dk.is_nan() { f64::NAN } else if zk.is_nan() { f64::INFINITY } else { (zk - dk).abs() };
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
        region.for_rows(j0, j1, |q| out[q - j0 * w] = region_error(pb, samples, q));
    });
}

/// |Δz| at raster cell `q` on the PB-spline path ([`eval_errors_region`]'s value).
#[inline]
fn region_error(pb: &PbSpline, samples: &Samples, q: usize) -> f64 {
    let w = samples.width;
    let dk = samples.z.get(q);
    if dk.is_nan() {
        f64::NAN
    } else {
        let zk = pb.point((q % w) as f64, (q / w) as f64)[2];
        if zk.is_nan() { f64::INFINITY } else { (zk - dk).abs() }
    }
}

/// [`over_tolerance`] of a local try: the count of valid cells of `region` over the tolerance
/// and the leaves holding them, from the errors [`eval_errors_region`] would write, computed
/// one row block at a time into a block-sized buffer (no per-cell array). Coarsening's local
/// tries ask this first and write `errs` only once a try has passed, so a failed try needs no
/// copy of the region's old errors to undo (docs/decisions.md#coarsening-decides-before-it-writes).
/// Cells outside `region` keep errors within the tolerance (every kept state passes at every
/// cell), so the verdict and the leaves are those of [`summarize`] over the whole updated array.
pub(crate) fn over_tolerance_region(mesh: &TMesh, pb: &PbSpline, samples: &Samples, region: &Region, tol: &Tolerance) -> (usize, Vec<CellId>) {
    let w = samples.width;
    let sub = (PASS_BLOCK / w.max(1)).max(1);
    let blocks = samples.height.div_ceil(sub);
    let pos = |q: usize| ((q % w) as f64, (q / w) as f64);
    let scan = OverScan::new(mesh, pb, &pos, tol);
    let parts: Vec<(usize, Vec<CellId>)> = (0..blocks)
        .into_par_iter()
        .map_init(Vec::new, |buf: &mut Vec<f64>, b| {
            let j0 = b * sub;
            let j1 = (j0 + sub).min(samples.height);
            buf.clear();
            buf.resize((j1 - j0) * w, f64::NAN);
            let mut any = false;
            region.for_rows(j0, j1, |q| {
                buf[q - j0 * w] = region_error(pb, samples, q);
                any = true;
            });
            if !any {
                return (0, Vec::new());
            }
            let (acc, over) = scan.chunk(buf, j0 * w);
            (acc.over, over)
        })
        .collect();
    let mut count = 0;
    let mut over = Vec::new();
    for (c, o) in parts {
        count += c;
        over.extend(o);
    }
    over.sort_unstable();
    over.dedup();
    (count, over)
}

/// Statistics of `errs` over the valid cells (summed over fixed blocks in order: independent of
/// the thread count) and the leaf cells whose closed box holds a cell over the tolerance.
/// The median is that of the errors rounded to f32 ([`nth_smallest_f32`], no copy of the
/// errors); the maximum and the tolerance test use the f64 errors.
pub fn summarize(mesh: &TMesh, pb: &PbSpline, w: usize, errs: &[f64], tol: &Tolerance) -> (ErrorStats, Vec<CellId>) {
    summarize_at(mesh, pb, &|q| ((q % w) as f64, (q / w) as f64), errs, tol)
}

/// [`summarize`] with the parameter position of error `q` given by `pos`.
pub(crate) fn summarize_at(mesh: &TMesh, pb: &PbSpline, pos: &(dyn Fn(usize) -> (f64, f64) + Sync), errs: &[f64], tol: &Tolerance) -> (ErrorStats, Vec<CellId>) {
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
    (ErrorStats { count: n, mean, sigma, median, max: acc.max, rms: (acc.sumsq / n as f64).sqrt(), over_tolerance: acc.over }, over)
}

/// The statistics of `errs` (errors `offset..` of the raster or point list) and the leaf cells
/// whose closed box holds one over the tolerance (sorted, each once): the scan of [`summarize_at`]
/// without the median, summed over fixed blocks in order.
fn over_in(mesh: &TMesh, pb: &PbSpline, pos: &(dyn Fn(usize) -> (f64, f64) + Sync), errs: &[f64], offset: usize, tol: &Tolerance) -> (ErrAcc, Vec<CellId>) {
    let scan = OverScan::new(mesh, pb, pos, tol);
    let parts: Vec<(ErrAcc, Vec<CellId>)> = errs.par_chunks(PASS_BLOCK).enumerate().map(|(b, ch)| scan.chunk(ch, offset + b * PASS_BLOCK)).collect();
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
struct OverScan<'a> {
    mesh: &'a TMesh,
    pb: &'a PbSpline,
    pos: &'a (dyn Fn(usize) -> (f64, f64) + Sync),
    tol: &'a Tolerance,
    leaf_ids: Vec<CellId>,
    same_order: bool,
}

impl<'a> OverScan<'a> {
    fn new(mesh: &'a TMesh, pb: &'a PbSpline, pos: &'a (dyn Fn(usize) -> (f64, f64) + Sync), tol: &'a Tolerance) -> OverScan<'a> {
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
        if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
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

/// Share of the PB points whose basis changed (new, or other knots) up to which an iteration
/// re-solves and re-checks locally instead of globally.
const LOCAL_SHARE: f64 = 0.2;

/// The local update after a refinement (an optimisation of the loop, not of the result's
/// guarantee): points whose blending function changed (new points, changed knots) and every
/// point whose support overlaps theirs are re-solved with the others held; the surface changes
/// only inside the supports of the re-solved points, so only those cells are re-checked.
/// Returns None when the change is too large for that to pay (the iteration goes global).
pub(crate) fn local_update(old: &PbSpline, new: &PbSpline, n_points: usize, w: usize, h: usize) -> Option<(Vec<bool>, Region)> {
    let n = new.knots.len();
    let mut old_of = vec![u32::MAX; n_points];
    for (i, &pid) in old.point_ids.iter().enumerate() {
        old_of[pid as usize] = i as u32;
    }
    let changed: Vec<bool> = (0..n)
        .map(|i| {
            let o = old_of[new.point_ids[i] as usize];
            o == u32::MAX || old.knots[o as usize] != new.knots[i] || old.geom[o as usize][3] != new.geom[i][3]
        })
        .collect();
    // points of `old` gone from `new` (coarsening): the surface changes over their old supports
    let mut in_new = vec![false; n_points];
    for &pid in &new.point_ids {
        in_new[pid as usize] = true;
    }
    let k = new.degree.k();
    let removed: Vec<(f64, f64, f64, f64)> = (0..old.knots.len())
        .filter(|&o| !in_new[old.point_ids[o] as usize])
        .map(|o| {
            let a = &old.knots[o];
            (a[0], a[k + 1], a[5], a[5 + k + 1])
        })
        .collect();
    let nu = changed.iter().filter(|&&c| c).count() + removed.len();
    if nu == 0 || nu as f64 > LOCAL_SHARE * n as f64 {
        return None;
    }
    let supp = |i: usize| {
        let a = &new.knots[i];
        (a[0], a[k + 1], a[5], a[5 + k + 1])
    };
    let lists: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .filter(|&i| changed[i])
        .map(|i| {
            let (s0, s1, t0, t1) = supp(i);
            let (i0, i1) = new.grid.index_range(s0, s1, true);
            let (j0, j1) = new.grid.index_range(t0, t1, false);
            let mut v = vec![i as u32];
            for bj in j0..=j1 {
                for bi in i0..=i1 {
                    let b = (bj * new.grid.ns + bi) as usize;
                    for &q in &new.pt_items[new.pt_start[b] as usize..new.pt_start[b + 1] as usize] {
                        let (a0, a1, b0, b1) = supp(q as usize);
                        if s1.min(a1) - s0.max(a0) > 0.0 && t1.min(b1) - t0.max(b0) > 0.0 {
                            v.push(q);
                        }
                    }
                }
            }
            v
        })
        .collect();
    let mut free = vec![false; n];
    for l in &lists {
        for &q in l {
            free[q as usize] = true;
        }
    }
    let mut region = Region::new(w, h);
    for i in (0..n).filter(|&i| free[i]) {
        let (s0, s1, t0, t1) = supp(i);
        region.add_rect(s0, s1, t0, t1);
    }
    for &(s0, s1, t0, t1) in &removed {
        region.add_rect(s0, s1, t0, t1);
    }
    if region.len() * 2 > w * h {
        return None;
    }
    Some((free, region))
}

/// Rasters from which [`release_free_memory`] trims (2²⁴ cells).
const TRIM_CELLS: usize = 1 << 24;

/// Hands the allocator's free pages back to the system (glibc's `malloc_trim`; elsewhere
/// nothing). Why: glibc keeps freed blocks below its (dynamic, up to 32 MiB) mmap threshold in
/// its arenas, so the partial sums of one assembly and the PB-spline of the previous iteration
/// stayed resident under the next solve's factor; called before each solve and each
/// iteration, it takes tens of MiB off the peak (~30 MiB at 10⁷ cells) for a few ms per call
/// (BENCHMARKS.md "Peak memory per cell without the copies").
/// Only for rasters of [`TRIM_CELLS`] cells or more, where the per-cell arrays leave little
/// room: each call costs page faults later (+4 % CPU on the 1.6·10⁶-cell BAG fit).
pub(crate) fn release_free_memory(cells: usize) {
    let _ = cells;
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if cells >= TRIM_CELLS {
        extern "C" {
            fn malloc_trim(pad: usize) -> std::os::raw::c_int;
        }
        // SAFETY: glibc's malloc_trim takes no pointer and may be called at any time
        unsafe {
            malloc_trim(0);
        }
    }
}

pub(crate) enum Refined {
    Stop(StopReason),
    /// The refined mesh and the number of cells marked and split.
    Next(TMesh, usize),
}

/// One refinement: split the splittable leaves over the tolerance, repair; or the reason to
/// stop (minimum cell size, control-point cap). [`SplitRule::Anisotropic`]: each leaf is split
/// as [`split_direction`] chooses from the residual inside it.
pub(crate) fn refine(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    opts: &FitOptions,
    over_leaves: Vec<CellId>,
    err: &ErrorStats,
) -> Result<Refined, TsplineError> {
    let mut marked = over_leaves;
    marked.sort_unstable();
    marked.dedup();
    let can_split = |c: CellId| {
        let r = mesh.cells[c as usize].rect;
        match opts.split {
            SplitRule::Quad => r.width().min(r.height()) >= 2.0,
            SplitRule::Anisotropic => r.width().max(r.height()) >= 2.0,
        }
    };
    if opts.split == SplitRule::Anisotropic {
        // A leaf at the minimum size that is still over the tolerance has no split left; its
        // surface there is set by the blending functions of the leaves around it, which 2-splits
        // may have left long (a 1:2 balance only along the shared side): those leaves (closed
        // boxes that touch it) are split instead (docs/decisions.md#anisotropic-splits-issue-19).
        let stuck: Vec<CellId> = marked.iter().copied().filter(|&c| !can_split(c)).collect();
        for c in stuck {
            marked.extend(mesh.leaves_in(mesh.cells[c as usize].rect).into_iter().filter(|&n| can_split(n)));
        }
        marked.sort_unstable();
        marked.dedup();
    }
    let splittable: Vec<CellId> = marked.into_iter().filter(|&c| can_split(c)).collect();
    if splittable.is_empty() {
        return Ok(Refined::Stop(StopReason::MinCellSize { cells_over: err.over_tolerance }));
    }
    let dirs: Vec<SplitDir> = match opts.split {
        SplitRule::Quad => vec![SplitDir::Quad; splittable.len()],
        SplitRule::Anisotropic => splittable.par_iter().map(|&c| split_direction(pb, samples, mesh.cells[c as usize].rect, opts.max_error)).collect(),
    };
    let mut next = mesh.clone();
    let mut geom = |s: f64, t: f64| (s, t, {
        let z = pb.point(s, t)[2];
        if z.is_nan() { 0.0 } else { z }
    });
    for (&c, &dir) in splittable.iter().zip(&dirs) {
        if next.cells[c as usize].is_leaf() {
            next.split_dir(c, dir, &mut geom);
        }
    }
    next.repair_with(1.0, opts.split, &mut geom);
    if let Some(cap) = opts.max_points {
        let n = next.active_points().iter().filter(|a| **a).count();
        if n > cap {
            return Ok(Refined::Stop(StopReason::MaxPoints { cap }));
        }
    }
    Ok(Refined::Next(next, splittable.len()))
}

/// How much more one split direction must explain than the other to be chosen alone.
const ANISO_RATIO: f64 = 1.5;

/// A leaf whose residual (on the cells [`kink_gains`] looks at) reaches this many times the
/// tolerance is split into four: it is too coarse in both directions, and the kinks' direction
/// means something only near the tolerance (measured: BENCHMARKS.md, anisotropic refinement).
const ANISO_FAR: f64 = 4.0;

/// Raster cells per side of a leaf that [`kink_gains`] looks at, at most.
const KINK_SAMPLES: f64 = 24.0;

/// The anisotropic split of a leaf `r` over the tolerance, chosen from the residual
/// e = data − surface at the valid raster cells in its closed box: with u, v the cell's
/// coordinates scaled to [−1, 1], the least-squares fit of e by {1, u, v, uv} is compared with
/// the fits that add a kink at the s mid-point ({|u|, |u|v}: what a knot line across s adds) and
/// at the t mid-point ({|v|, u|v|}). A 4-split where |e| reaches [`ANISO_FAR`] times the
/// tolerance `e_max`; else a 2-split across the direction whose kink explains [`ANISO_RATIO`]
/// times more of e than the other's; else a 4-split. A side shorter than 2
/// (the sample spacing, spec §2.2) is not halved; the aspect stays at most
/// [`crate::mesh::MAX_ASPECT`]. docs/decisions.md#anisotropic-splits-issue-19
pub(crate) fn split_direction(pb: &PbSpline, samples: &Samples, r: Rect, e_max: f64) -> SplitDir {
    let (w, h) = (r.width(), r.height());
    let can_s = w >= 2.0;
    let can_t = h >= 2.0;
    let dir = match (can_s, can_t) {
        (false, false) | (true, true) => {
            let (gs, gt, emax) = kink_gains(pb, samples, r);
            if emax > ANISO_FAR * e_max {
                SplitDir::Quad
            } else if gs > ANISO_RATIO * gt {
                SplitDir::S
            } else if gt > ANISO_RATIO * gs {
                SplitDir::T
            } else {
                SplitDir::Quad
            }
        }
        (true, false) => return SplitDir::S,
        (false, true) => return SplitDir::T,
    };
    crate::mesh::aspect_capped(&r, dir, 1.0)
}

/// (SSE explained by the s kink, by the t kink, max |e|) of the residual in `r` (see
/// [`split_direction`]).
fn kink_gains(pb: &PbSpline, samples: &Samples, r: Rect) -> (f64, f64, f64) {
    let sm = 0.5 * (r.s_min + r.s_max);
    let tm = 0.5 * (r.t_min + r.t_max);
    let (hw, hh) = (0.5 * r.width(), 0.5 * r.height());
    let i0 = r.s_min.ceil().max(0.0);
    let j0 = r.t_min.ceil().max(0.0);
    let i1 = r.s_max.floor().min(samples.width as f64 - 1.0);
    let j1 = r.t_max.floor().min(samples.height as f64 - 1.0);
    // Gram of the 8 functions [1, u, v, uv, |u|, |u|v, |v|, u|v|] and their moments with e
    let mut g = [[0.0f64; 8]; 8];
    let mut m = [0.0f64; 8];
    let mut ee = 0.0;
    let mut emax = 0.0f64;
    if i1 >= i0 && j1 >= j0 {
        // at most KINK_SAMPLES² cells of a large leaf (a regular subsample): the direction of a
        // coarse leaf's residual does not need every cell, and early iterations mark most of
        // the raster
        let step = |n: f64| ((n / KINK_SAMPLES).ceil() as usize).max(1);
        let (si, sj) = (step(i1 - i0 + 1.0), step(j1 - j0 + 1.0));
        for j in (j0 as usize..=j1 as usize).step_by(sj) {
            let v = (j as f64 - tm) / hh;
            for i in (i0 as usize..=i1 as usize).step_by(si) {
                let d = samples.get(i, j);
                if d.is_nan() {
                    continue;
                }
                let z = pb.point(i as f64, j as f64)[2];
                if !z.is_finite() {
                    continue;
                }
                let e = d - z;
                emax = emax.max(e.abs());
                let u = (i as f64 - sm) / hw;
                let f = [1.0, u, v, u * v, u.abs(), u.abs() * v, v.abs(), u * v.abs()];
                for a in 0..8 {
                    m[a] += f[a] * e;
                    for b in a..8 {
                        g[a][b] += f[a] * f[b];
                    }
                }
                ee += e * e;
            }
        }
    }
    let explained = |idx: &[usize]| -> f64 {
        // bᵀ G⁻¹ b on the subset (a tiny ridge keeps a rank-deficient subset solvable)
        let n = idx.len();
        let mut a = vec![vec![0.0f64; n + 1]; n];
        for (p, &ia) in idx.iter().enumerate() {
            for (q, &ib) in idx.iter().enumerate() {
                a[p][q] = if ia <= ib { g[ia][ib] } else { g[ib][ia] };
            }
            a[p][p] += 1e-9 * (1.0 + g[ia][ia]);
            a[p][n] = m[ia];
        }
        for col in 0..n {
            let piv = (col..n).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs())).unwrap_or(col);
            a.swap(col, piv);
            let d = a[col][col];
            if d.abs() < 1e-300 {
                continue;
            }
            let (top, below) = a.split_at_mut(col + 1);
            let pivot = &top[col];
            for r in below.iter_mut() {
                let f = r[col] / d;
                for (x, p) in r[col..].iter_mut().zip(&pivot[col..]) {
                    *x -= f * p;
                }
            }
        }
        let mut x = vec![0.0f64; n];
        for row in (0..n).rev() {
            let d = a[row][row];
            if d.abs() < 1e-300 {
                continue;
            }
            let mut acc = a[row][n];
            for k in row + 1..n {
                acc -= a[row][k] * x[k];
            }
            x[row] = acc / d;
        }
        idx.iter().zip(&x).map(|(&i, xi)| m[i] * xi).sum::<f64>().clamp(0.0, ee)
    };
    let base = explained(&[0, 1, 2, 3]);
    let gs = (explained(&[0, 1, 2, 3, 4, 5]) - base).max(0.0);
    let gt = (explained(&[0, 1, 2, 3, 6, 7]) - base).max(0.0);
    (gs, gt, emax)
}

/// The largest |z| a fit accepts: 1e100, so that squares (1e200) and sums of squares over any
/// raster (≪ 1e100 cells) stay finite. No elevation or measurement comes near it; values
/// beyond it (e.g. 1.797e308 in a corrupt file) are refused up front instead of turning the
/// control points into infinities.
pub const MAX_ABS_VALUE: f64 = 1e100;

/// Fails with [`TsplineError::ValueRange`] when a finite value of `z` has |z| > [`MAX_ABS_VALUE`]
/// (non-finite values are no data and skipped).
pub fn check_value_range(z: &[f64]) -> Result<(), TsplineError> {
    check_range_of(z.iter().copied())
}

/// [`check_value_range`] over stored heights.
fn check_heights_range(z: &Heights) -> Result<(), TsplineError> {
    check_range_of(z.iter())
}

fn check_range_of(z: impl Iterator<Item = f64>) -> Result<(), TsplineError> {
    let (min, max) = z.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    // no finite value at all is not a range problem: the fit names the empty raster itself
    if min <= max && (min.abs() > MAX_ABS_VALUE || max.abs() > MAX_ABS_VALUE) {
        return Err(TsplineError::ValueRange { min, max, limit: MAX_ABS_VALUE });
    }
    Ok(())
}

/// The approximation loop (Alg. 3). `progress` gets every iteration's statistics.
pub fn fit(samples: &Samples, opts: &FitOptions, backend: &Backend, progress: &mut dyn FnMut(&IterationStats)) -> Result<FitResult, TsplineError> {
    fit_impl(samples, None, opts, backend, progress)
}

/// The loop on scattered data (indirect reduction): `pts` are what least squares fits and what
/// the tolerance is checked at (every point); `grid` gives the parameter extent of the initial
/// mesh. Every iteration is global.
pub fn fit_points(
    grid: &Samples,
    pts: &Scattered,
    opts: &FitOptions,
    backend: &Backend,
    progress: &mut dyn FnMut(&IterationStats),
) -> Result<FitResult, TsplineError> {
    if pts.st.len() != pts.z.len() || pts.z.iter().any(|v| !v.is_finite()) || pts.st.iter().flatten().any(|v| !v.is_finite()) {
        return Err(TsplineError::Fit("scattered data: positions and values must be finite and as many".into()));
    }
    if pts.z.is_empty() {
        return Err(TsplineError::Fit("the raster has no valid cell".into()));
    }
    fit_impl(grid, Some(pts), opts, backend, progress)
}

/// |Δz| of the surface into `errs` and its statistics with the leaves over the tolerance: at
/// every point (scattered data), at the raster cells of `region` (a local update: the others
/// keep their errors), or at every valid raster cell.
#[allow(clippy::too_many_arguments)]
pub(crate) fn check(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    pts: Option<&Scattered>,
    region: Option<&Region>,
    backend: &Backend,
    errs: &mut [f64],
    tol: &Tolerance,
) -> Result<(ErrorStats, Vec<CellId>), TsplineError> {
    if let Some(p) = pts {
        let z = match backend {
            Backend::OpenCl(o) => o.eval_points(&o.upload(pb)?, &p.st)?,
            Backend::Cpu => pb.eval_z(&p.st, true),
        };
        errs.par_iter_mut().zip(&z).zip(&p.z).for_each(|((e, zk), dk)| *e = if zk.is_nan() { f64::INFINITY } else { (zk - dk).abs() });
        return Ok(summarize_at(mesh, pb, &|q| (p.st[q][0], p.st[q][1]), errs, tol));
    }
    match region {
        Some(r) => eval_errors_region(pb, samples, r, errs),
        None => eval_errors(pb, samples, backend, errs)?,
    }
    Ok(summarize(mesh, pb, samples.width, errs, tol))
}

/// The loop's tolerance (T − δ) and the final acceptance check's (T − δ/2), δ the margin of
/// `crate::tolerance` (docs/decisions.md#the-guarantee-holds-for-what-eval-computes): the loop
/// and its coarsening keep δ free, the check of the written mesh may use half of it for the
/// rounding between the loop's and `eval`'s evaluation paths, and the other half stays for
/// the paths not checked here (the OpenCL kernels).
pub(crate) fn tolerances(samples: &Samples, pts: Option<&Scattered>, opts: &FitOptions) -> Result<(Tolerance, Tolerance), TsplineError> {
    let zscale = match pts {
        Some(p) => p.z.iter().filter(|v| v.is_finite()).fold(0.0f64, |m, v| m.max(v.abs())),
        None => samples.z.iter().filter(|v| v.is_finite()).fold(0.0f64, |m, v| m.max(v.abs())),
    };
    let (cells, min_tol) = match &opts.cell_tolerance {
        None => (None, opts.max_error),
        Some(c) => {
            if pts.is_some() {
                return Err(TsplineError::Fit("a per-cell tolerance applies to raster fits, not to scattered points (--indirect)".into()));
            }
            if c.uncertainty.len() != samples.z.len() {
                return Err(TsplineError::Fit(format!("{} per-cell tolerances for {} cells", c.uncertainty.len(), samples.z.len())));
            }
            let min = c.min_over(|q| !samples.z.get(q).is_nan()).unwrap_or(opts.max_error);
            if !(min > 0.0 && min.is_finite()) {
                return Err(TsplineError::Fit(format!("the per-cell tolerance must be positive at every valid cell, got {min}")));
            }
            (Some(c.clone()), min)
        }
    };
    let delta = crate::tolerance::margin(zscale, min_tol);
    let t = Tolerance::new(opts.max_error, cells, delta);
    let fin = t.with_margin(0.5 * delta);
    Ok((t, fin))
}

/// The mesh as the output file holds it: written with [`crate::format::write`] and read back
/// (compacted numbering, text round trip). What `geofit eval` reads.
pub fn as_written(mesh: &TMesh) -> Result<TMesh, TsplineError> {
    let file = crate::format::TMeshFile { mesh: mesh.clone(), georef: crate::format::Georef::identity(), mask: None, warp: None };
    let mut bytes = Vec::new();
    crate::format::write(&file, &mut bytes)?;
    Ok(crate::format::read(&bytes)?.mesh)
}

/// Heights of the surface of `pb` on the raster rows j0..j1 exactly as [`PbSpline::eval_z`]
/// computes them for the whole grid `w`×`h` at once (`geofit eval` on the fitted grid): the
/// same element-extraction-or-reference choice (made for `w·h` points, not per block), the same
/// per-point arithmetic (an element owns its points half-open, so the row order does not
/// matter). `ex`: the extraction when that choice takes it.
fn eval_rows_as_eval(pb: &PbSpline, ex: Option<&crate::extraction::Extraction>, w: usize, j0: usize, j1: usize) -> Vec<f64> {
    let g = GridSpec { s0: 0.0, t0: j0 as f64, ds: 1.0, dt: 1.0, ns: w, nt: j1 - j0 };
    match ex {
        Some(ex) => ex.eval_grid(pb, &g, false),
        None => (0..w * (j1 - j0)).map(|k| pb.point((k % w) as f64, (j0 + k / w) as f64)[2]).collect(),
    }
}

/// The acceptance check: |Δz| of the mesh as written ([`as_written`]), evaluated as `geofit
/// eval` does (raster: [`eval_rows_as_eval`] over every cell; scattered data: `eval_z` at the
/// points), into `errs`; statistics and the leaves (of `mesh`, through its `pb`) over `tol`.
pub(crate) fn check_written(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    pts: Option<&Scattered>,
    errs: &mut [f64],
    tol: &Tolerance,
) -> Result<(ErrorStats, Vec<CellId>), TsplineError> {
    let written = PbSpline::build(&as_written(mesh)?);
    let err_of = |zk: f64, dk: f64| if dk.is_nan() { f64::NAN } else if zk.is_nan() { f64::INFINITY } else { (zk - dk).abs() };
    if let Some(p) = pts {
        let z = written.eval_z(&p.st, true);
        errs.par_iter_mut().zip(&z).zip(&p.z).for_each(|((e, zk), dk)| *e = err_of(*zk, *dk));
        return Ok(summarize_at(mesh, pb, &|q| (p.st[q][0], p.st[q][1]), errs, tol));
    }
    let (w, h) = (samples.width, samples.height);
    let ex = written.use_extraction(w * h).then(|| crate::extraction::Extraction::new(&written, true));
    let rows = (PASS_BLOCK / w.max(1)).max(1);
    errs.par_chunks_mut(rows * w).enumerate().for_each(|(b, out)| {
        let j0 = b * rows;
        let z = eval_rows_as_eval(&written, ex.as_ref(), w, j0, j0 + out.len() / w);
        for (k, (e, zk)) in out.iter_mut().zip(z).enumerate() {
            *e = err_of(zk, samples.z.get(j0 * w + k));
        }
    });
    Ok(summarize(mesh, pb, w, errs, tol))
}

fn fit_impl(
    samples: &Samples,
    pts: Option<&Scattered>,
    opts: &FitOptions,
    backend: &Backend,
    progress: &mut dyn FnMut(&IterationStats),
) -> Result<FitResult, TsplineError> {
    if !(opts.max_error > 0.0 && opts.max_error.is_finite()) {
        return Err(TsplineError::Fit(format!("the maximum error must be a positive number, got {}", opts.max_error)));
    }
    if samples.width * samples.height == 0 || samples.z.len() != samples.width * samples.height {
        return Err(TsplineError::Fit("the raster is empty".into()));
    }
    if samples.valid_count() == 0 {
        return Err(TsplineError::Fit("the raster has no valid cell".into()));
    }
    check_heights_range(&samples.z)?;
    if opts.split != SplitRule::Quad && opts.domain.is_some() {
        // docs/decisions.md#anisotropic-splits-issue-19: the seam stitch needs square cells
        return Err(TsplineError::Fit("anisotropic splits are not available for tiles of a plan (their seams need square cells)".into()));
    }
    if let Some(p) = pts {
        check_value_range(&p.z)?;
    }
    let (tol, tol_final) = tolerances(samples, pts, opts)?;
    // a final check that failed (rounding beyond the margin: not seen) turns coarsening off, so
    // that refinement converges instead of merging the same cells back
    let mut may_coarsen = opts.coarsen && opts.method == Method::Lsq;
    let mut mesh = initial_mesh(samples, opts);
    let mut iterations = Vec::new();
    let mut refined = 0usize;
    // |Δz| per raster cell of the current surface, kept across iterations (local updates
    // re-check only the cells whose surface value can have changed)
    let mut errs = vec![f64::NAN; pts.map_or(samples.z.len(), |p| p.z.len())];
    let mut prev: Option<PbSpline> = None;
    let asm = if opts.opencl_assembly && opts.method == Method::Lsq { Some(crate::ocl_fit::OclModel::new()?) } else { None };
    let mut split_rects: Vec<crate::mesh::Rect> = Vec::new();
    let (w, h) = (samples.width, samples.height);
    for it in 0.. {
        let t0 = Instant::now();
        // the previous PB-spline serves the incremental build and the local update's
        // comparison only: dropped before the solve (a PB-spline of 1.5·10⁵ points is ~70 MiB)
        let old = prev.take();
        release_free_memory(samples.z.len());
        let mut pb = match (&old, backend) {
            (Some(old), Backend::Cpu) => build_pb_incremental(&mesh, old, &split_rects),
            _ => build_pb(&mesh, backend)?,
        };
        let t_build = t0.elapsed().as_secs_f64();
        let local = match (&old, opts.method, opts.local_updates) {
            (Some(old), Method::Lsq, true) if pts.is_none() => local_update(old, &pb, mesh.points.len(), w, h),
            _ => None,
        };
        drop(old);
        let z = match (opts.method, &local) {
            (Method::Lsq, Some((free, region))) => fit_lsq_local(&mesh, &pb, samples, None, Some(free), Some(region), None)?,
            (Method::Lsq, None) => fit_lsq_local(&mesh, &pb, samples, pts, None, None, asm.as_ref())?,
            (Method::Drag, _) => fit_drag(&pb, samples, opts.drag_steps, 0.01 * opts.max_error, backend)?,
        };
        if z.iter().any(|v| !v.is_finite()) {
            // the range check above makes this unreachable for sound solvers; a typed error
            // rather than an invalid mesh (which would panic when written) if it happens anyway
            return Err(TsplineError::Fit(format!("iteration {it}: the least-squares solution has non-finite control points")));
        }
        set_z(&mut mesh, &mut pb, &z);
        let t_opt = t0.elapsed().as_secs_f64();
        let region = local.as_ref().map(|(_, r)| r);
        let (mut err, mut over_leaves) = check(&mesh, &pb, samples, pts, region, backend, &mut errs, &tol)?;
        if err.over_tolerance == 0 && region.is_some() {
            // the tolerance is declared only on a fresh check of every cell
            (err, over_leaves) = check(&mesh, &pb, samples, pts, None, backend, &mut errs, &tol)?;
        }
        drop(local);
        let t_check = t0.elapsed().as_secs_f64();
        let st = IterationStats {
            iteration: it,
            control_points: pb.point_ids.len(),
            cells: mesh.leaf_count(),
            refined_cells: refined,
            merged_cells: 0,
            error: err.clone(),
            seconds: t0.elapsed().as_secs_f64(),
            seconds_build: t_build,
            seconds_optimise: t_opt - t_build,
            seconds_check: t_check - t_opt,
        };
        progress(&st);
        iterations.push(st);
        if err.over_tolerance == 0 {
            // the coarsened mesh's cells over the tolerance on its fresh check (None: it passed)
            let mut missed = None;
            if may_coarsen {
                let c = crate::coarsen::coarsen(mesh, pb, samples, pts, opts, backend, &mut errs, it + 1, progress, &tol)?;
                mesh = c.mesh;
                pb = c.pb;
                // the tolerance is declared only on a fresh check of every cell (scattered data:
                // every round coarsen::refit kept was already checked at every point)
                if pts.is_none() && !c.rounds.is_empty() {
                    let (f, over) = check(&mesh, &pb, samples, None, None, backend, &mut errs, &tol)?;
                    if f.over_tolerance > 0 {
                        // cannot happen when the checks above are sound; keep the guarantee
                        // anyway: refine where the coarsened mesh misses, coarsening off (no copy
                        // of the pre-coarsening mesh is kept for this:
                        // docs/decisions.md#coarsening-decides-before-it-writes)
                        missed = Some((f, over));
                    }
                }
                iterations.extend(c.rounds);
            }
            match missed {
                Some(m) => {
                    may_coarsen = false;
                    (err, over_leaves) = m;
                }
                None => {
                    // The acceptance: the mesh as written, evaluated as `geofit eval` evaluates it.
                    let (fin, over) = check_written(&mesh, &pb, samples, pts, &mut errs, &tol_final)?;
                    if fin.over_tolerance == 0 {
                        if let Some(last) = iterations.last_mut() {
                            last.error = fin;
                        }
                        return Ok(FitResult { mesh, iterations, stop: StopReason::ToleranceReached });
                    }
                    // beyond the margin: refine where the written mesh misses, as for any miss
                    may_coarsen = false;
                    (err, over_leaves) = (fin, over);
                }
            }
        }
        if it >= opts.max_iterations {
            return Ok(FitResult { mesh, iterations, stop: StopReason::MaxIterations });
        }
        match refine(&mesh, &pb, samples, opts, over_leaves, &err)? {
            Refined::Stop(stop) => return Ok(FitResult { mesh, iterations, stop }),
            Refined::Next(next, n_split) => {
                refined = n_split;
                // leaves of this mesh that the refinement (splits and repair) turned into parents
                split_rects = mesh.leaves().filter(|&c| !next.cells[c as usize].is_leaf()).map(|c| mesh.cells[c as usize].rect).collect();
                mesh = next;
                prev = Some(pb);
            }
        }
    }
    unreachable!("the loop returns")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Rect;

    use crate::testing::lcg;

    fn sample(pb: &PbSpline, w: usize, h: usize) -> Samples {
        let g = GridSpec { s0: 0.0, t0: 0.0, ds: 1.0, dt: 1.0, ns: w, nt: h };
        Samples { width: w, height: h, z: pb.eval_grid(&g, true).into() }
    }

    /// The radix selection agrees with sorting an f32 copy, across signs, zeros, infinities,
    /// ties and values that round to the same f32.
    #[test]
    fn nth_smallest_f32_is_the_sorted_f32_copys_element() {
        let mut seed = 3u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut errs: Vec<f64> = (0..200_000).map(|_| (rnd() - 0.3) * 10f64.powi((rnd() * 12.0) as i32 - 6)).collect();
        errs.extend([0.0, -0.0, f64::INFINITY, f64::NEG_INFINITY, f64::NAN, f64::NAN, 1.0, 1.0 + 1e-12, 1.0]);
        let mut sorted: Vec<f32> = errs.iter().filter(|e| !e.is_nan()).map(|&e| e as f32).collect();
        sorted.sort_by(|a, b| a.total_cmp(b));
        for k in [0, 1, 2, 7, 1000, sorted.len() / 2 - 1, sorted.len() / 2, sorted.len() - 2, sorted.len() - 1] {
            assert_eq!(nth_smallest_f32(&errs, [k])[0].to_bits(), sorted[k].to_bits(), "k = {k}");
            let [a, b] = nth_smallest_f32(&errs, [k, sorted.len() - 1 - k]);
            assert_eq!((a.to_bits(), b.to_bits()), (sorted[k].to_bits(), sorted[sorted.len() - 1 - k].to_bits()), "k = {k}");
        }
    }

    #[test]
    fn bilinear_standard_form() {
        let s = Samples { width: 2, height: 2, z: vec![1.0, 2.0, 3.0, f64::NAN].into() };
        assert_eq!(s.bilinear(0.0, 0.0), 1.0);
        assert_eq!(s.bilinear(1.0, 0.0), 2.0); // integer position next to a no-data corner
        assert_eq!(s.bilinear(0.5, 0.0), 1.5);
        assert!(s.bilinear(0.5, 0.5).is_nan());
        assert!(s.bilinear(-0.1, 0.0).is_nan());
    }

    /// Synthetic truth: a raster sampled from a known T-spline whose mesh is the fit's initial
    /// mesh refined by 4-way splits is recovered to 1e-9 — the surface, and (linear: nested
    /// spaces keep vertex values) the truth's control points.
    #[test]
    fn synthetic_truth_recovered() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let samples0 = Samples { width: 65, height: 65, z: vec![0.0; 65 * 65].into() };
            let mut opts = FitOptions::new(degree, 1e-9);
            opts.overhang = 0.0;
            let mut truth = initial_mesh(&samples0, &opts);
            assert_eq!(truth.bounds(), Rect::new(0.0, 0.0, 64.0, 64.0));
            let mut g = |s: f64, t: f64| (s, t, 0.0);
            for (s, t) in [(20.0, 20.0), (21.0, 21.0), (40.0, 50.0)] {
                let c = truth.leaves_in(Rect::new(s, t, s, t))[0];
                truth.split(c, &mut g);
            }
            truth.repair(1.0, &mut g);
            let mut seed = 5u64;
            for p in &mut truth.points {
                p.z = 100.0 * lcg(&mut seed) - 50.0;
            }
            let tpb = PbSpline::build(&truth);
            let samples = sample(&tpb, 65, 65);
            // geometry only, on the truth topology: the same control points
            let mut m = truth.clone();
            for p in &mut m.points {
                p.z = 0.0;
            }
            let pb = PbSpline::build(&m);
            let z = fit_lsq(&m, &pb, &samples).unwrap();
            for (i, &pid) in pb.point_ids.iter().enumerate() {
                assert!((z[i] - truth.points[pid as usize].z).abs() < 1e-9, "{degree:?}: {} vs {}", z[i], truth.points[pid as usize].z);
            }
            // the whole loop
            let r = fit(&samples, &opts, &Backend::Cpu, &mut |_| {}).unwrap();
            assert_eq!(r.stop, StopReason::ToleranceReached, "{degree:?}");
            assert!(r.iterations.last().unwrap().error.max <= 1e-9);
            if degree == Degree::Linear {
                for p in &truth.points {
                    let id = r.mesh.point_id_at(p.s, p.t).expect("truth point in the fitted mesh");
                    assert!((r.mesh.points[id as usize].z - p.z).abs() < 1e-9);
                }
            }
        }
    }

    /// The acceptance check evaluates the written mesh bitwise as `geofit eval` does on the
    /// raster's own grid (`PbSpline::eval_grid` in its north-up order: the separable path, and on
    /// a grid too sparse for it the reference path); per-point `eval_z` (eval --points) agrees to
    /// well inside the check's margin; the fitted surface read back holds E at every cell.
    #[test]
    fn final_check_evaluates_as_eval_does() {
        let (w, h) = (70, 50);
        let z: Vec<f64> = (0..w * h).map(|q| ((q % w) as f64 * 0.21).sin() * 7.0 + ((q / w) as f64 * 0.13).cos() * 4.0).collect();
        let s = Samples { width: w, height: h, z: z.into() };
        for (degree, method) in [(Degree::Cubic, Method::Lsq), (Degree::Linear, Method::Drag)] {
            let mut o = FitOptions::new(degree, 0.5);
            o.method = method;
            let r = fit(&s, &o, &Backend::Cpu, &mut |_| {}).unwrap();
            assert_eq!(r.stop, StopReason::ToleranceReached);
            let written = PbSpline::build(&as_written(&r.mesh).unwrap());
            for (gw, gh) in [(w, h), (3, 2)] {
                let st: Vec<[f64; 2]> = (0..gh).rev().flat_map(|j| (0..gw).map(move |i| [i as f64, j as f64])).collect();
                let z_eval = written.eval_z(&st, true);
                let ex = written.use_extraction(gw * gh).then(|| crate::extraction::Extraction::new(&written, true));
                assert_eq!(ex.is_some(), (gw, gh) == (w, h), "both paths covered");
                let z_rows = eval_rows_as_eval(&written, ex.as_ref(), gw, 0, gh);
                let north_up = GridSpec { s0: 0.0, t0: (gh - 1) as f64, ds: 1.0, dt: -1.0, ns: gw, nt: gh };
                let z_cli = written.eval_grid(&north_up, true);
                for (k, p) in st.iter().enumerate() {
                    let checked = z_rows[p[1] as usize * gw + p[0] as usize];
                    assert_eq!(z_cli[k].to_bits(), checked.to_bits(), "{degree:?} at {p:?}");
                    assert!((z_eval[k] - checked).abs() <= 1e-12 * (1.0 + checked.abs()), "{degree:?} at {p:?}");
                }
                if (gw, gh) == (w, h) {
                    let max = st.iter().enumerate().map(|(k, p)| (z_eval[k] - s.get(p[0] as usize, p[1] as usize)).abs()).fold(0.0, f64::max);
                    assert!(max <= 0.5, "{degree:?} {method:?}: {max}");
                }
            }
        }
    }

    /// The incremental PB-spline build (knots re-inferred only near split cells) equals a full
    /// build after every refinement step of a fit on a bumpy surface.
    #[test]
    fn incremental_knots_equal_full_inference() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut m = TMesh::grid(degree, -8.0, -8.0, 16.0, 5, 4);
            let mut g = |s: f64, t: f64| (s, t, 0.0);
            let mut seed = 11u64;
            let mut old = PbSpline::build(&m);
            for _ in 0..5 {
                let leaves: Vec<CellId> = m.leaves().collect();
                let mut next = m.clone();
                for &c in &leaves {
                    let r = m.cells[c as usize].rect;
                    if lcg(&mut seed) < 0.15 && r.width() >= 2.0 && next.cells[c as usize].is_leaf() {
                        next.split(c, &mut g);
                    }
                }
                next.repair(1.0, &mut g);
                let split: Vec<Rect> = m.leaves().filter(|&c| !next.cells[c as usize].is_leaf()).map(|c| m.cells[c as usize].rect).collect();
                let inc = build_pb_incremental(&next, &old, &split);
                let full = PbSpline::build(&next);
                assert_eq!(inc.point_ids, full.point_ids);
                assert_eq!(inc.knots, full.knots, "{degree:?}");
                m = next;
                old = full;
            }
        }
    }

    /// A tile's domain ends on its window's pixel edges at the anchored corner and reaches over
    /// the other sides by whole square cells; the fit's initial mesh is that grid.
    #[test]
    fn tile_domain_is_anchored_on_pixel_edges() {
        let d = Domain::anchored(100, 60, 25.0, true);
        assert_eq!((d.s0, d.ns, d.nt), (-0.5, 4, 3));
        assert_eq!(d.t0 + d.nt as f64 * d.cell, 59.5); // the top edge (first raster row)
        let d = Domain::anchored(100, 60, 25.0, false);
        assert_eq!(d.t0, -0.5);
        let samples = Samples { width: 100, height: 60, z: vec![1.0; 6000].into() };
        let mut o = FitOptions::new(Degree::Cubic, 0.1);
        o.domain = Some(Domain::anchored(100, 60, 25.0, true));
        let m = initial_mesh(&samples, &o);
        assert_eq!(m.bounds(), Rect::new(-0.5, -15.5, 99.5, 59.5));
        assert_eq!(m.leaf_count(), 12);
    }

    /// A plane is fitted with the initial mesh only (no refinement).
    #[test]
    fn plane_needs_only_the_initial_mesh() {
        let (w, h) = (120, 80);
        let z: Vec<f64> = (0..w * h).map(|q| 12.0 + 0.3 * (q % w) as f64 - 0.7 * (q / w) as f64).collect();
        let s = Samples { width: w, height: h, z: z.into() };
        let r = fit(&s, &FitOptions::new(Degree::Linear, 1e-6), &Backend::Cpu, &mut |_| {}).unwrap();
        assert_eq!(r.stop, StopReason::ToleranceReached);
        assert_eq!(r.iterations.len(), 1);
        assert!(r.iterations[0].error.max < 1e-8);
    }

    /// The loop honours the tolerance on a bumpy surface with holes, for both methods.
    #[test]
    fn tolerance_reached_everywhere() {
        let (w, h) = (90, 70);
        let z: Vec<f64> = (0..w * h)
            .map(|q| {
                let (x, y) = ((q % w) as f64, (q / w) as f64);
                if (x - 30.0).powi(2) + (y - 40.0).powi(2) < 60.0 {
                    f64::NAN
                } else {
                    (x * 0.15).sin() * 8.0 + (y * 0.07).cos() * 5.0 + 0.02 * x * y
                }
            })
            .collect();
        let s = Samples { width: w, height: h, z: z.into() };
        for (degree, method) in [(Degree::Linear, Method::Lsq), (Degree::Cubic, Method::Lsq), (Degree::Linear, Method::Drag)] {
            let mut o = FitOptions::new(degree, 0.25);
            o.method = method;
            let r = fit(&s, &o, &Backend::Cpu, &mut |_| {}).unwrap();
            let last = r.iterations.last().unwrap();
            match r.stop {
                StopReason::ToleranceReached => assert!(last.error.max <= 0.25),
                ref other => panic!("{degree:?} {method:?}: {other:?}, max {}", last.error.max),
            }
            // every leaf at least the sample spacing
            for c in r.mesh.leaves() {
                assert!(r.mesh.cells[c as usize].rect.width() >= 1.0);
            }
        }
    }

    #[test]
    fn control_point_cap_is_reported() {
        let (w, h) = (64, 64);
        let z: Vec<f64> = (0..w * h).map(|q| ((q % w) as f64 * 0.3).sin() * 10.0).collect();
        let s = Samples { width: w, height: h, z: z.into() };
        let mut o = FitOptions::new(Degree::Linear, 0.01);
        o.max_points = Some(60);
        let r = fit(&s, &o, &Backend::Cpu, &mut |_| {}).unwrap();
        assert_eq!(r.stop, StopReason::MaxPoints { cap: 60 });
        assert!(r.iterations.last().unwrap().control_points <= 60);
    }

    #[test]
    fn bad_inputs() {
        let s = Samples { width: 3, height: 3, z: vec![f64::NAN; 9].into() };
        assert!(fit(&s, &FitOptions::new(Degree::Linear, 1.0), &Backend::Cpu, &mut |_| {}).is_err());
        let s = Samples { width: 1, height: 1, z: vec![5.0].into() };
        assert!(fit(&s, &FitOptions::new(Degree::Linear, 0.0), &Backend::Cpu, &mut |_| {}).is_err());
        let r = fit(&s, &FitOptions::new(Degree::Cubic, 0.1), &Backend::Cpu, &mut |_| {}).unwrap();
        assert_eq!(r.stop, StopReason::ToleranceReached);
        // constant raster
        let s = Samples { width: 10, height: 7, z: vec![-3.0; 70].into() };
        let r = fit(&s, &FitOptions::new(Degree::Cubic, 1e-9), &Backend::Cpu, &mut |_| {}).unwrap();
        assert_eq!(r.iterations.len(), 1);
    }

    /// A local system: rows 1 and 3 held (identity rows, prior heights), rows 0, 2, 4 free
    /// and coupled. The mirror copies the upper triangle (checked against the transposed
    /// search), and the free-block solve gives the held points their priors exactly and the
    /// free ones the solution of the free block (its inverse applied by hand: the 3×3 system
    /// tridiag(−1, 4, −1) with b = A·(1, 2, 3)).
    #[test]
    fn free_block_solve_matches_the_whole_system() {
        let rows: [&[u32]; 5] = [&[0, 2], &[1], &[0, 2, 4], &[3], &[2, 4]];
        let mut a = Csr { start: vec![0], cols: Vec::new(), vals: Vec::new() };
        for r in rows {
            a.cols.extend_from_slice(r);
            a.start.push(a.cols.len());
        }
        // upper triangle only, as the assembly leaves it
        let upper = |i: usize, j: usize| if i == j { if i % 2 == 1 { 1.0 } else { 4.0 } } else { -1.0 };
        a.vals = (0..5).flat_map(|i| rows[i].iter().map(move |&j| if j as usize >= i { upper(i, j as usize) } else { f64::NAN })).collect();
        mirror_upper(&mut a);
        for i in 0..5 {
            for k in a.start[i]..a.start[i + 1] {
                let j = a.cols[k] as usize;
                assert_eq!(a.vals[k], a.vals[entry(&a, j, i as u32)]);
            }
        }
        let truth = [1.0, 2.0, 3.0];
        let b_free = [4.0 * 1.0 - 2.0, -1.0 + 4.0 * 2.0 - 3.0, -2.0 + 4.0 * 3.0];
        let prior = [0.5, 7.25, 0.5, -3.5, 0.5];
        let rhs = [b_free[0], prior[1], b_free[1], prior[3], b_free[2]];
        let free = [true, false, true, false, true];
        let z = solve_free(&a, &rhs, &prior, &free).unwrap();
        assert_eq!((z[1], z[3]), (7.25, -3.5));
        for (q, i) in [0, 2, 4].into_iter().enumerate() {
            assert!((z[i] - truth[q]).abs() < 1e-12, "{z:?}");
        }
        let whole = solve(&a, &rhs, &prior).unwrap();
        assert!(whole.iter().zip(&z).all(|(p, q)| (p - q).abs() < 1e-12));
    }

    /// A ridge: heights that vary along s only (a sharp profile), the same in every row. The
    /// anisotropic refinement cuts across s and needs fewer control points than 4-splits at the
    /// same tolerance, which both meet at every raster cell on an evaluation of the output mesh
    /// alone; and the blending functions of the anisotropic mesh stay linearly independent.
    #[test]
    fn aniso_fits_a_ridge_with_fewer_points() {
        let (w, h) = (97usize, 65usize);
        let profile = |x: f64| 8.0 * (-((x - 40.0) / 3.0).powi(2)).exp() + 0.05 * x + 2.0 * (x * 0.3).sin();
        let z: Vec<f64> = (0..w * h).map(|q| profile((q % w) as f64)).collect();
        let samples = Samples { width: w, height: h, z: z.into() };
        for degree in [Degree::Linear, Degree::Cubic] {
            let e = 0.05;
            let mut n = Vec::new();
            for rule in [SplitRule::Quad, SplitRule::Anisotropic] {
                let mut o = FitOptions::new(degree, e);
                o.split = rule;
                let r = fit(&samples, &o, &Backend::Cpu, &mut |_| {}).unwrap();
                assert_eq!(r.stop, StopReason::ToleranceReached, "{degree:?} {rule:?}");
                let pb = PbSpline::build(&as_written(&r.mesh).unwrap());
                let mut errs = vec![0.0; w * h];
                eval_errors(&pb, &samples, &Backend::Cpu, &mut errs).unwrap();
                let max = errs.iter().cloned().fold(0.0, f64::max);
                assert!(max <= e, "{degree:?} {rule:?}: max |dz| {max}");
                if rule == SplitRule::Anisotropic {
                    assert!(r.mesh.leaves().any(|c| { let q = r.mesh.cells[c as usize].rect; q.width() < q.height() }), "no cell cut across s");
                    assert_linearly_independent(&r.mesh);
                }
                n.push(pb.point_ids.len());
            }
            eprintln!("ridge {degree:?}: quad {} control points, aniso {}", n[0], n[1]);
            assert!(n[1] < n[0], "{degree:?}: aniso {} control points, quad {}", n[1], n[0]);
        }
    }

    /// The blending functions of `mesh` (rational, as the fit uses them: independent iff the
    /// N_i are, Σ w N > 0) are linearly independent: their Gram
    /// matrix, sampled at 4×4 points per leaf cell, has a Cholesky factor whose smallest pivot
    /// is not negligible next to the largest diagonal entry.
    pub(crate) fn assert_linearly_independent(mesh: &TMesh) {
        let pb = PbSpline::build(mesh);
        let n = pb.point_ids.len();
        assert!(n < 3000, "a small mesh: {n} points");
        let mut g = vec![0.0f64; n * n];
        let mut scratch = Vec::new();
        let mut row: Vec<(u32, f64)> = Vec::new();
        for c in mesh.leaves() {
            let r = mesh.cells[c as usize].rect;
            for a in 0..4 {
                for b in 0..4 {
                    let s = r.s_min + (a as f64 + 0.5) / 4.0 * r.width();
                    let t = r.t_min + (b as f64 + 0.5) / 4.0 * r.height();
                    row.clear();
                    pb.for_each_basis(s, t, &mut scratch, |i, v| row.push((i, v)));
                    for &(i, vi) in &row {
                        for &(j, vj) in &row {
                            g[i as usize * n + j as usize] += vi * vj;
                        }
                    }
                }
            }
        }
        let dmax = (0..n).map(|i| g[i * n + i]).fold(0.0, f64::max);
        // dense Cholesky, lower triangle in place
        let mut min_pivot = f64::INFINITY;
        for j in 0..n {
            let mut d = g[j * n + j];
            for k in 0..j {
                d -= g[j * n + k] * g[j * n + k];
            }
            min_pivot = min_pivot.min(d);
            assert!(d > 1e-10 * dmax, "dependent blending functions: pivot {d} of {dmax} at point {j} of {n}");
            let d = d.sqrt();
            g[j * n + j] = d;
            for i in j + 1..n {
                let mut v = g[i * n + j];
                for k in 0..j {
                    v -= g[i * n + k] * g[j * n + k];
                }
                g[i * n + j] = v / d;
            }
        }
        eprintln!("linear independence: {n} blending functions, smallest Cholesky pivot {min_pivot:.3e} of largest diagonal {dmax:.3e}");
    }

    /// Random anisotropic meshes (2- and 4-splits, anisotropic repair): linearly independent
    /// blending functions, linear and cubic.
    #[test]
    fn aniso_meshes_are_linearly_independent() {
        for degree in [Degree::Linear, Degree::Cubic] {
            for seed in [11u64, 12, 13] {
                assert_linearly_independent(&crate::testing::aniso_mesh(degree, seed, 3));
            }
        }
    }
}
