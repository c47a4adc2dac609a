//! The `[f64; 3]` vector operations of the building-model crates (this one, `normalize`,
//! `adjust`, `heal`), written once.
//!
//! Plain arrays rather than nalgebra: the model stores `[f64; 3]` coordinates and values, and
//! these are the few operations its users need between them. The operation order is fixed (x, y,
//! z summed left to right), so every caller gets the bits its former private copy gave.
//! `adjust::equations` keeps its own generic versions: they run on automatic-differentiation
//! scalars, not on `f64`.

/// Difference `a − b`.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Cross product `a × b`.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Dot product `a · b`.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a` scaled to unit length; the zero vector is returned as it is (no direction to keep).
pub fn unit(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        [a[0] / n, a[1] / n, a[2] / n]
    } else {
        a
    }
}

/// Newell's vector of the closed polygon `pts` (twice its area times its unit normal,
/// right-hand rule), with every point taken relative to `origin`.
///
/// Callers choose the origin: the centroid for an accurate area on large (UTM) coordinates
/// ([`crate::topology::newell`]), `[0.0; 3]` where only a starting direction is needed. Taking
/// `x − 0.0` is exact, so the zero origin gives the bits of the plain textbook sum.
pub fn newell_about(pts: &[[f64; 3]], origin: [f64; 3]) -> [f64; 3] {
    let c = origin;
    let k = pts.len();
    let mut n = [0.0; 3];
    for i in 0..k {
        let a = pts[i];
        let b = pts[(i + 1) % k];
        let (ax, ay, az) = (a[0] - c[0], a[1] - c[1], a[2] - c[2]);
        let (bx, by, bz) = (b[0] - c[0], b[1] - c[1], b[2] - c[2]);
        n[0] += (ay - by) * (az + bz);
        n[1] += (az - bz) * (ax + bx);
        n[2] += (ax - bx) * (ay + by);
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A counter-clockwise 2 × 3 rectangle in a tilted plane far from the origin: Newell's vector
    /// is twice the area along the plane's normal, whatever origin it is taken about.
    #[test]
    fn newell_is_twice_the_area_along_the_normal() {
        let (u, v) = ([0.6, 0.0, 0.8], [0.0, 1.0, 0.0]);
        let at = |s: f64, t: f64| {
            [500_000.0 + s * u[0] + t * v[0], 5_400_000.0 + s * u[1] + t * v[1], 100.0 + s * u[2] + t * v[2]]
        };
        let ring = [at(0.0, 0.0), at(2.0, 0.0), at(2.0, 3.0), at(0.0, 3.0)];
        let normal = [-0.8, 0.0, 0.6]; // u × v
        for origin in [[0.0; 3], ring[0], [500_001.0, 5_400_001.0, 101.0]] {
            let n = newell_about(&ring, origin);
            assert!((dot(n, normal) - 12.0).abs() < 1e-3, "{n:?}");
        }
        let n = crate::topology::newell(&ring);
        assert!((dot(n, normal) - 12.0).abs() < 1e-9 && (dot(unit(n), normal) - 1.0).abs() < 1e-12, "{n:?}");
    }
}
