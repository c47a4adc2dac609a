//! Points of a file in batches, so that a consumer that needs each point once (Gauss splatting,
//! bounds) holds one batch, not the cloud: 24 bytes a point held whole is 1.2 GB for 5·10⁷
//! lidar returns (docs/decisions.md#streaming-points).
//!
//! [`PointBatches::open`] reads LAS/LAZ by the `las` crate's chunks and XYZ/CSV text by lines,
//! with point-io's terrain dialect (`point_io::terrain`); every batch is `Ok(points)` in file
//! order, an unreadable point ends the stream with one `Err` naming it, and a file without a
//! point (or without one of the wanted class) ends it with `PointsError::Empty`.
//!
//! # Examples
//!
//! ```
//! use raster_io::point_batches::{BoundsXy, PointBatches};
//!
//! let path = std::env::temp_dir().join(format!("batches-doctest-{}.xyz", std::process::id()));
//! std::fs::write(&path, "x,y,z\n1,2,3\n4,0,6\n").unwrap();
//! let mut bounds = BoundsXy::default();
//! for batch in PointBatches::open(&path, None).unwrap() {
//!     bounds.extend(&batch.unwrap());
//! }
//! assert_eq!(bounds.count, 2);
//! assert_eq!(bounds.get(), Some((1.0, 0.0, 4.0, 2.0)));
//! std::fs::remove_file(&path).unwrap();
//! ```

use std::path::Path;

use point_io::terrain::LasBatches;

use crate::error::PointsError;
use crate::points::las_crs;
use crate::PointFormat;

pub use point_io::terrain::XyzBatches;
pub use point_io::BATCH_POINTS;

/// The points of one file, batch by batch (see the module docs).
pub enum PointBatches {
    /// LAS/LAZ with its CRS as WKT (WKT VLR or GeoTIFF keys).
    Las {
        points: Box<LasBatches>,
        crs: Option<String>,
    },
    Xyz(XyzBatches<std::io::BufReader<std::fs::File>>),
}

impl PointBatches {
    /// Opens a point file by extension: LAS/LAZ (with the class filter) or XYZ text; `class`
    /// on an XYZ file is an error (text points carry no class).
    pub fn open(path: &Path, class: Option<u8>) -> Result<PointBatches, PointsError> {
        let name = path.display().to_string();
        match PointFormat::from_path(path) {
            PointFormat::Las => {
                let points = LasBatches::open(path, class)?;
                let crs = las_crs(points.las());
                Ok(PointBatches::Las { points: Box::new(points), crs })
            }
            PointFormat::Xyz => {
                if class.is_some() {
                    return Err(PointsError::Io {
                        name,
                        message: "a class filter needs a LAS/LAZ file; XYZ text has no classes".into(),
                    });
                }
                let f = std::fs::File::open(path)
                    .map_err(|e| PointsError::Io { name: name.clone(), message: e.to_string() })?;
                Ok(PointBatches::Xyz(XyzBatches::new(std::io::BufReader::new(f), &name)))
            }
        }
    }

    /// The CRS the file declares (LAS WKT or GeoTIFF keys), as WKT.
    pub fn crs(&self) -> Option<&str> {
        match self {
            PointBatches::Las { crs, .. } => crs.as_deref(),
            PointBatches::Xyz(_) => None,
        }
    }
}

impl Iterator for PointBatches {
    type Item = Result<Vec<[f64; 3]>, PointsError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            PointBatches::Las { points, .. } => points.next(),
            PointBatches::Xyz(x) => x.next(),
        }
    }
}

/// The xy bounding box and the number of points seen, grown batch by batch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BoundsXy {
    pub count: usize,
    min: [f64; 2],
    max: [f64; 2],
}

impl BoundsXy {
    pub fn extend(&mut self, points: &[[f64; 3]]) {
        for p in points {
            if self.count == 0 {
                self.min = [p[0], p[1]];
                self.max = [p[0], p[1]];
            }
            self.count += 1;
            self.min = [self.min[0].min(p[0]), self.min[1].min(p[1])];
            self.max = [self.max[0].max(p[0]), self.max[1].max(p[1])];
        }
    }

    /// (min x, min y, max x, max y), as `PointCloud::bounds_xy`; `None` before any point.
    pub fn get(&self) -> Option<(f64, f64, f64, f64)> {
        (self.count > 0).then_some((self.min[0], self.min[1], self.max[0], self.max[1]))
    }
}
