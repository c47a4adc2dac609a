//! raster-proc: raster processing beside `raster-io` (which only reads and writes).
//!
//! - [`grid`]: raster grids that cover a point set at a given cell size.
//! - [`splat`]: Gauss splatting of scattered values into a grid (spec §2.3.4, A5).
//! - [`tin`]: TIN-linear rasterization (spade Delaunay, barycentric).
//! - [`dilate`]: dilation fill of unknown cells (spec §2.3.5, Alg. 2, A6).
//! - [`point_input`]: point files for rasterization (text separator and decimal mark given or
//!   detected, what the text was read as).
//! - [`pca`]: principal-axis rotation (spec §2.3.1, A3).
//! - [`warp`]: landmark warp field, forward/inverse mapping, raster warping (spec §2.3.2–2.3.3, A4).
//! - [`diff`]: raster-vs-raster error statistics, histograms and error-class maps (spec §4.2, A17).
//! - [`diff_figures`]: the comparison's map with legend and its histogram chart.
//!
//! # Examples
//!
//! Points on a plane splatted onto a 1 m grid that covers them; every cell near a point gets a
//! value on the plane (a weighted mean of points on a plane stays on it where they surround the
//! cell), cells far from every point stay no data:
//!
//! ```
//! use raster_io::PointCloud;
//! use raster_proc::grid::GridSpec;
//! use raster_proc::splat::{splat_points, SplatKernel};
//! let plane = |x: f64, y: f64| 2.0 * x - y + 5.0;
//! let mut points = Vec::new();
//! for i in 0..=40 {
//!     for j in 0..=40 {
//!         let (x, y) = (i as f64 * 0.25, j as f64 * 0.25);
//!         if x < 6.0 || y < 6.0 { points.push([x, y, plane(x, y)]); } // an empty 4×4 m corner
//!     }
//! }
//! let cloud = PointCloud { points, crs: None };
//! let grid = GridSpec::covering((0.0, 0.0, 10.0, 10.0), 1.0).unwrap();
//! let r = splat_points(&cloud, &grid, SplatKernel::Gauss { sigma: 0.5, radius: 1.0 }, None).unwrap();
//! let (x, y) = r.cell_centre(2, 7); // inside the points
//! assert!((r.get(2, 7).unwrap() - plane(x, y)).abs() < 1e-9);
//! let far = (0..r.width).find(|&c| r.cell_centre(c, 0).0 > 8.0).unwrap();
//! assert_eq!(r.get(far, 0), None); // the empty corner, top right of a north-up grid
//! ```

pub mod diff;
pub mod diff_figures;
pub mod dilate;
pub mod grid;
pub mod pca;
pub mod point_input;
pub mod splat;
pub mod tin;
pub mod warp;

/// Errors of the processing steps.
#[derive(Debug, thiserror::Error)]
pub enum ProcError {
    /// Inputs that cannot produce a result (no points, all-nodata raster, degenerate grid).
    #[error("{0}")]
    Input(String),
    /// A grid with more cells than the machine can hold (checked before allocating it).
    #[error("grid of {width} × {height} cells ({size} as f64) is too large: more than the limit of {limit}; a cell size of {min_cell} or more fits")]
    TooLarge { width: usize, height: usize, size: String, limit: String, min_cell: f64 },
    /// More points than a TIN of them fits in memory (checked before triangulating).
    #[error("a TIN of {points} points needs about {size} ({bytes_per_point} bytes a point), more than the limit of {limit}; --method gauss streams the points in constant memory")]
    TinTooLarge { points: usize, size: String, bytes_per_point: u64, limit: String },
    /// The warp field folds over (crossing displacement vectors).
    #[error("warp field folds over: {0}")]
    FoldOver(String),
    /// A stored warp field that cannot be decoded.
    #[error("warp field: {0}")]
    Field(String),
    #[error(transparent)]
    Raster(#[from] raster_io::RasterError),
}
