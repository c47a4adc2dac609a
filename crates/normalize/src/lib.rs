//! Normalization (spec §3): from a polygon soup (CityGML rings, OBJ sketch faces) to a popa3d model.
//!
//! 1. [`topology`]: topological normalization — snap points to nodes, build directed edges and
//!    half-edges, drop duplicate faces, orient every solid consistently, check it is closed.
//! 2. [`geometry`]: geometric normalization — a least-squares plane per face, merge parallel normals
//!    (within an angle tolerance), merge coplanar planes (within a distance tolerance), optionally share
//!    parameters between orthogonal normals.
//! 3. [`conditions`]: conditions from geometry and semantics (spec §8.2 step 5) and sketch priors
//!    (spec §4.6).
//!
//! [`citygml`] and [`obj`] turn the input formats into [`soup::Soup`]s; [`convert`] runs the whole
//! conversion of a CityGML document's buildings; [`counts`] reports the
//! before/after counts the way the spec's Tables 7.1 and 7.4 do.
//!
//! # Examples
//!
//! A box sketched as an OBJ solid becomes 8 nodes on 6 faces, 6 planes and 3 normals (parallel
//! faces share a normal), each node the intersection of its three planes:
//!
//! ```
//! use normalize::{normalize_into, obj::read_sketch, Tolerances};
//! use popa3d_model::{Incidence, NodeId, Popa3d};
//! let obj = b"o room\nv 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n\
//! f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
//! let soup = read_sketch(obj, "box.obj").unwrap();
//! let mut model = Popa3d::new([0.0; 3]);
//! let done = normalize_into(&mut model, &soup, &Tolerances::default()).unwrap();
//! let last = done.counts.last();
//! assert_eq!((last.nodes, last.faces, last.planes, last.normals), (8, 6, 6, 3));
//! let corners = model.node_positions(&Incidence::new(&model)).unwrap();
//! assert!(corners.iter().any(|p| (p[0] - 4.0).abs() < 1e-9 && (p[1] - 3.0).abs() < 1e-9 && (p[2] - 2.5).abs() < 1e-9));
//! ```

pub mod citygml;
pub mod conditions;
pub mod convert;
pub mod counts;
pub mod curved;
pub mod geometry;
pub mod identity;
pub mod obj;
pub mod soup;
pub mod to_citygml;
pub mod topology;

pub use counts::{Counts, SourceCounts, StageCounts};
pub use soup::{Soup, SoupPolygon, SoupSolid};

use popa3d_model::Popa3d;
use serde::Serialize;

/// Tolerances of normalization. Spec §3.1/§3.2 give none (\[gap\]); these defaults are decided here
/// for survey-grade building models in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Tolerances {
    /// Points closer than this are one node (m). Default 1 mm: below LoD2 capture accuracy, above
    /// the rounding of coordinates written with 3 decimals.
    pub snap: f64,
    /// Largest distance of a face vertex from the face's least-squares plane before the face is
    /// rejected as "far from planar" (m). Default 0.1 m.
    pub planarity: f64,
    /// Normals within this angle (degrees) are merged into one normal (parallel faces). Default
    /// 0.01°: merges what is parallel up to coordinate rounding; larger deviations become generated
    /// parallelism conditions instead, so they stay testable.
    pub normal_angle_deg: f64,
    /// Planes on one normal whose d differ by less than this are merged (coplanar faces, m).
    /// Default 1 mm, like `snap`.
    pub plane_distance: f64,
    /// Share parameters between orthogonal normals (spec §3.2 step 4). Off by default: it snaps
    /// near-zero components to zero and forces exact orthogonality.
    pub share_orthogonal: bool,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            snap: 0.001,
            planarity: 0.1,
            normal_angle_deg: 0.01,
            plane_distance: 0.001,
            share_orthogonal: false,
        }
    }
}

/// Why an object (building, sketch) could not be converted: the rule it broke, the source element
/// (gml:id, polygon id, OBJ line) and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, thiserror::Error)]
#[error("{rule}: {element}: {message}")]
pub struct Rejection {
    /// A short rule id: TA03 (open shell), TA05 (< 3 distinct points), GA-PLANAR (far from planar),
    /// GA01 (node without 3 independent planes), NO-SOLID (MultiSurface-only geometry not closed),
    /// NO-GEOMETRY, ORIENT (shell cannot be oriented consistently).
    pub rule: String,
    /// The gml:id (or other locator) of the offending element.
    pub element: String,
    pub message: String,
}

impl Rejection {
    pub fn new(rule: &str, element: impl Into<String>, message: impl Into<String>) -> Self {
        Rejection { rule: rule.to_string(), element: element.into(), message: message.into() }
    }
}

/// A finding that did not stop the conversion (a removed duplicate face, a dropped sliver).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Notice {
    pub rule: String,
    pub element: String,
    pub message: String,
}

/// The result of normalizing one soup into a model.
#[derive(Debug, Clone)]
pub struct Normalized {
    pub counts: Counts,
    pub notices: Vec<Notice>,
}

/// Normalizes one soup and appends it to `model` (shared exterior solid, new ids). On a rejection
/// the model is left unchanged.
pub fn normalize_into(model: &mut Popa3d, soup: &Soup, tol: &Tolerances) -> Result<Normalized, Rejection> {
    let mut notices = Vec::new();
    let topo = topology::build(soup, tol, &mut notices).map_err(|r| {
        if soup.multisurface_only && r.rule == "TA03" {
            Rejection::new(
                "NO-SOLID",
                &soup.name,
                format!(
                    "MultiSurface-only geometry (no lodNSolid) that does not close into a solid: {}: {}",
                    r.element, r.message
                ),
            )
        } else {
            r
        }
    })?;
    let mut part = geometry::build(soup, &topo, tol, model.origin)?;
    let counts = part.counts.clone();
    notices.append(&mut part.notices);
    geometry::append(model, &mut part);
    Ok(Normalized { counts, notices })
}
