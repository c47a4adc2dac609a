//! Discrete Smooth Interpolation on a tetrahedral mesh (seed appendix A) with the base + float
//! split of the constraints (seed §3).
//!
//! Every constraint c is one linear row `A_cᵗ·φ ≃ b_c` over the mesh nodes, normalised and
//! weighted as in seed eq. 9 (`A_c ← ϖ_c/‖A_c‖·A_c`, same for `b_c`), so ϖ_c² is its relative
//! weight. Classes:
//! - value ("boundary") constraints: φ(p) = v, with φ(p) the barycentric combination of the four
//!   nodes of the tetrahedron holding p;
//! - inequality constraints from normals, a small step δ along and against the normal:
//!   φ(p + δn) ≥ v + δg and φ(p − δn) ≤ v − δg (g: expected gradient magnitude; without a value
//!   at p, φ(p + δn) − φ(p − δn) ≥ 2δg), and from side points: s·φ(p) ≥ δg. They are soft and
//!   one-sided: a row counts only while violated (an active-set loop re-solves until the set of
//!   violated rows stops changing or the round cap is hit);
//! - the roughness constraint on the gradient across the mesh graph: for each interior face the
//!   jump of ∂φ/∂n between its two tetrahedra ≃ 0 (Frank, Tertois & Mallet 2007's "constant
//!   gradient" criterion; its null space is the linear functions, so a planar field is not
//!   penalised, and a face between tetrahedra on two sides of a fault is not in the graph).
//!
//! The minimiser of seed eq. 12 solves `A·φ = b` with `A = Σ A_c A_cᵗ = A_B + A_F` (seed eq. 1–3),
//! solved by conjugate gradients with an incomplete-Cholesky IC(0) preconditioner (`sparse_spd`,
//! the workspace's one sparse module).
//!
//! The default roughness weight is not a constant but follows the data's noise measured in cells
//! ([`auto_roughness`]), so one default serves a unit sphere and geology in metres alike.

use rayon::prelude::*;

use crate::geom::{add, barycentric, cross, dot, hat_gradients, norm, scale, sub, V3};
use crate::mesh::{Locator, TetMesh};
use crate::Error;
use sparse_spd::{CgStats, Checkpoint, NotConverged, PcgOptions, Preconditioner, SymCsr};

/// Relative weights ϖ of the three constraint classes (seed eq. 9).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    pub value: f64,
    pub normal: f64,
    pub rough: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Weights { value: 1.0, normal: 1.0, rough: DEFAULT_ROUGHNESS }
    }
}

/// Fallback ϖ_r where the noise cannot be estimated (no horizon with enough value points for a
/// local fit, see [`crate::noise`]): the value [`auto_roughness`] gives the noisy unit sphere of
/// tests/implicit.rs `roughness_sweep_traces_u_shape` (σ = 0.03 at cell 0.158).
pub const DEFAULT_ROUGHNESS: f64 = 5.0;

/// τ: the roughness residual the true surface is expected to leave per face, in units of g·h
/// (g: gradient scale, h: finest cell), i.e. how much a surface bends across one cell.
pub const ROUGHNESS_TAU: f64 = 0.04;

/// Default roughness weight from the data: ϖ_r = √((σ̂/h)² + (τ/2)²) / τ.
///
/// WHY (seed §2.2 and eq. 9): eq. 9 normalises every row to ‖A_c‖ = 1 and then weights it by ϖ_c,
/// so ϖ_c² is the relative weight of one constraint against the others. Read as weighted least
/// squares (the maximum-likelihood reading of eq. 8), a row's weight is the inverse standard
/// deviation of its residual, and only the ratio ϖ_r/ϖ_v matters:
/// - a normalised value row `(φ(p) − v)/‖λ(p)‖` has residual ≈ g·σ (σ: the points' noise across
///   the surface in distance units, g: the gradient scale) — the data's own noise;
/// - a normalised roughness row (jump of ∂φ/∂n across a face, divided by its coefficient norm
///   ∝ 1/h) has residual ≈ g·h·τ for the true surface, τ being how far the gradient turns across
///   one cell (τ ∝ h·κ for curvature κ).
///
/// So ϖ_r/ϖ_v = σ/(τ·h): the weight depends on the noise measured in cells, not on the value
/// units (g cancels: Claudius' 0–330 horizons or a unit sphere's distance field give the same
/// weight for the same geometry) nor on the coordinate units (σ and h scale together). A fixed
/// ϖ_r is right only for one noise-to-cell ratio: ϖ_r = 5 suits the noisy sphere (σ/h ≈ 0.2) but
/// over-smooths Claudius' seismic picks (σ̂ ≈ 1.5 m at h ≈ 198 m, σ/h ≈ 0.008) — their mean
/// misfit was 3.9 at ϖ_r = 5 and 0.8 here.
///
/// σ̂ comes from the data alone ([`crate::noise::estimate`]: leave-one-out residuals of local
/// quadric fits, no solve). The floor τ/2 for σ/h stands for the P1 elements' own error (a piecewise
/// linear field cannot follow a bending surface closer than a fraction of τ·h) and keeps noise-free
/// data from driving ϖ_r to 0, which would leave φ in data gaps to the conditioning of CG; ϖ_r is
/// therefore at least 0.5. τ = 0.04 is the one calibrated number: it puts the default at the
/// minimum of the sphere's U-shaped error curve at σ = 0.03 (tests/implicit.rs
/// `roughness_sweep_traces_u_shape`), and the same τ then lands near the minima at σ = 0.01 and
/// σ = 0.06 too (tests/implicit.rs `auto_roughness_tracks_the_noise`; table in
/// benches/results/implicit.md). Capped at 50 (CG conditioning).
pub fn auto_roughness(sigma: Option<f64>, cell: f64) -> f64 {
    match sigma {
        Some(s) if s.is_finite() && s >= 0.0 && cell > 0.0 => {
            let nu = s / cell;
            ((nu * nu + 0.25 * ROUGHNESS_TAU * ROUGHNESS_TAU).sqrt() / ROUGHNESS_TAU).min(50.0)
        }
        _ => DEFAULT_ROUGHNESS,
    }
}

/// The largest weight ϖ accepted. Weights are squared in the normal system: 10³⁰⁰ overflowed
/// it to infinity and the solve never returned; beyond 10¹⁰ (10²⁰ against a roughness of
/// about 1) the system is numerically singular anyway
/// (docs/decisions.md#crashes-and-hangs-of-issue-40).
pub const MAX_WEIGHT: f64 = 1e10;
/// The largest CG iteration cap a model may hold.
pub const MAX_ITER: usize = 100_000_000;
/// The largest active-set round cap a model may hold.
pub const MAX_ROUNDS: usize = 10_000;

/// Solver and constraint parameters stored with a model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    pub weights: Weights,
    /// δ: step along and against each normal for the inequality constraints.
    pub step: f64,
    /// g: gradient magnitude the inequality constraints ask for (1 = φ is a distance).
    pub grad: f64,
    /// CG stops when ‖r‖ ≤ tol·‖b‖.
    pub tol: f64,
    /// CG iteration cap per solve.
    pub max_iter: usize,
    /// Cap on active-set rounds of the inequality constraints.
    pub rounds: usize,
}

impl Params {
    /// What is wrong with these parameters (a weight that is not a number in 0..=[`MAX_WEIGHT`],
    /// a non-finite step, gradient or tolerance, a cap beyond [`MAX_ITER`] / [`MAX_ROUNDS`]).
    pub fn check(&self) -> Result<(), String> {
        let w = &self.weights;
        for (v, name) in [(w.value, "value weight"), (w.normal, "normal weight"), (w.rough, "roughness weight")] {
            if !(0.0..=MAX_WEIGHT).contains(&v) {
                return Err(format!("{name} {} is not a number from 0 to {MAX_WEIGHT:e}", short(v)));
            }
        }
        for (v, name) in [(self.step, "normal step"), (self.grad, "gradient"), (self.tol, "CG tolerance")] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} {} is not a finite non-negative number", short(v)));
            }
        }
        if self.max_iter > MAX_ITER {
            return Err(format!("CG iteration cap {} is above {MAX_ITER}", self.max_iter));
        }
        if self.rounds > MAX_ROUNDS {
            return Err(format!("active-set round cap {} is above {MAX_ROUNDS}", self.rounds));
        }
        Ok(())
    }
}

/// A number for a message: `1e300`, not its 301 digits.
fn short(v: f64) -> String {
    if v.is_finite() && v.abs() >= 1e6 {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// One input constraint (positions in the model's local frame).
#[derive(Debug, Clone, PartialEq)]
pub struct Constraint {
    pub pos: V3,
    pub value: Option<f64>,
    pub normal: Option<V3>,
    /// +1 / −1 for a side point (φ > 0 / φ < 0), 0 otherwise.
    pub side: f64,
    /// Float constraint (seed §3): added or moved after the base model was solved.
    pub float: bool,
}

/// Constraint rows in compressed form (already normalised and weighted, seed eq. 9).
#[derive(Debug, Default, Clone)]
pub struct Rows {
    pub ptr: Vec<usize>,
    pub idx: Vec<u32>,
    pub val: Vec<f64>,
    pub rhs: Vec<f64>,
    /// One-sided (A·φ ≥ b) rather than A·φ ≃ b.
    pub ineq: Vec<bool>,
    pub float: Vec<bool>,
    /// The constraint a row came from (u32::MAX: roughness).
    pub owner: Vec<u32>,
    /// The factor ϖ_c/‖A_c‖ the row was scaled by (seed eq. 9), to recover A_cᵗφ − b_c in the
    /// constraint's own units.
    pub scale: Vec<f64>,
    /// Value rows (φ(p) ≃ v), as opposed to normal / side / roughness rows.
    pub is_value: Vec<bool>,
}

impl Rows {
    fn new() -> Rows {
        Rows { ptr: vec![0], ..Default::default() }
    }
    fn push(&mut self, coefs: &[(u32, f64)], rhs: f64, weight: f64, ineq: bool, float: bool, owner: u32) {
        self.push_kind(coefs, rhs, weight, ineq, float, owner, false)
    }
    #[allow(clippy::too_many_arguments)]
    fn push_kind(
        &mut self,
        coefs: &[(u32, f64)],
        rhs: f64,
        weight: f64,
        ineq: bool,
        float: bool,
        owner: u32,
        is_value: bool,
    ) {
        // Merge duplicate columns (e.g. both offset points in the same tetrahedron).
        let mut c: Vec<(u32, f64)> = Vec::with_capacity(coefs.len());
        for &(i, v) in coefs {
            if let Some(e) = c.iter_mut().find(|e| e.0 == i) {
                e.1 += v;
            } else {
                c.push((i, v));
            }
        }
        let n: f64 = c.iter().map(|e| e.1 * e.1).sum::<f64>().sqrt();
        if !(n > 0.0) {
            return;
        }
        let s = weight / n; // seed eq. 9
        for (i, v) in c {
            self.idx.push(i);
            self.val.push(v * s);
        }
        self.ptr.push(self.idx.len());
        self.rhs.push(rhs * s);
        self.ineq.push(ineq);
        self.float.push(float);
        self.owner.push(owner);
        self.scale.push(s);
        self.is_value.push(is_value);
    }
    pub fn len(&self) -> usize {
        self.rhs.len()
    }
    pub fn is_empty(&self) -> bool {
        self.rhs.is_empty()
    }
    pub fn row(&self, r: usize) -> (&[u32], &[f64]) {
        (&self.idx[self.ptr[r]..self.ptr[r + 1]], &self.val[self.ptr[r]..self.ptr[r + 1]])
    }
    pub fn dot(&self, r: usize, x: &[f64]) -> f64 {
        let (i, v) = self.row(r);
        i.iter().zip(v).map(|(&i, &v)| v * x[i as usize]).sum()
    }
}

/// The barycentric row of φ at `p`.
fn point_row(mesh: &TetMesh, loc: &Locator, p: V3) -> Option<[(u32, f64); 4]> {
    let (t, l) = loc.locate(mesh, p)?;
    let v = mesh.tets[t];
    Some([(v[0], l[0]), (v[1], l[1]), (v[2], l[2]), (v[3], l[3])])
}

/// Evaluates a nodal field at `p` (None outside the mesh).
pub fn eval(mesh: &TetMesh, loc: &Locator, field: &[f64], p: V3) -> Option<f64> {
    point_row(mesh, loc, p).map(|r| r.iter().map(|&(i, w)| w * field[i as usize]).sum())
}

/// Builds the data rows of `constraints` (value, normal and side rows). Fails on a constraint
/// outside the mesh, naming it.
pub fn data_rows(mesh: &TetMesh, loc: &Locator, cs: &[Constraint], p: &Params) -> Result<Rows, Error> {
    let mut rows = Rows::new();
    let outside = |i: usize, q: V3| {
        Error::BadInput(format!(
            "constraint #{i} (or its normal step) lies outside the model's mesh, {:.3} from the frame centre; \
             the domain is fixed when the model is interpolated",
            norm(q)
        ))
    };
    let (d, g) = (p.step, p.grad);
    // Point location is the costly part: done in parallel, rows appended in constraint order.
    type Located = (Option<[(u32, f64); 4]>, Option<([(u32, f64); 4], [(u32, f64); 4])>);
    let located: Vec<Result<Located, Error>> = cs
        .par_iter()
        .enumerate()
        .map(|(i, c)| {
            let at = if c.value.is_some() || c.side != 0.0 {
                Some(point_row(mesh, loc, c.pos).ok_or_else(|| outside(i, c.pos))?)
            } else {
                None
            };
            let steps = match c.normal {
                Some(n) => {
                    let pp = add(c.pos, scale(n, d));
                    let pm = sub(c.pos, scale(n, d));
                    let rp = point_row(mesh, loc, pp).ok_or_else(|| outside(i, pp))?;
                    let rm = point_row(mesh, loc, pm).ok_or_else(|| outside(i, pm))?;
                    Some((rp, rm))
                }
                None => None,
            };
            Ok((at, steps))
        })
        .collect();
    for (i, (c, l)) in cs.iter().zip(located).enumerate() {
        let (at, steps) = l?;
        let o = i as u32;
        if let (Some(v), Some(r)) = (c.value, at) {
            rows.push_kind(&r, v, p.weights.value, false, c.float, o, true);
        }
        if let Some((rp, rm)) = steps {
            match c.value {
                Some(v) => {
                    rows.push(&rp, v + d * g, p.weights.normal, true, c.float, o);
                    let neg: Vec<(u32, f64)> = rm.iter().map(|&(j, w)| (j, -w)).collect();
                    rows.push(&neg, -(v - d * g), p.weights.normal, true, c.float, o);
                }
                None => {
                    let mut diff: Vec<(u32, f64)> = rp.to_vec();
                    diff.extend(rm.iter().map(|&(j, w)| (j, -w)));
                    rows.push(&diff, 2.0 * d * g, p.weights.normal, true, c.float, o);
                }
            }
        }
        if let (true, Some(r)) = (c.side != 0.0, at) {
            let sr: Vec<(u32, f64)> = r.iter().map(|&(j, w)| (j, c.side * w)).collect();
            rows.push(&sr, d * g, p.weights.normal, true, c.float, o);
        }
    }
    Ok(rows)
}

/// Roughness rows: the jump of the normal derivative across each interior face ≃ 0.
pub fn roughness_rows(mesh: &TetMesh, weight: f64) -> Rows {
    let faces = mesh.interior_faces();
    let per: Vec<Option<Vec<(u32, f64)>>> = faces
        .par_iter()
        .map(|f| {
            let c1 = mesh.corners(f.tets[0] as usize);
            let c2 = mesh.corners(f.tets[1] as usize);
            let g1 = hat_gradients(&c1)?;
            let g2 = hat_gradients(&c2)?;
            let [a, b, c] = f.verts.map(|v| mesh.verts[v as usize]);
            let n = cross(sub(b, a), sub(c, a));
            let nn = norm(n);
            if nn == 0.0 {
                return None;
            }
            let n = scale(n, 1.0 / nn);
            let mut coefs: Vec<(u32, f64)> = Vec::with_capacity(8);
            let v1 = mesh.tets[f.tets[0] as usize];
            let v2 = mesh.tets[f.tets[1] as usize];
            for k in 0..4 {
                coefs.push((v1[k], dot(n, g1[k])));
            }
            for k in 0..4 {
                coefs.push((v2[k], -dot(n, g2[k])));
            }
            Some(coefs)
        })
        .collect();
    let mut rows = Rows::new();
    for c in per.into_iter().flatten() {
        rows.push(&c, 0.0, weight, false, false, u32::MAX);
    }
    rows
}

/// `A = Σ A_c A_cᵗ` and `b = Σ b_c A_c` (seed eq. 11) over the rows that `select` keeps.
/// Row-by-row sparse product AᵀA (Gustavson) over the transposed rows: no sort of triplets,
/// rows in parallel, each summed in a fixed order (bit-identical results).
pub fn normal_system(n: usize, rows: &[&Rows], select: &dyn Fn(usize, usize) -> bool) -> (SymCsr, Vec<f64>) {
    // Selected rows as (set, row) in a fixed order.
    let sel: Vec<(usize, usize)> = rows
        .iter()
        .enumerate()
        .flat_map(|(s, rs)| (0..rs.len()).filter(move |&r| select(s, r)).map(move |r| (s, r)))
        .collect();
    // Transpose: for each unknown, the selected rows touching it with the coefficient.
    let mut cnt = vec![0usize; n + 1];
    for &(s, r) in &sel {
        for &i in rows[s].row(r).0 {
            cnt[i as usize + 1] += 1;
        }
    }
    for i in 0..n {
        cnt[i + 1] += cnt[i];
    }
    let mut fill = cnt.clone();
    let mut t_row = vec![0u32; cnt[n]];
    let mut t_val = vec![0.0f64; cnt[n]];
    for (k, &(s, r)) in sel.iter().enumerate() {
        let (ii, vv) = rows[s].row(r);
        for (&i, &v) in ii.iter().zip(vv) {
            t_row[fill[i as usize]] = k as u32;
            t_val[fill[i as usize]] = v;
            fill[i as usize] += 1;
        }
    }
    let per: Vec<(Vec<(u32, f64)>, f64)> = (0..n)
        .into_par_iter()
        .map_init(
            || (vec![0.0f64; n], vec![false; n], Vec::<u32>::new()),
            |(acc, seen, touched), i| {
                let mut bi = 0.0;
                for k in cnt[i]..cnt[i + 1] {
                    let (s, r) = sel[t_row[k] as usize];
                    let a = t_val[k];
                    bi += rows[s].rhs[r] * a;
                    let (jj, vv) = rows[s].row(r);
                    for (&j, &v) in jj.iter().zip(vv) {
                        if !seen[j as usize] {
                            seen[j as usize] = true;
                            touched.push(j);
                        }
                        acc[j as usize] += a * v;
                    }
                }
                touched.sort_unstable();
                let out: Vec<(u32, f64)> = touched.iter().map(|&j| (j, acc[j as usize])).collect();
                for &j in touched.iter() {
                    acc[j as usize] = 0.0;
                    seen[j as usize] = false;
                }
                touched.clear();
                (out, bi)
            },
        )
        .collect();
    let mut m = SymCsr { start: vec![0; n + 1], cols: Vec::new(), vals: Vec::new() };
    let mut b = vec![0.0; n];
    for (i, (row, bi)) in per.into_iter().enumerate() {
        for (j, v) in row {
            m.cols.push(j);
            m.vals.push(v);
        }
        m.start[i + 1] = m.cols.len();
        b[i] = bi;
    }
    (m, b)
}

/// The CG of the DSI system: IC(0)-preconditioned, stopping and judged at `tol`.
pub fn pcg(
    a: &SymCsr,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
    check: Option<Checkpoint<'_>>,
) -> Result<CgStats, NotConverged> {
    sparse_spd::pcg(a, b, x, &Preconditioner::ic0(a), &PcgOptions::new(tol, max_iter), check)
}

/// Hysteresis of the active set, as a fraction of the margin δ·g the inequality rows ask for.
pub const ACTIVE_HYSTERESIS: f64 = 1e-3;

/// The active set after an iterate `x`: equality rows always; an inequality row A·φ ≥ b turns
/// active when violated by more than ε = [`ACTIVE_HYSTERESIS`]·δ·g and inactive when satisfied by
/// more than ε, and otherwise keeps its state. Without the band, rows sitting on their bound
/// (|A·φ − b| at the level of the CG residual) flip back and forth between rounds and force
/// extra rounds that change φ by less than ε.
pub fn next_active(data: &Rows, x: &[f64], act: &[bool], p: &Params) -> Vec<bool> {
    let band = ACTIVE_HYSTERESIS * p.step * p.grad;
    (0..data.len())
        .map(|r| {
            if !data.ineq[r] {
                return true;
            }
            // Margin in the constraint's own units (φ), undoing the eq. 9 scale.
            let m = (data.dot(r, x) - data.rhs[r]) / data.scale[r];
            if m < -band {
                true
            } else if m > band {
                false
            } else {
                act.get(r).copied().unwrap_or(m < 0.0)
            }
        })
        .collect()
}

/// Result of [`solve`].
#[derive(Debug, Clone, Default)]
pub struct Solution {
    pub phi: Vec<f64>,
    /// Active flags of the data rows (inequality rows active when violated; equality rows true).
    pub active: Vec<bool>,
    /// CG iterations per active-set round.
    pub iterations: Vec<usize>,
    pub residual: f64,
    pub unknowns: usize,
    pub rows: usize,
    /// (constraint index, |φ(p) − v|) at every value constraint, in constraint order: from the
    /// value rows themselves, so no second point location.
    pub value_misfit: Vec<(u32, f64)>,
}

/// Solves the DSI system: base rows (`float == false`, plus roughness) form A_B, float rows A_F
/// (seed §3 eq. 1–4). `start` warm-starts CG (e.g. the saved solution); `active` the saved
/// active set of the data rows. `progress(round, iterations, residual)` is called per round.
pub fn solve(
    mesh: &TetMesh,
    loc: &Locator,
    cs: &[Constraint],
    p: &Params,
    start: Option<&[f64]>,
    active: Option<&[bool]>,
    progress: &mut dyn FnMut(usize, usize, f64),
) -> Result<Solution, Error> {
    let data = data_rows(mesh, loc, cs, p)?;
    solve_rows(mesh, &data, p, start, active, progress)
}

/// [`solve`] with the data rows already built by [`data_rows`] (a warm update builds them once
/// to carry the saved active set over, and solves with the same rows).
pub fn solve_rows(
    mesh: &TetMesh,
    data: &Rows,
    p: &Params,
    start: Option<&[f64]>,
    active: Option<&[bool]>,
    progress: &mut dyn FnMut(usize, usize, f64),
) -> Result<Solution, Error> {
    let n = mesh.verts.len();
    let rough = roughness_rows(mesh, p.weights.rough);
    let mut act: Vec<bool> = match active {
        Some(a) if a.len() == data.len() => a.to_vec(),
        _ => vec![true; data.len()],
    };
    let mut x = match start {
        Some(s) if s.len() == n => s.to_vec(),
        _ => vec![0.0; n],
    };
    // Roughness rows never change: assemble them once as part of the base matrix.
    let (a_rough, _) = normal_system(n, &[&rough], &|_, _| true);
    let scale_diag = a_rough.diag().iter().cloned().fold(0.0, f64::max).max(1e-300);
    let shift = 1e-12 * scale_diag; // keeps A positive definite for nodes no data reaches
    let mut iters = Vec::new();
    let mut last_res;
    // Inexact active-set iterations: while the set of violated inequality rows may still change,
    // CG runs to a loose tolerance; once a round leaves the set unchanged, one final solve goes
    // to `p.tol` from there. A warm start (saved φ and active set) then needs one loose and one
    // tight solve, both from close to the answer. (Going straight to `p.tol` on a warm start was
    // measured worse: the saved set was fixed at a loose iterate, so the converged φ still flips a
    // few rows and the restart costs more than the loose phase.)
    let loose = (p.tol * 100.0).max(1e-4);
    let has_ineq = data.ineq.iter().any(|&b| b);
    let mut round = 0;
    let mut settled = !has_ineq;
    loop {
        let (a_base, b_base) = normal_system(n, &[data], &|_, r| act[r] && !data.float[r]);
        let (a_float, b_float) = normal_system(n, &[data], &|_, r| act[r] && data.float[r]);
        let b: Vec<f64> = b_base.iter().zip(&b_float).map(|(a, b)| a + b).collect();
        // seed §3: the base and float systems are merged into one system for CG.
        let a = SymCsr::sum(&[&a_rough, &a_base, &a_float], shift);
        if !(a.vals.iter().chain(&b).all(|v| v.is_finite())) {
            return Err(Error::BadInput(
                "the DSI system has a non-finite entry: a weight, position or value beyond what 64-bit floats hold"
                    .into(),
            ));
        }
        let last = settled || round + 1 >= p.rounds.max(1);
        // Not the last round: stop at the loose tolerance unless the active set is already
        // unchanged there, in which case the same CG run goes on to `p.tol` and we are done.
        let mut next: Option<Vec<bool>> = None;
        let mut done = last;
        let st = if last {
            pcg(&a, &b, &mut x, p.tol, p.max_iter, None)
        } else {
            let mut go_on = |xx: &[f64]| {
                let new = next_active(data, xx, &act, p);
                let same = new == act;
                if std::env::var_os("GEOFIT_DEBUG_ACTIVE").is_some() {
                    // debug output: a closed or full stderr must not abort the solve
                    let changed = new.iter().zip(&act).filter(|(a, b)| a != b).count();
                    let _ = std::io::Write::write_fmt(
                        &mut std::io::stderr(),
                        format_args!("active-set round {round}: {changed} rows change\n"),
                    );
                }
                next = Some(new);
                same
            };
            let st = pcg(&a, &b, &mut x, p.tol, p.max_iter, Some(Checkpoint { loose, go_on: &mut go_on }));
            if next.as_ref() == Some(&act) {
                done = true;
            }
            st
        };
        let st = st.map_err(|e| {
            progress(round, e.iterations, e.residual);
            Error::NotConverged { iterations: e.iterations, residual: e.residual, tol: e.tol }
        })?;
        iters.push(st.iterations);
        last_res = st.residual;
        progress(round, st.iterations, st.residual);
        if done {
            break;
        }
        match next {
            Some(new) => act = new,
            None => {
                // Converged to the loose tolerance before the first check (start already close):
                // decide from the current iterate.
                let new = next_active(data, &x, &act, p);
                settled = new == act;
                act = new;
            }
        }
        round += 1;
    }
    if x.iter().any(|v| !v.is_finite()) {
        return Err(Error::BadInput("the solution contains non-finite values (degenerate mesh or constraints)".into()));
    }
    let value_misfit: Vec<(u32, f64)> = (0..data.len())
        .filter(|&r| data.is_value[r] && data.scale[r] > 0.0)
        .map(|r| (data.owner[r], ((data.dot(r, &x) - data.rhs[r]) / data.scale[r]).abs()))
        .collect();
    Ok(Solution {
        phi: x,
        active: act,
        iterations: iters,
        residual: last_res,
        unknowns: n,
        rows: data.len() + rough.len(),
        value_misfit,
    })
}

/// Expected gradient magnitude g: the slope of the least-squares linear fit of the values
/// when they vary, otherwise 1 (φ is then a distance near the surface).
pub fn gradient_scale(cs: &[Constraint]) -> f64 {
    let vals: Vec<(V3, f64)> = cs.iter().filter_map(|c| c.value.map(|v| (c.pos, v))).collect();
    if vals.len() < 4 {
        return 1.0;
    }
    let (lo, hi) = vals.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, v)| (a.min(*v), b.max(*v)));
    if hi - lo <= 0.0 {
        return 1.0;
    }
    // Normal equations of v ≈ c + a·x, 4×4, solved by Gaussian elimination with pivoting.
    let mut m = [[0.0f64; 5]; 4];
    for (p, v) in &vals {
        let row = [1.0, p[0], p[1], p[2]];
        for i in 0..4 {
            for j in 0..4 {
                m[i][j] += row[i] * row[j];
            }
            m[i][4] += row[i] * v;
        }
    }
    for c in 0..4 {
        let piv = (c..4).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs())).unwrap_or(c);
        m.swap(c, piv);
        if m[c][c].abs() < 1e-300 {
            return 1.0;
        }
        for r in 0..4 {
            if r != c {
                let f = m[r][c] / m[c][c];
                for k in c..5 {
                    m[r][k] -= f * m[c][k];
                }
            }
        }
    }
    let a = [m[1][4] / m[1][1], m[2][4] / m[2][2], m[3][4] / m[3][3]];
    let g = norm(a);
    if g.is_finite() && g > 0.0 {
        g
    } else {
        1.0
    }
}

/// (constraint index, misfit |φ(p) − v|) at every value constraint, evaluating φ at the points
/// (constraints outside the mesh are left out). [`Solution::value_misfit`] has the same from the
/// value rows without a second point location.
pub fn value_misfits(mesh: &TetMesh, loc: &Locator, cs: &[Constraint], phi: &[f64]) -> Vec<(u32, f64)> {
    cs.iter()
        .enumerate()
        .filter_map(|(i, c)| {
            let v = c.value?;
            eval(mesh, loc, phi, c.pos).map(|f| (i as u32, (f - v).abs()))
        })
        .collect()
}

/// Barycentric weights of `p` in the tetrahedron `t` of `mesh` (helper for tests and tools).
pub fn bary(mesh: &TetMesh, t: usize, p: V3) -> Option<[f64; 4]> {
    barycentric(&mesh.corners(t), p)
}
