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

pub mod csv;
pub mod geometry;
pub mod ids;
pub mod model;
pub mod observation;
pub mod topology;
pub mod validate;
pub mod xml;

pub use geometry::GeometryError;
pub use ids::*;
pub use model::*;
pub use observation::*;
pub use topology::Incidence;
pub use xml::{read, write, write_to_vec, XmlError};
