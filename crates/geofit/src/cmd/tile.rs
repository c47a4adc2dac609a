//! `geofit tile`: the per-tile commands a workflow engine runs (plan, extract, tileset, report);
//! the rules and algorithms are the `tiling` crate's.

use std::path::{Path, PathBuf};

use clap::{Args as ClapArgs, Subcommand, ValueEnum};

use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};
use tiling::plan::PlanFormat;
use tiling::TilingError;

const AFTER_HELP: &str = "\
Example (what workflows/Snakefile runs; make -j, a Slurm array or GNU parallel run the same lines):
  geofit tile plan LoD2_*.gml --buildings-per-tile 2000 -o plan.jsonl
  geofit tile extract plan.jsonl --tile x1296_y22916 -o tiles/x1296_y22916.gml
  geofit heal tiles/x1296_y22916.gml -o healed/x1296_y22916.gml --report healed/x1296_y22916.heal.json
  geofit export healed/x1296_y22916.gml -o glb/x1296_y22916.glb
  geofit tile report healed/*.heal.json reports/*.validate.json -o report.json
  geofit tile tileset glb/*.glb -o tileset.json
  geofit tile plan dem.vrt --cells-per-tile 4194304 --halo 32 --format tsv

Buildings: every top-level object holding a Building or BuildingPart belongs to exactly one tile,
the cell of a grid (aligned at 0, power-of-two metres) that holds its footprint centroid (area
centroid of its GroundSurface polygons on xy, else its envelope centre). The step is the largest
that keeps every tile at or under --buildings-per-tile, or --tile-size. Buildings of other tiles
that reach into a tile are its halo: listed in the plan, read-only, never extracted twice.
Rasters: square core windows of about --cells-per-tile cells, halo grown by --halo pixels and
clipped to the raster; only the size and geotransform are read.

Exit codes: 0 written; 2 bad options or a tile not in the plan; 3 unreadable input; 4 I/O.";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    #[command(subcommand)]
    pub command: TileCommand,
}

#[derive(Subcommand, Debug)]
pub enum TileCommand {
    /// Tile list of CityGML files (buildings) or of one raster (any GDAL source).
    Plan(PlanArgs),
    /// One tile's buildings from its sources as a CityGML document (member bytes copied).
    Extract(ExtractArgs),
    /// A 3D Tiles 1.1 tileset.json over per-tile glb from `geofit export`.
    Tileset(TilesetArgs),
    /// Sum per-tile `heal --report` and `validate --json` outputs into one JSON report.
    Report(ReportArgs),
}

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

#[derive(ClapArgs, Debug)]
pub struct TilesetArgs {
    /// glb files from `geofit export`, at or below the tileset's directory.
    #[arg(required = true)]
    pub glb: Vec<String>,
    /// CRS of the glb coordinates for PROJ (default: the CRS each glb records).
    #[arg(long)]
    pub crs: Option<String>,
    /// Added to heights to make them ellipsoidal (e.g. the geoid undulation, m).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub height_offset: f64,
    /// tileset.json path (content URIs are relative to its directory).
    #[arg(short, long)]
    pub output: String,
}

#[derive(ClapArgs, Debug)]
pub struct ReportArgs {
    /// Per-tile reports named `<tile>.<anything>.json`.
    #[arg(required = true)]
    pub reports: Vec<String>,
    #[arg(short, long)]
    pub output: Option<String>,
}

fn tiling_error(e: TilingError) -> CliError {
    match e {
        TilingError::Usage(m) => CliError::usage(m),
        e @ TilingError::Unreadable { .. } => CliError::unreadable(e.to_string()),
    }
}

fn read_text(path: &str) -> Result<String, CliError> {
    std::fs::read_to_string(path).map_err(|e| CliError::unreadable(format!("{path}: {e}")))
}

/// Is this file a CityGML document (root element CityModel) rather than a raster?
fn is_citygml(path: &str) -> bool {
    let mut head = vec![0u8; 4096];
    let n = std::fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut head)).unwrap_or(0);
    String::from_utf8_lossy(&head[..n]).contains("CityModel")
}

fn plan(a: PlanArgs, config: &Config) -> CmdResult {
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

fn extract(a: ExtractArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    let tiles = tiling::plan::read_plan(&read_text(&a.plan)?, &a.plan).map_err(tiling_error)?;
    let tile = tiling::plan::find_tile(&tiles, &a.tile, &a.plan).map_err(tiling_error)?;
    let read = |p: &str| std::fs::read(p).map_err(|e| TilingError::Unreadable { name: p.to_string(), message: e.to_string() });
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

fn tileset(a: TilesetArgs, config: &Config) -> CmdResult {
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
            CliError::usage(format!("{g}: not below the tileset's directory {} (content URIs are relative)", base.display()))
        })?;
        let uri = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect::<Vec<_>>().join("/");
        tiles.push(tiling::tileset::ContentTile { uri, extent });
    }
    let generator = format!("geofit {}", env!("CARGO_PKG_VERSION"));
    let t = tiling::tileset::tileset(&tiles, a.crs.as_deref(), a.height_offset, &generator).map_err(tiling_error)?;
    let text = serde_json::to_string_pretty(&t).map_err(|e| CliError::internal(format!("tileset: {e}")))? + "\n";
    output.write_bytes(text.as_bytes())?;
    if !config.quiet {
        crate::say!("tile tileset: {} tiles", tiles.len());
    }
    Ok(Exit::Ok)
}

fn report(a: ReportArgs, _config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    let reports = a
        .reports
        .iter()
        .map(|p| tiling::report::TileReport::parse(p, &read_text(p)?).map_err(tiling_error))
        .collect::<Result<Vec<_>, _>>()?;
    let merged = tiling::report::merge(reports).map_err(tiling_error)?;
    let text = serde_json::to_string_pretty(&merged).map_err(|e| CliError::internal(format!("report: {e}")))? + "\n";
    output.write_bytes(text.as_bytes())?;
    Ok(Exit::Ok)
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    match args.command {
        TileCommand::Plan(a) => plan(a, config),
        TileCommand::Extract(a) => extract(a, config),
        TileCommand::Tileset(a) => tileset(a, config),
        TileCommand::Report(a) => report(a, config),
    }
}
