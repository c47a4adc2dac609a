//! Triangle–triangle contact in 3D: the extreme points of the set where two triangles meet
//! (a segment for transversal triangles, a convex polygon for coplanar ones). The shell
//! self-intersection test (306) decides with it whether two faces meet anywhere other than along
//! the vertices and edges they share.

use crate::geom::V3;

/// Extreme points of `a ∩ b` (empty when the triangles do not meet). `eps` is the distance below
/// which a point counts as lying on a plane or line.
pub fn contact(a: &[V3; 3], b: &[V3; 3], eps: f64) -> Vec<V3> {
    let na = (a[1] - a[0]).cross(&(a[2] - a[0]));
    let nb = (b[1] - b[0]).cross(&(b[2] - b[0]));
    let (la, lb) = (na.norm(), nb.norm());
    if la == 0.0 || lb == 0.0 {
        return Vec::new();
    }
    let (na, nb) = (na / la, nb / lb);
    let db: [f64; 3] = [0, 1, 2].map(|i| na.dot(&(b[i] - a[0])));
    let da: [f64; 3] = [0, 1, 2].map(|i| nb.dot(&(a[i] - b[0])));
    if db.iter().all(|&d| d > eps) || db.iter().all(|&d| d < -eps) {
        return Vec::new();
    }
    if da.iter().all(|&d| d > eps) || da.iter().all(|&d| d < -eps) {
        return Vec::new();
    }
    let coplanar = db.iter().all(|d| d.abs() <= eps) || da.iter().all(|d| d.abs() <= eps);
    if coplanar {
        return coplanar_contact(a, b, &na, eps);
    }
    let dir = na.cross(&nb);
    let ln = dir.norm();
    if ln == 0.0 {
        return coplanar_contact(a, b, &na, eps);
    }
    let dir = dir / ln;
    let (Some(sa), Some(sb)) = (plane_section(a, &da, eps), plane_section(b, &db, eps)) else {
        return Vec::new();
    };
    let t = |p: &V3| p.dot(&dir);
    let (mut a0, mut a1) = sa;
    if t(&a0) > t(&a1) {
        std::mem::swap(&mut a0, &mut a1);
    }
    let (mut b0, mut b1) = sb;
    if t(&b0) > t(&b1) {
        std::mem::swap(&mut b0, &mut b1);
    }
    let lo = if t(&a0) >= t(&b0) { a0 } else { b0 };
    let hi = if t(&a1) <= t(&b1) { a1 } else { b1 };
    if t(&lo) > t(&hi) + eps {
        return Vec::new();
    }
    vec![lo, hi]
}

/// The part of triangle `tri` on the other triangle's plane, given signed distances `d`.
fn plane_section(tri: &[V3; 3], d: &[f64; 3], eps: f64) -> Option<(V3, V3)> {
    let mut pts: Vec<V3> = Vec::with_capacity(3);
    for i in 0..3 {
        if d[i].abs() <= eps {
            pts.push(tri[i]);
        }
        let j = (i + 1) % 3;
        if (d[i] > eps && d[j] < -eps) || (d[i] < -eps && d[j] > eps) {
            let s = d[i] / (d[i] - d[j]);
            pts.push(tri[i] + (tri[j] - tri[i]) * s);
        }
    }
    if pts.is_empty() {
        return None;
    }
    // the two points farthest apart
    let (mut best, mut bi, mut bj) = (-1.0, 0, 0);
    for i in 0..pts.len() {
        for j in i..pts.len() {
            let d = (pts[i] - pts[j]).norm_squared();
            if d > best {
                best = d;
                bi = i;
                bj = j;
            }
        }
    }
    Some((pts[bi], pts[bj]))
}

/// Coplanar triangles: clip `a` by the three half-planes of `b` (boundaries included).
fn coplanar_contact(a: &[V3; 3], b: &[V3; 3], n: &V3, eps: f64) -> Vec<V3> {
    // b counter-clockwise around n
    let mut b = *b;
    if (b[1] - b[0]).cross(&(b[2] - b[0])).dot(n) < 0.0 {
        b.swap(1, 2);
    }
    let mut poly: Vec<V3> = a.to_vec();
    for k in 0..3 {
        let (p, q) = (b[k], b[(k + 1) % 3]);
        let e = q - p;
        let el = e.norm();
        if el == 0.0 {
            return Vec::new();
        }
        // signed distance to the edge line inside the plane (positive = inside)
        let side = |x: &V3| n.cross(&e).dot(&(x - p)) / el;
        let mut out = Vec::with_capacity(poly.len() + 2);
        for i in 0..poly.len() {
            let (c, d) = (poly[i], poly[(i + 1) % poly.len()]);
            let (sc, sd) = (side(&c), side(&d));
            if sc >= -eps {
                out.push(c);
            }
            if (sc > eps && sd < -eps) || (sc < -eps && sd > eps) {
                out.push(c + (d - c) * (sc / (sc - sd)));
            }
        }
        poly = out;
        if poly.is_empty() {
            return poly;
        }
    }
    poly
}

#[cfg(test)]
mod tests {
    use super::*;
    fn v(x: f64, y: f64, z: f64) -> V3 {
        V3::new(x, y, z)
    }
    #[test]
    fn crossing_triangles_meet_in_a_segment() {
        let a = [v(0., 0., 0.), v(2., 0., 0.), v(0., 2., 0.)];
        let b = [v(0.5, 0.5, -1.), v(0.5, 0.5, 1.), v(1.5, -1., 0.)];
        let c = contact(&a, &b, 1e-9);
        assert_eq!(c.len(), 2);
    }
    #[test]
    fn apart_triangles_do_not_meet() {
        let a = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
        let b = [v(0., 0., 1.), v(1., 0., 1.), v(0., 1., 1.)];
        assert!(contact(&a, &b, 1e-9).is_empty());
    }
    #[test]
    fn tip_touching_a_face_is_a_point() {
        let a = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
        let b = [v(0.2, 0.2, 0.), v(1., 1., 1.), v(0., 1., 1.)];
        let c = contact(&a, &b, 1e-9);
        assert!(!c.is_empty());
        assert!(c.iter().all(|p| (p - v(0.2, 0.2, 0.)).norm() < 1e-9));
    }
    #[test]
    fn coplanar_overlap_has_area() {
        let a = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
        let b = [v(0.2, 0.2, 0.), v(1.2, 0.2, 0.), v(0.2, 1.2, 0.)];
        assert!(contact(&a, &b, 1e-9).len() >= 3);
    }
}
