//! The terrain dialect: soundings and lidar returns as x y z, in batches.
//!
//! XYZ/CSV rules (one point per line):
//! - the field separator (`,` `;` tab, blanks) and the decimal mark (`.` or `,`) are detected
//!   as [`crate::text`] says, or given ([`XyzBatches::with_format`]): `x;y;z` over
//!   `341000,5;5724000,25;12,5` reads 341000.5, 5724000.25, 12.5; a text that could be read two
//!   ways is refused, never guessed;
//! - blank lines and lines starting with `#`, `%` or `>` (GMT segment headers) are skipped; a
//!   UTF-8 BOM and CRLF line ends are read as nothing;
//! - the FIRST content line may be a header: when a field is not a number it names the columns,
//!   and the columns called x/y/z (or lon/lat, easting/northing, elevation/depth/value…, a unit
//!   in brackets ignored, see [`crate::columns`]) are used; a header naming some of them but not
//!   all, or none with more than three columns, is refused (which column is z?); three unknown
//!   names mean x y z. Without a header the first three fields are x, y, z and extra fields are
//!   ignored. Values are taken as they are: a `depth` column positive down stays positive down;
//! - every data line has as many fields as the header (or, without one, as the first row): a
//!   row of 5 numbers under `x y z` is an error naming its line, as is any line that does not
//!   give three finite numbers (NaN and ±inf included: a sounding without a depth is a data
//!   error, not a hole).
//!
//! LAS/LAZ through [`crate::las::LasPoints`], with its errors worded for this dialect.

use std::io::BufRead;

use input_limits::lines::LineError;
use input_limits::quote;

use crate::columns::{is_geographic_name, terrain_xyz};
use crate::las::{LasError, LasPoints};
use crate::text::{
    could_be_decimal_commas, detect_separator, looks_numeric, split_fields, Decimals, FieldError, Separator, TextFormat,
};
use crate::{PointsError, BATCH_POINTS};

/// How the data lines of a text are read, fixed by its first content line.
#[derive(Debug)]
struct Layout {
    sep: Separator,
    /// Whether the separator was detected (not given).
    detected: bool,
    /// The fields of x, y, z.
    columns: [usize; 3],
    /// The number of fields every data line has.
    fields: usize,
    /// The header's line and names, if there is one.
    header: Option<(usize, Vec<String>)>,
    /// The line the field count comes from.
    counted_at: usize,
}

/// The line-by-line state of a terrain XYZ/CSV reader.
#[derive(Debug, Default)]
struct XyzLines {
    line_no: usize,
    buf: String,
    given: TextFormat,
    layout: Option<Layout>,
    decimals: Decimals,
}

impl XyzLines {
    fn new(given: TextFormat) -> XyzLines {
        XyzLines { given, decimals: Decimals::new(given.decimal), ..XyzLines::default() }
    }

    /// The next point, `None` at the end of the text.
    fn next_point<R: BufRead>(&mut self, reader: &mut R, name: &str) -> Result<Option<[f64; 3]>, PointsError> {
        loop {
            self.buf.clear();
            if read_line(reader, &mut self.buf, name, self.line_no)? == 0 {
                return Ok(None);
            }
            self.line_no += 1;
            let line = std::mem::take(&mut self.buf);
            let point = self.line(&line, name);
            self.buf = line;
            if let Some(p) = point? {
                return Ok(Some(p));
            }
        }
    }

    /// One line: a comment, the header, or a point.
    fn line(&mut self, raw: &str, name: &str) -> Result<Option<[f64; 3]>, PointsError> {
        let mut line = raw.trim_end_matches(['\n', '\r']);
        if self.line_no == 1 {
            line = line.trim_start_matches('\u{feff}');
        }
        let content = line.trim();
        if content.is_empty() || content.starts_with('#') || content.starts_with('%') || content.starts_with('>') {
            return Ok(None);
        }
        let line_no = self.line_no;
        let err = |m: String| PointsError::line(name, line_no, m);
        if self.layout.is_none() {
            let (sep, detected) = match self.given.separator {
                Some(s) => (s, false),
                None => (detect_separator(content).map_err(err)?, true),
            };
            let fields = split_fields(if sep == Separator::Whitespace { content } else { line }, sep)
                .ok_or_else(|| err(format!("a double quote is not closed in {:?}", quote(content))))?;
            if fields.iter().any(|f| !f.is_empty() && !looks_numeric(f)) {
                self.layout = Some(self.header(&fields, sep, detected, content, name)?);
                return Ok(None);
            }
            if detected && sep == Separator::Comma && self.given.decimal.is_none() && could_be_decimal_commas(&fields) {
                return Err(err(format!(
                    "{:?} may be {} whole numbers or {} numbers with decimal commas; give --sep , to read commas as separators, or write the file with ';' between fields",
                    quote(content),
                    fields.len(),
                    fields.len() / 2
                )));
            }
            self.layout = Some(Layout {
                sep,
                detected,
                columns: [0, 1, 2],
                fields: fields.len(),
                header: None,
                counted_at: line_no,
            });
        }
        let Some(layout) = self.layout.as_ref() else { return Ok(None) };
        let fields = split_fields(if layout.sep == Separator::Whitespace { content } else { line }, layout.sep)
            .ok_or_else(|| err(format!("a double quote is not closed in {:?}", quote(content))))?;
        if fields.len() != layout.fields {
            return Err(err(count_message(&fields, layout)));
        }
        xyz_fields(&fields, layout.columns, layout.sep, &mut self.decimals, name, line_no).map(Some)
    }

    /// A header: maps named columns (other columns, an index column "" or "id" among them, are
    /// skipped); a header without recognisable names means the first three columns.
    fn header(
        &self,
        fields: &[&str],
        sep: Separator,
        detected: bool,
        line: &str,
        name: &str,
    ) -> Result<Layout, PointsError> {
        let err = |m: String| PointsError::line(name, self.line_no, m);
        let named = terrain_xyz(fields);
        let numeric = fields.iter().any(|f| looks_numeric(f));
        if numeric && !matches!(named, Ok(Some(_))) {
            return Err(err(format!("expected three numbers x y z, found {:?}", quote(line))));
        }
        let columns = match named.map_err(err)? {
            Some(c) => c,
            None if fields.len() < 3 => {
                let how = if detected { "" } else { " (as given)" };
                return Err(err(format!(
                    "{:?} is {} field(s) split by {}{how}: a point needs x, y and z",
                    quote(line),
                    fields.len(),
                    sep.describe()
                )));
            }
            None if fields.len() == 3 => [0, 1, 2],
            None => {
                let found = fields.join(", ");
                return Err(err(format!(
                    "cannot tell which of the header's {} columns are x, y, z (found: {found}); name them x, y, z",
                    fields.len()
                )));
            }
        };
        let names = fields.iter().map(|f| f.to_string()).collect();
        Ok(Layout {
            sep,
            detected,
            columns,
            fields: fields.len(),
            header: Some((self.line_no, names)),
            counted_at: self.line_no,
        })
    }
}

/// Why a row's field count is wrong, with what the text was read as.
fn count_message(fields: &[&str], layout: &Layout) -> String {
    let how = format!(
        "fields separated by {}{}",
        layout.sep.describe(),
        if layout.detected { " (detected; --sep gives another)" } else { "" }
    );
    let mut m = match &layout.header {
        Some((line, names)) => format!(
            "{} fields, but the header (line {line}) has {} ({}); {how}",
            fields.len(),
            layout.fields,
            names.join(", ")
        ),
        None => format!("{} fields, but line {} has {}; {how}", fields.len(), layout.counted_at, layout.fields),
    };
    if layout.sep == Separator::Comma && fields.len() > layout.fields && !fields.iter().any(|f| f.contains('.')) {
        m.push_str("; decimal commas cannot be told from separators in a comma-separated file: use ';' between fields or quote the numbers");
    }
    m
}

/// One line through the bounded reader (`/dev/zero` has no newline): errors name the line.
fn read_line<R: BufRead>(reader: &mut R, buf: &mut String, name: &str, line_no: usize) -> Result<usize, PointsError> {
    input_limits::lines::read_line(reader, buf).map_err(|e| match e {
        LineError::Io(e) => PointsError::Io { name: name.into(), message: e.to_string() },
        e => PointsError::line(name, line_no + 1, e.to_string()),
    })
}

/// The point in `columns` of a data line's fields.
fn xyz_fields(
    fields: &[&str],
    columns: [usize; 3],
    sep: Separator,
    decimals: &mut Decimals,
    name: &str,
    line: usize,
) -> Result<[f64; 3], PointsError> {
    let mut p = [0.0; 3];
    for (k, &c) in columns.iter().enumerate() {
        let axis = ["x", "y", "z"][k];
        let f = fields.get(c).copied().filter(|s| !s.is_empty()).ok_or_else(|| {
            PointsError::line(name, line, format!("missing {axis} (column {}): a point needs x, y and z", c + 1))
        })?;
        p[k] = decimals.parse(f, sep, line).map_err(|e| {
            let message = match e {
                FieldError::NotANumber => format!("{axis} = {:?} is not a number", quote(f)),
                FieldError::NotFinite => format!("{axis} = {} is not a finite number", quote(f)),
                FieldError::Decimal(why) => format!("{axis} = {:?} {why}", quote(f)),
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
    /// Reads `reader`, detecting its separator and decimal mark; `name` is used in error
    /// messages.
    pub fn new(reader: R, name: &str) -> XyzBatches<R> {
        XyzBatches::with_text_format(reader, name, TextFormat::default())
    }

    /// Reads `reader` with the separator and decimal mark of `format` where it gives them.
    pub fn with_text_format(reader: R, name: &str, format: TextFormat) -> XyzBatches<R> {
        XyzBatches { reader, lines: XyzLines::new(format), name: name.to_string(), yielded: 0, done: false }
    }

    /// Reads `reader` with the separator (`,` `;` `tab` `space`) and decimal mark (`.` `,`)
    /// named as by `--sep` and `--decimal` (`None`: detected); an unknown name is an error
    /// naming the choices ([`TextFormat::from_names`]).
    pub fn with_format(
        reader: R,
        name: &str,
        sep: Option<&str>,
        decimal: Option<&str>,
    ) -> Result<XyzBatches<R>, String> {
        Ok(XyzBatches::with_text_format(reader, name, TextFormat::from_names(sep, decimal)?))
    }

    /// What the text was read as, once its first content line is read: the separator (and
    /// whether it was detected), the decimal mark once a number had one, and the columns
    /// taken for x, y, z, e.g. `';' separated (detected), decimal comma, x y z = columns
    /// Easting, Northing, depth (values as given: a depth stays positive down)`.
    pub fn describe(&self) -> Option<String> {
        let l = self.lines.layout.as_ref()?;
        let mut s = format!("{} separated{}", l.sep.describe(), if l.detected { " (detected)" } else { "" });
        if let Some(m) = self.lines.decimals.mark() {
            s.push_str(&format!(", {}", m.describe()));
        }
        match &l.header {
            Some((_, names)) => {
                let cols: Vec<&str> = l.columns.iter().map(|&c| names[c].as_str()).collect();
                s.push_str(&format!(", x y z = columns {}", cols.join(", ")));
                if ["depth", "tiefe"].iter().any(|d| cols[2].to_lowercase().starts_with(d)) {
                    s.push_str(" (values as given: a depth stays positive down)");
                }
            }
            None => s.push_str(", no header: x y z = the first three fields"),
        }
        Some(s)
    }

    /// Whether the header names the x and y columns as longitude and latitude (degrees).
    pub fn geographic_columns(&self) -> bool {
        self.lines
            .layout
            .as_ref()
            .and_then(|l| l.header.as_ref().map(|(_, n)| (l, n)))
            .is_some_and(|(l, n)| is_geographic_name(&n[l.columns[0]]) && is_geographic_name(&n[l.columns[1]]))
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
        LasError::Open(_) | LasError::Read(_) | LasError::NonFinite { .. } | LasError::Short { .. } => {
            PointsError::Las { name, message }
        }
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
        assert_eq!(
            parse(",Z,X,Y,extra\n0,30,10,20,a\n1,31,11,21,b\n").unwrap(),
            vec![[10.0, 20.0, 30.0], [11.0, 21.0, 31.0]]
        );
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
    fn decimal_commas_where_semicolons_tabs_or_blanks_separate() {
        let want = vec![[341000.5, 5724000.25, 12.5], [341001.0, 5724001.0, -3.75]];
        assert_eq!(parse("x;y;z\n341000,5;5724000,25;12,5\n341001;5724001;-3,75\n").unwrap(), want);
        assert_eq!(parse("341000,5\t5724000,25\t12,5\n341001\t5724001\t-3,75\n").unwrap(), want);
        assert_eq!(parse("341000,5 5724000,25 12,5\n341001 5724001 -3,75\n").unwrap(), want);
        // quoted decimal commas in a comma-separated file
        assert_eq!(parse("x,y,z\n\"341000,5\",\"5724000,25\",\"12,5\"\n").unwrap(), want[..1]);
        // given: comma separator, decimal point
        let given = |s: &str, sep, dec| -> Result<Vec<[f64; 3]>, PointsError> {
            let mut points = Vec::new();
            for batch in XyzBatches::with_format(s.as_bytes(), "t.xyz", sep, dec).unwrap() {
                points.extend(batch?);
            }
            Ok(points)
        };
        assert_eq!(given("1,2,3,4,5,6\n", Some(","), None).unwrap(), vec![[1.0, 2.0, 3.0]]);
        assert_eq!(
            given("1;2;3\n", Some("space"), None).unwrap_err().to_string(),
            "t.xyz:1: \"1;2;3\" is 1 field(s) split by blanks (as given): a point needs x, y and z"
        );
        assert_eq!(
            given("1;2;3,5\n", None, Some(".")).unwrap_err().to_string(),
            "t.xyz:1: z = \"3,5\" has a decimal comma, but the decimal mark given is '.'"
        );
    }

    #[test]
    fn texts_read_two_ways_are_refused() {
        // the file with commas for separators: 6 fields under a 3-column header
        let e = parse("x,y,z\n341000,5,5724000,25,12,5\n").unwrap_err().to_string();
        assert!(
            e.starts_with("t.xyz:2: 6 fields, but the header (line 1) has 3 (x, y, z); fields separated by ','"),
            "{e}"
        );
        assert!(e.contains("decimal commas"), "{e}");
        // headerless: 6 whole numbers or 3 with decimal commas?
        let e = parse("341000,5,5724000,25,12,5\n").unwrap_err().to_string();
        assert!(
            e.starts_with(
                "t.xyz:1: \"341000,5,5724000,25,12,5\" may be 6 whole numbers or 3 numbers with decimal commas"
            ),
            "{e}"
        );
        // both marks in one text, or in one number
        let e = parse("x;y;z\n1,5;2;3\n1.5;2;3\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "t.xyz:3: x = \"1.5\" has a decimal point, but line 2 has a decimal comma (\"1,5\"); give --decimal"
        );
        let e = parse("x;y;z\n\"1.234,5\";2;3\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:2: x = \"1.234,5\" has both ',' and '.'"), "{e}");
        let e = parse("x,y,z\n\"1,234\",2,3\n").unwrap_err().to_string();
        assert!(e.contains("decimal comma or a thousands separator"), "{e}");
        let e = parse("1,2 3,4,5\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:1: cannot tell the field separator"), "{e}");
        // two columns for one axis
        let e = parse("lon,lat,x,y,z\n1,2,3,4,5\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:1: the header names 2 columns for x (lon, x): keep one");
    }

    #[test]
    fn headers_that_do_not_say_which_columns_are_refused() {
        let e = parse("ID,Easting,Northing,Sounding\n1,2,3,4\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "t.xyz:1: the header names no z column (found: ID, Easting, Northing, Sounding); name the columns x, y, z"
        );
        let e = parse("Punkt Spalte2 Spalte3 Spalte4\n1 2 3 4\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:1: cannot tell which of the header's 4 columns are x, y, z"), "{e}");
        assert_eq!(parse("ID;Easting [m];Northing [m];Depth (m)\n1;2;3;4,5\n").unwrap(), vec![[2.0, 3.0, 4.5]]);
    }

    #[test]
    fn every_row_has_the_header_s_field_count() {
        let e = parse("x y z\n1 2 3\n1 2 3 4 5\n").unwrap_err().to_string();
        assert_eq!(e, "t.xyz:3: 5 fields, but the header (line 1) has 3 (x, y, z); fields separated by blanks (detected; --sep gives another)");
        let e = parse("1 2 3\n\n4 5 6 7\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "t.xyz:3: 4 fields, but line 1 has 3; fields separated by blanks (detected; --sep gives another)"
        );
        let e = parse("x;y;z\n1;2\n").unwrap_err().to_string();
        assert!(e.starts_with("t.xyz:2: 2 fields, but the header"), "{e}");
        // a tab-separated header with an empty column keeps its place
        assert_eq!(parse("\tx\ty\tz\n0\t1\t2\t3\n").unwrap(), vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn crlf_bom_and_what_was_read() {
        let text = "\u{feff}Easting;Northing;Depth\r\n1,5;2;3\r\n4;5;6,25\r\n";
        assert_eq!(parse(text).unwrap(), vec![[1.5, 2.0, 3.0], [4.0, 5.0, 6.25]]);
        let mut b = XyzBatches::new(text.as_bytes(), "t");
        b.next().unwrap().unwrap();
        assert_eq!(b.describe().unwrap(), "';' separated (detected), decimal comma, x y z = columns Easting, Northing, Depth (values as given: a depth stays positive down)");
        assert!(!b.geographic_columns());
        let mut b = XyzBatches::new("lat\tlon\tz\n52\t7\t1\n".as_bytes(), "t");
        assert_eq!(b.next().unwrap().unwrap(), vec![[7.0, 52.0, 1.0]]);
        assert!(b.geographic_columns());
        assert_eq!(b.describe().unwrap(), "tabs separated (detected), x y z = columns lon, lat, z");
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
