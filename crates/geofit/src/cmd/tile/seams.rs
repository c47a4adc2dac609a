//! `geofit tile seams`: the continuity report over every seam of a plan's tile meshes, measured
//! where a user sees the surface (over the data, relative to the data's height range) and read
//! pair by pair (a tile and its neighbours at a time: memory bounded by nine meshes).

use std::collections::HashMap;

use clap::Args as ClapArgs;

use super::{placed_tiles, read_text, tiling_error};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs, Debug)]
pub struct SeamsArgs {
    /// JSON-lines plan from `geofit tile plan`.
    pub plan: String,
    /// The tile meshes: a path with `{id}` for the tile id.
    #[arg(long, value_name = "TEMPLATE")]
    pub meshes: String,
    /// Fail (exit 1) when a seam's gap over the data, relative to the data's height range,
    /// exceeds this (1e-6: a micrometre per metre of relief, far below what a viewer shows and
    /// above the rounding of heights far from zero).
    #[arg(long, default_value_t = 1e-6)]
    pub max_gap_relative: f64,
    /// The data's height range (e.g. `gdalinfo -mm`); default: the range of the tiles' control
    /// points.
    #[arg(long, num_args = 2, value_names = ["MIN", "MAX"], allow_hyphen_values = true)]
    pub z_range: Option<Vec<f64>>,
    #[arg(short, long)]
    pub output: Option<String>,
}

type PlacedTile = (String, tspline::format::TMeshFile, tspline::seams::Placed);

/// Whether plan cell (s, t) (whole numbers) holds data in the tile's stored mask: None where
/// the tile's window does not cover it.
fn cell_in(p: &PlacedTile, s: i64, t: i64) -> Option<bool> {
    let m = p.1.mask.as_ref()?;
    let (i, j) = (s - p.2.offset[0] as i64, t - p.2.offset[1] as i64);
    (i >= 0 && j >= 0 && (i as usize) < m.width && (j as usize) < m.height).then(|| m.get(i as usize, j as usize))
}

/// The data region of two tiles at plan (s, t): every cell centre within one pixel holds data in
/// a tile that covers it (and some tile covers it). Tiles without a stored mask: everywhere.
fn in_data(a: &PlacedTile, b: &PlacedTile, s: f64, t: f64) -> bool {
    if a.1.mask.is_none() || b.1.mask.is_none() {
        return true;
    }
    let (s0, s1, t0, t1) = (s.floor() as i64, s.ceil() as i64, t.floor() as i64, t.ceil() as i64);
    [(s0, t0), (s1, t0), (s0, t1), (s1, t1)].iter().all(|&(i, j)| match (cell_in(a, i, j), cell_in(b, i, j)) {
        (None, None) => false,
        (x, y) => x.unwrap_or(true) && y.unwrap_or(true),
    })
}

pub(super) fn run(a: SeamsArgs, config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    if a.z_range.as_ref().is_some_and(|r| !(r[1] > r[0] && r[0].is_finite() && r[1].is_finite())) {
        return Err(CliError::usage("--z-range MIN MAX: two finite numbers, MIN < MAX"));
    }
    let tiles = tiling::plan::read_plan(&read_text(&a.plan)?, &a.plan).map_err(tiling_error)?;
    let index: HashMap<&str, usize> = tiles.iter().enumerate().map(|(i, t)| (t.id.as_str(), i)).collect();
    let mut rows = Vec::new();
    let (mut gap, mut ang) = (0.0f64, 0.0f64);
    let (mut zlo, mut zhi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (i, t) in tiles.iter().enumerate().filter(|(_, t)| t.work > 0) {
        // this tile and its later neighbours: each seam once
        let mut ids = vec![t.id.as_str()];
        ids.extend(t.neighbours.iter().map(|n| n.as_str()).filter(|n| index.get(n).is_some_and(|&j| j > i)));
        let placed = placed_tiles(&tiles, &a.plan, &a.meshes, &ids)?;
        let own = &placed[0];
        for p in &own.1.mesh.points {
            (zlo, zhi) = (zlo.min(p.z), zhi.max(p.z));
        }
        for other in &placed[1..] {
            let region = |s: f64, t: f64| in_data(own, other, s, t);
            let cell = [own.1.georef.dx, own.1.georef.dy];
            let Some(c) = tspline::seams::continuity_in(&own.2, &other.2, cell, &region) else { continue };
            gap = gap.max(c.max_gap);
            ang = ang.max(c.max_normal_angle_deg);
            rows.push(serde_json::json!({"a": own.0, "b": other.0, "samples": c.samples, "max_gap": c.max_gap, "max_normal_angle_deg": c.max_normal_angle_deg, "median_normal_angle_deg": c.median_normal_angle_deg}));
        }
    }
    let (range, from) = match &a.z_range {
        Some(r) => (r[1] - r[0], "--z-range"),
        None => (zhi - zlo, "control points"),
    };
    let rel = gap / range.max(f64::MIN_POSITIVE);
    let doc = serde_json::json!({
        "schema": "geofit-tile-seams-report/2",
        "units": {
            "max_gap": crate::report::Z_UNIT, "z_range": crate::report::Z_UNIT, "max_gap_relative": "max_gap / z_range", "max_normal_angle_deg": "deg",
            "per_seam[].max_gap": crate::report::Z_UNIT, "per_seam[].max_normal_angle_deg": "deg", "per_seam[].median_normal_angle_deg": "deg"
        },
        "measured": "seam positions whose neighbouring cells hold data",
        "tiles": tiles.iter().filter(|t| t.work > 0).count(),
        "seams": rows.len(),
        "z_range": range,
        "z_range_from": from,
        "max_gap": gap,
        "max_gap_relative": rel,
        "max_normal_angle_deg": ang,
        "per_seam": rows,
    });
    let text = serde_json::to_string_pretty(&doc).map_err(|e| CliError::internal(format!("seams: {e}")))? + "\n";
    output.write_bytes(text.as_bytes())?;
    if !config.quiet {
        crate::say!("tile seams: {} seams, max gap over the data {gap:.3e} ({rel:.3e} of the height range), max normal-angle jump {ang:.4}°", rows.len());
    }
    Ok(if rel <= a.max_gap_relative { Exit::Ok } else { Exit::Findings })
}
