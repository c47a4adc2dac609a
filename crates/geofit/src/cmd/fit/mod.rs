//! `geofit fit`: raster → T-mesh by adaptive refinement and least squares or dragging
//! (spec §4.1, Alg. 3). This file: the options and the order of the steps; `input.rs` reads the
//! raster (a window of it for a tile) and screens it, `output.rs` writes the mesh and the report.
//! The algorithms are in `tspline` (the fit) and `tspline_raster` (layout, screening, warp).

mod blunders;
mod input;
mod lerc;
mod output;
mod storage;
mod zunit;

use clap::{Args as ClapArgs, ValueEnum};

use tspline::fit::{Backend, FitOptions, IterationStats, Method};
use tspline::Degree;

use crate::config::Config;
use crate::error::{CliError, CmdResult};
use crate::terrain_io::{select_device, tspline_err, Device};

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

  $ geofit fit gmt_grid.nc -o g.tmesh --max-error 10      # its band says Unit Type: km
  geofit: gmt_grid.nc: heights in km (the band's unit type): --max-error 10 m is 0.01 km
  $ geofit fit dem_ft.tif -o d.tmesh --max-error 0.5 --z-unit us-ft   # the file declares none
  $ geofit fit dem.png -b 1 -o r.tmesh --max-error 1        # 3 or more bands need -b N
  $ geofit fit tile.png --terrain-rgb -o t.tmesh --max-error 1   # Mapbox Terrain-RGB heights

Units: --max-error is in metres (--error-unit ft, cm, ... for another unit) and is converted into
the unit of the heights before the fit: the band's unit type (m, km, cm, ft, US survey foot, ...),
else the vertical unit of a compound CRS; --z-unit overrides both. Without either the heights
are taken as metres, except in a CRS whose x/y are in feet. A unit geofit does not know is
refused (exit 3) naming it; --z-unit says what it is. The report states both (z_unit,
max_error_given) and its heights are in z_unit.

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

/// How the refinement splits a cell over the tolerance (docs/decisions.md#anisotropic-splits-issue-19).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplitArg {
    /// Into four at the centre (square cells).
    Quad,
    /// In two across the direction the residual needs, or in four (rectangles up to 4:1).
    Aniso,
}

#[derive(ClapArgs, Debug)]
#[command(about = "Fit a T-spline surface (T-mesh) to a raster within a maximum error", after_help = EXAMPLE)]
pub struct Args {
    /// Input raster (GeoTIFF, netCDF, ASCII grid, ...; `-` = stdin).
    pub input: String,
    /// Output T-mesh file (`-` or none = stdout): XML `.tmesh`, or the compact binary form when
    /// the name ends in `.tmb` (its heights stored to the error budget: --storage-share;
    /// `eval`, `surface`, `export` and `info` read both).
    #[arg(short, long)]
    pub output: Option<String>,
    /// `.tmb`: store the control-point heights as exact f64 (the fit then takes all of
    /// --max-error).
    #[arg(long)]
    pub lossless: bool,
    /// `.tmb`: the share of --max-error the stored heights may take (they are rounded to steps
    /// of twice that; the fit aims at the rest). Default 0.15, or 0.7 on data rough at cell scale.
    #[arg(long, value_name = "FRACTION")]
    pub storage_share: Option<f64>,
    /// Maximum |Δz| allowed at every valid raster cell, in metres (--error-unit), converted
    /// into the unit of the heights (km, ft, cm, ...). With --max-error-from-uncertainty: the
    /// floor of the per-cell tolerance.
    #[arg(long, allow_negative_numbers = true, required_unless_present = "max_error_from_uncertainty")]
    pub max_error: Option<f64>,
    /// The unit --max-error is given in (m, km, cm, mm, ft, us-ft, ...).
    #[arg(long, value_name = "UNIT")]
    pub error_unit: Option<String>,
    /// The unit of the raster's heights, when the file declares none or declares it wrongly
    /// (m, km, cm, mm, ft, us-ft, ...); default: the band's unit type, else the CRS's vertical
    /// unit, else the heights are taken as metres.
    #[arg(long, value_name = "UNIT")]
    pub z_unit: Option<String>,
    /// The band that holds the heights (GDAL's numbering, from 1); needed when the raster has
    /// several (a BAG, or two bands read with --max-error-from-uncertainty, need none).
    #[arg(short = 'b', long = "band", value_name = "N")]
    pub band: Option<usize>,
    /// The input is a Mapbox Terrain-RGB raster: heights decoded from red, green and blue
    /// (h = -10000 + (R·65536 + G·256 + B) · 0.1 m), transparent cells are no data.
    #[arg(long, conflicts_with = "band")]
    pub terrain_rgb: bool,
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
    /// Write the blunders found (row, col, x, y, value, predicted, deviation, rejected) as CSV;
    /// predicted is the local prediction nearest the value (the one the test compares).
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
    /// How the refinement splits a cell over the tolerance: `quad` (into four), or `aniso` (in
    /// two across the direction the residual varies in, or in four; not with --tile or --srcwin).
    #[arg(long, value_enum, default_value_t = SplitArg::Quad)]
    pub split: SplitArg,
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

/// Refusals of option combinations, before anything is read.
fn check_args(args: &Args) -> Result<Degree, CliError> {
    crate::config::check_report_target(args.report.as_deref(), args.output.as_deref())?;
    input::check_tolerance_args(args)?;
    storage::check_share(args)?;
    let degree = Degree::from_u32(args.degree)
        .ok_or_else(|| CliError::usage(format!("--degree must be 1 or 3, got {}", args.degree)))?;
    if !(args.overhang >= 0.0 && args.overhang <= 4.0) {
        return Err(CliError::usage(format!("--overhang must be within 0..4, got {}", args.overhang)));
    }
    // The warp options shape the warp `--indirect` builds: say so instead of ignoring them.
    if args.warp_spacing.is_some() && !(args.indirect && args.warp == WarpMode::Full) {
        return Err(CliError::usage(
            "--warp-spacing sets the landmark spacing of the local warp: it needs --indirect --warp full",
        ));
    }
    if args.warp == WarpMode::Full && !args.indirect {
        return Err(CliError::usage("--warp full chooses the warp of the indirect reduction: it needs --indirect"));
    }
    if args.split == SplitArg::Aniso && (args.srcwin.is_some() || args.tile.is_some()) {
        return Err(CliError::usage(
            "--split aniso is not available for tiles of a plan (--tile, --srcwin): their seams need square cells",
        ));
    }
    if args.assembly == Assembly::Opencl {
        // The T29 kernel serves the direct least-squares fit only: say so instead of ignoring it,
        // and fail before reading (and warping) the raster when there is no OpenCL at all.
        if args.method == MethodArg::Drag || args.indirect {
            return Err(CliError::usage(
                "--assembly opencl applies to the direct least-squares fit (not --method drag or --indirect)",
            ));
        }
        if !ocl::core::get_platform_ids().map(|v| !v.is_empty()).unwrap_or(false) {
            return Err(CliError::internal(
                "--assembly opencl: no OpenCL platform found (install pocl-opencl-icd, or use --assembly cpu)",
            ));
        }
    }
    Ok(degree)
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let degree = check_args(&args)?;
    let t_start = std::time::Instant::now();
    crate::terrain_io::gdal_notices(config);
    let prepared = input::prepare(&args, config)?;
    let ocl = select_device(args.device, config)?;
    let backend = match &ocl {
        Some(o) => Backend::OpenCl(o),
        None => Backend::Cpu,
    };
    let device_name =
        ocl.as_ref().map(|o| format!("opencl: {}", o.device_name())).unwrap_or_else(|| "cpu (rayon)".into());
    let mut opts = FitOptions::new(degree, prepared.e_min);
    opts.cell_tolerance = prepared.cell_tolerance.clone();
    storage::fit_share(&args, &prepared, &mut opts);
    opts.max_points = args.max_points;
    opts.max_iterations = args.max_iterations;
    opts.overhang = args.overhang;
    opts.opencl_assembly = args.assembly == Assembly::Opencl;
    opts.coarsen = !args.no_coarsen;
    opts.split = match args.split {
        SplitArg::Quad => tspline::mesh::SplitRule::Quad,
        SplitArg::Aniso => tspline::mesh::SplitRule::Anisotropic,
    };
    opts.domain = prepared.domain;
    opts.method = match args.method {
        MethodArg::Lsq => Method::Lsq,
        MethodArg::Drag => Method::Drag,
    };
    // The bar counts the valid cells within the tolerance: it fills as refinement converges
    // (iterations run to no fixed count, so counting them would jump to the end).
    let valid = prepared.valid;
    let progress = config.progress("fit", valid as u64);
    let mut on_iteration = |st: &IterationStats| {
        progress.set((valid - st.error.over_tolerance.min(valid)) as u64, &output::iteration_line(st, &prepared.e_text))
    };
    let result = match &prepared.points {
        Some(p) => tspline::fit::fit_points(&prepared.samples, p, &opts, &backend, &mut on_iteration),
        None => tspline::fit::fit(&prepared.samples, &opts, &backend, &mut on_iteration),
    }
    .map_err(|e| tspline_err(&prepared.name, e))?;
    let (exit, line) = output::stop_line(&result, &prepared.e_text, args.max_iterations);
    progress.finish(&line);
    let done = output::Done { exit, line, t_start, device_name, method: opts.method };
    output::write(&args, config, prepared, result, done)
}
