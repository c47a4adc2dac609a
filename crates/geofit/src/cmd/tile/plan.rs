//! `geofit tile plan`: the tile list of CityGML files (buildings) or of one raster.

use clap::{Args as ClapArgs, ValueEnum};
use tiling::plan::PlanFormat;

use super::tiling_error;
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum Format {
    Jsonl,
    Tsv,
    Make,
}

#[derive(ClapArgs, Debug)]
pub struct PlanArgs {
    /// CityGML files, or exactly one raster.
    #[arg(required = true)]
    pub inputs: Vec<String>,
    /// Buildings: the most buildings a tile may own (picks the grid step).
    #[arg(long, default_value_t = 2000)]
    pub buildings_per_tile: usize,
    /// Rasters: cells of a core window (its side is ⌊√N⌋ pixels).
    #[arg(long, default_value_t = 4_194_304)]
    pub cells_per_tile: usize,
    /// Fixed grid step instead: metres for buildings, pixels for a raster.
    #[arg(long)]
    pub tile_size: Option<f64>,
    /// Rasters: halo width in pixels.
    #[arg(long, default_value_t = 32)]
    pub halo: usize,
    #[arg(long, value_enum, default_value_t = Format::Jsonl)]
    pub format: Format,
    /// Output (stdout when missing or `-`).
    #[arg(short, long)]
    pub output: Option<String>,
}

/// Is this file a CityGML document (root element CityModel) rather than a raster?
fn is_citygml(path: &str) -> bool {
    let mut head = vec![0u8; 4096];
    let n = std::fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut head)).unwrap_or(0);
    String::from_utf8_lossy(&head[..n]).contains("CityModel")
}

pub(super) fn run(a: PlanArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    let format = match a.format {
        Format::Jsonl => PlanFormat::JsonLines,
        Format::Tsv => PlanFormat::Tsv,
        Format::Make => PlanFormat::Make,
    };
    let tiles = if a.inputs.iter().all(|p| is_citygml(p)) {
        let size = match a.tile_size {
            Some(m) => tiling::buildings::GridSize::Metres(m),
            None => tiling::buildings::GridSize::BuildingsPerTile(a.buildings_per_tile),
        };
        let p = tiling::buildings::plan(&a.inputs, size).map_err(tiling_error)?;
        if !config.quiet {
            let step = p.tiles.first().map_or(0.0, |t| t.size);
            crate::say!("tile plan: {} buildings in {} tiles of {step} m", p.buildings, p.tiles.len());
            if p.without_coordinates > 0 {
                crate::say!("tile plan: {} building(s) without coordinates belong to no tile", p.without_coordinates);
            }
        }
        p.tiles
    } else if let [raster] = a.inputs.as_slice() {
        if a.tile_size.is_some_and(|s| s.fract() != 0.0 || s < 1.0) {
            return Err(CliError::usage("--tile-size for a raster: a whole number of pixels"));
        }
        let opts = tiling::raster::RasterTiling {
            tile_pixels: a.tile_size.map(|s| s as usize),
            cells_per_tile: a.cells_per_tile,
            halo: a.halo,
        };
        let t = tiling::raster::plan(raster, &opts).map_err(tiling_error)?;
        if !config.quiet {
            crate::say!("tile plan: {} tiles of {} px", t.len(), t.first().map_or(0.0, |t| t.size));
        }
        t
    } else {
        return Err(CliError::usage("tile plan: give CityGML files, or exactly one raster"));
    };
    output.write_bytes(tiling::plan::write_plan(&tiles, format).as_bytes())?;
    Ok(Exit::Ok)
}
