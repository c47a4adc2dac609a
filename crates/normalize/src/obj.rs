//! OBJ sketch → polygon soup (spec §8.1: a 3D sketch drawn by eye in any modeller, exported as OBJ).
//!
//! Every OBJ object/group (`o`/`g`) becomes one solid (a room); faces keep their polygons (no
//! triangulation). A wall between two rooms may be drawn once per room (two opposite faces): it
//! becomes one face shared by both rooms. Face provenance: `NAME/fK` (K = 1-based face number within
//! the object); node provenance: the 0-based OBJ vertex index (`v` lines in file order).

use crate::soup::{Soup, SoupPolygon, SoupSolid};
use popa3d_model::{FaceSource, SolidKind, VertexSource};
use std::collections::HashMap;

/// Why an OBJ file cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ObjError(pub String);

/// Reads an OBJ sketch into one soup (all objects together, one solid per object/group).
pub fn read_sketch(bytes: &[u8], name: &str) -> Result<Soup, ObjError> {
    // Global vertex indices for provenance: tobj re-indexes per object, so map positions back to the
    // first `v` line with exactly the same (f32-parsed, like tobj) coordinates.
    let text = String::from_utf8_lossy(bytes);
    let mut global: HashMap<[u32; 3], u32> = HashMap::new();
    let totals = ElementCounts::of(&text);
    let mut seen = ElementCounts::default();
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it.take(3).filter_map(|x| x.parse::<f32>().ok()).collect();
                if c.len() != 3 {
                    return Err(ObjError(format!("{name}:{}: a `v` line needs three numbers", ln + 1)));
                }
                global.entry([c[0].to_bits(), c[1].to_bits(), c[2].to_bits()]).or_insert(seen.v as u32);
            }
            // the lines tobj resolves indices of (it skips `p` lines, so they are not checked)
            Some("f" | "l") => {
                for reference in it {
                    check_reference(reference, &seen, &totals)
                        .map_err(|why| ObjError(format!("{name}:{}: face vertex {reference:?}: {why}", ln + 1)))?;
                }
            }
            _ => {}
        }
        seen.count(line);
    }
    let opts = tobj::LoadOptions { single_index: false, triangulate: false, ignore_points: true, ignore_lines: true };
    let mut rd = std::io::BufReader::new(bytes);
    let (models, _) = tobj::load_obj_buf(&mut rd, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| ObjError(format!("{name}: not a readable OBJ file: {e}")))?;
    if models.is_empty() {
        return Err(ObjError(format!("{name}: no faces")));
    }
    let mut soup = Soup { name: name.to_string(), ..Default::default() };
    for (si, m) in models.iter().enumerate() {
        let oname = if m.name.is_empty() { format!("object{}", si + 1) } else { m.name.clone() };
        soup.solids.push(SoupSolid { kind: SolidKind::Room, name: Some(oname.clone()) });
        let mesh = &m.mesh;
        let arities: Vec<u32> =
            if mesh.face_arities.is_empty() { vec![3; mesh.indices.len() / 3] } else { mesh.face_arities.clone() };
        let mut off = 0usize;
        for (fi, &a) in arities.iter().enumerate() {
            let idx = &mesh.indices[off..off + a as usize];
            off += a as usize;
            let mut ring = Vec::with_capacity(idx.len());
            let mut src = Vec::with_capacity(idx.len());
            for &i in idx {
                let i = i as usize;
                let p = [mesh.positions[3 * i], mesh.positions[3 * i + 1], mesh.positions[3 * i + 2]];
                let g = global.get(&[p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]).copied().unwrap_or(u32::MAX);
                ring.push([p[0] as f64, p[1] as f64, p[2] as f64]);
                src.push(VertexSource::Obj { vertex: g });
            }
            let pid = format!("{oname}/f{}", fi + 1);
            soup.polygons.push(SoupPolygon {
                rings: vec![ring],
                vertex_sources: vec![src],
                solid: si,
                source: FaceSource { polygon: pid.clone(), ..FaceSource::default() },
                locator: format!("{name}: object {} face {}", input_limits::quote(&oname), fi + 1),
                parent: None,
            });
            soup.source_rings += 1;
        }
    }
    Ok(soup)
}

/// How many positions (`v`), texture coordinates (`vt`) and normals (`vn`) a text declares.
#[derive(Default)]
struct ElementCounts {
    v: usize,
    vt: usize,
    vn: usize,
}

impl ElementCounts {
    fn of(text: &str) -> ElementCounts {
        let mut c = ElementCounts::default();
        for line in text.lines() {
            c.count(line);
        }
        c
    }

    fn count(&mut self, line: &str) {
        match line.split_whitespace().next() {
            Some("v") => self.v += 1,
            Some("vt") => self.vt += 1,
            Some("vn") => self.vn += 1,
            _ => {}
        }
    }
}

/// Checks one face vertex `v`, `v/vt`, `v//vn` or `v/vt/vn` before tobj sees it: every index a
/// whole number naming an element the file declares (1-based from the start, or negative
/// counting back from the elements `seen` before the line). tobj turns an index outside these
/// into a wrapped offset (`f 1//-10` with one normal: an integer overflow, found by fuzzing).
fn check_reference(reference: &str, seen: &ElementCounts, totals: &ElementCounts) -> Result<(), String> {
    let kinds =
        [("position", seen.v, totals.v), ("texture coordinate", seen.vt, totals.vt), ("normal", seen.vn, totals.vn)];
    let parts: Vec<&str> = reference.split('/').collect();
    if parts.len() > 3 || parts[0].is_empty() {
        return Err("not v, v/vt, v//vn or v/vt/vn".into());
    }
    for (part, (kind, before, total)) in parts.into_iter().zip(kinds) {
        if part.is_empty() {
            continue;
        }
        let i: i64 = part.parse().map_err(|_| format!("{kind} index {part:?} is not a whole number"))?;
        let fits = match i {
            0 => false,
            i if i > 0 => i as u64 <= total as u64,
            i => i.unsigned_abs() <= before as u64,
        };
        if !fits {
            let declared = if i > 0 { total } else { before };
            return Err(format!(
                "{kind} index {i} is outside the {declared} declared{}",
                if i < 0 { " before it" } else { "" }
            ));
        }
    }
    Ok(())
}

/// The origin of a sketch's model. Sketches are drawn in local coordinates, so each axis keeps 0
/// unless the sketch's centre lies more than 1 km from it; then it is the centre floored to metres,
/// which keeps coordinates small for the adjustment without moving a local sketch.
pub fn sketch_origin(soup: &Soup) -> [f64; 3] {
    let mut origin = [0.0f64; 3];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in soup.polygons.iter().flat_map(|p| p.rings.iter().flatten()) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    for k in 0..3 {
        let c = (lo[k] + hi[k]) / 2.0;
        if c.abs() > 1000.0 {
            origin[k] = c.floor();
        }
    }
    origin
}

#[cfg(test)]
mod tests {
    use super::read_sketch;

    const SQUARE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n";

    #[test]
    fn face_indices_outside_the_declared_elements_are_named() {
        for (face, why) in [
            ("f 1//-10 2 3 4", "normal index -10 is outside the 1 declared before it"),
            ("f 0 1 2", "position index 0 is outside the 4 declared"),
            ("f 1 2 99999999999999999 3", "position index 99999999999999999 is outside the 4 declared"),
            ("f -5 1 2", "position index -5 is outside the 4 declared before it"),
            ("f 1/x 2 3", "texture coordinate index \"x\" is not a whole number"),
        ] {
            let e = read_sketch(format!("{SQUARE}{face}\n").as_bytes(), "room.obj").unwrap_err().to_string();
            assert!(e.starts_with("room.obj:6: face vertex") && e.ends_with(why), "{face}: {e}");
        }
    }

    #[test]
    fn relative_and_absolute_indices_still_read() {
        for face in ["f 1 2 3 4", "f -4 -3 -2 -1", "f 1//1 2//1 3//-1 4//1", "p 0\nf 1 2 3 4"] {
            let soup = read_sketch(format!("{SQUARE}{face}\n").as_bytes(), "room.obj").unwrap();
            assert_eq!(soup.polygons.len(), 1, "{face}");
            assert_eq!(soup.polygons[0].rings[0].len(), 4, "{face}");
        }
    }

    /// Every reproducer the fuzzer found (fuzz/regressions/obj) reads or fails with an error,
    /// never a panic.
    #[test]
    fn fuzz_regressions_do_not_panic() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/regressions/obj");
        let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
        assert!(!files.is_empty(), "no reproducers in {}", dir.display());
        for f in files {
            let _ = read_sketch(&std::fs::read(&f).unwrap(), "fuzz.obj");
        }
    }
}
