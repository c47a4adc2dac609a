//! Ring-level repairs on a ring of snapped vertices: consecutive repeats (102), spikes and folds
//! (104), and rings that pass twice through a vertex (104: a keyhole cut or a pinch), which are
//! split into simple loops. Each function works on one open ring (no closing point) of
//! `(vertex id, coordinates)`; the ids come from one snapper per geometry, as the validator
//! builds them, so "the same vertex" means here what it means to the validator.

/// A point as written in the document.
pub type P3 = [f64; 3];

/// One ring vertex: its snapped id and the coordinates it has in the document.
pub type Vx = (u32, P3);

pub(crate) fn sub(a: &P3, b: &P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn dot(a: &P3, b: &P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: &P3, b: &P3) -> P3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
pub(crate) fn norm(a: &P3) -> f64 {
    dot(a, a).sqrt()
}

/// Removes consecutive vertices with the same id (the ring read cyclically), keeping the first
/// of each run: 102 CONSECUTIVE_POINTS_SAME. Returns how many were removed.
///
/// # Examples
/// ```
/// use heal::repair::ring::drop_repeats;
/// let mut r = vec![(0, [0.0, 0.0, 0.0]), (1, [1.0, 0.0, 0.0]), (1, [1.0005, 0.0, 0.0]), (2, [1.0, 1.0, 0.0]), (0, [0.0, 0.0, 0.0])];
/// assert_eq!(drop_repeats(&mut r), 2);
/// assert_eq!(r.iter().map(|v| v.0).collect::<Vec<_>>(), vec![0, 1, 2]);
/// ```
pub fn drop_repeats(r: &mut Vec<Vx>) -> usize {
    let before = r.len();
    r.dedup_by_key(|v| v.0);
    while r.len() > 1 && r[0].0 == r[r.len() - 1].0 {
        r.pop();
    }
    before - r.len()
}

/// Is the vertex `b` between `a` and `c` the tip of a spike: the ring runs a → b and back
/// towards a along (within `tol` of) the same line?
fn is_spike(a: &Vx, b: &Vx, c: &Vx, tol: f64) -> bool {
    if a.0 == c.0 {
        return true;
    }
    let (u, w) = (sub(&a.1, &b.1), sub(&c.1, &b.1));
    let (lu, lw) = (norm(&u), norm(&w));
    if lu == 0.0 || lw == 0.0 || dot(&u, &w) <= 0.0 {
        return false;
    }
    // the shorter leg's far end lies within tol of the longer leg's line
    norm(&cross(&u, &w)) / lu.max(lw) <= tol
}

/// Removes spike tips (a vertex whose two edges fold back onto each other) until none is left,
/// with the repeats they leave behind. Returns the number of tips removed, or `None` when the
/// ring would collapse below 3 vertices (it is then left as it was).
///
/// # Examples
/// ```
/// use heal::repair::ring::drop_spikes;
/// // a square with a 2 m spike out of its right edge
/// let mut r = vec![(0, [0.0, 0.0, 0.0]), (1, [1.0, 0.0, 0.0]), (2, [1.0, 0.5, 0.0]), (3, [3.0, 0.5, 0.0]),
///                  (2, [1.0, 0.5, 0.0]), (4, [1.0, 1.0, 0.0]), (5, [0.0, 1.0, 0.0])];
/// assert_eq!(drop_spikes(&mut r, 0.001), Some(1));
/// assert_eq!(r.iter().map(|v| v.0).collect::<Vec<_>>(), vec![0, 1, 2, 4, 5]);
/// ```
pub fn drop_spikes(r: &mut Vec<Vx>, tol: f64) -> Option<usize> {
    let mut work = r.clone();
    let mut removed = 0;
    drop_repeats(&mut work);
    'outer: loop {
        let n = work.len();
        if n < 3 {
            return None;
        }
        for i in 0..n {
            let (a, b, c) = (&work[(i + n - 1) % n], &work[i], &work[(i + 1) % n]);
            if is_spike(a, b, c, tol) {
                work.remove(i);
                removed += 1;
                drop_repeats(&mut work);
                continue 'outer;
            }
        }
        break;
    }
    if work.len() < 3 {
        return None;
    }
    *r = work;
    Some(removed)
}

/// How a ring that passes twice through one vertex was cut apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cut {
    /// The ring runs along an edge and back (A B … B A): a keyhole's cut, which has no area.
    Keyhole,
    /// The ring touches itself at one vertex.
    Pinch,
}

/// Splits a ring at its first repeated vertex into two rings (each keeps the traversal
/// direction of the input), or `None` when no vertex repeats (or every vertex does).
pub fn split_once(r: &[Vx]) -> Option<(Vec<Vx>, Vec<Vx>, Cut)> {
    let n = r.len();
    let mut count: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for v in r {
        *count.entry(v.0).or_default() += 1;
    }
    // start at a vertex the ring passes once, so a repeat never wraps around the start
    let start = (0..n).find(|&k| count[&r[k].0] == 1)?;
    let r: Vec<Vx> = r[start..].iter().chain(r[..start].iter()).cloned().collect();
    let mut first: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for j in 0..n {
        let Some(&i) = first.get(&r[j].0) else {
            first.insert(r[j].0, j);
            continue;
        };
        // r[i] == r[j], 1 <= i < j
        if j + 1 < n && r[i - 1].0 == r[j + 1].0 && i + 1 < j {
            // … A B … B A …: the edge A–B is run both ways (a keyhole's cut): drop it
            let outer: Vec<Vx> = r[..i].iter().chain(r[j + 2..].iter()).cloned().collect();
            return Some((outer, r[i..j].to_vec(), Cut::Keyhole));
        }
        if r[i + 1].0 == r[j - 1].0 && i + 2 < j - 1 {
            // … A B … B A … seen from A
            let outer: Vec<Vx> = r[..=i].iter().chain(r[j + 1..].iter()).cloned().collect();
            return Some((outer, r[i + 1..j - 1].to_vec(), Cut::Keyhole));
        }
        let outer: Vec<Vx> = r[..=i].iter().chain(r[j + 1..].iter()).cloned().collect();
        return Some((outer, r[i..j].to_vec(), Cut::Pinch));
    }
    None
}

/// Splits a ring into simple loops (no vertex repeated), recursively. Returns the loops and the
/// number of cuts of each kind `(keyholes, pinches)`.
pub fn split_all(r: &[Vx]) -> (Vec<Vec<Vx>>, usize, usize) {
    let mut out = Vec::new();
    let (mut keyholes, mut pinches) = (0, 0);
    let mut todo = vec![r.to_vec()];
    while let Some(mut x) = todo.pop() {
        drop_repeats(&mut x);
        match split_once(&x) {
            Some((a, b, cut)) => {
                match cut {
                    Cut::Keyhole => keyholes += 1,
                    Cut::Pinch => pinches += 1,
                }
                todo.push(a);
                todo.push(b);
            }
            None => out.push(x),
        }
    }
    (out, keyholes, pinches)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(ids_pts: &[(u32, [f64; 2])]) -> Vec<Vx> {
        ids_pts.iter().map(|(i, p)| (*i, [p[0], p[1], 0.0])).collect()
    }

    #[test]
    fn repeats_wrap_around() {
        let mut r = ring(&[(0, [0., 0.]), (1, [1., 0.]), (2, [1., 1.]), (0, [0., 0.0004])]);
        assert_eq!(drop_repeats(&mut r), 1);
        assert_eq!(r.len(), 3);
    }

    #[test]
    fn a_fold_along_an_edge_is_a_spike() {
        // 0,0 → 2,0 → 1,0 (back along the same edge) → 1,1: vertex (2,0) folds back
        let mut r = ring(&[(0, [0., 0.]), (1, [2., 0.]), (2, [1., 0.]), (3, [1., 1.])]);
        assert_eq!(drop_spikes(&mut r, 1e-6), Some(1));
        assert_eq!(r.iter().map(|v| v.0).collect::<Vec<_>>(), vec![0, 2, 3]);
    }

    #[test]
    fn a_right_angle_is_not_a_spike() {
        let mut r = ring(&[(0, [0., 0.]), (1, [1., 0.]), (2, [1., 1.]), (3, [0., 1.])]);
        assert_eq!(drop_spikes(&mut r, 1e-3), Some(0));
        assert_eq!(r.len(), 4);
    }

    #[test]
    fn a_ring_that_is_all_spike_is_left() {
        let mut r = ring(&[(0, [0., 0.]), (1, [1., 0.]), (2, [2., 0.])]);
        assert_eq!(drop_spikes(&mut r, 1e-6), None);
        assert_eq!(r.len(), 3);
    }

    #[test]
    fn a_keyhole_becomes_outer_and_inner() {
        // outer square 0..4 with a cut from (0,2) to the inner square 1..3
        let r = ring(&[
            (0, [0., 0.]),
            (1, [4., 0.]),
            (2, [4., 4.]),
            (3, [0., 4.]),
            (4, [0., 2.]),
            (5, [1., 2.]),
            (6, [1., 3.]),
            (7, [3., 3.]),
            (8, [3., 1.]),
            (9, [1., 1.]),
            (5, [1., 2.]),
            (4, [0., 2.]),
        ]);
        let (loops, k, p) = split_all(&r);
        assert_eq!((k, p, loops.len()), (1, 0, 2));
        let ids: Vec<Vec<u32>> = loops.iter().map(|l| l.iter().map(|v| v.0).collect()).collect();
        assert!(ids.contains(&vec![0, 1, 2, 3, 4]));
        assert!(ids.contains(&vec![5, 6, 7, 8, 9]));
    }

    #[test]
    fn a_pinch_splits_into_two_lobes() {
        // two triangles meeting at vertex 2 (the QIE i104_2 top face once (1, 0.5) is inserted)
        let r = ring(&[(0, [0., 0.]), (1, [1., 0.]), (2, [1., 0.5]), (3, [1., 1.]), (4, [0., 1.]), (2, [1., 0.5])]);
        let (loops, k, p) = split_all(&r);
        assert_eq!((k, p), (0, 1));
        let ids: Vec<Vec<u32>> = loops.iter().map(|l| l.iter().map(|v| v.0).collect()).collect();
        assert!(ids.contains(&vec![0, 1, 2]));
        assert!(ids.contains(&vec![2, 3, 4]));
    }
}
