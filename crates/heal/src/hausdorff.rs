//! The move guard as a Hausdorff bound: the largest distance from any input vertex to the output
//! surface and from any output vertex to the input surface (point-to-polygon distance in 3D).
//! Measuring only the vertices that remain misses the corner a merge drops: the outline then cuts
//! the corner and the dropped vertex ends 7.5–23 cm from the surface while the largest remaining
//! move is below 1 cm (docs/decisions.md#move-guard-as-a-hausdorff-bound).
//!
//! # Examples
//! ```
//! use heal::hausdorff::{hausdorff, Surface};
//! // a unit square, and the same square with its corner (1, 1) cut off by 0.1 m along both edges
//! let square = Surface::new(vec![vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]]]);
//! let cut = Surface::new(vec![vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.9, 0.0], [0.9, 1.0, 0.0], [0.0, 1.0, 0.0]]]]);
//! let d = hausdorff(&square, &cut);
//! assert!((d - 0.1 / 2f64.sqrt()).abs() < 1e-12);
//! ```

type P3 = [f64; 3];

/// One polygon: its rings (exterior first, no closing repeat), the plane of its Newell normal
/// through its centroid, and its bounding box.
struct Poly {
    rings: Vec<Vec<P3>>,
    n: P3,
    d: f64,
    lo: P3,
    hi: P3,
}

/// A set of polygons (a building's surface) prepared for point distances.
pub struct Surface {
    polys: Vec<Poly>,
}

fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Surface {
    /// Polygons as rings of points (the closing repeat, if any, is ignored).
    pub fn new(polygons: Vec<Vec<Vec<P3>>>) -> Surface {
        let polys = polygons
            .into_iter()
            .filter_map(|mut rings| {
                for r in &mut rings {
                    if r.len() > 1 && r.first() == r.last() {
                        r.pop();
                    }
                }
                let ext = rings.first()?;
                if ext.is_empty() {
                    return None;
                }
                let nw = popa3d_model::topology::newell(ext);
                let len = dot(nw, nw).sqrt();
                let n = if len > 0.0 { [nw[0] / len, nw[1] / len, nw[2] / len] } else { [0.0; 3] };
                let c = ext.iter().fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]);
                let c = c.map(|v| v / ext.len() as f64);
                let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for p in rings.iter().flatten() {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                Some(Poly { d: dot(n, c), rings, n, lo, hi })
            })
            .collect();
        Surface { polys }
    }

    /// Every vertex of the surface.
    pub fn vertices(&self) -> impl Iterator<Item = &P3> {
        self.polys.iter().flat_map(|p| p.rings.iter().flatten())
    }

    /// The distance from `q` to the surface, or a value ≤ `enough` as soon as one polygon is
    /// that close (the caller needs no more).
    pub fn distance(&self, q: P3, enough: f64) -> f64 {
        let mut best = f64::INFINITY;
        for p in &self.polys {
            if box_distance(q, p.lo, p.hi) >= best {
                continue;
            }
            best = best.min(polygon_distance(q, p));
            if best <= enough {
                break;
            }
        }
        best
    }
}

/// The Hausdorff distance between two surfaces measured at their vertices: the largest distance
/// from a vertex of either to the other surface (m). 0 when both are empty, infinite when only
/// one is.
pub fn hausdorff(a: &Surface, b: &Surface) -> f64 {
    let mut worst: f64 = 0.0;
    for (from, to) in [(a, b), (b, a)] {
        for &q in from.vertices() {
            // a vertex closer than the worst so far cannot raise it: stop looking for it early
            worst = worst.max(to.distance(q, worst));
        }
    }
    worst
}

fn box_distance(q: P3, lo: P3, hi: P3) -> f64 {
    let mut s = 0.0;
    for k in 0..3 {
        let e = if q[k] < lo[k] {
            lo[k] - q[k]
        } else if q[k] > hi[k] {
            q[k] - hi[k]
        } else {
            0.0
        };
        s += e * e;
    }
    s.sqrt()
}

fn segment_distance(q: P3, a: P3, b: P3) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 { (dot(sub(q, a), ab) / l2).clamp(0.0, 1.0) } else { 0.0 };
    let c = [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]];
    let v = sub(q, c);
    dot(v, v).sqrt()
}

/// Distance from `q` to the polygon: to its plane where the projection of `q` falls inside (even–odd
/// over all rings, in the plane's dominant projection), else to its nearest boundary edge.
fn polygon_distance(q: P3, p: &Poly) -> f64 {
    let h = dot(p.n, q) - p.d;
    let proj = [q[0] - h * p.n[0], q[1] - h * p.n[1], q[2] - h * p.n[2]];
    let k = (0..3).max_by(|&i, &j| p.n[i].abs().total_cmp(&p.n[j].abs())).unwrap_or(2);
    let (u, v) = ((k + 1) % 3, (k + 2) % 3);
    let mut inside = false;
    let mut edge = f64::INFINITY;
    for r in &p.rings {
        for i in 0..r.len() {
            let (a, b) = (r[i], r[(i + 1) % r.len()]);
            if (a[v] > proj[v]) != (b[v] > proj[v]) {
                let x = a[u] + (proj[v] - a[v]) * (b[u] - a[u]) / (b[v] - a[v]);
                if proj[u] < x {
                    inside = !inside;
                }
            }
            edge = edge.min(segment_distance(q, a, b));
        }
    }
    if inside && p.n != [0.0; 3] {
        h.abs().min(edge)
    } else {
        edge
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f64) -> Vec<Vec<P3>> {
        vec![vec![[0.0, 0.0, z], [2.0, 0.0, z], [2.0, 2.0, z], [0.0, 2.0, z]]]
    }

    #[test]
    fn a_point_above_the_inside_is_at_its_height_and_beside_at_the_edge() {
        let s = Surface::new(vec![square(0.0)]);
        assert!((s.distance([1.0, 1.0, 0.3], 0.0) - 0.3).abs() < 1e-12);
        assert!((s.distance([3.0, 1.0, 0.0], 0.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_point_over_a_hole_is_at_the_hole_edge() {
        let mut p = square(0.0);
        p.push(vec![[0.5, 0.5, 0.0], [0.5, 1.5, 0.0], [1.5, 1.5, 0.0], [1.5, 0.5, 0.0]]);
        let s = Surface::new(vec![p]);
        assert!((s.distance([1.0, 1.0, 0.0], 0.0) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_lifted_copy_is_as_far_as_the_lift_both_ways() {
        let (a, b) = (Surface::new(vec![square(0.0)]), Surface::new(vec![square(0.04)]));
        assert!((hausdorff(&a, &b) - 0.04).abs() < 1e-12);
    }
}
