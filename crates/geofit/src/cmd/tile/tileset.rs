//! `geofit tile tileset`: a 3D Tiles 1.1 tileset.json over per-tile glb.

use std::path::{Path, PathBuf};

use clap::Args as ClapArgs;

use super::tiling_error;
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs, Debug)]
pub struct TilesetArgs {
    /// glb files from `geofit export`, at or below the tileset's directory.
    #[arg(required = true)]
    pub glb: Vec<String>,
    /// CRS of the glb coordinates for PROJ (default: the CRS each glb records).
    #[arg(long)]
    pub crs: Option<String>,
    /// Heights become ellipsoidal as h = H + M (M in metres, e.g. the geoid undulation: ~46.5 m
    /// in NRW). Needed for a CRS with a height system whose geoid grid is not installed.
    #[arg(long, value_name = "M", allow_hyphen_values = true, conflicts_with_all = ["heights_as_is", "geoid"])]
    pub height_offset: Option<f64>,
    /// Take the heights as ellipsoidal, whatever height system the CRS names.
    #[arg(long, conflicts_with = "geoid")]
    pub heights_as_is: bool,
    /// A PROJ geoid grid (file name in PROJ's search path, or a path): h = H + N(grid) at each
    /// tile origin.
    #[arg(long, value_name = "GRID")]
    pub geoid: Option<String>,
    /// tileset.json path (content URIs are relative to its directory).
    #[arg(short, long)]
    pub output: String,
}

pub(super) fn run(a: TilesetArgs, config: &Config) -> CmdResult {
    citygml_io::crs::quiet_proj();
    let output = Output::from_arg(Some(&a.output));
    output.check_target()?;
    let out_dir = match Path::new(&a.output).parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let base = out_dir.canonicalize().map_err(|e| CliError::usage(format!("{}: {e}", out_dir.display())))?;
    let mut tiles = Vec::new();
    for g in &a.glb {
        let bytes = std::fs::read(g).map_err(|e| CliError::unreadable(format!("{g}: {e}")))?;
        let extent = tiling::tileset::glb_extent(&bytes, g).map_err(tiling_error)?;
        let abs = Path::new(g).canonicalize().map_err(|e| CliError::unreadable(format!("{g}: {e}")))?;
        let rel = abs.strip_prefix(&base).map_err(|_| {
            CliError::usage(format!(
                "{g}: not below the tileset's directory {} (content URIs are relative)",
                base.display()
            ))
        })?;
        let uri = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect::<Vec<_>>().join("/");
        tiles.push(tiling::tileset::ContentTile { uri, extent });
    }
    let generator = format!("geofit {}", env!("CARGO_PKG_VERSION"));
    let heights = match (a.height_offset, a.heights_as_is, &a.geoid) {
        (Some(m), ..) if !m.is_finite() => {
            return Err(CliError::usage(format!("--height-offset must be a finite number of metres, got {m}")))
        }
        (Some(m), ..) => tiling::tileset::Heights::Offset(m),
        (None, true, _) => tiling::tileset::Heights::AsIs,
        (None, false, Some(g)) => tiling::tileset::Heights::Geoid(g.clone()),
        (None, false, None) => tiling::tileset::Heights::Auto,
    };
    let t = tiling::tileset::tileset(&tiles, a.crs.as_deref(), &heights, &generator).map_err(tiling_error)?;
    let text = serde_json::to_string_pretty(&t).map_err(|e| CliError::internal(format!("tileset: {e}")))? + "\n";
    output.write_bytes(text.as_bytes())?;
    if !config.quiet {
        crate::say!("tile tileset: {} tiles", tiles.len());
    }
    Ok(Exit::Ok)
}
