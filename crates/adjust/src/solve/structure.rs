//! The structure of a problem: parameter nets per condition, M blocks of conditions coupled
//! through shared or correlated observations, and the independent components adjusted one by one.

use super::*;

/// One group of conditions coupled through shared or correlated observations (one M block).
pub(super) struct Block {
    pub(super) conds: Vec<usize>,
    pub(super) obs: Vec<usize>,
    /// Q_ll of the block's observations (dense, small), in σ0² units.
    pub(super) q: DMatrix<f64>,
}

pub(super) struct Component {
    /// Global unknown ids of this component (active, i.e. not fixed).
    pub(super) unknowns: Vec<usize>,
    pub(super) blocks: Vec<usize>,
    pub(super) restrictions: Vec<usize>,
}

/// Per-condition parameter-net resolution: distinct variables and slot maps (spec §6.2).
pub(super) struct Net {
    /// Distinct unknown ids (global) of the equation, then distinct observations.
    pub(super) unk: Vec<usize>,
    pub(super) obs: Vec<usize>,
    pub(super) xmap: Vec<(usize, f64)>,
    pub(super) lmap: Vec<usize>,
}

pub(super) fn build_net(x: &[crate::problem::Slot], l: &[ObsId]) -> Net {
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

pub(super) struct UnionFind(Vec<usize>);
impl UnionFind {
    pub(super) fn new(n: usize) -> Self {
        UnionFind((0..n).collect())
    }
    pub(super) fn find(&mut self, mut a: usize) -> usize {
        while self.0[a] != a {
            self.0[a] = self.0[self.0[a]];
            a = self.0[a];
        }
        a
    }
    pub(super) fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.0[a.max(b)] = a.min(b);
        }
    }
}

/// M blocks: conditions coupled through shared observations or covariance groups, each with its
/// observations and their cofactor matrix Q = C / σ0².
pub(super) fn condition_blocks(p: &Problem, nets: &[Net], opts: &Options) -> Vec<Block> {
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
pub(super) fn components(
    p: &Problem,
    nets: &[Net],
    rnets: &[Net],
    blocks: &[Block],
) -> Result<Vec<Component>, AdjustError> {
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
    let untouched: Vec<String> =
        (0..nu).filter(|&u| active(u) && !touched[u]).map(|u| p.unknowns[u].name.clone()).collect();
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
