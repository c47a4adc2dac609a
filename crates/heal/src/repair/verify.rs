//! The repairs of one building checked before they are written, like the planarity heal is
//! checked after: the repaired geometry (a copy of the building with the new rings) is
//! validated and measured, and the repairs are dropped if any (feature, code) count grows, the
//! area of any thematic surface type changes by `max_area_change` or more, or an input vertex
//! ends further than `max_move` from the output surface. Opening a closed shell is a new 302,
//! so the first rule covers it. The heal's own verify-after-write then checks the written
//! document again.

use super::ring::{cross, dot, norm, sub, P3};
use super::rings::newell;
use super::work::{Face, WPoly};
use crate::measure::own_polygons;
use citygml_io::{CityObject, GeometryKind, Polygon, Ring};
use std::collections::{BTreeMap, HashMap, HashSet};

type Key = (usize, usize);

fn closed(r: &[P3]) -> Vec<P3> {
    let mut v = r.to_vec();
    if let Some(&f) = r.first() {
        v.push(f);
    }
    v
}

fn with_face(p: &Polygon, face: &Face, id: bool) -> Polygon {
    let mut q = p.clone();
    q.exterior.points = closed(&face[0]);
    q.interiors = face[1..]
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let mut ring: Ring = p.interiors.get(k).cloned().unwrap_or_else(|| Ring { id: None, ..p.exterior.clone() });
            ring.points = closed(r);
            ring
        })
        .collect();
    if !id {
        q.id = None;
    }
    q
}

fn apply_list(ps: &mut Vec<Polygon>, changes: &HashMap<Key, &WPoly>) {
    let mut out = Vec::with_capacity(ps.len());
    for p in ps.drain(..) {
        let Some(w) = changes.get(&(p.span.bytes.start, p.span.bytes.end)) else {
            out.push(p);
            continue;
        };
        if w.removed {
            continue;
        }
        out.push(with_face(&p, &w.face, true));
        for f in &w.extra {
            out.push(with_face(&p, f, false));
        }
    }
    *ps = out;
}

/// Puts the changed polygons into a copy of the building (every use of each, XLink copies
/// included).
pub fn apply(obj: &mut CityObject, changes: &HashMap<Key, &WPoly>) {
    for g in &mut obj.geometries {
        match &mut g.kind {
            GeometryKind::Surfaces(ps) => apply_list(ps, changes),
            GeometryKind::Solid { exterior, interior } => {
                apply_list(&mut exterior.polygons, changes);
                for s in interior {
                    apply_list(&mut s.polygons, changes);
                }
            }
            GeometryKind::Solids(v) => {
                for (e, i) in v {
                    apply_list(&mut e.polygons, changes);
                    for s in i {
                        apply_list(&mut s.polygons, changes);
                    }
                }
            }
        }
    }
    for c in &mut obj.children {
        apply(c, changes);
    }
}

/// (feature, code) → number of findings.
pub type Findings = BTreeMap<(Option<String>, u16), usize>;

pub fn findings(objects: &[&CityObject], opts: &citygml_validate::Options) -> Findings {
    let mut m = Findings::new();
    for f in citygml_validate::validate_objects_only(objects, opts) {
        *m.entry((f.feature, f.code)).or_insert(0) += 1;
    }
    m
}

fn ring_area(r: &[P3]) -> f64 {
    0.5 * norm(&newell(r))
}

/// Area per thematic surface type (`None`: polygons outside any thematic surface), m².
pub fn areas(objects: &[&CityObject]) -> BTreeMap<Option<citygml_io::SurfaceType>, f64> {
    let mut m = BTreeMap::new();
    for p in own_polygons(objects) {
        let a = ring_area(&p.exterior.points) - p.interiors.iter().map(|r| ring_area(&r.points)).sum::<f64>();
        *m.entry(p.semantic).or_insert(0.0) += a;
    }
    m
}

/// Distance from `q` to a polygon (its rings in its Newell plane).
fn polygon_distance(q: &P3, p: &Polygon) -> f64 {
    let rings: Vec<&[P3]> =
        std::iter::once(p.exterior.points.as_slice()).chain(p.interiors.iter().map(|r| r.points.as_slice())).collect();
    let mut edge = f64::INFINITY;
    for r in &rings {
        for w in r.windows(2) {
            edge = edge.min(point_segment(q, &w[0], &w[1]));
        }
    }
    let n = newell(&p.exterior.points);
    let ln = norm(&n);
    if !(ln > 0.0) {
        return edge;
    }
    let n = [n[0] / ln, n[1] / ln, n[2] / ln];
    let o = p.exterior.points[0];
    let h = dot(&sub(q, &o), &n);
    let a = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let u = cross(&n, &a);
    let lu = norm(&u);
    let u = [u[0] / lu, u[1] / lu, u[2] / lu];
    let v = cross(&n, &u);
    let to2 = |x: &P3| (dot(&sub(x, &o), &u), dot(&sub(x, &o), &v));
    let (px, py) = to2(q);
    let mut inside = false;
    for r in &rings {
        for w in r.windows(2) {
            let ((ax, ay), (bx, by)) = (to2(&w[0]), to2(&w[1]));
            if (ay > py) != (by > py) && px < ax + (py - ay) * (bx - ax) / (by - ay) {
                inside = !inside;
            }
        }
    }
    if inside {
        h.abs().min(edge)
    } else {
        edge
    }
}

fn point_segment(p: &P3, a: &P3, b: &P3) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(&ab, &ab);
    if l2 == 0.0 {
        return norm(&sub(p, a));
    }
    let t = (dot(&sub(p, a), &ab) / l2).clamp(0.0, 1.0);
    norm(&sub(p, &[a[0] + ab[0] * t, a[1] + ab[1] * t, a[2] + ab[2] * t]))
}

/// The largest distance from an input vertex that is no longer an output vertex to the output
/// surface (m); 0 when every input vertex is still there.
pub fn max_vertex_distance(before: &[&CityObject], after: &[&CityObject]) -> f64 {
    let bits = |q: &P3| q.map(f64::to_bits);
    let out_polys = own_polygons(after);
    let out: HashSet<[u64; 3]> = out_polys
        .iter()
        .flat_map(|p| std::iter::once(&p.exterior).chain(p.interiors.iter()))
        .flat_map(|r| r.points.iter().map(bits))
        .collect();
    let mut worst: f64 = 0.0;
    for p in own_polygons(before) {
        for r in std::iter::once(&p.exterior).chain(p.interiors.iter()) {
            for q in &r.points {
                if out.contains(&bits(q)) {
                    continue;
                }
                let d = out_polys.iter().map(|o| polygon_distance(q, o)).fold(f64::INFINITY, f64::min);
                worst = worst.max(d);
            }
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_to_segment_distances() {
        assert_eq!(point_segment(&[0.5, 1.0, 0.0], &[0.0, 0.0, 0.0], &[1.0, 0.0, 0.0]), 1.0);
        assert_eq!(point_segment(&[2.0, 0.0, 0.0], &[0.0, 0.0, 0.0], &[1.0, 0.0, 0.0]), 1.0);
    }

    #[test]
    fn ring_area_of_a_2_by_3_rectangle() {
        let r = [[0., 0., 7.], [2., 0., 7.], [2., 3., 7.], [0., 3., 7.], [0., 0., 7.]];
        assert!((ring_area(&r) - 6.0).abs() < 1e-12);
    }
}
