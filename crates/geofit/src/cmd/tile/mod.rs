//! `geofit tile`: the per-tile commands a workflow engine runs (plan, extract, tileset, report,
//! stitch, seams), one file each; the rules and algorithms are the `tiling` crate's (and
//! `tspline::seams` for raster seams). This module holds what they share.

mod extract;
mod plan;
mod report;
mod seams;
mod stitch;
mod tileset;

use clap::{Args as ClapArgs, Subcommand};

use crate::config::Config;
use crate::error::{CliError, CmdResult};
use tiling::TilingError;

pub use extract::ExtractArgs;
pub use plan::PlanArgs;
pub use report::ReportArgs;
pub use seams::SeamsArgs;
pub use stitch::StitchArgs;
pub use tileset::TilesetArgs;

const AFTER_HELP: &str = "\
Example (what workflows/Snakefile runs; make -j, a Slurm array or GNU parallel run the same lines):
  geofit tile plan LoD2_*.gml --buildings-per-tile 2000 -o plan.jsonl
  geofit tile extract plan.jsonl --tile x1296_y22916 -o tiles/x1296_y22916.gml
  geofit heal tiles/x1296_y22916.gml -o healed/x1296_y22916.gml --report healed/x1296_y22916.heal.json
  geofit export healed/x1296_y22916.gml -o glb/x1296_y22916.glb
  geofit tile report healed/*.heal.json reports/*.validate.json -o report.json
  geofit tile tileset glb/*.glb --height-offset 46.5 -o tileset.json   # NRW: DHHN2016 heights
  geofit tile plan dem.vrt --tile-size 1024 --halo 2 -o plan.jsonl
  geofit fit dem.vrt --plan plan.jsonl --tile c3_r1 --max-error 0.5 -o fit/c3_r1.tmb
  geofit tile stitch dem.vrt --plan plan.jsonl --tile c3_r1 --meshes fit/{id}.tmb -o st/c3_r1.tmb
  geofit tile seams plan.jsonl --meshes 'st/{id}.tmb' -o seams.json
  (stitch needs the fit's tolerance too: --max-error 0.5)

Buildings: every top-level object holding a Building or BuildingPart belongs to exactly one tile,
the cell of a grid (aligned at 0, power-of-two metres) that holds its footprint centroid (area
centroid of its GroundSurface polygons on xy, else its envelope centre). The step is the largest
that keeps every tile at or under --buildings-per-tile, or --tile-size. Buildings of other tiles
that reach into a tile are its halo: listed in the plan, read-only, never extracted twice.
Rasters: core windows of about --cells-per-tile cells cut along the knot lattice of the whole
raster's fit (seams on pixel centres), halo grown by --halo pixels and clipped to the raster; the
data is read one core at a time and tiles without a valid cell get work 0 (no jobs, no seams).
`fit --plan --tile` fits a tile's window as the whole fit would; `stitch` makes it C0 with its
neighbours' fits along every seam (reading its halo: plan with --halo 2 or more) and re-checks
--max-error on every valid cell; `seams` reports the gap and the normal-angle jump per seam over
the data (exit 1 when a gap exceeds --max-gap-relative of the height range).

Tileset heights: 3D Tiles wants ellipsoidal heights (m). A CRS that names a height system (NRW's
urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016, a compound CRS such as EPSG:25832+5773) gets the
undulation N of its PROJ geoid grid at each tile origin (h = H + N; EGM96, EGM2008, NAP, GEOID18
... where the grid is installed); without the grid it is refused (exit 2) unless --geoid GRID,
--height-offset M (h = H + M) or --heights-as-is states the choice. The tileset records it in
asset.extras.heights and each tile's extras.height_offset_m. A CRS without a height system keeps
its heights.

Exit codes: 0 written; 1 stitch stopped before the tolerance held / a seam gap over the bound;
2 bad options or a tile not in the plan; 3 unreadable input; 4 I/O.";

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
    /// Make a raster tile's fitted surface C0 with its neighbours along every seam (shared seam
    /// curves), refitting and refining until every valid cell is within --max-error again.
    Stitch(StitchArgs),
    /// Continuity report over every seam of a plan's tile meshes (max gap, normal-angle jump).
    Seams(SeamsArgs),
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    match args.command {
        TileCommand::Plan(a) => plan::run(a, config),
        TileCommand::Extract(a) => extract::run(a, config),
        TileCommand::Tileset(a) => tileset::run(a, config),
        TileCommand::Report(a) => report::run(a, config),
        TileCommand::Stitch(a) => stitch::run(a, config),
        TileCommand::Seams(a) => seams::run(a, config),
    }
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

/// A plan's raster tiles (`tiles`, read from `plan`) and the mesh of each (read by `template`
/// with `{id}`), placed in the plan's frame.
fn placed_tiles(
    tiles: &[tiling::Tile],
    plan: &str,
    template: &str,
    ids: &[&str],
) -> Result<Vec<(String, tspline::format::TMeshFile, tspline::seams::Placed)>, CliError> {
    let mut out = Vec::new();
    for id in ids {
        let t = tiling::plan::find_tile(tiles, id, plan).map_err(tiling_error)?;
        let path = template.replace("{id}", &t.id);
        let file = crate::terrain_io::read_tmesh_arg(&path)?;
        let g = &file.georef;
        let offset = tiling::raster::frame_offset(tiles, g.x0, g.y0, g.dx, g.dy);
        let placed = tspline::seams::Placed { mesh: file.mesh.clone(), offset };
        out.push((t.id.clone(), file, placed));
    }
    Ok(out)
}
