//! A cheap screen run before the validator: most buildings of a city model have nothing the
//! repairs act on, and validating each one twice (here and in the heal's own measures) would cost
//! heal about a third more CPU time (NRW tile 332_5729: validation 0.05 s, heal 0.17 s user
//! time). Every finding the repairs can remove leaves a trace the screen sees: a ring that runs
//! through one vertex twice (102, 104 pinches and keyholes, 101), a shell edge not used exactly
//! twice in opposite directions (302, 307, and 104 spikes and folds inside a shell), or a shell
//! whose signed volume has the wrong sign (405).

use super::ring::{cross, dot, sub, Vx};
use super::work::{Kind, Work};
use std::collections::HashMap;

/// Does any ring repeat a vertex?
fn repeats(faces: &[Vec<Vec<Vx>>]) -> bool {
    faces.iter().flatten().any(|r| {
        let mut ids: Vec<u32> = r.iter().map(|v| v.0).collect();
        let n = ids.len();
        ids.sort_unstable();
        ids.dedup();
        ids.len() != n || n < 3
    })
}

/// Is any edge of the shell used other than exactly twice in opposite directions, or does the
/// shell point the wrong way?
fn open_or_turned(faces: &[Vec<Vec<Vx>>], kind: Kind) -> bool {
    let mut uses: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    let mut volume = 0.0;
    let o = faces.iter().flatten().flatten().next().map(|v| v.1).unwrap_or([0.0; 3]);
    for r in faces.iter().flatten() {
        for i in 0..r.len() {
            let (a, b) = (r[i].0, r[(i + 1) % r.len()].0);
            let e = uses.entry((a.min(b), a.max(b))).or_insert((0, 0));
            if a < b {
                e.0 += 1;
            } else {
                e.1 += 1;
            }
        }
        if r.len() >= 3 {
            let p = sub(&r[0].1, &o);
            for i in 1..r.len() - 1 {
                volume += dot(&p, &cross(&sub(&r[i].1, &o), &sub(&r[i + 1].1, &o)));
            }
        }
    }
    let wrong_way = match kind {
        Kind::Interior => volume > 0.0,
        _ => volume < 0.0,
    };
    wrong_way || uses.values().any(|&u| u != (1, 1))
}

/// Whether the building may have a finding the repairs act on (false: it certainly has none).
pub fn suspect(w: &Work, tol: f64) -> bool {
    w.polys.iter().any(|p| p.frozen)
        || w.contexts.iter().any(|c| {
            let (_, _, faces) = w.snap(c, tol);
            repeats(&faces) || (c.kind != Kind::Surfaces && open_or_turned(&faces, c.kind))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(ids: [u32; 4], pts: [[f64; 3]; 4]) -> Vec<Vec<Vx>> {
        vec![ids.iter().zip(pts).map(|(i, p)| (*i, p)).collect()]
    }

    #[test]
    fn a_closed_outward_tetrahedron_passes_and_a_turned_one_does_not() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let tri = |a: usize, b: usize, c: usize| vec![vec![(a as u32, p[a]), (b as u32, p[b]), (c as u32, p[c])]];
        let faces = vec![tri(0, 2, 1), tri(0, 1, 3), tri(1, 2, 3), tri(0, 3, 2)];
        assert!(!open_or_turned(&faces, Kind::Exterior));
        assert!(open_or_turned(&faces, Kind::Interior));
        assert!(open_or_turned(&faces[..3], Kind::Exterior));
        assert!(!repeats(&faces));
        let pinched = quad([0, 1, 0, 2], [p[0], p[1], p[0], p[2]]);
        assert!(repeats(&[pinched]));
    }
}
