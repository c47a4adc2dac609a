//! Issue 35, repairs beyond planarity: on the QIE and NRW files with 102, 104, 302
//! (T-junction), 307 and 405 findings, `geofit heal` removes those findings, and the result
//! passes an independent check (`tests/scripts/heal_repair_check.py`, lxml + numpy: every edge
//! of a repaired shell used exactly twice in opposite directions, signed volume > 0, no
//! duplicate consecutive points); and it does no harm: no (feature, code) count grows in the
//! file, the area of every thematic surface type of every repaired building stays within 0.5 %,
//! every gml:id in a repaired building is kept.

mod common;

use common::{code, run};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The codes the repairs act on.
const REPAIRED: [i64; 5] = [102, 104, 302, 307, 405];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The independent check of one file (see the script's documentation).
fn check(f: &Path, only: &BTreeSet<String>) -> Value {
    let script = common::repo_root().join("tests/scripts/heal_repair_check.py");
    let list = only.iter().cloned().collect::<Vec<_>>().join(",");
    let mut cmd = common::python();
    cmd.arg(script).arg(f);
    if !only.is_empty() {
        cmd.args(["--only", &list]);
    }
    let o = cmd.output().expect("python3");
    assert!(o.status.success(), "heal_repair_check.py {}: {}", f.display(), String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// `geofit validate` findings per (feature gml:id, code).
fn findings(f: &Path) -> BTreeMap<(String, i64), usize> {
    common::findings_by_feature(f)
}

/// The fixtures with findings the repairs act on (the file name of a QIE file gives its code).
fn fixtures() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for q in ["i104_2", "i308_1", "t302_2"] {
        v.extend(common::fixture(&format!("citygml/qie/{q}.gml")));
    }
    for t in ["LoD2_32_327_5723_1_NW", "LoD2_32_328_5733_1_NW", "LoD2_32_332_5729_1_NW", "LoD2_32_338_5724_1_NW"] {
        v.extend(common::fixture(&format!("citygml/nrw/{t}.gml")));
    }
    v
}

#[test]
fn repairs_remove_their_findings_and_pass_an_independent_check() {
    let dir = common::tempdir();
    for src in fixtures() {
        let name = src.file_name().unwrap().to_string_lossy().to_string();
        let (out, rep) = (dir.path().join(&name), dir.path().join(format!("{name}.json")));
        let h = run(&["heal", "-q", s(&src), "-o", s(&out), "--report", s(&rep)], None);
        assert_eq!(code(&h), 0, "{name}: {}", String::from_utf8_lossy(&h.stderr));
        let report: Value = serde_json::from_slice(&std::fs::read(&rep).unwrap()).unwrap();

        let (before, after) = (findings(&src), findings(&out));
        let targets: BTreeSet<String> =
            before.keys().filter(|(_, c)| REPAIRED.contains(c)).map(|(f, _)| f.clone()).collect();
        assert!(!targets.is_empty(), "{name}: the fixture has no finding the repairs act on");
        // those findings are gone
        let left: Vec<_> = after.iter().filter(|((_, c), _)| REPAIRED.contains(c)).collect();
        assert!(left.is_empty(), "{name}: left after heal: {left:?}\nreport: {}", report["repairs"]);
        // no (feature, code) count grows
        for ((f, c), n) in &after {
            let was = before.get(&(f.clone(), *c)).copied().unwrap_or(0);
            assert!(*n <= was, "{name}: {f} has code {c} ×{n} after heal, ×{was} before");
        }
        // each building repaired is named in the report with the repairs it got
        let repairs = report["repairs"].as_object().expect("report.repairs");
        for f in targets.iter().filter(|f| *f != "(no id)") {
            let r = repairs.get(f).unwrap_or_else(|| panic!("{name}: {f} not in report.repairs"));
            assert!(!r["repairs"].as_object().unwrap().is_empty(), "{name}: {f}: {r}");
        }

        // the independent check on the repaired buildings: closed, paired edges, outward, no duplicates
        let (cb, ca) = (check(&src, &targets), check(&out, &targets));
        assert!(
            !cb["problems"].as_array().unwrap().is_empty(),
            "{name}: the independent check finds nothing wrong in the input"
        );
        assert!(ca["shells"].as_u64().unwrap() > 0, "{name}: no shell checked");
        assert!(ca["problems"].as_array().unwrap().is_empty(), "{name}: {}", ca["problems"]);

        // no harm on the repaired buildings: areas per thematic type within 0.5 %, every gml:id
        // in them kept (the other buildings of a tile are the planarity heal's: tests/heal.rs,
        // tests/heal_semantics.rs)
        let (all_b, all_a) = (check(&src, &BTreeSet::new()), check(&out, &BTreeSet::new()));
        for (unit, types) in all_b["areas"].as_object().unwrap() {
            if !targets.contains(unit) && !targets.contains("(no id)") {
                continue;
            }
            for (t, a0) in types.as_object().unwrap() {
                let a0 = a0.as_f64().unwrap();
                let a1 = all_a["areas"][unit][t].as_f64().unwrap_or(0.0);
                assert!(a0 == 0.0 || (a1 / a0 - 1.0).abs() < 0.005, "{name}: {unit} {t} area {a0} → {a1}");
            }
        }
        let ids = |v: &Value| -> BTreeSet<String> {
            let m = v["ids"].as_object().unwrap();
            m.iter().filter(|(_, u)| u.as_str().is_some_and(|u| targets.contains(u))).map(|(k, _)| k.clone()).collect()
        };
        assert!(!ids(&all_b).is_empty() || targets.contains("(no id)"), "{name}: no gml:id in the repaired buildings");
        let lost: Vec<String> = ids(&all_b).difference(&ids(&all_a)).cloned().collect();
        assert!(lost.is_empty(), "{name}: gml:ids lost: {lost:?}");
    }
}

/// The repairs are refused, not half-done, where they would make a building worse: QIE i302_1
/// (a cube without its bottom face) and i101_1 (a face with 2 points) keep their geometry and
/// the report says why.
#[test]
fn unrepairable_findings_are_left_alone_and_reported() {
    let dir = common::tempdir();
    for q in ["i302_1", "i101_1"] {
        let Some(src) = common::fixture(&format!("citygml/qie/{q}.gml")) else { continue };
        let (out, rep) = (dir.path().join(format!("{q}.gml")), dir.path().join(format!("{q}.json")));
        let h = run(&["heal", "-q", s(&src), "-o", s(&out), "--report", s(&rep)], None);
        assert!(code(&h) == 0 || code(&h) == 1, "{q}: {}", String::from_utf8_lossy(&h.stderr));
        if !rep.exists() {
            continue; // refused as a whole: nothing written
        }
        let report: Value = serde_json::from_slice(&std::fs::read(&rep).unwrap()).unwrap();
        let recs: Vec<&Value> = report["repairs"].as_object().unwrap().values().collect();
        assert_eq!(recs.len(), 1, "{q}: {}", report["repairs"]);
        assert!(recs[0]["repairs"].as_object().unwrap().is_empty(), "{q}: {}", recs[0]);
        assert!(!recs[0]["left_alone"].as_object().unwrap().is_empty(), "{q}: {}", recs[0]);
        assert!(recs[0]["refused"].is_string(), "{q}: {}", recs[0]);
        if out.exists() {
            assert_eq!(findings(&src), findings(&out), "{q}: the findings changed");
        }
    }
}
