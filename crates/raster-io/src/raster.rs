//! The in-memory raster every terrain stage shares: a north-up (or general affine) grid of f64
//! values (NaN = no value), its GDAL geotransform and CRS.
//!
//! Conventions (fixed here once, spec §2.1 and A21):
//! - `data` is row-major, row 0 is the FIRST row GDAL stores (the northern one for the usual
//!   north-up rasters with `geotransform[5] < 0`), column 0 the western one.
//! - The geotransform is GDAL's: the world position of the pixel *corner* (col, row) is
//!   `x = gt[0] + col·gt[1] + row·gt[2]`, `y = gt[3] + col·gt[4] + row·gt[5]`.
//!   A cell's value belongs to its CENTRE, i.e. pixel position (col + ½, row + ½). The thesis'
//!   "cell (i, j) at (x0 + i·dx, y0 + j·dy)" is that centre with x0 = gt\[0\] + ½·gt\[1\].
//! - "Pixel coordinates" (`px`, `py`) in this crate are continuous and centre-based: integer
//!   values hit cell centres, so `(px, py) = (col, row)` is the centre of cell (col, row).
//! - No data is NaN in `data` and nothing else: every value is finite or NaN (±∞ becomes NaN
//!   on the way in), and there is no separate validity mask (docs/decisions.md#nan-is-no-data).
//!   The file's own nodata marker is kept in `nodata` for writing back.

use std::collections::BTreeMap;

use crate::error::RasterError;

/// GDAL's six-number affine geotransform (see the module docs for the convention).
pub type GeoTransform = [f64; 6];

/// A single-band raster of f64 values, NaN where a cell has no value.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Number of columns.
    pub width: usize,
    /// Number of rows.
    pub height: usize,
    /// GDAL geotransform (pixel-corner based).
    pub geotransform: GeoTransform,
    /// Coordinate reference system as WKT (`None` when the file has none).
    pub crs: Option<String>,
    /// Row-major values; NaN = no value. The data footprint of spec §2.2 / §9.1 item 3 is the
    /// set of non-NaN cells (docs/decisions.md#nan-is-no-data).
    pub data: Vec<f64>,
    /// The nodata marker the file used (kept so a write can reuse it); `None` = none declared.
    pub nodata: Option<f64>,
    /// Dataset metadata of the default domain (key → value), e.g. the warp field stored by
    /// `geofit warp`. Written back to formats that keep metadata (GeoTIFF, netCDF).
    pub metadata: BTreeMap<String, String>,
    /// The band's unit type as the file declares it (GDAL's `GetUnitType`: "m", "km",
    /// "US survey foot", ...); `None` when it declares none. Read by `units::resolve_z_unit`,
    /// written back to formats that keep it.
    pub z_unit: Option<String>,
}

/// What [`Raster::sample`] does when a bilinear corner with non-zero weight has no value
/// (spec §2.1 "\[decision\]").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MissingCorners {
    /// Any missing corner with non-zero weight ⇒ no value. The safe default: no value is ever
    /// invented next to a hole or the survey border.
    #[default]
    Strict,
    /// Renormalise the bilinear weights over the corners that have values (no value only when
    /// all weighted corners are missing). Useful for probing close to a ragged footprint.
    Renormalize,
}

impl Raster {
    /// A raster of `width × height` cells, all invalid (NaN).
    pub fn new_empty(width: usize, height: usize, geotransform: GeoTransform, crs: Option<String>) -> Raster {
        let n = width * height;
        Raster {
            width,
            height,
            geotransform,
            crs,
            data: vec![f64::NAN; n],
            nodata: None,
            metadata: BTreeMap::new(),
            z_unit: None,
        }
    }

    /// Builds a raster from values where non-finite values mean "no value"; checks the size
    /// and that the geotransform can be inverted.
    pub fn from_values(
        width: usize,
        height: usize,
        geotransform: GeoTransform,
        crs: Option<String>,
        data: Vec<f64>,
    ) -> Result<Raster, RasterError> {
        if width == 0 || height == 0 {
            return Err(RasterError::Invalid(format!("raster size {width}×{height} has no cells")));
        }
        if data.len() != width * height {
            return Err(RasterError::Invalid(format!(
                "{} values for a {width}×{height} raster ({} expected)",
                data.len(),
                width * height
            )));
        }
        check_geotransform(&geotransform)?;
        let mut r =
            Raster { width, height, geotransform, crs, data, nodata: None, metadata: BTreeMap::new(), z_unit: None };
        for v in r.data.iter_mut() {
            if !v.is_finite() {
                *v = f64::NAN;
            }
        }
        Ok(r)
    }

    /// A north-up raster whose cell (col, row) has its centre at
    /// `(x0 + col·dx, y0 + row·dy)` (the thesis' implicit positions; dy is negative for
    /// north-up rasters that start at the top).
    pub fn geotransform_from_centres(x0: f64, y0: f64, dx: f64, dy: f64) -> GeoTransform {
        [x0 - 0.5 * dx, dx, 0.0, y0 - 0.5 * dy, 0.0, dy]
    }

    #[inline]
    pub fn index(&self, col: usize, row: usize) -> usize {
        row * self.width + col
    }

    /// The value of cell (col, row), `None` when it has none or lies outside.
    #[inline]
    pub fn get(&self, col: usize, row: usize) -> Option<f64> {
        if col >= self.width || row >= self.height {
            return None;
        }
        let v = self.data[self.index(col, row)];
        (!v.is_nan()).then_some(v)
    }

    /// Whether cell `q` (row-major index) has a value.
    #[inline]
    pub fn is_valid(&self, q: usize) -> bool {
        !self.data[q].is_nan()
    }

    /// One flag per cell, true = value present: the footprint as a mask, for callers that
    /// combine footprints (derived from the NaN cells each time; nothing stores it).
    pub fn valid_mask(&self) -> Vec<bool> {
        self.data.iter().map(|v| !v.is_nan()).collect()
    }

    /// Sets cell (col, row); a non-finite value clears it.
    #[inline]
    pub fn set(&mut self, col: usize, row: usize, value: f64) {
        let i = self.index(col, row);
        self.data[i] = if value.is_finite() { value } else { f64::NAN };
    }

    /// Number of cells with a value.
    pub fn valid_count(&self) -> usize {
        self.data.iter().filter(|v| !v.is_nan()).count()
    }

    /// Number of cells without a value.
    pub fn nodata_count(&self) -> usize {
        self.data.len() - self.valid_count()
    }

    /// True when the geotransform has no rotation/shear terms.
    pub fn is_axis_aligned(&self) -> bool {
        self.geotransform[2] == 0.0 && self.geotransform[4] == 0.0
    }

    /// Cell size (|dx|, |dy|) for an axis-aligned raster (the lengths of the pixel edge vectors
    /// in general).
    pub fn cell_size(&self) -> (f64, f64) {
        let gt = &self.geotransform;
        (gt[1].hypot(gt[4]), gt[2].hypot(gt[5]))
    }

    /// World position of the centre of cell (col, row).
    pub fn cell_centre(&self, col: usize, row: usize) -> (f64, f64) {
        self.pixel_to_world(col as f64, row as f64)
    }

    /// World position of centre-based pixel coordinates (see module docs).
    #[inline]
    pub fn pixel_to_world(&self, px: f64, py: f64) -> (f64, f64) {
        let gt = &self.geotransform;
        let c = px + 0.5;
        let r = py + 0.5;
        (gt[0] + c * gt[1] + r * gt[2], gt[3] + c * gt[4] + r * gt[5])
    }

    /// Centre-based pixel coordinates of a world position (inverse of [`Raster::pixel_to_world`]).
    #[inline]
    pub fn world_to_pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let gt = &self.geotransform;
        let det = gt[1] * gt[5] - gt[2] * gt[4];
        let dx = x - gt[0];
        let dy = y - gt[3];
        let c = (gt[5] * dx - gt[2] * dy) / det;
        let r = (-gt[4] * dx + gt[1] * dy) / det;
        (c - 0.5, r - 0.5)
    }

    /// World-space bounding box (min x, min y, max x, max y) of the raster's cell footprint.
    pub fn extent(&self) -> (f64, f64, f64, f64) {
        let corners = [
            self.pixel_to_world(-0.5, -0.5),
            self.pixel_to_world(self.width as f64 - 0.5, -0.5),
            self.pixel_to_world(-0.5, self.height as f64 - 0.5),
            self.pixel_to_world(self.width as f64 - 0.5, self.height as f64 - 0.5),
        ];
        let mut e = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for (x, y) in corners {
            e.0 = e.0.min(x);
            e.1 = e.1.min(y);
            e.2 = e.2.max(x);
            e.3 = e.3.max(y);
        }
        e
    }

    /// Bilinear sample at a world position (spec §2.1 eq. 4.1 in its standard form, A2).
    /// See [`Raster::sample_pixel`] for borders and missing corners.
    #[inline]
    pub fn sample(&self, x: f64, y: f64, missing: MissingCorners) -> Option<f64> {
        let (px, py) = self.world_to_pixel(x, y);
        self.sample_pixel(px, py, missing)
    }

    /// Bilinear sample at centre-based pixel coordinates.
    ///
    /// - Standard weights with i = ⌊px⌋, f = px − i: (1−f)(1−g), f(1−g), (1−f)g, fg (spec A2:
    ///   the printed ⌈s⌉−s form gives 0 at integer positions; this one returns the cell value).
    /// - Borders: a position inside the raster's cell footprint but outside the hull of the
    ///   cell centres (the outer half cell) is clamped to the edge centres, so every point of
    ///   the footprint has a value; outside the footprint there is none (spec A10: no
    ///   clamp-to-edge extrapolation beyond the data).
    /// - Corners with zero weight are never consulted, so an exact cell centre returns that
    ///   cell's value even when its neighbours are missing.
    /// - Missing corners with non-zero weight: see [`MissingCorners`].
    pub fn sample_pixel(&self, px: f64, py: f64, missing: MissingCorners) -> Option<f64> {
        if !(px >= -0.5 && py >= -0.5 && px <= self.width as f64 - 0.5 && py <= self.height as f64 - 0.5) {
            return None; // also rejects NaN
        }
        let px = px.clamp(0.0, (self.width - 1) as f64);
        let py = py.clamp(0.0, (self.height - 1) as f64);
        let i0 = (px.floor() as usize).min(self.width - 1);
        let j0 = (py.floor() as usize).min(self.height - 1);
        let fx = px - i0 as f64;
        let fy = py - j0 as f64;
        let i1 = (i0 + 1).min(self.width - 1);
        let j1 = (j0 + 1).min(self.height - 1);
        let corners = [
            (i0, j0, (1.0 - fx) * (1.0 - fy)),
            (i1, j0, fx * (1.0 - fy)),
            (i0, j1, (1.0 - fx) * fy),
            (i1, j1, fx * fy),
        ];
        let mut sum = 0.0;
        let mut wsum = 0.0;
        for (c, r, w) in corners {
            if w == 0.0 {
                continue;
            }
            let k = r * self.width + c;
            if !self.data[k].is_nan() {
                sum += w * self.data[k];
                wsum += w;
            } else if missing == MissingCorners::Strict {
                return None;
            }
        }
        if wsum > 0.0 {
            Some(sum / wsum)
        } else {
            None
        }
    }

    /// Finite minimum and maximum over the valid cells (`None` when there are none).
    pub fn min_max(&self) -> Option<(f64, f64)> {
        let mut it = self.data.iter().copied().filter(|d| !d.is_nan());
        let first = it.next()?;
        Some(it.fold((first, first), |(lo, hi), v| (lo.min(v), hi.max(v))))
    }

    /// Checks the invariants (size, every value finite or NaN, invertible geotransform).
    pub fn validate(&self) -> Result<(), RasterError> {
        if self.width == 0 || self.height == 0 {
            return Err(RasterError::Invalid(format!("raster size {}×{} has no cells", self.width, self.height)));
        }
        let n = self.width * self.height;
        if self.data.len() != n {
            return Err(RasterError::Invalid(format!(
                "raster {}×{} holds {} values",
                self.width,
                self.height,
                self.data.len()
            )));
        }
        if let Some(i) = self.data.iter().position(|d| d.is_infinite()) {
            return Err(RasterError::Invalid(format!(
                "cell ({}, {}) holds {} (no data is NaN)",
                i % self.width,
                i / self.width,
                self.data[i]
            )));
        }
        check_geotransform(&self.geotransform)
    }
}

/// Rejects geotransforms that cannot map world ↔ pixel (zero or non-finite cell size).
pub fn check_geotransform(gt: &GeoTransform) -> Result<(), RasterError> {
    let det = gt[1] * gt[5] - gt[2] * gt[4];
    if gt.iter().any(|v| !v.is_finite()) || det == 0.0 || !det.is_finite() {
        return Err(RasterError::Invalid(format!("geotransform {gt:?} is not invertible")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r3x2() -> Raster {
        // centres at x = 0,1,2 and y = 10, 9 (north-up, dy = -1)
        let gt = Raster::geotransform_from_centres(0.0, 10.0, 1.0, -1.0);
        Raster::from_values(3, 2, gt, None, vec![1.0, 2.0, 3.0, 4.0, 5.0, f64::NAN]).unwrap()
    }

    #[test]
    fn centres_map_both_ways() {
        let r = r3x2();
        assert_eq!(r.cell_centre(2, 1), (2.0, 9.0));
        let (px, py) = r.world_to_pixel(2.0, 9.0);
        assert!((px - 2.0).abs() < 1e-12 && (py - 1.0).abs() < 1e-12);
        assert_eq!(r.extent(), (-0.5, 8.5, 2.5, 10.5));
    }

    #[test]
    fn bilinear_hand_values() {
        let r = r3x2();
        // integer position returns the cell even though a neighbour is missing (A2)
        assert_eq!(r.sample(1.0, 9.0, MissingCorners::Strict), Some(5.0));
        // midpoint of cells 0,1,3,4: (1+2+4+5)/4 = 3
        assert_eq!(r.sample(0.5, 9.5, MissingCorners::Strict), Some(3.0));
        // f = 0.25 along x on the top row: 1·0.75 + 2·0.25
        assert_eq!(r.sample(0.25, 10.0, MissingCorners::Strict), Some(1.25));
        // touches the missing cell (2,1) ⇒ strict none, renormalised average of 2,3,5
        assert_eq!(r.sample(1.5, 9.5, MissingCorners::Strict), None);
        let v = r.sample(1.5, 9.5, MissingCorners::Renormalize).unwrap();
        assert!((v - (2.0 + 3.0 + 5.0) / 3.0).abs() < 1e-12);
    }

    #[test]
    fn borders_clamp_inside_footprint_only() {
        let r = r3x2();
        assert_eq!(r.sample(-0.5, 10.5, MissingCorners::Strict), Some(1.0));
        assert_eq!(r.sample(-0.51, 10.0, MissingCorners::Strict), None);
        assert_eq!(r.sample(f64::NAN, 10.0, MissingCorners::Strict), None);
    }

    #[test]
    fn one_by_one_raster_samples() {
        let gt = Raster::geotransform_from_centres(5.0, 5.0, 2.0, -2.0);
        let r = Raster::from_values(1, 1, gt, None, vec![7.0]).unwrap();
        assert_eq!(r.sample(5.9, 4.1, MissingCorners::Strict), Some(7.0));
        assert_eq!(r.sample(6.1, 5.0, MissingCorners::Strict), None);
    }

    #[test]
    fn rejects_bad_shapes() {
        let gt = Raster::geotransform_from_centres(0.0, 0.0, 1.0, -1.0);
        assert!(Raster::from_values(0, 3, gt, None, vec![]).is_err());
        assert!(Raster::from_values(2, 2, gt, None, vec![1.0]).is_err());
        assert!(Raster::from_values(1, 1, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0], None, vec![1.0]).is_err());
    }
}
