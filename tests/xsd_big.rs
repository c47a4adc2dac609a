//! Issue 40: XSD validation of big files (docs/decisions.md#xsd-validation-of-big-files). From
//! 64 MiB on, `validate` checks the schema through libxml2's streaming reader; both ways lift
//! libxml2's dictionary limit, past which every further gml:id was a false "not a valid value of
//! the atomic type 'xs:ID'". Truth: xmllint (the same libxml2, as a separate program) and the
//! verdict on the small source file.

mod common;

use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `validate --json --no-geometry` with the streaming threshold given (None: the default).
fn geofit_xsd(file: &Path, xsd: &Path, stream_from: Option<&str>) -> (i32, Value) {
    let mut cmd = common::geofit();
    cmd.args(["-q", "validate", "--json", "--no-geometry", "--schemas"]).arg(xsd).arg(file);
    if let Some(n) = stream_from {
        cmd.env("GEOFIT_XSD_STREAM_BYTES", n);
    }
    let o = cmd.output().unwrap();
    let r: Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{}: no JSON ({e}): {}", file.display(), String::from_utf8_lossy(&o.stderr)));
    let r = if r["files"].is_array() { r["files"][0].clone() } else { r };
    assert!(r["xsd"]["checked"].as_bool().unwrap(), "{}: XSD not checked: {}", file.display(), r["xsd"]);
    (common::code(&o), r)
}

fn lines_of(r: &Value) -> BTreeSet<u64> {
    r["xsd"]["errors"].as_array().unwrap().iter().map(|e| e["line"].as_u64().unwrap()).collect()
}

/// Lines xmllint reports schema errors on (`--huge`: xmllint's own default limits are the bug).
fn xmllint_lines(file: &Path, wrapper: &Path) -> (bool, BTreeSet<u64>) {
    let o = Command::new("xmllint")
        .args(["--noout", "--nonet", "--huge", "--schema"])
        .arg(wrapper)
        .arg(file)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let name = file.to_str().unwrap();
    let lines =
        err.lines().filter_map(|l| l.strip_prefix(name)?.strip_prefix(':')?.split(':').next()?.parse().ok()).collect();
    (o.status.code() == Some(0), lines)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn streaming_check_finds_what_xmllint_finds() {
    let (Some(xsd), true) = (common::shared_xsd(), common::tool("xmllint")) else { return };
    let tmp = common::tempdir();
    for (rel, v) in [
        ("citygml/nrw/LoD2_32_324_5729_1_NW.gml", "1.0"),
        ("citygml/v3/FZK-Haus-LoD2-KIT-IAI-KHH-B36-V1__v3.gml", "3.0"),
    ] {
        let Some(src) = common::fixture(rel) else { return };
        let text = std::fs::read_to_string(&src).unwrap();
        let stem = format!("v{}", v.replace('.', ""));
        let k = text.find("gml:id=\"").unwrap() + 8;
        let bad_id = write(tmp.path(), &format!("{stem}_badid.gml"), &format!("{}1{}", &text[..k], &text[k..]));
        let p = text.find("<gml:posList").or_else(|| text.find("<gml:pos")).unwrap();
        let no_ring =
            write(tmp.path(), &format!("{stem}_element.gml"), &format!("{}<gml:bogus/>{}", &text[..p], &text[p..]));
        let wrapper = xsd.join(format!("citygml-{v}.xsd"));
        let (code, r) = geofit_xsd(&src, &xsd, Some("0"));
        let lines = lines_of(&r);
        assert!(
            lines.is_empty() && code == 0 && xmllint_lines(&src, &wrapper).0,
            "{rel}: valid source, streaming: {lines:?}"
        );
        for f in [bad_id, no_ring] {
            let (lint_ok, lint_lines) = xmllint_lines(&f, &wrapper);
            assert!(!lint_ok && !lint_lines.is_empty(), "{}: xmllint should reject it", f.display());
            let (code_tree, tree) = geofit_xsd(&f, &xsd, None);
            let (code_stream, stream) = geofit_xsd(&f, &xsd, Some("0"));
            assert_eq!((code_tree, code_stream), (1, 1), "{}: both ways find it invalid", f.display());
            assert_eq!(lines_of(&stream), lint_lines, "{}: streaming lines vs xmllint", f.display());
            assert_eq!(lines_of(&tree), lint_lines, "{}: tree lines vs xmllint", f.display());
        }
    }
}

/// A valid NRW tile ×250 (311 MB, every gml:id made unique): valid, as its 1.2 MB source, with
/// no finding; before, 1.8 GB of tree and, past libxml2's 10 MB dictionary, false xs:ID errors.
#[test]
fn a_valid_300_mb_tile_is_valid() {
    let (Some(xsd), Some(src)) = (common::shared_xsd(), common::fixture("citygml/nrw/LoD2_32_332_5729_1_NW.gml"))
    else {
        return;
    };
    let tmp = common::tempdir();
    let big = tmp.path().join("x250.gml");
    let copies = common::repo_root().join("benches/citygml_copies.py");
    let o = common::python().arg(&copies).arg(&src).arg(&big).arg("250").output().unwrap();
    assert!(o.status.success(), "citygml_copies.py: {}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::metadata(&big).unwrap().len() > 300_000_000);
    let (code_src, small) = geofit_xsd(&src, &xsd, None);
    let t = std::time::Instant::now();
    let (code_big, r) = geofit_xsd(&big, &xsd, None);
    assert_eq!((code_src, small["xsd"]["valid"].as_bool()), (0, Some(true)), "the source tile is valid");
    assert_eq!(r["xsd"]["errors"].as_array().unwrap().len(), 0, "false findings: {}", r["xsd"]["errors"][0]);
    assert_eq!((code_big, r["xsd"]["valid"].as_bool()), (0, Some(true)));
    assert!(t.elapsed().as_secs() < 120, "311 MB took {:?}", t.elapsed());
}
