//! The Gauss–Helmert iteration with restrictions (spec §6.1, corrected formulas) on sparse normal
//! equations, plus the post-adjustment statistics (spec §6.1 "after convergence").
//!
//! Corrections of the thesis followed here (spec §10.2 item 7):
//! - M = B·Q_ll·Bᵀ (printed BᵀQB), N = Aᵀ·M⁻¹·A (printed with M instead of M⁻¹);
//! - v_{k+1} = Q_ll·Bᵀ·M⁻¹·(ŵ − A·Δx) with ŵ = w_f + B·v_k (T 5.16 drops B·v_k);
//! - B is linearised at l + v, not at l (Böck 1961);
//! - normalised residual NV = |v| / (σ0·sqrt(Q_vv,ii)) (printed |v|/(σ0²Q_vv)).
//!
//! Solver choice (spec §10.2 item 9, the thesis' PCG does not apply to the indefinite bordered
//! system): the problem is split into independent connected components (each building of a city
//! tile is its own component, with its own datum). Per component the restrictions are folded into
//! a positive definite matrix N̄ = N + Cᵀ·Ω·C, which leaves the bordered system's solution and the
//! Q_xx block of its inverse unchanged, N̄ is factorised by faer's sparse supernodal Cholesky (AMD
//! ordering), and the restrictions are met exactly through the small dense Schur complement
//! S = C·N̄⁻¹·Cᵀ. M is block diagonal: one block per group of conditions that share observations
//! or correlated observations (1×1 for the classic design, 2×2/3×3 for polar pointings).

use crate::problem::{ObsId, Problem, UnknownId};
use crate::stats::{chi2_quantile, normal_quantile};
use crate::AdjustError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymbolicCholesky, SymmetricOrdering};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

mod bordered;
mod factor;
mod iteration;
mod linearise;
mod structure;

use self::bordered::*;
use self::factor::*;
use self::iteration::*;
use self::linearise::*;
use self::structure::*;

/// How the datum (and any configuration defect) is handled by the engine itself.
#[derive(Clone, Debug, Default)]
pub enum Datum {
    /// The caller made the problem determined: with fixed unknowns (hard datum, [`Problem::fix`]),
    /// identity observations (soft datum, [`Problem::add_identity_observation`]) or restrictions.
    /// A remaining defect is an error naming the undetermined unknowns.
    #[default]
    Determined,
    /// Free datum (spec §4.7.1): inner constraints Gᵀ·Δx = 0 on the listed unknowns (partial
    /// trace minimisation), with G the numerical null space of the normal equations at the
    /// approximations (the spec's eigenvector proposal, which also covers defects below 6 caused
    /// by shared parameters). Unknowns outside the subset (set-ups, fixed points) take no part.
    Free { subset: Vec<UnknownId> },
}

/// Iteration and testing options.
#[derive(Clone, Debug)]
pub struct Options {
    /// Convergence: max |Δx_i| / (1 + |x_i|) and max |Δv_i| / (1 + |l_i|) below this (spec §6.1 proposal 1e−10).
    pub tolerance: f64,
    /// Iteration cap (spec §6.1 proposal ≈ 50).
    pub max_iterations: usize,
    pub datum: Datum,
    /// A-priori standard deviation of unit weight.
    pub sigma0: f64,
    /// Significance level of Baarda's data snooping (two-sided, per observation). Default 0.001 (k = 3.29, spec §6.1).
    pub alpha: f64,
    /// Significance level of the global χ² test.
    pub alpha_global: f64,
    /// Redundancy numbers below this mark an observation "not controllable" (spec: EV < 10 %).
    pub min_redundancy: f64,
    /// Compute Q_xx-based statistics (redundancy numbers, normalised residuals, σ of unknowns).
    pub statistics: bool,
    /// Also compute a-posteriori σ of every unknown (one extra solve per unknown).
    pub unknown_sigmas: bool,
    /// Largest component for which the dense rank check / numeric null space is computed.
    pub dense_check_limit: usize,
    /// Only compute the free-datum null space (for choosing a hard datum), do not iterate.
    pub null_space_only: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            tolerance: 1e-10,
            max_iterations: 50,
            datum: Datum::Determined,
            sigma0: 1.0,
            alpha: 0.001,
            alpha_global: 0.05,
            min_redundancy: 0.1,
            statistics: true,
            unknown_sigmas: true,
            dense_check_limit: 2500,
            null_space_only: false,
        }
    }
}

/// Per-observation result.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ObsResult {
    /// Residual v (adjusted observation = l + v).
    pub v: f64,
    /// Redundancy number r_i = (Q_vv·P)_ii ∈ [0, 1] ("EV", controllability).
    pub redundancy: f64,
    /// Normalised residual / Baarda's w = |(P v)_i| / (σ0 sqrt((P Q_vv P)_ii)); for uncorrelated
    /// observations this is |v_i| / (σ0 sqrt(Q_vv,ii)).
    pub normalised: f64,
    /// Standard deviation of the residual, σ0·sqrt(Q_vv,ii).
    pub sigma_v: f64,
    /// r_i ≥ `min_redundancy`: a blunder here can be detected.
    pub controllable: bool,
    /// w exceeds the critical value k = Φ⁻¹(1 − α/2) and the observation is controllable.
    pub rejected: bool,
}

/// The global χ² test of vᵀPv/σ0² against χ²(r).
#[derive(Clone, Debug, serde::Serialize)]
pub struct GlobalTest {
    pub statistic: f64,
    pub dof: usize,
    pub lower: f64,
    pub upper: f64,
    /// lower ≤ statistic ≤ upper (two-sided; see `verdict` for which side failed).
    pub passed: bool,
    pub verdict: GlobalVerdict,
}

/// Which way the global test went. Only `AboveUpper` is a failure of the data: `BelowLower` means
/// the observations fit better than their σ claim (σ too pessimistic, or the conditions are met
/// exactly, e.g. generated from the same geometry), which is no reason to distrust the result.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GlobalVerdict {
    Passed,
    BelowLower,
    AboveUpper,
}

impl GlobalVerdict {
    pub fn of(statistic: f64, lower: f64, upper: f64) -> Self {
        if statistic > upper || statistic.is_nan() {
            GlobalVerdict::AboveUpper
        } else if statistic < lower {
            GlobalVerdict::BelowLower
        } else {
            GlobalVerdict::Passed
        }
    }
}

/// Result of [`adjust`].
#[derive(Clone, Debug)]
pub struct Solution {
    /// All unknowns (fixed ones keep their value).
    pub x: Vec<f64>,
    /// Per observation.
    pub obs: Vec<ObsResult>,
    /// A-posteriori σ of every unknown (0 for fixed ones), when requested.
    pub sigma_x: Option<Vec<f64>>,
    /// Largest number of iterations over the components.
    pub iterations: usize,
    /// Conditions + restrictions (incl. datum restrictions) − active unknowns.
    pub redundancy: usize,
    /// Σ r_i (equals `redundancy` when the statistics are correct).
    pub redundancy_sum: f64,
    pub vtpv: f64,
    /// σ̂0 = sqrt(vᵀPv / r) (None when r = 0).
    pub sigma0_post: Option<f64>,
    pub global_test: Option<GlobalTest>,
    /// Critical value of the w-test.
    pub critical_w: f64,
    /// The controllable observation with the largest normalised residual.
    pub largest_suspect: Option<ObsId>,
    /// Number of datum restrictions added for the free datum (over all components).
    pub datum_restrictions: usize,
    /// Number of independent components solved.
    pub components: usize,
    /// Free datum: the null-space vectors restricted to the datum subset (one per defect).
    pub null_space: Vec<Vec<(UnknownId, f64)>>,
}

// ---------------------------------------------------------------------------------------------

/// Linearised equation row: value, sparse gradient over component-local unknowns, dense
/// gradient over the block's observations.
struct Row {
    f: f64,
    a: Vec<(usize, f64)>,
    b: Vec<(usize, f64)>,
}

/// Values of one component over the global index space: the problem's values, overlaid by the
/// component's own updates (no per-component copy of the whole problem).
struct Overlay<'a> {
    base: &'a [f64],
    map: std::collections::HashMap<usize, f64>,
}

impl<'a> Overlay<'a> {
    fn new(base: &'a [f64]) -> Self {
        Overlay { base, map: Default::default() }
    }
}

impl std::ops::Index<usize> for Overlay<'_> {
    type Output = f64;
    fn index(&self, i: usize) -> &f64 {
        self.map.get(&i).unwrap_or(&self.base[i])
    }
}

impl std::ops::IndexMut<usize> for Overlay<'_> {
    fn index_mut(&mut self, i: usize) -> &mut f64 {
        let b = self.base[i];
        self.map.entry(i).or_insert(b)
    }
}

struct Ctx<'a> {
    x0: Vec<f64>,
    l0: Vec<f64>,
    p: &'a Problem,
    nets: Vec<Net>,
    rnets: Vec<Net>,
    blocks: Vec<Block>,
    opts: &'a Options,
}

impl<'a> Ctx<'a> {
    /// Evaluate one condition at (x, l + v). `local` maps global unknown → component column.
    fn eval_row(
        &self,
        net: &Net,
        eqi: usize,
        restriction: bool,
        x: &Overlay,
        lv: &Overlay,
        local: &dyn Fn(usize) -> Option<usize>,
        block_obs: &[usize],
    ) -> Result<Row, AdjustError> {
        let def = if restriction { &self.p.restrictions[eqi] } else { &self.p.conditions[eqi] };
        let vars: Vec<f64> = net.unk.iter().map(|&u| x[u]).chain(net.obs.iter().map(|&o| lv[o])).collect();
        let mut g = vec![0.0; vars.len()];
        let f = def
            .eq
            .value_grad(&vars, &net.xmap, &net.lmap, &mut g)
            .ok_or_else(|| AdjustError::TooManyVariables { equation: def.name.clone(), count: vars.len() })?;
        if !f.is_finite() || g.iter().any(|v| !v.is_finite()) {
            return Err(AdjustError::NonFinite { what: format!("linearisation of {} ({})", def.name, def.eq.kind()) });
        }
        let mut a = Vec::with_capacity(net.unk.len());
        for (i, &u) in net.unk.iter().enumerate() {
            if let Some(c) = local(u) {
                a.push((c, g[i]));
            }
        }
        let mut b = Vec::with_capacity(net.obs.len());
        for (i, &o) in net.obs.iter().enumerate() {
            let pos = block_obs.binary_search(&o).expect("observation in its block");
            b.push((pos, g[net.unk.len() + i]));
        }
        Ok(Row { f, a, b })
    }
}

/// Adjust a problem. Consumes nothing; returns the solution or a precise error.
pub fn adjust(problem: &Problem, opts: &Options) -> Result<Solution, AdjustError> {
    let p = problem;
    check_approximations(p)?;
    let nets: Vec<Net> = p.conditions.iter().map(|c| build_net(&c.x, &c.l)).collect();
    let rnets: Vec<Net> = p.restrictions.iter().map(|c| build_net(&c.x, &c.l)).collect();

    let blocks = condition_blocks(p, &nets, opts);
    let comps = components(p, &nets, &rnets, &blocks)?;

    let ctx = Ctx {
        x0: p.unknowns.iter().map(|u| u.value).collect(),
        l0: p.obs.iter().map(|o| o.value).collect(),
        p,
        nets,
        rnets,
        blocks,
        opts,
    };
    let datum_subset = free_datum_mask(&opts.datum, p.unknowns.len())?;

    let results: Vec<Result<CompResult, AdjustError>> =
        comps.par_iter().map(|c| solve_component(&ctx, c, datum_subset.as_deref())).collect();
    let mut merged = Merged::new(p, opts);
    for (c, res) in comps.iter().zip(results) {
        merged.add(c, res?);
    }
    Ok(merged.into_solution(opts, comps.len()))
}

/// Every approximate value must be finite before anything is linearised.
fn check_approximations(p: &Problem) -> Result<(), AdjustError> {
    match p.unknowns.iter().find(|u| !u.value.is_finite()) {
        Some(u) => Err(AdjustError::NonFinite { what: format!("approximate value of unknown {}", u.name) }),
        None => Ok(()),
    }
}

/// The unknowns a free datum is defined on, as a mask over all unknowns (`None` when the datum
/// is determined by the observations).
fn free_datum_mask(datum: &Datum, nu: usize) -> Result<Option<Vec<bool>>, AdjustError> {
    let Datum::Free { subset } = datum else { return Ok(None) };
    let mut m = vec![false; nu];
    for u in subset {
        if u.0 >= nu {
            return Err(AdjustError::UnknownUnknown { equation: "free datum subset".into(), id: u.0 });
        }
        m[u.0] = true;
    }
    Ok(Some(m))
}

/// The components' results gathered into whole-problem vectors and sums, in component order.
struct Merged {
    x: Vec<f64>,
    obs: Vec<ObsResult>,
    sigma_x: Option<Vec<f64>>,
    null_space: Vec<Vec<(UnknownId, f64)>>,
    iterations: usize,
    vtpv: f64,
    redundancy_sum: f64,
    redundancy: i64,
    datum_rows: usize,
}

impl Merged {
    fn new(p: &Problem, opts: &Options) -> Merged {
        let want_sigma = opts.unknown_sigmas && opts.statistics;
        Merged {
            x: p.unknowns.iter().map(|u| u.value).collect(),
            obs: vec![ObsResult::default(); p.obs.len()],
            sigma_x: want_sigma.then(|| vec![0.0; p.unknowns.len()]),
            null_space: Vec::new(),
            iterations: 0,
            vtpv: 0.0,
            redundancy_sum: 0.0,
            redundancy: 0,
            datum_rows: 0,
        }
    }

    fn add(&mut self, c: &Component, res: CompResult) {
        for row in &res.null {
            self.null_space.push(row.iter().map(|&(k, g)| (UnknownId(c.unknowns[k]), g)).collect());
        }
        self.iterations = self.iterations.max(res.iterations);
        self.vtpv += res.vtpv;
        self.redundancy += res.redundancy;
        self.datum_rows += res.datum_rows;
        for (k, &u) in c.unknowns.iter().enumerate() {
            self.x[u] = res.x[k];
            if let (Some(sx), Some(s)) = (self.sigma_x.as_mut(), res.qxx_diag.as_ref()) {
                sx[u] = s[k];
            }
        }
        for (o, r) in res.obs {
            self.redundancy_sum += r.redundancy;
            self.obs[o] = r;
        }
    }

    fn into_solution(mut self, opts: &Options, components: usize) -> Solution {
        let redundancy = self.redundancy.max(0) as usize;
        let sigma0_post =
            if redundancy > 0 { Some((self.vtpv / redundancy as f64).sqrt() * opts.sigma0) } else { None };
        if let Some(sx) = self.sigma_x.as_mut() {
            let s0 = sigma0_post.unwrap_or(opts.sigma0);
            sx.iter_mut().for_each(|v| *v = s0 * v.max(0.0).sqrt());
        }
        let critical_w = normal_quantile(1.0 - opts.alpha / 2.0);
        let largest = flag_observations(&mut self.obs, critical_w, opts);
        let global_test =
            (redundancy > 0 && opts.statistics).then(|| global_test(self.vtpv, redundancy, opts.alpha_global));
        Solution {
            x: self.x,
            obs: self.obs,
            sigma_x: self.sigma_x,
            iterations: self.iterations,
            redundancy,
            redundancy_sum: self.redundancy_sum,
            vtpv: self.vtpv,
            sigma0_post,
            global_test,
            critical_w,
            largest_suspect: largest,
            datum_restrictions: self.datum_rows,
            components,
            null_space: self.null_space,
        }
    }
}

/// Marks each observation controllable (enough redundancy) and rejected (normalised residual
/// over the critical value); returns the controllable one with the largest normalised residual.
fn flag_observations(obs: &mut [ObsResult], critical_w: f64, opts: &Options) -> Option<ObsId> {
    let mut largest: Option<(usize, f64)> = None;
    for (i, o) in obs.iter_mut().enumerate() {
        o.controllable = o.redundancy >= opts.min_redundancy;
        o.rejected = o.controllable && o.normalised > critical_w;
        if o.controllable && opts.statistics && largest.is_none_or(|(_, w)| o.normalised > w) {
            largest = Some((i, o.normalised));
        }
    }
    largest.map(|(i, _)| ObsId(i))
}

/// The two-sided χ² test of vᵀPv (already divided by σ0² through Q_ll = C_ll/σ0²).
fn global_test(vtpv: f64, dof: usize, alpha_global: f64) -> GlobalTest {
    let lower = chi2_quantile(alpha_global / 2.0, dof as f64);
    let upper = chi2_quantile(1.0 - alpha_global / 2.0, dof as f64);
    GlobalTest {
        statistic: vtpv,
        dof,
        lower,
        upper,
        passed: vtpv >= lower && vtpv <= upper,
        verdict: GlobalVerdict::of(vtpv, lower, upper),
    }
}

struct CompResult {
    null: Vec<Vec<(usize, f64)>>,
    x: Vec<f64>,
    obs: Vec<(usize, ObsResult)>,
    qxx_diag: Option<Vec<f64>>,
    iterations: usize,
    vtpv: f64,
    redundancy: i64,
    datum_rows: usize,
}

/// Hard datum (spec §4.7.3): choose a minimal set of unknowns from `candidates` (in the given
/// order, e.g. plane d's first, then normal parameters) whose fixing removes the datum defect. The
/// defect's null space is computed numerically as for the free datum; an unknown is taken when its
/// row of the null-space basis raises the rank of the rows taken so far.
pub fn hard_datum_choice(
    problem: &Problem,
    candidates: &[UnknownId],
    opts: &Options,
) -> Result<Vec<UnknownId>, AdjustError> {
    let mut o = opts.clone();
    o.datum = Datum::Free { subset: candidates.to_vec() };
    o.null_space_only = true;
    let sol = adjust(problem, &o)?;
    if sol.null_space.is_empty() {
        return Ok(vec![]);
    }
    // Group null vectors by component (they share unknowns).
    let mut chosen = Vec::new();
    let mut remaining: Vec<Vec<(UnknownId, f64)>> = sol.null_space;
    while !remaining.is_empty() {
        // Vectors of one component: those sharing an unknown with the first.
        let first: std::collections::HashSet<usize> = remaining[0].iter().map(|(u, _)| u.0).collect();
        let (group, rest): (Vec<_>, Vec<_>) =
            remaining.into_iter().partition(|v| v.iter().any(|(u, _)| first.contains(&u.0)));
        remaining = rest;
        let d = group.len();
        let maps: Vec<std::collections::HashMap<usize, f64>> =
            group.iter().map(|v| v.iter().map(|(u, g)| (u.0, *g)).collect()).collect();
        let mut rows: Vec<DVector<f64>> = Vec::new();
        for &c in candidates {
            if rows.len() == d {
                break;
            }
            let row = DVector::from_iterator(d, maps.iter().map(|m| m.get(&c.0).copied().unwrap_or(0.0)));
            if row.amax() < 1e-9 {
                continue;
            }
            let mut mat = DMatrix::<f64>::zeros(rows.len() + 1, d);
            for (i, r) in rows.iter().chain(std::iter::once(&row)).enumerate() {
                mat.set_row(i, &r.transpose());
            }
            let sv = mat.singular_values();
            let smax = sv.iter().fold(0.0f64, |a, &b| a.max(b));
            let smin = sv.iter().fold(f64::INFINITY, |a, &b| a.min(b));
            if smin > 1e-6 * smax.max(1e-300) {
                rows.push(row);
                chosen.push(c);
            }
        }
        if rows.len() < d {
            let names = group
                .iter()
                .flat_map(|v| v.iter().map(|(u, _)| problem.unknown_name(*u).to_string()))
                .collect::<std::collections::BTreeSet<_>>()
                .into_iter()
                .collect();
            return Err(AdjustError::Defect { defect: d - rows.len(), unknowns: names });
        }
    }
    Ok(chosen)
}
