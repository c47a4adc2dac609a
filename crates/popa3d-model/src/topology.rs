//! Incidence indices and loops, rebuilt on demand (spec §2.2: loops are not stored).

use crate::ids::*;
use crate::model::Popa3d;

/// Reverse references of the object topology, built once per model state.
#[derive(Debug, Clone, Default)]
pub struct Incidence {
    /// Edges starting or ending at each node.
    pub node_edges: Vec<Vec<EdgeId>>,
    /// Half-edges using each edge.
    pub edge_half_edges: Vec<Vec<HalfEdgeId>>,
    /// Half-edges of each face.
    pub face_half_edges: Vec<Vec<HalfEdgeId>>,
}

impl Incidence {
    /// Builds the index. References out of range are skipped (the validator reports them, MA02–MA04).
    pub fn new(m: &Popa3d) -> Incidence {
        let mut inc = Incidence {
            node_edges: vec![Vec::new(); m.nodes.len()],
            edge_half_edges: vec![Vec::new(); m.edges.len()],
            face_half_edges: vec![Vec::new(); m.faces.len()],
        };
        for (i, e) in m.edges.iter().enumerate() {
            for n in [e.start, e.end] {
                if let Some(v) = inc.node_edges.get_mut(n.idx()) {
                    if !v.contains(&EdgeId::from(i)) {
                        v.push(EdgeId::from(i));
                    }
                }
            }
        }
        for (i, h) in m.half_edges.iter().enumerate() {
            if let Some(v) = inc.edge_half_edges.get_mut(h.edge.idx()) {
                v.push(HalfEdgeId::from(i));
            }
            if let Some(v) = inc.face_half_edges.get_mut(h.face.idx()) {
                v.push(HalfEdgeId::from(i));
            }
        }
        inc
    }

    /// Faces using an edge (through its half-edges), in half-edge order, without repeats.
    pub fn edge_faces(&self, m: &Popa3d, e: EdgeId) -> Vec<FaceId> {
        let mut out: Vec<FaceId> = Vec::new();
        for h in &self.edge_half_edges[e.idx()] {
            let f = m.half_edge(*h).face;
            if !out.contains(&f) {
                out.push(f);
            }
        }
        out
    }

    /// Faces around a node, sorted by id, without repeats.
    pub fn node_faces(&self, m: &Popa3d, n: NodeId) -> Vec<FaceId> {
        let mut out: Vec<FaceId> = Vec::new();
        for e in &self.node_edges[n.idx()] {
            out.extend(self.edge_faces(m, *e));
        }
        out.sort();
        out.dedup();
        out
    }

    /// Distinct planes of the faces around a node, sorted by id.
    pub fn node_planes(&self, m: &Popa3d, n: NodeId) -> Vec<PlaneId> {
        let mut out: Vec<PlaneId> =
            self.node_faces(m, n).into_iter().filter_map(|f| m.faces.get(f.idx()).map(|f| f.plane)).collect();
        out.sort();
        out.dedup();
        out
    }

    /// Distinct planes of the faces along an edge, in half-edge order.
    pub fn edge_planes(&self, m: &Popa3d, e: EdgeId) -> Vec<PlaneId> {
        let mut out: Vec<PlaneId> = Vec::new();
        for f in self.edge_faces(m, e) {
            if let Some(face) = m.faces.get(f.idx()) {
                if !out.contains(&face.plane) {
                    out.push(face.plane);
                }
            }
        }
        out
    }

    /// The loops of a face: its half-edges chained end→start. Returns `None` if they do not form
    /// closed simple cycles (TA07/TA08). Loops are in chaining order; use [`Popa3d::face_loops`] for
    /// the outer-first order that needs geometry.
    pub fn face_cycles(&self, m: &Popa3d, f: FaceId) -> Option<Vec<Vec<HalfEdgeId>>> {
        let hes = &self.face_half_edges[f.idx()];
        let oriented = |h: HalfEdgeId| {
            let he = m.half_edge(h);
            let e = m.edge(he.edge);
            match he.sign {
                Sign::Plus => (e.start, e.end),
                Sign::Minus => (e.end, e.start),
            }
        };
        // start node → half-edge; a simple cycle set has each start node once.
        let mut by_start: std::collections::HashMap<NodeId, HalfEdgeId> = std::collections::HashMap::new();
        for h in hes {
            if by_start.insert(oriented(*h).0, *h).is_some() {
                return None;
            }
        }
        let mut used = std::collections::HashSet::new();
        let mut loops = Vec::new();
        let mut order: Vec<HalfEdgeId> = hes.clone();
        order.sort();
        for h0 in order {
            if used.contains(&h0) {
                continue;
            }
            let mut lp = vec![h0];
            used.insert(h0);
            let start = oriented(h0).0;
            let mut cur = oriented(h0).1;
            while cur != start {
                let next = *by_start.get(&cur)?;
                if !used.insert(next) {
                    return None;
                }
                lp.push(next);
                cur = oriented(next).1;
            }
            loops.push(lp);
        }
        Some(loops)
    }
}

impl Popa3d {
    /// The start node of a half-edge in its signed direction.
    pub fn half_edge_start(&self, h: HalfEdgeId) -> NodeId {
        let he = self.half_edge(h);
        let e = self.edge(he.edge);
        match he.sign {
            Sign::Plus => e.start,
            Sign::Minus => e.end,
        }
    }

    /// The loops of a face as node sequences, outer loop first (largest area, spec §2.2), the others
    /// in chaining order. `positions` are the node positions (e.g. from [`Popa3d::node_positions`]).
    pub fn face_loops(&self, inc: &Incidence, f: FaceId, positions: &[[f64; 3]]) -> Option<Vec<Vec<NodeId>>> {
        let cycles = inc.face_cycles(self, f)?;
        let n = self.face_plane_value(f).n;
        let mut loops: Vec<(f64, Vec<NodeId>)> = cycles
            .into_iter()
            .map(|c| {
                let nodes: Vec<NodeId> = c.iter().map(|h| self.half_edge_start(*h)).collect();
                let pts: Vec<[f64; 3]> = nodes.iter().map(|n| positions[n.idx()]).collect();
                let a = newell(&pts);
                let area = (a[0] * n[0] + a[1] * n[1] + a[2] * n[2]).abs();
                (area, nodes)
            })
            .collect();
        // Stable: the largest area first, ties keep chaining order.
        let imax = loops.iter().enumerate().fold(0, |b, (i, l)| if l.0 > loops[b].0 { i } else { b });
        if !loops.is_empty() {
            let outer = loops.remove(imax);
            loops.insert(0, outer);
        }
        Some(loops.into_iter().map(|l| l.1).collect())
    }
}

/// Newell's vector of a polygon: twice its area times its unit normal (right-hand rule).
/// Zero for fewer than three points.
pub fn newell(pts: &[[f64; 3]]) -> [f64; 3] {
    let k = pts.len();
    if k < 3 {
        return [0.0; 3];
    }
    // Centre the points first: Newell on large coordinates loses digits.
    let mut c = [0.0; 3];
    for p in pts {
        for i in 0..3 {
            c[i] += p[i] / k as f64;
        }
    }
    crate::vec3::newell_about(pts, c)
}
