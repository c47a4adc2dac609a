//! Template vertices that lost their node. Normalization's GA01 repair merges nearly coplanar
//! faces and removes the nodes left with two neighbours (the corner between two walls within 1°);
//! writing the polygons without those vertices cut the corner, and the input vertex ended 7.5–23 cm
//! from the output surface on real files. Instead such a vertex is written at the point of its
//! polygons' planes nearest to where it was (the anchored intersection: on the line where the
//! merged plane meets the other face, or on the plane alone), so every polygon keeps its own ring
//! and vertex on the shared plane (docs/decisions.md#merges-keep-semantics-and-identity). A vertex
//! within 1 mm of a ring neighbour with a node was merged into it by the snap and is still written
//! once, as the neighbour.

use super::{anchored_intersection, ring_len, ring_of, PolyInfo, P3};
use popa3d_model::{FaceId, PlaneId, Popa3d};
use std::collections::HashMap;

/// A vertex closer than this to its ring neighbour was merged into it by the snap (m).
const SNAPPED: f64 = 1e-3;

/// The faces of the polygons holding each template point (by its exact coordinates).
pub(super) struct Dropped {
    faces_at: HashMap<[u64; 3], Vec<FaceId>>,
}

fn key(p: &P3) -> [u64; 3] {
    p.map(|v| v.to_bits())
}

impl Dropped {
    /// `face_of`: the face of every mapped polygon (a polygon merged into another's face by
    /// normalization: that face).
    pub(super) fn new(
        mapped: &[String],
        polys: &HashMap<String, PolyInfo<'_>>,
        face_of: &HashMap<String, FaceId>,
    ) -> Dropped {
        let mut faces_at: HashMap<[u64; 3], Vec<FaceId>> = HashMap::new();
        for id in mapped {
            let Some(&f) = face_of.get(id) else { continue };
            let p = polys[id].poly;
            for r in std::iter::once(&p.exterior).chain(p.interiors.iter()) {
                for q in &r.points {
                    let v = faces_at.entry(key(q)).or_default();
                    if !v.contains(&f) {
                        v.push(f);
                    }
                }
            }
        }
        Dropped { faces_at }
    }

    /// Where vertex `k` of ring `ri` of polygon `p` goes when it has no node: `None` when it was
    /// snapped into a ring neighbour that has one (`has_node` tells), else the point of its
    /// polygons' planes nearest to it (world coordinates).
    pub(super) fn position(
        &self,
        m: &Popa3d,
        p: &citygml_io::Polygon,
        ri: u32,
        k: usize,
        has_node: &dyn Fn(usize) -> bool,
    ) -> Option<P3> {
        let r = ring_of(p, ri)?;
        let n = ring_len(r);
        let q = r.points[k];
        let near = |j: usize| has_node(j) && super::dist(r.points[j], q) < SNAPPED;
        if n < 2 || near((k + 1) % n) || near((k + n - 1) % n) {
            return None;
        }
        let mut planes: Vec<PlaneId> = self.faces_at.get(&key(&q))?.iter().map(|f| m.faces[f.idx()].plane).collect();
        planes.sort();
        planes.dedup();
        let local = [q[0] - m.origin[0], q[1] - m.origin[1], q[2] - m.origin[2]];
        let x = anchored_intersection(m, &planes, local)?;
        Some([x[0] + m.origin[0], x[1] + m.origin[1], x[2] + m.origin[2]])
    }
}
