//! How many raster cells a command may allocate, checked against what a file's header (or an
//! extent and a cell size) claims **before** allocating: a 88-byte ASCII grid that claims
//! 10⁶ × 10⁶ cells must get a clear error, not an abort in the allocator.
//!
//! The budget is the memory the machine has available now (`MemAvailable` in `/proc/meminfo`)
//! divided by what one cell costs the caller; where that cannot be read, a fixed
//! [`FALLBACK_MAX_CELLS`] (2³³ cells). The environment variable `GEOFIT_MAX_CELLS` replaces
//! the budget with a cell count (to raise it on a machine with swap, or to lower it).

/// The budget when available memory cannot be read: 2³³ cells (64 GiB of f64).
pub const FALLBACK_MAX_CELLS: u64 = 1 << 33;

/// What one cell of a raster read through GDAL costs: the f64 value, the validity flag and
/// GDAL's mask byte.
pub const READ_BYTES_PER_CELL: u64 = 10;

/// The environment variable that sets the cell budget explicitly.
pub const MAX_CELLS_ENV: &str = "GEOFIT_MAX_CELLS";

/// Memory available to a new allocation, in bytes (`MemAvailable`), if the system says.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// Where a [`CellBudget`] comes from, for the message that refuses a size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BudgetSource {
    /// `GEOFIT_MAX_CELLS`.
    Env,
    /// Available memory (bytes) divided by the cost of a cell.
    Memory(u64),
    /// Neither: [`FALLBACK_MAX_CELLS`].
    Fallback,
}

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

/// The one budget rule of cells and points: the number `env` sets, else what available memory
/// holds at `bytes_per_unit`, else the fixed fallback.
fn budget(env: &str, bytes_per_unit: u64) -> (u64, BudgetSource) {
    if let Some(n) = std::env::var(env).ok().and_then(|v| v.trim().parse::<u64>().ok()) {
        return (n, BudgetSource::Env);
    }
    match available_memory() {
        Some(b) => (b / bytes_per_unit.max(1), BudgetSource::Memory(b)),
        None => (FALLBACK_MAX_CELLS, BudgetSource::Fallback),
    }
}

/// Why a budget is what it is, for an error message ("… more than {this}").
fn describe(limit: u64, what: &str, source: BudgetSource, env: &str) -> String {
    match source {
        BudgetSource::Env => format!("{limit} {what} set by {env}"),
        BudgetSource::Memory(b) => format!("{limit} {what}, what the {} of available memory hold; {env} sets another limit", gib(b)),
        BudgetSource::Fallback => format!("{limit} {what}; {env} sets another limit"),
    }
}

/// `bytes` as "12.3 GiB".
pub fn gib(bytes: u64) -> String {
    format!("{:.1} GiB", bytes as f64 / (1u64 << 30) as f64)
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
