//! Tile plans for rasters: square core windows of about the cells budget, halo windows grown by
//! a margin and clipped to the raster, both in pixels (for GDAL windowed reads) and in the
//! raster's CRS. Only the size and geotransform are read: a VRT or COG of any size plans in
//! milliseconds.

use std::path::Path;

use crate::plan::{Tile, TileKind, Window};
use crate::TilingError;

/// Raster tiling options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterTiling {
    /// Side of a core window in pixels; `None`: ⌊√cells_per_tile⌋.
    pub tile_pixels: Option<usize>,
    pub cells_per_tile: usize,
    /// Halo width in pixels on each side.
    pub halo: usize,
}

/// Plans the tiles of the raster at `path` (any GDAL source).
pub fn plan(path: &str, opts: &RasterTiling) -> Result<Vec<Tile>, TilingError> {
    // libnetcdf sizes allocations by header counts before checking them (input_limits::netcdf)
    input_limits::netcdf::check_file(Path::new(path)).map_err(|e| TilingError::unreadable(path, e))?;
    let ds = gdal::Dataset::open(Path::new(path)).map_err(|e| TilingError::unreadable(path, e))?;
    let (w, h) = ds.raster_size();
    let gt = ds.geo_transform().map_err(|e| TilingError::unreadable(path, format!("no geotransform: {e}")))?;
    if gt[2] != 0.0 || gt[4] != 0.0 {
        // the fit of every tile would refuse it (tspline_raster::Error::Rotated): say so once, here
        return Err(TilingError::unreadable(path, format!("rotated rasters are not supported (geotransform {gt:?}); gdalwarp it to a north-up grid first")));
    }
    plan_grid(path, w, h, gt, opts)
}

/// Plans a `w` × `h` raster with geotransform `gt` (GDAL order).
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
    let (nx, ny) = (w.div_ceil(side), h.div_ceil(side));
    let id = |c: usize, r: usize| format!("c{c}_r{r}");
    let mut tiles = Vec::with_capacity(nx * ny);
    for r in 0..ny {
        for c in 0..nx {
            let core = [c * side, r * side, side.min(w - c * side), side.min(h - r * side)];
            let (x0, y0) = (core[0].saturating_sub(opts.halo), core[1].saturating_sub(opts.halo));
            let (x1, y1) = ((core[0] + core[2] + opts.halo).min(w), (core[1] + core[3] + opts.halo).min(h));
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

/// The side of the square initial cells of a tile's fit (pixels): the plan's tile side halved
/// until it is at most 32. Every full tile of a plan is then a whole number of such cells, so
/// neighbouring tiles' domains meet exactly along their seams
/// (docs/decisions.md#raster-tiles-and-seams).
pub fn base_cell(tile_side: usize) -> f64 {
    let mut c = tile_side.max(1) as f64;
    while c > 32.0 {
        c /= 2.0;
    }
    c
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
    corners.iter().fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, p| [b[0].min(p.0), b[1].min(p.1), b[2].max(p.0), b[3].max(p.1)])
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
        assert_eq!(last.core.pixels, Some([20, 10, 5, 2]));
        assert_eq!(last.halo.pixels, Some([17, 7, 8, 5]));
        assert_eq!(last.core.bounds, [1040.0, 4976.0, 1050.0, 4980.0]);
        assert_eq!(last.neighbours, vec!["c1_r0", "c2_r0", "c1_r1"]);
        assert_eq!(tiles[4].neighbours.len(), 5);
        // the lower-left core cell centre is the plan frame's origin
        assert_eq!(frame_offset(&tiles, 1001.0, 4977.0, 2.0, 2.0), [0.0, 0.0]);
        assert_eq!(frame_offset(&tiles, 1021.0, 4977.0 + 2.0 * 10.0, 2.0, 2.0), [10.0, 10.0]);
        assert_eq!((base_cell(100), base_cell(32), base_cell(4096)), (25.0, 32.0, 32.0));
    }
}
