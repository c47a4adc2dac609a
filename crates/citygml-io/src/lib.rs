//! Streaming CityGML 1.0 / 2.0 / 3.0 reader and lossless writer.
//!
//! The reader builds a [`CityModel`] (objects, semantics, geometry, gml:ids, XLinks resolved) and
//! remembers the byte span of every coordinate text and geometry element. The writer never
//! re-serialises the document: it copies the source bytes and splices in [`Edit`]s, so everything the
//! model does not understand (ADEs, appearances, generic attributes, comments) is kept as it was.
//!
//! - [`parse`]: a whole document into a [`CityModel`].
//! - [`ObjectStream`]: top-level objects one at a time (bounded memory for big tiles).
//! - [`write_with_edits`], [`format_coordinates`], [`ring_edits`]: lossless writing.
//! - [`summary::DocumentCounts`]: what a document holds, counted object by object.
//!
//! What the reader understands: the version from the namespaces (never the file name), a UTF-8
//! BOM, `gml:posList` / `gml:pos` / `gml:coordinates` with srsDimension 2 or 3, interior rings,
//! `gml:OrientableSurface orientation="-"`, MultiSurface / CompositeSurface / Solid /
//! CompositeSolid / MultiSolid (members inline or by `xlink:href`; a member that cannot be read
//! is listed in [`Geometry::skipped_members`], never dropped silently) / TIN, lod0–lod4 properties (CityGML 3.0 `core:lodN…` and
//! `core:boundary` included), Building / BuildingPart / Room / installation / boundary surface /
//! opening nesting, and every other top-level feature as an opaque object with id, type and
//! envelope. Geometric defects (a ring with 3 positions, an unclosed ring) are kept as written
//! for the validator; only what cannot be decoded at all is a [`ReadError`].

pub mod crs;
pub mod error;
mod lines;
pub mod model;
mod reader;
mod stream;
pub mod summary;
pub mod writer;

pub use error::{ReadError, WriteError};
pub use lines::LineIndex;
pub use model::*;
pub use stream::{parse, ObjectStream};
pub use writer::{format_coordinates, ring_edits, write_with_edits, Edit};
