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
//!   the blending functions (new points, changed knots; on a system of 10⁴ points or more: at
//!   most half of them, and at most 70 % of the points free), only those points and the points whose
//!   supports overlap theirs are re-solved (the others held, their terms on the right-hand side)
//!   and only the cells inside the re-solved supports — the only cells whose surface value can
//!   change — are re-evaluated; "tolerance reached" is declared only after a fresh check of
//!   every cell. Knots are re-inferred only for points whose support meets a split cell.
//!   The OpenCL model-matrix rows (T29) are in `ocl_fit` (kernel + CPU twin).
//! - **Coarsening** (`coarsen`, our extension of §3.9): after the tolerance is reached
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

mod approximation;
mod check;
mod coarsen;
mod drag;
mod errors;
mod least_squares;
mod refine;
mod samples;

pub use check::*;
pub use drag::*;
pub use errors::*;
pub use least_squares::*;
pub(crate) use refine::*;
pub use samples::*;

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
    /// not need (`coarsen`).
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
        FitOptions {
            degree,
            max_error,
            max_points: None,
            max_iterations: 100,
            method: Method::Lsq,
            overhang: 0.25,
            initial_cells: 4,
            drag_steps: 40,
            local_updates: true,
            opencl_assembly: false,
            coarsen: true,
            cell_tolerance: None,
            domain: None,
            split: SplitRule::Quad,
        }
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
    MaxPoints {
        cap: usize,
    },
    MaxIterations,
    /// Cells over the tolerance remain, but their mesh cells are at the minimum size.
    MinCellSize {
        cells_over: usize,
    },
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
    let tree: RTree<Rectangle<[f64; 2]>> = RTree::bulk_load(
        split.iter().map(|r| Rectangle::from_corners([r.s_min, r.t_min], [r.s_max, r.t_max])).collect(),
    );
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
    // the points that keep their old knots keep their old polynomial pieces too
    let reuse: Vec<u32> =
        point_ids.iter().zip(&knots).map(|(&i, kn)| if kn.is_some() { old_of[i as usize] } else { u32::MAX }).collect();
    let knots = crate::knots::infer_missing(mesh, &point_ids, knots);
    PbSpline::from_parts_reusing(mesh, point_ids, knots, Some((old, &reuse)))
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
            let covers = if opts.overhang > 0.0 {
                o < 0.0 && o + *n as f64 * c0 > len
            } else {
                o <= 0.0 && o + *n as f64 * c0 >= len
            };
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
    if cnt == 0 {
        0.0
    } else {
        sum / cnt as f64
    }
}

/// Rasters from which [`release_free_memory`] trims (2²⁴ cells).
pub(crate) const TRIM_CELLS: usize = 1 << 24;

/// Hands the allocator's free pages back to the system (glibc's `malloc_trim`; elsewhere
/// nothing). Why: glibc keeps freed blocks below its (dynamic, up to 32 MiB) mmap threshold in
/// its arenas, so the partial sums of one assembly and the PB-spline of the previous iteration
/// stayed resident under the next solve's factor; called before each solve and each
/// iteration, it takes tens of MiB off the peak (~30 MiB at 10⁷ cells) for a few ms per call
/// (BENCHMARKS.md "Peak memory per cell without the copies"). Since
/// [`big_blocks_from_system`] fixes the threshold at 8 MiB on the same rasters, what it trims
/// are the blocks below that.
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

/// Rasters from this many cells on free the Cholesky's factor and scratch after every solve.
/// Why: kept, they sit under the next error pass, whose per-cell arrays dominate on large
/// rasters (10⁷ cells: 482 → 574 MiB peak with them kept); below it they are kept for the next
/// solve (BAG, 2.5·10⁶ cells: ~0.2 s less of the fit's one thread for ~40 MiB more peak;
/// BENCHMARKS.md "Kept solver workspace, one final check").
pub(crate) const KEEP_WORKSPACE_BELOW_CELLS: usize = 1 << 23;

/// Frees the Cholesky's kept factor and scratch (`sparse_spd::release_workspace`) on rasters
/// of [`KEEP_WORKSPACE_BELOW_CELLS`] cells or more; on smaller ones they stay for the next
/// solve (no fresh pages to fault in). Called after every least-squares solve (`Normal::solve`).
pub(crate) fn release_solver_workspace(cells: usize) {
    if cells >= KEEP_WORKSPACE_BELOW_CELLS {
        sparse_spd::release_workspace();
    }
}

/// Big blocks (8 MiB or more) come from the system and go back to it when freed, for the rest
/// of the process (glibc's `mallopt(M_MMAP_THRESHOLD)`; elsewhere nothing). Why: glibc's
/// threshold grows with the blocks freed (up to 32 MiB), so the solves' factors, partial sums
/// and PB-splines of one iteration were kept in its arenas under the next one's; fixed at 8
/// MiB, the 10⁸-cell fit peaks ~70 MiB lower, for ~6 s more system time in ~50 s
/// (docs/decisions.md#big-blocks-from-the-system). Only for rasters of [`TRIM_CELLS`] cells
/// or more, and not when the user set glibc's own `MALLOC_MMAP_THRESHOLD_`.
pub(crate) fn big_blocks_from_system(cells: usize) {
    let _ = cells;
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if cells >= TRIM_CELLS && std::env::var_os("MALLOC_MMAP_THRESHOLD_").is_none() {
        const M_MMAP_THRESHOLD: std::os::raw::c_int = -3;
        extern "C" {
            fn mallopt(param: std::os::raw::c_int, value: std::os::raw::c_int) -> std::os::raw::c_int;
        }
        // SAFETY: glibc's mallopt takes no pointer and may be called at any time
        unsafe {
            mallopt(M_MMAP_THRESHOLD, 8 << 20);
        }
    }
}

/// The approximation loop (Alg. 3). `progress` gets every iteration's statistics.
pub fn fit(
    samples: &Samples,
    opts: &FitOptions,
    backend: &Backend,
    progress: &mut dyn FnMut(&IterationStats),
) -> Result<FitResult, TsplineError> {
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
    if pts.st.len() != pts.z.len()
        || pts.z.iter().any(|v| !v.is_finite())
        || pts.st.iter().flatten().any(|v| !v.is_finite())
    {
        return Err(TsplineError::Fit("scattered data: positions and values must be finite and as many".into()));
    }
    if pts.z.is_empty() {
        return Err(TsplineError::Fit("the raster has no valid cell".into()));
    }
    fit_impl(grid, Some(pts), opts, backend, progress)
}

fn fit_impl(
    samples: &Samples,
    pts: Option<&Scattered>,
    opts: &FitOptions,
    backend: &Backend,
    progress: &mut dyn FnMut(&IterationStats),
) -> Result<FitResult, TsplineError> {
    check_inputs(samples, pts, opts)?;
    big_blocks_from_system(samples.z.len());
    approximation::Approximation::new(samples, pts, opts, backend)?.run(initial_mesh(samples, opts), progress)
}

/// The arguments and data a fit refuses before it starts: a tolerance that is not a positive
/// number, an empty raster or one without a valid cell, values out of range, anisotropic
/// splits on a tile of a plan.
fn check_inputs(samples: &Samples, pts: Option<&Scattered>, opts: &FitOptions) -> Result<(), TsplineError> {
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
        return Err(TsplineError::Fit(
            "anisotropic splits are not available for tiles of a plan (their seams need square cells)".into(),
        ));
    }
    if let Some(p) = pts {
        check_value_range(&p.z)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assembly::entry;
    use crate::mesh::Rect;

    use crate::testing::lcg;

    fn sample(pb: &PbSpline, w: usize, h: usize) -> Samples {
        let g = GridSpec { s0: 0.0, t0: 0.0, ds: 1.0, dt: 1.0, ns: w, nt: h };
        Samples { width: w, height: h, z: pb.eval_grid(&g, true).into() }
    }

    /// A region is the set of cells its rectangles cover: membership and count against a set
    /// built cell by cell, for rectangles that start, end and span 64-bit words anywhere
    /// (rows of 150 cells: runs cross word boundaries), overlap, and stick out of the raster.
    #[test]
    fn region_holds_the_cells_of_its_rectangles() {
        let (w, h) = (150, 40);
        let mut r = Region::new(w, h);
        let mut truth = std::collections::HashSet::new();
        let mut seed = 3u64;
        for _ in 0..60 {
            let s0 = lcg(&mut seed) * 170.0 - 10.0;
            let t0 = lcg(&mut seed) * 50.0 - 5.0;
            let (s1, t1) = (s0 + lcg(&mut seed) * 90.0, t0 + lcg(&mut seed) * 12.0);
            r.add_rect(s0, s1, t0, t1);
            for j in 0..h {
                for i in 0..w {
                    if (i as f64) >= s0 && (i as f64) <= s1 && (j as f64) >= t0 && (j as f64) <= t1 {
                        truth.insert(j * w + i);
                    }
                }
            }
            assert_eq!(r.len(), truth.len());
        }
        assert!((0..w * h).all(|q| r.contains(q) == truth.contains(&q)));
        let mut listed = Vec::new();
        r.for_rows(0, h, |q| listed.push(q));
        assert_eq!(listed.len(), truth.len());
    }

    /// A passing local try's kept verdict writes into `errs` exactly what the region evaluation
    /// writes (bit for bit, cells outside the region untouched), and the verdict counts the
    /// region's cells over the tolerance as a count over those errors does. Data: the surface
    /// of a refined mesh plus a ripple, on a raster so wide that a verdict block is 16 rows:
    /// five blocks, the middle one without a region cell.
    #[test]
    fn kept_verdict_errors_are_the_region_errors() {
        let mesh = crate::testing::refined_mesh(Degree::Cubic);
        let pb = PbSpline::build(&mesh);
        let (w, h) = (4096, 80);
        let mut s = sample(&pb, w, h);
        let z: Vec<f64> = (0..w * h)
            .map(|q| s.z.get(q) + if q % 7 == 0 { f64::NAN } else { 0.3 * ((q % 13) as f64 - 6.0) })
            .collect();
        s.z = z.into();
        let mut region = Region::new(w, h);
        region.add_rect(5.5, 40.0, 3.0, 30.2);
        region.add_rect(60.0, 95.0, 50.0, 79.0);
        let tol = Tolerance::uniform(1.0);
        let (count, _, kept) = over_tolerance_region(&mesh, &pb, &s, &region, &tol);
        assert!(kept.kept());
        let mut evaluated = vec![-7.0; w * h];
        eval_errors_region(&pb, &s, &region, &mut evaluated);
        let mut written = vec![-7.0; w * h];
        kept.write(&region, w, &mut written);
        assert!(evaluated.iter().zip(&written).all(|(a, b)| a.to_bits() == b.to_bits()));
        let over = evaluated.iter().filter(|&&e| e > 1.0).count();
        assert!(over > 0 && count == over, "{count} vs {over}");
        assert_eq!(written.iter().filter(|&&e| e != -7.0).count(), region.len());
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
            assert_eq!(
                (a.to_bits(), b.to_bits()),
                (sorted[k].to_bits(), sorted[sorted.len() - 1 - k].to_bits()),
                "k = {k}"
            );
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
                assert!(
                    (z[i] - truth.points[pid as usize].z).abs() < 1e-9,
                    "{degree:?}: {} vs {}",
                    z[i],
                    truth.points[pid as usize].z
                );
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

    /// The final check evaluates the compacted mesh in place of the mesh read back from its
    /// file: both are the same points (bit for bit), in the same order, and the same leaves.
    #[test]
    fn written_mesh_is_the_compacted_mesh() {
        let (w, h) = (60, 45);
        let z: Vec<f64> = (0..w * h)
            .map(|q| ((q % w) as f64 * 0.37).sin() * 3.0 + ((q / w) as f64 * 0.29).cos() * 5.0 + 1e3)
            .collect();
        let s = Samples { width: w, height: h, z: z.into() };
        for degree in [Degree::Linear, Degree::Cubic] {
            let r = fit(&s, &FitOptions::new(degree, 0.2), &Backend::Cpu, &mut |_| {}).unwrap();
            assert!(
                r.iterations.iter().any(|it| it.merged_cells > 0) || degree == Degree::Cubic,
                "a coarsened mesh (dead cells) is covered"
            );
            let (read, compact) = (as_written(&r.mesh).unwrap(), r.mesh.compacted());
            let bits = |m: &TMesh| {
                m.points.iter().map(|p| [p.s, p.t, p.x, p.y, p.z, p.w].map(f64::to_bits)).collect::<Vec<_>>()
            };
            assert_eq!(bits(&read), bits(&compact), "{degree:?}");
            let leaves = |m: &TMesh| m.cells.iter().map(|c| (c.corners, c.is_leaf())).collect::<Vec<_>>();
            assert_eq!(leaves(&read), leaves(&compact), "{degree:?}");
            assert!(
                compact.points.len() < r.mesh.points.len() || compact.cells.len() < r.mesh.cells.len(),
                "compaction dropped something"
            );
        }
    }

    /// The acceptance check evaluates the written mesh bitwise as `geofit eval` does on the
    /// raster's own grid (`PbSpline::eval_grid` in its north-up order: the separable path, and on
    /// a grid too sparse for it the reference path); per-point `eval_z` (eval --points) agrees to
    /// well inside the check's margin; the fitted surface read back holds E at every cell.
    #[test]
    fn final_check_evaluates_as_eval_does() {
        let (w, h) = (70, 50);
        let z: Vec<f64> =
            (0..w * h).map(|q| ((q % w) as f64 * 0.21).sin() * 7.0 + ((q / w) as f64 * 0.13).cos() * 4.0).collect();
        let s = Samples { width: w, height: h, z: z.into() };
        for (degree, method) in [(Degree::Cubic, Method::Lsq), (Degree::Linear, Method::Drag)] {
            let mut o = FitOptions::new(degree, 0.5);
            o.method = method;
            let r = fit(&s, &o, &Backend::Cpu, &mut |_| {}).unwrap();
            assert_eq!(r.stop, StopReason::ToleranceReached);
            let written = PbSpline::build(&as_written(&r.mesh).unwrap());
            for (gw, gh) in [(w, h), (3, 2)] {
                let st: Vec<[f64; 2]> =
                    (0..gh).rev().flat_map(|j| (0..gw).map(move |i| [i as f64, j as f64])).collect();
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
                    let max = st
                        .iter()
                        .enumerate()
                        .map(|(k, p)| (z_eval[k] - s.get(p[0] as usize, p[1] as usize)).abs())
                        .fold(0.0, f64::max);
                    assert!(max <= 0.5, "{degree:?} {method:?}: {max}");
                }
            }
        }
    }

    /// The incremental PB-spline build (knots re-inferred only near split cells, polynomial
    /// pieces kept where the knots are) equals a full build after every refinement step of a
    /// fit on a bumpy surface.
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
                let split: Vec<Rect> = m
                    .leaves()
                    .filter(|&c| !next.cells[c as usize].is_leaf())
                    .map(|c| m.cells[c as usize].rect)
                    .collect();
                let inc = build_pb_incremental(&next, &old, &split);
                let full = PbSpline::build(&next);
                assert_eq!(inc.point_ids, full.point_ids);
                assert_eq!(inc.knots, full.knots, "{degree:?}");
                // the polynomial pieces kept from `old` are the ones a full build computes
                assert!(
                    inc.poly.iter().zip(&full.poly).all(|(a, b)| a.to_bits() == b.to_bits())
                        && inc.poly.len() == full.poly.len(),
                    "{degree:?}"
                );
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
        for (degree, method) in
            [(Degree::Linear, Method::Lsq), (Degree::Cubic, Method::Lsq), (Degree::Linear, Method::Drag)]
        {
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
        let upper = |i: usize, j: usize| {
            if i == j {
                if i % 2 == 1 {
                    1.0
                } else {
                    4.0
                }
            } else {
                -1.0
            }
        };
        a.vals = (0..5)
            .flat_map(|i| rows[i].iter().map(move |&j| if j as usize >= i { upper(i, j as usize) } else { f64::NAN }))
            .collect();
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
                    assert!(
                        r.mesh.leaves().any(|c| {
                            let q = r.mesh.cells[c as usize].rect;
                            q.width() < q.height()
                        }),
                        "no cell cut across s"
                    );
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
