//! Topological normalization (spec §3.1): polygon soup → nodes, directed edges, half-edges, faces
//! referencing solids. Snap tolerance: [`crate::Tolerances::snap`] (spec \[gap\], decided there).

use crate::soup::Soup;
use crate::{Notice, Rejection, Tolerances};
use popa3d_model::vec3::{cross, dot, sub};
use popa3d_model::VertexSource;
use std::collections::HashMap;

/// A face after topological normalization: rings of node indices oriented so that the right-hand
/// normal points out of `back` (into `front`, `None` = the exterior space).
#[derive(Debug, Clone)]
pub struct TopoFace {
    pub rings: Vec<Vec<usize>>,
    /// Index of the source polygon in the soup.
    pub polygon: usize,
    /// Soup polygons merged into this face by [`repair`].
    pub absorbed: Vec<usize>,
    pub back: usize,
    pub front: Option<usize>,
}

/// The point-parameterised topological model of one soup.
#[derive(Debug, Clone, Default)]
pub struct Topo {
    /// Node coordinates (source CRS; the first point snapped to a node is its representative).
    pub points: Vec<[f64; 3]>,
    pub node_sources: Vec<Vec<VertexSource>>,
    pub faces: Vec<TopoFace>,
    /// Directed edges (start, end).
    pub edges: Vec<(usize, usize)>,
    /// (edge, +1/−1, face).
    pub half_edges: Vec<(usize, i8, usize)>,
    /// Counts before normalization: distinct nodes, distinct edges, input polygons.
    pub soup_nodes: usize,
    pub soup_edges: usize,
    pub soup_faces: usize,
    pub soup_points: usize,
    /// Source vertices lying on an edge between its end nodes (collinear nodes removed by
    /// [`repair`]), keyed by the edge's node pair (smaller index first).
    pub edge_sources: HashMap<(usize, usize), Vec<VertexSource>>,
}

/// Grid hash for snapping points within `tol`.
struct Snapper {
    tol: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

impl Snapper {
    fn key(&self, p: &[f64; 3]) -> [i64; 3] {
        [(p[0] / self.tol).floor() as i64, (p[1] / self.tol).floor() as i64, (p[2] / self.tol).floor() as i64]
    }
    fn find_or_insert(&mut self, p: [f64; 3], points: &mut Vec<[f64; 3]>) -> usize {
        let k = self.key(&p);
        let mut best: Option<(usize, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        for &i in v {
                            let d = dist(&points[i], &p);
                            if d <= self.tol && best.is_none_or(|(_, b)| d < b) {
                                best = Some((i, d));
                            }
                        }
                    }
                }
            }
        }
        if let Some((i, _)) = best {
            return i;
        }
        points.push(p);
        let i = points.len() - 1;
        self.cells.entry(k).or_default().push(i);
        i
    }
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Builds the topology of one soup. Rejects (naming the source polygon) rings with fewer than three
/// distinct points (TA05), open shells (TA03) and shells that cannot be oriented consistently.
/// Duplicate faces of one solid are removed with a notice (spec §3.1: duplicates are redundancy).
pub fn build(soup: &Soup, tol: &Tolerances, notices: &mut Vec<Notice>) -> Result<Topo, Rejection> {
    if soup.polygons.is_empty() {
        return Err(Rejection::new("NO-GEOMETRY", &soup.name, "no polygons to convert"));
    }
    let mut t = Topo { soup_faces: soup.polygons.len(), ..Default::default() };
    let mut rings_nodes = snap_rings(soup, tol, &mut t)?;
    t.soup_nodes = t.points.len();
    t.soup_edges = count_edges(&rings_nodes);
    insert_t_junctions(&mut rings_nodes, &t.points, tol.snap);
    merge_duplicate_faces(&rings_nodes, soup, &mut t, notices);
    // Orientation per solid: breadth-first over faces sharing edges, then the sign of the volume.
    let nsol = soup.solids.len();
    // flip[f] for the face as seen from its back solid.
    let mut flip = vec![false; t.faces.len()];
    for s in 0..nsol {
        let faces: Vec<usize> =
            (0..t.faces.len()).filter(|&f| t.faces[f].back == s || t.faces[f].front == Some(s)).collect();
        if faces.is_empty() {
            continue;
        }
        let uses = edge_uses(&t, &faces);
        check_closed(&uses, &t, soup)?;
        let (o, comps) = orient_components(&faces, &uses, &t, soup)?;
        for comp in comps {
            let outward = signed_volume(&t, &comp, &o) >= 0.0;
            for &f in &comp {
                let out_for_s = o[&f] == outward;
                // Decide the stored orientation from the face's back solid only.
                if t.faces[f].back == s {
                    flip[f] = !out_for_s;
                } else if t.faces[f].front == Some(s) && !faces_has_back_decided(&t.faces[f], s) {
                    // A shared face first met from its front solid: seen from the back it is reversed.
                    flip[f] = out_for_s;
                }
            }
        }
    }
    for (f, fl) in flip.iter().enumerate() {
        if *fl {
            for r in t.faces[f].rings.iter_mut() {
                r.reverse();
            }
        }
    }

    rebuild_edges(&mut t);
    Ok(t)
}

/// Every ring as node ids: points within the snap tolerance are one node (hashed on a grid of the
/// tolerance), consecutive repeats and the closing point dropped; a ring left with fewer than 3
/// distinct nodes, or with a coordinate that is not finite, is refused (TA05). Fills the points,
/// their sources and the soup's point count in `t`.
fn snap_rings(soup: &Soup, tol: &Tolerances, t: &mut Topo) -> Result<Vec<Vec<Vec<usize>>>, Rejection> {
    // Reduce to a local frame before hashing so snapping works at the same resolution everywhere.
    let mut snap = Snapper { tol: tol.snap.max(1e-9), cells: HashMap::new() };
    let mut rings_nodes: Vec<Vec<Vec<usize>>> = Vec::with_capacity(soup.polygons.len());
    for poly in &soup.polygons {
        let mut rings = Vec::new();
        for (ri, ring) in poly.rings.iter().enumerate() {
            t.soup_points += ring.len();
            let mut ids: Vec<usize> = Vec::with_capacity(ring.len());
            for (vi, p) in ring.iter().enumerate() {
                if !p.iter().all(|x| x.is_finite()) {
                    return Err(Rejection::new(
                        "TA05",
                        &poly.locator,
                        format!("ring {ri} point {vi} is not a finite coordinate"),
                    ));
                }
                let n = snap.find_or_insert(*p, &mut t.points);
                if t.node_sources.len() < t.points.len() {
                    t.node_sources.push(Vec::new());
                }
                if let Some(s) = poly.vertex_sources.get(ri).and_then(|r| r.get(vi)) {
                    t.node_sources[n].push(s.clone());
                }
                if ids.last() != Some(&n) {
                    ids.push(n);
                }
            }
            while ids.len() > 1 && ids.first() == ids.last() {
                ids.pop();
            }
            let mut distinct = ids.clone();
            distinct.sort();
            distinct.dedup();
            if distinct.len() < 3 {
                return Err(Rejection::new(
                    "TA05",
                    &poly.locator,
                    format!(
                        "{} ring {ri} has {} distinct point(s) within the snap tolerance {} m; a face needs at least 3",
                        if ri == 0 { "exterior" } else { "interior" },
                        distinct.len(),
                        tol.snap
                    ),
                ));
            }
            rings.push(ids);
        }
        rings_nodes.push(rings);
    }
    Ok(rings_nodes)
}

/// Distinct undirected edges of the rings.
fn count_edges(rings_nodes: &[Vec<Vec<usize>>]) -> usize {
    let mut es = std::collections::HashSet::new();
    for rings in rings_nodes {
        for r in rings {
            for i in 0..r.len() {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                es.insert((a.min(b), a.max(b)));
            }
        }
    }
    es.len()
}

/// T-junctions: a node lying on another face's edge (within `snap` of it) is inserted into that
/// edge, so both faces share the same edges (common in LoD2 data where a wall meets two roof
/// polygons).
fn insert_t_junctions(rings_nodes: &mut [Vec<Vec<usize>>], points: &[[f64; 3]], snap: f64) {
    for rings in rings_nodes.iter_mut() {
        for r in rings.iter_mut() {
            let mut out = Vec::with_capacity(r.len());
            for i in 0..r.len() {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                out.push(a);
                let pa = points[a];
                let ab = sub(points[b], pa);
                let len2 = dot(ab, ab);
                if len2 <= 0.0 {
                    continue;
                }
                let mut on: Vec<(f64, usize)> = Vec::new();
                for (n, p) in points.iter().enumerate() {
                    if n == a || n == b {
                        continue;
                    }
                    let ap = sub(*p, pa);
                    let s = dot(ap, ab) / len2;
                    if s <= 0.0 || s >= 1.0 {
                        continue;
                    }
                    let c = cross(ap, ab);
                    if dot(c, c) / len2 <= snap * snap {
                        on.push((s, n));
                    }
                }
                on.sort_by(|x, y| x.0.total_cmp(&y.0));
                out.extend(on.into_iter().map(|x| x.1));
            }
            *r = out;
        }
    }
}

/// Duplicate faces: the same cycle in either direction. In the same solid: removed with a notice;
/// in two different solids: one face shared by both (it separates them, spec §3.1 item 5).
fn merge_duplicate_faces(rings_nodes: &[Vec<Vec<usize>>], soup: &Soup, t: &mut Topo, notices: &mut Vec<Notice>) {
    let mut seen: HashMap<Vec<usize>, usize> = HashMap::new();
    for (pi, rings) in rings_nodes.iter().enumerate() {
        let key = cycle_key(&rings[0]);
        let solid = soup.polygons[pi].solid;
        if let Some(&fi) = seen.get(&key) {
            let f: &mut TopoFace = &mut t.faces[fi];
            if f.back == solid || f.front == Some(solid) {
                notices.push(Notice {
                    rule: "DUPLICATE".into(),
                    element: soup.polygons[pi].locator.clone(),
                    message: format!(
                        "duplicate of polygon {} (same boundary); removed",
                        soup.polygons[f.polygon].locator
                    ),
                });
            } else if f.front.is_none() {
                f.front = Some(solid);
            } else {
                notices.push(Notice {
                    rule: "DUPLICATE".into(),
                    element: soup.polygons[pi].locator.clone(),
                    message: "a third solid uses this face; removed".into(),
                });
            }
            continue;
        }
        seen.insert(key, t.faces.len());
        t.faces.push(TopoFace { rings: rings.clone(), polygon: pi, absorbed: Vec::new(), back: solid, front: None });
    }
}

/// (face, stored direction a→b) per undirected edge of `faces`.
#[allow(clippy::type_complexity)]
fn edge_uses(t: &Topo, faces: &[usize]) -> HashMap<(usize, usize), Vec<(usize, bool)>> {
    // (face, stored direction a→b) per undirected edge.
    let mut uses: HashMap<(usize, usize), Vec<(usize, bool)>> = HashMap::new();
    for &f in faces {
        for r in &t.faces[f].rings {
            for i in 0..r.len() {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                uses.entry((a.min(b), a.max(b))).or_default().push((f, a < b));
            }
        }
    }
    uses
}

/// Closedness (TA03): every edge used an even number of times by the solid's faces (2-manifold: 2).
fn check_closed(uses: &HashMap<(usize, usize), Vec<(usize, bool)>>, t: &Topo, soup: &Soup) -> Result<(), Rejection> {
    let mut open: Vec<(&(usize, usize), &Vec<(usize, bool)>)> = uses.iter().filter(|(_, v)| v.len() % 2 == 1).collect();
    if !open.is_empty() {
        open.sort_by_key(|(k, _)| **k);
        let (k, v) = open[0];
        let p = &soup.polygons[t.faces[v[0].0].polygon];
        let (a, b) = (t.points[k.0], t.points[k.1]);
        return Err(Rejection::new(
            "TA03",
            &p.locator,
            format!(
                "open shell: the edge ({:.3} {:.3} {:.3})–({:.3} {:.3} {:.3}) of this polygon is used by no other face of the solid ({} such edge(s) in all); a closed solid needs every edge in two faces",
                a[0], a[1], a[2], b[0], b[1], b[2], open.len()
            ),
        ));
    }
    Ok(())
}

/// Orientation as seen from the solid: o[f] = the face's stored direction is consistent with
/// the first face of its component (breadth-first over faces sharing a 2-manifold edge, which
/// must run it in opposite directions; ORIENT when they cannot). Returns o and the components.
#[allow(clippy::type_complexity)]
fn orient_components(
    faces: &[usize],
    uses: &HashMap<(usize, usize), Vec<(usize, bool)>>,
    t: &Topo,
    soup: &Soup,
) -> Result<(HashMap<usize, bool>, Vec<Vec<usize>>), Rejection> {
    let mut o: HashMap<usize, bool> = HashMap::new();
    let mut edges_of: HashMap<usize, Vec<(usize, usize)>> = HashMap::new();
    for (k, v) in uses {
        for (f, _) in v {
            edges_of.entry(*f).or_default().push(*k);
        }
    }
    let mut comps: Vec<Vec<usize>> = Vec::new();
    for &f0 in faces {
        if o.contains_key(&f0) {
            continue;
        }
        o.insert(f0, true);
        let mut comp = vec![f0];
        let mut queue = std::collections::VecDeque::from([f0]);
        while let Some(f) = queue.pop_front() {
            let mut ks = edges_of.get(&f).cloned().unwrap_or_default();
            ks.sort();
            ks.dedup();
            for k in ks {
                let v = &uses[&k];
                if v.len() != 2 {
                    continue; // non-manifold edge: leave to the neighbours through other edges
                }
                let (g, gdir) = if v[0].0 == f { v[1] } else { v[0] };
                let fdir = if v[0].0 == f { v[0].1 } else { v[1].1 };
                if g == f {
                    continue;
                }
                // Consistent: the two faces run the edge in opposite directions.
                let want = if fdir == gdir { !o[&f] } else { o[&f] };
                match o.get(&g) {
                    Some(&x) if x != want => {
                        return Err(Rejection::new(
                            "ORIENT",
                            &soup.polygons[t.faces[g].polygon].locator,
                            "the shell cannot be oriented consistently (non-orientable or self-overlapping faces)",
                        ))
                    }
                    Some(_) => {}
                    None => {
                        o.insert(g, want);
                        comp.push(g);
                        queue.push_back(g);
                    }
                }
            }
        }
        comps.push(comp);
    }
    Ok((o, comps))
}

/// Signed volume of a component with the chosen orientation (negative: it faces inward).
fn signed_volume(t: &Topo, comp: &[usize], o: &HashMap<usize, bool>) -> f64 {
    // Signed volume with the chosen orientation; negative → flip the whole component.
    let c = t.points[t.faces[comp[0]].rings[0][0]];
    let mut vol = 0.0;
    for &f in comp {
        let sgn = if o[&f] { 1.0 } else { -1.0 };
        for r in &t.faces[f].rings {
            let p0 = sub(t.points[r[0]], c);
            for i in 1..r.len() - 1 {
                let p1 = sub(t.points[r[i]], c);
                let p2 = sub(t.points[r[i + 1]], c);
                vol += sgn * dot(p0, cross(p1, p2)) / 6.0;
            }
        }
    }
    vol
}

/// Shared faces always have their back solid processed first (solids in index order, the back solid
/// is the one that listed the polygon first), so the front side never decides.
fn faces_has_back_decided(f: &TopoFace, s: usize) -> bool {
    f.back < s
}

/// A cycle's key independent of start node and direction.
fn cycle_key(r: &[usize]) -> Vec<usize> {
    let n = r.len();
    let m = (0..n).min_by_key(|&i| r[i]).unwrap_or(0);
    let fwd: Vec<usize> = (0..n).map(|i| r[(m + i) % n]).collect();
    let bwd: Vec<usize> = (0..n).map(|i| r[(m + n - i) % n]).collect();
    fwd.min(bwd)
}

/// (Re)builds directed edges and half-edges from the faces' rings: an edge takes the direction of
/// its first use.
pub fn rebuild_edges(t: &mut Topo) {
    t.edges.clear();
    t.half_edges.clear();
    let mut edge_ix: HashMap<(usize, usize), usize> = HashMap::new();
    for (fi, f) in t.faces.iter().enumerate() {
        for r in &f.rings {
            for i in 0..r.len() {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                let k = (a.min(b), a.max(b));
                let e = *edge_ix.entry(k).or_insert_with(|| {
                    t.edges.push((a, b));
                    t.edges.len() - 1
                });
                let sign = if t.edges[e] == (a, b) { 1 } else { -1 };
                t.half_edges.push((e, sign, fi));
            }
        }
    }
}

/// Repairs nodes that are not the intersection of three independent planes (GA01), the two typical
/// cases of spec §7.4 / Fig. 6.3: an edge between two coplanar faces of the same semantic type and
/// solids is deleted and the faces merged; a node left with only two neighbours on a straight line
/// ("a face side split at a node with only 2 edges", TA01) is removed and its two edges merged.
/// `deficient` are the nodes to repair; `mergeable(f, g)` says whether two faces may become one
/// (nearly coplanar); merged pairs of source polygons are appended to `merged`. Returns whether anything changed. Removed nodes keep no popa3d node: their
/// source vertices lie on the line of their neighbours.
pub fn repair(
    t: &mut Topo,
    deficient: &[usize],
    mergeable: &dyn Fn(usize, usize) -> bool,
    merged: &mut Vec<(usize, usize)>,
) -> bool {
    let mut changed = merge_faces_at_deficient_nodes(t, deficient, mergeable, merged);
    changed |= remove_two_neighbour_nodes(t, deficient);
    if changed {
        renumber_used_nodes(t);
        rebuild_edges(t);
    }
    changed
}

/// Step 1 of [`repair`]: merges mergeable faces with the same solids across the edges at deficient
/// nodes (each merged pair appended to `merged`). Returns whether any faces were merged.
fn merge_faces_at_deficient_nodes(
    t: &mut Topo,
    deficient: &[usize],
    mergeable: &dyn Fn(usize, usize) -> bool,
    merged: &mut Vec<(usize, usize)>,
) -> bool {
    let def: std::collections::HashSet<usize> = deficient.iter().cloned().collect();
    let uses = edge_face_uses(t);
    let mut parent: Vec<usize> = (0..t.faces.len()).collect();
    let mut changed = false;
    let mut keys: Vec<&(usize, usize)> = uses.keys().collect();
    keys.sort();
    for k in keys {
        let v = &uses[k];
        if v.len() != 2 || !(def.contains(&k.0) || def.contains(&k.1)) {
            continue;
        }
        let (f, g) = (v[0], v[1]);
        if f == g || !mergeable(f, g) {
            continue;
        }
        if t.faces[f].back != t.faces[g].back || t.faces[f].front != t.faces[g].front {
            continue;
        }
        let (rf, rg) = (find_root(&mut parent, f), find_root(&mut parent, g));
        if rf != rg {
            parent[rf.max(rg)] = rf.min(rg);
            merged.push((t.faces[f].polygon, t.faces[g].polygon));
            changed = true;
        }
    }
    if changed {
        t.faces = merged_faces(t, &mut parent);
    }
    changed
}

/// Undirected edge → the faces using it (a face once per use), in face order.
fn edge_face_uses(t: &Topo) -> HashMap<(usize, usize), Vec<usize>> {
    let mut uses: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (fi, f) in t.faces.iter().enumerate() {
        for r in &f.rings {
            for i in 0..r.len() {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                uses.entry((a.min(b), a.max(b))).or_default().push(fi);
            }
        }
    }
    uses
}

/// The root of `x` in the union-find forest `p`, compressing `x`'s path.
fn find_root(p: &mut [usize], x: usize) -> usize {
    let mut r = x;
    while p[r] != r {
        r = p[r];
    }
    p[x] = r;
    r
}

/// One face per union-find group, at the position of its root (the group's first face); a group
/// whose boundary closes no ring is dropped.
fn merged_faces(t: &Topo, parent: &mut [usize]) -> Vec<TopoFace> {
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for f in 0..t.faces.len() {
        let r = find_root(parent, f);
        groups.entry(r).or_default().push(f);
    }
    (0..t.faces.len()).filter_map(|f| groups.get(&f).and_then(|g| merged_face(t, f, g))).collect()
}

/// Face `root` grown by the other faces of its group `g`: their common boundary as rings, the
/// outer one first, and their polygons recorded as absorbed.
fn merged_face(t: &Topo, root: usize, g: &[usize]) -> Option<TopoFace> {
    if g.len() == 1 {
        return Some(t.faces[root].clone());
    }
    let mut rings = group_boundary_rings(t, g);
    if rings.is_empty() {
        return None;
    }
    // Outer ring first: the largest |Newell| area.
    let area = |r: &Vec<usize>| {
        let p: Vec<[f64; 3]> = r.iter().map(|&i| t.points[i]).collect();
        let n = popa3d_model::topology::newell(&p);
        (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
    };
    let imax = (0..rings.len()).max_by(|&a, &b| area(&rings[a]).total_cmp(&area(&rings[b]))).unwrap_or(0);
    rings.swap(0, imax);
    let mut nf = t.faces[root].clone();
    nf.rings = rings;
    for &h in g.iter().filter(|&&h| h != root) {
        nf.absorbed.push(t.faces[h].polygon);
        nf.absorbed.extend(t.faces[h].absorbed.iter().copied());
    }
    Some(nf)
}

/// The directed boundary edges of a group of faces minus the internal ones (used in both
/// directions), chained into rings of at least 3 nodes, starting from the smallest edge.
fn group_boundary_rings(t: &Topo, g: &[usize]) -> Vec<Vec<usize>> {
    let mut de: Vec<(usize, usize)> = Vec::new();
    for &h in g {
        for r in &t.faces[h].rings {
            for i in 0..r.len() {
                de.push((r[i], r[(i + 1) % r.len()]));
            }
        }
    }
    let set: std::collections::HashSet<(usize, usize)> = de.iter().cloned().collect();
    let mut rest: Vec<(usize, usize)> = de.into_iter().filter(|(a, b)| !set.contains(&(*b, *a))).collect();
    rest.sort();
    let mut rings = Vec::new();
    while let Some(&(a0, b0)) = rest.first() {
        rest.remove(0);
        let mut ring = vec![a0];
        let mut cur = b0;
        while cur != a0 {
            ring.push(cur);
            match rest.iter().position(|(a, _)| *a == cur) {
                Some(i) => cur = rest.remove(i).1,
                None => break,
            }
        }
        if ring.len() >= 3 {
            rings.push(ring);
        }
    }
    rings
}

/// Step 2 of [`repair`]: removes the deficient nodes with exactly two neighbours from the rings,
/// their source vertices carried to the edge that replaces them; rings left with < 3 nodes and
/// faces left without rings are dropped. Returns whether a ring lost a node.
fn remove_two_neighbour_nodes(t: &mut Topo, deficient: &[usize]) -> bool {
    let nb = node_neighbours(t);
    let removable: std::collections::HashSet<usize> =
        deficient.iter().cloned().filter(|n| nb.get(n).is_some_and(|s| s.len() == 2)).collect();
    if removable.is_empty() {
        return false;
    }
    carry_sources_past(t, &removable);
    let mut changed = false;
    for f in t.faces.iter_mut() {
        for r in f.rings.iter_mut() {
            let before = r.len();
            r.retain(|n| !removable.contains(n));
            if r.len() != before {
                changed = true;
            }
        }
        f.rings.retain(|r| r.len() >= 3);
    }
    t.faces.retain(|f| !f.rings.is_empty());
    changed
}

/// Node → its neighbours along the faces' rings.
fn node_neighbours(t: &Topo) -> HashMap<usize, std::collections::BTreeSet<usize>> {
    let mut nb: HashMap<usize, std::collections::BTreeSet<usize>> = HashMap::new();
    for f in &t.faces {
        for r in &f.rings {
            for i in 0..r.len() {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                nb.entry(a).or_default().insert(b);
                nb.entry(b).or_default().insert(a);
            }
        }
    }
    nb
}

/// Carries the removed nodes' source vertices (and those already on the edges they split) to
/// the edge between the kept neighbours, so no source vertex is lost with its node.
fn carry_sources_past(t: &mut Topo, removable: &std::collections::HashSet<usize>) {
    let mut done: std::collections::HashSet<(usize, usize)> = std::collections::HashSet::new();
    let mut moved: Vec<((usize, usize), Vec<VertexSource>)> = Vec::new();
    for f in &t.faces {
        for r in &f.rings {
            let k = r.len();
            for i in 0..k {
                if removable.contains(&r[i]) || !removable.contains(&r[(i + 1) % k]) {
                    continue;
                }
                let chain = removed_chain(r, i, removable);
                let (p, q) = (chain[0], chain[chain.len() - 1]);
                let key = (p.min(q), p.max(q));
                if done.insert(key) {
                    moved.push((key, chain_sources(&mut t.edge_sources, &t.node_sources, &chain)));
                }
            }
        }
    }
    for (k, v) in moved {
        t.edge_sources.entry(k).or_default().extend(v);
    }
}

/// From the kept node `r[i]` along the ring over the removable nodes to the next kept one
/// (both ends included).
fn removed_chain(r: &[usize], i: usize, removable: &std::collections::HashSet<usize>) -> Vec<usize> {
    let k = r.len();
    let mut chain = vec![r[i]];
    let mut j = (i + 1) % k;
    while removable.contains(&r[j]) && chain.len() <= k {
        chain.push(r[j]);
        j = (j + 1) % k;
    }
    chain.push(r[j]);
    chain
}

/// The sources on the chain's edges (taken from `edge_sources`) followed by its inner nodes'.
fn chain_sources(
    edge_sources: &mut HashMap<(usize, usize), Vec<VertexSource>>,
    node_sources: &[Vec<VertexSource>],
    chain: &[usize],
) -> Vec<VertexSource> {
    let mut src = Vec::new();
    for w in chain.windows(2) {
        if let Some(v) = edge_sources.remove(&(w[0].min(w[1]), w[0].max(w[1]))) {
            src.extend(v);
        }
    }
    for n in &chain[1..chain.len() - 1] {
        src.extend(node_sources[*n].iter().cloned());
    }
    src
}

/// Drops nodes no ring uses any more and renumbers the rest in order of first use.
fn renumber_used_nodes(t: &mut Topo) {
    let mut map = vec![usize::MAX; t.points.len()];
    let mut points = Vec::new();
    let mut sources = Vec::new();
    for f in t.faces.iter_mut() {
        for r in f.rings.iter_mut() {
            for n in r.iter_mut() {
                if map[*n] == usize::MAX {
                    map[*n] = points.len();
                    points.push(t.points[*n]);
                    sources.push(t.node_sources[*n].clone());
                }
                *n = map[*n];
            }
        }
    }
    t.points = points;
    t.node_sources = sources;
    t.edge_sources = std::mem::take(&mut t.edge_sources)
        .into_iter()
        .filter(|((a, b), _)| map[*a] != usize::MAX && map[*b] != usize::MAX)
        .map(|((a, b), v)| ((map[a].min(map[b]), map[a].max(map[b])), v))
        .collect();
}
