//! Derived geometry (spec §2.3 "Derived geometry", §4.1): normals assembled from signed parameters,
//! edge lines and node points as plane intersections.

use crate::ids::*;
use crate::model::Popa3d;
use crate::topology::Incidence;
use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// Why a derived point or line cannot be computed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GeometryError {
    /// GA01: fewer than three linearly independent planes meet at the node.
    #[error("GA01: {node} is reached by {planes} distinct plane(s) of rank {rank}; at least 3 linearly independent planes are needed")]
    NodeUnderdetermined { node: NodeId, planes: usize, rank: usize },
    /// AA01: the edge's two planes are parallel (or the edge has fewer than two distinct planes).
    #[error("AA01: {edge} is not the intersection of two non-parallel planes")]
    EdgeParallelPlanes { edge: EdgeId },
}

/// A plane as numbers: unit-free normal `n` (as assembled from its parameters, with the plane's sign)
/// and distance `d`, so that ⟨n, x⟩ = d on the plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneValue {
    pub n: [f64; 3],
    pub d: f64,
}

/// Relative threshold on the smallest singular value (scaled by the largest) below which a plane
/// system counts as rank deficient: 1e-6 rad ≈ planes within 0.2″ of each other are "parallel".
pub const RANK_EPS: f64 = 1e-6;

impl Popa3d {
    /// The normal vector's value n = (s_x·p_a, s_y·p_b, s_z·p_c) (spec §4.1).
    pub fn normal_value(&self, id: NormalId) -> [f64; 3] {
        let nv = self.normal(id);
        let mut n = [0.0; 3];
        for (k, (p, s)) in nv.comps.iter().enumerate() {
            n[k] = s.f64() * self.parameter(*p).value;
        }
        n
    }

    /// The plane's signed normal and d.
    pub fn plane_value(&self, id: PlaneId) -> PlaneValue {
        let p = self.plane(id);
        let n = self.normal_value(p.normal);
        let s = p.sign.f64();
        PlaneValue { n: [s * n[0], s * n[1], s * n[2]], d: p.d }
    }

    /// The face's normal (its plane's normal times the face orientation) and the matching d.
    pub fn face_plane_value(&self, id: FaceId) -> PlaneValue {
        let f = self.face(id);
        let pv = self.plane_value(f.plane);
        let s = f.orientation.f64();
        PlaneValue { n: [s * pv.n[0], s * pv.n[1], s * pv.n[2]], d: s * pv.d }
    }

    /// Position of a node (model coordinates, i.e. relative to `origin`) from the distinct planes of
    /// its faces (spec §2.3): 3 planes → the 3×3 system (T 2.3); more → least squares
    /// AᵀA·P = Aᵀd (T 2.4, corrected from the printed "A d", spec §2.3 \[erratum\]).
    pub fn node_position(&self, inc: &Incidence, node: NodeId) -> Result<[f64; 3], GeometryError> {
        let planes = inc.node_planes(self, node);
        self.intersect_planes(&planes).ok_or_else(|| {
            let rank = self.plane_rank(&planes);
            GeometryError::NodeUnderdetermined { node, planes: planes.len(), rank }
        })
    }

    /// Positions of all nodes (see [`Popa3d::node_position`]).
    pub fn node_positions(&self, inc: &Incidence) -> Result<Vec<[f64; 3]>, GeometryError> {
        (0..self.nodes.len()).map(|i| self.node_position(inc, NodeId::from(i))).collect()
    }

    /// Least-squares intersection point of planes (None if their normals have rank < 3). Uses the
    /// normal equations on the (few) planes of one node; the normals are unit vectors, so AᵀA is well
    /// scaled.
    pub fn intersect_planes(&self, planes: &[PlaneId]) -> Option<[f64; 3]> {
        let vals: Vec<PlaneValue> = planes.iter().map(|p| self.plane_value(*p)).collect();
        intersect_plane_values(&vals)
    }

    /// Numerical rank (0..=3) of the normals of the given planes.
    pub fn plane_rank(&self, planes: &[PlaneId]) -> usize {
        let vals: Vec<PlaneValue> = planes.iter().map(|p| self.plane_value(*p)).collect();
        normals_rank(&vals)
    }

    /// The best-conditioned triple of a node's planes (max |det| of the three unit normals), the
    /// choice spec §2.3 \[proposal\] makes for equations that use exactly three planes per node
    /// (spec §10.2 item 11: decided here; ties are broken by the lowest plane ids).
    pub fn node_plane_triple(&self, inc: &Incidence, node: NodeId) -> Result<[PlaneId; 3], GeometryError> {
        let planes = inc.node_planes(self, node);
        let units: Vec<Vector3<f64>> = planes
            .iter()
            .map(|p| {
                let v = Vector3::from(self.plane_value(*p).n);
                v / v.norm().max(f64::MIN_POSITIVE)
            })
            .collect();
        let mut best: Option<([PlaneId; 3], f64)> = None;
        for i in 0..planes.len() {
            for j in i + 1..planes.len() {
                for k in j + 1..planes.len() {
                    let det = Matrix3::from_rows(&[units[i].transpose(), units[j].transpose(), units[k].transpose()])
                        .determinant()
                        .abs();
                    if best.is_none_or(|(_, b)| det > b + 1e-12) {
                        best = Some(([planes[i], planes[j], planes[k]], det));
                    }
                }
            }
        }
        match best {
            Some((t, det)) if det > RANK_EPS => Ok(t),
            _ => Err(GeometryError::NodeUnderdetermined { node, planes: planes.len(), rank: self.plane_rank(&planes) }),
        }
    }

    /// The two planes of an edge (those of its incident faces, most orthogonal pair if the edge has
    /// more than two distinct planes).
    pub fn edge_planes(&self, inc: &Incidence, edge: EdgeId) -> Result<[PlaneId; 2], GeometryError> {
        let planes = inc.edge_planes(self, edge);
        let mut best: Option<([PlaneId; 2], f64)> = None;
        for i in 0..planes.len() {
            for j in i + 1..planes.len() {
                let a = Vector3::from(self.plane_value(planes[i]).n);
                let b = Vector3::from(self.plane_value(planes[j]).n);
                let s = a.cross(&b).norm() / (a.norm() * b.norm()).max(f64::MIN_POSITIVE);
                if best.is_none_or(|(_, x)| s > x + 1e-12) {
                    best = Some(([planes[i], planes[j]], s));
                }
            }
        }
        match best {
            Some((p, s)) if s > RANK_EPS => Ok(p),
            _ => Err(GeometryError::EdgeParallelPlanes { edge }),
        }
    }

    /// The edge's line: the point nearest the origin, p_jk = [n_j; n_k; n_j×n_k]⁻¹·(d_j, d_k, 0)ᵀ, and
    /// the direction n_j×n_k (spec §2.3, §4.1).
    pub fn edge_line(&self, inc: &Incidence, edge: EdgeId) -> Result<([f64; 3], [f64; 3]), GeometryError> {
        let [j, k] = self.edge_planes(inc, edge)?;
        let (pj, pk) = (self.plane_value(j), self.plane_value(k));
        let nj = Vector3::from(pj.n);
        let nk = Vector3::from(pk.n);
        let c = nj.cross(&nk);
        let m = Matrix3::from_rows(&[nj.transpose(), nk.transpose(), c.transpose()]);
        let p = m.lu().solve(&Vector3::new(pj.d, pk.d, 0.0)).ok_or(GeometryError::EdgeParallelPlanes { edge })?;
        Ok(([p.x, p.y, p.z], [c.x, c.y, c.z]))
    }
}

/// Least-squares intersection of plane values (None when the normals have rank < 3).
pub fn intersect_plane_values(vals: &[PlaneValue]) -> Option<[f64; 3]> {
    if vals.len() < 3 || normals_rank(vals) < 3 {
        return None;
    }
    let p = if vals.len() == 3 {
        let m = Matrix3::from_rows(&[
            Vector3::from(vals[0].n).transpose(),
            Vector3::from(vals[1].n).transpose(),
            Vector3::from(vals[2].n).transpose(),
        ]);
        m.lu().solve(&Vector3::new(vals[0].d, vals[1].d, vals[2].d))?
    } else {
        let mut ata = Matrix3::zeros();
        let mut atd = Vector3::zeros();
        for v in vals {
            let n = Vector3::from(v.n);
            ata += n * n.transpose();
            atd += n * v.d;
        }
        ata.cholesky()?.solve(&atd)
    };
    if p.iter().all(|x| x.is_finite()) {
        Some([p.x, p.y, p.z])
    } else {
        None
    }
}

/// Numerical rank of the (normalised) normals: singular values of the stacked unit normals relative to
/// the largest, threshold [`RANK_EPS`].
pub fn normals_rank(vals: &[PlaneValue]) -> usize {
    if vals.is_empty() {
        return 0;
    }
    let mut ata = Matrix3::zeros();
    for v in vals {
        let n = Vector3::from(v.n);
        let len = n.norm();
        if len > 0.0 {
            let u = n / len;
            ata += u * u.transpose();
        }
    }
    let ev = ata.symmetric_eigenvalues();
    let max = ev.iter().cloned().fold(0.0f64, f64::max);
    if max <= 0.0 {
        return 0;
    }
    // Eigenvalues of AᵀA are squared singular values.
    ev.iter().filter(|&&e| e.max(0.0).sqrt() > RANK_EPS * max.sqrt()).count()
}
