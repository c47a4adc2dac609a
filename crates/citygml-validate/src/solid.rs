//! Solid level (401–405) and CompositeSolid level (501–503).
//!
//! Solid: each shell must be valid on its own; then the exterior shell must face outwards and
//! interior shells (cavities) inwards (405), interior shells must not be duplicates (402), must
//! not cross another shell or share (part of) a face with it (401), must not lie outside the
//! exterior (403), and where shells touch along lines the contact must not close a loop that
//! cuts the interior of the solid in two (404, the 3D twin of 205).
//!
//! Shells may touch at points and along lines (as rings may in 2D). For genus-0 shells, the
//! union of the shells separates space into one region more than expected exactly when their
//! line contacts form a cycle (Alexander duality: the complement has 1 + b2 regions, and by
//! Mayer–Vietoris b2 grows by the first Betti number of the contact graph), so 404 is decided
//! on the contact graph: vertices merged at the contact tolerance, segments split where they
//! meet, cycles counted as E − V + C.
//!
//! CompositeSolid ([`check_composite_solid`]): each solid valid on its own, then no two solids
//! identical (502), no two with intersecting interiors (501: surfaces crossing, or one solid's
//! faces inside the other), and all of them connected through shared (parts of) faces (503).

use crate::codes::ErrorCode;
use crate::geom::V3;
use crate::polygon::PolygonInput;
use crate::shell::{check_shell, contact_eps, ShellMesh};
use crate::tritri::contact;
use crate::{Issue, Options};
use rstar::{primitives::GeomWithData, primitives::Rectangle, RTree, AABB};

fn solid_issue(code: ErrorCode, shell: usize, detail: String) -> Issue {
    Issue { code, polygon: None, ring: None, shell: Some(shell), detail, value: None }
}

/// Checks a solid given as its shells (index 0 = exterior, then cavities).
pub fn check_solid(shells: &[Vec<PolygonInput>], opts: &Options) -> Vec<Issue> {
    solid_meshes(shells, opts).0
}

/// The checks of [`check_solid`]; also returns the shells' meshes (common frame: the exterior
/// shell's origin) when the solid is valid. Each stage runs only when the ones before found
/// nothing: shells, 405, 402, 401, 403 / 401, 404.
fn solid_meshes(shells: &[Vec<PolygonInput>], opts: &Options) -> (Vec<Issue>, Vec<ShellMesh>) {
    let (issues, mut meshes) = shell_meshes(shells, opts);
    if !issues.is_empty() {
        return (issues, Vec::new());
    }
    let issues = check_shell_orientations(&meshes);
    if !issues.is_empty() {
        return (issues, Vec::new());
    }
    let o = to_common_frame(&mut meshes);
    if meshes.len() < 2 {
        return (issues, meshes);
    }
    let issues = check_duplicated_shells(&meshes, opts);
    if !issues.is_empty() {
        return (issues, Vec::new());
    }
    let extent = meshes[0].points.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let (eps, touch) = contact_eps(opts, extent);
    let (issues, lines) = check_shell_intersections(&meshes, eps, touch, o);
    if !issues.is_empty() {
        return (issues, Vec::new());
    }
    let issues = check_cavity_positions(&meshes, touch);
    if !issues.is_empty() {
        return (issues, Vec::new());
    }
    let issues = check_contact_loops(&lines, touch, o);
    if !issues.is_empty() {
        return (issues, Vec::new());
    }
    (issues, meshes)
}

/// Every shell's own checks (issues tagged with the shell's index), and the meshes of the valid ones.
fn shell_meshes(shells: &[Vec<PolygonInput>], opts: &Options) -> (Vec<Issue>, Vec<ShellMesh>) {
    let mut issues = Vec::new();
    let mut meshes: Vec<ShellMesh> = Vec::new();
    for (si, polys) in shells.iter().enumerate() {
        let (is, mesh) = check_shell(polys, opts);
        issues.extend(is.into_iter().map(|mut i| {
            i.shell = Some(si);
            i
        }));
        if let Some(m) = mesh {
            meshes.push(m);
        }
    }
    (issues, meshes)
}

/// 405: the exterior shell's normals point outwards (positive volume), the cavities' inwards.
fn check_shell_orientations(meshes: &[ShellMesh]) -> Vec<Issue> {
    let mut issues = Vec::new();
    for (si, m) in meshes.iter().enumerate() {
        let vol = m.signed_volume();
        if si == 0 && vol < 0.0 {
            issues.push(solid_issue(
                ErrorCode::WrongOrientationShell,
                si,
                format!("exterior shell has its normals pointing inwards (signed volume {:.6} m³)", vol),
            ));
        } else if si > 0 && vol > 0.0 {
            issues.push(solid_issue(
                ErrorCode::WrongOrientationShell,
                si,
                format!("interior shell {} has its normals pointing outwards (signed volume {:.6} m³)", si, vol),
            ));
        }
    }
    issues
}

/// Moves every mesh into the exterior shell's frame, so shells can be compared point by point;
/// returns that common origin.
fn to_common_frame(meshes: &mut [ShellMesh]) -> V3 {
    let o = meshes[0].origin;
    for m in meshes.iter_mut() {
        let d = m.origin - o;
        for p in m.points.iter_mut() {
            *p += d;
        }
        m.origin = o;
    }
    o
}

/// 402: two shells with the same vertices.
fn check_duplicated_shells(meshes: &[ShellMesh], opts: &Options) -> Vec<Issue> {
    let mut issues = Vec::new();
    let keys: Vec<_> = meshes.iter().map(|m| vertex_key(&m.points, opts)).collect();
    for a in 0..meshes.len() {
        for b in a + 1..meshes.len() {
            if keys[a] == keys[b] {
                issues.push(solid_issue(
                    ErrorCode::DuplicatedShells,
                    b,
                    format!("shells {} and {} are identical", a + 1, b + 1),
                ));
            }
        }
    }
    issues
}

/// 401: shells may touch at points and along lines, but not cross or share a face piece.
/// Also returns the lines along which shells touch (for 404).
fn check_shell_intersections(meshes: &[ShellMesh], eps: f64, touch: f64, o: V3) -> (Vec<Issue>, Vec<(V3, V3)>) {
    let mut issues = Vec::new();
    let trees: Vec<_> = meshes.iter().map(|m| tri_tree(m, touch)).collect();
    let mut lines: Vec<(V3, V3)> = Vec::new();
    for a in 0..meshes.len() {
        for b in a + 1..meshes.len() {
            let m = meet(&meshes[a], &trees[a], &meshes[b], &trees[b], eps, touch);
            if let Some(p) = m.crossing.or(m.shared_at) {
                let how = if m.crossing.is_some() { "intersect" } else { "share part of a face" };
                issues.push(solid_issue(
                    ErrorCode::IntersectionShells,
                    b,
                    format!("shells {} and {} {how} near {}", a + 1, b + 1, fmt(&(p + o))),
                ));
            }
            lines.extend(m.lines);
        }
    }
    (issues, lines)
}

/// 403 / 401: where a cavity lies (generalised winding number of its face centroids): all
/// outside the exterior is 403; partly outside, or inside another cavity, is 401 (a shell
/// crossing another along one of its own edges is not seen by the triangle pairs alone).
fn check_cavity_positions(meshes: &[ShellMesh], touch: f64) -> Vec<Issue> {
    let mut issues = Vec::new();
    let inside = |t: usize, p: &V3| winding_number(&meshes[t].points, &meshes[t].triangles, p);
    for s in 1..meshes.len() {
        let cs = samples(&meshes[s], touch);
        let outside = cs.iter().filter(|p| inside(0, p).abs() < 0.5).count();
        if outside == cs.len() {
            issues.push(solid_issue(
                ErrorCode::InnerShellOutside,
                s,
                format!("interior shell {} is not inside the exterior shell", s),
            ));
        } else if outside > 0 {
            issues.push(solid_issue(
                ErrorCode::IntersectionShells,
                s,
                format!("interior shell {} is partly outside the exterior shell (they cross)", s),
            ));
        } else if let Some(t) =
            (1..meshes.len()).filter(|&t| t != s).find(|&t| cs.iter().any(|p| inside(t, p).abs() > 0.5))
        {
            issues.push(solid_issue(
                ErrorCode::IntersectionShells,
                s,
                format!("interior shells {} and {} intersect (one reaches inside the other)", t, s),
            ));
        }
    }
    issues
}

/// 404: line contacts that close a loop cut a pocket out of the interior.
fn check_contact_loops(lines: &[(V3, V3)], touch: f64, o: V3) -> Vec<Issue> {
    let mut issues = Vec::new();
    let cycles = contact_cycles(lines, touch);
    if cycles > 0 {
        let at = lines.first().map(|l| fmt(&(l.0 + o))).unwrap_or_default();
        issues.push(solid_issue(
            ErrorCode::SolidInteriorDisconnected,
            0,
            format!(
                "the shells touch along {cycles} closed loop{} (near {at}): the interior of the solid is cut in pieces",
                if cycles == 1 { "" } else { "s" }
            ),
        ));
    }
    issues
}

/// Checks a CompositeSolid given as its solids (each: exterior shell, then cavities). Returns
/// the issues with the index of the solid they belong to (for 50x: the second solid involved).
/// Each stage runs only when the ones before found nothing: the solids one by one, then 502,
/// 501, 503.
pub fn check_composite_solid(solids: &[Vec<Vec<PolygonInput>>], opts: &Options) -> Vec<(usize, Issue)> {
    let (out, mut exts) = exterior_shells(solids, opts);
    if !out.is_empty() || exts.len() < 2 {
        return out;
    }
    let o = to_common_frame(&mut exts);
    let out = check_duplicated_solids(&exts, opts);
    if !out.is_empty() {
        return out;
    }
    let (out, adjacent) = SolidPairs::new(&exts, opts).check_intersections(o);
    if !out.is_empty() {
        return out;
    }
    check_disconnected_solids(adjacent, exts.len())
}

/// Each solid's own issues (with its index), and the exterior shells of the solids that have
/// meshes.
fn exterior_shells(solids: &[Vec<Vec<PolygonInput>>], opts: &Options) -> (Vec<(usize, Issue)>, Vec<ShellMesh>) {
    let mut out = Vec::new();
    let mut exts: Vec<ShellMesh> = Vec::new();
    for (k, shells) in solids.iter().enumerate() {
        let (is, mut meshes) = solid_meshes(shells, opts);
        out.extend(is.into_iter().map(|i| (k, i)));
        if !meshes.is_empty() {
            exts.push(meshes.swap_remove(0));
        }
    }
    (out, exts)
}

fn composite_issue(code: ErrorCode, detail: String) -> Issue {
    Issue { code, polygon: None, ring: None, shell: None, detail, value: None }
}

/// 502: two solids with the same vertices.
fn check_duplicated_solids(exts: &[ShellMesh], opts: &Options) -> Vec<(usize, Issue)> {
    let mut out = Vec::new();
    let keys: Vec<_> = exts.iter().map(|m| vertex_key(&m.points, opts)).collect();
    for a in 0..exts.len() {
        for b in a + 1..exts.len() {
            if keys[a] == keys[b] {
                out.push((
                    b,
                    composite_issue(
                        ErrorCode::DuplicatedSolids,
                        format!("solids {} and {} are identical", a + 1, b + 1),
                    ),
                ));
            }
        }
    }
    out
}

/// 503: every solid reachable from the first through shared faces.
fn check_disconnected_solids(mut adjacent: crate::shell::Dsu, count: usize) -> Vec<(usize, Issue)> {
    let root = adjacent.find(0);
    let detail = |k: usize| format!("solid {} shares no face with the other solids of the CompositeSolid", k + 1);
    (1..count)
        .filter(|&k| adjacent.find(k) != root)
        .map(|k| (k, composite_issue(ErrorCode::DisconnectedSolids, detail(k))))
        .collect()
}

/// The exterior shells of a CompositeSolid (in a common frame) for the pair tests, each shell's
/// triangle tree and inside samples built the first time a pair needs them.
struct SolidPairs<'a> {
    exts: &'a [ShellMesh],
    eps: f64,
    touch: f64,
    /// Bounding boxes grown by the contact tolerance: two solids whose boxes are apart can
    /// neither cross, nor share a face, nor hold one another, so the pair tests (triangle
    /// pairs, winding numbers) run only for pairs whose boxes meet.
    boxes: Vec<([f64; 3], [f64; 3])>,
    indexed: Vec<Option<(TriTree, Vec<V3>)>>,
}

impl<'a> SolidPairs<'a> {
    fn new(exts: &'a [ShellMesh], opts: &Options) -> SolidPairs<'a> {
        // The tolerances scale with the largest coordinate of any solid (in the common frame),
        // not of the first one only: a small first solid must not make them too tight for the
        // others.
        let extent = exts.iter().flat_map(|m| m.points.iter()).map(|p| p.norm()).fold(0.0, f64::max);
        let (eps, touch) = contact_eps(opts, extent);
        let boxes = exts.iter().map(|m| bbox(&m.points, touch)).collect();
        SolidPairs { exts, eps, touch, boxes, indexed: (0..exts.len()).map(|_| None).collect() }
    }

    /// 501 for each pair whose interiors intersect; the pairs that share a face joined.
    fn check_intersections(mut self, o: V3) -> (Vec<(usize, Issue)>, crate::shell::Dsu) {
        let mut out = Vec::new();
        let mut adjacent = crate::shell::Dsu::new(self.exts.len());
        for a in 0..self.exts.len() {
            for b in a + 1..self.exts.len() {
                if !self.boxes_overlap(a, b) {
                    continue;
                }
                let (crossing, shared) = self.meet(a, b);
                if let Some(p) = crossing {
                    let detail =
                        format!("the interiors of solids {} and {} intersect near {}", a + 1, b + 1, fmt(&(p + o)));
                    out.push((b, composite_issue(ErrorCode::IntersectionSolids, detail)));
                } else if shared {
                    adjacent.union(a, b);
                }
            }
        }
        (out, adjacent)
    }

    fn boxes_overlap(&self, a: usize, b: usize) -> bool {
        let boxes = &self.boxes;
        (0..3).all(|i| boxes[a].0[i] <= boxes[b].1[i] && boxes[b].0[i] <= boxes[a].1[i])
    }

    /// Where solids `a` and `b` intersect (crossing surfaces, or a point just inside one that
    /// is inside the other), else whether they share a face.
    fn meet(&mut self, a: usize, b: usize) -> (Option<V3>, bool) {
        for k in [a, b] {
            if self.indexed[k].is_none() {
                self.indexed[k] = Some((tri_tree(&self.exts[k], self.touch), samples(&self.exts[k], self.touch)));
            }
        }
        let (Some((ta, _)), Some((tb, _))) = (&self.indexed[a], &self.indexed[b]) else { return (None, false) };
        let m = meet(&self.exts[a], ta, &self.exts[b], tb, self.eps, self.touch);
        let crossing = m.crossing.or_else(|| self.inside(b, a)).or_else(|| self.inside(a, b));
        (crossing, m.shared_at.is_some())
    }

    /// A sample just inside solid `x` that lies inside solid `y` (only samples inside `y`'s
    /// box can be).
    fn inside(&self, x: usize, y: usize) -> Option<V3> {
        let (_, samples) = self.indexed[x].as_ref()?;
        let (lo, hi) = self.boxes[y];
        let in_box = |p: &V3| (0..3).all(|i| p[i] >= lo[i] && p[i] <= hi[i]);
        samples
            .iter()
            .filter(|p| in_box(p))
            .find(|p| winding_number(&self.exts[y].points, &self.exts[y].triangles, p).abs() > 0.5)
            .copied()
    }
}

/// Axis-aligned box of `ps`, grown by `grow` on every side.
fn bbox(ps: &[V3], grow: f64) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in ps {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    (lo.map(|v| v - grow), hi.map(|v| v + grow))
}

fn vertex_key(ps: &[V3], opts: &Options) -> Vec<[i64; 3]> {
    let mut k: Vec<[i64; 3]> =
        ps.iter().map(|p| [p.x, p.y, p.z].map(|c| (c / opts.snap_tol.max(1e-9)).round() as i64)).collect();
    k.sort_unstable();
    k.dedup();
    k
}

fn tri(m: &ShellMesh, t: &[u32; 3]) -> [V3; 3] {
    [m.points[t[0] as usize], m.points[t[1] as usize], m.points[t[2] as usize]]
}

/// One point per triangle, just inside the volume the shell bounds: the centroid moved
/// 10 × `touch` against the triangle's normal (with the normal for a cavity, whose faces point
/// into its void). Off the surface, so the winding number of such a point with respect to
/// another shell is 0 or ±1 even where the two shells share a face (on a surface it is not
/// well defined).
fn samples(m: &ShellMesh, touch: f64) -> Vec<V3> {
    let sign = if m.signed_volume() >= 0.0 { 1.0 } else { -1.0 };
    m.triangles
        .iter()
        .filter_map(|t| {
            let p = tri(m, t);
            let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
            let ln = n.norm();
            (ln > 0.0).then(|| (p[0] + p[1] + p[2]) / 3.0 - n * (sign * 10.0 * touch / ln))
        })
        .collect()
}

type TriTree = RTree<GeomWithData<Rectangle<[f64; 3]>, usize>>;

fn tri_tree(m: &ShellMesh, touch: f64) -> TriTree {
    let items = m
        .triangles
        .iter()
        .enumerate()
        .map(|(k, t)| {
            let p = tri(m, t);
            let lo = [0, 1, 2].map(|i| p.iter().map(|q| q[i]).fold(f64::INFINITY, f64::min) - touch);
            let hi = [0, 1, 2].map(|i| p.iter().map(|q| q[i]).fold(f64::NEG_INFINITY, f64::max) + touch);
            GeomWithData::new(Rectangle::from_corners(lo, hi), k)
        })
        .collect();
    RTree::bulk_load(items)
}

/// How the surfaces of two closed meshes meet.
#[derive(Default)]
struct Meeting {
    /// A point where they cross (a triangle of each passes through the other).
    crossing: Option<V3>,
    /// A point of a face piece they share (coplanar overlap with an area).
    shared_at: Option<V3>,
    /// Segments along which they touch.
    lines: Vec<(V3, V3)>,
}

fn meet(ma: &ShellMesh, ta: &TriTree, mb: &ShellMesh, tb: &TriTree, eps: f64, touch: f64) -> Meeting {
    let mut m = Meeting::default();
    for ia in ta.iter() {
        let a = tri(ma, &ma.triangles[ia.data]);
        let env = AABB::from_corners(ia.geom().lower(), ia.geom().upper());
        for ib in tb.locate_in_envelope_intersecting(&env) {
            let b = tri(mb, &mb.triangles[ib.data]);
            let c = contact(&a, &b, eps);
            if c.is_empty() {
                continue;
            }
            let (mut p, mut q, mut spread) = (c[0], c[0], 0.0);
            for x in &c {
                for y in &c {
                    let d = (x - y).norm();
                    if d > spread {
                        (p, q, spread) = (*x, *y, d);
                    }
                }
            }
            if spread <= touch {
                continue; // touching at a point
            }
            if c.len() >= 3 {
                let area: f64 = (1..c.len() - 1).map(|i| (c[i] - c[0]).cross(&(c[i + 1] - c[0])).norm() / 2.0).sum();
                if area > touch * spread {
                    m.shared_at.get_or_insert((p + q) / 2.0);
                    continue;
                }
            }
            if straddles(&a, &b, eps) && straddles(&b, &a, eps) {
                m.crossing.get_or_insert((p + q) / 2.0);
            } else {
                m.lines.push((p, q));
            }
        }
    }
    m
}

/// Whether triangle `t` has vertices strictly on both sides of the plane of `other`.
fn straddles(t: &[V3; 3], other: &[V3; 3], eps: f64) -> bool {
    let n = (other[1] - other[0]).cross(&(other[2] - other[0]));
    let ln = n.norm();
    if ln == 0.0 {
        return false;
    }
    let d = t.map(|p| n.dot(&(p - other[0])) / ln);
    d.iter().any(|&x| x > eps) && d.iter().any(|&x| x < -eps)
}

/// First Betti number (independent cycles) of the graph made by the contact segments: end
/// points merged within `tol`, each segment split at the vertices lying on it, repeated
/// pieces counted once.
fn contact_cycles(lines: &[(V3, V3)], tol: f64) -> usize {
    let mut verts: Vec<V3> = Vec::new();
    let id = |p: V3, verts: &mut Vec<V3>| -> usize {
        match verts.iter().position(|v| (v - p).norm() <= tol) {
            Some(i) => i,
            None => {
                verts.push(p);
                verts.len() - 1
            }
        }
    };
    let ends: Vec<(usize, usize)> = lines.iter().map(|(p, q)| (id(*p, &mut verts), id(*q, &mut verts))).collect();
    let mut edges: Vec<(usize, usize)> = Vec::new();
    for &(i, j) in &ends {
        if i == j {
            continue;
        }
        let (p, q) = (verts[i], verts[j]);
        let d = q - p;
        let len2 = d.norm_squared();
        // vertices on the segment, ordered along it
        let mut on: Vec<(f64, usize)> = vec![(0.0, i), (1.0, j)];
        for (k, v) in verts.iter().enumerate() {
            if k == i || k == j {
                continue;
            }
            let t = (v - p).dot(&d) / len2;
            if t > 0.0 && t < 1.0 && (p + d * t - v).norm() <= tol {
                on.push((t, k));
            }
        }
        on.sort_by(|a, b| a.0.total_cmp(&b.0));
        for w in on.windows(2) {
            let (x, y) = (w[0].1.min(w[1].1), w[0].1.max(w[1].1));
            if x != y {
                edges.push((x, y));
            }
        }
    }
    edges.sort_unstable();
    edges.dedup();
    let mut dsu = crate::shell::Dsu::new(verts.len());
    let mut cycles = 0;
    for &(a, b) in &edges {
        if !dsu.union(a, b) {
            cycles += 1;
        }
    }
    cycles
}

fn fmt(p: &V3) -> String {
    let r = |x: f64| (x * 1e6).round() / 1e6;
    format!("({}, {}, {})", r(p.x), r(p.y), r(p.z))
}

/// Generalised winding number of `q` with respect to a closed triangle mesh (Van Oosterom and
/// Strackee solid angles): 1 inside, 0 outside.
pub fn winding_number(points: &[V3], tris: &[[u32; 3]], q: &V3) -> f64 {
    let mut total = 0.0;
    for t in tris {
        let a = points[t[0] as usize] - q;
        let b = points[t[1] as usize] - q;
        let c = points[t[2] as usize] - q;
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let num = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + b.dot(&c) * la + c.dot(&a) * lb;
        total += 2.0 * num.atan2(den);
    }
    total / (4.0 * std::f64::consts::PI)
}
