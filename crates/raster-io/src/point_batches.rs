//! Points of a file in batches, so that a consumer that needs each point once (Gauss splatting,
//! bounds) holds one batch, not the cloud: 24 bytes a point held whole is 1.2 GB for 5·10⁷
//! lidar returns (docs/decisions.md#streaming-points).
//!
//! [`PointBatches::open`] reads LAS/LAZ by the `las` crate's chunks and XYZ/CSV text by lines,
//! with the rules of the [`crate::points`] module docs; every batch is `Ok(points)` in file
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

use std::io::BufRead;
use std::path::Path;

use crate::error::PointsError;
use crate::points::{LasPoints, XyzLines};
use crate::PointFormat;

/// Points a batch holds at most (the `las` crate's read size; 1.5 MiB of coordinates).
pub const BATCH_POINTS: usize = 1 << 16;

/// The points of one file, batch by batch (see the module docs).
pub enum PointBatches {
    Las(Box<LasPoints>),
    Xyz(XyzBatches<std::io::BufReader<std::fs::File>>),
}

impl PointBatches {
    /// Opens a point file by extension: LAS/LAZ (with the class filter) or XYZ text; `class`
    /// on an XYZ file is an error (text points carry no class).
    pub fn open(path: &Path, class: Option<u8>) -> Result<PointBatches, PointsError> {
        let name = path.display().to_string();
        match PointFormat::from_path(path) {
            PointFormat::Las => LasPoints::open(path, class).map(|l| PointBatches::Las(Box::new(l))),
            PointFormat::Xyz => {
                if class.is_some() {
                    return Err(PointsError::Io { name, message: "a class filter needs a LAS/LAZ file; XYZ text has no classes".into() });
                }
                let f = std::fs::File::open(path).map_err(|e| PointsError::Io { name: name.clone(), message: e.to_string() })?;
                Ok(PointBatches::Xyz(XyzBatches::new(std::io::BufReader::new(f), &name)))
            }
        }
    }

    /// The CRS the file declares (LAS WKT or GeoTIFF keys), as WKT.
    pub fn crs(&self) -> Option<&str> {
        match self {
            PointBatches::Las(l) => l.crs.as_deref(),
            PointBatches::Xyz(_) => None,
        }
    }
}

impl Iterator for PointBatches {
    type Item = Result<Vec<[f64; 3]>, PointsError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            PointBatches::Las(l) => l.next(),
            PointBatches::Xyz(x) => x.next(),
        }
    }
}

/// XYZ/CSV text in batches of [`BATCH_POINTS`].
pub struct XyzBatches<R> {
    reader: R,
    lines: XyzLines,
    name: String,
    yielded: usize,
    done: bool,
}

impl<R: BufRead> XyzBatches<R> {
    pub fn new(reader: R, name: &str) -> XyzBatches<R> {
        XyzBatches { reader, lines: XyzLines::default(), name: name.to_string(), yielded: 0, done: false }
    }

    fn fill(&mut self) -> Result<Vec<[f64; 3]>, PointsError> {
        let mut batch = Vec::with_capacity(BATCH_POINTS.min(1024));
        while batch.len() < BATCH_POINTS {
            match self.lines.next_point(&mut self.reader, &self.name)? {
                Some(p) => batch.push(p),
                None => break,
            }
        }
        Ok(batch)
    }
}

impl<R: BufRead> Iterator for XyzBatches<R> {
    type Item = Result<Vec<[f64; 3]>, PointsError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let batch = self.fill();
        match &batch {
            Ok(b) if b.is_empty() => {
                self.done = true;
                if self.yielded > 0 {
                    return None;
                }
                let message = "no points (empty file or only comments)".into();
                return Some(Err(PointsError::Empty { name: self.name.clone(), message }));
            }
            Ok(b) => self.yielded += b.len(),
            Err(_) => self.done = true,
        }
        Some(batch)
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
