//! Issue 38: CityJSON in and out. Every check compares with independent truth: lxml and json
//! read the CityGML and CityJSON themselves, the official CityJSON 2.0 JSON schemas (shipped
//! in xsd/cityjson/) judge the CityJSON with jsonschema, cjio reads the publisher files, and
//! /usr/bin/time measures the memory of the streaming runs.

mod common;

use std::path::{Path, PathBuf};

use common::{fixture, geofit, in_ci, python, repo_root, tempdir};

/// The independent round-trip check (lxml + json + jsonschema + scipy), one problem per line.
const CHECK_ROUNDTRIP: &str = include_str!("cityjson_check.py");

fn run_ok(args: &[&str]) -> std::process::Output {
    let o = geofit().args(args).output().expect("run geofit");
    assert!(o.status.success(), "geofit {args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
    o
}

/// Python modules the checks need; missing: skip (a failure in CI).
fn python_has(modules: &str) -> bool {
    let ok = python().args(["-c", &format!("import {modules}")]).output().is_ok_and(|o| o.status.success());
    if !ok {
        assert!(!in_ci(), "python modules {modules} missing in CI (make setup-pip)");
        eprintln!("SKIP: python modules {modules} missing (make setup-pip)");
    }
    ok
}

fn schema_dir() -> PathBuf {
    repo_root().join("xsd/cityjson")
}

#[test]
fn every_citygml_fixture_round_trips_through_cityjson() {
    let Some(dir) = fixture("citygml") else { return };
    if !python_has("lxml, jsonschema, referencing, scipy") {
        return;
    }
    let files = common::gml_files(&dir);
    assert!(files.len() >= 60, "expected the 66 CityGML fixtures, found {}", files.len());
    let tmp = tempdir();
    let mut args: Vec<String> = vec!["-c".into(), CHECK_ROUNDTRIP.into(), schema_dir().display().to_string()];
    for (i, f) in files.iter().enumerate() {
        let json = tmp.path().join(format!("{i}.city.json"));
        let back = tmp.path().join(format!("{i}.gml"));
        let report = tmp.path().join(format!("{i}.report.json"));
        let (f_s, j_s, b_s, r_s) =
            (f.to_str().unwrap(), json.to_str().unwrap(), back.to_str().unwrap(), report.to_str().unwrap());
        run_ok(&["-q", "convert", f_s, "-o", j_s, "--report", r_s]);
        run_ok(&["-q", "convert", j_s, "-o", b_s]);
        args.extend([f_s.to_string(), j_s.to_string(), b_s.to_string(), r_s.to_string()]);
    }
    let o = python().args(&args).output().expect("python");
    let problems = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "check script failed: {}", String::from_utf8_lossy(&o.stderr));
    let checked = String::from_utf8_lossy(&o.stderr).lines().filter(|l| l.starts_with("OK ")).count();
    assert_eq!(checked, files.len(), "every file checked");
    assert!(problems.trim().is_empty(), "round-trip problems:\n{problems}");
}

#[test]
fn the_checker_sees_a_lost_attribute_and_a_moved_vertex() {
    // A check that cannot fail is no check: damage a round trip on purpose.
    let Some(f) = fixture("citygml/v2/FZK-Haus-LoD2-KIT-IAI-KHH-B36-V1.gml") else { return };
    if !python_has("lxml, jsonschema, referencing, scipy") {
        return;
    }
    let tmp = tempdir();
    let json = tmp.path().join("a.city.json");
    let report = tmp.path().join("r.json");
    run_ok(&["-q", "convert", f.to_str().unwrap(), "-o", json.to_str().unwrap(), "--report", report.to_str().unwrap()]);
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let objects = doc["CityObjects"].as_object_mut().unwrap();
    let (_, b) = objects.iter_mut().find(|(_, o)| o["type"] == "Building").unwrap();
    let attrs = b["attributes"].as_object_mut().expect("FZK-Haus has attributes");
    let key = attrs.keys().next().expect("at least one").clone();
    attrs.remove(&key);
    doc["vertices"][0][0] = serde_json::json!(doc["vertices"][0][0].as_i64().unwrap() + 50);
    std::fs::write(&json, serde_json::to_vec(&doc).unwrap()).unwrap();
    let back = tmp.path().join("b.gml");
    run_ok(&["-q", "convert", json.to_str().unwrap(), "-o", back.to_str().unwrap()]);
    let o = python()
        .args([
            "-c",
            CHECK_ROUNDTRIP,
            schema_dir().to_str().unwrap(),
            f.to_str().unwrap(),
            json.to_str().unwrap(),
            back.to_str().unwrap(),
            report.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let problems = String::from_utf8_lossy(&o.stdout);
    assert!(problems.contains(&format!("attribute {key}=")), "{problems}");
    assert!(problems.contains("coordinates moved"), "{problems}");
}

fn publisher_files() -> Vec<PathBuf> {
    let dir = repo_root().join("fixtures/cityjson");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".city.json"))
        .collect();
    v.sort();
    v
}

/// cjio's view of a CityJSON file: object ids, types, attributes, parents and the real
/// coordinates of every geometry's vertices, per object and LoD.
const CJIO_DIGEST: &str = r#"
import sys, json
from cjio import cityjson
def flat(b, out):
    if isinstance(b, list):
        for x in b: flat(x, out)
    else:
        out.append(b)
    return out
def digest(path):
    cm = cityjson.reader(open(path, encoding="utf-8-sig"))
    if cm.get_version() != "2.0":
        cm.upgrade_version("2.0", 3)
    cm.decompress()
    j = cm.j; V = j["vertices"]
    out = {}
    for oid, co in j["CityObjects"].items():
        geoms = []
        for g in co.get("geometry", []):
            pts = sorted({tuple(round(c, 3) for c in V[i]) for i in flat(g["boundaries"], [])}) if len(sys.argv) < 4 else []
            sem = g.get("semantics", {})
            surf = sem.get("surfaces", [])
            faces = sorted(str(surf[v]["type"]) if v is not None else "-" for v in flat(sem.get("values", []) or [], []))
            geoms.append([g["type"], str(g["lod"]), pts, faces])
        out[oid] = {"type": co["type"], "attributes": co.get("attributes", {}), "parents": sorted(co.get("parents", [])),
                    "children": sorted(co.get("children", [])), "geometry": sorted(geoms)}
    return out
a, b = digest(sys.argv[1]), digest(sys.argv[2])
bad = [k for k in a if a[k] != b.get(k)] + [k for k in b if k not in a]
for k in bad[:3]:
    x, y = a.get(k) or {}, b.get(k) or {}
    print(k, [f for f in set(x) | set(y) if x.get(f) != y.get(f)], json.dumps(x)[:300], "\n  ->", json.dumps(y)[:300])
print(len(a), "objects compared", file=sys.stderr)
"#;

#[test]
fn publisher_files_read_and_round_trip_through_cjio_unchanged() {
    let files = publisher_files();
    assert_eq!(files.len(), 3, "fixtures/cityjson holds three publisher files");
    let cjio = python_has("cjio");
    let tmp = tempdir();
    for f in &files {
        let fs = f.to_str().unwrap();
        let info = run_ok(&["info", "--json", fs]);
        let v: serde_json::Value = serde_json::from_slice(&info.stdout).expect("info --json");
        let original: serde_json::Value = serde_json::from_slice(&std::fs::read(f).unwrap()).unwrap();
        let buildings =
            original["CityObjects"].as_object().unwrap().values().filter(|o| o["type"] == "Building").count();
        assert_eq!(v.to_string().matches("\"Building\"").count().min(1), 1, "{fs}: info names buildings: {v}");
        assert!(buildings > 0);
        let gml = tmp.path().join("x.gml");
        let back = tmp.path().join("x.city.json");
        run_ok(&["-q", "convert", fs, "-o", gml.to_str().unwrap()]);
        // Through the lenient path every geometry survives: heal's view (input layer) then back.
        run_ok(&["-q", "convert", fs, "-o", back.to_str().unwrap(), "--to", "cityjson"]);
        // heal writes CityJSON back; its own verification is the no-harm check (area, move).
        let healed = tmp.path().join("healed.city.json");
        let h = run_ok(&["heal", fs, "-o", healed.to_str().unwrap()]);
        let summary = String::from_utf8_lossy(&h.stderr);
        let moved: f64 = summary
            .split("largest move ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|v| v.parse().ok())
            .expect("heal names its largest move");
        assert!(moved <= 0.05, "{fs}: heal moved a vertex {moved} m");
        assert!(
            std::fs::read(&healed).unwrap().starts_with(b"{\"type\":\"CityJSON\""),
            "{fs}: heal wrote CityJSON back"
        );
        if cjio {
            for (out, mode) in [(&back, None), (&healed, Some("no-coords"))] {
                let mut a = vec!["-c", CJIO_DIGEST, fs, out.to_str().unwrap()];
                a.extend(mode);
                let o = python().args(&a).output().unwrap();
                assert!(o.status.success(), "{fs}: cjio: {}", String::from_utf8_lossy(&o.stderr));
                let diff = String::from_utf8_lossy(&o.stdout);
                assert!(diff.trim().is_empty(), "{fs} → {}: cjio sees a difference:\n{diff}", out.display());
            }
        }
    }
}

#[test]
fn validate_findings_on_cityjson_equal_those_on_citygml() {
    let Some(dir) = fixture("citygml/qie") else { return };
    let tmp = tempdir();
    let codes = |p: &Path| -> Vec<(String, String)> {
        let o = geofit().args(["validate", "--json", "--no-xsd", p.to_str().unwrap()]).output().unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout)
            .unwrap_or_else(|_| panic!("{}: {}", p.display(), String::from_utf8_lossy(&o.stderr)));
        let mut c: Vec<(String, String)> = v["geometry"]["findings"]
            .as_array()
            .into_iter()
            .flatten()
            // An id-less feature gets one in CityJSON (`geofit-N`): compare it as id-less.
            // 103 (ring not closed): CityJSON rings are closed implicitly, so the defect has no
            // CityJSON form (docs/decisions.md#cityjson-semantics-as-boundary-surfaces).
            .filter(|f| f["code"].to_string().trim_matches('"') != "103")
            .map(|f| {
                (
                    f["code"].to_string(),
                    f["feature"].as_str().filter(|id| !id.starts_with("geofit-")).unwrap_or("").to_string(),
                )
            })
            .collect();
        c.sort();
        c
    };
    let mut compared = 0;
    for f in common::gml_files(&dir) {
        let json = tmp.path().join("q.city.json");
        run_ok(&["-q", "convert", f.to_str().unwrap(), "-o", json.to_str().unwrap()]);
        let (a, b) = (codes(&f), codes(&json));
        assert_eq!(a, b, "{}: findings differ between CityGML and CityJSON", f.display());
        compared += usize::from(!a.is_empty());
    }
    assert!(compared >= 10, "the QIE files have findings to compare ({compared})");
}

#[test]
fn unreadable_cityjson_names_file_and_line_and_exits_3() {
    let tmp = tempdir();
    let p = tmp.path().join("bad.city.jsonl");
    std::fs::write(
        &p,
        "{\"type\":\"CityJSON\",\"version\":\"2.0\",\"transform\":{\"scale\":[1,1,1],\"translate\":[0,0,0]},\"CityObjects\":{},\"vertices\":[]}\n\
         {\"type\":\"CityJSONFeature\",\"id\":\"A\",\"CityObjects\":{\"A\":{\"type\":\"Building\",\"geometry\":[{\"type\":\"MultiSurface\",\"lod\":\"1\",\"boundaries\":[[[0,1,9]]]}]}},\"vertices\":[[0,0,0],[1,0,0],[1,1,0]]}\n",
    )
    .unwrap();
    for cmd in [vec!["info"], vec!["validate", "--no-xsd"], vec!["convert", "--to", "citygml"]] {
        let mut args = cmd.clone();
        args.push(p.to_str().unwrap());
        let o = geofit().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(3), "{cmd:?}: {err}");
        assert!(err.contains("bad.city.jsonl:2: object A: vertex index 9"), "{cmd:?}: {err}");
    }
}

/// Peak RSS (KiB) of a geofit run, by /usr/bin/time -v, and its stdout.
fn peak_rss_kib(args: &[&str]) -> Option<(u64, Vec<u8>)> {
    if !Path::new("/usr/bin/time").exists() {
        assert!(!in_ci(), "/usr/bin/time missing in CI");
        return None;
    }
    let o = std::process::Command::new("/usr/bin/time")
        .arg("-v")
        .arg(env!("CARGO_BIN_EXE_geofit"))
        .args(args)
        .output()
        .unwrap();
    assert!(o.status.code().is_some_and(|c| c <= 1), "geofit {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    let rss = err
        .lines()
        .find_map(|l| l.trim().strip_prefix("Maximum resident set size (kbytes): "))
        .and_then(|v| v.parse().ok())?;
    Some((rss, o.stdout))
}

/// A CityJSONSeq of `n` unit-cube buildings written by Python (not by geofit).
fn write_seq(path: &Path, n: usize) {
    let script = r#"
import json, sys
n = int(sys.argv[2])
with open(sys.argv[1], "w") as f:
    f.write(json.dumps({"type": "CityJSON", "version": "2.0", "transform": {"scale": [0.001]*3, "translate": [100000.0, 400000.0, 0.0]},
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"}, "CityObjects": {}, "vertices": []}) + "\n")
    faces = [[[0,3,2,1]], [[4,5,6,7]], [[0,1,5,4]], [[1,2,6,5]], [[2,3,7,6]], [[3,0,4,7]]]
    for i in range(n):
        x, y = (i % 1000) * 20000, (i // 1000) * 20000
        v = [[x+a*10000, y+b*10000, c*10000] for c in (0, 1) for a, b in ((0,0),(1,0),(1,1),(0,1))]
        f.write(json.dumps({"type": "CityJSONFeature", "id": f"b{i}", "CityObjects": {f"b{i}": {"type": "Building",
            "attributes": {"n": i}, "geometry": [{"type": "Solid", "lod": "1.2", "boundaries": [faces],
            "semantics": {"surfaces": [{"type": "GroundSurface"}, {"type": "RoofSurface"}, {"type": "WallSurface"}], "values": [[0, 1, 2, 2, 2, 2]]}}]}},
            "vertices": v}) + "\n")
"#;
    let o = python().args(["-c", script, path.to_str().unwrap(), &n.to_string()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_cityjsonseq_of_100000_features_streams_in_bounded_memory() {
    let tmp = tempdir();
    let small = tmp.path().join("s.city.jsonl");
    let big = tmp.path().join("b.city.jsonl");
    write_seq(&small, 10_000);
    write_seq(&big, 100_000);
    let size = std::fs::metadata(&big).unwrap().len() / 1024;
    let Some((info_small, _)) = peak_rss_kib(&["info", "--json", small.to_str().unwrap()]) else { return };
    let Some((info_big, out)) = peak_rss_kib(&["info", "--json", big.to_str().unwrap()]) else { return };
    let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
    assert!(
        v.to_string().contains("100000"),
        "info counts 100000 buildings: {}",
        &v.to_string()[..v.to_string().len().min(600)]
    );
    let Some((validate_big, out)) = peak_rss_kib(&["validate", "--no-xsd", big.to_str().unwrap()]) else { return };
    assert!(String::from_utf8_lossy(&out).contains("VALID"), "validate reports on the 10^5 buildings");
    eprintln!("peak RSS: info {info_small} KiB for 10^4 features, {info_big} KiB for 10^5; validate {validate_big} KiB for 10^5 ({size} KiB of CityJSONSeq)");
    // Ten times the features may not take anywhere near ten times the memory.
    assert!(
        info_big < info_small * 2 + 20_000,
        "info: peak RSS grows with the file: {info_small} KiB → {info_big} KiB"
    );
    assert!(
        info_big < size && validate_big < size,
        "peak RSS ({info_big}, {validate_big} KiB) is not below the file size {size} KiB"
    );
    assert!(validate_big < info_small * 3 + 40_000, "validate: peak RSS {validate_big} KiB grows with the file");
}
