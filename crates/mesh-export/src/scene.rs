//! The in-memory scene every writer takes: a tree of named nodes holding triangle meshes and line
//! sets in world coordinates (f64), a material table and the local origin.
//!
//! World coordinates stay `f64` until a writer subtracts [`Scene::origin`]: UTM eastings/northings
//! (≈ 10⁵–10⁶ m) lose decimetres in `f32`, local coordinates around the origin keep ≈ 0.1 mm over
//! kilometres.

use crate::ExportError;

/// A material: a name (OBJ `usemtl`, glTF `material.name`) and a linear RGBA colour in 0..=1.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    /// Base colour, linear RGB and alpha in 0..=1; alpha < 1 is written as glTF `BLEND` and OBJ `d`.
    pub rgba: [f32; 4],
    /// Rendered from both sides (glTF `doubleSided`). Keep `true` for data whose ring orientation
    /// is not guaranteed (CityGML in the wild).
    pub double_sided: bool,
}

impl Material {
    pub fn new(name: impl Into<String>, rgba: [f32; 4]) -> Self {
        Material { name: name.into(), rgba, double_sided: true }
    }
}

/// Triangles sharing one material (one glTF primitive, one OBJ `usemtl` run).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions in world coordinates (the origin is subtracted on writing).
    pub positions: Vec<[f64; 3]>,
    /// Three vertex indices per triangle, counter-clockwise seen from the front.
    pub indices: Vec<u32>,
    /// Optional per-vertex normals (normalised on writing; a zero or non-finite normal is an error).
    /// Leave `None` for flat-shaded data: glTF viewers then compute flat normals themselves.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Optional per-vertex linear RGBA colours (glTF `COLOR_0`, OBJ `v x y z r g b`).
    pub colors: Option<Vec<[f32; 4]>>,
    /// Index into [`Scene::materials`]; `None` = the viewer's default material.
    pub material: Option<usize>,
}

impl TriangleMesh {
    pub fn new(material: Option<usize>) -> Self {
        TriangleMesh { material, ..Default::default() }
    }

    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Appends a vertex and returns its index.
    pub fn push_vertex(&mut self, p: [f64; 3]) -> u32 {
        self.positions.push(p);
        (self.positions.len() - 1) as u32
    }

    /// Total area of the triangles (in world units², from the f64 positions).
    pub fn area(&self) -> f64 {
        self.indices
            .chunks_exact(3)
            .map(|t| {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| self.positions[i as usize]);
                crate::vec3::triangle_area(a, b, c)
            })
            .sum()
    }
}

/// Line segments (glTF primitive mode `LINES`, OBJ `l`), e.g. T-mesh edges or wireframes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LineSet {
    /// Vertex positions in world coordinates.
    pub positions: Vec<[f64; 3]>,
    /// Two vertex indices per segment.
    pub indices: Vec<u32>,
    /// Optional per-vertex linear RGBA colours.
    pub colors: Option<Vec<[f32; 4]>>,
    /// Index into [`Scene::materials`].
    pub material: Option<usize>,
}

/// A named node (glTF node, OBJ object `o`): a building, a terrain tile, an isosurface.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MeshNode {
    /// Display name (glTF `node.name`/`mesh.name`; OBJ object name with whitespace replaced by `_`).
    pub name: String,
    /// Application data written as the glTF node's `extras` (e.g. `{"gml_id": "..."}`); ignored by OBJ.
    pub extras: Option<serde_json::Value>,
    /// Triangle meshes, one per material.
    pub meshes: Vec<TriangleMesh>,
    /// Line sets, one per material.
    pub lines: Vec<LineSet>,
    /// Child nodes (glTF children; OBJ objects named `parent/child`).
    pub children: Vec<MeshNode>,
}

impl MeshNode {
    pub fn new(name: impl Into<String>) -> Self {
        MeshNode { name: name.into(), ..Default::default() }
    }

    /// This node and its descendants, depth first (parents before children).
    pub fn walk(&self) -> Vec<&MeshNode> {
        let mut out = vec![self];
        for c in &self.children {
            out.extend(c.walk());
        }
        out
    }

    /// The triangle mesh with `material`, created empty on first use.
    pub fn mesh_for(&mut self, material: Option<usize>) -> &mut TriangleMesh {
        let i = match self.meshes.iter().position(|m| m.material == material && m.colors.is_none()) {
            Some(i) => i,
            None => {
                self.meshes.push(TriangleMesh::new(material));
                self.meshes.len() - 1
            }
        };
        &mut self.meshes[i]
    }
}

/// What the writers take: nodes, materials and the origin subtracted from every coordinate.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scene {
    /// Top-level nodes, written in this order.
    pub nodes: Vec<MeshNode>,
    pub materials: Vec<Material>,
    /// Local origin in world coordinates: written coordinates are `world - origin`, and the origin
    /// itself is recorded in the output (glTF root node `extras.origin`, OBJ header comment) so that
    /// `world = local + origin` can be recovered exactly. `[0, 0, 0]` = no shift.
    pub origin: [f64; 3],
    /// CRS of the world coordinates (e.g. `EPSG:25832`), recorded beside the origin.
    pub crs: Option<String>,
    /// Written as glTF `asset.generator` and in the OBJ header (e.g. `geofit 0.1.0`).
    pub generator: Option<String>,
}

impl Scene {
    /// All nodes, depth first.
    pub fn walk(&self) -> Vec<&MeshNode> {
        self.nodes.iter().flat_map(|n| n.walk()).collect()
    }

    pub fn triangle_count(&self) -> usize {
        self.walk().iter().flat_map(|n| n.meshes.iter()).map(|m| m.triangle_count()).sum()
    }

    /// Total triangle area in world units² (f64, before the origin shift).
    pub fn area(&self) -> f64 {
        self.walk().iter().flat_map(|n| n.meshes.iter()).map(|m| m.area()).sum()
    }

    /// Bounding box `(min, max)` of all vertices (triangles and lines), `None` when there are none.
    pub fn bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let mut min = [f64::INFINITY; 3];
        let mut max = [f64::NEG_INFINITY; 3];
        for n in self.walk() {
            let pts = n.meshes.iter().flat_map(|m| m.positions.iter());
            for p in pts.chain(n.lines.iter().flat_map(|l| l.positions.iter())) {
                for k in 0..3 {
                    min[k] = min[k].min(p[k]);
                    max[k] = max[k].max(p[k]);
                }
            }
        }
        (min[0] <= max[0]).then_some((min, max))
    }

    /// A convenient origin for large coordinates: the bounding box centre in x and y and its
    /// bottom in z, rounded to whole units so the recorded offset reads well and is exact.
    /// `[0, 0, 0]` for an empty scene.
    pub fn auto_origin(&self) -> [f64; 3] {
        match self.bounds() {
            None => [0.0; 3],
            Some((min, max)) => [((min[0] + max[0]) / 2.0).round(), ((min[1] + max[1]) / 2.0).round(), min[2].floor()],
        }
    }

    /// Checks indices, attribute lengths, material references and finiteness, so that writers can
    /// rely on them (and never write NaN or an out-of-range index).
    pub fn validate(&self) -> Result<(), ExportError> {
        if self.origin.iter().any(|v| !v.is_finite()) {
            return Err(ExportError::NonFinite { node: "<scene origin>".into() });
        }
        for n in self.walk() {
            let bad = |what: String| ExportError::InvalidMesh { node: n.name.clone(), what };
            for (mi, m) in n.meshes.iter().enumerate() {
                if m.indices.len() % 3 != 0 {
                    return Err(bad(format!("mesh {mi}: {} indices is not a multiple of 3", m.indices.len())));
                }
                check_common(&m.positions, &m.indices, m.colors.as_deref(), m.material, self.materials.len())
                    .map_err(|w| bad(format!("mesh {mi}: {w}")))?;
                if let Some(nr) = &m.normals {
                    if nr.len() != m.positions.len() {
                        return Err(bad(format!("mesh {mi}: {} normals for {} vertices", nr.len(), m.positions.len())));
                    }
                    if let Some(i) = nr.iter().position(|v| {
                        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                        !(l.is_finite() && l > 0.0)
                    }) {
                        return Err(bad(format!("mesh {mi}: normal {i} is zero or not finite")));
                    }
                }
                if m.positions.iter().any(|p| p.iter().any(|v| !v.is_finite())) {
                    return Err(ExportError::NonFinite { node: n.name.clone() });
                }
            }
            for (li, l) in n.lines.iter().enumerate() {
                if l.indices.len() % 2 != 0 {
                    return Err(bad(format!("line set {li}: {} indices is not a multiple of 2", l.indices.len())));
                }
                check_common(&l.positions, &l.indices, l.colors.as_deref(), l.material, self.materials.len())
                    .map_err(|w| bad(format!("line set {li}: {w}")))?;
                if l.positions.iter().any(|p| p.iter().any(|v| !v.is_finite())) {
                    return Err(ExportError::NonFinite { node: n.name.clone() });
                }
            }
        }
        for m in &self.materials {
            if m.rgba.iter().any(|c| !(0.0..=1.0).contains(c)) {
                return Err(ExportError::InvalidMaterial { name: m.name.clone() });
            }
        }
        Ok(())
    }
}

fn check_common(
    positions: &[[f64; 3]],
    indices: &[u32],
    colors: Option<&[[f32; 4]]>,
    material: Option<usize>,
    n_materials: usize,
) -> Result<(), String> {
    if positions.len() > u32::MAX as usize - 1 {
        return Err(format!("{} vertices exceed the u32 index range", positions.len()));
    }
    if let Some(&i) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        return Err(format!("index {i} out of range ({} vertices)", positions.len()));
    }
    if let Some(c) = colors {
        if c.len() != positions.len() {
            return Err(format!("{} colours for {} vertices", c.len(), positions.len()));
        }
        if c.iter().any(|c| c.iter().any(|v| !(0.0..=1.0).contains(v))) {
            return Err("colour component outside 0..=1 or not finite".into());
        }
    }
    if let Some(m) = material {
        if m >= n_materials {
            return Err(format!("material {m} does not exist ({n_materials} materials)"));
        }
    }
    Ok(())
}
