//! Measurements from CSV (`geofit obj2popa3d --distances`, `geofit observe --add`).
//!
//! One measurement per line, comma-separated: `type,a,b,value,sigma`. `#` starts a comment line;
//! a first non-comment line starting with `type,` is a header. `type` is `distance` (the class follows from the
//! kinds of a and b) or a Table B.1 distance class name (`DistanceFaceFace`, ...). A primitive is
//! `face:ID`, `edge:ID`, `node:ID` (popa3d ids), `v:N` (the node of OBJ vertex N, 1-based as in the
//! OBJ file), or any other text = the face whose source polygon is that id (CityGML gml:id, or
//! `OBJECT/fK` for the K-th face of an OBJ object). Values in metres, σ > 0.

use crate::ids::*;
use crate::model::{Popa3d, VertexSource};
use crate::observation::*;
use std::collections::HashMap;
use thiserror::Error;

/// A CSV problem at a 1-based line and column (field start).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("line {line}, column {column}: {message}")]
pub struct CsvError {
    pub line: usize,
    pub column: usize,
    pub message: String,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Prim {
    Face(FaceId),
    Edge(EdgeId),
    Node(NodeId),
}

/// Parses distance observations and resolves their primitives against the model.
pub fn parse_distances(text: &str, m: &Popa3d) -> Result<Vec<Observation>, CsvError> {
    let resolver = Resolver::new(m);
    let mut out = Vec::new();
    let mut first = true;
    for (ln, raw) in text.lines().enumerate() {
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let header = first && t.to_ascii_lowercase().starts_with("type,");
        first = false;
        if !header {
            out.push(CsvLine::split(ln + 1, raw).observation(&resolver)?);
        }
    }
    Ok(out)
}

/// The model's primitives by the names a CSV line may give them.
struct Resolver<'m> {
    model: &'m Popa3d,
    /// The first face made from each source polygon id.
    by_polygon: HashMap<&'m str, FaceId>,
    /// The first node made from each OBJ vertex (0-based).
    by_vertex: HashMap<u32, NodeId>,
}

impl<'m> Resolver<'m> {
    fn new(m: &'m Popa3d) -> Resolver<'m> {
        let mut by_polygon: HashMap<&str, FaceId> = HashMap::new();
        for (i, f) in m.faces.iter().enumerate() {
            if let Some(s) = &f.source {
                by_polygon.entry(s.polygon.as_str()).or_insert(FaceId::from(i));
            }
        }
        let mut by_vertex: HashMap<u32, NodeId> = HashMap::new();
        for (i, n) in m.nodes.iter().enumerate() {
            for s in &n.sources {
                if let VertexSource::Obj { vertex } = s {
                    by_vertex.entry(*vertex).or_insert(NodeId::from(i));
                }
            }
        }
        Resolver { model: m, by_polygon, by_vertex }
    }
}

/// One measurement line: its 1-based number and its fields with their start columns.
struct CsvLine<'t> {
    line: usize,
    fields: Vec<(usize, &'t str)>,
}

impl<'t> CsvLine<'t> {
    fn split(line: usize, raw: &'t str) -> CsvLine<'t> {
        let mut fields: Vec<(usize, &str)> = Vec::new();
        let mut col = 1;
        for f in raw.split(',') {
            fields.push((col + (f.len() - f.trim_start().len()), f.trim()));
            col += f.len() + 1;
        }
        CsvLine { line, fields }
    }

    /// An error at field `k` (column 1 when the line has no such field).
    fn err(&self, k: usize, message: String) -> CsvError {
        CsvError { line: self.line, column: self.fields.get(k).map_or(1, |f| f.0), message }
    }

    /// The observation on this line; checks in field order, the type last.
    fn observation(&self, r: &Resolver) -> Result<Observation, CsvError> {
        if self.fields.len() != 5 {
            return Err(self.err(0, format!("expected 5 fields `type,a,b,value,sigma`, found {}", self.fields.len())));
        }
        let (a, b) = (self.primitive(1, r)?, self.primitive(2, r)?);
        let l = self.measured()?;
        let kind = distance_kind(a, b, l);
        let ty = self.fields[0].1;
        if ty != "distance" && ty != kind.class_name() {
            let q = input_limits::quote(ty);
            return Err(self.err(
                0,
                format!(
                    "type `{q}` does not match the primitives ({}); use `distance` or {}",
                    kind.class_name(),
                    kind.class_name()
                ),
            ));
        }
        Ok(Observation::new(kind, ObsOrigin::Measured).with_label(format!("csv line {}", self.line)))
    }

    /// The primitive field `k` names (see the module docs).
    fn primitive(&self, k: usize, r: &Resolver) -> Result<Prim, CsvError> {
        let s = self.fields[k].1;
        let q = input_limits::quote(s);
        if let Some(p) = s.strip_prefix("face:") {
            return Ok(Prim::Face(FaceId(self.element_id(k, &q, p, r.model.faces.len())?)));
        }
        if let Some(p) = s.strip_prefix("edge:") {
            return Ok(Prim::Edge(EdgeId(self.element_id(k, &q, p, r.model.edges.len())?)));
        }
        if let Some(p) = s.strip_prefix("node:") {
            return Ok(Prim::Node(NodeId(self.element_id(k, &q, p, r.model.nodes.len())?)));
        }
        if let Some(p) = s.strip_prefix("v:") {
            let v: u32 = p
                .parse()
                .map_err(|_| self.err(k, format!("`{q}`: `{}` is not a vertex number", input_limits::quote(p))))?;
            return v
                .checked_sub(1)
                .and_then(|v| r.by_vertex.get(&v).copied())
                .map(Prim::Node)
                .ok_or_else(|| self.err(k, format!("`{q}`: no node comes from OBJ vertex {v}")));
        }
        if s.is_empty() {
            return Err(self.err(k, "empty primitive reference".into()));
        }
        r.by_polygon
            .get(s)
            .copied()
            .map(Prim::Face)
            .ok_or_else(|| self.err(k, format!("`{q}`: no face comes from a source polygon with this id")))
    }

    /// The popa3d id `p` of field `k` (quoted whole as `q`), below the element count `n`.
    fn element_id(&self, k: usize, q: &str, p: &str, n: usize) -> Result<u32, CsvError> {
        p.parse::<u32>().map_err(|_| self.err(k, format!("`{q}`: `{}` is not an id", input_limits::quote(p)))).and_then(
            |v| {
                if (v as usize) < n {
                    Ok(v)
                } else {
                    Err(self.err(k, format!("`{q}`: no such element (the model has {n})")))
                }
            },
        )
    }

    /// The distance and its standard deviation (fields 3 and 4), MA11/MA12 checked.
    fn measured(&self) -> Result<Measured, CsvError> {
        let (value, sigma) = (self.finite(3)?, self.finite(4)?);
        if value < 0.0 {
            return Err(self.err(3, format!("MA11: a distance must be ≥ 0, found {value}")));
        }
        if sigma <= 0.0 {
            return Err(self.err(4, format!("MA12: a standard deviation must be > 0, found {sigma}")));
        }
        Ok(Measured::new(value, sigma))
    }

    fn finite(&self, k: usize) -> Result<f64, CsvError> {
        let s = self.fields[k].1;
        match s.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(self.err(k, format!("`{}` is not a finite number", input_limits::quote(s)))),
        }
    }
}

/// The Table B.1 distance class of two primitives given in either order; the class holds them
/// in its canonical order face < edge < node.
fn distance_kind(a: Prim, b: Prim, l: Measured) -> ObsKind {
    match (a, b) {
        (Prim::Face(a), Prim::Face(b)) => ObsKind::DistanceFaceFace { a, b, l },
        (Prim::Face(a), Prim::Edge(b)) | (Prim::Edge(b), Prim::Face(a)) => ObsKind::DistanceFaceEdge { a, b, l },
        (Prim::Face(a), Prim::Node(b)) | (Prim::Node(b), Prim::Face(a)) => ObsKind::DistanceFaceNode { a, b, l },
        (Prim::Edge(a), Prim::Edge(b)) => ObsKind::DistanceEdgeEdge { a, b, l },
        (Prim::Edge(a), Prim::Node(b)) | (Prim::Node(b), Prim::Edge(a)) => ObsKind::DistanceEdgeNode { a, b, l },
        (Prim::Node(a), Prim::Node(b)) => ObsKind::DistanceNodeNode { a, b, l },
    }
}
