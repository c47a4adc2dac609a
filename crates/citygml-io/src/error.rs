//! Typed errors of the reader and the writer. A [`ReadError`] always knows where it happened
//! (1-based line and column, byte offset) so the CLI can print `FILE:LINE:COL: message`.

use thiserror::Error;

/// The document cannot be read as CityGML at all (not XML, not CityGML, truncated, geometry
/// that cannot be decoded). Geometric defects that a validator reports (a ring with too few
/// points, a non-planar polygon) are NOT read errors: the reader keeps them as written.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{line}:{column}: {message}")]
pub struct ReadError {
    /// 1-based line of the offending position.
    pub line: usize,
    /// 1-based column (in bytes) of the offending position.
    pub column: usize,
    /// Byte offset into the source (BOM included).
    pub byte: usize,
    /// What is wrong, one line.
    pub message: String,
}

/// The writer could not apply the edits or write the output.
#[derive(Debug, Error)]
pub enum WriteError {
    #[error("edits overlap: bytes {a_start}..{a_end} and {b_start}..{b_end}")]
    Overlap { a_start: usize, a_end: usize, b_start: usize, b_end: usize },
    #[error("edit range {start}..{end} lies outside the {len}-byte document")]
    OutOfBounds { start: usize, end: usize, len: usize },
    #[error("{0}")]
    Coordinates(String),
    #[error("write failed: {0}")]
    Io(#[from] std::io::Error),
}
