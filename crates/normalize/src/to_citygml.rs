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
//! Polygons without gml:id are addressed by the line and column of their start tag
//! ([`crate::citygml::polygon_key`]). Rewritten numbers keep the text of the input where the
//! value did not change at the document's number of decimals (the most any of its coordinates
//! has), and are otherwise written with that many (or `BackOptions::precision`). Deleted elements take their now
//! blank lines with them. Limitation (stated, not hidden): merged polygons are written as
//! `gml:posList` rings.

use citygml_io::{CityModel, CityObject, Edit, Polygon, Ring};
use popa3d_model::vec3::sub;
use popa3d_model::{FaceId, Incidence, NodeId, PlaneId, Popa3d, VertexSource};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

mod dropped;

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
    /// Decimals of rewritten coordinates; `None`: the most decimals of the template's coordinates.
    pub precision: Option<usize>,
}

impl Default for BackOptions {
    fn default() -> Self {
        BackOptions {
            coplanar_tolerance: 1e-3,
            collapse_tolerance: 1e-6,
            area_tolerance: 1e-6,
            merge: true,
            precision: None,
        }
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
    /// Largest vertex move per building (gml:id of the Building/BuildingPart, m).
    pub max_move_by_building: BTreeMap<String, f64>,
}

impl BackReport {
    /// The buildings whose largest vertex move exceeds `limit` (m), worst first: a write-back
    /// that moved a building that far is not a correction, so the caller refuses it.
    pub fn moved_further_than(&self, limit: f64) -> Option<MovedTooFar> {
        let mut far: Vec<(String, f64)> =
            self.max_move_by_building.iter().filter(|(_, &m)| m > limit).map(|(b, &m)| (b.clone(), m)).collect();
        far.sort_by(|a, b| b.1.total_cmp(&a.1));
        (!far.is_empty()).then_some(MovedTooFar { limit, buildings: far })
    }
}

/// Buildings moved further than the accepted limit, worst first; displays the count and the
/// worst five.
#[derive(Debug, Clone, PartialEq)]
pub struct MovedTooFar {
    /// The limit (m).
    pub limit: f64,
    /// (gml:id, largest vertex move in m), worst first.
    pub buildings: Vec<(String, f64)>,
}

impl std::fmt::Display for MovedTooFar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let named: Vec<String> = self.buildings.iter().take(5).map(|(b, m)| format!("{b} ({m:.3} m)")).collect();
        let more = if self.buildings.len() > 5 { ", ..." } else { "" };
        write!(
            f,
            "{} building(s) would move further than --max-move {} m: {}{more}",
            self.buildings.len(),
            self.limit,
            named.join(", ")
        )
    }
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
/// A rewritten ring: each point with its index in the template ring.
type IndexedRing = Vec<(P3, usize)>;

fn dist(a: P3, b: P3) -> f64 {
    let d = sub(a, b);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}
/// Union–find whose root is always the smallest index of its class: the labels the pairwise
/// relabelling loops computed (smaller label wins), without relabelling every element per pair.
fn uf_find(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}
fn uf_union(parent: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (uf_find(parent, a), uf_find(parent, b));
    if ra != rb {
        parent[ra.max(rb)] = ra.min(rb);
    }
}

/// For every node, the smallest index among the nodes within `tol` of it, transitively (the
/// classes of the "within `tol`" relation, each named by its smallest member).
///
/// Linear in the number of nodes (docs/decisions.md#node-merging-union-find): exact duplicates
/// are united through a hash of their coordinates first (765 identical buildings at one place
/// put 765 nodes on each corner, and pairwise relabelling of every node made that cubic), the
/// remaining positions through a hash grid of cells `2·tol` wide (a point within `tol` lies in
/// a neighbouring cell), with a union–find whose root is always the smallest index.
fn coincident_classes(pos: &[P3], tol: f64) -> Vec<usize> {
    let mut parent: Vec<usize> = (0..pos.len()).collect();
    if !(tol >= 0.0) {
        return parent; // nothing is within a negative tolerance, not even a node of itself
    }
    // Exact duplicates (-0.0 and 0.0 alike): one representative each.
    let key = |p: &P3| [(p[0] + 0.0).to_bits(), (p[1] + 0.0).to_bits(), (p[2] + 0.0).to_bits()];
    let mut first: HashMap<[u64; 3], usize> = HashMap::with_capacity(pos.len());
    let mut reps: Vec<usize> = Vec::new();
    for (i, p) in pos.iter().enumerate() {
        match first.entry(key(p)) {
            std::collections::hash_map::Entry::Occupied(e) => uf_union(&mut parent, *e.get(), i),
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(i);
                reps.push(i);
            }
        }
    }
    if tol > 0.0 {
        let cell = 2.0 * tol;
        let at = |p: &P3| [(p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64, (p[2] / cell).floor() as i64];
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::with_capacity(reps.len());
        for &i in &reps {
            let c = at(&pos[i]);
            for dx in -1..=1i64 {
                for dy in -1..=1i64 {
                    for dz in -1..=1i64 {
                        let n = [c[0].saturating_add(dx), c[1].saturating_add(dy), c[2].saturating_add(dz)];
                        let Some(others) = grid.get(&n) else { continue };
                        for &j in others {
                            if dist(pos[i], pos[j]) <= tol {
                                uf_union(&mut parent, i, j);
                            }
                        }
                    }
                }
            }
            grid.entry(c).or_default().push(i);
        }
    }
    (0..pos.len()).map(|i| uf_find(&mut parent, i)).collect()
}

fn newell_area(pts: &[P3]) -> f64 {
    let n = popa3d_model::topology::newell(pts);
    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

/// Remove consecutive duplicates (cyclically) within `tol`, keeping the input index of each kept
/// point.
fn collapse_indexed(pts: Vec<(P3, usize)>, tol: f64) -> Vec<(P3, usize)> {
    let mut out: Vec<(P3, usize)> = Vec::with_capacity(pts.len());
    for p in pts {
        if out.last().is_none_or(|q| dist(q.0, p.0) > tol) {
            out.push(p);
        }
    }
    while out.len() > 1 && dist(out[0].0, out.last().unwrap().0) <= tol {
        out.pop();
    }
    out
}

/// Remove consecutive duplicates (cyclically) within `tol`.
fn collapse(pts: Vec<P3>, tol: f64) -> Vec<P3> {
    collapse_indexed(pts.into_iter().map(|p| (p, 0)).collect(), tol).into_iter().map(|(p, _)| p).collect()
}

/// The enclosing element of a span: from the `<` of the start tag right before `start` to the
/// `>` of the end tag right after `end`, with only whitespace and comments between (GML property
/// wrappers like `<gml:interior>`, `<bldg:opening>` or `<gml:surfaceMember>`). `None` when text
/// or another element stands between.
fn enclosing(src: &[u8], start: usize, end: usize) -> Option<std::ops::Range<usize>> {
    let mut s = start;
    loop {
        while s > 0 && src[s - 1].is_ascii_whitespace() {
            s -= 1;
        }
        if s >= 3 && &src[s - 3..s] == b"-->" {
            s = memrfind(&src[..s - 3], b"<!--")?;
            continue;
        }
        break;
    }
    if s == 0 || src[s - 1] != b'>' || (s >= 2 && src[s - 2] == b'/') {
        return None;
    }
    let open = src[..s].iter().rposition(|&c| c == b'<')?;
    if matches!(src.get(open + 1), Some(b'/') | Some(b'!') | Some(b'?')) {
        return None;
    }
    let mut e = end;
    loop {
        while e < src.len() && src[e].is_ascii_whitespace() {
            e += 1;
        }
        if src[e..].starts_with(b"<!--") {
            e += find(&src[e..], b"-->")? + 3;
            continue;
        }
        break;
    }
    if src.get(e) != Some(&b'<') || src.get(e + 1) != Some(&b'/') {
        return None;
    }
    let close = src[e..].iter().position(|&c| c == b'>')? + e + 1;
    Some(open..close)
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn memrfind(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).rposition(|w| w == needle)
}

/// What to delete for an XLink reference to a removed polygon: the referencing property itself,
/// or, when it is the `baseSurface` of a `gml:OrientableSurface`, the member property holding
/// that OrientableSurface (an OrientableSurface without base surface is not schema-valid).
fn xlink_deletion(src: &[u8], r: std::ops::Range<usize>) -> std::ops::Range<usize> {
    let Some(parent) = enclosing(src, r.start, r.end) else { return r };
    if !src[parent.start..].starts_with(b"<") || !element_name(src, parent.start).ends_with("OrientableSurface") {
        return r;
    }
    enclosing(src, parent.start, parent.end).unwrap_or(parent)
}

/// The qualified name of the element whose start tag begins at `at`.
fn element_name(src: &[u8], at: usize) -> String {
    let tag: Vec<u8> =
        src[at + 1..].iter().take_while(|c| !c.is_ascii_whitespace() && **c != b'>' && **c != b'/').copied().collect();
    String::from_utf8_lossy(&tag).into_owned()
}

/// Namespace prefix of the element starting at `at` (`<gml:Polygon` → `gml:`; none → empty).
fn prefix_at(src: &[u8], at: usize) -> String {
    let t = element_name(src, at);
    match t.find(':') {
        Some(i) => t[..=i].to_string(),
        None => String::new(),
    }
}

/// A whole `gml:Polygon` in the prefix, ids and number format of the template polygon `kp`
/// it replaces, with `outer` and `holes` as posList rings.
fn polygon_text(template: &[u8], kp: &Polygon, outer: &[P3], holes: &[Vec<P3>], decimals: Option<usize>) -> String {
    let px = prefix_at(template, kp.span.bytes.start);
    let dim = kp.exterior.srs_dimension.max(3);
    let text = RingText::of(template, &kp.exterior, decimals);
    let mut rings = vec![(kp.exterior.id.as_deref(), fmt_points(outer, &[], dim, &text))];
    for (k, h) in holes.iter().enumerate() {
        rings.push((kp.interiors.get(k).and_then(|r| r.id.as_deref()), fmt_points(h, &[], dim, &text)));
    }
    citygml_io::writer::polygon_element(&px, kp.id.as_deref(), &rings, dim)
}

/// A closed posList text of `pts` (the first point repeated at the end); `src[k]` is the input
/// index of point k in the ring `text` was read from, when it has one.
fn fmt_points(pts: &[P3], src: &[Option<usize>], dim: u8, text: &RingText) -> String {
    let mut s = String::new();
    let n = pts.len();
    for i in 0..=n {
        let (p, at) = (&pts[i % n], src.get(i % n).copied().flatten());
        for (k, v) in p.iter().take(dim as usize).enumerate() {
            if i > 0 || k > 0 {
                s.push(' ');
            }
            s.push_str(&text.value(at, k, *v));
        }
    }
    s
}

struct PolyInfo<'a> {
    poly: &'a Polygon,
    /// Thematic surface (boundary surface / opening) owning the polygon.
    surface: Option<&'a CityObject>,
    /// The nearest Building / BuildingPart holding the polygon.
    building: Option<&'a CityObject>,
}

/// Where the polygons of a template go while it is indexed.
#[derive(Default)]
struct PolyIndex<'a> {
    polys: HashMap<String, PolyInfo<'a>>,
    refs: HashMap<String, Vec<XLinkUse>>,
    order: Vec<String>,
}

/// One XLink reference to a polygon: the referencing property's bytes and the start byte of the
/// Building / BuildingPart holding it (its identity).
#[derive(Clone)]
struct XLinkUse {
    bytes: std::ops::Range<usize>,
    building: Option<usize>,
}

fn collect_polys<'a>(
    o: &'a CityObject,
    surface: Option<&'a CityObject>,
    building: Option<&'a CityObject>,
    ix: &mut PolyIndex<'a>,
) {
    let surf = if citygml_io::SurfaceType::from_local_name(&o.kind).is_some() { Some(o) } else { surface };
    let building = if crate::citygml::is_building(o) { Some(o) } else { building };
    for g in &o.geometries {
        for p in g.polygons() {
            match (&p.via_xlink, &p.id) {
                (Some(r), Some(id)) => ix
                    .refs
                    .entry(id.clone())
                    .or_default()
                    .push(XLinkUse { bytes: r.bytes.clone(), building: building.map(|b| b.span.bytes.start) }),
                (Some(_), None) => {}
                (None, _) => {
                    let key = crate::citygml::polygon_key(p);
                    if !ix.polys.contains_key(&key) {
                        ix.order.push(key.clone());
                    }
                    ix.polys.insert(key, PolyInfo { poly: p, surface: surf, building });
                }
            }
        }
    }
    for c in &o.children {
        collect_polys(c, surf, building, ix);
    }
}

/// The gml:id of a building (or its position when it has none), as reports name it.
fn building_name(b: Option<&CityObject>) -> String {
    match b {
        Some(b) => crate::citygml::unit_name(b),
        None => "(no building)".into(),
    }
}

/// Widens a deletion to whole lines when it is alone on its lines (only whitespace before it
/// on its first line and after it on its last), so removed elements leave no blank lines.
fn whole_lines(src: &[u8], r: std::ops::Range<usize>) -> std::ops::Range<usize> {
    let mut s = r.start;
    while s > 0 && (src[s - 1] == b' ' || src[s - 1] == b'\t') {
        s -= 1;
    }
    let mut e = r.end;
    while e < src.len() && (src[e] == b' ' || src[e] == b'\t' || src[e] == b'\r') {
        e += 1;
    }
    let line_start = s == 0 || src[s - 1] == b'\n';
    if line_start && e < src.len() && src[e] == b'\n' {
        s..e + 1
    } else {
        r
    }
}

/// The coordinate tokens of a ring's text, in order.
fn ring_tokens<'t>(src: &'t [u8], r: &Ring) -> Vec<&'t str> {
    let spans: Vec<std::ops::Range<usize>> = match r.encoding {
        citygml_io::CoordEncoding::Pos => r.pos_spans.iter().map(|s| s.bytes.clone()).collect(),
        _ => vec![r.text_span.bytes.clone()],
    };
    let mut tokens = Vec::new();
    for sp in spans {
        let text = std::str::from_utf8(src.get(sp).unwrap_or_default()).unwrap_or("");
        tokens.extend(text.split(|c: char| c.is_ascii_whitespace() || c == ',').filter(|t| !t.is_empty()));
    }
    tokens
}

/// The most decimals any coordinate of these polygons is written with; `None` when one is in
/// exponent notation (then new numbers are written in shortest round-trip form).
fn document_decimals<'a>(src: &[u8], polys: impl Iterator<Item = &'a Polygon>) -> Option<usize> {
    let mut most = 0;
    for p in polys {
        for r in std::iter::once(&p.exterior).chain(p.interiors.iter()) {
            for t in ring_tokens(src, r) {
                most = most.max(decimals(t)?);
            }
        }
    }
    Some(most)
}

/// Number of decimals of a plain decimal number token (`12.345` → 3, `12` → 0); `None` for
/// exponent notation or anything else.
fn decimals(tok: &str) -> Option<usize> {
    let t = tok.strip_prefix(['-', '+']).unwrap_or(tok);
    let (int, frac) = t.split_once('.').unwrap_or((t, ""));
    if int.bytes().all(|c| c.is_ascii_digit())
        && frac.bytes().all(|c| c.is_ascii_digit())
        && !(int.is_empty() && frac.is_empty())
    {
        Some(frac.len())
    } else {
        None
    }
}

/// How rewritten coordinates of one ring are spelled: the input's tokens (one per value, in
/// order) and the number of decimals of the document (not of the ring: a node shared by rings
/// written with 1 and 2 decimals must come out as the same number in all of them).
struct RingText<'t> {
    tokens: Vec<&'t str>,
    /// Values per position in the input text.
    dim: usize,
    decimals: Option<usize>,
}

impl<'t> RingText<'t> {
    fn of(src: &'t [u8], r: &Ring, decimals: Option<usize>) -> RingText<'t> {
        RingText { tokens: ring_tokens(src, r), dim: r.srs_dimension.max(1) as usize, decimals }
    }

    /// The text of value `c` of point `p` (an index into the input ring, `None` for a new
    /// point): the input's own token when the value is unchanged at the document's decimals.
    fn value(&self, p: Option<usize>, c: usize, v: f64) -> String {
        if let (Some(tok), Some(d)) =
            (p.filter(|_| c < self.dim).and_then(|p| self.tokens.get(p * self.dim + c)), self.decimals)
        {
            if let Ok(old) = tok.parse::<f64>() {
                if format!("{:.*}", d, v).parse::<f64>().ok() == format!("{:.*}", d, old).parse::<f64>().ok() {
                    return tok.to_string();
                }
            }
        }
        match self.decimals {
            Some(d) => {
                let t = format!("{:.*}", d, v);
                if t.parse::<f64>().ok() == Some(0.0) {
                    format!("{:.*}", d, 0.0)
                } else {
                    t
                }
            }
            None => format!("{}", v + 0.0),
        }
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
pub fn to_citygml(
    model: &Popa3d,
    template: &[u8],
    city: &CityModel,
    opts: &BackOptions,
) -> Result<(Vec<u8>, BackReport), BackError> {
    to_citygml_with(model, &Template::new(template, city), opts)
}

/// The template document (its bytes and the model read from them) with its polygons by key
/// (gml:id or position, [`crate::citygml::polygon_key`]; with the thematic surface and building
/// that own each), the XLinks to each and the document order: what [`back_edits`] looks up.
/// Built once per template, so writing many models back into one document (`geofit heal`
/// writes every building on its own) does not scan it per model.
pub struct Template<'a> {
    bytes: &'a [u8],
    polys: HashMap<String, PolyInfo<'a>>,
    refs: HashMap<String, Vec<XLinkUse>>,
    doc_order: Vec<String>,
    /// Polygon keys per thematic surface (keyed by the surface's start byte).
    surface_polys: HashMap<usize, (&'a CityObject, Vec<String>)>,
    /// Decimals of the document's coordinates (see [`document_decimals`]).
    decimals: Option<usize>,
}

impl<'a> Template<'a> {
    /// `city` must be the model read from `bytes`.
    pub fn new(bytes: &'a [u8], city: &'a CityModel) -> Template<'a> {
        let mut ix = PolyIndex::default();
        for o in &city.objects {
            collect_polys(o, None, None, &mut ix);
        }
        let mut surface_polys: HashMap<usize, (&CityObject, Vec<String>)> = HashMap::new();
        for id in &ix.order {
            if let Some(s) = ix.polys[id].surface {
                surface_polys.entry(s.span.bytes.start).or_insert((s, Vec::new())).1.push(id.clone());
            }
        }
        let decimals = document_decimals(bytes, ix.polys.values().map(|p| p.poly));
        Template { bytes, polys: ix.polys, refs: ix.refs, doc_order: ix.order, surface_polys, decimals }
    }

    /// The template with `edits` applied (they must not overlap).
    pub fn apply(&self, edits: &[Edit]) -> Result<Vec<u8>, BackError> {
        let mut out = Vec::with_capacity(self.bytes.len());
        citygml_io::write_with_edits(self.bytes, edits, &mut out).map_err(|e| BackError::Write(e.to_string()))?;
        Ok(out)
    }
}

/// [`back_edits`] applied to the template: the new document and the report.
pub fn to_citygml_with(model: &Popa3d, tpl: &Template, opts: &BackOptions) -> Result<(Vec<u8>, BackReport), BackError> {
    let (edits, report) = back_edits(model, tpl, opts)?;
    Ok((tpl.apply(&edits)?, report))
}

/// The edits that write the adjusted model back into its template, and the report. Edits touch
/// only the polygons the model maps to (and XLinks to polygons it removes), so the edits of
/// models of different buildings can be applied together or left out one building at a time.
pub fn back_edits(model: &Popa3d, tpl: &Template, opts: &BackOptions) -> Result<(Vec<Edit>, BackReport), BackError> {
    let mut m = model.clone();
    let plane_cluster = snap_coplanar_planes(&mut m, opts.coplanar_tolerance);
    let inc = Incidence::new(&m);
    let pos = node_positions(&m, &inc, &tpl.polys)?;
    let vmap = vertex_map(&m, &tpl.polys)?;
    let absorbed = absorbed_polygons(&m, &tpl.polys);
    let mapped = mapped_polygons(tpl, &vmap, &absorbed);
    let mut report = BackReport { polygons_mapped: mapped.len(), ..Default::default() };
    let face_of = face_of_polygon(&m);
    let mut face_of_any = face_of.clone();
    for (host, guests) in &absorbed {
        if let Some(&f) = face_of.get(host) {
            face_of_any.extend(guests.iter().map(|g| (g.clone(), f)));
        }
    }
    let dropped = dropped::Dropped::new(&mapped, &tpl.polys, &face_of_any);
    let new_rings = rewritten_rings(&mapped, &tpl.polys, &vmap, &pos, (&m, &dropped), opts, &mut report)?;
    let external = externally_referenced(tpl, &mapped);
    let back = Back {
        tpl,
        opts,
        decimals: opts.precision.or(tpl.decimals),
        m: &m,
        plane_cluster,
        inc,
        pos,
        face_of,
        mapped: &mapped,
        external,
    };
    let mut fate = Fate::default();
    back.remove_degenerate(&new_rings, &mut fate, &mut report);
    back.write_changed_faces_whole(&vmap, &absorbed, &mut fate, &mut report);
    if opts.merge {
        back.merge_coplanar(&mut fate, &mut report);
    }
    back.check_external_kept(&fate)?;
    let mut edits: Vec<Edit> = Vec::new();
    let (emptied, inserts) = back.surface_edits(&fate, &mut edits, &mut report);
    for id in back.mapped {
        back.polygon_edits(id, &fate, &emptied, &new_rings[id], &mut edits)?;
    }
    for (at, bytes) in inserts {
        edits.push(Edit { bytes: at..at, replacement: bytes });
    }
    for e in &mut edits {
        if e.replacement.is_empty() {
            e.bytes = whole_lines(tpl.bytes, e.bytes.clone());
        }
    }
    report.removed_degenerate.sort();
    report.removed_surfaces.sort();
    Ok((edits, report))
}

/// Polygons merged into another polygon's face by normalization, as (host, merged ones present
/// in the template): they belong to the model even when none of their vertices kept a node.
fn absorbed_polygons(m: &Popa3d, polys: &HashMap<String, PolyInfo<'_>>) -> Vec<(String, Vec<String>)> {
    m.faces
        .iter()
        .filter_map(|f| f.source.as_ref())
        .filter(|s| !s.merged.is_empty() && polys.contains_key(&s.polygon))
        .map(|s| (s.polygon.clone(), s.merged.iter().filter(|g| polys.contains_key(*g)).cloned().collect()))
        .collect()
}

/// The template's polygons the model maps to, in document order: those with a vertex on a node,
/// and hosts and merged polygons too (a face can keep none of its polygon's own vertices: the
/// middle one of three collinear wall segments).
fn mapped_polygons(
    tpl: &Template,
    vmap: &HashMap<(String, u32, u32), NodeId>,
    absorbed: &[(String, Vec<String>)],
) -> Vec<String> {
    let mut mapped_set: HashSet<&String> = vmap.keys().map(|k| &k.0).collect();
    mapped_set.extend(absorbed.iter().flat_map(|(h, g)| std::iter::once(h).chain(g.iter())));
    tpl.doc_order.iter().filter(|id| mapped_set.contains(id)).cloned().collect()
}

/// Polygons referenced (XLink) from outside their own building: removing or merging them would
/// change another building, so they keep their own polygon.
fn externally_referenced(tpl: &Template, mapped: &[String]) -> HashSet<String> {
    mapped
        .iter()
        .filter(|id| {
            let own = tpl.polys[*id].building.map(|b| b.span.bytes.start);
            tpl.refs.get(*id).is_some_and(|rs| rs.iter().any(|r| r.building != own))
        })
        .cloned()
        .collect()
}

/// The face of each source polygon id.
fn face_of_polygon(m: &Popa3d) -> HashMap<String, FaceId> {
    let mut face_of: HashMap<String, FaceId> = HashMap::new();
    for (i, f) in m.faces.iter().enumerate() {
        if let Some(s) = &f.source {
            face_of.insert(s.polygon.clone(), FaceId::from(i));
        }
    }
    face_of
}

/// What writing back decided for the mapped polygons other than rewriting their vertices.
#[derive(Default)]
struct Fate {
    /// Degenerate: removed.
    removed: HashSet<String>,
    /// Kept id → its new polygon text (written whole).
    replaced: HashMap<String, String>,
    /// Removed id → the kept id it was merged into.
    merged_away: HashMap<String, String>,
}

impl Fate {
    fn gone(&self, id: &String) -> bool {
        self.removed.contains(id) || self.merged_away.contains_key(id)
    }
}

/// The adjusted model (coplanar planes snapped) with the template it is written into.
struct Back<'t, 'a> {
    tpl: &'t Template<'a>,
    opts: &'t BackOptions,
    decimals: Option<usize>,
    m: &'t Popa3d,
    plane_cluster: Vec<usize>,
    inc: Incidence,
    pos: Vec<P3>,
    face_of: HashMap<String, FaceId>,
    mapped: &'t [String],
    external: HashSet<String>,
}

impl Back<'_, '_> {
    /// 3. Polygons whose outer ring collapsed are removed.
    fn remove_degenerate(
        &self,
        new_rings: &HashMap<String, Vec<Option<IndexedRing>>>,
        fate: &mut Fate,
        report: &mut BackReport,
    ) {
        for id in self.mapped {
            if new_rings[id][0].is_none() {
                fate.removed.insert(id.clone());
                report.removed_degenerate.push(id.clone());
            }
        }
    }

    /// A polygon whose face has other nodes than its own vertices (it absorbed a neighbour, or
    /// lost collinear vertices to a neighbour's merge) is written as its face. Polygons that
    /// normalization merged into the face of another polygon (GA01 repair, spec §7.4: coplanar
    /// neighbours whose common edge left a node without three planes) have vertices in the model
    /// but no face of their own. Writing them vertex by vertex would drop them as degenerate and
    /// lose their surface; instead the host face is written whole into its own polygon and they
    /// are merged away into it ([`Back::merge_absorbed`]).
    fn write_changed_faces_whole(
        &self,
        vmap: &HashMap<(String, u32, u32), NodeId>,
        absorbed: &[(String, Vec<String>)],
        fate: &mut Fate,
        report: &mut BackReport,
    ) {
        let mut nodes_of: HashMap<&String, BTreeSet<NodeId>> = HashMap::new();
        for ((p, _, _), n) in vmap {
            nodes_of.entry(p).or_default().insert(*n);
        }
        let hosts: HashSet<&String> = absorbed.iter().map(|(h, _)| h).collect();
        for id in self.mapped {
            let Some(&f) = self.face_of.get(id) else { continue };
            let Some(loops) = self.m.face_loops(&self.inc, f, &self.pos) else { continue };
            let on_face: BTreeSet<NodeId> = loops.iter().flatten().copied().collect();
            // a host keeps its own ring, its guests theirs, all on the shared plane
            if nodes_of.get(id) == Some(&on_face) || hosts.contains(id) {
                continue;
            }
            let mut rings: Vec<Vec<P3>> = loops
                .iter()
                .map(|l| collapse(l.iter().map(|n| self.pos[n.idx()]).collect(), self.opts.collapse_tolerance))
                .collect();
            if rings.is_empty() || rings[0].len() < 3 || newell_area(&rings[0]) < self.opts.area_tolerance {
                continue;
            }
            let outer = rings.remove(0);
            rings.retain(|r| r.len() >= 3 && newell_area(r) >= self.opts.area_tolerance);
            fate.replaced.insert(
                id.clone(),
                polygon_text(self.tpl.bytes, self.tpl.polys[id].poly, &outer, &rings, self.decimals),
            );
            fate.removed.remove(id);
            report.removed_degenerate.retain(|r| r != id);
        }
    }

    /// Step 4: polygons on one plane cluster with the same semantic type, orientation and solids that
    /// share edges become one polygon, written into the first of them.
    fn merge_coplanar(&self, fate: &mut Fate, report: &mut BackReport) {
        let canon = coincident_classes(&self.pos, self.opts.collapse_tolerance);
        for (_, ids) in self.merge_groups(fate) {
            if ids.len() < 2 {
                continue;
            }
            let es: Vec<Vec<(usize, usize)>> = ids.iter().map(|id| self.canonical_edges(id, &canon)).collect();
            for (_, members) in edge_components(&es) {
                let Some(members) = self.keeping_identity(&ids, members) else { continue };
                let Some(loops) = union_boundary(&es, &members, &self.pos, self.opts) else { continue };
                self.merge_members(&ids, &members, loops, fate, report);
            }
        }
    }

    /// The members of a merge reordered so that the one polygon with a gml:id (if any) keeps the
    /// merged polygon; `None` when fewer than two members or more than one has an id (merging
    /// would delete an element with an identity).
    fn keeping_identity(&self, ids: &[String], mut members: Vec<usize>) -> Option<Vec<usize>> {
        let with_id: Vec<usize> =
            members.iter().copied().filter(|&k| self.tpl.polys[&ids[k]].poly.id.is_some()).collect();
        if members.len() < 2 || with_id.len() > 1 {
            return None;
        }
        if let Some(&k) = with_id.first() {
            members.retain(|&x| x != k);
            members.insert(0, k);
        }
        Some(members)
    }

    /// The polygons that may merge, keyed by (plane cluster, semantic type, orientation, solids).
    fn merge_groups(&self, fate: &Fate) -> BTreeMap<(usize, String, String, i8, Option<usize>), Vec<String>> {
        let (m, polys) = (self.m, &self.tpl.polys);
        let mut groups: BTreeMap<(usize, String, String, i8, Option<usize>), Vec<String>> = BTreeMap::new();
        for id in self.mapped {
            if fate.removed.contains(id) || self.external.contains(id) || fate.merged_away.contains_key(id) {
                continue;
            }
            let (Some(&f), Some(sem)) = (self.face_of.get(id), polys[id].poly.semantic) else { continue };
            let face = m.face(f);
            let solid = ((face.back.0.min(face.front.0) as usize) << 32) | face.back.0.max(face.front.0) as usize;
            // A surface with an id or attributes merges only its own polygons (its own group);
            // surfaces without identity may merge with each other (docs/decisions.md#merges-keep-semantics-and-identity).
            let surface = polys[id]
                .surface
                .filter(|s| crate::identity::must_stay(self.tpl.bytes, s))
                .map(|s| s.span.bytes.start.to_string())
                .unwrap_or_default();
            let key = (
                self.plane_cluster[face.plane.idx()],
                sem.local_name().to_string(),
                surface,
                face.orientation.i8() * m.plane(face.plane).sign.i8(),
                Some(solid),
            );
            groups.entry(key).or_default().push(id.clone());
        }
        groups
    }

    /// The directed edges of a polygon's face between canonical (coincident-merged) nodes.
    fn canonical_edges(&self, id: &String, canon: &[usize]) -> Vec<(usize, usize)> {
        let f = self.face_of[id];
        let loops = self.m.face_loops(&self.inc, f, &self.pos).unwrap_or_default();
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
    }

    /// Writes the union `loops` (largest first as outer ring) into the first member and merges
    /// the others away into it, also where earlier merges pointed at them.
    fn merge_members(
        &self,
        ids: &[String],
        members: &[usize],
        mut loops: Vec<Vec<P3>>,
        fate: &mut Fate,
        report: &mut BackReport,
    ) {
        let imax =
            (0..loops.len()).max_by(|&a, &b| newell_area(&loops[a]).total_cmp(&newell_area(&loops[b]))).unwrap_or(0);
        let outer = loops.remove(imax);
        let kept = ids[members[0]].clone();
        let t = polygon_text(self.tpl.bytes, self.tpl.polys[&kept].poly, &outer, &loops, self.decimals);
        fate.replaced.insert(kept.clone(), t);
        let others: Vec<String> = members[1..].iter().map(|&k| ids[k].clone()).collect();
        for o in &others {
            fate.merged_away.insert(o.clone(), kept.clone());
            fate.replaced.remove(o);
        }
        for target in fate.merged_away.values_mut() {
            if others.contains(target) {
                *target = kept.clone();
            }
        }
        report.merged.push((kept, others));
    }

    /// A polygon referenced from another building must keep its area.
    fn check_external_kept(&self, fate: &Fate) -> Result<(), BackError> {
        match self.mapped.iter().find(|id| fate.gone(id) && self.external.contains(*id)) {
            Some(id) => Err(BackError::Geometry {
                element: format!("polygon `{id}` of {}", building_name(self.tpl.polys[id].building)),
                message: "would lose its area but is referenced (XLink) from another building".into(),
            }),
            None => Ok(()),
        }
    }

    /// Surfaces that lose every polygon (only a surface holding a polygon that went can) are
    /// removed, their openings moved to the surface keeping the merged polygon. Returns the
    /// emptied surfaces (by start byte) and the bytes to insert (by position).
    fn surface_edits(
        &self,
        fate: &Fate,
        edits: &mut Vec<Edit>,
        report: &mut BackReport,
    ) -> (HashSet<usize>, BTreeMap<usize, Vec<u8>>) {
        let (template, polys) = (self.tpl.bytes, &self.tpl.polys);
        let gone = |id: &String| fate.gone(id);
        let mut emptied: HashSet<usize> = HashSet::new();
        let mut inserts: BTreeMap<usize, Vec<u8>> = BTreeMap::new();
        let surf_keys: BTreeSet<usize> = self
            .mapped
            .iter()
            .filter(|id| gone(id))
            .filter_map(|id| polys[id].surface.map(|s| s.span.bytes.start))
            .collect();
        for k in &surf_keys {
            let (s, ids) = &self.tpl.surface_polys[k];
            if ids.iter().all(gone)
                && !citygml_io::SurfaceType::from_local_name(&s.kind).is_some_and(|t| t.is_opening())
            {
                let Some(r) = enclosing(template, s.span.bytes.start, s.span.bytes.end) else { continue };
                emptied.insert(*k);
                report.removed_surfaces.push(s.id.clone().unwrap_or_else(|| format!("{}@{}", s.kind, s.span.line)));
                // Move openings to the surface keeping the merged polygon.
                let target = ids.iter().find_map(|i| fate.merged_away.get(i)).and_then(|kept| polys[kept].surface);
                if let Some(t) = target {
                    let close =
                        template[..t.span.bytes.end].iter().rposition(|&c| c == b'<').unwrap_or(t.span.bytes.end);
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
        (emptied, inserts)
    }

    /// The edits of one mapped polygon: removed (with the XLinks to it) when gone, nothing when
    /// its surface went, its new text when written whole, else its rings rewritten.
    fn polygon_edits(
        &self,
        id: &String,
        fate: &Fate,
        emptied: &HashSet<usize>,
        rings: &[Option<IndexedRing>],
        edits: &mut Vec<Edit>,
    ) -> Result<(), BackError> {
        let p = self.tpl.polys[id].poly;
        let in_emptied = self.tpl.polys[id].surface.is_some_and(|s| emptied.contains(&s.span.bytes.start));
        if fate.gone(id) {
            if !in_emptied {
                let span = p.member_span.as_ref().map(|s| s.bytes.clone()).unwrap_or(p.span.bytes.clone());
                edits.push(Edit { bytes: span, replacement: vec![] });
            }
            for r in self.tpl.refs.get(id).cloned().unwrap_or_default() {
                edits.push(Edit { bytes: xlink_deletion(self.tpl.bytes, r.bytes), replacement: vec![] });
            }
            return Ok(());
        }
        if in_emptied {
            return Ok(());
        }
        if let Some(t) = fate.replaced.get(id) {
            edits.push(Edit { bytes: p.span.bytes.clone(), replacement: t.clone().into_bytes() });
            return Ok(());
        }
        for (ri, r) in std::iter::once(&p.exterior).chain(p.interiors.iter()).enumerate() {
            match &rings[ri] {
                Some(pts) => edits.extend(self.ring_edits(id, ri, r, pts)?),
                None => {
                    // A degenerate hole: drop it with its <gml:interior> wrapper.
                    if let Some(w) = enclosing(self.tpl.bytes, r.span.bytes.start, r.span.bytes.end) {
                        edits.push(Edit { bytes: w, replacement: vec![] });
                    }
                }
            }
        }
        Ok(())
    }

    /// One ring's new coordinates: edited in place value by value, or the whole ring element
    /// rewritten when a `gml:pos` ring changes its number of points.
    fn ring_edits(&self, id: &str, ri: usize, r: &Ring, pts: &IndexedRing) -> Result<Vec<Edit>, BackError> {
        let template = self.tpl.bytes;
        let text = RingText::of(template, r, self.decimals);
        let (xyz, src): (Vec<P3>, Vec<Option<usize>>) = pts.iter().map(|&(q, k)| (q, Some(k))).unzip();
        let dim = r.srs_dimension.max(3);
        if r.encoding == citygml_io::CoordEncoding::Pos && pts.len() + 1 != r.pos_spans.len() {
            let px = prefix_at(template, r.span.bytes.start);
            let t =
                citygml_io::writer::linear_ring_element(&px, r.id.as_deref(), &fmt_points(&xyz, &src, dim, &text), dim);
            return Ok(vec![Edit { bytes: r.span.bytes.clone(), replacement: t.into_bytes() }]);
        }
        let mut closed = xyz.clone();
        closed.push(xyz[0]);
        let mut at = src.clone();
        at.push(src[0]);
        citygml_io::writer::ring_edits_with(r, &closed, |i, c, v| text.value(at[i], c, v))
            .map_err(|e| BackError::Write(format!("polygon `{id}` ring {ri}: {e}")))
    }
}

/// Polygons (by their directed edges) that share an edge in opposite directions, grouped into
/// connected components (union–find over an edge index, linear where comparing every pair was
/// quadratic); each component lists its polygons' indices in `es`.
fn edge_components(es: &[Vec<(usize, usize)>]) -> BTreeMap<usize, Vec<usize>> {
    let n = es.len();
    let mut comp: Vec<usize> = (0..n).collect();
    let mut owners: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (k, e) in es.iter().enumerate() {
        for &d in e {
            owners.entry(d).or_default().push(k);
        }
    }
    for (k, e) in es.iter().enumerate() {
        for &(x, y) in e {
            for &o in owners.get(&(y, x)).map(Vec::as_slice).unwrap_or(&[]) {
                if o != k {
                    uf_union(&mut comp, k, o);
                }
            }
        }
    }
    let comp: Vec<usize> = (0..n).map(|k| uf_find(&mut comp, k)).collect();
    let mut cs: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (k, &c) in comp.iter().enumerate() {
        cs.entry(c).or_default().push(k);
    }
    cs
}

/// The boundary of the union of polygons `members` (directed edges over canonical node ids):
/// opposite edges cancel, the rest is walked into loops at `pos`, collapsed and kept where they
/// have area. `None` when the edges do not close into loops or no loop is left.
fn union_boundary(
    es: &[Vec<(usize, usize)>],
    members: &[usize],
    pos: &[P3],
    opts: &BackOptions,
) -> Option<Vec<Vec<P3>>> {
    let mut cnt: HashMap<(usize, usize), i32> = HashMap::new();
    for &k in members {
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
    (ok && !loops.is_empty()).then_some(loops)
}

/// The new rings of every mapped polygon, each point with its index in the template ring (a
/// vertex without node was merged into its neighbour by normalization and is written once, as
/// the neighbour); `None` for a ring that collapsed below 3 points or the area tolerance. Adds
/// the vertex moves to `report`.
fn rewritten_rings(
    mapped: &[String],
    polys: &HashMap<String, PolyInfo<'_>>,
    vmap: &HashMap<(String, u32, u32), NodeId>,
    pos: &[P3],
    (m, dropped): (&Popa3d, &dropped::Dropped),
    opts: &BackOptions,
    report: &mut BackReport,
) -> Result<HashMap<String, Vec<Option<IndexedRing>>>, BackError> {
    let mut new_rings: HashMap<String, Vec<Option<IndexedRing>>> = HashMap::new();
    let (mut moves, mut nmoves, mut maxmove) = (0.0, 0usize, 0.0f64);
    for id in mapped {
        let p = polys[id].poly;
        let bname = building_name(polys[id].building);
        let mut rings = Vec::new();
        for (ri, r) in std::iter::once(&p.exterior).chain(p.interiors.iter()).enumerate() {
            let n = ring_len(r);
            let mut pts = Vec::with_capacity(n);
            for k in 0..n {
                // A vertex without node was merged into its neighbour by normalization (snap):
                // it is written once, as the neighbour.
                let q = match vmap.get(&(id.clone(), ri as u32, k as u32)) {
                    Some(node) => pos[node.idx()],
                    None => {
                        let has_node = |j: usize| vmap.contains_key(&(id.clone(), ri as u32, j as u32));
                        let Some(q) = dropped.position(m, p, ri as u32, k, &has_node) else {
                            report.vertices_dropped += 1;
                            continue;
                        };
                        q
                    }
                };
                let d = dist(q, r.points[k]);
                if !d.is_finite() {
                    return Err(BackError::Geometry {
                        element: format!("polygon `{id}` of {bname}"),
                        message: format!(
                            "vertex {k} of ring {ri} would move by {d} m (a coordinate is not finite or out of range)"
                        ),
                    });
                }
                moves += d;
                nmoves += 1;
                maxmove = maxmove.max(d);
                let e = report.max_move_by_building.entry(bname.clone()).or_insert(0.0);
                *e = e.max(d);
                pts.push((q, k));
            }
            let c = collapse_indexed(pts, opts.collapse_tolerance);
            let area_ok =
                c.len() >= 3 && newell_area(&c.iter().map(|x| x.0).collect::<Vec<_>>()) >= opts.area_tolerance;
            rings.push(if area_ok { Some(c) } else { None });
        }
        new_rings.insert(id.clone(), rings);
    }
    report.max_move = maxmove;
    report.mean_move = if nmoves > 0 { moves / nmoves as f64 } else { 0.0 };
    report.vertices_written = nmoves;
    Ok(new_rings)
}

/// Makes near-coplanar planes on one normal exactly coplanar: planes whose signed distances lie
/// within `tolerance` of their neighbour's take their cluster's mean. Returns each plane's cluster.
fn snap_coplanar_planes(m: &mut Popa3d, tolerance: f64) -> Vec<usize> {
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
            if k == v.len() || v[k].0 - v[k - 1].0 > tolerance {
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
    plane_cluster
}

/// Node positions in world coordinates: the plane intersection (spec T 2.3/T 2.4). When the
/// adjustment made a node's planes (nearly) linearly dependent — e.g. two faces meeting at a
/// slight kink became parallel, spec §7.4 GA01/GA02 "can fail after adjustment" — the
/// intersection is a line or plane, and the node takes the point of it nearest to its original
/// vertex (truncated pseudo-inverse anchored at the source position, singular values below
/// 1e-4 dropped).
fn node_positions(m: &Popa3d, inc: &Incidence, polys: &HashMap<String, PolyInfo<'_>>) -> Result<Vec<P3>, BackError> {
    (0..m.nodes.len())
        .map(|i| {
            let p0 = source_vertex(m, polys, i)?;
            let p = anchored_intersection(m, &inc.node_planes(m, NodeId::from(i)), p0).ok_or_else(|| {
                BackError::Geometry { element: format!("node {i}"), message: "position is not finite".into() }
            })?;
            Ok([p[0] + m.origin[0], p[1] + m.origin[1], p[2] + m.origin[2]])
        })
        .collect()
}

/// Node `i`'s original vertex in the template, relative to the model's origin.
fn source_vertex(m: &Popa3d, polys: &HashMap<String, PolyInfo<'_>>, i: usize) -> Result<P3, BackError> {
    m.nodes[i]
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
                Some(VertexSource::CityGml { polygon, ring, index }) => {
                    format!("its source vertex (polygon `{polygon}` ring {ring} vertex {index}) is not in the template")
                }
                Some(VertexSource::Obj { vertex }) => format!("comes from OBJ vertex {vertex}, not from CityGML"),
                None => "has no source vertex".into(),
            },
        })
}

/// The point of the planes' intersection nearest to `p0` (local coordinates): the truncated
/// pseudo-inverse of the planes' normal equations, directions with an eigenvalue below 1e-4 of
/// the largest left at `p0`. `None` when the result is not finite.
fn anchored_intersection(m: &Popa3d, planes: &[PlaneId], p0: P3) -> Option<P3> {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atr = nalgebra::Vector3::<f64>::zeros();
    let x0 = nalgebra::Vector3::new(p0[0], p0[1], p0[2]);
    for q in planes {
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
    p.iter().all(|v| v.is_finite()).then(|| [p[0], p[1], p[2]])
}

/// Provenance → (polygon, ring, index) → node; every source vertex must be in the template.
fn vertex_map(
    m: &Popa3d,
    polys: &HashMap<String, PolyInfo<'_>>,
) -> Result<HashMap<(String, u32, u32), NodeId>, BackError> {
    let mut vmap: HashMap<(String, u32, u32), NodeId> = HashMap::new();
    for (i, n) in m.nodes.iter().enumerate() {
        for s in &n.sources {
            match s {
                VertexSource::CityGml { polygon, ring, index } => {
                    let Some(pi) = polys.get(polygon) else {
                        return Err(BackError::Provenance {
                            element: format!("node {i}"),
                            message: format!("polygon `{polygon}` is not in the template"),
                        });
                    };
                    let Some(r) = ring_of(pi.poly, *ring) else {
                        return Err(BackError::Provenance {
                            element: format!("node {i}"),
                            message: format!("polygon `{polygon}` has no ring {ring} in the template"),
                        });
                    };
                    if *index as usize >= ring_len(r) {
                        return Err(BackError::Provenance { element: format!("node {i}"), message: format!("polygon `{polygon}` ring {ring} has {} vertices in the template, provenance names vertex {index}", ring_len(r)) });
                    }
                    vmap.insert((polygon.clone(), *ring, *index), NodeId::from(i));
                }
                VertexSource::Obj { .. } => {
                    return Err(BackError::Provenance {
                        element: format!("node {i}"),
                        message: "comes from an OBJ sketch, not from CityGML".into(),
                    });
                }
            }
        }
    }
    Ok(vmap)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two unit squares side by side, counter-clockwise, over the nodes
    /// 3 4 5 / 0 1 2 (y = 1 / y = 0).
    fn two_squares() -> (Vec<Vec<(usize, usize)>>, Vec<P3>) {
        let pos: Vec<P3> =
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0]];
        let a = vec![(0, 1), (1, 4), (4, 3), (3, 0)];
        let b = vec![(1, 2), (2, 5), (5, 4), (4, 1)];
        (vec![a, b], pos)
    }

    #[test]
    fn buildings_over_the_move_limit_are_named_worst_first_and_at_most_five() {
        let mut r = BackReport::default();
        for (k, m) in [0.01, 0.2, 0.05, 0.9, 0.3, 0.4, 0.6, 0.06].into_iter().enumerate() {
            r.max_move_by_building.insert(format!("b{k}"), m);
        }
        assert_eq!(r.moved_further_than(1.0), None);
        assert_eq!(r.moved_further_than(0.05).unwrap().to_string(), "6 building(s) would move further than --max-move 0.05 m: b3 (0.900 m), b6 (0.600 m), b5 (0.400 m), b4 (0.300 m), b1 (0.200 m), ...");
        let one = r.moved_further_than(0.7).unwrap();
        assert_eq!(one.buildings, vec![("b3".to_string(), 0.9)]);
        assert_eq!(one.to_string(), "1 building(s) would move further than --max-move 0.7 m: b3 (0.900 m)");
    }

    #[test]
    fn polygons_sharing_an_edge_form_one_component_and_merge_into_their_outline() {
        let (mut es, pos) = two_squares();
        let comps: Vec<Vec<usize>> = edge_components(&es).into_values().collect();
        assert_eq!(comps, vec![vec![0, 1]]);
        let loops = union_boundary(&es, &[0, 1], &pos, &BackOptions::default()).expect("one loop");
        assert_eq!(loops.len(), 1);
        assert!((newell_area(&loops[0]) - 2.0).abs() < 1e-12, "{loops:?}");
        // a third square touching only at a corner is a component of its own
        es.push(vec![(5, 6), (6, 7), (7, 8), (8, 5)]);
        assert_eq!(edge_components(&es).len(), 2);
    }

    #[test]
    fn edges_that_do_not_close_give_no_outline() {
        let (es, pos) = two_squares();
        let open = vec![es[0][..3].to_vec()];
        assert!(union_boundary(&open, &[0], &pos, &BackOptions::default()).is_none());
    }
}
