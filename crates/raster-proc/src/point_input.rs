//! Point input of rasterization: a LAS/LAZ file, or XYZ/CSV text read with the separator and
//! decimal mark a user gave (`--sep`, `--decimal`) or detected by point-io
//! (docs/decisions.md#point-text-separators-and-decimal-commas-issue-41), with what the text
//! was read as ([`TextFacts`]) so the caller can say it and check the units of lon/lat columns.
//!
//! # Examples
//!
//! ```
//! use raster_proc::point_input::read_text;
//! let text = "Easting;Northing;Depth\r\n341000,5;5724000,25;12,5\r\n";
//! let (cloud, facts) = read_text(text.as_bytes(), "s.csv", None, None).unwrap();
//! assert_eq!(cloud.points, [[341000.5, 5724000.25, 12.5]]);
//! assert!(facts.read_as.unwrap().starts_with("';' separated (detected), decimal comma"));
//! assert!(!facts.geographic);
//! ```

use std::io::BufRead;
use std::path::Path;

use raster_io::limits::{PointBudget, READ_BYTES_PER_POINT};
use raster_io::point_batches::{PointBatches, XyzBatches};
use raster_io::{PointCloud, PointFormat, PointsError};

/// What a point text was read as.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TextFacts {
    /// Separator, decimal mark and columns, in words (`None`: not text, or nothing read).
    pub read_as: Option<String>,
    /// The header names the x and y columns longitude and latitude.
    pub geographic: bool,
}

impl TextFacts {
    /// The facts of `batches` after a pass over them.
    pub fn of(batches: &PointBatches) -> TextFacts {
        match batches {
            PointBatches::Xyz(x) => TextFacts { read_as: x.describe(), geographic: x.geographic_columns() },
            PointBatches::Las { .. } => TextFacts::default(),
        }
    }
}

/// Opens a point file by extension: LAS/LAZ (with the class filter; `sep`/`decimal` are for
/// text only and refused here), or XYZ text read with `sep` and `decimal` where given.
pub fn open_file(
    path: &Path,
    class: Option<u8>,
    sep: Option<&str>,
    decimal: Option<&str>,
) -> Result<PointBatches, PointsError> {
    let name = path.display().to_string();
    let io = |message: String| PointsError::Io { name: name.clone(), message };
    match PointFormat::from_path(path) {
        PointFormat::Las if sep.is_some() || decimal.is_some() => {
            Err(io("a field separator or decimal mark is for XYZ/CSV text, not LAS/LAZ".into()))
        }
        PointFormat::Xyz if class.is_none() => {
            let f = std::fs::File::open(path).map_err(|e| io(e.to_string()))?;
            Ok(PointBatches::Xyz(XyzBatches::with_format(std::io::BufReader::new(f), &name, sep, decimal).map_err(io)?))
        }
        _ => PointBatches::open(path, class),
    }
}

/// Every point of `batches` in one cloud, within the point budget (`GEOFIT_MAX_POINTS` or the
/// available memory).
pub fn collect(
    batches: &mut dyn Iterator<Item = Result<Vec<[f64; 3]>, PointsError>>,
    name: &str,
    crs: Option<String>,
) -> Result<PointCloud, PointsError> {
    let budget = PointBudget::for_cost(READ_BYTES_PER_POINT);
    let mut points = Vec::new();
    for batch in batches {
        let batch = batch?;
        if (points.len() + batch.len()) as u64 > budget.max_points {
            return Err(PointsError::TooLarge {
                name: name.into(),
                message: format!("more than {}", budget.describe()),
            });
        }
        points.extend(batch);
    }
    Ok(PointCloud { points, crs })
}

/// A point file read whole (TIN needs every point), with its text facts.
pub fn read_file(
    path: &Path,
    class: Option<u8>,
    sep: Option<&str>,
    decimal: Option<&str>,
) -> Result<(PointCloud, TextFacts), PointsError> {
    let mut batches = open_file(path, class, sep, decimal)?;
    let crs = batches.crs().map(str::to_string);
    let cloud = collect(&mut batches, &path.display().to_string(), crs)?;
    Ok((cloud, TextFacts::of(&batches)))
}

/// XYZ text from a reader (stdin) read whole, with its text facts.
pub fn read_text<R: BufRead>(
    reader: R,
    name: &str,
    sep: Option<&str>,
    decimal: Option<&str>,
) -> Result<(PointCloud, TextFacts), PointsError> {
    let mut batches = XyzBatches::with_format(reader, name, sep, decimal)
        .map_err(|message| PointsError::Io { name: name.into(), message })?;
    let cloud = collect(&mut batches, name, None)?;
    let facts = TextFacts { read_as: batches.describe(), geographic: batches.geographic_columns() };
    Ok((cloud, facts))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_are_for_text_and_classes_for_las() {
        let dir = std::env::temp_dir().join(format!("point-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let las = dir.join("a.laz");
        let e = open_file(&las, None, Some(";"), None).err().unwrap().to_string();
        assert!(e.ends_with("a field separator or decimal mark is for XYZ/CSV text, not LAS/LAZ"), "{e}");
        let txt = dir.join("a.xyz");
        std::fs::write(&txt, "lon lat depth\n7,5 52,25 3\n").unwrap();
        let e = open_file(&txt, Some(2), None, None).err().unwrap().to_string();
        assert!(e.contains("needs a LAS/LAZ file"), "{e}");
        let (cloud, facts) = read_file(&txt, None, None, None).unwrap();
        assert_eq!(cloud.points, [[7.5, 52.25, 3.0]]);
        assert!(facts.geographic);
        let e = read_file(&txt, None, Some("space"), Some(".")).unwrap_err().to_string();
        assert!(e.contains("x = \"7,5\" has a decimal comma, but the decimal mark given is '.'"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
