//! Coordinate reference systems given on the command line (`--s-srs`, `--t-srs`), read the way
//! `gdalsrsinfo` reads them (GDAL's `SetFromUserInput`: `EPSG:25832`, WKT, PROJ strings,
//! PROJJSON, URNs), so a string GDAL refuses is refused here too instead of PROJ guessing a
//! meaning for it (`foo` became a Bessel longlat), and point reprojection for `rasterize`.

use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};

/// A CRS that GDAL understood.
#[derive(Debug, Clone)]
pub struct Crs {
    /// The string as the user gave it.
    pub given: String,
    /// GDAL's WKT of it (what outputs store).
    pub wkt: String,
    /// Geographic (degrees) rather than projected or local (metres, feet).
    pub geographic: bool,
}

/// A CRS string GDAL does not understand, or a transformation PROJ cannot build.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct CrsError(pub String);

impl Crs {
    /// Parses `def` like `gdalsrsinfo`; the error names the string.
    pub fn parse(def: &str) -> Result<Crs, CrsError> {
        let refuse = || {
            CrsError(format!("'{def}' is not a coordinate reference system GDAL knows (try EPSG:code, WKT or a PROJ string; `gdalsrsinfo '{def}'` says the same)"))
        };
        if def.trim().is_empty() {
            return Err(refuse());
        }
        let srs = SpatialRef::from_definition(def).map_err(|_| refuse())?;
        let wkt = srs.to_wkt().map_err(|_| refuse())?;
        Ok(Crs { given: def.to_string(), wkt, geographic: srs.is_geographic() })
    }

    /// The CRS stored in a file (WKT), e.g. a LAS header's.
    pub fn from_wkt(wkt: &str) -> Result<Crs, CrsError> {
        let srs = SpatialRef::from_wkt(wkt).map_err(|e| CrsError(format!("the file's CRS is not readable: {e}")))?;
        Ok(Crs {
            given: srs.name().unwrap_or_else(|| "the file's CRS".into()),
            wkt: wkt.to_string(),
            geographic: srs.is_geographic(),
        })
    }

    fn spatial_ref(&self) -> Result<SpatialRef, CrsError> {
        let mut s = SpatialRef::from_wkt(&self.wkt).map_err(|e| CrsError(format!("{}: {e}", self.given)))?;
        // x = easting/longitude, y = northing/latitude, whatever the authority's axis order.
        s.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
        Ok(s)
    }
}

/// Transforms `points` (x y z, traditional GIS order: longitude first) from `from` to `to` in
/// place; z is kept. Fails naming the first point PROJ cannot transform.
pub fn reproject(points: &mut [[f64; 3]], from: &Crs, to: &Crs) -> Result<(), CrsError> {
    let t = CoordTransform::new(&from.spatial_ref()?, &to.spatial_ref()?)
        .map_err(|e| CrsError(format!("no transformation from {} to {}: {e}", from.given, to.given)))?;
    const CHUNK: usize = 4096;
    for chunk in points.chunks_mut(CHUNK) {
        let mut x: Vec<f64> = chunk.iter().map(|p| p[0]).collect();
        let mut y: Vec<f64> = chunk.iter().map(|p| p[1]).collect();
        let mut z = vec![0.0; chunk.len()];
        t.transform_coords(&mut x, &mut y, &mut z).map_err(|e| {
            CrsError(format!(
                "cannot transform ({}, {}) from {} to {}: {e}",
                chunk[0][0], chunk[0][1], from.given, to.given
            ))
        })?;
        for (i, p) in chunk.iter_mut().enumerate() {
            if !(x[i].is_finite() && y[i].is_finite()) {
                return Err(CrsError(format!("({}, {}) has no position in {}", p[0], p[1], to.given)));
            }
            p[0] = x[i];
            p[1] = y[i];
        }
    }
    Ok(())
}

/// The CRS a grid of points is made in: the points' own (`--s-srs`, else the file's), or a
/// target CRS with the reprojection into it.
#[derive(Debug, Clone)]
pub struct GridCrs {
    pub grid: Option<Crs>,
    pub reproject: Option<(Crs, Crs)>,
}

/// Why a [`GridCrs`] cannot be made, by the option at fault.
#[derive(Debug, thiserror::Error)]
pub enum GridCrsError {
    #[error("--s-srs: {0}")]
    Source(CrsError),
    #[error("--t-srs: {0}")]
    Target(CrsError),
    /// A target CRS without any source CRS.
    #[error("names no CRS: give the points' CRS with --s-srs to reproject them")]
    NoSource,
}

impl GridCrs {
    /// `source` (a user's string) overrides the file's WKT, which is ignored when unreadable;
    /// `target` asks for a reprojection, which needs one of the two.
    ///
    /// # Examples
    ///
    /// ```
    /// use raster_io::crs::GridCrs;
    /// let plan = GridCrs::plan(Some("EPSG:4326"), None, Some("EPSG:32633")).unwrap();
    /// let mut p = [[15.0, 0.0, 7.0]];
    /// plan.apply(&mut p).unwrap();
    /// assert!((p[0][0] - 500_000.0).abs() < 1e-6 && p[0][1].abs() < 1e-6 && p[0][2] == 7.0);
    /// assert!(GridCrs::plan(None, None, Some("EPSG:32633")).is_err());
    /// ```
    pub fn plan(source: Option<&str>, file_wkt: Option<&str>, target: Option<&str>) -> Result<GridCrs, GridCrsError> {
        let source = match (source, file_wkt) {
            (Some(s), _) => Some(Crs::parse(s).map_err(GridCrsError::Source)?),
            (None, Some(wkt)) => Crs::from_wkt(wkt).ok(),
            (None, None) => None,
        };
        let Some(t) = target else { return Ok(GridCrs { grid: source, reproject: None }) };
        let target = Crs::parse(t).map_err(GridCrsError::Target)?;
        let source = source.ok_or(GridCrsError::NoSource)?;
        Ok(GridCrs { grid: Some(target.clone()), reproject: Some((source, target)) })
    }

    /// Reprojects `points` in place when the plan says so.
    pub fn apply(&self, points: &mut [[f64; 3]]) -> Result<(), CrsError> {
        match &self.reproject {
            Some((from, to)) => reproject(points, from, to),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn garbage_is_refused_like_gdalsrsinfo() {
        assert!(Crs::parse("foo").is_err());
        assert!(Crs::parse("").is_err());
        assert!(Crs::parse("EPSG:999999").is_err());
        let c = Crs::parse("EPSG:4326").unwrap();
        assert!(c.geographic);
        assert!(!Crs::parse("EPSG:25832").unwrap().geographic);
    }

    #[test]
    fn utm_zone_origin() {
        // 9° E on the equator is the central meridian of UTM 32: easting 500000, northing 0.
        let mut p = [[9.0, 0.0, 5.0]];
        reproject(&mut p, &Crs::parse("EPSG:4326").unwrap(), &Crs::parse("EPSG:32632").unwrap()).unwrap();
        assert!((p[0][0] - 500000.0).abs() < 1e-6 && p[0][1].abs() < 1e-6 && p[0][2] == 5.0, "{p:?}");
    }
}
