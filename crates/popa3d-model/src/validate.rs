//! Layered integrity rules of spec §7 (MA, TA, GA, AA), checked bottom-up: a layer runs only when
//! the layers below it hold (spec §7.1). Each violation names its rule, the element and the reason
//! (spec §7.6 \[proposal\]).
//!
//! Decisions: GA03 (self-intersecting face boundaries) is not checked here (the CityGML validator
//! covers it on the source polygons); TA10: see [`topology_axioms`]; AA02 is the counting condition m + p ≥ u (a rank check belongs to the
//! adjustment, which sees the linearised system).

use crate::geometry::GeometryError;
use crate::ids::*;
use crate::model::Popa3d;
use crate::observation::ObsKind;
use crate::topology::Incidence;
use crate::xml::{observation_refs, Ref};
use serde::Serialize;

/// One broken rule.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Violation {
    /// MA01..MA12, TA01..TA10, GA01..GA04, AA01, AA02.
    pub rule: String,
    /// The element, e.g. `node 5`, `DistanceFaceEdge 12`.
    pub element: String,
    pub message: String,
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}: {}", self.rule, self.element, self.message)
    }
}

fn v(rule: &str, element: impl Into<String>, message: impl Into<String>) -> Violation {
    Violation { rule: rule.into(), element: element.into(), message: message.into() }
}

/// Runs the layers MA → TA → GA → AA and returns the violations of the first failing layer.
pub fn validate(m: &Popa3d) -> Vec<Violation> {
    let ma = model_axioms(m);
    if !ma.is_empty() {
        return ma;
    }
    let inc = Incidence::new(m);
    let ta = topology_axioms(m, &inc);
    if !ta.is_empty() {
        return ta;
    }
    let ga = geometry_axioms(m, &inc);
    if !ga.is_empty() {
        return ga;
    }
    adjustment_axioms(m, &inc)
}

/// MA02–MA12 (MA01 is structural: ids are indices).
pub fn model_axioms(m: &Popa3d) -> Vec<Violation> {
    let mut out = Vec::new();
    for (i, e) in m.edges.iter().enumerate() {
        if e.start.idx() >= m.nodes.len() || e.end.idx() >= m.nodes.len() {
            out.push(v("MA02", format!("edge {i}"), "references a node that does not exist"));
        }
    }
    for (i, h) in m.half_edges.iter().enumerate() {
        if h.edge.idx() >= m.edges.len() || h.face.idx() >= m.faces.len() {
            out.push(v("MA03", format!("halfedge {i}"), "references an edge or face that does not exist"));
        }
    }
    for (i, f) in m.faces.iter().enumerate() {
        if f.plane.idx() >= m.planes.len() || f.front.idx() >= m.solids.len() || f.back.idx() >= m.solids.len() {
            out.push(v("MA04", format!("face {i}"), "references a plane or solid that does not exist"));
        }
    }
    for (i, p) in m.planes.iter().enumerate() {
        if p.normal.idx() >= m.normals.len() {
            out.push(v("MA05", format!("plane {i}"), "references a normal that does not exist"));
        }
    }
    for (i, n) in m.normals.iter().enumerate() {
        if n.comps.iter().any(|(p, _)| p.idx() >= m.parameters.len()) {
            out.push(v("MA06", format!("normal {i}"), "references a parameter that does not exist"));
        }
    }
    for (i, p) in m.parameters.iter().enumerate() {
        if !(-1.0..=1.0).contains(&p.value) {
            out.push(v("MA08", format!("parameter {i}"), format!("value {} outside [-1, 1]", p.value)));
        }
    }
    for (i, o) in m.observations.iter().enumerate() {
        let el = format!("{} {i}", o.kind.class_name());
        for r in observation_refs(&o.kind) {
            let ok = match r {
                Ref::Face(x) => x.idx() < m.faces.len(),
                Ref::Edge(x) => x.idx() < m.edges.len(),
                Ref::Node(x) => x.idx() < m.nodes.len(),
                Ref::Plane(x) => x.idx() < m.planes.len(),
                Ref::Normal(x) => x.idx() < m.normals.len(),
                Ref::Param(x) => x.idx() < m.parameters.len(),
                Ref::FixedPoint(x) => x.idx() < m.fixed_points.len(),
                Ref::Setup(x) => x.idx() < m.setups.len(),
            };
            if !ok {
                out.push(v("MA07", el.clone(), format!("references {r:?}, which does not exist")));
            }
        }
        use ObsKind::*;
        match &o.kind {
            ConstraintFaceFace { l, .. } | ConstraintFaceEdge { l, .. } | ConstraintEdgeEdge { l, .. } => {
                if ![-1.0, 0.0, 1.0].contains(&l.value) {
                    out.push(v("MA09", el.clone(), format!("angle constraint value {} is not -1, 0 or 1", l.value)));
                }
            }
            PointOnFace { hz, v: vv, .. } | PointOnEdge { hz, v: vv, .. } | PointOnNode { hz, v: vv, .. } => {
                for (n, a) in [("Hz", hz), ("V", vv)] {
                    if !(0.0..400.0).contains(&a.value) {
                        out.push(v("MA10", el.clone(), format!("{n} = {} gon outside [0, 400)", a.value)));
                    }
                }
            }
            DistanceFaceFace { l, .. }
            | DistanceFaceEdge { l, .. }
            | DistanceFaceNode { l, .. }
            | DistanceEdgeEdge { l, .. }
            | DistanceEdgeNode { l, .. }
            | DistanceNodeNode { l, .. } => {
                if l.value < 0.0 {
                    out.push(v("MA11", el.clone(), format!("distance {} < 0", l.value)));
                }
            }
            _ => {}
        }
        for s in o.kind.measured() {
            if s.sigma.is_nan() || s.sigma <= 0.0 {
                out.push(v("MA12", el.clone(), format!("standard deviation {} is not > 0", s.sigma)));
            }
        }
    }
    out
}

/// TA01–TA10.
pub fn topology_axioms(m: &Popa3d, inc: &Incidence) -> Vec<Violation> {
    let mut out = Vec::new();
    for (i, es) in inc.node_edges.iter().enumerate() {
        if es.len() < 3 {
            out.push(v("TA01", format!("node {i}"), format!("used by {} edge(s), at least 3 are needed", es.len())));
        }
    }
    for (i, e) in m.edges.iter().enumerate() {
        if e.start == e.end {
            out.push(v("TA02", format!("edge {i}"), "starts and ends at the same node"));
        }
        let n = inc.edge_half_edges[i].len();
        if n < 2 {
            out.push(v("TA03", format!("edge {i}"), format!("used by {n} half-edge(s); a closed solid needs 2")));
        }
    }
    let mut inner_rings = 0usize;
    for f in 0..m.faces.len() {
        let hes = &inc.face_half_edges[f];
        let mut edges: Vec<EdgeId> = hes.iter().map(|h| m.half_edge(*h).edge).collect();
        edges.sort();
        let before = edges.len();
        edges.dedup();
        if edges.len() != before {
            out.push(v("TA04", format!("face {f}"), "uses an edge twice"));
        }
        if hes.len() < 3 {
            out.push(v("TA05", format!("face {f}"), format!("has {} half-edge(s), at least 3 are needed", hes.len())));
        }
        let mut nodes: Vec<NodeId> = edges.iter().flat_map(|e| [m.edge(*e).start, m.edge(*e).end]).collect();
        nodes.sort();
        nodes.dedup();
        if nodes.len() != edges.len() {
            out.push(v("TA06", format!("face {f}"), format!("{} edges but {} nodes", edges.len(), nodes.len())));
        }
        match inc.face_cycles(m, FaceId::from(f)) {
            Some(c) => inner_rings += c.len().saturating_sub(1),
            None => {
                out.push(v("TA07", format!("face {f}"), "its half-edges do not form simple closed cycles (TA07/TA08)"))
            }
        }
    }
    for (s, solid) in m.solids.iter().enumerate() {
        let n = m.faces.iter().filter(|f| f.front.idx() == s || f.back.idx() == s).count();
        if n < 3 && solid.kind != crate::model::SolidKind::Exterior {
            out.push(v("TA09", format!("solid {s}"), format!("bounded by {n} face(s), at least 3 are needed")));
        }
    }
    if out.is_empty() {
        // TA10: Euler–Poincaré. A 2-manifold (every edge in exactly 2 faces) uses Mäntylä's second form
        // v − e + f = 2(s − h) + r (s = shells = connected face components, r = inner rings), which
        // must admit a non-negative integer genus h. A cell complex of several rooms (edges in 3+
        // faces, spec §8.1) uses the Kruschwitz form v − e + f − r − S = c − t + b (S rooms, c
        // components, t transfixions, b bubbles) with b = 0, i.e. χ = v − e + f − r − S ≤ c.
        let shells = face_components(m, inc) as i64;
        let (vv, e, f, r) = (m.nodes.len() as i64, m.edges.len() as i64, m.faces.len() as i64, inner_rings as i64);
        let manifold = inc.edge_half_edges.iter().all(|h| h.len() == 2);
        if manifold {
            let two_h = 2 * shells - (vv - e + f - r);
            if two_h < 0 || two_h % 2 != 0 {
                out.push(v(
                    "TA10",
                    "model",
                    format!(
                        "Mäntylä: v − e + f = {} but 2(s − h) + r with s = {shells}, r = {r} admits no genus h ≥ 0",
                        vv - e + f
                    ),
                ));
            }
        } else {
            let rooms = m.solids.iter().filter(|s| s.kind != crate::model::SolidKind::Exterior).count() as i64;
            let chi = vv - e + f - r - rooms;
            if chi > shells {
                out.push(v(
                    "TA10",
                    "model",
                    format!("Kruschwitz: v − e + f − r − S = {chi} exceeds the {shells} component(s) (a bubble or a face not bounding any room)"),
                ));
            }
        }
    }
    out
}

fn face_components(m: &Popa3d, inc: &Incidence) -> usize {
    let mut parent: Vec<usize> = (0..m.faces.len()).collect();
    fn find(p: &mut [usize], x: usize) -> usize {
        let mut r = x;
        while p[r] != r {
            r = p[r];
        }
        p[x] = r;
        r
    }
    for hs in &inc.edge_half_edges {
        for w in hs.windows(2) {
            let (a, b) = (m.half_edge(w[0]).face.idx(), m.half_edge(w[1]).face.idx());
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            parent[ra.max(rb)] = ra.min(rb);
        }
    }
    (0..m.faces.len()).filter(|&f| find(&mut parent, f) == f).count()
}

/// GA01, GA02, GA04 (GA03 is left to the CityGML validator, see the module doc).
pub fn geometry_axioms(m: &Popa3d, inc: &Incidence) -> Vec<Violation> {
    let mut out = Vec::new();
    let mut pos = vec![None; m.nodes.len()];
    for n in 0..m.nodes.len() {
        match m.node_position(inc, NodeId::from(n)) {
            Ok(p) => pos[n] = Some(p),
            Err(GeometryError::NodeUnderdetermined { planes, rank, .. }) => out.push(v(
                "GA01",
                format!("node {n}"),
                format!("reached by {planes} distinct plane(s) of rank {rank}; 3 independent planes are needed"),
            )),
            Err(e) => out.push(v("GA01", format!("node {n}"), e.to_string())),
        }
    }
    for (i, e) in m.edges.iter().enumerate() {
        if let (Some(a), Some(b)) = (pos[e.start.idx()], pos[e.end.idx()]) {
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            if d < 1e-6 {
                out.push(v("GA02", format!("edge {i}"), format!("its nodes coincide geometrically ({d:.1e} m apart)")));
            }
        }
    }
    for n in 0..m.normals.len() {
        let x = m.normal_value(NormalId::from(n));
        let len = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
        if (len - 1.0).abs() > 1e-6 {
            out.push(v("GA04", format!("normal {n}"), format!("length {len}, not 1")));
        }
    }
    out
}

/// AA01 (edges used by observations are built from two non-parallel planes) and the counting form of
/// AA02.
pub fn adjustment_axioms(m: &Popa3d, inc: &Incidence) -> Vec<Violation> {
    let mut out = Vec::new();
    for (i, o) in m.observations.iter().enumerate() {
        for r in observation_refs(&o.kind) {
            if let Ref::Edge(e) = r {
                if m.edge_planes(inc, e).is_err() {
                    out.push(v(
                        "AA01",
                        format!("{} {i}", o.kind.class_name()),
                        format!("{e} is not built from two non-parallel planes"),
                    ));
                }
            }
        }
    }
    let u = m.planes.len() + m.parameters.len() + 3 * m.fixed_points.len() + 4 * m.setups.len();
    let eq: usize = m
        .observations
        .iter()
        .map(|o| match o.kind {
            ObsKind::PointOnFace { .. } => 1,
            ObsKind::PointOnEdge { .. } => 2,
            ObsKind::PointOnNode { .. } => 3,
            _ => 1,
        })
        .sum();
    if u > 0 && eq < u {
        out.push(v(
            "AA02",
            "model",
            format!("{eq} equations for {u} unknowns: the geometry is not determined (add measurements, sketch priors or a soft datum)"),
        ));
    }
    out
}
