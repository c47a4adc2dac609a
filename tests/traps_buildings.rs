//! Traps (issue 41): CRSs of buildings. Each case builds what a user really sends (a shipped
//! NRW tile converted by pyproj to EPSG:4979, written in the declared or the wrong axis order; a
//! compound CRS; a CRS PROJ does not know) and checks one of two things: the answer equals an
//! independent computation (the findings and mesh of the UTM original; pyproj's ellipsoidal
//! heights), or the exit is 2/3 with one stderr line, no file at `-o`, and every input
//! byte-identical after (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).

mod common;

use std::path::{Path, PathBuf};

use common::{code, run};
use serde_json::Value;

/// 1 building (9 polygons), valid.
const SMALL: &str = "citygml/nrw/LoD2_32_324_5729_1_NW.gml";
/// 13 buildings, 2 findings (302).
const MEDIUM: &str = "citygml/nrw/LoD2_32_327_5723_1_NW.gml";
/// 62 buildings, 34 findings (203 and others): the strong comparison.
const LARGE: &str = "citygml/nrw/LoD2_32_332_5729_1_NW.gml";

const EPSG_4979: &str = "urn:ogc:def:crs:EPSG::4979";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn script(name: &str) -> PathBuf {
    common::repo_root().join("tests/scripts").join(name)
}

/// pyproj with what it needs, else a printed skip (a failure in CI).
fn python_ok() -> bool {
    let ok = common::python().args(["-c", "import pyproj"]).output().map(|o| o.status.success()).unwrap_or(false);
    if !ok {
        assert!(!common::in_ci(), "pyproj missing in CI (make setup installs it)");
        eprintln!("SKIP: python3 with pyproj not found (set GEOFIT_PYTHON to the venv's python3)");
    }
    ok
}

/// `src` reprojected by pyproj (tests/scripts/citygml_reproject.py) into `out`.
fn reproject(src: &Path, out: &Path, from: &str, to: &str, srs_name: &str, order: &str) {
    let o = common::python()
        .arg(script("citygml_reproject.py"))
        .args([s(src), s(out), "--from", from, "--to", to, "--srs-name", srs_name, "--order", order])
        .output()
        .unwrap();
    assert!(o.status.success(), "citygml_reproject.py: {}", String::from_utf8_lossy(&o.stderr));
}

/// `src` with every srsName replaced (coordinates untouched).
fn relabel(src: &Path, out: &Path, srs_name: &str) {
    let text = std::fs::read_to_string(src).unwrap();
    std::fs::write(out, replace_srs_names(&text, srs_name)).unwrap();
}

fn replace_srs_names(text: &str, srs_name: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("srsName=\"") {
        out.push_str(&rest[..i + 9]);
        rest = &rest[i + 9..];
        let end = rest.find('"').unwrap();
        out.push_str(srs_name);
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// A refusal (see [`common::refused`]).
#[track_caller]
fn refused(args: &[&str], exit: i32, words: &[&str], out: Option<&Path>, untouched: &[&Path]) {
    common::refused(args, None, exit, words, out, untouched);
}

fn validate_json(file: &Path) -> (i32, Value) {
    let o = run(&["-q", "validate", "--no-xsd", "--json", s(file)], None);
    assert!(matches!(code(&o), 0 | 1), "validate {}: {}", file.display(), String::from_utf8_lossy(&o.stderr));
    (code(&o), serde_json::from_slice(&o.stdout).unwrap())
}

/// (code, feature, primitive, line) of every finding, and the measured values by the same key.
fn findings(r: &Value) -> Vec<(u64, String, String, u64, Option<f64>)> {
    r["geometry"]["findings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let t = |k: &str| f[k].as_str().unwrap_or("").to_string();
            (
                f["code"].as_u64().unwrap(),
                t("feature"),
                t("primitive"),
                f["line"].as_u64().unwrap(),
                f["value"].as_f64(),
            )
        })
        .collect()
}

#[track_caller]
fn same_findings(utm: &Value, geo: &Value) {
    let (a, b) = (findings(utm), findings(geo));
    assert_eq!(a.len(), b.len(), "findings: UTM {a:?}\ngeographic {b:?}");
    for (x, y) in a.iter().zip(&b) {
        assert_eq!((x.0, &x.1, &x.2, x.3), (y.0, &y.1, &y.2, y.3), "finding differs");
        if let (Some(u), Some(v)) = (x.4, y.4) {
            // 203 distances (m) / 204 angles (deg): the same to 1 µm / 1e-6 deg
            assert!((u - v).abs() < 1e-6, "value {u} (UTM) vs {v} (geographic) for {x:?}");
        }
    }
}

/// Trap: the same buildings in EPSG:4979 (pyproj, latitude first as EPSG declares) and in UTM
/// give the same findings; written longitude first under CRS84h, too. Before: 120 false 102s.
#[test]
fn validate_in_epsg_4979_gives_the_findings_of_the_utm_original() {
    let (Some(large), Some(medium)) = (common::fixture(LARGE), common::fixture(MEDIUM)) else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let geo = dir.path().join("large_4979.gml");
    reproject(&large, &geo, "EPSG:25832", "EPSG:4979", EPSG_4979, "latlon");
    let (cu, utm) = validate_json(&large);
    let (cg, g) = validate_json(&geo);
    assert!(findings(&utm).len() >= 10, "the UTM original has findings to compare: {}", findings(&utm).len());
    assert_eq!(cu, cg);
    same_findings(&utm, &g);
    let frame = g["geometry"]["frame"].as_str().expect("the report names the metric frame");
    assert!(frame.contains("EPSG:4979") && frame.contains("UTM zone 32N"), "{frame}");
    assert!(utm["geometry"].get("frame").is_none());

    let crs84 = dir.path().join("medium_crs84.gml");
    reproject(&medium, &crs84, "EPSG:25832", "EPSG:4979", "urn:ogc:def:crs:OGC:1.3:CRS84h", "lonlat");
    let (_, utm) = validate_json(&medium);
    let (_, g) = validate_json(&crs84);
    assert!(!findings(&utm).is_empty());
    same_findings(&utm, &g);
}

/// Trap: longitude first under EPSG:4979 (which declares latitude first), where it shows (a
/// longitude beyond 90°: the NRW coordinates taken as UTM zone 54N, 141° E): validate and export
/// refuse in one line instead of reading a mirrored building somewhere else.
#[test]
fn longitude_first_under_epsg_4979_is_refused() {
    let Some(small) = common::fixture(SMALL) else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let swapped = dir.path().join("swapped.gml");
    reproject(&small, &swapped, "EPSG:32654", "EPSG:4979", EPSG_4979, "lonlat");
    refused(
        &["-q", "validate", "--no-xsd", s(&swapped)],
        3,
        &["swapped.gml", "EPSG:4979", "other order"],
        None,
        &[&swapped],
    );
    let out = dir.path().join("b.glb");
    refused(
        &["-q", "export", s(&swapped), "--t-srs", "EPSG:32654", "-o", s(&out)],
        3,
        &["EPSG:4979", "other axis order"],
        Some(&out),
        &[&swapped],
    );
    // the same file in the declared order is read, in zone 54
    let right = dir.path().join("right.gml");
    reproject(&small, &right, "EPSG:32654", "EPSG:4979", EPSG_4979, "latlon");
    let (c, r) = validate_json(&right);
    assert_eq!(c, 0, "{r}");
    assert!(r["geometry"]["frame"].as_str().unwrap().contains("UTM zone 54N"));
}

/// Trap: citygml2popa3d of an EPSG:4979 file (before: an unrelated message) is refused naming the
/// CRS and the UTM zone to reproject to.
#[test]
fn citygml2popa3d_refuses_a_geographic_file_naming_the_zone() {
    let Some(small) = common::fixture(SMALL) else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let geo = dir.path().join("b4979.gml");
    reproject(&small, &geo, "EPSG:25832", "EPSG:4979", EPSG_4979, "latlon");
    let out = dir.path().join("b.popa3d");
    refused(
        &["-q", "citygml2popa3d", s(&geo), "-o", s(&out)],
        2,
        &["b4979.gml", "EPSG:4979", "degrees", "EPSG:32632"],
        Some(&out),
        &[&geo],
    );
}

fn export_report(args: &[&str], report: &Path) -> Value {
    let mut a = vec!["-q", "export"];
    a.extend_from_slice(args);
    a.extend_from_slice(&["--origin", "none", "--report", s(report)]);
    let o = run(&a, None);
    assert_eq!(code(&o), 0, "{a:?}: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&std::fs::read(report).unwrap()).unwrap()
}

/// Traps: export of an EPSG:4979 file without --t-srs (before: a 0.0015 × 0.0013 × 9.3 mesh) and
/// with a geographic --t-srs (before: degrees beside metre heights) are refused; with a UTM
/// --t-srs the mesh is the UTM original's (area, triangles; axis order handled).
#[test]
fn export_of_a_geographic_file_needs_a_projected_target() {
    let Some(medium) = common::fixture(MEDIUM) else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let geo = dir.path().join("m4979.gml");
    reproject(&medium, &geo, "EPSG:25832", "EPSG:4979", EPSG_4979, "latlon");
    let out = dir.path().join("m.glb");
    refused(
        &["-q", "export", s(&geo), "-o", s(&out)],
        2,
        &["m4979.gml", "geographic", "--t-srs EPSG:32632"],
        Some(&out),
        &[&geo],
    );
    refused(
        &["-q", "export", s(&geo), "--t-srs", "EPSG:4326", "-o", s(&out)],
        2,
        &["--t-srs EPSG:4326", "geographic"],
        Some(&out),
        &[&geo],
    );
    refused(
        &["-q", "export", s(&medium), "--t-srs", "EPSG:4979", "-o", s(&out)],
        2,
        &["EPSG:4979", "geographic"],
        Some(&out),
        &[&medium],
    );

    let utm = export_report(&[s(&medium), "-o", s(&dir.path().join("u.glb"))], &dir.path().join("u.json"));
    let g = export_report(&[s(&geo), "--t-srs", "EPSG:25832", "-o", s(&out)], &dir.path().join("g.json"));
    assert_eq!(utm["triangles"], g["triangles"]);
    assert_eq!(utm["skipped"], g["skipped"]);
    let (a, b) = (utm["area"].as_f64().unwrap(), g["area"].as_f64().unwrap());
    assert!(a > 1000.0 && (a - b).abs() < 1e-6 * a, "area {a} (UTM original) vs {b} (from EPSG:4979)");
}

/// The glb of `gml` (export) under `dir`.
fn glb_of(gml: &Path, dir: &Path, name: &str) -> PathBuf {
    let glb = dir.join(name);
    let o = run(&["-q", "export", s(gml), "-o", s(&glb)], None);
    assert_eq!(code(&o), 0, "export: {}", String::from_utf8_lossy(&o.stderr));
    glb
}

/// pyproj's check of the tile origins (tests/scripts/tileset_origins.py).
fn origins(tileset: &Path, from: &str, dz: f64) -> Value {
    let o = common::python()
        .arg(script("tileset_origins.py"))
        .args([s(tileset), "--from", from, "--dz", &dz.to_string()])
        .output()
        .unwrap();
    assert!(o.status.success(), "tileset_origins.py: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Trap: a tileset of an NRW tile (DHHN2016 normal heights; its geoid grid GCG2016 is not in
/// PROJ-data) without a height choice is refused (before: every building ~46 m under the
/// globe); with --height-offset the origins are pyproj's position at H + offset (to 0.05 m), and
/// the tileset records the choice.
#[test]
fn tileset_of_an_nrw_tile_needs_a_height_choice() {
    let Some(small) = common::fixture(SMALL) else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let glb = glb_of(&small, dir.path(), "nrw.glb");
    let ts = dir.path().join("tileset.json");
    refused(
        &["-q", "tile", "tileset", s(&glb), "-o", s(&ts)],
        2,
        &["nrw.glb", "DHHN2016", "--height-offset", "--heights-as-is", "--geoid"],
        Some(&ts),
        &[&glb],
    );
    refused(
        &["-q", "tile", "tileset", s(&glb), "--crs", "EPSG:25832", "-o", s(&ts)],
        2,
        &["DHHN2016"],
        Some(&ts),
        &[&glb],
    );

    let o = run(&["-q", "tile", "tileset", s(&glb), "--height-offset", "46.5", "-o", s(&ts)], None);
    assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    let r = origins(&ts, "EPSG:25832", 46.5);
    assert_eq!(r["tiles"], 1);
    assert!(r["max_dh_m"].as_f64().unwrap() < 0.05 && r["max_horizontal_m"].as_f64().unwrap() < 0.05, "{r}");
    let t: Value = serde_json::from_slice(&std::fs::read(&ts).unwrap()).unwrap();
    let h = &t["asset"]["extras"]["heights"];
    assert_eq!((h["method"].as_str(), h["offset_m"].as_f64()), (Some("offset"), Some(46.5)), "{h}");
    assert!(h["vertical"].as_str().unwrap().contains("DHHN2016"));

    // --heights-as-is: the old placement, now stated
    let o = run(&["-q", "tile", "tileset", s(&glb), "--heights-as-is", "-o", s(&ts)], None);
    assert_eq!(code(&o), 0);
    let r = origins(&ts, "EPSG:25832", 0.0);
    assert!(r["max_dh_m"].as_f64().unwrap() < 0.05, "{r}");
    // a missing --geoid grid is refused
    refused(
        &["-q", "tile", "tileset", s(&glb), "--geoid", "no_such_grid.tif", "-o", s(&dir.path().join("t2.json"))],
        2,
        &["no_such_grid.tif"],
        Some(&dir.path().join("t2.json")),
        &[&glb],
    );
}

/// Trap: a compound CRS (UTM 32N + EGM96 heights, as an OGC compound URN) goes to ellipsoidal
/// heights through the EGM96 grid Debian's proj-data ships: the tile origins agree with pyproj's
/// EPSG:25832+5773 → EPSG:4979 transformation to 0.05 m (which moves them by ~44 m: the grid is
/// really applied). validate names the vertical part.
#[test]
fn compound_crs_heights_go_through_the_geoid_grid() {
    let Some(small) = common::fixture(SMALL) else { return };
    if !python_ok() {
        return;
    }
    let dir = common::tempdir();
    let egm = dir.path().join("egm96.gml");
    relabel(&small, &egm, "urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5773");
    let (_, r) = validate_json(&egm);
    assert_eq!(
        (r["heights"]["epsg"].as_u64(), r["heights"]["name"].as_str()),
        (Some(5773), Some("EGM96 height")),
        "{r}"
    );
    let o = run(&["-q", "validate", "--no-xsd", s(&small)], None);
    assert!(String::from_utf8_lossy(&o.stdout).contains("heights: DHHN2016 height (EPSG:7837, normal heights)"));

    let glb = glb_of(&egm, dir.path(), "egm.glb");
    let ts = dir.path().join("tileset.json");
    let o = run(&["-q", "tile", "tileset", s(&glb), "-o", s(&ts)], None);
    if code(&o) == 2 && String::from_utf8_lossy(&o.stderr).contains("not found by PROJ") {
        // no EGM96 grid here: then the refusal is the right answer (proj-data ships it on Debian)
        assert!(!common::in_ci(), "EGM96 grid missing in CI: {}", String::from_utf8_lossy(&o.stderr));
        eprintln!("SKIP: no EGM96 grid installed");
        return;
    }
    assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    let r = origins(&ts, "EPSG:25832+5773", 0.0);
    assert!(r["min_abs_h_minus_H_m"].as_f64().unwrap() > 30.0, "pyproj applied no geoid grid: {r}");
    assert!(r["max_dh_m"].as_f64().unwrap() < 0.05 && r["max_horizontal_m"].as_f64().unwrap() < 0.05, "{r}");
    let t: Value = serde_json::from_slice(&std::fs::read(&ts).unwrap()).unwrap();
    assert_eq!(t["asset"]["extras"]["heights"]["method"], "geoid");
}

/// Trap: a CRS PROJ does not know, recorded in the glb or given with --crs, is refused in one
/// line naming it (PROJ's own stderr lines silenced).
#[test]
fn a_crs_proj_does_not_know_is_refused() {
    let Some(small) = common::fixture(SMALL) else { return };
    let dir = common::tempdir();
    let odd = dir.path().join("odd.gml");
    relabel(&small, &odd, "urn:example:crs:site-grid");
    let glb = glb_of(&odd, dir.path(), "odd.glb");
    let ts = dir.path().join("tileset.json");
    refused(
        &["-q", "tile", "tileset", s(&glb), "--heights-as-is", "-o", s(&ts)],
        2,
        &["urn:example:crs:site-grid", "--crs"],
        Some(&ts),
        &[&glb],
    );
    refused(
        &["-q", "tile", "tileset", s(&glb), "--crs", "EPSG:999999", "--heights-as-is", "-o", s(&ts)],
        2,
        &["EPSG:999999"],
        Some(&ts),
        &[&glb],
    );
    let out = dir.path().join("o.glb");
    refused(
        &["-q", "export", s(&odd), "--t-srs", "EPSG:25832", "-o", s(&out)],
        2,
        &["urn:example:crs:site-grid"],
        Some(&out),
        &[&odd],
    );
}
