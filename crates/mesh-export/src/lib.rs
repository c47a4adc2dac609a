//! Triangle meshes out: glTF 2.0 (`.glb`, `.gltf`) and Wavefront OBJ (+ MTL).
//!
//! This crate knows nothing of buildings, splines or implicit surfaces: callers build a [`Scene`]
//! — a tree of named [`MeshNode`]s, each with [`TriangleMesh`]es (one per material) and
//! [`LineSet`]s, a [`Material`] table, and an `origin` — and hand it to a writer.
//!
//! # Examples
//!
//! ```
//! use mesh_export::{Material, MeshNode, Scene, TriangleMesh};
//! let mut scene = Scene { materials: vec![Material::new("roof", [0.8, 0.2, 0.1, 1.0])], ..Default::default() };
//! let mut node = MeshNode::new("building-1");
//! let mut mesh = TriangleMesh::new(Some(0));
//! mesh.positions = vec![[458000.0, 5438000.0, 10.0], [458010.0, 5438000.0, 10.0], [458000.0, 5438010.0, 10.0]];
//! mesh.indices = vec![0, 1, 2];
//! node.meshes.push(mesh);
//! scene.nodes.push(node);
//! scene.origin = scene.auto_origin(); // large UTM coordinates → small local ones, offset recorded
//! let mut glb = Vec::new();
//! mesh_export::write_glb(&scene, &mut glb).unwrap();
//! let (mut obj, mut mtl) = (Vec::new(), Vec::new());
//! mesh_export::write_obj(&scene, &mut obj, Some(("model.mtl", &mut mtl))).unwrap();
//! ```
//!
//! Guarantees: output is a pure function of the scene (byte-identical for identical input); no
//! NaN or out-of-range index is ever written ([`Scene::validate`] runs first); glTF output passes
//! the Khronos glTF-Validator (see [`gltf`] for the layout and how the origin is recorded).

pub mod colour;
pub mod gltf;
pub mod obj;
pub mod scene;
pub mod triangulate;
pub mod vec3;

pub use gltf::{write_glb, write_gltf, GltfBuffer};
pub use obj::{write_mtl, write_obj};
pub use scene::{LineSet, Material, MeshNode, Scene, TriangleMesh};
pub use triangulate::{triangulate_polygon, PolygonTriangles, TriangulateError};

/// What can go wrong while writing.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("node `{node}`: {what}")]
    InvalidMesh { node: String, what: String },
    #[error("node `{node}`: a coordinate is NaN or infinite")]
    NonFinite { node: String },
    #[error("material `{name}`: colour component outside 0..=1 or not finite")]
    InvalidMaterial { name: String },
    #[error("output of {0} bytes exceeds the 4 GiB limit of a .glb file")]
    TooLarge(usize),
    #[error("glTF JSON: {0}")]
    Json(String),
    #[error("write failed: {0}")]
    Io(#[from] std::io::Error),
}

#[cfg(test)]
mod tests;
