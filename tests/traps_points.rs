//! Traps (issue 41): point text as surveyors send it, read by `geofit rasterize`.
//!
//! Each trap is written here, in a temporary directory. A trap that can be read is rasterized
//! with `--method tin` (or Gauss, streamed) and the raster, read back by GDAL
//! (`gdal_translate -of XYZ`, `gdalinfo -json`), is compared with values computed here: TIN
//! interpolation reproduces a plane exactly, so every cell with a value must hold the plane's
//! value at its centre, and the grid must lie where the points are. A trap that cannot be read
//! must end with exit 2 or 3, exactly one line on stderr naming the problem (and `file:line`
//! where a line is at fault), no file at `-o`, and the input unchanged.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// How close a value read back must be: the rasters are Float32 (values here are under 20, so
/// rounding is under 1e-6); a misread decimal comma is off by metres to kilometres.
const F32: f64 = 2e-6;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The plane the lattice points lie on (projected metres, ETRS89 / UTM 32N-like numbers); on
/// the lattice its values have at most two decimals (or float noise), never the three digits
/// after a comma that could be a thousands group.
fn plane(x: f64, y: f64) -> f64 {
    0.5 * (x - 341000.0) - 0.2 * (y - 5724000.0) + 10.0
}

/// 7 × 7 points with fractional coordinates on [`plane`]: x 341000.5…341009.5, y
/// 5724000.25…5724007.75 (fractions that a misread decimal comma turns into whole new numbers).
fn lattice() -> Vec<[f64; 3]> {
    let mut pts = Vec::new();
    for j in 0..7 {
        for i in 0..7 {
            let (x, y) = (341000.5 + 1.5 * i as f64, 5724000.25 + 1.25 * j as f64);
            pts.push([x, y, plane(x, y)]);
        }
    }
    pts
}

/// `v` with a decimal comma.
fn comma(v: f64) -> String {
    format!("{v}").replace('.', ",")
}

/// A text of `header` and one row per point, each value formatted by `f`, joined by `sep`,
/// lines ended by `eol`.
fn text(header: Option<&str>, pts: &[[f64; 3]], sep: &str, eol: &str, f: impl Fn(f64) -> String) -> String {
    let mut t = String::new();
    if let Some(h) = header {
        t.push_str(h);
        t.push_str(eol);
    }
    for p in pts {
        t.push_str(&p.iter().map(|v| f(*v)).collect::<Vec<_>>().join(sep));
        t.push_str(eol);
    }
    t
}

fn write(dir: &Path, name: &str, content: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, content).unwrap();
    p
}

/// The cells of a raster with a value, as GDAL reads them: (x, y, value) of each cell centre.
fn cells(tif: &Path) -> Vec<(f64, f64, f64)> {
    let info = gdalinfo(tif);
    let nodata = info["bands"][0]["noDataValue"].as_f64();
    let o = Command::new("gdal_translate").args(["-q", "-of", "XYZ", s(tif), "/vsistdout/"]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            (v[0], v[1], v[2])
        })
        .filter(|c| Some(c.2) != nodata)
        .collect()
}

fn gdalinfo(tif: &Path) -> serde_json::Value {
    let o = Command::new("gdalinfo").args(["-json", s(tif)]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn gdal() -> bool {
    common::tool("gdal_translate") && common::tool("gdalinfo")
}

/// Runs `rasterize INPUT --cell 1 --method tin -o OUT extra...`, expects exit 0, and checks
/// that the raster holds [`plane`] in every cell with a value, that at least half the cells
/// of the points' hull have one, and that the grid lies over the lattice.
fn tin_gives_the_plane(input: &str, stdin: Option<&[u8]>, dir: &Path, extra: &[&str]) -> String {
    let out = dir.join("plane.tif");
    let _ = std::fs::remove_file(&out);
    let mut args = vec!["rasterize", input, "--cell", "1", "--method", "tin", "-o", s(&out)];
    args.extend_from_slice(extra);
    let o = common::run(&args, stdin);
    let e = stderr(&o);
    assert_eq!(common::code(&o), 0, "{args:?}: {e}");
    if !gdal() {
        return e;
    }
    let cells = cells(&out);
    // the hull is 9 × 7.5 m: 63 cells at 1 m lie inside it, allow the boundary
    assert!(cells.len() >= 40, "{} cells with a value: {e}", cells.len());
    for (x, y, v) in &cells {
        assert!((341000.0..=341010.0).contains(x) && (5724000.0..=5724008.0).contains(y), "cell at {x} {y}: {e}");
        assert!((v - plane(*x, *y)).abs() < F32, "cell {x} {y}: {v} != plane {}", plane(*x, *y));
    }
    e
}

/// A refusal (see [`common::refused`]): `input` unchanged, nothing at `out`.
#[track_caller]
fn refused(args: &[&str], code: i32, needles: &[&str], input: &Path, out: &Path) -> String {
    common::refused(args, None, code, needles, Some(out), &[input])
}

/// The file: `x;y;z` over `341000,5;5724000,25;12,5` (German office CSV) was read as
/// x=341000, y=5, z=5724000 with exit 0. Now `;` separates and `,` is the decimal comma.
#[test]
fn semicolons_with_decimal_commas() {
    let d = common::tempdir();
    let p = write(d.path(), "lot.csv", text(Some("x;y;z"), &lattice(), ";", "\n", comma).as_bytes());
    assert!(std::fs::read_to_string(&p).unwrap().contains("341000,5;5724000,25;"));
    let e = tin_gives_the_plane(s(&p), None, d.path(), &[]);
    assert!(e.contains("';' separated (detected), decimal comma"), "{e}");
    // the same through stdin (read whole) and with the choice given
    let bytes = std::fs::read(&p).unwrap();
    tin_gives_the_plane("-", Some(&bytes), d.path(), &[]);
    tin_gives_the_plane(s(&p), None, d.path(), &["--sep", ";", "--decimal", ","]);
}

/// Tab-separated decimal commas with a UTF-8 BOM and CRLF line ends (a spreadsheet export on
/// Windows), and blank-separated decimal commas; Gauss (the streamed path reads the file twice)
/// puts the grid over the points.
#[test]
fn tabs_blanks_crlf_and_bom() {
    let d = common::tempdir();
    let mut bytes = b"\xef\xbb\xbf".to_vec();
    bytes.extend(text(Some("Rechtswert\tHochwert\tHoehe"), &lattice(), "\t", "\r\n", comma).into_bytes());
    let p = write(d.path(), "tab.txt", &bytes);
    tin_gives_the_plane(s(&p), None, d.path(), &[]);
    let p = write(d.path(), "blank.xyz", text(None, &lattice(), "  ", "\r\n", comma).as_bytes());
    tin_gives_the_plane(s(&p), None, d.path(), &[]);
    // CRLF and a BOM on an ordinary CSV with decimal points
    let mut bytes = b"\xef\xbb\xbf".to_vec();
    bytes.extend(text(Some("Easting,Northing,Elevation"), &lattice(), ",", "\r\n", |v| v.to_string()).into_bytes());
    let p = write(d.path(), "crlf.csv", &bytes);
    tin_gives_the_plane(s(&p), None, d.path(), &[]);
    // Gauss, streamed: a constant height everywhere, and the grid exactly where covering puts it
    let flat: Vec<[f64; 3]> = lattice().iter().map(|p| [p[0], p[1], 12.5]).collect();
    let p = write(d.path(), "flat.csv", text(Some("x;y;z"), &flat, ";", "\r\n", comma).as_bytes());
    let out = d.path().join("flat.tif");
    let o = common::run(&["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    if !gdal() {
        return;
    }
    let gt: Vec<f64> = gdalinfo(&out)["geoTransform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let size: Vec<f64> = gdalinfo(&out)["size"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    // x 341000.5…341009.5 on 1 m cells: 341000…341010; y 5724000.25…5724007.75: 5724000…5724008
    assert_eq!((gt[0], gt[3], size[0], size[1]), (341000.0, 5724008.0, 10.0, 8.0), "{gt:?} {size:?}");
    let c = cells(&out);
    assert!(c.len() >= 49 && c.iter().all(|c| (c.2 - 12.5).abs() < F32), "{c:?}");
}

/// Commas as separators AND decimal commas: under an `x,y,z` header the row has 6 fields
/// (refused, naming the line and why); without a header, six whole numbers that may be three
/// with decimal commas are refused until `--sep ,` says they are fields.
#[test]
fn decimal_commas_in_a_comma_separated_file_are_refused() {
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    let p = write(d.path(), "c.csv", b"x,y,z\n341000,5,5724000,25,12,5\n341001,5,5724000,25,12,5\n");
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)];
    refused(&args, 3, &["c.csv:2:", "6 fields, but the header (line 1) has 3", "decimal commas"], &p, &out);
    let p = write(d.path(), "h.csv", b"341000,5,5724000,25,12,5\n341002,5,5724002,25,13,5\n341000,5,5724002,25,14,5\n");
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)];
    refused(&args, 3, &["h.csv:1:", "may be 6 whole numbers or 3 numbers with decimal commas", "--sep ,"], &p, &out);
    // given as fields: x, y, z are the first three whole numbers of rows that also carry
    // three whole-number attributes, on the plane z = 12 + (x − 341000) + 0.5 (y − 5724000)
    let p = write(
        d.path(),
        "g.csv",
        b"341000,5724000,12,1,2,3\n341004,5724000,16,1,2,3\n341000,5724004,14,1,2,3\n341004,5724004,18,1,2,3\n",
    );
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "--method", "tin", "-o", s(&out)];
    refused(&args, 3, &["g.csv:1:", "may be 6 whole numbers"], &p, &out);
    let o =
        common::run(&["-q", "rasterize", s(&p), "--cell", "1", "--method", "tin", "-o", s(&out), "--sep", ","], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    if gdal() {
        let c = cells(&out);
        assert!(c.len() >= 16, "{c:?}");
        for (x, y, v) in c {
            assert!((v - (12.0 + (x - 341000.0) + 0.5 * (y - 5724000.0))).abs() < F32, "{x} {y} {v}");
        }
    }
    // quoted decimal commas in a comma-separated file are read right
    let p = write(
        d.path(),
        "q.csv",
        text(Some("x,y,z"), &lattice(), ",", "\n", |v| format!("\"{}\"", comma(v))).as_bytes(),
    );
    tin_gives_the_plane(s(&p), None, d.path(), &[]);
}

/// A row with more (or fewer) fields than the header, or than the first row of a headerless
/// file, was taken silently (5 numbers under `x y z` gave x y z of the first three).
#[test]
fn rows_whose_field_count_differs_are_refused() {
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    let p = write(d.path(), "five.xyz", b"x y z\n0 0 1\n4 0 2\n0 4 3 7 9\n4 4 5\n");
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)];
    refused(&args, 3, &["five.xyz:4:", "5 fields, but the header (line 1) has 3 (x, y, z)"], &p, &out);
    let p = write(d.path(), "short.csv", b"x;y;z\r\n0;0;1\r\n4;0\r\n");
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)];
    refused(&args, 3, &["short.csv:3:", "2 fields, but the header"], &p, &out);
    let p = write(d.path(), "noheader.xyz", b"0 0 1\n4 0 2\n\n0 4 3 7\n");
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)];
    refused(&args, 3, &["noheader.xyz:4:", "4 fields, but line 1 has 3"], &p, &out);
    // the same rows with the same counts are read (extra columns of a headerless file ignored)
    let p = write(
        d.path(),
        "extra.xyz",
        text(None, &lattice(), " ", "\n", |v| v.to_string()).replace('\n', " 99\n").as_bytes(),
    );
    tin_gives_the_plane(s(&p), None, d.path(), &[]);
}

/// Numbers that could be read two ways: thousands separators (`"1.234,5"` quoted in a CSV, a
/// `"1,234"` that is 1.234 in Germany and 1234 in the US), marks that change within a file,
/// spaces between digit groups. Each is refused naming the line; `--decimal` settles `"1,234"`.
#[test]
fn thousands_separators_and_mixed_marks_are_refused() {
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    let cases: [(&str, &[u8], &[&str]); 4] = [
        (
            "t.csv",
            b"x,y,z\n\"341.000,5\",\"5.724.000,25\",\"12,5\"\n",
            &["t.csv:2:", "x = \"341.000,5\"", "thousands separator"],
        ),
        (
            "m.csv",
            b"x;y;z\n341000,5;5724000;1\n341001.5;5724000;2\n",
            &["m.csv:3:", "decimal point, but line 2 has a decimal comma (\"341000,5\")"],
        ),
        ("s.csv", b"x;y;z\n341000;5 724 000,25;1\n", &["s.csv:2:", "y = \"5 724 000,25\" is not a number"]),
        (
            "a.csv",
            b"x,y,z\n\"1,234\",2,3\n5,6,7\n",
            &["a.csv:2:", "decimal comma or a thousands separator", "--decimal"],
        ),
    ];
    for (name, content, needles) in cases {
        let p = write(d.path(), name, content);
        refused(&["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)], 3, needles, &p, &out);
    }
    // settled by --decimal: "1,234" is 1.234 (quoted decimal commas, comma separator)
    let flat: Vec<[f64; 3]> = lattice().iter().map(|p| [p[0], p[1], 1.234]).collect();
    let p =
        write(d.path(), "dec.csv", text(Some("x,y,z"), &flat, ",", "\n", |v| format!("\"{}\"", comma(v))).as_bytes());
    refused(&["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)], 3, &["dec.csv:2: z = \"1,234\""], &p, &out);
    let o = common::run(
        &["-q", "rasterize", s(&p), "--cell", "1", "--method", "tin", "-o", s(&out), "--decimal", ","],
        None,
    );
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    if gdal() {
        let c = cells(&out);
        assert!(c.len() >= 40 && c.iter().all(|c| (c.2 - 1.234).abs() < F32), "{c:?}");
    }
    std::fs::remove_file(&out).unwrap();
    // a --decimal that the text contradicts is refused, not obeyed
    let p = write(d.path(), "pt.csv", text(Some("x;y;z"), &lattice(), ";", "\n", |v| v.to_string()).as_bytes());
    let args = ["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out), "--decimal", ","];
    refused(
        &args,
        3,
        &["pt.csv:2:", "x = \"341000.5\" has a decimal point", "the decimal mark given is ','"],
        &p,
        &out,
    );
}

/// A sounding without a depth (`NaN`, empty, `inf`) is a data error naming its line, not a
/// hole and not a zero.
#[test]
fn nan_and_missing_depths_are_refused() {
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    for (name, content, needle) in [
        ("nan.csv", &b"x;y;depth\n0;0;1,5\n4;0;NaN\n"[..], "nan.csv:3: z = NaN is not a finite number"),
        ("empty.csv", b"x;y;depth\n0;0;1,5\n4;0;\n", "empty.csv:3: missing z (column 3)"),
        ("inf.xyz", b"0 0 1\n4 0 -inf\n", "inf.xyz:2: z = -inf is not a finite number"),
    ] {
        let p = write(d.path(), name, content);
        refused(&["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)], 3, &[needle], &p, &out);
    }
}

/// A `depth` column (positive down) is gridded as given, and the notice says so: the raster
/// holds depths, not elevations with the sign flipped or not.
#[test]
fn depth_columns_stay_positive_down_and_the_notice_says_so() {
    let d = common::tempdir();
    let pts: Vec<[f64; 3]> = lattice().iter().map(|p| [p[0], p[1], plane(p[0], p[1])]).collect();
    assert!(pts.iter().all(|p| p[2] > 0.0));
    let p = write(
        d.path(),
        "depth.csv",
        text(
            Some("Northing;Easting;Depth"),
            &pts.iter().map(|p| [p[1], p[0], p[2]]).collect::<Vec<_>>(),
            ";",
            "\n",
            comma,
        )
        .as_bytes(),
    );
    // columns in another order: y first; the plane check proves x and y were not swapped
    let e = tin_gives_the_plane(s(&p), None, d.path(), &[]);
    assert!(
        e.contains("x y z = columns Easting, Northing, Depth (values as given: a depth stays positive down)"),
        "{e}"
    );
}

/// Lon/lat soundings with a cell meant as metres were gridded in degrees (a 1×1 grid) with
/// exit 0 when the cell was under 1. Now a lon/lat header or a geographic `--s-srs` with a
/// metre-sized cell is refused naming the UTM zone to give as `--t-srs`; given, the grid is
/// in metres and covers the points as PROJ (gdaltransform) puts them.
#[test]
fn lon_lat_soundings_with_metre_cells() {
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    let pts: Vec<[f64; 3]> =
        (0..100).map(|k| [7.0 + 0.0001 * (k % 10) as f64, 51.5 + 0.0001 * (k / 10) as f64, 4.25]).collect();
    let p = write(d.path(), "ll.csv", text(Some("lon,lat,depth"), &pts, ",", "\n", |v| v.to_string()).as_bytes());
    let args = ["-q", "rasterize", s(&p), "--cell", "0.5", "-o", s(&out)];
    refused(
        &args,
        2,
        &["--cell 0.5", "header names longitude/latitude columns", "--s-srs EPSG:4326 --t-srs EPSG:32632"],
        &p,
        &out,
    );
    let q = write(d.path(), "plain.xyz", text(None, &pts, " ", "\n", |v| v.to_string()).as_bytes());
    let args = ["-q", "rasterize", s(&q), "--cell", "0.5", "-o", s(&out), "--s-srs", "EPSG:4326"];
    refused(&args, 2, &["geographic CRS", "--t-srs EPSG:32632 (UTM zone 32N"], &q, &out);
    // degrees meant as degrees are gridded: 10 × 10 cells of 0.0001°
    let o = common::run(&["-q", "rasterize", s(&p), "--cell", "0.0001", "-o", s(&out)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    // metres through the suggested reprojection
    let o = common::run(
        &[
            "-q",
            "rasterize",
            s(&p),
            "--cell",
            "2",
            "--method",
            "tin",
            "-o",
            s(&out),
            "--s-srs",
            "EPSG:4326",
            "--t-srs",
            "EPSG:32632",
        ],
        None,
    );
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    if !gdal() || !common::tool("gdaltransform") {
        return;
    }
    let info = gdalinfo(&out);
    assert!(info["coordinateSystem"]["wkt"].as_str().unwrap().contains("UTM zone 32N"));
    let gt: Vec<f64> = info["geoTransform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let size: Vec<f64> = info["size"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!((gt[1], gt[5]), (2.0, -2.0));
    let input: String = pts.iter().map(|p| format!("{} {}\n", p[0], p[1])).collect();
    let mut t = Command::new("gdaltransform");
    t.args(["-s_srs", "EPSG:4326", "-t_srs", "EPSG:32632"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped());
    let mut child = t.spawn().unwrap();
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), input.as_bytes()).unwrap();
    let o = child.wait_with_output().unwrap();
    let xy: Vec<(f64, f64)> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            (v[0], v[1])
        })
        .collect();
    assert_eq!(xy.len(), 100);
    for (x, y) in &xy {
        assert!(
            *x >= gt[0] && *x <= gt[0] + size[0] * gt[1] && *y <= gt[3] && *y >= gt[3] + size[1] * gt[5],
            "{x} {y} outside {gt:?} {size:?}"
        );
    }
    // ~70 m × 111 m of points on 2 m cells: a real grid, every value the depth as given
    assert!(size[0] > 25.0 && size[1] > 45.0, "{size:?}");
    assert!(cells(&out).iter().all(|c| (c.2 - 4.25).abs() < F32));
}

/// Headers that name a column twice for one axis (`lon,lat,x,y,z`: degrees or metres?) or
/// name some axes but not all (the first three columns were taken: ID, Easting, Northing), a
/// separator that cannot be told, `--sep`/`--decimal` on a LAS file and an unknown `--sep`.
#[test]
fn ambiguous_headers_and_options_are_refused() {
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    let p = write(d.path(), "two.csv", b"lon,lat,x,y,z\n7,51,341000,5724000,3\n");
    refused(
        &["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)],
        3,
        &["two.csv:1:", "2 columns for x (lon, x)"],
        &p,
        &out,
    );
    // a header that names x and y but no z (ID first: the first three columns would be wrong)
    let p = write(d.path(), "partial.csv", b"ID,Easting,Northing,Sounding\n1,341000,5724000,3\n");
    refused(
        &["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)],
        3,
        &["partial.csv:1:", "the header names no z column"],
        &p,
        &out,
    );
    let p = write(d.path(), "unnamed.txt", b"Punkt Spalte2 Spalte3 Spalte4\n1 341000 5724000 3\n");
    refused(
        &["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)],
        3,
        &["unnamed.txt:1:", "cannot tell which of the header's 4 columns"],
        &p,
        &out,
    );
    let p = write(d.path(), "mixed.xyz", b"1,2 3,4,5\n");
    refused(
        &["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out)],
        3,
        &["mixed.xyz:1:", "cannot tell the field separator", "--sep"],
        &p,
        &out,
    );
    let p = write(d.path(), "semi.csv", b"x;y;z\n0;0;1\n");
    refused(
        &["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out), "--sep", ","],
        3,
        &["semi.csv:1:", "1 field(s) split by ','"],
        &p,
        &out,
    );
    let o = common::run(&["-q", "rasterize", s(&p), "--cell", "1", "-o", s(&out), "--sep", "|"], None);
    assert_eq!(common::code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("--sep") && !out.exists());
    if let Some(las) = common::fixture("terrain/lidR_Topography.laz") {
        refused(
            &["-q", "rasterize", s(&las), "--cell", "2", "-o", s(&out), "--decimal", ","],
            2,
            &["--sep and --decimal are for XYZ/CSV text"],
            &las,
            &out,
        );
    }
}

/// The GMT fixture (tab-separated columns padded with blanks) still reads as before: the point
/// count matches the lines of three numbers, and the notice says tabs were detected.
#[test]
fn gmt_tab_padded_columns_read_as_before() {
    let Some(ship) = common::fixture("terrain/gmt_ship_03.txt") else { return };
    let lines = std::fs::read_to_string(&ship).unwrap();
    let n = lines.lines().filter(|l| l.split_whitespace().count() == 3).count();
    let d = common::tempdir();
    let out = d.path().join("o.tif");
    let o = common::run(&["rasterize", s(&ship), "--cell", "0.05", "-o", s(&out)], None);
    let e = stderr(&o);
    assert_eq!(common::code(&o), 0, "{e}");
    assert!(
        e.contains(&format!("read {n} points from")) && e.contains("tabs separated (detected), decimal point"),
        "{e}"
    );
}
