//! The Gauss–Helmert iteration of one component: state, convergence, datum restrictions.

use super::*;

pub(super) fn solve_component(ctx: &Ctx, comp: &Component, datum: Option<&[bool]>) -> Result<CompResult, AdjustError> {
    let (p, opts) = (ctx.p, ctx.opts);
    let mut local_map: std::collections::HashMap<usize, usize> =
        comp.unknowns.iter().enumerate().map(|(k, &u)| (u, k)).collect();
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
            return Ok(CompResult {
                null: datum_rows,
                x: xs,
                obs: vec![],
                qxx_diag: None,
                iterations: 0,
                vtpv: 0.0,
                redundancy: 0,
                datum_rows: 0,
            });
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
        return Err(AdjustError::NotConverged {
            iterations: opts.max_iterations,
            step: progress.prev_step,
            first: p.unknowns[comp.unknowns[0]].name.clone(),
        });
    }
    let lin = last.expect("linear system");
    state.result(ctx, comp, &lin, &datum_rows, iterations)
}

/// The current state of a component's iteration: the unknowns x (global, for evaluation), the
/// residuals v and l + v of its observations.
pub(super) struct IterationState<'a> {
    pub(super) x: Overlay<'a>,
    pub(super) v: std::collections::HashMap<usize, f64>,
    pub(super) lv: Overlay<'a>,
}

impl<'a> IterationState<'a> {
    pub(super) fn new(ctx: &'a Ctx, comp: &Component) -> Self {
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
    pub(super) fn apply(
        &mut self,
        p: &Problem,
        comp: &Component,
        sol: &LinSol,
        iterations: usize,
    ) -> Result<(f64, usize), AdjustError> {
        let mut step = 0.0f64;
        let mut worst = 0usize;
        for (k, &u) in comp.unknowns.iter().enumerate() {
            let s = sol.dx[k].abs() / (1.0 + self.x[u].abs());
            if !(s.is_finite()) {
                return Err(AdjustError::Diverged {
                    iteration: iterations,
                    reason: format!("non-finite update of {}", p.unknowns[u].name),
                });
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
                return Err(AdjustError::Diverged {
                    iteration: iterations,
                    reason: format!("non-finite residual of {}", p.obs[o].name),
                });
            }
            step = step.max(s);
            self.lv[o] = p.obs[o].value + vn;
        }
        if step > 1e8 {
            return Err(AdjustError::Diverged {
                iteration: iterations,
                reason: format!("update of {} exploded (relative step {step:.3e})", p.unknowns[worst].name),
            });
        }
        Ok((step, worst))
    }

    /// The converged component: vᵀPv, residuals and (with `opts.statistics`) redundancy numbers,
    /// normalised residuals and the unknowns' cofactors from one more solve at the solution.
    pub(super) fn result(
        &self,
        ctx: &Ctx,
        comp: &Component,
        lin: &Linear,
        datum_rows: &[Vec<(usize, f64)>],
        iterations: usize,
    ) -> Result<CompResult, AdjustError> {
        let opts = ctx.opts;
        let m_cond: usize = comp.blocks.iter().map(|&b| ctx.blocks[b].conds.len()).sum();
        let redundancy =
            m_cond as i64 + (comp.restrictions.len() + datum_rows.len()) as i64 - comp.unknowns.len() as i64;
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
        Ok(CompResult {
            null: vec![],
            x: xs,
            obs: obs_out,
            qxx_diag,
            iterations,
            vtpv,
            redundancy,
            datum_rows: datum_rows.len(),
        })
    }
}

/// When the iteration stops: the relative step below the tolerance, or twice on the round-off
/// floor (tiny but no longer shrinking); six growing steps in a row diverge.
pub(super) struct StepProgress {
    pub(super) prev_step: f64,
    pub(super) growth: usize,
    pub(super) floor_hits: usize,
    pub(super) converged: bool,
}

impl StepProgress {
    pub(super) fn new() -> Self {
        StepProgress { prev_step: f64::INFINITY, growth: 0, floor_hits: 0, converged: false }
    }

    /// Judges one iteration's relative `step` (`worst` names the unknown that made it).
    pub(super) fn converged_after(
        &mut self,
        step: f64,
        tolerance: f64,
        iterations: usize,
        worst: &str,
    ) -> Result<bool, AdjustError> {
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
                return Err(AdjustError::Diverged {
                    iteration: iterations,
                    reason: format!("updates grow for 6 iterations (largest at {worst}, relative step {step:.3e})"),
                });
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
pub(super) fn datum_rows_of(
    ctx: &Ctx,
    comp: &Component,
    lin: &Linear,
    datum: Option<&[bool]>,
) -> Result<Vec<Vec<(usize, f64)>>, AdjustError> {
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
            return Err(AdjustError::Defect {
                defect: null.len(),
                unknowns: name_null_vectors(p, &comp.unknowns, &null),
            });
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
            let row: Vec<(usize, f64)> =
                (0..nloc).filter(|&k| subset[comp.unknowns[k]] && g[k] != 0.0).map(|k| (k, g[k])).collect();
            datum_rows.push(row);
        }
    } else if datum.is_some() {
        return Err(AdjustError::ComponentTooLarge {
            unknowns: nloc,
            limit: opts.dense_check_limit,
            first: p.unknowns[comp.unknowns[0]].name.clone(),
        });
    }
    Ok(datum_rows)
}
