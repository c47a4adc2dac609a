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
    let mut global: HashMap<[u32; 3], u32> = HashMap::new();
    let mut nv = 0u32;
    for (ln, line) in String::from_utf8_lossy(bytes).lines().enumerate() {
        let mut it = line.split_whitespace();
        if it.next() == Some("v") {
            let c: Vec<f32> = it.take(3).filter_map(|x| x.parse::<f32>().ok()).collect();
            if c.len() != 3 {
                return Err(ObjError(format!("{name}:{}: a `v` line needs three numbers", ln + 1)));
            }
            global.entry([c[0].to_bits(), c[1].to_bits(), c[2].to_bits()]).or_insert(nv);
            nv += 1;
        }
    }
    let opts = tobj::LoadOptions { single_index: false, triangulate: false, ignore_points: true, ignore_lines: true, ..Default::default() };
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
        let arities: Vec<u32> = if mesh.face_arities.is_empty() { vec![3; mesh.indices.len() / 3] } else { mesh.face_arities.clone() };
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
