//! How many raster cells a command may allocate, checked against what a file's header (or an
//! extent and a cell size) claims **before** allocating: a 88-byte ASCII grid that claims
//! 10⁶ × 10⁶ cells must get a clear error, not an abort in the allocator.
//!
//! The budget is the memory the machine has available now (`MemAvailable` in `/proc/meminfo`)
//! divided by what one cell costs the caller; where that cannot be read, a fixed
//! [`FALLBACK_MAX_CELLS`] (2³³ cells). The environment variable `GEOFIT_MAX_CELLS` replaces
//! the budget with a cell count (to raise it on a machine with swap, or to lower it).

/// The budget when available memory cannot be read: 2³³ cells (64 GiB of f64).
pub const FALLBACK_MAX_CELLS: u64 = input_limits::budget::FALLBACK_MAX_UNITS;

/// What one cell of a raster read through GDAL costs: the f64 value (NaN = no data, no flag
/// beside it: docs/decisions.md#nan-is-no-data) and GDAL's mask byte.
pub const READ_BYTES_PER_CELL: u64 = 9;

/// The environment variable that sets the cell budget explicitly.
pub const MAX_CELLS_ENV: &str = "GEOFIT_MAX_CELLS";

pub use input_limits::budget::{available_memory, gib, BudgetSource};
use input_limits::budget::{budget, describe};

/// The most cells one raster may have, and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellBudget {
    pub max_cells: u64,
    pub source: BudgetSource,
}

impl CellBudget {
    /// The budget for rasters costing `bytes_per_cell` each.
    pub fn for_cost(bytes_per_cell: u64) -> CellBudget {
        let (max_cells, source) = budget(MAX_CELLS_ENV, bytes_per_cell);
        CellBudget { max_cells, source }
    }

    /// Whether `width × height` cells fit (no overflow).
    pub fn allows(&self, width: usize, height: usize) -> bool {
        (width as u64).checked_mul(height as u64).is_some_and(|c| c <= self.max_cells)
    }

    /// Why the limit is what it is, for an error message ("… more than {this}").
    pub fn describe(&self) -> String {
        describe(self.max_cells, "cells", self.source, MAX_CELLS_ENV)
    }
}

/// What one point read into a [`crate::PointCloud`] costs: three f64, twice over while the
/// vector grows by doubling.
pub const READ_BYTES_PER_POINT: u64 = 48;

/// The environment variable that sets the point budget explicitly.
pub const MAX_POINTS_ENV: &str = "GEOFIT_MAX_POINTS";

/// The most points one point file may deliver, and why: the same rule as [`CellBudget`] (available
/// memory over the cost of a point, `GEOFIT_MAX_POINTS`, or a fixed fallback), so an endless
/// stream (`yes 1 2 3 | geofit rasterize -`) or a LAZ file decoding far more points than it can
/// hold ends with a message instead of taking the machine's memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointBudget {
    pub max_points: u64,
    pub source: BudgetSource,
}

impl PointBudget {
    /// The budget for points costing `bytes_per_point` each.
    pub fn for_cost(bytes_per_point: u64) -> PointBudget {
        let (max_points, source) = budget(MAX_POINTS_ENV, bytes_per_point);
        PointBudget { max_points, source }
    }

    /// Why the limit is what it is, for an error message ("… more than {this}").
    pub fn describe(&self) -> String {
        describe(self.max_points, "points", self.source, MAX_POINTS_ENV)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_refuses_overflowing_and_large_sizes() {
        let b = CellBudget { max_cells: 100, source: BudgetSource::Fallback };
        assert!(b.allows(10, 10));
        assert!(!b.allows(10, 11));
        assert!(!b.allows(usize::MAX, 2));
        assert!(available_memory().is_some_and(|m| m > 0) || !std::path::Path::new("/proc/meminfo").exists());
    }
}
