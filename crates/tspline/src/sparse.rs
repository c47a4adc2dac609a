//! The least-squares fit's solver policy over `sparse_spd` (issue 19: the solve dominated the
//! fit once a mesh passed ~10⁴ control points; issue 16: one sparse module for the workspace).
//!
//! Why a direct factorisation: the normal equations of a T-spline fit have ~(2K+1)² entries
//! per row on a 2-D lattice, so a fill-reducing ordering (AMD) keeps the Cholesky factor near
//! O(n log n) and the factorisation is a fraction of a second at 10⁵ unknowns, while the
//! Jacobi-preconditioned conjugate gradients needed hundreds to thousands of iterations
//! (the system's condition grows with the mesh's spread of cell sizes). Measured side by side
//! in `benches/tspline_speed.sh` (BENCHMARKS.md, "T-spline speed").
//!
//! - A non-positive pivot or a factor larger than [`MAX_FACTOR_BYTES`] falls back to the
//!   warm-started Jacobi-PCG; a CG that does not reach its tolerance is an error naming the
//!   residual reached, never a silent approximate answer.
//! - `GEOFIT_TSPLINE_SOLVER=cg` selects the CG for measurements (benches); anything else or
//!   unset is the default (Cholesky).

pub use sparse_spd::{NotConverged, SolveInfo, SymCsr};
use sparse_spd::{PcgOptions, SolveOptions};

/// Relative residual the CG's stopping rule aims at.
pub const TOLERANCE: f64 = 1e-13;
/// Largest Cholesky factor (bytes of its values) the direct path builds; bigger systems take
/// the PCG. Why: the factor's fill grows faster than the system (measured: +117 MiB of peak
/// for 3·10⁴ cubic control points on Kilauea 5 m), and at 10⁸ raster cells the per-cell
/// arrays already take most of the memory budget.
pub const MAX_FACTOR_BYTES: usize = 256 << 20;
/// Results (Cholesky after refinement, or CG) with a true relative residual up to this are
/// accepted: the factorisation's rounding on ill-conditioned systems; above it CG continues
/// from the Cholesky solution.
const ACCEPT: f64 = 1e-10;
/// The dot products' summation chunk the fits were made with (it fixes the CG's last bits).
const DOT_CHUNK: usize = 8192;

fn use_cg_only() -> bool {
    std::env::var("GEOFIT_TSPLINE_SOLVER").is_ok_and(|v| v.eq_ignore_ascii_case("cg"))
}

/// Solves A x = b for a symmetric positive definite A; `x0` is the CG's warm start.
pub fn solve_spd(a: &SymCsr, b: &[f64], x0: &[f64]) -> Result<(Vec<f64>, SolveInfo), NotConverged> {
    let cg = PcgOptions { tol: TOLERANCE, max_iter: 20 * a.n() + 2000, accept: ACCEPT, dot_chunk: DOT_CHUNK };
    let opts = SolveOptions { direct: !use_cg_only(), max_factor_bytes: MAX_FACTOR_BYTES, direct_accept: ACCEPT, cg };
    sparse_spd::solve_spd(a, b, x0, &opts)
}

/// Whether the direct solve of a system with the pattern `start`, `cols` would build a new
/// symbolic factorisation (this thread's cached one is another pattern's; not in CG-only
/// mode). When it would, the cached one is dropped now: the caller builds the new one ahead
/// (`sparse_spd::cholesky_symbolic`), and two are not held at once.
pub fn symbolic_needed(start: &[usize], cols: &[u32]) -> bool {
    if use_cg_only() || sparse_spd::symbolic_cached(start, cols) {
        return false;
    }
    sparse_spd::clear_symbolic();
    true
}
