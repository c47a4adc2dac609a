//! Ring level (101–104) and polygon level (201–208) checks, in the polygon's own plane.
//!
//! Order follows val3dity: per ring 103, 101, 102; per polygon 104 for a collapsed triangle, 203
//! against the least-squares plane, then the rings projected to that plane: 104 (simple ring),
//! 208 (inner rings opposite to the outer), then the GEOS-style topology checks 202, 201, 206, 207,
//! 205; finally 204 on the polygon's triangulation. A polygon stops at its first error.

use crate::codes::ErrorCode;
use crate::geom::{angle_deg, fit_plane, newell_normal, signed_area, Plane, Snapper, V2, V3};
use crate::{Issue, Options};
use geo::coordinate_position::CoordPos;
use geo::line_intersection::{line_intersection, LineIntersection};
use geo::{coord, CoordinatePosition, Line, LineString};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// One polygon as plain coordinates: rings as written in the file (closing point included).
#[derive(Debug, Clone)]
pub struct PolygonInput<'a> {
    pub exterior: &'a [[f64; 3]],
    pub interiors: Vec<&'a [[f64; 3]]>,
    /// `gml:OrientableSurface orientation="-"`: the polygon's sense is reversed.
    pub reversed: bool,
}

/// A polygon that passed the ring and polygon checks, ready for shell checks.
#[derive(Debug, Clone)]
pub struct PreparedPolygon {
    /// Vertex ids (into the snapper) of each ring, closing point removed; ring 0 is the exterior.
    pub rings: Vec<Vec<u32>>,
    /// Unit normal following the polygon's orientation (exterior counter-clockwise around it,
    /// `reversed` applied).
    pub normal: V3,
    /// Triangles of the polygon, counter-clockwise around `normal`.
    pub triangles: Vec<[u32; 3]>,
}

fn issue(code: ErrorCode, polygon: usize, ring: Option<usize>, detail: String) -> Issue {
    Issue { code, polygon: Some(polygon), ring, shell: None, detail, value: None }
}

fn with_value(v: f64, mut i: Issue) -> Issue {
    i.value = Some(v);
    i
}

fn fmt_pt(p: &V3, origin: &V3) -> String {
    let q = p + origin;
    format!("({}, {}, {})", round6(q.x), round6(q.y), round6(q.z))
}

fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}

/// Snaps all points of `polys` (in order, like val3dity's parser) and checks every polygon.
/// Returns the issues and, per polygon, its prepared form when it is valid.
pub fn check_polygons(
    polys: &[PolygonInput],
    snap: &mut Snapper,
    opts: &Options,
) -> (Vec<Issue>, Vec<Option<PreparedPolygon>>) {
    let finite = |p: &PolygonInput| {
        std::iter::once(p.exterior)
            .chain(p.interiors.iter().copied())
            .all(|r| r.iter().all(|q| q.iter().all(|c| c.is_finite())))
    };
    let ids: Vec<Option<Vec<Vec<u32>>>> = polys
        .iter()
        .map(|p| {
            finite(p).then(|| {
                std::iter::once(p.exterior)
                    .chain(p.interiors.iter().copied())
                    .map(|r| r.iter().map(|pt| snap.add(pt)).collect())
                    .collect()
            })
        })
        .collect();
    let mut issues = Vec::new();
    let mut out = Vec::with_capacity(polys.len());
    for (i, (poly, rings)) in polys.iter().zip(ids).enumerate() {
        let Some(rings) = rings else {
            issues.push(issue(ErrorCode::InvalidInputFile, i, None, "a coordinate is not a finite number".into()));
            out.push(None);
            continue;
        };
        match check_polygon(i, poly, rings, snap, opts) {
            Ok(p) => out.push(Some(p)),
            Err(is) => {
                issues.push(is);
                out.push(None);
            }
        }
    }
    (issues, out)
}

/// Ring-level checks on snapped ids: 103, 101, 102. Returns the ring without its closing point.
fn check_ring(pi: usize, ri: usize, mut ids: Vec<u32>, snap: &Snapper) -> Result<Vec<u32>, Issue> {
    if ids.len() >= 2 && ids[0] != ids[ids.len() - 1] {
        let a = snap.points[ids[0] as usize];
        let b = snap.points[ids[ids.len() - 1] as usize];
        let mut is = issue(
            ErrorCode::RingNotClosed,
            pi,
            Some(ri),
            format!("first and last points are {:.6} m apart", (a - b).norm()),
        );
        is.value = Some((a - b).norm());
        return Err(is);
    }
    ids.pop();
    if ids.len() < 3 {
        return Err(issue(
            ErrorCode::TooFewPoints,
            pi,
            Some(ri),
            format!("{} distinct points, at least 3 needed", ids.len()),
        ));
    }
    let n = ids.len();
    for k in 0..n {
        if ids[k] == ids[(k + 1) % n] {
            let o = snap.origin();
            return Err(issue(
                ErrorCode::ConsecutivePointsSame,
                pi,
                Some(ri),
                format!(
                    "points {} and {} coincide at {}",
                    k + 1,
                    (k + 1) % n + 1,
                    fmt_pt(&snap.points[ids[k] as usize], &o)
                ),
            ));
        }
    }
    Ok(ids)
}

/// Ring checks, then polygon checks in val3dity's order; the first error stops the polygon.
fn check_polygon(
    pi: usize,
    poly: &PolygonInput,
    rings: Vec<Vec<u32>>,
    snap: &Snapper,
    opts: &Options,
) -> Result<PreparedPolygon, Issue> {
    let mut rs = Vec::with_capacity(rings.len());
    for (ri, r) in rings.into_iter().enumerate() {
        rs.push(check_ring(pi, ri, r, snap)?);
    }
    let pts = |r: &Vec<u32>| -> Vec<V3> { r.iter().map(|&i| snap.points[i as usize]).collect() };
    let ext3 = pts(&rs[0]);
    let all3: Vec<V3> = rs.iter().flat_map(pts).collect();
    let newell = newell_normal(&ext3);
    let extent = extent_from_first(&all3);
    if !(newell.norm() > 1e-12 * extent * extent) {
        return Err(issue(
            ErrorCode::RingSelfIntersection,
            pi,
            Some(0),
            "outer ring is collapsed to a line or a point".into(),
        ));
    }
    let plane = polygon_plane(pi, &rs, &ext3, &all3, newell, snap, opts)?;
    let (u, v) = plane.basis();
    let rings2: Vec<Vec<V2>> = rs.iter().map(|r| project_ring(r, snap, &plane, u, v)).collect();
    check_projected_rings(pi, &rings2, &rs)?;
    let splits = check_ring_topology(pi, &rings2, &rs, extent)?;
    let rings_split = split_rings(&rs, splits);
    let triangles = triangulate(&rings_split, snap, &plane, u, v).ok_or_else(|| {
        issue(
            ErrorCode::RingSelfIntersection,
            pi,
            None,
            "polygon cannot be triangulated in its plane (rings touch or cross)".into(),
        )
    })?;
    check_triangle_normals(pi, &triangles, snap, extent, opts)?;
    let (normal, triangles) = if poly.reversed {
        (-plane.normal, triangles.into_iter().map(|t| [t[0], t[2], t[1]]).collect())
    } else {
        (plane.normal, triangles)
    };
    Ok(PreparedPolygon { rings: rs, normal, triangles })
}

/// The largest distance of a point from the first one: the polygon's size, which scales the
/// collapse and touch tolerances.
fn extent_from_first(all3: &[V3]) -> f64 {
    let mut e: f64 = 0.0;
    for p in all3 {
        e = e.max((p - all3[0]).norm());
    }
    e
}

/// The polygon's plane, its normal turned to agree with the exterior's Newell normal: a lone
/// triangle lies in its own plane; otherwise the least-squares plane, which must pass 203.
fn polygon_plane(
    pi: usize,
    rs: &[Vec<u32>],
    ext3: &[V3],
    all3: &[V3],
    newell: V3,
    snap: &Snapper,
    opts: &Options,
) -> Result<Plane, Issue> {
    if rs.len() == 1 && rs[0].len() == 3 {
        return Ok(Plane { point: ext3[0], normal: newell.normalize() });
    }
    let Some(mut pl) = fit_plane(all3) else {
        return Err(issue(ErrorCode::RingSelfIntersection, pi, Some(0), "polygon is collapsed to a line".into()));
    };
    check_planarity(pi, &pl, all3, snap, opts)?;
    if pl.normal.dot(&newell) < 0.0 {
        pl.normal = -pl.normal;
    }
    Ok(pl)
}

/// 203: the farthest point from the fitted plane must lie within the planarity tolerance.
fn check_planarity(pi: usize, pl: &Plane, all3: &[V3], snap: &Snapper, opts: &Options) -> Result<(), Issue> {
    // spec: val3dity checks every point against the least-squares plane (203).
    let (mut dmax, mut at) = (0.0f64, 0usize);
    for (k, p) in all3.iter().enumerate() {
        let d = pl.distance(p).abs();
        if d > dmax {
            dmax = d;
            at = k;
        }
    }
    if dmax > opts.planarity_tol {
        return Err(with_value(
            dmax,
            issue(
                ErrorCode::NonPlanarPolygonDistancePlane,
                pi,
                None,
                format!(
                    "distance to fitted plane {:.6} m at {} (tolerance {} m)",
                    dmax,
                    fmt_pt(&all3[at], &snap.origin()),
                    opts.planarity_tol
                ),
            ),
        ));
    }
    Ok(())
}

/// A ring's points in the plane's 2D basis (`u`, `v`) around the plane's point.
fn project_ring(r: &[u32], snap: &Snapper, plane: &Plane, u: V3, v: V3) -> Vec<V2> {
    r.iter()
        .map(|&i| {
            let d = snap.points[i as usize] - plane.point;
            V2::new(d.dot(&u), d.dot(&v))
        })
        .collect()
}

/// 104 on each projected ring (simple), then 208: the exterior runs counter-clockwise around the
/// oriented normal; inner rings must not.
fn check_projected_rings(pi: usize, rings2: &[Vec<V2>], rs: &[Vec<u32>]) -> Result<(), Issue> {
    for (ri, (r2, ids)) in rings2.iter().zip(rs).enumerate() {
        if let Some(why) = ring_not_simple(r2, ids) {
            return Err(issue(ErrorCode::RingSelfIntersection, pi, Some(ri), why));
        }
    }
    for ri in 1..rings2.len() {
        if signed_area(&rings2[ri]) > 0.0 {
            return Err(issue(
                ErrorCode::OrientationRingsSame,
                pi,
                Some(ri),
                "inner ring has the same orientation as the outer ring".into(),
            ));
        }
    }
    Ok(())
}

/// The rings with every touch point inserted into the segment it touches, so the triangulation
/// sees the rings meet at shared vertices.
fn split_rings(rs: &[Vec<u32>], mut splits: Vec<Split>) -> Vec<Vec<u32>> {
    let mut rings_split = rs.to_vec();
    // later segments first, and within a segment the farthest split first, so indices stay valid
    splits.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)).then(b.3.total_cmp(&a.3)));
    for (ri, seg, vid, _t) in splits {
        insert_split(&mut rings_split[ri], seg, vid);
    }
    rings_split
}

/// 204: the normals of the triangles must not deviate from each other by more than the tolerance.
fn check_triangle_normals(
    pi: usize,
    triangles: &[[u32; 3]],
    snap: &Snapper,
    extent: f64,
    opts: &Options,
) -> Result<(), Issue> {
    let normals: Vec<(f64, V3)> = triangles
        .iter()
        .filter_map(|t| {
            let a = snap.points[t[0] as usize];
            let n = (snap.points[t[1] as usize] - a).cross(&(snap.points[t[2] as usize] - a));
            let area = n.norm();
            (area > 1e-12 * extent * extent).then(|| (area, n / area))
        })
        .collect();
    if normals.len() > 1 {
        let worst = worst_normal_deviation(&normals);
        if worst > opts.normals_tol_deg {
            return Err(with_value(
                worst,
                issue(
                    ErrorCode::NonPlanarPolygonNormalsDeviation,
                    pi,
                    None,
                    format!("normals of its triangles deviate by {:.4}° (tolerance {}°)", worst, opts.normals_tol_deg),
                ),
            ));
        }
    }
    Ok(())
}

/// Largest angle in degrees between (area, unit normal) pairs: every pair up to 256 normals, above
/// that each against the largest triangle's normal, so big polygons do not cost n².
fn worst_normal_deviation(normals: &[(f64, V3)]) -> f64 {
    let mut worst = 0.0f64;
    if normals.len() <= 256 {
        for i in 0..normals.len() {
            for j in i + 1..normals.len() {
                worst = worst.max(angle_deg(&normals[i].1, &normals[j].1));
            }
        }
    } else {
        let r = normals.iter().max_by(|a, b| a.0.total_cmp(&b.0)).unwrap().1;
        for n in normals {
            worst = worst.max(angle_deg(&r, &n.1));
        }
    }
    worst
}

fn gline(a: &V2, b: &V2) -> Line<f64> {
    Line::new(coord! {x: a.x, y: a.y}, coord! {x: b.x, y: b.y})
}

fn seg_bbox_overlap(a: &V2, b: &V2, c: &V2, d: &V2) -> bool {
    a.x.min(b.x) <= c.x.max(d.x)
        && c.x.min(d.x) <= a.x.max(b.x)
        && a.y.min(b.y) <= c.y.max(d.y)
        && c.y.min(d.y) <= a.y.max(b.y)
}

/// Pairs (i, j) of segments of rings `a` and `b` whose bounding boxes overlap, found by a sweep
/// along x (sorted by the segments' smallest x), so long rings do not cost n². With `same`, `a`
/// and `b` are one ring and each pair is listed once with i < j.
fn overlapping_segments(a: &[V2], b: &[V2], same: bool) -> Vec<(usize, usize)> {
    let seg = |r: &[V2], k: usize| (r[k], r[(k + 1) % r.len()]);
    // (min x, max x, ring 0/1, index)
    let mut ev: Vec<(f64, f64, u8, usize)> = Vec::with_capacity(a.len() + b.len());
    for k in 0..a.len() {
        let (p, q) = seg(a, k);
        ev.push((p.x.min(q.x), p.x.max(q.x), 0, k));
    }
    if !same {
        for k in 0..b.len() {
            let (p, q) = seg(b, k);
            ev.push((p.x.min(q.x), p.x.max(q.x), 1, k));
        }
    }
    ev.sort_by(|u, v| u.0.total_cmp(&v.0).then(u.2.cmp(&v.2)).then(u.3.cmp(&v.3)));
    let mut out = Vec::new();
    for x in 0..ev.len() {
        let (_, hi, ra, ka) = ev[x];
        for &(lo2, _, rb, kb) in &ev[x + 1..] {
            if lo2 > hi {
                break;
            }
            if !same && ra == rb {
                continue;
            }
            let (i, j) = if same || ra == 0 { (ka, kb) } else { (kb, ka) };
            let (p, q) = seg(a, i);
            let (s, t) = seg(if same { a } else { b }, j);
            if seg_bbox_overlap(&p, &q, &s, &t) {
                out.push(if same { (i.min(j), i.max(j)) } else { (i, j) });
            }
        }
    }
    out.sort_unstable();
    out
}

/// Why a projected ring is not simple (crossing, touching itself, spike, zero area), if it is not.
fn ring_not_simple(r: &[V2], ids: &[u32]) -> Option<String> {
    let n = r.len();
    let area = signed_area(r).abs();
    let per: f64 = (0..n).map(|i| (r[(i + 1) % n] - r[i]).norm()).sum();
    if !(area > 1e-12 * per * per) {
        return Some("ring is collapsed to a line".into());
    }
    let mut seen = std::collections::HashMap::new();
    for (k, id) in ids.iter().enumerate() {
        if let Some(j) = seen.insert(*id, k) {
            return Some(format!("ring passes twice through the same point (points {} and {})", j + 1, k + 1));
        }
    }
    for (i, j) in overlapping_segments(r, r, true) {
        let (a, b) = (r[i], r[(i + 1) % n]);
        {
            let (c, d) = (r[j], r[(j + 1) % n]);
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            match line_intersection(gline(&a, &b), gline(&c, &d)) {
                None => {}
                Some(LineIntersection::SinglePoint { .. }) if adjacent => {}
                Some(LineIntersection::Collinear { intersection })
                    if adjacent && intersection.start == intersection.end => {}
                Some(_) => {
                    return Some(format!("segments {} and {} of the ring intersect", i + 1, j + 1));
                }
            }
        }
    }
    None
}

/// Where a vertex of one ring touches the inside of a segment of another ring:
/// (ring, segment, vertex id, parameter along the segment).
type Split = (usize, usize, u32, f64);

/// The distinct points where two rings touch, by ring pair (a < b).
type Touches = Vec<((usize, usize), Vec<V2>)>;

/// Topology between the rings of one polygon (after each ring is simple): 202, 201, 206, 207, 205.
/// Returns the points where a vertex of one ring touches the inside of a segment of another
/// (ring, segment, vertex id, parameter), so the triangulation can split that segment.
fn check_ring_topology(pi: usize, rings: &[Vec<V2>], ids: &[Vec<u32>], extent: f64) -> Result<Vec<Split>, Issue> {
    let nr = rings.len();
    if nr == 1 {
        return Ok(Vec::new());
    }
    check_duplicated_rings(pi, ids)?;
    let eps = 1e-9 * extent.max(1e-9);
    let mut splits = Vec::new();
    let touches = ring_touches(pi, rings, ids, eps, &mut splits)?;
    check_inner_ring_positions(pi, rings)?;
    check_interior_connected(pi, nr, &touches)?;
    Ok(splits)
}

/// 202: two rings with the same set of vertices are the same ring written twice.
fn check_duplicated_rings(pi: usize, ids: &[Vec<u32>]) -> Result<(), Issue> {
    let nr = ids.len();
    for a in 0..nr {
        for b in a + 1..nr {
            let mut sa = ids[a].clone();
            let mut sb = ids[b].clone();
            sa.sort_unstable();
            sb.sort_unstable();
            if sa == sb {
                return Err(issue(
                    ErrorCode::DuplicatedRings,
                    pi,
                    Some(b),
                    format!("rings {} and {} are identical", a + 1, b + 1),
                ));
            }
        }
    }
    Ok(())
}

/// 201 for every ring pair, in pair order: rings may touch in points but not cross or share a
/// segment. Collects the touch points per pair (for 205) and the segment splits (into `splits`).
fn ring_touches(
    pi: usize,
    rings: &[Vec<V2>],
    ids: &[Vec<u32>],
    eps: f64,
    splits: &mut Vec<Split>,
) -> Result<Touches, Issue> {
    let nr = rings.len();
    let mut touches: Touches = Vec::new();
    for a in 0..nr {
        for b in a + 1..nr {
            let pts = ring_pair_contacts(pi, (a, b), rings, ids, eps, splits)?;
            let distinct = distinct_points(pts, eps);
            if !distinct.is_empty() {
                touches.push(((a, b), distinct));
            }
        }
    }
    Ok(touches)
}

/// The points where rings `a` and `b` meet (with repeats), or 201 when they cross or share a
/// segment; a meeting inside a segment is recorded in `splits`.
fn ring_pair_contacts(
    pi: usize,
    (a, b): (usize, usize),
    rings: &[Vec<V2>],
    ids: &[Vec<u32>],
    eps: f64,
    splits: &mut Vec<Split>,
) -> Result<Vec<V2>, Issue> {
    let (ra, rb) = (&rings[a], &rings[b]);
    let mut pts: Vec<V2> = Vec::new();
    for (i, j) in overlapping_segments(ra, rb, false) {
        let (p, q) = (ra[i], ra[(i + 1) % ra.len()]);
        let (s, t) = (rb[j], rb[(j + 1) % rb.len()]);
        match line_intersection(gline(&p, &q), gline(&s, &t)) {
            None => {}
            Some(LineIntersection::SinglePoint { is_proper: true, .. }) => {
                return Err(issue(
                    ErrorCode::IntersectionRings,
                    pi,
                    Some(b),
                    format!("ring {} crosses ring {}", b + 1, a + 1),
                ));
            }
            Some(LineIntersection::Collinear { intersection }) => {
                let (x0, x1) = (intersection.start, intersection.end);
                if (x0.x - x1.x).hypot(x0.y - x1.y) > eps {
                    return Err(issue(
                        ErrorCode::IntersectionRings,
                        pi,
                        Some(b),
                        format!("rings {} and {} share a segment", a + 1, b + 1),
                    ));
                }
                pts.push(V2::new(x0.x, x0.y));
            }
            Some(LineIntersection::SinglePoint { intersection: x, .. }) => {
                let x = V2::new(x.x, x.y);
                pts.push(x);
                splits.extend(vertex_on_segment(x, (a, i, p, q), (b, j, s, t), ids, eps));
            }
        }
    }
    Ok(pts)
}

/// A vertex of one ring inside a segment of the other: that segment must be split at it.
/// `sa` and `sb` are (ring, segment index, start, end) of the two segments meeting at `x`.
fn vertex_on_segment(
    x: V2,
    (a, i, p, q): (usize, usize, V2, V2),
    (b, j, s, t): (usize, usize, V2, V2),
    ids: &[Vec<u32>],
    eps: f64,
) -> Option<Split> {
    let near = |u: &V2, w: &V2| (u - w).norm() <= eps;
    if !near(&x, &p) && !near(&x, &q) {
        if near(&x, &s) {
            return Some((a, i, ids[b][j], (x - p).norm() / (q - p).norm()));
        } else if near(&x, &t) {
            return Some((a, i, ids[b][(j + 1) % ids[b].len()], (x - p).norm() / (q - p).norm()));
        }
    } else if !near(&x, &s) && !near(&x, &t) {
        let vid = if near(&x, &p) { ids[a][i] } else { ids[a][(i + 1) % ids[a].len()] };
        return Some((b, j, vid, (x - s).norm() / (t - s).norm()));
    }
    None
}

/// `pts` without repeats closer than `eps`, in first-seen order.
fn distinct_points(pts: Vec<V2>, eps: f64) -> Vec<V2> {
    let mut distinct: Vec<V2> = Vec::new();
    for p in pts {
        if !distinct.iter().any(|q| (q - p).norm() <= eps) {
            distinct.push(p);
        }
    }
    distinct
}

/// 206: every inner ring inside the outer ring; 207: no inner ring inside another.
fn check_inner_ring_positions(pi: usize, rings: &[Vec<V2>]) -> Result<(), Issue> {
    let nr = rings.len();
    let polys: Vec<geo::Polygon<f64>> = rings
        .iter()
        .map(|r| {
            let mut cs: Vec<geo::Coord<f64>> = r.iter().map(|p| coord! {x: p.x, y: p.y}).collect();
            cs.push(cs[0]);
            geo::Polygon::new(LineString::new(cs), vec![])
        })
        .collect();
    let position = |inner: usize, outer: usize| ring_position(&rings[inner], &polys[outer]);
    for b in 1..nr {
        if position(b, 0) == CoordPos::Outside {
            return Err(issue(
                ErrorCode::InnerRingOutside,
                pi,
                Some(b),
                format!("inner ring {} lies outside the outer ring", b + 1),
            ));
        }
    }
    for b in 1..nr {
        for c in 1..nr {
            if b != c && position(b, c) == CoordPos::Inside {
                return Err(issue(
                    ErrorCode::InnerRingsNested,
                    pi,
                    Some(b),
                    format!("inner ring {} lies inside inner ring {}", b + 1, c + 1),
                ));
            }
        }
    }
    Ok(())
}

/// Position of ring `r` relative to `outer`: that of its first vertex (or segment midpoint) not
/// on the boundary of `outer`, since rings may touch.
fn ring_position(r: &[V2], outer: &geo::Polygon<f64>) -> CoordPos {
    let cands = r.iter().copied().chain((0..r.len()).map(|k| (r[k] + r[(k + 1) % r.len()]) * 0.5));
    for c in cands {
        let pos = outer.coordinate_position(&coord! {x: c.x, y: c.y});
        if pos != CoordPos::OnBoundary {
            return pos;
        }
    }
    CoordPos::OnBoundary
}

/// 205: two rings touching twice, or rings touching in a cycle, cut the interior apart.
/// Rings are joined in a union-find as their touches are read; a touch within one set closes a cycle.
fn check_interior_connected(pi: usize, nr: usize, touches: &Touches) -> Result<(), Issue> {
    let mut parent: Vec<usize> = (0..nr).collect();
    for ((a, b), pts) in touches {
        if pts.len() >= 2 {
            return Err(issue(
                ErrorCode::InteriorDisconnected,
                pi,
                Some(*b),
                format!("rings {} and {} touch at {} points", a + 1, b + 1, pts.len()),
            ));
        }
        let (ra, rb) = (union_find_root(&mut parent, *a), union_find_root(&mut parent, *b));
        if ra == rb {
            return Err(issue(
                ErrorCode::InteriorDisconnected,
                pi,
                Some(*b),
                "rings touch each other in a cycle, the interior is cut into pieces".into(),
            ));
        }
        parent[ra] = rb;
    }
    Ok(())
}

/// Root of `x`'s set in the union-find `p`, halving the path on the way.
fn union_find_root(p: &mut [usize], x: usize) -> usize {
    let mut x = x;
    while p[x] != x {
        p[x] = p[p[x]];
        x = p[x];
    }
    x
}

/// Inserts vertex `vid` into segment `seg` of a ring (after the segment's start), keeping several
/// splits of one segment ordered by their parameter.
fn insert_split(ring: &mut Vec<u32>, seg: usize, vid: u32) {
    if ring.contains(&vid) {
        return;
    }
    let pos = (seg + 1).min(ring.len());
    ring.insert(pos, vid);
}

/// Constrained Delaunay triangulation of the polygon in its plane; triangles inside the polygon
/// (odd nesting level) are returned counter-clockwise in (u, v), i.e. around the plane normal.
fn triangulate(rings: &[Vec<u32>], snap: &Snapper, plane: &Plane, u: V3, v: V3) -> Option<Vec<[u32; 3]>> {
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> = ConstrainedDelaunayTriangulation::new();
    let mut id_of: Vec<u32> = Vec::new();
    let mut handles: Vec<Vec<spade::handles::FixedVertexHandle>> = Vec::new();
    for r in rings {
        let mut hs = Vec::with_capacity(r.len());
        for &id in r {
            let d = snap.points[id as usize] - plane.point;
            let h = cdt.insert(Point2::new(d.dot(&u), d.dot(&v))).ok()?;
            if h.index() >= id_of.len() {
                id_of.resize(h.index() + 1, u32::MAX);
            }
            if id_of[h.index()] == u32::MAX {
                id_of[h.index()] = id;
            }
            hs.push(h);
        }
        handles.push(hs);
    }
    for hs in &handles {
        for k in 0..hs.len() {
            let (a, b) = (hs[k], hs[(k + 1) % hs.len()]);
            if a != b {
                if !cdt.can_add_constraint(a, b) {
                    return None;
                }
                cdt.add_constraint(a, b);
            }
        }
    }
    // nesting level by flood fill from the outside; crossing a constraint edge changes the parity
    let nf = cdt.num_all_faces();
    let mut level = vec![-1i32; nf];
    let mut fixed = vec![None; nf];
    for f in cdt.inner_faces() {
        fixed[f.fix().index()] = Some(f.fix());
    }
    let mut stack: Vec<(usize, i32)> = Vec::new();
    for f in cdt.inner_faces() {
        for e in f.adjacent_edges() {
            if e.rev().face().is_outer() {
                let l = if e.is_constraint_edge() { 1 } else { 0 };
                stack.push((f.fix().index(), l));
            }
        }
    }
    while let Some((fi, l)) = stack.pop() {
        if level[fi] >= 0 {
            continue;
        }
        level[fi] = l;
        let Some(fh) = fixed[fi] else { continue };
        let f = cdt.face(fh);
        for e in f.adjacent_edges() {
            let nb = e.rev().face();
            if let Some(inner) = nb.as_inner() {
                let ni = inner.fix().index();
                if level[ni] < 0 {
                    stack.push((ni, l + if e.is_constraint_edge() { 1 } else { 0 }));
                }
            }
        }
    }
    let mut tris = Vec::new();
    for f in cdt.inner_faces() {
        if level[f.fix().index()] % 2 == 1 {
            let vs = f.vertices();
            let t = [id_of[vs[0].fix().index()], id_of[vs[1].fix().index()], id_of[vs[2].fix().index()]];
            if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                tris.push(t);
            }
        }
    }
    if tris.is_empty() {
        return None;
    }
    Some(tris)
}
