//! Typed errors of raster-io. Each message names the file and, for text input, the line.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    /// GDAL could not open or read the file (corrupt, unsupported, missing).
    #[error("{path}: {message}")]
    Open { path: PathBuf, message: String },
    /// A file GDAL opened but that holds nothing usable (no raster band, bad geotransform...).
    #[error("{path}: {message}")]
    Content { path: PathBuf, message: String },
    /// The header claims more cells than the machine can hold (checked before allocating).
    #[error("{path}: the file claims {width}×{height} cells ({size} as f64), more than the limit of {limit}")]
    TooLarge { path: PathBuf, width: usize, height: usize, size: String, limit: String },
    /// An output format, band type or creation option that cannot be written (checked before
    /// the work: a usage error).
    #[error("{0}")]
    Format(String),
    /// Writing failed.
    #[error("{path}: cannot write: {message}")]
    Write { path: PathBuf, message: String },
    /// An in-memory raster that breaks the `Raster` invariants.
    #[error("invalid raster: {0}")]
    Invalid(String),
}

/// Point reading errors are point-io's (one point reader for the workspace, issue 16).
pub use point_io::PointsError;
