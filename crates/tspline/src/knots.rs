//! Local knot vectors by ray casting (spec §3.6, Alg. 7).
//!
//! From a control point, rays go west, east, south and north. A hit is a vertex on the ray or a
//! crossing with an orthogonal edge; since every leaf cell that the ray's line touches
//! (closed boxes) contributes its two orthogonal edge coordinates, both kinds are covered: a
//! T-junction on the ray is a corner of the cell below/above it. Duplicates (shared edges) are
//! removed. The nearest k = (K+1)/2 distinct values per direction are kept; fewer hits (mesh
//! border) are padded by repeating the outermost found value, or the point's own value when none
//! was found (spec §3.6 step 5).
//!
//! A14: a ray ends where it would leave the domain (the union of leaf cells along the line has a
//! gap); hits beyond a gap are ignored.

use crate::mesh::{Rect, TMesh};

/// Local knot vectors of one control point: K+2 values per direction (unused tail = 0 for K=1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalKnots {
    pub s: [f64; 5],
    pub t: [f64; 5],
}

/// Collects up to `k` distinct edge coordinates beyond `from` in direction `dir` (+1 / −1) along
/// the line, with the domain-gap stop of A14.
fn ray(mesh: &TMesh, horizontal: bool, at: f64, from: f64, dir: f64, k: usize, limit: f64, buf: &mut Vec<Rect>) -> Vec<f64> {
    // Start with a short window and double it: most rays find their k knots nearby.
    let mut len = 1.0f64;
    // Use the size of cells touching the point as the first window estimate.
    let total = (limit - from).abs();
    loop {
        let (lo, hi) = if dir > 0.0 { (from, (from + len).min(limit)) } else { ((from - len).max(limit), from) };
        mesh.leaves_on_line(horizontal, at, lo, hi, buf);
        // Intervals along the line, oriented so that "forward" is increasing u.
        let mut iv: Vec<(f64, f64)> = buf
            .iter()
            .map(|r| if horizontal { (r.s_min, r.s_max) } else { (r.t_min, r.t_max) })
            .map(|(a, b)| if dir > 0.0 { (a, b) } else { (-b, -a) })
            .collect();
        let f = from * dir;
        iv.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap().then(a.1.partial_cmp(&b.1).unwrap()));
        let mut reach = f;
        let mut vals: Vec<f64> = Vec::new();
        let window_end = if dir > 0.0 { hi } else { -lo };
        let mut gap = false;
        for &(a, b) in &iv {
            if b <= f {
                continue;
            }
            if a > reach {
                gap = true;
                break;
            }
            reach = reach.max(b);
            if a > f {
                vals.push(a);
            }
            vals.push(b);
        }
        vals.retain(|&v| v > f && v <= reach && v <= window_end);
        vals.sort_by(|a, b| a.partial_cmp(b).unwrap());
        vals.dedup();
        let complete = vals.len() >= k || gap || reach < window_end || len >= total;
        if complete {
            vals.truncate(k);
            return vals.into_iter().map(|v| v * dir).collect();
        }
        len *= 2.0;
    }
}

/// Knot inference for one point (spec §3.6): returns σ_i, τ_i with K+2 entries each.
pub fn infer(mesh: &TMesh, s: f64, t: f64) -> LocalKnots {
    infer_in(mesh, mesh.bounds(), s, t)
}

/// [`infer`] with the mesh bounds given: `TMesh::bounds` visits every cell, so callers that
/// infer the knots of many points compute it once (the fit: O(n) instead of O(n·cells)).
pub fn infer_in(mesh: &TMesh, b: Rect, s: f64, t: f64) -> LocalKnots {
    let k = mesh.degree.half();
    let mut buf = Vec::new();
    let mut out = LocalKnots { s: [0.0; 5], t: [0.0; 5] };
    for (horizontal, centre, at, lo_lim, hi_lim) in [(true, s, t, b.s_min, b.s_max), (false, t, s, b.t_min, b.t_max)] {
        let fwd = ray(mesh, horizontal, at, centre, 1.0, k, hi_lim, &mut buf);
        let back = ray(mesh, horizontal, at, centre, -1.0, k, lo_lim, &mut buf);
        let dst = if horizontal { &mut out.s } else { &mut out.t };
        // back: nearest first → reversed into ascending order, padded at the far end
        let pad = |v: &[f64]| -> Vec<f64> {
            let mut v = v.to_vec();
            let last = v.last().copied().unwrap_or(centre);
            while v.len() < k {
                v.push(last);
            }
            v
        };
        let back = pad(&back);
        let fwd = pad(&fwd);
        for i in 0..k {
            dst[i] = back[k - 1 - i];
        }
        dst[k] = centre;
        for i in 0..k {
            dst[k + 1 + i] = fwd[i];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{ControlPoint, Degree, TMesh};

    fn thesis(degree: Degree) -> TMesh {
        let st = [(0., 2.), (1., 2.), (2., 2.), (0., 1.), (1., 1.), (2., 1.), (0., 0.), (2., 0.)];
        let points = st.iter().map(|&(s, t)| ControlPoint { s, t, x: s, y: t, z: 0.0, w: 1.0 }).collect();
        TMesh::from_cells(degree, points, vec![[0, 1, 3, 4], [1, 2, 4, 5], [3, 5, 6, 7]]).unwrap()
    }

    /// Spec §5.2 [derived] knots of the Table 5.1–5.3 fixture.
    #[test]
    fn thesis_fixture_knots() {
        let m = thesis(Degree::Linear);
        let k = infer(&m, 1.0, 1.0);
        assert_eq!(&k.s[..3], &[0., 1., 2.]);
        assert_eq!(&k.t[..3], &[0., 1., 2.]);
        let k = infer(&m, 0.0, 0.0);
        assert_eq!(&k.s[..3], &[0., 0., 2.]);
        assert_eq!(&k.t[..3], &[0., 0., 1.]);
        let m = thesis(Degree::Cubic);
        let k = infer(&m, 1.0, 1.0);
        assert_eq!(k.s, [0., 0., 1., 2., 2.]);
        assert_eq!(k.t, [0., 0., 1., 2., 2.]);
    }

    /// Fig. 5.6: a cubic border point gets σ = [0,0,1,2,3], τ = [2,3,4,5,6] on a unit grid
    /// (point at (0, 4) of a grid reaching s = 3 and t = 6 and beyond).
    #[test]
    fn fig_5_6_border_point_cubic() {
        let m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 1.0, 6, 9);
        let k = infer(&m, 0.0, 4.0);
        assert_eq!(k.s, [0., 0., 0., 1., 2.].map(|v| v)); // own value repeated: s=0 has no west hit
        // The thesis figure shows the point one column in: s = 1 → [0,0,1,2,3].
        let k = infer(&m, 1.0, 4.0);
        assert_eq!(k.s, [0., 0., 1., 2., 3.]);
        assert_eq!(k.t, [2., 3., 4., 5., 6.]);
    }

    /// Fig. 6.5: linear horizontal knots (1, 2, 2½): a point at s = 2 whose west neighbour is at 1
    /// and whose east ray hits the edge of a half-size cell at 2.5.
    #[test]
    fn fig_6_5_linear_knots() {
        let mut m = TMesh::grid(Degree::Linear, 0.0, 0.0, 1.0, 4, 2);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        // split the cell [2,3]x[1,2]: the mid-point (2.5, 1) lies on the ray t = 1 from (2, 1)
        let c = m.leaves_in(crate::mesh::Rect::new(2.4, 1.4, 2.6, 1.6))[0];
        m.split(c, &mut g);
        let k = infer(&m, 2.0, 1.0);
        assert_eq!(&k.s[..3], &[1.0, 2.0, 2.5]);
    }

    /// A14: rays stop at a gap between two merged meshes.
    #[test]
    fn rays_stop_at_gaps() {
        let a = TMesh::grid(Degree::Cubic, 0.0, 0.0, 1.0, 2, 2);
        let b = TMesh::grid(Degree::Cubic, 3.0, 0.0, 1.0, 2, 2);
        let m = a.merge(&b).unwrap();
        let k = infer(&m, 1.0, 1.0);
        assert_eq!(k.s, [0., 0., 1., 2., 2.]);
    }
}
