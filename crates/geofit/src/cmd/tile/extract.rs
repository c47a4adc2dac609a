//! `geofit tile extract`: one tile's buildings from its sources as a CityGML document.

use clap::Args as ClapArgs;
use tiling::TilingError;

use super::{read_text, tiling_error};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs, Debug)]
pub struct ExtractArgs {
    /// JSON-lines plan from `geofit tile plan`.
    pub plan: String,
    /// Tile id.
    #[arg(long)]
    pub tile: String,
    #[arg(short, long)]
    pub output: Option<String>,
}

pub(super) fn run(a: ExtractArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    let tiles = tiling::plan::read_plan(&read_text(&a.plan)?, &a.plan).map_err(tiling_error)?;
    let tile = tiling::plan::find_tile(&tiles, &a.tile, &a.plan).map_err(tiling_error)?;
    let read =
        |p: &str| std::fs::read(p).map_err(|e| TilingError::Unreadable { name: p.to_string(), message: e.to_string() });
    let x = tiling::extract::extract(tile, &read).map_err(tiling_error)?;
    if x.buildings != tile.work {
        return Err(CliError::unreadable(format!(
            "tile {}: the plan says {} buildings, the sources now give {} (sources changed since the plan?)",
            tile.id, tile.work, x.buildings
        )));
    }
    output.write_bytes(&x.document)?;
    if !config.quiet {
        crate::say!("tile extract: {}: {} buildings", tile.id, x.buildings);
    }
    Ok(Exit::Ok)
}
