//! `adjust`: a generic Gauss–Helmert least-squares engine with restrictions, and the popa3d
//! building equations on top of it.
//!
//! - Conditions `f(x, l + v) = 0` with uncorrelated or fully correlated observations, restrictions
//!   `g(x) = 0`, iterated to convergence (spec §6.1, corrected formulas; see [`solve`]).
//! - Linearisation by forward-mode automatic differentiation over the distinct unknowns each
//!   equation touches ([`ad`], spec §5, §6.2).
//! - Sparse normal equations solved per connected component with faer's sparse Cholesky.
//! - Datum: free (inner constraints on a subset, numeric null space), soft (identity
//!   observations), hard (fixed unknowns) (spec §4.7); defects are reported by naming the
//!   undetermined unknowns.
//! - Statistics: σ̂0 and the global χ² test, residuals, redundancy numbers, normalised residuals,
//!   Baarda's data snooping with the largest suspect.
//!
//! Usable alone for fits with errors in all coordinates, see [`fits`].
//!
//! # Examples
//!
//! ```
//! use adjust::fits::fit_line_2d;
//! // points on y = 1 + 2x, equal σ in x and y
//! let pts = [(0.0, 1.01), (1.0, 2.98), (2.0, 5.02), (3.0, 6.99)];
//! let fit = fit_line_2d(&pts, &[0.01; 4], &[0.01; 4]).unwrap();
//! assert!((fit.slope - 2.0).abs() < 0.02 && (fit.intercept - 1.0).abs() < 0.05);
//! ```

pub mod ad;
pub mod equations;
pub mod fits;
pub mod popa3d;
pub mod problem;
pub mod solve;
pub mod stats;

pub use ad::{DynEquation, Equation, Scalar};
pub use problem::{ConditionId, ObsId, Problem, Slot, UnknownId};
pub use solve::{adjust, Datum, GlobalTest, GlobalVerdict, ObsResult, Options, Solution};

/// Everything that can go wrong in an adjustment; each message names the offending element.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum AdjustError {
    #[error("{equation}: references unknown #{id}, which does not exist")]
    UnknownUnknown { equation: String, id: usize },
    #[error("{equation}: references observation #{id}, which does not exist")]
    UnknownObservation { equation: String, id: usize },
    #[error("observation {observation}: standard deviation must be > 0 and finite, got {sigma}")]
    InvalidSigma { observation: String, sigma: f64 },
    #[error("covariance of [{observations}]: {reason}")]
    InvalidCovariance { observations: String, reason: String },
    #[error("non-finite number in {what}")]
    NonFinite { what: String },
    #[error("{equation}: touches {count} distinct variables, more than the supported {}", ad::MAX_VARS)]
    TooManyVariables { equation: String, count: usize },
    #[error("datum or configuration defect of {defect}: these unknowns are not determined by the observations, restrictions and datum: {}", list(unknowns))]
    Defect { defect: usize, unknowns: Vec<String> },
    #[error("restrictions are linearly dependent: {}", list(restrictions))]
    DependentRestrictions { restrictions: Vec<String> },
    #[error("restriction {restriction} involves only fixed unknowns and is violated by {value:e}")]
    InconsistentRestriction { restriction: String, value: f64 },
    #[error("condition {condition}: its observations have no influence on it (B row is zero), M is singular")]
    SingularM { condition: String },
    #[error("iteration diverged at iteration {iteration}: {reason}")]
    Diverged { iteration: usize, reason: String },
    #[error("no convergence after {iterations} iterations (last relative step {step:.3e}, component of {first})")]
    NotConverged { iterations: usize, step: f64, first: String },
    #[error("free datum: the component of {first} has {unknowns} unknowns, more than the dense null-space limit {limit}; use a soft or hard datum")]
    ComponentTooLarge { unknowns: usize, limit: usize, first: String },
}

fn list(v: &[String]) -> String {
    const MAX: usize = 20;
    if v.len() <= MAX {
        v.join(", ")
    } else {
        format!("{}, … ({} more)", v[..MAX].join(", "), v.len() - MAX)
    }
}
