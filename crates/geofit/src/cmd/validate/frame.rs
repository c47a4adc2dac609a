//! A geographic CRS in `validate`: the tolerances are metres, so coordinates in degrees are
//! checked in a metric frame, the UTM zone (GRS80) of the document's first point, through PROJ.
//! The axis order is the one the CRS declares (EPSG: latitude first; CRS84: longitude first)
//! and is checked for plausibility: a "latitude" beyond ±90° is refused in one line, not
//! guessed (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).

use citygml_io::crs::{axis_order, geographic_epsg, is_position, utm_epsg, AxisOrder};
use citygml_io::frame::map_points;
use citygml_io::{CityObject, Point3};
use citygml_validate::document::ObjectFrame;

/// The metric frame of one document: built on the first geographic point met.
#[derive(Default)]
pub(super) struct GeographicFrame {
    /// The last srsName asked about and what it is (geographic EPSG code, axis order).
    last: Option<(String, Option<(u32, AxisOrder)>)>,
    /// The UTM zone's EPSG code, PROJ's conversion to it, and the source CRS as first met.
    utm: Option<(u32, proj::Proj, String, u32, AxisOrder)>,
}

/// UTM on GRS80 from longitude, latitude in degrees (GRS80 and WGS 84 differ by 0.1 mm; every
/// geographic CRS geofit recognises is on one of them).
fn utm_conversion(epsg: u32) -> Result<proj::Proj, String> {
    let zone = epsg % 100;
    let south = if epsg >= 32700 { " +south" } else { "" };
    let def = format!("+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=utm +zone={zone}{south} +ellps=GRS80");
    proj::Proj::new(&def).map_err(|e| format!("PROJ cannot build the UTM zone {zone} conversion: {e}"))
}

impl GeographicFrame {
    fn kind(&mut self, srs: &str) -> Option<(u32, AxisOrder)> {
        if self.last.as_ref().map(|(s, _)| s.as_str()) != Some(srs) {
            let k = geographic_epsg(srs).map(|e| (e, axis_order(srs)));
            self.last = Some((srs.to_string(), k));
        }
        self.last.as_ref().and_then(|(_, k)| *k)
    }

    fn point(&mut self, srs: Option<&str>, p: &mut Point3) -> Result<(), String> {
        let Some(srs) = srs else { return Ok(()) };
        let Some((epsg, order)) = self.kind(srs) else { return Ok(()) };
        let (lon, lat) = order.lon_lat(p);
        if !is_position(lon, lat) {
            let (first, axes) = (if order == AxisOrder::LatLon { "latitude" } else { "longitude" }, order.describe());
            return Err(if is_position(lat, lon) {
                format!(
                    "srsName {srs} (EPSG:{epsg}) declares {axes} but ({}, {}) has a {first} beyond its range: \
                     the coordinates are in the other order; declare that order (urn:ogc:def:crs:OGC:1.3:CRS84h is \
                     longitude, latitude, height) or swap the axes",
                    p[0], p[1]
                )
            } else {
                format!("srsName {srs} (EPSG:{epsg}) is geographic but ({}, {}) are not degrees: name the CRS the coordinates are in", p[0], p[1])
            });
        }
        if self.utm.is_none() {
            let zone = utm_epsg(lon, lat);
            self.utm = Some((zone, utm_conversion(zone)?, srs.to_string(), epsg, order));
        }
        let (zone, conv, ..) = self.utm.as_ref().expect("set above");
        let (e, n) = conv
            .convert((lon, lat))
            .map_err(|e| format!("({}, {}) has no position in EPSG:{zone}: {e}", p[0], p[1]))?;
        (p[0], p[1]) = (e, n);
        Ok(())
    }
}

impl GeographicFrame {
    /// Whether any geometry of `obj` (or its children) is in a geographic CRS: the others are
    /// left exactly as read.
    fn any_geographic(&mut self, document_srs: Option<&str>, obj: &CityObject) -> bool {
        obj.geometries.iter().any(|g| g.srs_name.as_deref().or(document_srs).is_some_and(|s| self.kind(s).is_some()))
            || obj.children.iter().any(|c| self.any_geographic(document_srs, c))
    }
}

impl ObjectFrame for GeographicFrame {
    fn apply(&mut self, document_srs: Option<&str>, obj: &mut CityObject) -> Result<(), String> {
        if !self.any_geographic(document_srs, obj) {
            return Ok(());
        }
        map_points(obj, document_srs, &mut |srs, p| self.point(srs, p))
    }

    fn describe(&self) -> Option<String> {
        let (zone, _, srs, epsg, order) = self.utm.as_ref()?;
        let order = order.describe();
        Some(format!(
            "{srs} (EPSG:{epsg}, degrees, {order}) checked in UTM zone {}{} (EPSG:{zone} axes, GRS80), metres; heights as written",
            zone % 100,
            if *zone >= 32700 { "S" } else { "N" }
        ))
    }
}
