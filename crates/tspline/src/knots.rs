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
//!
//! Two implementations give the same values to the bit (tested on fitted meshes):
//! [`infer_batch`], the one the evaluation and the fit use, answers all points at once from one
//! sorted list of edge coordinates per grid line (cost proportional to the mesh: each leaf is
//! visited once per line that crosses it); [`infer`] / [`infer_in`] cast the rays of one point
//! through the mesh's R-tree (the spec's Alg. 7 as written; kept for single points and as the
//! oracle of the batch).

use rayon::prelude::*;

use crate::mesh::{Rect, TMesh};

/// Local knot vectors of one control point: K+2 values per direction (unused tail = 0 for K=1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalKnots {
    pub s: [f64; 5],
    pub t: [f64; 5],
}

/// Collects up to `k` distinct edge coordinates beyond `from` in direction `dir` (+1 / −1) along
/// the line, with the domain-gap stop of A14.
fn ray(
    mesh: &TMesh,
    horizontal: bool,
    at: f64,
    from: f64,
    dir: f64,
    k: usize,
    limit: f64,
    buf: &mut Vec<Rect>,
) -> Vec<f64> {
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
        *dst = knot_vector(k, centre, &back, &fwd);
    }
    out
}

/// One direction's K+2 knots from the hits of its two rays (`back` and `fwd` nearest first, at
/// most k each): ascending, the point's own value in the middle, a short ray padded by
/// repeating its outermost hit, or the point's value when it has none (spec §3.6 step 5).
fn knot_vector(k: usize, centre: f64, back: &[f64], fwd: &[f64]) -> [f64; 5] {
    let padded = |hits: &[f64], i: usize| hits.get(i).or(hits.last()).copied().unwrap_or(centre);
    let mut dst = [0.0; 5];
    for i in 0..k {
        dst[k - 1 - i] = padded(back, i);
        dst[k + 1 + i] = padded(fwd, i);
    }
    dst[k] = centre;
    dst
}

/// Knot inference for many points at once (spec §3.6), in the order of `points` (s, t); equal
/// to [`infer`] point by point, bit for bit. The rays of all points on one grid line meet the
/// same leaves, so each line's leaves are gathered once (a sweep over the leaves, not an
/// R-tree query per ray) and every ray is two binary searches in the line's edge list.
pub fn infer_batch(mesh: &TMesh, points: &[(f64, f64)]) -> Vec<LocalKnots> {
    let k = mesh.degree.half();
    let leaves: Vec<Rect> = mesh.cells.iter().filter(|c| c.is_leaf()).map(|c| c.rect).collect();
    let along_s = knots_along_lines(&leaves, points, Axis::S, k);
    let along_t = knots_along_lines(&leaves, points, Axis::T, k);
    along_s.into_iter().zip(along_t).map(|(s, t)| LocalKnots { s, t }).collect()
}

/// `known[i]`, or where it is `None` the inferred knots of point `point_ids[i]` (one
/// [`infer_batch`] for all of those): the fit's re-inference after a refinement, which keeps the
/// knots of points far from the split cells.
pub fn infer_missing(mesh: &TMesh, point_ids: &[u32], known: Vec<Option<LocalKnots>>) -> Vec<LocalKnots> {
    let missing: Vec<usize> = (0..known.len()).filter(|&i| known[i].is_none()).collect();
    let params: Vec<(f64, f64)> =
        missing.iter().map(|&i| mesh.points[point_ids[i] as usize]).map(|p| (p.s, p.t)).collect();
    let mut out: Vec<LocalKnots> = known.iter().map(|k| k.unwrap_or(LocalKnots { s: [0.0; 5], t: [0.0; 5] })).collect();
    for (&i, kn) in missing.iter().zip(infer_batch(mesh, &params)) {
        out[i] = kn;
    }
    out
}

/// The direction of a family of grid lines: `S` lines run along s at a fixed t (the rays that
/// give σ), `T` lines along t at a fixed s (τ).
#[derive(Clone, Copy)]
enum Axis {
    S,
    T,
}

impl Axis {
    /// (coordinate along the line, the line's fixed coordinate) of a parameter pair.
    fn split(self, (s, t): (f64, f64)) -> (f64, f64) {
        match self {
            Axis::S => (s, t),
            Axis::T => (t, s),
        }
    }
    /// A rectangle's extent along the line's direction.
    fn along(self, r: &Rect) -> (f64, f64) {
        match self {
            Axis::S => (r.s_min, r.s_max),
            Axis::T => (r.t_min, r.t_max),
        }
    }
    /// A rectangle's extent across the lines.
    fn across(self, r: &Rect) -> (f64, f64) {
        match self {
            Axis::S => (r.t_min, r.t_max),
            Axis::T => (r.s_min, r.s_max),
        }
    }
}

/// The knot vector along `axis` of every point: points grouped by their line, the leaves of
/// each line gathered in one pass (CSR of leaf indices), then each line on its own (parallel).
fn knots_along_lines(leaves: &[Rect], points: &[(f64, f64)], axis: Axis, k: usize) -> Vec<[f64; 5]> {
    let across = |i: u32| axis.split(points[i as usize]).1;
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.par_sort_unstable_by(|&a, &b| across(a).total_cmp(&across(b)));
    // Lines: runs of equal fixed coordinate in `order` (== also joins +0.0 and -0.0, which the
    // R-tree's closed-box test cannot tell apart either).
    let mut runs: Vec<(f64, usize)> = Vec::new();
    for (n, &i) in order.iter().enumerate() {
        if runs.last().is_none_or(|&(c, _)| c != across(i)) {
            runs.push((across(i), n));
        }
    }
    let (start, members) = leaves_per_line(leaves, &runs, axis);
    let mut out = vec![[0.0; 5]; points.len()];
    let per_line: Vec<Vec<(u32, [f64; 5])>> = (0..runs.len())
        .into_par_iter()
        .map(|l| {
            let line =
                Line::new(members[start[l]..start[l + 1]].iter().map(|&c| axis.along(&leaves[c as usize])).collect());
            let end = runs.get(l + 1).map_or(order.len(), |r| r.1);
            order[runs[l].1..end].iter().map(|&i| (i, line.knot_vector(axis.split(points[i as usize]).0, k))).collect()
        })
        .collect();
    for (i, v) in per_line.into_iter().flatten() {
        out[i as usize] = v;
    }
    out
}

/// For each line (`runs`: its fixed coordinate, ascending), the leaves whose closed box it
/// crosses, as CSR (`start`, `members`): each leaf is binary-searched once into the range of
/// lines within its extent across.
fn leaves_per_line(leaves: &[Rect], runs: &[(f64, usize)], axis: Axis) -> (Vec<usize>, Vec<u32>) {
    let ranges: Vec<(usize, usize)> = leaves
        .iter()
        .map(|r| {
            let (lo, hi) = axis.across(r);
            (runs.partition_point(|&(c, _)| c < lo), runs.partition_point(|&(c, _)| c <= hi))
        })
        .collect();
    let mut start = vec![0usize; runs.len() + 1];
    for &(a, b) in &ranges {
        for l in a..b {
            start[l + 1] += 1;
        }
    }
    for l in 0..runs.len() {
        start[l + 1] += start[l];
    }
    let mut fill = start.clone();
    let mut members = vec![0u32; start[runs.len()]];
    for (c, &(a, b)) in ranges.iter().enumerate() {
        for l in a..b {
            members[fill[l]] = c as u32;
            fill[l] += 1;
        }
    }
    (start, members)
}

/// One grid line: the distinct edge coordinates of the leaves it crosses (ascending) and the
/// spans the leaves cover (closed, disjoint, ascending; rays end at a span's ends, A14).
struct Line {
    edges: Vec<f64>,
    spans: Vec<(f64, f64)>,
}

impl Line {
    /// From the leaves' intervals along the line (any order).
    fn new(mut intervals: Vec<(f64, f64)>) -> Line {
        intervals.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let mut spans: Vec<(f64, f64)> = Vec::new();
        for &(a, b) in &intervals {
            match spans.last_mut() {
                Some(span) if a <= span.1 => span.1 = span.1.max(b),
                _ => spans.push((a, b)),
            }
        }
        let mut edges: Vec<f64> = intervals.iter().flat_map(|&(a, b)| [a, b]).collect();
        edges.sort_unstable_by(f64::total_cmp);
        edges.dedup();
        Line { edges, spans }
    }

    /// The knot vector of a point at `u` on this line: the nearest k edges each way within the
    /// span that holds `u` (none when no span does).
    fn knot_vector(&self, u: f64, k: usize) -> [f64; 5] {
        let (lo, hi) = match self.spans.partition_point(|sp| sp.0 <= u).checked_sub(1).map(|i| self.spans[i]) {
            Some((lo, hi)) if u <= hi => (lo, hi),
            _ => (u, u),
        };
        let after = self.edges.partition_point(|&v| v <= u);
        let before = self.edges.partition_point(|&v| v < u);
        let fwd: Vec<f64> = self.edges[after..].iter().copied().take_while(|&v| v <= hi).take(k).collect();
        let back: Vec<f64> = self.edges[..before].iter().rev().copied().take_while(|&v| v >= lo).take(k).collect();
        knot_vector(k, u, &back, &fwd)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{ControlPoint, Degree, TMesh};
    use crate::testing::lcg;

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
    /// The batch inference against the per-point rays (the oracle): every active point of `m`,
    /// plus points on and off the mesh lines, inside and outside the domain.
    fn assert_batch_equals_rays(m: &TMesh, what: &str) {
        let active = m.active_points();
        let mut pts: Vec<(f64, f64)> =
            m.points.iter().zip(&active).filter(|(_, a)| **a).map(|(p, _)| (p.s, p.t)).collect();
        let b = m.bounds();
        let mut seed = 3u64;
        for _ in 0..200 {
            // quarter-steps of the cell sizes: on edges, on lines through cells, in gaps, outside
            let s = b.s_min - 2.0 + ((b.width() + 4.0) * lcg(&mut seed) * 4.0).floor() / 4.0;
            let t = b.t_min - 2.0 + ((b.height() + 4.0) * lcg(&mut seed) * 4.0).floor() / 4.0;
            pts.push((s, t));
        }
        let batch = infer_batch(m, &pts);
        for (&(s, t), kb) in pts.iter().zip(&batch) {
            let kr = infer(m, s, t);
            // bits, not ==: a knot must be the same f64 to give the same surface
            assert_eq!(
                (kb.s.map(f64::to_bits), kb.t.map(f64::to_bits)),
                (kr.s.map(f64::to_bits), kr.t.map(f64::to_bits)),
                "{what}: point ({s}, {t})"
            );
        }
    }

    #[test]
    fn batch_equals_rays_on_hand_made_meshes() {
        for degree in [Degree::Linear, Degree::Cubic] {
            assert_batch_equals_rays(&thesis(degree), "thesis");
            assert_batch_equals_rays(&crate::testing::refined_mesh(degree), "refined");
            // gaps and a notch: two grids side by side with a hole between, and an L shape
            let a = TMesh::grid(degree, 0.0, 0.0, 1.0, 3, 3);
            let gap = a.merge(&TMesh::grid(degree, 4.0, 1.0, 1.0, 2, 4)).unwrap();
            assert_batch_equals_rays(&gap, "gap");
            let l = a.merge(&TMesh::grid(degree, 3.0, 0.0, 1.0, 2, 1)).unwrap();
            assert_batch_equals_rays(&l, "L");
        }
    }

    /// Random splits, repairs and coarsenings (retained parents and orphaned points).
    #[test]
    fn batch_equals_rays_after_splits_and_coarsening() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut m = TMesh::grid(degree, -8.0, -8.0, 16.0, 5, 4);
            let mut g = |s: f64, t: f64| (s, t, 0.0);
            let mut seed = 17u64;
            for round in 0..4 {
                for c in m.leaves().collect::<Vec<_>>() {
                    if lcg(&mut seed) < 0.2 && m.cells[c as usize].rect.width() >= 2.0 {
                        m.split(c, &mut g);
                    }
                }
                m.repair(1.0, &mut g);
                if round == 2 {
                    let parents: Vec<u32> = (0..m.cells.len() as u32)
                        .filter(|&c| m.cells[c as usize].alive && m.cells[c as usize].children.is_some())
                        .collect();
                    for &c in parents.iter().step_by(5) {
                        if m.cells[c as usize].alive && m.cells[c as usize].children.is_some() {
                            m.coarsen(c).unwrap();
                        }
                    }
                }
                assert_batch_equals_rays(&m, &format!("round {round}"));
            }
        }
    }

    /// Meshes fitted by the crate's own loop (refinement, repair, coarsening) to a raster with
    /// a smooth hill, a narrow channel and noise; [`infer_missing`] fills only the gaps.
    #[test]
    fn batch_equals_rays_on_fitted_meshes() {
        use crate::fit::{fit, Backend, FitOptions, Samples};
        let (w, h) = (61usize, 47usize);
        let mut seed = 9u64;
        let z: Vec<f64> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let channel = if (x - 0.6 * y - 12.0).abs() < 2.0 { -4.0 } else { 0.0 };
                20.0 * (-((x - 30.0).powi(2) + (y - 20.0).powi(2)) / 200.0).exp() + channel + 0.3 * lcg(&mut seed)
            })
            .collect();
        let samples = Samples { width: w, height: h, z: z.into() };
        for (degree, e) in [(Degree::Linear, 1.0), (Degree::Cubic, 1.0), (Degree::Cubic, 0.4)] {
            let r = fit(&samples, &FitOptions::new(degree, e), &Backend::Cpu, &mut |_| {}).unwrap();
            assert!(r.mesh.leaf_count() > 40, "the fit refined");
            assert_batch_equals_rays(&r.mesh, &format!("fit {degree:?} {e}"));
            let ids: Vec<u32> =
                (0..r.mesh.points.len() as u32).filter(|&i| r.mesh.active_points()[i as usize]).collect();
            let known: Vec<Option<LocalKnots>> =
                ids.iter().map(|&i| (i % 3 == 0).then_some(LocalKnots { s: [7.0; 5], t: [7.0; 5] })).collect();
            let filled = infer_missing(&r.mesh, &ids, known);
            for (&i, kn) in ids.iter().zip(&filled) {
                let p = r.mesh.points[i as usize];
                let want = if i % 3 == 0 { LocalKnots { s: [7.0; 5], t: [7.0; 5] } } else { infer(&r.mesh, p.s, p.t) };
                assert_eq!(*kn, want);
            }
        }
    }

    /// Knots of the points of a 2-split rectangle: a cell [0,4]×[0,4] of a 2×1 grid split
    /// across s has its new points at s = 2; their s knots see the cut, their t knots the cell's
    /// full height (no cut across t).
    #[test]
    fn split_rectangle_knots() {
        let mut m = TMesh::grid(Degree::Linear, 0.0, 0.0, 4.0, 2, 1);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        m.split_dir(0, crate::mesh::SplitDir::S, &mut g);
        let k = infer(&m, 2.0, 4.0);
        assert_eq!(&k.s[..3], &[0.0, 2.0, 4.0]);
        assert_eq!(&k.t[..3], &[0.0, 4.0, 4.0]);
        // the old corner (4, 0) still sees 4 to its west (the cut is at 2 only for t in [0,4])
        let k = infer(&m, 4.0, 0.0);
        assert_eq!(&k.s[..3], &[2.0, 4.0, 8.0]);
        let mut m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 4.0, 3, 3);
        let c = m.leaves_in(crate::mesh::Rect::new(5.0, 5.0, 5.0, 5.0))[0];
        let kids = m.split_dir(c, crate::mesh::SplitDir::T, &mut g);
        m.split_dir(kids.as_slice()[1], crate::mesh::SplitDir::S, &mut g);
        // (6, 6): the mid-point of the upper half's... the cut across s of [4,8]×[6,8] at s = 6
        let k = infer(&m, 6.0, 8.0);
        assert_eq!(k.s, [0.0, 4.0, 6.0, 8.0, 12.0]);
        assert_eq!(k.t, [4.0, 6.0, 8.0, 12.0, 12.0]);
        let k = infer(&m, 4.0, 6.0);
        assert_eq!(k.s, [0.0, 0.0, 4.0, 6.0, 8.0]);
        assert_eq!(k.t, [0.0, 4.0, 6.0, 8.0, 12.0]);
    }

    /// The batch inference equals the rays on random anisotropic meshes.
    #[test]
    fn batch_equals_rays_on_aniso_meshes() {
        for degree in [Degree::Linear, Degree::Cubic] {
            for seed in [5u64, 6] {
                assert_batch_equals_rays(&crate::testing::aniso_mesh(degree, seed, 4), &format!("aniso {seed}"));
            }
        }
    }
}
