//! CityGML I/O end to end: `geofit info` on every shared fixture against independent counts
//! (Python xml.etree script + the fixtures README table), version/BOM/stdin, and bad input.
//! The library-level checks (C14N round trip with lxml, coordinate edits, XLinks, streaming)
//! are in `crates/citygml-io/tests/fixtures.rs`.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

fn citygml_root() -> Option<PathBuf> {
    common::fixture("citygml")
}

/// Every `.gml` under fixtures/citygml, sorted.
fn all_fixtures() -> Vec<PathBuf> {
    let Some(root) = citygml_root() else { return Vec::new() };
    let out = common::gml_files(&root);
    assert!(out.len() >= 60, "expected the 66 CityGML fixtures, found {}", out.len());
    out
}

fn rel(p: &Path) -> String {
    p.strip_prefix(citygml_root().unwrap()).unwrap().to_string_lossy().into_owned()
}

fn info_json(p: &Path) -> (i32, Value, String) {
    let o = common::run(&["info", "--json", p.to_str().unwrap()], None);
    let code = common::code(&o);
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    let v: Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{}: info --json is not JSON ({e}); stderr: {stderr}", p.display()));
    (code, v, stderr)
}

fn python_counts(files: &[PathBuf]) -> BTreeMap<String, Value> {
    let script = common::repo_root().join("tests/scripts/citygml_counts.py");
    let o = common::python().arg(script).args(files).output().expect("python3");
    assert!(o.status.success(), "citygml_counts.py failed: {}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    v.as_array().unwrap().iter().map(|c| (c["file"].as_str().unwrap().to_string(), c.clone())).collect()
}

fn feature(v: &Value, kind: &str) -> u64 {
    v["feature_types"][kind].as_u64().unwrap_or(0)
}

#[test]
fn every_fixture_reads_and_counts_match_independent_script() {
    let files = all_fixtures();
    if files.is_empty() || !common::tool("python3") {
        return;
    }
    let truth = python_counts(&files);
    for f in &files {
        let name = rel(f);
        let (code, v, stderr) = info_json(f);
        // qie/i101_1 is the one fixture with a 3-position ring (QIE 101): readable, exit 1, listed.
        if name == "qie/i101_1.gml" {
            assert_eq!(code, 1, "{name}: {stderr}");
            assert!(stderr.contains(&format!("{}:12:11: gml:LinearRing has 3 positions", f.display())), "{stderr}");
        } else {
            assert_eq!(code, 0, "{name}: {stderr}");
        }
        let t = &truth[f.to_str().unwrap()];
        assert_eq!(v["version"], t["version"], "{name}: version");
        assert_eq!(feature(&v, "Building"), t["buildings"].as_u64().unwrap(), "{name}: buildings");
        assert_eq!(feature(&v, "BuildingPart"), t["building_parts"].as_u64().unwrap(), "{name}: parts");
        for key in ["solids", "polygons", "rings", "interior_rings", "points"] {
            assert_eq!(v[key], t[key], "{name}: {key}");
        }
        assert_eq!(v["xlinks_resolved"], t["xlinks"], "{name}: xlinks");
        assert_eq!(v["unresolved_xlinks"], 0, "{name}");
    }
}

/// The `Bldg / BPart / Solid / Polygon` column of shared/fixtures/README.md.
#[test]
fn counts_match_fixture_readme_table() {
    let Some(readme) = common::fixture("README.md") else { return };
    let text = std::fs::read_to_string(readme).unwrap();
    let mut rows = 0;
    for line in text.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 7 || !cells[1].starts_with('`') || !cells[1].ends_with(".gml`") {
            continue;
        }
        let name = cells[1].trim_matches('`');
        let nums: Vec<u64> = cells[5].split('/').map(|s| s.trim().parse().unwrap()).collect();
        let Some(p) = common::fixture(&format!("citygml/{name}")) else { continue };
        let (_, v, _) = info_json(&p);
        assert_eq!(v["version"].as_str().unwrap(), cells[2], "{name}: version");
        assert_eq!(feature(&v, "Building"), nums[0], "{name}: buildings");
        assert_eq!(feature(&v, "BuildingPart"), nums[1], "{name}: parts");
        assert_eq!(v["solids"].as_u64().unwrap(), nums[2], "{name}: solids");
        assert_eq!(v["polygons"].as_u64().unwrap(), nums[3], "{name}: polygons");
        rows += 1;
    }
    assert_eq!(rows, 66, "README table rows checked");
}

#[test]
fn version_comes_from_namespaces_and_bom_is_accepted() {
    let Some(f) = common::fixture("citygml/ogc-xlink/2_SimpleBuilding_Roof_Overhangs/CityGML_2.gml") else { return };
    let (code, v, _) = info_json(&f);
    assert_eq!((code, v["version"].as_str().unwrap()), (0, "1.0"));
    let Some(f) = common::fixture("citygml/ogc-xlink/1_SimpleBuilding/CityGML_2.gml") else { return };
    assert!(std::fs::read(&f).unwrap().starts_with(b"\xEF\xBB\xBF"));
    let (code, v, _) = info_json(&f);
    assert_eq!((code, v["version"].as_str().unwrap()), (0, "2.0"));
    // stdin
    let o = common::run(&["info", "--json", "-"], Some(&std::fs::read(&f).unwrap()));
    assert_eq!(common::code(&o), 0);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["polygons"], 7);
}

/// One line on stderr naming FILE:LINE:COL, the expected exit code, no panic — from `geofit
/// info`, and from `geofit validate` (geometric checks; the XSD pass has its own messages) with
/// the same exit code; a geometry finding (exit 1) is listed by `validate` on stdout at the same
/// position, under `validate_code`.
fn expect_error(dir: &Path, name: &str, bytes: &[u8], exit: i32, line: usize, col: usize, what: &str) {
    expect_error_code(dir, name, bytes, exit, line, col, what, None)
}

#[allow(clippy::too_many_arguments)]
fn expect_error_code(
    dir: &Path,
    name: &str,
    bytes: &[u8],
    exit: i32,
    line: usize,
    col: usize,
    what: &str,
    validate_code: Option<&str>,
) {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    let o = common::run(&["info", p.to_str().unwrap()], None);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(common::code(&o), exit, "{name}: {stderr}");
    assert!(!stderr.contains("panicked"), "{name}: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{name}: one line expected: {stderr}");
    let at = format!("{}:{line}:{col}: ", p.display());
    assert!(lines[0].contains(&at), "{name}: expected position {at} in: {stderr}");
    assert!(lines[0].contains(what), "{name}: expected '{what}' in: {stderr}");

    let o = common::run(&["-q", "validate", "--no-xsd", p.to_str().unwrap()], None);
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert_eq!(common::code(&o), exit, "validate {name}: {out}{err}");
    assert!(!err.contains("panicked"), "validate {name}: {err}");
    match validate_code {
        None => {
            let lines: Vec<&str> = err.lines().collect();
            assert_eq!(lines.len(), 1, "validate {name}: one line expected: {err}");
            assert!(
                lines[0].contains(&at) && lines[0].contains(what),
                "validate {name}: expected {at}…{what} in: {err}"
            );
        }
        Some(code) => {
            let hit = out
                .lines()
                .find(|l| l.contains(&at))
                .unwrap_or_else(|| panic!("validate {name}: no finding at {at}: {out}"));
            assert!(hit.contains(code), "validate {name}: expected {code} in: {hit}");
        }
    }
}

#[test]
fn bad_input_gives_one_line_with_position() {
    // An NRW tile: CityGML 1.0, one posList per ring.
    let Some(f) = common::fixture("citygml/nrw/LoD2_32_324_5729_1_NW.gml") else { return };
    let good = std::fs::read_to_string(&f).unwrap();
    let dir = common::tempdir();
    let d = dir.path();
    // Position of the first ring's <gml:posList ...> (1-based line/column) in the unmodified text
    // (the tile's first posList is a terrain-intersection curve).
    let first_ring = good.find("<gml:LinearRing").unwrap();
    let at = first_ring + good[first_ring..].find("<gml:posList").unwrap();
    let line = good[..at].matches('\n').count() + 1;
    let col = at - good[..at].rfind('\n').map(|i| i + 1).unwrap_or(0) + 1;

    expect_error(d, "empty.gml", b"", 3, 1, 1, "empty file");
    let mut garbage: Vec<u8> = (0..4096u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
    garbage[0] = 0x89;
    expect_error(d, "binary.gml", &garbage, 3, 1, 1, "not an XML document");
    // Truncated in the middle of the file: cut at the first posList.
    let cut = &good[..at + 20];
    let cut_lines = cut.matches('\n').count() + 1;
    let o = {
        let p = d.join("truncated.gml");
        std::fs::write(&p, cut).unwrap();
        common::run(&["info", p.to_str().unwrap()], None)
    };
    assert_eq!(common::code(&o), 3);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains(&format!("truncated.gml:{cut_lines}:")) && e.contains("end of file"), "{e}");
    assert_eq!(e.lines().count(), 1);
    let same_from_validate = |name: &str, want: &str| {
        let o = common::run(&["-q", "validate", "--no-xsd", d.join(name).to_str().unwrap()], None);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(common::code(&o), 3, "validate {name}: {e}");
        assert_eq!(e.lines().count(), 1, "validate {name}: {e}");
        assert!(e.contains(want), "validate {name}: expected {want} in {e}");
    };
    same_from_validate("truncated.gml", &format!("truncated.gml:{cut_lines}:"));
    // Truncated at an element boundary: the open root is named.
    let cut2 = &good[..good.rfind("</core:cityObjectMember>").unwrap()];
    let p = d.join("truncated2.gml");
    std::fs::write(&p, cut2).unwrap();
    let o = common::run(&["info", p.to_str().unwrap()], None);
    assert_eq!(common::code(&o), 3);
    assert!(String::from_utf8_lossy(&o.stderr).contains("is not closed"), "{}", String::from_utf8_lossy(&o.stderr));
    same_from_validate("truncated2.gml", "is not closed");

    let wrong = good.replace("\"http://www.opengis.net/citygml/1.0\"", "\"http://example.com/not-citygml\"");
    assert_ne!(wrong, good);
    let root_at = good.find("<core:CityModel").or_else(|| good.find("<CityModel")).unwrap();
    let rl = good[..root_at].matches('\n').count() + 1;
    expect_error(d, "wrongns.gml", wrong.as_bytes(), 3, rl, 1, "not a CityGML core namespace");

    // Missing coordinates: the first posList element removed.
    let end = at + good[at..].find("</gml:posList>").unwrap() + "</gml:posList>".len();
    let missing = format!("{}{}", &good[..at], &good[end..]);
    let ring_at = good[..at].rfind("<gml:LinearRing").unwrap();
    let rline = good[..ring_at].matches('\n').count() + 1;
    let rcol = ring_at - good[..ring_at].rfind('\n').map(|i| i + 1).unwrap_or(0) + 1;
    expect_error(d, "missing.gml", missing.as_bytes(), 3, rline, rcol, "no coordinates");

    // Odd coordinate count: one value dropped from the first posList.
    let text_start = at + good[at..].find('>').unwrap() + 1;
    let text_end = at + good[at..].find("</gml:posList>").unwrap();
    let mut vals: Vec<&str> = good[text_start..text_end].split_whitespace().collect();
    vals.pop();
    let odd = format!("{}{}{}", &good[..text_start], vals.join(" "), &good[text_end..]);
    expect_error(d, "odd.gml", odd.as_bytes(), 3, line, col, "not a multiple of srsDimension 3");

    // A ring of 2 positions: readable, but a geometry finding (exit 1), listed with position.
    let two = format!("{}0 0 0 1 1 1{}", &good[..text_start], &good[text_end..]);
    // validate: not closed comes first, as in val3dity (103 is checked before 101)
    expect_error_code(d, "two.gml", two.as_bytes(), 1, rline, rcol, "has 2 positions", Some("103 RING_NOT_CLOSED"));
    // two points, closed (3 positions): 101
    let two_closed = format!("{}0 0 0 1 1 1 0 0 0{}", &good[..text_start], &good[text_end..]);
    expect_error_code(
        d,
        "two_closed.gml",
        two_closed.as_bytes(),
        1,
        rline,
        rcol,
        "has 3 positions",
        Some("101 TOO_FEW_POINTS"),
    );

    // Not a number.
    let nan = format!("{}0 0 zero{}", &good[..text_start], &good[text_end..]);
    expect_error(d, "nan.gml", nan.as_bytes(), 3, line, col + (text_start - at) + 4, "'zero' is not a number");
}

/// Solids are counted where they are defined: a `lod2Solid xlink:href` copy is not a second
/// solid, whatever its number of faces (a one-face solid used to be counted twice), and a face
/// XLink to a city object is reported with what the id names.
#[test]
fn info_counts_a_referenced_solid_once() {
    let face = "<gml:surfaceMember><gml:Polygon gml:id=\"f\"><gml:exterior><gml:LinearRing><gml:posList>\
                0 0 0 1 0 0 1 1 0 0 1 0 0 0 0</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>";
    let doc = format!(
        "<?xml version=\"1.0\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\" \
         xmlns:bldg=\"http://www.opengis.net/citygml/building/2.0\" xmlns:gml=\"http://www.opengis.net/gml\" \
         xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n\
         <core:cityObjectMember><bldg:Building gml:id=\"a\"><bldg:lod2Solid><gml:Solid gml:id=\"S\"><gml:exterior><gml:Shell>\
         {face}</gml:Shell></gml:exterior></gml:Solid></bldg:lod2Solid></bldg:Building></core:cityObjectMember>\n\
         <core:cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod2Solid xlink:href=\"#S\"/></bldg:Building></core:cityObjectMember>\n\
         <core:cityObjectMember><bldg:Building gml:id=\"c\"><bldg:lod2MultiSurface><gml:MultiSurface>\
         <gml:surfaceMember xlink:href=\"#a\"/></gml:MultiSurface></bldg:lod2MultiSurface></bldg:Building></core:cityObjectMember>\n\
         </core:CityModel>\n"
    );
    let dir = common::tempdir();
    let p = dir.path().join("ref.gml");
    std::fs::write(&p, &doc).unwrap();
    let (code, v, stderr) = info_json(&p);
    assert_eq!((v["solids"].as_u64(), v["polygons"].as_u64()), (Some(1), Some(1)), "{v}");
    assert_eq!(code, 1, "the reference to a building is a finding: {stderr}");
    assert!(
        stderr.contains(&format!("{}:5:", p.display()))
            && stderr.contains("xlink:href=\"#a\" points to <bldg:Building>, not a geometry"),
        "{stderr}"
    );
}

/// `geofit info --json DIR` (issue 14): one JSON line per file, equal to the one-file report
/// plus its `schema` key, in path order, then a summary recounted here from the one-file runs'
/// exit codes; the text form is each file's block and a blank line, then a summary line.
#[test]
fn info_on_a_directory_equals_the_single_file_runs() {
    let files = all_fixtures();
    if files.is_empty() {
        return;
    }
    let root = citygml_root().unwrap();
    let o = common::run(&["-q", "info", "--json", root.to_str().unwrap()], None);
    let batch_code = common::code(&o);
    let stdout = String::from_utf8(o.stdout).unwrap();
    let mut lines: Vec<Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let summary = lines.pop().unwrap();
    assert_eq!(lines.len(), files.len());
    let (mut clean, mut with_findings, mut worst) = (0, 0, 0);
    let mut text_want = String::new();
    for (f, line) in files.iter().zip(&lines) {
        let (code, single, _) = info_json(f);
        assert_eq!(line["schema"], "geofit-info/1");
        assert_eq!(*line, single, "{}: the line is the one-file report", f.display());
        match code {
            0 => clean += 1,
            1 => with_findings += 1,
            c => panic!("{}: exit {c}", f.display()),
        }
        worst = worst.max(code);
        let t = common::run(&["info", f.to_str().unwrap()], None);
        text_want += &format!("{}\n", String::from_utf8(t.stdout).unwrap());
    }
    assert_eq!(batch_code, worst);
    let s = &summary["summary"];
    assert_eq!(summary["schema"], "geofit-info/1");
    assert_eq!((s["files"].as_u64(), s["clean"].as_u64()), (Some(files.len() as u64), Some(clean)));
    assert_eq!((s["with_findings"].as_u64(), s["unreadable"].as_u64()), (Some(with_findings), Some(0)));
    let o = common::run(&["-q", "info", root.to_str().unwrap()], None);
    let text = String::from_utf8(o.stdout).unwrap();
    let (body, last) = text.trim_end().rsplit_once('\n').unwrap();
    assert_eq!(format!("{body}\n"), text_want);
    assert!(
        last.starts_with(&format!(
            "summary: {} files: {clean} without findings, {with_findings} with findings, 0 unreadable;",
            files.len()
        )),
        "{last}"
    );
}

/// A file that cannot be read among good ones: its own error line (exit 3), the others summarised.
#[test]
fn info_reports_a_bad_file_in_its_place() {
    let Some(good) = common::fixture("citygml/v2/FZK-Haus-LoD2-KIT-IAI-KHH-B36-V1.gml") else { return };
    let tmp = common::tempdir();
    let bad = tmp.path().join("bad.gml");
    std::fs::write(&bad, "<core:CityModel").unwrap();
    let args = ["-q", "info", "--json", bad.to_str().unwrap(), good.to_str().unwrap()];
    let o = common::run(&args, None);
    assert_eq!(common::code(&o), 3, "{}", String::from_utf8_lossy(&o.stderr));
    let lines: Vec<Value> =
        String::from_utf8(o.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[0]["exit"], 3);
    assert!(lines[0]["error"].as_str().unwrap().contains("bad.gml"), "{}", lines[0]);
    let (_, single, _) = info_json(&good);
    assert_eq!(lines[1]["polygons"], single["polygons"]);
    assert_eq!(lines[2]["summary"]["unreadable"], 1);
}
