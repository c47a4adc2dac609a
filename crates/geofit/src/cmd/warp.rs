//! `geofit warp`: the indirect reduction's combined transform (spec §2.3): principal-axis
//! rotation, landmark x/y warp, forward mapping by Gauss splatting and dilation fill. The
//! displacement field travels inside the output (GDAL metadata item `GEOFIT_WARP_FIELD`, JSON,
//! with the source grid and footprint), so `geofit unwarp` needs no side file.

use clap::{Args as ClapArgs, ValueEnum};
use serde::Serialize;

use raster_proc::dilate::Neighbourhood;
use raster_proc::pca::Mass;
use raster_proc::splat::SplatKernel;
use raster_proc::warp::{warp_raster, WarpParams, WarpStats};

use crate::config::Config;
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use crate::terrain_io::{gdal_notices, proc_err, read_raster_arg_typed, write_raster_arg, RasterOutArgs};
use raster_io::RasterFormat;

const EXAMPLE: &str = "\
Example:
  $ geofit warp channel.tif -o channel.warped.tif --spacing 20 --block 50 --window 50
  geofit: rotation -30.10°, 1184 landmarks (412 inside the data), 2230 triangles
  geofit: target 2410 x 388 cells: 402113 splatted, 532967 filled by dilation (61 passes)
  $ geofit unwarp channel.warped.tif -o channel.back.tif

Lengths are in the raster's units; defaults follow the thesis' ratios at 1 m cells: landmark
spacing 20 cells, strip width and y-window 2.5 × spacing. Exit 1 when the warp would fold over
(crossing displacement vectors) or the raster has no valid cell; exit 3 for unreadable input.";

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MassArg {
    /// Every valid cell weighs 1 (footprint PCA).
    Unit,
    /// Water-column mass max(-z, 0), as in the thesis.
    Depth,
}

#[derive(ClapArgs, Debug)]
#[command(about = "Rotate and warp a raster to fill a rectangle (indirect reduction); the field is stored inside the output", after_help = EXAMPLE)]
pub struct Args {
    /// Input raster (anything GDAL reads; `-` = stdin).
    pub input: String,
    /// Output GeoTIFF (.tif; it keeps the field in its metadata; `-` or missing = stdout).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Landmark spacing, in the CRS's units (metres for UTM; default 20 cells). Refused on a
    /// raster in degrees (geographic CRS): the default applies there.
    #[arg(long)]
    pub spacing: Option<f64>,
    /// Strip width of the x-warp, in the CRS's units (default 2.5 × spacing).
    #[arg(long)]
    pub block: Option<f64>,
    /// Full window width of the y-warp, in the CRS's units (default 2.5 × spacing).
    #[arg(long)]
    pub window: Option<f64>,
    /// Skip the principal-axis rotation.
    #[arg(long)]
    pub no_rotate: bool,
    /// Skip the x-warp.
    #[arg(long)]
    pub no_x: bool,
    /// Skip the y-warp.
    #[arg(long)]
    pub no_y: bool,
    #[arg(long, value_enum, default_value_t = MassArg::Unit)]
    pub mass: MassArg,
    /// Dilation neighbourhood: 4 or 8.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u8).range(4..=8))]
    pub neighbourhood: u8,
    /// Resample with the thesis' literal splat (nearest cell, exp(-d/2)) instead of a Gaussian.
    #[arg(long)]
    pub literal_splat: bool,
    /// Write a JSON report to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
    #[command(flatten)]
    pub raster_out: RasterOutArgs,
}

/// `--report`: the warp field's statistics.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-warp-report/1",
    units: &[("rotation_deg", "deg"), ("target_width", "cells"), ("target_height", "cells")],
};

#[derive(Serialize)]
struct Report<'a> {
    input: &'a str,
    #[serde(flatten)]
    stats: WarpStats,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    gdal_notices(config);
    if args.neighbourhood != 4 && args.neighbourhood != 8 {
        return Err(CliError::usage(format!("--neighbourhood {} must be 4 or 8", args.neighbourhood)));
    }
    for (name, v) in [("--spacing", args.spacing), ("--block", args.block), ("--window", args.window)] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                return Err(CliError::usage(format!("{name} {v} must be a positive length")));
            }
        }
    }
    // Only GeoTIFF keeps a long metadata string intact (netCDF rewrites it as a number list,
    // ESRI ASCII grids have no metadata).
    let needs_tiff = |opts: &raster_io::WriteOptions| {
        let tiff = match &opts.format {
            Some(f) => matches!(f, RasterFormat::Cog | RasterFormat::GeoTiff),
            None => args.output.as_deref().is_none_or(|p| {
                let ext = std::path::Path::new(p).extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
                matches!(ext.as_deref(), Some("tif" | "tiff")) || p == "-"
            }),
        };
        if tiff {
            Ok(())
        } else {
            Err(CliError::usage(format!(
                "{}: the warp field needs a GeoTIFF output (.tif, -of COG or -of GTiff)",
                args.output.as_deref().unwrap_or("-")
            )))
        }
    };
    needs_tiff(&args.raster_out.checked(args.output.as_deref(), Some(raster_io::SampleType::Float32))?)?;
    let (raster, name, sample_type) = read_raster_arg_typed(&args.input)?;
    let given = [("--spacing", args.spacing), ("--block", args.block), ("--window", args.window)];
    if let Some((flag, _)) = given.iter().find(|(_, v)| v.is_some()) {
        if raster_io::units::horizontal_unit(raster.crs.as_deref()) == raster_io::units::Horizontal::Degrees {
            return Err(CliError::usage(format!(
                "{flag}: {name} is in degrees (geographic CRS), and {flag} is a length in the CRS's units: leave it out (the default is 20 cells) or reproject the raster (gdalwarp -t_srs)"
            )));
        }
    }
    let write_opts = args.raster_out.checked(args.output.as_deref(), Some(sample_type))?;
    let params = WarpParams {
        rotate: !args.no_rotate,
        mass: match args.mass {
            MassArg::Unit => Mass::Unit,
            MassArg::Depth => Mass::Depth,
        },
        landmark_spacing: args.spacing,
        block_width: args.block,
        window: args.window,
        x_warp: !args.no_x,
        y_warp: !args.no_y,
        kernel: if args.literal_splat { SplatKernel::Literal } else { SplatKernel::default() },
        neighbourhood: if args.neighbourhood == 4 { Neighbourhood::Four } else { Neighbourhood::Eight },
    };
    let (warped, _field, stats) = warp_raster(&raster, &params).map_err(|e| proc_err(&name, e))?;
    config.notice(&format!(
        "rotation {:.2}°, {} landmarks ({} inside the data), {} triangles",
        stats.rotation_deg, stats.landmarks, stats.landmarks_inside, stats.triangles
    ));
    config.notice(&format!(
        "target {} x {} cells: {} splatted, {} filled by dilation ({} passes)",
        stats.target_width, stats.target_height, stats.cells_splatted, stats.cells_filled, stats.dilation_passes
    ));
    write_raster_arg(&warped, args.output.as_deref(), &write_opts)?;
    if let Some(path) = &args.report {
        write_json_report(path, &REPORT, &Report { input: &name, stats })?;
    }
    Ok(Exit::Ok)
}
