//! Shell level (301–307) on the triangulated shell, like val3dity: the polygons are checked first
//! (ring and polygon levels), triangulated in their planes, and the triangles' edges on snapped
//! vertices give the combinatorial checks; a triangle–triangle test gives the geometric one.
//!
//! Order: 301 too few polygons; 303 an edge shared by more than two faces, also where other
//! polygons meet the inside of a polygon along one of its triangulation edges (a pinched vertex);
//! 307 two faces using an edge in the same direction; 303 a vertex whose faces form several fans
//! (unless the faces actually cross there, which is 306); 305 parts that share no vertex; 302
//! border edges (holes); 306 faces meeting anywhere other than along shared vertices and edges.
//!
//! Definitions are val3dity's ("Error codes" in its documentation): 302 SHELL_NOT_CLOSED, the shell
//! has holes (edges used by one face only); 303 NON_MANIFOLD_VERTEX, a vertex whose incident
//! polygons do not form one umbrella, and 304 NON_MANIFOLD_EDGE, an edge with other than two
//! incident polygons (both reported as 303, as val3dity does today); 305
//! MULTIPLE_CONNECTED_COMPONENTS, parts of the shell that share no vertex or edge; 306
//! SHELL_SELF_INTERSECTION only once the topology is right (no 301–305).
//!
//! Where geofit keeps its own answer (see docs/decisions.md, "validate vs val3dity"): a face
//! flipped against its neighbours is 307 alone; val3dity, building the shell face by face, may
//! add a 303 for a later face depending on the order of the faces in the file.

use crate::codes::ErrorCode;
use crate::geom::{point_segment_distance, Snapper, V3};
use crate::polygon::{check_polygons, PolygonInput};
use crate::tritri::contact;
use crate::{Issue, Options};
use rstar::{primitives::GeomWithData, primitives::Rectangle, RTree, AABB};
use std::collections::{BTreeMap, HashMap, HashSet};

/// A shell that passed all checks up to the shell level, as a triangle mesh.
pub struct ShellMesh {
    /// Vertices relative to `origin`.
    pub points: Vec<V3>,
    pub origin: V3,
    pub triangles: Vec<[u32; 3]>,
    /// Index of the polygon each triangle comes from.
    pub triangle_polygon: Vec<usize>,
}

impl ShellMesh {
    /// Signed volume (positive when the faces point outwards).
    pub fn signed_volume(&self) -> f64 {
        let c = self.points.first().copied().unwrap_or_else(V3::zeros);
        self.triangles
            .iter()
            .map(|t| {
                let (a, b, d) =
                    (self.points[t[0] as usize] - c, self.points[t[1] as usize] - c, self.points[t[2] as usize] - c);
                a.dot(&b.cross(&d)) / 6.0
            })
            .sum()
    }
    pub fn abs_point(&self, i: u32) -> V3 {
        self.points[i as usize] + self.origin
    }
    fn extent(&self) -> f64 {
        let c = self.points.first().copied().unwrap_or_else(V3::zeros);
        self.points.iter().map(|p| (p - c).norm()).fold(0.0, f64::max)
    }
}

fn shell_issue(code: ErrorCode, polygon: Option<usize>, detail: String) -> Issue {
    Issue { code, polygon, ring: None, shell: None, detail, value: None }
}

fn fmt_abs(p: &V3) -> String {
    let r = |x: f64| (x * 1e6).round() / 1e6;
    format!("({}, {}, {})", r(p.x), r(p.y), r(p.z))
}

pub(crate) struct Dsu(Vec<usize>);
impl Dsu {
    pub(crate) fn new(n: usize) -> Self {
        Dsu((0..n).collect())
    }
    pub(crate) fn find(&mut self, x: usize) -> usize {
        let mut x = x;
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    pub(crate) fn union(&mut self, a: usize, b: usize) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        self.0[ra] = rb;
        true
    }
}

/// Tolerances derived from the options and the shell's size: `plane` for on-plane decisions in
/// the triangle test, `touch` for how far a contact may reach beyond a shared vertex or edge.
pub(crate) fn contact_eps(opts: &Options, extent: f64) -> (f64, f64) {
    let plane = 1e-9 * extent.max(1.0);
    let touch = (opts.snap_tol * 0.01).max(plane * 10.0);
    (plane, touch)
}

/// Checks one shell. Returns its issues and, when it is valid, its triangle mesh.
pub fn check_shell(polys: &[PolygonInput], opts: &Options) -> (Vec<Issue>, Option<ShellMesh>) {
    if polys.is_empty() {
        return (vec![shell_issue(ErrorCode::EmptyPrimitive, None, "shell has no polygons".into())], None);
    }
    let mut snap = Snapper::new(opts.snap_tol);
    let (issues, prepared) = check_polygons(polys, &mut snap, opts);
    if !issues.is_empty() {
        return (issues, None);
    }
    if polys.len() < 4 {
        return (
            vec![shell_issue(
                ErrorCode::TooFewPolygons,
                None,
                format!("{} polygons, a shell needs at least 4", polys.len()),
            )],
            None,
        );
    }
    let mut mesh = ShellMesh {
        points: snap.points.clone(),
        origin: snap.origin(),
        triangles: Vec::new(),
        triangle_polygon: Vec::new(),
    };
    for (pi, p) in prepared.iter().enumerate() {
        let p = p.as_ref().expect("valid polygons are prepared");
        for t in &p.triangles {
            mesh.triangles.push(*t);
            mesh.triangle_polygon.push(pi);
        }
    }
    let issues = shell_topology_and_geometry(&mesh, opts);
    if issues.is_empty() {
        (issues, Some(mesh))
    } else {
        (issues, None)
    }
}

/// The shell checks in val3dity's order, each returning early so that one defect is reported
/// under the code val3dity gives it, not also under the codes it causes further down.
fn shell_topology_and_geometry(mesh: &ShellMesh, opts: &Options) -> Vec<Issue> {
    let edges = edge_uses(&mesh.triangles);
    let issues = non_manifold_edges(mesh, &edges);
    if !issues.is_empty() {
        return issues;
    }
    let issues = faces_meeting_polygon_insides(mesh, &edges);
    if !issues.is_empty() {
        return issues;
    }
    if edges.values().any(|u| u.len() == 2 && u[0].1 == u[1].1) {
        return orientation_issues(mesh, &edges);
    }
    let vertices = non_manifold_vertices(&mesh.triangles);
    if !vertices.is_empty() {
        // faces crossing at the vertex are the cause; report that (306) instead
        let si = self_intersections(mesh, opts);
        if !si.is_empty() {
            return si;
        }
        return vertices.iter().map(|v| non_manifold_vertex_issue(mesh, *v)).collect();
    }
    if let Some(issue) = separate_parts(mesh) {
        return vec![issue];
    }
    let issues = hole_issues(mesh, &edges);
    if !issues.is_empty() {
        return issues;
    }
    self_intersections(mesh, opts)
}

/// Each undirected edge of the triangles → its uses: (triangle, runs from the lower to the higher
/// vertex id). Two uses in opposite directions are a manifold, consistently oriented edge.
type EdgeUses = BTreeMap<(u32, u32), Vec<(usize, bool)>>;

fn edge_uses(triangles: &[[u32; 3]]) -> EdgeUses {
    let mut edges = EdgeUses::new();
    for (ti, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push((ti, a < b));
        }
    }
    edges
}

fn edge_str(mesh: &ShellMesh, e: &(u32, u32)) -> String {
    format!("{}–{}", fmt_abs(&mesh.abs_point(e.0)), fmt_abs(&mesh.abs_point(e.1)))
}

/// The polygons using an edge, split into (on their boundary, inside them): a triangulation edge
/// inside a polygon shows up twice for that polygon (once per side).
fn boundary_and_inner_polygons(mesh: &ShellMesh, uses: &[(usize, bool)]) -> (Vec<usize>, Vec<usize>) {
    let mut count: BTreeMap<usize, usize> = BTreeMap::new();
    for u in uses {
        *count.entry(mesh.triangle_polygon[u.0]).or_default() += 1;
    }
    let inner = count.iter().filter(|(_, &c)| c >= 2).map(|(&p, _)| p).collect();
    let bound = count.iter().filter(|(_, &c)| c == 1).map(|(&p, _)| p).collect();
    (bound, inner)
}

/// 303: non-manifold edges (a polygon edge shared by more than two polygons).
fn non_manifold_edges(mesh: &ShellMesh, edges: &EdgeUses) -> Vec<Issue> {
    let mut issues = Vec::new();
    for (e, uses) in edges.iter().filter(|(_, u)| u.len() > 2) {
        let (bound, inner) = boundary_and_inner_polygons(mesh, uses);
        if inner.is_empty() && bound.len() > 2 {
            issues.push(shell_issue(
                ErrorCode::NonManifoldCase,
                Some(bound[0]),
                format!("edge {} is shared by {} polygons ({})", edge_str(mesh, e), bound.len(), list1(&bound)),
            ));
        }
    }
    issues
}

/// 303: other polygons meet the inside of a polygon along one of its triangulation edges. The
/// polygon is split there (a face on each side of the edge), so the edge has more than two
/// incident faces (val3dity 304 NON_MANIFOLD_EDGE, "each edge of a shell should have exactly
/// 2 incident polygons", reported as 303) and the faces around each of its end vertices form
/// two fans (303 NON_MANIFOLD_VERTEX, "its incident polygons do not form one umbrella"). This
/// is the pinched vertex of QIE i306_4, where an inner ring touches the outer ring: val3dity's
/// halfedge builder cannot attach the third face to the edge and reports 303 while building
/// the shell, before it tests for intersections (306).
fn faces_meeting_polygon_insides(mesh: &ShellMesh, edges: &EdgeUses) -> Vec<Issue> {
    let mut issues = Vec::new();
    for (e, uses) in edges.iter().filter(|(_, u)| u.len() > 2) {
        let (bound, inner) = boundary_and_inner_polygons(mesh, uses);
        if let (Some(&a), Some(&b)) = (inner.first(), bound.first().or(inner.get(1))) {
            issues.push(shell_issue(
                ErrorCode::NonManifoldCase,
                Some(a.min(b)),
                format!(
                    "non-manifold vertices at {} and {}: polygon #{} meets the inside of polygon #{} along the edge between them, \
                     so the faces around each form two fans",
                    fmt_abs(&mesh.abs_point(e.0)),
                    fmt_abs(&mesh.abs_point(e.1)),
                    b + 1,
                    a + 1,
                ),
            ));
        }
    }
    issues
}

/// 307: orientation, by propagating relative flips over shared edges. In each connected group of
/// polygons the smaller side (the flipped ones, on a tie) is reported as the wrong one.
fn orientation_issues(mesh: &ShellMesh, edges: &EdgeUses) -> Vec<Issue> {
    let adj = flip_adjacency(mesh, edges);
    let mut label: Vec<Option<bool>> = vec![None; adj.len()];
    let mut issues = Vec::new();
    for start in 0..adj.len() {
        if label[start].is_some() {
            continue;
        }
        let comp = label_flips_from(start, &adj, &mut label);
        let flipped: Vec<usize> = comp.iter().copied().filter(|&p| label[p] == Some(true)).collect();
        let kept = comp.len() - flipped.len();
        let wrong: Vec<usize> = if flipped.len() <= kept {
            flipped
        } else {
            comp.iter().copied().filter(|&p| label[p] == Some(false)).collect()
        };
        for p in wrong {
            issues.push(shell_issue(
                ErrorCode::PolygonWrongOrientation,
                Some(p),
                "polygon is oriented opposite to its neighbours".into(),
            ));
        }
    }
    if issues.is_empty() {
        issues.push(shell_issue(
            ErrorCode::PolygonWrongOrientation,
            None,
            "faces use an edge in the same direction".into(),
        ));
    }
    issues
}

/// Polygon → (neighbour over a manifold edge, whether the two use that edge in the same direction).
fn flip_adjacency(mesh: &ShellMesh, edges: &EdgeUses) -> Vec<Vec<(usize, bool)>> {
    let tp = &mesh.triangle_polygon;
    let np = tp.iter().max().map_or(0, |m| m + 1);
    let mut adj: Vec<Vec<(usize, bool)>> = vec![Vec::new(); np];
    for u in edges.values().filter(|u| u.len() == 2) {
        let (pa, pb) = (tp[u[0].0], tp[u[1].0]);
        if pa != pb {
            let flip = u[0].1 == u[1].1;
            adj[pa].push((pb, flip));
            adj[pb].push((pa, flip));
        }
    }
    adj
}

/// Labels the polygons reachable from `start` flipped (true) or not relative to `start`; returns
/// them in the order they were reached.
fn label_flips_from(start: usize, adj: &[Vec<(usize, bool)>], label: &mut [Option<bool>]) -> Vec<usize> {
    let mut comp = vec![start];
    label[start] = Some(false);
    let mut stack = vec![start];
    while let Some(p) = stack.pop() {
        let lp = label[p] == Some(true);
        for &(q, flip) in &adj[p] {
            if label[q].is_none() {
                label[q] = Some(lp ^ flip);
                comp.push(q);
                stack.push(q);
            }
        }
    }
    comp
}

/// Vertices whose faces form several fans, at least one of them closed, sorted. Faces around a
/// vertex are one fan when connected through the edges at that vertex.
fn non_manifold_vertices(triangles: &[[u32; 3]]) -> Vec<u32> {
    let mut corners: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            corners.entry(t[k]).or_default().push((t[(k + 1) % 3], t[(k + 2) % 3]));
        }
    }
    let mut vertices: Vec<u32> =
        corners.iter().filter(|(_, cs)| has_closed_fan_among_several(cs)).map(|(v, _)| *v).collect();
    vertices.sort_unstable();
    vertices
}

/// A fan is closed when each of its edges at the vertex is used by two of its corners. Several
/// fans with at least one closed is a non-manifold vertex (val3dity cannot attach a face to a
/// closed vertex umbrella); several open fans is a hole or a T-junction (302).
fn has_closed_fan_among_several(corners: &[(u32, u32)]) -> bool {
    let mut d = Dsu::new(corners.len());
    let mut by_nb: HashMap<u32, usize> = HashMap::new();
    for (ci, (a, b)) in corners.iter().enumerate() {
        for nb in [a, b] {
            if let Some(&other) = by_nb.get(nb) {
                d.union(ci, other);
            } else {
                by_nb.insert(*nb, ci);
            }
        }
    }
    let mut fans: HashMap<usize, HashMap<u32, usize>> = HashMap::new();
    for (ci, (a, b)) in corners.iter().enumerate() {
        let m = fans.entry(d.find(ci)).or_default();
        *m.entry(*a).or_default() += 1;
        *m.entry(*b).or_default() += 1;
    }
    fans.len() > 1 && fans.values().any(|m| m.values().all(|&c| c == 2))
}

fn non_manifold_vertex_issue(mesh: &ShellMesh, v: u32) -> Issue {
    shell_issue(
        ErrorCode::NonManifoldCase,
        None,
        format!("non-manifold vertex at {}: its faces form more than one fan", fmt_abs(&mesh.abs_point(v))),
    )
}

/// 305 MULTIPLE_CONNECTED_COMPONENTS (val3dity, "Error codes": polygons that are not connected
/// to the rest of the shell). Connected means sharing a vertex, not only an edge: val3dity
/// builds the shell as a halfedge structure on the snapped vertices and keeps its largest
/// connected component, whose traversal goes around vertices, so two groups of faces that
/// share vertices but no edge (real LoD2 solids whose two halves meet at T-junctions, where
/// one side's edge is split in two on the other) are one component. Their edges used once
/// are holes in it: 302 SHELL_NOT_CLOSED ("the shell must not have holes").
fn separate_parts(mesh: &ShellMesh) -> Option<Issue> {
    let tris = &mesh.triangles;
    let mut dv = Dsu::new(mesh.points.len());
    for t in tris {
        dv.union(t[0] as usize, t[1] as usize);
        dv.union(t[0] as usize, t[2] as usize);
    }
    let ncomp = tris.iter().map(|t| dv.find(t[0] as usize)).collect::<HashSet<_>>().len();
    (ncomp > 1).then(|| {
        shell_issue(ErrorCode::MultipleConnectedComponents, None, format!("the faces form {ncomp} separate parts"))
    })
}

/// The number of parts the faces form through shared edges: more than one means the parts meet
/// only at vertices.
fn parts_through_edges(mesh: &ShellMesh, edges: &EdgeUses) -> usize {
    let mut de = Dsu::new(mesh.triangles.len());
    for u in edges.values().filter(|u| u.len() == 2) {
        de.union(u[0].0, u[1].0);
    }
    (0..mesh.triangles.len()).map(|i| de.find(i)).collect::<HashSet<_>>().len()
}

/// 302: border edges (used by one face only), grouped into holes by shared vertices, one issue
/// per hole in the order its first edge comes.
fn hole_issues(mesh: &ShellMesh, edges: &EdgeUses) -> Vec<Issue> {
    let border: Vec<BorderEdge> = edges.iter().filter(|(_, u)| u.len() == 1).map(|(e, u)| (e, u[0].0)).collect();
    if border.is_empty() {
        return Vec::new();
    }
    let edge_parts = parts_through_edges(mesh, edges);
    holes(mesh, &border)
        .iter()
        .map(|hole| {
            let (e, ti) = hole[0];
            let mut detail = format!("hole in the shell at edge {}", edge_str(mesh, e));
            if edge_parts > 1 {
                // the faces fall into parts that share vertices but no edge: name every edge
                // used once, so each place where the parts fail to share an edge can be found
                let all: Vec<String> = hole.iter().map(|(e, _)| edge_str(mesh, e)).collect();
                detail = format!(
                    "{detail}: the faces form {edge_parts} parts that share vertices but no edge; edges used once: {}",
                    all.join(", ")
                );
            }
            shell_issue(ErrorCode::ShellNotClosed, Some(mesh.triangle_polygon[ti]), detail)
        })
        .collect()
}

/// The border edges grouped by shared vertices, groups in the order of their first edge.
fn holes<'a>(mesh: &ShellMesh, border: &[BorderEdge<'a>]) -> Vec<Vec<BorderEdge<'a>>> {
    let mut dh = Dsu::new(mesh.points.len());
    for (e, _) in border {
        dh.union(e.0 as usize, e.1 as usize);
    }
    let mut holes: BTreeMap<usize, Vec<BorderEdge>> = BTreeMap::new();
    let mut order = Vec::new();
    for b in border {
        let r = dh.find(b.0 .0 as usize);
        holes
            .entry(r)
            .or_insert_with(|| {
                order.push(r);
                Vec::new()
            })
            .push(*b);
    }
    order.into_iter().filter_map(|r| holes.remove(&r)).collect()
}

/// An edge used by one face only, with that face's triangle.
type BorderEdge<'a> = (&'a (u32, u32), usize);

fn list1(ps: &[usize]) -> String {
    ps.iter().map(|p| format!("#{}", p + 1)).collect::<Vec<_>>().join(", ")
}

type TriBox = GeomWithData<Rectangle<[f64; 3]>, usize>;

fn tri_box(p: &[V3; 3], pad: f64, data: usize) -> TriBox {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for q in p {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k] - pad);
            hi[k] = hi[k].max(q[k] + pad);
        }
    }
    GeomWithData::new(Rectangle::from_corners(lo, hi), data)
}

/// 306: pairs of faces (from different polygons) that meet beyond the vertices they share.
fn self_intersections(mesh: &ShellMesh, opts: &Options) -> Vec<Issue> {
    let (eps, touch) = contact_eps(opts, mesh.extent());
    let tri_pts = |t: &[u32; 3]| [mesh.points[t[0] as usize], mesh.points[t[1] as usize], mesh.points[t[2] as usize]];
    let boxes: Vec<TriBox> = mesh.triangles.iter().enumerate().map(|(i, t)| tri_box(&tri_pts(t), touch, i)).collect();
    let tree = RTree::bulk_load(boxes.clone());
    let mut pairs: BTreeMap<(usize, usize), V3> = BTreeMap::new();
    for bi in &boxes {
        let i = bi.data;
        let ti = mesh.triangles[i];
        let env: AABB<[f64; 3]> = bi.geom().envelope_box();
        for bj in tree.locate_in_envelope_intersecting(&env) {
            let j = bj.data;
            if j <= i || mesh.triangle_polygon[i] == mesh.triangle_polygon[j] {
                continue;
            }
            let key = (mesh.triangle_polygon[i], mesh.triangle_polygon[j]);
            let key = (key.0.min(key.1), key.0.max(key.1));
            if pairs.contains_key(&key) {
                continue;
            }
            let tj = mesh.triangles[j];
            let shared: Vec<V3> = ti.iter().filter(|v| tj.contains(v)).map(|&v| mesh.points[v as usize]).collect();
            if shared.len() == 3 {
                pairs.insert(key, mesh.points[ti[0] as usize]);
                continue;
            }
            let c = contact(&tri_pts(&ti), &tri_pts(&tj), eps);
            let beyond = c.iter().find(|p| match shared.len() {
                0 => true,
                1 => (*p - shared[0]).norm() > touch,
                _ => point_segment_distance(p, &shared[0], &shared[1]) > touch,
            });
            if let Some(p) = beyond {
                pairs.insert(key, *p);
            }
        }
    }
    pairs
        .into_iter()
        .map(|((a, b), p)| {
            shell_issue(
                ErrorCode::ShellSelfIntersection,
                Some(a),
                format!("polygons #{} and #{} intersect near {}", a + 1, b + 1, fmt_abs(&(p + mesh.origin))),
            )
        })
        .collect()
}

trait EnvelopeBox {
    fn envelope_box(&self) -> AABB<[f64; 3]>;
}
impl EnvelopeBox for Rectangle<[f64; 3]> {
    fn envelope_box(&self) -> AABB<[f64; 3]> {
        AABB::from_corners(self.lower(), self.upper())
    }
}
