//! Scale-out of a raster (issue 17): `snakemake --cores 2` over a 3×3 tiling of a window of the
//! shipped lidar DEM (workflows/raster.smk: plan → per-tile windowed fit → stitch → eval →
//! mosaic.vrt, seams.json), checked by an independent numpy/GDAL script
//! (tests/scripts/scaleout_raster.py) and the independent T-mesh decoder on every stitched tile
//! (tests/scripts/tiles_check.py): every valid source cell within --max-error of the merged
//! surface (seams included), and the tiles' surfaces, evaluated by `geofit eval` on a grid of
//! points on every pixel edge, equal to 1e-9 relative wherever two tiles meet. The C1 figure
//! (normal-angle jump across the seams) is reported. The per-tile glb and their 3D Tiles
//! tileset: the Khronos glTF validator, the independent tileset reader with PROJ's cs2cs
//! (tests/scripts/scaleout_tileset.py), and tests/scripts/tileset_seams.py: the tiles' triangles
//! cover the cores exactly once and share height and colour at every seam vertex.
//! `make -j2 -f workflows/tiles.mk` runs the same lines and gives the same bytes. Rules:
//! docs/decisions.md#raster-tiles-and-seams, docs/decisions.md#terrain-tilesets.

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;

const DEM: &str = "terrain/giswqs-lidar_dem.tif";
/// A 3×3 plan of 40-pixel tiles over a 120×120 window (debug builds: well under two minutes).
const WINDOW: [&str; 4] = ["140", "140", "120", "120"];
const TILE: &str = "40";
const MAX_ERROR: &str = "0.25";
/// Cells between glb vertices (the workflow's default; divides TILE).
const SURFACE_STEP: &str = "4";
/// The source window's CRS (NAD83 / UTM 15N), for the independent ECEF check.
const CRS: &str = "EPSG:26915";

fn ok(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what} failed ({:?}):\nstdout: {}\nstderr: {}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn tools() -> bool {
    let have =
        ["snakemake", "gdal_translate", "gdal_create", "gdalbuildvrt", "gdalinfo"].iter().all(|t| common::tool(t));
    let py = common::python().args(["-c", "import numpy"]).output().map(|o| o.status.success()).unwrap_or(false);
    if !(have && py) {
        if common::in_ci() {
            panic!("snakemake, GDAL's tools or python3 with numpy missing in CI");
        }
        eprintln!("SKIP: snakemake, GDAL's tools or python3 with numpy not found");
    }
    have && py
}

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    out.insert("tileset.json".into(), std::fs::read(dir.join("tileset.json")).unwrap());
    for sub in ["fit", "stitched", "eval", "glb"] {
        for e in std::fs::read_dir(dir.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "tmb" || x == "tif" || x == "glb") {
                out.insert(format!("{sub}/{}", p.file_name().unwrap().to_string_lossy()), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

#[test]
fn snakemake_raster_tiles_keep_the_tolerance_and_meet_at_the_seams() {
    let Some(dem) = common::fixture(DEM) else { return };
    if !tools() {
        return;
    }
    let geofit = env!("CARGO_BIN_EXE_geofit");
    let work = common::tempdir();
    let src = work.path().join("dem.tif");
    let mut c = Command::new("gdal_translate");
    c.args(["-q", "-srcwin"]).args(WINDOW).arg(&dem).arg(&src).env("GDAL_PAM_ENABLED", "NO");
    ok(&c.output().unwrap(), "gdal_translate -srcwin");

    // 1. the workflow, with the centre tile's fit failing once (injected) and retried
    let config = [
        format!("raster={}", src.display()),
        "out=out".into(),
        format!("geofit={geofit}"),
        format!("max_error={MAX_ERROR}"),
        format!("tile_pixels={TILE}"),
    ];
    let snakemake = |extra: &[&str]| {
        let mut c = Command::new("snakemake");
        c.arg("-s")
            .arg(common::repo_root().join("workflows/Snakefile"))
            .arg("--directory")
            .arg(work.path())
            .args(["--cores", "2"])
            .args(extra)
            .arg("--config")
            .args(&config);
        c.env_remove("GEOFIT_FAIL_ONCE");
        c
    };
    let marker = work.path().join("fail-once");
    let mut c = snakemake(&["--retries", "1"]);
    c.env("GEOFIT_FAIL_ONCE", "c1_r1").env("GEOFIT_FAIL_ONCE_DIR", &marker);
    ok(&c.output().unwrap(), "snakemake --cores 2 --retries 1 (raster, one injected failure)");
    assert!(marker.join("c1_r1").exists(), "the injected failure happened");
    let out = work.path().join("out");
    let plan: Vec<Value> = std::fs::read_to_string(out.join("plan.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(plan.len(), 9, "a 3×3 plan");
    let ids: Vec<String> = plan.iter().map(|t| t["id"].as_str().unwrap().to_string()).collect();
    for id in &ids {
        let rep: Value =
            serde_json::from_slice(&std::fs::read(out.join(format!("stitched/{id}.json"))).unwrap()).unwrap();
        assert_eq!(rep["stop"]["reason"], "tolerance_reached", "{id}: {rep}");
        eprintln!(
            "stitch {id}: {} control points, {} rounds, C1 held {}",
            rep["control_points"],
            rep["iterations"].as_array().unwrap().len(),
            rep["c1_held"]
        );
    }

    // 2. the tiles' surfaces on a grid of ⅛-pixel points: every pixel edge is a grid line (binary
    //    fractions keep the positions exact), and along a seam every other point falls halfway
    //    between two seam vertices (¼ px apart)
    let (w, h) = (WINDOW[2].parse::<f64>().unwrap(), WINDOW[3].parse::<f64>().unwrap());
    let info: Value =
        serde_json::from_slice(&Command::new("gdalinfo").arg("-json").arg(&src).output().unwrap().stdout).unwrap();
    let gt: Vec<f64> = info["geoTransform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let (q, n, m) = (gt[1] / 8.0, (8.0 * w) as usize + 1, (8.0 * h) as usize + 1);
    let edges = work.path().join("edges.tif");
    let (ulx, uly) = (gt[0] - 0.5 * q, gt[3] + 0.5 * q);
    let (lrx, lry) = (ulx + n as f64 * q, uly - m as f64 * q);
    let mut c = Command::new("gdal_create");
    c.args(["-q", "-of", "GTiff", "-ot", "Float64", "-outsize"]).arg(n.to_string()).arg(m.to_string());
    // shortest round-trip decimals: GDAL parses back the exact doubles
    c.args(["-a_ullr"]).args([ulx, uly, lrx, lry].map(|v| format!("{v}"))).arg(&edges);
    ok(&c.output().unwrap(), "gdal_create (edge grid)");
    let mut edge_tifs = Vec::new();
    for id in &ids {
        let p = work.path().join(format!("edges_{id}.tif"));
        let o = common::geofit()
            .args(["-q", "eval"])
            .arg(out.join(format!("stitched/{id}.tmb")))
            .arg("--like")
            .arg(&edges)
            .args(["--no-mask", "-ot", "Float64", "-o"])
            .arg(&p)
            .output()
            .unwrap();
        ok(&o, "geofit eval --like edges");
        edge_tifs.push(p);
    }

    // 3. the independent check
    let o = common::python()
        .arg(common::repo_root().join("tests/scripts/scaleout_raster.py"))
        .arg(&src)
        .arg(out.join("mosaic.vrt"))
        .args([MAX_ERROR, "1e-9"])
        .args(&edge_tifs)
        .env("GDAL_PAM_ENABLED", "NO")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    eprintln!("independent check: {text}");
    ok(&o, "scaleout_raster.py");
    let r: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    assert_eq!(r["valid_cells"].as_u64().unwrap() as f64, w * h);
    assert!(r["seam_points"].as_u64().unwrap() as f64 >= 4.0 * (8.0 * w), "{r}");

    // 3b. every stitched tile decoded and evaluated independently (tests/scripts/tmb_decode_eval.py)
    let o = common::python()
        .arg(common::repo_root().join("tests/scripts/tiles_check.py"))
        .arg(out.join("plan.jsonl"))
        .arg(&src)
        .arg(MAX_ERROR)
        .arg(out.join("stitched/{id}.tmb"))
        .env("GDAL_PAM_ENABLED", "NO")
        .output()
        .unwrap();
    eprintln!("tiles_check: {}", String::from_utf8_lossy(&o.stdout));
    ok(&o, "tiles_check.py");

    // 4. geofit's own continuity report over the data: C0 to 1e-6 of the height range (rounding
    //    at |z| ≈ 400 m), the C1 figure reported
    let seams: Value = serde_json::from_slice(&std::fs::read(out.join("seams.json")).unwrap()).unwrap();
    assert_eq!(seams["schema"], "geofit-tile-seams-report/2");
    assert_eq!(seams["seams"], 12, "a 3×3 plan has 12 shared edges");
    assert_eq!(seams["z_range_from"], "--z-range", "{seams}");
    assert!(seams["max_gap_relative"].as_f64().unwrap() <= 1e-6, "{seams}");
    let medians: Vec<f64> =
        seams["per_seam"].as_array().unwrap().iter().map(|s| s["median_normal_angle_deg"].as_f64().unwrap()).collect();
    eprintln!(
        "seams: max gap {} ({} relative), C1: max normal-angle jump {}°, per-seam medians {medians:?}°",
        seams["max_gap"], seams["max_gap_relative"], seams["max_normal_angle_deg"]
    );

    // 5. the terrain tileset: glb valid, tileset read back independently, tiles meeting at seams
    let o = common::python()
        .arg(common::repo_root().join("tests/scripts/tileset_seams.py"))
        .arg(out.join("plan.jsonl"))
        .arg(out.join("glb"))
        .arg(SURFACE_STEP)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    eprintln!("glb seams: {text}");
    // the seams run along pixel centres (docs/decisions.md#tiles-on-the-whole-fits-lattice), so the
    // script's core-edge coverage test (pixel edges) does not apply; what it measures at the
    // seams does: shared vertices with equal heights and colours
    let r: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    let along = |cells: f64| cells / SURFACE_STEP.parse::<f64>().unwrap() + 1.0;
    // 2 inner vertical and 2 inner horizontal seam lines (their ends may stop one step short of
    // the raster's border), their 4 crossings counted once
    assert!(r["shared_vertices"].as_f64().unwrap() >= 2.0 * along(h) + 2.0 * along(w) - 8.0, "{r}");
    assert!(r["max_seam_dz"].as_f64().unwrap() <= 1e-4, "{r}");
    assert!(r["max_seam_colour_diff"].as_f64().unwrap() <= 1e-6, "one colour ramp over all tiles: {r}");
    if common::tool("node") && common::tool("cs2cs") {
        for id in &ids {
            let glb = out.join(format!("glb/{id}.glb"));
            let o = Command::new("node")
                .arg(common::repo_root().join("tests/scripts/gltf_validator.js"))
                .arg(&glb)
                .output()
                .unwrap();
            ok(&o, "gltf_validator.js");
            let v: Value = serde_json::from_slice(&o.stdout).expect("validator report is JSON");
            assert_eq!(v["issues"]["numErrors"], 0, "{}: {}", glb.display(), v["issues"]["messages"]);
        }
        let o = common::python()
            .arg(common::repo_root().join("tests/scripts/scaleout_tileset.py"))
            .arg(out.join("tileset.json"))
            .args(["--crs", CRS])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        ok(&o, "scaleout_tileset.py");
        let r: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
        assert!(r["errors"].as_array().unwrap().is_empty(), "{r}");
        assert_eq!(r["tiles"].as_u64().unwrap() as usize, ids.len());
        eprintln!("tileset: {r}");
    } else if common::in_ci() {
        panic!("node (Khronos glTF validator) or cs2cs missing in CI");
    }
    if let Some(r) = common::tileset_read_by_py3dtiles(&out.join("tileset.json")) {
        assert_eq!(r["contents"].as_u64().unwrap() as usize, ids.len(), "{r}");
        eprintln!("py3dtiles: {r}");
    }

    // 6. nothing left to do; a deleted tile glb is made again with the tileset, nothing else
    let first = files(&out);
    let jobs = common::snakemake_dry_run_jobs(&snakemake(&["-n"]).output().unwrap());
    assert!(jobs.is_empty(), "second run would do {jobs:?}");
    std::fs::remove_file(out.join("glb/c1_r1.glb")).unwrap();
    let jobs = common::snakemake_dry_run_jobs(&snakemake(&["-n"]).output().unwrap());
    let want: std::collections::BTreeSet<(String, String)> =
        [("glb", "c1_r1"), ("tileset", ""), ("all", "")].iter().map(|(r, t)| (r.to_string(), t.to_string())).collect();
    assert_eq!(jobs, want);
    ok(&snakemake(&[]).output().unwrap(), "snakemake (one glb made again)");
    assert!(files(&out) == first, "the remade glb and tileset are the same bytes");

    // 7. make -j2 runs the same lines: the same bytes
    let work2 = common::tempdir();
    let mut c = Command::new("make");
    c.current_dir(work2.path()).args(["-j2", "-s", "-f"]).arg(common::repo_root().join("workflows/tiles.mk"));
    c.arg(format!("RASTER={}", src.display())).arg("OUT=out").arg(format!("GEOFIT={geofit}"));
    c.env("GEOFIT_MAX_ERROR", MAX_ERROR).env("GEOFIT_TILE_PIXELS", TILE);
    ok(&c.output().unwrap(), "make -j2 -f workflows/tiles.mk RASTER=…");
    let second = files(&work2.path().join("out"));
    assert_eq!(first.keys().collect::<Vec<_>>(), second.keys().collect::<Vec<_>>());
    for (k, v) in &first {
        assert!(second[k] == *v, "{k} differs between snakemake and make");
    }
}

/// A rotated raster is refused by the plan, before any tile job runs (each tile's fit would
/// refuse it anyway), with the way out in the message.
#[test]
fn a_rotated_raster_is_refused_by_the_plan() {
    let Some(dem) = common::fixture(DEM) else { return };
    if !common::tool("gdal_translate") {
        assert!(!common::in_ci(), "gdal_translate missing in CI");
        return;
    }
    let work = common::tempdir();
    let vrt = work.path().join("rot.vrt");
    let mut c = Command::new("gdal_translate");
    c.args(["-q", "-of", "VRT"]).arg(&dem).arg(&vrt);
    ok(&c.output().unwrap(), "gdal_translate -of VRT");
    let text = std::fs::read_to_string(&vrt).unwrap();
    let (a, rest) = text.split_once("<GeoTransform>").unwrap();
    let (_, b) = rest.split_once("</GeoTransform>").unwrap();
    std::fs::write(
        &vrt,
        format!("{a}<GeoTransform>429392.3, 0.8660254, -0.5, 5150745.4, -0.5, -0.8660254</GeoTransform>{b}"),
    )
    .unwrap();
    let plan = work.path().join("plan.jsonl");
    let o =
        common::run(&["tile", "plan", "--tile-size", "40", "-o", plan.to_str().unwrap(), vrt.to_str().unwrap()], None);
    assert_eq!(o.status.code(), Some(3), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("rot.vrt") && err.contains("rotated rasters are not supported") && err.contains("gdalwarp"),
        "{err}"
    );
    assert!(!plan.exists(), "no plan written");
}
