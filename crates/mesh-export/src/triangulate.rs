//! Triangulation of a planar (or nearly planar) 3D polygon with holes, in its own plane.
//!
//! Steps: (1) the polygon's plane normal is the Newell normal of the exterior ring (robust for
//! non-convex rings and the least-squares-like choice for slightly non-planar ones); (2) all rings
//! are projected onto that plane, centred on the exterior's centroid (keeps spade's exact
//! predicates well inside their range); (3) spade's constrained Delaunay triangulation with every
//! ring edge as a constraint (edges that cross each other, i.e. self-intersecting or overlapping
//! rings, are split at the crossing instead of failing); (4) a triangle is kept when its centroid
//! is inside by the even–odd rule over all rings (inside the exterior, outside every hole).
//!
//! Output vertices are the ORIGINAL 3D points (not their projections), so edges shared with
//! neighbouring polygons stay shared and closed shells stay closed; only vertices created at
//! constraint crossings are lifted back onto the plane. Triangles are oriented like the exterior
//! ring (counter-clockwise seen from the side its Newell normal points to).

use crate::vec3::{cross, dot, norm, sub, P3};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// A triangulated polygon: vertices (3D) and counter-clockwise triangles indexing them.
#[derive(Debug, Clone, PartialEq)]
pub struct PolygonTriangles {
    pub positions: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Unit Newell normal of the exterior ring (the triangles' orientation).
    pub normal: [f64; 3],
    /// A point of the polygon's plane (the exterior ring's vertex mean); with `normal` it
    /// defines the plane the triangulation was made in.
    pub plane_point: [f64; 3],
}

impl PolygonTriangles {
    /// Moves every vertex onto the polygon's plane (orthogonal projection). The triangles' total
    /// area then equals the polygon's Newell (projected) area exactly, at the price of opening
    /// gaps, as wide as the polygon's non-planarity, towards neighbours that share its vertices.
    pub fn flatten(&mut self) {
        let (n, c) = (self.normal, self.plane_point);
        for p in &mut self.positions {
            let d = dot(sub(*p, c), n);
            *p = [p[0] - d * n[0], p[1] - d * n[1], p[2] - d * n[2]];
        }
    }
}

/// Why a polygon could not be triangulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TriangulateError {
    #[error("exterior ring has {0} distinct points, at least 3 needed")]
    TooFewPoints(usize),
    #[error("polygon has no area (its points are collinear or coincide)")]
    Degenerate,
    #[error("a coordinate is NaN or infinite")]
    NonFinite,
    #[error("triangulation failed: {0}")]
    Spade(String),
}

/// Newell's normal vector of a ring (not normalised; its length is twice the projected area).
/// Computed relative to the first point so large (UTM) coordinates do not cancel digits.
/// (The building-model crates centre on the centroid instead, `popa3d_model::vec3::newell_about`;
/// this crate depends on none of them, and changing the origin would change output bits.)
pub fn newell_normal(ring: &[P3]) -> P3 {
    let mut n = [0.0; 3];
    if ring.is_empty() {
        return n;
    }
    let o = ring[0];
    for i in 0..ring.len() {
        let a = sub(ring[i], o);
        let b = sub(ring[(i + 1) % ring.len()], o);
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

/// Drops the closing point (first == last) and consecutive duplicates.
pub fn open_ring(ring: &[P3]) -> Vec<P3> {
    let mut out: Vec<P3> = Vec::with_capacity(ring.len());
    for &p in ring {
        if out.last() != Some(&p) {
            out.push(p);
        }
    }
    while out.len() > 1 && out.first() == out.last() {
        out.pop();
    }
    out
}

/// Triangulates the polygon bounded by `exterior` with `holes`. Rings may be given closed
/// (first point repeated at the end) or open.
pub fn triangulate_polygon(exterior: &[P3], holes: &[&[P3]]) -> Result<PolygonTriangles, TriangulateError> {
    let ext = open_ring(exterior);
    let holes: Vec<Vec<P3>> = holes.iter().map(|h| open_ring(h)).filter(|h| h.len() >= 3).collect();
    if ext.iter().chain(holes.iter().flatten()).any(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(TriangulateError::NonFinite);
    }
    if ext.len() < 3 {
        return Err(TriangulateError::TooFewPoints(ext.len()));
    }
    let nv = newell_normal(&ext);
    let len = norm(nv);
    let scale = ext.iter().map(|p| norm(sub(*p, ext[0]))).fold(0.0, f64::max);
    if len.is_nan() || len <= 1e-12 * scale * scale {
        return Err(TriangulateError::Degenerate);
    }
    let n = [nv[0] / len, nv[1] / len, nv[2] / len];
    // Right-handed basis (u, v, n): counter-clockwise in (u, v) ⇔ normal +n.
    let a = if n[0].abs() <= n[1].abs() && n[0].abs() <= n[2].abs() {
        [1.0, 0.0, 0.0]
    } else if n[1].abs() <= n[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let u = cross(a, n);
    let ul = norm(u);
    let u = [u[0] / ul, u[1] / ul, u[2] / ul];
    let v = cross(n, u);
    let k = ext.len() as f64;
    let c = ext.iter().fold([0.0; 3], |s, p| [s[0] + p[0] / k, s[1] + p[1] / k, s[2] + p[2] / k]);
    let to2 = |p: P3| {
        let d = sub(p, c);
        [dot(d, u), dot(d, v)]
    };
    let rings2: Vec<Vec<[f64; 2]>> =
        std::iter::once(&ext).chain(holes.iter()).map(|r| r.iter().map(|&p| to2(p)).collect()).collect();

    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> = ConstrainedDelaunayTriangulation::new();
    // 3D position per spade vertex index (insertion order; a repeated 2D position maps to the
    // vertex inserted first).
    let mut pos3: Vec<P3> = Vec::new();
    let mut ring_handles = Vec::with_capacity(rings2.len());
    for (r2, r3) in rings2.iter().zip(std::iter::once(&ext).chain(holes.iter())) {
        let mut hs = Vec::with_capacity(r2.len());
        for (q, &p) in r2.iter().zip(r3.iter()) {
            let h = cdt.insert(Point2::new(q[0], q[1])).map_err(|e| TriangulateError::Spade(format!("{e:?}")))?;
            if h.index() == pos3.len() {
                pos3.push(p);
            }
            hs.push(h);
        }
        ring_handles.push(hs);
    }
    for hs in &ring_handles {
        for i in 0..hs.len() {
            let (a, b) = (hs[i], hs[(i + 1) % hs.len()]);
            if a != b {
                cdt.add_constraint_and_split(a, b, |p| p);
            }
        }
    }
    // Vertices created at constraint crossings: lift back onto the plane.
    for vh in cdt.vertices().skip(pos3.len()) {
        let p = vh.position();
        pos3.push([c[0] + p.x * u[0] + p.y * v[0], c[1] + p.x * u[1] + p.y * v[1], c[2] + p.x * u[2] + p.y * v[2]]);
    }

    let mut triangles = Vec::new();
    for f in cdt.inner_faces() {
        let vs = f.vertices();
        let p = vs.map(|h| h.position());
        let centroid = [(p[0].x + p[1].x + p[2].x) / 3.0, (p[0].y + p[1].y + p[2].y) / 3.0];
        if !inside_even_odd(centroid, &rings2) {
            continue;
        }
        let mut t = vs.map(|h| h.fix().index() as u32);
        let orient = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x);
        if orient < 0.0 {
            t.swap(1, 2);
        }
        triangles.push(t);
    }
    if triangles.is_empty() {
        return Err(TriangulateError::Degenerate);
    }
    // Keep only referenced vertices, numbered in order of first use (deterministic).
    let mut remap = vec![u32::MAX; pos3.len()];
    let mut positions = Vec::new();
    for t in &mut triangles {
        for i in t.iter_mut() {
            if remap[*i as usize] == u32::MAX {
                remap[*i as usize] = positions.len() as u32;
                positions.push(pos3[*i as usize]);
            }
            *i = remap[*i as usize];
        }
    }
    Ok(PolygonTriangles { positions, triangles, normal: n, plane_point: c })
}

/// Even–odd point-in-polygon test over all rings (crossing number of a ray towards +x).
fn inside_even_odd(p: [f64; 2], rings: &[Vec<[f64; 2]>]) -> bool {
    let mut inside = false;
    for r in rings {
        let n = r.len();
        let mut j = n - 1;
        for i in 0..n {
            let (a, b) = (r[i], r[j]);
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
                if p[0] < x {
                    inside = !inside;
                }
            }
            j = i;
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vec3::triangle_area;

    fn area(t: &PolygonTriangles) -> f64 {
        t.triangles
            .iter()
            .map(|tr| {
                let [a, b, c] = tr.map(|i| t.positions[i as usize]);
                triangle_area(a, b, c)
            })
            .sum()
    }

    fn oriented_normal_sum(t: &PolygonTriangles) -> P3 {
        t.triangles.iter().fold([0.0; 3], |s, tr| {
            let [a, b, c] = tr.map(|i| t.positions[i as usize]);
            let n = cross(sub(b, a), sub(c, a));
            [s[0] + n[0], s[1] + n[1], s[2] + n[2]]
        })
    }

    #[test]
    fn wall_with_window_hole() {
        // A vertical 10 m × 5 m wall (normal −y) at UTM-like coordinates with a 2 × 1 m window.
        let (x0, y0) = (458_000.0, 5_438_000.0);
        let ext = [[x0, y0, 0.0], [x0 + 10.0, y0, 0.0], [x0 + 10.0, y0, 5.0], [x0, y0, 5.0], [x0, y0, 0.0]];
        let hole = [[x0 + 2.0, y0, 2.0], [x0 + 2.0, y0, 3.0], [x0 + 4.0, y0, 3.0], [x0 + 4.0, y0, 2.0]];
        let t = triangulate_polygon(&ext, &[&hole]).unwrap();
        assert!((area(&t) - 48.0).abs() < 1e-9, "{}", area(&t));
        assert_eq!(t.positions.len(), 8);
        // 8 vertices, 2 boundaries → V − E + F = 0 for an annulus: T = V + 2·(holes) − 2 = 8.
        assert_eq!(t.triangles.len(), 8);
        let s = oriented_normal_sum(&t);
        assert!(s[1] < 0.0 && s[0].abs() < 1e-6 && s[2].abs() < 1e-6, "{s:?}");
        assert!((t.normal[1] + 1.0).abs() < 1e-12);
        // Output vertices are the input vertices, bit for bit.
        assert!(t.positions.iter().all(|p| ext.contains(p) || hole.contains(p)));
    }

    #[test]
    fn non_convex_l_shape_clockwise() {
        // Clockwise L-shape (normal −z), area 3.
        let ring =
            [[0.0, 0.0, 1.0], [0.0, 2.0, 1.0], [1.0, 2.0, 1.0], [1.0, 1.0, 1.0], [2.0, 1.0, 1.0], [2.0, 0.0, 1.0]];
        let t = triangulate_polygon(&ring, &[]).unwrap();
        assert!((area(&t) - 3.0).abs() < 1e-12);
        assert_eq!(t.triangles.len(), 4);
        assert!(oriented_normal_sum(&t)[2] < 0.0);
    }

    #[test]
    fn self_intersecting_bowtie_is_split_not_panicking() {
        let ring = [[0.0, 0.0, 0.0], [2.0, 2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        // Newell normal of a symmetric bow-tie is zero: reported, not a panic.
        assert_eq!(triangulate_polygon(&ring, &[]), Err(TriangulateError::Degenerate));
        let ring = [[0.0, 0.0, 0.0], [4.0, 2.0, 0.0], [4.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let t = triangulate_polygon(&ring, &[]).unwrap();
        assert!(t.triangles.len() >= 2);
        assert!(area(&t) > 0.0);
    }

    #[test]
    fn degenerate_inputs() {
        assert_eq!(
            triangulate_polygon(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]], &[]),
            Err(TriangulateError::TooFewPoints(2))
        );
        let line = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]];
        assert_eq!(triangulate_polygon(&line, &[]), Err(TriangulateError::Degenerate));
        let nan = [[0.0, 0.0, 0.0], [1.0, f64::NAN, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(triangulate_polygon(&nan, &[]), Err(TriangulateError::NonFinite));
    }

    #[test]
    fn slightly_non_planar_roof_keeps_original_vertices() {
        let ring = [[0.0, 0.0, 10.0], [8.0, 0.0, 10.003], [8.0, 6.0, 13.0], [0.0, 6.0, 12.998]];
        let t = triangulate_polygon(&ring, &[]).unwrap();
        assert_eq!(t.triangles.len(), 2);
        assert!(t.positions.iter().all(|p| ring.contains(p)));
        let nn = newell_normal(&ring);
        assert!((area(&t) - 0.5 * norm(nn)).abs() / area(&t) < 1e-5);
    }

    #[test]
    fn flatten_gives_the_newell_area() {
        let ring = [[0.0, 0.0, 10.0], [8.0, 0.0, 10.05], [8.0, 6.0, 13.0], [0.0, 6.0, 13.05]];
        let mut t = triangulate_polygon(&ring, &[]).unwrap();
        let kept = area(&t);
        t.flatten();
        let newell = 0.5 * norm(newell_normal(&ring));
        assert!(kept > newell);
        assert!((area(&t) - newell).abs() < 1e-9 * newell, "{} vs {newell}", area(&t));
        for p in &t.positions {
            assert!(dot(sub(*p, t.plane_point), t.normal).abs() < 1e-9);
        }
    }

    #[test]
    fn hole_touching_nothing_and_many_vertices() {
        // Regular 200-gon with a square hole: area = polygon area − 1.
        let n = 200;
        let ring: Vec<P3> = (0..n)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / n as f64;
                [10.0 * a.cos(), 0.5, 10.0 * a.sin()]
            })
            .collect();
        let hole = [[-0.5, 0.5, -0.5], [0.5, 0.5, -0.5], [0.5, 0.5, 0.5], [-0.5, 0.5, 0.5]];
        let t = triangulate_polygon(&ring, &[&hole]).unwrap();
        let expected = 0.5 * n as f64 * 100.0 * (std::f64::consts::TAU / n as f64).sin() - 1.0;
        assert!((area(&t) - expected).abs() < 1e-9);
        assert_eq!(t.triangles.len(), n + 4);
    }
}
