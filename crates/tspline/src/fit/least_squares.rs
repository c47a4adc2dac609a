//! Least squares (decision A9): the normal equations' pattern, the global and local solves with
//! the regulariser, and the scattered data of the indirect reduction.

use super::*;

/// The normal equations' storage: `crate::sparse`'s symmetric CSR.
pub(super) type Csr = crate::sparse::SymCsr;

use crate::assembly::entry;

/// Pattern: pairs of PB points whose supports overlap with positive area, plus mesh-line
/// neighbours used by the regulariser.
pub(super) fn pattern(pb: &PbSpline, extra: &[Vec<u32>], free: Option<&[bool]>) -> Csr {
    let k = pb.degree.k();
    let n = pb.knots.len();
    let is_free = |i: usize| free.is_none_or(|f| f[i]);
    let first = crate::extraction::first_buckets(pb, true);
    let rows: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if !is_free(i) {
                return vec![i as u32]; // held: z_i = current value
            }
            let a = &pb.knots[i];
            let mut v = Vec::new();
            pb.for_points_in_buckets_once((a[0], a[k + 1]), (a[5], a[5 + k + 1]), &first, |q| {
                let c = &pb.knots[q as usize];
                let ow = a[k + 1].min(c[k + 1]) - a[0].max(c[0]);
                let oh = a[5 + k + 1].min(c[5 + k + 1]) - a[5].max(c[5]);
                if ow > 0.0 && oh > 0.0 {
                    v.push(q);
                }
            });
            v.push(i as u32);
            v.extend_from_slice(&extra[i]);
            v.retain(|&q| is_free(q as usize));
            v.sort_unstable();
            v.dedup();
            v
        })
        .collect();
    let mut start = Vec::with_capacity(n + 1);
    start.push(0);
    for r in &rows {
        start.push(start.last().unwrap() + r.len());
    }
    let cols: Vec<u32> = rows.into_iter().flatten().collect();
    let vals = vec![0.0; cols.len()];
    Csr { start, cols, vals }
}

/// Mesh-line neighbour triples for the regulariser: (left, right, weight_left, weight_right) so
/// that z_i − (wl·z_l + wr·z_r) is the second divided difference (zero on planes).
pub(super) fn line_triples(mesh: &TMesh, pb: &PbSpline) -> Vec<Vec<(u32, u32, f64, f64)>> {
    let h = pb.degree.half();
    let mut pb_of = vec![u32::MAX; mesh.points.len()];
    for (i, &pid) in pb.point_ids.iter().enumerate() {
        pb_of[pid as usize] = i as u32;
    }
    // in parallel: the points are independent, and this ran on the fit's one thread
    (0..pb.knots.len())
        .into_par_iter()
        .map(|i| {
            let kn = &pb.knots[i];
            let p = mesh.points[pb.point_ids[i] as usize];
            let mut v = Vec::new();
            for dim in 0..2 {
                let o = 5 * dim;
                let (lo, c, hi) = (kn[o + h - 1], kn[o + h], kn[o + h + 1]);
                if lo == c || hi == c {
                    continue;
                }
                let (a, b) = if dim == 0 { ((lo, p.t), (hi, p.t)) } else { ((p.s, lo), (p.s, hi)) };
                let (Some(pa), Some(pbb)) = (mesh.point_id_at(a.0, a.1), mesh.point_id_at(b.0, b.1)) else { continue };
                let (ia, ib) = (pb_of[pa as usize], pb_of[pbb as usize]);
                if ia == u32::MAX || ib == u32::MAX {
                    continue;
                }
                let wl = (hi - c) / (hi - lo);
                let wr = (c - lo) / (hi - lo);
                v.push((ia, ib, wl, wr));
            }
            v
        })
        .collect()
}

/// Least-squares geometry fit (spec §4.5, eq. 4.35 with W = 1 ⇒ ordinary least squares with the
/// rational basis): z of every PB point; the current z are the warm start and the regulariser's
/// prior. Returns the new z per PB point.
pub fn fit_lsq(mesh: &TMesh, pb: &PbSpline, samples: &Samples) -> Result<Vec<f64>, TsplineError> {
    fit_lsq_local(LsqProblem::global(mesh, samples), pb)
}

/// [`fit_lsq`] with the rows of the model matrix computed by the OpenCL kernel (spec T29,
/// [`crate::ocl_fit`]) block by block when `asm` is given; the host accumulates the normal
/// equations from them (the matrix is never stored whole).
pub fn fit_lsq_with(
    mesh: &TMesh,
    pb: &PbSpline,
    samples: &Samples,
    asm: Option<&crate::ocl_fit::OclModel>,
) -> Result<Vec<f64>, TsplineError> {
    fit_lsq_local(LsqProblem { asm, ..LsqProblem::global(mesh, samples) }, pb)
}

/// One least-squares problem on a mesh: its data (a raster, or scattered points in its
/// parameters), the points solved for (`free`; None: all, the others keep their heights), the
/// raster cells whose data enter (`region`; None: all) and the OpenCL model rows (`asm`, used
/// for the global raster assembly only).
#[derive(Clone, Copy)]
pub(crate) struct LsqProblem<'a> {
    pub mesh: &'a TMesh,
    pub samples: &'a Samples,
    pub pts: Option<&'a Scattered>,
    pub free: Option<&'a [bool]>,
    pub region: Option<&'a Region>,
    pub asm: Option<&'a crate::ocl_fit::OclModel>,
}

impl<'a> LsqProblem<'a> {
    /// Every point free, every raster cell, on the CPU.
    pub fn global(mesh: &'a TMesh, samples: &'a Samples) -> LsqProblem<'a> {
        LsqProblem { mesh, samples, pts: None, free: None, region: None, asm: None }
    }
}

/// Writes fitted heights (PB order) into the mesh and the PB-spline.
pub(crate) fn set_z(mesh: &mut TMesh, pb: &mut PbSpline, z: &[f64]) {
    for (i, &pid) in pb.point_ids.iter().enumerate() {
        mesh.points[pid as usize].z = z[i];
        pb.geom[i][2] = z[i];
    }
}

/// Scattered data in parameter units: positions and values (indirect reduction: the ORIGINAL
/// raster cells mapped forward into the warped frame, so the fit and its tolerance check work
/// on the original values at their warped positions, not on a resampled and dilated raster).
#[derive(Debug, Clone, Default)]
pub struct Scattered {
    pub st: Vec<[f64; 2]>,
    pub z: Vec<f64>,
}

/// A set of raster cells (bit per cell, row-major from t = 0).
#[derive(Debug, Clone)]
pub struct Region {
    w: usize,
    h: usize,
    bits: Vec<u64>,
    count: usize,
}

impl Region {
    pub fn new(w: usize, h: usize) -> Region {
        Region { w, h, bits: vec![0; (w * h).div_ceil(64)], count: 0 }
    }
    /// Adds the cells with s ∈ [s0, s1], t ∈ [t0, t1] (closed, clipped to the raster).
    pub fn add_rect(&mut self, s0: f64, s1: f64, t0: f64, t1: f64) {
        let i0 = s0.ceil().max(0.0);
        let i1 = s1.floor().min(self.w as f64 - 1.0);
        let j0 = t0.ceil().max(0.0);
        let j1 = t1.floor().min(self.h as f64 - 1.0);
        if i0 > i1 || j0 > j1 {
            return;
        }
        let (i0, i1) = (i0 as usize, i1 as usize);
        for j in j0 as usize..=j1 as usize {
            self.add_run(j * self.w + i0, j * self.w + i1 + 1);
        }
    }
    /// Adds the cells q0..q1 (one row's run) a word at a time: a local update adds the
    /// supports of 10⁴ free points, ~10³ cells each, on the fit's one thread.
    fn add_run(&mut self, q0: usize, q1: usize) {
        let mut q = q0;
        while q < q1 {
            let (wd, lo) = (q / 64, q % 64);
            let hi = (q1 - wd * 64).min(64);
            let mask = if hi - lo == 64 { u64::MAX } else { ((1u64 << (hi - lo)) - 1) << lo };
            self.count += (mask & !self.bits[wd]).count_ones() as usize;
            self.bits[wd] |= mask;
            q = wd * 64 + hi;
        }
    }
    #[inline]
    pub fn contains(&self, q: usize) -> bool {
        self.bits[q / 64] & (1u64 << (q % 64)) != 0
    }
    pub fn len(&self) -> usize {
        self.count
    }
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// Calls `f(q)` for the cells of rows j0..j1 in the set, in order (skips empty words).
    pub(crate) fn for_rows(&self, j0: usize, j1: usize, mut f: impl FnMut(usize)) {
        let (q0, q1) = (j0 * self.w, j1 * self.w);
        let mut q = q0;
        while q < q1 {
            let wd = self.bits[q / 64];
            if wd == 0 && q % 64 == 0 {
                q += 64;
                continue;
            }
            if wd & (1u64 << (q % 64)) != 0 {
                f(q);
            }
            q += 1;
        }
    }
}

/// [`fit_lsq`] with some control points held (`free[i] == false`: z_i stays at its current
/// value, its data terms move to the right-hand side) and the data restricted to `region` (the
/// supports of the free points; cells outside do not depend on them).
pub(crate) fn fit_lsq_local(p: LsqProblem<'_>, pb: &PbSpline) -> Result<Vec<f64>, TsplineError> {
    assemble(p, pb)?.solve(p.free)
}

/// [`fit_lsq_local`] that needs `pb` only until the normal equations are assembled: on a
/// raster of [`TRIM_CELLS`] cells or more it keeps only the PB-spline's points and knots
/// through the solve and compiles the rest again afterwards (the same PB-spline, bit for bit),
/// so that it and the Cholesky factor are not alive together
/// (docs/decisions.md#knots-only-through-the-solve).
pub(crate) fn fit_lsq_released(p: LsqProblem<'_>, pb: PbSpline) -> Result<(Vec<f64>, PbSpline), TsplineError> {
    let (mesh, samples, free) = (p.mesh, p.samples, p.free);
    let normal = assemble(p, &pb)?;
    if samples.z.len() < TRIM_CELLS {
        return Ok((normal.solve(free)?, pb));
    }
    let parts = pb.into_knots();
    release_free_memory(samples.z.len());
    let z = normal.solve(free)?;
    // the solve's arrays go back before the PB-spline and the error pass take memory again
    release_free_memory(samples.z.len());
    Ok((z, PbSpline::from_knots(mesh, parts)))
}

/// The assembled normal equations with the regulariser, and the current heights (the held
/// points' values and the iterative solver's warm start).
pub(crate) struct Normal {
    a: Csr,
    rhs: Vec<f64>,
    prior: Vec<f64>,
    /// Raster cells of the fit (whether the solver's workspace is kept for the next solve).
    cells: usize,
}

impl Normal {
    fn solve(self, free: Option<&[bool]>) -> Result<Vec<f64>, TsplineError> {
        let Normal { a, rhs, prior, cells } = self;
        let z = match free {
            Some(f) => solve_free(&a, &rhs, &prior, f),
            None => solve(&a, &rhs, &prior),
        };
        release_solver_workspace(cells);
        z
    }
}

fn assemble(p: LsqProblem<'_>, pb: &PbSpline) -> Result<Normal, TsplineError> {
    let LsqProblem { mesh, samples, pts, free, region, asm } = p;
    let n = pb.knots.len();
    // device rows only for the global raster assembly
    let asm = match (pts, region, asm) {
        (None, None, Some(o)) => Some((o, o.upload(pb)?)),
        _ => None,
    };
    let is_free = |i: usize| free.is_none_or(|f| f[i]);
    let triples = line_triples(mesh, pb);
    // The regulariser couples i, l and r of each triple: all pairs enter the pattern.
    let mut extra: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (i, ts) in triples.iter().enumerate() {
        for &(l, r, _, _) in ts {
            let ids = [i as u32, l, r];
            for &x in &ids {
                for &y in &ids {
                    if x != y {
                        extra[x as usize].push(y);
                    }
                }
            }
        }
    }
    let mut a = pattern(pb, &extra, free);
    drop(extra);
    let prior: Vec<f64> = pb.geom.iter().map(|g| g[2]).collect();
    let sys = crate::assembly::System { pattern: &a, pb, free, prior: &prior };
    // The symbolic factorisation needs only the pattern of the system solved (the free block
    // for a local update): it is built on the pool while the values are assembled, instead of
    // on this thread after them (it was ~15 % of this thread's time on the BAG at 0.1 m,
    // BENCHMARKS.md "Fit CPU on the largest mesh, again: bit-identical levers"); the same
    // ordering, so the same bits.
    let block = free.map(|f| free_block_pattern(&a, f));
    let (b_start, b_cols) = block.as_ref().map_or((&a.start[..], &a.cols[..]), |(s, c)| (&s[..], &c[..]));
    let on_cpu = || match pts {
        None => Ok(crate::assembly::by_elements(sys, samples, region)),
        Some(_) => crate::assembly::per_cell(sys, samples, pts, region, None),
    };
    let (symbolic, sums) = match &asm {
        Some((o, sp)) => (None, crate::assembly::per_cell(sys, samples, pts, region, Some((*o, sp)))),
        None if crate::sparse::symbolic_needed(b_start, b_cols) => {
            rayon::join(|| sparse_spd::cholesky_symbolic(b_start, b_cols).ok(), on_cpu)
        }
        None => (None, on_cpu()),
    };
    let sums = sums?;
    if let Some(s) = symbolic {
        sparse_spd::install_symbolic(s);
    }
    drop(block);
    let crate::assembly::Sums { vals, mut rhs, support } = sums;
    a.vals = vals;
    mirror_upper(&mut a);
    let diag: Vec<f64> = (0..n).map(|i| a.vals[entry(&a, i, i as u32)]).collect();
    let supported: Vec<f64> = (0..n).filter(|&i| is_free(i) && diag[i] > 0.0).map(|i| diag[i]).collect();
    if supported.is_empty() {
        return Err(TsplineError::Fit("no valid raster cell lies inside the mesh".into()));
    }
    let mean_diag = supported.iter().sum::<f64>() / supported.len() as f64;
    drop(supported);
    // A9 regulariser
    for i in 0..n {
        if !is_free(i) {
            let pii = entry(&a, i, i as u32);
            a.vals[pii] = 1.0;
            rhs[i] = prior[i];
            continue;
        }
        let lack = (1.0 - support[i] / 0.5).max(0.0);
        let lam = 1e-3 * mean_diag * lack * lack;
        // ridge: tiny everywhere, stronger where data is lacking
        let ridge = 1e-12 * diag[i].max(mean_diag * 1e-6) + 1e-6 * lam;
        let pii = entry(&a, i, i as u32);
        a.vals[pii] += ridge;
        rhs[i] += ridge * prior[i];
        if lam == 0.0 {
            continue;
        }
        for &(l, r, wl, wr) in &triples[i] {
            // λ (z_i − wl z_l − wr z_r)²
            let idx = [i as u32, l, r];
            let c = [1.0, -wl, -wr];
            for x in 0..3 {
                if !is_free(idx[x] as usize) {
                    continue;
                }
                for y in 0..3 {
                    if is_free(idx[y] as usize) {
                        let p = entry(&a, idx[x] as usize, idx[y]);
                        a.vals[p] += lam * c[x] * c[y];
                    } else {
                        rhs[idx[x] as usize] -= lam * c[x] * c[y] * prior[idx[y] as usize];
                    }
                }
            }
        }
    }
    // what the solve does not read goes before the factor is built (the solve's memory is the
    // fit's peak at 10⁸ cells: BENCHMARKS.md "Peak memory per cell without the copies")
    drop((triples, diag, support));
    release_free_memory(samples.z.len());
    Ok(Normal { a, rhs, prior, cells: samples.z.len() })
}

/// The sparse solve; the current heights are the iterative fallback's warm start.
pub(super) fn solve(a: &Csr, rhs: &[f64], prior: &[f64]) -> Result<Vec<f64>, TsplineError> {
    let (z, _info) =
        crate::sparse::solve_spd(a, rhs, prior).map_err(|e| TsplineError::Fit(format!("least squares: {e}")))?;
    Ok(z)
}

/// Copies the accumulated upper triangle onto the lower one. The pattern is symmetric, so
/// visiting rows in order meets the lower entries of each row j in column order: a cursor per
/// row finds the mirror position without a search.
pub(super) fn mirror_upper(a: &mut Csr) {
    let n = a.n();
    let mut cursor: Vec<usize> = a.start[..n].to_vec();
    for i in 0..n {
        for k in a.start[i]..a.start[i + 1] {
            let j = a.cols[k] as usize;
            if j > i {
                let m = cursor[j];
                debug_assert_eq!(a.cols[m] as usize, i, "symmetric pattern");
                a.vals[m] = a.vals[k];
                cursor[j] += 1;
            }
        }
    }
}

/// The pattern of [`solve_free`]'s free block (rows of the free points, columns renumbered in
/// order): what its Cholesky factorises.
fn free_block_pattern(a: &Csr, free: &[bool]) -> (Vec<usize>, Vec<u32>) {
    let n = a.n();
    let mut new_of = vec![u32::MAX; n];
    let mut q = 0u32;
    for i in (0..n).filter(|&i| free[i]) {
        new_of[i] = q;
        q += 1;
    }
    let mut start = Vec::with_capacity(q as usize + 1);
    let mut cols = Vec::new();
    start.push(0);
    for i in (0..n).filter(|&i| free[i]) {
        cols.extend(a.cols[a.start[i]..a.start[i + 1]].iter().map(|&c| new_of[c as usize]));
        start.push(cols.len());
    }
    (start, cols)
}

/// The solve of a local update: the held points' rows are identities (z = prior) and no free
/// row refers to a held point, so only the free block is factorised. Why: a local update holds
/// most points, and the ordering, symbolic and numeric factorisation of the whole system cost
/// in proportion to all of them (the held rows were 0.8 of a Kilauea 5 m solve's unknowns).
pub(super) fn solve_free(a: &Csr, rhs: &[f64], prior: &[f64], free: &[bool]) -> Result<Vec<f64>, TsplineError> {
    let n = a.n();
    let mut new_of = vec![u32::MAX; n];
    let ids: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
    for (q, &i) in ids.iter().enumerate() {
        new_of[i] = q as u32;
    }
    let mut sub = Csr { start: Vec::with_capacity(ids.len() + 1), cols: Vec::new(), vals: Vec::new() };
    sub.start.push(0);
    for &i in &ids {
        for k in a.start[i]..a.start[i + 1] {
            sub.cols.push(new_of[a.cols[k] as usize]);
            sub.vals.push(a.vals[k]);
        }
        sub.start.push(sub.cols.len());
    }
    let pick = |v: &[f64]| ids.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let zf = solve(&sub, &pick(rhs), &pick(prior))?;
    let mut z = prior.to_vec();
    for (&i, v) in ids.iter().zip(zf) {
        z[i] = v;
    }
    Ok(z)
}
