//! One step solved through the bordered normal system (restrictions folded into N̄, met exactly
//! through the Schur complement), with the post-adjustment statistics.

use super::*;

pub(super) struct Stats {
    /// (redundancy number, normalised residual w, sqrt(Q_vv,ii)) per observation in block order.
    pub(super) per_obs: Vec<(f64, f64, f64)>,
    pub(super) qxx_diag: Option<Vec<f64>>,
}

pub(super) struct LinSol {
    pub(super) dx: Vec<f64>,
    pub(super) v_new: Vec<(usize, f64)>,
    pub(super) stats: Option<Stats>,
}

/// One Gauss–Helmert step of a component with its restrictions (model, then datum) by the
/// bordered normal system; `with_stats` adds the redundancy numbers, normalised residuals and,
/// when asked for, the unknowns' cofactors.
pub(super) fn solve_linear(
    ctx: &Ctx,
    comp: &Component,
    lin: &Linear,
    datum_rows: &[Vec<(usize, f64)>],
    with_stats: bool,
) -> Result<LinSol, AdjustError> {
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
pub(super) struct Bordered<'r> {
    /// All restriction rows with their w_g: model restrictions then datum ones (w_g = 0).
    pub(super) c_all: Vec<(&'r [(usize, f64)], f64)>,
    /// w_N + Σ Ω_i c_i w_g,i.
    pub(super) rhs: Vec<f64>,
    pub(super) factor: Factor,
    pub(super) y: Mat<f64>,
    pub(super) s_chol: Option<nalgebra::linalg::Cholesky<f64, nalgebra::Dyn>>,
}

impl<'r> Bordered<'r> {
    pub(super) fn new(
        ctx: &Ctx,
        comp: &Component,
        lin: &'r Linear,
        datum_rows: &'r [Vec<(usize, f64)>],
    ) -> Result<Self, AdjustError> {
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

    pub(super) fn nloc(&self) -> usize {
        self.y.nrows()
    }

    pub(super) fn np(&self) -> usize {
        self.c_all.len()
    }

    /// y0 = N̄⁻¹ rhs ; k = S⁻¹ (C y0 − w_g) ; Δx = y0 − Y k
    pub(super) fn increment(&self) -> Vec<f64> {
        let (nloc, np) = (self.nloc(), self.np());
        let mut y0 = Mat::<f64>::zeros(nloc, 1);
        for i in 0..nloc {
            y0[(i, 0)] = self.rhs[i];
        }
        self.factor.solve(&mut y0);
        let mut dx: Vec<f64> = (0..nloc).map(|i| y0[(i, 0)]).collect();
        if let Some(sc) = &self.s_chol {
            let t = DVector::from_iterator(
                np,
                self.c_all.iter().map(|(row, wg)| row.iter().map(|&(i, a)| a * y0[(i, 0)]).sum::<f64>() - wg),
            );
            let k = sc.solve(&t);
            for (i, d) in dx.iter_mut().enumerate() {
                *d -= (0..np).map(|c| self.y[(i, c)] * k[c]).sum::<f64>();
            }
        }
        dx
    }

    /// Per observation in block order: (redundancy number, normalised residual w, sqrt(Q_vv,ii)).
    pub(super) fn observation_stats(&self, ctx: &Ctx, lin: &Linear, v_blocks: &[DVector<f64>]) -> Vec<(f64, f64, f64)> {
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
    pub(super) fn block_qxx_form(&self, rows: &[Row]) -> DMatrix<f64> {
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
    pub(super) fn qxx_diagonal(&self) -> Vec<f64> {
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
pub(super) fn bordered_normals(lin: &Linear, c_all: &[(&[(usize, f64)], f64)]) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
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
pub(super) fn factor_normals(
    p: &Problem,
    comp: &Component,
    trip: &[(usize, usize, f64)],
) -> Result<Factor, AdjustError> {
    let ftrip: Vec<Triplet<usize, usize, f64>> = trip.iter().map(|&(i, j, v)| Triplet::new(i, j, v)).collect();
    Factor::new(comp.unknowns.len(), &ftrip).map_err(|idx| {
        let name = idx
            .map(|k| p.unknowns[comp.unknowns[k]].name.clone())
            .unwrap_or_else(|| p.unknowns[comp.unknowns[0]].name.clone());
        AdjustError::Defect { defect: 1, unknowns: vec![name] }
    })
}

/// The Cholesky factor of S = C Y (symmetrised), after a scale-aware dependence check of the
/// restrictions (spec §4.1: they must be independent), which names the dependent ones.
pub(super) fn restriction_factor(
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
            .map(|i| {
                if i < lin.c_rows.len() {
                    p.restrictions[comp.restrictions[i]].name.clone()
                } else {
                    format!("free-datum condition {}", i - lin.c_rows.len() + 1)
                }
            })
            .collect();
        return Err(AdjustError::DependentRestrictions { restrictions: names });
    }
    Ok(Some(s.clone().cholesky().ok_or_else(|| AdjustError::DependentRestrictions { restrictions: vec![] })?))
}

/// Residuals per block: λ_b = M⁻¹(ŵ − A Δx), v = Q Bᵀ λ; as (observation, v) in block order and
/// as one vector per block.
pub(super) fn residuals(ctx: &Ctx, lin: &Linear, dx: &[f64]) -> (Vec<(usize, f64)>, Vec<DVector<f64>>) {
    let mut v_new = Vec::new();
    let mut v_blocks: Vec<DVector<f64>> = Vec::with_capacity(lin.blocks.len());
    for (bi, rows, minv, what) in &lin.blocks {
        let b = &ctx.blocks[*bi];
        let adx =
            DVector::from_iterator(rows.len(), rows.iter().map(|r| r.a.iter().map(|&(i, a)| a * dx[i]).sum::<f64>()));
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
