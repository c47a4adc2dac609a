//! `geofit unwarp`: maps a raster produced by `geofit warp` (or one evaluated on its grid)
//! back onto the original grid, using the displacement field stored inside it (spec §2.3.3
//! inverse mapping): each original cell of the stored footprint takes the bilinear value at
//! its forward image.

use clap::Args as ClapArgs;

use raster_proc::warp::{field_of, unwarp_raster};

use super::rasterize::{gdal_notices, proc_err, read_raster_arg, write_raster_arg};
use crate::config::Config;
use crate::error::{CmdResult, Exit};

const EXAMPLE: &str = "\
Example:
  $ geofit warp bathy.tif -o bathy.warped.tif
  $ geofit unwarp bathy.warped.tif -o bathy.back.tif
  $ geofit diff bathy.tif bathy.back.tif

The output has the original size, geotransform, CRS and data footprint. Exit 3 when the input
holds no (or a damaged) warp field.";

#[derive(ClapArgs, Debug)]
#[command(about = "Map a warped raster back onto its original grid (field read from the raster itself)", after_help = EXAMPLE)]
pub struct Args {
    /// Raster written by `geofit warp` (`-` = stdin).
    pub input: String,
    /// Output raster (`-` or missing = GeoTIFF on stdout).
    #[arg(short, long)]
    pub output: Option<String>,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    gdal_notices(config);
    let (warped, name) = read_raster_arg(&args.input)?;
    let field = field_of(&warped).map_err(|e| proc_err(&name, e))?;
    let out = unwarp_raster(&warped, &field).map_err(|e| proc_err(&name, e))?;
    config.notice(&format!("{} x {} cells, {} with a value", out.width, out.height, out.valid_count()));
    write_raster_arg(&out, args.output.as_deref())?;
    Ok(Exit::Ok)
}
