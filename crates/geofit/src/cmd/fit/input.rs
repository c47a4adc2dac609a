//! The input side of `geofit fit`: the raster (or a tile's window of it), declared no-data, the
//! per-cell tolerance, the blunder screen with its report, and for `--indirect` the warp; the
//! result is the fit's samples in the parameter layout.

use raster_io::Raster;
use raster_proc::warp::WarpField;
use tspline::fit::{Domain, Samples, Scattered};
use tspline::format::Georef;
use tspline::tolerance::CellTolerance;
use tspline_raster::indirect::{self, WarpChoice};
use tspline_raster::screening::{self, RasterTolerance, ScreenError};

use super::blunders::report_blunders;
use super::{Args, WarpMode};
use crate::config::Config;
use crate::error::CliError;
use crate::terrain_io::{choose_band, raster_layout, read_raster_arg_band, tspline_err, Band};

/// Blunders are reported at this K when `--reject-outliers` does not give one.
const REPORT_OUTLIERS_K: f64 = 10.0;

/// `--report`'s account of the blunder screen.
#[derive(serde::Serialize)]
pub(super) struct OutlierReport {
    /// The K of the test (|z − prediction| > K × tolerance, isolated).
    k: f64,
    found: usize,
    rejected: bool,
}

/// Everything the fit and its outputs need from the input.
pub(super) struct Prepared {
    pub name: String,
    pub samples: Samples,
    pub georef: Georef,
    /// `--indirect`: the warp field and the original cells as scattered points.
    pub field: Option<WarpField>,
    pub points: Option<Scattered>,
    pub cell_tolerance: Option<CellTolerance>,
    pub e_min: f64,
    pub e_text: String,
    pub valid: usize,
    pub domain: Option<Domain>,
    pub outliers: OutlierReport,
    pub units: super::zunit::FitUnits,
}

pub(super) fn check_tolerance_args(args: &Args) -> Result<(), CliError> {
    let positive = |v: f64| v > 0.0 && v.is_finite();
    if let Some(e) = args.max_error.filter(|&e| !positive(e)) {
        return Err(CliError::usage(format!("--max-error must be a positive number, got {e}")));
    }
    if let Some(k) = args.max_error_from_uncertainty {
        if !positive(k) {
            return Err(CliError::usage(format!("--max-error-from-uncertainty must be a positive factor, got {k}")));
        }
        if args.indirect {
            return Err(CliError::usage("--max-error-from-uncertainty applies to the direct fit (not --indirect)"));
        }
        if args.input == "-" {
            return Err(CliError::usage("--max-error-from-uncertainty reads the uncertainty layer from the input file: it needs a path, not stdin"));
        }
    }
    if let Some(k) = args.reject_outliers.filter(|&k| !positive(k)) {
        return Err(CliError::usage(format!("--reject-outliers must be a positive factor, got {k}")));
    }
    if args.outliers_csv.as_deref() == Some("-") && args.output.as_deref().is_none_or(|o| o == "-") {
        return Err(CliError::usage("--outliers-csv - with the T-mesh also on stdout would mix the two: give -o FILE"));
    }
    if args.nodata.is_some_and(|v| v.is_nan()) {
        return Err(CliError::usage("--nodata must be a number (NaN cells are no data already)"));
    }
    Ok(())
}

/// A tile fit's initial mesh: the plan's (the whole fit's lattice, docs/decisions.md#tiles-on-the-whole-fits-lattice)
/// or, for --srcwin, square cells of --tile-cell anchored at the window's first pixel edge.
enum TileDomain {
    Plan(Domain),
    Anchored(f64),
}

/// The window and initial mesh of a tile fit (--srcwin/--tile-cell or --plan/--tile).
fn tile_window(args: &Args) -> Result<Option<([usize; 4], TileDomain)>, CliError> {
    if let (Some(plan), Some(id)) = (&args.plan, &args.tile) {
        let text = std::fs::read_to_string(plan).map_err(|e| CliError::unreadable(format!("{plan}: {e}")))?;
        let tiles = tiling::plan::read_plan(&text, plan).map_err(|e| CliError::unreadable(e.to_string()))?;
        let t = tiling::plan::find_tile(&tiles, id, plan).map_err(|e| CliError::usage(e.to_string()))?;
        let f = tiling::raster::fit_window(&tiles, t).map_err(|e| CliError::usage(format!("{plan}: {e}")))?;
        let d = Domain { s0: f.s0, t0: f.t0, cell: f.cell, ns: f.ns, nt: f.nt };
        return Ok(Some((f.pixels, TileDomain::Plan(d))));
    }
    let Some(w) = &args.srcwin else { return Ok(None) };
    let win = [w[0], w[1], w[2], w[3]];
    let cell = args
        .tile_cell
        .ok_or_else(|| CliError::usage("--srcwin needs --tile-cell PIXELS (the same for every tile of a plan)"))?;
    if !(cell >= 1.0 && cell.is_finite()) {
        return Err(CliError::usage(format!("--tile-cell must be at least 1 pixel, got {cell}")));
    }
    Ok(Some((win, TileDomain::Anchored(cell))))
}

/// The raster, or the window of it a tile fit reads, and the tile's domain.
fn read_input(args: &Args) -> Result<(Raster, String, Option<Domain>), CliError> {
    let window = tile_window(args)?;
    if window.is_some() && (args.indirect || args.max_error_from_uncertainty.is_some() || args.input == "-") {
        return Err(CliError::usage("--srcwin / --tile fit a window of a raster file with the direct fit (not stdin, --indirect or --max-error-from-uncertainty)"));
    }
    let choice = match args.band {
        Some(b) => Band::Given(b),
        None if args.max_error_from_uncertainty.is_some() => Band::ElevationOfSurvey,
        None => Band::Only,
    };
    if args.terrain_rgb && (window.is_some() || args.input == "-") {
        return Err(CliError::usage("--terrain-rgb reads a whole raster file (not stdin, --srcwin or --tile)"));
    }
    let (raster, name) = match &window {
        _ if args.terrain_rgb => {
            let r = raster_io::read_terrain_rgb(std::path::Path::new(&args.input))
                .map_err(crate::terrain_io::raster_err)?;
            (r, args.input.clone())
        }
        Some((win, _)) => {
            let path = std::path::Path::new(&args.input);
            let band = choose_band(path, &args.input, choice)?;
            let (r, _) =
                raster_io::read_raster_window_typed(path, band, Some(*win)).map_err(crate::terrain_io::raster_err)?;
            (r, format!("{} (window {} {} {} {})", args.input, win[0], win[1], win[2], win[3]))
        }
        None => read_raster_arg_band(&args.input, choice).map(|(r, name, _)| (r, name))?,
    };
    let domain = window.map(|(_, d)| match d {
        TileDomain::Plan(d) => d,
        TileDomain::Anchored(cell) => Domain::anchored(raster.width, raster.height, cell, raster.geotransform[5] < 0.0),
    });
    Ok((raster, name, domain))
}

/// The uncertainty layer of the input file, on the elevation's grid.
fn read_uncertainty(input: &str, elevation: &Raster, name: &str) -> Result<Raster, CliError> {
    let (u, band) =
        raster_io::read_uncertainty(std::path::Path::new(input)).map_err(|e| CliError::unreadable(e.to_string()))?;
    if (u.width, u.height, u.geotransform) != (elevation.width, elevation.height, elevation.geotransform) {
        return Err(CliError::unreadable(format!(
            "{name}: the uncertainty layer (band {band}) is not on the elevation's grid"
        )));
    }
    Ok(u)
}

/// Every valid cell needs a positive tolerance: an uncertainty, or the floor --max-error.
fn check_coverage(tol: &RasterTolerance, r: &Raster, name: &str) -> Result<(), CliError> {
    let bad = tol.uncovered(r);
    let Some(&q) = bad.first() else { return Ok(()) };
    let u = tol.uncertainty.map_or(f64::NAN, |u| u[q]);
    Err(CliError::unreadable(format!(
        "{name}: {} valid cells have no usable uncertainty (first: row {}, col {}, uncertainty {u}); give --max-error E as the tolerance floor for them",
        bad.len(),
        q / r.width,
        q % r.width
    )))
}

/// The blunder screen (docs/decisions.md#blunders-before-a-fit) with its report: the count and
/// the first positions on stderr, all of them in `--outliers-csv`; a refusal names the cell.
fn screen(r: &mut Raster, name: &str, args: &Args, tol: &RasterTolerance) -> Result<OutlierReport, CliError> {
    let k = args.reject_outliers.unwrap_or(REPORT_OUTLIERS_K);
    let reject = args.reject_outliers.is_some();
    let (screening, refusal) = match screening::screen_blunders(r, k, reject, tol) {
        Ok(s) => (s, None),
        Err(ScreenError::Range(e)) => return Err(tspline_err(name, e)),
        Err(ScreenError::BeyondPrecision(b)) => {
            let b = *b;
            let (p, v) = (b.first, b.value);
            let hint = if b.isolated { " or --reject-outliers K to exclude the blunders" } else { "" };
            let message = format!(
                "{name}: {} cell(s) hold values no fit within the tolerance can follow in f64 arithmetic, first row {}, col {} (x {}, y {}): {v:e}; if {v:e} marks missing data pass --nodata {v:e}{hint}",
                b.count, p.row, p.col, p.x, p.y
            );
            (b.screening, Some(message))
        }
    };
    report_blunders(&screening, name, k, args.outliers_csv.as_deref())?;
    match refusal {
        Some(m) => Err(CliError::unreadable(m)),
        None => Ok(OutlierReport { k, found: screening.found.len(), rejected: reject }),
    }
}

/// `--indirect` (spec §1, §2.3): the raster the fit works on, its warp field and the original
/// raster whose cells it follows (docs in `tspline_raster::indirect`).
fn warp(
    raster: Raster,
    name: &str,
    args: &Args,
    config: &Config,
) -> Result<(Raster, Option<WarpField>, Option<Raster>), CliError> {
    if !args.indirect {
        return Ok((raster, None, None));
    }
    if let Some(sp) = args.warp_spacing.filter(|sp| !(*sp > 0.0 && sp.is_finite())) {
        return Err(CliError::usage(format!("--warp-spacing must be a positive number of cells, got {sp}")));
    }
    let choice = match args.warp {
        WarpMode::Rotate => WarpChoice::Rotate,
        WarpMode::Full => WarpChoice::Full { spacing_cells: args.warp_spacing },
    };
    let w = indirect::warp_for_fit(raster, choice).map_err(|e| crate::terrain_io::proc_err(name, e))?;
    if w.original.is_none() {
        config.notice(&format!(
            "notice: {name} is already warped: fitting its resampled, filled cells (the tolerance holds in the warped frame); pass the original raster for a fit to the original cells"
        ));
        if args.warp_spacing.is_some() || args.warp == WarpMode::Full {
            config.notice(&format!("notice: {name} carries its own warp: --warp / --warp-spacing are not used"));
        }
    }
    Ok((w.warped, Some(w.field), w.original))
}

/// Reads, screens and lays out the input for the fit.
pub(super) fn prepare(args: &Args, config: &Config) -> Result<Prepared, CliError> {
    let (mut raster, name, domain) = read_input(args)?;
    if let Some(v) = args.nodata {
        screening::declare_nodata(&mut raster, v);
    }
    let uncertainty = match args.max_error_from_uncertainty {
        Some(_) => Some(read_uncertainty(&args.input, &raster, &name)?),
        None => None,
    };
    // --max-error in the heights' unit (a band in km: 10 m is 0.01)
    let units = super::zunit::resolve(&raster, &name, args, config)?;
    let floor = args.max_error.map(|e| units.to_data(e));
    let tol = RasterTolerance {
        floor,
        k: args.max_error_from_uncertainty,
        uncertainty: uncertainty.as_ref().map(|u| &u.data[..]),
    };
    check_coverage(&tol, &raster, &name)?;
    let outliers = screen(&mut raster, &name, args, &tol)?;
    let e_min = tol.min_over(&raster);
    let e_text = units.describe(tol.describe(), args.max_error);
    let (raster, field, original) = warp(raster, &name, args, config)?;
    // the samples take the raster's values (rows flipped in place, f32 when they are f32)
    let layout = raster_layout(raster, &name)?;
    let cell_tolerance = match (uncertainty, args.max_error_from_uncertainty) {
        (Some(u), Some(k)) => {
            let us = raster_layout(u, &name)?.samples;
            let u32s: Vec<f32> = us.z.iter().map(|v| v as f32).collect();
            Some(CellTolerance { k, floor: floor.unwrap_or(0.0), uncertainty: std::sync::Arc::new(u32s) })
        }
        _ => None,
    };
    let (mut samples, georef) = (layout.samples, layout.georef);
    let points = match (&original, &field) {
        (Some(o), Some(f)) => Some(indirect::scatter_forward(o, f, &georef, &mut samples)),
        _ => None,
    };
    drop(original);
    let valid = points.as_ref().map_or_else(|| samples.valid_count(), |p| p.z.len());
    if valid == 0 {
        return Err(CliError::findings(format!("{name}: the raster has no valid cell")));
    }
    // Tolerance below the data's own precision: integer-valued data resolve 1 unit at best.
    let integers = samples.z.iter().filter(|v| !v.is_nan()).all(|v| v.fract() == 0.0);
    if integers && e_min < 0.5 {
        config.notice(&format!(
            "warning: {name} holds integer values (precision 1); a tolerance of {e_min} is below the data's own precision and forces interpolation of every cell"
        ));
    }
    Ok(Prepared { name, samples, georef, field, points, cell_tolerance, e_min, e_text, valid, domain, outliers, units })
}
