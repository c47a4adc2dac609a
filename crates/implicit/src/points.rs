//! Input points: XYZ/CSV text (optional values and normals) and LAS/LAZ, plus side points.
//!
//! Text columns are found from a header (`x y z [val|value] [nx ny nz]`, any order, comma or
//! whitespace separated, as in LoopStructural's CSVs) or, without a header, from the column count:
//! 3 = `x y z`, 4 = `x y z v`, 6 = `x y z nx ny nz`, 7 = `x y z v nx ny nz`. Empty CSV fields mean
//! "absent" (a row with a normal but no value only orients φ).
//!
//! Not `raster_io::points` on purpose: that reader takes a `value` column as z, folds empty
//! fields away and knows no normals (terrain soundings); this dialect is LoopStructural's.

use crate::geom::{norm, scale, V3};
use crate::Error;

/// One input sample: a position, optionally the value φ must take there and a normal (the
/// direction in which φ increases).
#[derive(Debug, Clone, PartialEq)]
pub struct DataPoint {
    pub pos: V3,
    pub value: Option<f64>,
    pub normal: Option<V3>,
    /// 1-based source line (0 for binary inputs such as LAS).
    pub line: usize,
}

/// An explicit side point: φ > 0 (`side` = +1) or φ < 0 (`side` = −1) at `pos`.
#[derive(Debug, Clone, PartialEq)]
pub struct SidePoint {
    pub pos: V3,
    pub side: f64,
    pub line: usize,
}

fn split_fields(line: &str) -> Vec<&str> {
    if line.contains(',') {
        line.split(',').map(|s| s.trim()).collect()
    } else if line.contains(';') {
        line.split(';').map(|s| s.trim()).collect()
    } else {
        line.split_whitespace().collect()
    }
}

#[derive(Default, Clone, Copy)]
struct Columns {
    x: usize,
    y: usize,
    z: usize,
    v: Option<usize>,
    n: Option<[usize; 3]>,
}

fn header_columns(fields: &[&str], source: &str, line: usize) -> Result<Columns, Error> {
    let find = |names: &[&str]| {
        fields.iter().position(|f| {
            let l = f.trim_matches('"').to_ascii_lowercase();
            names.contains(&l.as_str())
        })
    };
    let miss = |c: &str| Error::Parse {
        file: source.to_string(),
        line,
        msg: format!("header has no `{c}` column (found: {})", input_limits::quote(&fields.join(","))),
    };
    let x = find(&["x", "easting", "east"]).ok_or_else(|| miss("x"))?;
    let y = find(&["y", "northing", "north"]).ok_or_else(|| miss("y"))?;
    let z = find(&["z", "elevation", "depth", "height"]).ok_or_else(|| miss("z"))?;
    let v = find(&["val", "value", "v", "phi", "scalar"]);
    let n = match (find(&["nx"]), find(&["ny"]), find(&["nz"])) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        (None, None, None) => None,
        _ => return Err(miss("nx, ny and nz (only some normal columns are present)")),
    };
    Ok(Columns { x, y, z, v, n })
}

fn count_columns(n: usize, source: &str, line: usize) -> Result<Columns, Error> {
    Ok(match n {
        3 => Columns { x: 0, y: 1, z: 2, v: None, n: None },
        4 => Columns { x: 0, y: 1, z: 2, v: Some(3), n: None },
        6 => Columns { x: 0, y: 1, z: 2, v: None, n: Some([3, 4, 5]) },
        7 => Columns { x: 0, y: 1, z: 2, v: Some(3), n: Some([4, 5, 6]) },
        _ => {
            return Err(Error::Parse {
                file: source.to_string(),
                line,
                msg: format!(
                    "{n} columns without a header; expected 3 (x y z), 4 (x y z v), 6 (x y z nx ny nz) or 7 (x y z v nx ny nz)"
                ),
            })
        }
    })
}

fn parse_num(f: Option<&&str>, what: &str, source: &str, line: usize) -> Result<Option<f64>, Error> {
    let Some(s) = f else { return Ok(None) };
    let s = s.trim().trim_matches('"');
    if s.is_empty() {
        return Ok(None);
    }
    let v: f64 = s.parse().map_err(|_| Error::Parse {
        file: source.to_string(),
        line,
        msg: format!("{what} `{}` is not a number", input_limits::quote(s)),
    })?;
    if !v.is_finite() {
        return Err(Error::Parse { file: source.to_string(), line, msg: format!("{what} is {} (NaN or infinite)", input_limits::quote(s)) });
    }
    Ok(Some(v))
}

/// Parses XYZ/CSV text into data points (see the module doc for the columns).
pub fn parse_xyz(text: &[u8], source: &str) -> Result<Vec<DataPoint>, Error> {
    let text = std::str::from_utf8(text).map_err(|e| Error::Parse {
        file: source.to_string(),
        line: 0,
        msg: format!("not UTF-8 text ({e}); LAS/LAZ files need the .las/.laz extension"),
    })?;
    let mut cols: Option<Columns> = None;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') || l.starts_with("//") {
            continue;
        }
        let fields = split_fields(l);
        if cols.is_none() {
            let is_header = fields.iter().any(|f| {
                let f = f.trim_matches('"');
                !f.is_empty() && f.parse::<f64>().is_err() && !f.eq_ignore_ascii_case("nan")
            });
            if is_header {
                cols = Some(header_columns(&fields, source, line)?);
                continue;
            }
            cols = Some(count_columns(fields.len(), source, line)?);
        }
        let c = cols.unwrap_or_default();
        let req = |idx: usize, what: &str| -> Result<f64, Error> {
            parse_num(fields.get(idx), what, source, line)?.ok_or_else(|| Error::Parse {
                file: source.to_string(),
                line,
                msg: format!("{what} is missing"),
            })
        };
        let pos = [req(c.x, "x")?, req(c.y, "y")?, req(c.z, "z")?];
        let value = match c.v {
            Some(v) => parse_num(fields.get(v), "value", source, line)?,
            None => None,
        };
        let normal = match c.n {
            Some([a, b, d]) => {
                let n = (
                    parse_num(fields.get(a), "nx", source, line)?,
                    parse_num(fields.get(b), "ny", source, line)?,
                    parse_num(fields.get(d), "nz", source, line)?,
                );
                match n {
                    (Some(a), Some(b), Some(d)) => {
                        let v = [a, b, d];
                        let l = norm(v);
                        if l == 0.0 {
                            return Err(Error::Parse {
                                file: source.to_string(),
                                line,
                                msg: "normal (0, 0, 0) has no direction".into(),
                            });
                        }
                        Some(scale(v, 1.0 / l))
                    }
                    (None, None, None) => None,
                    _ => {
                        return Err(Error::Parse {
                            file: source.to_string(),
                            line,
                            msg: "normal has only some of nx, ny, nz".into(),
                        })
                    }
                }
            }
            None => None,
        };
        out.push(DataPoint { pos, value, normal, line });
    }
    Ok(out)
}

/// Parses side points: `x y z s` per line, `s` > 0 for φ > 0 and `s` < 0 for φ < 0.
pub fn parse_side_points(text: &[u8], source: &str) -> Result<Vec<SidePoint>, Error> {
    let text = std::str::from_utf8(text)
        .map_err(|e| Error::Parse { file: source.to_string(), line: 0, msg: format!("not UTF-8 text ({e})") })?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let f = split_fields(l);
        if f.len() != 4 {
            if out.is_empty() && f.iter().any(|s| s.parse::<f64>().is_err()) {
                continue; // header line
            }
            return Err(Error::Parse {
                file: source.to_string(),
                line,
                msg: format!("side point needs 4 columns `x y z side`, found {}", f.len()),
            });
        }
        let g = |k: usize, w: &str| {
            parse_num(f.get(k), w, source, line)?.ok_or_else(|| Error::Parse {
                file: source.to_string(),
                line,
                msg: format!("{w} is missing"),
            })
        };
        let s = g(3, "side")?;
        if s == 0.0 {
            return Err(Error::Parse { file: source.to_string(), line, msg: "side must be +1 or -1, not 0".into() });
        }
        out.push(SidePoint { pos: [g(0, "x")?, g(1, "y")?, g(2, "z")?], side: s.signum(), line });
    }
    Ok(out)
}

/// Reads LAS or LAZ bytes (positions only: LAS carries no normals or values).
///
/// The header's counts are checked against the bytes first (`input_limits::las`), and points
/// are read in batches: memory grows with the points decoded, never with the count a header
/// claims (`read_all` pre-allocated 10¹² points for a 300-byte file).
pub fn read_las(bytes: Vec<u8>, source: &str) -> Result<Vec<DataPoint>, Error> {
    let perr = |msg: String| Error::Parse { file: source.to_string(), line: 0, msg };
    let mut cursor = std::io::Cursor::new(bytes);
    let len = cursor.get_ref().len() as u64;
    input_limits::las::check(&mut cursor, len).map_err(|e| perr(format!("LAS/LAZ: {e}")))?;
    cursor.set_position(0);
    let mut reader = las::Reader::new(cursor).map_err(|e| perr(format!("LAS/LAZ: {e}")))?;
    let total = reader.header().number_of_points();
    let mut out = Vec::new();
    let mut read = 0u64;
    while read < total {
        let data = reader.read_points(1 << 16).map_err(|e| perr(format!("LAS/LAZ points: {e}")))?;
        if data.is_empty() {
            break;
        }
        read += data.len() as u64;
        for ((x, y), z) in data.x().zip(data.y()).zip(data.z()) {
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                return Err(Error::Parse {
                    file: source.to_string(),
                    line: out.len() + 1,
                    msg: "LAS point with a non-finite coordinate".into(),
                });
            }
            out.push(DataPoint { pos: [x, y, z], value: None, normal: None, line: 0 });
        }
    }
    Ok(out)
}

/// True when `bytes` start with the LAS signature.
pub fn is_las(bytes: &[u8]) -> bool {
    bytes.starts_with(b"LASF")
}
