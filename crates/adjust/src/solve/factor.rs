//! Factorisations: the sparse Cholesky of the normal matrix and the dense null-space analysis
//! that finds (and names) a datum defect.

use super::*;

/// Sparse Cholesky of a symmetric positive definite matrix given by lower-triangle triplets.
pub(super) struct Factor {
    pub(super) symbolic: SymbolicCholesky<usize>,
    pub(super) values: Vec<f64>,
}

impl Factor {
    pub(super) fn new(n: usize, trip: &[Triplet<usize, usize, f64>]) -> Result<Factor, Option<usize>> {
        let mat = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, trip).map_err(|_| None)?;
        let symbolic =
            factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, SymmetricOrdering::Amd, Default::default())
                .map_err(|_| None)?;
        let mut values = vec![0.0; symbolic.len_val()];
        let par = Par::Seq;
        let mut buf = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        let res = symbolic.factorize_numeric_llt::<f64>(
            &mut values,
            mat.as_ref(),
            Side::Lower,
            Default::default(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        );
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

    pub(super) fn solve(&self, rhs: &mut Mat<f64>) {
        let par = Par::Seq;
        let k = rhs.ncols();
        let llt = faer::sparse::linalg::cholesky::LltRef::<'_, usize, f64>::new(&self.symbolic, &self.values);
        let mut buf = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(k, par));
        llt.solve_in_place_with_conj(Conj::No, rhs.as_mut(), par, MemStack::new(&mut buf));
    }
}

/// Dense symmetric null-space analysis of a (scaled) matrix: returns null vectors (columns).
pub(super) fn dense_null_space(n: usize, trip: &[(usize, usize, f64)]) -> (Vec<DVector<f64>>, Vec<f64>) {
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

pub(super) fn name_null_vectors(p: &Problem, unknowns: &[usize], null: &[DVector<f64>]) -> Vec<String> {
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
