//! citygml-io geometries → CityJSON geometry objects: polygons as rings of indices into a
//! shared, quantised vertex list, semantics from the boundary surface each face belongs to
//! (docs/decisions.md#cityjson-semantics-as-boundary-surfaces).

use std::collections::HashMap;

use citygml_io::{Geometry, GeometryKind, Polygon, Ring, Shell};
use serde_json::{json, Map, Value};

use crate::transform::Transform;

/// The vertex list of one document or CityJSONFeature, each integer vertex once.
pub struct VertexPool {
    pub transform: Transform,
    pub vertices: Vec<[i64; 3]>,
    index: HashMap<[i64; 3], usize>,
}

impl VertexPool {
    pub fn new(transform: Transform) -> VertexPool {
        VertexPool { transform, vertices: Vec::new(), index: HashMap::new() }
    }

    fn add(&mut self, p: &[f64; 3]) -> usize {
        let q = self.transform.quantise(*p);
        let n = self.vertices.len();
        *self.index.entry(q).or_insert_with(|| {
            self.vertices.push(q);
            n
        })
    }

    /// A ring as indices: the closing point dropped (CityJSON rings are implicitly closed), the
    /// order reversed for a `-` orientation.
    fn ring(&mut self, r: &Ring, reversed: bool) -> Vec<usize> {
        let mut ids: Vec<usize> = r.points.iter().map(|p| self.add(p)).collect();
        if ids.len() > 1 && ids.first() == ids.last() {
            ids.pop();
        }
        if reversed {
            ids.reverse();
        }
        ids
    }

    fn polygon(&mut self, p: &Polygon) -> Value {
        let mut rings = vec![self.ring(&p.exterior, p.reversed)];
        rings.extend(p.interiors.iter().map(|r| self.ring(r, p.reversed)));
        json!(rings)
    }

    pub fn into_json(self) -> Value {
        json!(self.vertices)
    }
}

/// Which semantic surface a face belongs to (an index into the object's surface list).
pub type SemanticOf<'a> = dyn Fn(&Polygon) -> Option<usize> + 'a;

/// The object's semantic surfaces: JSON objects (type, id, attributes) and the parent of each.
pub struct SurfaceList {
    pub objects: Vec<Map<String, Value>>,
    pub parent: Vec<Option<usize>>,
}

/// Builds one geometry's `semantics`: only the surfaces its faces use (and their parents).
struct SemanticTable<'s> {
    list: &'s SurfaceList,
    local: HashMap<usize, usize>,
    order: Vec<usize>,
}

impl SemanticTable<'_> {
    fn value(&mut self, s: Option<usize>) -> Value {
        match s {
            Some(s) => json!(self.index(s)),
            None => Value::Null,
        }
    }

    fn index(&mut self, s: usize) -> usize {
        if let Some(i) = self.local.get(&s) {
            return *i;
        }
        let i = self.order.len();
        self.local.insert(s, i);
        self.order.push(s);
        if let Some(p) = self.list.parent[s] {
            self.index(p);
        }
        i
    }

    fn surfaces(&self) -> Vec<Value> {
        self.order
            .iter()
            .map(|s| {
                let mut o = self.list.objects[*s].clone();
                if let Some(p) = self.list.parent[*s] {
                    o.insert("parent".into(), json!(self.local[&p]));
                }
                let children: Vec<usize> =
                    self.order.iter().filter(|c| self.list.parent[**c] == Some(*s)).map(|c| self.local[c]).collect();
                if !children.is_empty() {
                    o.insert("children".into(), json!(children));
                }
                Value::Object(o)
            })
            .collect()
    }
}

/// One CityJSON geometry of `lod` from a citygml-io geometry.
pub fn geometry(
    g: &Geometry,
    lod: &str,
    pool: &mut VertexPool,
    surfaces: &SurfaceList,
    semantic_of: &SemanticOf<'_>,
) -> Value {
    let mut t = SemanticTable { list: surfaces, local: HashMap::new(), order: Vec::new() };
    let mut any = false;
    let mut face = |p: &Polygon, pool: &mut VertexPool, t: &mut SemanticTable<'_>| {
        let s = semantic_of(p);
        any |= s.is_some();
        (pool.polygon(p), t.value(s))
    };
    let mut shell = |s: &Shell, pool: &mut VertexPool, t: &mut SemanticTable<'_>| -> (Vec<Value>, Vec<Value>) {
        s.polygons.iter().map(|p| face(p, pool, t)).unzip()
    };
    let (ty, boundaries, values) = match &g.kind {
        GeometryKind::Surfaces(ps) => {
            let (b, v): (Vec<Value>, Vec<Value>) = ps.iter().map(|p| face(p, pool, &mut t)).unzip();
            let ty = if g.gml_type == "CompositeSurface" { "CompositeSurface" } else { "MultiSurface" };
            (ty, json!(b), json!(v))
        }
        GeometryKind::Solid { exterior, interior } => {
            let (b, v): (Vec<Value>, Vec<Value>) = std::iter::once(exterior)
                .chain(interior)
                .map(|s| shell(s, pool, &mut t))
                .map(|(b, v)| (json!(b), json!(v)))
                .unzip();
            ("Solid", json!(b), json!(v))
        }
        GeometryKind::Solids(solids) => {
            let (b, v): (Vec<Value>, Vec<Value>) = solids
                .iter()
                .map(|(e, i)| {
                    let (b, v): (Vec<Value>, Vec<Value>) = std::iter::once(e)
                        .chain(i)
                        .map(|s| shell(s, pool, &mut t))
                        .map(|(b, v)| (json!(b), json!(v)))
                        .unzip();
                    (json!(b), json!(v))
                })
                .unzip();
            let ty = if g.gml_type == "CompositeSolid" { "CompositeSolid" } else { "MultiSolid" };
            (ty, json!(b), json!(v))
        }
    };
    let mut out = json!({"type": ty, "lod": lod, "boundaries": boundaries});
    if any {
        out["semantics"] = json!({"surfaces": t.surfaces(), "values": values});
    }
    out
}

/// A MultiSurface of loose faces (boundary-surface polygons no geometry of the object holds).
pub fn multi_surface(faces: &[(usize, &Polygon)], lod: &str, pool: &mut VertexPool, surfaces: &SurfaceList) -> Value {
    let mut t = SemanticTable { list: surfaces, local: HashMap::new(), order: Vec::new() };
    let (b, v): (Vec<Value>, Vec<Value>) = faces.iter().map(|(s, p)| (pool.polygon(p), t.value(Some(*s)))).unzip();
    json!({"type": "MultiSurface", "lod": lod, "boundaries": b, "semantics": {"surfaces": t.surfaces(), "values": v}})
}

/// The LoD of a geometry: the refinement geofit wrote into the gml:id (`…-lod2.2`) when it
/// matches the property's LoD, else the property's LoD.
pub fn lod_string(g: &Geometry) -> Option<String> {
    let from_id =
        g.id.as_deref()
            .filter(|id| id.starts_with("geofit-"))
            .and_then(|id| id.rsplit_once("-lod"))
            .map(|(_, l)| l.to_string());
    match (from_id, g.lod) {
        // CityJSON has LoDs 0-3: CityGML 2.0's LoD 4 (interiors) is written as 3.
        (_, Some(4)) => Some("3".into()),
        (Some(l), Some(n)) if l.starts_with(char::from(b'0' + n)) && l.len() <= 3 => Some(l),
        (_, Some(n)) => Some(n.to_string()),
        (_, None) => None,
    }
}
