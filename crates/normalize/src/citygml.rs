//! CityGML → polygon soups: one soup per Building / BuildingPart with geometry.
//!
//! Decisions (spec §10.2 item 18): every CityGML version the reader knows (1.0, 2.0, 3.0) and LoD
//! 1–4 are read; the unit of conversion is each Building or BuildingPart that has geometry of its
//! own; it becomes one solid (kind `building`, named by its gml:id) bounded by the exterior space.
//! Its polygons are those of its `lodNSolid` (highest LoD ≤ the requested one, xlinked faces carry
//! the semantics of the boundary surface they point into); without a solid, the polygons of its
//! boundary surfaces and `lodNMultiSurface`s are used and must close by themselves.

use crate::soup::{Soup, SoupPolygon, SoupSolid};
use crate::Rejection;
use citygml_io::{CityModel, CityObject, GeometryKind, Polygon};
use popa3d_model::{FaceSource, SolidKind, VertexSource};

/// Is this object a conversion unit?
pub(crate) fn is_building(o: &CityObject) -> bool {
    o.kind == "Building" || o.kind == "BuildingPart"
}

/// All Building/BuildingPart objects in document order (parts after their parent).
pub fn buildings(model: &CityModel) -> Vec<&CityObject> {
    model.all_objects().into_iter().filter(|o| is_building(o)).collect()
}

/// The local origin for a CityGML model: the centre of its envelope, rounded down to whole metres
/// (readable, and d stays within ≈ the model's extent).
pub fn local_origin(model: &CityModel) -> [f64; 3] {
    let e = &model.envelope;
    if e.is_empty() {
        return [0.0; 3];
    }
    [0, 1, 2].map(|k| ((e.min[k] + e.max[k]) / 2.0).floor())
}

/// The objects of a building that belong to it and not to a nested BuildingPart (the building
/// first): what one conversion unit reads, validates and writes.
pub fn own_objects(b: &CityObject) -> Vec<&CityObject> {
    let mut out = vec![b];
    for c in &b.children {
        if !is_building(c) {
            out.extend(own_objects_rec(c));
        }
    }
    out
}

fn own_objects_rec(o: &CityObject) -> Vec<&CityObject> {
    let mut out = vec![o];
    for c in &o.children {
        if !is_building(c) {
            out.extend(own_objects_rec(c));
        }
    }
    out
}

/// How reports name a Building / BuildingPart: its gml:id, else its element and position.
pub fn unit_name(b: &CityObject) -> String {
    b.id.clone().unwrap_or_else(|| format!("{}@{}:{}", b.kind, b.span.line, b.span.column))
}

/// The provenance key of a polygon: its gml:id, or `@line:column` of its `<gml:Polygon>` start
/// tag when it has none (unique in the document and found again from the same template by
/// `to_citygml`, so polygons without ids — common in real city models — can be written back).
pub fn polygon_key(p: &Polygon) -> String {
    match &p.id {
        Some(id) => id.clone(),
        None => format!("@{}:{}", p.span.line, p.span.column),
    }
}

/// Whether a building object has geometry of its own (else it is only a container of parts).
pub fn has_own_geometry(b: &CityObject) -> bool {
    own_objects(b).iter().any(|o| !o.geometries.is_empty())
}

/// How rejections and the per-building report name a building: its gml:id, else `Building@line:column`.
pub fn building_id(b: &CityObject) -> String {
    b.id.clone().unwrap_or_else(|| format!("Building@{}:{}", b.span.line, b.span.column))
}

/// Builds the soup of one building. `max_lod`: the highest LoD to use.
pub fn building_soup(b: &CityObject, max_lod: u8) -> Result<Soup, Rejection> {
    let bid = building_id(b);
    let objs = own_objects(b);
    // Parent boundary surface of each opening.
    let mut parent_of: std::collections::HashMap<String, String> = std::collections::HashMap::new();
    for o in &objs {
        for c in &o.children {
            if let (Some(cid), Some(oid)) = (&c.id, &o.id) {
                if c.kind == "Window" || c.kind == "Door" {
                    parent_of.insert(cid.clone(), oid.clone());
                }
            }
        }
    }
    // Solids under the building object itself, best LoD ≤ max_lod.
    let solid_geom = b
        .geometries
        .iter()
        .filter(|g| matches!(g.kind, GeometryKind::Solid { .. } | GeometryKind::Solids(_)))
        .filter(|g| g.lod.is_none_or(|l| l <= max_lod))
        .max_by_key(|g| g.lod.unwrap_or(0));
    let polys: Vec<&Polygon> = match solid_geom {
        Some(g) => match &g.kind {
            GeometryKind::Solid { exterior, .. } => exterior.polygons.iter().collect(),
            GeometryKind::Solids(v) => v.iter().flat_map(|(e, _)| e.polygons.iter()).collect(),
            GeometryKind::Surfaces(p) => p.iter().collect(),
        },
        None => {
            // MultiSurface-only: every surface geometry of the building and its boundary surfaces.
            let lod =
                objs.iter().flat_map(|o| o.geometries.iter()).filter_map(|g| g.lod).filter(|l| *l <= max_lod).max();
            let v: Vec<&Polygon> = objs
                .iter()
                .flat_map(|o| o.geometries.iter())
                .filter(|g| g.lod == lod || g.lod.is_none())
                .filter(|g| matches!(g.kind, GeometryKind::Surfaces(_)))
                .flat_map(|g| g.polygons())
                .collect();
            if v.is_empty() {
                return Err(Rejection::new("NO-GEOMETRY", &bid, format!("no polygons at LoD ≤ {max_lod}")));
            }
            v
        }
    };
    let mut soup = Soup {
        name: bid.clone(),
        solids: vec![SoupSolid { kind: SolidKind::Building, name: Some(bid.clone()) }],
        polygons: Vec::with_capacity(polys.len()),
        source_rings: 0,
        multisurface_only: solid_geom.is_none(),
    };
    for (n, p) in polys.iter().enumerate() {
        let pid = polygon_key(p);
        let mut rings = Vec::new();
        let mut srcs = Vec::new();
        for (ri, r) in std::iter::once(&p.exterior).chain(p.interiors.iter()).enumerate() {
            let mut pts = r.points.clone();
            if pts.len() > 1 && pts.first() == pts.last() {
                pts.pop();
            }
            let s: Vec<VertexSource> = (0..pts.len())
                .map(|i| VertexSource::CityGml { polygon: pid.clone(), ring: ri as u32, index: i as u32 })
                .collect();
            if p.reversed {
                // Orientation is re-derived during normalization; keep the source indices as written.
                pts.reverse();
                let mut s = s;
                s.reverse();
                srcs.push(s);
            } else {
                srcs.push(s);
            }
            rings.push(pts);
            soup.source_rings += 1;
        }
        let locator = match &p.id {
            Some(id) => id.clone(),
            None => format!("{bid} polygon #{n} (line {})", p.span.line),
        };
        soup.polygons.push(SoupPolygon {
            rings,
            vertex_sources: srcs,
            solid: 0,
            source: FaceSource {
                polygon: pid,
                semantic: p.semantic.map(|s| s.local_name().to_string()),
                owner: p.semantic_owner.clone(),
                merged: Vec::new(),
            },
            locator,
            parent: p.semantic_owner.as_ref().and_then(|o| parent_of.get(o).cloned()),
        });
    }
    Ok(soup)
}
