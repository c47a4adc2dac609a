//! The way back: popa3d → CityGML (spec §8.2 step 3, §10.1 item 19).
//!
//! The user's original CityGML file is the template: it holds everything that is not geometry.
//! The popa3d provenance (each node's source polygon gml:id, ring and vertex index) says which
//! coordinates each node maps to. The output is the template with only these edits spliced in
//! (`citygml_io::write_with_edits`, nothing else is re-serialised):
//!
//! 1. Planes on one normal object whose offsets differ by less than `coplanar_tolerance` are made
//!    identical (their mean) — coplanarity conditions the adjustment met within their σ become
//!    exact, so coplanar walls stay coplanar to rounding error.
//! 2. New vertex coordinates are plane intersections (spec T 2.3/T 2.4), written into each ring in
//!    its own encoding; consecutive vertices that coincide are written once.
//! 3. Polygons that lost their area (the former storey-offset strips) are removed with their
//!    wrappers and every XLink reference to them; a thematic surface left without polygons is
//!    removed with its `boundedBy` property (the deletion cascades, spec §8.2 step 3).
//! 4. Coplanar polygons of the same semantic type and building that touch are merged into the first
//!    of them (document order); the openings (windows, doors) of a thematic surface that lost all its
//!    polygons to the merge are moved to the surface that keeps the merged polygon.
//!
//! Limitations (stated, not hidden): polygons without gml:id (`#n` provenance) cannot be mapped
//! back and are reported as a provenance mismatch; merged polygons are written as `gml:posList`
//! rings.

use citygml_io::{CityModel, CityObject, Edit, Polygon, Ring};
use popa3d_model::{FaceId, Incidence, NodeId, Popa3d, VertexSource};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

/// Options of [`to_citygml`].
#[derive(Debug, Clone, Serialize)]
pub struct BackOptions {
    /// Planes on one normal closer than this become one plane (m).
    pub coplanar_tolerance: f64,
    /// Vertices closer than this after the adjustment are one vertex (m).
    pub collapse_tolerance: f64,
    /// Rings with a smaller area are degenerate (m²).
    pub area_tolerance: f64,
    /// Merge touching coplanar polygons of the same semantic type.
    pub merge: bool,
}

impl Default for BackOptions {
    fn default() -> Self {
        BackOptions { coplanar_tolerance: 1e-3, collapse_tolerance: 1e-6, area_tolerance: 1e-6, merge: true }
    }
}

/// What the back-transformation did.
#[derive(Debug, Clone, Serialize, Default)]
pub struct BackReport {
    /// Polygons of the template that the model maps to.
    pub polygons_mapped: usize,
    /// gml:ids of polygons removed because they lost their area.
    pub removed_degenerate: Vec<String>,
    /// Merges: (kept polygon, merged-away polygons).
    pub merged: Vec<(String, Vec<String>)>,
    /// Thematic surfaces removed because all their polygons were removed or merged away.
    pub removed_surfaces: Vec<String>,
    /// Openings moved to the surface that keeps their merged wall polygon.
    pub moved_openings: Vec<String>,
    /// Largest and mean vertex move over the vertices written back (m).
    pub max_move: f64,
    pub mean_move: f64,
    pub vertices_written: usize,
    /// Template vertices without a popa3d node (merged by the normalization's snap).
    pub vertices_dropped: usize,
}

/// Why the model cannot be written back into the template.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum BackError {
    #[error("template does not match the popa3d provenance: {element}: {message}")]
    Provenance { element: String, message: String },
    #[error("{element}: {message}")]
    Geometry { element: String, message: String },
    #[error("writing the CityGML: {0}")]
    Write(String),
}

type P3 = [f64; 3];

fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dist(a: P3, b: P3) -> f64 {
    let d = sub(a, b);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}
fn newell_area(pts: &[P3]) -> f64 {
    let n = popa3d_model::topology::newell(pts);
    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

/// Remove consecutive duplicates (cyclically) within `tol`.
fn collapse(pts: Vec<P3>, tol: f64) -> Vec<P3> {
    let mut out: Vec<P3> = Vec::with_capacity(pts.len());
    for p in pts {
        if out.last().is_none_or(|q| dist(*q, p) > tol) {
            out.push(p);
        }
    }
    while out.len() > 1 && dist(out[0], *out.last().unwrap()) <= tol {
        out.pop();
    }
    out
}

/// The enclosing element of a span: from the `<` of the nearest start tag before `span.start`
/// to the `>` of the nearest end tag after `span.end` (whitespace-only gaps assumed, as in GML
/// property wrappers like `<gml:interior>` or `<bldg:opening>`).
fn enclosing(src: &[u8], start: usize, end: usize) -> Option<std::ops::Range<usize>> {
    let mut s = start;
    while s > 0 {
        s -= 1;
        if src[s] == b'<' {
            break;
        }
        if !src[s].is_ascii_whitespace() && src[s] != b'>' {
            // text between: not a pure wrapper
        }
    }
    if src.get(s) != Some(&b'<') || src.get(s + 1) == Some(&b'/') {
        return None;
    }
    // `s` is the start of the previous tag; it must be a start tag that ends right before `start`
    let mut e = end;
    while e < src.len() && src[e].is_ascii_whitespace() {
        e += 1;
    }
    if src.get(e) != Some(&b'<') || src.get(e + 1) != Some(&b'/') {
        return None;
    }
    let close = src[e..].iter().position(|&c| c == b'>')? + e + 1;
    Some(s..close)
}

/// Namespace prefix of the element starting at `at` (`<gml:Polygon` → `gml:`; none → empty).
fn prefix_at(src: &[u8], at: usize) -> String {
    let tag: Vec<u8> = src[at + 1..].iter().take_while(|c| !c.is_ascii_whitespace() && **c != b'>' && **c != b'/').copied().collect();
    let t = String::from_utf8_lossy(&tag).to_string();
    match t.find(':') {
        Some(i) => t[..=i].to_string(),
        None => String::new(),
    }
}

fn fmt_points(pts: &[P3], dim: u8) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    for (i, p) in pts.iter().chain(std::iter::once(&pts[0])).enumerate() {
        for (k, v) in p.iter().take(dim as usize).enumerate() {
            if i > 0 || k > 0 {
                s.push(' ');
            }
            let _ = write!(s, "{}", v + 0.0);
        }
    }
    s
}

struct PolyInfo<'a> {
    poly: &'a Polygon,
    /// Thematic surface (boundary surface / opening) owning the polygon.
    surface: Option<&'a CityObject>,
}

fn collect_polys<'a>(o: &'a CityObject, surface: Option<&'a CityObject>, out: &mut HashMap<String, PolyInfo<'a>>, refs: &mut HashMap<String, Vec<std::ops::Range<usize>>>, order: &mut Vec<String>) {
    let surf = if citygml_io::SurfaceType::from_local_name(&o.kind).is_some() { Some(o) } else { surface };
    for g in &o.geometries {
        for p in g.polygons() {
            let Some(id) = &p.id else { continue };
            match &p.via_xlink {
                Some(r) => refs.entry(id.clone()).or_default().push(r.bytes.clone()),
                None => {
                    if !out.contains_key(id) {
                        order.push(id.clone());
                    }
                    out.insert(id.clone(), PolyInfo { poly: p, surface: surf });
                }
            }
        }
    }
    for c in &o.children {
        collect_polys(c, surf, out, refs, order);
    }
}

fn ring_of(p: &Polygon, r: u32) -> Option<&Ring> {
    if r == 0 {
        Some(&p.exterior)
    } else {
        p.interiors.get(r as usize - 1)
    }
}

fn ring_len(r: &Ring) -> usize {
    let n = r.points.len();
    if n > 1 && r.points[0] == r.points[n - 1] {
        n - 1
    } else {
        n
    }
}

/// Write the adjusted model back into its template. Returns the new document and a report.
pub fn to_citygml(model: &Popa3d, template: &[u8], city: &CityModel, opts: &BackOptions) -> Result<(Vec<u8>, BackReport), BackError> {
    to_citygml_with(model, &Template::new(template, city), opts, true)
}

/// The template document (its bytes and the model read from them) with its polygons by gml:id
/// (and the thematic surface that owns each), the XLinks to each and the document order: what
/// [`to_citygml_with`] looks up. Built once per template, so writing many models back into one
/// document (`geofit heal` checks every building on its own) does not scan it per model.
pub struct Template<'a> {
    bytes: &'a [u8],
    polys: HashMap<String, PolyInfo<'a>>,
    refs: HashMap<String, Vec<std::ops::Range<usize>>>,
    doc_order: Vec<String>,
    /// Polygon ids per thematic surface (keyed by the surface's start byte).
    surface_polys: HashMap<usize, (&'a CityObject, Vec<String>)>,
}

impl<'a> Template<'a> {
    /// `city` must be the model read from `bytes`.
    pub fn new(bytes: &'a [u8], city: &'a CityModel) -> Template<'a> {
        let mut polys: HashMap<String, PolyInfo> = HashMap::new();
        let mut refs: HashMap<String, Vec<std::ops::Range<usize>>> = HashMap::new();
        let mut doc_order: Vec<String> = Vec::new();
        for o in &city.objects {
            collect_polys(o, None, &mut polys, &mut refs, &mut doc_order);
        }
        let mut surface_polys: HashMap<usize, (&CityObject, Vec<String>)> = HashMap::new();
        for id in &doc_order {
            if let Some(s) = polys[id].surface {
                surface_polys.entry(s.span.bytes.start).or_insert((s, Vec::new())).1.push(id.clone());
            }
        }
        Template { bytes, polys, refs, doc_order, surface_polys }
    }
}

/// [`to_citygml`] against a prepared [`Template`]; with `write` false the edits are checked
/// but no document is produced (the returned bytes are empty): a dry run for the report.
pub fn to_citygml_with(model: &Popa3d, tpl: &Template, opts: &BackOptions, write: bool) -> Result<(Vec<u8>, BackReport), BackError> {
    let (template, polys, refs, doc_order) = (tpl.bytes, &tpl.polys, &tpl.refs, &tpl.doc_order);
    let mut m = model.clone();
    // 1. Make near-coplanar planes on one normal exactly coplanar.
    let mut by_normal: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (i, p) in m.planes.iter().enumerate() {
        by_normal.entry(p.normal.0).or_default().push(i);
    }
    let mut plane_cluster = vec![usize::MAX; m.planes.len()];
    let mut nclusters = 0;
    for (_, ids) in by_normal {
        let mut v: Vec<(f64, usize)> = ids.iter().map(|&i| (m.planes[i].sign.f64() * m.planes[i].d, i)).collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut start = 0;
        for k in 1..=v.len() {
            if k == v.len() || v[k].0 - v[k - 1].0 > opts.coplanar_tolerance {
                let mean = v[start..k].iter().map(|x| x.0).sum::<f64>() / (k - start) as f64;
                for &(_, i) in &v[start..k] {
                    m.planes[i].d = m.planes[i].sign.f64() * mean;
                    plane_cluster[i] = nclusters;
                }
                nclusters += 1;
                start = k;
            }
        }
    }
    // Template polygons (`tpl`, needed first: the original vertices anchor ill-conditioned nodes).
    // 2. Node positions: the plane intersection (spec T 2.3/T 2.4). When the adjustment made a
    //    node's planes (nearly) linearly dependent — e.g. two faces meeting at a slight kink became
    //    parallel, spec §7.4 GA01/GA02 "can fail after adjustment" — the intersection is a line or
    //    plane, and the node takes the point of it nearest to its original vertex (truncated
    //    pseudo-inverse anchored at the source position, singular values below 1e-4 dropped).
    let inc = Incidence::new(&m);
    let mut pos: Vec<P3> = Vec::with_capacity(m.nodes.len());
    for i in 0..m.nodes.len() {
        let node = NodeId::from(i);
        let p0: P3 = m.nodes[i]
            .sources
            .iter()
            .find_map(|s| match s {
                VertexSource::CityGml { polygon, ring, index } => polys
                    .get(polygon)
                    .and_then(|pi| ring_of(pi.poly, *ring))
                    .and_then(|r| r.points.get(*index as usize))
                    .map(|q| [q[0] - m.origin[0], q[1] - m.origin[1], q[2] - m.origin[2]]),
                _ => None,
            })
            .ok_or_else(|| BackError::Provenance {
                element: format!("node {i}"),
                message: match m.nodes[i].sources.first() {
                    Some(VertexSource::CityGml { polygon, ring, index }) => format!("its source vertex (polygon `{polygon}` ring {ring} vertex {index}) is not in the template"),
                    Some(VertexSource::Obj { vertex }) => format!("comes from OBJ vertex {vertex}, not from CityGML"),
                    None => "has no source vertex".into(),
                },
            })?;
        let planes = inc.node_planes(&m, node);
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atr = nalgebra::Vector3::<f64>::zeros();
        let x0 = nalgebra::Vector3::new(p0[0], p0[1], p0[2]);
        for q in &planes {
            let pv = m.plane_value(*q);
            let n = nalgebra::Vector3::new(pv.n[0], pv.n[1], pv.n[2]);
            ata += n * n.transpose();
            atr += n * (pv.d - n.dot(&x0));
        }
        let e = ata.symmetric_eigen();
        let lmax = e.eigenvalues.iter().fold(0.0f64, |a, &b| a.max(b));
        let mut p = x0;
        for k in 0..3 {
            if e.eigenvalues[k] > 1e-4 * lmax && lmax > 0.0 {
                let v = e.eigenvectors.column(k);
                p += v * (v.dot(&atr) / e.eigenvalues[k]);
            }
        }
        if p.iter().any(|v| !v.is_finite()) {
            return Err(BackError::Geometry { element: format!("node {i}"), message: "position is not finite".into() });
        }
        pos.push([p[0] + m.origin[0], p[1] + m.origin[1], p[2] + m.origin[2]]);
    }
    // Provenance → (polygon, ring, index) → node.
    let mut vmap: HashMap<(String, u32, u32), NodeId> = HashMap::new();
    for (i, n) in m.nodes.iter().enumerate() {
        for s in &n.sources {
            match s {
                VertexSource::CityGml { polygon, ring, index } => {
                    let Some(pi) = polys.get(polygon) else {
                        return Err(BackError::Provenance { element: format!("node {i}"), message: format!("polygon `{polygon}` is not in the template") });
                    };
                    let Some(r) = ring_of(pi.poly, *ring) else {
                        return Err(BackError::Provenance { element: format!("node {i}"), message: format!("polygon `{polygon}` has no ring {ring} in the template") });
                    };
                    if *index as usize >= ring_len(r) {
                        return Err(BackError::Provenance { element: format!("node {i}"), message: format!("polygon `{polygon}` ring {ring} has {} vertices in the template, provenance names vertex {index}", ring_len(r)) });
                    }
                    vmap.insert((polygon.clone(), *ring, *index), NodeId::from(i));
                }
                VertexSource::Obj { .. } => {
                    return Err(BackError::Provenance { element: format!("node {i}"), message: "comes from an OBJ sketch, not from CityGML".into() });
                }
            }
        }
    }
    let mapped_set: HashSet<&String> = vmap.keys().map(|k| &k.0).collect();
    let mapped: Vec<String> = doc_order.iter().filter(|id| mapped_set.contains(id)).cloned().collect();
    let mut report = BackReport { polygons_mapped: mapped.len(), ..Default::default() };
    // New rings per mapped polygon.
    let mut new_rings: HashMap<String, Vec<Option<Vec<P3>>>> = HashMap::new();
    let (mut moves, mut nmoves, mut maxmove) = (0.0, 0usize, 0.0f64);
    for id in &mapped {
        let p = polys[id].poly;
        let mut rings = Vec::new();
        for (ri, r) in std::iter::once(&p.exterior).chain(p.interiors.iter()).enumerate() {
            let n = ring_len(r);
            let mut pts = Vec::with_capacity(n);
            for k in 0..n {
                // A vertex without node was merged into its neighbour by normalization (snap):
                // it is written once, as the neighbour.
                let Some(node) = vmap.get(&(id.clone(), ri as u32, k as u32)) else {
                    report.vertices_dropped += 1;
                    continue;
                };
                let q = pos[node.idx()];
                let d = dist(q, r.points[k]);
                moves += d;
                nmoves += 1;
                maxmove = maxmove.max(d);
                pts.push(q);
            }
            let c = collapse(pts, opts.collapse_tolerance);
            rings.push(if c.len() >= 3 && newell_area(&c) >= opts.area_tolerance { Some(c) } else { None });
        }
        new_rings.insert(id.clone(), rings);
    }
    report.max_move = maxmove;
    report.mean_move = if nmoves > 0 { moves / nmoves as f64 } else { 0.0 };
    report.vertices_written = nmoves;

    // 3./4. Degenerate polygons and merge groups.
    let mut removed: HashSet<String> = HashSet::new();
    for id in &mapped {
        if new_rings[id][0].is_none() {
            removed.insert(id.clone());
            report.removed_degenerate.push(id.clone());
        }
    }
    // face per polygon id
    let mut face_of: HashMap<String, FaceId> = HashMap::new();
    for (i, f) in m.faces.iter().enumerate() {
        if let Some(s) = &f.source {
            face_of.insert(s.polygon.clone(), FaceId::from(i));
        }
    }
    let mut replaced: HashMap<String, String> = HashMap::new(); // kept id → new polygon text
    let mut merged_away: HashMap<String, String> = HashMap::new(); // removed id → kept id
    if opts.merge {
        // canonical nodes by position
        let mut canon: Vec<usize> = (0..pos.len()).collect();
        {
            let mut idx: Vec<usize> = (0..pos.len()).collect();
            idx.sort_by(|&a, &b| pos[a][0].total_cmp(&pos[b][0]));
            for a in 0..idx.len() {
                for b in a + 1..idx.len() {
                    if pos[idx[b]][0] - pos[idx[a]][0] > opts.collapse_tolerance {
                        break;
                    }
                    if dist(pos[idx[a]], pos[idx[b]]) <= opts.collapse_tolerance {
                        let (x, y) = (canon[idx[a]].min(canon[idx[b]]), canon[idx[a]].max(canon[idx[b]]));
                        for c in canon.iter_mut() {
                            if *c == y {
                                *c = x;
                            }
                        }
                    }
                }
            }
        }
        let mut groups: BTreeMap<(usize, String, String, i8, Option<usize>), Vec<String>> = BTreeMap::new();
        for id in &mapped {
            if removed.contains(id) {
                continue;
            }
            let (Some(&f), Some(sem)) = (face_of.get(id), polys[id].poly.semantic) else { continue };
            let face = m.face(f);
            let solid = ((face.back.0.min(face.front.0) as usize) << 32) | face.back.0.max(face.front.0) as usize;
            let key = (plane_cluster[face.plane.idx()], sem.local_name().to_string(), String::new(), face.orientation.i8() * m.plane(face.plane).sign.i8(), Some(solid));
            groups.entry(key).or_default().push(id.clone());
        }
        for (_, ids) in groups {
            if ids.len() < 2 {
                continue;
            }
            // Connected components by shared (canonical) edges.
            let edges_of = |id: &String| -> Vec<(usize, usize)> {
                let f = face_of[id];
                let loops = m.face_loops(&inc, f, &pos).unwrap_or_default();
                let mut e = Vec::new();
                for l in loops {
                    for k in 0..l.len() {
                        let (a, b) = (canon[l[k].idx()], canon[l[(k + 1) % l.len()].idx()]);
                        if a != b {
                            e.push((a, b));
                        }
                    }
                }
                e
            };
            let es: Vec<Vec<(usize, usize)>> = ids.iter().map(edges_of).collect();
            let n = ids.len();
            let mut comp: Vec<usize> = (0..n).collect();
            for a in 0..n {
                for b in a + 1..n {
                    let sa: HashSet<(usize, usize)> = es[a].iter().copied().collect();
                    if es[b].iter().any(|&(x, y)| sa.contains(&(y, x))) {
                        let (x, y) = (comp[a].min(comp[b]), comp[a].max(comp[b]));
                        for c in comp.iter_mut() {
                            if *c == y {
                                *c = x;
                            }
                        }
                    }
                }
            }
            let mut cs: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
            for (k, &c) in comp.iter().enumerate() {
                cs.entry(c).or_default().push(k);
            }
            for (_, members) in cs {
                if members.len() < 2 {
                    continue;
                }
                // Union boundary: cancel opposite directed edges.
                let mut cnt: HashMap<(usize, usize), i32> = HashMap::new();
                for &k in &members {
                    for &(a, b) in &es[k] {
                        if let Some(c) = cnt.get_mut(&(b, a)) {
                            *c -= 1;
                            if *c == 0 {
                                cnt.remove(&(b, a));
                            }
                        } else {
                            *cnt.entry((a, b)).or_insert(0) += 1;
                        }
                    }
                }
                let mut out: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
                for (&(a, b), &c) in &cnt {
                    for _ in 0..c {
                        out.entry(a).or_default().push(b);
                    }
                }
                let mut loops: Vec<Vec<P3>> = Vec::new();
                let mut ok = true;
                while let Some((&s, _)) = out.iter().find(|(_, v)| !v.is_empty()) {
                    let mut l = vec![s];
                    let mut cur = s;
                    loop {
                        let Some(nx) = out.get_mut(&cur).and_then(|v| v.pop()) else {
                            ok = false;
                            break;
                        };
                        if nx == s {
                            break;
                        }
                        l.push(nx);
                        cur = nx;
                        if l.len() > pos.len() + 1 {
                            ok = false;
                            break;
                        }
                    }
                    if !ok {
                        break;
                    }
                    let pts = collapse(l.iter().map(|&i| pos[i]).collect(), opts.collapse_tolerance);
                    if pts.len() >= 3 && newell_area(&pts) >= opts.area_tolerance {
                        loops.push(pts);
                    }
                }
                if !ok || loops.is_empty() {
                    continue;
                }
                let imax = (0..loops.len()).max_by(|&a, &b| newell_area(&loops[a]).total_cmp(&newell_area(&loops[b]))).unwrap();
                let outer = loops.remove(imax);
                let kept = ids[members[0]].clone();
                let kp = polys[&kept].poly;
                let at = kp.span.bytes.start;
                let px = prefix_at(template, at);
                let dim = kp.exterior.srs_dimension.max(3);
                let mut t = format!("<{px}Polygon {px}id=\"{kept}\"><{px}exterior><{px}LinearRing><{px}posList srsDimension=\"{dim}\">{}</{px}posList></{px}LinearRing></{px}exterior>", fmt_points(&outer, dim));
                for h in &loops {
                    t.push_str(&format!("<{px}interior><{px}LinearRing><{px}posList srsDimension=\"{dim}\">{}</{px}posList></{px}LinearRing></{px}interior>", fmt_points(h, dim)));
                }
                t.push_str(&format!("</{px}Polygon>"));
                replaced.insert(kept.clone(), t);
                let others: Vec<String> = members[1..].iter().map(|&k| ids[k].clone()).collect();
                for o in &others {
                    merged_away.insert(o.clone(), kept.clone());
                }
                report.merged.push((kept, others));
            }
        }
    }

    // Surfaces that lose every polygon (only a surface holding a polygon that went can).
    let surface_polys = &tpl.surface_polys;
    let gone = |id: &String| removed.contains(id) || merged_away.contains_key(id);
    let mut edits: Vec<Edit> = Vec::new();
    let mut emptied: HashSet<usize> = HashSet::new();
    let mut inserts: BTreeMap<usize, Vec<u8>> = BTreeMap::new();
    let surf_keys: BTreeSet<usize> = mapped.iter().filter(|id| gone(id)).filter_map(|id| polys[id].surface.map(|s| s.span.bytes.start)).collect();
    for k in &surf_keys {
        let (s, ids) = &surface_polys[k];
        if ids.iter().all(gone) && !citygml_io::SurfaceType::from_local_name(&s.kind).is_some_and(|t| t.is_opening()) {
            let Some(r) = enclosing(template, s.span.bytes.start, s.span.bytes.end) else { continue };
            emptied.insert(*k);
            report.removed_surfaces.push(s.id.clone().unwrap_or_else(|| format!("{}@{}", s.kind, s.span.line)));
            // Move openings to the surface keeping the merged polygon.
            let target = ids.iter().find_map(|i| merged_away.get(i)).and_then(|kept| polys[kept].surface);
            if let Some(t) = target {
                let close = template[..t.span.bytes.end].iter().rposition(|&c| c == b'<').unwrap_or(t.span.bytes.end);
                for c in &s.children {
                    if let Some(or) = enclosing(template, c.span.bytes.start, c.span.bytes.end) {
                        inserts.entry(close).or_default().extend_from_slice(&template[or.clone()]);
                        report.moved_openings.push(c.id.clone().unwrap_or_default());
                    }
                }
            }
            edits.push(Edit { bytes: r, replacement: vec![] });
        }
    }
    let in_emptied = |id: &String| polys[id].surface.is_some_and(|s| emptied.contains(&s.span.bytes.start));
    for id in &mapped {
        let p = polys[id].poly;
        let id_refs = refs.get(id).cloned().unwrap_or_default();
        if gone(id) {
            if !in_emptied(id) {
                let span = p.member_span.as_ref().map(|s| s.bytes.clone()).unwrap_or(p.span.bytes.clone());
                edits.push(Edit { bytes: span, replacement: vec![] });
            }
            for r in id_refs {
                edits.push(Edit { bytes: r, replacement: vec![] });
            }
            continue;
        }
        if in_emptied(id) {
            continue;
        }
        if let Some(t) = replaced.get(id) {
            edits.push(Edit { bytes: p.span.bytes.clone(), replacement: t.clone().into_bytes() });
            continue;
        }
        let rings = &new_rings[id];
        for (ri, r) in std::iter::once(&p.exterior).chain(p.interiors.iter()).enumerate() {
            match &rings[ri] {
                Some(pts) => {
                    let mut closed = pts.clone();
                    closed.push(pts[0]);
                    if r.encoding == citygml_io::CoordEncoding::Pos && closed.len() != r.pos_spans.len() {
                        let px = prefix_at(template, r.span.bytes.start);
                        let dim = r.srs_dimension.max(3);
                        let t = format!("<{px}LinearRing><{px}posList srsDimension=\"{dim}\">{}</{px}posList></{px}LinearRing>", fmt_points(pts, dim));
                        edits.push(Edit { bytes: r.span.bytes.clone(), replacement: t.into_bytes() });
                    } else {
                        let e = citygml_io::writer::ring_edits(r, &closed).map_err(|e| BackError::Write(format!("polygon `{id}` ring {ri}: {e}")))?;
                        edits.extend(e);
                    }
                }
                None => {
                    // A degenerate hole: drop it with its <gml:interior> wrapper.
                    if let Some(w) = enclosing(template, r.span.bytes.start, r.span.bytes.end) {
                        edits.push(Edit { bytes: w, replacement: vec![] });
                    }
                }
            }
        }
    }
    for (at, bytes) in inserts {
        edits.push(Edit { bytes: at..at, replacement: bytes });
    }
    let mut out = Vec::with_capacity(if write { template.len() } else { 0 });
    let sink: &mut dyn std::io::Write = if write { &mut out } else { &mut std::io::sink() };
    citygml_io::write_with_edits(template, &edits, sink).map_err(|e| BackError::Write(e.to_string()))?;
    report.removed_degenerate.sort();
    report.removed_surfaces.sort();
    Ok((out, report))
}
