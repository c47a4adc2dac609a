//! CityGML validation.
//!
//! * Geometric validation with the val3dity / OGC QIE error codes ([`codes::ErrorCode`]), checked
//!   level by level — ring, polygon, shell, solid — and stopping at the first level that fails,
//!   so one defect is reported once and not as a cascade. Ring and polygon checks run in the
//!   polygon's own least-squares plane; shells are checked on their triangulation.
//! * XSD validation with libxml2 linked in-process ([`xsd`]).

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
pub use model::{add_unresolved_xlinks, sort_findings, validate_model, validate_object, validate_objects, validate_objects_only, Finding};
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
        return vec![Issue { code: ErrorCode::EmptyPrimitive, polygon: None, ring: None, shell: None, detail: "no polygons".into(), value: None }];
    }
    let mut snap = geom::Snapper::new(opts.snap_tol);
    polygon::check_polygons(polys, &mut snap, opts).0
}

pub use solid::{check_composite_solid, check_solid};

#[cfg(test)]
mod tests;
