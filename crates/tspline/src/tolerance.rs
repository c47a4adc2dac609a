//! What a fit accepts at each cell (issue 19; docs/decisions.md#the-guarantee-holds-for-what-eval-computes
//! and docs/decisions.md#per-cell-tolerance-from-the-survey-uncertainty).
//!
//! - One tolerance E for every cell (`--max-error E`), or one per cell from the survey's
//!   uncertainty u (`--max-error-from-uncertainty K`): T = max(floor, K·u), the floor being
//!   `--max-error` when given (a survey's uncertainty may be tiny or zero; nobody needs a
//!   reduced model more exact than a stated E).
//! - A margin δ kept free below T by the refinement loop, so that the surface as another
//!   evaluation path computes it (the mesh re-read from its file, the OpenCL kernels, a
//!   different extraction/reference choice) is still within T:
//!   δ = min(1e-9 · max|z|, min T / 1000). The paths agree to ~1e-12 · |z| (rounding of the
//!   rational sums), so 1e-9 · |z| leaves three orders of magnitude; the cap keeps δ
//!   negligible against T on data of huge magnitude (then T is near f64's own resolution of
//!   the data and the margin cannot be more than a thousandth of it).

use std::sync::Arc;

/// Per-cell tolerance T_q = max(floor, k · u_q) (u in the samples' parameter layout, NaN = no
/// uncertainty: T_q = floor).
#[derive(Debug, Clone)]
pub struct CellTolerance {
    pub k: f64,
    pub floor: f64,
    pub uncertainty: Arc<Vec<f32>>,
}

impl CellTolerance {
    /// T_q before the margin.
    #[inline]
    pub fn at(&self, q: usize) -> f64 {
        let u = self.uncertainty[q];
        if u.is_nan() {
            self.floor
        } else {
            (self.k * u as f64).max(self.floor)
        }
    }

    /// The smallest T over the cells where `valid` holds (None when there is none).
    pub fn min_over(&self, valid: impl Fn(usize) -> bool) -> Option<f64> {
        (0..self.uncertainty.len()).filter(|&q| valid(q)).map(|q| self.at(q)).reduce(f64::min)
    }
}

/// The tolerance a check compares |Δz| against: T_q − margin.
#[derive(Debug, Clone)]
pub struct Tolerance {
    uniform: f64,
    cells: Option<CellTolerance>,
    margin: f64,
}

impl Tolerance {
    /// One tolerance for every cell, no margin.
    pub fn uniform(e: f64) -> Tolerance {
        Tolerance { uniform: e, cells: None, margin: 0.0 }
    }

    /// `e` everywhere or `cells` per cell, less `margin`.
    pub fn new(e: f64, cells: Option<CellTolerance>, margin: f64) -> Tolerance {
        Tolerance { uniform: e, cells, margin }
    }

    /// The same tolerance with another margin.
    pub fn with_margin(&self, margin: f64) -> Tolerance {
        Tolerance { margin, ..self.clone() }
    }

    /// What |Δz| at cell (or point) `q` must not exceed.
    #[inline]
    pub fn at(&self, q: usize) -> f64 {
        match &self.cells {
            Some(c) => c.at(q) - self.margin,
            None => self.uniform - self.margin,
        }
    }

    pub fn margin(&self) -> f64 {
        self.margin
    }

    pub fn is_per_cell(&self) -> bool {
        self.cells.is_some()
    }
}

/// The margin δ for data whose largest magnitude is `zscale` and whose smallest tolerance is
/// `min_tol` (see the module doc).
pub fn margin(zscale: f64, min_tol: f64) -> f64 {
    (1e-9 * zscale.abs()).min(min_tol / 1000.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_cell_tolerance_with_floor_and_margin() {
        let c = CellTolerance { k: 2.0, floor: 0.5, uncertainty: Arc::new(vec![0.1, 1.0, f32::NAN, 0.25]) };
        assert_eq!([c.at(0), c.at(1), c.at(2), c.at(3)], [0.5, 2.0, 0.5, 0.5]);
        assert_eq!(c.min_over(|q| q == 1), Some(2.0));
        let t = Tolerance::new(9.0, Some(c), 0.01);
        assert!((t.at(1) - 1.99).abs() < 1e-15);
        assert_eq!(Tolerance::uniform(3.0).at(7), 3.0);
        assert_eq!(Tolerance::uniform(3.0).with_margin(1.0).at(0), 2.0);
        assert_eq!(margin(5000.0, 1.0), 5e-6);
        assert_eq!(margin(1e30, 1.0), 1e-3);
    }
}
