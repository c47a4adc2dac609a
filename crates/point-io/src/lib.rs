//! point-io: geofit's one point reader. Scattered points come as XYZ/CSV text or LAS/LAZ, and
//! text is read in one of two dialects that differ on purpose ([`Dialect`]):
//!
//! - [`terrain`]: soundings and lidar returns, `x y z`, streamed in batches
//!   ([`terrain::XyzBatches`], [`terrain::LasBatches`]) so a consumer that needs each point once
//!   never holds the cloud; a `value` column is the elevation;
//! - [`loop_structural`]: samples of a scalar field for implicit modelling, `x y z [value]
//!   [nx ny nz]` with empty CSV fields meaning "absent" ([`loop_structural::parse_xyz`]).
//!
//! The terrain dialect detects the field separator and the decimal mark ([`text`]: `x;y;z` over
//! `341000,5;5724000,25;12,5` is read with decimal commas) and refuses a text it could read two
//! ways. Both share one field splitter ([`fields`]), one table of column names ([`columns`]), one
//! number rule ([`number`]), one LAS/LAZ reader ([`las::LasPoints`], header claims checked
//! before decoding) and one error type ([`PointsError`], `name:line: message`). No GDAL: a
//! LAS file's GeoTIFF EPSG code is handed out as a number for the caller to resolve.
//!
//! # Examples
//!
//! The same text in both dialects: the terrain reader takes `value` as z, the LoopStructural
//! reader as the scalar field φ (and then needs a z column of its own).
//!
//! ```
//! use point_io::{loop_structural, terrain::XyzBatches};
//!
//! let text = "x,y,value\n1,2,3\n";
//! let batches: Vec<_> = XyzBatches::new(text.as_bytes(), "a.csv").collect::<Result<_, _>>().unwrap();
//! assert_eq!(batches, [vec![[1.0, 2.0, 3.0]]]);
//!
//! let e = loop_structural::parse_xyz(text.as_bytes(), "a.csv").unwrap_err();
//! assert_eq!(e.to_string(), "a.csv:1: header has no `z` column (found: x,y,value)");
//!
//! let samples = loop_structural::parse_xyz(b"x,y,z,value\n1,2,3,\n4,5,6,0.5\n", "b.csv").unwrap();
//! assert_eq!((samples[0].value, samples[1].value), (None, Some(0.5)));
//! assert_eq!(samples[1].line, 3);
//! ```

pub mod columns;
pub mod error;
pub mod fields;
pub mod las;
pub mod loop_structural;
pub mod number;
pub mod terrain;
pub mod text;

use std::path::Path;

pub use columns::Dialect;
pub use error::PointsError;

/// Points a batch holds at most (the `las` crate's read size; 1.5 MiB of coordinates).
pub const BATCH_POINTS: usize = 1 << 16;

/// Point file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointFormat {
    Xyz,
    Las,
}

impl PointFormat {
    /// `.las`/`.laz` → LAS, everything else → XYZ text.
    pub fn from_path(path: &Path) -> PointFormat {
        match path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).as_deref() {
            Some("las") | Some("laz") => PointFormat::Las,
            _ => PointFormat::Xyz,
        }
    }
}
