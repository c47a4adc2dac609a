//! Scattered points (soundings, lidar returns) from XYZ/CSV text and LAS/LAZ.
//!
//! XYZ/CSV rules (one point per line):
//! - fields separated by whitespace, commas or semicolons (mixed is fine);
//! - blank lines and lines starting with `#`, `%` or `>` (GMT segment headers) are skipped;
//! - the FIRST content line may be a header: when it is not numeric it names the columns, and
//!   the columns called x/y/z (or lon/lat, easting/northing, elevation/depth/value…) are used;
//!   without a header the first three fields are x, y, z and extra fields are ignored;
//! - any later line that does not give three finite numbers is an error naming the line
//!   (NaN and ±inf included: a sounding without a depth is a data error, not a hole).
//!
//! `implicit::points` reads XYZ/CSV and LAS too, in another dialect on purpose: there a `value`
//! column is the scalar field φ (here it is z), empty CSV fields mean "absent", and rows may carry
//! normals. Merging the two would change what files mean or which error a user sees.

use std::io::BufRead;
use std::path::Path;

use input_limits::lines::LineError;
use input_limits::quote;

use crate::error::PointsError;
use crate::limits::{PointBudget, READ_BYTES_PER_POINT};
use crate::point_batches::{PointBatches, XyzBatches};

/// Scattered 3D points with an optional CRS.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// (x, y, z) per point, in file order.
    pub points: Vec<[f64; 3]>,
    /// CRS as WKT when the file declares one (LAS WKT VLR).
    pub crs: Option<String>,
}

impl PointCloud {
    /// Bounding box (min x, min y, max x, max y); `None` for an empty cloud.
    pub fn bounds_xy(&self) -> Option<(f64, f64, f64, f64)> {
        let first = self.points.first()?;
        let mut b = (first[0], first[1], first[0], first[1]);
        for p in &self.points {
            b.0 = b.0.min(p[0]);
            b.1 = b.1.min(p[1]);
            b.2 = b.2.max(p[0]);
            b.3 = b.3.max(p[1]);
        }
        Some(b)
    }
}

/// Point file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointFormat {
    Xyz,
    Las,
}

impl PointFormat {
    /// `.las`/`.laz` → LAS, everything else → XYZ text.
    pub fn from_path(path: &Path) -> PointFormat {
        match path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).as_deref() {
            Some("las") | Some("laz") => PointFormat::Las,
            _ => PointFormat::Xyz,
        }
    }
}

fn split_fields(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c.is_whitespace() || c == ',' || c == ';').filter(|s| !s.is_empty())
}

/// Column names recognised in a header for x, y and z.
fn column_role(name: &str) -> Option<usize> {
    let n = name.trim().trim_matches('"').to_ascii_lowercase();
    match n.as_str() {
        "x" | "lon" | "long" | "longitude" | "easting" | "east" | "e" => Some(0),
        "y" | "lat" | "latitude" | "northing" | "north" | "n" => Some(1),
        "z" | "depth" | "elevation" | "elev" | "height" | "h" | "value" | "val" | "alt" | "altitude" => Some(2),
        _ => None,
    }
}

/// Reads XYZ/CSV text (see the module docs). `name` is used in error messages.
pub fn read_xyz<R: BufRead>(reader: R, name: &str) -> Result<PointCloud, PointsError> {
    collect(XyzBatches::new(reader, name), name, None)
}

/// The points of `batches` in one cloud, within the point budget.
fn collect(batches: impl Iterator<Item = Result<Vec<[f64; 3]>, PointsError>>, name: &str, crs: Option<String>) -> Result<PointCloud, PointsError> {
    let budget = PointBudget::for_cost(READ_BYTES_PER_POINT);
    let mut points = Vec::new();
    for batch in batches {
        let batch = batch?;
        check_budget((points.len() + batch.len()).saturating_sub(1), &budget, name)?;
        points.extend(batch);
    }
    Ok(PointCloud { points, crs })
}

/// The line-by-line state of an XYZ/CSV reader: which columns hold x, y, z once a header named
/// them, and how data lines are split then.
#[derive(Debug, Default)]
pub(crate) struct XyzLines {
    line_no: usize,
    buf: String,
    seen_content: bool,
    /// `Some(csv)` after a header that named the columns: data lines are then split as the
    /// header was (empty CSV fields count).
    named: Option<(bool, [usize; 3])>,
}

impl XyzLines {
    /// The next point, `None` at the end of the text.
    pub(crate) fn next_point<R: BufRead>(&mut self, reader: &mut R, name: &str) -> Result<Option<[f64; 3]>, PointsError> {
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
        let fields: Vec<&str> = split_fields(line).collect();
        let first_content = !self.seen_content;
        self.seen_content = true;
        if first_content && fields.iter().any(|f| f.parse::<f64>().is_err() && !f.is_empty()) {
            self.header(line, name)?;
            return Ok(None);
        }
        parse_xyz_fields(&fields, [0, 1, 2], name, self.line_no).map(Some)
    }

    /// A header: maps named columns (the CSV index column, "" or "id", is just skipped); a
    /// header without recognisable names means the first three columns.
    fn header(&mut self, line: &str, name: &str) -> Result<(), PointsError> {
        let raw: Vec<&str> = line.split(|c: char| c == ',' || c == ';' || (c.is_whitespace() && !line.contains(','))).collect();
        let mut found = [None, None, None];
        for (i, f) in raw.iter().enumerate() {
            if let Some(role) = column_role(f) {
                if found[role].is_none() {
                    found[role] = Some(i);
                }
            }
        }
        if let [Some(x), Some(y), Some(z)] = found {
            self.named = Some((line.contains(','), [x, y, z]));
            return Ok(());
        }
        if raw.iter().all(|f| f.trim().parse::<f64>().is_err()) {
            return Ok(());
        }
        Err(PointsError::Line {
            name: name.into(),
            line: self.line_no,
            message: format!("expected three numbers x y z, found {:?}", quote(line)),
        })
    }

    /// A data line after a header that named the columns.
    fn named_line(&self, raw: &str, csv: bool, columns: [usize; 3], name: &str) -> Result<Option<[f64; 3]>, PointsError> {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            return Ok(None);
        }
        let fields: Vec<&str> = if csv { line.split([',', ';']).map(str::trim).collect() } else { split_fields(line).collect() };
        parse_xyz_fields(&fields, columns, name, self.line_no).map(Some)
    }
}

/// One line through the bounded reader (`/dev/zero` has no newline): errors name the line.
fn read_line<R: BufRead>(reader: &mut R, buf: &mut String, name: &str, line_no: usize) -> Result<usize, PointsError> {
    input_limits::lines::read_line(reader, buf).map_err(|e| match e {
        LineError::Io(e) => PointsError::Io { name: name.into(), message: e.to_string() },
        e => PointsError::Line { name: name.into(), line: line_no + 1, message: e.to_string() },
    })
}

/// Refuses the point after `n` when the budget is spent.
fn check_budget(n: usize, budget: &PointBudget, name: &str) -> Result<(), PointsError> {
    if n as u64 >= budget.max_points {
        return Err(PointsError::TooLarge { name: name.into(), message: format!("more than {}", budget.describe()) });
    }
    Ok(())
}

fn parse_xyz_fields(fields: &[&str], columns: [usize; 3], name: &str, line: usize) -> Result<[f64; 3], PointsError> {
    let mut p = [0.0; 3];
    for (k, &c) in columns.iter().enumerate() {
        let axis = ["x", "y", "z"][k];
        let f = fields.get(c).copied().filter(|s| !s.is_empty()).ok_or_else(|| PointsError::Line {
            name: name.into(),
            line,
            message: format!("missing {axis} (column {}): a point needs x, y and z", c + 1),
        })?;
        let v: f64 = f.parse().map_err(|_| PointsError::Line {
            name: name.into(),
            line,
            message: format!("{axis} = {:?} is not a number", quote(f)),
        })?;
        if !v.is_finite() {
            return Err(PointsError::Line { name: name.into(), line, message: format!("{axis} = {} is not a finite number", quote(f)) });
        }
        p[k] = v;
    }
    Ok(p)
}

/// Reads a LAS/LAZ file; `class = Some(c)` keeps only points of ASPRS class `c`
/// (2 = ground). Coordinates are the scaled/offset real-world values.
pub fn read_las(path: &Path, class: Option<u8>) -> Result<PointCloud, PointsError> {
    let points = LasPoints::open(path, class)?;
    let crs = points.crs.clone();
    collect(points, &path.display().to_string(), crs)
}

/// A LAS/LAZ file in the `las` crate's batches, filtered by class (see `point_batches`).
pub struct LasPoints {
    reader: las::Reader,
    name: String,
    class: Option<u8>,
    /// The file's CRS as WKT (WKT VLR, else GeoTIFF keys).
    pub crs: Option<String>,
    total: u64,
    read: u64,
    kept: u64,
    classes_seen: [u64; 256],
    done: bool,
}

impl LasPoints {
    pub fn open(path: &Path, class: Option<u8>) -> Result<LasPoints, PointsError> {
        let name = path.display().to_string();
        guard_las(path, &name)?;
        let reader = las::Reader::from_path(path).map_err(|e| PointsError::Las { name: name.clone(), message: e.to_string() })?;
        let crs = reader
            .header()
            .get_wkt_crs_bytes()
            .map(|b| String::from_utf8_lossy(b).trim_end_matches('\0').trim().to_string())
            .filter(|s| !s.is_empty())
            .or_else(|| geotiff_crs_wkt(reader.header()));
        let total = reader.header().number_of_points();
        Ok(LasPoints { reader, name, class, crs, total, read: 0, kept: 0, classes_seen: [0; 256], done: false })
    }

    /// The next batch of kept points; an empty batch at the end of the file.
    fn batch(&mut self) -> Result<Vec<[f64; 3]>, PointsError> {
        let las_err = |e: las::Error| PointsError::Las { name: self.name.clone(), message: e.to_string() };
        let mut kept = Vec::new();
        while kept.is_empty() && self.read < self.total {
            let batch = self.reader.read_points(crate::point_batches::BATCH_POINTS as u64).map_err(las_err)?;
            if batch.is_empty() {
                break;
            }
            let first = self.read as usize;
            self.read += batch.len() as u64;
            for (i, ((x, y), (z, c))) in batch.x().zip(batch.y()).zip(batch.z().zip(batch.classification())).enumerate() {
                self.classes_seen[c as usize] += 1;
                if self.class.is_some_and(|k| k != c) {
                    continue;
                }
                if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                    let message = format!("point {} has a non-finite coordinate", first + i);
                    return Err(PointsError::Las { name: self.name.clone(), message });
                }
                kept.push([x, y, z]);
            }
        }
        self.kept += kept.len() as u64;
        Ok(kept)
    }

    /// Why the stream ends without a point, or short of the points the header announced.
    fn end_error(&self) -> Option<PointsError> {
        let name = self.name.clone();
        if self.read < self.total {
            return Some(PointsError::Las { name, message: format!("header announces {} points but the file holds {}", self.total, self.read) });
        }
        if self.kept > 0 {
            return None;
        }
        let present: Vec<String> =
            self.classes_seen.iter().enumerate().filter(|(_, n)| **n > 0).map(|(c, n)| format!("{c} ({n})")).collect();
        let message = match self.class {
            Some(c) => format!("no point of class {c}; classes present: {}", present.join(", ")),
            None => "no points".into(),
        };
        Some(PointsError::Empty { name, message })
    }
}

impl Iterator for LasPoints {
    type Item = Result<Vec<[f64; 3]>, PointsError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.batch() {
            Ok(b) if b.is_empty() => {
                self.done = true;
                self.end_error().map(Err)
            }
            Ok(b) => Some(Ok(b)),
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}

/// Checks what a LAS/LAZ header claims against the file's size before the `las` crate sizes
/// allocations by it (a LAZ chunk table of 4·10⁹ entries aborted inside `laz`).
fn guard_las(path: &Path, name: &str) -> Result<(), PointsError> {
    let Ok(mut f) = std::fs::File::open(path) else { return Ok(()) }; // las names the error
    let Ok(meta) = f.metadata() else { return Ok(()) };
    if !meta.is_file() {
        return Ok(());
    }
    input_limits::las::check(&mut f, meta.len()).map_err(|e| match e {
        input_limits::las::LasClaim::Io(e) => PointsError::Las { name: name.into(), message: e.to_string() },
        e => PointsError::TooLarge { name: name.into(), message: e.to_string() },
    })
}

/// The CRS of LAS 1.0–1.3 files (GeoTIFF key VLRs): the projected or geographic EPSG code,
/// turned into WKT by GDAL/PROJ. `None` for user-defined (32767) or unknown codes.
fn geotiff_crs_wkt(header: &las::Header) -> Option<String> {
    let keys = header.get_geotiff_crs().ok()??;
    let code = keys.get_projected_crs_geo_key_value().or_else(|| keys.get_geodetic_crs_geo_key_value())?;
    if code == 0 || code >= 32767 {
        return None;
    }
    gdal::spatial_ref::SpatialRef::from_epsg(code as u32).ok()?.to_wkt().ok()
}

/// Reads a point file by extension: LAS/LAZ (with the class filter) or XYZ text.
/// `class` on an XYZ file is an error (text points carry no class).
pub fn read_points(path: &Path, class: Option<u8>) -> Result<PointCloud, PointsError> {
    let batches = PointBatches::open(path, class)?;
    let crs = batches.crs().map(str::to_string);
    collect(batches, &path.display().to_string(), crs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<PointCloud, PointsError> {
        read_xyz(s.as_bytes(), "t.xyz")
    }

    #[test]
    fn whitespace_comma_and_header() {
        assert_eq!(parse("1 2 3\n4\t5  6\n").unwrap().points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(parse("x,y,z\n1,2,3\n").unwrap().points, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(parse("# c\n\n1, 2, 3, 99\n").unwrap().points, vec![[1.0, 2.0, 3.0]]);
        // named columns in another order, with an index column
        let pc = parse(",Z,X,Y,extra\n0,30,10,20,a\n1,31,11,21,b\n").unwrap();
        assert_eq!(pc.points, vec![[10.0, 20.0, 30.0], [11.0, 21.0, 31.0]]);
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
        assert!(parse("# nothing\n").is_err());
    }
}
