//! The popa3d equation objects of spec Table B.1, written once generically over the scalar type.
//!
//! Slot layout: every plane enters as four unknown slots `[nx, ny, nz, d]` (each normal component
//! a signed reference to a shared parameter, spec §2.3; the signs live in the [`crate::Slot`]s).
//! A face is one plane, an edge two planes (j, k), a node three planes (j, k, l); the caller picks
//! the planes (spec §10.2 item 11: we take the best-conditioned ones, see the popa3d mapping).
//! Set-ups add `[q0, q1, q2, q3, tx, ty, tz]`.
//!
//! Corrections followed (spec §4.3–§4.5, §10.2):
//! - face–face and face–edge distances: absolute value of the WHOLE expression with the sign
//!   frozen at the current values (T 3.15/3.17 pick the branch wrongly); a distance of exactly 0
//!   (coplanarity, T 7.1) uses the signed form, which is differentiable at the solution;
//! - edge–edge uses (d_i, d_j, 0) (T 3.23 typo);
//! - angle constraints are signed cosines with normalised cross products (T 3.49/3.50);
//! - polar pointings: T 3.33 convention x = s·sinV·sinHz, y = s·sinV·cosHz, z = s·cosV (Hz clockwise
//!   from +y, gon), standard quaternion rotation matrix (T 3.13/3.35 print a symmetric one);
//!   point-on-edge/node use one plane equation per target plane sharing the three observations
//!   (block M) instead of the non-differentiable ‖·‖ = 0 (T 3.44/3.46).

use crate::ad::{Equation, Scalar};

/// A 3-vector of automatic-differentiation scalars. The helpers below are generic over the
/// scalar (value or dual number), which is why they are not `popa3d_model::vec3`'s `f64` ones.
type V3<D> = [D; 3];

fn dot<D: Scalar>(a: &V3<D>, b: &V3<D>) -> D {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross<D: Scalar>(a: &V3<D>, b: &V3<D>) -> V3<D> {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn sub<D: Scalar>(a: &V3<D>, b: &V3<D>) -> V3<D> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn norm<D: Scalar>(a: &V3<D>) -> D {
    dot(a, a).sqrt()
}

/// Plane `k` of a slot array: (n, d).
fn plane<D: Scalar>(x: &[D], k: usize) -> (V3<D>, D) {
    let o = 4 * k;
    ([x[o], x[o + 1], x[o + 2]], x[o + 3])
}

/// The first `N` planes of a slot array, in slot order.
fn planes<D: Scalar, const N: usize>(x: &[D]) -> [(V3<D>, D); N] {
    std::array::from_fn(|k| plane(x, k))
}

/// Declares one equation type of Table B.1: a unit struct, its report name and its residual
/// `f(x, l)` over the unknown slots `x` and the observations `l` (generic over the AD scalar `D`).
macro_rules! equation {
    ($(#[$doc:meta])* $name:ident, $kind:literal, |$x:ident, $l:ident| $body:block) => {
        $(#[$doc])*
        pub struct $name;
        impl Equation for $name {
            fn kind(&self) -> &str {
                $kind
            }
            fn eval<D: Scalar>(&self, $x: &[D], $l: &[D]) -> D $body
        }
    };
}

/// Solve [r0; r1; r2]·p = rhs by Cramer's rule (rows are the listed vectors).
fn solve3<D: Scalar>(r0: &V3<D>, r1: &V3<D>, r2: &V3<D>, rhs: &V3<D>) -> V3<D> {
    // p = (rhs0 (r1×r2) + rhs1 (r2×r0) + rhs2 (r0×r1)) / det
    let c12 = cross(r1, r2);
    let c20 = cross(r2, r0);
    let c01 = cross(r0, r1);
    let det = dot(r0, &c12);
    [
        (rhs[0] * c12[0] + rhs[1] * c20[0] + rhs[2] * c01[0]) / det,
        (rhs[0] * c12[1] + rhs[1] * c20[1] + rhs[2] * c01[1]) / det,
        (rhs[0] * c12[2] + rhs[1] * c20[2] + rhs[2] * c01[2]) / det,
    ]
}

/// Point of line j∩k nearest to the origin (spec §4.1): [n_j; n_k; n_j×n_k]⁻¹ (d_j, d_k, 0).
pub fn edge_point<D: Scalar>(nj: &V3<D>, dj: D, nk: &V3<D>, dk: D) -> V3<D> {
    let c = cross(nj, nk);
    solve3(nj, nk, &c, &[dj, dk, D::from(0.0)])
}

/// Foot of q on line j∩k: [n_j; n_k; n_j×n_k]⁻¹ (d_j, d_k, ⟨n_j×n_k, q⟩).
pub fn edge_foot<D: Scalar>(nj: &V3<D>, dj: D, nk: &V3<D>, dk: D, q: &V3<D>) -> V3<D> {
    let c = cross(nj, nk);
    let t = dot(&c, q);
    solve3(nj, nk, &c, &[dj, dk, t])
}

/// Node point [n_j; n_k; n_l]⁻¹ (d_j, d_k, d_l) (T 2.3).
pub fn node_point<D: Scalar>(nj: &V3<D>, dj: D, nk: &V3<D>, dk: D, nl: &V3<D>, dl: D) -> V3<D> {
    solve3(nj, nk, nl, &[dj, dk, dl])
}

/// |e| with the branch frozen at the current value; the signed form when the observed distance
/// is 0 (coplanarity), where |·| has no derivative.
fn frozen_abs<D: Scalar>(e: D, observed: D) -> D {
    if observed.re() == 0.0 || e.re() >= 0.0 {
        e
    } else {
        -e
    }
}

equation! {
    /// DistanceFaceFace: slots [plane i, plane j], obs \[l\]. l + v = |d_j − s·d_i| with s = sign⟨n_i, n_j⟩.
    DistanceFaceFace, "DistanceFaceFace", |x, l| {
        let [(ni, di), (nj, dj)] = planes(x);
        let s = if dot(&ni, &nj).re() >= 0.0 { 1.0 } else { -1.0 };
        frozen_abs(dj - di * s, l[0]) - l[0]
    }
}

equation! {
    /// DistanceFaceEdge: slots [face i, edge plane j, edge plane k], obs \[l\]. l + v = |d_i − ⟨n_i, p_jk⟩|.
    DistanceFaceEdge, "DistanceFaceEdge", |x, l| {
        let [(ni, di), (nj, dj), (nk, dk)] = planes(x);
        let p = edge_point(&nj, dj, &nk, dk);
        frozen_abs(di - dot(&ni, &p), l[0]) - l[0]
    }
}

equation! {
    /// DistanceFaceNode: slots [face i, node planes j, k, l], obs \[l\]. l + v = |d_i − ⟨n_i, p_jkl⟩|.
    DistanceFaceNode, "DistanceFaceNode", |x, l| {
        let [(ni, di), (n1, d1), (n2, d2), (n3, d3)] = planes(x);
        let p = node_point(&n1, d1, &n2, d2, &n3, d3);
        frozen_abs(di - dot(&ni, &p), l[0]) - l[0]
    }
}

equation! {
    /// DistanceEdgeEdge: slots [i, j, k, l], obs \[l\]. l + v = ‖p_ij − p_kl‖ (T 3.23 corrected).
    DistanceEdgeEdge, "DistanceEdgeEdge", |x, l| {
        let [(n1, d1), (n2, d2), (n3, d3), (n4, d4)] = planes(x);
        let a = edge_point(&n1, d1, &n2, d2);
        let b = edge_point(&n3, d3, &n4, d4);
        norm(&sub(&a, &b)) - l[0]
    }
}

equation! {
    /// DistanceEdgeNode: slots [edge i, j, node k, l, m], obs \[l\]. l + v = ‖p_ij(p_klm) − p_klm‖.
    DistanceEdgeNode, "DistanceEdgeNode", |x, l| {
        let [(n1, d1), (n2, d2), (n3, d3), (n4, d4), (n5, d5)] = planes(x);
        let q = node_point(&n3, d3, &n4, d4, &n5, d5);
        let f = edge_foot(&n1, d1, &n2, d2, &q);
        norm(&sub(&f, &q)) - l[0]
    }
}

equation! {
    /// DistanceNodeNode: slots [i, j, k, l, m, n], obs \[l\]. l + v = ‖p_ijk − p_lmn‖.
    DistanceNodeNode, "DistanceNodeNode", |x, l| {
        let [(n1, d1), (n2, d2), (n3, d3), (n4, d4), (n5, d5), (n6, d6)] = planes(x);
        let a = node_point(&n1, d1, &n2, d2, &n3, d3);
        let b = node_point(&n4, d4, &n5, d5, &n6, d6);
        norm(&sub(&a, &b)) - l[0]
    }
}

equation! {
    /// Angle constraint face–face: slots [n_i(3), n_j(3)], obs [l = cosine]. l + v = ⟨n_i, n_j⟩ (signed, spec §4.5 proposal).
    ConstraintFaceFace, "ConstraintFaceFace", |x, l| {
        let a = [x[0], x[1], x[2]];
        let b = [x[3], x[4], x[5]];
        dot(&a, &b) - l[0]
    }
}

equation! {
    /// Angle constraint face–edge: slots [n_i, n_j, n_k] (3 each). l + v = ⟨n_i, n_j×n_k/‖n_j×n_k‖⟩ (T 3.49 normalised).
    ConstraintFaceEdge, "ConstraintFaceEdge", |x, l| {
        let a = [x[0], x[1], x[2]];
        let c = cross(&[x[3], x[4], x[5]], &[x[6], x[7], x[8]]);
        dot(&a, &c) / norm(&c) - l[0]
    }
}

equation! {
    /// Angle constraint edge–edge: slots [n_i, n_j, n_k, n_l]. l + v = ⟨ĉ_ij, ĉ_kl⟩ with normalised cross products (T 3.50).
    ConstraintEdgeEdge, "ConstraintEdgeEdge", |x, l| {
        let c1 = cross(&[x[0], x[1], x[2]], &[x[3], x[4], x[5]]);
        let c2 = cross(&[x[6], x[7], x[8]], &[x[9], x[10], x[11]]);
        dot(&c1, &c2) / (norm(&c1) * norm(&c2)) - l[0]
    }
}

equation! {
    /// RelativeDistancePlanePlane (sketch prior, spec §4.6): slots [d_i, d_j]. l + v = d_j − d_i.
    RelativeDistancePlanePlane, "RelativeDistancePlanePlane", |x, l| {
        x[1] - x[0] - l[0]
    }
}

equation! {
    /// RelativeAngleNormalNormal (sketch prior): slots [n_i, n_j]. l + v = ⟨n_i, n_j⟩.
    RelativeAngleNormalNormal, "RelativeAngleNormalNormal", |x, l| {
        dot(&[x[0], x[1], x[2]], &[x[3], x[4], x[5]]) - l[0]
    }
}

equation! {
    /// NormNV as pseudo-observation (T 3.5): slots \[n\], obs [l = 1]. l + v = ‖n‖.
    NormNvObs, "NormNV", |x, l| {
        norm(&[x[0], x[1], x[2]]) - l[0]
    }
}

/// NormNV as restriction (T 3.6): ‖n‖ − 1 = 0.
pub use crate::fits::UnitNorm3 as NormNvRestriction;

equation! {
    /// NormQ restriction (T 3.14): q0² + q1² + q2² + q3² − 1 = 0.
    NormQ, "NormQ", |x, _l| {
        x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3] - 1.0
    }
}

equation! {
    /// Levelling restriction (T 3.37): one quaternion component = 0 (used for q1 and q2).
    Levelled, "Levelled", |x, _l| {
        x[0]
    }
}

/// Soft-datum offset of a plane at a fixed reference point c (PlaneOffsetObs): slots [n(3), d],
/// obs \[l\]. l + v = d − ⟨n, c⟩, the signed distance of the plane from c along its normal (sign
/// reversed). Unlike the identity observation of d (spec §4.7 item 2, whose "drawback is that these
/// values depend on the datum"), it does not change when the model origin moves, as long as c is a
/// point of the plane's own geometry (see [`crate::popa3d::plane_reference_points`]): d and ⟨n, c⟩
/// change by the same ⟨n, t⟩, so a rotating normal pivots the plane about c, not about the origin.
pub struct PlaneOffset {
    /// The reference point c (model coordinates, constant during the adjustment).
    pub c: [f64; 3],
}
impl Equation for PlaneOffset {
    fn kind(&self) -> &str {
        "PlaneOffsetObs"
    }
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D {
        x[3] - (x[0] * self.c[0] + x[1] * self.c[1] + x[2] * self.c[2]) - l[0]
    }
}

/// Standard rotation matrix of a (unit) quaternion (spec §4.2, corrected T 3.13/3.35).
pub fn rotation<D: Scalar>(q: &[D; 4]) -> [[D; 3]; 3] {
    let (q0, q1, q2, q3) = (q[0], q[1], q[2], q[3]);
    let two = 2.0;
    [
        [q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, (q1 * q2 - q0 * q3) * two, (q1 * q3 + q0 * q2) * two],
        [(q1 * q2 + q0 * q3) * two, q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, (q2 * q3 - q0 * q1) * two],
        [(q1 * q3 - q0 * q2) * two, (q2 * q3 + q0 * q1) * two, q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3],
    ]
}

/// gon → rad.
pub const GON: f64 = std::f64::consts::PI / 200.0;

/// Polar (Hz, V in gon, s in m) → instrument frame (T 3.33: Hz clockwise from +y).
pub fn polar_to_local<D: Scalar>(hz: D, v: D, s: D) -> V3<D> {
    let (shz, chz) = (hz * GON).sin_cos();
    let (sv, cv) = (v * GON).sin_cos();
    [s * sv * shz, s * sv * chz, s * cv]
}

/// Target point of a pointing: p = R(q)·x + (tx, ty, tz + iH) (spec §4.4).
pub fn pointing_target<D: Scalar>(q: &[D; 4], t: &V3<D>, ih: f64, hz: D, v: D, s: D) -> V3<D> {
    let xl = polar_to_local(hz, v, s);
    let r = rotation(q);
    [
        r[0][0] * xl[0] + r[0][1] * xl[1] + r[0][2] * xl[2] + t[0],
        r[1][0] * xl[0] + r[1][1] * xl[1] + r[1][2] * xl[2] + t[1],
        r[2][0] * xl[0] + r[2][1] * xl[1] + r[2][2] * xl[2] + t[2] + ih,
    ]
}

/// One target plane of a polar pointing (PointOnFace; PointOnEdge uses two, PointOnNode three of
/// these conditions on the same three observations): slots [q0..q3, tx, ty, tz, n(3), d],
/// obs [Hz, V, s]. ⟨p, n⟩ − d = 0 (T 3.42).
pub struct PointOnPlanePolar {
    /// Instrument height iH (constant).
    pub ih: f64,
    /// Class name for reports: PointOnFace, PointOnEdge or PointOnNode.
    pub class: &'static str,
}
impl Equation for PointOnPlanePolar {
    fn kind(&self) -> &str {
        self.class
    }
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D {
        let q = [x[0], x[1], x[2], x[3]];
        let t = [x[4], x[5], x[6]];
        let n = [x[7], x[8], x[9]];
        let p = pointing_target(&q, &t, self.ih, l[0], l[1], l[2]);
        dot(&p, &n) - x[10]
    }
}

/// A pointing for the starting-value search: polar values and the current target planes.
#[derive(Clone, Debug)]
pub struct Pointing {
    pub hz_gon: f64,
    pub v_gon: f64,
    pub s: f64,
    /// (unit normal, d) of each target plane (1 face, 2 edge, 3 node).
    pub planes: Vec<([f64; 3], f64)>,
}

/// Starting values of one set-up by the spec's grid search (§4.4, P11): a levelled instrument is
/// assumed, R = R_z(i) for i = 0, 1, …, 399 gon, and for each i the translation comes from the
/// linear least-squares problem ⟨R x_k + t + (0, 0, iH), n_j⟩ − d_j = v. Returns the quaternion,
/// translation and Σv² of the best i, or None with fewer than 3 independent plane equations.
pub fn polar_start(pointings: &[Pointing], ih: f64) -> Option<([f64; 4], [f64; 3], f64)> {
    let mut best: Option<([f64; 4], [f64; 3], f64)> = None;
    for i in 0..400 {
        let a = i as f64 * GON;
        let q = [(a / 2.0).cos(), 0.0, 0.0, (a / 2.0).sin()];
        let r = rotation(&q);
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atb = nalgebra::Vector3::<f64>::zeros();
        let mut rows: Vec<([f64; 3], f64)> = Vec::new();
        for pt in pointings {
            let xl = polar_to_local(pt.hz_gon, pt.v_gon, pt.s);
            let rx = [
                r[0][0] * xl[0] + r[0][1] * xl[1] + r[0][2] * xl[2],
                r[1][0] * xl[0] + r[1][1] * xl[1] + r[1][2] * xl[2],
                r[2][0] * xl[0] + r[2][1] * xl[1] + r[2][2] * xl[2] + ih,
            ];
            for &(n, d) in &pt.planes {
                let nv = nalgebra::Vector3::new(n[0], n[1], n[2]);
                let rhs = d - (n[0] * rx[0] + n[1] * rx[1] + n[2] * rx[2]);
                ata += nv * nv.transpose();
                atb += nv * rhs;
                rows.push((n, rhs));
            }
        }
        let chol = ata.cholesky()?;
        let t = chol.solve(&atb);
        let ssr: f64 = rows.iter().map(|(n, rhs)| (n[0] * t[0] + n[1] * t[1] + n[2] * t[2] - rhs).powi(2)).sum();
        if best.as_ref().is_none_or(|b| ssr < b.2) {
            best = Some((q, [t[0], t[1], t[2]], ssr));
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::{ad_gradient, finite_difference_gradient};

    fn unit(v: [f64; 3]) -> [f64; 3] {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    }
    fn pl(n: [f64; 3], d: f64) -> Vec<f64> {
        let n = unit(n);
        vec![n[0], n[1], n[2], d]
    }

    fn check<E: Equation>(eq: &E, x: &[f64], l: &[f64]) {
        let g = ad_gradient(eq, x, l);
        let fd = finite_difference_gradient(eq, x, l, 1e-6);
        for (k, (a, b)) in g.iter().zip(&fd).enumerate() {
            assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{}: slot {k}: AD {a} vs FD {b}", eq.kind());
        }
        assert!(g.iter().any(|v| *v != 0.0), "{}: zero gradient", eq.kind());
    }

    /// AD gradients equal central finite differences for every equation type (acceptance).
    #[test]
    fn ad_equals_finite_differences_for_every_equation() {
        let a = pl([1.0, 0.1, 0.05], 3.0);
        let a2 = pl([0.98, 0.12, 0.04], 5.5);
        let b = pl([-0.1, 1.0, 0.02], 2.0);
        let c = pl([0.03, -0.05, 1.0], 2.7);
        let e = pl([0.7, 0.7, 0.1], 1.0);
        let f = pl([0.1, -0.6, 0.8], -1.5);
        let cat = |v: &[&Vec<f64>]| v.iter().flat_map(|p| p.iter().copied()).collect::<Vec<f64>>();
        check(&DistanceFaceFace, &cat(&[&a, &a2]), &[2.4]);
        check(&DistanceFaceEdge, &cat(&[&a2, &b, &c]), &[1.0]);
        check(&DistanceFaceNode, &cat(&[&a2, &a, &b, &c]), &[2.0]);
        check(&DistanceEdgeEdge, &cat(&[&b, &c, &e, &f]), &[2.0]);
        check(&DistanceEdgeNode, &cat(&[&b, &c, &a, &e, &f]), &[2.0]);
        check(&DistanceNodeNode, &cat(&[&a, &b, &c, &e, &f, &a2]), &[3.0]);
        let n = |p: &Vec<f64>| p[..3].to_vec();
        check(&ConstraintFaceFace, &[n(&a), n(&b)].concat(), &[0.0]);
        check(&ConstraintFaceEdge, &[n(&a), n(&b), n(&c)].concat(), &[1.0]);
        check(&ConstraintEdgeEdge, &[n(&a), n(&b), n(&e), n(&f)].concat(), &[0.0]);
        check(&RelativeDistancePlanePlane, &[3.0, 5.5], &[2.4]);
        check(&RelativeAngleNormalNormal, &[n(&a), n(&a2)].concat(), &[0.99]);
        check(&NormNvObs, &n(&e), &[1.0]);
        check(&NormNvRestriction, &n(&e), &[]);
        check(&NormQ, &[0.9, 0.1, -0.2, 0.3], &[]);
        check(&Levelled, &[0.01], &[]);
        check(&PlaneOffset { c: [120.0, -35.5, 7.25] }, &a, &[-2.0]);
        let q = unit([0.9, 0.02, -0.01]);
        let setup = [q[0], q[1], q[2], 0.3, 1.0, 2.0, 0.5];
        check(
            &PointOnPlanePolar { ih: 1.5, class: "PointOnFace" },
            &[setup.to_vec(), a.clone()].concat(),
            &[123.4, 97.0, 4.2],
        );
        check(&crate::fits::PointOnCircle, &[1.0, 2.0, 3.0], &[3.5, 4.0]);
        check(&crate::fits::PointOnPlane, &a, &[1.0, 2.0, 0.5]);
        check(&crate::fits::LineYofX, &[1.0, 2.0], &[0.5, 2.1]);
    }

    #[test]
    fn derived_points_lie_on_their_planes() {
        let (a, b, c) = (pl([1.0, 0.1, 0.05], 3.0), pl([-0.1, 1.0, 0.02], 2.0), pl([0.03, -0.05, 1.0], 2.7));
        let v3 = |p: &Vec<f64>| [p[0], p[1], p[2]];
        let p = node_point(&v3(&a), a[3], &v3(&b), b[3], &v3(&c), c[3]);
        for q in [&a, &b, &c] {
            assert!((dot(&v3(q), &p) - q[3]).abs() < 1e-12);
        }
        let e = edge_point(&v3(&a), a[3], &v3(&b), b[3]);
        assert!((dot(&v3(&a), &e) - a[3]).abs() < 1e-12 && (dot(&v3(&b), &e) - b[3]).abs() < 1e-12);
        // rotation is proper: det = +1 for a unit quaternion
        let q = unit([0.5, 0.5, 0.5]);
        let qq = [0.5, q[0] * 0.866_025_403_784_438_6, q[1] * 0.866_025_403_784_438_6, q[2] * 0.866_025_403_784_438_6];
        let r = rotation(&qq);
        let det = dot(&r[0], &cross(&r[1], &r[2]));
        assert!((det - 1.0).abs() < 1e-12);
    }

    #[test]
    fn grid_search_recovers_a_levelled_setup() {
        // Room box: planes x=0, x=6, y=0, y=4, z=0, z=3; instrument at (2, 1.5, 0) with iH=1.4, rotated 137 gon.
        let planes = [
            ([1.0, 0.0, 0.0], 0.0),
            ([1.0, 0.0, 0.0], 6.0),
            ([0.0, 1.0, 0.0], 0.0),
            ([0.0, 1.0, 0.0], 4.0),
            ([0.0, 0.0, 1.0], 0.0),
            ([0.0, 0.0, 1.0], 3.0),
        ];
        let kappa = 137.0 * GON;
        let q = [(kappa / 2.0).cos(), 0.0, 0.0, (kappa / 2.0).sin()];
        let t = [2.0, 1.5, 0.0];
        let ih = 1.4;
        let r = rotation(&q);
        let mut pts = Vec::new();
        // Aim at points on planes, compute polar values in the instrument frame.
        let targets = [
            ([0.0, 2.0, 1.0], 0usize),
            ([6.0, 1.0, 2.0], 1),
            ([3.0, 0.0, 1.5], 2),
            ([1.0, 4.0, 0.5], 3),
            ([4.0, 3.0, 0.0], 4),
            ([2.5, 2.5, 3.0], 5),
        ];
        for (p, k) in targets {
            let dxw = [p[0] - t[0], p[1] - t[1], p[2] - t[2] - ih];
            // x_local = Rᵀ dxw
            let xl = [
                r[0][0] * dxw[0] + r[1][0] * dxw[1] + r[2][0] * dxw[2],
                r[0][1] * dxw[0] + r[1][1] * dxw[1] + r[2][1] * dxw[2],
                r[0][2] * dxw[0] + r[1][2] * dxw[1] + r[2][2] * dxw[2],
            ];
            let s = (xl[0] * xl[0] + xl[1] * xl[1] + xl[2] * xl[2]).sqrt();
            let mut hz = xl[0].atan2(xl[1]) / GON;
            if hz < 0.0 {
                hz += 400.0;
            }
            let v = (xl[2] / s).acos() / GON;
            pts.push(Pointing { hz_gon: hz, v_gon: v, s, planes: vec![planes[k]] });
        }
        let (qs, ts, ssr) = polar_start(&pts, ih).unwrap();
        let ang = 2.0 * qs[3].atan2(qs[0]) / GON;
        assert!((ang - 137.0).abs() < 1e-9 || (ang - 137.0 + 400.0).abs() < 1e-9, "{ang}");
        assert!(ssr < 1e-18 && (ts[0] - 2.0).abs() < 1e-9 && (ts[1] - 1.5).abs() < 1e-9 && ts[2].abs() < 1e-9);
    }
}
