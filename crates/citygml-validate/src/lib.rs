//! CityGML validation.
//!
//! * Geometric validation with the val3dity / OGC QIE error codes ([`codes::ErrorCode`]), checked
//!   level by level — ring, polygon, shell, solid — and stopping at the first level that fails,
//!   so one defect is reported once and not as a cascade. Ring and polygon checks run in the
//!   polygon's own least-squares plane; shells are checked on their triangulation.
//! * XSD validation with libxml2 linked in-process ([`xsd`]).
//!
//! # Examples
//!
//! A wall whose fourth corner is 0.5 m off the plane of the other three: error 203
//! (NON_PLANAR_POLYGON_DISTANCE_PLANE), named by the polygon's gml:id.
//!
//! ```
//! use citygml_validate::document::{validate_document, Checks};
//! let gml = br#"<CityModel xmlns="http://www.opengis.net/citygml/2.0" xmlns:bldg="http://www.opengis.net/citygml/building/2.0"
//!   xmlns:gml="http://www.opengis.net/gml">
//!   <cityObjectMember><bldg:Building gml:id="B1">
//!     <bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon gml:id="wall">
//!       <gml:exterior><gml:LinearRing><gml:posList>0 0 0 4 0 0 4 0.5 3 0 0 3 0 0 0</gml:posList></gml:LinearRing></gml:exterior>
//!     </gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface>
//!   </bldg:Building></cityObjectMember>
//! </CityModel>"#;
//! let checks = Checks { xsd: Err("schemas not used here".into()), geometry: true, options: Default::default() };
//! let report = validate_document(gml, "wall.gml", &checks, &|_| {}).unwrap();
//! assert!(!report.valid);
//! let f = &report.geometry.findings[0];
//! assert_eq!((f.code, f.primitive.as_deref(), f.feature.as_deref()), (203, Some("wall"), Some("B1")));
//! ```

pub mod codes;
pub mod document;
pub mod geom;
pub mod model;
pub mod polygon;
pub mod shell;
pub mod solid;
pub mod tritri;
pub mod xsd;

pub use codes::ErrorCode;
pub use model::{
    add_unresolved_xlinks, sort_findings, validate_model, validate_object, validate_objects, validate_objects_only,
    Finding,
};
pub use polygon::PolygonInput;

/// Tolerances, with val3dity's defaults.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Options {
    /// Vertices closer than this are the same vertex (m).
    pub snap_tol: f64,
    /// Maximum distance of a polygon's vertex to its least-squares plane (m).
    pub planarity_tol: f64,
    /// Maximum angle between the normals of a polygon's triangles (degrees).
    pub normals_tol_deg: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options { snap_tol: 0.001, planarity_tol: 0.01, normals_tol_deg: 20.0 }
    }
}

/// One problem found by the geometric checks, located by indices into the checked primitive.
#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    pub code: ErrorCode,
    /// Polygon index within its shell (or surface set).
    pub polygon: Option<usize>,
    /// Ring index within the polygon (0 = exterior).
    pub ring: Option<usize>,
    /// Shell index within the solid (0 = exterior).
    pub shell: Option<usize>,
    pub detail: String,
    /// The measured quantity behind the verdict, when there is one (plane distance in m for 203,
    /// normal deviation in degrees for 204, gap in m for 103).
    pub value: Option<f64>,
}

/// Checks a set of independent polygons (MultiSurface / CompositeSurface): ring and polygon levels.
pub fn check_surfaces(polys: &[PolygonInput], opts: &Options) -> Vec<Issue> {
    if polys.is_empty() {
        return vec![Issue {
            code: ErrorCode::EmptyPrimitive,
            polygon: None,
            ring: None,
            shell: None,
            detail: "no polygons".into(),
            value: None,
        }];
    }
    let mut snap = geom::Snapper::new(opts.snap_tol);
    polygon::check_polygons(polys, &mut snap, opts).0
}

pub use solid::{check_composite_solid, check_solid};

#[cfg(test)]
mod tests;
