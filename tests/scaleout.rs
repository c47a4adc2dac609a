//! Scale-out (issue 17): `geofit tile …` and the buildings workflow (workflows/Snakefile, the
//! same job lines under make), checked against independent truth:
//! - per building, the tiled healed output has the same member bytes as the whole-file heal
//!   (tests/scripts/scaleout_buildings.py: lxml + a byte tag scanner, no geofit code);
//! - the merged report equals the sum of the per-tile reports (tests/scripts/scaleout_report.py);
//! - the glb pass the Khronos glTF validator, the tileset.json is read back by an independent
//!   reader whose ECEF positions come from PROJ's cs2cs (tests/scripts/scaleout_tileset.py);
//! - Snakemake's own bookkeeping: a fault injected once is retried, a deleted output is exactly
//!   what a dry run redoes, a second run does nothing; `make -j2` gives the same bytes.
//!
//! Rules: docs/decisions.md#scale-out-tiles-and-workflows.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const NRW: &str = "citygml/nrw";
/// Small enough that the six NRW fixture files (174 buildings) give several tiles (21 of 256 m),
/// some with buildings reaching across their border.
const BUILDINGS_PER_TILE: &str = "30";

fn script(name: &str) -> PathBuf {
    common::repo_root().join("tests/scripts").join(name)
}

fn nrw_sources() -> Option<Vec<PathBuf>> {
    let dir = common::fixture(NRW)?;
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "gml"))
        .collect();
    v.sort();
    assert!(v.len() >= 2, "NRW fixture tiles expected");
    Some(v)
}

fn ok(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what} failed ({:?}):\nstdout: {}\nstderr: {}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn last_json(o: &Output, what: &str) -> Value {
    ok(o, what);
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.lines().last().unwrap_or("")).unwrap_or_else(|e| panic!("{what}: not JSON ({e}): {text}"))
}

fn python_ok() -> bool {
    let o = common::python().args(["-c", "import lxml, numpy"]).output();
    let found = o.map(|o| o.status.success()).unwrap_or(false);
    if !found {
        if common::in_ci() {
            panic!("python3 with lxml and numpy missing in CI");
        }
        eprintln!("SKIP: python3 with lxml/numpy not found");
    }
    found
}

fn plan(sources: &[PathBuf], out: &Path) -> Vec<Value> {
    let mut args = vec![
        "-q".to_string(),
        "tile".into(),
        "plan".into(),
        "--buildings-per-tile".into(),
        BUILDINGS_PER_TILE.into(),
        "-o".into(),
        out.display().to_string(),
    ];
    args.extend(sources.iter().map(|p| p.display().to_string()));
    let o = common::geofit().args(&args).output().unwrap();
    ok(&o, "geofit tile plan");
    std::fs::read_to_string(out).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// Plan + extract alone: every building of the sources is in exactly one extract, with the
/// source's bytes; the plan's halo buildings (footprint reaching across a tile border) are in
/// their centroid's tile only — the rule for buildings cut by a tile border.
#[test]
fn extracts_partition_the_buildings_and_halo_buildings_stay_home() {
    let Some(sources) = nrw_sources() else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let tiles = plan(&sources, &dir.path().join("plan.jsonl"));
    assert!(tiles.len() >= 6, "{} tiles", tiles.len());
    let mut extracts = Vec::new();
    for t in &tiles {
        let id = t["id"].as_str().unwrap();
        assert!(t["work"].as_u64().unwrap() <= 30, "tile {id} over budget");
        let p = dir.path().join(format!("{id}.gml"));
        let o = common::geofit()
            .args(["-q", "tile", "extract"])
            .arg(dir.path().join("plan.jsonl"))
            .args(["--tile", id, "-o"])
            .arg(&p)
            .output()
            .unwrap();
        ok(&o, "geofit tile extract");
        extracts.push(p);
    }
    // each extract names the sources' CRS (heal refuses degrees, export records it) and stays
    // schema-valid with its new envelope
    let source_text = std::fs::read_to_string(&sources[0]).unwrap();
    let srs =
        source_text.split("srsName=\"").nth(1).and_then(|r| r.split('"').next()).expect("the source names its CRS");
    for p in &extracts {
        assert!(
            std::fs::read_to_string(p).unwrap().contains(&format!("srsName=\"{srs}\"")),
            "{} lacks srsName",
            p.display()
        );
    }
    if let Some(xsd) = common::shared_xsd() {
        let o = common::geofit()
            .args(["-q", "validate", "--no-geometry", "--schemas"])
            .arg(&xsd)
            .arg(&extracts[0])
            .output()
            .unwrap();
        ok(&o, "geofit validate (XSD) of an extract");
    }
    let mut c = common::python();
    c.arg(script("scaleout_buildings.py")).arg("--whole").args(&sources).arg("--tiled").args(&extracts);
    let r = last_json(&c.output().unwrap(), "scaleout_buildings.py");
    let whole = r["whole"].as_u64().unwrap();
    assert!(whole >= 150, "{r}");
    assert_eq!(r["equal"].as_u64().unwrap(), whole, "{r}");
    assert_eq!(r["tiled"].as_u64().unwrap(), whole, "{r}");
    assert!(r["duplicates"].as_array().unwrap().is_empty(), "{r}");
    assert_eq!(tiles.iter().map(|t| t["work"].as_u64().unwrap()).sum::<u64>(), whole);

    // halo buildings: listed by the tiles they reach into, extracted only by their own tile
    let halo: Vec<(String, String)> = tiles
        .iter()
        .flat_map(|t| {
            let id = t["id"].as_str().unwrap().to_string();
            t["halo_buildings"]
                .as_array()
                .cloned()
                .unwrap_or_default()
                .into_iter()
                .map(move |b| (id.clone(), b.as_str().unwrap().to_string()))
        })
        .collect();
    assert!(!halo.is_empty(), "no building crosses a tile border at this tile size: the rule is untested");
    for (tile, b) in &halo {
        let text = std::fs::read_to_string(dir.path().join(format!("{tile}.gml"))).unwrap();
        assert!(!text.contains(&format!("gml:id=\"{b}\"")), "halo building {b} written into tile {tile}");
        let homes = extracts
            .iter()
            .filter(|p| std::fs::read_to_string(p).unwrap().contains(&format!("gml:id=\"{b}\"")))
            .count();
        assert_eq!(homes, 1, "halo building {b} is in {homes} extracts");
    }
}

/// Raster plans read only size and geotransform; windows checked against gdalinfo.
#[test]
fn raster_plan_windows_cover_the_raster_once() {
    let Some(raster) = common::fixture("terrain/giswqs-lidar_dem.tif") else { return };
    if !common::tool("gdalinfo") {
        return;
    }
    let info: Value =
        serde_json::from_slice(&Command::new("gdalinfo").arg("-json").arg(&raster).output().unwrap().stdout).unwrap();
    let (w, h) = (info["size"][0].as_u64().unwrap() as usize, info["size"][1].as_u64().unwrap() as usize);
    let gt: Vec<f64> = info["geoTransform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let o = common::geofit()
        .args(["-q", "tile", "plan", "--cells-per-tile", "10000", "--halo", "8"])
        .arg(&raster)
        .output()
        .unwrap();
    ok(&o, "geofit tile plan (raster)");
    let tiles: Vec<Value> =
        String::from_utf8_lossy(&o.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(tiles.len(), w.div_ceil(100) * h.div_ceil(100));
    let mut covered = vec![0u8; w * h];
    for t in &tiles {
        let px: Vec<usize> =
            t["core"]["pixels"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        for r in px[1]..px[1] + px[3] {
            for c in px[0]..px[0] + px[2] {
                covered[r * w + c] += 1;
            }
        }
        let halo: Vec<usize> =
            t["halo"]["pixels"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        // 8 px of halo each side where the raster has them, and the neighbour's first column
        // beyond (the seam runs along pixel centres: docs/decisions.md#raster-tiles-and-seams)
        let (halo_end, core_end) = (halo[0] + halo[2], px[0] + px[2]);
        assert!(halo[0] <= px[0].saturating_sub(8) && px[0] - halo[0] <= 9, "{t}");
        assert!(halo_end >= (core_end + 8).min(w) && halo_end <= (core_end + 9).min(w), "{t}");
        // georeferenced core from gdalinfo's geotransform (north-up)
        let b: Vec<f64> = t["core"]["bounds"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let x0 = gt[0] + px[0] as f64 * gt[1];
        let y_top = gt[3] + px[1] as f64 * gt[5];
        assert!((b[0] - x0).abs() < 1e-6 && (b[3] - y_top).abs() < 1e-6, "{t}");
    }
    assert!(covered.iter().all(|&n| n == 1), "core windows overlap or leave gaps");
}

fn snakemake(work: &Path, config: &[String], extra: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new("snakemake");
    c.arg("-s")
        .arg(common::repo_root().join("workflows/Snakefile"))
        .arg("--directory")
        .arg(work)
        .args(["--cores", "2"])
        .args(extra)
        .arg("--config")
        .args(config);
    c.env_remove("GEOFIT_FAIL_ONCE");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("snakemake runs")
}

/// Every file under `dir` (relative path → bytes), hidden files and Snakemake's state left out.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(base: &Path, d: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            if p.is_dir() {
                walk(base, &p, out);
            } else {
                out.insert(p.strip_prefix(base).unwrap().display().to_string(), std::fs::read(&p).unwrap());
            }
        }
    }
    let mut m = BTreeMap::new();
    walk(dir, dir, &mut m);
    m
}

#[test]
fn snakemake_tiled_run_matches_whole_file_retries_and_make() {
    let Some(sources) = nrw_sources() else { return };
    if !common::tool("snakemake") || !python_ok() {
        return;
    }
    let geofit = env!("CARGO_BIN_EXE_geofit");
    let work = common::tempdir();
    let out = work.path().join("out");
    let glob = sources[0].parent().unwrap().join("*.gml").display().to_string();
    let config = vec![
        format!("sources={glob}"),
        "out=out".to_string(),
        format!("geofit={geofit}"),
        format!("buildings_per_tile={BUILDINGS_PER_TILE}"),
        // NRW heights are DHHN2016 normal heights and its geoid grid is not installed: the
        // tileset needs a stated height choice (issue 41)
        "tileset_args=--crs EPSG:25832 --heights-as-is".to_string(),
        "validate_args=--no-xsd".to_string(),
    ];

    // 1. full run
    ok(&snakemake(work.path(), &config, &[], &[]), "snakemake full run");
    let tiles: Vec<String> = std::fs::read_to_string(out.join("plan.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap()["id"].as_str().unwrap().to_string())
        .collect();
    assert!(tiles.len() >= 6);
    let first = tree(&out);

    // 2. per building the same bytes as the whole-file heal (same heal options)
    let mut whole = Vec::new();
    for (i, s) in sources.iter().enumerate() {
        let p = work.path().join(format!("whole{i}.gml"));
        let o = common::geofit().args(["-q", "heal", "--precision", "3"]).arg(s).arg("-o").arg(&p).output().unwrap();
        ok(&o, "whole-file heal");
        whole.push(p);
    }
    let healed: Vec<PathBuf> = tiles.iter().map(|t| out.join(format!("healed/{t}.gml"))).collect();
    let mut c = common::python();
    c.arg(script("scaleout_buildings.py")).arg("--whole").args(&whole).arg("--tiled").args(&healed);
    let r = last_json(&c.output().unwrap(), "scaleout_buildings.py");
    assert!(r["whole"].as_u64().unwrap() >= 150, "{r}");
    assert_eq!(r["equal"], r["whole"], "per-building bytes differ: {r}");
    assert_eq!(r["tiled"], r["whole"], "{r}");
    assert!(r["duplicates"].as_array().unwrap().is_empty(), "{r}");

    // 3. the merged report is the sum of the per-tile reports
    let mut c = common::python();
    c.arg(script("scaleout_report.py")).arg(out.join("report.json")).arg("--heal");
    c.args(tiles.iter().map(|t| out.join(format!("healed/{t}.heal.json")))).arg("--validate");
    c.args(tiles.iter().map(|t| out.join(format!("validate/{t}.validate.json"))));
    let r = last_json(&c.output().unwrap(), "scaleout_report.py");
    assert!(r["mismatches"].as_array().unwrap().is_empty(), "{r}");
    assert!(r["checked"].as_u64().unwrap() >= 14);

    // 4. glb: Khronos validator; tileset: independent reader with cs2cs positions
    if common::tool("node") && common::tool("cs2cs") {
        for t in &tiles {
            let glb = out.join(format!("glb/{t}.glb"));
            let o = Command::new("node").arg(script("gltf_validator.js")).arg(&glb).output().unwrap();
            ok(&o, "gltf_validator.js");
            let v: Value = serde_json::from_slice(&o.stdout).expect("validator report is JSON");
            assert_eq!(v["issues"]["numErrors"], 0, "{}: {}", glb.display(), v["issues"]["messages"]);
        }
        let mut c = common::python();
        c.arg(script("scaleout_tileset.py")).arg(out.join("tileset.json")).args(["--crs", "EPSG:25832"]);
        let r = last_json(&c.output().unwrap(), "scaleout_tileset.py");
        assert!(r["errors"].as_array().unwrap().is_empty(), "{r}");
        assert_eq!(r["tiles"].as_u64().unwrap() as usize, tiles.len());
        eprintln!("tileset: {r}");
    }
    if let Some(r) = common::tileset_read_by_py3dtiles(&out.join("tileset.json")) {
        assert_eq!(r["contents"].as_u64().unwrap() as usize, tiles.len(), "{r}");
        eprintln!("py3dtiles: {r}");
    }

    // 5. a second run does nothing
    let o = snakemake(work.path(), &config, &["-n"], &[]);
    let jobs = common::snakemake_dry_run_jobs(&o);
    assert!(jobs.is_empty(), "second run would do {jobs:?}");

    // 6. delete one tile output: the dry run lists exactly that tile's job and what depends on it
    let victim = &tiles[tiles.len() / 2];
    std::fs::remove_file(out.join(format!("healed/{victim}.gml"))).unwrap();
    let jobs = common::snakemake_dry_run_jobs(&snakemake(work.path(), &config, &["-n"], &[]));
    let want: BTreeSet<(String, String)> =
        [("heal", victim.as_str()), ("export", victim.as_str()), ("report", ""), ("tileset", ""), ("all", "")]
            .iter()
            .map(|(r, t)| (r.to_string(), t.to_string()))
            .collect();
    assert_eq!(jobs, want, "dry run after deleting healed/{victim}.gml");

    // 7. fault injection: the heal job of `victim` fails once; without retries the run fails,
    //    with --retries 1 it succeeds, and the outputs are the first run's bytes
    let marker = work.path().join("faults");
    let env = [("GEOFIT_FAIL_ONCE", victim.as_str()), ("GEOFIT_FAIL_ONCE_DIR", marker.to_str().unwrap())];
    let o = snakemake(work.path(), &config, &[], &env);
    assert!(!o.status.success(), "the injected failure must fail a run without retries");
    assert!(marker.join(victim).exists());
    std::fs::remove_dir_all(&marker).unwrap();
    let o = snakemake(work.path(), &config, &["--retries", "1"], &env);
    ok(&o, "snakemake --retries 1 with one injected failure");
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("injected failure"), "the fault was not injected:\n{log}");
    assert!(tree(&out) == first, "outputs after the retried run differ from the first run");

    // 8. make -j2 over the same plan, in another directory with the same relative OUT (the
    //    reports record their input path): the same bytes. Without --crs here: the tileset takes
    //    the CRS the glb record (the tiles' AdV URN, read as EPSG:25832), so the same bytes also
    //    show that mapping.
    let work2 = common::tempdir();
    let mut c = Command::new("make");
    c.current_dir(work2.path()).args(["-j2", "-s", "-f"]).arg(common::repo_root().join("workflows/tiles.mk"));
    c.arg("OUT=out")
        .arg(format!("SOURCES={}", sources.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" ")));
    c.arg(format!("GEOFIT={geofit}")).arg(format!("GEOFIT_BUILDINGS_PER_TILE={BUILDINGS_PER_TILE}"));
    c.arg("GEOFIT_TILESET_ARGS=--heights-as-is").arg("GEOFIT_VALIDATE_ARGS=--no-xsd");
    ok(&c.output().unwrap(), "make -j2 -f workflows/tiles.mk");
    let mut made = tree(&work2.path().join("out"));
    assert!(made.remove("plan.mk").is_some(), "make writes its plan fragment");
    assert_eq!(
        made.keys().collect::<Vec<_>>(),
        first.keys().collect::<Vec<_>>(),
        "make and Snakemake write different files"
    );
    for (k, v) in &first {
        assert!(&made[k] == v, "make output {k} differs from Snakemake's");
    }
}

/// Exit codes of the tile commands: a tile the plan does not have is a usage error (2), a plan
/// that is not JSON lines or a file that is not a glb is unreadable (3); `--format make` lists
/// the same ids as the JSON plan.
#[test]
fn tile_commands_exit_codes_and_make_fragment() {
    let Some(sources) = nrw_sources() else { return };
    let dir = common::tempdir();
    let plan_path = dir.path().join("plan.jsonl");
    let tiles = plan(&sources[..2], &plan_path);
    let p = plan_path.to_str().unwrap();
    let o = common::run(&["tile", "extract", p, "--tile", "x0_y0"], None);
    assert_eq!(common::code(&o), 2, "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::write(dir.path().join("bad.jsonl"), "not json\n").unwrap();
    let o = common::run(&["tile", "extract", dir.path().join("bad.jsonl").to_str().unwrap(), "--tile", "x0_y0"], None);
    assert_eq!(common::code(&o), 3, "{}", String::from_utf8_lossy(&o.stderr));
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    let glb = dir.path().join("a.glb");
    std::fs::write(&glb, b"glTF").unwrap();
    let o = common::run(
        &["tile", "tileset", glb.to_str().unwrap(), "-o", sub.join("tileset.json").to_str().unwrap()],
        None,
    );
    assert_eq!(common::code(&o), 3, "a 4-byte glb is unreadable: {}", String::from_utf8_lossy(&o.stderr));
    let mut args = vec!["-q", "tile", "plan", "--buildings-per-tile", BUILDINGS_PER_TILE, "--format", "make"];
    let srcs: Vec<String> = sources[..2].iter().map(|s| s.display().to_string()).collect();
    args.extend(srcs.iter().map(String::as_str));
    let o = common::run(&args, None);
    assert_eq!(common::code(&o), 0);
    let text = String::from_utf8_lossy(&o.stdout);
    let ids: Vec<&str> =
        text.lines().find_map(|l| l.strip_prefix("TILES := ")).expect("TILES line").split(' ').collect();
    let want: Vec<&str> = tiles.iter().map(|t| t["id"].as_str().unwrap()).collect();
    assert_eq!(ids, want);
}
