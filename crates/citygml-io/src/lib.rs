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
//!
//! # Examples
//!
//! Read a document, move one vertex, write it back: only the coordinate text changes.
//!
//! ```
//! let gml = br#"<?xml version="1.0" encoding="UTF-8"?>
//! <CityModel xmlns="http://www.opengis.net/citygml/2.0" xmlns:bldg="http://www.opengis.net/citygml/building/2.0"
//!   xmlns:gml="http://www.opengis.net/gml">
//!   <cityObjectMember><bldg:Building gml:id="B1"><!-- kept -->
//!     <bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon gml:id="roof">
//!       <gml:exterior><gml:LinearRing><gml:posList>0 0 0 1 0 0 1 1 0 0 0 0</gml:posList></gml:LinearRing></gml:exterior>
//!     </gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface>
//!   </bldg:Building></cityObjectMember>
//! </CityModel>"#;
//! let model = citygml_io::parse(gml).unwrap();
//! assert_eq!(model.version.as_str(), "2.0");
//! let building = &model.objects[0];
//! assert_eq!((building.id.as_deref(), building.kind.as_str()), (Some("B1"), "Building"));
//! let ring = &building.all_polygons()[0].exterior;
//! assert_eq!(ring.points.len(), 4);
//!
//! let mut moved = ring.points.clone();
//! moved[2] = [1.0, 2.0, 0.0];
//! let edits = citygml_io::ring_edits(ring, &moved).unwrap();
//! let mut out = Vec::new();
//! citygml_io::write_with_edits(gml, &edits, &mut out).unwrap();
//! let text = String::from_utf8(out).unwrap();
//! assert!(text.contains("<gml:posList>0 0 0 1 0 0 1 2 0 0 0 0</gml:posList>"));
//! assert!(text.contains("<!-- kept -->"));
//! assert_eq!(text.len(), gml.len()); // nothing else was re-serialised
//! ```

pub mod crs;
pub mod error;
pub mod frame;
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
