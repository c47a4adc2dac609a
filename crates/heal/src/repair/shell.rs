//! Shell repairs: T-junctions and tiny gaps that leave a shell open (302), and the orientation
//! of its faces (307 one face against its neighbours, 405 the whole shell inwards).

use super::ring::{dot, norm, sub, Vx, P3};
use super::work::{Kind, Work};
use super::{names, Counts};
use std::collections::{BTreeMap, HashMap};

fn bump(counts: &mut Counts, name: &'static str, n: usize) {
    if n > 0 {
        *counts.entry(name).or_insert(0) += n;
    }
}

/// Undirected edges of a context's rings with their number of uses.
fn edge_uses(faces: &[Vec<Vec<Vx>>]) -> HashMap<(u32, u32), usize> {
    let mut m = HashMap::new();
    for f in faces {
        for r in f {
            for i in 0..r.len() {
                let (a, b) = (r[i].0, r[(i + 1) % r.len()].0);
                if a != b {
                    *m.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                }
            }
        }
    }
    m
}

/// The vertices lying inside the segment a–b (within `tol` of it, strictly between its ends),
/// ordered from a to b.
fn on_segment(a: &Vx, b: &Vx, coords: &[P3], tol: f64) -> Vec<Vx> {
    let ab = sub(&b.1, &a.1);
    let l2 = dot(&ab, &ab);
    if l2 == 0.0 {
        return Vec::new();
    }
    let l = l2.sqrt();
    let lo: Vec<f64> = (0..3).map(|k| a.1[k].min(b.1[k]) - tol).collect();
    let hi: Vec<f64> = (0..3).map(|k| a.1[k].max(b.1[k]) + tol).collect();
    let mut hits: Vec<(f64, Vx)> = Vec::new();
    for (id, c) in coords.iter().enumerate() {
        let id = id as u32;
        if id == a.0 || id == b.0 || (0..3).any(|k| c[k] < lo[k] || c[k] > hi[k]) {
            continue;
        }
        let ac = sub(c, &a.1);
        let t = dot(&ac, &ab) / l2;
        if t * l <= tol || (1.0 - t) * l <= tol {
            continue;
        }
        let d = norm(&sub(&ac, &[ab[0] * t, ab[1] * t, ab[2] * t]));
        if d <= tol {
            hits.push((t, (id, *c)));
        }
    }
    hits.sort_by(|x, y| x.0.total_cmp(&y.0));
    hits.into_iter().map(|h| h.1).collect()
}

/// Inserts into every edge used by one face only the vertices of the shell lying on it (a
/// T-junction: the neighbour's edge is split there, this one is not); `reach`: how far off the
/// edge such a vertex may lie. Returns the number of vertices inserted.
pub fn insert_t_junctions(w: &mut Work, tol: f64, reach: f64, counts: &mut Counts) -> usize {
    let mut total = 0;
    for ci in 0..w.contexts.len() {
        if w.contexts[ci].kind == Kind::Surfaces {
            continue;
        }
        let (coords, refs, faces) = w.snap(&w.contexts[ci], tol);
        let uses = edge_uses(&faces);
        for (r, face) in refs.iter().zip(&faces) {
            let mut n = 0;
            let new: Vec<Vec<Vx>> = face
                .iter()
                .map(|ring| {
                    let mut out = Vec::with_capacity(ring.len());
                    for i in 0..ring.len() {
                        let (a, b) = (&ring[i], &ring[(i + 1) % ring.len()]);
                        out.push(*a);
                        if uses.get(&(a.0.min(b.0), a.0.max(b.0))) == Some(&1) {
                            let add = on_segment(a, b, &coords, reach);
                            n += add.len();
                            out.extend(add);
                        }
                    }
                    out
                })
                .collect();
            if n > 0 {
                w.set_face(r, &new);
                total += n;
            }
        }
    }
    bump(counts, names::T_JUNCTION, total);
    total
}

/// Closes gaps narrower than `gap` between the borders of a shell: a vertex on an edge used
/// once moves onto the nearest other such vertex when that closes border edges (the vertex
/// used by fewer faces moves; a short border edge between them collapses). Kept per shell only
/// when the number of border edges falls.
pub fn snap_gaps(w: &mut Work, tol: f64, gap: f64, counts: &mut Counts) -> usize {
    let mut total = 0;
    for ci in 0..w.contexts.len() {
        if w.contexts[ci].kind == Kind::Surfaces {
            continue;
        }
        let (coords, refs, faces) = w.snap(&w.contexts[ci], tol);
        let uses = edge_uses(&faces);
        let border_before = uses.values().filter(|&&u| u == 1).count();
        if border_before == 0 {
            continue;
        }
        let moves = gap_moves(&faces, &uses, &coords, tol, gap);
        if moves.is_empty() {
            continue;
        }
        let moved: Vec<Vec<Vec<Vx>>> = faces
            .iter()
            .map(|f| {
                f.iter()
                    .map(|r| r.iter().map(|v| moves.get(&v.0).map_or(*v, |&t| (t, coords[t as usize]))).collect())
                    .collect()
            })
            .collect();
        let border_after = edge_uses(&moved).values().filter(|&&u| u == 1).count();
        if border_after >= border_before {
            continue;
        }
        for (r, f) in refs.iter().zip(&moved) {
            w.set_face(r, f);
        }
        total += moves.len();
    }
    bump(counts, names::GAP, total);
    total
}

/// Which border vertex moves onto which (by vertex id).
fn gap_moves(
    faces: &[Vec<Vec<Vx>>],
    uses: &HashMap<(u32, u32), usize>,
    coords: &[P3],
    tol: f64,
    gap: f64,
) -> BTreeMap<u32, u32> {
    let mut border: Vec<u32> = uses.iter().filter(|(_, &u)| u == 1).flat_map(|(e, _)| [e.0, e.1]).collect();
    border.sort_unstable();
    border.dedup();
    let mut faces_of: HashMap<u32, usize> = HashMap::new();
    for f in faces {
        let mut ids: Vec<u32> = f.iter().flatten().map(|v| v.0).collect();
        ids.sort_unstable();
        ids.dedup();
        for id in ids {
            *faces_of.entry(id).or_insert(0) += 1;
        }
    }
    let mut pairs: Vec<(f64, u32, u32)> = Vec::new();
    for (i, &a) in border.iter().enumerate() {
        for &b in &border[i + 1..] {
            let d = norm(&sub(&coords[a as usize], &coords[b as usize]));
            // a pair joined by a short border edge (a T-junction just inserted) collapses it
            if d > tol && d <= gap {
                pairs.push((d, a, b));
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut moves: BTreeMap<u32, u32> = BTreeMap::new();
    let mut fixed: std::collections::HashSet<u32> = std::collections::HashSet::new();
    for (_, a, b) in pairs {
        if moves.contains_key(&a) || moves.contains_key(&b) {
            continue;
        }
        let (fa, fb) = (faces_of.get(&a).copied().unwrap_or(0), faces_of.get(&b).copied().unwrap_or(0));
        let (from, to) = if fa < fb || (fa == fb && a > b) { (a, b) } else { (b, a) };
        if fixed.contains(&from) {
            continue;
        }
        moves.insert(from, to);
        fixed.insert(to);
    }
    moves
}

/// Orients the faces of every shell consistently (by pairing each edge's two uses in opposite
/// directions, spreading from face to face) and outwards (signed volume positive for an
/// exterior shell, negative for a cavity). A shell whose faces cannot be made consistent (an
/// edge used by more than two faces, a one-sided surface) is left as it is.
pub fn orient_shells(w: &mut Work, tol: f64, counts: &mut Counts) -> bool {
    let mut any = false;
    for ci in 0..w.contexts.len() {
        let kind = w.contexts[ci].kind;
        if kind == Kind::Surfaces {
            continue;
        }
        let (_, refs, faces) = w.snap(&w.contexts[ci], tol);
        // a face's rings as the shell uses it (a `-` use runs them the other way)
        let used: Vec<Vec<Vec<Vx>>> =
            refs.iter().zip(&faces).map(|(r, f)| f.iter().map(|ring| oriented(ring, r.reversed)).collect()).collect();
        let Some(flip) = consistent_flips(&used) else { continue };
        let o = used.iter().flatten().flatten().next().map(|v| v.1).unwrap_or([0.0; 3]);
        let volume: f64 =
            used.iter().zip(&flip).map(|(f, &fl)| if fl { -face_volume(f, &o) } else { face_volume(f, &o) }).sum();
        let outward = match kind {
            Kind::Interior => volume < 0.0,
            _ => volume > 0.0,
        };
        let flip: Vec<bool> = flip.iter().map(|&f| if outward { f } else { !f }).collect();
        let n = flip.iter().filter(|&&f| f).count();
        if n == 0 {
            continue;
        }
        if n == flip.len() {
            bump(counts, names::SHELL_ORIENTATION, 1);
        } else {
            bump(counts, names::FACE_ORIENTATION, n);
        }
        for ((r, f), &fl) in refs.iter().zip(&faces).zip(&flip) {
            if fl {
                let rev: Vec<Vec<Vx>> = f.iter().map(|ring| oriented(ring, true)).collect();
                w.set_face(r, &rev);
            }
        }
        any = true;
    }
    any
}

/// A ring as given, or run the other way (first vertex kept first).
fn oriented(ring: &[Vx], reverse: bool) -> Vec<Vx> {
    if !reverse || ring.is_empty() {
        return ring.to_vec();
    }
    std::iter::once(ring[0]).chain(ring[1..].iter().rev().copied()).collect()
}

/// Which faces to turn so that every edge used by two faces is used once each way; `None` when
/// that is impossible or an edge has more than two uses.
fn consistent_flips(faces: &[Vec<Vec<Vx>>]) -> Option<Vec<bool>> {
    let mut uses: HashMap<(u32, u32), Vec<(usize, bool)>> = HashMap::new();
    for (fi, f) in faces.iter().enumerate() {
        for r in f {
            for i in 0..r.len() {
                let (a, b) = (r[i].0, r[(i + 1) % r.len()].0);
                uses.entry((a.min(b), a.max(b))).or_default().push((fi, a < b));
            }
        }
    }
    let mut adj: Vec<Vec<(usize, bool)>> = vec![Vec::new(); faces.len()];
    for u in uses.values() {
        if u.len() > 2 {
            return None;
        }
        if u.len() == 2 && u[0].0 != u[1].0 {
            let same = u[0].1 == u[1].1; // same direction: one of the two must turn
            adj[u[0].0].push((u[1].0, same));
            adj[u[1].0].push((u[0].0, same));
        }
    }
    let mut flip: Vec<Option<bool>> = vec![None; faces.len()];
    for start in 0..faces.len() {
        if flip[start].is_some() {
            continue;
        }
        flip[start] = Some(false);
        let mut stack = vec![start];
        while let Some(f) = stack.pop() {
            let ff = flip[f]?;
            for &(g, same) in &adj[f] {
                let want = ff ^ same;
                match flip[g] {
                    None => {
                        flip[g] = Some(want);
                        stack.push(g);
                    }
                    Some(x) if x != want => return None,
                    _ => {}
                }
            }
        }
    }
    flip.into_iter().collect()
}

/// The face's share of the shell's signed volume: tetrahedra from `o` (the same point for every
/// face of the shell) to a fan of triangles per ring; holes run the other way and subtract.
fn face_volume(f: &[Vec<Vx>], o: &P3) -> f64 {
    let o = *o;
    let mut v = 0.0;
    for r in f {
        if r.len() < 3 {
            continue;
        }
        let a = sub(&r[0].1, &o);
        for i in 1..r.len() - 1 {
            let (b, c) = (sub(&r[i].1, &o), sub(&r[i + 1].1, &o));
            v += dot(&a, &super::ring::cross(&b, &c)) / 6.0;
        }
    }
    v
}
