//! `geofit fit`: raster → T-mesh by adaptive refinement and least squares or dragging
//! (spec §4.1, Alg. 3). Also holds the helpers the other T-spline commands share
//! (raster ↔ parameter layout, `--device` selection, error mapping).

use clap::{Args as ClapArgs, ValueEnum};

use raster_io::Raster;
use tspline::fit::{Backend, Domain, FitOptions, IterationStats, Method, StopReason};
use tspline::format::{Encoding, TMeshFile};
use tspline::Degree;

use crate::terrain_io::{read_raster_arg, samples_from_raster, select_device, tspline_err, Device};
use crate::config::{Config, Input, Output};
use crate::report::{write_json_report, ReportKind, Z_UNIT};
use crate::error::{CliError, CmdResult, Exit};

const EXAMPLE: &str = "\
Example:
  $ geofit fit bathy.tif -o bathy.tmesh --max-error 0.5 --degree 3 --report fit.json
  geofit: fit
  geofit:   iteration 0: 16 control points, max 12.3 m, RMS 3.1 m, 401233 cells over 0.5 m (0.2 s)
  ...
  geofit:   iteration 7: 5120 control points, max 0.49 m, RMS 0.08 m, 0 cells over 0.5 m (1.9 s)
  geofit:   tolerance reached: every valid cell within 0.5 m

The T-mesh starts as a few square cells covering the data plus 25 % overhang; every iteration
fits the control-point heights (least squares over all valid cells, or dragging), evaluates the
surface at every valid cell, and splits cells whose 3x3 probes or cells miss --max-error (rule 2
and 1:2 balance repaired). Once every cell is within --max-error, least squares merges back the
splits that were not needed (--no-coarsen keeps the loop's mesh). The fit ends when every valid
cell is within --max-error (exit 0), or
with exit 1 and the error reached when --max-points, --max-iterations or the minimum cell size
(one raster cell) stops it first. The output stores the data mask (and the CRS) for `geofit eval`.
The final check evaluates the mesh as written, as `geofit eval` does, so `geofit diff --check`
at the same tolerance passes on its output.

  $ geofit fit survey.bag -o s.tmesh --max-error-from-uncertainty 1 --max-error 0.05
  $ geofit fit dem.tif -o d.tmesh --max-error 0.5 --reject-outliers 10 --outliers-csv spikes.csv

Per-cell tolerance: max(--max-error, K × the uncertainty band). Blunders (isolated cells more
than K × the tolerance off every local linear prediction) are always reported; --reject-outliers
excludes them from the fit and the data mask. A value no f64 fit can follow (an undeclared
no-data marker such as 1e30) is refused by position (exit 3): --nodata V declares it.";

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Assembly {
    Cpu,
    Opencl,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WarpMode {
    Rotate,
    Full,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    Lsq,
    Drag,
}

#[derive(ClapArgs, Debug)]
#[command(about = "Fit a T-spline surface (T-mesh) to a raster within a maximum error", after_help = EXAMPLE)]
pub struct Args {
    /// Input raster (GeoTIFF, netCDF, ASCII grid, ...; `-` = stdin).
    pub input: String,
    /// Output T-mesh file (`-` or none = stdout): XML `.tmesh`, or the compact binary form when
    /// the name ends in `.tmb` (lossless; `eval`, `surface`, `export` and `info` read both).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Maximum |Δz| allowed at every valid raster cell (raster units). With
    /// --max-error-from-uncertainty: the floor of the per-cell tolerance.
    #[arg(long, allow_negative_numbers = true, required_unless_present = "max_error_from_uncertainty")]
    pub max_error: Option<f64>,
    /// Per-cell tolerance from the survey's uncertainty layer (the band named "uncertainty", as in
    /// a BAG, else band 2): every valid cell within max(--max-error, K × its uncertainty).
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    pub max_error_from_uncertainty: Option<f64>,
    /// Cells holding this value are no data (an undeclared marker such as 1e30; also matched at
    /// float32 precision, as GDAL matches a Float32 band's marker).
    #[arg(long, value_name = "V", allow_negative_numbers = true)]
    pub nodata: Option<f64>,
    /// Exclude blunders from the fit and from the output's data mask: isolated cells more than
    /// K × the tolerance from what their neighbourhood predicts. Without it they are reported
    /// (at K = 10) and fitted.
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    pub reject_outliers: Option<f64>,
    /// Write the blunders found (row, col, x, y, value, predicted, deviation, rejected) as CSV.
    #[arg(long, value_name = "FILE")]
    pub outliers_csv: Option<String>,
    /// Polynomial degree (1 or 3).
    #[arg(long, default_value_t = 3)]
    pub degree: u32,
    /// Geometry optimiser.
    #[arg(long, value_enum, default_value_t = MethodArg::Lsq)]
    pub method: MethodArg,
    /// Fit the raster after the warp stored in it by `geofit warp` (indirect reduction).
    #[arg(long)]
    pub indirect: bool,
    /// `--indirect` on an unwarped raster: which warp to build (`rotate`: the principal-axis
    /// rotation only; `full`: rotation plus the local x/y warp of `geofit warp`). The default is
    /// `rotate`: the local warp is piecewise linear, so the warped surface has kinks along its
    /// triangle edges that cost control points at tight tolerances (measured in
    /// benches/results/tspline.md).
    #[arg(long, value_enum, default_value_t = WarpMode::Rotate)]
    pub warp: WarpMode,
    /// `--indirect`: landmark spacing of the local warp in cells (default that of `geofit warp`).
    #[arg(long)]
    pub warp_spacing: Option<f64>,
    /// Stop before the mesh would exceed this many control points.
    #[arg(long)]
    pub max_points: Option<usize>,
    /// Stop after this many refinement iterations.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Overhang of the initial mesh on every side, as a fraction of the data extent.
    #[arg(long, default_value_t = 0.25)]
    pub overhang: f64,
    /// Where dense evaluations run.
    #[arg(long, value_enum, default_value_t = Device::Auto)]
    pub device: Device,
    /// Where the least-squares model-matrix rows are computed: `cpu`, or `opencl` (the
    /// kernel; the host accumulates the normal equations from its rows block by block).
    #[arg(long, value_enum, default_value_t = Assembly::Cpu)]
    pub assembly: Assembly,
    /// Keep the mesh the refinement loop ends with: no coarsening pass (least squares on a
    /// raster merges back, after the tolerance is reached, the splits it did not need; every
    /// valid cell stays within --max-error).
    #[arg(long)]
    pub no_coarsen: bool,
    /// Write a JSON report (options, per-iteration table, stop reason) to this path.
    #[arg(long)]
    pub report: Option<String>,
    /// Fit only this pixel window of the input (GDAL's -srcwin: column and row offset, width,
    /// height), read through a GDAL windowed read: a tile of a raster of any size. The mesh
    /// domain ends on the window's pixel edges (square cells of --tile-cell pixels), so the tiles
    /// of a plan meet along their seams for `geofit tile stitch`.
    #[arg(long, num_args = 4, value_names = ["XOFF", "YOFF", "XSIZE", "YSIZE"], conflicts_with = "tile")]
    pub srcwin: Option<Vec<usize>>,
    /// With --srcwin: side of the initial square cells in pixels (the same for every tile of a
    /// plan; a full tile's side must be a whole number of them).
    #[arg(long, value_name = "PIXELS", requires = "srcwin")]
    pub tile_cell: Option<f64>,
    /// Fit tile ID of a raster plan (`geofit tile plan --format jsonl`): its core window, with
    /// the plan's cell size (the --srcwin of that tile).
    #[arg(long, value_name = "ID", requires = "plan")]
    pub tile: Option<String>,
    /// The plan of --tile.
    #[arg(long, value_name = "PLAN", requires = "tile")]
    pub plan: Option<String>,
}

/// The window and initial cell size of a tile fit (--srcwin/--tile-cell or --plan/--tile).
fn tile_window(args: &Args) -> Result<Option<([usize; 4], f64)>, CliError> {
    if let (Some(plan), Some(id)) = (&args.plan, &args.tile) {
        let text = std::fs::read_to_string(plan).map_err(|e| CliError::unreadable(format!("{plan}: {e}")))?;
        let tiles = tiling::plan::read_plan(&text, plan).map_err(|e| CliError::unreadable(e.to_string()))?;
        let t = tiling::plan::find_tile(&tiles, id, plan).map_err(|e| CliError::usage(e.to_string()))?;
        let px = t.core.pixels.ok_or_else(|| CliError::usage(format!("{plan}: tile {id} is not a raster tile")))?;
        return Ok(Some((px, tiling::raster::base_cell(t.size as usize))));
    }
    let Some(w) = &args.srcwin else { return Ok(None) };
    let win = [w[0], w[1], w[2], w[3]];
    let cell = args.tile_cell.ok_or_else(|| CliError::usage("--srcwin needs --tile-cell PIXELS (the same for every tile of a plan)"))?;
    if !(cell >= 1.0 && cell.is_finite()) {
        return Err(CliError::usage(format!("--tile-cell must be at least 1 pixel, got {cell}")));
    }
    Ok(Some((win, cell)))
}

/// `--report`: what the fit did and how far it got.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-fit-report/1",
    units: &[
        ("width", "cells"),
        ("height", "cells"),
        ("max_error", Z_UNIT),
        ("max_error_from_uncertainty", "multiple of the uncertainty band"),
        ("max_abs_error", Z_UNIT),
        ("compression_ratio", "valid cells per control point"),
        ("iterations[].mean", Z_UNIT),
        ("iterations[].sigma", Z_UNIT),
        ("iterations[].median", Z_UNIT),
        ("iterations[].max", Z_UNIT),
        ("iterations[].rms", Z_UNIT),
        ("iterations[].seconds", "s"),
        ("seconds", "s"),
        ("peak_rss_mib", "MiB"),
    ],
};

#[derive(serde::Serialize)]
struct Report<'a> {
    input: &'a str,
    width: usize,
    height: usize,
    valid_cells: usize,
    degree: u32,
    method: Method,
    /// The tolerance; with a per-cell tolerance, its smallest value.
    max_error: f64,
    max_error_from_uncertainty: Option<f64>,
    outliers: OutlierReport,
    max_points: Option<usize>,
    device: String,
    stop: &'a StopReason,
    control_points: usize,
    cells: usize,
    max_abs_error: f64,
    compression_ratio: f64,
    iterations: &'a [IterationStats],
    seconds: f64,
    /// Peak resident memory of the process (Linux VmHWM), MiB; null elsewhere.
    peak_rss_mib: Option<f64>,
}

/// Blunders are reported at this K when `--reject-outliers` does not give one.
const REPORT_OUTLIERS_K: f64 = 10.0;
/// Blunders listed by position on stderr (all of them go to `--outliers-csv`).
const LISTED_OUTLIERS: usize = 5;

fn check_tolerance_args(args: &Args) -> Result<(), CliError> {
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

/// `--nodata V`: cells equal to V (or to V at float32 precision) become no data.
fn declare_nodata(r: &mut Raster, v: f64) {
    let v32 = v as f32;
    for (d, ok) in r.data.iter_mut().zip(r.valid.iter_mut()) {
        if *ok && (*d == v || (v32.is_finite() && *d as f32 == v32)) {
            *ok = false;
            *d = f64::NAN;
        }
    }
}

/// The uncertainty layer of the input file, on the elevation's grid.
fn read_uncertainty_arg(input: &str, elevation: &Raster, name: &str) -> Result<Raster, CliError> {
    let (u, band) = raster_io::read_uncertainty(std::path::Path::new(input)).map_err(|e| CliError::unreadable(e.to_string()))?;
    if (u.width, u.height, u.geotransform) != (elevation.width, elevation.height, elevation.geotransform) {
        return Err(CliError::unreadable(format!("{name}: the uncertainty layer (band {band}) is not on the elevation's grid")));
    }
    Ok(u)
}

/// The tolerance per cell of the raster as read (file layout): `e` everywhere, or
/// max(e, k·u) with the uncertainty layer `u` (NaN = none: the floor e).
struct CellTol<'a> {
    e: Option<f64>,
    k: Option<f64>,
    u: Option<&'a [f64]>,
}

impl CellTol<'_> {
    fn at(&self, q: usize) -> f64 {
        let floor = self.e.unwrap_or(0.0);
        match (self.k, self.u) {
            (Some(k), Some(u)) if !u[q].is_nan() => (k * u[q]).max(floor),
            _ => floor,
        }
    }
    /// The smallest tolerance over the valid cells.
    fn min_over(&self, r: &Raster) -> f64 {
        (0..r.valid.len()).filter(|&q| r.valid[q]).map(|q| self.at(q)).fold(f64::INFINITY, f64::min)
    }
    fn describe(&self) -> String {
        match (self.e, self.k) {
            (Some(e), Some(k)) => format!("max({e}, {k} × uncertainty)"),
            (None, Some(k)) => format!("{k} × uncertainty"),
            (Some(e), None) => format!("{e}"),
            (None, None) => unreachable!("clap requires one of them"),
        }
    }
    /// Every valid cell needs a positive tolerance: an uncertainty, or the floor --max-error.
    fn check_coverage(&self, r: &Raster, name: &str) -> Result<(), CliError> {
        let bad: Vec<usize> = (0..r.valid.len()).filter(|&q| r.valid[q] && !(self.at(q) > 0.0 && self.at(q).is_finite())).collect();
        let Some(&q) = bad.first() else { return Ok(()) };
        let u = self.u.map_or(f64::NAN, |u| u[q]);
        Err(CliError::unreadable(format!(
            "{name}: {} valid cells have no usable uncertainty (first: row {}, col {}, uncertainty {u}); give --max-error E as the tolerance floor for them",
            bad.len(),
            q / r.width,
            q % r.width
        )))
    }
}

#[derive(serde::Serialize)]
struct OutlierReport {
    /// The K of the test (|z − prediction| > K × tolerance, isolated).
    k: f64,
    found: usize,
    rejected: bool,
}

/// Blunder screening (docs/decisions.md#blunders-before-a-fit): detects isolated cells far from
/// their neighbourhood's prediction, reports them (count and the first positions on stderr, all
/// in `--outliers-csv`), excludes them with `--reject-outliers`; refuses cells beyond the f64
/// precision at the tolerance (an undeclared no-data marker) that are not excluded.
fn screen_outliers(r: &mut Raster, name: &str, args: &Args, tol: &CellTol) -> Result<OutlierReport, CliError> {
    let k = args.reject_outliers.unwrap_or(REPORT_OUTLIERS_K);
    let reject = args.reject_outliers.is_some();
    for (d, ok) in r.data.iter_mut().zip(&r.valid) {
        if !ok {
            *d = f64::NAN; // the scans below read NaN as no data
        }
    }
    // values beyond ±1e100 get the library's own refusal (the range its sums stay finite in)
    tspline::fit::check_value_range(&r.data).map_err(|e| tspline_err(name, e))?;
    let found = tspline::blunders::detect(&r.data, r.width, r.height, &|q| k * tol.at(q));
    let (width, gt) = (r.width, r.geotransform);
    let at = move |q: usize| {
        let (col, row) = (q % width, q / width);
        let (x, y) = (gt[0] + (col as f64 + 0.5) * gt[1], gt[3] + (row as f64 + 0.5) * gt[5]);
        (row, col, x, y)
    };
    if let Some(path) = &args.outliers_csv {
        Output::from_arg(Some(path)).write_with(|w| {
            let mut text = String::from("row,col,x,y,value,predicted,deviation,rejected\n");
            for b in &found {
                let (row, col, x, y) = at(b.index);
                text.push_str(&format!("{row},{col},{x},{y},{},{},{},{reject}\n", b.value, b.predicted, b.deviation()));
            }
            w.write_all(text.as_bytes()).map_err(CliError::io_out)
        })?;
    }
    if !found.is_empty() {
        let list: Vec<String> = found
            .iter()
            .take(LISTED_OUTLIERS)
            .map(|b| {
                let (row, col, x, y) = at(b.index);
                format!("row {row}, col {col} (x {x}, y {y}): {} where the neighbourhood predicts {:.6}", b.value, b.predicted)
            })
            .collect();
        let more = if found.len() > LISTED_OUTLIERS { format!("; {} more", found.len() - LISTED_OUTLIERS) } else { String::new() };
        let what = if reject { "excluded from the fit and the data mask (--reject-outliers)" } else { "fitted as data; --reject-outliers K excludes them" };
        crate::say!(
            "geofit: {name}: {} blunder(s) (isolated cells more than {k} × the tolerance off their neighbourhood: blunders or single-cell features), {what}: {}{more}",
            found.len(),
            list.join("; ")
        );
    }
    if reject {
        for b in &found {
            r.valid[b.index] = false;
            r.data[b.index] = f64::NAN;
        }
    }
    let beyond = tspline::blunders::beyond_precision(&r.data, &|q| tol.at(q));
    if let Some(&q) = beyond.first() {
        let (row, col, x, y) = at(q);
        let v = r.data[q];
        let isolated = found.iter().any(|b| b.index == q);
        let hint = if isolated { " or --reject-outliers K to exclude the blunders" } else { "" };
        return Err(CliError::unreadable(format!(
            "{name}: {} cell(s) hold values no fit within the tolerance can follow in f64 arithmetic, first row {row}, col {col} (x {x}, y {y}): {v:e}; if {v:e} marks missing data pass --nodata {v:e}{hint}",
            beyond.len()
        )));
    }
    Ok(OutlierReport { k, found: found.len(), rejected: reject })
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    crate::config::check_report_target(args.report.as_deref(), args.output.as_deref())?;
    check_tolerance_args(&args)?;
    let degree = Degree::from_u32(args.degree).ok_or_else(|| CliError::usage(format!("--degree must be 1 or 3, got {}", args.degree)))?;
    if !(args.overhang >= 0.0 && args.overhang <= 4.0) {
        return Err(CliError::usage(format!("--overhang must be within 0..4, got {}", args.overhang)));
    }
    // The warp options shape the warp `--indirect` builds: say so instead of ignoring them.
    if args.warp_spacing.is_some() && !(args.indirect && args.warp == WarpMode::Full) {
        return Err(CliError::usage("--warp-spacing sets the landmark spacing of the local warp: it needs --indirect --warp full"));
    }
    if args.warp == WarpMode::Full && !args.indirect {
        return Err(CliError::usage("--warp full chooses the warp of the indirect reduction: it needs --indirect"));
    }
    if args.assembly == Assembly::Opencl {
        // The T29 kernel serves the direct least-squares fit only: say so instead of ignoring it,
        // and fail before reading (and warping) the raster when there is no OpenCL at all.
        if args.method == MethodArg::Drag || args.indirect {
            return Err(CliError::usage("--assembly opencl applies to the direct least-squares fit (not --method drag or --indirect)"));
        }
        if !ocl::core::get_platform_ids().map(|v| !v.is_empty()).unwrap_or(false) {
            return Err(CliError::internal("--assembly opencl: no OpenCL platform found (install pocl-opencl-icd, or use --assembly cpu)"));
        }
    }
    let t_start = std::time::Instant::now();
    crate::terrain_io::gdal_notices(config);
    let window = tile_window(&args)?;
    if window.is_some() && (args.indirect || args.max_error_from_uncertainty.is_some() || args.input == "-") {
        return Err(CliError::usage("--srcwin / --tile fit a window of a raster file with the direct fit (not stdin, --indirect or --max-error-from-uncertainty)"));
    }
    let (mut raster, name) = match window {
        Some((win, _)) => {
            let (r, _) = raster_io::read_raster_window_typed(std::path::Path::new(&args.input), 1, Some(win)).map_err(crate::terrain_io::raster_err)?;
            (r, format!("{} (window {} {} {} {})", args.input, win[0], win[1], win[2], win[3]))
        }
        None => read_raster_arg(&args.input)?,
    };
    let domain = window.map(|(_, cell)| Domain::anchored(raster.width, raster.height, cell, raster.geotransform[5] < 0.0));
    if let Some(v) = args.nodata {
        declare_nodata(&mut raster, v);
    }
    let uncertainty = match args.max_error_from_uncertainty {
        Some(_) => Some(read_uncertainty_arg(&args.input, &raster, &name)?),
        None => None,
    };
    let tol = CellTol { e: args.max_error, k: args.max_error_from_uncertainty, u: uncertainty.as_ref().map(|u| &u.data[..]) };
    tol.check_coverage(&raster, &name)?;
    let outliers = screen_outliers(&mut raster, &name, &args, &tol)?;
    let e_min = tol.min_over(&raster);
    let e_text = tol.describe();
    // Indirect reduction (spec §1, §2.3). A raster not yet warped is warped here with the default
    // parameters and the fit works on its ORIGINAL cells mapped forward into the warped frame
    // (scattered data): least squares and the tolerance check see the original values at the
    // positions `geofit eval` evaluates them at, so neither the splat's resampling error nor the
    // dilation-filled cells (which the direct fit never has to follow) enter the fit. A raster
    // written by `geofit warp` no longer holds the original values: it is fitted as it is (the
    // tolerance then holds in the warped frame, said in a notice).
    let (raster, field, original) = if args.indirect {
        match raster_proc::warp::field_of(&raster) {
            Ok(f) => {
                config.notice(&format!(
                    "notice: {name} is already warped: fitting its resampled, filled cells (the tolerance holds in the warped frame); pass the original raster for a fit to the original cells"
                ));
                if args.warp_spacing.is_some() || args.warp == WarpMode::Full {
                    config.notice(&format!("notice: {name} carries its own warp: --warp / --warp-spacing are not used"));
                }
                (raster, Some(f), None)
            }
            Err(_) => {
                let mut wp = raster_proc::warp::WarpParams::default();
                if args.warp == WarpMode::Rotate {
                    wp.x_warp = false;
                    wp.y_warp = false;
                }
                if let Some(sp) = args.warp_spacing {
                    if !(sp > 0.0 && sp.is_finite()) {
                        return Err(CliError::usage(format!("--warp-spacing must be a positive number of cells, got {sp}")));
                    }
                    let (dx, dy) = raster.cell_size();
                    wp.landmark_spacing = Some(sp * (dx * dy).abs().sqrt());
                }
                let (w, f, _) = raster_proc::warp::warp_raster(&raster, &wp)
                    .map_err(|e| crate::terrain_io::proc_err(&name, e))?;
                (w, Some(f), Some(raster))
            }
        }
    } else {
        (raster, None, None)
    };
    let (mut samples, georef, mask) = samples_from_raster(&raster, &name)?;
    drop(raster); // the samples hold the data from here on (halves the peak for big rasters)
    let cell_tolerance = match (&uncertainty, args.max_error_from_uncertainty) {
        (Some(u), Some(k)) => {
            let (us, _, _) = samples_from_raster(u, &name)?;
            let u32s: Vec<f32> = us.z.iter().map(|&v| v as f32).collect();
            Some(tspline::tolerance::CellTolerance { k, floor: args.max_error.unwrap_or(0.0), uncertainty: std::sync::Arc::new(u32s) })
        }
        _ => None,
    };
    drop(uncertainty);
    let points = match (&original, &field) {
        (Some(o), Some(f)) => {
            let mapper = f.mapper();
            let mut pts = tspline::fit::Scattered::default();
            for row in 0..o.height {
                for col in 0..o.width {
                    if let Some(z) = o.get(col, row) {
                        let (x, y) = o.cell_centre(col, row);
                        let q = mapper.forward([x, y]);
                        let (s, t) = georef.param(q[0], q[1]);
                        pts.st.push([s, t]);
                        pts.z.push(z);
                    }
                }
            }
            // the probes' reference: the warped raster where original cells land, NaN elsewhere
            let (w, h) = (samples.width, samples.height);
            let mut near = vec![false; w * h];
            for p in &pts.st {
                let (i0, j0) = (p[0].floor(), p[1].floor());
                for (di, dj) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let (i, j) = (i0 + di, j0 + dj);
                    if i >= 0.0 && j >= 0.0 && (i as usize) < w && (j as usize) < h {
                        near[j as usize * w + i as usize] = true;
                    }
                }
            }
            for (z, n) in samples.z.iter_mut().zip(&near) {
                if !n {
                    *z = f64::NAN;
                }
            }
            Some(pts)
        }
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
    let ocl = select_device(args.device, config)?;
    let backend = match &ocl {
        Some(o) => Backend::OpenCl(o),
        None => Backend::Cpu,
    };
    let device_name = ocl.as_ref().map(|o| format!("opencl: {}", o.device_name())).unwrap_or_else(|| "cpu (rayon)".into());
    let mut opts = FitOptions::new(degree, e_min);
    opts.cell_tolerance = cell_tolerance;
    opts.max_points = args.max_points;
    opts.max_iterations = args.max_iterations;
    opts.overhang = args.overhang;
    opts.opencl_assembly = args.assembly == Assembly::Opencl;
    opts.coarsen = !args.no_coarsen;
    opts.domain = domain;
    opts.method = match args.method {
        MethodArg::Lsq => Method::Lsq,
        MethodArg::Drag => Method::Drag,
    };
    // The bar counts the valid cells within the tolerance: it fills as refinement converges
    // (iterations run to no fixed count, so counting them would jump to the end).
    let progress = config.progress("fit", valid as u64);
    let e = &e_text;
    let mut cb = |st: &IterationStats| {
        let stage = if st.merged_cells > 0 { format!("coarsening ({} cells merged)", st.merged_cells) } else { "iteration".into() };
        progress.set(
            (valid - st.error.over_tolerance.min(valid)) as u64,
            &format!(
                "{stage} {}: {} control points, max {:.4}, mean {:.4}, RMS {:.4}, {} cells over {} ({:.2} s: build {:.2}, optimise {:.2}, check {:.2})",
                st.iteration,
                st.control_points,
                st.error.max,
                st.error.mean,
                st.error.rms,
                st.error.over_tolerance,
                e,
                st.seconds,
                st.seconds_build,
                st.seconds_optimise,
                st.seconds_check
            ),
        );
    };
    let result = match &points {
        Some(p) => tspline::fit::fit_points(&samples, p, &opts, &backend, &mut cb),
        None => tspline::fit::fit(&samples, &opts, &backend, &mut cb),
    }
    .map_err(|e| tspline_err(&name, e))?;
    let last = result.iterations.last().cloned().expect("at least one iteration");
    let (exit, line) = match &result.stop {
        StopReason::ToleranceReached => (Exit::Ok, format!("tolerance reached: every valid cell within {e}")),
        StopReason::MaxPoints { cap } => (
            Exit::Findings,
            format!("stopped at the control-point cap {cap}: max error {:.4} > {e} at {} cells", last.error.max, last.error.over_tolerance),
        ),
        StopReason::MaxIterations => (
            Exit::Findings,
            format!("stopped after {} iterations: max error {:.4} > {e} at {} cells", args.max_iterations, last.error.max, last.error.over_tolerance),
        ),
        StopReason::MinCellSize { cells_over } => (
            Exit::Findings,
            format!("the minimum cell size (one raster cell) stops refinement: {cells_over} cells still over {e}, max error {:.4}", last.error.max),
        ),
    };
    progress.finish(&line);
    if let Some(mib) = crate::process_stats::peak_rss_mib() {
        config.notice(&format!("fit: {:.1} s, peak memory {mib:.0} MiB", t_start.elapsed().as_secs_f64()));
    }
    let points = last.control_points;
    if points as f64 > 0.25 * valid as f64 {
        config.notice(&format!(
            "warning: {name} does not compress: {points} control points for {valid} valid cells ({:.0} %)",
            100.0 * points as f64 / valid as f64
        ));
    }
    if exit != Exit::Ok {
        crate::say!("geofit: {name}: {line}");
    }
    let mut mesh = result.mesh;
    let (mask, warp) = match &field {
        Some(f) => {
            // Map every control point's geometry back through the inverted field (spec §2.3.7);
            // parameters and z stay. The original footprint travels in the field's source grid.
            let mapper = f.mapper();
            for p in &mut mesh.points {
                let (xw, yw) = georef.world(p.s, p.t);
                let q = mapper.inverse([xw, yw]);
                let (ps, pt) = georef.param(q[0], q[1]);
                p.x = ps;
                p.y = pt;
            }
            (None, Some(f.to_json()))
        }
        None => (Some(mask), None),
    };
    let file = TMeshFile { mesh, georef, mask, warp };
    // A fit that missed --max-error is a failed step: no mesh for the next one (make) unless
    // --keep-partial; the report below still says how far it got.
    if config.keeps_output(exit, args.output.as_deref()) {
        // `-o x.tmb`: the compact binary form; anything else the XML exchange format
        let encoding = Encoding::for_path(args.output.as_deref());
        let mut bytes = Vec::new();
        tspline::format::write_as(&file, encoding, &mut bytes).map_err(CliError::io_out)?;
        Output::from_arg(args.output.as_deref()).write_with(|w| std::io::Write::write_all(w, &bytes).map_err(CliError::io_out))?;
        if let Some(input_bytes) = Input::from_arg(&args.input).path().and_then(|p| std::fs::metadata(p).ok()).map(|m| m.len()) {
            if bytes.len() as u64 >= input_bytes {
                config.notice(&format!(
                    "notice: the T-mesh ({} bytes) is not smaller than the input raster file ({input_bytes} bytes){}",
                    bytes.len(),
                    if encoding == Encoding::Xml { "; -o NAME.tmb writes the compact binary form" } else { "" }
                ));
            }
        }
    }
    if let Some(path) = &args.report {
        let rep = Report {
            input: &name,
            width: samples.width,
            height: samples.height,
            valid_cells: valid,
            degree: args.degree,
            method: opts.method,
            max_error: e_min,
            max_error_from_uncertainty: args.max_error_from_uncertainty,
            outliers,
            max_points: args.max_points,
            device: device_name,
            stop: &result.stop,
            control_points: points,
            cells: last.cells,
            max_abs_error: last.error.max,
            compression_ratio: valid as f64 / points as f64,
            iterations: &result.iterations,
            seconds: t_start.elapsed().as_secs_f64(),
            peak_rss_mib: crate::process_stats::peak_rss_mib(),
        };
        write_json_report(path, &REPORT, &rep)?;
    }
    Ok(exit)
}
