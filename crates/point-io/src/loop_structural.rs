//! The LoopStructural dialect: samples of a scalar field φ for implicit modelling.
//!
//! Text columns are found from a header (`x y z [val|value] [nx ny nz]`, any order, comma or
//! whitespace separated, as in LoopStructural's CSVs; names in [`crate::columns`]) or, without
//! a header, from the column count: 3 = `x y z`, 4 = `x y z v`, 6 = `x y z nx ny nz`,
//! 7 = `x y z v nx ny nz`. Empty CSV fields mean "absent" (a row with a normal but no value
//! only orients φ). Lines starting with `#` or `//` are comments. Every data line has the
//! header's (or the first row's) field count, and six or more whole numbers split by commas
//! on a headerless first row are refused (they may be half as many with decimal commas,
//! docs/decisions.md#point-text-separators-and-decimal-commas-issue-41).
//!
//! Not the terrain dialect on purpose: there a `value` column is z, empty fields are folded
//! away and rows have no normals; reading one as the other would change what files mean.

use input_limits::quote;

use crate::columns::{find_column, Dialect, Role};
use crate::fields::split_by_first_separator;
use crate::las::{LasError, LasPoints};
use crate::number::{is_number, parse_finite, NumberError};
use crate::text::could_be_decimal_commas;
use crate::PointsError;

/// One input sample: a position, optionally the value φ must take there and a unit normal (the
/// direction in which φ increases).
#[derive(Debug, Clone, PartialEq)]
pub struct DataPoint {
    pub pos: [f64; 3],
    pub value: Option<f64>,
    pub normal: Option<[f64; 3]>,
    /// 1-based source line (0 for binary inputs such as LAS).
    pub line: usize,
}

/// Which field holds what on the data lines.
#[derive(Debug, Clone, Copy)]
struct Columns {
    x: usize,
    y: usize,
    z: usize,
    v: Option<usize>,
    n: Option<[usize; 3]>,
}

/// Parses XYZ/CSV text into data points (see the module docs). `source` names the text in
/// errors.
pub fn parse_xyz(text: &[u8], source: &str) -> Result<Vec<DataPoint>, PointsError> {
    let text = std::str::from_utf8(text).map_err(|e| {
        PointsError::line(source, 0, format!("not UTF-8 text ({e}); LAS/LAZ files need the .las/.laz extension"))
    })?;
    let mut columns: Option<Columns> = None;
    // the field count every data line has: the header's or the first row's, and its line
    let mut count: Option<(usize, usize, &str)> = None;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = if i == 0 { raw.trim_start_matches('\u{feff}') } else { raw }.trim();
        if l.is_empty() || l.starts_with('#') || l.starts_with("//") {
            continue;
        }
        let fields = split_by_first_separator(l);
        if let Some((n, at, what)) = count {
            if fields.len() != n {
                let message = format!("{} fields, but {what} (line {at}) has {n}", fields.len());
                return Err(PointsError::line(source, line, message));
            }
        }
        let c = match columns {
            Some(c) => c,
            None if is_header(&fields) => {
                columns = Some(header_columns(&fields, source, line)?);
                count = Some((fields.len(), line, "the header"));
                continue;
            }
            None => {
                if l.contains(',') && could_be_decimal_commas(&fields) {
                    let n = fields.len();
                    let message = format!("{:?} may be {n} whole numbers or {} numbers with decimal commas; write the file with ';' or blanks between fields", quote(l), n / 2);
                    return Err(PointsError::line(source, line, message));
                }
                count = Some((fields.len(), line, "the first row"));
                *columns.insert(count_columns(fields.len(), source, line)?)
            }
        };
        out.push(data_point(&fields, c, source, line)?);
    }
    Ok(out)
}

/// Whether the first content line names columns: a field that is not a number.
fn is_header(fields: &[&str]) -> bool {
    fields.iter().any(|f| {
        let f = f.trim_matches('"');
        !f.is_empty() && !is_number(f) && !f.eq_ignore_ascii_case("nan")
    })
}

fn header_columns(fields: &[&str], source: &str, line: usize) -> Result<Columns, PointsError> {
    let find = |role| find_column(fields, role, Dialect::LoopStructural);
    let miss = |c: &str| {
        PointsError::line(source, line, format!("header has no `{c}` column (found: {})", quote(&fields.join(","))))
    };
    let x = find(Role::X).ok_or_else(|| miss("x"))?;
    let y = find(Role::Y).ok_or_else(|| miss("y"))?;
    let z = find(Role::Z).ok_or_else(|| miss("z"))?;
    let v = find(Role::Value);
    let n = match (find(Role::Nx), find(Role::Ny), find(Role::Nz)) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        (None, None, None) => None,
        _ => return Err(miss("nx, ny and nz (only some normal columns are present)")),
    };
    Ok(Columns { x, y, z, v, n })
}

fn count_columns(n: usize, source: &str, line: usize) -> Result<Columns, PointsError> {
    Ok(match n {
        3 => Columns { x: 0, y: 1, z: 2, v: None, n: None },
        4 => Columns { x: 0, y: 1, z: 2, v: Some(3), n: None },
        6 => Columns { x: 0, y: 1, z: 2, v: None, n: Some([3, 4, 5]) },
        7 => Columns { x: 0, y: 1, z: 2, v: Some(3), n: Some([4, 5, 6]) },
        _ => {
            let message =
                format!("{n} columns without a header; expected 3 (x y z), 4 (x y z v), 6 (x y z nx ny nz) or 7 (x y z v nx ny nz)");
            return Err(PointsError::line(source, line, message));
        }
    })
}

/// The sample on one data line.
fn data_point(fields: &[&str], c: Columns, source: &str, line: usize) -> Result<DataPoint, PointsError> {
    let req = |idx: usize, what: &str| required_number(fields.get(idx).copied(), what, source, line);
    let pos = [req(c.x, "x")?, req(c.y, "y")?, req(c.z, "z")?];
    let value = match c.v {
        Some(v) => optional_number(fields.get(v).copied(), "value", source, line)?,
        None => None,
    };
    let normal = match c.n {
        Some(n) => unit_normal(fields, n, source, line)?,
        None => None,
    };
    Ok(DataPoint { pos, value, normal, line })
}

/// The normal in columns `n`, scaled to unit length; `None` when all three fields are absent.
fn unit_normal(fields: &[&str], n: [usize; 3], source: &str, line: usize) -> Result<Option<[f64; 3]>, PointsError> {
    let component = |k: usize, what: &str| optional_number(fields.get(n[k]).copied(), what, source, line);
    let v = match (component(0, "nx")?, component(1, "ny")?, component(2, "nz")?) {
        (Some(a), Some(b), Some(c)) => [a, b, c],
        (None, None, None) => return Ok(None),
        _ => return Err(PointsError::line(source, line, "normal has only some of nx, ny, nz")),
    };
    let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if length == 0.0 {
        return Err(PointsError::line(source, line, "normal (0, 0, 0) has no direction"));
    }
    let s = 1.0 / length;
    Ok(Some([v[0] * s, v[1] * s, v[2] * s]))
}

/// A field as a number: `None` when the field is absent or empty (blanks and surrounding double
/// quotes ignored); an error naming `what` and the line when it is not a finite number.
pub fn optional_number(field: Option<&str>, what: &str, source: &str, line: usize) -> Result<Option<f64>, PointsError> {
    let Some(s) = field else { return Ok(None) };
    let s = s.trim().trim_matches('"');
    if s.is_empty() {
        return Ok(None);
    }
    let message = match parse_finite(s) {
        Ok(v) => return Ok(Some(v)),
        Err(NumberError::NotANumber) => format!("{what} `{}` is not a number", quote(s)),
        Err(NumberError::NotFinite) => format!("{what} is {} (NaN or infinite)", quote(s)),
    };
    Err(PointsError::line(source, line, message))
}

/// [`optional_number`] for a field that must be there (`{what} is missing` otherwise).
pub fn required_number(field: Option<&str>, what: &str, source: &str, line: usize) -> Result<f64, PointsError> {
    optional_number(field, what, source, line)?
        .ok_or_else(|| PointsError::line(source, line, format!("{what} is missing")))
}

/// Reads LAS or LAZ bytes (positions only: LAS carries no normals or values). Errors are
/// [`PointsError::Line`] at line 0, or at the 1-based point for a non-finite coordinate.
pub fn read_las(bytes: Vec<u8>, source: &str) -> Result<Vec<DataPoint>, PointsError> {
    let mut las = LasPoints::from_bytes(bytes, None).map_err(|e| las_error(source, e))?;
    let mut out = Vec::new();
    loop {
        let batch = las.next_batch().map_err(|e| las_error(source, e))?;
        if batch.is_empty() {
            return Ok(out);
        }
        out.extend(batch.into_iter().map(|pos| DataPoint { pos, value: None, normal: None, line: 0 }));
    }
}

/// A LAS error in this dialect's words.
fn las_error(source: &str, e: LasError) -> PointsError {
    match e {
        LasError::NonFinite { index } => PointsError::line(source, index + 1, "LAS point with a non-finite coordinate"),
        LasError::Read(e) => PointsError::line(source, 0, format!("LAS/LAZ points: {e}")),
        e => PointsError::line(source, 0, format!("LAS/LAZ: {e}")),
    }
}

/// True when `bytes` start with the LAS signature.
pub fn is_las(bytes: &[u8]) -> bool {
    bytes.starts_with(b"LASF")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Vec<DataPoint>, PointsError> {
        parse_xyz(s.as_bytes(), "s.csv")
    }

    fn sample(pos: [f64; 3], value: Option<f64>, normal: Option<[f64; 3]>, line: usize) -> DataPoint {
        DataPoint { pos, value, normal, line }
    }

    #[test]
    fn columns_from_the_count() {
        let p = parse("1 2 3\n").unwrap();
        assert_eq!(p, [sample([1.0, 2.0, 3.0], None, None, 1)]);
        let p = parse("# c\n1 2 3 7\n").unwrap();
        assert_eq!(p, [sample([1.0, 2.0, 3.0], Some(7.0), None, 2)]);
        let p = parse("1 2 3 0 0 2\n").unwrap();
        assert_eq!(p, [sample([1.0, 2.0, 3.0], None, Some([0.0, 0.0, 1.0]), 1)]);
        let p = parse("// c\n1;2;3;5;0;2;0\n").unwrap();
        assert_eq!(p, [sample([1.0, 2.0, 3.0], Some(5.0), Some([0.0, 1.0, 0.0]), 2)]);
    }

    #[test]
    fn header_in_any_order_value_is_phi_and_empty_fields_are_absent() {
        let p = parse("nz,ny,nx,Val,Z,Y,X\n1,0,0,,3,2,1\n,,,4,6,5,\"4\"\n").unwrap();
        assert_eq!(
            p,
            [sample([1.0, 2.0, 3.0], None, Some([0.0, 0.0, 1.0]), 2), sample([4.0, 5.0, 6.0], Some(4.0), None, 3)]
        );
    }

    #[test]
    fn errors_name_the_line() {
        let e = |s: &str| parse(s).unwrap_err().to_string();
        assert_eq!(e("x y z\n1 2 3\n1 two 3\n"), "s.csv:3: y `two` is not a number");
        assert_eq!(e("1 2 3\n1 2 inf\n"), "s.csv:2: z is inf (NaN or infinite)");
        assert_eq!(e("1 2 3 0 0 0\n"), "s.csv:1: normal (0, 0, 0) has no direction");
        assert_eq!(e("x,y,z,nx,ny,nz\n1,2,3,1,,\n"), "s.csv:2: normal has only some of nx, ny, nz");
        assert_eq!(e("x,y,z\n1,,3\n"), "s.csv:2: y is missing");
        assert_eq!(e("lon lat z\n"), "s.csv:1: header has no `x` column (found: lon,lat,z)");
        assert_eq!(
            e("x y z nx\n"),
            "s.csv:1: header has no `nx, ny and nz (only some normal columns are present)` column (found: x,y,z,nx)"
        );
        assert!(e("\n1 2 3 4 5\n").starts_with("s.csv:2: 5 columns without a header"));
        assert!(parse_xyz(b"1 2 \xff", "b").unwrap_err().to_string().starts_with("b:0: not UTF-8 text"));
    }

    #[test]
    fn numbers_trim_quotes_and_blanks() {
        assert_eq!(optional_number(Some(" \"2.5\" "), "v", "s", 1).unwrap(), Some(2.5));
        assert_eq!(optional_number(Some("\"\""), "v", "s", 1).unwrap(), None);
        assert_eq!(required_number(None, "side", "s", 4).unwrap_err().to_string(), "s:4: side is missing");
    }

    #[test]
    fn las_errors_are_line_errors() {
        assert!(is_las(b"LASF\x00") && !is_las(b"1 2 3"));
        let e = read_las(b"LASF".to_vec(), "p.las").unwrap_err().to_string();
        assert!(e.starts_with("p.las:0: LAS/LAZ: "), "{e}");
    }

    #[test]
    fn field_counts_hold_and_decimal_commas_are_not_taken_for_fields() {
        let e = parse_xyz(b"x y z\n1 2 3\n1 2 3 4 5\n", "s.xyz").unwrap_err().to_string();
        assert_eq!(e, "s.xyz:3: 5 fields, but the header (line 1) has 3");
        let e = parse_xyz(b"1 2 3 4\n1 2 3\n", "s.xyz").unwrap_err().to_string();
        assert_eq!(e, "s.xyz:2: 3 fields, but the first row (line 1) has 4");
        let e = parse_xyz(b"341000,5,5724000,25,12,5\n", "s.csv").unwrap_err().to_string();
        assert!(e.starts_with("s.csv:1: \"341000,5,5724000,25,12,5\" may be 6 whole numbers or 3"), "{e}");
        let p = parse_xyz("\u{feff}x,y,z\r\n1,2,3\r\n".as_bytes(), "s.csv").unwrap();
        assert_eq!(p[0].pos, [1.0, 2.0, 3.0]);
    }
}
