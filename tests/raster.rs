//! End-to-end tests of the raster side of the terrain work: reading every terrain fixture
//! against gdalinfo/gdal_translate + numpy, TIN rasterization against `gdal_grid -a linear`,
//! LAZ ground-class rasterization, warp → unwarp, `diff` against numpy, and bad input.

mod common;

use std::path::{Path, PathBuf};

use serde_json::Value;

fn script(name: &str) -> PathBuf {
    common::repo_root().join("tests/scripts").join(name)
}

fn python_json(args: &[&str]) -> Value {
    let out = common::python().args(args).output().expect("python3");
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("script JSON")
}

fn ok(args: &[&str]) -> std::process::Output {
    let o = common::run(args, None);
    assert_eq!(common::code(&o), 0, "geofit {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    o
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn tools() -> bool {
    common::tool("gdalinfo") && common::tool("gdal_translate") && common::tool("python3")
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// Every raster in the terrain fixtures reads with gdalinfo's size, geotransform and nodata
/// marker, numpy's nodata count (from gdal_translate's XYZ dump) and the same min/max/mean.
#[test]
fn terrain_fixtures_read_like_gdal() {
    let Some(dir) = common::fixture("terrain") else { return };
    if !tools() {
        return;
    }
    let mut rasters: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("nc" | "tiff" | "tif" | "asc")))
        .collect();
    rasters.sort();
    assert!(rasters.len() >= 7, "{rasters:?}");
    for p in &rasters {
        let truth = python_json(&[script("raster_gdal_truth.py").to_str().unwrap(), p.to_str().unwrap()]);
        let r = raster_io::read_raster(p).unwrap_or_else(|e| panic!("{e}"));
        let name = p.file_name().unwrap().to_string_lossy();
        assert_eq!(r.width as u64, truth["width"].as_u64().unwrap(), "{name} width");
        assert_eq!(r.height as u64, truth["height"].as_u64().unwrap(), "{name} height");
        let gt: Vec<f64> = truth["geotransform"].as_array().unwrap().iter().map(f).collect();
        for k in 0..6 {
            assert!(
                (r.geotransform[k] - gt[k]).abs() <= 1e-12 * gt[k].abs().max(1.0),
                "{name} gt[{k}] {} vs {}",
                r.geotransform[k],
                gt[k]
            );
        }
        assert_eq!(r.nodata_count() as u64, truth["nodata_count"].as_u64().unwrap(), "{name} nodata count");
        // gdalinfo -json prints a Float32 marker with 7 significant digits (-3.402823e+38 for
        // f32::MIN): compare at single precision, the precision of such a band.
        let same = match (r.nodata, truth["nodata"].as_f64()) {
            (Some(a), Some(b)) => a == b || (a as f32) == (b as f32) || (a.is_nan() && b.is_nan()),
            (a, b) => a == b,
        };
        assert!(same, "{name} nodata marker: {:?} vs gdalinfo {:?}", r.nodata, truth["nodata"]);
        let (lo, hi) = r.min_max().unwrap();
        assert_eq!(lo, f(&truth["min"]), "{name} min");
        assert_eq!(hi, f(&truth["max"]), "{name} max");
        let mean = r.data.iter().filter(|d| !d.is_nan()).sum::<f64>() / r.valid_count() as f64;
        assert!(
            (mean - f(&truth["mean"])).abs() < 1e-9 * mean.abs().max(1.0),
            "{name} mean {mean} vs {}",
            truth["mean"]
        );
        // no data is NaN and nothing else: every other value is finite
        assert!(r.data.iter().all(|d| d.is_nan() || d.is_finite()), "{name} values");
        // `geofit info --json` reports the same size, geotransform and nodata count.
        let o = common::run(&["-q", "info", "--json", p.to_str().unwrap()], None);
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let info: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(info["kind"], "raster", "{name}");
        assert_eq!(info["width"], truth["width"], "{name} info width");
        assert_eq!(info["height"], truth["height"], "{name} info height");
        assert_eq!(info["nodata_count"], truth["nodata_count"], "{name} info nodata count");
        let igt: Vec<f64> = info["geotransform"].as_array().unwrap().iter().map(f).collect();
        for k in 0..6 {
            assert!(
                (igt[k] - gt[k]).abs() <= 1e-12 * gt[k].abs().max(1.0),
                "{name} info gt[{k}] {} vs {}",
                igt[k],
                gt[k]
            );
        }
    }
    // The README's count for Kilauea, as a fixed anchor.
    let k = raster_io::read_raster(&dir.join("gmt_Kilauea.utm.nc")).unwrap();
    assert_eq!((k.width, k.height, k.nodata_count()), (857, 793, 20_656));
}

/// Writes `pts` (x y z text) as CSV plus an OGR VRT and runs `gdal_grid -a linear:radius=0`
/// on the grid `report` describes; returns the path of gdal_grid's raster.
fn gdal_grid_linear(dir: &Path, points_txt: &Path, report: &Value) -> PathBuf {
    let text = std::fs::read_to_string(points_txt).unwrap();
    let mut csv = String::from("x,y,z\n");
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: Vec<&str> = line.split_whitespace().collect();
        csv.push_str(&format!("{},{},{}\n", v[0], v[1], v[2]));
    }
    std::fs::write(dir.join("pts.csv"), csv).unwrap();
    std::fs::write(
        dir.join("pts.vrt"),
        "<OGRVRTDataSource><OGRVRTLayer name=\"pts\"><SrcDataSource>pts.csv</SrcDataSource>\
<GeometryType>wkbPoint</GeometryType><GeometryField encoding=\"PointFromColumns\" x=\"x\" y=\"y\" z=\"z\"/>\
</OGRVRTLayer></OGRVRTDataSource>",
    )
    .unwrap();
    let gt: Vec<f64> = report["geotransform"].as_array().unwrap().iter().map(f).collect();
    let (w, h) = (report["width"].as_u64().unwrap(), report["height"].as_u64().unwrap());
    let (xmin, xmax) = (gt[0], gt[0] + w as f64 * gt[1]);
    let (ymax, ymin) = (gt[3], gt[3] + h as f64 * gt[5]);
    let out = dir.join("gdal_grid.tif");
    let st = std::process::Command::new("gdal_grid")
        .current_dir(dir)
        .args(["-q", "-zfield", "z", "-a", "linear:radius=0:nodata=-9999", "-ot", "Float64", "-of", "GTiff"])
        .args(["-txe", &format!("{xmin:?}"), &format!("{xmax:?}"), "-tye", &format!("{ymin:?}"), &format!("{ymax:?}")])
        .args(["-outsize", &w.to_string(), &h.to_string(), "pts.vrt", out.to_str().unwrap()])
        .status()
        .expect("gdal_grid");
    assert!(st.success());
    out
}

/// TIN-linear rasterization equals `gdal_grid -a linear:radius=0` on the same grid: both are
/// barycentric interpolation in the Delaunay triangulation of the same points, computed in
/// double precision, so the only expected differences are rounding (and a different diagonal
/// where four points are exactly cocircular, which these data sets do not hit). Tolerance:
/// 1e-9 of the z range (observed: 2e-13 for Table 5.11, 1.2e-9 m on a 5,000 m range for
/// ship_03), on every cell both fill.
#[test]
fn tin_matches_gdal_grid_linear() {
    let Some(dir) = common::fixture("terrain") else { return };
    if !tools() || !common::tool("gdal_grid") {
        return;
    }
    for (file, cell) in [("gmt_Table_5_11.txt", "0.1"), ("gmt_ship_03.txt", "0.02")] {
        let tmp = common::tempdir();
        let pts = dir.join(file);
        let ours = tmp.path().join("ours.tif");
        let rep = tmp.path().join("rep.json");
        ok(&[
            "-q",
            "rasterize",
            pts.to_str().unwrap(),
            "-o",
            ours.to_str().unwrap(),
            "--cell",
            cell,
            "--method",
            "tin",
            "--report",
            rep.to_str().unwrap(),
        ]);
        let report: Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        let theirs = gdal_grid_linear(tmp.path(), &pts, &report);
        let a = raster_io::read_raster(&theirs).unwrap();
        let b = raster_io::read_raster(&ours).unwrap();
        assert_eq!((a.width, a.height), (b.width, b.height), "{file}");
        // gdal_grid derives the pixel size as (xmax − xmin)/w: equal up to rounding
        for k in 0..6 {
            assert!(
                (a.geotransform[k] - b.geotransform[k]).abs() <= 1e-12 * a.geotransform[k].abs().max(1.0),
                "{file}: {:?} vs {:?}",
                a.geotransform,
                b.geotransform
            );
        }
        // Footprint: every cell gdal_grid fills, we fill. Along a single ship track the hull holds
        // extremely flat sliver triangles that gdal_grid's qhull triangulation drops; there we
        // fill a few extra cells (26 of 7,522 for ship_03), never more than 0.5 %.
        let (av, bv) = (a.valid_mask(), b.valid_mask());
        let missing = av.iter().zip(&bv).filter(|(x, y)| **x && !**y).count();
        let extra = av.iter().zip(&bv).filter(|(x, y)| !**x && **y).count();
        assert_eq!(missing, 0, "{file}: cells gdal_grid fills but we do not");
        assert!(extra * 200 <= b.valid_count(), "{file}: {extra} extra cells of {}", b.valid_count());
        if file == "gmt_Table_5_11.txt" {
            assert_eq!(extra, 0, "{file}: a compact point set must give the identical footprint");
        }
        assert!(b.valid_count() > 100, "{file}: {}", b.valid_count());
        let (lo, hi) = a.min_max().unwrap();
        let tol = 1e-9 * (hi - lo);
        let worst =
            a.data.iter().zip(&b.data).filter(|(x, _)| x.is_finite()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(worst <= tol, "{file}: max |ours − gdal_grid| = {worst} > {tol}");
    }
}

/// The LAZ fixture rasterizes with its ground class: 8,159 class-2 points (fixture README),
/// values within the ground points' z range, and a clear message for an absent class.
#[test]
fn laz_ground_class_rasterizes() {
    let Some(laz) = common::fixture("terrain/lidR_Topography.laz") else { return };
    let tmp = common::tempdir();
    let out = tmp.path().join("ground.tif");
    let rep = tmp.path().join("rep.json");
    ok(&[
        "-q",
        "rasterize",
        laz.to_str().unwrap(),
        "--class",
        "2",
        "-o",
        out.to_str().unwrap(),
        "--cell",
        "2",
        "--report",
        rep.to_str().unwrap(),
    ]);
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(report["points"], 8159);
    let r = raster_io::read_raster(&out).unwrap();
    // 285 m × 285 m at 2 m: about 143 × 143 cells
    assert!((140..=146).contains(&r.width) && (140..=146).contains(&r.height), "{} × {}", r.width, r.height);
    let (lo, hi) = r.min_max().unwrap();
    // weighted means of ground points stay inside their z range (README: 789..830 m, rounded)
    assert!(lo >= 788.9 && hi <= 830.0, "{lo}..{hi}");
    // the LAS 1.2 GeoTIFF-key CRS travels into the raster as WKT
    assert!(r.crs.as_deref().is_some_and(|w| w.starts_with("PROJCS") || w.starts_with("PROJCRS")), "{:?}", r.crs);
    assert!(r.valid_count() > 1000);
    let water = common::run(
        &[
            "-q",
            "rasterize",
            laz.to_str().unwrap(),
            "--class",
            "9",
            "-o",
            tmp.path().join("w.tif").to_str().unwrap(),
            "--cell",
            "2",
            "--report",
            "-",
        ],
        None,
    );
    assert_eq!(common::code(&water), 0, "{}", stderr(&water));
    let wrep: Value = serde_json::from_slice(&water.stdout).unwrap();
    assert_eq!(wrep["points"], 3897);
    let none = common::run(
        &[
            "rasterize",
            laz.to_str().unwrap(),
            "--class",
            "17",
            "-o",
            tmp.path().join("n.tif").to_str().unwrap(),
            "--cell",
            "2",
        ],
        None,
    );
    assert_eq!(common::code(&none), 3);
    let e = stderr(&none);
    assert!(e.contains("no point of class 17") && e.contains("2 (8159)"), "{e}");
}

/// Gauss splatting reproduces a constant exactly and leaves cells far from any point empty.
#[test]
fn gauss_splat_leaves_nodata_where_no_point_is_near() {
    let tmp = common::tempdir();
    let pts = tmp.path().join("p.xyz");
    // two clusters 20 m apart, z = 5 everywhere
    let mut s = String::from("x y z\n");
    for i in 0..10 {
        for j in 0..10 {
            s.push_str(&format!("{} {} 5\n", i as f64 * 0.5, j as f64 * 0.5));
            s.push_str(&format!("{} {} 5\n", 20.0 + i as f64 * 0.5, j as f64 * 0.5));
        }
    }
    std::fs::write(&pts, s).unwrap();
    for method in ["gauss", "gauss-literal", "tin"] {
        let out = tmp.path().join(format!("{method}.tif"));
        ok(&[
            "-q",
            "rasterize",
            pts.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--cell",
            "1",
            "--method",
            method,
            "--max-edge",
            "3",
        ]);
        let r = raster_io::read_raster(&out).unwrap();
        assert!(r.data.iter().filter(|v| v.is_finite()).all(|v| (v - 5.0).abs() < 1e-12), "{method}");
        // the gap between the clusters (x = 8..19) has no value
        let (px, _) = r.world_to_pixel(14.0, 2.0);
        assert!((0..r.height).all(|row| r.get(px.round() as usize, row).is_none()), "{method}");
        assert!(r.valid_count() >= 40, "{method}: {}", r.valid_count());
    }
}

fn make_synthetic(dir: &Path, args: &[&str]) {
    let out = common::python().arg(script("raster_make_synthetic.py")).args(args).current_dir(dir).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// warp → unwarp on a rotated channel: the warped raster is a full rectangle carrying its field,
/// the unwarped one has the original grid and footprint (checked with gdalinfo/numpy) and values
/// close to the original (two resamplings: RMS well under the channel's relief).
#[test]
fn warp_then_unwarp_restores_grid_and_values() {
    if !tools() {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    make_synthetic(d, &["channel", d.to_str().unwrap()]);
    let src = d.join("channel.asc");
    let warped = d.join("w.tif");
    let back = d.join("back.tif");
    let rep = d.join("warp.json");
    ok(&[
        "-q",
        "warp",
        src.to_str().unwrap(),
        "-o",
        warped.to_str().unwrap(),
        "--spacing",
        "10",
        "--report",
        rep.to_str().unwrap(),
    ]);
    let wr: Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert!((f(&wr["rotation_deg"]) + 30.0).abs() < 2.0, "{}", wr["rotation_deg"]);
    let wt = python_json(&[script("raster_gdal_truth.py").to_str().unwrap(), warped.to_str().unwrap()]);
    assert_eq!(wt["nodata_count"], 0, "the warped raster is filled");
    // the field is inside the output's metadata, readable by GDAL itself
    let md = std::process::Command::new("gdalinfo").args(["-json", warped.to_str().unwrap()]).output().unwrap();
    let md: Value = serde_json::from_slice(&md.stdout).unwrap();
    let field = md["metadata"][""]["GEOFIT_WARP_FIELD"].as_str().expect("field in metadata");
    assert!(field.contains("\"triangles\""));
    // rotation removed most of the overhang: the warped rectangle is smaller than the source
    let st = python_json(&[script("raster_gdal_truth.py").to_str().unwrap(), src.to_str().unwrap()]);
    let cells = |v: &Value| v["width"].as_u64().unwrap() * v["height"].as_u64().unwrap();
    assert!(cells(&wt) < cells(&st), "{} ≥ {}", cells(&wt), cells(&st));

    ok(&["-q", "unwarp", warped.to_str().unwrap(), "-o", back.to_str().unwrap()]);
    let bt = python_json(&[script("raster_gdal_truth.py").to_str().unwrap(), back.to_str().unwrap()]);
    assert_eq!(bt["width"], st["width"]);
    assert_eq!(bt["height"], st["height"]);
    assert_eq!(bt["geotransform"], st["geotransform"]);
    assert_eq!(bt["nodata_count"], st["nodata_count"]);
    let truth = python_json(&[
        script("raster_diff_truth.py").to_str().unwrap(),
        src.to_str().unwrap(),
        back.to_str().unwrap(),
        "1",
        "0.1,1",
    ]);
    assert_eq!(truth["only_in_a"], 0);
    assert_eq!(truth["only_in_b"], 0);
    assert!(f(&truth["rms"]) < 0.25, "RMS after warp+unwarp {}", truth["rms"]);

    // points: original → warped → original within 1e-6 of a cell (cell = 1 m here)
    let mut pts = String::new();
    let mut seed = 99u64;
    let mut orig = Vec::new();
    for _ in 0..5000 {
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (x, y) = (500000.0 - 20.0 + 280.0 * next(), 5700000.0 - 20.0 + 220.0 * next());
        pts.push_str(&format!("{x:?} {y:?} 1.5\n"));
        orig.push((x, y));
    }
    let p0 = d.join("p0.xyz");
    let p1 = d.join("p1.xyz");
    let p2 = d.join("p2.xyz");
    std::fs::write(&p0, pts).unwrap();
    ok(&[
        "-q",
        "unwarp",
        warped.to_str().unwrap(),
        "--points",
        p0.to_str().unwrap(),
        "--forward",
        "-o",
        p1.to_str().unwrap(),
    ]);
    ok(&["-q", "unwarp", warped.to_str().unwrap(), "--points", p1.to_str().unwrap(), "-o", p2.to_str().unwrap()]);
    let read = |p: &Path| -> Vec<(f64, f64, f64)> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .map(|l| {
                let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
                (v[0], v[1], v[2])
            })
            .collect()
    };
    let (fwd, back) = (read(&p1), read(&p2));
    assert_eq!(back.len(), 5000);
    let moved = orig.iter().zip(&fwd).filter(|(o, f)| (o.0 - f.0).hypot(o.1 - f.1) > 1.0).count();
    assert!(moved > 2500, "the warp moves points ({moved} of 5000 by more than a cell)");
    let worst = orig.iter().zip(&back).map(|(o, b)| (o.0 - b.0).hypot(o.1 - b.1)).fold(0.0, f64::max);
    assert!(worst < 1e-6, "round trip error {worst} cells");
    assert!(back.iter().all(|b| b.2 == 1.5));

    // the field needs GeoTIFF metadata: other output formats are refused before any work
    let o = common::run(&["warp", src.to_str().unwrap(), "-o", d.join("w.asc").to_str().unwrap()], None);
    assert_eq!(common::code(&o), 2);
    assert!(stderr(&o).contains("needs a GeoTIFF output"), "{}", stderr(&o));
    // unwarp needs the field: a plain raster is refused with a clear message
    let o = common::run(&["unwarp", src.to_str().unwrap(), "-o", d.join("x.tif").to_str().unwrap()], None);
    assert_eq!(common::code(&o), 3);
    assert!(stderr(&o).contains("not a raster written by `geofit warp`"), "{}", stderr(&o));
}

/// `geofit diff` statistics equal numpy's on the same rasters (Kilauea and a perturbed copy).
#[test]
fn diff_statistics_match_numpy() {
    let Some(k) = common::fixture("terrain/gmt_Kilauea.utm.nc") else { return };
    if !tools() {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    let a = d.join("a.asc");
    let st = std::process::Command::new("gdal_translate")
        .args(["-q", "-of", "AAIGrid", k.to_str().unwrap(), a.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(st.success());
    let b = d.join("b.asc");
    make_synthetic(d, &["perturb", a.to_str().unwrap(), b.to_str().unwrap(), "42"]);
    let bounds = "0.01,0.02,0.05,0.1,0.2,0.5,1,2";
    let png = d.join("map.png");
    let hist = d.join("hist.png");
    let o = ok(&[
        "diff",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--tolerance",
        "0.5",
        "--classes",
        bounds,
        "--json",
        "--png",
        png.to_str().unwrap(),
        "--hist",
        hist.to_str().unwrap(),
    ]);
    let ours: Value = serde_json::from_slice(&o.stdout).unwrap();
    let truth = python_json(&[
        script("raster_diff_truth.py").to_str().unwrap(),
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "0.5",
        bounds,
    ]);
    for k in ["cells_compared", "only_in_a", "only_in_b", "over_tolerance"] {
        assert_eq!(ours[k], truth[k], "{k}");
    }
    for k in ["mean_abs", "std_abs", "median_abs", "max_abs", "rms", "mean_signed"] {
        let (x, y) = (f(&ours[k]), f(&truth[k]));
        assert!((x - y).abs() <= 1e-9 * y.abs().max(1e-3), "{k}: {x} vs numpy {y}");
    }
    let counts: Vec<Value> = ours["histogram"].as_array().unwrap().iter().map(|c| c["count"].clone()).collect();
    assert_eq!(Value::Array(counts), truth["histogram"]);
    check_error_map_picture(&a, &png, &ours, bounds.split(',').count() + 1);
    check_histogram_picture(&hist, &ours);
    // --plain: the bare map, one pixel per cell, placed exactly on A's grid
    let plain = d.join("plain.png");
    ok(&[
        "diff",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--classes",
        bounds,
        "--png",
        plain.to_str().unwrap(),
        "--plain",
    ]);
    let (w, h, _) = decode_png(&plain);
    assert_eq!((w, h), (857, 793));
    assert_eq!(
        gdal_json(&[plain.to_str().unwrap()])["geoTransform"],
        gdal_json(&[a.to_str().unwrap()])["geoTransform"]
    );
    // --check turns cells over the tolerance into exit 1
    let c = common::run(&["diff", a.to_str().unwrap(), b.to_str().unwrap(), "--tolerance", "0.5", "--check"], None);
    assert_eq!(common::code(&c), 1);
    // identical rasters: all zero, exit 0 even with --check
    let same = ok(&["diff", a.to_str().unwrap(), a.to_str().unwrap(), "--json", "--check"]);
    let s: Value = serde_json::from_slice(&same.stdout).unwrap();
    assert_eq!(f(&s["max_abs"]), 0.0);
}

/// A PNG as (width, height, RGBA8 pixels), decoded by the png crate.
fn decode_png(path: &Path) -> (usize, usize, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba, "{}", path.display());
    buf.truncate(info.buffer_size());
    (info.width as usize, info.height as usize, buf)
}

fn gdal_json(args: &[&str]) -> Value {
    let o = std::process::Command::new("gdalinfo").arg("-json").args(args).output().unwrap();
    assert!(o.status.success(), "gdalinfo {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Distinct saturated colours (not grey, opaque) among the pixels in columns `x0..` of a picture.
fn saturated_colours(w: usize, px: &[u8], x0: usize) -> std::collections::BTreeSet<[u8; 3]> {
    px.chunks(4)
        .enumerate()
        .filter(|(i, p)| i % w >= x0 && p[3] == 255 && !(p[0] == p[1] && p[1] == p[2]))
        .map(|(_, p)| [p[0], p[1], p[2]])
        .collect()
}

/// The error map: A's grid one pixel per cell inside a frame with a title and a legend; GDAL
/// places it through the world file and reads A's CRS from the .aux.xml; the pixel GDAL finds at
/// the largest error's location is that cell's (red, large-class) colour; the legend shows a
/// swatch for every class, the empty ones included.
fn check_error_map_picture(a: &Path, png: &Path, report: &Value, n_classes: usize) {
    let (w, h, px) = decode_png(png);
    let (ia, ip) = (gdal_json(&[a.to_str().unwrap()]), gdal_json(&[png.to_str().unwrap()]));
    let (ga, gp) = (ia["geoTransform"].as_array().unwrap(), ip["geoTransform"].as_array().unwrap());
    let (ga, gp): (Vec<f64>, Vec<f64>) = (ga.iter().map(f).collect(), gp.iter().map(f).collect());
    assert_eq!((gp[1], gp[5]), (ga[1], ga[5]), "pixel size");
    let (ox, oy) = ((ga[0] - gp[0]) / ga[1], (ga[3] - gp[3]) / ga[5]);
    assert!(ox.fract().abs() < 1e-6 && oy.fract().abs() < 1e-6 && ox >= 1.0 && oy >= 1.0, "map offset {ox} {oy}");
    let (ox, oy) = (ox.round() as usize, oy.round() as usize);
    let size = ia["size"].as_array().unwrap();
    let (aw, ah) = (size[0].as_u64().unwrap() as usize, size[1].as_u64().unwrap() as usize);
    assert!(ox + aw < w && oy + ah <= h, "the map lies inside the {w}×{h} picture");
    assert!(ip["coordinateSystem"]["wkt"].as_str().is_some_and(|s| s.contains("UTM zone 5N")), "CRS from the .aux.xml");
    let at = report["max_at"].as_array().unwrap();
    let (c, r) = (at[0].as_u64().unwrap() as usize, at[1].as_u64().unwrap() as usize);
    let (x, y) = (ga[0] + (c as f64 + 0.5) * ga[1], ga[3] + (r as f64 + 0.5) * ga[5]);
    let o = std::process::Command::new("gdallocationinfo")
        .args(["-valonly", "-geoloc", png.to_str().unwrap(), &x.to_string(), &y.to_string()])
        .output()
        .unwrap();
    let rgba: Vec<u8> = String::from_utf8_lossy(&o.stdout).split_whitespace().map(|v| v.parse().unwrap()).collect();
    let i = 4 * ((oy + r) * w + ox + c);
    assert_eq!(rgba, px[i..i + 4], "GDAL's pixel at the largest error");
    assert!(rgba[0] == 255 && rgba[1] < 200, "the largest error is drawn at the red end: {rgba:?}");
    let legend = saturated_colours(w, &px, ox + aw);
    assert!(legend.len() >= n_classes, "{} legend colours for {n_classes} classes", legend.len());
    let title_dark = px[..4 * w * oy].chunks(4).filter(|p| p[..3] == [0, 0, 0]).count();
    assert!(title_dark > 100, "a title above the map");
}

/// The histogram: a bar per non-empty class in its colour, heights in proportion to the shares.
fn check_histogram_picture(hist: &Path, report: &Value) {
    let (w, _, px) = decode_png(hist);
    let classes = report["histogram"].as_array().unwrap();
    let non_empty = classes.iter().filter(|c| c["count"].as_u64().unwrap() > 0).count();
    assert!(saturated_colours(w, &px, 0).len() >= non_empty);
    assert!(px.chunks(4).filter(|p| p[..3] == [0, 0, 0]).count() > 500, "axes and labels");
}

/// Bad input gets one clear line and the documented exit code; never a panic.
#[test]
fn bad_input_is_reported_clearly() {
    let tmp = common::tempdir();
    let d = tmp.path();
    let out = d.join("o.tif");
    let o_s = out.to_str().unwrap();
    let check = |args: &[&str], code: i32, needle: &str| {
        let o = common::run(args, None);
        let e = stderr(&o);
        assert_eq!(common::code(&o), code, "{args:?}: {e}");
        assert!(e.contains(needle), "{args:?}: expected {needle:?} in {e:?}");
        assert!(!e.contains("panicked"), "{e}");
        assert!(e.trim().lines().filter(|l| l.starts_with("geofit: error")).count() == 1, "{e}");
    };
    // points: NaN, inf, non-numeric, too few columns
    for (text, needle) in [
        ("1 2 3\n4 5 nan\n", "p.xyz:2: z = nan is not a finite number"),
        ("1 2 3\n4 5 6\n7 8 -inf\n", "p.xyz:3: z = -inf is not a finite number"),
        ("x y z\n1 2 3\n4 abc 6\n", "p.xyz:3: y = \"abc\" is not a number"),
        ("1 2\n", "p.xyz:1: missing z"),
        ("# only a comment\n", "no points"),
    ] {
        let p = d.join("p.xyz");
        std::fs::write(&p, text).unwrap();
        check(&["rasterize", p.to_str().unwrap(), "-o", o_s, "--cell", "1"], 3, needle);
    }
    // stdin, with the line number
    let o = common::run(&["rasterize", "-", "-o", o_s, "--cell", "1"], Some(b"0 0 1\n1 1 x\n"));
    assert_eq!(common::code(&o), 3);
    assert!(stderr(&o).contains("<stdin>:2:"), "{}", stderr(&o));
    // usage errors
    let p = d.join("ok.xyz");
    std::fs::write(&p, "0 0 1\n1 0 2\n0 1 3\n").unwrap();
    check(&["rasterize", p.to_str().unwrap(), "-o", o_s, "--cell", "0"], 2, "--cell 0 must be a positive number");
    check(&["rasterize", p.to_str().unwrap(), "-o", o_s, "--cell", "1", "--radius", "0.1"], 2, "radius");
    check(&["rasterize", p.to_str().unwrap(), "-o", o_s, "--cell", "1e-9"], 2, "too large");
    check(&["rasterize", p.to_str().unwrap(), "-o", o_s, "--cell", "1", "--class", "2"], 3, "needs a LAS/LAZ file");
    // corrupt and unsupported files
    let bad = d.join("bad.tif");
    std::fs::write(&bad, b"II*\0garbage that is not a TIFF").unwrap();
    for cmd in
        [&["diff", bad.to_str().unwrap(), bad.to_str().unwrap()][..], &["warp", bad.to_str().unwrap(), "-o", o_s][..]]
    {
        check(cmd, 3, "bad.tif");
    }
    let txt = d.join("notes.txt");
    std::fs::write(&txt, "hello\n").unwrap();
    check(&["warp", txt.to_str().unwrap(), "-o", o_s], 3, "notes.txt");
    check(&["diff", d.join("missing.tif").to_str().unwrap(), txt.to_str().unwrap()], 3, "missing.tif: no such file");
    let laz = d.join("bad.laz");
    std::fs::write(&laz, b"LASF but truncated").unwrap();
    check(&["rasterize", laz.to_str().unwrap(), "-o", o_s, "--cell", "1"], 3, "bad.laz");
    // all-nodata and 1×1 rasters
    if !common::tool("python3") {
        return;
    }
    make_synthetic(d, &["allnodata", d.join("empty.asc").to_str().unwrap()]);
    make_synthetic(d, &["single", d.join("one.asc").to_str().unwrap()]);
    let empty = d.join("empty.asc");
    let one = d.join("one.asc");
    check(&["warp", empty.to_str().unwrap(), "-o", o_s], 1, "no valid cell");
    check(&["diff", empty.to_str().unwrap(), one.to_str().unwrap()], 1, "share no valid cell");
    // a 1×1 raster is legitimate: diff with itself works, warp gives a 1×1 result and unwarps
    let s = ok(&["diff", one.to_str().unwrap(), one.to_str().unwrap(), "--json"]);
    let v: Value = serde_json::from_slice(&s.stdout).unwrap();
    assert_eq!(v["cells_compared"], 1);
    ok(&["-q", "warp", one.to_str().unwrap(), "-o", o_s]);
    let back = d.join("one_back.tif");
    ok(&["-q", "unwarp", o_s, "-o", back.to_str().unwrap()]);
    let r = raster_io::read_raster(&back).unwrap();
    assert_eq!((r.width, r.height, r.get(0, 0)), (1, 1, Some(3.5)));
    // nothing half-written left behind by the failures
    assert!(std::fs::read_dir(d).unwrap().all(|e| !e.unwrap().file_name().to_string_lossy().starts_with(".geofit")));
}

/// Identical input and options give byte-identical output.
#[test]
fn outputs_are_deterministic() {
    let Some(pts) = common::fixture("terrain/gmt_Table_5_11.txt") else { return };
    let tmp = common::tempdir();
    let a = tmp.path().join("a.tif");
    let b = tmp.path().join("b.tif");
    for o in [&a, &b] {
        ok(&["-q", "rasterize", pts.to_str().unwrap(), "-o", o.to_str().unwrap(), "--cell", "0.2"]);
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let wa = tmp.path().join("wa.tif");
    let wb = tmp.path().join("wb.tif");
    for (i, o) in [&wa, &wb].into_iter().enumerate() {
        let src = if i == 0 { &a } else { &b };
        ok(&["-q", "warp", src.to_str().unwrap(), "-o", o.to_str().unwrap(), "--spacing", "1"]);
    }
    assert_eq!(std::fs::read(&wa).unwrap(), std::fs::read(&wb).unwrap());
}

/// Issue 13, item 4: sizes claimed by a header (or by an extent and a cell size) are checked
/// before anything is allocated for them. Before, an 88-byte ASCII grid or a VRT claiming
/// 10⁶ × 10⁶ cells aborted `info`, `fit`, `warp`, `diff` and `eval --like` in the allocator
/// (SIGABRT, exit 134), and `rasterize` of 3 points 46 km apart at `--cell 1` tried a 16.9 GB grid.
#[test]
fn claimed_sizes_are_checked_before_allocating() {
    let dir = common::tempdir();
    let d = dir.path();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let asc = d.join("big.asc");
    std::fs::write(
        &asc,
        "ncols 1000000\nnrows 1000000\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n1 2 3\n",
    )
    .unwrap();
    let vrt = d.join("big.vrt");
    std::fs::write(&vrt, r#"<VRTDataset rasterXSize="1000000" rasterYSize="1000000"><VRTRasterBand dataType="Float64" band="1"/></VRTDataset>"#).unwrap();
    let small = d.join("small.asc");
    std::fs::write(
        &small,
        "ncols 3\nnrows 3\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n1 2 3\n4 5 6\n7 8 10\n",
    )
    .unwrap();
    let mesh = d.join("m.tmesh");
    let o = common::run(&["-q", "fit", &s(&small), "--max-error", "0.5", "-o", &s(&mesh)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let out = s(&d.join("out.tif"));
    let tmesh = s(&d.join("out.tmesh"));
    for big in [&asc, &vrt] {
        let b = s(big);
        let cmds: [Vec<&str>; 5] = [
            vec!["info", &b],
            vec!["fit", &b, "--max-error", "1", "-o", &tmesh],
            vec!["warp", &b, "-o", &out],
            vec!["diff", &b, &b],
            vec!["eval", mesh.to_str().unwrap(), "--like", &b, "-o", &out],
        ];
        for args in cmds {
            let o = common::run(&args, None);
            let e = stderr(&o);
            assert_eq!(common::code(&o), 3, "{args:?}: {e}");
            assert_eq!(e.lines().count(), 1, "{args:?}: one line: {e}");
            assert!(
                e.contains(&b) && e.contains("1000000×1000000 cells") && e.contains("GEOFIT_MAX_CELLS"),
                "{args:?}: {e}"
            );
        }
    }
    // rasterize: 3 points spanning 46 km at --cell 1 (2.1·10⁹ cells); the budget is fixed by
    // GEOFIT_MAX_CELLS so the test does not depend on this machine's memory
    let pts = d.join("far.xyz");
    std::fs::write(&pts, "0 0 1\n46000 0 2\n0 46000 3\n").unwrap();
    let o = common::geofit()
        .args(["rasterize", &s(&pts), "--cell", "1", "-o", &out])
        .env("GEOFIT_MAX_CELLS", "1000000")
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(common::code(&o), 2, "{e}");
    assert!(
        e.contains("--cell 1") && e.contains("46001 × 46001 cells") && e.contains("a cell size of 47 or more fits"),
        "{e}"
    );
    assert!(!Path::new(&out).exists());
    // and that suggestion works
    let o = common::geofit()
        .args(["-q", "rasterize", &s(&pts), "--cell", "47", "-o", &out])
        .env("GEOFIT_MAX_CELLS", "1000000")
        .output()
        .unwrap();
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
}
