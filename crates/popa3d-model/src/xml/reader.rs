//! The popa3d XML reader: structure, dense ids per type and references checked as the schema
//! checks them, errors at line:column.

use super::*;

// ---------------------------------------------------------------------------------------------
// Reader

/// Line/column lookup for byte offsets.
pub(super) struct Lines {
    pub(super) starts: Vec<usize>,
}

impl Lines {
    pub(super) fn new(b: &[u8]) -> Lines {
        let mut starts = vec![0];
        for (i, c) in b.iter().enumerate() {
            if *c == b'\n' {
                starts.push(i + 1);
            }
        }
        Lines { starts }
    }
    pub(super) fn at(&self, pos: usize) -> (usize, usize) {
        let l = match self.starts.binary_search(&pos) {
            Ok(i) => i,
            Err(i) => i - 1,
        };
        (l + 1, pos - self.starts[l] + 1)
    }
}

/// One element's attributes, with its position for messages.
pub(super) struct El {
    pub(super) name: String,
    pub(super) attrs: Vec<(String, String)>,
    pub(super) line: usize,
    pub(super) column: usize,
}

impl El {
    pub(super) fn err(&self, message: impl Into<String>) -> XmlError {
        XmlError::Syntax {
            line: self.line,
            column: self.column,
            message: format!("<{}>: {}", input_limits::quote(&self.name), message.into()),
        }
    }
    /// An attribute whose value is wrong; the value is quoted at most ~200 bytes long.
    pub(super) fn bad(&self, k: &str, v: &str, what: &str) -> XmlError {
        self.err(format!("attribute `{}`=\"{}\" {what}", input_limits::quote(k), input_limits::quote(v)))
    }
    pub(super) fn opt(&self, k: &str) -> Option<&str> {
        self.attrs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str())
    }
    pub(super) fn req(&self, k: &str) -> Result<&str, XmlError> {
        self.opt(k).ok_or_else(|| self.err(format!("missing attribute `{k}`")))
    }
    pub(super) fn u32(&self, k: &str) -> Result<u32, XmlError> {
        let v = self.req(k)?;
        v.trim().parse::<u32>().map_err(|_| self.bad(k, v, "is not a non-negative integer id"))
    }
    pub(super) fn f64(&self, k: &str) -> Result<f64, XmlError> {
        let v = self.req(k)?;
        let t = v.trim();
        // xs:double lexical form; Rust's parser also takes "inf"/"nan", which a popa3d document never holds.
        match t.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            Ok(_) => Err(self.bad(k, v, "is not a finite number")),
            Err(_) => Err(self.bad(k, v, "is not a number")),
        }
    }
    pub(super) fn sign(&self, k: &str) -> Result<Sign, XmlError> {
        match self.req(k)?.trim() {
            "1" | "+1" => Ok(Sign::Plus),
            "-1" => Ok(Sign::Minus),
            v => Err(self.bad(k, v, "must be 1 or -1")),
        }
    }
    pub(super) fn bool(&self, k: &str) -> Result<bool, XmlError> {
        match self.req(k)?.trim() {
            "true" | "1" => Ok(true),
            "false" | "0" => Ok(false),
            v => Err(self.bad(k, v, "must be true or false")),
        }
    }
    pub(super) fn measured(&self, v: &str, s: &str) -> Result<Measured, XmlError> {
        Ok(Measured { value: self.f64(v)?, sigma: self.f64(s)? })
    }
}

/// Elements of one type collected with their ids, then checked to be 0..n in any order.
pub(super) struct Table<T> {
    pub(super) kind: &'static str,
    pub(super) items: Vec<(u32, T, usize, usize)>,
}

impl<T> Table<T> {
    pub(super) fn new(kind: &'static str) -> Self {
        Table { kind, items: Vec::new() }
    }
    pub(super) fn push(&mut self, el: &El, v: T) -> Result<(), XmlError> {
        let id = el.u32("id")?;
        self.items.push((id, v, el.line, el.column));
        Ok(())
    }
    /// Sorted by id; ids must be exactly 0..n (MA01 and the dense-id convention).
    pub(super) fn finish(mut self) -> Result<(Vec<T>, Vec<(usize, usize)>), XmlError> {
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

pub(super) fn parse_unknown(el: &El) -> Result<Unknown, XmlError> {
    let comp = |max: u8| -> Result<u8, XmlError> {
        let c = el.u32("component")?;
        if c >= max as u32 {
            return Err(el.err(format!("component {c} out of range 0..{}", max - 1)));
        }
        Ok(c as u8)
    };
    let given: Vec<&str> =
        ["plane", "parameter", "fixedpoint", "setup"].into_iter().filter(|k| el.opt(k).is_some()).collect();
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

pub(super) fn parse_observation(el: &El) -> Result<ObsKind, XmlError> {
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
        "RelativeAngleNormalNormal" => {
            RelativeAngleNormalNormal { a: NormalId(ab("a")?), b: NormalId(ab("b")?), l: l()? }
        }
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

pub(super) const SECTIONS: [(&str, &str); 11] = [
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
            XmlError::Syntax {
                line,
                column,
                message: format!("malformed XML: {}", input_limits::quote(&e.to_string())),
            }
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
pub(super) fn tag_start(bytes: &[u8], start_pos: usize) -> usize {
    let mut p = start_pos;
    while p < bytes.len() && bytes[p] != b'<' {
        p += 1;
    }
    p
}

/// A document being read: one table per element type, filled element by element (ids are only
/// checked to be dense once all are in), and the `<node>`/`<on>` elements whose `<src>` children
/// are still being collected.
pub(super) struct Reading {
    pub(super) model: Popa3d,
    pub(super) solids: Table<Solid>,
    pub(super) nodes: Table<Node>,
    pub(super) edges: Table<Edge>,
    pub(super) half_edges: Table<HalfEdge>,
    pub(super) faces: Table<Face>,
    pub(super) planes: Table<Plane>,
    pub(super) normals: Table<NormalVector>,
    pub(super) parameters: Table<Parameter>,
    pub(super) fixed_points: Table<FixedPoint>,
    pub(super) setups: Table<Setup>,
    pub(super) observations: Table<Observation>,
    pub(super) open_node: Option<(El, Vec<VertexSource>)>,
    pub(super) open_on: Option<(El, EdgeId, Vec<VertexSource>)>,
    pub(super) edge_vertices: Vec<(El, EdgeId, Vec<VertexSource>)>,
    pub(super) saw_root: bool,
    pub(super) saw_origin: bool,
}

impl Reading {
    pub(super) fn new() -> Self {
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
    pub(super) fn start(&mut self, parent: Option<&str>, el: El, is_empty: bool) -> Result<(), XmlError> {
        match (parent, el.name.as_str()) {
            (None, "popa3d") => {
                self.saw_root = true;
                check_version(&el)
            }
            (None, other) => {
                Err(el.err(format!("the root element must be <popa3d>, found <{}>", input_limits::quote(other))))
            }
            (Some("popa3d"), "origin") => {
                self.saw_origin = true;
                self.model.origin = [el.f64("x")?, el.f64("y")?, el.f64("z")?];
                self.model.srs_name = el.opt("srsName").map(str::to_string);
                Ok(())
            }
            (Some("popa3d"), "source") => {
                self.model.source =
                    Some(SourceDocument { format: el.req("format")?.to_string(), file: el.req("file")?.to_string() });
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
            (Some("edges"), "edge") => {
                self.edges.push(&el, Edge { start: NodeId(el.u32("start")?), end: NodeId(el.u32("end")?) })
            }
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
            (Some(p), c) => Err(el.err(format!(
                "unexpected element <{}> inside <{}>",
                input_limits::quote(c),
                input_limits::quote(p)
            ))),
        }
    }

    /// `<on edge=..>`: the vertices lying on an edge; its `<src>` children follow unless empty.
    pub(super) fn start_on(&mut self, el: El, is_empty: bool) -> Result<(), XmlError> {
        let e = EdgeId(el.u32("edge")?);
        if is_empty {
            self.edge_vertices.push((el, e, Vec::new()));
        } else {
            self.open_on = Some((el, e, Vec::new()));
        }
        Ok(())
    }

    /// The end tag of `name`: a `<node>` or `<on>` is complete with its sources.
    pub(super) fn end(&mut self, name: &str) -> Result<(), XmlError> {
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
    pub(super) fn finish(self) -> Result<Popa3d, XmlError> {
        if !self.saw_root {
            return Err(XmlError::Syntax {
                line: 1,
                column: 1,
                message: "not a popa3d document: no <popa3d> root element".into(),
            });
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

pub(super) fn check_version(el: &El) -> Result<(), XmlError> {
    match el.opt("version") {
        Some(v) if v != VERSION => Err(
            el.err(format!("unsupported popa3d version \"{}\" (this reader knows {VERSION})", input_limits::quote(v)))
        ),
        _ => Ok(()),
    }
}

pub(super) fn parse_solid(el: &El) -> Result<Solid, XmlError> {
    let kind = SolidKind::parse(el.req("kind")?)
        .ok_or_else(|| el.err("kind must be exterior, building, room or component"))?;
    Ok(Solid { kind, name: el.opt("name").map(str::to_string) })
}

pub(super) fn parse_half_edge(el: &El) -> Result<HalfEdge, XmlError> {
    Ok(HalfEdge { edge: EdgeId(el.u32("edge")?), sign: el.sign("sign")?, face: FaceId(el.u32("face")?) })
}

pub(super) fn parse_face(el: &El) -> Result<Face, XmlError> {
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

pub(super) fn parse_plane(el: &El) -> Result<Plane, XmlError> {
    Ok(Plane { normal: NormalId(el.u32("normal")?), sign: el.sign("sign")?, d: el.f64("d")? })
}

pub(super) fn parse_normal(el: &El) -> Result<NormalVector, XmlError> {
    let c = |p: &str, s: &str| -> Result<(ParamId, Sign), XmlError> { Ok((ParamId(el.u32(p)?), el.sign(s)?)) };
    Ok(NormalVector { comps: [c("x", "sx")?, c("y", "sy")?, c("z", "sz")?] })
}

pub(super) fn parse_parameter(el: &El) -> Result<Parameter, XmlError> {
    // `wert` is the thesis' attribute name (spec §2.6); accepted on input.
    let value = if el.opt("value").is_some() { el.f64("value")? } else { el.f64("wert")? };
    Ok(Parameter { value })
}

pub(super) fn parse_setup(el: &El) -> Result<Setup, XmlError> {
    Ok(Setup {
        fixed_point: FixedPointId(el.u32("fixedpoint")?),
        instrument_height: el.f64("ih")?,
        q: [el.f64("q0")?, el.f64("q1")?, el.f64("q2")?, el.f64("q3")?],
        levelled: if el.opt("levelled").is_some() { el.bool("levelled")? } else { false },
    })
}

/// An observation element: its kind from the element name, then the attributes every kind shares.
pub(super) fn parse_observation_element(el: &El) -> Result<Observation, XmlError> {
    let kind = parse_observation(el)?;
    let origin = match el.opt("origin") {
        Some(o) => {
            ObsOrigin::parse(o).ok_or_else(|| el.err(format!("unknown origin \"{}\"", input_limits::quote(o))))?
        }
        None => ObsOrigin::Measured,
    };
    let induced_by = match el.opt("inducedBy") {
        Some(_) => Some(ObsId(el.u32("inducedBy")?)),
        None => None,
    };
    Ok(Observation { kind, origin, induced_by, label: el.opt("label").map(str::to_string) })
}

pub(super) fn parse_src(el: &El) -> Result<VertexSource, XmlError> {
    Ok(if el.opt("vertex").is_some() {
        VertexSource::Obj { vertex: el.u32("vertex")? }
    } else {
        VertexSource::CityGml {
            polygon: el.req("polygon")?.to_string(),
            ring: el.u32("ring")?,
            index: el.u32("index")?,
        }
    })
}

pub(super) fn el_name(s: &BytesStart) -> String {
    String::from_utf8_lossy(s.local_name().as_ref()).into_owned()
}

pub(super) fn element(s: &BytesStart, line: usize, column: usize) -> Result<El, XmlError> {
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
        let v = a.unescape_value().map_err(|e| bad("bad attribute value", &e))?.into_owned();
        attrs.push((key, v));
    }
    Ok(El { name, attrs, line, column })
}

#[allow(clippy::too_many_arguments)]
pub(super) fn check_references(
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
        chk(
            s.fixed_point.idx() < m.fixed_points.len(),
            spos[i],
            format!("setup {i} references {}, which", s.fixed_point),
            "MA07",
        )?;
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
            chk(
                b.idx() < m.observations.len(),
                opos[i],
                format!("{} {i} inducedBy {b}, which", o.kind.class_name()),
                "MA07",
            )?;
        }
    }
    Ok(())
}
