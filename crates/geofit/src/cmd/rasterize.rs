//! `geofit rasterize`: scattered points (XYZ/CSV text, LAS/LAZ) → a regular raster by Gauss
//! splatting or TIN-linear interpolation, nodata where no point is near (spec §2.1).
//! Also holds the raster-side error mapping the other terrain commands share.

use clap::{Args as ClapArgs, ValueEnum};
use serde::Serialize;

use raster_io::{read_xyz, PointCloud, PointsError, Raster, RasterError, RasterFormat, WriteOptions};
use raster_proc::grid::GridSpec;
use raster_proc::splat::{splat_points, SplatKernel};
use raster_proc::tin::{tin_points, TinOptions};
use raster_proc::ProcError;

use crate::config::{write_json_report, Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};

const EXAMPLE: &str = "\
Example:
  $ geofit rasterize soundings.xyz -o bathy.tif --cell 1 --method tin --max-edge 25
  geofit: read 7000 points from soundings.xyz
  geofit: 812 x 640 cells of 1, 401233 with a value (TIN, 6998 vertices)
  $ geofit rasterize survey.laz --class 2 -o ground.tif --cell 0.5      # ground only, Gauss splat

Methods:
  gauss          every point spreads over the cells within --radius (cells) with weight
                 exp(-d²/2σ²), σ = --sigma (cells); cells no point reaches get nodata
  gauss-literal  the thesis as printed: nearest cell only, weight exp(-d/2) (holes where a cell
                 holds no point)
  tin            linear interpolation in the Delaunay triangulation (like gdal_grid -a
                 linear:radius=0); nodata outside the hull and, with --max-edge, in triangles
                 with a longer edge

The grid's cell edges lie on multiples of --cell and cover every point, unless --bounds gives
the outer edges exactly. Text input: whitespace, comma or semicolon separated x y z, optional
header line; a bad line is an error naming its line number. Exit 3 for unreadable input.";

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    Gauss,
    GaussLiteral,
    Tin,
}

#[derive(ClapArgs, Debug)]
#[command(about = "Grid scattered points (XYZ/CSV, LAS/LAZ) into a raster: Gauss splat or TIN-linear", after_help = EXAMPLE)]
pub struct Args {
    /// Point file: .las/.laz, or XYZ/CSV text (`-` = stdin, text only).
    pub input: String,
    /// Output raster (.tif, .asc, .nc, ...; `-` or missing = GeoTIFF on stdout).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Cell size in the points' units.
    #[arg(long)]
    pub cell: f64,
    #[arg(long, value_enum, default_value_t = Method::Gauss)]
    pub method: Method,
    /// Keep only LAS points of this ASPRS class (2 = ground).
    #[arg(long)]
    pub class: Option<u8>,
    /// Gauss σ in cells.
    #[arg(long, default_value_t = 0.5)]
    pub sigma: f64,
    /// Gauss footprint radius in cells (≥ 0.7072).
    #[arg(long, default_value_t = 1.5)]
    pub radius: f64,
    /// TIN: no value inside triangles with an edge longer than this (points' units).
    #[arg(long)]
    pub max_edge: Option<f64>,
    /// Exact outer grid edges XMIN YMIN XMAX YMAX (a whole number of cells).
    #[arg(long, num_args = 4, value_names = ["XMIN", "YMIN", "XMAX", "YMAX"], allow_hyphen_values = true)]
    pub bounds: Option<Vec<f64>>,
    /// Write a JSON report (counts, grid) to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
}

#[derive(Debug, Serialize)]
struct RasterizeReport {
    input: String,
    points: usize,
    method: Method,
    width: usize,
    height: usize,
    geotransform: [f64; 6],
    cells_with_value: usize,
    cells_without_value: usize,
    tin_vertices: Option<usize>,
    merged_duplicates: Option<usize>,
}

/// One line for a raster-io error (its message already names the file).
pub fn raster_err(e: RasterError) -> CliError {
    match e {
        RasterError::Open { .. } | RasterError::Content { .. } | RasterError::TooLarge { .. } => CliError::unreadable(e.to_string()),
        RasterError::Write { .. } => CliError::output(e.to_string()),
        RasterError::Invalid(_) => CliError::findings(e.to_string()),
    }
}

/// One line for a point-file error.
pub fn points_err(e: PointsError) -> CliError {
    CliError::unreadable(e.to_string())
}

/// One line for a processing error, prefixed with what was being processed.
pub fn proc_err(what: &str, e: ProcError) -> CliError {
    match e {
        ProcError::Raster(r) => raster_err(r),
        ProcError::Input(m) => CliError::findings(format!("{what}: {m}")),
        ProcError::FoldOver(_) => CliError::findings(format!("{what}: {e}")),
        ProcError::TooLarge { .. } => CliError::unreadable(format!("{what}: {e}")),
        ProcError::Field(_) => CliError::unreadable(format!("{what}: {e}")),
    }
}

/// Shows GDAL's warnings as geofit notices (one line each, silent under `--quiet`) instead of
/// GDAL's own "Warning 1: ..." lines.
pub fn gdal_notices(config: &Config) {
    let quiet = config.quiet;
    raster_io::gdal_io::route_gdal_warnings(move |m| {
        if !quiet {
            crate::say!("geofit: GDAL: {m}");
        }
    });
}

/// Reads a raster from a path argument (GDAL needs a path; stdin is spooled to a temp file).
pub fn read_raster_arg(arg: &str) -> Result<(Raster, String), CliError> {
    let input = Input::from_arg(arg);
    let name = input.display_name();
    match input.path() {
        Some(p) => Ok((raster_io::read_raster(p).map_err(raster_err)?, name)),
        None => Ok((raster_from_stdin_bytes(&input.read_all()?)?, name)),
    }
}

/// A raster from bytes read on stdin: GDAL opens paths, so they are spooled to a temporary file
/// (errors name `<stdin>`, not the spool file).
pub fn raster_from_stdin_bytes(bytes: &[u8]) -> Result<Raster, CliError> {
    let dir = tempfile::tempdir().map_err(|e| CliError::internal(format!("temporary directory: {e}")))?;
    let p = dir.path().join("stdin.raster");
    std::fs::write(&p, bytes).map_err(|e| CliError::internal(format!("temporary file: {e}")))?;
    raster_io::read_raster(&p).map_err(|e| CliError::unreadable(e.to_string().replace(&p.display().to_string(), "<stdin>")))
}

/// Writes a raster to `-o` (format from the extension; stdout = GeoTIFF bytes).
pub fn write_raster_arg(r: &Raster, output: Option<&str>) -> Result<(), CliError> {
    let out = Output::from_arg(output);
    match out.path() {
        Some(p) => raster_io::write_raster(r, p, &WriteOptions::default()).map_err(raster_err),
        None => {
            let bytes = raster_io::gdal_io::raster_to_bytes(r, &RasterFormat::GeoTiff).map_err(raster_err)?;
            out.write_bytes(&bytes)
        }
    }
}

pub fn read_cloud(arg: &str, class: Option<u8>) -> Result<PointCloud, CliError> {
    let input = Input::from_arg(arg);
    match input.path() {
        Some(p) => raster_io::read_points(p, class).map_err(points_err),
        None => {
            if class.is_some() {
                return Err(CliError::usage("--class needs a LAS/LAZ file, not stdin"));
            }
            read_xyz(input.open()?, "<stdin>").map_err(points_err)
        }
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    crate::config::check_report_target(args.report.as_deref(), args.output.as_deref())?;
    gdal_notices(config);
    if !(args.cell.is_finite() && args.cell > 0.0) {
        return Err(CliError::usage(format!("--cell {} must be a positive number", args.cell)));
    }
    if let Some(p) = Input::from_arg(&args.input).path() {
        if !p.exists() {
            return Err(CliError::unreadable(format!("{}: no such file", p.display())));
        }
    }
    let cloud = read_cloud(&args.input, args.class)?;
    config.notice(&format!(
        "read {} points from {}{}",
        cloud.points.len(),
        args.input,
        args.class.map(|c| format!(" (class {c})")).unwrap_or_default()
    ));
    let grid = match &args.bounds {
        Some(b) => GridSpec::from_edges(b[0], b[1], b[2], b[3], args.cell),
        None => GridSpec::covering(cloud.bounds_xy().expect("non-empty cloud"), args.cell),
    }
    .map_err(|e| match e {
        ProcError::Input(m) => CliError::usage(m),
        e @ ProcError::TooLarge { .. } => CliError::usage(format!("--cell {}: {e}", args.cell)),
        other => proc_err(&args.input, other),
    })?;
    let crs = cloud.crs.clone();
    let (raster, tin_stats) = match args.method {
        Method::Gauss | Method::GaussLiteral => {
            let kernel = if args.method == Method::Gauss {
                SplatKernel::Gauss { sigma: args.sigma, radius: args.radius }
            } else {
                SplatKernel::Literal
            };
            kernel.validate().map_err(|e| CliError::usage(e.to_string()))?;
            (splat_points(&cloud, &grid, kernel, crs).map_err(|e| proc_err(&args.input, e))?, None)
        }
        Method::Tin => {
            let (r, s) = tin_points(&cloud, &grid, &TinOptions { max_edge: args.max_edge }, crs).map_err(|e| proc_err(&args.input, e))?;
            (r, Some(s))
        }
    };
    let with_value = raster.valid_count();
    config.notice(&format!(
        "{} x {} cells of {}, {} with a value{}",
        raster.width,
        raster.height,
        args.cell,
        with_value,
        tin_stats.map(|s| format!(" (TIN, {} vertices)", s.vertices)).unwrap_or_default()
    ));
    if with_value == 0 {
        return Err(CliError::findings(format!("{}: no cell of the grid received a value", args.input)));
    }
    write_raster_arg(&raster, args.output.as_deref())?;
    if let Some(path) = &args.report {
        let rep = RasterizeReport {
            input: args.input.clone(),
            points: cloud.points.len(),
            method: args.method,
            width: raster.width,
            height: raster.height,
            geotransform: raster.geotransform,
            cells_with_value: with_value,
            cells_without_value: raster.nodata_count(),
            tin_vertices: tin_stats.map(|s| s.vertices),
            merged_duplicates: tin_stats.map(|s| s.merged_duplicates),
        };
        write_json_report(path, &rep)?;
    }
    Ok(Exit::Ok)
}
