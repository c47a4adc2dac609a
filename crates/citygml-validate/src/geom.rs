//! Small geometric building blocks: vertex snapping, least-squares planes, projection to a plane.

use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};
use std::collections::HashMap;

pub type V3 = Vector3<f64>;
pub type V2 = Vector2<f64>;

/// Merges vertices closer than the snap tolerance, like val3dity: a new point takes the id of the
/// first earlier point within `tol` (first come, first served, not a transitive closure).
/// Coordinates are stored relative to the first point, which keeps large UTM values well-conditioned.
pub struct Snapper {
    tol: f64,
    origin: Option<V3>,
    pub points: Vec<V3>,
    grid: HashMap<(i64, i64, i64), Vec<u32>>,
}

impl Snapper {
    pub fn new(tol: f64) -> Self {
        Snapper { tol, origin: None, points: Vec::new(), grid: HashMap::new() }
    }

    pub fn origin(&self) -> V3 {
        self.origin.unwrap_or_else(V3::zeros)
    }

    fn cell_size(&self) -> f64 {
        if self.tol > 0.0 {
            self.tol
        } else {
            1e-6
        }
    }

    fn cell(&self, p: &V3) -> (i64, i64, i64) {
        let c = self.cell_size();
        ((p.x / c).floor() as i64, (p.y / c).floor() as i64, (p.z / c).floor() as i64)
    }

    /// Adds a point (absolute coordinates) and returns its vertex id.
    pub fn add(&mut self, p: &[f64; 3]) -> u32 {
        let o = *self.origin.get_or_insert(V3::new(p[0], p[1], p[2]));
        let q = V3::new(p[0], p[1], p[2]) - o;
        let (cx, cy, cz) = self.cell(&q);
        let tol2 = self.tol * self.tol;
        let mut best: Option<u32> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    // wrapping: a cell index of an absurd coordinate (1e308) saturates at i64::MAX
                    if let Some(ids) = self.grid.get(&(cx.wrapping_add(dx), cy.wrapping_add(dy), cz.wrapping_add(dz))) {
                        for &id in ids {
                            let d2 = (self.points[id as usize] - q).norm_squared();
                            let hit = if self.tol > 0.0 { d2 <= tol2 } else { d2 == 0.0 };
                            if hit && best.is_none_or(|b| id < b) {
                                best = Some(id);
                            }
                        }
                    }
                }
            }
        }
        if let Some(b) = best {
            return b;
        }
        let id = self.points.len() as u32;
        self.points.push(q);
        self.grid.entry((cx, cy, cz)).or_default().push(id);
        id
    }
}

/// A plane through `point` with unit `normal`.
#[derive(Debug, Clone, Copy)]
pub struct Plane {
    pub point: V3,
    pub normal: V3,
}

impl Plane {
    pub fn distance(&self, p: &V3) -> f64 {
        (p - self.point).dot(&self.normal)
    }

    /// An orthonormal basis (u, v) of the plane such that (u, v, normal) is right-handed:
    /// a ring that turns counter-clockwise around `normal` has positive area in (u, v).
    pub fn basis(&self) -> (V3, V3) {
        let n = self.normal;
        let a = if n.x.abs() <= n.y.abs() && n.x.abs() <= n.z.abs() {
            V3::x()
        } else if n.y.abs() <= n.z.abs() {
            V3::y()
        } else {
            V3::z()
        };
        let u = n.cross(&a).normalize();
        let v = n.cross(&u);
        (u, v)
    }
}

/// Least-squares plane through points (total least squares): the normal is the eigenvector of the
/// covariance matrix with the smallest eigenvalue. Returns `None` for fewer than 3 points or when
/// all points are (nearly) collinear.
pub fn fit_plane(points: &[V3]) -> Option<Plane> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let c = points.iter().fold(V3::zeros(), |a, p| a + p) / n;
    let mut m = Matrix3::zeros();
    for p in points {
        let d = p - c;
        m += d * d.transpose();
    }
    let eig = SymmetricEigen::new(m);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].partial_cmp(&eig.eigenvalues[b]).unwrap_or(std::cmp::Ordering::Equal));
    // Collinear points: the two smallest eigenvalues both vanish, no unique plane.
    let scale = eig.eigenvalues[order[2]].abs();
    if !(scale > 0.0) || eig.eigenvalues[order[1]].abs() <= scale * 1e-20 {
        return None;
    }
    let normal: V3 = eig.eigenvectors.column(order[0]).into_owned().normalize();
    if !normal.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some(Plane { point: c, normal })
}

/// Newell's normal of a closed ring (not normalised; its length is twice the area).
///
/// The plain sum on absolute coordinates, on the nalgebra vectors validation computes with. The
/// other crate families keep their own variant with a different origin (bits differ):
/// `popa3d_model::vec3::newell_about` (building model: the centroid) and
/// `mesh_export::triangulate::newell_normal` (meshes: the first point).
pub fn newell_normal(ring: &[V3]) -> V3 {
    let mut n = V3::zeros();
    for i in 0..ring.len() {
        let a = ring[i];
        let b = ring[(i + 1) % ring.len()];
        n.x += (a.y - b.y) * (a.z + b.z);
        n.y += (a.z - b.z) * (a.x + b.x);
        n.z += (a.x - b.x) * (a.y + b.y);
    }
    n
}

/// Signed area of a 2D ring (counter-clockwise positive).
pub fn signed_area(ring: &[V2]) -> f64 {
    let mut s = 0.0;
    for i in 0..ring.len() {
        let a = ring[i];
        let b = ring[(i + 1) % ring.len()];
        s += a.x * b.y - b.x * a.y;
    }
    0.5 * s
}

/// Angle between two vectors in degrees (atan2 form, accurate for small angles).
pub fn angle_deg(a: &V3, b: &V3) -> f64 {
    a.cross(b).norm().atan2(a.dot(b)).to_degrees()
}

/// Distance from p to the segment [a, b].
pub fn point_segment_distance(p: &V3, a: &V3, b: &V3) -> f64 {
    let ab = b - a;
    let l2 = ab.norm_squared();
    if l2 == 0.0 {
        return (p - a).norm();
    }
    let t = ((p - a).dot(&ab) / l2).clamp(0.0, 1.0);
    (p - (a + ab * t)).norm()
}
