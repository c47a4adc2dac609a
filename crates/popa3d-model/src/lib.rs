//! popa3d: a plane-parameterised 3D building model after Clemen (2010); the sections it follows
//! (§1–§3) are summarised in docs/sources.md#popa3d.
//!
//! * Topology ([`Node`], [`Edge`], [`HalfEdge`], [`Face`], [`Solid`]) is explicit and stores no
//!   coordinates: a node's position is the intersection of the planes of its faces (spec §2.2).
//! * Geometry is [`Plane`] → signed [`NormalVector`] → three signed [`Parameter`]s. Sharing a plane
//!   encodes coplanarity, sharing a normal parallelism, sharing parameters (with swap and sign)
//!   orthogonality (spec §2.3).
//! * Observations and conditions ([`Observation`], [`ObsKind`]) are the classes of Table B.1, each
//!   with value and σ (spec §2.5); survey set-ups ([`FixedPoint`], [`Setup`]) carry the unknowns of
//!   polar observations (spec §2.4).
//! * All coordinates are relative to [`Popa3d::origin`] (a local origin near the model), so that plane
//!   distances stay small for UTM-sized coordinates and the normal equations are well conditioned.
//! * Provenance ties every node and face back to its source (CityGML polygon/ring/vertex or OBJ vertex)
//!   for the way back to CityGML.
//!
//! Element ids are dense per-type indices (`NodeId(5)` is `model.nodes[5]`), which makes MA01
//! (uniqueness per type namespace) structural; the XML reader enforces density with a precise message.
//!
//! # Examples
//!
//! A box far from the origin (UTM-sized coordinates, built by `normalize` from an OBJ sketch),
//! written as popa3d XML and read back: the same planes, the same corners.
//!
//! ```
//! use popa3d_model::{read, write_to_vec, Incidence, Popa3d};
//! let obj = b"o room\nv 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n\
//! f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
//! let soup = normalize::obj::read_sketch(obj, "box.obj").unwrap();
//! let mut model = Popa3d::new([-2.0, -1.5, -1.0]); // a local origin inside the box
//! normalize::normalize_into(&mut model, &soup, &normalize::Tolerances::default()).unwrap();
//! assert_eq!((model.nodes.len(), model.faces.len(), model.planes.len(), model.normals.len()), (8, 6, 6, 3));
//!
//! let again = read(&write_to_vec(&model).unwrap()).unwrap();
//! let corners = |m: &Popa3d| m.node_positions(&Incidence::new(m)).unwrap();
//! for (a, b) in corners(&model).iter().zip(corners(&again)) {
//!     assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-9));
//! }
//! ```

pub mod csv;
pub mod geometry;
pub mod ids;
pub mod model;
pub mod observation;
pub mod topology;
pub mod validate;
pub mod vec3;
pub mod xml;

pub use geometry::GeometryError;
pub use ids::*;
pub use model::*;
pub use observation::*;
pub use topology::Incidence;
pub use xml::{read, write, write_to_vec, XmlError};
