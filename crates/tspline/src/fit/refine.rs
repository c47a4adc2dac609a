//! What changes after a refinement: the local update's re-solved points and cells, and the
//! refinement itself (quad or anisotropic splits, docs/decisions.md#anisotropic-splits-issue-19).

use super::*;

/// Share of the PB points whose basis changed (new, or other knots) up to which an iteration
/// re-solves and re-checks locally instead of globally.
pub(super) const LOCAL_SHARE: f64 = 0.2;

/// PB points from which a least-squares system is a large one: its sparse factorisation, not
/// the raster cells, sets an iteration's time (BAG at 0.1 m: 0.2–0.6 s a solve at 3–5·10⁴
/// points; at 3·10³ points a few ms), so a local update pays whenever its free block is
/// clearly smaller than the whole, however many cells it re-checks
/// (docs/decisions.md#large-systems-solve-locally-issue-19).
pub(super) const LARGE_SYSTEM: usize = 10_000;

/// For a large system: the share of changed points up to which a local update is worked out,
/// and the share of free points (changed ones and those their supports overlap) up to which
/// it is taken. Above half the basis changed, the free block is nearly every point (BAG 0.1 m:
/// 62 % changed → 97 % free; Kilauea 5 m: 62 % → 90 %).
pub(super) const LARGE_LOCAL_SHARE: f64 = 0.5;
pub(super) const LARGE_FREE_SHARE: f64 = 0.7;

/// The local update after a refinement (an optimisation of the loop, not of the result's
/// guarantee): points whose blending function changed (new points, changed knots) and every
/// point whose support overlaps theirs are re-solved with the others held; the surface changes
/// only inside the supports of the re-solved points, so only those cells are re-checked.
/// Returns None when the change is too large for that to pay (the iteration goes global):
/// on a small system when more than [`LOCAL_SHARE`] of the basis changed or the re-checked
/// cells are more than half the raster; on a [`LARGE_SYSTEM`] when more than
/// [`LARGE_LOCAL_SHARE`] changed or more than [`LARGE_FREE_SHARE`] of the points are free.
pub(crate) fn local_update(
    old: &PbSpline,
    new: &PbSpline,
    n_points: usize,
    w: usize,
    h: usize,
) -> Option<(Vec<bool>, Region)> {
    let n = new.knots.len();
    let large = n >= large_system();
    let mut old_of = vec![u32::MAX; n_points];
    for (i, &pid) in old.point_ids.iter().enumerate() {
        old_of[pid as usize] = i as u32;
    }
    let changed: Vec<bool> = (0..n)
        .map(|i| {
            let o = old_of[new.point_ids[i] as usize];
            o == u32::MAX || old.knots[o as usize] != new.knots[i] || old.geom[o as usize][3] != new.geom[i][3]
        })
        .collect();
    // points of `old` gone from `new` (coarsening): the surface changes over their old supports
    let mut in_new = vec![false; n_points];
    for &pid in &new.point_ids {
        in_new[pid as usize] = true;
    }
    let k = new.degree.k();
    let removed: Vec<(f64, f64, f64, f64)> = (0..old.knots.len())
        .filter(|&o| !in_new[old.point_ids[o] as usize])
        .map(|o| {
            let a = &old.knots[o];
            (a[0], a[k + 1], a[5], a[5 + k + 1])
        })
        .collect();
    let nu = changed.iter().filter(|&&c| c).count() + removed.len();
    let share = if large { LARGE_LOCAL_SHARE } else { LOCAL_SHARE };
    if nu == 0 || nu as f64 > share * n as f64 {
        return None;
    }
    let supp = |i: usize| {
        let a = &new.knots[i];
        (a[0], a[k + 1], a[5], a[5 + k + 1])
    };
    let lists: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .filter(|&i| changed[i])
        .map(|i| {
            let (s0, s1, t0, t1) = supp(i);
            let (i0, i1) = new.grid.index_range(s0, s1, true);
            let (j0, j1) = new.grid.index_range(t0, t1, false);
            let mut v = vec![i as u32];
            for bj in j0..=j1 {
                for bi in i0..=i1 {
                    let b = (bj * new.grid.ns + bi) as usize;
                    for &q in &new.pt_items[new.pt_start[b] as usize..new.pt_start[b + 1] as usize] {
                        let (a0, a1, b0, b1) = supp(q as usize);
                        if s1.min(a1) - s0.max(a0) > 0.0 && t1.min(b1) - t0.max(b0) > 0.0 {
                            v.push(q);
                        }
                    }
                }
            }
            v
        })
        .collect();
    let mut free = vec![false; n];
    for l in &lists {
        for &q in l {
            free[q as usize] = true;
        }
    }
    if large && free.iter().filter(|&&f| f).count() as f64 > LARGE_FREE_SHARE * n as f64 {
        return None;
    }
    let mut region = Region::new(w, h);
    for i in (0..n).filter(|&i| free[i]) {
        let (s0, s1, t0, t1) = supp(i);
        region.add_rect(s0, s1, t0, t1);
    }
    for &(s0, s1, t0, t1) in &removed {
        region.add_rect(s0, s1, t0, t1);
    }
    if !large && region.len() * 2 > w * h {
        return None;
    }
    #[cfg(test)]
    if region.len() * 2 > w * h {
        tests::LARGE_REGIONS.set(tests::LARGE_REGIONS.get() + 1);
    }
    Some((free, region))
}

/// [`LARGE_SYSTEM`], or in a test the size it sets (so that a small raster takes the path).
fn large_system() -> usize {
    #[cfg(test)]
    return tests::LARGE_FROM.get();
    #[cfg(not(test))]
    LARGE_SYSTEM
}

pub(crate) enum Refined {
    Stop(StopReason),
    /// The refined mesh and the number of cells marked and split.
    Next(TMesh, usize),
}

/// One refinement: split the splittable leaves over the tolerance, repair; or the reason to
/// stop (minimum cell size, control-point cap). [`SplitRule::Anisotropic`]: each leaf is split
/// as [`split_direction`] chooses from the residual inside it.
pub(crate) fn refine(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    opts: &FitOptions,
    over_leaves: Vec<CellId>,
    err: &ErrorStats,
) -> Result<Refined, TsplineError> {
    let mut marked = over_leaves;
    marked.sort_unstable();
    marked.dedup();
    let can_split = |c: CellId| {
        let r = mesh.cells[c as usize].rect;
        match opts.split {
            SplitRule::Quad => r.width().min(r.height()) >= 2.0,
            SplitRule::Anisotropic => r.width().max(r.height()) >= 2.0,
        }
    };
    if opts.split == SplitRule::Anisotropic {
        // A leaf at the minimum size that is still over the tolerance has no split left; its
        // surface there is set by the blending functions of the leaves around it, which 2-splits
        // may have left long (a 1:2 balance only along the shared side): those leaves (closed
        // boxes that touch it) are split instead (docs/decisions.md#anisotropic-splits-issue-19).
        let stuck: Vec<CellId> = marked.iter().copied().filter(|&c| !can_split(c)).collect();
        for c in stuck {
            marked.extend(mesh.leaves_in(mesh.cells[c as usize].rect).into_iter().filter(|&n| can_split(n)));
        }
        marked.sort_unstable();
        marked.dedup();
    }
    let splittable: Vec<CellId> = marked.into_iter().filter(|&c| can_split(c)).collect();
    if splittable.is_empty() {
        return Ok(Refined::Stop(StopReason::MinCellSize { cells_over: err.over_tolerance }));
    }
    let dirs: Vec<SplitDir> = match opts.split {
        SplitRule::Quad => vec![SplitDir::Quad; splittable.len()],
        SplitRule::Anisotropic => splittable
            .par_iter()
            .map(|&c| split_direction(pb, samples, mesh.cells[c as usize].rect, opts.max_error))
            .collect(),
    };
    let mut next = mesh.clone();
    let mut geom = |s: f64, t: f64| {
        (s, t, {
            let z = pb.point(s, t)[2];
            if z.is_nan() {
                0.0
            } else {
                z
            }
        })
    };
    for (&c, &dir) in splittable.iter().zip(&dirs) {
        if next.cells[c as usize].is_leaf() {
            next.split_dir(c, dir, &mut geom);
        }
    }
    next.repair_with(1.0, opts.split, &mut geom);
    next.shrink_to_fit();
    if let Some(cap) = opts.max_points {
        let n = next.active_points().iter().filter(|a| **a).count();
        if n > cap {
            return Ok(Refined::Stop(StopReason::MaxPoints { cap }));
        }
    }
    Ok(Refined::Next(next, splittable.len()))
}

/// How much more one split direction must explain than the other to be chosen alone.
pub(super) const ANISO_RATIO: f64 = 1.5;

/// A leaf whose residual (on the cells [`kink_gains`] looks at) reaches this many times the
/// tolerance is split into four: it is too coarse in both directions, and the kinks' direction
/// means something only near the tolerance (measured: BENCHMARKS.md, anisotropic refinement).
pub(super) const ANISO_FAR: f64 = 4.0;

/// Raster cells per side of a leaf that [`kink_gains`] looks at, at most.
pub(super) const KINK_SAMPLES: f64 = 24.0;

/// The anisotropic split of a leaf `r` over the tolerance, chosen from the residual
/// e = data − surface at the valid raster cells in its closed box: with u, v the cell's
/// coordinates scaled to [−1, 1], the least-squares fit of e by {1, u, v, uv} is compared with
/// the fits that add a kink at the s mid-point ({|u|, |u|v}: what a knot line across s adds) and
/// at the t mid-point ({|v|, u|v|}). A 4-split where |e| reaches [`ANISO_FAR`] times the
/// tolerance `e_max`; else a 2-split across the direction whose kink explains [`ANISO_RATIO`]
/// times more of e than the other's; else a 4-split. A side shorter than 2
/// (the sample spacing, spec §2.2) is not halved; the aspect stays at most
/// [`crate::mesh::MAX_ASPECT`]. docs/decisions.md#anisotropic-splits-issue-19
pub(crate) fn split_direction(pb: &PbSpline, samples: &Samples, r: Rect, e_max: f64) -> SplitDir {
    let (w, h) = (r.width(), r.height());
    let can_s = w >= 2.0;
    let can_t = h >= 2.0;
    let dir = match (can_s, can_t) {
        (false, false) | (true, true) => {
            let (gs, gt, emax) = kink_gains(pb, samples, r);
            if emax > ANISO_FAR * e_max {
                SplitDir::Quad
            } else if gs > ANISO_RATIO * gt {
                SplitDir::S
            } else if gt > ANISO_RATIO * gs {
                SplitDir::T
            } else {
                SplitDir::Quad
            }
        }
        (true, false) => return SplitDir::S,
        (false, true) => return SplitDir::T,
    };
    crate::mesh::aspect_capped(&r, dir, 1.0)
}

/// (SSE explained by the s kink, by the t kink, max |e|) of the residual in `r` (see
/// [`split_direction`]).
pub(super) fn kink_gains(pb: &PbSpline, samples: &Samples, r: Rect) -> (f64, f64, f64) {
    let sm = 0.5 * (r.s_min + r.s_max);
    let tm = 0.5 * (r.t_min + r.t_max);
    let (hw, hh) = (0.5 * r.width(), 0.5 * r.height());
    let i0 = r.s_min.ceil().max(0.0);
    let j0 = r.t_min.ceil().max(0.0);
    let i1 = r.s_max.floor().min(samples.width as f64 - 1.0);
    let j1 = r.t_max.floor().min(samples.height as f64 - 1.0);
    // Gram of the 8 functions [1, u, v, uv, |u|, |u|v, |v|, u|v|] and their moments with e
    let mut g = [[0.0f64; 8]; 8];
    let mut m = [0.0f64; 8];
    let mut ee = 0.0;
    let mut emax = 0.0f64;
    if i1 >= i0 && j1 >= j0 {
        // at most KINK_SAMPLES² cells of a large leaf (a regular subsample): the direction of a
        // coarse leaf's residual does not need every cell, and early iterations mark most of
        // the raster
        let step = |n: f64| ((n / KINK_SAMPLES).ceil() as usize).max(1);
        let (si, sj) = (step(i1 - i0 + 1.0), step(j1 - j0 + 1.0));
        for j in (j0 as usize..=j1 as usize).step_by(sj) {
            let v = (j as f64 - tm) / hh;
            for i in (i0 as usize..=i1 as usize).step_by(si) {
                let d = samples.get(i, j);
                if d.is_nan() {
                    continue;
                }
                let z = pb.point(i as f64, j as f64)[2];
                if !z.is_finite() {
                    continue;
                }
                let e = d - z;
                emax = emax.max(e.abs());
                let u = (i as f64 - sm) / hw;
                let f = [1.0, u, v, u * v, u.abs(), u.abs() * v, v.abs(), u * v.abs()];
                for a in 0..8 {
                    m[a] += f[a] * e;
                    for b in a..8 {
                        g[a][b] += f[a] * f[b];
                    }
                }
                ee += e * e;
            }
        }
    }
    let explained = |idx: &[usize]| -> f64 {
        // bᵀ G⁻¹ b on the subset (a tiny ridge keeps a rank-deficient subset solvable)
        let n = idx.len();
        let mut a = vec![vec![0.0f64; n + 1]; n];
        for (p, &ia) in idx.iter().enumerate() {
            for (q, &ib) in idx.iter().enumerate() {
                a[p][q] = if ia <= ib { g[ia][ib] } else { g[ib][ia] };
            }
            a[p][p] += 1e-9 * (1.0 + g[ia][ia]);
            a[p][n] = m[ia];
        }
        for col in 0..n {
            let piv = (col..n).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs())).unwrap_or(col);
            a.swap(col, piv);
            let d = a[col][col];
            if d.abs() < 1e-300 {
                continue;
            }
            let (top, below) = a.split_at_mut(col + 1);
            let pivot = &top[col];
            for r in below.iter_mut() {
                let f = r[col] / d;
                for (x, p) in r[col..].iter_mut().zip(&pivot[col..]) {
                    *x -= f * p;
                }
            }
        }
        let mut x = vec![0.0f64; n];
        for row in (0..n).rev() {
            let d = a[row][row];
            if d.abs() < 1e-300 {
                continue;
            }
            let mut acc = a[row][n];
            for k in row + 1..n {
                acc -= a[row][k] * x[k];
            }
            x[row] = acc / d;
        }
        idx.iter().zip(&x).map(|(&i, xi)| m[i] * xi).sum::<f64>().clamp(0.0, ee)
    };
    let base = explained(&[0, 1, 2, 3]);
    let gs = (explained(&[0, 1, 2, 3, 4, 5]) - base).max(0.0);
    let gt = (explained(&[0, 1, 2, 3, 6, 7]) - base).max(0.0);
    (gs, gt, emax)
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use crate::fit::{eval_errors, fit, Backend, FitOptions, Samples};
    use crate::mesh::Degree;
    use crate::testing::lcg;

    thread_local! {
        /// The system size from which [`super::local_update`] uses the large system's rules.
        pub(super) static LARGE_FROM: Cell<usize> = const { Cell::new(super::LARGE_SYSTEM) };
        /// Local updates taken whose re-checked region is more than half the raster (only a
        /// large system's rules take them).
        pub(super) static LARGE_REGIONS: Cell<usize> = const { Cell::new(0) };
    }

    /// Ridges and noise on a slope: refinement spreads over the whole raster, so later
    /// iterations change a few percent of the basis but re-check most cells.
    fn ridges(w: usize, h: usize) -> Samples {
        let mut seed = 7u64;
        let z: Vec<f64> = (0..w * h)
            .map(|q| {
                let (x, y) = ((q % w) as f64, (q / w) as f64);
                let noise = (lcg(&mut seed) - 0.5) * 0.2;
                3.0 * (x * 0.11 + y * 0.05).sin() + 1.5 * (y * 0.13).cos() * (x * 0.02).sin() + 0.03 * x + noise
            })
            .collect();
        Samples { width: w, height: h, z: z.into() }
    }

    /// The large system's rules (local updates whose region is most of the raster) give a fit
    /// that meets the tolerance at every cell, checked here from the output mesh alone, with
    /// about the control points of the small system's rules (a local solve holds points the
    /// global one would move a little).
    #[test]
    fn large_system_local_updates_keep_the_guarantee() {
        let s = ridges(110, 90);
        let e = 0.12;
        for degree in [Degree::Linear, Degree::Cubic] {
            let run = |large_from: usize| {
                LARGE_FROM.set(large_from);
                LARGE_REGIONS.set(0);
                let r = fit(&s, &FitOptions::new(degree, e), &Backend::Cpu, &mut |_| {}).unwrap();
                LARGE_FROM.set(super::LARGE_SYSTEM);
                (r, LARGE_REGIONS.get())
            };
            let (small, k_small) = run(usize::MAX);
            let (large, k_large) = run(0);
            assert_eq!(k_small, 0, "{degree:?}: a small system took a region of more than half the raster");
            assert!(
                k_large > 0,
                "{degree:?}: no local update with a large region: the test does not exercise the rule"
            );
            let n_small = small.iterations.last().unwrap().control_points;
            let n_large = large.iterations.last().unwrap().control_points;
            assert!(
                n_large.abs_diff(n_small) * 50 <= n_small,
                "{degree:?}: {n_large} against {n_small} control points"
            );
            let pb = crate::eval::PbSpline::build(&large.mesh);
            assert_eq!(pb.point_ids.len(), n_large);
            let mut errs = vec![0.0; s.z.len()];
            eval_errors(&pb, &s, &Backend::Cpu, &mut errs).unwrap();
            let max = errs.iter().cloned().fold(0.0, f64::max);
            assert!(max <= e, "{degree:?}: max |dz| {max} with the large system's rules");
        }
    }
}
