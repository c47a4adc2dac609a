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

// ---------------------------------------------------------------------------------------------
// Writer

fn num(x: f64, what: &dyn Fn() -> String) -> Result<String, XmlError> {
    if x.is_finite() {
        Ok(format!("{x:?}"))
    } else {
        Err(XmlError::Value { element: what(), message: format!("value {x} is not finite") })
    }
}

fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&apos;"),
            '\n' => o.push_str("&#10;"),
            '\r' => o.push_str("&#13;"),
            '\t' => o.push_str("&#9;"),
            c => o.push(c),
        }
    }
    o
}

fn sgn(s: Sign) -> &'static str {
    match s {
        Sign::Plus => "1",
        Sign::Minus => "-1",
    }
}

/// Writes the document into a byte vector.
pub fn write_to_vec(m: &Popa3d) -> Result<Vec<u8>, XmlError> {
    let mut v = Vec::new();
    write(m, &mut v)?;
    Ok(v)
}

/// Writes the document. The output is a pure function of the model (byte-identical for equal models).
pub fn write<W: Write + ?Sized>(m: &Popa3d, w: &mut W) -> Result<(), XmlError> {
    let mut o = String::with_capacity(256 + m.half_edges.len() * 56 + m.nodes.len() * 80);
    write_header(&mut o, m)?;
    write_topology(&mut o, m)?;
    write_geometry(&mut o, m)?;
    write_survey(&mut o, m)?;
    o.push_str("</popa3d>\n");
    w.write_all(o.as_bytes())?;
    Ok(())
}

/// The XML declaration, the root's start tag, `<origin>` and `<source>`.
fn write_header(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
    use std::fmt::Write as _;
    o.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(o, "<popa3d xmlns=\"{NAMESPACE}\" version=\"{VERSION}\">");
    let org = |k: usize| num(m.origin[k], &|| "origin".into());
    let _ = write!(o, "  <origin x=\"{}\" y=\"{}\" z=\"{}\"", org(0)?, org(1)?, org(2)?);
    if let Some(s) = &m.srs_name {
        let _ = write!(o, " srsName=\"{}\"", esc(s));
    }
    o.push_str("/>\n");
    if let Some(s) = &m.source {
        let _ = writeln!(o, "  <source format=\"{}\" file=\"{}\"/>", esc(&s.format), esc(&s.file));
    }
    Ok(())
}

/// Solids, nodes, edges (with the vertices on them), half-edges and faces.
fn write_topology(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
    use std::fmt::Write as _;
    section(o, "solids", m.solids.len(), |o| {
        for (i, s) in m.solids.iter().enumerate() {
            let _ = write!(o, "    <solid id=\"{i}\" kind=\"{}\"", s.kind.as_str());
            if let Some(n) = &s.name {
                let _ = write!(o, " name=\"{}\"", esc(n));
            }
            o.push_str("/>\n");
        }
        Ok(())
    })?;
    section(o, "nodes", m.nodes.len(), |o| {
        for (i, n) in m.nodes.iter().enumerate() {
            if n.sources.is_empty() {
                let _ = writeln!(o, "    <node id=\"{i}\"/>");
                continue;
            }
            let _ = write!(o, "    <node id=\"{i}\">");
            for s in &n.sources {
                write_src(o, s);
            }
            o.push_str("</node>\n");
        }
        Ok(())
    })?;
    section(o, "edges", m.edges.len(), |o| {
        for (i, e) in m.edges.iter().enumerate() {
            let _ = writeln!(o, "    <edge id=\"{i}\" start=\"{}\" end=\"{}\"/>", e.start.0, e.end.0);
        }
        Ok(())
    })?;
    write_edge_vertices(o, m);
    section(o, "halfedges", m.half_edges.len(), |o| {
        for (i, h) in m.half_edges.iter().enumerate() {
            let _ = writeln!(
                o,
                "    <halfedge id=\"{i}\" edge=\"{}\" sign=\"{}\" face=\"{}\"/>",
                h.edge.0,
                sgn(h.sign),
                h.face.0
            );
        }
        Ok(())
    })?;
    section(o, "faces", m.faces.len(), |o| {
        for (i, f) in m.faces.iter().enumerate() {
            write_face(o, i, f);
        }
        Ok(())
    })
}

/// `<edgevertices>`: the source vertices lying on edges (only when there are any).
fn write_edge_vertices(o: &mut String, m: &Popa3d) {
    use std::fmt::Write as _;
    if m.edge_vertices.is_empty() {
        return;
    }
    o.push_str("  <edgevertices>\n");
    for ev in &m.edge_vertices {
        let _ = write!(o, "    <on edge=\"{}\">", ev.edge.0);
        for s in &ev.sources {
            write_src(o, s);
        }
        o.push_str("</on>\n");
    }
    o.push_str("  </edgevertices>\n");
}

fn write_face(o: &mut String, i: usize, f: &Face) {
    use std::fmt::Write as _;
    let _ = write!(
        o,
        "    <face id=\"{i}\" plane=\"{}\" orientation=\"{}\" front=\"{}\" back=\"{}\"",
        f.plane.0,
        sgn(f.orientation),
        f.front.0,
        f.back.0
    );
    if let Some(s) = &f.source {
        let _ = write!(o, " polygon=\"{}\"", esc(&s.polygon));
        if let Some(t) = &s.semantic {
            let _ = write!(o, " semantic=\"{}\"", esc(t));
        }
        if let Some(t) = &s.owner {
            let _ = write!(o, " owner=\"{}\"", esc(t));
        }
        if !s.merged.is_empty() {
            let _ = write!(o, " merged=\"{}\"", esc(&s.merged.join(" ")));
        }
    }
    o.push_str("/>\n");
}

/// Planes, normals and parameters.
fn write_geometry(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
    use std::fmt::Write as _;
    section(o, "planes", m.planes.len(), |o| {
        for (i, p) in m.planes.iter().enumerate() {
            let d = num(p.d, &|| format!("plane {i}"))?;
            let _ = writeln!(o, "    <plane id=\"{i}\" normal=\"{}\" sign=\"{}\" d=\"{d}\"/>", p.normal.0, sgn(p.sign));
        }
        Ok(())
    })?;
    section(o, "normals", m.normals.len(), |o| {
        for (i, n) in m.normals.iter().enumerate() {
            let c = n.comps;
            let _ = writeln!(
                o,
                "    <normal id=\"{i}\" x=\"{}\" sx=\"{}\" y=\"{}\" sy=\"{}\" z=\"{}\" sz=\"{}\"/>",
                c[0].0 .0,
                sgn(c[0].1),
                c[1].0 .0,
                sgn(c[1].1),
                c[2].0 .0,
                sgn(c[2].1)
            );
        }
        Ok(())
    })?;
    section(o, "parameters", m.parameters.len(), |o| {
        for (i, p) in m.parameters.iter().enumerate() {
            let v = num(p.value, &|| format!("parameter {i}"))?;
            let _ = writeln!(o, "    <parameter id=\"{i}\" value=\"{v}\"/>");
        }
        Ok(())
    })
}

/// Fixed points, set-ups and observations.
fn write_survey(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
    use std::fmt::Write as _;
    section(o, "fixedpoints", m.fixed_points.len(), |o| {
        for (i, p) in m.fixed_points.iter().enumerate() {
            let f = |k: usize| num(p.t[k], &|| format!("fixedpoint {i}"));
            let _ = writeln!(o, "    <fixedpoint id=\"{i}\" tx=\"{}\" ty=\"{}\" tz=\"{}\"/>", f(0)?, f(1)?, f(2)?);
        }
        Ok(())
    })?;
    section(o, "setups", m.setups.len(), |o| {
        for (i, s) in m.setups.iter().enumerate() {
            let f = |x: f64| num(x, &|| format!("setup {i}"));
            let _ = writeln!(
                o,
                "    <setup id=\"{i}\" fixedpoint=\"{}\" ih=\"{}\" q0=\"{}\" q1=\"{}\" q2=\"{}\" q3=\"{}\" levelled=\"{}\"/>",
                s.fixed_point.0,
                f(s.instrument_height)?,
                f(s.q[0])?,
                f(s.q[1])?,
                f(s.q[2])?,
                f(s.q[3])?,
                s.levelled
            );
        }
        Ok(())
    })?;
    section(o, "observations", m.observations.len(), |o| {
        for (i, ob) in m.observations.iter().enumerate() {
            write_observation(o, i, ob)?;
        }
        Ok(())
    })
}

fn write_src(o: &mut String, s: &VertexSource) {
    use std::fmt::Write as _;
    match s {
        VertexSource::CityGml { polygon, ring, index } => {
            let _ = write!(o, "<src polygon=\"{}\" ring=\"{ring}\" index=\"{index}\"/>", esc(polygon));
        }
        VertexSource::Obj { vertex } => {
            let _ = write!(o, "<src vertex=\"{vertex}\"/>");
        }
    }
}

fn section(
    o: &mut String,
    name: &str,
    len: usize,
    body: impl FnOnce(&mut String) -> Result<(), XmlError>,
) -> Result<(), XmlError> {
    if len == 0 {
        o.push_str(&format!("  <{name}/>\n"));
        return Ok(());
    }
    o.push_str(&format!("  <{name}>\n"));
    body(o)?;
    o.push_str(&format!("  </{name}>\n"));
    Ok(())
}

fn unknown_attrs(u: &Unknown) -> String {
    match *u {
        Unknown::PlaneD(p) => format!("plane=\"{}\"", p.0),
        Unknown::Param(p) => format!("parameter=\"{}\"", p.0),
        Unknown::Translation(f, k) => format!("fixedpoint=\"{}\" component=\"{k}\"", f.0),
        Unknown::Rotation(s, k) => format!("setup=\"{}\" component=\"{k}\"", s.0),
    }
}

fn write_observation(o: &mut String, i: usize, ob: &Observation) -> Result<(), XmlError> {
    use std::fmt::Write as _;
    use ObsKind::*;
    let el = ob.kind.class_name();
    let what = || format!("{el} {i}");
    let vs = |l: &Measured| -> Result<String, XmlError> {
        Ok(format!("value=\"{}\" sigma=\"{}\"", num(l.value, &what)?, num(l.sigma, &what)?))
    };
    let body = match &ob.kind {
        DistanceFaceFace { a, b, l } | ConstraintFaceFace { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceFaceEdge { a, b, l } | ConstraintFaceEdge { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceFaceNode { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceEdgeEdge { a, b, l } | ConstraintEdgeEdge { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceEdgeNode { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceNodeNode { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        PointOnFace { setup, target, hz, v, s } => polar(setup.0, target.0, hz, v, s, &what)?,
        PointOnEdge { setup, target, hz, v, s } => polar(setup.0, target.0, hz, v, s, &what)?,
        PointOnNode { setup, target, hz, v, s } => polar(setup.0, target.0, hz, v, s, &what)?,
        RelativeDistancePlanePlane { lower, upper, l } => format!("lower=\"{}\" upper=\"{}\" {}", lower.0, upper.0, vs(l)?),
        RelativeAngleNormalNormal { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        NormNV { normal, sigma } => match sigma {
            Some(s) => format!("normal=\"{}\" sigma=\"{}\"", normal.0, num(*s, &what)?),
            None => format!("normal=\"{}\"", normal.0),
        },
        NormQ { setup } => format!("setup=\"{}\"", setup.0),
        ParameterFix { unknown, value } => format!("{} value=\"{}\"", unknown_attrs(unknown), num(*value, &what)?),
        ParameterObs { unknown, l } => format!("{} {}", unknown_attrs(unknown), vs(l)?),
    };
    let _ = write!(o, "    <{el} id=\"{i}\" {body} origin=\"{}\"", ob.origin.as_str());
    if let Some(b) = ob.induced_by {
        let _ = write!(o, " inducedBy=\"{}\"", b.0);
    }
    if let Some(l) = &ob.label {
        let _ = write!(o, " label=\"{}\"", esc(l));
    }
    o.push_str("/>\n");
    Ok(())
}

fn polar(setup: u32, target: u32, hz: &Measured, v: &Measured, s: &Measured, what: &dyn Fn() -> String) -> Result<String, XmlError> {
    Ok(format!(
        "setup=\"{setup}\" target=\"{target}\" hz=\"{}\" hzSigma=\"{}\" v=\"{}\" vSigma=\"{}\" s=\"{}\" sSigma=\"{}\"",
        num(hz.value, what)?,
        num(hz.sigma, what)?,
        num(v.value, what)?,
        num(v.sigma, what)?,
        num(s.value, what)?,
        num(s.sigma, what)?
    ))
}

// ---------------------------------------------------------------------------------------------
// Reader

/// Line/column lookup for byte offsets.
struct Lines {
    starts: Vec<usize>,
}

impl Lines {
    fn new(b: &[u8]) -> Lines {
        let mut starts = vec![0];
        for (i, c) in b.iter().enumerate() {
            if *c == b'\n' {
                starts.push(i + 1);
            }
        }
        Lines { starts }
    }
    fn at(&self, pos: usize) -> (usize, usize) {
        let l = match self.starts.binary_search(&pos) {
            Ok(i) => i,
            Err(i) => i - 1,
        };
        (l + 1, pos - self.starts[l] + 1)
    }
}

/// One element's attributes, with its position for messages.
struct El {
    name: String,
    attrs: Vec<(String, String)>,
    line: usize,
    column: usize,
}

impl El {
    fn err(&self, message: impl Into<String>) -> XmlError {
        XmlError::Syntax { line: self.line, column: self.column, message: format!("<{}>: {}", input_limits::quote(&self.name), message.into()) }
    }
    /// An attribute whose value is wrong; the value is quoted at most ~200 bytes long.
    fn bad(&self, k: &str, v: &str, what: &str) -> XmlError {
        self.err(format!("attribute `{}`=\"{}\" {what}", input_limits::quote(k), input_limits::quote(v)))
    }
    fn opt(&self, k: &str) -> Option<&str> {
        self.attrs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str())
    }
    fn req(&self, k: &str) -> Result<&str, XmlError> {
        self.opt(k).ok_or_else(|| self.err(format!("missing attribute `{k}`")))
    }
    fn u32(&self, k: &str) -> Result<u32, XmlError> {
        let v = self.req(k)?;
        v.trim().parse::<u32>().map_err(|_| self.bad(k, v, "is not a non-negative integer id"))
    }
    fn f64(&self, k: &str) -> Result<f64, XmlError> {
        let v = self.req(k)?;
        let t = v.trim();
        // xs:double lexical form; Rust's parser also takes "inf"/"nan", which a popa3d document never holds.
        match t.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            Ok(_) => Err(self.bad(k, v, "is not a finite number")),
            Err(_) => Err(self.bad(k, v, "is not a number")),
        }
    }
    fn sign(&self, k: &str) -> Result<Sign, XmlError> {
        match self.req(k)?.trim() {
            "1" | "+1" => Ok(Sign::Plus),
            "-1" => Ok(Sign::Minus),
            v => Err(self.bad(k, v, "must be 1 or -1")),
        }
    }
    fn bool(&self, k: &str) -> Result<bool, XmlError> {
        match self.req(k)?.trim() {
            "true" | "1" => Ok(true),
            "false" | "0" => Ok(false),
            v => Err(self.bad(k, v, "must be true or false")),
        }
    }
    fn measured(&self, v: &str, s: &str) -> Result<Measured, XmlError> {
        Ok(Measured { value: self.f64(v)?, sigma: self.f64(s)? })
    }
}

/// Elements of one type collected with their ids, then checked to be 0..n in any order.
struct Table<T> {
    kind: &'static str,
    items: Vec<(u32, T, usize, usize)>,
}

impl<T> Table<T> {
    fn new(kind: &'static str) -> Self {
        Table { kind, items: Vec::new() }
    }
    fn push(&mut self, el: &El, v: T) -> Result<(), XmlError> {
        let id = el.u32("id")?;
        self.items.push((id, v, el.line, el.column));
        Ok(())
    }
    /// Sorted by id; ids must be exactly 0..n (MA01 and the dense-id convention).
    fn finish(mut self) -> Result<(Vec<T>, Vec<(usize, usize)>), XmlError> {
        self.items.sort_by_key(|x| x.0);
        let mut out = Vec::with_capacity(self.items.len());
        let mut pos = Vec::with_capacity(self.items.len());
        for (i, (id, v, line, column)) in self.items.into_iter().enumerate() {
            if id as usize != i {
                let message = if (id as usize) < i {
                    format!("MA01: duplicate {} id {id}", self.kind)
                } else {
                    format!("{} ids must be numbered 0..n without gaps: id {i} is missing (found {id})", self.kind)
                };
                return Err(XmlError::Syntax { line, column, message });
            }
            out.push(v);
            pos.push((line, column));
        }
        Ok((out, pos))
    }
}

fn parse_unknown(el: &El) -> Result<Unknown, XmlError> {
    let comp = |max: u8| -> Result<u8, XmlError> {
        let c = el.u32("component")?;
        if c >= max as u32 {
            return Err(el.err(format!("component {c} out of range 0..{}", max - 1)));
        }
        Ok(c as u8)
    };
    let given: Vec<&str> = ["plane", "parameter", "fixedpoint", "setup"].into_iter().filter(|k| el.opt(k).is_some()).collect();
    if given.len() != 1 {
        return Err(el.err("exactly one of the attributes plane, parameter, fixedpoint, setup is required"));
    }
    Ok(match given[0] {
        "plane" => Unknown::PlaneD(PlaneId(el.u32("plane")?)),
        "parameter" => Unknown::Param(ParamId(el.u32("parameter")?)),
        "fixedpoint" => Unknown::Translation(FixedPointId(el.u32("fixedpoint")?), comp(3)?),
        _ => Unknown::Rotation(SetupId(el.u32("setup")?), comp(4)?),
    })
}

fn parse_observation(el: &El) -> Result<ObsKind, XmlError> {
    use ObsKind::*;
    let l = || el.measured("value", "sigma");
    let ab = |k: &str| el.u32(k);
    let pol = || -> Result<(SetupId, u32, Measured, Measured, Measured), XmlError> {
        Ok((
            SetupId(el.u32("setup")?),
            el.u32("target")?,
            el.measured("hz", "hzSigma")?,
            el.measured("v", "vSigma")?,
            el.measured("s", "sSigma")?,
        ))
    };
    Ok(match el.name.as_str() {
        "DistanceFaceFace" => DistanceFaceFace { a: FaceId(ab("a")?), b: FaceId(ab("b")?), l: l()? },
        "DistanceFaceEdge" => DistanceFaceEdge { a: FaceId(ab("a")?), b: EdgeId(ab("b")?), l: l()? },
        "DistanceFaceNode" => DistanceFaceNode { a: FaceId(ab("a")?), b: NodeId(ab("b")?), l: l()? },
        "DistanceEdgeEdge" => DistanceEdgeEdge { a: EdgeId(ab("a")?), b: EdgeId(ab("b")?), l: l()? },
        "DistanceEdgeNode" => DistanceEdgeNode { a: EdgeId(ab("a")?), b: NodeId(ab("b")?), l: l()? },
        "DistanceNodeNode" => DistanceNodeNode { a: NodeId(ab("a")?), b: NodeId(ab("b")?), l: l()? },
        "PointOnFace" => {
            let (setup, t, hz, v, s) = pol()?;
            PointOnFace { setup, target: FaceId(t), hz, v, s }
        }
        "PointOnEdge" => {
            let (setup, t, hz, v, s) = pol()?;
            PointOnEdge { setup, target: EdgeId(t), hz, v, s }
        }
        "PointOnNode" => {
            let (setup, t, hz, v, s) = pol()?;
            PointOnNode { setup, target: NodeId(t), hz, v, s }
        }
        "ConstraintFaceFace" => ConstraintFaceFace { a: FaceId(ab("a")?), b: FaceId(ab("b")?), l: l()? },
        "ConstraintFaceEdge" => ConstraintFaceEdge { a: FaceId(ab("a")?), b: EdgeId(ab("b")?), l: l()? },
        "ConstraintEdgeEdge" => ConstraintEdgeEdge { a: EdgeId(ab("a")?), b: EdgeId(ab("b")?), l: l()? },
        "RelativeDistancePlanePlane" => {
            RelativeDistancePlanePlane { lower: PlaneId(ab("lower")?), upper: PlaneId(ab("upper")?), l: l()? }
        }
        "RelativeAngleNormalNormal" => RelativeAngleNormalNormal { a: NormalId(ab("a")?), b: NormalId(ab("b")?), l: l()? },
        "NormNV" => NormNV {
            normal: NormalId(ab("normal")?),
            sigma: if el.opt("sigma").is_some() { Some(el.f64("sigma")?) } else { None },
        },
        "NormQ" => NormQ { setup: SetupId(ab("setup")?) },
        "ParameterFix" => ParameterFix { unknown: parse_unknown(el)?, value: el.f64("value")? },
        "ParameterObs" => ParameterObs { unknown: parse_unknown(el)?, l: l()? },
        other => return Err(el.err(format!("unknown observation class `{}`", input_limits::quote(other)))),
    })
}

const SECTIONS: [(&str, &str); 11] = [
    ("solids", "solid"),
    ("nodes", "node"),
    ("edges", "edge"),
    ("halfedges", "halfedge"),
    ("faces", "face"),
    ("planes", "plane"),
    ("normals", "normal"),
    ("parameters", "parameter"),
    ("fixedpoints", "fixedpoint"),
    ("setups", "setup"),
    ("observations", ""),
];

/// Reads a popa3d document. Checks what the schema checks (structure, ids unique and dense per type,
/// references to existing elements = xs:keyref, value ranges of MA08–MA12 are left to the validator),
/// so the returned model can be indexed without bounds failures. Errors name line:column.
pub fn read(bytes: &[u8]) -> Result<Popa3d, XmlError> {
    let lines = Lines::new(bytes);
    let mut reader = quick_xml::Reader::from_reader(bytes);
    reader.config_mut().trim_text(true);
    let mut reading = Reading::new();
    let mut stack: Vec<String> = Vec::new();
    loop {
        let start_pos = reader.buffer_position() as usize;
        let ev = reader.read_event().map_err(|e| {
            let (line, column) = lines.at(reader.error_position() as usize);
            XmlError::Syntax { line, column, message: format!("malformed XML: {}", input_limits::quote(&e.to_string())) }
        })?;
        match &ev {
            Event::Start(s) | Event::Empty(s) => {
                let is_empty = matches!(ev, Event::Empty(_));
                let (line, column) = lines.at(tag_start(bytes, start_pos));
                let el = element(s, line, column)?;
                reading.start(stack.last().map(String::as_str), el, is_empty)?;
                if !is_empty {
                    stack.push(el_name(s));
                }
            }
            Event::End(_) => {
                if let Some(name) = stack.pop() {
                    reading.end(&name)?;
                }
            }
            Event::Text(t) => {
                if !t.iter().all(|c| c.is_ascii_whitespace()) {
                    let (line, column) = lines.at(start_pos);
                    return Err(XmlError::Syntax { line, column, message: "unexpected text content".into() });
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    reading.finish()
}

/// Position of the '<' of a tag read from `start_pos` (skipping whitespace trimmed before it), so
/// that messages point at the tag and not at the end of the previous one.
fn tag_start(bytes: &[u8], start_pos: usize) -> usize {
    let mut p = start_pos;
    while p < bytes.len() && bytes[p] != b'<' {
        p += 1;
    }
    p
}

/// A document being read: one table per element type, filled element by element (ids are only
/// checked to be dense once all are in), and the `<node>`/`<on>` elements whose `<src>` children
/// are still being collected.
struct Reading {
    model: Popa3d,
    solids: Table<Solid>,
    nodes: Table<Node>,
    edges: Table<Edge>,
    half_edges: Table<HalfEdge>,
    faces: Table<Face>,
    planes: Table<Plane>,
    normals: Table<NormalVector>,
    parameters: Table<Parameter>,
    fixed_points: Table<FixedPoint>,
    setups: Table<Setup>,
    observations: Table<Observation>,
    open_node: Option<(El, Vec<VertexSource>)>,
    open_on: Option<(El, EdgeId, Vec<VertexSource>)>,
    edge_vertices: Vec<(El, EdgeId, Vec<VertexSource>)>,
    saw_root: bool,
    saw_origin: bool,
}

impl Reading {
    fn new() -> Self {
        Reading {
            model: Popa3d::default(),
            solids: Table::new("solid"),
            nodes: Table::new("node"),
            edges: Table::new("edge"),
            half_edges: Table::new("halfedge"),
            faces: Table::new("face"),
            planes: Table::new("plane"),
            normals: Table::new("normal"),
            parameters: Table::new("parameter"),
            fixed_points: Table::new("fixedpoint"),
            setups: Table::new("setup"),
            observations: Table::new("observation"),
            open_node: None,
            open_on: None,
            edge_vertices: Vec::new(),
            saw_root: false,
            saw_origin: false,
        }
    }

    /// One start (or empty) tag inside `parent`: the schema's structure, element by element.
    fn start(&mut self, parent: Option<&str>, el: El, is_empty: bool) -> Result<(), XmlError> {
        match (parent, el.name.as_str()) {
            (None, "popa3d") => {
                self.saw_root = true;
                check_version(&el)
            }
            (None, other) => Err(el.err(format!("the root element must be <popa3d>, found <{}>", input_limits::quote(other)))),
            (Some("popa3d"), "origin") => {
                self.saw_origin = true;
                self.model.origin = [el.f64("x")?, el.f64("y")?, el.f64("z")?];
                self.model.srs_name = el.opt("srsName").map(str::to_string);
                Ok(())
            }
            (Some("popa3d"), "source") => {
                self.model.source = Some(SourceDocument { format: el.req("format")?.to_string(), file: el.req("file")?.to_string() });
                Ok(())
            }
            (Some("popa3d"), sec) if sec == "edgevertices" || SECTIONS.iter().any(|(s, _)| *s == sec) => Ok(()),
            (Some("solids"), "solid") => self.solids.push(&el, parse_solid(&el)?),
            (Some("nodes"), "node") if is_empty => self.nodes.push(&el, Node::default()),
            (Some("nodes"), "node") => {
                self.open_node = Some((el, Vec::new()));
                Ok(())
            }
            (Some("edgevertices"), "on") => self.start_on(el, is_empty),
            (Some("on"), "src") => {
                let src = parse_src(&el)?;
                if let Some((_, _, v)) = self.open_on.as_mut() {
                    v.push(src);
                }
                Ok(())
            }
            (Some("node"), "src") => {
                let src = parse_src(&el)?;
                if let Some((_, v)) = self.open_node.as_mut() {
                    v.push(src);
                }
                Ok(())
            }
            (Some("edges"), "edge") => self.edges.push(&el, Edge { start: NodeId(el.u32("start")?), end: NodeId(el.u32("end")?) }),
            (Some("halfedges"), "halfedge") => self.half_edges.push(&el, parse_half_edge(&el)?),
            (Some("faces"), "face") => self.faces.push(&el, parse_face(&el)?),
            (Some("planes"), "plane") => self.planes.push(&el, parse_plane(&el)?),
            (Some("normals"), "normal") => self.normals.push(&el, parse_normal(&el)?),
            (Some("parameters"), "parameter") => self.parameters.push(&el, parse_parameter(&el)?),
            (Some("fixedpoints"), "fixedpoint") => {
                self.fixed_points.push(&el, FixedPoint { t: [el.f64("tx")?, el.f64("ty")?, el.f64("tz")?] })
            }
            (Some("setups"), "setup") => self.setups.push(&el, parse_setup(&el)?),
            (Some("observations"), _) => self.observations.push(&el, parse_observation_element(&el)?),
            (Some(p), c) => Err(el.err(format!("unexpected element <{}> inside <{}>", input_limits::quote(c), input_limits::quote(p)))),
        }
    }

    /// `<on edge=..>`: the vertices lying on an edge; its `<src>` children follow unless empty.
    fn start_on(&mut self, el: El, is_empty: bool) -> Result<(), XmlError> {
        let e = EdgeId(el.u32("edge")?);
        if is_empty {
            self.edge_vertices.push((el, e, Vec::new()));
        } else {
            self.open_on = Some((el, e, Vec::new()));
        }
        Ok(())
    }

    /// The end tag of `name`: a `<node>` or `<on>` is complete with its sources.
    fn end(&mut self, name: &str) -> Result<(), XmlError> {
        if name == "on" {
            if let Some(x) = self.open_on.take() {
                self.edge_vertices.push(x);
            }
        }
        if name == "node" {
            if let Some((el, v)) = self.open_node.take() {
                self.nodes.push(&el, Node { sources: v })?;
            }
        }
        Ok(())
    }

    /// The model, once the root and origin were seen, every table's ids are dense and every
    /// reference points at an existing element (checked in this order, so the first error in a
    /// document is always the same one).
    fn finish(self) -> Result<Popa3d, XmlError> {
        if !self.saw_root {
            return Err(XmlError::Syntax { line: 1, column: 1, message: "not a popa3d document: no <popa3d> root element".into() });
        }
        if !self.saw_origin {
            return Err(XmlError::Syntax { line: 1, column: 1, message: "<popa3d>: missing <origin>".into() });
        }
        let mut m = self.model;
        (m.solids, _) = self.solids.finish()?;
        (m.nodes, _) = self.nodes.finish()?;
        let (edges, epos) = self.edges.finish()?;
        m.edges = edges;
        for (el, e, sources) in self.edge_vertices {
            if e.idx() >= m.edges.len() {
                return Err(el.err(format!("references {e}, which does not exist")));
            }
            m.edge_vertices.push(EdgeVertices { edge: e, sources });
        }
        let (half_edges, hpos) = self.half_edges.finish()?;
        let (faces, fpos) = self.faces.finish()?;
        let (planes, ppos) = self.planes.finish()?;
        let (normals, npos) = self.normals.finish()?;
        (m.half_edges, m.faces, m.planes, m.normals) = (half_edges, faces, planes, normals);
        (m.parameters, _) = self.parameters.finish()?;
        (m.fixed_points, _) = self.fixed_points.finish()?;
        let (setups, spos) = self.setups.finish()?;
        let (observations, opos) = self.observations.finish()?;
        (m.setups, m.observations) = (setups, observations);
        check_references(&m, &epos, &hpos, &fpos, &ppos, &npos, &spos, &opos)?;
        Ok(m)
    }
}

fn check_version(el: &El) -> Result<(), XmlError> {
    match el.opt("version") {
        Some(v) if v != VERSION => Err(el.err(format!("unsupported popa3d version \"{}\" (this reader knows {VERSION})", input_limits::quote(v)))),
        _ => Ok(()),
    }
}

fn parse_solid(el: &El) -> Result<Solid, XmlError> {
    let kind = SolidKind::parse(el.req("kind")?).ok_or_else(|| el.err("kind must be exterior, building, room or component"))?;
    Ok(Solid { kind, name: el.opt("name").map(str::to_string) })
}

fn parse_half_edge(el: &El) -> Result<HalfEdge, XmlError> {
    Ok(HalfEdge { edge: EdgeId(el.u32("edge")?), sign: el.sign("sign")?, face: FaceId(el.u32("face")?) })
}

fn parse_face(el: &El) -> Result<Face, XmlError> {
    let source = el.opt("polygon").map(|p| FaceSource {
        polygon: p.to_string(),
        semantic: el.opt("semantic").map(str::to_string),
        owner: el.opt("owner").map(str::to_string),
        merged: el.opt("merged").map(|m| m.split_whitespace().map(str::to_string).collect()).unwrap_or_default(),
    });
    Ok(Face {
        plane: PlaneId(el.u32("plane")?),
        orientation: el.sign("orientation")?,
        front: SolidId(el.u32("front")?),
        back: SolidId(el.u32("back")?),
        source,
    })
}

fn parse_plane(el: &El) -> Result<Plane, XmlError> {
    Ok(Plane { normal: NormalId(el.u32("normal")?), sign: el.sign("sign")?, d: el.f64("d")? })
}

fn parse_normal(el: &El) -> Result<NormalVector, XmlError> {
    let c = |p: &str, s: &str| -> Result<(ParamId, Sign), XmlError> { Ok((ParamId(el.u32(p)?), el.sign(s)?)) };
    Ok(NormalVector { comps: [c("x", "sx")?, c("y", "sy")?, c("z", "sz")?] })
}

fn parse_parameter(el: &El) -> Result<Parameter, XmlError> {
    // `wert` is the thesis' attribute name (spec §2.6); accepted on input.
    let value = if el.opt("value").is_some() { el.f64("value")? } else { el.f64("wert")? };
    Ok(Parameter { value })
}

fn parse_setup(el: &El) -> Result<Setup, XmlError> {
    Ok(Setup {
        fixed_point: FixedPointId(el.u32("fixedpoint")?),
        instrument_height: el.f64("ih")?,
        q: [el.f64("q0")?, el.f64("q1")?, el.f64("q2")?, el.f64("q3")?],
        levelled: if el.opt("levelled").is_some() { el.bool("levelled")? } else { false },
    })
}

/// An observation element: its kind from the element name, then the attributes every kind shares.
fn parse_observation_element(el: &El) -> Result<Observation, XmlError> {
    let kind = parse_observation(el)?;
    let origin = match el.opt("origin") {
        Some(o) => ObsOrigin::parse(o).ok_or_else(|| el.err(format!("unknown origin \"{}\"", input_limits::quote(o))))?,
        None => ObsOrigin::Measured,
    };
    let induced_by = match el.opt("inducedBy") {
        Some(_) => Some(ObsId(el.u32("inducedBy")?)),
        None => None,
    };
    Ok(Observation { kind, origin, induced_by, label: el.opt("label").map(str::to_string) })
}

fn parse_src(el: &El) -> Result<VertexSource, XmlError> {
    Ok(if el.opt("vertex").is_some() {
        VertexSource::Obj { vertex: el.u32("vertex")? }
    } else {
        VertexSource::CityGml { polygon: el.req("polygon")?.to_string(), ring: el.u32("ring")?, index: el.u32("index")? }
    })
}

fn el_name(s: &BytesStart) -> String {
    String::from_utf8_lossy(s.local_name().as_ref()).into_owned()
}

fn element(s: &BytesStart, line: usize, column: usize) -> Result<El, XmlError> {
    let name = el_name(s);
    let mut attrs = Vec::new();
    for a in s.attributes() {
        let bad = |what: &str, e: &dyn std::fmt::Display| XmlError::Syntax {
            line,
            column,
            message: format!("<{}>: {what}: {}", input_limits::quote(&name), input_limits::quote(&e.to_string())),
        };
        let a = a.map_err(|e| bad("bad attribute", &e))?;
        let key = String::from_utf8_lossy(a.key.local_name().as_ref()).into_owned();
        if a.key.as_ref().starts_with(b"xmlns") {
            continue;
        }
        let v = a
            .unescape_value()
            .map_err(|e| bad("bad attribute value", &e))?
            .into_owned();
        attrs.push((key, v));
    }
    Ok(El { name, attrs, line, column })
}

#[allow(clippy::too_many_arguments)]
fn check_references(
    m: &Popa3d,
    epos: &[(usize, usize)],
    hpos: &[(usize, usize)],
    fpos: &[(usize, usize)],
    ppos: &[(usize, usize)],
    npos: &[(usize, usize)],
    spos: &[(usize, usize)],
    opos: &[(usize, usize)],
) -> Result<(), XmlError> {
    let err = |(line, column): (usize, usize), message: String| XmlError::Syntax { line, column, message };
    let chk = |ok: bool, pos: (usize, usize), what: String, rule: &str| -> Result<(), XmlError> {
        if ok {
            Ok(())
        } else {
            Err(err(pos, format!("{rule}: {what} does not exist")))
        }
    };
    for (i, e) in m.edges.iter().enumerate() {
        for n in [e.start, e.end] {
            chk(n.idx() < m.nodes.len(), epos[i], format!("edge {i} references {n}, which"), "MA02")?;
        }
    }
    for (i, h) in m.half_edges.iter().enumerate() {
        chk(h.edge.idx() < m.edges.len(), hpos[i], format!("halfedge {i} references {}, which", h.edge), "MA03")?;
        chk(h.face.idx() < m.faces.len(), hpos[i], format!("halfedge {i} references {}, which", h.face), "MA03")?;
    }
    for (i, f) in m.faces.iter().enumerate() {
        chk(f.plane.idx() < m.planes.len(), fpos[i], format!("face {i} references {}, which", f.plane), "MA04")?;
        for s in [f.front, f.back] {
            chk(s.idx() < m.solids.len(), fpos[i], format!("face {i} references {s}, which"), "MA04")?;
        }
    }
    for (i, p) in m.planes.iter().enumerate() {
        chk(p.normal.idx() < m.normals.len(), ppos[i], format!("plane {i} references {}, which", p.normal), "MA05")?;
    }
    for (i, n) in m.normals.iter().enumerate() {
        for (p, _) in n.comps {
            chk(p.idx() < m.parameters.len(), npos[i], format!("normal {i} references {p}, which"), "MA06")?;
        }
    }
    for (i, s) in m.setups.iter().enumerate() {
        chk(s.fixed_point.idx() < m.fixed_points.len(), spos[i], format!("setup {i} references {}, which", s.fixed_point), "MA07")?;
    }
    for (i, o) in m.observations.iter().enumerate() {
        for r in observation_refs(&o.kind) {
            let (ok, name) = match r {
                Ref::Face(x) => (x.idx() < m.faces.len(), x.to_string()),
                Ref::Edge(x) => (x.idx() < m.edges.len(), x.to_string()),
                Ref::Node(x) => (x.idx() < m.nodes.len(), x.to_string()),
                Ref::Plane(x) => (x.idx() < m.planes.len(), x.to_string()),
                Ref::Normal(x) => (x.idx() < m.normals.len(), x.to_string()),
                Ref::Param(x) => (x.idx() < m.parameters.len(), x.to_string()),
                Ref::FixedPoint(x) => (x.idx() < m.fixed_points.len(), x.to_string()),
                Ref::Setup(x) => (x.idx() < m.setups.len(), x.to_string()),
            };
            chk(ok, opos[i], format!("{} {i} references {name}, which", o.kind.class_name()), "MA07")?;
        }
        if let Some(b) = o.induced_by {
            chk(b.idx() < m.observations.len(), opos[i], format!("{} {i} inducedBy {b}, which", o.kind.class_name()), "MA07")?;
        }
    }
    Ok(())
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
        let e = err(&doc("  <nodes><node id=\"0\"/></nodes>\n  <edges>\n    <edge id=\"0\" start=\"0\" end=\"7\"/>\n  </edges>\n"));
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
