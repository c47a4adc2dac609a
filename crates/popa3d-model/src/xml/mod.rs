//! popa3d XML: writer and reader for the schema `xsd/popa3d.xsd` (spec §2.6, §10.2 item 17: names
//! decided here, observation elements named after the Table B.1 classes).
//!
//! Doubles are written in Rust's shortest round-trip form (`{:?}`), so every value reads back
//! bit-identical and write→read→write is byte-identical (spec §2.6: never a fixed 6-digit form).
//! Non-finite values are refused on write and on read: a popa3d document never holds NaN.

use crate::ids::*;
use crate::model::*;
use crate::observation::*;
use quick_xml::events::{BytesStart, Event};
use std::io::Write;
use thiserror::Error;

mod reader;
mod writer;

pub use self::reader::read;
pub use self::writer::{write, write_to_vec};

/// The namespace of popa3d documents.
pub const NAMESPACE: &str = "urn:geofit:popa3d:1";
/// The format version written in `popa3d/@version`.
pub const VERSION: &str = "1";

#[derive(Debug, Error)]
pub enum XmlError {
    /// Malformed XML or a document that does not follow the schema, at 1-based line:column.
    #[error("{line}:{column}: {message}")]
    Syntax { line: usize, column: usize, message: String },
    /// A value that cannot be written (NaN or infinite), naming the element.
    #[error("cannot write {element}: {message}")]
    Value { element: String, message: String },
    #[error("write failed: {0}")]
    Io(#[from] std::io::Error),
}

/// A reference from an observation to a model element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ref {
    Face(FaceId),
    Edge(EdgeId),
    Node(NodeId),
    Plane(PlaneId),
    Normal(NormalId),
    Param(ParamId),
    FixedPoint(FixedPointId),
    Setup(SetupId),
}

/// Every element an observation references.
pub fn observation_refs(k: &ObsKind) -> Vec<Ref> {
    use ObsKind::*;
    let unk = |u: &Unknown| match *u {
        Unknown::PlaneD(p) => Ref::Plane(p),
        Unknown::Param(p) => Ref::Param(p),
        Unknown::Translation(f, _) => Ref::FixedPoint(f),
        Unknown::Rotation(s, _) => Ref::Setup(s),
    };
    match k {
        DistanceFaceFace { a, b, .. } | ConstraintFaceFace { a, b, .. } => vec![Ref::Face(*a), Ref::Face(*b)],
        DistanceFaceEdge { a, b, .. } | ConstraintFaceEdge { a, b, .. } => vec![Ref::Face(*a), Ref::Edge(*b)],
        DistanceFaceNode { a, b, .. } => vec![Ref::Face(*a), Ref::Node(*b)],
        DistanceEdgeEdge { a, b, .. } | ConstraintEdgeEdge { a, b, .. } => vec![Ref::Edge(*a), Ref::Edge(*b)],
        DistanceEdgeNode { a, b, .. } => vec![Ref::Edge(*a), Ref::Node(*b)],
        DistanceNodeNode { a, b, .. } => vec![Ref::Node(*a), Ref::Node(*b)],
        PointOnFace { setup, target, .. } => vec![Ref::Setup(*setup), Ref::Face(*target)],
        PointOnEdge { setup, target, .. } => vec![Ref::Setup(*setup), Ref::Edge(*target)],
        PointOnNode { setup, target, .. } => vec![Ref::Setup(*setup), Ref::Node(*target)],
        RelativeDistancePlanePlane { lower, upper, .. } => vec![Ref::Plane(*lower), Ref::Plane(*upper)],
        RelativeAngleNormalNormal { a, b, .. } => vec![Ref::Normal(*a), Ref::Normal(*b)],
        NormNV { normal, .. } => vec![Ref::Normal(*normal)],
        NormQ { setup } => vec![Ref::Setup(*setup)],
        ParameterFix { unknown, .. } | ParameterObs { unknown, .. } => vec![unk(unknown)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(body: &str) -> String {
        format!("<?xml version=\"1.0\"?>\n<popa3d xmlns=\"{NAMESPACE}\" version=\"1\">\n  <origin x=\"0\" y=\"0\" z=\"0\"/>\n{body}</popa3d>\n")
    }

    fn err(s: &str) -> String {
        read(s.as_bytes()).unwrap_err().to_string()
    }

    #[test]
    fn malformed_documents_get_line_and_column() {
        let e = err(&doc("  <nodes><node id=\"0\"/><node id=\"1\"/></nodes>\n  <edges>\n    <edge id=\"0\" start=\"0\"/>\n  </edges>\n"));
        assert_eq!(e, "6:5: <edge>: missing attribute `end`");
        let e = err(&doc(
            "  <nodes><node id=\"0\"/></nodes>\n  <edges>\n    <edge id=\"0\" start=\"0\" end=\"7\"/>\n  </edges>\n",
        ));
        assert!(e.starts_with("6:5: MA02: edge 0 references node 7"), "{e}");
        let e = err(&doc("  <nodes><node id=\"0\"/><node id=\"0\"/></nodes>\n"));
        assert!(e.contains("MA01: duplicate node id 0"), "{e}");
        let e = err(&doc("  <parameters><parameter id=\"0\" value=\"NaN\"/></parameters>\n"));
        assert!(e.starts_with("4:15: <parameter>: attribute `value`=\"NaN\" is not a finite number"), "{e}");
        let e = err(&doc("  <nodes><node id=\"0\"></nodes>\n"));
        assert!(e.starts_with("4:") && e.contains("malformed XML"), "{e}");
        let e = err("<city/>");
        assert!(e.contains("root element must be <popa3d>"), "{e}");
    }

    #[test]
    fn doubles_round_trip_bit_identical() {
        let mut m = Popa3d::new([345678.123456789, 5712345.000000001, -0.0]);
        for v in [0.1, 1.0 / 3.0, f64::MIN_POSITIVE, 0.70710678118654857, -1.0, 5e-324, 1e300] {
            m.add_parameter(Parameter { value: v });
        }
        let a = write_to_vec(&m).unwrap();
        let b = read(&a).unwrap();
        for (x, y) in m.parameters.iter().zip(&b.parameters) {
            assert_eq!(x.value.to_bits(), y.value.to_bits());
        }
        assert_eq!(m.origin.map(f64::to_bits), b.origin.map(f64::to_bits));
        assert_eq!(write_to_vec(&b).unwrap(), a);
        m.parameters[0].value = f64::NAN;
        assert!(write_to_vec(&m).unwrap_err().to_string().contains("parameter 0"));
    }
}
