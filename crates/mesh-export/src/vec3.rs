//! The few `[f64; 3]` vector operations the crate needs, written once.
//!
//! Plain arrays rather than nalgebra: the scene types store `[f64; 3]` positions and the crate has no
//! linear-algebra dependency. The operation order is fixed (x, y, z summed left to right), so every
//! caller gets the same bits it got from its former private copy.

/// A point or vector in world coordinates.
pub type P3 = [f64; 3];

/// `a − b`.
pub fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Dot product `a · b`.
pub fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product `a × b` (right-hand rule).
pub fn cross(a: P3, b: P3) -> P3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Euclidean length.
pub fn norm(a: P3) -> f64 {
    dot(a, a).sqrt()
}

/// Area of the triangle `a b c`: half the length of `(b − a) × (c − a)`.
pub fn triangle_area(a: P3, b: P3, c: P3) -> f64 {
    0.5 * norm(cross(sub(b, a), sub(c, a)))
}
