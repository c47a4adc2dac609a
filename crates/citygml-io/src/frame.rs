//! Moving a city object's coordinates into another frame: a geographic CRS's degrees into a
//! local metric frame before metre tolerances apply to them
//! (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).

use crate::model::{CityObject, Envelope, GeometryKind, Point3, Ring};

/// What moves one point: gets the srsName that applies to it (the geometry's own, else the
/// document's) and the point, and moves it or says, in one line, why it cannot.
pub type PointMap<'a> = dyn FnMut(Option<&str>, &mut Point3) -> Result<(), String> + 'a;

fn shell_rings<'a>(s: &'a mut crate::model::Shell, out: &mut Vec<&'a mut Ring>) {
    for p in &mut s.polygons {
        out.push(&mut p.exterior);
        out.extend(p.interiors.iter_mut());
    }
}

fn rings_mut(kind: &mut GeometryKind) -> Vec<&mut Ring> {
    let mut out = Vec::new();
    let shell = shell_rings;
    match kind {
        GeometryKind::Surfaces(polys) => {
            for p in polys {
                out.push(&mut p.exterior);
                out.extend(p.interiors.iter_mut());
            }
        }
        GeometryKind::Solid { exterior, interior } => {
            shell(exterior, &mut out);
            for s in interior {
                shell(s, &mut out);
            }
        }
        GeometryKind::Solids(solids) => {
            for (e, inner) in solids {
                shell(e, &mut out);
                for s in inner {
                    shell(s, &mut out);
                }
            }
        }
    }
    out
}

/// Moves every point of `obj` and its children through `f` (with the geometry's srsName, else
/// `document_srs`) and recomputes the objects' envelopes from the moved points.
pub fn map_points(obj: &mut CityObject, document_srs: Option<&str>, f: &mut PointMap<'_>) -> Result<(), String> {
    let mut envelope = Envelope::empty();
    for g in &mut obj.geometries {
        let srs = g.srs_name.clone();
        let srs = srs.as_deref().or(document_srs);
        for r in rings_mut(&mut g.kind) {
            for p in &mut r.points {
                f(srs, p)?;
                envelope.add_point(p);
            }
        }
    }
    for c in &mut obj.children {
        map_points(c, document_srs, f)?;
        if !c.envelope.is_empty() {
            envelope.merge(&c.envelope);
        }
    }
    obj.envelope = envelope;
    Ok(())
}

/// The first point of `obj` (or of its children), with the srsName that applies to it.
pub fn first_point(obj: &CityObject, document_srs: Option<&str>) -> Option<(Option<String>, Point3)> {
    for g in &obj.geometries {
        if let Some(p) = g.polygons().first().and_then(|p| p.exterior.points.first()) {
            return Some((g.srs_name.clone().or(document_srs.map(str::to_string)), *p));
        }
    }
    obj.children.iter().find_map(|c| first_point(c, document_srs))
}

/// The first geographic srsName of a document (the model's, else a geometry's) with its EPSG
/// code and the document's first point in longitude, latitude: what export and citygml2popa3d
/// refuse with a suggested UTM zone.
/// `srs_override` (a `--s-srs`) replaces every srsName of the document.
pub fn geographic_document(city: &crate::model::CityModel, srs_override: Option<&str>) -> Option<GeographicDocument> {
    if let Some(s) = srs_override {
        let epsg = crate::crs::geographic_epsg(s)?;
        let first = city.objects.iter().find_map(|o| first_point(o, None)).map(|(_, p)| p);
        let lon_lat = first.map(|p| crate::crs::axis_order(s).lon_lat(&p));
        return Some(GeographicDocument { srs: s.to_string(), epsg, lon_lat });
    }
    let doc = city.srs_name.as_deref();
    let first = city.objects.iter().find_map(|o| first_point(o, doc));
    let srs = doc
        .filter(|s| crate::crs::geographic_epsg(s).is_some())
        .map(str::to_string)
        .or_else(|| first.as_ref().and_then(|(s, _)| s.clone()).filter(|s| crate::crs::geographic_epsg(s).is_some()))?;
    let epsg = crate::crs::geographic_epsg(&srs)?;
    let lon_lat = first.map(|(_, p)| crate::crs::axis_order(&srs).lon_lat(&p));
    Some(GeographicDocument { srs, epsg, lon_lat })
}

/// See [`geographic_document`].
#[derive(Debug, Clone, PartialEq)]
pub struct GeographicDocument {
    pub srs: String,
    pub epsg: u32,
    /// The first point as longitude, latitude in the declared axis order (None: no points).
    pub lon_lat: Option<(f64, f64)>,
}

impl GeographicDocument {
    /// Whether the first point is a position in the declared axis order (|latitude| ≤ 90°).
    pub fn plausible(&self) -> bool {
        self.lon_lat.is_none_or(|(lon, lat)| crate::crs::is_position(lon, lat))
    }

    /// `EPSG:32632 (the UTM zone of its first point)`, or a generic hint without points.
    pub fn suggestion(&self) -> String {
        match self.lon_lat.filter(|_| self.plausible()) {
            Some((lon, lat)) => format!("EPSG:{} (the UTM zone of its first point)", crate::crs::utm_epsg(lon, lat)),
            None => "EPSG:326zz (its UTM zone)".to_string(),
        }
    }

    /// One line: `CRS urn:…4979 is geographic (EPSG:4979, degrees, latitude, longitude)`.
    pub fn what(&self) -> String {
        format!(
            "CRS {} is geographic (EPSG:{}, degrees, {})",
            self.srs,
            self.epsg,
            crate::crs::axis_order(&self.srs).describe()
        )
    }
}
