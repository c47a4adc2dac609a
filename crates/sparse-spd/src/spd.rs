//! The direct-first policy: Cholesky where it is possible and accurate, CG where not.

use crate::cholesky::cholesky_solve;
use crate::csr::{det_dot, SymCsr};
use crate::pcg::{pcg, true_residual, PcgOptions, Preconditioner};
use crate::NotConverged;

/// How [`solve_spd`] goes about a system.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Try the Cholesky first (false: CG only, e.g. to measure one against the other).
    pub direct: bool,
    /// Largest Cholesky factor (bytes of its values) to build; bigger systems take the CG.
    pub max_factor_bytes: usize,
    /// A Cholesky answer with a true relative residual up to this is returned as it is; above
    /// it CG continues from it.
    pub direct_accept: f64,
    /// The CG (Jacobi-preconditioned) when the direct answer is missing or not accurate.
    pub cg: PcgOptions,
}

/// How a system was solved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveInfo {
    /// "cholesky" or "cg".
    pub method: &'static str,
    /// CG iterations (0 for Cholesky).
    pub iterations: usize,
    /// ‖b − A x‖ / ‖b‖ of the returned x.
    pub relative_residual: f64,
    /// Whether the symbolic factorisation of the previous system was re-used.
    pub symbolic_reused: bool,
}

/// Solves A x = b for a symmetric positive definite A: Cholesky (one refinement step) when
/// `opts.direct` and the factorisation succeeds; CG from the Cholesky answer when that is not
/// accurate enough; Jacobi-PCG from `x0` when the factorisation was refused (too large, not
/// positive definite). Err when the CG misses its tolerance.
pub fn solve_spd(
    a: &SymCsr,
    b: &[f64],
    x0: &[f64],
    opts: &SolveOptions,
) -> Result<(Vec<f64>, SolveInfo), NotConverged> {
    let bnorm = det_dot(b, b, opts.cg.dot_chunk).sqrt().max(1e-300);
    if opts.direct {
        if let Ok((x, reused)) = cholesky_solve(a, b, opts.max_factor_bytes) {
            let res = true_residual(a, b, &x, bnorm, opts.cg.dot_chunk);
            if res <= opts.direct_accept {
                return Ok((
                    x,
                    SolveInfo { method: "cholesky", iterations: 0, relative_residual: res, symbolic_reused: reused },
                ));
            }
            return jacobi_cg(a, b, &x, &opts.cg).map(|(x, info)| (x, SolveInfo { symbolic_reused: reused, ..info }));
        }
    }
    jacobi_cg(a, b, x0, &opts.cg)
}

/// Jacobi-preconditioned CG from `x0`.
pub fn jacobi_cg(a: &SymCsr, b: &[f64], x0: &[f64], opts: &PcgOptions) -> Result<(Vec<f64>, SolveInfo), NotConverged> {
    let mut x = x0.to_vec();
    let st = pcg(a, b, &mut x, &Preconditioner::jacobi(a), opts, None)?;
    Ok((
        x,
        SolveInfo {
            method: "cg",
            iterations: st.iterations,
            relative_residual: st.true_residual,
            symbolic_reused: false,
        },
    ))
}
