//! Tile plans for CityGML buildings: each building-owning top-level object goes to the grid cell
//! that holds its footprint centroid (docs/decisions.md#scale-out-tiles-and-workflows).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use citygml_io::{CityObject, ObjectStream, SurfaceType};

use crate::plan::{Tile, TileKind, Window};
use crate::TilingError;

/// How the grid step is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GridSize {
    /// The largest power of two (metres) that keeps every tile at or under this many buildings.
    BuildingsPerTile(usize),
    /// A fixed step in metres.
    Metres(f64),
}

/// One building-owning top-level object, as the plan sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildingSite {
    pub id: Option<String>,
    /// Index of its source file.
    pub source: usize,
    /// Footprint centroid (x, y).
    pub centroid: [f64; 2],
    /// xy bounds of all its coordinates `[xmin, ymin, xmax, ymax]`.
    pub bounds: [f64; 4],
}

/// Does this top-level object hold a Building or BuildingPart (the unit heal works on)?
pub fn owns_building(o: &CityObject) -> bool {
    o.walk().iter().any(|c| c.kind == "Building" || c.kind == "BuildingPart")
}

/// The footprint centroid: the area centroid of the object's GroundSurface polygons projected on
/// xy (exterior rings, holes ignored), else the centre of its xy envelope. `None` without any
/// coordinate.
pub fn footprint_centroid(o: &CityObject) -> Option<[f64; 2]> {
    let (mut a, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for c in o.walk() {
        for g in &c.geometries {
            for p in g.polygons().into_iter().filter(|p| p.via_xlink.is_none()) {
                if p.semantic != Some(SurfaceType::Ground) {
                    continue;
                }
                let (pa, px, py) = ring_moments(&p.exterior.points);
                a += pa;
                cx += px;
                cy += py;
            }
        }
    }
    if a.abs() > 1e-9 {
        return Some([cx / a, cy / a]);
    }
    let e = &o.envelope;
    (!e.is_empty()).then(|| [(e.min[0] + e.max[0]) / 2.0, (e.min[1] + e.max[1]) / 2.0])
}

/// Signed area and first moments of a ring on xy (shoelace), about the ring's first point for
/// precision with UTM coordinates, shifted back.
fn ring_moments(pts: &[[f64; 3]]) -> (f64, f64, f64) {
    let Some(o) = pts.first() else { return (0.0, 0.0, 0.0) };
    let (mut a, mut mx, mut my) = (0.0, 0.0, 0.0);
    for w in pts.windows(2) {
        let (x0, y0, x1, y1) = (w[0][0] - o[0], w[0][1] - o[1], w[1][0] - o[0], w[1][1] - o[1]);
        let cross = x0 * y1 - x1 * y0;
        a += cross / 2.0;
        mx += (x0 + x1) * cross / 6.0;
        my += (y0 + y1) * cross / 6.0;
    }
    // area-weighted centroid relative to o → absolute, as moments
    (a, mx + a * o[0], my + a * o[1])
}

/// The grid cell of a point for step `size`.
pub fn cell(p: [f64; 2], size: f64) -> (i64, i64) {
    ((p[0] / size).floor() as i64, (p[1] / size).floor() as i64)
}

/// Tile id of a cell: `x<ix>_y<iy>` (negative indices keep their minus sign).
pub fn cell_id(c: (i64, i64)) -> String {
    format!("x{}_y{}", c.0, c.1)
}

fn cell_bounds(c: (i64, i64), size: f64) -> [f64; 4] {
    [c.0 as f64 * size, c.1 as f64 * size, (c.0 + 1) as f64 * size, (c.1 + 1) as f64 * size]
}

/// Reads one CityGML source and lists its building-owning objects.
pub fn sites_of(bytes: &[u8], name: &str, source: usize) -> Result<(Vec<BuildingSite>, usize), TilingError> {
    let stream = ObjectStream::new(bytes).map_err(|e| TilingError::unreadable(name, e))?;
    let (mut sites, mut without_coordinates) = (Vec::new(), 0);
    for o in stream {
        let o = o.map_err(|e| TilingError::unreadable(name, e))?;
        if !owns_building(&o) {
            continue;
        }
        let Some(centroid) = footprint_centroid(&o) else {
            without_coordinates += 1;
            continue;
        };
        let e = &o.envelope;
        let bounds = [e.min[0], e.min[1], e.max[0], e.max[1]];
        if let Some(why) = misplaced(centroid, bounds) {
            let id = o.id.as_deref().unwrap_or("(no gml:id)");
            return Err(TilingError::unreadable(name, format!("building {id}: {why}")));
        }
        sites.push(BuildingSite { id: o.id.clone(), source, centroid, bounds });
    }
    Ok((sites, without_coordinates))
}

/// The widest xy extent a building may have (metres): the largest buildings are a few km long.
/// A wider one holds a misplaced vertex, most often one at 0 0 0 (docs/decisions.md#crashes-and-hangs-of-issue-40).
pub const MAX_BUILDING_SPAN: f64 = 20_000.0;
/// The largest |coordinate| a plan takes (metres; the earth's circumference is 4·10⁷).
pub const MAX_COORDINATE: f64 = 1e9;

/// What is wrong with a building's footprint centroid and xy bounds, if anything: a
/// non-finite or far-off coordinate, or an extent no building has.
fn misplaced(centroid: [f64; 2], b: [f64; 4]) -> Option<String> {
    let far = |v: f64| !(v.abs() <= MAX_COORDINATE);
    if b.iter().chain(&centroid).any(|&v| far(v)) {
        return Some(format!(
            "a coordinate beyond ±{MAX_COORDINATE:e} (x {} … {}, y {} … {}); fix the vertex",
            short(b[0]),
            short(b[2]),
            short(b[1]),
            short(b[3])
        ));
    }
    let (w, h) = (b[2] - b[0], b[3] - b[1]);
    if w > MAX_BUILDING_SPAN || h > MAX_BUILDING_SPAN {
        let zero = if b[0] <= 0.0 && b[1] <= 0.0 { " (one at 0 0 0?)" } else { "" };
        return Some(format!(
            "its coordinates span {} × {} m (x {} … {}, y {} … {}), wider than any building ({MAX_BUILDING_SPAN} m): a misplaced vertex{zero}; fix it",
            short(w),
            short(h),
            short(b[0]),
            short(b[2]),
            short(b[1]),
            short(b[3])
        ));
    }
    None
}

/// A coordinate for a message: `1e308`, not its 309 digits.
fn short(v: f64) -> String {
    if v.is_finite() && v.abs() >= 1e9 {
        format!("{v:e}")
    } else {
        format!("{}", (v * 1000.0).round() / 1000.0)
    }
}

/// A buildings plan and what the plan could not place.
#[derive(Debug, Clone)]
pub struct BuildingPlan {
    pub tiles: Vec<Tile>,
    pub buildings: usize,
    /// Building-owning objects without a single coordinate (no tile: nothing to heal or export).
    pub without_coordinates: usize,
}

/// Plans tiles for the CityGML files `sources` (read one at a time).
pub fn plan(sources: &[String], size: GridSize) -> Result<BuildingPlan, TilingError> {
    let mut sites = Vec::new();
    let mut without_coordinates = 0;
    for (i, s) in sources.iter().enumerate() {
        let bytes = std::fs::read(Path::new(s)).map_err(|e| TilingError::unreadable(s, e))?;
        let (found, none) = sites_of(&bytes, s, i)?;
        sites.extend(found);
        without_coordinates += none;
    }
    let step = match size {
        GridSize::Metres(m) if m > 0.0 && m.is_finite() => m,
        GridSize::Metres(m) => {
            return Err(TilingError::Usage(format!("tile size {m}: must be a positive number of metres")))
        }
        GridSize::BuildingsPerTile(0) => {
            return Err(TilingError::Usage("buildings per tile must be at least 1".into()))
        }
        GridSize::BuildingsPerTile(n) => step_for_budget(&sites, n),
    };
    Ok(BuildingPlan { tiles: tiles_for(&sites, sources, step), buildings: sites.len(), without_coordinates })
}

/// The largest power-of-two step (metres, at least 1 m, from twice the extent down) whose
/// fullest tile has at most `budget` buildings. Buildings closer than 1 m share a tile whatever the budget.
pub fn step_for_budget(sites: &[BuildingSite], budget: usize) -> f64 {
    let span = sites.iter().map(|s| s.centroid).fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, c| {
        [b[0].min(c[0]), b[1].min(c[1]), b[2].max(c[0]), b[3].max(c[1])]
    });
    let extent = (span[2] - span[0]).max(span[3] - span[1]).max(1.0);
    // Cells of step s/2 nest in cells of step s (both aligned at 0), so the fullest tile never
    // grows when halving: the first step that fits is the largest power of two that does.
    let mut step = 2f64.powi(extent.log2().ceil() as i32 + 1);
    while step > 1.0 && fullest(sites, step) > budget {
        step /= 2.0;
    }
    step
}

fn fullest(sites: &[BuildingSite], step: f64) -> usize {
    let mut n: BTreeMap<(i64, i64), usize> = BTreeMap::new();
    for s in sites {
        *n.entry(cell(s.centroid, step)).or_default() += 1;
    }
    n.values().copied().max().unwrap_or(0)
}

/// The non-empty tiles of a grid with step `step`, ordered by (iy, ix).
fn tiles_for(sites: &[BuildingSite], sources: &[String], step: f64) -> Vec<Tile> {
    let mut owned: BTreeMap<(i64, i64), (usize, BTreeSet<usize>)> = BTreeMap::new();
    for s in sites {
        let e = owned.entry(cell(s.centroid, step)).or_default();
        e.0 += 1;
        e.1.insert(s.source);
    }
    // halo: buildings of other tiles whose xy bounds reach into a core. Only the owned cells
    // inside a building's box are visited (rows, then columns, by range): walking every cell of
    // the box never ended for a box of 10³⁰⁸ m (docs/decisions.md#crashes-and-hangs-of-issue-40).
    let mut rows: BTreeMap<i64, BTreeSet<i64>> = BTreeMap::new();
    for &(ix, iy) in owned.keys() {
        rows.entry(iy).or_default().insert(ix);
    }
    let mut halo: BTreeMap<(i64, i64), (Vec<String>, [f64; 4])> = BTreeMap::new();
    for s in sites {
        let home = cell(s.centroid, step);
        let (lo, hi) = (cell([s.bounds[0], s.bounds[1]], step), cell([s.bounds[2], s.bounds[3]], step));
        if lo.0 > hi.0 || lo.1 > hi.1 {
            continue;
        }
        for (&iy, xs) in rows.range(lo.1..=hi.1) {
            for &ix in xs.range(lo.0..=hi.0) {
                if (ix, iy) == home {
                    continue;
                }
                let h = halo.entry((ix, iy)).or_insert_with(|| (Vec::new(), cell_bounds((ix, iy), step)));
                h.0.push(s.id.clone().unwrap_or_else(|| format!("(no gml:id, {})", sources[s.source])));
                h.1 = union(h.1, s.bounds);
            }
        }
    }
    let mut keys: Vec<(i64, i64)> = owned.keys().copied().collect();
    keys.sort_by_key(|c| (c.1, c.0));
    keys.iter()
        .map(|&c| {
            let (work, srcs) = &owned[&c];
            let core = cell_bounds(c, step);
            let (halo_buildings, halo_bounds) = halo.get(&c).cloned().unwrap_or((Vec::new(), core));
            let neighbours = (-1..=1)
                .flat_map(|dy| (-1..=1).map(move |dx| (c.0 + dx, c.1 + dy)))
                .filter(|n| *n != c && owned.contains_key(n))
                .map(cell_id)
                .collect();
            Tile {
                id: cell_id(c),
                kind: TileKind::Buildings,
                size: step,
                core: Window { bounds: core, pixels: None },
                halo: Window { bounds: halo_bounds, pixels: None },
                neighbours,
                work: *work,
                halo_buildings,
                sources: srcs.iter().map(|&i| sources[i].clone()).collect(),
            }
        })
        .collect()
}

fn union(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn site(x: f64, y: f64, half: f64) -> BuildingSite {
        BuildingSite {
            id: Some(format!("b{x}_{y}")),
            source: 0,
            centroid: [x, y],
            bounds: [x - half, y - half, x + half, y + half],
        }
    }

    #[test]
    fn centroid_of_a_unit_square_ring() {
        let sq = [[10.0, 20.0, 0.0], [12.0, 20.0, 0.0], [12.0, 22.0, 0.0], [10.0, 22.0, 0.0], [10.0, 20.0, 0.0]];
        let (a, mx, my) = ring_moments(&sq);
        assert!((a - 4.0).abs() < 1e-12);
        assert!((mx / a - 11.0).abs() < 1e-12 && (my / a - 21.0).abs() < 1e-12);
    }

    #[test]
    fn cells_are_floor_divisions() {
        assert_eq!(cell([-0.5, 3.9], 1.0), (-1, 3));
        assert_eq!(cell_id((-1, 3)), "x-1_y3");
    }

    #[test]
    fn budget_gives_the_largest_step_that_fits() {
        // four buildings in the corners of a 100 m square: budget 1 needs cells < 100 m apart
        let sites: Vec<_> =
            [(0.5, 0.5), (100.5, 0.5), (0.5, 100.5), (100.5, 100.5)].iter().map(|&(x, y)| site(x, y, 0.1)).collect();
        let s = step_for_budget(&sites, 1);
        assert!(fullest(&sites, s) <= 1 && fullest(&sites, s * 2.0) > 1, "step {s}");
        assert_eq!(step_for_budget(&sites, 4), 256.0); // one tile holds all: extent 100 → 2^8
        assert!(fullest(&sites, 256.0) == 4);
    }

    #[test]
    fn every_building_in_one_tile_and_halo_is_read_only_neighbours() {
        // b0 straddles the border x = 10 with its centroid left of it; b1 sits right of it
        let sites = vec![site(9.0, 5.0, 2.0), site(15.0, 5.0, 1.0)];
        let tiles = tiles_for(&sites, &["s.gml".into()], 10.0);
        assert_eq!(tiles.len(), 2);
        assert_eq!(tiles.iter().map(|t| t.work).sum::<usize>(), 2);
        let right = tiles.iter().find(|t| t.id == "x1_y0").unwrap();
        assert_eq!(right.halo_buildings, vec!["b9_5".to_string()]);
        assert_eq!(right.halo.bounds, [7.0, 0.0, 20.0, 10.0]);
        assert_eq!(right.neighbours, vec!["x0_y0".to_string()]);
    }

    /// Issue 40: a building box of 10³⁰⁸ m (or from 0 0 0 to UTM) was walked cell by cell;
    /// now only the owned cells inside it are visited.
    #[test]
    fn a_huge_building_box_takes_no_time() {
        let t0 = std::time::Instant::now();
        let mut sites = vec![site(9.0, 5.0, 2.0), site(15.0, 5.0, 1.0), site(350_000.0, 5_600_000.0, 5.0)];
        sites[2].bounds[0] = 0.0;
        sites[2].bounds[1] = 0.0;
        sites.push(BuildingSite {
            id: Some("far".into()),
            source: 0,
            centroid: [20.0, 20.0],
            bounds: [-1e308, -1e308, 1e308, 1e308],
        });
        let tiles = tiles_for(&sites, &["s.gml".into()], 1.0);
        assert_eq!(tiles.len(), 4);
        assert!(t0.elapsed().as_secs() < 5, "{:?}", t0.elapsed());
        let right = tiles.iter().find(|t| t.id == "x15_y5").unwrap();
        assert_eq!(right.halo_buildings, vec!["b350000_5600000".to_string(), "far".to_string()]);
    }

    #[test]
    fn misplaced_vertices_are_named() {
        assert_eq!(misplaced([5.0, 5.0], [0.0, 0.0, 10.0, 10.0]), None);
        let e = misplaced([350_000.0, 5_600_000.0], [0.0, 0.0, 350_010.0, 5_600_010.0]).unwrap();
        assert!(e.contains("span 350010 × 5600010 m") && e.contains("0 0 0?"), "{e}");
        let e = misplaced([5.0, 5.0], [0.0, 0.0, 1e308, 10.0]).unwrap();
        assert!(e.contains("x 0 … 1e308"), "{e}");
        assert!(misplaced([f64::NAN, 5.0], [0.0, 0.0, 1.0, 1.0]).is_some());
    }
}
