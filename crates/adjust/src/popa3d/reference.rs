//! Reference points of planes: the centroid of the nodes on their faces, so a datum observation
//! of a plane offset does not depend on the model origin.

use super::*;

/// Reference point of every plane, in model coordinates: the centroid of the positions of the
/// nodes on its faces (spec §2.3 node points), so it moves with the geometry when the model origin
/// moves. A plane without a computable node falls back to its foot point n·d/‖n‖² (which does
/// depend on the origin). Planes, normals and parameters must be valid references.
pub fn plane_reference_points(m: &Popa3d, inc: &Incidence) -> Vec<[f64; 3]> {
    reference_points_of(m, &plane_node_points(m, inc))
}

/// The positions of the nodes on every plane's faces (model coordinates; nodes without three
/// independent planes are left out).
pub fn plane_node_points(m: &Popa3d, inc: &Incidence) -> Vec<Vec<[f64; 3]>> {
    let np = m.planes.len();
    let mut pts = vec![Vec::new(); np];
    for i in 0..m.nodes.len() {
        let planes = inc.node_planes(m, pm::NodeId::from(i));
        if planes.iter().any(|q| q.idx() >= np) {
            continue;
        }
        let Some(x) = m.intersect_planes(&planes) else { continue };
        if !x.iter().all(|v| v.is_finite()) {
            continue;
        }
        for q in planes {
            pts[q.idx()].push(x);
        }
    }
    pts
}

pub(super) fn reference_points_of(m: &Popa3d, pts: &[Vec<[f64; 3]>]) -> Vec<[f64; 3]> {
    pts.iter()
        .enumerate()
        .map(|(i, xs)| {
            if !xs.is_empty() {
                let s = xs.iter().fold([0.0; 3], |a, x| [a[0] + x[0], a[1] + x[1], a[2] + x[2]]);
                s.map(|v| v / xs.len() as f64)
            } else {
                let pv = m.plane_value(pm::PlaneId::from(i));
                let nn = dot(pv.n, pv.n);
                if nn > 0.0 {
                    pv.n.map(|v| v * pv.d / nn)
                } else {
                    [0.0; 3]
                }
            }
        })
        .collect()
}
