//! T-splines on rasters: what lies between a GDAL raster (`raster_io::Raster`, rows from the top,
//! NaN for no data) and a T-spline fit or evaluation (`tspline`, parameters s = column,
//! t = row counted from the bottom, NaN for no data).
//!
//! - [`layout`]: the one place the rows are flipped (docs/decisions.md#A21), both ways.
//! - [`indirect`]: the indirect reduction's scattered points and the mapping of control points
//!   back through the warp field (spec §2.3.7).
//! - [`screening`]: declared no-data values, the per-cell tolerance on the raster and the blunder
//!   screen that runs before a fit (docs/decisions.md#blunders-before-a-fit).
//!
//! # Examples
//!
//! A 2×2 north-up raster becomes samples whose first row is the raster's bottom row:
//!
//! ```
//! use raster_io::Raster;
//! let mut r = Raster::new_empty(2, 2, [100.0, 1.0, 0.0, 202.0, 0.0, -1.0], None);
//! r.data = vec![1.0, 2.0, 3.0, f64::NAN];
//! let layout = tspline_raster::layout::samples_from_raster(r).unwrap();
//! assert_eq!(layout.samples.z.get(0), 3.0);           // bottom-left
//! assert!(layout.samples.z.get(1).is_nan());          // the bottom-right cell has no data
//! assert_eq!([layout.samples.z.get(2), layout.samples.z.get(3)], [1.0, 2.0]); // the top row comes last
//! assert_eq!(layout.georef.world(0.0, 0.0), (100.5, 200.5)); // s, t of the bottom-left centre
//! ```

pub mod indirect;
pub mod layout;
pub mod screening;

/// What goes wrong between a raster and a T-spline.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The parameter layout needs rows and columns along the axes.
    #[error("a rotated or sheared raster (geotransform {0:?}) is not supported: make it north-up first (gdalwarp in.tif out.tif)")]
    Rotated([f64; 6]),
    /// An output grid over the limit ([`layout::MAX_GRID_CELLS`]), named by its size.
    #[error("the output grid {width}×{height} is too large")]
    GridTooLarge { width: usize, height: usize },
}
