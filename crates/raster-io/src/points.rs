//! Scattered points (soundings, lidar returns) from XYZ/CSV text and LAS/LAZ, as one
//! [`PointCloud`] within the point budget ([`crate::limits::PointBudget`]).
//!
//! The reading is point-io's terrain dialect (`point_io::terrain`: fields, header names,
//! comments, line-numbered errors); this module adds what needs GDAL or the machine's memory:
//! the CRS of a LAS file that names it only by an EPSG code, and the budget.

use std::io::BufRead;
use std::path::Path;

use point_io::las::LasPoints;
use point_io::terrain::{LasBatches, XyzBatches};

use crate::error::PointsError;
use crate::limits::{PointBudget, READ_BYTES_PER_POINT};
use crate::point_batches::PointBatches;

pub use point_io::PointFormat;

/// Scattered 3D points with an optional CRS.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// (x, y, z) per point, in file order.
    pub points: Vec<[f64; 3]>,
    /// CRS as WKT when the file declares one (LAS WKT VLR).
    pub crs: Option<String>,
}

impl PointCloud {
    /// Bounding box (min x, min y, max x, max y); `None` for an empty cloud.
    pub fn bounds_xy(&self) -> Option<(f64, f64, f64, f64)> {
        let first = self.points.first()?;
        let mut b = (first[0], first[1], first[0], first[1]);
        for p in &self.points {
            b.0 = b.0.min(p[0]);
            b.1 = b.1.min(p[1]);
            b.2 = b.2.max(p[0]);
            b.3 = b.3.max(p[1]);
        }
        Some(b)
    }
}

/// Reads XYZ/CSV text (the rules of `point_io::terrain`). `name` is used in error messages.
pub fn read_xyz<R: BufRead>(reader: R, name: &str) -> Result<PointCloud, PointsError> {
    collect(XyzBatches::new(reader, name), name, None)
}

/// The points of `batches` in one cloud, within the point budget.
fn collect(
    batches: impl Iterator<Item = Result<Vec<[f64; 3]>, PointsError>>,
    name: &str,
    crs: Option<String>,
) -> Result<PointCloud, PointsError> {
    let budget = PointBudget::for_cost(READ_BYTES_PER_POINT);
    let mut points = Vec::new();
    for batch in batches {
        let batch = batch?;
        check_budget((points.len() + batch.len()).saturating_sub(1), &budget, name)?;
        points.extend(batch);
    }
    Ok(PointCloud { points, crs })
}

/// Refuses the point after `n` when the budget is spent.
fn check_budget(n: usize, budget: &PointBudget, name: &str) -> Result<(), PointsError> {
    if n as u64 >= budget.max_points {
        return Err(PointsError::TooLarge { name: name.into(), message: format!("more than {}", budget.describe()) });
    }
    Ok(())
}

/// Reads a LAS/LAZ file; `class = Some(c)` keeps only points of ASPRS class `c`
/// (2 = ground). Coordinates are the scaled/offset real-world values.
pub fn read_las(path: &Path, class: Option<u8>) -> Result<PointCloud, PointsError> {
    let points = LasBatches::open(path, class)?;
    let crs = las_crs(points.las());
    collect(points, &path.display().to_string(), crs)
}

/// The CRS of a LAS/LAZ file as WKT: its WKT VLR, else the EPSG code of its GeoTIFF keys (LAS
/// 1.0–1.3) turned into WKT by GDAL/PROJ; `None` for user-defined or unknown codes.
pub(crate) fn las_crs(las: &LasPoints) -> Option<String> {
    las.wkt_crs().or_else(|| gdal::spatial_ref::SpatialRef::from_epsg(las.geotiff_epsg()? as u32).ok()?.to_wkt().ok())
}

/// Reads a point file by extension: LAS/LAZ (with the class filter) or XYZ text.
/// `class` on an XYZ file is an error (text points carry no class).
pub fn read_points(path: &Path, class: Option<u8>) -> Result<PointCloud, PointsError> {
    let batches = PointBatches::open(path, class)?;
    let crs = batches.crs().map(str::to_string);
    collect(batches, &path.display().to_string(), crs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_points_in_one_cloud_without_crs() {
        let cloud = read_xyz(",Z,X,Y\n0,30,10,20\n1,31,11,21\n".as_bytes(), "t.xyz").unwrap();
        assert_eq!(cloud, PointCloud { points: vec![[10.0, 20.0, 30.0], [11.0, 21.0, 31.0]], crs: None });
        assert_eq!(cloud.bounds_xy(), Some((10.0, 20.0, 11.0, 21.0)));
        let e = read_xyz("1 2 3\n4 5 nan\n".as_bytes(), "t.xyz").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:2: z = nan is not a finite number");
    }

    #[test]
    fn the_budget_refuses_the_point_after_the_last_allowed() {
        let budget = PointBudget { max_points: 2, source: crate::limits::BudgetSource::Fallback };
        assert!(check_budget(1, &budget, "t").is_ok());
        assert_eq!(
            check_budget(2, &budget, "t").unwrap_err().to_string(),
            format!("t: more than {}", budget.describe())
        );
    }
}
