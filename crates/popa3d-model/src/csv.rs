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
    let mut out = Vec::new();
    let mut first = true;
    for (ln, raw) in text.lines().enumerate() {
        let line = ln + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let header = first && t.to_ascii_lowercase().starts_with("type,");
        first = false;
        if header {
            continue;
        }
        // Field start columns for messages.
        let mut fields: Vec<(usize, &str)> = Vec::new();
        let mut col = 1;
        for f in raw.split(',') {
            fields.push((col + (f.len() - f.trim_start().len()), f.trim()));
            col += f.len() + 1;
        }
        let err = |k: usize, message: String| CsvError { line, column: fields.get(k).map_or(1, |f| f.0), message };
        if fields.len() != 5 {
            return Err(err(0, format!("expected 5 fields `type,a,b,value,sigma`, found {}", fields.len())));
        }
        let prim = |k: usize| -> Result<Prim, CsvError> {
            let s = fields[k].1;
            let q = input_limits::quote(s);
            let q = &q;
            let num = |p: &str, n: usize| -> Result<u32, CsvError> {
                p.parse::<u32>().map_err(|_| err(k, format!("`{q}`: `{}` is not an id", input_limits::quote(p))))
                    .and_then(|v| if (v as usize) < n { Ok(v) } else { Err(err(k, format!("`{q}`: no such element (the model has {n})"))) })
            };
            if let Some(p) = s.strip_prefix("face:") {
                return Ok(Prim::Face(FaceId(num(p, m.faces.len())?)));
            }
            if let Some(p) = s.strip_prefix("edge:") {
                return Ok(Prim::Edge(EdgeId(num(p, m.edges.len())?)));
            }
            if let Some(p) = s.strip_prefix("node:") {
                return Ok(Prim::Node(NodeId(num(p, m.nodes.len())?)));
            }
            if let Some(p) = s.strip_prefix("v:") {
                let v: u32 = p.parse().map_err(|_| err(k, format!("`{q}`: `{}` is not a vertex number", input_limits::quote(p))))?;
                return v
                    .checked_sub(1)
                    .and_then(|v| by_vertex.get(&v).copied())
                    .map(Prim::Node)
                    .ok_or_else(|| err(k, format!("`{q}`: no node comes from OBJ vertex {v}")));
            }
            if s.is_empty() {
                return Err(err(k, "empty primitive reference".into()));
            }
            by_polygon.get(s).copied().map(Prim::Face).ok_or_else(|| err(k, format!("`{q}`: no face comes from a source polygon with this id")))
        };
        let (a, b) = (prim(1)?, prim(2)?);
        let val = |k: usize| -> Result<f64, CsvError> {
            let s = fields[k].1;
            match s.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(err(k, format!("`{}` is not a finite number", input_limits::quote(s)))),
            }
        };
        let (value, sigma) = (val(3)?, val(4)?);
        if value < 0.0 {
            return Err(err(3, format!("MA11: a distance must be ≥ 0, found {value}")));
        }
        if sigma <= 0.0 {
            return Err(err(4, format!("MA12: a standard deviation must be > 0, found {sigma}")));
        }
        let l = Measured::new(value, sigma);
        // Canonical order face < edge < node.
        let rank = |p: &Prim| match p {
            Prim::Face(_) => 0,
            Prim::Edge(_) => 1,
            Prim::Node(_) => 2,
        };
        let (a, b) = if rank(&a) <= rank(&b) { (a, b) } else { (b, a) };
        let kind = match (a, b) {
            (Prim::Face(a), Prim::Face(b)) => ObsKind::DistanceFaceFace { a, b, l },
            (Prim::Face(a), Prim::Edge(b)) => ObsKind::DistanceFaceEdge { a, b, l },
            (Prim::Face(a), Prim::Node(b)) => ObsKind::DistanceFaceNode { a, b, l },
            (Prim::Edge(a), Prim::Edge(b)) => ObsKind::DistanceEdgeEdge { a, b, l },
            (Prim::Edge(a), Prim::Node(b)) => ObsKind::DistanceEdgeNode { a, b, l },
            (Prim::Node(a), Prim::Node(b)) => ObsKind::DistanceNodeNode { a, b, l },
            _ => unreachable!("ordered by rank"),
        };
        let ty = fields[0].1;
        if ty != "distance" && ty != kind.class_name() {
            return Err(err(0, format!("type `{}` does not match the primitives ({}); use `distance` or {}", input_limits::quote(ty), kind.class_name(), kind.class_name())));
        }
        out.push(Observation::new(kind, ObsOrigin::Measured).with_label(format!("csv line {line}")));
    }
    Ok(out)
}
