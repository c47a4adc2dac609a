//! Conditions generated from geometry and semantics (spec §8.2 step 5), sketch priors (spec §4.6)
//! and observation-induced angle constraints (spec §4.5).
//!
//! Decisions for the spec's \[gap\]s (§8.2, §10.2 items 10, 13):
//! * Parallelism / orthogonality are generated once per pair of *distinct* normal objects (between
//!   their largest faces), not per face pair: faces on one normal are parallel by construction, and a
//!   per-face-pair list would be quadratic with no extra information.
//! * Coplanarity: planes on parallel normals (same normal object, or normals the parallelism
//!   conditions make parallel) whose faces have the same non-opening semantic type and whose d differ
//!   by less than ε get a face–face distance 0 — between consecutive planes in d order (a chain, not
//!   all pairs).
//! * Wall–window: each opening face gets a face–face distance to the parallel face of its parent
//!   wall surface (or, without a parent, the nearest parallel wall face) with the source offset as
//!   value, even below ε, so openings keep their place.
//! * Soft datum: an identity observation for every plane d and normal parameter.
//! * Unit norm: one `NormNV` per normal, skipped for a normal whose parameters are a signed
//!   permutation of an earlier one's (the same norm, spec §3.3).

use popa3d_model::vec3::{dot, unit};
use popa3d_model::*;
use serde::Serialize;
use std::collections::HashMap;

/// Tolerances and weights of the generated conditions. Defaults: decided here (the thesis gives no
/// numbers, spec §8.2 / §10.2 item 10).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConditionOptions {
    /// Normals within this angle (degrees) of parallel get a parallelism condition. Default 2°.
    pub parallel_deg: f64,
    /// Normals within this angle (degrees) of orthogonal get an orthogonality condition. Default 2°.
    pub orthogonal_deg: f64,
    /// ε: parallel planes of the same semantic type closer than this (m) get a coplanarity
    /// condition. Default 0.2 m (above the storey offsets LoD2/3 data sets carry, below wall thickness).
    pub epsilon: f64,
    /// σ of angle conditions, in cosine units. Default 1e-4 (strong, Pasewaldt: constraints strong).
    pub sigma_angle: f64,
    /// σ of coplanarity and wall–window distances (m). Default 1 mm.
    pub sigma_distance: f64,
    /// σ of identity observations of plane distances (m). Default 0.1 m (weak: the geometry yields).
    pub sigma_identity_d: f64,
    /// σ of identity observations of normal parameters. Default 0.05.
    pub sigma_identity_param: f64,
    /// σ of the unit-norm pseudo-observations; `None` = restrictions. Default `None`.
    pub sigma_norm: Option<f64>,
}

impl Default for ConditionOptions {
    fn default() -> Self {
        ConditionOptions {
            parallel_deg: 2.0,
            orthogonal_deg: 2.0,
            epsilon: 0.2,
            sigma_angle: 1e-4,
            sigma_distance: 0.001,
            sigma_identity_d: 0.1,
            sigma_identity_param: 0.05,
            sigma_norm: None,
        }
    }
}

/// How many conditions of each kind were generated (the shape of the spec's Fig. 7.16 table).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ConditionCounts {
    pub parallelism: usize,
    pub coplanarity: usize,
    pub orthogonality: usize,
    pub wall_window: usize,
    pub identity: usize,
    pub norm: usize,
}

impl ConditionCounts {
    /// The counts of several objects added up (the summary line over all buildings).
    pub fn sum<'a>(counts: impl IntoIterator<Item = &'a ConditionCounts>) -> ConditionCounts {
        let mut cc = ConditionCounts::default();
        for r in counts {
            cc.parallelism += r.parallelism;
            cc.coplanarity += r.coplanarity;
            cc.orthogonality += r.orthogonality;
            cc.wall_window += r.wall_window;
            cc.identity += r.identity;
            cc.norm += r.norm;
        }
        cc
    }
}

/// Element ranges of one normalized object inside a model.
#[derive(Debug, Clone, Default)]
pub struct Ranges {
    pub faces: std::ops::Range<usize>,
    pub planes: std::ops::Range<usize>,
    pub normals: std::ops::Range<usize>,
    pub parameters: std::ops::Range<usize>,
}

impl Ranges {
    /// Every element of `m`: for conditions over a whole model (one building in it) rather than
    /// over the part one object added to a shared model.
    pub fn whole(m: &Popa3d) -> Ranges {
        Ranges {
            faces: 0..m.faces.len(),
            planes: 0..m.planes.len(),
            normals: 0..m.normals.len(),
            parameters: 0..m.parameters.len(),
        }
    }

    /// What `m` gained since `before` (an earlier [`Ranges::whole`] of it): the elements one
    /// object appended to a shared model.
    pub fn since(m: &Popa3d, before: &Ranges) -> Ranges {
        let now = Ranges::whole(m);
        Ranges {
            faces: before.faces.end..now.faces.end,
            planes: before.planes.end..now.planes.end,
            normals: before.normals.end..now.normals.end,
            parameters: before.parameters.end..now.parameters.end,
        }
    }
}

/// Face areas (from the model's own geometry).
fn face_areas(m: &Popa3d, inc: &Incidence, pos: &[[f64; 3]], faces: &std::ops::Range<usize>) -> HashMap<usize, f64> {
    let mut out = HashMap::new();
    for f in faces.clone() {
        let fid = FaceId::from(f);
        let mut a = 0.0;
        if let Some(loops) = m.face_loops(inc, fid, pos) {
            let n = unit(m.face_plane_value(fid).n);
            for (i, l) in loops.iter().enumerate() {
                let p: Vec<[f64; 3]> = l.iter().map(|x| pos[x.idx()]).collect();
                let v = dot(popa3d_model::topology::newell(&p), n).abs() / 2.0;
                a += if i == 0 { v } else { -v };
            }
        }
        out.insert(f, a);
    }
    out
}

/// The unit-norm and soft-datum conditions shared by both use cases.
fn norms_and_identities(
    m: &Popa3d,
    r: &Ranges,
    o: &ConditionOptions,
    out: &mut Vec<Observation>,
    c: &mut ConditionCounts,
    identities: bool,
) {
    let mut seen: Vec<Vec<ParamId>> = Vec::new();
    for nv in r.normals.clone() {
        let mut key: Vec<ParamId> = m.normals[nv].comps.iter().map(|x| x.0).collect();
        key.sort();
        if seen.contains(&key) {
            continue;
        }
        seen.push(key);
        out.push(Observation::new(
            ObsKind::NormNV { normal: NormalId::from(nv), sigma: o.sigma_norm },
            ObsOrigin::Consistency,
        ));
        c.norm += 1;
    }
    if identities {
        for p in r.planes.clone() {
            let l = Measured::new(m.planes[p].d, o.sigma_identity_d);
            out.push(Observation::new(
                ObsKind::ParameterObs { unknown: Unknown::PlaneD(PlaneId::from(p)), l },
                ObsOrigin::Datum,
            ));
            c.identity += 1;
        }
        for p in r.parameters.clone() {
            let l = Measured::new(m.parameters[p].value, o.sigma_identity_param);
            out.push(Observation::new(
                ObsKind::ParameterObs { unknown: Unknown::Param(ParamId::from(p)), l },
                ObsOrigin::Datum,
            ));
            c.identity += 1;
        }
    }
}

fn is_opening(s: Option<&str>) -> bool {
    matches!(s, Some("Window") | Some("Door"))
}

/// Generates the conditions of the CityGML use case (spec §8.2) for one object and appends them to
/// the model. Node positions must be computable (normalization guarantees it); an object with a
/// node whose planes do not meet in a point gets none. For many objects of one model use
/// [`semantic_many`].
pub fn semantic(m: &mut Popa3d, r: &Ranges, o: &ConditionOptions) -> ConditionCounts {
    semantic_many(m, std::slice::from_ref(r), o).pop().unwrap_or_default()
}

/// [`semantic`] for several objects of one model (each given by its element ranges), in order.
/// The incidence and the node positions (a plane intersection per node) are built once: built
/// per object they cost O(model) each, which made converting a tile quadratic in its buildings
/// (an NRW tile repeated 20×: 12 s). Only observations are added, so both stay valid throughout.
pub fn semantic_many(m: &mut Popa3d, rs: &[Ranges], o: &ConditionOptions) -> Vec<ConditionCounts> {
    let inc = Incidence::new(m);
    // NaN where a node's planes do not meet in a point
    let pos: Vec<[f64; 3]> =
        (0..m.nodes.len()).map(|i| m.node_position(&inc, NodeId::from(i)).unwrap_or([f64::NAN; 3])).collect();
    rs.iter()
        .map(|r| {
            let computable = r
                .faces
                .clone()
                .all(|f| inc.face_half_edges[f].iter().all(|&h| !pos[m.half_edge_start(h).idx()][0].is_nan()));
            if computable {
                semantic_with(m, r, o, &inc, &pos)
            } else {
                ConditionCounts::default()
            }
        })
        .collect()
}

fn semantic_with(
    m: &mut Popa3d,
    r: &Ranges,
    o: &ConditionOptions,
    inc: &Incidence,
    pos: &[[f64; 3]],
) -> ConditionCounts {
    let area = face_areas(m, inc, pos, &r.faces);
    let mut c = ConditionCounts::default();
    let mut out: Vec<Observation> = Vec::new();
    let normal_face = largest_face_per_normal(m, r, &area);
    let normals: Vec<usize> = r.normals.clone().filter(|n| normal_face.contains_key(n)).collect();
    // No squaring of the facets of a curved facade (docs/decisions.md#no-squaring-on-curved-facades).
    let curved_faces = crate::curved::curved_facets(m, inc, pos, r.faces.clone());
    let curved: std::collections::HashSet<usize> =
        normals.iter().copied().filter(|n| curved_faces.contains(&normal_face[n])).collect();
    let groups = angle_conditions(m, &normals, &normal_face, &curved, o, &mut out, &mut c);
    // Coplanarity and wall–window distances within each parallel group.
    for (g, ns) in groups {
        let refn = unit(m.face_plane_value(FaceId::from(normal_face[&g])).n);
        let faces = group_face_offsets(m, r, inc, pos, &ns, refn);
        coplanarity_conditions(m, &faces, &area, o, &mut out, &mut c);
        wall_window_conditions(m, &faces, o, &mut out, &mut c);
    }
    norms_and_identities(m, r, o, &mut out, &mut c, true);
    for ob in out {
        m.add_observation(ob);
    }
    c
}

/// The largest face of each normal: its plane value stands for the normal in angle tests.
fn largest_face_per_normal(m: &Popa3d, r: &Ranges, area: &HashMap<usize, f64>) -> HashMap<usize, usize> {
    let mut normal_face: HashMap<usize, usize> = HashMap::new();
    for f in r.faces.clone() {
        let nv = m.planes[m.faces[f].plane.idx()].normal.idx();
        let best = normal_face.entry(nv).or_insert(f);
        if area[&f] > area[best] {
            *best = f;
        }
    }
    normal_face
}

/// Parallelism and orthogonality conditions between every pair of normals within the angle
/// tolerances (not swap pairs, not the facets of a curved facade `curved`, orthogonal by construction, spec §3.2 step 4). Returns the
/// parallel groups (union–find over the parallel pairs) as (root, members), by root.
fn angle_conditions(
    m: &Popa3d,
    normals: &[usize],
    normal_face: &HashMap<usize, usize>,
    curved: &std::collections::HashSet<usize>,
    o: &ConditionOptions,
    out: &mut Vec<Observation>,
    c: &mut ConditionCounts,
) -> Vec<(usize, Vec<usize>)> {
    let cos_par = o.parallel_deg.to_radians().cos();
    let sin_ort = o.orthogonal_deg.to_radians().sin();
    let mut group: HashMap<usize, usize> = normals.iter().map(|&n| (n, n)).collect();
    let pset = |n: usize| {
        let mut k: Vec<ParamId> = m.normals[n].comps.iter().map(|x| x.0).collect();
        k.sort();
        k
    };
    for (i, &a) in normals.iter().enumerate() {
        for &b in &normals[i + 1..] {
            if pset(a) == pset(b) {
                continue; // a swap pair: orthogonal by construction (spec §3.2 step 4)
            }
            if curved.contains(&a) || curved.contains(&b) {
                continue; // a facet of a curved facade is not squared
            }
            let (fa, fb) = (normal_face[&a], normal_face[&b]);
            let cs = dot(unit(m.face_plane_value(FaceId::from(fa)).n), unit(m.face_plane_value(FaceId::from(fb)).n));
            let kind = if cs.abs() >= cos_par {
                c.parallelism += 1;
                let (ra, rb) = (group_root(&mut group, a), group_root(&mut group, b));
                group.insert(ra.max(rb), ra.min(rb));
                Some(cs.signum())
            } else if cs.abs() <= sin_ort {
                c.orthogonality += 1;
                Some(0.0)
            } else {
                None
            };
            if let Some(v) = kind {
                let ob = Observation::new(
                    ObsKind::ConstraintFaceFace {
                        a: FaceId::from(fa),
                        b: FaceId::from(fb),
                        l: Measured::new(v, o.sigma_angle),
                    },
                    ObsOrigin::Semantic,
                );
                out.push(ob.with_label(if v == 0.0 { "orthogonal" } else { "parallel" }));
            }
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for &n in normals {
        let g = group_root(&mut group, n);
        groups.entry(g).or_default().push(n);
    }
    let mut groups: Vec<(usize, Vec<usize>)> = groups.into_iter().collect();
    groups.sort_by_key(|g| g.0);
    groups
}

/// The root of `x` in the union–find map `g`, compressing the path.
fn group_root(g: &mut HashMap<usize, usize>, x: usize) -> usize {
    let p = g[&x];
    if p == x {
        x
    } else {
        let r = group_root(g, p);
        g.insert(x, r);
        r
    }
}

/// (signed offset along `refn`, face) for each face of the range whose normal is one of `ns`:
/// the offset of the face's plane, measured at its first node.
fn group_face_offsets(
    m: &Popa3d,
    r: &Ranges,
    inc: &Incidence,
    pos: &[[f64; 3]],
    ns: &[usize],
    refn: [f64; 3],
) -> Vec<(f64, usize)> {
    let mut faces: Vec<(f64, usize)> = Vec::new();
    for f in r.faces.clone() {
        let pl = m.faces[f].plane.idx();
        if !ns.contains(&m.planes[pl].normal.idx()) {
            continue;
        }
        let h = inc.face_half_edges[f][0];
        let p = pos[m.half_edge_start(h).idx()];
        faces.push((dot(refn, p), f));
    }
    faces
}

/// Coplanarity: per semantic type (openings aside), one representative (largest face) per
/// plane, planes sorted by offset, consecutive pairs within ε get a distance-0 condition.
fn coplanarity_conditions(
    m: &Popa3d,
    faces: &[(f64, usize)],
    area: &HashMap<usize, f64>,
    o: &ConditionOptions,
    out: &mut Vec<Observation>,
    c: &mut ConditionCounts,
) {
    let sem = |f: usize| m.faces[f].source.as_ref().and_then(|s| s.semantic.clone());
    let mut by_sem: HashMap<Option<String>, Vec<(f64, usize)>> = HashMap::new();
    for &(t, f) in faces {
        if !is_opening(sem(f).as_deref()) {
            by_sem.entry(sem(f)).or_default().push((t, f));
        }
    }
    let mut sems: Vec<Option<String>> = by_sem.keys().cloned().collect();
    sems.sort();
    for s in sems {
        let mut per_plane: HashMap<usize, (f64, usize)> = HashMap::new();
        for &(t, f) in &by_sem[&s] {
            let pl = m.faces[f].plane.idx();
            let e = per_plane.entry(pl).or_insert((t, f));
            if area[&f] > area[&e.1] {
                *e = (t, f);
            }
        }
        let mut v: Vec<(f64, usize)> = per_plane.into_values().collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for w in v.windows(2) {
            let dd = w[1].0 - w[0].0;
            if dd.abs() < o.epsilon {
                let ob = Observation::new(
                    ObsKind::DistanceFaceFace {
                        a: FaceId::from(w[0].1),
                        b: FaceId::from(w[1].1),
                        l: Measured::new(0.0, o.sigma_distance),
                    },
                    ObsOrigin::Semantic,
                );
                out.push(
                    ob.with_label(format!("coplanar {} (source offset {dd:.4} m)", s.clone().unwrap_or_default())),
                );
                c.coplanarity += 1;
            }
        }
    }
}

/// Wall–window: each opening face to the nearest parallel wall face on another plane, at its
/// source distance (kept even below ε: the reveal depth is real).
fn wall_window_conditions(
    m: &Popa3d,
    faces: &[(f64, usize)],
    o: &ConditionOptions,
    out: &mut Vec<Observation>,
    c: &mut ConditionCounts,
) {
    for &(t, f) in faces {
        let src = match &m.faces[f].source {
            Some(s) if is_opening(s.semantic.as_deref()) => s.clone(),
            _ => continue,
        };
        let mut best: Option<(f64, usize)> = None;
        for &(t2, f2) in faces {
            if f2 == f || m.faces[f2].plane == m.faces[f].plane {
                continue;
            }
            let s2 = match &m.faces[f2].source {
                Some(s) => s,
                None => continue,
            };
            if s2.semantic.as_deref() != Some("WallSurface") {
                continue;
            }
            let dd = (t2 - t).abs();
            if best.is_none_or(|(b, _)| dd < b) {
                best = Some((dd, f2));
            }
        }
        if let Some((dd, f2)) = best {
            let ob = Observation::new(
                ObsKind::DistanceFaceFace {
                    a: FaceId::from(f2),
                    b: FaceId::from(f),
                    l: Measured::new(dd, o.sigma_distance),
                },
                ObsOrigin::Semantic,
            );
            out.push(ob.with_label(format!("wall-window {}", src.owner.clone().unwrap_or(src.polygon.clone()))));
            c.wall_window += 1;
        }
    }
}

/// σ of the sketch priors (spec Table 7.2: plane differences ±10 cm, relative angles ±0.001,
/// normal norm ±0.001).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SketchOptions {
    pub sigma_plane_difference: f64,
    pub sigma_relative_angle: f64,
    pub sigma_norm: f64,
}

impl Default for SketchOptions {
    fn default() -> Self {
        SketchOptions { sigma_plane_difference: 0.1, sigma_relative_angle: 0.001, sigma_norm: 0.001 }
    }
}

/// Sketch priors of the first use case (spec §4.6, P10): per normal, planes sorted by their d in
/// the canonical direction (T 2.5), consecutive differences; all pairwise normal dot products; unit
/// norms as pseudo-observations. Returns (plane differences, relative angles, norms).
pub fn sketch_priors(m: &mut Popa3d, r: &Ranges, o: &SketchOptions) -> (usize, usize, usize) {
    let mut out = Vec::new();
    let mut nd = 0;
    for nv in r.normals.clone() {
        // d' = sign·d: the plane's offset along its normal object's direction (normal objects are
        // already in the canonical direction of T 2.5, spec §4.6 step 1).
        let mut ps: Vec<(f64, usize)> = r
            .planes
            .clone()
            .filter(|&p| m.planes[p].normal.idx() == nv)
            .map(|p| (m.planes[p].sign.f64() * m.planes[p].d, p))
            .collect();
        ps.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for w in ps.windows(2) {
            out.push(Observation::new(
                ObsKind::RelativeDistancePlanePlane {
                    lower: PlaneId::from(w[0].1),
                    upper: PlaneId::from(w[1].1),
                    l: Measured::new(w[1].0 - w[0].0, o.sigma_plane_difference),
                },
                ObsOrigin::Sketch,
            ));
            nd += 1;
        }
    }
    let mut na = 0;
    let nvs: Vec<usize> = r.normals.clone().collect();
    for (i, &a) in nvs.iter().enumerate() {
        for &b in &nvs[i + 1..] {
            let v = dot(m.normal_value(NormalId::from(a)), m.normal_value(NormalId::from(b)));
            out.push(Observation::new(
                ObsKind::RelativeAngleNormalNormal {
                    a: NormalId::from(a),
                    b: NormalId::from(b),
                    l: Measured::new(v, o.sigma_relative_angle),
                },
                ObsOrigin::Sketch,
            ));
            na += 1;
        }
    }
    let mut c = ConditionCounts::default();
    let co = ConditionOptions { sigma_norm: Some(o.sigma_norm), ..Default::default() };
    norms_and_identities(m, r, &co, &mut out, &mut c, false);
    for ob in out {
        m.add_observation(ob);
    }
    (nd, na, c.norm)
}

/// Adds measured distances one by one with [`add_distance`]; returns how many distances and how
/// many induced constraints went in.
pub fn add_distances(m: &mut Popa3d, distances: Vec<Observation>, sigma_induced: f64) -> (usize, usize) {
    let (mut added, mut induced) = (0, 0);
    for o in distances {
        let ids = add_distance(m, o, sigma_induced);
        added += 1;
        induced += ids.len().saturating_sub(1);
    }
    (added, induced)
}

/// Adds a measured distance and, for face–face, face–edge and edge–edge distances, the induced
/// "parallel" angle constraint (spec §4.5, P9) — unless parallelism already holds by construction
/// (the same normal object), which would duplicate a condition and cause a rank defect (spec §10.2
/// item 13). Returns the ids added. `sigma_induced` is the σ of induced constraints (cosine units).
pub fn add_distance(m: &mut Popa3d, obs: Observation, sigma_induced: f64) -> Vec<ObsId> {
    let inc = Incidence::new(m);
    let face_normal = |f: FaceId| m.planes[m.faces[f.idx()].plane.idx()].normal;
    let edge_normals = |e: EdgeId| -> Vec<NormalId> {
        let mut v: Vec<NormalId> = inc.edge_planes(m, e).iter().map(|p| m.planes[p.idx()].normal).collect();
        v.sort();
        v.dedup();
        v
    };
    let induced: Option<ObsKind> = match obs.kind {
        ObsKind::DistanceFaceFace { a, b, .. } => {
            if face_normal(a) == face_normal(b) {
                None
            } else {
                let cs = dot(unit(m.face_plane_value(a).n), unit(m.face_plane_value(b).n));
                Some(ObsKind::ConstraintFaceFace {
                    a,
                    b,
                    l: Measured::new(if cs < 0.0 { -1.0 } else { 1.0 }, sigma_induced),
                })
            }
        }
        ObsKind::DistanceFaceEdge { a, b, .. } => {
            if edge_normals(b).contains(&face_normal(a)) {
                None
            } else {
                Some(ObsKind::ConstraintFaceEdge { a, b, l: Measured::new(0.0, sigma_induced) })
            }
        }
        ObsKind::DistanceEdgeEdge { a, b, .. } => {
            if edge_normals(a) == edge_normals(b) {
                None
            } else {
                let da = m.edge_line(&inc, a).map(|x| unit(x.1)).unwrap_or([0.0; 3]);
                let db = m.edge_line(&inc, b).map(|x| unit(x.1)).unwrap_or([0.0; 3]);
                let cs = dot(da, db);
                Some(ObsKind::ConstraintEdgeEdge {
                    a,
                    b,
                    l: Measured::new(if cs < 0.0 { -1.0 } else { 1.0 }, sigma_induced),
                })
            }
        }
        _ => None,
    };
    let id = m.add_observation(obs);
    let mut ids = vec![id];
    if let Some(k) = induced {
        let mut o = Observation::new(k, ObsOrigin::Induced);
        o.induced_by = Some(id);
        ids.push(m.add_observation(o));
    }
    ids
}
