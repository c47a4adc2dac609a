//! Input points: XYZ/CSV text (optional values and normals) and LAS/LAZ, plus side points.
//!
//! The samples are read by point-io in its LoopStructural dialect (`point_io::loop_structural`:
//! columns from a header `x y z [val|value] [nx ny nz]` or from the column count, empty CSV
//! fields "absent", normals scaled to unit length); this module turns its errors into
//! [`Error::Parse`] and reads side points, which only implicit models have.

use point_io::fields::split_by_first_separator;
use point_io::loop_structural::required_number;
use point_io::number::is_number;
use point_io::PointsError;

use crate::Error;

pub use point_io::loop_structural::{is_las, DataPoint};

/// An explicit side point: φ > 0 (`side` = +1) or φ < 0 (`side` = −1) at `pos`.
#[derive(Debug, Clone, PartialEq)]
pub struct SidePoint {
    pub pos: crate::geom::V3,
    pub side: f64,
    pub line: usize,
}

impl From<PointsError> for Error {
    /// A line error keeps its file and line; point-io's LoopStructural dialect reports nothing
    /// else, but any other error keeps its text.
    fn from(e: PointsError) -> Error {
        match e {
            PointsError::Line { name, line, message } => Error::Parse { file: name, line, msg: message },
            e => Error::BadInput(e.to_string()),
        }
    }
}

/// Parses XYZ/CSV text into data points (see `point_io::loop_structural` for the columns).
pub fn parse_xyz(text: &[u8], source: &str) -> Result<Vec<DataPoint>, Error> {
    Ok(point_io::loop_structural::parse_xyz(text, source)?)
}

/// Parses side points: `x y z s` per line, `s` > 0 for φ > 0 and `s` < 0 for φ < 0.
pub fn parse_side_points(text: &[u8], source: &str) -> Result<Vec<SidePoint>, Error> {
    let text = std::str::from_utf8(text).map_err(|e| Error::Parse {
        file: source.to_string(),
        line: 0,
        msg: format!("not UTF-8 text ({e})"),
    })?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let f = split_by_first_separator(l);
        if f.len() != 4 {
            if out.is_empty() && f.iter().any(|s| !is_number(s)) {
                continue; // header line
            }
            return Err(Error::Parse {
                file: source.to_string(),
                line,
                msg: format!("side point needs 4 columns `x y z side`, found {}", f.len()),
            });
        }
        let g = |k: usize, w: &str| required_number(f.get(k).copied(), w, source, line);
        let s = g(3, "side")?;
        if s == 0.0 {
            return Err(Error::Parse { file: source.to_string(), line, msg: "side must be +1 or -1, not 0".into() });
        }
        out.push(SidePoint { pos: [g(0, "x")?, g(1, "y")?, g(2, "z")?], side: s.signum(), line });
    }
    Ok(out)
}

/// Reads LAS or LAZ bytes (positions only: LAS carries no normals or values); the header's
/// claims are checked against the bytes first, and memory grows with the points decoded.
pub fn read_las(bytes: Vec<u8>, source: &str) -> Result<Vec<DataPoint>, Error> {
    Ok(point_io::loop_structural::read_las(bytes, source)?)
}
