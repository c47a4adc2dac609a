//! raster-io: the terrain pipeline's file formats. Rasters through GDAL (GeoTIFF, netCDF,
//! ESRI ASCII grid, anything GDAL opens) into one [`Raster`] type (f64 values, NaN = no data,
//! geotransform, CRS WKT), and scattered points from XYZ/CSV text and LAS/LAZ into
//! [`PointCloud`]. Reading and writing only; processing (splatting, TIN, warping) lives in
//! `raster-proc`.
//!
//! # Examples
//!
//! Typical use by the fitting and evaluation code:
//!
//! ```no_run
//! use raster_io::{read_raster, write_raster, MissingCorners, Raster, WriteOptions};
//! let r = read_raster(std::path::Path::new("bathy.nc")).unwrap();
//! // reference value at a cell centre (exact) and at any world point (bilinear, spec §2.1)
//! let (x, y) = r.cell_centre(10, 20);
//! let z = r.sample(x + 0.3, y - 0.2, MissingCorners::Strict);
//! // an evaluated surface on the same grid, masked by the data footprint (spec §2.2)
//! let mut out = Raster::new_empty(r.width, r.height, r.geotransform, r.crs.clone());
//! for row in 0..r.height {
//!     for col in 0..r.width {
//!         if r.is_valid(r.index(col, row)) {
//!             out.set(col, row, -10.0);
//!         }
//!     }
//! }
//! write_raster(&out, std::path::Path::new("surface.tif"), &WriteOptions::default()).unwrap();
//! # let _ = z;
//! ```
//! For the indirect reduction, `raster_proc::warp::WarpField` (serde) is the displacement
//! field; `field.mapper().inverse([x, y])` maps a control point back (spec §2.3.7).

pub mod crs;
pub mod error;
pub mod gdal_io;
pub mod limits;
pub mod point_batches;
pub mod points;
pub mod raster;
pub mod units;

pub use error::{PointsError, RasterError};
pub use gdal_io::{
    bands, check_write, read_raster, read_raster_band, read_raster_band_typed, read_raster_window_typed,
    read_terrain_rgb, read_uncertainty, write_raster, BandInfo, RasterFormat, SampleType, WriteOptions,
};
pub use points::{read_las, read_points, read_xyz, PointCloud, PointFormat};
pub use raster::{GeoTransform, MissingCorners, Raster};
