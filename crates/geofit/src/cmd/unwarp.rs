//! `geofit unwarp`: maps a raster produced by `geofit warp` (or one evaluated on its grid)
//! back onto the original grid, using the displacement field stored inside it (spec §2.3.3
//! inverse mapping): each original cell of the stored footprint takes the bilinear value at
//! its forward image.

use clap::Args as ClapArgs;

use raster_proc::warp::{field_of, unwarp_raster};

use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::terrain_io::{gdal_notices, proc_err, read_cloud, read_raster_arg_typed, write_raster_arg, RasterOutArgs};

const EXAMPLE: &str = "\
Example:
  $ geofit warp bathy.tif -o bathy.warped.tif
  $ geofit unwarp bathy.warped.tif -o bathy.back.tif
  $ geofit diff bathy.tif bathy.back.tif

  $ geofit unwarp bathy.warped.tif --points features_warped.xyz -o features.xyz
  $ geofit unwarp bathy.warped.tif --points features.xyz --forward -o features_warped.xyz

The output raster has the original size, geotransform, CRS and data footprint. With --points,
XYZ points are mapped instead (warped frame → original; --forward the other way), z kept, one
`x y z` line each with shortest round-trip decimals: the inverse is exact for the piecewise-
linear warp, so forward then back returns each point to within rounding. Exit 3
when the input holds no (or a damaged) warp field.";

#[derive(ClapArgs, Debug)]
#[command(about = "Map a warped raster back onto its original grid (field read from the raster itself)", after_help = EXAMPLE)]
pub struct Args {
    /// Raster written by `geofit warp` (`-` = stdin).
    pub input: String,
    /// Output raster (`-` or missing = GeoTIFF on stdout).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Map the points of this XYZ file (`-` = stdin) instead of the raster; writes XYZ text.
    #[arg(long)]
    pub points: Option<String>,
    /// With --points: map from the original frame into the warped one.
    #[arg(long, requires = "points")]
    pub forward: bool,
    #[command(flatten)]
    pub raster_out: RasterOutArgs,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    gdal_notices(config);
    if args.points.is_none() {
        args.raster_out.checked(args.output.as_deref(), Some(raster_io::SampleType::Float32))?;
    } else if args.raster_out.of.is_some() || !args.raster_out.co.is_empty() || args.raster_out.ot.is_some() {
        return Err(CliError::usage("--points writes XYZ text: -of, -co and --ot apply to raster output only"));
    }
    let (warped, name, sample_type) = read_raster_arg_typed(&args.input)?;
    let field = field_of(&warped).map_err(|e| proc_err(&name, e))?;
    if let Some(pts) = &args.points {
        if args.input == "-" && pts == "-" {
            return Err(CliError::usage("the raster and --points cannot both be stdin"));
        }
        let cloud = read_cloud(pts, None)?;
        let mapper = field.mapper();
        let out = Output::from_arg(args.output.as_deref());
        out.write_with(|w| {
            for p in &cloud.points {
                let q = if args.forward { mapper.forward([p[0], p[1]]) } else { mapper.inverse([p[0], p[1]]) };
                writeln!(w, "{:?} {:?} {:?}", q[0], q[1], p[2]).map_err(CliError::io_out)?;
            }
            Ok(())
        })?;
        config.notice(&format!(
            "mapped {} points {}",
            cloud.points.len(),
            if args.forward { "into the warped frame" } else { "back to the original frame" }
        ));
        return Ok(Exit::Ok);
    }
    let write_opts = args.raster_out.checked(args.output.as_deref(), Some(sample_type))?;
    let out = unwarp_raster(&warped, &field).map_err(|e| proc_err(&name, e))?;
    config.notice(&format!("{} x {} cells, {} with a value", out.width, out.height, out.valid_count()));
    write_raster_arg(&out, args.output.as_deref(), &write_opts)?;
    Ok(Exit::Ok)
}
