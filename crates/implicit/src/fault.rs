//! Faults cut the neighbourhood graph of the mesh (seed §2.1: "Diskontinuitäten ... durch
//! Diskontinuitäten im Graphen des Tetraedergitters").
//!
//! A face between two tetrahedra is cut when the segment joining their centroids crosses a fault
//! triangle. Each vertex is then duplicated once per group of its tetrahedra that stay connected
//! through uncut faces around it: the two sides of the fault get separate unknowns, so φ jumps
//! across it, and the roughness rows (built on faces shared by index) no longer couple them. A
//! fault that ends inside the domain leaves the vertices around its tip connected, so φ is
//! continuous there.

use crate::geom::{segment_hits_triangle, sub, V3};
use crate::mesh::TetMesh;
use crate::Error;

/// A fault surface: triangles in the model's local frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Fault {
    pub name: String,
    pub tris: Vec<[V3; 3]>,
}

/// Reads a fault surface from OBJ bytes (`tobj`, triangulated), shifting it by `-origin`.
pub fn read_fault_obj(bytes: &[u8], name: &str, origin: V3) -> Result<Fault, Error> {
    let mut reader = std::io::BufReader::new(bytes);
    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ..Default::default() };
    let (models, _) = tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| Error::Parse { file: name.to_string(), line: 0, msg: format!("OBJ: {e}") })?;
    let mut tris = Vec::new();
    for m in &models {
        let p = &m.mesh.positions;
        let v = |i: u32| {
            let i = i as usize * 3;
            [p[i] as f64 - origin[0], p[i + 1] as f64 - origin[1], p[i + 2] as f64 - origin[2]]
        };
        for f in m.mesh.indices.chunks_exact(3) {
            tris.push([v(f[0]), v(f[1]), v(f[2])]);
        }
    }
    if tris.is_empty() {
        return Err(Error::Parse { file: name.to_string(), line: 0, msg: "OBJ has no triangles (faces)".into() });
    }
    if tris.iter().flatten().flatten().any(|x| !x.is_finite()) {
        return Err(Error::Parse { file: name.to_string(), line: 0, msg: "OBJ has a NaN or infinite vertex".into() });
    }
    Ok(Fault { name: name.to_string(), tris })
}

/// Points spread over the fault triangles at about `spacing`, so refinement makes the cut fine.
pub fn fault_samples(f: &Fault, spacing: f64) -> Vec<V3> {
    let mut out = Vec::new();
    for t in &f.tris {
        let l = crate::geom::norm(sub(t[1], t[0]))
            .max(crate::geom::norm(sub(t[2], t[0])))
            .max(crate::geom::norm(sub(t[2], t[1])));
        let n = ((l / spacing).ceil() as usize).clamp(1, 2000);
        for i in 0..=n {
            for j in 0..=n - i {
                let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                let c = 1.0 - a - b;
                out.push([
                    c * t[0][0] + a * t[1][0] + b * t[2][0],
                    c * t[0][1] + a * t[1][1] + b * t[2][1],
                    c * t[0][2] + a * t[1][2] + b * t[2][2],
                ]);
            }
        }
    }
    out
}

fn find(p: &mut [u32], mut x: u32) -> u32 {
    while p[x as usize] != x {
        p[x as usize] = p[p[x as usize] as usize];
        x = p[x as usize];
    }
    x
}

/// Cuts `mesh` along `faults`; returns the cut mesh (duplicated vertices) and, for each of its
/// vertices, the vertex of `mesh` it copies. Errors when a fault cuts no face.
pub fn cut(mesh: &TetMesh, faults: &[Fault]) -> Result<(TetMesh, Vec<u32>), Error> {
    if faults.is_empty() {
        return Ok((mesh.clone(), (0..mesh.verts.len() as u32).collect()));
    }
    let faces = mesh.interior_faces();
    let centroid = |t: u32| {
        let c = mesh.corners(t as usize);
        let mut s = [0.0; 3];
        for p in &c {
            for k in 0..3 {
                s[k] += p[k] * 0.25;
            }
        }
        s
    };
    // Triangle bounding boxes for a cheap reject.
    let boxes = fault_triangle_boxes(faults);
    let mut hits = vec![0usize; faults.len()];
    let cutf: Vec<Option<usize>> = {
        use rayon::prelude::*;
        faces
            .par_iter()
            .map(|f| {
                let (a, b) = (centroid(f.tets[0]), centroid(f.tets[1]));
                for (fi, fault) in faults.iter().enumerate() {
                    for (ti, t) in fault.tris.iter().enumerate() {
                        let (lo, hi) = boxes[fi][ti];
                        if (0..3).any(|k| a[k].max(b[k]) < lo[k] || a[k].min(b[k]) > hi[k]) {
                            continue;
                        }
                        if segment_hits_triangle(a, b, t[0], t[1], t[2]) {
                            return Some(fi);
                        }
                    }
                }
                None
            })
            .collect()
    };
    for c in cutf.iter().flatten() {
        hits[*c] += 1;
    }
    if let Some(i) = hits.iter().position(|&h| h == 0) {
        return Err(Error::FaultOutsideDomain(faults[i].name.clone()));
    }
    // Incidences (vertex, tet) in CSR by vertex.
    let nv = mesh.verts.len();
    let (start, inc) = vertex_tet_incidences(mesh);
    let pos = |v: u32, t: u32| -> u32 {
        let s = start[v as usize];
        (s + inc[s..start[v as usize + 1]].iter().position(|&x| x == t).unwrap_or(0)) as u32
    };
    let mut parent: Vec<u32> = (0..inc.len() as u32).collect();
    for (f, c) in faces.iter().zip(&cutf) {
        if c.is_some() {
            continue;
        }
        for &v in &f.verts {
            let (a, b) = (pos(v, f.tets[0]), pos(v, f.tets[1]));
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        }
    }
    let mut dof_of_inc = vec![u32::MAX; inc.len()];
    let mut verts = Vec::new();
    let mut dof_vertex = Vec::new();
    for v in 0..nv {
        for k in start[v]..start[v + 1] {
            let r = find(&mut parent, k as u32) as usize;
            if dof_of_inc[r] == u32::MAX {
                dof_of_inc[r] = verts.len() as u32;
                verts.push(mesh.verts[v]);
                dof_vertex.push(v as u32);
            }
            dof_of_inc[k] = dof_of_inc[r];
        }
    }
    let tets = mesh.tets.iter().enumerate().map(|(ti, t)| t.map(|v| dof_of_inc[pos(v, ti as u32) as usize])).collect();
    Ok((TetMesh { verts, tets }, dof_vertex))
}

/// The bounding box of every fault triangle, per fault: the cheap reject before the exact
/// segment/triangle test in [`cut`].
fn fault_triangle_boxes(faults: &[Fault]) -> Vec<Vec<(V3, V3)>> {
    faults
        .iter()
        .map(|f| {
            f.tris
                .iter()
                .map(|t| {
                    let mut lo = t[0];
                    let mut hi = t[0];
                    for p in &t[1..] {
                        for k in 0..3 {
                            lo[k] = lo[k].min(p[k]);
                            hi[k] = hi[k].max(p[k]);
                        }
                    }
                    (lo, hi)
                })
                .collect()
        })
        .collect()
}

/// The (vertex, tet) incidences of `mesh` in CSR form by vertex: `start` (one more entry than
/// vertices) and the tets, so each vertex's incidences can be split into copies along a fault.
fn vertex_tet_incidences(mesh: &TetMesh) -> (Vec<usize>, Vec<u32>) {
    let nv = mesh.verts.len();
    let mut start = vec![0usize; nv + 1];
    for t in &mesh.tets {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for i in 0..nv {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut inc = vec![0u32; start[nv]];
    for (ti, t) in mesh.tets.iter().enumerate() {
        for &v in t {
            inc[fill[v as usize]] = ti as u32;
            fill[v as usize] += 1;
        }
    }
    (start, inc)
}
