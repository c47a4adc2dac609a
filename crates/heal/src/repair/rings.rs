//! The ring repairs over a whole building: repeated points (102), spikes (104), rings collapsed
//! to no area (101), and rings that pass twice through a vertex (104), split into an outer
//! ring, holes and lobes in the polygon's plane.

use super::ring::{cross, dot, drop_repeats, drop_spikes, norm, split_all, sub, Vx, P3};
use super::work::{FaceRef, Work};
use super::{names, Counts};

fn bump(counts: &mut Counts, name: &'static str, n: usize) {
    if n > 0 {
        *counts.entry(name).or_insert(0) += n;
    }
}

/// Drops repeated points and spike tips in every ring; removes a ring left with fewer than 3
/// vertices (it has no area) where that is safe: an interior ring, or a polygon nothing refers
/// to. Returns whether anything changed.
pub fn fix_points(w: &mut Work, tol: f64, counts: &mut Counts) -> bool {
    let mut any = false;
    for ci in 0..w.contexts.len() {
        let (_, refs, mut faces) = w.snap(&w.contexts[ci], tol);
        for (r, face) in refs.iter().zip(faces.iter_mut()) {
            let mut changed = false;
            let mut collapsed = Vec::new();
            for (k, ring) in face.iter_mut().enumerate() {
                let d = drop_repeats(ring);
                bump(counts, names::DUPLICATE_POINTS, d);
                changed |= d > 0;
                match drop_spikes(ring, tol) {
                    Some(s) => {
                        bump(counts, names::SPIKE, s);
                        changed |= s > 0;
                    }
                    None => collapsed.push(k),
                }
            }
            if let Some(&0) = collapsed.first() {
                if remove_polygon(w, r) {
                    bump(counts, names::COLLAPSED_POLYGON, 1);
                    any = true;
                }
                continue;
            }
            for &k in collapsed.iter().rev() {
                face.remove(k);
                bump(counts, names::COLLAPSED_RING, 1);
                changed = true;
            }
            if changed {
                w.set_face(r, face);
                any = true;
            }
        }
    }
    any
}

/// Removes a polygon whose exterior has collapsed, if nothing else refers to it.
fn remove_polygon(w: &mut Work, r: &FaceRef) -> bool {
    let p = &mut w.polys[r.poly];
    if r.face != 0 || p.referenced || p.src.member_span.is_none() || !p.extra.is_empty() || p.removed {
        return false;
    }
    p.removed = true;
    true
}

/// Newell vector of a ring (twice its vector area).
pub fn newell(r: &[P3]) -> P3 {
    let mut n = [0.0; 3];
    let c = r.first().copied().unwrap_or([0.0; 3]);
    for i in 0..r.len() {
        let (a, b) = (sub(&r[i], &c), sub(&r[(i + 1) % r.len()], &c));
        let x = cross(&a, &b);
        for k in 0..3 {
            n[k] += x[k];
        }
    }
    n
}

fn loop_points(l: &[Vx]) -> Vec<P3> {
    l.iter().map(|v| v.1).collect()
}

/// Even-odd point-in-ring test in the plane with unit normal `n`.
fn inside(p: &P3, ring: &[P3], n: &P3) -> bool {
    let a = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let u = cross(n, &a);
    let u = [u[0] / norm(&u), u[1] / norm(&u), u[2] / norm(&u)];
    let v = cross(n, &u);
    let to2 = |q: &P3| (dot(q, &u), dot(q, &v));
    let (px, py) = to2(p);
    let mut c = false;
    for i in 0..ring.len() {
        let (ax, ay) = to2(&ring[i]);
        let (bx, by) = to2(&ring[(i + 1) % ring.len()]);
        if (ay > py) != (by > py) && px < ax + (py - ay) * (bx - ax) / (by - ay) {
            c = !c;
        }
    }
    c
}

/// How a ring that passes twice through a vertex is rebuilt: the outer loop, its holes, the
/// lobes that become polygons of their own, and the number of zero-area loops dropped.
struct Parts {
    outer: Vec<Vx>,
    holes: Vec<Vec<Vx>>,
    lobes: Vec<Vec<Vx>>,
    folds: usize,
}

/// Sorts the simple loops of one ring: the largest loop turning like the ring is the outer; a
/// loop turning the other way inside it is a hole; one turning the same way outside it a lobe;
/// one without area a fold. Anything else (a loop crossing another): `None`.
fn classify(loops: Vec<Vec<Vx>>, tol: f64) -> Option<Parts> {
    let whole: Vec<P3> = loops.iter().flat_map(|l| loop_points(l)).collect();
    let n = newell(&whole);
    let ln = norm(&n);
    if !(ln > 0.0) {
        return None;
    }
    let n = [n[0] / ln, n[1] / ln, n[2] / ln];
    let area = |l: &[Vx]| 0.5 * dot(&newell(&loop_points(l)), &n);
    let perimeter = |l: &[Vx]| (0..l.len()).map(|i| norm(&sub(&l[(i + 1) % l.len()].1, &l[i].1))).sum::<f64>();
    let oi = (0..loops.len()).max_by(|&a, &b| area(&loops[a]).total_cmp(&area(&loops[b])))?;
    if area(&loops[oi]) <= tol * perimeter(&loops[oi]) {
        return None;
    }
    let outer_pts = loop_points(&loops[oi]);
    let outer_ids: std::collections::HashSet<u32> = loops[oi].iter().map(|v| v.0).collect();
    let mut parts = Parts { outer: loops[oi].clone(), holes: Vec::new(), lobes: Vec::new(), folds: 0 };
    for (k, l) in loops.into_iter().enumerate() {
        if k == oi {
            continue;
        }
        let a = area(&l);
        if l.len() < 3 || a.abs() <= tol * perimeter(&l) {
            parts.folds += 1;
            continue;
        }
        let probe = l.iter().find(|v| !outer_ids.contains(&v.0))?;
        let within = inside(&probe.1, &outer_pts, &n);
        match (a < 0.0, within) {
            (true, true) => parts.holes.push(l),
            (false, false) => parts.lobes.push(l),
            _ => return None,
        }
    }
    Some(parts)
}

/// Splits every exterior ring that passes twice through a vertex (104): a keyhole cut becomes
/// a hole, a pinch a hole or a lobe (a new polygon, only where nothing refers to the polygon),
/// a loop without area is dropped. Returns whether anything changed.
pub fn split_rings(w: &mut Work, tol: f64, counts: &mut Counts) -> bool {
    let mut any = false;
    for ci in 0..w.contexts.len() {
        let (_, refs, faces) = w.snap(&w.contexts[ci], tol);
        for (r, face) in refs.iter().zip(faces) {
            let Some(ext) = face.first() else { continue };
            let (loops, keyholes, pinches) = split_all(ext);
            if loops.len() < 2 {
                continue;
            }
            let Some(parts) = classify(loops, tol) else { continue };
            let p = &w.polys[r.poly];
            if !parts.lobes.is_empty() && (r.face != 0 || p.referenced || p.src.member_span.is_none()) {
                continue;
            }
            let mut rings: Vec<Vec<Vx>> = vec![parts.outer];
            rings.extend(parts.holes);
            rings.extend(face.iter().skip(1).cloned());
            w.set_face(r, &rings);
            for l in parts.lobes {
                w.polys[r.poly].extra.push(vec![loop_points(&l)]);
            }
            bump(counts, names::KEYHOLE, keyholes);
            bump(counts, names::PINCH, pinches);
            bump(counts, names::FOLD, parts.folds);
            any = true;
        }
    }
    any
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vx(ids_pts: &[(u32, [f64; 2])]) -> Vec<Vx> {
        ids_pts.iter().map(|(i, p)| (*i, [p[0], p[1], 5.0])).collect()
    }

    #[test]
    fn keyhole_loops_are_an_outer_ring_and_a_hole() {
        let outer = vx(&[(0, [0., 0.]), (1, [4., 0.]), (2, [4., 4.]), (3, [0., 4.])]);
        let hole = vx(&[(5, [1., 2.]), (6, [1., 3.]), (7, [3., 3.]), (8, [3., 1.]), (9, [1., 1.])]);
        let p = classify(vec![hole, outer], 1e-3).unwrap();
        assert_eq!((p.outer.len(), p.holes.len(), p.lobes.len(), p.folds), (4, 1, 0, 0));
    }

    #[test]
    fn two_triangles_at_a_vertex_are_lobes() {
        let a = vx(&[(0, [0., 0.]), (1, [1., 0.]), (2, [1., 0.5])]);
        let b = vx(&[(2, [1., 0.5]), (3, [1., 1.]), (4, [0., 1.])]);
        let p = classify(vec![a, b], 1e-3).unwrap();
        assert_eq!((p.holes.len(), p.lobes.len()), (0, 1));
    }

    #[test]
    fn a_hole_turning_like_the_outer_ring_is_refused() {
        let outer = vx(&[(0, [0., 0.]), (1, [4., 0.]), (2, [4., 4.]), (3, [0., 4.])]);
        let same = vx(&[(5, [1., 1.]), (6, [3., 1.]), (7, [3., 3.])]);
        assert!(classify(vec![outer, same], 1e-3).is_none());
    }

    #[test]
    fn newell_of_a_unit_square_is_twice_its_area() {
        let n = newell(&[[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]]);
        assert_eq!(n, [0.0, 0.0, 2.0]);
    }
}
