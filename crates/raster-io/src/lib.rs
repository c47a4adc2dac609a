//! raster-io: the terrain pipeline's file formats. Rasters through GDAL (GeoTIFF, netCDF,
//! ESRI ASCII grid, anything GDAL opens) into one [`Raster`] type (f64 values, validity mask,
//! geotransform, CRS WKT), and scattered points from XYZ/CSV text and LAS/LAZ into
//! [`PointCloud`]. Reading and writing only; processing (splatting, TIN, warping) lives in
//! `raster-proc`.

pub mod error;
pub mod gdal_io;
pub mod points;
pub mod raster;

pub use error::{PointsError, RasterError};
pub use gdal_io::{read_raster, read_raster_band, write_raster, RasterFormat, WriteOptions};
pub use points::{read_las, read_points, read_xyz, PointCloud, PointFormat};
pub use raster::{GeoTransform, MissingCorners, Raster};
