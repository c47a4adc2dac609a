//! The linearised system of one iteration: rows, M blocks and the normal-matrix triplets.

use super::*;

/// The linearised system of one iteration.
pub(super) struct Linear {
    /// Per block: rows, M⁻¹, ŵ.
    pub(super) blocks: Vec<(usize, Vec<Row>, DMatrix<f64>, DVector<f64>)>,
    pub(super) n_trip: Vec<(usize, usize, f64)>,
    pub(super) diag: Vec<f64>,
    pub(super) w_n: Vec<f64>,
    /// Restriction rows (sparse over local unknowns) and w_g = −g.
    pub(super) c_rows: Vec<(Vec<(usize, f64)>, f64)>,
}

pub(super) fn add_outer(trip: &mut Vec<(usize, usize, f64)>, row: &[(usize, f64)], w: f64) {
    for &(i, ai) in row {
        for &(j, aj) in row {
            if i >= j {
                trip.push((i, j, w * ai * aj));
            }
        }
    }
}

/// Ω_i for folding a restriction into N̄: commensurate with the diagonal it touches.
pub(super) fn row_weight(diag: &[f64], row: &[(usize, f64)]) -> f64 {
    let nn: f64 = row.iter().map(|&(_, a)| a * a).sum();
    let dm: f64 = row.iter().map(|&(i, _)| diag[i]).sum::<f64>() / row.len().max(1) as f64;
    let scale = if dm > 0.0 { dm } else { 1.0 };
    if nn > 0.0 {
        scale / nn
    } else {
        0.0
    }
}

pub(super) fn assemble(
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
