//! The popa3d XML writer: a pure function of the model, doubles in shortest round-trip form.

use super::*;

// ---------------------------------------------------------------------------------------------
// Writer

pub(super) fn num(x: f64, what: &dyn Fn() -> String) -> Result<String, XmlError> {
    if x.is_finite() {
        Ok(format!("{x:?}"))
    } else {
        Err(XmlError::Value { element: what(), message: format!("value {x} is not finite") })
    }
}

pub(super) fn esc(s: &str) -> String {
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

pub(super) fn sgn(s: Sign) -> &'static str {
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
pub(super) fn write_header(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
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
pub(super) fn write_topology(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
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
pub(super) fn write_edge_vertices(o: &mut String, m: &Popa3d) {
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

pub(super) fn write_face(o: &mut String, i: usize, f: &Face) {
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
pub(super) fn write_geometry(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
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
pub(super) fn write_survey(o: &mut String, m: &Popa3d) -> Result<(), XmlError> {
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

pub(super) fn write_src(o: &mut String, s: &VertexSource) {
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

pub(super) fn section(
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

pub(super) fn unknown_attrs(u: &Unknown) -> String {
    match *u {
        Unknown::PlaneD(p) => format!("plane=\"{}\"", p.0),
        Unknown::Param(p) => format!("parameter=\"{}\"", p.0),
        Unknown::Translation(f, k) => format!("fixedpoint=\"{}\" component=\"{k}\"", f.0),
        Unknown::Rotation(s, k) => format!("setup=\"{}\" component=\"{k}\"", s.0),
    }
}

pub(super) fn write_observation(o: &mut String, i: usize, ob: &Observation) -> Result<(), XmlError> {
    use std::fmt::Write as _;
    use ObsKind::*;
    let el = ob.kind.class_name();
    let what = || format!("{el} {i}");
    let vs = |l: &Measured| -> Result<String, XmlError> {
        Ok(format!("value=\"{}\" sigma=\"{}\"", num(l.value, &what)?, num(l.sigma, &what)?))
    };
    let body = match &ob.kind {
        DistanceFaceFace { a, b, l } | ConstraintFaceFace { a, b, l } => {
            format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?)
        }
        DistanceFaceEdge { a, b, l } | ConstraintFaceEdge { a, b, l } => {
            format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?)
        }
        DistanceFaceNode { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceEdgeEdge { a, b, l } | ConstraintEdgeEdge { a, b, l } => {
            format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?)
        }
        DistanceEdgeNode { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        DistanceNodeNode { a, b, l } => format!("a=\"{}\" b=\"{}\" {}", a.0, b.0, vs(l)?),
        PointOnFace { setup, target, hz, v, s } => polar(setup.0, target.0, hz, v, s, &what)?,
        PointOnEdge { setup, target, hz, v, s } => polar(setup.0, target.0, hz, v, s, &what)?,
        PointOnNode { setup, target, hz, v, s } => polar(setup.0, target.0, hz, v, s, &what)?,
        RelativeDistancePlanePlane { lower, upper, l } => {
            format!("lower=\"{}\" upper=\"{}\" {}", lower.0, upper.0, vs(l)?)
        }
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

pub(super) fn polar(
    setup: u32,
    target: u32,
    hz: &Measured,
    v: &Measured,
    s: &Measured,
    what: &dyn Fn() -> String,
) -> Result<String, XmlError> {
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
