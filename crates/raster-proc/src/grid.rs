//! Raster grids laid over scattered points.

use raster_io::{GeoTransform, Raster};

use crate::ProcError;

/// The most cells a grid may have (2³¹): beyond that the cell size is surely a mistake.
pub const MAX_CELLS: usize = 1 << 31;

/// What one grid cell costs while points are gridded: the Gauss splat's two f64 sums, the
/// output's f64 value and its validity flag (TIN needs less per cell).
pub const GRID_BYTES_PER_CELL: u64 = 25;

/// A north-up grid: size and GDAL geotransform (corner based, `gt[5] < 0`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    pub width: usize,
    pub height: usize,
    pub geotransform: GeoTransform,
}

impl GridSpec {
    /// The grid whose cell EDGES lie on multiples of `cell` (GDAL's `-tap` convention) and
    /// whose cells contain every point of the bounds: a point on the upper edge gets its own
    /// row/column, so every input point falls inside a cell.
    pub fn covering(bounds: (f64, f64, f64, f64), cell: f64) -> Result<GridSpec, ProcError> {
        let (minx, miny, maxx, maxy) = bounds;
        check_cell(cell)?;
        if ![minx, miny, maxx, maxy].iter().all(|v| v.is_finite()) || minx > maxx || miny > maxy {
            return Err(ProcError::Input(format!("bounds {bounds:?} are not a finite box")));
        }
        let x0 = (minx / cell).floor() * cell;
        let y0 = (miny / cell).floor() * cell;
        let width = ((maxx - x0) / cell).floor() as usize + 1;
        let height = ((maxy - y0) / cell).floor() as usize + 1;
        let top = y0 + height as f64 * cell;
        Self::checked(width, height, [x0, cell, 0.0, top, 0.0, -cell])
    }

    /// Fails with [`ProcError::TooLarge`] when the grid has more cells than [`MAX_CELLS`] or
    /// than the memory available holds ([`raster_io::limits::CellBudget`], at
    /// [`GRID_BYTES_PER_CELL`] a cell) — to be called before allocating for it.
    pub fn check_budget(&self) -> Result<(), ProcError> {
        let mut budget = raster_io::limits::CellBudget::for_cost(GRID_BYTES_PER_CELL);
        if budget.max_cells > MAX_CELLS as u64 {
            budget = raster_io::limits::CellBudget {
                max_cells: MAX_CELLS as u64,
                source: raster_io::limits::BudgetSource::Fallback,
            };
        }
        if budget.allows(self.width, self.height) {
            return Ok(());
        }
        let cells = self.width as f64 * self.height as f64;
        let cell = self.geotransform[1].abs();
        // the side grows with the square root of the cell count; 2 significant digits, up
        let need = cell * (cells / budget.max_cells.max(1) as f64).sqrt() * 1.01;
        let mag = 10f64.powf(need.log10().floor() - 1.0);
        let min_cell = (need / mag).ceil() * mag;
        let min_cell = format!("{min_cell:.6}").trim_end_matches('0').trim_end_matches('.').parse().unwrap_or(min_cell);
        Err(ProcError::TooLarge {
            width: self.width,
            height: self.height,
            size: raster_io::limits::gib((cells * 8.0).min(u64::MAX as f64) as u64),
            limit: budget.describe(),
            min_cell,
        })
    }

    /// The grid with exactly these outer EDGES (like `gdal_grid -txe xmin xmax -tye ymin ymax`);
    /// the extent must be a whole number of cells (to 1e-9 relative).
    pub fn from_edges(xmin: f64, ymin: f64, xmax: f64, ymax: f64, cell: f64) -> Result<GridSpec, ProcError> {
        check_cell(cell)?;
        if !(xmax > xmin && ymax > ymin) {
            return Err(ProcError::Input(format!(
                "bounds {xmin} {ymin} {xmax} {ymax}: need xmin < xmax and ymin < ymax"
            )));
        }
        let w = (xmax - xmin) / cell;
        let h = (ymax - ymin) / cell;
        let (wr, hr) = (w.round(), h.round());
        if (w - wr).abs() > 1e-9 * w.max(1.0) || (h - hr).abs() > 1e-9 * h.max(1.0) {
            return Err(ProcError::Input(format!(
                "bounds {xmin} {ymin} {xmax} {ymax} are not a whole number of {cell} cells ({w} × {h})"
            )));
        }
        Self::checked(wr as usize, hr as usize, [xmin, cell, 0.0, ymax, 0.0, -cell])
    }

    fn checked(width: usize, height: usize, geotransform: GeoTransform) -> Result<GridSpec, ProcError> {
        if width == 0 || height == 0 {
            return Err(ProcError::Input("grid has no cells".into()));
        }
        let g = GridSpec { width, height, geotransform };
        g.check_budget()?;
        Ok(g)
    }

    /// An empty raster on this grid.
    pub fn empty_raster(&self, crs: Option<String>) -> Raster {
        Raster::new_empty(self.width, self.height, self.geotransform, crs)
    }

    /// Centre-based pixel coordinates of a world point (see `raster_io::raster`).
    #[inline]
    pub fn world_to_pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let gt = &self.geotransform;
        ((x - gt[0]) / gt[1] - 0.5, (y - gt[3]) / gt[5] - 0.5)
    }

    /// World position of the centre of cell (col, row).
    #[inline]
    pub fn cell_centre(&self, col: usize, row: usize) -> (f64, f64) {
        let gt = &self.geotransform;
        (gt[0] + (col as f64 + 0.5) * gt[1], gt[3] + (row as f64 + 0.5) * gt[5])
    }
}

fn check_cell(cell: f64) -> Result<(), ProcError> {
    if !(cell.is_finite() && cell > 0.0) {
        return Err(ProcError::Input(format!("cell size {cell} must be a positive number")));
    }
    Ok(())
}

/// How sure the degree heuristic is that the points are in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Degrees {
    /// The points' CRS is geographic.
    Declared,
    /// No CRS is declared and every point lies within longitude/latitude bounds.
    Guessed,
}

impl GridSpec {
    /// A cell size that is almost certainly metres on points in degrees: geographic coordinates
    /// (`geographic`: the declared CRS's kind, `None` = no CRS, then guessed from the bounds:
    /// every x in −180…360, y in −90…90), a cell of 1 or more (any size where the CRS or a
    /// lon/lat header says degrees), and a grid of fewer than 10 cells
    /// across with 10 or more points per cell (7000 lon/lat soundings at `--cell 25` made a 1×2
    /// grid). docs/decisions.md#raster-outputs-by-driver
    ///
    /// # Examples
    ///
    /// ```
    /// use raster_proc::grid::{Degrees, GridSpec};
    /// let bounds = (5.0, 52.0, 5.01, 52.01);
    /// let grid = GridSpec::covering(bounds, 25.0).unwrap();
    /// assert_eq!(grid.cell_in_metres_on_degrees(bounds, 7000, None, 25.0), Some(Degrees::Guessed));
    /// assert_eq!(grid.cell_in_metres_on_degrees(bounds, 7000, Some(false), 25.0), None);
    /// ```
    pub fn cell_in_metres_on_degrees(
        &self,
        bounds: (f64, f64, f64, f64),
        points: usize,
        geographic: Option<bool>,
        cell: f64,
    ) -> Option<Degrees> {
        let (x0, y0, x1, y1) = bounds;
        let degrees = geographic.unwrap_or(x0 >= -180.0 && x1 <= 360.0 && y0 >= -90.0 && y1 <= 90.0);
        let (w, h) = (self.width as f64, self.height as f64);
        // declared degrees: any cell size (0.5 meant as metres on 0.01° of soundings is 1×1)
        let metre_sized = cell >= 1.0 || geographic == Some(true);
        if !(degrees && metre_sized && w.max(h) < 10.0 && points as f64 >= 10.0 * w * h) {
            return None;
        }
        Some(if geographic == Some(true) { Degrees::Declared } else { Degrees::Guessed })
    }
}

impl Degrees {
    /// The one-line refusal of `--cell` on points in degrees: what says they are degrees (a
    /// declared CRS, or else a lon/lat header when `lonlat_header`), the grid it would make,
    /// and the fix, with the UTM zone of the points' centre as `--t-srs` (and `--s-srs
    /// EPSG:4326` where no CRS was declared).
    #[allow(clippy::too_many_arguments)]
    pub fn refusal(
        self,
        input: &str,
        cell: f64,
        bounds: (f64, f64, f64, f64),
        grid: &GridSpec,
        points: usize,
        crs_declared: bool,
        lonlat_header: bool,
    ) -> String {
        let (x0, y0, x1, y1) = bounds;
        let what = match self {
            Degrees::Declared if !crs_declared && lonlat_header => {
                "the header names longitude/latitude columns (degrees)"
            }
            Degrees::Declared => "the points are in a geographic CRS (degrees)",
            Degrees::Guessed => "the points declare no CRS and lie within longitude/latitude bounds",
        };
        let epsg = utm_epsg((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        format!(
            "--cell {cell} on {input}: {what} (x {x0}…{x1}, y {y0}…{y1}), and a cell of {cell} makes a grid of only {w}×{h} \
             cells for {points} points. --cell is in the points' units: in degrees, ≈ {deg:.6} is {cell} m at the equator; \
             to grid in metres, reproject with {s}--t-srs EPSG:{epsg} (UTM zone {z}{ns}, where they lie){hint}",
            w = grid.width as f64,
            h = grid.height as f64,
            deg = cell / 111_320.0,
            s = if crs_declared { "" } else { "--s-srs EPSG:4326 " },
            z = epsg % 100,
            ns = if epsg < 32700 { 'N' } else { 'S' },
            hint = if self == Degrees::Guessed { "; if they are not degrees, declare their CRS with --s-srs" } else { "" },
        )
    }
}

/// The WGS 84 / UTM zone (EPSG code) of a longitude and latitude in degrees (longitudes
/// 180…360 read as −180…0): what to suggest as `--t-srs` for soundings in degrees.
///
/// ```
/// assert_eq!(raster_proc::grid::utm_epsg(7.1, 51.4), 32632); // Bochum, zone 32N
/// assert_eq!(raster_proc::grid::utm_epsg(326.1, -8.7), 32725); // 33.9° W, zone 25S
/// ```
pub fn utm_epsg(lon: f64, lat: f64) -> u32 {
    let lon = if lon >= 180.0 { lon - 360.0 } else { lon };
    let zone = (((lon + 180.0) / 6.0).floor() as i64).clamp(0, 59) as u32 + 1;
    if lat >= 0.0 {
        32600 + zone
    } else {
        32700 + zone
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covering_contains_every_point() {
        let g = GridSpec::covering((0.3, 6.1, 6.3, 6.2), 0.5).unwrap();
        assert_eq!(g.geotransform[0], 0.0);
        assert_eq!(g.width, 13); // 0.0 .. 6.5
        assert_eq!(g.height, 1); // 6.0 .. 6.5
        let (px, py) = g.world_to_pixel(6.3, 6.1);
        assert!(px.round() as usize == 12 && py.round() as usize == 0);
        assert!(GridSpec::covering((0.0, 0.0, 1.0, 1.0), 0.0).is_err());
        assert!(GridSpec::covering((0.0, 0.0, 1e9, 1e9), 1e-3).is_err());
    }

    #[test]
    fn metre_cells_on_declared_degrees_are_refused_at_any_size() {
        let bounds = (7.0, 52.0, 7.01, 52.01);
        let g = GridSpec::covering(bounds, 0.5).unwrap();
        assert_eq!(g.cell_in_metres_on_degrees(bounds, 100, Some(true), 0.5), Some(Degrees::Declared));
        assert_eq!(g.cell_in_metres_on_degrees(bounds, 100, None, 0.5), None, "a guess needs a cell of 1 or more");
        let m = Degrees::Declared.refusal("s.csv", 0.5, bounds, &g, 100, false, true);
        assert!(
            m.contains("header names longitude/latitude")
                && m.contains("--s-srs EPSG:4326 --t-srs EPSG:32632 (UTM zone 32N"),
            "{m}"
        );
    }

    #[test]
    fn from_edges_needs_whole_cells() {
        let g = GridSpec::from_edges(0.0, 0.0, 6.5, 6.5, 0.25).unwrap();
        assert_eq!((g.width, g.height), (26, 26));
        assert_eq!(g.cell_centre(0, 0), (0.125, 6.375));
        assert!(GridSpec::from_edges(0.0, 0.0, 6.4, 6.5, 0.25).is_err());
    }
}
