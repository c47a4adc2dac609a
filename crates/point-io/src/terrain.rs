//! The terrain dialect: soundings and lidar returns as x y z, in batches.
//!
//! XYZ/CSV rules (one point per line):
//! - fields separated by whitespace, commas or semicolons (mixed is fine);
//! - blank lines and lines starting with `#`, `%` or `>` (GMT segment headers) are skipped;
//! - the FIRST content line may be a header: when it is not numeric it names the columns, and
//!   the columns called x/y/z (or lon/lat, easting/northing, elevation/depth/value…, see
//!   [`crate::columns`]) are used; without a header the first three fields are x, y, z and
//!   extra fields are ignored;
//! - any later line that does not give three finite numbers is an error naming the line
//!   (NaN and ±inf included: a sounding without a depth is a data error, not a hole).
//!
//! LAS/LAZ through [`crate::las::LasPoints`], with its errors worded for this dialect.

use std::io::BufRead;

use input_limits::lines::LineError;
use input_limits::quote;

use crate::columns::{find_column, Dialect, Role};
use crate::fields::{split_csv, split_folded};
use crate::las::{LasError, LasPoints};
use crate::number::{is_number, parse_finite, NumberError};
use crate::{PointsError, BATCH_POINTS};

/// The line-by-line state of a terrain XYZ/CSV reader: which columns hold x, y, z once a header
/// named them, and how data lines are split then.
#[derive(Debug, Default)]
struct XyzLines {
    line_no: usize,
    buf: String,
    seen_content: bool,
    /// `Some(csv)` after a header that named the columns: data lines are then split as the
    /// header was (empty CSV fields count).
    named: Option<(bool, [usize; 3])>,
}

impl XyzLines {
    /// The next point, `None` at the end of the text.
    fn next_point<R: BufRead>(&mut self, reader: &mut R, name: &str) -> Result<Option<[f64; 3]>, PointsError> {
        loop {
            self.buf.clear();
            if read_line(reader, &mut self.buf, name, self.line_no)? == 0 {
                return Ok(None);
            }
            self.line_no += 1;
            let line = std::mem::take(&mut self.buf);
            let point = match self.named {
                Some((csv, columns)) => self.named_line(&line, csv, columns, name),
                None => self.plain_line(&line, name),
            };
            self.buf = line;
            if let Some(p) = point? {
                return Ok(Some(p));
            }
        }
    }

    /// A line before any header named the columns: the first content line may be that header.
    fn plain_line(&mut self, raw: &str, name: &str) -> Result<Option<[f64; 3]>, PointsError> {
        let line = raw.trim_start_matches('\u{feff}').trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with('%') || line.starts_with('>') {
            return Ok(None);
        }
        let fields: Vec<&str> = split_folded(line).collect();
        let first_content = !self.seen_content;
        self.seen_content = true;
        if first_content && fields.iter().any(|f| !is_number(f) && !f.is_empty()) {
            self.header(line, name)?;
            return Ok(None);
        }
        xyz_fields(&fields, [0, 1, 2], name, self.line_no).map(Some)
    }

    /// A header: maps named columns (the CSV index column, "" or "id", is just skipped); a
    /// header without recognisable names means the first three columns.
    fn header(&mut self, line: &str, name: &str) -> Result<(), PointsError> {
        let raw: Vec<&str> = line.split(|c: char| c == ',' || c == ';' || (c.is_whitespace() && !line.contains(','))).collect();
        let column = |role| find_column(&raw, role, Dialect::Terrain);
        if let (Some(x), Some(y), Some(z)) = (column(Role::X), column(Role::Y), column(Role::Z)) {
            self.named = Some((line.contains(','), [x, y, z]));
            return Ok(());
        }
        if raw.iter().all(|f| !is_number(f.trim())) {
            return Ok(());
        }
        Err(PointsError::line(name, self.line_no, format!("expected three numbers x y z, found {:?}", quote(line))))
    }

    /// A data line after a header that named the columns.
    fn named_line(&self, raw: &str, csv: bool, columns: [usize; 3], name: &str) -> Result<Option<[f64; 3]>, PointsError> {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            return Ok(None);
        }
        let fields: Vec<&str> = if csv { split_csv(line) } else { split_folded(line).collect() };
        xyz_fields(&fields, columns, name, self.line_no).map(Some)
    }
}

/// One line through the bounded reader (`/dev/zero` has no newline): errors name the line.
fn read_line<R: BufRead>(reader: &mut R, buf: &mut String, name: &str, line_no: usize) -> Result<usize, PointsError> {
    input_limits::lines::read_line(reader, buf).map_err(|e| match e {
        LineError::Io(e) => PointsError::Io { name: name.into(), message: e.to_string() },
        e => PointsError::line(name, line_no + 1, e.to_string()),
    })
}

/// The point in `columns` of a data line's fields.
fn xyz_fields(fields: &[&str], columns: [usize; 3], name: &str, line: usize) -> Result<[f64; 3], PointsError> {
    let mut p = [0.0; 3];
    for (k, &c) in columns.iter().enumerate() {
        let axis = ["x", "y", "z"][k];
        let f = fields.get(c).copied().filter(|s| !s.is_empty()).ok_or_else(|| {
            PointsError::line(name, line, format!("missing {axis} (column {}): a point needs x, y and z", c + 1))
        })?;
        p[k] = parse_finite(f).map_err(|e| {
            let message = match e {
                NumberError::NotANumber => format!("{axis} = {:?} is not a number", quote(f)),
                NumberError::NotFinite => format!("{axis} = {} is not a finite number", quote(f)),
            };
            PointsError::line(name, line, message)
        })?;
    }
    Ok(p)
}

/// Terrain XYZ/CSV text in batches of at most [`BATCH_POINTS`] points (see the module docs);
/// text without a point ends with [`PointsError::Empty`].
pub struct XyzBatches<R> {
    reader: R,
    lines: XyzLines,
    name: String,
    yielded: usize,
    done: bool,
}

impl<R: BufRead> XyzBatches<R> {
    /// Reads `reader`; `name` is used in error messages.
    pub fn new(reader: R, name: &str) -> XyzBatches<R> {
        XyzBatches { reader, lines: XyzLines::default(), name: name.to_string(), yielded: 0, done: false }
    }

    fn fill(&mut self) -> Result<Vec<[f64; 3]>, PointsError> {
        let mut batch = Vec::with_capacity(BATCH_POINTS.min(1024));
        while batch.len() < BATCH_POINTS {
            match self.lines.next_point(&mut self.reader, &self.name)? {
                Some(p) => batch.push(p),
                None => break,
            }
        }
        Ok(batch)
    }
}

impl<R: BufRead> Iterator for XyzBatches<R> {
    type Item = Result<Vec<[f64; 3]>, PointsError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let batch = self.fill();
        match &batch {
            Ok(b) if b.is_empty() => {
                self.done = true;
                if self.yielded > 0 {
                    return None;
                }
                let message = "no points (empty file or only comments)".into();
                return Some(Err(PointsError::Empty { name: self.name.clone(), message }));
            }
            Ok(b) => self.yielded += b.len(),
            Err(_) => self.done = true,
        }
        Some(batch)
    }
}

/// A LAS/LAZ file's points in batches, with terrain errors: a file short of the points its
/// header announces, or without a (kept) point, ends the stream with one `Err`.
pub struct LasBatches {
    points: LasPoints,
    name: String,
    done: bool,
}

impl LasBatches {
    /// Opens the LAS/LAZ file at `path`, keeping the points of ASPRS class `class` (2 = ground)
    /// or all.
    pub fn open(path: &std::path::Path, class: Option<u8>) -> Result<LasBatches, PointsError> {
        let name = path.display().to_string();
        let points = LasPoints::open(path, class).map_err(|e| las_error(&name, e))?;
        Ok(LasBatches { points, name, done: false })
    }

    /// The underlying reader (for the file's CRS).
    pub fn las(&self) -> &LasPoints {
        &self.points
    }
}

impl Iterator for LasBatches {
    type Item = Result<Vec<[f64; 3]>, PointsError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.points.next_batch() {
            Ok(b) if b.is_empty() => {
                self.done = true;
                self.points.check_end().err().map(|e| Err(las_error(&self.name, e)))
            }
            Ok(b) => Some(Ok(b)),
            Err(e) => {
                self.done = true;
                Some(Err(las_error(&self.name, e)))
            }
        }
    }
}

/// A LAS error in the terrain dialect's words: a header claiming more than the file holds is
/// "too large", a file without points "empty", anything else a LAS error.
fn las_error(name: &str, e: LasError) -> PointsError {
    let name = name.to_string();
    let message = e.to_string();
    match e {
        LasError::Claim(input_limits::las::LasClaim::Io(_)) => PointsError::Las { name, message },
        LasError::Claim(_) => PointsError::TooLarge { name, message },
        LasError::NoPoints | LasError::NoPointOfClass { .. } => PointsError::Empty { name, message },
        LasError::Open(_) | LasError::Read(_) | LasError::NonFinite { .. } | LasError::Short { .. } => PointsError::Las { name, message },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Vec<[f64; 3]>, PointsError> {
        let mut points = Vec::new();
        for batch in XyzBatches::new(s.as_bytes(), "t.xyz") {
            points.extend(batch?);
        }
        Ok(points)
    }

    #[test]
    fn whitespace_comma_and_header() {
        assert_eq!(parse("1 2 3\n4\t5  6\n").unwrap(), vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(parse("x,y,z\n1,2,3\n").unwrap(), vec![[1.0, 2.0, 3.0]]);
        assert_eq!(parse("# c\n\n1, 2, 3, 99\n").unwrap(), vec![[1.0, 2.0, 3.0]]);
        // named columns in another order, with an index column
        assert_eq!(parse(",Z,X,Y,extra\n0,30,10,20,a\n1,31,11,21,b\n").unwrap(), vec![[10.0, 20.0, 30.0], [11.0, 21.0, 31.0]]);
        // a `value` column is the elevation here; a header of unknown names means x y z first
        assert_eq!(parse("lon lat value\n1 2 3\n").unwrap(), vec![[1.0, 2.0, 3.0]]);
        assert_eq!(parse("a b c\n1 2 3\n").unwrap(), vec![[1.0, 2.0, 3.0]]);
        // BOM, GMT segment headers and `%` comments before the data
        assert_eq!(parse("\u{feff}> seg\n% c\n1;2;3\n").unwrap(), vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn named_csv_columns_keep_empty_fields() {
        let e = parse("x,y,z\n1,,3\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:2: missing y (column 2): a point needs x, y and z");
    }

    #[test]
    fn bad_lines_name_their_number() {
        let e = parse("1 2 3\n4 5 nan\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:2: z = nan is not a finite number");
        let e = parse("1 2 3\n4 5 inf\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:2:"), "{e}");
        let e = parse("1 2 3\n\n4 five 6\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:3: y = \"five\" is not a number");
        let e = parse("1 2\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:1: missing z"), "{e}");
        let e = parse("1 2 3\nx y z\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:2:"), "{e}");
        let e = parse("x 1 z\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:1: expected three numbers x y z, found \"x 1 z\"");
        let e = parse("# nothing\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz: no points (empty file or only comments)");
    }

    #[test]
    fn batches_hold_at_most_batch_points() {
        let text = "1 2 3\n".repeat(BATCH_POINTS + 1);
        let sizes: Vec<usize> = XyzBatches::new(text.as_bytes(), "t").map(|b| b.unwrap().len()).collect();
        assert_eq!(sizes, [BATCH_POINTS, 1]);
    }

    #[test]
    fn las_errors_in_terrain_words() {
        let path = std::env::temp_dir().join(format!("point-io-terrain-{}.las", std::process::id()));
        let bytes = crate::las::tests::las_bytes(&[([1.0, 2.0, 3.0], 2)]);
        std::fs::write(&path, &bytes).unwrap();
        let name = path.display().to_string();
        let batches: Vec<_> = LasBatches::open(&path, Some(6)).unwrap().collect();
        let e = batches.into_iter().next().unwrap().unwrap_err();
        assert!(matches!(&e, PointsError::Empty { .. }), "{e:?}");
        assert_eq!(e.to_string(), format!("{name}: no point of class 6; classes present: 2 (1)"));
        std::fs::write(&path, &bytes[..bytes.len() - 5]).unwrap();
        let e = LasBatches::open(&path, None).err().unwrap();
        assert!(matches!(&e, PointsError::TooLarge { .. }), "{e:?}");
        std::fs::remove_file(&path).unwrap();
    }
}
