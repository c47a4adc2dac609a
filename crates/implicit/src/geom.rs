//! Small 3-vector helpers (plain arrays keep the mesh and model files simple).
//!
//! The implicit-model crate's own copy of what `popa3d_model::vec3` and `mesh_export::vec3` hold
//! for their families: this crate depends on neither (only on `input-limits`), and pulling in
//! either for five one-line functions would tie the geology model to the building or export code.

pub type V3 = [f64; 3];

#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
#[inline]
pub fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
#[inline]
pub fn mid(a: V3, b: V3) -> V3 {
    [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5, (a[2] + b[2]) * 0.5]
}
pub fn normalize(a: V3) -> Option<V3> {
    let n = norm(a);
    if n > 0.0 && n.is_finite() {
        Some(scale(a, 1.0 / n))
    } else {
        None
    }
}

/// Six times the signed volume of tetrahedron (a, b, c, d).
#[inline]
pub fn vol6(a: V3, b: V3, c: V3, d: V3) -> f64 {
    dot(sub(b, a), cross(sub(c, a), sub(d, a)))
}

/// Barycentric coordinates of `p` in tetrahedron `t` (None when degenerate).
pub fn barycentric(t: &[V3; 4], p: V3) -> Option<[f64; 4]> {
    let v = vol6(t[0], t[1], t[2], t[3]);
    if v.abs() < 1e-300 {
        return None;
    }
    let l0 = vol6(p, t[1], t[2], t[3]) / v;
    let l1 = vol6(t[0], p, t[2], t[3]) / v;
    let l2 = vol6(t[0], t[1], p, t[3]) / v;
    let l3 = 1.0 - l0 - l1 - l2;
    Some([l0, l1, l2, l3])
}

/// Gradients of the four barycentric (P1 hat) functions of a tetrahedron.
pub fn hat_gradients(t: &[V3; 4]) -> Option<[V3; 4]> {
    let e1 = sub(t[1], t[0]);
    let e2 = sub(t[2], t[0]);
    let e3 = sub(t[3], t[0]);
    let det = dot(e1, cross(e2, e3));
    if det.abs() < 1e-300 {
        return None;
    }
    // Rows of the inverse of [e1 e2 e3] are the gradients of λ1..λ3.
    let g1 = scale(cross(e2, e3), 1.0 / det);
    let g2 = scale(cross(e3, e1), 1.0 / det);
    let g3 = scale(cross(e1, e2), 1.0 / det);
    let g0 = scale(add(add(g1, g2), g3), -1.0);
    Some([g0, g1, g2, g3])
}

/// Segment–triangle intersection (Möller–Trumbore restricted to the segment's parameter range).
pub fn segment_hits_triangle(p: V3, q: V3, a: V3, b: V3, c: V3) -> bool {
    let d = sub(q, p);
    let e1 = sub(b, a);
    let e2 = sub(c, a);
    let h = cross(d, e2);
    let det = dot(e1, h);
    if det.abs() < 1e-14 * norm(d).max(1e-300) * norm(e1) * norm(e2) {
        return false;
    }
    let inv = 1.0 / det;
    let s = sub(p, a);
    let u = dot(s, h) * inv;
    if !(-1e-12..=1.0 + 1e-12).contains(&u) {
        return false;
    }
    let qv = cross(s, e1);
    let v = dot(d, qv) * inv;
    if v < -1e-12 || u + v > 1.0 + 1e-12 {
        return false;
    }
    let t = dot(e2, qv) * inv;
    (0.0..=1.0).contains(&t)
}
