//! Geometric normalization (spec §3.2): points → planes → shared normals → shared parameters.
//!
//! Decisions for the spec's \[gap\]s (§3.2, §10.2 items 14, 15):
//! * Plane fit: orthogonal least squares through all vertices of all rings (centroid + eigenvector of
//!   the smallest eigenvalue of the scatter matrix), oriented like the outer ring's Newell normal.
//! * Equal normals: greedy clustering in order of decreasing face area; a normal joins the first
//!   cluster whose direction is within the angle tolerance of it or of its negation (spec §4.6 step 1
//!   canonical direction, T 2.5, is applied to the cluster's mean). Merged values are area-weighted
//!   means (spec \[proposal\]).
//! * Equal planes: per normal, faces sorted by d = ⟨n, centroid⟩; a plane collects faces within the
//!   distance tolerance of its first face; d is the area-weighted mean.
//! * Orthogonal parameter sharing: a normal whose component k is zero (within the angle tolerance,
//!   then snapped to 0) pairs with another such normal equal to the first rotated by 90° about axis k;
//!   the partner references the first's parameters swapped with a sign, (a, b, c) → (−b, a, c), and
//!   the shared zero parameter c gets a `ParameterFix` (spec §3.3: "α6 = 0, needed by the sign-swap
//!   trick"). Each normal takes part in at most one pair.

use crate::counts::{Counts, StageCounts};
use crate::soup::Soup;
use crate::topology::Topo;
use crate::{Rejection, Tolerances};
use nalgebra::{Matrix3, Vector3};
use popa3d_model::*;

/// One normalized soup, ready to be appended to a model (ids local, starting at 0).
#[derive(Debug, Clone)]
pub struct Part {
    pub model: Popa3d,
    pub counts: Counts,
    /// Parameters that must stay 0 (the shared component of a swap pair).
    pub zero_params: Vec<ParamId>,
    /// Largest distance between a node recomputed from its planes and its source point (m).
    pub max_node_shift: f64,
    /// Repairs made on the way (merged faces).
    pub notices: Vec<crate::Notice>,
}

/// Nodes whose planes' unit normals have a smallest singular value below sin(1°) count as not
/// determined (GA01, spec §7.4): their intersection moves by ≈ δd / sin(angle), metres for the
/// millimetre noise of real LoD2 data. They are repaired by merging the nearly coplanar faces
/// around them (spec §7.4: "delete that undefined edge, merge the faces").
pub const ILL_CONDITIONED_DEG: f64 = 1.0;

/// Smallest singular value of the stacked unit normals (0 for fewer than 3 planes).
fn min_singular(vals: &[popa3d_model::geometry::PlaneValue]) -> f64 {
    if vals.len() < 3 {
        return 0.0;
    }
    let mut ata = Matrix3::zeros();
    for v in vals {
        let n = Vector3::from(v.n);
        let u = n / n.norm().max(f64::MIN_POSITIVE);
        ata += u * u.transpose();
    }
    ata.symmetric_eigenvalues().iter().cloned().fold(f64::INFINITY, f64::min).max(0.0).sqrt()
}

fn newell(pts: &[[f64; 3]]) -> Vector3<f64> {
    Vector3::from(popa3d_model::topology::newell(pts))
}

/// Computes planes, normals, parameters for the topology and builds the part's model. `origin` is
/// the model's local origin (subtracted from every coordinate).
pub fn build(soup: &Soup, topo: &Topo, tol: &Tolerances, origin: [f64; 3]) -> Result<Part, Rejection> {
    build_depth(soup, topo, tol, origin, 0)
}

fn build_depth(soup: &Soup, topo: &Topo, tol: &Tolerances, origin: [f64; 3], depth: usize) -> Result<Part, Rejection> {
    let pts: Vec<[f64; 3]> =
        topo.points.iter().map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]]).collect();
    let net = PlaneNet::of(soup, topo, &pts, tol)?;
    // GA01 repair (spec §7.4): nodes whose faces span fewer than 3 independent plane directions.
    if depth < 4 {
        let deficient = net.deficient_nodes(topo, pts.len());
        if !deficient.is_empty() {
            if let Some(part) = repaired(soup, topo, tol, origin, depth, &net, &deficient)? {
                return Ok(part);
            }
        }
    }
    let (m, zero_params) = net.model(soup, topo, origin);
    let inc = Incidence::new(&m);
    check_simple_cycles(&m, &inc, soup)?;
    let max_shift = max_node_shift(&m, &inc, topo, &pts, tol, soup)?;
    let counts = part_counts(soup, topo, &m, &net, max_shift);
    Ok(Part { model: m, counts, zero_params, max_node_shift: max_shift, notices: Vec::new() })
}

/// Steps 1–4 of geometric normalization on one part's faces: per face its least-squares
/// normal, plane and sign relative to the cluster normal; the cluster normals
/// (orthogonal partners sharing parameters) and the planes as (cluster, d, first face).
struct PlaneNet {
    fnormal: Vec<Vector3<f64>>,
    fsign: Vec<f64>,
    fplane: Vec<usize>,
    cnormal: Vec<Vector3<f64>>,
    partner: Vec<Option<(usize, usize)>>,
    planes: Vec<(usize, f64, usize)>,
}

impl PlaneNet {
    fn of(soup: &Soup, topo: &Topo, pts: &[[f64; 3]], tol: &Tolerances) -> Result<PlaneNet, Rejection> {
        let nf = topo.faces.len();
        let (fnormal, fcent, farea) = face_planes(soup, topo, pts, tol)?;

        let cos_tol = tol.normal_angle_deg.to_radians().cos();
        let (mut cnormal, fcluster) = cluster_normals(&fnormal, &farea, cos_tol);

        // 4 (before 3, since it changes the normals): orthogonal sharing.
        let partner = if tol.share_orthogonal {
            share_orthogonal(&mut cnormal, cos_tol, tol.normal_angle_deg.to_radians().sin())
        } else {
            vec![None; cnormal.len()]
        };

        // 3. Planes per normal (coplanar faces).
        let fsign: Vec<f64> =
            (0..nf).map(|f| if cnormal[fcluster[f]].dot(&fnormal[f]) >= 0.0 { 1.0 } else { -1.0 }).collect();
        let fd: Vec<f64> = (0..nf).map(|f| cnormal[fcluster[f]].dot(&fcent[f])).collect();
        let (planes, fplane) = coplanar_planes(cnormal.len(), &fcluster, &fd, &farea, tol.plane_distance);
        Ok(PlaneNet { fnormal, fsign, fplane, cnormal, partner, planes })
    }

    /// Nodes whose planes' normals are not 3 independent directions (smallest singular value
    /// below sin(ILL_CONDITIONED_DEG)).
    fn deficient_nodes(&self, topo: &Topo, n_points: usize) -> Vec<usize> {
        let mut node_planes: Vec<Vec<usize>> = vec![Vec::new(); n_points];
        for (fi, f) in topo.faces.iter().enumerate() {
            for r in &f.rings {
                for &n in r {
                    if !node_planes[n].contains(&self.fplane[fi]) {
                        node_planes[n].push(self.fplane[fi]);
                    }
                }
            }
        }
        (0..n_points)
            .filter(|&n| {
                let vals: Vec<popa3d_model::geometry::PlaneValue> = node_planes[n]
                    .iter()
                    .map(|&p| {
                        let c = self.cnormal[self.planes[p].0];
                        popa3d_model::geometry::PlaneValue { n: [c.x, c.y, c.z], d: self.planes[p].1 }
                    })
                    .collect();
                !node_planes[n].is_empty() && min_singular(&vals) < ILL_CONDITIONED_DEG.to_radians().sin()
            })
            .collect()
    }

    /// The part's model: solids, nodes, edges, parameters, normals, planes (ordered by their
    /// first face so ids follow the source order), faces and half-edges; with the parameters that
    /// must stay 0.
    fn model(&self, soup: &Soup, topo: &Topo, origin: [f64; 3]) -> (Popa3d, Vec<ParamId>) {
        let mut porder: Vec<usize> = (0..self.planes.len()).collect();
        porder.sort_by_key(|&p| self.planes[p].2);
        let mut prank = vec![0usize; self.planes.len()];
        for (r, &p) in porder.iter().enumerate() {
            prank[p] = r;
        }
        let mut m = Popa3d::new(origin);
        add_topology(&mut m, soup, topo);
        let zero_params = self.add_normals(&mut m);
        // Planes: sign of its first face, d accordingly.
        for &p in &porder {
            let (c, d, first) = self.planes[p];
            let s = self.fsign[first];
            m.add_plane(Plane {
                normal: NormalId::from(c),
                sign: if s > 0.0 { Sign::Plus } else { Sign::Minus },
                d: s * d,
            });
        }
        for (fi, f) in topo.faces.iter().enumerate() {
            let p = prank[self.fplane[fi]];
            let psign = m.planes[p].sign.f64();
            let orient = self.fsign[fi] * psign;
            let poly = &soup.polygons[f.polygon];
            m.add_face(Face {
                plane: PlaneId::from(p),
                orientation: if orient > 0.0 { Sign::Plus } else { Sign::Minus },
                front: SolidId::from(f.front.map_or(0, |s| s + 1)),
                back: SolidId::from(f.back + 1),
                source: Some(FaceSource {
                    merged: f.absorbed.iter().map(|&i| soup.polygons[i].source.polygon.clone()).collect(),
                    ..poly.source.clone()
                }),
            });
        }
        for &(e, s, f) in &topo.half_edges {
            m.add_half_edge(HalfEdge {
                edge: EdgeId::from(e),
                sign: if s > 0 { Sign::Plus } else { Sign::Minus },
                face: FaceId::from(f),
            });
        }
        (m, zero_params)
    }

    /// Parameters: bases and unpaired normals first (3 each), partners reference their base;
    /// then the normals. Returns the parameters that must stay 0 (a partner's shared component).
    fn add_normals(&self, m: &mut Popa3d) -> Vec<ParamId> {
        let cnormal = &self.cnormal;
        let mut nparams: Vec<Option<[(ParamId, Sign); 3]>> = vec![None; cnormal.len()];
        let mut zero_params = Vec::new();
        for c in 0..cnormal.len() {
            if self.partner[c].is_some() {
                continue;
            }
            let n = cnormal[c];
            let ids = [0, 1, 2].map(|k| (m.add_parameter(Parameter { value: n[k] }), Sign::Plus));
            nparams[c] = Some(ids);
        }
        for c in 0..cnormal.len() {
            if let Some((b, k)) = self.partner[c] {
                let Some(bp) = nparams[b] else { continue };
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let mut comps = [bp[0]; 3];
                comps[i] = (bp[j].0, Sign::Minus);
                comps[j] = (bp[i].0, Sign::Plus);
                comps[k] = (bp[k].0, Sign::Plus);
                nparams[c] = Some(comps);
                if !zero_params.contains(&bp[k].0) {
                    zero_params.push(bp[k].0);
                }
            }
        }
        for c in 0..cnormal.len() {
            m.add_normal(NormalVector { comps: nparams[c].expect("every normal has parameters") });
        }
        zero_params
    }
}

/// Step 3: faces of one normal cluster whose d lie within `plane_distance` of the group's first
/// (in order of d) share a plane at their area-weighted d. Returns the planes as (cluster, d,
/// first face) and each face's plane.
fn coplanar_planes(
    n_clusters: usize,
    fcluster: &[usize],
    fd: &[f64],
    farea: &[f64],
    plane_distance: f64,
) -> (Vec<(usize, f64, usize)>, Vec<usize>) {
    let nf = fcluster.len();
    let mut fplane = vec![0usize; nf];
    let mut planes: Vec<(usize, f64, usize)> = Vec::new();
    for c in 0..n_clusters {
        let mut fs: Vec<usize> = (0..nf).filter(|&f| fcluster[f] == c).collect();
        fs.sort_by(|&a, &b| fd[a].total_cmp(&fd[b]).then(a.cmp(&b)));
        let mut start = 0;
        while start < fs.len() {
            let d0 = fd[fs[start]];
            let mut end = start + 1;
            while end < fs.len() && fd[fs[end]] - d0 <= plane_distance {
                end += 1;
            }
            let group = &fs[start..end];
            let w: f64 = group.iter().map(|&f| farea[f]).sum();
            let d = group.iter().map(|&f| fd[f] * farea[f]).sum::<f64>() / w;
            let first = *group.iter().min().unwrap_or(&group[0]);
            for &f in group {
                fplane[f] = planes.len();
            }
            planes.push((c, d, first));
            start = end;
        }
    }
    (planes, fplane)
}

/// The GA01 repair: nearly coplanar faces across the deficient nodes merged, two-neighbour
/// nodes removed ([`crate::topology::repair`]) and the part built again from the repaired
/// topology, with a notice per merged pair. `None` when the repair changed nothing. The merge is
/// one of the model only, whatever the faces' thematic types: the write-back keeps every
/// polygon's own ring (and type) on the shared plane
/// (docs/decisions.md#merges-keep-semantics-and-identity).
fn repaired(
    soup: &Soup,
    topo: &Topo,
    tol: &Tolerances,
    origin: [f64; 3],
    depth: usize,
    net: &PlaneNet,
    deficient: &[usize],
) -> Result<Option<Part>, Rejection> {
    let cos_merge = ILL_CONDITIONED_DEG.to_radians().cos();
    let fnormal = &net.fnormal;
    let mergeable = |f: usize, g: usize| {
        topo.faces[f].back == topo.faces[g].back
            && topo.faces[f].front == topo.faces[g].front
            && fnormal[f].dot(&fnormal[g]).abs() >= cos_merge
    };
    let mut merged = Vec::new();
    let mut t2 = topo.clone();
    if !crate::topology::repair(&mut t2, deficient, &mergeable, &mut merged) {
        return Ok(None);
    }
    let mut part = build_depth(soup, &t2, tol, origin, depth + 1)?;
    for (a, b) in merged {
        let (pa, pb) = (&soup.polygons[a], &soup.polygons[b]);
        let sem = |p: &crate::soup::SoupPolygon| p.source.semantic.clone().unwrap_or_else(|| "no semantics".into());
        part.notices.push(crate::Notice {
            rule: "GA01-MERGE".into(),
            element: pb.locator.clone(),
            message: format!(
                "merged into face {} ({} / {}): the two are coplanar within {ILL_CONDITIONED_DEG}° and their common edge left a node without 3 independent planes",
                pa.locator,
                sem(pa),
                sem(pb)
            ),
        });
    }
    // Report the soup as it was read.
    part.counts.stages[0] = StageCounts::new("points", topo.soup_nodes, topo.soup_edges, topo.soup_faces, 0, 0, 0);
    Ok(Some(part))
}

/// The part's solids (the exterior first), nodes and edges with their sorted, deduplicated
/// source vertices.
fn add_topology(m: &mut Popa3d, soup: &Soup, topo: &Topo) {
    m.add_solid(Solid { kind: SolidKind::Exterior, name: None });
    for s in &soup.solids {
        m.add_solid(Solid { kind: s.kind, name: s.name.clone() });
    }
    for i in 0..topo.points.len() {
        let mut src = topo.node_sources[i].clone();
        src.sort();
        src.dedup();
        m.add_node(Node { sources: src });
    }
    for (i, &(a, b)) in topo.edges.iter().enumerate() {
        m.add_edge(Edge { start: NodeId::from(a), end: NodeId::from(b) });
        if let Some(v) = topo.edge_sources.get(&(a.min(b), a.max(b))) {
            let mut v = v.clone();
            v.sort();
            v.dedup();
            m.edge_vertices.push(EdgeVertices { edge: EdgeId::from(i), sources: v });
        }
    }
}

/// The before/after counts of the spec's Tables 7.1 and 7.4, one stage per normalization step.
fn part_counts(soup: &Soup, topo: &Topo, m: &Popa3d, net: &PlaneNet, max_shift: f64) -> Counts {
    let nf = topo.faces.len();
    let (n_nodes, n_edges, n_normals, n_planes) = (m.nodes.len(), m.edges.len(), net.cnormal.len(), net.planes.len());
    Counts {
        name: soup.name.clone(),
        source: crate::counts::SourceCounts {
            polygons: soup.polygons.len(),
            rings: soup.source_rings,
            points: topo.soup_points,
        },
        stages: vec![
            StageCounts::new("points", topo.soup_nodes, topo.soup_edges, topo.soup_faces, 0, 0, 0),
            StageCounts::new("planar", n_nodes, n_edges, nf, nf, nf, 3 * nf),
            StageCounts::new("parallel", n_nodes, n_edges, nf, nf, n_normals, 3 * n_normals),
            StageCounts::new("coplanar", n_nodes, n_edges, nf, n_planes, n_normals, 3 * n_normals),
            StageCounts::new("orthogonal", n_nodes, n_edges, nf, n_planes, n_normals, m.parameters.len()),
        ],
        half_edges: m.half_edges.len(),
        max_node_shift: max_shift,
    }
}

/// Step 1: the least-squares plane of every face (normal oriented like the outer ring's Newell
/// normal), its centroid and its area; refuses a face without area (TA05) or with a vertex
/// farther than the planarity tolerance from its plane (GA-PLANAR).
#[allow(clippy::type_complexity)]
fn face_planes(
    soup: &Soup,
    topo: &Topo,
    pts: &[[f64; 3]],
    tol: &Tolerances,
) -> Result<(Vec<Vector3<f64>>, Vec<Vector3<f64>>, Vec<f64>), Rejection> {
    let nf = topo.faces.len();
    let mut fnormal: Vec<Vector3<f64>> = Vec::with_capacity(nf);
    let mut fcent: Vec<Vector3<f64>> = Vec::with_capacity(nf);
    let mut farea: Vec<f64> = Vec::with_capacity(nf);
    for f in &topo.faces {
        let outer: Vec<[f64; 3]> = f.rings[0].iter().map(|&i| pts[i]).collect();
        let nw = newell(&outer);
        let all: Vec<Vector3<f64>> = f.rings.iter().flatten().map(|&i| Vector3::from(pts[i])).collect();
        let c = all.iter().fold(Vector3::zeros(), |a, p| a + p) / all.len() as f64;
        let mut s = Matrix3::zeros();
        for p in &all {
            let d = p - c;
            s += d * d.transpose();
        }
        let eig = s.symmetric_eigen();
        let imin = (0..3).min_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b])).unwrap_or(0);
        let mut n: Vector3<f64> = eig.eigenvectors.column(imin).into();
        let area = nw.norm() / 2.0;
        if area <= 0.0 || !n.iter().all(|x| x.is_finite()) {
            return Err(Rejection::new(
                "TA05",
                &soup.polygons[f.polygon].locator,
                "the polygon has no area (its points are collinear)",
            ));
        }
        if n.dot(&nw) < 0.0 {
            n = -n;
        }
        let dev = all.iter().map(|p| (p - c).dot(&n).abs()).fold(0.0, f64::max);
        if dev > tol.planarity {
            return Err(Rejection::new(
                "GA-PLANAR",
                &soup.polygons[f.polygon].locator,
                format!(
                    "far from planar: a vertex lies {dev:.4} m from the best-fitting plane (tolerance {} m)",
                    tol.planarity
                ),
            ));
        }
        fnormal.push(n);
        fcent.push(c);
        farea.push(area);
    }
    Ok((fnormal, fcent, farea))
}

/// Step 2: parallel faces share a normal. Faces are taken largest first; each joins the first
/// cluster whose representative is within the angle (cosine `cos_tol`, either direction), and a
/// cluster's normal is the canonical direction of its area-weighted sum. Returns the normals and
/// each face's cluster.
fn cluster_normals(fnormal: &[Vector3<f64>], farea: &[f64], cos_tol: f64) -> (Vec<Vector3<f64>>, Vec<usize>) {
    let nf = fnormal.len();
    let mut order: Vec<usize> = (0..nf).collect();
    order.sort_by(|&a, &b| farea[b].total_cmp(&farea[a]).then(a.cmp(&b)));
    let mut clusters: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new(); // (representative, weighted sum)
    let mut fcluster = vec![0usize; nf];
    for &f in &order {
        let n = fnormal[f];
        let mut found = None;
        for (ci, (rep, _)) in clusters.iter().enumerate() {
            if rep.dot(&n).abs() >= cos_tol {
                found = Some(ci);
                break;
            }
        }
        match found {
            Some(ci) => {
                let s = if clusters[ci].0.dot(&n) >= 0.0 { 1.0 } else { -1.0 };
                clusters[ci].1 += n * (s * farea[f]);
                fcluster[f] = ci;
            }
            None => {
                clusters.push((n, n * farea[f]));
                fcluster[f] = clusters.len() - 1;
            }
        }
    }
    let cnormal: Vec<Vector3<f64>> = clusters.iter().map(|(_, s)| canonical(s.normalize())).collect();
    (cnormal, fcluster)
}

/// Step 4 (run before step 3, since it changes the normals): near-zero components (within the
/// angle's sine) become zero, and two normals with a common zero axis that are orthogonal within
/// the angle share parameters: the second becomes exactly the first rotated by 90° about that
/// axis. Returns, per normal, its base normal and the axis (`None` for a base or an unpaired one).
fn share_orthogonal(cnormal: &mut [Vector3<f64>], cos_tol: f64, sin_tol: f64) -> Vec<Option<(usize, usize)>> {
    // partner[c] = Some((base, axis, flip)).
    let mut partner: Vec<Option<(usize, usize)>> = vec![None; cnormal.len()];
    let mut paired = vec![false; cnormal.len()];
    let mut zero_axes: Vec<Vec<usize>> = vec![Vec::new(); cnormal.len()];
    for n in cnormal.iter_mut() {
        let mut changed = false;
        for k in 0..3 {
            if n[k].abs() < sin_tol && n[k] != 0.0 {
                n[k] = 0.0;
                changed = true;
            }
        }
        if changed {
            *n = canonical(n.normalize());
        }
    }
    for (c, n) in cnormal.iter().enumerate() {
        zero_axes[c] = (0..3).filter(|&k| n[k] == 0.0).collect();
    }
    for b in 0..cnormal.len() {
        if paired[b] {
            continue;
        }
        'search: for m in b + 1..cnormal.len() {
            if paired[m] {
                continue;
            }
            for &k in &zero_axes[b] {
                if !zero_axes[m].contains(&k) {
                    continue;
                }
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let (nb, nm) = (cnormal[b], cnormal[m]);
                // rotated base: (−n_j, n_i) in the (i, j) components
                let rot = (-nb[j], nb[i]);
                let c = rot.0 * nm[i] + rot.1 * nm[j];
                if c.abs() >= cos_tol {
                    partner[m] = Some((b, k));
                    paired[b] = true;
                    paired[m] = true;
                    let mut v = Vector3::zeros();
                    v[i] = rot.0;
                    v[j] = rot.1;
                    // The partner's value is now exactly the base rotated by 90°; if the drawn
                    // normal pointed the other way, its planes take the sign (fsign below).
                    cnormal[m] = v;
                    break 'search;
                }
            }
        }
    }
    partner
}

/// TA04/TA07: a face boundary that runs along one edge twice (a slit or spike in the source ring)
/// or does not chain into simple cycles cannot be a popa3d face.
fn check_simple_cycles(m: &Popa3d, inc: &Incidence, soup: &Soup) -> Result<(), Rejection> {
    // ring) or does not chain into simple cycles cannot be a popa3d face.
    for f in 0..m.faces.len() {
        let mut es: Vec<EdgeId> = inc.face_half_edges[f].iter().map(|h| m.half_edges[h.idx()].edge).collect();
        es.sort();
        let n = es.len();
        es.dedup();
        if es.len() != n || inc.face_cycles(m, FaceId::from(f)).is_none() {
            let loc = m.faces[f].source.as_ref().map(|s| s.polygon.clone()).unwrap_or_else(|| soup.name.clone());
            return Err(Rejection::new(
                "TA04",
                loc,
                "the polygon's boundary runs along the same edge twice or touches itself (a slit or spike): its half-edges do not form simple cycles",
            ));
        }
    }
    Ok(())
}

/// GA01 and the largest distance of a node recomputed from its planes to its source point: a
/// node that is not the intersection of 3 independent planes, or lies farther than the planarity
/// tolerance from its point, is refused.
fn max_node_shift(
    m: &Popa3d,
    inc: &Incidence,
    topo: &Topo,
    pts: &[[f64; 3]],
    tol: &Tolerances,
    soup: &Soup,
) -> Result<f64, Rejection> {
    let mut max_shift: f64 = 0.0;
    for n in 0..m.nodes.len() {
        let id = NodeId::from(n);
        let p = m.node_position(inc, id).map_err(|e| {
            let faces = inc.node_faces(m, id);
            let loc = faces
                .first()
                .and_then(|f| m.faces[f.idx()].source.as_ref())
                .map(|s| s.polygon.clone())
                .unwrap_or_else(|| soup.name.clone());
            let q = topo.points[n];
            Rejection::new(
                "GA01",
                loc,
                format!(
                    "the node at ({:.3} {:.3} {:.3}) is not the intersection of 3 independent planes: {e}",
                    q[0], q[1], q[2]
                ),
            )
        })?;
        let d = ((p[0] - pts[n][0]).powi(2) + (p[1] - pts[n][1]).powi(2) + (p[2] - pts[n][2]).powi(2)).sqrt();
        if d > tol.planarity {
            let q = topo.points[n];
            let loc = inc
                .node_faces(m, id)
                .first()
                .and_then(|f| m.faces[f.idx()].source.as_ref())
                .map(|s| s.polygon.clone())
                .unwrap_or_else(|| soup.name.clone());
            return Err(Rejection::new(
                "GA01",
                loc,
                format!("the node at ({:.3} {:.3} {:.3}) recomputed from its planes lies {d:.3} m away (more than {} m): its planes are nearly dependent", q[0], q[1], q[2], tol.planarity),
            ));
        }
        max_shift = max_shift.max(d);
    }
    Ok(max_shift)
}

/// Canonical direction of a normal (T 2.5): nx > 0; else ny > 0; else nz > 0.
pub fn canonical(n: Vector3<f64>) -> Vector3<f64> {
    let flip = if n.x != 0.0 {
        n.x < 0.0
    } else if n.y != 0.0 {
        n.y < 0.0
    } else {
        n.z < 0.0
    };
    if flip {
        -n
    } else {
        n
    }
}

/// Appends a part to the model: the part's exterior solid maps onto the model's exterior solid
/// (created if the model has none), every other id is shifted. Zero parameters are fixed.
pub fn append(model: &mut Popa3d, part: &mut Part) {
    let ext = match model.solids.iter().position(|s| s.kind == SolidKind::Exterior) {
        Some(i) => i,
        None => {
            model.solids.insert(0, Solid { kind: SolidKind::Exterior, name: None });
            0
        }
    };
    let p = &part.model;
    let (s0, n0, e0, h0, f0, pl0, nv0, pa0) = (
        model.solids.len(),
        model.nodes.len(),
        model.edges.len(),
        model.half_edges.len(),
        model.faces.len(),
        model.planes.len(),
        model.normals.len(),
        model.parameters.len(),
    );
    let solid = |s: SolidId| if s.0 == 0 { SolidId::from(ext) } else { SolidId::from(s0 + s.idx() - 1) };
    model.solids.extend(p.solids.iter().skip(1).cloned());
    model.nodes.extend(p.nodes.iter().cloned());
    model.edges.extend(
        p.edges.iter().map(|e| Edge { start: NodeId::from(n0 + e.start.idx()), end: NodeId::from(n0 + e.end.idx()) }),
    );
    model.edge_vertices.extend(
        p.edge_vertices
            .iter()
            .map(|x| EdgeVertices { edge: EdgeId::from(e0 + x.edge.idx()), sources: x.sources.clone() }),
    );
    model.half_edges.extend(p.half_edges.iter().map(|h| HalfEdge {
        edge: EdgeId::from(e0 + h.edge.idx()),
        sign: h.sign,
        face: FaceId::from(f0 + h.face.idx()),
    }));
    let _ = h0;
    model.faces.extend(p.faces.iter().map(|f| Face {
        plane: PlaneId::from(pl0 + f.plane.idx()),
        orientation: f.orientation,
        front: solid(f.front),
        back: solid(f.back),
        source: f.source.clone(),
    }));
    model.planes.extend(p.planes.iter().map(|q| Plane {
        normal: NormalId::from(nv0 + q.normal.idx()),
        sign: q.sign,
        d: q.d,
    }));
    model.normals.extend(
        p.normals.iter().map(|n| NormalVector { comps: n.comps.map(|(pid, s)| (ParamId::from(pa0 + pid.idx()), s)) }),
    );
    model.parameters.extend(p.parameters.iter().cloned());
    for z in &part.zero_params {
        model.add_observation(Observation::new(
            ObsKind::ParameterFix { unknown: Unknown::Param(ParamId::from(pa0 + z.idx())), value: 0.0 },
            ObsOrigin::Consistency,
        ));
    }
}
