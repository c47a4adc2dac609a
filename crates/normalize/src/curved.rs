//! Facets of a curved facade: a run of short wall faces whose normals turn steadily (a round
//! tower, a bay, a curved street front, each approximated by flat facets). Squaring conditions
//! (parallel, orthogonal) between such a facet and any other face are not meant by the data: on
//! an NRW tile they pulled the 4 m² facets of a round building square and grew it by 11.5 % area
//! (docs/decisions.md#no-squaring-on-curved-facades).
//!
//! A facet belongs to a curved facade when it is a wall (normal within 20° of horizontal), at
//! most [`MAX_FACET_WIDTH`] wide, and it or one of its wall neighbours (sharing an edge) sits in
//! the middle of three such facets whose horizontal normals turn by [`MIN_TURN_DEG`] to
//! [`MAX_TURN_DEG`] each, both turns the same way.

use popa3d_model::vec3::unit;
use popa3d_model::*;
use std::collections::{BTreeSet, HashMap};

/// Widest facet counted as part of a curved facade (m).
pub const MAX_FACET_WIDTH: f64 = 5.0;
/// Smallest and largest turn between neighbouring facets (degrees): below, the two are one
/// (slightly kinked) wall; above, a corner.
pub const MIN_TURN_DEG: f64 = 1.0;
pub const MAX_TURN_DEG: f64 = 35.0;

/// A wall facet: its horizontal unit normal and width.
struct Facet {
    n: [f64; 2],
    width: f64,
}

fn facet(m: &Popa3d, inc: &Incidence, pos: &[[f64; 3]], f: FaceId) -> Option<Facet> {
    let n = unit(m.face_plane_value(f).n);
    let h = (n[0] * n[0] + n[1] * n[1]).sqrt();
    if h < 20f64.to_radians().cos() {
        return None;
    }
    let (hx, hy) = (n[0] / h, n[1] / h);
    let loops = m.face_loops(inc, f, pos)?;
    let along: Vec<f64> = loops.first()?.iter().map(|x| -hy * pos[x.idx()][0] + hx * pos[x.idx()][1]).collect();
    let width =
        along.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - along.iter().cloned().fold(f64::INFINITY, f64::min);
    (width <= MAX_FACET_WIDTH).then_some(Facet { n: [hx, hy], width })
}

/// Signed turn from `a` to `b` about the vertical (degrees).
fn turn(a: &Facet, b: &Facet) -> f64 {
    (a.n[0] * b.n[1] - a.n[1] * b.n[0]).atan2(a.n[0] * b.n[0] + a.n[1] * b.n[1]).to_degrees()
}

/// The faces of `faces` that are facets of a curved facade.
pub fn curved_facets(m: &Popa3d, inc: &Incidence, pos: &[[f64; 3]], faces: std::ops::Range<usize>) -> BTreeSet<usize> {
    let facets: HashMap<usize, Facet> =
        faces.clone().filter_map(|f| facet(m, inc, pos, FaceId::from(f)).map(|x| (f, x))).collect();
    let mut out = BTreeSet::new();
    for (&f, mid) in &facets {
        if mid.width <= 0.0 {
            continue;
        }
        // neighbours sharing an edge, with the turn from the neighbour to this facet
        let mut turns: Vec<(usize, f64)> = Vec::new();
        for h in &inc.face_half_edges[f] {
            for g in inc.edge_faces(m, m.half_edge(*h).edge) {
                let g = g.idx();
                if g == f || turns.iter().any(|t| t.0 == g) {
                    continue;
                }
                if let Some(nb) = facets.get(&g) {
                    let t = turn(nb, mid);
                    if (MIN_TURN_DEG..=MAX_TURN_DEG).contains(&t.abs()) {
                        turns.push((g, t));
                    }
                }
            }
        }
        // g1 → f → g2 turning the same way: the turn g1→f and f→g2 = −(g2→f) share a sign
        for (i, a) in turns.iter().enumerate() {
            for b in &turns[i + 1..] {
                if a.1 * b.1 < 0.0 {
                    out.extend([f, a.0, b.0]);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turns_are_signed_degrees_about_the_vertical() {
        let a = Facet { n: [1.0, 0.0], width: 1.0 };
        let b = Facet { n: [10f64.to_radians().cos(), 10f64.to_radians().sin()], width: 1.0 };
        assert!((turn(&a, &b) - 10.0).abs() < 1e-9);
        assert!((turn(&b, &a) + 10.0).abs() < 1e-9);
    }
}
