//! `geofit tile seams`: the continuity report over every seam of a plan's tile meshes.

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
    /// Fail (exit 1) when a seam's gap relative to the heights exceeds this.
    #[arg(long, default_value_t = 1e-9)]
    pub max_gap_relative: f64,
    #[arg(short, long)]
    pub output: Option<String>,
}

pub(super) fn run(a: SeamsArgs, config: &Config) -> CmdResult {
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
