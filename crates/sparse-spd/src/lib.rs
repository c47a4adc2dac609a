//! Sparse symmetric positive definite systems, the one module for them in the workspace
//! (issue 16: tspline's least-squares fit and implicit's DSI had each written their own CSR
//! matrix and conjugate gradients, and tspline's never reported non-convergence).
//!
//! - [`SymCsr`]: a symmetric matrix in CSR with both triangles stored, columns sorted;
//!   [`SymCsr::sum`] merges several on the union of their patterns.
//! - [`cholesky_solve`]: faer's supernodal sparse Cholesky (AMD ordering) with one step of
//!   iterative refinement; the symbolic factorisation is re-used while consecutive systems of
//!   a thread have the same pattern.
//! - [`pcg`]: preconditioned conjugate gradients, [`Preconditioner::Jacobi`] or
//!   [`Preconditioner::Ic0`], with an optional [`Checkpoint`] at a loose tolerance; the answer
//!   is judged by its true residual ‖b − A x‖/‖b‖ and a miss is a [`NotConverged`] error.
//! - [`solve_spd`]: the direct-first policy (Cholesky, CG where the factor is refused or not
//!   accurate enough).
//!
//! Every reduction has a fixed order (rows summed in column order, dot products in fixed
//! chunks, [`det_dot`]), so a solve gives bit-identical answers on any thread count.
//!
//! # Examples
//!
//! The 1-D Laplacian tridiag(−1, 2, −1) with b = (1, 0, …, 0, 1) has the solution x = 1,
//! found by both solvers:
//!
//! ```
//! use sparse_spd::{laplacian_1d, pcg, solve_spd, PcgOptions, Preconditioner, SolveOptions};
//! let n = 100;
//! let a = laplacian_1d(n, 0.0);
//! let mut b = vec![0.0; n];
//! (b[0], b[n - 1]) = (1.0, 1.0);
//! let cg = PcgOptions::new(1e-12, 1000);
//! let opts = SolveOptions { direct: true, max_factor_bytes: 1 << 20, direct_accept: 1e-12, cg };
//! let (x, info) = solve_spd(&a, &b, &vec![0.0; n], &opts).unwrap();
//! assert_eq!(info.method, "cholesky");
//! assert!(x.iter().all(|v| (v - 1.0).abs() < 1e-10));
//!
//! let mut y = vec![0.0; n];
//! let stats = pcg(&a, &b, &mut y, &Preconditioner::ic0(&a), &cg, None).unwrap();
//! assert!(stats.true_residual <= 1e-12);
//! assert!(y.iter().all(|v| (v - 1.0).abs() < 1e-8));
//! // Three iterations cannot get there: an error, not an approximate answer.
//! let mut z = vec![0.0; n];
//! let err = pcg(&a, &b, &mut z, &Preconditioner::jacobi(&a), &PcgOptions::new(1e-12, 3), None).unwrap_err();
//! assert_eq!(err.iterations, 3);
//! ```

// `!(x > 0.0)` is meant: a NaN pivot, curvature or residual must fail the test
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod cholesky;
mod csr;
mod pcg;
mod spd;

pub use cholesky::{
    cholesky_solve, cholesky_symbolic, clear_symbolic, install_symbolic, release_workspace, symbolic_cached,
    CholeskyError, Symbolic,
};
pub use csr::{det_dot, laplacian_1d, SymCsr};
pub use pcg::{pcg, CgStats, Checkpoint, Ic0, PcgOptions, Preconditioner, DEFAULT_DOT_CHUNK, IC0_SHIFTS};
pub use spd::{jacobi_cg, solve_spd, SolveInfo, SolveOptions};

/// A solve that did not reach its tolerance.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the {method} solve of {n} unknowns did not converge: relative residual {residual:e} after {iterations} iterations (tolerance {tol:e})")]
pub struct NotConverged {
    pub method: &'static str,
    pub n: usize,
    pub iterations: usize,
    /// The true relative residual ‖b − A x‖/‖b‖ reached.
    pub residual: f64,
    /// The relative residual that was asked for.
    pub tol: f64,
}

#[cfg(test)]
mod tests;
