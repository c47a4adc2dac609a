//! `geofit tile stitch`: a raster tile's fitted surface made C0 with its neighbours along every
//! seam, the tolerance re-established on every valid cell (`tspline::seams::stitch`).

use std::path::Path;

use clap::Args as ClapArgs;

use super::{placed_tiles, read_text, tiling_error};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

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

pub(super) fn run(a: StitchArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(Some(&a.output));
    output.check_target()?;
    if !(a.max_error > 0.0 && a.max_error.is_finite()) {
        return Err(CliError::usage(format!("--max-error must be a positive number, got {}", a.max_error)));
    }
    let t0 = std::time::Instant::now();
    let tiles = tiling::plan::read_plan(&read_text(&a.plan)?, &a.plan).map_err(tiling_error)?;
    let tile = tiling::plan::find_tile(&tiles, &a.tile, &a.plan).map_err(tiling_error)?;
    // the cells the tile's fit read (its core and the seam column/row it shares)
    let px = tiling::raster::fit_window(&tiles, tile).map_err(tiling_error)?.pixels;
    let mut ids = vec![tile.id.as_str()];
    ids.extend(tile.neighbours.iter().map(|s| s.as_str()));
    let mut placed = placed_tiles(&tiles, &a.plan, &a.meshes, &ids)?;
    let (_, own_file, own) = placed.remove(0);
    let neighbours: Vec<tspline::seams::Placed> = placed.into_iter().map(|(_, _, p)| p).collect();
    crate::terrain_io::gdal_notices(config);
    let (raster, _) = raster_io::read_raster_window_typed(Path::new(&a.source), 1, Some(px))
        .map_err(crate::terrain_io::raster_err)?;
    let name = format!("{} (tile {})", a.source, a.tile);
    let layout = crate::terrain_io::raster_layout(raster, &name)?;
    let (samples, georef) = (layout.samples, layout.georef);
    if georef.x0 != own_file.georef.x0 || georef.y0 != own_file.georef.y0 {
        return Err(CliError::usage(format!(
            "{}: the mesh of tile {} was not fitted on this tile's window of {}",
            a.meshes.replace("{id}", &a.tile),
            a.tile,
            a.source
        )));
    }
    let mut opts = tspline::fit::FitOptions::new(own.mesh.degree, a.max_error);
    opts.max_iterations = a.max_iterations;
    let progress = config.progress("stitch", a.max_iterations as u64);
    let mut cb = |st: &tspline::fit::IterationStats| {
        progress.set(
            st.iteration as u64,
            &format!(
                "round {}: {} control points, max {:.4}, {} cells over {}",
                st.iteration, st.control_points, st.error.max, st.error.over_tolerance, a.max_error
            ),
        );
    };
    // the source around the tile (its halo window): the data on both sides of every seam
    let hp = tile.halo.pixels.unwrap_or(px);
    let short = [px[0] - hp[0], px[1] - hp[1], (hp[0] + hp[2]) - (px[0] + px[2]), (hp[1] + hp[3]) - (px[1] + px[3])];
    if !tile.neighbours.is_empty() && short.iter().all(|&m| m < 2) {
        return Err(CliError::usage(format!(
            "{}: the plan's halo is under 2 px; the seams need the cells on both sides: plan with --halo 2 (or more)",
            a.plan
        )));
    }
    let (halo, _) = raster_io::read_raster_window_typed(Path::new(&a.source), 1, Some(hp))
        .map_err(crate::terrain_io::raster_err)?;
    let halo_layout = crate::terrain_io::raster_layout(halo, &name)?;
    let (hs, hg) = (halo_layout.samples, halo_layout.georef);
    let ho = tiling::raster::frame_offset(&tiles, hg.x0, hg.y0, hg.dx, hg.dy);
    let source = |s: i64, t: i64| -> f64 {
        let (i, j) = (s - ho[0] as i64, t - ho[1] as i64);
        if i < 0 || j < 0 || i as usize >= hs.width || j as usize >= hs.height {
            f64::NAN
        } else {
            hs.get(i as usize, j as usize)
        }
    };
    let r = tspline::seams::stitch(&own, &neighbours, &samples, &source, &opts, &tspline::fit::Backend::Cpu, &mut cb)
        .map_err(|e| crate::terrain_io::tspline_err(&name, e))?;
    let ok = r.stop == tspline::fit::StopReason::ToleranceReached;
    progress.finish(&if ok {
        format!("every valid cell within {}, {} seams", a.max_error, r.seams.len())
    } else {
        format!("stopped: {:?}", r.stop)
    });
    let exit = if ok { Exit::Ok } else { Exit::Findings };
    let file = tspline::format::TMeshFile {
        mesh: r.mesh,
        georef: own_file.georef.clone(),
        mask: own_file.mask.clone(),
        warp: None,
    };
    if config.keeps_output(exit, Some(&a.output)) {
        let mut bytes = Vec::new();
        tspline::format::write_as(&file, tspline::format::Encoding::for_path(Some(&a.output)), &mut bytes)
            .map_err(CliError::io_out)?;
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
        crate::say!(
            "geofit: {name}: stitching stopped before every valid cell was within {}: {:?}",
            a.max_error,
            r.stop
        );
    }
    Ok(exit)
}
