//! Streaming CityGML 1.0 / 2.0 / 3.0 reader and lossless writer.
//!
//! The reader builds a [`CityModel`] (objects, semantics, geometry, gml:ids, XLinks resolved) and
//! remembers the byte span of every coordinate text and geometry element. The writer never
//! re-serialises the document: it copies the source bytes and splices in [`Edit`]s, so everything the
//! model does not understand (ADEs, appearances, generic attributes, comments) is kept as it was.

pub mod model;

pub use model::*;
