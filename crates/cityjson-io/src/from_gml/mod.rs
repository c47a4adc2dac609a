//! CityGML (1.0, 2.0, 3.0, read by citygml-io) → CityJSON 2.0 city objects. Buildings, parts,
//! installations and rooms become CityJSON objects; boundary surfaces and openings become the
//! semantics of their parent's geometry; what has no CityJSON counterpart is reported
//! (docs/decisions.md#cityjson-semantics-as-boundary-surfaces).

mod attrs;
pub(crate) mod geometry;

use std::collections::{BTreeMap, HashMap, HashSet};

use citygml_io::{CityObject, Polygon, SurfaceType};
use serde_json::{json, Map, Value};

use crate::report::Report;
pub use geometry::VertexPool;
use geometry::{SurfaceList, VertexPool as Pool};

/// A CityGML feature's CityJSON type, if it has one.
fn cityjson_type(kind: &str) -> Option<&'static str> {
    Some(match kind {
        "Building" => "Building",
        "BuildingPart" => "BuildingPart",
        "BuildingInstallation" | "IntBuildingInstallation" => "BuildingInstallation",
        "Room" | "BuildingRoom" => "BuildingRoom",
        "BuildingFurniture" => "BuildingFurniture",
        "GenericCityObject" | "GenericOccupiedSpace" | "GenericUnoccupiedSpace" => "GenericCityObject",
        _ => return None,
    })
}

/// Turns features into CityJSON objects over one vertex pool.
pub struct ObjectMapper<'s> {
    pub src: &'s [u8],
    pub pool: Pool,
    pub report: Report,
    generated: usize,
    /// Surface type of every face defined in a boundary surface of the current top-level
    /// feature (by its byte offset): a face another feature of the tree points to keeps it.
    defined: HashMap<usize, SurfaceType>,
    /// The same by the face's gml:id (a copy reached by XLink may come from a re-parse).
    defined_ids: HashMap<String, SurfaceType>,
}

impl<'s> ObjectMapper<'s> {
    pub fn new(src: &'s [u8], pool: Pool) -> ObjectMapper<'s> {
        ObjectMapper {
            src,
            pool,
            report: Report::default(),
            generated: 0,
            defined: HashMap::new(),
            defined_ids: HashMap::new(),
        }
    }

    /// Maps `o` (and its children) into `out`; returns its id, or `None` (reported) when
    /// CityJSON has no place for it.
    pub fn object(&mut self, o: &CityObject, parent: Option<&str>, out: &mut Map<String, Value>) -> Option<String> {
        let Some(ty) = cityjson_type(&o.kind) else {
            let what = format!(
                "{}:{} feature (no CityJSON mapping in geofit: left out)",
                o.module.as_deref().unwrap_or("?"),
                o.kind
            );
            self.report.add(what, o.id.as_deref());
            return None;
        };
        if parent.is_none() {
            self.defined = o
                .walk()
                .into_iter()
                .filter_map(|f| SurfaceType::from_local_name(&f.kind).map(|t| (f, t)))
                .flat_map(|(f, t)| {
                    f.geometries
                        .iter()
                        .flat_map(|g| g.polygons())
                        .filter(|p| p.via_xlink.is_none())
                        .map(move |p| (p.span.bytes.start, t))
                })
                .collect();
        }
        if parent.is_none() {
            self.defined_ids = o
                .walk()
                .into_iter()
                .filter_map(|f| SurfaceType::from_local_name(&f.kind).map(|t| (f, t)))
                .flat_map(|(f, t)| {
                    f.geometries.iter().flat_map(|g| g.polygons()).filter_map(move |p| p.id.clone().map(|id| (id, t)))
                })
                .collect();
        }
        if o.kind == "IntBuildingInstallation" {
            self.report.add("IntBuildingInstallation (written as a BuildingInstallation)", o.id.as_deref());
        }
        let id = match &o.id {
            Some(id) if !out.contains_key(id) => id.clone(),
            _ => {
                self.generated += 1;
                self.report.add("feature without a (unique) gml:id (given one: geofit-N)", o.id.as_deref());
                format!("geofit-{}", self.generated)
            }
        };
        let bytes = self.src.get(o.span.bytes.clone()).unwrap_or_default();
        let attributes = attrs::scan(bytes, &id, &mut self.report);
        let mut surfaces = self.surfaces(o);
        let geometry = self.geometries(o, &mut surfaces, &id);
        let mut obj = Map::new();
        obj.insert("type".into(), json!(ty));
        if !attributes.is_empty() {
            obj.insert("attributes".into(), Value::Object(attributes));
        }
        if !geometry.is_empty() {
            obj.insert("geometry".into(), Value::Array(geometry));
        }
        if let Some(p) = parent {
            obj.insert("parents".into(), json!([p]));
        }
        out.insert(id.clone(), Value::Null);
        let children: Vec<String> = o
            .children
            .iter()
            .filter(|c| SurfaceType::from_local_name(&c.kind).is_none())
            .filter_map(|c| self.object(c, Some(&id), out))
            .collect();
        if !children.is_empty() {
            obj.insert("children".into(), json!(children));
        }
        out.insert(id.clone(), Value::Object(obj));
        Some(id)
    }

    /// The object's boundary surfaces and their openings, flattened, with their semantic objects.
    fn surfaces<'o>(&mut self, o: &'o CityObject) -> Flat<'o> {
        let mut flat = Flat { list: SurfaceList { objects: Vec::new(), parent: Vec::new() }, features: Vec::new() };
        for s in o.children.iter().filter(|c| SurfaceType::from_local_name(&c.kind).is_some()) {
            let i = self.surface(s, None, &mut flat);
            for op in
                s.children.iter().filter(|c| SurfaceType::from_local_name(&c.kind).is_some_and(SurfaceType::is_opening))
            {
                self.surface(op, Some(i), &mut flat);
            }
            for other in s
                .children
                .iter()
                .filter(|c| !SurfaceType::from_local_name(&c.kind).is_some_and(SurfaceType::is_opening))
            {
                self.report.add(format!("{} inside a boundary surface (not mapped)", other.kind), other.id.as_deref());
            }
        }
        flat
    }

    fn surface<'o>(&mut self, s: &'o CityObject, parent: Option<usize>, flat: &mut Flat<'o>) -> usize {
        let t = SurfaceType::from_local_name(&s.kind).expect("filtered");
        let mut m = Map::new();
        m.insert("type".into(), json!(t.local_name()));
        if let Some(id) = s.id.as_deref().filter(|id| !id.starts_with("geofit-")) {
            m.insert("id".into(), json!(id));
        }
        let bytes = self.src.get(s.span.bytes.clone()).unwrap_or_default();
        let label = s.id.clone().unwrap_or_else(|| s.kind.clone());
        for (k, v) in attrs::scan(bytes, &label, &mut self.report) {
            if v.is_object() || k == "id" {
                self.report.add("semantic surface attribute named id or holding an object (not mapped)", Some(&label));
                continue;
            }
            m.insert(k, v);
        }
        flat.list.objects.push(m);
        flat.list.parent.push(parent);
        flat.features.push(s);
        flat.list.objects.len() - 1
    }

    /// The object's own geometries, then its boundary surfaces' faces that none of them holds
    /// (one MultiSurface per LoD).
    fn geometries(&mut self, o: &CityObject, flat: &mut Flat<'_>, id: &str) -> Vec<Value> {
        let by_id: HashMap<&str, usize> =
            flat.features.iter().enumerate().filter_map(|(i, f)| f.id.as_deref().map(|d| (d, i))).collect();
        // Faces defined inline in a surface, and faces a surface points to by XLink.
        let mut claimed: HashMap<usize, usize> = HashMap::new();
        for (i, f) in flat.features.iter().enumerate() {
            for g in &f.geometries {
                for p in g.polygons() {
                    claimed.entry(p.span.bytes.start).or_insert(i);
                }
            }
        }
        // A face whose surface belongs to another feature (an XLink across features, e.g. into
        // a nested installation) keeps its type: one id-less semantic surface per type.
        let (defined, defined_ids) = (&self.defined, &self.defined_ids);
        let type_of = |p: &Polygon| {
            p.semantic
                .or_else(|| defined.get(&p.span.bytes.start).copied())
                .or_else(|| p.id.as_ref().and_then(|i| defined_ids.get(i).copied()))
        };
        let mut foreign: HashMap<SurfaceType, usize> = HashMap::new();
        for p in o.geometries.iter().flat_map(|g| g.polygons()) {
            let own = p.semantic_owner.as_deref().is_some_and(|o| by_id.contains_key(o))
                || claimed.contains_key(&p.span.bytes.start);
            if let (Some(t), false) = (type_of(p), own) {
                foreign.entry(t).or_insert_with(|| {
                    flat.list.objects.push(Map::from_iter([("type".to_string(), json!(t.local_name()))]));
                    flat.list.parent.push(None);
                    flat.list.objects.len() - 1
                });
            }
        }
        let semantic_of = |p: &Polygon| {
            p.semantic_owner
                .as_deref()
                .and_then(|o| by_id.get(o).copied())
                .or_else(|| claimed.get(&p.span.bytes.start).copied())
                .or_else(|| type_of(p).and_then(|t| foreign.get(&t).copied()))
        };
        let mut covered: HashSet<usize> = HashSet::new();
        let mut out = Vec::new();
        for g in &o.geometries {
            let Some(lod) = geometry::lod_string(g) else {
                self.report.add(format!("{} geometry without a LoD (left out)", g.property), Some(id));
                continue;
            };
            if g.lod == Some(4) {
                self.report.add("LoD 4 geometry (CityJSON has LoDs 0-3: written as LoD 3)", Some(id));
            }
            if !g.skipped_members.is_empty() {
                self.report.add("aggregate member the CityGML reader could not resolve (left out)", Some(id));
            }
            g.polygons().iter().for_each(|p| {
                covered.insert(p.span.bytes.start);
            });
            out.push(geometry::geometry(g, &lod, &mut self.pool, &flat.list, &semantic_of));
        }
        let mut loose: BTreeMap<String, Vec<(usize, &Polygon)>> = BTreeMap::new();
        for (i, f) in flat.features.iter().enumerate() {
            for g in &f.geometries {
                let Some(lod) = geometry::lod_string(g) else { continue };
                for p in
                    g.polygons().into_iter().filter(|p| p.via_xlink.is_none() && !covered.contains(&p.span.bytes.start))
                {
                    loose.entry(lod.clone()).or_default().push((i, p));
                }
            }
        }
        for (lod, faces) in loose {
            out.push(geometry::multi_surface(&faces, &lod, &mut self.pool, &flat.list));
        }
        out
    }
}

/// An object's boundary surfaces and openings in one list (index = semantic surface).
struct Flat<'o> {
    list: SurfaceList,
    features: Vec<&'o CityObject>,
}
