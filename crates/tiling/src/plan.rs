//! The tile list: one [`Tile`] per line, as JSON lines (what `geofit tile extract` reads), TSV
//! (for `cut`/`awk`/Slurm arrays) or a Makefile fragment (`TILES := ...`).

use serde::{Deserialize, Serialize};

use crate::TilingError;

/// What a tile cuts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TileKind {
    Buildings,
    Raster,
}

/// An axis-aligned window: georeferenced bounds, and for rasters the pixel window
/// (`col_off, row_off, width, height`) that GDAL's windowed read takes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// `[xmin, ymin, xmax, ymax]` in the source CRS; half-open in x and y for building cores.
    pub bounds: [f64; 4],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixels: Option<[usize; 4]>,
}

impl Window {
    pub fn contains_xy(&self, x: f64, y: f64) -> bool {
        let [x0, y0, x1, y1] = self.bounds;
        x >= x0 && x < x1 && y >= y0 && y < y1
    }
}

/// One job's share of the work.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tile {
    /// Stable name, usable in file names (`x1296_y22916`, `c3_r1`).
    pub id: String,
    pub kind: TileKind,
    /// Grid step: metres for buildings, pixels for rasters.
    pub size: f64,
    /// What the tile owns: buildings whose footprint centroid is inside; raster cells.
    pub core: Window,
    /// What the tile reads: the core plus the buildings that reach into it from neighbouring
    /// tiles (read-only); for rasters the core grown by the halo width, clipped to the raster.
    pub halo: Window,
    /// Ids of the adjacent tiles of the plan (8-neighbourhood; empty tiles are not in the plan).
    pub neighbours: Vec<String>,
    /// The work: buildings owned, or raster cells in the core.
    pub work: usize,
    /// Buildings of other tiles whose footprint reaches into this core (gml:ids; read-only here).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub halo_buildings: Vec<String>,
    /// The files the tile's objects come from (as given to the plan), in order.
    pub sources: Vec<String>,
}

/// How the plan is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanFormat {
    JsonLines,
    Tsv,
    Make,
}

/// The plan as text in `format`, tiles in the given order. JSON lines hold every tile; the job
/// lists (TSV, make) leave out raster tiles without data (`work` 0,
/// docs/decisions.md#tiles-on-the-whole-fits-lattice).
pub fn write_plan(tiles: &[Tile], format: PlanFormat) -> String {
    match format {
        PlanFormat::JsonLines => {
            tiles.iter().map(|t| serde_json::to_string(t).expect("a tile serialises") + "\n").collect()
        }
        PlanFormat::Tsv => {
            let mut s = String::from("#id\tkind\tsize\tcore\thalo\tcore_px\thalo_px\tneighbours\twork\tsources\n");
            for t in tiles.iter().filter(|t| t.work > 0) {
                let b = |w: &Window| w.bounds.map(|v| v.to_string()).join(",");
                let px =
                    |w: &Window| w.pixels.map(|p| p.map(|v| v.to_string()).join(",")).unwrap_or_else(|| "-".into());
                s += &format!(
                    "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\n",
                    t.id,
                    kind_name(t.kind),
                    t.size,
                    b(&t.core),
                    b(&t.halo),
                    px(&t.core),
                    px(&t.halo),
                    if t.neighbours.is_empty() { "-".into() } else { t.neighbours.join(",") },
                    t.work,
                    t.sources.join(",")
                );
            }
            s
        }
        PlanFormat::Make => {
            let ids: Vec<&str> = tiles.iter().filter(|t| t.work > 0).map(|t| t.id.as_str()).collect();
            format!("# geofit tile plan: {} tiles\nTILES := {}\n", tiles.len(), ids.join(" "))
        }
    }
}

fn kind_name(k: TileKind) -> &'static str {
    match k {
        TileKind::Buildings => "buildings",
        TileKind::Raster => "raster",
    }
}

/// Reads a JSON-lines plan (`name` for messages).
pub fn read_plan(text: &str, name: &str) -> Result<Vec<Tile>, TilingError> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|e| {
                TilingError::unreadable(format!("{name}:{}", i + 1), format!("not a JSON-lines tile plan line: {e}"))
            })
        })
        .collect()
}

/// The tile `id` of a plan.
pub fn find_tile<'a>(tiles: &'a [Tile], id: &str, name: &str) -> Result<&'a Tile, TilingError> {
    tiles
        .iter()
        .find(|t| t.id == id)
        .ok_or_else(|| TilingError::Usage(format!("{name}: no tile '{id}' in the plan ({} tiles)", tiles.len())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(id: &str) -> Tile {
        let w = Window { bounds: [0.0, 0.0, 1.0, 1.0], pixels: None };
        Tile {
            id: id.into(),
            kind: TileKind::Buildings,
            size: 1.0,
            core: w,
            halo: w,
            neighbours: vec![],
            work: 2,
            halo_buildings: vec![],
            sources: vec!["a.gml".into()],
        }
    }

    #[test]
    fn json_lines_round_trip() {
        let tiles = vec![tile("x0_y0"), tile("x1_y0")];
        let text = write_plan(&tiles, PlanFormat::JsonLines);
        assert_eq!(read_plan(&text, "p").unwrap(), tiles);
        assert!(find_tile(&tiles, "x2_y0", "p").is_err());
    }

    #[test]
    fn make_fragment_lists_ids() {
        let text = write_plan(&[tile("a"), tile("b")], PlanFormat::Make);
        assert!(text.ends_with("TILES := a b\n"), "{text}");
    }

    #[test]
    fn core_window_is_half_open() {
        let w = Window { bounds: [0.0, 0.0, 2.0, 2.0], pixels: None };
        assert!(w.contains_xy(0.0, 0.0));
        assert!(!w.contains_xy(2.0, 1.0));
        assert!(!w.contains_xy(1.0, 2.0));
    }
}
