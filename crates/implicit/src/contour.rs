//! Iso-surfaces by marching tetrahedra (seed §2.1, a specialisation of marching cubes \[LC87\]),
//! plane sections, and CSG of two models by min/max of their fields (seed §4).
//!
//! Conventions: a vertex counts as "below" when f < iso, else "above", so every tetrahedron
//! contributes 0, 1 or 2 triangles and iso-vertices are shared through their mesh edge: the
//! surface is a manifold (closed when it does not reach the mesh boundary). Triangles are
//! oriented so their normal points towards increasing f (outwards when φ > 0 outside).
//!
//! Clean-up: values within a tiny fraction of the field's range of the iso-value are nudged off
//! it, so no iso-vertex lands on a mesh vertex (no zero-length edges, no duplicated positions);
//! then edges much shorter than the local element size are collapsed where the link condition
//! allows it (topology kept), and triangles that became degenerate are dropped.

use std::collections::HashMap;

use crate::geom::{cross, dot, hat_gradients, norm, sub, V3};
use crate::mesh::{Locator, Refiner, TetMesh};
use crate::model::Model;

/// A triangle surface with one optional scalar per vertex (for colouring).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Surface {
    pub positions: Vec<V3>,
    pub tris: Vec<[u32; 3]>,
    pub scalars: Option<Vec<f64>>,
}

impl Surface {
    /// Enclosed volume by the divergence theorem (meaningful for closed, oriented surfaces).
    pub fn volume(&self) -> f64 {
        self.tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize]);
                dot(a, cross(b, c)) / 6.0
            })
            .sum()
    }
    pub fn area(&self) -> f64 {
        self.tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize]);
                0.5 * norm(cross(sub(b, a), sub(c, a)))
            })
            .sum()
    }
    /// Every edge is shared by exactly two triangles.
    pub fn is_closed(&self) -> bool {
        let mut e: HashMap<(u32, u32), i32> = HashMap::new();
        for t in &self.tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *e.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        !e.is_empty() && e.values().all(|&c| c == 2)
    }
    pub fn translate(&mut self, d: V3) {
        for p in &mut self.positions {
            *p = [p[0] + d[0], p[1] + d[1], p[2] + d[2]];
        }
    }
}

/// Marching tetrahedra of `field` at `iso`; `attr` is interpolated onto the iso-vertices.
pub fn iso_surface(mesh: &TetMesh, field: &[f64], iso: f64, attr: Option<&[f64]>) -> Surface {
    let (fmin, fmax) = field.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let eps = 1e-7 * (fmax - fmin).abs().max(1e-300);
    // Clean-up step 1: keep the field off the iso-value at vertices.
    let f: Vec<f64> = field.iter().map(|&x| if (x - iso).abs() < eps { iso + eps } else { x }).collect();
    let mut s = Surface { scalars: attr.map(|_| Vec::new()), ..Default::default() };
    let mut emap: HashMap<u64, u32> = HashMap::new();
    let mut vsize: Vec<f64> = Vec::new();
    for (ti, t) in mesh.tets.iter().enumerate() {
        let below: Vec<usize> = (0..4).filter(|&k| f[t[k] as usize] < iso).collect();
        if below.is_empty() || below.len() == 4 {
            continue;
        }
        let above: Vec<usize> = (0..4).filter(|&k| f[t[k] as usize] >= iso).collect();
        let h = mesh.tet_size(ti);
        let mut vert = |a: usize, b: usize, s: &mut Surface| -> u32 {
            let (ia, ib) = (t[a], t[b]);
            let key = ((ia.min(ib) as u64) << 32) | ia.max(ib) as u64;
            *emap.entry(key).or_insert_with(|| {
                let (fa, fb) = (f[ia as usize], f[ib as usize]);
                let w = (iso - fa) / (fb - fa);
                let (pa, pb) = (mesh.verts[ia as usize], mesh.verts[ib as usize]);
                s.positions.push([
                    pa[0] + w * (pb[0] - pa[0]),
                    pa[1] + w * (pb[1] - pa[1]),
                    pa[2] + w * (pb[2] - pa[2]),
                ]);
                if let (Some(sc), Some(at)) = (s.scalars.as_mut(), attr) {
                    sc.push(at[ia as usize] + w * (at[ib as usize] - at[ia as usize]));
                }
                vsize.push(h);
                (s.positions.len() - 1) as u32
            })
        };
        let tris: Vec<[u32; 3]> = match below.len() {
            1 | 3 => {
                let (lone, others) =
                    if below.len() == 1 { (below[0], above.clone()) } else { (above[0], below.clone()) };
                vec![[vert(lone, others[0], &mut s), vert(lone, others[1], &mut s), vert(lone, others[2], &mut s)]]
            }
            _ => {
                let (a, b, c, d) = (below[0], below[1], above[0], above[1]);
                let (ac, ad, bd, bc) = (vert(a, c, &mut s), vert(a, d, &mut s), vert(b, d, &mut s), vert(b, c, &mut s));
                vec![[ac, ad, bd], [ac, bd, bc]]
            }
        };
        let grad = hat_gradients(&mesh.corners(ti)).map(|g| {
            let mut v = [0.0; 3];
            for k in 0..4 {
                for j in 0..3 {
                    v[j] += f[t[k] as usize] * g[k][j];
                }
            }
            v
        });
        for mut tri in tris {
            let [p, q, r] = tri.map(|i| s.positions[i as usize]);
            let n = cross(sub(q, p), sub(r, p));
            if let Some(g) = grad {
                if dot(n, g) < 0.0 {
                    tri.swap(1, 2);
                }
            }
            s.tris.push(tri);
        }
    }
    collapse_short_edges(&mut s, &vsize, 1e-3);
    s
}

/// Clean-up step 2: collapses edges shorter than `rel` × the local element size when the link
/// condition holds (the two end points share exactly the two opposite vertices), so the surface
/// stays manifold; drops triangles that degenerate and compacts the vertex list.
fn collapse_short_edges(s: &mut Surface, vsize: &[f64], rel: f64) {
    let n = s.positions.len();
    let mut map: Vec<u32> = (0..n as u32).collect();
    let find = |m: &Vec<u32>, mut x: u32| {
        while m[x as usize] != x {
            x = m[x as usize];
        }
        x
    };
    // Vertex → triangle adjacency for the link test.
    let mut vt: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (i, t) in s.tris.iter().enumerate() {
        for &v in t {
            vt[v as usize].push(i as u32);
        }
    }
    let mut dead = vec![false; s.tris.len()];
    for ti in 0..s.tris.len() {
        if dead[ti] {
            continue;
        }
        for k in 0..3 {
            let t = s.tris[ti].map(|v| find(&map, v));
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a == b {
                continue;
            }
            let l = norm(sub(s.positions[a as usize], s.positions[b as usize]));
            if l >= rel * vsize[a as usize].min(vsize[b as usize]) {
                continue;
            }
            // Link condition: neighbours of a ∩ neighbours of b = the opposite vertices of the
            // (at most two) triangles on edge ab.
            let nb = |v: u32| {
                let mut out: Vec<u32> = Vec::new();
                for &tt in &vt[v as usize] {
                    if dead[tt as usize] {
                        continue;
                    }
                    let tv = s.tris[tt as usize].map(|x| find(&map, x));
                    if !tv.contains(&v) {
                        continue;
                    }
                    for x in tv {
                        if x != v && !out.contains(&x) {
                            out.push(x);
                        }
                    }
                }
                out
            };
            let (na, nbv) = (nb(a), nb(b));
            let common: Vec<u32> = na.iter().filter(|x| nbv.contains(x)).cloned().collect();
            let on_edge: Vec<u32> = vt[a as usize]
                .iter()
                .filter(|&&tt| !dead[tt as usize])
                .map(|&tt| s.tris[tt as usize].map(|x| find(&map, x)))
                .filter(|tv| tv.contains(&a) && tv.contains(&b))
                .map(|tv| tv.into_iter().find(|&x| x != a && x != b).unwrap_or(a))
                .collect();
            if common.len() != on_edge.len() || on_edge.len() != 2 {
                continue;
            }
            // Collapse b into a at the midpoint.
            let m = crate::geom::mid(s.positions[a as usize], s.positions[b as usize]);
            s.positions[a as usize] = m;
            if let Some(sc) = s.scalars.as_mut() {
                sc[a as usize] = 0.5 * (sc[a as usize] + sc[b as usize]);
            }
            map[b as usize] = a;
            let moved = std::mem::take(&mut vt[b as usize]);
            for &tt in &moved {
                let tv = s.tris[tt as usize].map(|x| find(&map, x));
                if tv[0] == tv[1] || tv[1] == tv[2] || tv[0] == tv[2] {
                    dead[tt as usize] = true;
                }
            }
            vt[a as usize].extend(moved);
            break;
        }
    }
    // Compact.
    compact_collapsed(s, &map, &dead);
}

/// Compacts a surface after [`collapse_short_edges`]: drops dead and degenerate triangles, maps
/// collapsed vertices to their survivors (`map`, a union-find forest) and keeps only the vertices
/// still used, so the collapse loop itself never has to renumber.
fn compact_collapsed(s: &mut Surface, map: &[u32], dead: &[bool]) {
    let n = s.positions.len();
    let find = |m: &[u32], mut x: u32| {
        while m[x as usize] != x {
            x = m[x as usize];
        }
        x
    };
    let mut new_id = vec![u32::MAX; n];
    let mut pos = Vec::new();
    let mut sc = s.scalars.as_ref().map(|_| Vec::new());
    let mut tris = Vec::new();
    for (ti, t) in s.tris.iter().enumerate() {
        if dead[ti] {
            continue;
        }
        let t = t.map(|v| find(map, v));
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            continue;
        }
        let t = t.map(|v| {
            if new_id[v as usize] == u32::MAX {
                new_id[v as usize] = pos.len() as u32;
                pos.push(s.positions[v as usize]);
                if let (Some(out), Some(src)) = (sc.as_mut(), s.scalars.as_ref()) {
                    out.push(src[v as usize]);
                }
            }
            new_id[v as usize]
        });
        tris.push(t);
    }
    s.positions = pos;
    s.tris = tris;
    s.scalars = sc;
}

/// The part of the plane through `point` with normal `normal` inside the mesh, with φ (or the
/// model's attribute when `use_attribute`) as the vertex scalar.
pub fn section(model: &Model, point: V3, normal: V3, use_attribute: bool) -> Surface {
    let p0 = sub(point, model.origin);
    let dist: Vec<f64> = model.mesh.verts.iter().map(|v| dot(sub(*v, p0), normal)).collect();
    let attr = match (&model.attribute, use_attribute) {
        (Some((_, a)), true) => a.as_slice(),
        _ => model.phi.as_slice(),
    };
    let mut s = iso_surface(&model.mesh, &dist, 0.0, Some(attr));
    s.translate(model.origin);
    s
}

/// The CSG operations of seed §4 on fields with φ < 0 inside.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CsgOp {
    Union,
    Intersection,
    Difference,
}

/// Combines two models on a fresh adaptive mesh over both domains, refined where either zero
/// set passes, with union = min(φA, φB), intersection = max, difference = max(φA, −φB).
/// Outside a model's domain its field counts as "outside" (positive). Returns the zero surface
/// (world coordinates) and the combined mesh and field (local to `a.origin`).
pub fn csg(a: &Model, b: &Model, op: CsgOp) -> (Surface, TetMesh, Vec<f64>) {
    let origin = a.origin;
    let (alo, ahi) = a.mesh.bounds();
    let (blo, bhi) = b.mesh.bounds();
    let off = sub(b.origin, origin);
    let lo = [0, 1, 2].map(|k| alo[k].min(blo[k] + off[k]));
    let hi = [0, 1, 2].map(|k| ahi[k].max(bhi[k] + off[k]));
    let cell = a.cell.min(b.cell);
    let longest = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    let mut cube = cell;
    while cube * 2.0 <= longest / 8.0 {
        cube *= 2.0;
    }
    let dims = [0, 1, 2].map(|k| (((hi[k] - lo[k]) / cube).ceil() as usize).max(1));
    let mut r = Refiner::new(lo, dims, cube);
    // One level finer than the inputs: the min/max creases are cut by linear pieces, so the
    // elements along them must be small.
    let target = r.level_of_cube_fraction(cell) + 3;
    let mut samples: Vec<V3> = iso_surface(&a.mesh, &a.phi, 0.0, None).positions;
    samples.extend(
        iso_surface(&b.mesh, &b.phi, 0.0, None).positions.iter().map(|p| [p[0] + off[0], p[1] + off[1], p[2] + off[2]]),
    );
    r.add_points(&samples, target);
    r.refine();
    let mesh = r.mesh();
    let (la, lb) = (a.locator(), b.locator());
    let big = |m: &Model| m.phi.iter().fold(0.0f64, |x, v| x.max(v.abs())).max(1.0);
    let (ba, bb) = (big(a), big(b));
    let field: Vec<f64> = mesh
        .verts
        .iter()
        .map(|&p| {
            let fa = crate::dsi::eval(&a.mesh, &la, &a.phi, p).unwrap_or(ba);
            let pb = sub(p, off);
            let fb = crate::dsi::eval(&b.mesh, &lb, &b.phi, pb).unwrap_or(bb);
            match op {
                CsgOp::Union => fa.min(fb),
                CsgOp::Intersection => fa.max(fb),
                CsgOp::Difference => fa.max(-fb),
            }
        })
        .collect();
    let mut s = iso_surface(&mesh, &field, 0.0, None);
    s.translate(origin);
    (s, mesh, field)
}

/// Locator-free helper: the world bounding box of a model's mesh.
pub fn world_bounds(m: &Model) -> (V3, V3) {
    let (lo, hi) = m.mesh.bounds();
    (
        [lo[0] + m.origin[0], lo[1] + m.origin[1], lo[2] + m.origin[2]],
        [hi[0] + m.origin[0], hi[1] + m.origin[1], hi[2] + m.origin[2]],
    )
}

#[allow(dead_code)]
fn _unused(_: &Locator) {}
