//! Wavefront OBJ (+ MTL) writer.
//!
//! OBJ has no axis convention; CAD tools (FreeCAD, MeshLab) treat it as Z-up, so coordinates stay
//! in the source frame, minus the origin, written as shortest round-trip `f64` decimals (no `f32`
//! rounding in a text format). The header comment records the origin and CRS:
//! `# origin: X Y Z` (world = local + origin). One object `o` per node (children as
//! `parent/child`), one `usemtl` run per mesh, per-vertex colours as the common `v x y z r g b`
//! extension (alpha dropped), line sets as `l i j`.
//!
//! Vertices are shared within an object: a position (with its colour) is written once per `o`
//! and every face that uses it refers to the same `v`, while normals stay per face corner (`vn`
//! is indexed separately). Without that, MeshLab and FreeCAD see every polygon as an island and
//! every edge as a boundary until the user merges close vertices.

use std::io::Write;

use crate::{ExportError, MeshNode, Scene};

/// Writes `scene` as OBJ to `obj`; with `mtl = Some((file_name, writer))` also writes the material
/// library to `writer` and references it as `mtllib file_name` (give the name relative to the OBJ).
/// Without `mtl`, `usemtl` lines are still written (readers fall back to a default material).
pub fn write_obj(scene: &Scene, obj: &mut dyn Write, mtl: Option<(&str, &mut dyn Write)>) -> Result<(), ExportError> {
    scene.validate()?;
    let o = scene.origin;
    writeln!(obj, "# {}", scene.generator.as_deref().unwrap_or("mesh-export"))?;
    writeln!(obj, "# origin: {} {} {}", o[0], o[1], o[2])?;
    if let Some(crs) = &scene.crs {
        writeln!(obj, "# crs: {crs}")?;
    }
    writeln!(obj, "# coordinates: world = local + origin (Z-up)")?;
    if let Some((name, w)) = mtl {
        writeln!(obj, "mtllib {}", sanitize(name))?;
        write_mtl(scene, w)?;
    }
    // OBJ indices are 1-based and global over the file.
    // Readers (tobj, MeshLab) expect colours on all vertices or on none: once any mesh has
    // per-vertex colours, the others get their material's colour (light grey without one).
    let any_colors = scene
        .walk()
        .iter()
        .any(|n| n.meshes.iter().any(|m| m.colors.is_some()) || n.lines.iter().any(|l| l.colors.is_some()));
    let mut next = Counters { vertex: 1, normal: 1, any_colors };
    for n in &scene.nodes {
        write_node(scene, n, "", obj, &mut next)?;
    }
    Ok(())
}

/// Next 1-based `v` and `vn` numbers (OBJ numbers vertices and normals separately).
struct Counters {
    vertex: u64,
    normal: u64,
    /// Write a colour on every `v` line.
    any_colors: bool,
}

fn write_node(
    scene: &Scene,
    n: &MeshNode,
    prefix: &str,
    obj: &mut dyn Write,
    next: &mut Counters,
) -> Result<(), ExportError> {
    let name = format!("{prefix}{}", sanitize(&n.name));
    let has_geometry = n.meshes.iter().any(|m| !m.indices.is_empty()) || n.lines.iter().any(|l| !l.indices.is_empty());
    if has_geometry {
        writeln!(obj, "o {name}")?;
    }
    let mut shared = SharedVertices::default();
    for m in n.meshes.iter().filter(|m| !m.indices.is_empty()) {
        let number = write_vertices(obj, scene, &m.positions, m.colors.as_deref(), m.material, next, &mut shared)?;
        let nbase = next.normal;
        if let Some(nr) = &m.normals {
            next.normal += nr.len() as u64;
            for v in nr {
                let l = (v.iter().map(|&c| (c as f64) * (c as f64)).sum::<f64>()).sqrt();
                writeln!(obj, "vn {} {} {}", v[0] as f64 / l, v[1] as f64 / l, v[2] as f64 / l)?;
            }
        }
        write_usemtl(obj, scene, m.material)?;
        for t in m.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| number[i as usize]);
            if m.normals.is_some() {
                // Normals were written in the same order as the vertices of this mesh.
                let [na, nb, nc] = [t[0], t[1], t[2]].map(|i| nbase + i as u64);
                writeln!(obj, "f {a}//{na} {b}//{nb} {c}//{nc}")?;
            } else {
                writeln!(obj, "f {a} {b} {c}")?;
            }
        }
    }
    for l in n.lines.iter().filter(|l| !l.indices.is_empty()) {
        let number = write_vertices(obj, scene, &l.positions, l.colors.as_deref(), l.material, next, &mut shared)?;
        write_usemtl(obj, scene, l.material)?;
        for s in l.indices.chunks_exact(2) {
            writeln!(obj, "l {} {}", number[s[0] as usize], number[s[1] as usize])?;
        }
    }
    let child_prefix = format!("{name}/");
    for c in &n.children {
        write_node(scene, c, &child_prefix, obj, next)?;
    }
    Ok(())
}

/// Switches to the material of the faces or lines that follow (nothing for an unmaterialled part).
fn write_usemtl(obj: &mut dyn Write, scene: &Scene, material: Option<usize>) -> Result<(), ExportError> {
    if let Some(mi) = material {
        writeln!(obj, "usemtl {}", sanitize(&scene.materials[mi].name))?;
    }
    Ok(())
}

/// The colour given to uncoloured vertices when other vertices have colours.
fn fallback(scene: &Scene, material: Option<usize>) -> [f32; 4] {
    material.map(|m| scene.materials[m].rgba).unwrap_or([0.8, 0.8, 0.8, 1.0])
}

/// The `v` numbers already written in the current object, by exact position and written colour.
#[derive(Default)]
struct SharedVertices(std::collections::HashMap<([u64; 3], [u32; 3]), u64>);

/// Writes the `v` lines (local = world − origin) of positions not yet written in this object and
/// returns the OBJ number of every position, in order. Uncoloured vertices take the colour of
/// `material` when other vertices of the file have colours.
fn write_vertices(
    obj: &mut dyn Write,
    scene: &Scene,
    positions: &[[f64; 3]],
    colors: Option<&[[f32; 4]]>,
    material: Option<usize>,
    next: &mut Counters,
    shared: &mut SharedVertices,
) -> Result<Vec<u64>, ExportError> {
    let (o, fallback) = (scene.origin, fallback(scene, material));
    let mut numbers = Vec::with_capacity(positions.len());
    for (i, p) in positions.iter().enumerate() {
        let rgb = match (colors, next.any_colors) {
            (Some(c), _) => Some([c[i][0], c[i][1], c[i][2]]),
            (None, true) => Some([fallback[0], fallback[1], fallback[2]]),
            (None, false) => None,
        };
        // a material's fallback colour exists only because readers want colours on all vertices
        // or none: it does not keep a position from being shared (the face's usemtl colours it)
        let key_colour = match colors {
            Some(_) => rgb.unwrap_or_default().map(f32::to_bits),
            None => [u32::MAX; 3],
        };
        let key = (p.map(f64::to_bits), key_colour);
        if let Some(&n) = shared.0.get(&key) {
            numbers.push(n);
            continue;
        }
        let (x, y, z) = (p[0] - o[0], p[1] - o[1], p[2] - o[2]);
        match rgb {
            Some([r, g, b]) => writeln!(obj, "v {x} {y} {z} {r} {g} {b}")?,
            None => writeln!(obj, "v {x} {y} {z}")?,
        }
        shared.0.insert(key, next.vertex);
        numbers.push(next.vertex);
        next.vertex += 1;
    }
    Ok(numbers)
}

/// Writes the MTL library: every material of the scene, in order (`Kd` colour, `d` opacity).
pub fn write_mtl(scene: &Scene, mtl: &mut dyn Write) -> Result<(), ExportError> {
    writeln!(mtl, "# {}", scene.generator.as_deref().unwrap_or("mesh-export"))?;
    for m in &scene.materials {
        let [r, g, b, a] = m.rgba;
        writeln!(mtl, "newmtl {}", sanitize(&m.name))?;
        writeln!(mtl, "Ka 0 0 0")?;
        writeln!(mtl, "Kd {r} {g} {b}")?;
        writeln!(mtl, "Ks 0 0 0")?;
        writeln!(mtl, "d {a}")?;
        writeln!(mtl, "illum 1")?;
    }
    Ok(())
}

/// OBJ/MTL names end at whitespace: replace whitespace (and control characters) with `_`;
/// an empty name becomes `_`.
pub fn sanitize(name: &str) -> String {
    let s: String = name.chars().map(|c| if c.is_whitespace() || c.is_control() { '_' } else { c }).collect();
    if s.is_empty() {
        "_".into()
    } else {
        s
    }
}
