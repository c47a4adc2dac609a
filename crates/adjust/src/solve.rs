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

/// One group of conditions coupled through shared or correlated observations (one M block).
struct Block {
    conds: Vec<usize>,
    obs: Vec<usize>,
    /// Q_ll of the block's observations (dense, small), in σ0² units.
    q: DMatrix<f64>,
}

struct Component {
    /// Global unknown ids of this component (active, i.e. not fixed).
    unknowns: Vec<usize>,
    blocks: Vec<usize>,
    restrictions: Vec<usize>,
}

/// Per-condition parameter-net resolution: distinct variables and slot maps (spec §6.2).
struct Net {
    /// Distinct unknown ids (global) of the equation, then distinct observations.
    unk: Vec<usize>,
    obs: Vec<usize>,
    xmap: Vec<(usize, f64)>,
    lmap: Vec<usize>,
}

fn build_net(x: &[crate::problem::Slot], l: &[ObsId]) -> Net {
    let mut unk: Vec<usize> = Vec::new();
    let mut xmap = Vec::with_capacity(x.len());
    for s in x {
        let i = match unk.iter().position(|&u| u == s.unknown.0) {
            Some(i) => i,
            None => {
                unk.push(s.unknown.0);
                unk.len() - 1
            }
        };
        xmap.push((i, s.sign));
    }
    let mut obs: Vec<usize> = Vec::new();
    let mut lmap = Vec::with_capacity(l.len());
    for o in l {
        let i = match obs.iter().position(|&u| u == o.0) {
            Some(i) => i,
            None => {
                obs.push(o.0);
                obs.len() - 1
            }
        };
        lmap.push(unk.len() + i);
    }
    Net { unk, obs, xmap, lmap }
}

struct UnionFind(Vec<usize>);
impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind((0..n).collect())
    }
    fn find(&mut self, mut a: usize) -> usize {
        while self.0[a] != a {
            self.0[a] = self.0[self.0[a]];
            a = self.0[a];
        }
        a
    }
    fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.0[a.max(b)] = a.min(b);
        }
    }
}

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
    fn eval_row(&self, net: &Net, eqi: usize, restriction: bool, x: &Overlay, lv: &Overlay, local: &dyn Fn(usize) -> Option<usize>, block_obs: &[usize]) -> Result<Row, AdjustError> {
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

    let ctx = Ctx { x0: p.unknowns.iter().map(|u| u.value).collect(), l0: p.obs.iter().map(|o| o.value).collect(), p, nets, rnets, blocks, opts };
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
        let sigma0_post = if redundancy > 0 { Some((self.vtpv / redundancy as f64).sqrt() * opts.sigma0) } else { None };
        if let Some(sx) = self.sigma_x.as_mut() {
            let s0 = sigma0_post.unwrap_or(opts.sigma0);
            sx.iter_mut().for_each(|v| *v = s0 * v.max(0.0).sqrt());
        }
        let critical_w = normal_quantile(1.0 - opts.alpha / 2.0);
        let largest = flag_observations(&mut self.obs, critical_w, opts);
        let global_test = (redundancy > 0 && opts.statistics).then(|| global_test(self.vtpv, redundancy, opts.alpha_global));
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
    GlobalTest { statistic: vtpv, dof, lower, upper, passed: vtpv >= lower && vtpv <= upper, verdict: GlobalVerdict::of(vtpv, lower, upper) }
}

/// M blocks: conditions coupled through shared observations or covariance groups, each with its
/// observations and their cofactor matrix Q = C / σ0².
fn condition_blocks(p: &Problem, nets: &[Net], opts: &Options) -> Vec<Block> {
    let nc = p.conditions.len();
    let mut uf = UnionFind::new(nc);
    {
        let mut owner: Vec<Option<usize>> = vec![None; p.obs.len()];
        let mut gowner: Vec<Option<usize>> = vec![None; p.cov_groups.len()];
        for (ci, net) in nets.iter().enumerate() {
            for &o in &net.obs {
                if let Some(c2) = owner[o] {
                    uf.union(ci, c2);
                } else {
                    owner[o] = Some(ci);
                }
                if let Some(g) = p.obs[o].group {
                    if let Some(c2) = gowner[g] {
                        uf.union(ci, c2);
                    } else {
                        gowner[g] = Some(ci);
                    }
                }
            }
        }
    }
    let mut block_of = vec![usize::MAX; nc];
    let mut blocks: Vec<Block> = Vec::new();
    for ci in 0..nc {
        let r = uf.find(ci);
        if block_of[r] == usize::MAX {
            block_of[r] = blocks.len();
            blocks.push(Block { conds: vec![], obs: vec![], q: DMatrix::zeros(0, 0) });
        }
        let b = block_of[r];
        block_of[ci] = b;
        blocks[b].conds.push(ci);
    }
    for b in blocks.iter_mut() {
        let mut obs: Vec<usize> = Vec::new();
        for &ci in &b.conds {
            obs.extend(&nets[ci].obs);
        }
        // Correlated partners that no condition uses still belong to the group's Q; they get no
        // residual (B column zero), so only the used ones matter. Keep used ones only.
        obs.sort_unstable();
        obs.dedup();
        let n = obs.len();
        let mut q = DMatrix::zeros(n, n);
        for (i, &o) in obs.iter().enumerate() {
            q[(i, i)] = p.obs[o].sigma * p.obs[o].sigma;
            if let Some(g) = p.obs[o].group {
                let grp = &p.cov_groups[g];
                let gi = grp.obs.iter().position(|x| x.0 == o).unwrap();
                let gn = grp.obs.len();
                for (j, &o2) in obs.iter().enumerate() {
                    if let Some(gj) = grp.obs.iter().position(|x| x.0 == o2) {
                        q[(i, j)] = grp.cov[gi * gn + gj];
                    }
                }
            }
        }
        let s2 = opts.sigma0 * opts.sigma0;
        b.q = q / s2;
        b.obs = obs;
    }
    blocks
}

/// Components: union-find over the active unknowns and the blocks (and restrictions) that tie
/// them; each is adjusted on its own. Refuses unknowns no equation touches (a configuration
/// defect) and restrictions on fixed unknowns that do not hold.
fn components(p: &Problem, nets: &[Net], rnets: &[Net], blocks: &[Block]) -> Result<Vec<Component>, AdjustError> {
    let nu = p.unknowns.len();
    let nb = blocks.len();
    let mut uf = UnionFind::new(nu + nb);
    let active = |u: usize| !p.unknowns[u].fixed;
    for (bi, b) in blocks.iter().enumerate() {
        for &ci in &b.conds {
            for &u in &nets[ci].unk {
                if active(u) {
                    uf.union(nu + bi, u);
                }
            }
        }
    }
    for net in rnets {
        let act: Vec<usize> = net.unk.iter().copied().filter(|&u| active(u)).collect();
        for w in act.windows(2) {
            uf.union(w[0], w[1]);
        }
    }
    let mut comp_of_root: std::collections::HashMap<usize, usize> = Default::default();
    let mut comps: Vec<Component> = Vec::new();
    let mut touched = vec![false; nu];
    for b in blocks {
        for &ci in &b.conds {
            for &u in &nets[ci].unk {
                touched[u] = true;
            }
        }
    }
    for net in rnets {
        for &u in &net.unk {
            touched[u] = true;
        }
    }
    // Unknowns no equation touches: a configuration defect, named.
    let untouched: Vec<String> = (0..nu).filter(|&u| active(u) && !touched[u]).map(|u| p.unknowns[u].name.clone()).collect();
    if !untouched.is_empty() {
        return Err(AdjustError::Defect { defect: untouched.len(), unknowns: untouched });
    }
    let mut comp_idx = |uf: &mut UnionFind, node: usize, comps: &mut Vec<Component>| -> usize {
        let r = uf.find(node);
        *comp_of_root.entry(r).or_insert_with(|| {
            comps.push(Component { unknowns: vec![], blocks: vec![], restrictions: vec![] });
            comps.len() - 1
        })
    };
    for u in 0..nu {
        if active(u) {
            let c = comp_idx(&mut uf, u, &mut comps);
            comps[c].unknowns.push(u);
        }
    }
    for bi in 0..nb {
        let c = comp_idx(&mut uf, nu + bi, &mut comps);
        comps[c].blocks.push(bi);
    }
    for (ri, net) in rnets.iter().enumerate() {
        match net.unk.iter().find(|&&u| active(u)) {
            Some(&u) => {
                let c = comp_idx(&mut uf, u, &mut comps);
                comps[c].restrictions.push(ri);
            }
            None => {
                // Restriction on fixed unknowns only: must hold already.
                let def = &p.restrictions[ri];
                let x: Vec<f64> = def.x.iter().map(|s| s.sign * p.unknowns[s.unknown.0].value).collect();
                let g = def.eq.value(&x, &[]);
                if g.abs() > 1e-9 {
                    return Err(AdjustError::InconsistentRestriction { restriction: def.name.clone(), value: g });
                }
            }
        }
    }
    Ok(comps)
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

/// Sparse Cholesky of a symmetric positive definite matrix given by lower-triangle triplets.
struct Factor {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
}

impl Factor {
    fn new(n: usize, trip: &[Triplet<usize, usize, f64>]) -> Result<Factor, Option<usize>> {
        let mat = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, trip).map_err(|_| None)?;
        let symbolic = factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, SymmetricOrdering::Amd, Default::default()).map_err(|_| None)?;
        let mut values = vec![0.0; symbolic.len_val()];
        let par = Par::Seq;
        let mut buf = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        let res = symbolic.factorize_numeric_llt::<f64>(&mut values, mat.as_ref(), Side::Lower, Default::default(), par, MemStack::new(&mut buf), Default::default());
        match res {
            Ok(_) => {}
            Err(faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index }) => {
                // index is in the permuted order: map it back to the original column.
                let orig = match symbolic.perm() {
                    Some(perm) => perm.arrays().0[index],
                    None => index,
                };
                return Err(Some(orig));
            }
        }
        Ok(Factor { symbolic, values })
    }

    fn solve(&self, rhs: &mut Mat<f64>) {
        let par = Par::Seq;
        let k = rhs.ncols();
        let llt = faer::sparse::linalg::cholesky::LltRef::<'_, usize, f64>::new(&self.symbolic, &self.values);
        let mut buf = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(k, par));
        llt.solve_in_place_with_conj(Conj::No, rhs.as_mut(), par, MemStack::new(&mut buf));
    }
}

/// Dense symmetric null-space analysis of a (scaled) matrix: returns null vectors (columns).
fn dense_null_space(n: usize, trip: &[(usize, usize, f64)]) -> (Vec<DVector<f64>>, Vec<f64>) {
    let mut m = DMatrix::<f64>::zeros(n, n);
    for &(i, j, v) in trip {
        m[(i, j)] += v;
        if i != j {
            m[(j, i)] += v;
        }
    }
    let d: Vec<f64> = (0..n).map(|i| if m[(i, i)] > 0.0 { 1.0 / m[(i, i)].sqrt() } else { 1.0 }).collect();
    for i in 0..n {
        for j in 0..n {
            m[(i, j)] *= d[i] * d[j];
        }
    }
    let eig = nalgebra::SymmetricEigen::new(m);
    let lmax = eig.eigenvalues.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    let mut out = Vec::new();
    for k in 0..n {
        if eig.eigenvalues[k] <= 1e-12 * lmax {
            let y = eig.eigenvectors.column(k);
            // back to the unscaled variables
            let mut x = DVector::from_iterator(n, (0..n).map(|i| y[i] * d[i]));
            let nrm = x.norm();
            if nrm > 0.0 {
                x /= nrm;
            }
            out.push(x);
        }
    }
    (out, d)
}

fn name_null_vectors(p: &Problem, unknowns: &[usize], null: &[DVector<f64>]) -> Vec<String> {
    let mut names: Vec<usize> = Vec::new();
    for g in null {
        let mx = g.amax();
        for (k, &u) in unknowns.iter().enumerate() {
            if g[k].abs() > 0.05 * mx && !names.contains(&u) {
                names.push(u);
            }
        }
    }
    names.sort_unstable();
    names.into_iter().map(|u| p.unknowns[u].name.clone()).collect()
}

fn solve_component(ctx: &Ctx, comp: &Component, datum: Option<&[bool]>) -> Result<CompResult, AdjustError> {
    let (p, opts) = (ctx.p, ctx.opts);
    let mut local_map: std::collections::HashMap<usize, usize> = comp.unknowns.iter().enumerate().map(|(k, &u)| (u, k)).collect();
    local_map.shrink_to_fit();
    let local = |u: usize| local_map.get(&u).copied();
    let mut state = IterationState::new(ctx, comp);
    let mut datum_rows: Vec<Vec<(usize, f64)>> = Vec::new();
    let mut progress = StepProgress::new();
    let mut iterations = 0usize;
    // Assembled linear system of the last iteration (for statistics).
    let mut last: Option<Linear> = None;
    for it in 0..=opts.max_iterations {
        let lin = assemble(ctx, comp, &state.x, &state.lv, &state.v, &local)?;
        if it == 0 {
            datum_rows = datum_rows_of(ctx, comp, &lin, datum)?;
        }
        if opts.null_space_only {
            let xs = comp.unknowns.iter().map(|&u| state.x[u]).collect();
            return Ok(CompResult { null: datum_rows, x: xs, obs: vec![], qxx_diag: None, iterations: 0, vtpv: 0.0, redundancy: 0, datum_rows: 0 });
        }
        if it == opts.max_iterations {
            last = Some(lin);
            break;
        }
        let sol = solve_linear(ctx, comp, &lin, &datum_rows, false)?;
        iterations = it + 1;
        let (step, worst) = state.apply(p, comp, &sol, iterations)?;
        if progress.converged_after(step, opts.tolerance, iterations, &p.unknowns[worst].name)? {
            // Re-linearise at the solution for the statistics.
            last = Some(assemble(ctx, comp, &state.x, &state.lv, &state.v, &local)?);
            break;
        }
    }
    if !progress.converged {
        return Err(AdjustError::NotConverged { iterations: opts.max_iterations, step: progress.prev_step, first: p.unknowns[comp.unknowns[0]].name.clone() });
    }
    let lin = last.expect("linear system");
    state.result(ctx, comp, &lin, &datum_rows, iterations)
}

/// The current state of a component's iteration: the unknowns x (global, for evaluation), the
/// residuals v and l + v of its observations.
struct IterationState<'a> {
    x: Overlay<'a>,
    v: std::collections::HashMap<usize, f64>,
    lv: Overlay<'a>,
}

impl<'a> IterationState<'a> {
    fn new(ctx: &'a Ctx, comp: &Component) -> Self {
        let mut v: std::collections::HashMap<usize, f64> = Default::default();
        for &bi in &comp.blocks {
            for &o in &ctx.blocks[bi].obs {
                v.insert(o, 0.0);
            }
        }
        IterationState { x: Overlay::new(&ctx.x0), v, lv: Overlay::new(&ctx.l0) }
    }

    /// Applies one solution's Δx and new residuals. Returns the largest relative step and the
    /// unknown that made it; a non-finite update or residual, or an exploding step, diverged.
    fn apply(&mut self, p: &Problem, comp: &Component, sol: &LinSol, iterations: usize) -> Result<(f64, usize), AdjustError> {
        let mut step = 0.0f64;
        let mut worst = 0usize;
        for (k, &u) in comp.unknowns.iter().enumerate() {
            let s = sol.dx[k].abs() / (1.0 + self.x[u].abs());
            if !(s.is_finite()) {
                return Err(AdjustError::Diverged { iteration: iterations, reason: format!("non-finite update of {}", p.unknowns[u].name) });
            }
            if s > step {
                step = s;
                worst = u;
            }
            self.x[u] += sol.dx[k];
        }
        for &(o, vn) in &sol.v_new {
            let vo = self.v.insert(o, vn).unwrap_or(0.0);
            let s = (vn - vo).abs() / (1.0 + p.obs[o].value.abs());
            if !s.is_finite() {
                return Err(AdjustError::Diverged { iteration: iterations, reason: format!("non-finite residual of {}", p.obs[o].name) });
            }
            step = step.max(s);
            self.lv[o] = p.obs[o].value + vn;
        }
        if step > 1e8 {
            return Err(AdjustError::Diverged { iteration: iterations, reason: format!("update of {} exploded (relative step {step:.3e})", p.unknowns[worst].name) });
        }
        Ok((step, worst))
    }

    /// The converged component: vᵀPv, residuals and (with `opts.statistics`) redundancy numbers,
    /// normalised residuals and the unknowns' cofactors from one more solve at the solution.
    fn result(&self, ctx: &Ctx, comp: &Component, lin: &Linear, datum_rows: &[Vec<(usize, f64)>], iterations: usize) -> Result<CompResult, AdjustError> {
        let opts = ctx.opts;
        let m_cond: usize = comp.blocks.iter().map(|&b| ctx.blocks[b].conds.len()).sum();
        let redundancy = m_cond as i64 + (comp.restrictions.len() + datum_rows.len()) as i64 - comp.unknowns.len() as i64;
        // vᵀPv per block through λ: vᵀPv = λᵀ M λ with λ = M⁻¹ B v... compute directly with Q⁻¹.
        let mut vtpv = 0.0;
        let mut obs_out: Vec<(usize, ObsResult)> = Vec::new();
        for &bi in &comp.blocks {
            let b = &ctx.blocks[bi];
            let vb = DVector::from_iterator(b.obs.len(), b.obs.iter().map(|o| self.v[o]));
            let qinv = b.q.clone().cholesky().expect("Q checked positive definite").inverse();
            vtpv += (vb.transpose() * &qinv * &vb)[(0, 0)];
            for &o in &b.obs {
                obs_out.push((o, ObsResult { v: self.v[&o], ..Default::default() }));
            }
        }
        let mut qxx_diag = None;
        if opts.statistics {
            let sol = solve_linear(ctx, comp, lin, datum_rows, true)?;
            let stats = sol.stats.expect("statistics requested");
            for (k, out) in obs_out.iter_mut().enumerate() {
                let (r, w, sv) = stats.per_obs[k];
                out.1.redundancy = r;
                out.1.normalised = w;
                out.1.sigma_v = sv * opts.sigma0;
            }
            qxx_diag = stats.qxx_diag;
        }
        let xs = comp.unknowns.iter().map(|&u| self.x[u]).collect();
        Ok(CompResult { null: vec![], x: xs, obs: obs_out, qxx_diag, iterations, vtpv, redundancy, datum_rows: datum_rows.len() })
    }
}

/// When the iteration stops: the relative step below the tolerance, or twice on the round-off
/// floor (tiny but no longer shrinking); six growing steps in a row diverge.
struct StepProgress {
    prev_step: f64,
    growth: usize,
    floor_hits: usize,
    converged: bool,
}

impl StepProgress {
    fn new() -> Self {
        StepProgress { prev_step: f64::INFINITY, growth: 0, floor_hits: 0, converged: false }
    }

    /// Judges one iteration's relative `step` (`worst` names the unknown that made it).
    fn converged_after(&mut self, step: f64, tolerance: f64, iterations: usize, worst: &str) -> Result<bool, AdjustError> {
        if step <= tolerance {
            self.converged = true;
        } else if step <= tolerance * 1e4 && step >= 0.5 * self.prev_step {
            // Round-off floor: the step no longer shrinks although it is tiny.
            self.floor_hits += 1;
            if self.floor_hits >= 2 {
                self.converged = true;
            }
        }
        if step > self.prev_step && step > 1e-6 {
            self.growth += 1;
            if self.growth >= 6 {
                return Err(AdjustError::Diverged { iteration: iterations, reason: format!("updates grow for 6 iterations (largest at {worst}, relative step {step:.3e})") });
            }
        } else {
            self.growth = 0;
        }
        self.prev_step = step;
        Ok(self.converged)
    }
}

/// AA02 (spec §7.5): rank check before solving. A defect is an error without a datum; with a free
/// datum the null space G, restricted to the datum subset (which must determine it), gives the
/// datum restrictions.
fn datum_rows_of(ctx: &Ctx, comp: &Component, lin: &Linear, datum: Option<&[bool]>) -> Result<Vec<Vec<(usize, f64)>>, AdjustError> {
    let (p, opts, nloc) = (ctx.p, ctx.opts, comp.unknowns.len());
    let mut datum_rows: Vec<Vec<(usize, f64)>> = Vec::new();
    if nloc <= opts.dense_check_limit {
        let mut trip: Vec<(usize, usize, f64)> = lin.n_trip.clone();
        for (row, _) in &lin.c_rows {
            add_outer(&mut trip, row, row_weight(&lin.diag, row));
        }
        let (null, _) = dense_null_space(nloc, &trip);
        if null.is_empty() {
            return Ok(datum_rows);
        }
        let Some(subset) = datum else {
            return Err(AdjustError::Defect { defect: null.len(), unknowns: name_null_vectors(p, &comp.unknowns, &null) });
        };
        // G restricted to the datum subset; Gs must determine the null space.
        let d = null.len();
        let mut gtg = DMatrix::<f64>::zeros(d, d);
        for a in 0..d {
            for b in 0..d {
                gtg[(a, b)] = (0..nloc).filter(|&k| subset[comp.unknowns[k]]).map(|k| null[a][k] * null[b][k]).sum();
            }
        }
        let sv = gtg.clone().symmetric_eigen().eigenvalues;
        let smin = sv.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        if smin < 1e-12 {
            return Err(AdjustError::Defect { defect: d, unknowns: name_null_vectors(p, &comp.unknowns, &null) });
        }
        for g in &null {
            let row: Vec<(usize, f64)> = (0..nloc).filter(|&k| subset[comp.unknowns[k]] && g[k] != 0.0).map(|k| (k, g[k])).collect();
            datum_rows.push(row);
        }
    } else if datum.is_some() {
        return Err(AdjustError::ComponentTooLarge { unknowns: nloc, limit: opts.dense_check_limit, first: p.unknowns[comp.unknowns[0]].name.clone() });
    }
    Ok(datum_rows)
}

/// The linearised system of one iteration.
struct Linear {
    /// Per block: rows, M⁻¹, ŵ.
    blocks: Vec<(usize, Vec<Row>, DMatrix<f64>, DVector<f64>)>,
    n_trip: Vec<(usize, usize, f64)>,
    diag: Vec<f64>,
    w_n: Vec<f64>,
    /// Restriction rows (sparse over local unknowns) and w_g = −g.
    c_rows: Vec<(Vec<(usize, f64)>, f64)>,
}

fn add_outer(trip: &mut Vec<(usize, usize, f64)>, row: &[(usize, f64)], w: f64) {
    for &(i, ai) in row {
        for &(j, aj) in row {
            if i >= j {
                trip.push((i, j, w * ai * aj));
            }
        }
    }
}

/// Ω_i for folding a restriction into N̄: commensurate with the diagonal it touches.
fn row_weight(diag: &[f64], row: &[(usize, f64)]) -> f64 {
    let nn: f64 = row.iter().map(|&(_, a)| a * a).sum();
    let dm: f64 = row.iter().map(|&(i, _)| diag[i]).sum::<f64>() / row.len().max(1) as f64;
    let scale = if dm > 0.0 { dm } else { 1.0 };
    if nn > 0.0 {
        scale / nn
    } else {
        0.0
    }
}

fn assemble(
    ctx: &Ctx,
    comp: &Component,
    x: &Overlay,
    lv: &Overlay,
    v: &std::collections::HashMap<usize, f64>,
    local: &dyn Fn(usize) -> Option<usize>,
) -> Result<Linear, AdjustError> {
    let p = ctx.p;
    let nloc = comp.unknowns.len();
    let mut n_trip = Vec::new();
    let mut w_n = vec![0.0; nloc];
    let mut blocks_out = Vec::with_capacity(comp.blocks.len());
    for &bi in &comp.blocks {
        let b = &ctx.blocks[bi];
        let nb = b.conds.len();
        let no = b.obs.len();
        let mut rows = Vec::with_capacity(nb);
        for &ci in &b.conds {
            rows.push(ctx.eval_row(&ctx.nets[ci], ci, false, x, lv, local, &b.obs)?);
        }
        // B (nb × no), M = B Q Bᵀ, ŵ = −f + B v.
        let mut bm = DMatrix::<f64>::zeros(nb, no);
        for (r, row) in rows.iter().enumerate() {
            for &(k, g) in &row.b {
                bm[(r, k)] += g;
            }
        }
        let vb = DVector::from_iterator(no, b.obs.iter().map(|o| v.get(o).copied().unwrap_or(0.0)));
        let bv = &bm * &vb;
        let what = DVector::from_iterator(nb, rows.iter().enumerate().map(|(r, row)| -row.f + bv[r]));
        let m = &bm * &b.q * bm.transpose();
        let minv = match m.clone().cholesky() {
            Some(c) => c.inverse(),
            None => {
                // Name the condition whose observation gradient vanishes (or the first one).
                let bad = (0..nb).find(|&r| bm.row(r).amax() == 0.0).unwrap_or(0);
                return Err(AdjustError::SingularM { condition: p.conditions[b.conds[bad]].name.clone() });
            }
        };
        // N += Aᵀ M⁻¹ A ; w_N += Aᵀ M⁻¹ ŵ
        let mw = &minv * &what;
        for r in 0..nb {
            for &(i, ai) in &rows[r].a {
                w_n[i] += ai * mw[r];
                for s in 0..nb {
                    let wrs = minv[(r, s)];
                    if wrs == 0.0 {
                        continue;
                    }
                    for &(j, aj) in &rows[s].a {
                        if i >= j {
                            n_trip.push((i, j, ai * wrs * aj));
                        }
                    }
                }
            }
        }
        blocks_out.push((bi, rows, minv, what));
    }
    let mut diag = vec![0.0; nloc];
    for &(i, j, val) in &n_trip {
        if i == j {
            diag[i] += val;
        }
    }
    let mut c_rows = Vec::with_capacity(comp.restrictions.len());
    for &ri in &comp.restrictions {
        let row = ctx.eval_row(&ctx.rnets[ri], ri, true, x, lv, local, &[])?;
        c_rows.push((row.a, -row.f));
    }
    Ok(Linear { blocks: blocks_out, n_trip, diag, w_n, c_rows })
}

struct Stats {
    /// (redundancy number, normalised residual w, sqrt(Q_vv,ii)) per observation in block order.
    per_obs: Vec<(f64, f64, f64)>,
    qxx_diag: Option<Vec<f64>>,
}

struct LinSol {
    dx: Vec<f64>,
    v_new: Vec<(usize, f64)>,
    stats: Option<Stats>,
}

/// One Gauss–Helmert step of a component with its restrictions (model, then datum) by the
/// bordered normal system; `with_stats` adds the redundancy numbers, normalised residuals and,
/// when asked for, the unknowns' cofactors.
fn solve_linear(ctx: &Ctx, comp: &Component, lin: &Linear, datum_rows: &[Vec<(usize, f64)>], with_stats: bool) -> Result<LinSol, AdjustError> {
    let sys = Bordered::new(ctx, comp, lin, datum_rows)?;
    let dx = sys.increment();
    let (v_new, v_blocks) = residuals(ctx, lin, &dx);
    let stats = with_stats.then(|| Stats {
        per_obs: sys.observation_stats(ctx, lin, &v_blocks),
        qxx_diag: ctx.opts.unknown_sigmas.then(|| sys.qxx_diagonal()),
    });
    Ok(LinSol { dx, v_new, stats })
}

/// The factored normal system of one component bordered by its restrictions C: N̄ = N + Σ Ω_i c_i c_iᵀ
/// (sparse Cholesky), Y = N̄⁻¹ Cᵀ and the Cholesky factor of S = C Y (none without restrictions).
/// Adding Ω_i c_i c_iᵀ keeps N̄ regular where N alone has the datum defect.
struct Bordered<'r> {
    /// All restriction rows with their w_g: model restrictions then datum ones (w_g = 0).
    c_all: Vec<(&'r [(usize, f64)], f64)>,
    /// w_N + Σ Ω_i c_i w_g,i.
    rhs: Vec<f64>,
    factor: Factor,
    y: Mat<f64>,
    s_chol: Option<nalgebra::linalg::Cholesky<f64, nalgebra::Dyn>>,
}

impl<'r> Bordered<'r> {
    fn new(ctx: &Ctx, comp: &Component, lin: &'r Linear, datum_rows: &'r [Vec<(usize, f64)>]) -> Result<Self, AdjustError> {
        let nloc = comp.unknowns.len();
        let mut c_all: Vec<(&[(usize, f64)], f64)> = lin.c_rows.iter().map(|(r, w)| (r.as_slice(), *w)).collect();
        for r in datum_rows {
            c_all.push((r.as_slice(), 0.0));
        }
        let (trip, rhs) = bordered_normals(lin, &c_all);
        let factor = factor_normals(ctx.p, comp, &trip)?;
        // Y = N̄⁻¹ Cᵀ
        let mut y = Mat::<f64>::zeros(nloc, c_all.len());
        for (c, (row, _)) in c_all.iter().enumerate() {
            for &(i, a) in row.iter() {
                y[(i, c)] += a;
            }
        }
        factor.solve(&mut y);
        let s_chol = restriction_factor(ctx.p, comp, lin, &c_all, &y)?;
        Ok(Bordered { c_all, rhs, factor, y, s_chol })
    }

    fn nloc(&self) -> usize {
        self.y.nrows()
    }

    fn np(&self) -> usize {
        self.c_all.len()
    }

    /// y0 = N̄⁻¹ rhs ; k = S⁻¹ (C y0 − w_g) ; Δx = y0 − Y k
    fn increment(&self) -> Vec<f64> {
        let (nloc, np) = (self.nloc(), self.np());
        let mut y0 = Mat::<f64>::zeros(nloc, 1);
        for i in 0..nloc {
            y0[(i, 0)] = self.rhs[i];
        }
        self.factor.solve(&mut y0);
        let mut dx: Vec<f64> = (0..nloc).map(|i| y0[(i, 0)]).collect();
        if let Some(sc) = &self.s_chol {
            let t = DVector::from_iterator(np, self.c_all.iter().map(|(row, wg)| row.iter().map(|&(i, a)| a * y0[(i, 0)]).sum::<f64>() - wg));
            let k = sc.solve(&t);
            for (i, d) in dx.iter_mut().enumerate() {
                *d -= (0..np).map(|c| self.y[(i, c)] * k[c]).sum::<f64>();
            }
        }
        dx
    }

    /// Per observation in block order: (redundancy number, normalised residual w, sqrt(Q_vv,ii)).
    fn observation_stats(&self, ctx: &Ctx, lin: &Linear, v_blocks: &[DVector<f64>]) -> Vec<(f64, f64, f64)> {
        let mut per_obs = Vec::new();
        for (bidx, (bi, rows, minv, _)) in lin.blocks.iter().enumerate() {
            let b = &ctx.blocks[*bi];
            let h = self.block_qxx_form(rows);
            let qkk = minv - minv * &h * minv;
            let mut bm = DMatrix::<f64>::zeros(rows.len(), b.obs.len());
            for (r, row) in rows.iter().enumerate() {
                for &(k, g) in &row.b {
                    bm[(r, k)] += g;
                }
            }
            let btqb = bm.transpose() * &qkk * &bm; // Bᵀ Q_kk B = P Q_vv P
            let qvv = &b.q * &btqb * &b.q;
            let rr = &b.q * &btqb; // Q_vv P
            let qinv = b.q.clone().cholesky().expect("Q positive definite").inverse();
            let pv = &qinv * &v_blocks[bidx];
            for k in 0..b.obs.len() {
                let r_i = rr[(k, k)];
                let ppp = btqb[(k, k)];
                let w = if ppp > 1e-14 * qinv[(k, k)] { pv[k].abs() / ppp.sqrt() } else { 0.0 };
                per_obs.push((r_i, w, qvv[(k, k)].max(0.0).sqrt()));
            }
        }
        per_obs
    }

    /// The block's Q_xx quadratic form H = A Q_xx Aᵀ with Q_xx = N̄⁻¹ − Y S⁻¹ Yᵀ (zero when the
    /// block's rows involve no unknown).
    fn block_qxx_form(&self, rows: &[Row]) -> DMatrix<f64> {
        let (nloc, np, nb) = (self.nloc(), self.np(), rows.len());
        let mut h = DMatrix::<f64>::zeros(nb, nb);
        if !rows.iter().any(|r| !r.a.is_empty()) {
            return h;
        }
        let mut z = Mat::<f64>::zeros(nloc, nb);
        for (r, row) in rows.iter().enumerate() {
            for &(i, a) in &row.a {
                z[(i, r)] += a;
            }
        }
        self.factor.solve(&mut z);
        for r in 0..nb {
            for s2 in 0..nb {
                h[(r, s2)] = rows[r].a.iter().map(|&(i, a)| a * z[(i, s2)]).sum();
            }
        }
        if let Some(sc) = &self.s_chol {
            // (A Y) S⁻¹ (A Y)ᵀ
            let mut ay = DMatrix::<f64>::zeros(nb, np);
            for r in 0..nb {
                for c in 0..np {
                    ay[(r, c)] = rows[r].a.iter().map(|&(i, a)| a * self.y[(i, c)]).sum();
                }
            }
            let sinv_ayt = sc.solve(&ay.transpose());
            h -= &ay * sinv_ayt;
        }
        h
    }

    /// diag(Q_xx), solved for 64 unit vectors at a time to bound the memory of the dense right side.
    fn qxx_diagonal(&self) -> Vec<f64> {
        let (nloc, np) = (self.nloc(), self.np());
        let mut out = vec![0.0; nloc];
        let chunk = 64;
        let mut start = 0;
        while start < nloc {
            let end = (start + chunk).min(nloc);
            let mut e = Mat::<f64>::zeros(nloc, end - start);
            for k in start..end {
                e[(k, k - start)] = 1.0;
            }
            self.factor.solve(&mut e);
            for k in start..end {
                let mut q = e[(k, k - start)];
                if let Some(sc) = &self.s_chol {
                    let yk = DVector::from_iterator(np, (0..np).map(|c| self.y[(k, c)]));
                    q -= yk.dot(&sc.solve(&yk));
                }
                out[k] = q;
            }
            start = end;
        }
        out
    }
}

/// N̄ = N + Σ Ω_i c_i c_iᵀ (lower triplets) and rhs = w_N + Σ Ω_i c_i w_g,i.
fn bordered_normals(lin: &Linear, c_all: &[(&[(usize, f64)], f64)]) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
    let mut trip = lin.n_trip.clone();
    let mut rhs = lin.w_n.clone();
    for (row, wg) in c_all {
        let om = row_weight(&lin.diag, row);
        add_outer(&mut trip, row, om);
        for &(i, a) in row.iter() {
            rhs[i] += om * a * wg;
        }
    }
    (trip, rhs)
}

/// The sparse Cholesky factor of N̄; a non-positive pivot is a datum defect the restrictions did
/// not remove, named by its unknown.
fn factor_normals(p: &Problem, comp: &Component, trip: &[(usize, usize, f64)]) -> Result<Factor, AdjustError> {
    let ftrip: Vec<Triplet<usize, usize, f64>> = trip.iter().map(|&(i, j, v)| Triplet::new(i, j, v)).collect();
    Factor::new(comp.unknowns.len(), &ftrip).map_err(|idx| {
        let name = idx.map(|k| p.unknowns[comp.unknowns[k]].name.clone()).unwrap_or_else(|| p.unknowns[comp.unknowns[0]].name.clone());
        AdjustError::Defect { defect: 1, unknowns: vec![name] }
    })
}

/// The Cholesky factor of S = C Y (symmetrised), after a scale-aware dependence check of the
/// restrictions (spec §4.1: they must be independent), which names the dependent ones.
fn restriction_factor(
    p: &Problem,
    comp: &Component,
    lin: &Linear,
    c_all: &[(&[(usize, f64)], f64)],
    y: &Mat<f64>,
) -> Result<Option<nalgebra::linalg::Cholesky<f64, nalgebra::Dyn>>, AdjustError> {
    let np = c_all.len();
    if np == 0 {
        return Ok(None);
    }
    let mut s = DMatrix::<f64>::zeros(np, np);
    for (a, (row, _)) in c_all.iter().enumerate() {
        for b in 0..np {
            s[(a, b)] = row.iter().map(|&(i, v)| v * y[(i, b)]).sum();
        }
    }
    let s = (&s + s.transpose()) * 0.5;
    let d: Vec<f64> = (0..np).map(|i| s[(i, i)].abs().sqrt().max(1e-300)).collect();
    let mut sc = s.clone();
    for i in 0..np {
        for j in 0..np {
            sc[(i, j)] /= d[i] * d[j];
        }
    }
    let e = sc.clone().symmetric_eigen();
    let emin = e.eigenvalues.iter().fold(f64::INFINITY, |a, &b| a.min(b));
    if emin < 1e-12 {
        let k = e.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |m| m.0);
        let vecs = e.eigenvectors.column(k);
        let mx = vecs.amax();
        let names: Vec<String> = (0..np)
            .filter(|&i| vecs[i].abs() > 0.05 * mx)
            .map(|i| if i < lin.c_rows.len() { p.restrictions[comp.restrictions[i]].name.clone() } else { format!("free-datum condition {}", i - lin.c_rows.len() + 1) })
            .collect();
        return Err(AdjustError::DependentRestrictions { restrictions: names });
    }
    Ok(Some(s.clone().cholesky().ok_or_else(|| AdjustError::DependentRestrictions { restrictions: vec![] })?))
}

/// Residuals per block: λ_b = M⁻¹(ŵ − A Δx), v = Q Bᵀ λ; as (observation, v) in block order and
/// as one vector per block.
fn residuals(ctx: &Ctx, lin: &Linear, dx: &[f64]) -> (Vec<(usize, f64)>, Vec<DVector<f64>>) {
    let mut v_new = Vec::new();
    let mut v_blocks: Vec<DVector<f64>> = Vec::with_capacity(lin.blocks.len());
    for (bi, rows, minv, what) in &lin.blocks {
        let b = &ctx.blocks[*bi];
        let adx = DVector::from_iterator(rows.len(), rows.iter().map(|r| r.a.iter().map(|&(i, a)| a * dx[i]).sum::<f64>()));
        let lam = minv * (what - adx);
        let mut btl = DVector::<f64>::zeros(b.obs.len());
        for (r, row) in rows.iter().enumerate() {
            for &(k, g) in &row.b {
                btl[k] += g * lam[r];
            }
        }
        let vb = &b.q * btl;
        for (k, &o) in b.obs.iter().enumerate() {
            v_new.push((o, vb[k]));
        }
        v_blocks.push(vb);
    }
    (v_new, v_blocks)
}

/// Hard datum (spec §4.7.3): choose a minimal set of unknowns from `candidates` (in the given
/// order, e.g. plane d's first, then normal parameters) whose fixing removes the datum defect. The
/// defect's null space is computed numerically as for the free datum; an unknown is taken when its
/// row of the null-space basis raises the rank of the rows taken so far.
pub fn hard_datum_choice(problem: &Problem, candidates: &[UnknownId], opts: &Options) -> Result<Vec<UnknownId>, AdjustError> {
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
        let (group, rest): (Vec<_>, Vec<_>) = remaining.into_iter().partition(|v| v.iter().any(|(u, _)| first.contains(&u.0)));
        remaining = rest;
        let d = group.len();
        let maps: Vec<std::collections::HashMap<usize, f64>> = group.iter().map(|v| v.iter().map(|(u, g)| (u.0, *g)).collect()).collect();
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
            let names = group.iter().flat_map(|v| v.iter().map(|(u, _)| problem.unknown_name(*u).to_string())).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
            return Err(AdjustError::Defect { defect: d - rows.len(), unknowns: names });
        }
    }
    Ok(chosen)
}
