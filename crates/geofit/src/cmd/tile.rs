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
Rasters: square core windows of about --cells-per-tile cells, halo grown by --halo pixels and
clipped to the raster; only the size and geotransform are read. `fit --plan --tile` fits a tile's
core window; `stitch` makes it C0 with its neighbours' fits along every seam (reading its halo:
plan with --halo 2 or more) and re-checks --max-error on every valid cell; `seams` reports the
gap and the normal-angle jump per seam (exit 1 when a gap exceeds --max-gap-relative).

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

#[derive(ClapArgs, Debug)]
pub struct StitchArgs {
    /// The raster the plan was made from (the tile's core window is read, nothing else).
    pub source: String,
    /// JSON-lines plan from `geofit tile plan`.
    #[arg(long)]
    pub plan: String,
    /// Tile id.
    #[arg(long)]
    pub tile: String,
    /// Where the first-pass tile meshes are: a path with `{id}` for the tile id.
    #[arg(long, value_name = "TEMPLATE")]
    pub meshes: String,
    /// The tolerance of the tile fits (every valid cell within it after stitching).
    #[arg(long)]
    pub max_error: f64,
    /// Stop after this many refit/refine rounds.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Output T-mesh (`.tmb`: binary form).
    #[arg(short, long)]
    pub output: String,
    /// JSON report (per-iteration table, the seams' curves and deviations).
    #[arg(long)]
    pub report: Option<String>,
}

#[derive(ClapArgs, Debug)]
pub struct SeamsArgs {
    /// JSON-lines plan from `geofit tile plan`.
    pub plan: String,
    /// The tile meshes: a path with `{id}` for the tile id.
    #[arg(long, value_name = "TEMPLATE")]
    pub meshes: String,
    /// Fail (exit 1) when a seam's gap relative to the heights exceeds this.
    #[arg(long, default_value_t = 1e-9)]
    pub max_gap_relative: f64,
    #[arg(short, long)]
    pub output: Option<String>,
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

/// A plan's raster tiles and the mesh of each (read by `template` with `{id}`), placed in the
/// plan's frame.
fn placed_tiles(plan: &str, template: &str, ids: &[&str]) -> Result<Vec<(String, tspline::format::TMeshFile, tspline::seams::Placed)>, CliError> {
    let tiles = tiling::plan::read_plan(&read_text(plan)?, plan).map_err(tiling_error)?;
    let mut out = Vec::new();
    for id in ids {
        let t = tiling::plan::find_tile(&tiles, id, plan).map_err(tiling_error)?;
        let path = template.replace("{id}", &t.id);
        let file = crate::terrain_io::read_tmesh_arg(&path)?;
        let g = &file.georef;
        let offset = tiling::raster::frame_offset(&tiles, g.x0, g.y0, g.dx, g.dy);
        let placed = tspline::seams::Placed { mesh: file.mesh.clone(), offset };
        out.push((t.id.clone(), file, placed));
    }
    Ok(out)
}

/// `tile stitch --report`: how the tile's seams were made and the tolerance re-established.
const STITCH_REPORT: crate::report::ReportKind = crate::report::ReportKind {
    schema: "geofit-tile-stitch-report/1",
    units: &[
        ("max_error", crate::report::Z_UNIT),
        ("seams[].max_curve_deviation", crate::report::Z_UNIT),
        ("iterations[].max", crate::report::Z_UNIT),
        ("iterations[].rms", crate::report::Z_UNIT),
        ("iterations[].seconds", "s"),
        ("seconds", "s"),
    ],
};

#[derive(serde::Serialize)]
struct StitchReport<'a> {
    tile: &'a str,
    max_error: f64,
    stop: &'a tspline::fit::StopReason,
    /// The first inward column held to the data's slope (approximately C1 with the neighbours).
    c1_held: bool,
    control_points: usize,
    seams: Vec<serde_json::Value>,
    iterations: &'a [tspline::fit::IterationStats],
    seconds: f64,
}

fn stitch(a: StitchArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(Some(&a.output));
    output.check_target()?;
    if !(a.max_error > 0.0 && a.max_error.is_finite()) {
        return Err(CliError::usage(format!("--max-error must be a positive number, got {}", a.max_error)));
    }
    let t0 = std::time::Instant::now();
    let tiles = tiling::plan::read_plan(&read_text(&a.plan)?, &a.plan).map_err(tiling_error)?;
    let tile = tiling::plan::find_tile(&tiles, &a.tile, &a.plan).map_err(tiling_error)?;
    let px = tile.core.pixels.ok_or_else(|| CliError::usage(format!("{}: tile {} is not a raster tile", a.plan, a.tile)))?;
    let mut ids = vec![tile.id.as_str()];
    ids.extend(tile.neighbours.iter().map(|s| s.as_str()));
    let mut placed = placed_tiles(&a.plan, &a.meshes, &ids)?;
    let (_, own_file, own) = placed.remove(0);
    let neighbours: Vec<tspline::seams::Placed> = placed.into_iter().map(|(_, _, p)| p).collect();
    crate::terrain_io::gdal_notices(config);
    let (raster, _) = raster_io::read_raster_window_typed(Path::new(&a.source), 1, Some(px)).map_err(crate::terrain_io::raster_err)?;
    let name = format!("{} (tile {})", a.source, a.tile);
    let layout = crate::terrain_io::raster_layout(&raster, &name)?;
    let (samples, georef) = (layout.samples, layout.georef);
    drop(raster);
    if georef.x0 != own_file.georef.x0 || georef.y0 != own_file.georef.y0 {
        return Err(CliError::usage(format!("{}: the mesh of tile {} was not fitted on this tile's window of {}", a.meshes.replace("{id}", &a.tile), a.tile, a.source)));
    }
    let mut opts = tspline::fit::FitOptions::new(own.mesh.degree, a.max_error);
    opts.max_iterations = a.max_iterations;
    let progress = config.progress("stitch", a.max_iterations as u64);
    let mut cb = |st: &tspline::fit::IterationStats| {
        progress.set(st.iteration as u64, &format!("round {}: {} control points, max {:.4}, {} cells over {}", st.iteration, st.control_points, st.error.max, st.error.over_tolerance, a.max_error));
    };
    // the source around the tile (its halo window): the data on both sides of every seam
    let hp = tile.halo.pixels.unwrap_or(px);
    let short = [px[0] - hp[0], px[1] - hp[1], (hp[0] + hp[2]) - (px[0] + px[2]), (hp[1] + hp[3]) - (px[1] + px[3])];
    if !tile.neighbours.is_empty() && short.iter().all(|&m| m < 2) {
        return Err(CliError::usage(format!("{}: the plan's halo is under 2 px; the seams need the cells on both sides: plan with --halo 2 (or more)", a.plan)));
    }
    let (halo, _) = raster_io::read_raster_window_typed(Path::new(&a.source), 1, Some(hp)).map_err(crate::terrain_io::raster_err)?;
    let halo_layout = crate::terrain_io::raster_layout(&halo, &name)?;
    let (hs, hg) = (halo_layout.samples, halo_layout.georef);
    drop(halo);
    let ho = tiling::raster::frame_offset(&tiles, hg.x0, hg.y0, hg.dx, hg.dy);
    let source = |s: i64, t: i64| -> f64 {
        let (i, j) = (s - ho[0] as i64, t - ho[1] as i64);
        if i < 0 || j < 0 || i as usize >= hs.width || j as usize >= hs.height { f64::NAN } else { hs.get(i as usize, j as usize) }
    };
    let r = tspline::seams::stitch(&own, &neighbours, &samples, &source, &opts, &tspline::fit::Backend::Cpu, &mut cb)
        .map_err(|e| crate::terrain_io::tspline_err(&name, e))?;
    let ok = r.stop == tspline::fit::StopReason::ToleranceReached;
    progress.finish(&if ok { format!("every valid cell within {}, {} seams", a.max_error, r.seams.len()) } else { format!("stopped: {:?}", r.stop) });
    let exit = if ok { Exit::Ok } else { Exit::Findings };
    let file = tspline::format::TMeshFile { mesh: r.mesh, georef: own_file.georef.clone(), mask: own_file.mask.clone(), warp: None };
    if config.keeps_output(exit, Some(&a.output)) {
        let mut bytes = Vec::new();
        tspline::format::write_as(&file, tspline::format::Encoding::for_path(Some(&a.output)), &mut bytes).map_err(CliError::io_out)?;
        output.write_bytes(&bytes)?;
    }
    if let Some(path) = &a.report {
        let neighbour_ids = &ids[1..];
        let rep = StitchReport {
            tile: &a.tile,
            max_error: a.max_error,
            stop: &r.stop,
            c1_held: r.c1_held,
            control_points: r.iterations.last().map_or(0, |i| i.control_points),
            seams: r
                .seams
                .iter()
                .map(|s| serde_json::json!({"side": s.side, "neighbour": neighbour_ids[s.neighbour], "curve_vertices": s.curve_vertices, "max_curve_deviation": s.max_curve_deviation}))
                .collect(),
            iterations: &r.iterations,
            seconds: t0.elapsed().as_secs_f64(),
        };
        crate::report::write_json_report(path, &STITCH_REPORT, &rep)?;
    }
    if !ok {
        crate::say!("geofit: {name}: stitching stopped before every valid cell was within {}: {:?}", a.max_error, r.stop);
    }
    Ok(exit)
}

fn seams(a: SeamsArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    let tiles = tiling::plan::read_plan(&read_text(&a.plan)?, &a.plan).map_err(tiling_error)?;
    let ids: Vec<&str> = tiles.iter().map(|t| t.id.as_str()).collect();
    let placed = placed_tiles(&a.plan, &a.meshes, &ids)?;
    let mut rows = Vec::new();
    let (mut gap, mut rel, mut ang) = (0.0f64, 0.0f64, 0.0f64);
    for (i, (ia, fa, pa)) in placed.iter().enumerate() {
        for (ib, _, pb) in &placed[i + 1..] {
            let Some(c) = tspline::seams::continuity(pa, pb, [fa.georef.dx, fa.georef.dy]) else { continue };
            gap = gap.max(c.max_gap);
            rel = rel.max(c.max_gap_relative);
            ang = ang.max(c.max_normal_angle_deg);
            rows.push(serde_json::json!({"a": ia, "b": ib, "samples": c.samples, "max_gap": c.max_gap, "max_gap_relative": c.max_gap_relative, "max_normal_angle_deg": c.max_normal_angle_deg, "median_normal_angle_deg": c.median_normal_angle_deg}));
        }
    }
    let doc = serde_json::json!({
        "schema": "geofit-tile-seams-report/1",
        "units": {
            "max_gap": crate::report::Z_UNIT, "max_gap_relative": "max_gap / max |z| on the seam", "max_normal_angle_deg": "deg",
            "per_seam[].max_gap": crate::report::Z_UNIT, "per_seam[].max_normal_angle_deg": "deg", "per_seam[].median_normal_angle_deg": "deg"
        },
        "tiles": tiles.len(),
        "seams": rows.len(),
        "max_gap": gap,
        "max_gap_relative": rel,
        "max_normal_angle_deg": ang,
        "per_seam": rows,
    });
    let text = serde_json::to_string_pretty(&doc).map_err(|e| CliError::internal(format!("seams: {e}")))? + "\n";
    output.write_bytes(text.as_bytes())?;
    if !config.quiet {
        crate::say!("tile seams: {} seams, max gap {gap:.3e} ({rel:.3e} relative), max normal-angle jump {ang:.4}°", rows.len());
    }
    Ok(if rel <= a.max_gap_relative { Exit::Ok } else { Exit::Findings })
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    match args.command {
        TileCommand::Plan(a) => plan(a, config),
        TileCommand::Extract(a) => extract(a, config),
        TileCommand::Tileset(a) => tileset(a, config),
        TileCommand::Report(a) => report(a, config),
        TileCommand::Stitch(a) => stitch(a, config),
        TileCommand::Seams(a) => seams(a, config),
    }
}
