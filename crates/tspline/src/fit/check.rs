//! Checks of the input values and of the result: the value range, the tolerance check of an
//! iteration, the tolerances and the check of the mesh as written
//! (docs/decisions.md#the-guarantee-holds-for-what-eval-computes).

use super::*;

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
pub(super) fn check_heights_range(z: &Heights) -> Result<(), TsplineError> {
    check_range_of(z.iter())
}

pub(super) fn check_range_of(z: impl Iterator<Item = f64>) -> Result<(), TsplineError> {
    let (min, max) =
        z.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    // no finite value at all is not a range problem: the fit names the empty raster itself
    if min <= max && (min.abs() > MAX_ABS_VALUE || max.abs() > MAX_ABS_VALUE) {
        return Err(TsplineError::ValueRange { min, max, limit: MAX_ABS_VALUE });
    }
    Ok(())
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
        errs.par_iter_mut()
            .zip(&z)
            .zip(&p.z)
            .for_each(|((e, zk), dk)| *e = if zk.is_nan() { f64::INFINITY } else { (zk - dk).abs() });
        return Ok(summarize_at(mesh, pb, &|q| (p.st[q][0], p.st[q][1]), errs, tol));
    }
    match region {
        Some(r) => eval_errors_region(pb, samples, r, errs),
        None => eval_errors(pb, samples, backend, errs)?,
    }
    Ok(summarize(mesh, pb, samples.width, errs, tol))
}

/// [`check`] of a local try on a raster whose verdict kept its region's errors (`kept`,
/// [`over_tolerance_region`]): they are written into `errs`, not evaluated again.
pub(crate) fn check_kept(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    region: &Region,
    kept: &RegionErrors,
    errs: &mut [f64],
    tol: &Tolerance,
) -> (ErrorStats, Vec<CellId>) {
    kept.write(region, samples.width, errs);
    summarize(mesh, pb, samples.width, errs, tol)
}

/// The loop's tolerance (T − δ) and the final acceptance check's (T − δ/2), δ the margin of
/// `crate::tolerance` (docs/decisions.md#the-guarantee-holds-for-what-eval-computes): the loop
/// and its coarsening keep δ free, the check of the written mesh may use half of it for the
/// rounding between the loop's and `eval`'s evaluation paths, and the other half stays for
/// the paths not checked here (the OpenCL kernels).
pub(crate) fn tolerances(
    samples: &Samples,
    pts: Option<&Scattered>,
    opts: &FitOptions,
) -> Result<(Tolerance, Tolerance), TsplineError> {
    let zscale = match pts {
        Some(p) => p.z.iter().filter(|v| v.is_finite()).fold(0.0f64, |m, v| m.max(v.abs())),
        None => samples.z.iter().filter(|v| v.is_finite()).fold(0.0f64, |m, v| m.max(v.abs())),
    };
    let (cells, min_tol) = match &opts.cell_tolerance {
        None => (None, opts.max_error),
        Some(c) => {
            if pts.is_some() {
                return Err(TsplineError::Fit(
                    "a per-cell tolerance applies to raster fits, not to scattered points (--indirect)".into(),
                ));
            }
            if c.uncertainty.len() != samples.z.len() {
                return Err(TsplineError::Fit(format!(
                    "{} per-cell tolerances for {} cells",
                    c.uncertainty.len(),
                    samples.z.len()
                )));
            }
            let min = c.min_over(|q| !samples.z.get(q).is_nan()).unwrap_or(opts.max_error);
            if !(min > 0.0 && min.is_finite()) {
                return Err(TsplineError::Fit(format!(
                    "the per-cell tolerance must be positive at every valid cell, got {min}"
                )));
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
    let file = crate::format::TMeshFile {
        mesh: mesh.clone(),
        georef: crate::format::Georef::identity(),
        mask: None,
        warp: None,
    };
    let mut bytes = Vec::new();
    crate::format::write(&file, &mut bytes)?;
    Ok(crate::format::read(&bytes)?.mesh)
}

/// Heights of the surface of `pb` on the raster rows j0..j1 exactly as [`PbSpline::eval_z`]
/// computes them for the whole grid `w`×`h` at once (`geofit eval` on the fitted grid): the
/// same element-extraction-or-reference choice (made for `w·h` points, not per block), the same
/// per-point arithmetic (an element owns its points half-open, so the row order does not
/// matter). `ex`: the extraction when that choice takes it.
pub(super) fn eval_rows_as_eval(
    pb: &PbSpline,
    ex: Option<&crate::extraction::Extraction>,
    w: usize,
    j0: usize,
    j1: usize,
) -> Vec<f64> {
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
    written_errors(mesh, samples, pts, errs)?;
    Ok(match pts {
        Some(p) => summarize_at(mesh, pb, &|q| (p.st[q][0], p.st[q][1]), errs, tol),
        None => summarize(mesh, pb, samples.width, errs, tol),
    })
}

/// [`check_written`] that needs `pb` only for the statistics: on a raster of [`TRIM_CELLS`]
/// cells or more only its points and knots are kept while the written mesh's PB-spline and
/// element extraction evaluate every cell, and the rest is compiled again for the leaves over
/// the tolerance (the same PB-spline, bit for bit;
/// docs/decisions.md#knots-only-through-the-solve).
pub(crate) fn check_written_released(
    mesh: &TMesh,
    pb: PbSpline,
    samples: &Samples,
    pts: Option<&Scattered>,
    errs: &mut [f64],
    tol: &Tolerance,
) -> Result<(ErrorStats, Vec<CellId>, PbSpline), TsplineError> {
    if pts.is_some() || samples.z.len() < TRIM_CELLS {
        let (stats, over) = check_written(mesh, &pb, samples, pts, errs, tol)?;
        return Ok((stats, over, pb));
    }
    let parts = pb.into_knots();
    release_free_memory(samples.z.len());
    written_errors(mesh, samples, None, errs)?;
    let pb = PbSpline::from_knots(mesh, parts);
    let (stats, over) = summarize(mesh, &pb, samples.width, errs, tol);
    Ok((stats, over, pb))
}

/// |Δz| of the mesh as written ([`as_written`]), evaluated as `geofit eval` does, into `errs`.
/// The mesh as written is its compacted copy: the file holds the compacted leaves and points
/// with round-trip floats, and reading builds them in the same order (test
/// `written_mesh_is_the_compacted_mesh`); the text round trip itself took ~0.1 s of the BAG
/// 0.1 m fit's one thread.
fn written_errors(
    mesh: &TMesh,
    samples: &Samples,
    pts: Option<&Scattered>,
    errs: &mut [f64],
) -> Result<(), TsplineError> {
    let written = PbSpline::build(&mesh.compacted());
    let err_of = |zk: f64, dk: f64| {
        if dk.is_nan() {
            f64::NAN
        } else if zk.is_nan() {
            f64::INFINITY
        } else {
            (zk - dk).abs()
        }
    };
    if let Some(p) = pts {
        let z = written.eval_z(&p.st, true);
        errs.par_iter_mut().zip(&z).zip(&p.z).for_each(|((e, zk), dk)| *e = err_of(*zk, *dk));
        return Ok(());
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
    Ok(())
}
