//! Counts of a CityGML document gathered object by object, so a tile of any size is summarised
//! from an [`ObjectStream`](crate::ObjectStream) without holding its model: what `geofit info`
//! reports.
//!
//! How things are counted: every city object, nested ones included, by type; geometry properties
//! and the polygons defined in them per LoD (`lod0`…`lod4`, `none` without a LoD); a solid where
//! it is defined (a copy reached by `xlink:href` is not counted again; NRW solids whose faces
//! point into the boundary surfaces one by one are definitions); a polygon reached by reference
//! once per distinct href, as an XLink, not as a polygon; triangles of TIN reliefs apart from
//! polygons. Rings with fewer than 4 positions (a closed ring needs 3 points and the repeated
//! first) are listed with their place, as val3dity's code 101 would name them.
//!
//! # Examples
//!
//! ```
//! use citygml_io::{summary::DocumentCounts, ObjectStream};
//!
//! let gml = br#"<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0"
//!     xmlns:bldg="http://www.opengis.net/citygml/building/2.0" xmlns:gml="http://www.opengis.net/gml">
//!   <core:cityObjectMember><bldg:Building gml:id="B1"><bldg:lod2MultiSurface><gml:MultiSurface>
//!     <gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing>
//!       <gml:posList>0 0 0 4 0 0 4 3 0 0 0 0</gml:posList>
//!     </gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>
//!   </gml:MultiSurface></bldg:lod2MultiSurface></bldg:Building></core:cityObjectMember>
//! </core:CityModel>"#;
//! let mut counts = DocumentCounts::default();
//! for obj in ObjectStream::new(gml).unwrap() {
//!     counts.add(&obj.unwrap());
//! }
//! assert_eq!((counts.top_level_objects, counts.polygons, counts.points), (1, 1, 4));
//! assert_eq!(counts.lods["lod2"].polygons, 1);
//! assert!(counts.short_rings.is_empty()); // 4 positions: a closed triangle
//! ```

use std::collections::{BTreeMap, HashSet};

use serde::Serialize;

use crate::model::{CityObject, Envelope, GeometryKind, Shell, SourceSpan};

/// Geometry properties and polygons of one LoD.
#[derive(Debug, Default, Clone, PartialEq, Eq, Serialize)]
pub struct LodCounts {
    /// Geometry properties with this LoD (`lod2Solid`, `lod2MultiSurface`, ...).
    pub geometries: usize,
    /// Polygons defined in them.
    pub polygons: usize,
}

/// What a document holds, added up object by object (see the module docs). Serialized as the
/// counts alone, in this order (the envelope and the short rings are reported by their users
/// in their own form).
#[derive(Debug, Default, Clone, Serialize)]
pub struct DocumentCounts {
    #[serde(skip)]
    pub envelope: Envelope,
    pub top_level_objects: usize,
    /// Every city object, nested ones included (Building, BuildingPart, WallSurface, ...).
    pub feature_types: BTreeMap<String, usize>,
    /// Keyed `lod0`..`lod4`, or `none` for geometry without a LoD in its property name.
    pub lods: BTreeMap<String, LodCounts>,
    pub solids: usize,
    pub polygons: usize,
    pub rings: usize,
    /// Triangles of TIN reliefs (gml:TriangulatedSurface / gml:Tin), not counted as polygons.
    pub triangles: usize,
    pub interior_rings: usize,
    pub points: usize,
    /// Distinct hrefs through which polygons were reached.
    pub xlinks_resolved: usize,
    /// Rings with fewer than 4 positions: where they are and how many they have.
    #[serde(skip)]
    pub short_rings: Vec<(SourceSpan, usize)>,
}

impl DocumentCounts {
    /// Adds one top-level object (with everything nested in it).
    pub fn add(&mut self, obj: &CityObject) {
        // One href may stand for several polygons (a CompositeSurface): count hrefs, not copies.
        let mut hrefs = HashSet::new();
        self.top_level_objects += 1;
        self.envelope.merge(&obj.envelope);
        for o in obj.walk() {
            *self.feature_types.entry(o.kind.clone()).or_insert(0) += 1;
            for g in &o.geometries {
                let key = g.lod.map(|l| format!("lod{l}")).unwrap_or_else(|| "none".into());
                self.lods.entry(key.clone()).or_default().geometries += 1;
                self.solids += defined_solids(&g.kind);
                let tin = matches!(g.gml_type.as_str(), "TriangulatedSurface" | "Tin");
                for p in g.polygons() {
                    if tin {
                        self.triangles += 1;
                    } else if let Some(v) = &p.via_xlink {
                        hrefs.insert(v.bytes.start);
                    } else {
                        self.lods.entry(key.clone()).or_default().polygons += 1;
                        self.add_polygon(p);
                    }
                }
            }
        }
        self.xlinks_resolved += hrefs.len();
    }

    fn add_polygon(&mut self, p: &crate::model::Polygon) {
        self.polygons += 1;
        for r in std::iter::once(&p.exterior).chain(&p.interiors) {
            self.rings += 1;
            self.points += r.points.len();
            if r.points.len() < 4 {
                self.short_rings.push((r.span.clone(), r.points.len()));
            }
        }
        self.interior_rings += p.interiors.len();
    }
}

/// Solids defined (not reached by reference) in one geometry.
fn defined_solids(kind: &GeometryKind) -> usize {
    let copy = |sh: &Shell| sh.via_xlink.is_some();
    match kind {
        GeometryKind::Solid { exterior, .. } => usize::from(!copy(exterior)),
        GeometryKind::Solids(v) => v.iter().filter(|s| !copy(&s.0)).count(),
        GeometryKind::Surfaces(_) => 0,
    }
}
