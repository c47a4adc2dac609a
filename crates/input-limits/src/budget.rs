//! The one rule for how much of something untrusted input may make geofit hold in memory:
//! the number an environment variable sets, else what the memory available now holds at the
//! stated cost per unit, else a fixed fallback. Cells (raster-io), points (raster-io, implicit)
//! and whole-input bytes ([`ByteBudget`]) share it, so every refusal reads alike and names the
//! variable that raises the limit.
//!
//! # Examples
//!
//! ```
//! use input_limits::budget::{ByteBudget, BudgetSource};
//!
//! let b = ByteBudget { max_bytes: 1 << 20, source: BudgetSource::Env };
//! assert!(b.allows(1 << 20) && !b.allows((1 << 20) + 1));
//! assert_eq!(b.describe(), "1048576 bytes set by GEOFIT_MAX_INPUT_BYTES");
//! ```

/// The budget when available memory cannot be read: 2³³ units.
pub const FALLBACK_MAX_UNITS: u64 = 1 << 33;

/// Memory available to a new allocation, in bytes (`MemAvailable`), if the system says.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// Where a budget comes from, for the message that refuses a size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BudgetSource {
    /// The environment variable.
    Env,
    /// Available memory (bytes) divided by the cost of a unit.
    Memory(u64),
    /// Neither: [`FALLBACK_MAX_UNITS`].
    Fallback,
}

/// The most units of `bytes_per_unit` each that may be held, and why: the number `env` sets,
/// else what available memory holds, else the fixed fallback.
pub fn budget(env: &str, bytes_per_unit: u64) -> (u64, BudgetSource) {
    if let Some(n) = std::env::var(env).ok().and_then(|v| v.trim().parse::<u64>().ok()) {
        return (n, BudgetSource::Env);
    }
    match available_memory() {
        Some(b) => (b / bytes_per_unit.max(1), BudgetSource::Memory(b)),
        None => (FALLBACK_MAX_UNITS, BudgetSource::Fallback),
    }
}

/// Why a budget is what it is, for an error message ("… more than {this}").
pub fn describe(limit: u64, what: &str, source: BudgetSource, env: &str) -> String {
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

/// The environment variable that sets the whole-input byte budget explicitly.
pub const MAX_INPUT_BYTES_ENV: &str = "GEOFIT_MAX_INPUT_BYTES";

/// What one byte of an input read whole costs before it is parsed: the byte itself, and as much
/// again for the parsed form built beside it (a CityGML tree, a popa3d model, a point list).
pub const READ_BYTES_PER_INPUT_BYTE: u64 = 2;

/// The most bytes a command may read whole from one input (a file, or stdin that never ends:
/// `geofit info /dev/zero`), and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ByteBudget {
    pub max_bytes: u64,
    pub source: BudgetSource,
}

impl ByteBudget {
    /// The budget of the running process ([`MAX_INPUT_BYTES_ENV`] or available memory).
    pub fn current() -> ByteBudget {
        let (max_bytes, source) = budget(MAX_INPUT_BYTES_ENV, READ_BYTES_PER_INPUT_BYTE);
        ByteBudget { max_bytes, source }
    }

    /// Whether `len` bytes fit.
    pub fn allows(&self, len: u64) -> bool {
        len <= self.max_bytes
    }

    /// Why the limit is what it is, for an error message ("… more than {this}").
    pub fn describe(&self) -> String {
        describe(self.max_bytes, "bytes", self.source, MAX_INPUT_BYTES_ENV)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_budget_divides_by_the_cost_and_names_the_variable() {
        if let (n, BudgetSource::Memory(b)) = budget("GEOFIT_TEST_UNSET_BUDGET_VARIABLE", 8) {
            assert_eq!(n, b / 8);
            assert!(describe(n, "cells", BudgetSource::Memory(b), "X").ends_with("; X sets another limit"));
        }
        assert_eq!(describe(5, "points", BudgetSource::Fallback, "Y"), "5 points; Y sets another limit");
    }
}
