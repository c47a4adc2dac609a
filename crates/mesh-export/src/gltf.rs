//! glTF 2.0 writer (binary `.glb`, or `.gltf` JSON with the buffer embedded as base64 or in a
//! separate `.bin`), built from `gltf-json` types so the JSON follows the schema by construction.
//!
//! Layout, chosen to pass the Khronos glTF-Validator without errors:
//! - one root node `"origin"` holds everything; its `matrix` rotates the Z-up source frame into
//!   glTF's Y-up frame (`(x, y, z) → (x, z, −y)`, entries 0/±1, so exact) and its `extras` record
//!   `origin` (f64, world = local + origin, in the Z-up source frame) and `crs`. The origin is not
//!   a node translation on purpose: `translation` is `f32`, which cannot hold UTM coordinates.
//! - vertex data is in the source frame minus the origin, as `f32`; one node per [`MeshNode`],
//!   one primitive per [`TriangleMesh`] (mode TRIANGLES) or [`LineSet`] (mode LINES).
//! - every buffer view starts at a multiple of 4 bytes; `POSITION` accessors carry the `min`/`max`
//!   of the written `f32` values (required by the spec); normals are normalised; indices are
//!   `UNSIGNED_INT`; only materials that are used are written (no "unused object" notes).
//!
//! Known reader limitation: MeshLab / pymeshlab (seen with 2025.7) mis-read `LINES` primitives
//! as unindexed triangles over their vertices (stray triangles; the files are valid: Khronos
//! validator, `gltf` crate, three.js). It crashed when the vertex count was not a multiple of 3,
//! so line sets are padded to one with unreferenced repeats of their last vertex. Scenes meant
//! for MeshLab should keep line sets out or use OBJ, whose `l` records MeshLab and FreeCAD skip.
//!
//! [`MeshNode`]: crate::MeshNode
//! [`TriangleMesh`]: crate::TriangleMesh
//! [`LineSet`]: crate::LineSet

use std::collections::BTreeMap;
use std::io::Write;

use base64::Engine as _;
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

use crate::{ExportError, MeshNode, Scene};

/// Column-major matrix taking Z-up source coordinates to glTF's Y-up: (x, y, z) → (x, z, −y).
pub const Z_UP_TO_Y_UP: [f32; 16] = [
    1.0, 0.0, 0.0, 0.0, //
    0.0, 0.0, -1.0, 0.0, //
    0.0, 1.0, 0.0, 0.0, //
    0.0, 0.0, 0.0, 1.0,
];

/// Where a `.gltf` file's binary buffer goes.
pub enum GltfBuffer<'a> {
    /// Inside the JSON as a `data:application/octet-stream;base64,` URI (one self-contained file).
    Embedded,
    /// In a separate file written to `bin`, referenced from the JSON by `uri` (relative, e.g.
    /// `"model.bin"`).
    External { uri: &'a str, bin: &'a mut dyn Write },
}

/// Writes `scene` as a binary glTF (`.glb`): header, JSON chunk, BIN chunk.
pub fn write_glb(scene: &Scene, out: &mut dyn Write) -> Result<(), ExportError> {
    let (root, bin) = build(scene, None)?;
    let mut json_bytes = json::serialize::to_vec(&root).map_err(|e| ExportError::Json(e.to_string()))?;
    // GLB chunks are 4-byte aligned: JSON padded with spaces, BIN with zeros (glTF 2.0 §4.4.3).
    while json_bytes.len() % 4 != 0 {
        json_bytes.push(b' ');
    }
    let mut bin = bin;
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let has_bin = !bin.is_empty();
    let total = 12 + 8 + json_bytes.len() + if has_bin { 8 + bin.len() } else { 0 };
    let total = u32::try_from(total).map_err(|_| ExportError::TooLarge(total))?;
    out.write_all(b"glTF")?;
    out.write_all(&2u32.to_le_bytes())?;
    out.write_all(&total.to_le_bytes())?;
    out.write_all(&(json_bytes.len() as u32).to_le_bytes())?;
    out.write_all(b"JSON")?;
    out.write_all(&json_bytes)?;
    if has_bin {
        out.write_all(&(bin.len() as u32).to_le_bytes())?;
        out.write_all(b"BIN\0")?;
        out.write_all(&bin)?;
    }
    Ok(())
}

/// Writes `scene` as glTF JSON (`.gltf`, pretty-printed) with its buffer as chosen by `buffer`.
pub fn write_gltf(scene: &Scene, out: &mut dyn Write, buffer: GltfBuffer<'_>) -> Result<(), ExportError> {
    match buffer {
        GltfBuffer::Embedded => {
            let (root, _) = build(scene, Some(BufferUri::Embed))?;
            json::serialize::to_writer_pretty(&mut *out, &root).map_err(|e| ExportError::Json(e.to_string()))?;
        }
        GltfBuffer::External { uri, bin } => {
            let (root, data) = build(scene, Some(BufferUri::External(uri)))?;
            json::serialize::to_writer_pretty(&mut *out, &root).map_err(|e| ExportError::Json(e.to_string()))?;
            bin.write_all(&data)?;
        }
    }
    out.write_all(b"\n")?;
    Ok(())
}

enum BufferUri<'a> {
    Embed,
    External(&'a str),
}

/// Accumulates the binary buffer and the views/accessors pointing into it.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
    origin: [f64; 3],
    /// Scene material index → written glTF material index.
    material_map: BTreeMap<usize, u32>,
}

impl Builder {
    fn view(&mut self, bytes: &[u8], target: json::buffer::Target) -> json::Index<json::buffer::View> {
        debug_assert!(self.bin.len().is_multiple_of(4));
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64(bytes.len() as u64),
            byte_offset: Some(USize64(offset as u64)),
            byte_stride: None,
            name: None,
            target: Some(Valid(target)),
            extensions: None,
            extras: None,
        })
    }

    fn accessor(
        &mut self,
        view: json::Index<json::buffer::View>,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        min_max: Option<(serde_json::Value, serde_json::Value)>,
    ) -> json::Index<json::Accessor> {
        let (min, max) = match min_max {
            Some((a, b)) => (Some(a), Some(b)),
            None => (None, None),
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64(count as u64),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: None,
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// POSITION accessor: world → local f32, with min/max of exactly the written values.
    fn positions(&mut self, positions: &[[f64; 3]]) -> json::Index<json::Accessor> {
        let mut bytes = Vec::with_capacity(positions.len() * 12);
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in positions {
            for k in 0..3 {
                let v = (p[k] - self.origin[k]) as f32;
                min[k] = min[k].min(v);
                max[k] = max[k].max(v);
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        let view = self.view(&bytes, json::buffer::Target::ArrayBuffer);
        self.accessor(
            view,
            positions.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            Some((serde_json::json!(min), serde_json::json!(max))),
        )
    }

    fn normals(&mut self, normals: &[[f32; 3]]) -> json::Index<json::Accessor> {
        let mut bytes = Vec::with_capacity(normals.len() * 12);
        for n in normals {
            // Normalise in f64 so the f32 result is as close to unit length as f32 allows.
            let l = (n.iter().map(|&v| (v as f64) * (v as f64)).sum::<f64>()).sqrt();
            for &v in n {
                bytes.extend_from_slice(&((v as f64 / l) as f32).to_le_bytes());
            }
        }
        let view = self.view(&bytes, json::buffer::Target::ArrayBuffer);
        self.accessor(view, normals.len(), json::accessor::ComponentType::F32, json::accessor::Type::Vec3, None)
    }

    fn colors(&mut self, colors: &[[f32; 4]]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = colors.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, json::buffer::Target::ArrayBuffer);
        self.accessor(view, colors.len(), json::accessor::ComponentType::F32, json::accessor::Type::Vec4, None)
    }

    fn indices(&mut self, indices: &[u32]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = indices.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, json::buffer::Target::ElementArrayBuffer);
        self.accessor(view, indices.len(), json::accessor::ComponentType::U32, json::accessor::Type::Scalar, None)
    }

    fn primitive(
        &mut self,
        positions: &[[f64; 3]],
        indices: &[u32],
        normals: Option<&[[f32; 3]]>,
        colors: Option<&[[f32; 4]]>,
        material: Option<usize>,
        mode: json::mesh::Mode,
    ) -> json::mesh::Primitive {
        let mut attributes = BTreeMap::new();
        attributes.insert(Valid(json::mesh::Semantic::Positions), self.positions(positions));
        if let Some(n) = normals {
            attributes.insert(Valid(json::mesh::Semantic::Normals), self.normals(n));
        }
        if let Some(c) = colors {
            attributes.insert(Valid(json::mesh::Semantic::Colors(0)), self.colors(c));
        }
        let indices = self.indices(indices);
        json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: None,
            indices: Some(indices),
            material: material.map(|m| json::Index::new(self.material_map[&m])),
            mode: Valid(mode),
            targets: None,
        }
    }

    fn node(&mut self, n: &MeshNode) -> Result<json::Index<json::Node>, ExportError> {
        let mut primitives = Vec::new();
        for m in n.meshes.iter().filter(|m| !m.indices.is_empty()) {
            let p = self.primitive(
                &m.positions,
                &m.indices,
                m.normals.as_deref(),
                m.colors.as_deref(),
                m.material,
                json::mesh::Mode::Triangles,
            );
            primitives.push(p);
        }
        for l in n.lines.iter().filter(|l| !l.indices.is_empty()) {
            // MeshLab reads a LINES primitive as unindexed triangles over its POSITION accessor
            // and reads past the end when the vertex count is not a multiple of 3 (crash): pad
            // with repeats of the last vertex, which no index refers to (valid glTF).
            let pad = (3 - l.positions.len() % 3) % 3;
            let positions: Vec<[f64; 3]> = l
                .positions
                .iter()
                .chain(std::iter::repeat_n(l.positions.last().unwrap_or(&[0.0; 3]), pad))
                .copied()
                .collect();
            let colors: Option<Vec<[f32; 4]>> = l
                .colors
                .as_ref()
                .map(|c| c.iter().chain(std::iter::repeat_n(c.last().unwrap_or(&[0.0; 4]), pad)).copied().collect());
            let p =
                self.primitive(&positions, &l.indices, None, colors.as_deref(), l.material, json::mesh::Mode::Lines);
            primitives.push(p);
        }
        let mesh = if primitives.is_empty() {
            None
        } else {
            Some(self.root.push(json::Mesh {
                extensions: None,
                extras: None,
                name: Some(n.name.clone()),
                primitives,
                weights: None,
            }))
        };
        let mut children = Vec::new();
        for c in &n.children {
            children.push(self.node(c)?);
        }
        let extras = match &n.extras {
            Some(v) => Some(serde_json::value::to_raw_value(v).map_err(|e| ExportError::Json(e.to_string()))?),
            None => None,
        };
        Ok(self.root.push(json::Node {
            children: (!children.is_empty()).then_some(children),
            mesh,
            name: Some(n.name.clone()),
            extras,
            ..Default::default()
        }))
    }
}

fn build(scene: &Scene, uri: Option<BufferUri<'_>>) -> Result<(json::Root, Vec<u8>), ExportError> {
    scene.validate()?;
    let used = used_materials(scene);

    let mut b =
        Builder { root: json::Root::default(), bin: Vec::new(), origin: scene.origin, material_map: BTreeMap::new() };
    b.root.asset = json::Asset { version: "2.0".into(), generator: scene.generator.clone(), ..Default::default() };
    for (k, &mi) in used.iter().enumerate() {
        let m = &scene.materials[mi];
        b.material_map.insert(mi, k as u32);
        let alpha_mode =
            if m.rgba[3] < 1.0 { json::material::AlphaMode::Blend } else { json::material::AlphaMode::Opaque };
        b.root.push(json::Material {
            name: Some(m.name.clone()),
            alpha_mode: Valid(alpha_mode),
            double_sided: m.double_sided,
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor(m.rgba),
                metallic_factor: json::material::StrengthFactor(0.0),
                roughness_factor: json::material::StrengthFactor(1.0),
                ..Default::default()
            },
            ..Default::default()
        });
    }

    let mut top = Vec::new();
    for n in &scene.nodes {
        top.push(b.node(n)?);
    }
    let mut extras = serde_json::Map::new();
    extras.insert("origin".into(), serde_json::json!(scene.origin));
    if let Some(crs) = &scene.crs {
        extras.insert("crs".into(), serde_json::json!(crs));
    }
    extras.insert(
        "frame".into(),
        serde_json::json!("vertex data: source (Z-up) coordinates minus origin; this node's matrix turns them Y-up"),
    );
    let extras = serde_json::value::to_raw_value(&serde_json::Value::Object(extras))
        .map_err(|e| ExportError::Json(e.to_string()))?;
    let root_node = b.root.push(json::Node {
        children: (!top.is_empty()).then_some(top),
        matrix: Some(Z_UP_TO_Y_UP),
        name: Some("origin".into()),
        extras: Some(extras),
        ..Default::default()
    });
    let scene_index = b.root.push(json::Scene { extensions: None, extras: None, name: None, nodes: vec![root_node] });
    b.root.scene = Some(scene_index);

    if !b.bin.is_empty() {
        let uri = match uri {
            None => None,
            Some(BufferUri::Embed) => Some(format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&b.bin)
            )),
            Some(BufferUri::External(u)) => Some(u.to_string()),
        };
        b.root.push(json::Buffer {
            byte_length: USize64(b.bin.len() as u64),
            name: None,
            uri,
            extensions: None,
            extras: None,
        });
    }
    Ok((b.root, b.bin))
}

/// The indices of the materials that some non-empty mesh or line set refers to, sorted and
/// unique: only those are written, so the glTF holds no unused material.
fn used_materials(scene: &Scene) -> Vec<usize> {
    let mut used: Vec<usize> = scene
        .walk()
        .iter()
        .flat_map(|n| {
            let m = n.meshes.iter().filter(|m| !m.indices.is_empty()).filter_map(|m| m.material);
            m.chain(n.lines.iter().filter(|l| !l.indices.is_empty()).filter_map(|l| l.material)).collect::<Vec<_>>()
        })
        .collect();
    used.sort_unstable();
    used.dedup();
    used
}
