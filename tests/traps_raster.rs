//! Traps (issue 41): traps_raster. Rasters as surveyors send them: heights in km, US survey
//! feet, cm or a unit nobody knows; a 4-band Terrain-RGB PNG; a `--like` grid with no-data
//! holes; a directory, an empty file or a raster where a T-mesh belongs; south-up and rotated
//! grids. Each trap is built here (the values written as an ESRI ASCII grid by this file, the
//! unit declared in GDAL's .aux.xml, converted by gdal_translate), and each check is either
//! GDAL's reading of geofit's output against the values this file wrote (converted to metres
//! here), or a refusal: exit 2/3, one stderr line, no file at `-o`, the input unchanged.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Metres per US survey foot.
const US_FT: f64 = 1200.0 / 3937.0;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs a GDAL command-line tool; panics with its stderr when it fails.
fn gdal(tool: &str, args: &[&str]) {
    let o = Command::new(tool).args(args).output().unwrap_or_else(|e| panic!("{tool}: {e}"));
    assert!(o.status.success(), "{tool} {args:?}: {}", stderr(&o));
}

fn have_gdal() -> bool {
    common::tool("gdal_translate") && common::tool("gdalinfo")
}

/// A smooth test surface in metres: 120 m ± 80 m of hills and a tilt.
fn surface_m(col: usize, row: usize) -> f64 {
    120.0 + 80.0 * (col as f64 / 9.0).sin() * (row as f64 / 7.0).cos() + 0.3 * col as f64
}

/// Writes an ESRI ASCII grid (rows from the top; NaN = -9999) and, with `unit`, the
/// `.aux.xml` that gives band 1 that unit type.
fn write_asc(path: &Path, w: usize, h: usize, cell: f64, values: &[f64], unit: Option<&str>) {
    let mut t =
        format!("ncols {w}\nnrows {h}\nxllcorner 500000\nyllcorner 5700000\ncellsize {cell}\nNODATA_value -9999\n");
    for row in 0..h {
        let line: Vec<String> = (0..w)
            .map(|c| values[row * w + c])
            .map(|v| if v.is_nan() { "-9999".into() } else { format!("{v:.17e}") })
            .collect();
        t.push_str(&line.join(" "));
        t.push('\n');
    }
    std::fs::write(path, t).unwrap();
    if let Some(u) = unit {
        let aux =
            format!("<PAMDataset><PAMRasterBand band=\"1\"><UnitType>{u}</UnitType></PAMRasterBand></PAMDataset>\n");
        std::fs::write(format!("{}.aux.xml", path.display()), aux).unwrap();
    }
}

/// A GeoTIFF of the surface in `unit` (metres divided by `metres_per_unit`), EPSG:25832, made by
/// gdal_translate from the ASCII grid (it carries the unit type into the GeoTIFF).
fn surface_tif(dir: &Path, name: &str, unit: Option<&str>, metres_per_unit: f64, holes: bool) -> (PathBuf, Vec<f64>) {
    let (w, h) = (60, 50);
    let mut v: Vec<f64> = (0..w * h).map(|q| surface_m(q % w, q / w) / metres_per_unit).collect();
    if holes {
        for (q, z) in v.iter_mut().enumerate() {
            let (c, r) = (q % w, q / w);
            if (20..30).contains(&c) && (10..22).contains(&r) || c + r < 8 {
                *z = f64::NAN;
            }
        }
    }
    let asc = dir.join(format!("{name}.asc"));
    write_asc(&asc, w, h, 10.0, &v, unit);
    let tif = dir.join(format!("{name}.tif"));
    gdal(
        "gdal_translate",
        &["-q", "-oo", "DATATYPE=Float64", "-ot", "Float64", "-a_srs", "EPSG:25832", s(&asc), s(&tif)],
    );
    (tif, v)
}

/// Band 1 of any raster as GDAL reads it: (width, height, values with NaN for no data, the
/// nodata marker), through gdal_translate to an ASCII grid.
fn read_back(path: &Path) -> (usize, usize, Vec<f64>, Option<f64>) {
    let dir = common::tempdir();
    let asc = dir.path().join("back.asc");
    gdal("gdal_translate", &["-q", "-b", "1", "-of", "AAIGrid", "-co", "SIGNIFICANT_DIGITS=17", s(path), s(&asc)]);
    let text = std::fs::read_to_string(&asc).unwrap();
    let (mut w, mut h, mut nodata, mut values) = (0, 0, None, Vec::new());
    for line in text.lines() {
        let mut f = line.split_whitespace();
        let Some(first) = f.next() else { continue };
        match first.to_ascii_lowercase().as_str() {
            "ncols" => w = f.next().unwrap().parse().unwrap(),
            "nrows" => h = f.next().unwrap().parse().unwrap(),
            "nodata_value" => nodata = Some(f.next().unwrap().parse::<f64>().unwrap()),
            "xllcorner" | "yllcorner" | "cellsize" | "dx" | "dy" | "xllcenter" | "yllcenter" => {}
            _ => values.extend(line.split_whitespace().map(|v| v.parse::<f64>().unwrap())),
        }
    }
    assert_eq!(values.len(), w * h, "{}", path.display());
    let values = values.into_iter().map(|v| if Some(v) == nodata { f64::NAN } else { v }).collect();
    (w, h, values, nodata)
}

/// Fits `input` with `args`, evaluates the mesh on the input's grid (`eval --like`) and returns
/// the largest |evaluated − truth| in metres over the cells `truth_m` has, with the report.
fn fit_error_m(
    dir: &Path,
    input: &Path,
    args: &[&str],
    truth_m: &[f64],
    metres_per_unit: f64,
) -> (f64, serde_json::Value, String) {
    let mesh = dir.join("m.tmesh");
    let rep = dir.join("fit.json");
    let mut a = vec!["fit", s(input), "--device", "cpu", "-o", s(&mesh), "--report", s(&rep)];
    a.extend_from_slice(args);
    let o = common::run(&a, None);
    let err = stderr(&o);
    assert_eq!(common::code(&o), 0, "{a:?}: {err}");
    let ev = dir.join("ev.tif");
    let o = common::run(&["-q", "eval", s(&mesh), "--device", "cpu", "--like", s(input), "-o", s(&ev)], None);
    assert_eq!(common::code(&o), 0, "eval: {}", stderr(&o));
    let (_, _, got, _) = read_back(&ev);
    let mut worst: f64 = 0.0;
    for (g, t) in got.iter().zip(truth_m) {
        if !t.is_nan() {
            assert!(!g.is_nan(), "a cell with data has no evaluated value");
            worst = worst.max((g * metres_per_unit - t).abs());
        }
    }
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&rep).unwrap()).unwrap();
    (worst, report, err)
}

/// The refusal rule (see [`common::refused`]): `input` unchanged, nothing at `out`.
#[track_caller]
fn assert_refused(args: &[&str], code: i32, needles: &[&str], input: &Path, out: &Path) {
    common::refused(args, None, code, needles, Some(out), &[input]);
}

/// The issue's case: a band in km fitted with --max-error 10 read it as 10 km. Now 0.5 m is
/// 0.0005 km, and GDAL's reading of the evaluated surface, in metres, is within 0.5 m of the
/// surface this test wrote; the report and the stage line state both units.
#[test]
fn a_band_in_km_is_fitted_to_a_tolerance_in_metres() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (tif, v) = surface_tif(d.path(), "km", Some("km"), 1000.0, false);
    let truth: Vec<f64> = v.iter().map(|z| z * 1000.0).collect();
    let (worst, rep, err) = fit_error_m(d.path(), &tif, &["--max-error", "0.5"], &truth, 1000.0);
    assert!(worst <= 0.5 + 1e-6, "max |dz| {worst} m over the 0.5 m tolerance");
    assert_eq!(rep["z_unit"], "km");
    assert_eq!(rep["units"]["max_error"], "km");
    assert_eq!(rep["units"]["max_error_given"], "m");
    assert_eq!(rep["max_error_given"], 0.5);
    assert!((rep["max_error"].as_f64().unwrap() - 0.0005).abs() < 1e-15, "{}", rep["max_error"]);
    assert!(err.contains("heights in km") && err.contains("0.0005 km"), "{err}");
}

/// US survey feet (the spelling GDAL uses for EPSG unit 9003), --max-error 0.3 m.
#[test]
fn a_band_in_us_survey_feet_is_fitted_to_a_tolerance_in_metres() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (tif, v) = surface_tif(d.path(), "usft", Some("US survey foot"), US_FT, false);
    let truth: Vec<f64> = v.iter().map(|z| z * US_FT).collect();
    let (worst, rep, _) = fit_error_m(d.path(), &tif, &["--max-error", "0.3"], &truth, US_FT);
    assert!(worst <= 0.3 + 1e-6, "max |dz| {worst} m over 0.3 m");
    assert_eq!(rep["z_unit"], "us-ft");
    assert!((rep["max_error"].as_f64().unwrap() - 0.3 / US_FT).abs() < 1e-12);
}

/// Centimetres: the tolerance grows 100-fold in the data's numbers; read as cm it is not
/// 0.2 cm (a needless, huge mesh) but 20 cm. --error-unit cm gives the same fit.
#[test]
fn a_band_in_cm_is_fitted_to_a_tolerance_in_metres() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (tif, v) = surface_tif(d.path(), "cm", Some("cm"), 0.01, true);
    let truth: Vec<f64> = v.iter().map(|z| z * 0.01).collect();
    let (worst, rep, _) = fit_error_m(d.path(), &tif, &["--max-error", "0.2"], &truth, 0.01);
    assert!(worst <= 0.2 + 1e-6, "max |dz| {worst} m over 0.2 m");
    assert_eq!(rep["max_error"], 20.0);
    let cps = rep["control_points"].as_u64().unwrap();
    let (_, rep2, _) = fit_error_m(d.path(), &tif, &["--max-error", "20", "--error-unit", "cm"], &truth, 0.01);
    assert_eq!(rep2["max_error"], 20.0);
    assert_eq!(rep2["control_points"].as_u64().unwrap(), cps);
}

/// A file that declares nothing, told by --z-unit ft that its heights are in feet.
#[test]
fn z_unit_declares_feet_for_a_file_that_says_nothing() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (tif, v) = surface_tif(d.path(), "ft", None, 0.3048, false);
    let truth: Vec<f64> = v.iter().map(|z| z * 0.3048).collect();
    let (worst, rep, _) = fit_error_m(d.path(), &tif, &["--max-error", "0.25", "--z-unit", "feet"], &truth, 0.3048);
    assert!(worst <= 0.25 + 1e-6, "max |dz| {worst} m over 0.25 m");
    assert_eq!(rep["z_unit"], "ft");
}

/// An unknown unit, a CRS in feet whose band says nothing, and a --z-unit nobody knows: each
/// refused in one line naming the unit and --z-unit, nothing written.
#[test]
fn unknown_or_missing_units_are_refused_not_guessed() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let out = d.path().join("out.tmesh");
    let (furlong, _) = surface_tif(d.path(), "furlong", Some("furlong"), 201.168, false);
    let fit = |input: &Path, extra: &[&str]| {
        let mut a = vec![
            "fit".to_string(),
            s(input).to_string(),
            "--max-error".into(),
            "1".into(),
            "-o".into(),
            s(&out).to_string(),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    let args = fit(&furlong, &[]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_refused(&args, 3, &["furlong", "--z-unit", "furlong.tif"], &furlong, &out);
    // a --z-unit geofit does not know is a usage error
    let args = fit(&furlong, &["--z-unit", "cubits"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_refused(&args, 2, &["cubits", "--z-unit"], &furlong, &out);
    // x/y in US survey feet (EPSG:2240) and no z unit: the heights may be in either
    let asc = d.path().join("sp.asc");
    write_asc(&asc, 10, 10, 30.0, &vec![5.0; 100], None);
    let sp = d.path().join("stateplane.tif");
    gdal("gdal_translate", &["-q", "-a_srs", "EPSG:2240", s(&asc), s(&sp)]);
    let args = fit(&sp, &[]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_refused(&args, 3, &["--z-unit", "stateplane.tif", "foot"], &sp, &out);
    // `info` says what the band declares
    let o = common::run(&["info", s(&furlong)], None);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("z unit:       furlong"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let o = common::run(&["info", "--json", s(&furlong)], None);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["z_unit"], "furlong");
}

/// A 4-band Terrain-RGB PNG (R, G, B, alpha) built from four ASCII grids.
fn terrain_rgb_png(dir: &Path) -> PathBuf {
    let (w, h) = (24, 20);
    let mut paths = Vec::new();
    for (i, name) in ["r", "g", "b", "a"].iter().enumerate() {
        let v: Vec<f64> = (0..w * h)
            .map(|q| if i == 3 { 255.0 } else { ((q % w) * 5 + (q / w) * 3 + i * 40) as f64 % 256.0 })
            .collect();
        let p = dir.join(format!("{name}.asc"));
        write_asc(&p, w, h, 1.0, &v, None);
        paths.push(p);
    }
    let vrt = dir.join("rgba.vrt");
    let mut a = vec!["-q", "-separate", s(&vrt)];
    a.extend(paths.iter().map(|p| s(p)));
    gdal("gdalbuildvrt", &a);
    let png = dir.join("terrain-rgb.png");
    gdal("gdal_translate", &["-q", "-ot", "Byte", "-a_nodata", "none", "-of", "PNG", s(&vrt), s(&png)]);
    png
}

/// A multi-band raster without -b is refused naming the band count (it was fitted as its red
/// band, exit 0); -b 1 fits band 1, which GDAL reads back as the same values; -b 5 is refused.
#[test]
fn a_four_band_png_needs_a_band() {
    if !have_gdal() || !common::tool("gdalbuildvrt") {
        return;
    }
    let d = common::tempdir();
    let png = terrain_rgb_png(d.path());
    let out = d.path().join("out.tmesh");
    assert_refused(
        &["fit", s(&png), "--max-error", "1", "-o", s(&out)],
        2,
        &["terrain-rgb.png", "4 bands", "-b"],
        &png,
        &out,
    );
    assert_refused(&["fit", s(&png), "-b", "5", "--max-error", "1", "-o", s(&out)], 2, &["-b 5", "4 band"], &png, &out);
    let tif = d.path().join("w.tif");
    for cmd in [vec!["warp", s(&png), "-o", s(&tif)], vec!["diff", s(&png), s(&png)]] {
        assert_refused(&cmd, 2, &["4 bands"], &png, &tif);
    }
    let (_, _, red, _) = read_back(&png);
    let (worst, _, _) = fit_error_m(d.path(), &png, &["-b", "1", "--max-error", "0.5", "--degree", "1"], &red, 1.0);
    assert!(worst <= 0.5 + 1e-9, "band 1: max |dz| {worst}");
}

/// `--terrain-rgb` decodes Mapbox Terrain-RGB heights (h = -10000 + (R·65536 + G·256 + B)·0.1 m):
/// the fit is within --max-error of the heights this test encoded, not of the red band.
#[test]
fn terrain_rgb_is_decoded() {
    if !have_gdal() || !common::tool("gdalbuildvrt") {
        return;
    }
    let d = common::tempdir();
    let (w, h) = (40, 32);
    let code: Vec<u32> = (0..w * h).map(|q| ((surface_m(q % w, q / w) + 10000.0) * 10.0).round() as u32).collect();
    let truth: Vec<f64> = code.iter().map(|&v| -10000.0 + v as f64 * 0.1).collect();
    let mut paths = Vec::new();
    for (name, f) in [("r", 0u32), ("g", 1), ("b", 2), ("a", 3)] {
        let v: Vec<f64> = code.iter().map(|&c| [c >> 16, (c >> 8) & 255, c & 255, 255][f as usize] as f64).collect();
        let p = d.path().join(format!("{name}.asc"));
        write_asc(&p, w, h, 1.0, &v, None);
        paths.push(p);
    }
    let vrt = d.path().join("rgba.vrt");
    let mut a = vec!["-q", "-separate", s(&vrt)];
    a.extend(paths.iter().map(|p| s(p)));
    gdal("gdalbuildvrt", &a);
    let png = d.path().join("tile.png");
    gdal("gdal_translate", &["-q", "-ot", "Byte", "-a_nodata", "none", "-of", "PNG", s(&vrt), s(&png)]);
    let (worst, rep, _) = fit_error_m(d.path(), &png, &["--terrain-rgb", "--max-error", "0.3"], &truth, 1.0);
    assert!(worst <= 0.3 + 1e-6, "max |dz| {worst} m over 0.3 m");
    assert_eq!(rep["z_unit"], "m");
}

/// `eval --like` keeps the like-raster's no-data cells as no data, with its nodata marker (every
/// one got a value: phantom shoals); --fill evaluates them.
#[test]
fn eval_like_keeps_the_no_data_cells() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (tif, v) = surface_tif(d.path(), "holes", None, 1.0, true);
    let mesh = d.path().join("h.tmesh");
    let o = common::run(&["-q", "fit", s(&tif), "--max-error", "0.5", "--device", "cpu", "-o", s(&mesh)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let ev = d.path().join("ev.tif");
    let o = common::run(&["-q", "eval", s(&mesh), "--device", "cpu", "--like", s(&tif), "-o", s(&ev)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let (_, _, got, nodata) = read_back(&ev);
    assert_eq!(nodata, Some(-9999.0), "the like-raster's marker");
    let holes = v.iter().filter(|z| z.is_nan()).count();
    assert!(holes > 100);
    for (q, (g, t)) in got.iter().zip(&v).enumerate() {
        assert_eq!(g.is_nan(), t.is_nan(), "cell {q}: no data in the like-raster iff no data in the output");
        if !t.is_nan() {
            assert!((g - t).abs() <= 0.5 + 1e-6, "cell {q}: {g} vs {t}");
        }
    }
    let filled = d.path().join("filled.tif");
    let o =
        common::run(&["-q", "eval", s(&mesh), "--device", "cpu", "--like", s(&tif), "--fill", "-o", s(&filled)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let (_, _, got, _) = read_back(&filled);
    assert!(got.iter().all(|g| !g.is_nan()), "--fill: every cell inside the mesh has a value");
}

/// `fit DIR`, `fit empty.tif`, `fit x.gml`, `eval grid.tif`: one line saying what the file is
/// and which command takes it (was "GDAL call GDALOpenEx failed", "cannot decode input using UTF-8").
#[test]
fn wrong_file_kinds_are_named() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let out = d.path().join("out.tmesh");
    let dir = d.path().join("survey");
    std::fs::create_dir(&dir).unwrap();
    let o = common::run(&["fit", s(&dir), "--max-error", "1", "-o", s(&out)], None);
    let e = stderr(&o);
    assert_eq!((common::code(&o), e.trim_end().lines().count()), (3, 1), "{e}");
    assert!(e.contains("survey") && e.contains("is a directory") && !e.contains("GDALOpenEx"), "{e}");
    assert!(!out.exists());
    let empty = d.path().join("empty.tif");
    std::fs::write(&empty, b"").unwrap();
    assert_refused(&["fit", s(&empty), "--max-error", "1", "-o", s(&out)], 3, &["empty.tif", "empty"], &empty, &out);
    let gml = d.path().join("city.gml");
    std::fs::write(&gml, "<?xml version=\"1.0\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\"></core:CityModel>\n").unwrap();
    assert_refused(&["fit", s(&gml), "--max-error", "1", "-o", s(&out)], 3, &["city.gml", "CityGML"], &gml, &out);
    let xyz = d.path().join("soundings.txt");
    std::fs::write(&xyz, "x y z\n500000.5 5700000.2 -12.5\n500003.1 5700007.9 -12.9\n500011.0 5700001.4 -13.2\n")
        .unwrap();
    assert_refused(
        &["fit", s(&xyz), "--max-error", "1", "-o", s(&out)],
        3,
        &["soundings.txt", "rasterize"],
        &xyz,
        &out,
    );
    let (tif, _) = surface_tif(d.path(), "grid", None, 1.0, false);
    let ev = d.path().join("ev.tif");
    assert_refused(&["eval", s(&tif), "-o", s(&ev)], 3, &["grid.tif", "raster", "T-mesh", "fit"], &tif, &ev);
}

/// A south-up raster (positive y pixel size) fits and evaluates onto its own cells; a rotated
/// geotransform is refused in one line naming gdalwarp (it was exit 1, a "finding").
#[test]
fn south_up_fits_and_rotated_is_refused() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (w, h) = (40, 30);
    let v: Vec<f64> = (0..w * h).map(|q| surface_m(q % w, q / w)).collect();
    let asc = d.path().join("s.asc");
    write_asc(&asc, w, h, 5.0, &v, None);
    let south = d.path().join("south.tif");
    // upper-left y below lower-right y: GDAL stores a positive y pixel size (row 0 is the south)
    gdal(
        "gdal_translate",
        &["-q", "-a_srs", "EPSG:25832", "-a_ullr", "500000", "5700000", "500200", "5700150", s(&asc), s(&south)],
    );
    let info = Command::new("gdalinfo").args(["-json", s(&south)]).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert!(j["geoTransform"][5].as_f64().unwrap() > 0.0, "south-up: {}", j["geoTransform"]);
    // GDAL's reading of the input, in the order it reads the output (an ASCII grid is north-up)
    let (_, _, truth, _) = read_back(&south);
    let (worst, _, _) = fit_error_m(d.path(), &south, &["--max-error", "0.2"], &truth, 1.0);
    assert!(worst <= 0.2 + 1e-6, "south-up: max |dz| {worst}");
    let rot = d.path().join("rot.vrt");
    let vrt = format!(
        "<VRTDataset rasterXSize=\"{w}\" rasterYSize=\"{h}\"><GeoTransform>500000, 4.33, 2.5, 5700150, 2.5, -4.33</GeoTransform>\
         <VRTRasterBand dataType=\"Float64\" band=\"1\"><SimpleSource><SourceFilename relativeToVRT=\"1\">s.asc</SourceFilename>\
         <SourceBand>1</SourceBand></SimpleSource></VRTRasterBand></VRTDataset>"
    );
    std::fs::write(&rot, vrt).unwrap();
    let out = d.path().join("rot.tmesh");
    assert_refused(
        &["fit", s(&rot), "--max-error", "1", "-o", s(&out)],
        3,
        &["rot.vrt", "rotated", "gdalwarp"],
        &rot,
        &out,
    );
}

/// Lengths in the CRS's units are not applied to degrees: warp --spacing on a geographic raster
/// is refused; without it the default (in cells) applies.
#[test]
fn horizontal_lengths_are_not_applied_to_degrees() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let asc = d.path().join("g.asc");
    let (w, h) = (40, 30);
    write_asc(&asc, w, h, 1.0, &(0..w * h).map(|q| surface_m(q % w, q / w)).collect::<Vec<_>>(), None);
    let geo = d.path().join("geo.tif");
    gdal("gdal_translate", &["-q", "-a_srs", "EPSG:4326", "-a_ullr", "7.0", "51.3", "7.04", "51.27", s(&asc), s(&geo)]);
    let out = d.path().join("w.tif");
    assert_refused(&["warp", s(&geo), "--spacing", "50", "-o", s(&out)], 2, &["--spacing", "degrees"], &geo, &out);
}

/// The blunder lines and CSV show the prediction the test compared: every listed deviation is
/// over K × the tolerance (47 of 4,040 were under it, printed from the median prediction). The
/// trap: a cell of 10 on flat ground whose diagonal neighbours are 20 has the local predictions
/// 0, 0, 20, 20, whose median (10) is the cell's value: deviation 0, yet every prediction is
/// 10 off it (the test's verdict).
#[test]
fn blunder_deviations_are_the_ones_the_test_used() {
    let d = common::tempdir();
    let (w, h) = (30, 30);
    let mut v = vec![0.0; w * h];
    for (row, col) in [(10usize, 10usize), (20, 18)] {
        v[row * w + col] = 10.0;
        for (dr, dc) in [(-1isize, -1isize), (-1, 1), (1, -1), (1, 1)] {
            v[(row as isize + dr) as usize * w + (col as isize + dc) as usize] = 20.0;
        }
    }
    let asc = d.path().join("spikes.asc");
    write_asc(&asc, w, h, 10.0, &v, None);
    let csv = d.path().join("b.csv");
    let o = common::run(
        &[
            "fit",
            s(&asc),
            "--max-error",
            "0.5",
            "--device",
            "cpu",
            "--outliers-csv",
            s(&csv),
            "-o",
            s(&d.path().join("m.tmesh")),
        ],
        None,
    );
    assert!(matches!(common::code(&o), 0 | 1), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert!(rows.iter().any(|r| r.starts_with("10,10,")), "the centre cell is found: {text}");
    for r in rows {
        let f: Vec<f64> = r.split(',').take(7).map(|x| x.parse().unwrap()).collect();
        let (row, col, value, predicted, deviation) = (f[0] as usize, f[1] as usize, f[4], f[5], f[6]);
        assert_eq!(value, v[row * w + col], "{r}");
        assert!((deviation - (value - predicted).abs()).abs() < 1e-9, "{r}");
        assert!(deviation > 10.0 * 0.5, "{r}: deviation under K × tolerance");
    }
    let e = stderr(&o);
    assert!(e.contains("row 10, col 10") && e.contains("10 where the nearest local prediction is 0.000000"), "{e}");
}

/// `diff` of a raster in km against one in m compares like with like (B converted into A's
/// unit, stated), and `info` prints the unit.
#[test]
fn diff_converts_declared_units_and_info_prints_them() {
    if !have_gdal() {
        return;
    }
    let d = common::tempdir();
    let (km, _) = surface_tif(d.path(), "a_km", Some("km"), 1000.0, false);
    let (m, _) = surface_tif(d.path(), "b_m", Some("metre"), 1.0, false);
    let o = common::run(&["diff", s(&km), s(&m), "--json"], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["units"]["max_abs"], "km");
    assert!(j["max_abs"].as_f64().unwrap() < 1e-9, "{}", j["max_abs"]);
    let o = common::run(&["info", s(&km)], None);
    assert!(String::from_utf8_lossy(&o.stdout).contains("z unit:       km"), "{}", String::from_utf8_lossy(&o.stdout));
}
