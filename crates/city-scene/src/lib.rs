//! CityGML city objects → a mesh scene (`mesh_export::Scene`) for glTF / OBJ writers and
//! viewers: what `geofit export` draws, and the rules a viewer user relies on.
//!
//! - One node per top-level object, named by its gml:id, with `gml_id`, `type` and `lod` in its
//!   extras; building/bridge/tunnel parts become child nodes, other nested objects (boundary
//!   surfaces, openings) add their polygons to their owner's node.
//! - One LoD per object: the one asked for, else the object's highest LoD with polygons.
//! - One mesh per semantic surface type, with a fixed material table ([`materials`]:
//!   CityGML viewer colours, closure surfaces and windows translucent); polygons without a
//!   semantic get "Unclassified".
//! - A polygon reached by XLink is written once, where it is defined (NRW solids point into
//!   their boundary surfaces); a polygon that cannot be triangulated or reprojected is left out
//!   and named in [`CityScene::skipped`] (`FILE:LINE:COL: polygon gml:id="…" of Building
//!   gml:id="…" skipped: why`).
//! - Coordinates stay in the model's CRS unless the caller passes a reprojection of (x, y);
//!   the scene's origin and CRS are the caller's to set.
//!
//! # Examples
//!
//! ```
//! use city_scene::{build_scene, SceneOptions};
//!
//! let gml = r#"<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0"
//!     xmlns:bldg="http://www.opengis.net/citygml/building/2.0" xmlns:gml="http://www.opengis.net/gml">
//!   <core:cityObjectMember><bldg:Building gml:id="B1"><bldg:lod2MultiSurface><gml:MultiSurface>
//!     <gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing>
//!       <gml:posList>0 0 0 4 0 0 4 3 0 0 3 0 0 0 0</gml:posList>
//!     </gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>
//!   </gml:MultiSurface></bldg:lod2MultiSurface></bldg:Building></core:cityObjectMember>
//! </core:CityModel>"#;
//! let model = citygml_io::parse(gml.as_bytes()).unwrap();
//! let built = build_scene(&model, "b.gml", &SceneOptions::default(), None, &|_| {});
//! assert_eq!(built.polygons, 1);
//! assert_eq!(built.scene.triangle_count(), 2);
//! assert_eq!(built.scene.nodes[0].name, "B1");
//! assert!((built.scene.area() - 12.0).abs() < 1e-9);
//! ```

pub mod crs;

use std::collections::HashSet;

use citygml_io::{CityModel, CityObject, Polygon, SurfaceType};
use mesh_export::{Material, MeshNode, Scene};

/// What to draw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SceneOptions {
    /// The LoD of every object; `None`: each object's highest LoD with polygons.
    pub lod: Option<u8>,
    /// Flatten each polygon onto its best-fit plane (removes the non-planarity of measured roofs
    /// that shows as creases in a viewer).
    pub planar: bool,
}

/// A reprojection of one (x, y) (z is kept), e.g. a PROJ transformation; an `Err` names why.
pub type Reproject<'a> = &'a dyn Fn(f64, f64) -> Result<(f64, f64), String>;

/// The scene of a model and what was left out of it.
#[derive(Debug)]
pub struct CityScene {
    /// Nodes and materials; `origin`, `crs` and `generator` at their defaults.
    pub scene: Scene,
    /// Polygons written.
    pub polygons: usize,
    /// Polygons left out, each `FILE:LINE:COL: what`.
    pub skipped: Vec<String>,
}

/// Builds the scene of `model` (see the crate docs); `name` is the file name used in the
/// skipped-polygon lines, `progress(n)` is called after each top-level object.
pub fn build_scene(
    model: &CityModel,
    name: &str,
    opts: &SceneOptions,
    reproject: Option<Reproject<'_>>,
    progress: &dyn Fn(usize),
) -> CityScene {
    let lods = object_lods(model, opts.lod);
    let mut b = Builder {
        name,
        defined: defined_polygons(model, &lods),
        emitted: HashSet::new(),
        transform: reproject,
        skipped: Vec::new(),
        polygons: 0,
        planar: opts.planar,
    };
    let mut scene = Scene { materials: materials(), ..Default::default() };
    for (i, (o, lod)) in model.objects.iter().zip(&lods).enumerate() {
        if let Some(n) = lod.and_then(|lod| b.node(o, lod, i + 1)) {
            scene.nodes.push(n);
        }
        progress(i + 1);
    }
    CityScene { scene, polygons: b.polygons, skipped: b.skipped }
}

/// Definition span starts of every polygon defined (not referenced) in an exported geometry.
fn defined_polygons(model: &CityModel, lods: &[Option<u8>]) -> HashSet<usize> {
    let mut defined = HashSet::new();
    for (o, lod) in model.objects.iter().zip(lods) {
        let Some(lod) = *lod else { continue };
        for c in o.walk() {
            for g in c.geometries.iter().filter(|g| g.lod == Some(lod)) {
                defined.extend(g.polygons().iter().filter(|p| p.via_xlink.is_none()).map(|p| p.span.bytes.start));
            }
        }
    }
    defined
}

/// The semantic materials, in a fixed order (the output does not depend on which come first).
/// Colours follow common CityGML viewer conventions; closure surfaces and windows are translucent.
pub fn materials() -> Vec<Material> {
    let m = |name: &str, rgba: [f32; 4]| Material::new(name, rgba);
    vec![
        m("WallSurface", [0.86, 0.84, 0.78, 1.0]),
        m("RoofSurface", [0.62, 0.18, 0.12, 1.0]),
        m("GroundSurface", [0.35, 0.33, 0.30, 1.0]),
        m("ClosureSurface", [0.70, 0.80, 0.90, 0.4]),
        m("FloorSurface", [0.60, 0.50, 0.38, 1.0]),
        m("CeilingSurface", [0.90, 0.90, 0.88, 1.0]),
        m("InteriorWallSurface", [0.95, 0.93, 0.88, 1.0]),
        m("OuterFloorSurface", [0.55, 0.53, 0.48, 1.0]),
        m("OuterCeilingSurface", [0.78, 0.76, 0.72, 1.0]),
        m("Window", [0.45, 0.70, 0.90, 0.6]),
        m("Door", [0.45, 0.30, 0.16, 1.0]),
        m("Unclassified", [0.75, 0.75, 0.75, 1.0]),
    ]
}

/// The index of a surface type's material in [`materials`].
pub fn material_index(s: Option<SurfaceType>) -> usize {
    match s {
        Some(SurfaceType::Wall) => 0,
        Some(SurfaceType::Roof) => 1,
        Some(SurfaceType::Ground) => 2,
        Some(SurfaceType::Closure) => 3,
        Some(SurfaceType::Floor) => 4,
        Some(SurfaceType::Ceiling) => 5,
        Some(SurfaceType::InteriorWall) => 6,
        Some(SurfaceType::OuterFloor) => 7,
        Some(SurfaceType::OuterCeiling) => 8,
        Some(SurfaceType::Window) => 9,
        Some(SurfaceType::Door) => 10,
        None => 11,
    }
}

fn is_part(o: &CityObject) -> bool {
    matches!(o.kind.as_str(), "BuildingPart" | "BridgePart" | "TunnelPart")
}

/// Highest LoD with polygons in this object and everything nested in it.
fn max_lod(o: &CityObject) -> Option<u8> {
    o.walk().iter().flat_map(|c| c.geometries.iter()).filter(|g| !g.polygons().is_empty()).filter_map(|g| g.lod).max()
}

/// Builds the nodes of a model; keeps the dedup state and the findings.
struct Builder<'a> {
    name: &'a str,
    /// Definition span starts of every polygon defined in an exported geometry.
    defined: HashSet<usize>,
    /// Definition span starts already written.
    emitted: HashSet<usize>,
    transform: Option<Reproject<'a>>,
    skipped: Vec<String>,
    polygons: usize,
    planar: bool,
}

impl Builder<'_> {
    fn polygon_label(p: &Polygon) -> String {
        match &p.id {
            Some(id) => format!("polygon gml:id=\"{id}\""),
            None => "polygon".to_string(),
        }
    }

    fn skip(&mut self, p: &Polygon, owner: &str, why: &str) {
        self.skipped.push(format!(
            "{}:{}:{}: {} of {owner} skipped: {why}",
            self.name,
            p.span.line,
            p.span.column,
            Self::polygon_label(p)
        ));
    }

    fn reproject(&self, ring: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, String> {
        let Some(t) = self.transform else { return Ok(ring.to_vec()) };
        ring.iter()
            .map(|p| {
                let (x, y) = t(p[0], p[1]).map_err(|e| format!("reprojection failed at ({}, {}): {e}", p[0], p[1]))?;
                if !(x.is_finite() && y.is_finite()) {
                    return Err(format!("reprojection of ({}, {}) gave no finite result", p[0], p[1]));
                }
                Ok([x, y, p[2]])
            })
            .collect()
    }

    fn add_polygon(&mut self, node: &mut MeshNode, p: &Polygon, owner: &str) {
        let key = p.span.bytes.start;
        if p.via_xlink.is_some() && self.defined.contains(&key) {
            return; // exported where it is defined
        }
        if !self.emitted.insert(key) {
            return;
        }
        let rings: Result<Vec<Vec<[f64; 3]>>, String> =
            std::iter::once(&p.exterior).chain(p.interiors.iter()).map(|r| self.reproject(&r.points)).collect();
        let rings = match rings {
            Ok(r) => r,
            Err(e) => return self.skip(p, owner, &e),
        };
        let holes: Vec<&[[f64; 3]]> = rings[1..].iter().map(|h| h.as_slice()).collect();
        let mut t = match mesh_export::triangulate_polygon(&rings[0], &holes) {
            Ok(t) => t,
            Err(e) => return self.skip(p, owner, &e.to_string()),
        };
        if self.planar {
            t.flatten();
        }
        self.polygons += 1;
        let mesh = node.mesh_for(Some(material_index(p.semantic)));
        let base = mesh.positions.len() as u32;
        mesh.positions.extend_from_slice(&t.positions);
        for tri in &t.triangles {
            let [a, b, c] = tri.map(|i| base + i);
            if p.reversed {
                mesh.indices.extend_from_slice(&[a, c, b]);
            } else {
                mesh.indices.extend_from_slice(&[a, b, c]);
            }
        }
    }

    /// Adds the polygons of `o` and of its nested non-part objects into `node`, and returns the
    /// nested parts (which become child nodes).
    fn collect<'o>(
        &mut self,
        node: &mut MeshNode,
        o: &'o CityObject,
        lod: u8,
        owner: &str,
        parts: &mut Vec<&'o CityObject>,
    ) {
        for g in o.geometries.iter().filter(|g| g.lod == Some(lod)) {
            for p in g.polygons() {
                self.add_polygon(node, p, owner);
            }
        }
        for c in &o.children {
            if is_part(c) {
                parts.push(c);
            } else {
                self.collect(node, c, lod, owner, parts);
            }
        }
    }

    fn node(&mut self, o: &CityObject, lod: u8, index: usize) -> Option<MeshNode> {
        let name = o.id.clone().unwrap_or_else(|| format!("{}_{index}", o.kind));
        let owner = match &o.id {
            Some(id) => format!("{} gml:id=\"{id}\"", o.kind),
            None => o.kind.clone(),
        };
        let mut node = MeshNode::new(name);
        let mut extras = serde_json::Map::new();
        if let Some(id) = &o.id {
            extras.insert("gml_id".into(), serde_json::json!(id));
        }
        extras.insert("type".into(), serde_json::json!(o.kind));
        extras.insert("lod".into(), serde_json::json!(lod));
        node.extras = Some(serde_json::Value::Object(extras));
        let mut parts = Vec::new();
        self.collect(&mut node, o, lod, &owner, &mut parts);
        for (i, part) in parts.into_iter().enumerate() {
            if let Some(child) = self.node(part, lod, i + 1) {
                node.children.push(child);
            }
        }
        (!node.meshes.is_empty() || !node.children.is_empty()).then_some(node)
    }
}

/// The LoD each top-level object is exported at.
fn object_lods(model: &CityModel, lod: Option<u8>) -> Vec<Option<u8>> {
    model.objects.iter().map(|o| lod.or_else(|| max_lod(o))).collect()
}
