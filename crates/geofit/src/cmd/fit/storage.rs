//! Heights stored to the error budget (issue 37): `fit --max-error E -o x.tmb` fits at
//! `E − q` and stores the control-point heights in steps of `2q`, `q` = the storage share of E;
//! the blending functions are a partition of unity, so the decoded surface stays within E
//! (docs/decisions.md#heights-quantised-to-the-error-budget-issue-37). The file's bytes are
//! decoded again and evaluated at every valid cell before they are written: the guarantee
//! is checked on the file as written, not on the fit's mesh.

use tspline::eval::{GridSpec, PbSpline};
use tspline::fit::{FitOptions, Samples};
use tspline::format::{Encoding, TMeshFile};
use tspline::tmb::WriteOptions;

use super::input::Prepared;
use super::Args;
use crate::error::CliError;

/// The storage share of the tolerance on smooth data (when `--storage-share` is not given): the
/// smallest files in total over the LiDAR DEM (0.5, 0.25, 0.1 m), the BAG (0.25, 0.1 m) and
/// Kilauea (5 m) among 0.1, 0.15, 0.2, 0.3 and 0.5 (within 5 % of each row's best; 0.3 was
/// 1–30 % larger, 0.5 up to 95 %): benches/results/tmb.md,
/// docs/decisions.md#heights-quantised-to-the-error-budget-issue-37.
pub(super) const SMOOTH_SHARE: f64 = 0.15;
/// The share on data rough at cell scale, where the mesh needs nearly a control point per cell
/// whatever the fit's share, so the bytes per height decide: 0.7 was the smallest of 0.15 … 0.7
/// on all seven rough rows measured (Iceland, GMT bathymetry, Guinea bay, DEM hills).
pub(super) const ROUGH_SHARE: f64 = 0.7;
/// Fraction of second differences over E from which data counts as rough: the smooth rows
/// measured were ≤ 0.06, the rough ones ≥ 0.28.
const ROUGH_FRACTION: f64 = 0.2;

/// The share of the tolerance the stored heights may take, or None for lossless heights (an
/// XML output, `--lossless`, `--indirect`: its mesh is mapped back through the warp; a tile of
/// a plan, `--srcwin` / `--tile`: `tile stitch` joins the tiles' own heights along the seams and
/// writes the delivered files itself).
pub(super) fn share(args: &Args, p: &Prepared) -> Option<f64> {
    let binary = Encoding::for_path(args.output.as_deref()) == Encoding::Binary;
    let tile = args.srcwin.is_some() || args.tile.is_some();
    if !binary || args.lossless || args.indirect || tile {
        return None;
    }
    Some(args.storage_share.unwrap_or_else(|| {
        if roughness(&p.samples, p.e_min) >= ROUGH_FRACTION {
            ROUGH_SHARE
        } else {
            SMOOTH_SHARE
        }
    }))
}

/// The fraction of the raster's second differences (|z[i−1] − 2 z\[i\] + z[i+1]| along rows and
/// columns, over valid cells) above `e`: how much of the data a smooth surface cannot follow
/// within E between neighbouring cells.
pub(super) fn roughness(s: &Samples, e: f64) -> f64 {
    let (w, h) = (s.width, s.height);
    let z = |i: usize, j: usize| s.z.get(j * w + i);
    let (mut n, mut over) = (0usize, 0usize);
    let mut count = |a: f64, b: f64, c: f64| {
        let d = (a - 2.0 * b + c).abs();
        if d.is_finite() {
            n += 1;
            over += (d > e) as usize;
        }
    };
    for j in 0..h {
        for i in 1..w.saturating_sub(1) {
            count(z(i - 1, j), z(i, j), z(i + 1, j));
        }
    }
    for j in 1..h.saturating_sub(1) {
        for i in 0..w {
            count(z(i, j - 1), z(i, j), z(i, j + 1));
        }
    }
    if n == 0 {
        0.0
    } else {
        over as f64 / n as f64
    }
}

/// `--storage-share` must leave the fit a share: within (0, 0.9].
pub(super) fn check_share(args: &Args) -> Result<(), CliError> {
    match args.storage_share {
        Some(r) if !(r > 0.0 && r <= 0.9) => {
            Err(CliError::usage(format!("--storage-share must be within (0, 0.9], got {r}")))
        }
        Some(_) if args.lossless => {
            Err(CliError::usage("--storage-share sets how far the stored heights may move: not with --lossless"))
        }
        _ => Ok(()),
    }
}

/// Takes the storage share off the fit's tolerances: the fit aims at (1 − r)·T at every cell
/// (the floor and the uncertainty multiple alike), so T·(1 − r) + r·E_min ≤ T.
pub(super) fn fit_share(args: &Args, p: &Prepared, opts: &mut FitOptions) {
    if let Some(r) = share(args, p) {
        opts.max_error *= 1.0 - r;
        if let Some(c) = &mut opts.cell_tolerance {
            c.k *= 1.0 - r;
            c.floor *= 1.0 - r;
        }
    }
}

/// What the stored file holds and how far its decoded surface is from the data.
#[derive(Debug, Clone, serde::Serialize)]
pub(super) struct Stored {
    /// The half-step `q` of the heights (the most a control point moved), null: lossless.
    pub quantum: Option<f64>,
    /// max |Δz| over the valid cells of the file decoded from its bytes (null: lossless
    /// heights, which the fit checked as written, or a fit that missed its tolerance).
    pub decoded_max_abs_error: Option<f64>,
    pub bytes: usize,
}

/// Encodes `file` as `args` asks. A quantised `.tmb` of a fit that reached its tolerance is
/// decoded and evaluated at every valid cell; a cell over its tolerance (not expected: the fit
/// left `q` free) halves `q`, down to lossless heights after three tries.
pub(super) fn encode(file: &TMeshFile, args: &Args, p: &Prepared, fit_ok: bool) -> Result<(Vec<u8>, Stored), CliError> {
    let encoding = Encoding::for_path(args.output.as_deref());
    let mut q = share(args, p).map(|r| r * p.e_min);
    for tries in 0.. {
        let mut bytes = Vec::new();
        match encoding {
            Encoding::Binary => {
                tspline::tmb::write_with(file, &WriteOptions { quantum: q }, &mut bytes).map_err(CliError::io_out)?
            }
            Encoding::Xml => tspline::format::write(file, &mut bytes).map_err(CliError::io_out)?,
        }
        // lossless heights are the fit's own, checked as written by the fit
        let checked = if fit_ok && q.is_some() { Some(decoded_errors(&bytes, p)?) } else { None };
        if checked.is_none_or(|(_, over)| over == 0) {
            let stored = Stored { quantum: q, decoded_max_abs_error: checked.map(|c| c.0), bytes: bytes.len() };
            return Ok((bytes, stored));
        }
        q = if tries < 2 { q.map(|v| 0.5 * v) } else { None };
    }
    unreachable!("the loop returns by lossless heights at the latest")
}

/// (max |Δz|, cells over their tolerance) of the mesh decoded from `bytes`, evaluated at every
/// cell of the raster as `geofit eval` evaluates it on the fitted grid.
fn decoded_errors(bytes: &[u8], p: &Prepared) -> Result<(f64, usize), CliError> {
    if p.points.is_some() {
        return Ok((f64::NAN, 0)); // --indirect: stored lossless, checked by the fit
    }
    let back = tspline::format::read(bytes)
        .map_err(|e| CliError::internal(format!("the T-mesh just encoded does not read back: {e}")))?;
    let s: &Samples = &p.samples;
    let g = GridSpec { s0: 0.0, t0: 0.0, ds: 1.0, dt: 1.0, ns: s.width, nt: s.height };
    let z = PbSpline::build(&back.mesh).eval_grid(&g, true);
    let (mut worst, mut over) = (0.0f64, 0usize);
    for (q, zq) in z.iter().enumerate() {
        let d = s.z.get(q);
        if d.is_nan() {
            continue;
        }
        let e = if zq.is_nan() { f64::INFINITY } else { (zq - d).abs() };
        let tol = p.cell_tolerance.as_ref().map_or(p.e_min, |c| c.at(q));
        worst = worst.max(e);
        over += (e > tol) as usize;
    }
    Ok((worst, over))
}
