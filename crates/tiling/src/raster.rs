//! Tile plans for rasters: core windows of about the cells budget, cut along lines of the knot
//! lattice the whole raster's fit would use, the fit window and the halo window of each tile,
//! in pixels (for GDAL windowed reads) and in the raster's CRS.
//!
//! A tile's fit is the whole fit restricted to its window (docs/decisions.md#tiles-on-the-whole-fits-lattice):
//! the whole fit's initial cells are squares of a power-of-two side whose corners sit on pixel
//! centres ([`Lattice`]); a plan cuts its tiles along lines of that lattice, so a tile's domain
//! runs from the pixel-centre column of its west seam to the one of its east seam (shared with
//! the neighbour: its first column), and refinement reaches single pixels with every knot on a
//! pixel centre, whatever the tile size. At the raster's border the domain overhangs the data by
//! at least half a lattice cell, as the whole fit's does.
//!
//! [`plan`] also reads the data: a tile whose core holds no valid cell keeps its line in the plan
//! with `work` 0 (the plan still describes the whole grid its lattice is anchored to) but is no
//! one's neighbour and is left out of the job lists (TSV, make fragment).

use std::path::Path;

use crate::plan::{Tile, TileKind, Window};
use crate::TilingError;

/// Raster tiling options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterTiling {
    /// Side of a core window in pixels; `None`: ⌊√cells_per_tile⌋.
    pub tile_pixels: Option<usize>,
    pub cells_per_tile: usize,
    /// Halo width in pixels on each side (around the fit window).
    pub halo: usize,
}

/// Plans the tiles of the raster at `path` (any GDAL source), reading the data to find the
/// tiles without a valid cell (one core window at a time: memory bounded by a tile).
pub fn plan(path: &str, opts: &RasterTiling) -> Result<Vec<Tile>, TilingError> {
    // libnetcdf sizes allocations by header counts before checking them (input_limits::netcdf)
    input_limits::netcdf::check_file(Path::new(path)).map_err(|e| TilingError::unreadable(path, e))?;
    let ds = gdal::Dataset::open(Path::new(path)).map_err(|e| TilingError::unreadable(path, e))?;
    let (w, h) = ds.raster_size();
    let gt = ds.geo_transform().map_err(|e| TilingError::unreadable(path, format!("no geotransform: {e}")))?;
    if gt[2] != 0.0 || gt[4] != 0.0 {
        // the fit of every tile would refuse it (tspline_raster::Error::Rotated): say so once, here
        return Err(TilingError::unreadable(
            path,
            format!("rotated rasters are not supported (geotransform {gt:?}); gdalwarp it to a north-up grid first"),
        ));
    }
    let mut tiles = plan_grid(path, w, h, gt, opts)?;
    let band = ds.rasterband(1).map_err(|e| TilingError::unreadable(path, e))?;
    let nodata = band.no_data_value();
    for t in &mut tiles {
        let [x, y, cw, ch] = t.core.pixels.expect("raster tiles have pixel windows");
        let buf = band
            .read_as::<f64>((x as isize, y as isize), (cw, ch), (cw, ch), None)
            .map_err(|e| TilingError::unreadable(path, e))?;
        t.work = buf.data().iter().filter(|&&v| is_valid(v, nodata)).count();
    }
    drop_empty_neighbours(&mut tiles);
    Ok(tiles)
}

/// A cell value is data unless NaN or the band's no-data value (compared in f32 too: a
/// Float32 band's no-data read as f64).
fn is_valid(v: f64, nodata: Option<f64>) -> bool {
    !v.is_nan() && nodata.is_none_or(|nd| v != nd && !(v as f32 == nd as f32 && nd.is_finite()))
}

/// Removes the tiles without data (`work` 0) from every neighbour list: their neighbours have no
/// seam there.
pub fn drop_empty_neighbours(tiles: &mut [Tile]) {
    let empty: std::collections::HashSet<String> = tiles.iter().filter(|t| t.work == 0).map(|t| t.id.clone()).collect();
    for t in tiles.iter_mut() {
        if t.work == 0 {
            t.neighbours.clear();
        } else {
            t.neighbours.retain(|n| !empty.contains(n));
        }
    }
}

/// The whole fit's knot lattice in the plan's frame (s = column, t = row counted from the
/// raster's lowest y, whole pixels): lines at `origin + k·cell`. `cell` is the side of a tile
/// fit's initial cells: a power of two, so halving it down to 1 px keeps every knot on a pixel
/// centre.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lattice {
    pub origin: [i64; 2],
    pub cell: i64,
}

/// Initial cells the whole fit puts along the longer side, and its overhang (`tspline::fit`'s
/// `FitOptions::new` defaults; A8).
const WHOLE_INITIAL_CELLS: f64 = 4.0;
const WHOLE_OVERHANG: f64 = 0.25;
/// Largest initial cell of a tile fit (pixels).
const MAX_TILE_CELL: i64 = 32;

impl Lattice {
    /// The lattice of a `w` × `h` raster's whole fit (its initial mesh: cells of side c0, a power
    /// of two, from an integer corner), at the cell a tile of `side` pixels starts from: the
    /// largest power of two ≤ min(32, side/2, c0).
    pub fn of_raster(w: usize, h: usize, side: usize) -> Lattice {
        let (lw, lh) = ((w.max(1) - 1) as f64, (h.max(1) - 1) as f64);
        let ext = lw.max(1.0).max(lh.max(1.0)) * (1.0 + 2.0 * WHOLE_OVERHANG);
        let mut c0 = 1.0f64;
        while c0 * WHOLE_INITIAL_CELLS < ext {
            c0 *= 2.0;
        }
        let place = |len: f64, mut n: usize| -> i64 {
            loop {
                let o = ((len - n as f64 * c0) * 0.5).floor();
                if o < 0.0 && o + n as f64 * c0 > len {
                    return o as i64;
                }
                n += 1;
            }
        };
        let n_for = |len: f64| ((len.max(1.0) * (1.0 + 2.0 * WHOLE_OVERHANG) / c0).ceil() as usize).max(1);
        let (s0, t0) = (place(lw, n_for(lw)), place(lh, n_for(lh)));
        let mut cell = 1i64;
        while cell * 2 <= MAX_TILE_CELL.min((side / 2).max(1) as i64).min(c0 as i64) {
            cell *= 2;
        }
        Lattice { origin: [s0.rem_euclid(cell), t0.rem_euclid(cell)], cell }
    }

    /// The lattice line nearest `x` along axis `a` (ties upwards).
    fn nearest(&self, a: usize, x: i64) -> i64 {
        let (o, c) = (self.origin[a], self.cell);
        o + (x - o + c / 2).div_euclid(c) * c
    }
    /// The greatest lattice line ≤ x.
    fn floor(&self, a: usize, x: i64) -> i64 {
        self.origin[a] + (x - self.origin[a]).div_euclid(self.cell) * self.cell
    }
    /// The least lattice line ≥ x.
    fn ceil(&self, a: usize, x: i64) -> i64 {
        -(Lattice { origin: [-self.origin[0], -self.origin[1]], cell: self.cell }).floor(a, -x)
    }
    /// The overhang of a domain beyond the data at the raster's border: half a cell, ≥ 1 px.
    fn margin(&self) -> i64 {
        (self.cell / 2).max(1)
    }
}

/// Where the tiles of a `len`-pixel axis meet: 0, the lattice lines nearest each multiple of
/// `side`, `len` (strictly increasing).
fn cuts(len: usize, side: usize, lat: &Lattice, axis: usize) -> Vec<usize> {
    let mut v = vec![0usize];
    let mut i = 1;
    while i * side < len {
        let b = lat.nearest(axis, (i * side) as i64);
        if b > *v.last().expect("starts with 0") as i64 && b < len as i64 {
            v.push(b as usize);
        }
        i += 1;
    }
    v.push(len);
    v
}

/// A tile's fit: the pixel window it reads (`col_off, row_off, width, height`) and its initial
/// mesh in the window's own frame (s = 0 at the window's first column centre, t = 0 at its
/// bottom row's): `ns × nt` square cells of side `cell` from (s0, t0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitWindow {
    pub pixels: [usize; 4],
    pub s0: f64,
    pub t0: f64,
    pub cell: f64,
    pub ns: usize,
    pub nt: usize,
}

/// The raster's grid as a plan sees it.
#[derive(Debug, Clone, Copy)]
struct Grid {
    w: usize,
    h: usize,
    north_up: bool,
    lat: Lattice,
}

impl Grid {
    /// Domain ends along one axis for a core `[a, b)` (plan frame) of an axis of `len` pixels:
    /// the seams, or beyond the raster's border by the margin.
    fn ends(&self, axis: usize, a: usize, b: usize, len: usize) -> (i64, i64) {
        let lo = if a == 0 { self.lat.floor(axis, -self.lat.margin()) } else { a as i64 };
        let hi = if b == len { self.lat.ceil(axis, len as i64 - 1 + self.lat.margin()) } else { b as i64 };
        (lo, hi)
    }

    /// The fit window of the core `[col_off, row_off, width, height]`.
    fn fit_window(&self, core: [usize; 4]) -> FitWindow {
        let (sa, sb) = (core[0], core[0] + core[2]);
        // plan t of the core's rows: north-up rasters count t from the bottom row
        let (ta, tb) =
            if self.north_up { (self.h - core[1] - core[3], self.h - core[1]) } else { (core[1], core[1] + core[3]) };
        let (s_lo, s_hi) = self.ends(0, sa, sb, self.w);
        let (t_lo, t_hi) = self.ends(1, ta, tb, self.h);
        let (c0, c1) = (s_lo.max(0) as usize, s_hi.min(self.w as i64 - 1) as usize);
        let (r0, r1) = (t_lo.max(0) as usize, t_hi.min(self.h as i64 - 1) as usize);
        let row_off = if self.north_up { self.h - 1 - r1 } else { r0 };
        let c = self.lat.cell;
        FitWindow {
            pixels: [c0, row_off, c1 - c0 + 1, r1 - r0 + 1],
            s0: (s_lo - c0 as i64) as f64,
            t0: (t_lo - r0 as i64) as f64,
            cell: c as f64,
            ns: ((s_hi - s_lo) / c) as usize,
            nt: ((t_hi - t_lo) / c) as usize,
        }
    }

    /// The grid of a plan's tiles (all of them, empty ones included: they still span the raster).
    fn of_plan(tiles: &[Tile]) -> Result<Grid, TilingError> {
        let px =
            |t: &Tile| t.core.pixels.ok_or_else(|| TilingError::Usage(format!("tile {} is not a raster tile", t.id)));
        let (mut w, mut h, mut side) = (0usize, 0usize, 0usize);
        for t in tiles {
            let p = px(t)?;
            (w, h, side) = (w.max(p[0] + p[2]), h.max(p[1] + p[3]), side.max(t.size as usize));
        }
        // north-up: a tile further down (larger row offset) lies lower in y
        let mut north_up = true;
        if let Some(a) = tiles.first() {
            if let Some(b) = tiles.iter().find(|b| b.core.pixels.map(|p| p[1]) != a.core.pixels.map(|p| p[1])) {
                let (pa, pb) = (px(a)?, px(b)?);
                north_up = (pa[1] < pb[1]) == (a.core.bounds[3] > b.core.bounds[3]);
            }
        }
        Ok(Grid { w, h, north_up, lat: Lattice::of_raster(w, h, side) })
    }
}

/// The fit window of `tile` of the plan `tiles` (docs/decisions.md#tiles-on-the-whole-fits-lattice).
pub fn fit_window(tiles: &[Tile], tile: &Tile) -> Result<FitWindow, TilingError> {
    let core = tile.core.pixels.ok_or_else(|| TilingError::Usage(format!("tile {} is not a raster tile", tile.id)))?;
    Ok(Grid::of_plan(tiles)?.fit_window(core))
}

/// Plans a `w` × `h` raster with geotransform `gt` (GDAL order); every tile's `work` is its
/// core's cell count (no data read).
pub fn plan_grid(path: &str, w: usize, h: usize, gt: [f64; 6], opts: &RasterTiling) -> Result<Vec<Tile>, TilingError> {
    let side = match opts.tile_pixels {
        Some(0) => return Err(TilingError::Usage("tile size must be at least 1 pixel".into())),
        Some(p) => p,
        None if opts.cells_per_tile == 0 => return Err(TilingError::Usage("cells per tile must be at least 1".into())),
        None => ((opts.cells_per_tile as f64).sqrt().floor() as usize).max(1),
    };
    if w == 0 || h == 0 {
        return Err(TilingError::unreadable(path, "the raster has no cells"));
    }
    let grid = Grid { w, h, north_up: gt[5] < 0.0, lat: Lattice::of_raster(w, h, side) };
    let (sx, st) = (cuts(w, side, &grid.lat, 0), cuts(h, side, &grid.lat, 1));
    let (nx, ny) = (sx.len() - 1, st.len() - 1);
    let id = |c: usize, r: usize| format!("c{c}_r{r}");
    let mut tiles = Vec::with_capacity(nx * ny);
    for r in 0..ny {
        // r counts tiles from the raster's first row; j the plan-t index
        let j = if grid.north_up { ny - 1 - r } else { r };
        let (rh, row_off) = (st[j + 1] - st[j], if grid.north_up { h - st[j + 1] } else { st[j] });
        for c in 0..nx {
            let core = [sx[c], row_off, sx[c + 1] - sx[c], rh];
            let f = grid.fit_window(core).pixels;
            let (x0, y0) = (f[0].saturating_sub(opts.halo), f[1].saturating_sub(opts.halo));
            let (x1, y1) = ((f[0] + f[2] + opts.halo).min(w), (f[1] + f[3] + opts.halo).min(h));
            let halo = [x0, y0, x1 - x0, y1 - y0];
            let mut neighbours = Vec::new();
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    let (nc, nr) = (c as i64 + dc, r as i64 + dr);
                    if (dc, dr) != (0, 0) && nc >= 0 && nr >= 0 && (nc as usize) < nx && (nr as usize) < ny {
                        neighbours.push(id(nc as usize, nr as usize));
                    }
                }
            }
            tiles.push(Tile {
                id: id(c, r),
                kind: TileKind::Raster,
                size: side as f64,
                core: Window { bounds: georef(&gt, core), pixels: Some(core) },
                halo: Window { bounds: georef(&gt, halo), pixels: Some(halo) },
                neighbours,
                work: core[2] * core[3],
                halo_buildings: Vec::new(),
                sources: vec![path.to_string()],
            });
        }
    }
    Ok(tiles)
}

/// Where a tile's parameter frame sits in the plan's frame, in whole pixels: (x0, y0) is the
/// world position of the tile's parameter origin (its first cell centre in s, its t = 0 row
/// centre), (dx, dy) the cell size with dy > 0 towards +t. The plan's frame has its origin at
/// the centre of the cell in the lower-left corner of the union of the cores, so every job that
/// places a tile gets the same shift (and shifts by whole pixels are exact in f64).
pub fn frame_offset(tiles: &[Tile], x0: f64, y0: f64, dx: f64, dy: f64) -> [f64; 2] {
    let xmin = tiles.iter().map(|t| t.core.bounds[0]).fold(f64::INFINITY, f64::min);
    let ymin = tiles.iter().map(|t| t.core.bounds[1]).fold(f64::INFINITY, f64::min);
    [((x0 - xmin) / dx - 0.5).round(), ((y0 - ymin) / dy - 0.5).round()]
}

/// xy bounds of a pixel window (outer cell edges), whatever the geotransform's rotation.
fn georef(gt: &[f64; 6], px: [usize; 4]) -> [f64; 4] {
    let at = |c: f64, r: f64| (gt[0] + c * gt[1] + r * gt[2], gt[3] + c * gt[4] + r * gt[5]);
    let (c0, r0, c1, r1) = (px[0] as f64, px[1] as f64, (px[0] + px[2]) as f64, (px[1] + px[3]) as f64);
    let corners = [at(c0, r0), at(c1, r0), at(c0, r1), at(c1, r1)];
    corners.iter().fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, p| {
        [b[0].min(p.0), b[1].min(p.1), b[2].max(p.0), b[3].max(p.1)]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_cover_the_raster_once_and_halos_clip() {
        let gt = [1000.0, 2.0, 0.0, 5000.0, 0.0, -2.0];
        let opts = RasterTiling { tile_pixels: None, cells_per_tile: 100, halo: 3 };
        let tiles = plan_grid("r.tif", 25, 12, gt, &opts).unwrap();
        assert_eq!(tiles.len(), 3 * 2);
        assert_eq!(tiles.iter().map(|t| t.work).sum::<usize>(), 25 * 12);
        let last = tiles.last().unwrap();
        assert_eq!(last.id, "c2_r1");
        assert_eq!(last.neighbours, vec!["c1_r0", "c2_r0", "c1_r1"]);
        assert_eq!(tiles[4].neighbours.len(), 5);
        // the lower-left core cell centre is the plan frame's origin
        let xmin = tiles.iter().map(|t| t.core.bounds[0]).fold(f64::INFINITY, f64::min);
        assert_eq!(frame_offset(&tiles, 1001.0, 4977.0, 2.0, 2.0), [0.0, 0.0]);
        assert_eq!(xmin, 1000.0);
    }

    /// Seams sit on lattice lines (pixel centres of the whole fit's lattice), every core is
    /// covered once, and a fit window ends on the seams' pixel-centre columns, reaching into the
    /// neighbour by exactly its first column, with square cells of one size.
    #[test]
    fn seams_sit_on_the_whole_fits_lattice_for_any_tile_size() {
        for (w, h, side) in [(300usize, 200usize, 100usize), (257, 131, 64), (120, 120, 40), (97, 61, 23)] {
            for north_up in [true, false] {
                let gt = if north_up { [0.0, 1.0, 0.0, h as f64, 0.0, -1.0] } else { [0.0, 1.0, 0.0, 0.0, 0.0, 1.0] };
                let opts = RasterTiling { tile_pixels: Some(side), cells_per_tile: 0, halo: 2 };
                let tiles = plan_grid("r", w, h, gt, &opts).unwrap();
                let lat = Lattice::of_raster(w, h, side);
                assert!(lat.cell <= (side as i64 / 2).max(1) && lat.cell.count_ones() == 1);
                let mut covered = vec![0u8; w * h];
                for t in &tiles {
                    let p = t.core.pixels.unwrap();
                    for r in p[1]..p[1] + p[3] {
                        for c in p[0]..p[0] + p[2] {
                            covered[r * w + c] += 1;
                        }
                    }
                    let f = fit_window(&tiles, t).unwrap();
                    assert!(f.s0 + f.ns as f64 * f.cell >= (f.pixels[2] - 1) as f64);
                    assert!(f.s0 <= 0.0 && f.t0 <= 0.0);
                    // interior seams: the window's first column is the core's, on the lattice
                    if p[0] > 0 {
                        assert_eq!((f.pixels[0], f.s0), (p[0], 0.0));
                        assert_eq!((p[0] as i64 - lat.origin[0]).rem_euclid(lat.cell), 0);
                    }
                    if p[0] + p[2] < w {
                        assert_eq!(
                            f.pixels[0] + f.pixels[2],
                            p[0] + p[2] + 1,
                            "{w} {side}: reaches the neighbour's first column"
                        );
                        assert_eq!(f.s0 + (f.ns as f64) * f.cell, f.pixels[2] as f64 - 1.0);
                    }
                    let h_all = f.pixels[1] + f.pixels[3];
                    assert!(h_all <= h);
                }
                assert!(covered.iter().all(|&c| c == 1), "{w}×{h}/{side}: every cell in one core");
            }
        }
    }

    /// The whole fit's initial mesh of a 120 × 80 raster: c0 = 64, s0 = −40 (A8); the lattice at
    /// 16 px keeps its lines.
    #[test]
    fn lattice_matches_the_whole_fits_initial_mesh() {
        let l = Lattice::of_raster(120, 80, 40);
        assert_eq!(l.cell, 16);
        // whole fit: ext = 119·1.5 = 178.5 → c0 = 64; ns = ⌈178.5/64⌉ = 3 → o = ⌊(119 − 192)/2⌋ = −37
        assert_eq!(l.origin[0], (-37i64).rem_euclid(16));
    }

    #[test]
    fn empty_tiles_are_nobodys_neighbours() {
        let gt = [0.0, 1.0, 0.0, 60.0, 0.0, -1.0];
        let mut tiles =
            plan_grid("r", 90, 60, gt, &RasterTiling { tile_pixels: Some(30), cells_per_tile: 0, halo: 2 }).unwrap();
        tiles[4].work = 0;
        drop_empty_neighbours(&mut tiles);
        assert!(tiles.iter().all(|t| !t.neighbours.contains(&tiles[4].id)));
        assert!(tiles[4].neighbours.is_empty());
    }
}
