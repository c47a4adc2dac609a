//! `geofit rasterize`: scattered points (XYZ/CSV text, LAS/LAZ) → a regular raster by Gauss
//! splatting or TIN-linear interpolation, nodata where no point is near (spec §2.1).

use clap::{Args as ClapArgs, ValueEnum};
use serde::Serialize;

use raster_io::crs::{Crs, GridCrs, GridCrsError};
use raster_io::point_batches::BoundsXy;
use raster_io::PointFormat;
use raster_proc::grid::GridSpec;
use raster_proc::splat::SplatKernel;

use crate::config::{Config, Input};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use crate::terrain_io::{gdal_notices, write_raster_arg, RasterOutArgs};

mod points;
use points::{rasterize_held, splat_streamed};

const EXAMPLE: &str = "\
Example:
  $ geofit rasterize soundings.xyz -o bathy.tif --cell 1 --method tin --max-edge 25
  geofit: read 7000 points from soundings.xyz
  geofit: 812 x 640 cells of 1, 401233 with a value (TIN, 6998 vertices)
  $ geofit rasterize survey.laz --class 2 -o ground.tif --cell 0.5      # ground only, Gauss splat

Methods:
  gauss          every point spreads over the cells within --radius (cells) with weight
                 exp(-d²/2σ²), σ = --sigma (cells); cells no point reaches get nodata.
                 A file is read twice in batches: memory is 16 bytes a cell, whatever the
                 number of points (stdin is held whole)
  gauss-literal  the thesis as printed: nearest cell only, weight exp(-d/2) (holes)
  tin            linear interpolation in the Delaunay triangulation (gdal_grid -a linear);
                 nodata outside the hull and, with --max-edge, in triangles with a longer
                 edge. Holds every point (~220 bytes each; exit 3 beyond the memory)

The grid's cell edges lie on multiples of --cell and cover every point, unless --bounds gives
the outer edges exactly. Text: x y z per line, or a header naming the columns (x/easting/lon,
y/northing/lat, z/elevation/depth/value; values as they are: a depth stays positive down).
The separator (, ; tab blanks) comes from the first line, the decimal mark from the first
number with one (or --sep, --decimal); where ; tab or blanks separate, a comma is decimal:
  $ printf 'Rechtswert;Hochwert;Tiefe\\r\\n341000,5;5724000,25;12,5\\r\\n' > lot.csv
  $ printf '341010,5;5724000,25;13\\r\\n341000,5;5724010,25;12,75\\r\\n' >> lot.csv
  $ geofit rasterize lot.csv --cell 1 -o lot.tif --s-srs EPSG:25832 --method tin
  geofit: read 3 points from lot.csv (';' separated (detected), decimal comma, x y z = columns
  Rechtswert, Hochwert, Tiefe (values as given: a depth stays positive down))
  geofit: 11 x 11 cells of 1, 55 with a value (TIN, 3 vertices)
Exit 3 naming the line: a row whose field count differs from the header's (or first row's),
a NaN or inf value, thousands separators (1.234,5), whole numbers split by commas that may be
decimal commas (--sep , reads them as fields). Exit 2: metres on points in degrees (naming the
UTM zone for --t-srs); a grid CRS in feet without --cell-unit (m converts, crs keeps feet).";

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    Gauss,
    GaussLiteral,
    Tin,
}

#[derive(ClapArgs, Debug, Clone)]
#[command(about = "Grid scattered points (XYZ/CSV, LAS/LAZ) into a raster: Gauss splat or TIN-linear", after_help = EXAMPLE)]
pub struct Args {
    /// Point file: .las/.laz, or XYZ/CSV text (`-` = stdin, text only).
    pub input: String,
    /// Output raster (.tif, .asc, .nc, ...; `-` or missing = GeoTIFF on stdout).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Cell size in the grid CRS's unit (metres in UTM; in a CRS of feet --cell-unit is needed).
    #[arg(long)]
    pub cell: f64,
    /// Unit of --cell where the grid's CRS is not in metres: m, ft, us-ft, ... or crs (its own).
    #[arg(long, value_name = "UNIT")]
    pub cell_unit: Option<String>,
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
    /// CRS of the points (EPSG:code, WKT, PROJ string), overriding a LAS file's own; stored in
    /// the output.
    #[arg(long, value_name = "CRS")]
    pub s_srs: Option<String>,
    /// Reproject the points into this CRS before gridding (--cell is then in its units).
    #[arg(long, value_name = "CRS")]
    pub t_srs: Option<String>,
    /// Field separator of XYZ/CSV text (detected from the first line when not given).
    #[arg(long, value_name = "SEP", value_parser = [",", ";", "tab", "space", "whitespace"])]
    pub sep: Option<String>,
    /// Decimal mark of XYZ/CSV text (detected from the first number that has one when not given).
    #[arg(long, value_name = "MARK", value_parser = [".", ","])]
    pub decimal: Option<String>,
    #[command(flatten)]
    pub raster_out: RasterOutArgs,
}

/// `--report`: the grid written and what went into it.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-rasterize-report/1",
    units: &[
        ("width", "cells"),
        ("height", "cells"),
        ("geotransform", "GDAL geotransform in CRS units (origin x, cell width, 0, origin y, 0, -cell height)"),
    ],
};

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

/// The grid's CRS and reprojection ([`GridCrs`]); a bad CRS string is a usage error.
fn crs_plan(args: &Args, file_crs: Option<&str>) -> Result<GridCrs, CliError> {
    GridCrs::plan(args.s_srs.as_deref(), file_crs, args.t_srs.as_deref()).map_err(|e| match e {
        GridCrsError::NoSource => CliError::usage(format!("{} {e}", args.input)),
        e => CliError::usage(e.to_string()),
    })
}

/// Reprojects a batch as `plan` says; a point PROJ cannot transform is a usage error.
fn reproject(plan: &GridCrs, points: &mut [[f64; 3]]) -> Result<(), CliError> {
    plan.apply(points).map_err(|e| CliError::usage(e.to_string()))
}

/// Refuses metres on points in degrees (`GridSpec::cell_in_metres_on_degrees`).
fn check_cell_units(
    args: &Args,
    seen: &BoundsXy,
    crs: Option<&Crs>,
    lonlat_header: bool,
    grid: &GridSpec,
) -> Result<(), CliError> {
    let Some(bounds) = seen.get() else { return Ok(()) };
    let geographic = crs.map(|c| c.geographic).or(lonlat_header.then_some(true));
    let Some(degrees) = grid.cell_in_metres_on_degrees(bounds, seen.count, geographic, args.cell) else {
        return Ok(());
    };
    Err(CliError::usage(degrees.refusal(
        &args.input,
        args.cell,
        bounds,
        grid,
        seen.count,
        crs.is_some(),
        lonlat_header,
    )))
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    crate::config::check_report_target(args.report.as_deref(), args.output.as_deref())?;
    gdal_notices(config);
    if !(args.cell.is_finite() && args.cell > 0.0) {
        return Err(CliError::usage(format!("--cell {} must be a positive number", args.cell)));
    }
    for (opt, v) in [("--s-srs", &args.s_srs), ("--t-srs", &args.t_srs)] {
        if let Some(s) = v {
            Crs::parse(s).map_err(|e| CliError::usage(format!("{opt}: {e}")))?;
        }
    }
    let write_opts = args.raster_out.checked(args.output.as_deref(), None)?;
    if let Some(p) = Input::from_arg(&args.input).path() {
        if !p.exists() {
            return Err(CliError::unreadable(format!("{}: no such file", p.display())));
        }
        if PointFormat::from_path(p) == PointFormat::Las && (args.sep.is_some() || args.decimal.is_some()) {
            return Err(CliError::usage("--sep and --decimal are for XYZ/CSV text, not LAS/LAZ"));
        }
    }
    let kernel = match args.method {
        Method::Gauss => Some(SplatKernel::Gauss { sigma: args.sigma, radius: args.radius }),
        Method::GaussLiteral => Some(SplatKernel::Literal),
        Method::Tin => None,
    };
    if let Some(k) = kernel {
        k.validate().map_err(|e| CliError::usage(e.to_string()))?;
    }
    let streamed = match (kernel, Input::from_arg(&args.input).path()) {
        (Some(k), Some(path)) => Some((k, path.to_path_buf())),
        _ => None,
    };
    let (seen, raster, tin_stats) = match streamed {
        Some((kernel, path)) => splat_streamed(&args, &path, kernel, config)?,
        None => rasterize_held(&args, kernel, config)?,
    };
    let with_value = raster.valid_count();
    config.notice(&format!(
        "{} x {} cells of {}, {} with a value{}",
        raster.width,
        raster.height,
        raster.geotransform[1],
        with_value,
        tin_stats.map(|s| format!(" (TIN, {} vertices)", s.vertices)).unwrap_or_default()
    ));
    if with_value == 0 {
        return Err(CliError::findings(format!("{}: no cell of the grid received a value", args.input)));
    }
    write_raster_arg(&raster, args.output.as_deref(), &write_opts)?;
    if let Some(path) = &args.report {
        let rep = RasterizeReport {
            input: args.input.clone(),
            points: seen.count,
            method: args.method,
            width: raster.width,
            height: raster.height,
            geotransform: raster.geotransform,
            cells_with_value: with_value,
            cells_without_value: raster.nodata_count(),
            tin_vertices: tin_stats.map(|s| s.vertices),
            merged_duplicates: tin_stats.map(|s| s.merged_duplicates),
        };
        write_json_report(path, &REPORT, &rep)?;
    }
    Ok(Exit::Ok)
}
