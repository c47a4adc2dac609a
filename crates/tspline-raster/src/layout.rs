//! The raster ↔ parameter layout (docs/decisions.md#A21): s = column, t = row counted from the
//! bottom, so a north-up raster's top row is the samples' last; the affine map between (s, t)
//! and world coordinates travels in the [`Georef`]. Every row flip of the terrain pipeline is in
//! this module: into the fit ([`samples_from_raster`]) and out of it ([`EvalGrid`]).
//!
//! # Examples
//!
//! The grid a fitted mesh is evaluated on by default is its own raster's, north-up again:
//!
//! ```
//! use raster_io::Raster;
//! use tspline_raster::layout::{samples_from_raster, EvalGrid};
//! use tspline::format::DataMask;
//! let mut r = Raster::new_empty(3, 2, [0.0, 2.0, 0.0, 4.0, 0.0, -2.0], Some("EPSG:25832".into()));
//! r.data = vec![1.0, f64::NAN, 3.0, 4.0, 5.0, 6.0];
//! let l = samples_from_raster(r.clone()).unwrap();
//! let grid = EvalGrid::of_mask(&l.georef, &DataMask::of_samples(&l.samples));
//! assert_eq!(grid.raster.geotransform, r.geotransform);
//! assert_eq!(grid.mask.unwrap().to_rows(), r.valid_mask()); // the stored mask, back in the raster's row order
//! ```

use raster_io::Raster;
use tspline::fit::{Heights, Samples};
use tspline::format::{DataMask, Georef};
use tspline::GridSpec;

use crate::Error;

/// A raster in the fit's layout: heights (NaN = no data; the `.tmesh`'s data mask is made from
/// them when the file is written, [`DataMask::of_samples`]) and the map back to world
/// coordinates.
pub struct Layout {
    pub samples: Samples,
    pub georef: Georef,
}

/// `r` in the parameter layout. Needs an axis-aligned raster. Takes the raster so that its
/// values become the samples in place: the rows are flipped inside the one array, which is
/// then kept as f32 when every height is an f32 (a float32 raster: 4 bytes a cell;
/// docs/decisions.md#float32-samples). Peak: the f64 values plus, while converting, the f32 copy.
pub fn samples_from_raster(r: Raster) -> Result<Layout, Error> {
    let gt = r.geotransform;
    if gt[2] != 0.0 || gt[4] != 0.0 {
        return Err(Error::Rotated(gt));
    }
    let (w, h) = (r.width, r.height);
    let north_up = gt[5] < 0.0;
    let x0 = gt[0] + 0.5 * gt[1];
    let (y0, dy) = if north_up { (gt[3] + (h as f64 - 0.5) * gt[5], -gt[5]) } else { (gt[3] + 0.5 * gt[5], gt[5]) };
    let georef = Georef { x0, y0, dx: gt[1], dy, crs: r.crs.unwrap_or_default() };
    let mut z = r.data;
    if north_up {
        flip_rows(&mut z, w);
    }
    Ok(Layout { samples: Samples { width: w, height: h, z: Heights::compact(z) }, georef })
}

/// Reverses the order of the rows of `z` (`w` values each) in place.
fn flip_rows(z: &mut [f64], w: usize) {
    let h = z.len() / w.max(1);
    for row in 0..h / 2 {
        let (top, bottom) = z.split_at_mut((h - 1 - row) * w);
        top[row * w..(row + 1) * w].swap_with_slice(&mut bottom[..w]);
    }
}

/// Where each output cell lies in the parameter domain: one (s, t) per cell, or a regular grid
/// (row-major, evaluated separably without a per-cell list).
pub enum Params {
    List(Vec<[f64; 2]>),
    Grid(GridSpec),
}

impl Params {
    /// Every (s, t), row-major (a grid expanded).
    pub fn list(&self) -> std::borrow::Cow<'_, [[f64; 2]]> {
        match self {
            Params::List(v) => std::borrow::Cow::Borrowed(v),
            Params::Grid(g) => {
                (0..g.ns * g.nt).map(|q| [g.s0 + (q % g.ns) as f64 * g.ds, g.t0 + (q / g.ns) as f64 * g.dt]).collect()
            }
        }
    }
}

/// An output raster (all cells no data yet), the parameters of its cells and the cells a stored
/// data mask keeps (`None`: all).
pub struct EvalGrid {
    pub raster: Raster,
    pub params: Params,
    pub mask: Option<Footprint>,
}

/// The cells a stored mask keeps, read in place: the `.tmesh` data mask counts rows from the
/// bottom (the fit's layout), the warp's footprint from the top (its raster's). One mask type,
/// [`DataMask`], for both; no row-flipped copy (docs/decisions.md#nan-is-no-data).
#[derive(Debug, Clone, PartialEq)]
pub struct Footprint {
    pub mask: DataMask,
    pub rows_from_bottom: bool,
}

impl Footprint {
    /// Whether output cell `q` (row-major, north-up) is inside the footprint.
    pub fn keeps(&self, q: usize) -> bool {
        let w = self.mask.width;
        let (col, row) = (q % w, q / w);
        let j = if self.rows_from_bottom { self.mask.height - 1 - row } else { row };
        self.mask.get(col, j)
    }
    /// Every cell's [`Footprint::keeps`], north-up row-major (for tests and reports).
    pub fn to_rows(&self) -> Vec<bool> {
        (0..self.mask.width * self.mask.height).map(|q| self.keeps(q)).collect()
    }
}

/// Outputs larger than this many cells are refused: they would not be written anyway.
pub const MAX_GRID_CELLS: usize = 2_000_000_000;

impl EvalGrid {
    /// The grid of `like` (size, geotransform, its CRS or else `crs`), each cell centre mapped
    /// through `to_param` (world → (s, t); the warp's forward map for indirect meshes).
    pub fn like(
        like: &Raster,
        crs: Option<String>,
        to_param: impl Fn(f64, f64) -> (f64, f64),
    ) -> Result<EvalGrid, Error> {
        let gt = like.geotransform;
        if gt[2] != 0.0 || gt[4] != 0.0 {
            return Err(Error::Rotated(gt));
        }
        let raster = Raster::new_empty(like.width, like.height, gt, like.crs.clone().or(crs));
        let params = Params::List(cell_params(&raster, to_param));
        Ok(EvalGrid { raster, params, mask: None })
    }

    /// The original raster of an indirect fit (stored with the warp field) and its footprint,
    /// each cell centre mapped through `to_param` (the warp's forward map, then the georeference).
    pub fn of_warp_source(
        src: &raster_proc::warp::SourceGrid,
        crs: Option<String>,
        to_param: impl Fn(f64, f64) -> (f64, f64),
    ) -> Result<EvalGrid, raster_proc::ProcError> {
        let raster = Raster::new_empty(src.width, src.height, src.geotransform, src.crs.clone().or(crs));
        let params = Params::List(cell_params(&raster, to_param));
        let mask = DataMask { width: src.width, height: src.height, bits: src.mask()? };
        Ok(EvalGrid { raster, params, mask: Some(Footprint { mask, rows_from_bottom: false }) })
    }

    /// The raster a mesh was fitted on, north-up, with its stored data mask.
    pub fn of_mask(georef: &Georef, mask: &DataMask) -> EvalGrid {
        let mut grid = EvalGrid::regular(georef, mask.width, mask.height, 0.0, 0.0);
        grid.mask = Some(Footprint { mask: mask.clone(), rows_from_bottom: true });
        grid
    }

    /// The integer (s, t) of a mesh domain `[s_min, s_max] × [t_min, t_max]` at the parameter
    /// spacing, north-up; an error naming the size when it would exceed [`MAX_GRID_CELLS`].
    pub fn of_domain(georef: &Georef, s_min: f64, s_max: f64, t_min: f64, t_max: f64) -> Result<EvalGrid, Error> {
        let (s0, t0) = (s_min.ceil(), t_min.ceil());
        let w = (s_max.floor() - s0) as usize + 1;
        let h = (t_max.floor() - t0) as usize + 1;
        if w.saturating_mul(h) > MAX_GRID_CELLS {
            return Err(Error::GridTooLarge { width: w, height: h });
        }
        Ok(EvalGrid::regular(georef, w, h, s0, t0))
    }

    /// A north-up `w × h` grid whose bottom-left cell is (s0, t0): row r holds t = t0 + h − 1 − r.
    fn regular(georef: &Georef, w: usize, h: usize, s0: f64, t0: f64) -> EvalGrid {
        let top = t0 + (h as f64 - 1.0);
        let (x0, ytop) = georef.world(s0, top);
        let gt = Raster::geotransform_from_centres(x0, ytop, georef.dx, -georef.dy);
        let crs = (!georef.crs.is_empty()).then(|| georef.crs.clone());
        let params = Params::Grid(GridSpec { s0, t0: top, ds: 1.0, dt: -1.0, ns: w, nt: h });
        EvalGrid { raster: Raster::new_empty(w, h, gt, crs), params, mask: None }
    }

    /// Stores the evaluated heights `z` (row-major, NaN outside the mesh) in the raster, keeping
    /// a cell where it is finite, the stored mask keeps it (unless `ignore_mask`) and `extra`
    /// (another raster of the same size) has a value there.
    pub fn fill(mut self, z: Vec<f64>, ignore_mask: bool, extra: Option<&Raster>) -> Raster {
        let stored = if ignore_mask { None } else { self.mask.as_ref() };
        for (q, v) in z.into_iter().enumerate() {
            if v.is_finite() && stored.is_none_or(|m| m.keeps(q)) && extra.is_none_or(|m| m.is_valid(q)) {
                self.raster.data[q] = v;
            }
        }
        self.raster
    }
}

/// (s, t) of every cell centre of `r`, row-major.
fn cell_params(r: &Raster, to_param: impl Fn(f64, f64) -> (f64, f64)) -> Vec<[f64; 2]> {
    let mut st = Vec::with_capacity(r.width * r.height);
    for row in 0..r.height {
        for col in 0..r.width {
            let (x, y) = r.cell_centre(col, row);
            let (s, t) = to_param(x, y);
            st.push([s, t]);
        }
    }
    st
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raster(north_up: bool) -> Raster {
        let gt = if north_up { [10.0, 1.0, 0.0, 20.0, 0.0, -1.0] } else { [10.0, 1.0, 0.0, 17.0, 0.0, 1.0] };
        let mut r = Raster::new_empty(2, 3, gt, None);
        r.data = (0..6).map(f64::from).collect();
        r.data[2] = f64::NAN;
        r
    }

    #[test]
    fn a_domain_grid_over_the_limit_is_named_by_its_size() {
        let g = Georef::identity();
        let e = EvalGrid::of_domain(&g, 0.0, 99_999.0, 0.0, 99_999.0).err().expect("10¹⁰ cells refused");
        assert_eq!(e.to_string(), "the output grid 100000×100000 is too large");
        let ok = EvalGrid::of_domain(&g, -0.5, 3.5, -0.5, 2.5).unwrap();
        assert_eq!((ok.raster.width, ok.raster.height), (4, 3));
    }

    #[test]
    fn every_valid_cell_keeps_its_value_at_its_world_position() {
        for north_up in [true, false] {
            let r = raster(north_up);
            let l = samples_from_raster(r.clone()).unwrap();
            for row in 0..3 {
                for col in 0..2 {
                    let (x, y) = r.cell_centre(col, row);
                    let (s, t) = l.georef.param(x, y);
                    let q = t.round() as usize * 2 + s.round() as usize;
                    assert!((s - s.round()).abs() < 1e-12 && (t - t.round()).abs() < 1e-12);
                    match r.get(col, row) {
                        Some(v) => assert_eq!(l.samples.z.get(q), v),
                        None => assert!(l.samples.z.get(q).is_nan() && !DataMask::of_samples(&l.samples).bits[q]),
                    }
                }
            }
        }
    }

    /// Heights that are all f32 values are stored as f32, any other as f64, the same numbers.
    #[test]
    fn float32_heights_are_kept_in_four_bytes() {
        let r = raster(true);
        assert_eq!(samples_from_raster(r.clone()).unwrap().samples.z.bytes_per_cell(), 4);
        let mut fine = r.clone();
        fine.data[0] = 0.1; // not an f32
        let l = samples_from_raster(fine).unwrap();
        assert_eq!(l.samples.z.bytes_per_cell(), 8);
        assert_eq!(l.samples.get(0, 2), 0.1);
    }

    #[test]
    fn a_rotated_raster_is_refused() {
        let mut r = raster(true);
        r.geotransform[2] = 0.1;
        assert!(matches!(samples_from_raster(r), Err(Error::Rotated(_))));
    }

    #[test]
    fn the_default_grid_returns_the_fitted_rasters_cells_and_mask() {
        let r = raster(true);
        let l = samples_from_raster(r.clone()).unwrap();
        let g = EvalGrid::of_mask(&l.georef, &DataMask::of_samples(&l.samples));
        assert_eq!(g.raster.geotransform, r.geotransform);
        assert_eq!(g.mask.map(|m| m.to_rows()), Some(r.valid_mask()));
        // every output cell's (s, t) is the parameter of its world centre
        for (q, st) in g.params.list().iter().enumerate() {
            let (x, y) = g.raster.cell_centre(q % 2, q / 2);
            assert_eq!(l.georef.param(x, y), (st[0], st[1]));
        }
    }

    #[test]
    fn fill_keeps_finite_values_inside_both_masks() {
        let r = raster(true);
        let l = samples_from_raster(r.clone()).unwrap();
        let g = EvalGrid::of_mask(&l.georef, &DataMask::of_samples(&l.samples));
        let mut extra = r.clone();
        extra.data = vec![0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0];
        let out = g.fill(vec![1.0, 2.0, 3.0, f64::NAN, 5.0, 6.0], false, Some(&extra));
        assert_eq!(out.valid_mask(), vec![true, false, false, false, true, true]);
        assert_eq!(out.data[0], 1.0);
    }
}
