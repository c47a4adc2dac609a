//! Raster tiles on real surveys (issue 36): a survey that is mostly no-data, with whole tiles
//! without a valid cell, runs through the workflow's job lines (`make -j2 -f workflows/tiles.mk`,
//! the lines Snakemake runs): the plan marks the empty tiles (work 0, nobody's neighbour), no job
//! runs for them, every valid cell is within E of its tile's stitched surface by the independent
//! T-mesh decoder (tests/scripts/tiles_check.py), and `tile seams`, measuring over the data
//! relative to the height range, passes on seams that cross no-data
//! (docs/decisions.md#tiles-on-the-whole-fits-lattice, docs/decisions.md#seams-gate-on-the-data).

mod common;

use std::process::{Command, Output};

use serde_json::Value;

const DEM: &str = "terrain/giswqs-lidar_dem.tif";
const MAX_ERROR: &str = "0.25";

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
    let have = ["make", "gdal_translate", "gdalinfo", "gdalbuildvrt"].iter().all(|t| common::tool(t));
    let py = common::python().args(["-c", "import numpy"]).output().map(|o| o.status.success()).unwrap_or(false);
    if !py {
        assert!(!common::in_ci(), "python3 with numpy missing in CI");
        eprintln!("SKIP: python3 with numpy not found");
    }
    have && py
}

#[test]
fn a_survey_with_80_percent_no_data_skips_its_empty_tiles_and_keeps_the_tolerance() {
    let Some(dem) = common::fixture(DEM) else { return };
    if !tools() {
        return;
    }
    let work = common::tempdir();
    let win = work.path().join("win.tif");
    let src = work.path().join("holes.tif");
    let o = Command::new("gdal_translate")
        .args(["-q", "-srcwin", "100", "100", "160", "160"])
        .arg(&dem)
        .arg(&win)
        .env("GDAL_PAM_ENABLED", "NO")
        .output()
        .unwrap();
    ok(&o, "gdal_translate -srcwin");
    let o = common::python()
        .arg(common::repo_root().join("tests/scripts/tiles_holes.py"))
        .arg(&win)
        .arg(&src)
        .arg("0.2")
        .output()
        .unwrap();
    ok(&o, "tiles_holes.py");
    let made: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(made["valid"].as_f64().unwrap() <= 0.21 * made["cells"].as_f64().unwrap(), "{made}");

    // the job lines, as make runs them (40-px tiles: 4×4, the far corner without data)
    let mut c = Command::new("make");
    c.current_dir(work.path()).args(["-j2", "-s", "-f"]).arg(common::repo_root().join("workflows/tiles.mk"));
    c.arg(format!("RASTER={}", src.display())).arg("OUT=out").arg(format!("GEOFIT={}", env!("CARGO_BIN_EXE_geofit")));
    c.env("GEOFIT_MAX_ERROR", MAX_ERROR).env("GEOFIT_TILE_PIXELS", "40");
    ok(&c.output().unwrap(), "make -j2 -f workflows/tiles.mk RASTER=… (mostly no data)");
    let out = work.path().join("out");
    let plan: Vec<Value> = std::fs::read_to_string(out.join("plan.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let empty: Vec<&str> = plan.iter().filter(|t| t["work"] == 0).map(|t| t["id"].as_str().unwrap()).collect();
    assert!(empty.len() >= 4, "whole tiles without data: {empty:?}");
    for t in &plan {
        let id = t["id"].as_str().unwrap();
        let fitted = out.join(format!("fit/{id}.tmb")).exists();
        assert_eq!(fitted, !empty.contains(&id), "{id}: a job runs exactly for the tiles with data");
        for n in t["neighbours"].as_array().unwrap() {
            assert!(!empty.contains(&n.as_str().unwrap()), "{id}: an empty tile is nobody's neighbour");
        }
    }

    // the independent check: every valid cell within E, the empty tiles really empty
    let o = common::python()
        .arg(common::repo_root().join("tests/scripts/tiles_check.py"))
        .arg(out.join("plan.jsonl"))
        .arg(&src)
        .arg(MAX_ERROR)
        .arg(out.join("stitched/{id}.tmb"))
        .arg("--first")
        .arg(out.join("fit/{id}.tmb"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    eprintln!("tiles_check: {text}");
    ok(&o, "tiles_check.py");
    let r: Value = serde_json::from_str(text.trim()).unwrap();
    assert_eq!(r["valid_cells"], made["valid"], "{r}");
    assert_eq!(r["empty_tiles"].as_u64().unwrap() as usize, empty.len());

    // seams over the data: the run's gate passed (make made seams.json); the report says how
    let seams: Value = serde_json::from_slice(&std::fs::read(out.join("seams.json")).unwrap()).unwrap();
    assert_eq!(seams["z_range_from"], "--z-range", "{seams}");
    assert!(seams["max_gap_relative"].as_f64().unwrap() <= 1e-6, "{seams}");
    assert!(seams["seams"].as_u64().unwrap() >= 4, "{seams}");
    eprintln!(
        "seams: max gap {} over the data ({} of the range), max normal jump {}°",
        seams["max_gap"], seams["max_gap_relative"], seams["max_normal_angle_deg"]
    );
}
