//! Unit tests against analytic truth.

use crate::contour::{iso_surface, CsgOp};
use crate::generate;
use crate::geom::{norm, sub};
use crate::mesh::{Locator, Refiner};
use crate::model::{build, BuildOptions};

fn mean_sphere_distance(s: &crate::contour::Surface, c: [f64; 3], r: f64) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for t in &s.tris {
        let [a, b, d] = t.map(|i| s.positions[i as usize]);
        let area = 0.5 * norm(crate::geom::cross(sub(b, a), sub(d, a)));
        let m = [(a[0] + b[0] + d[0]) / 3.0, (a[1] + b[1] + d[1]) / 3.0, (a[2] + b[2] + d[2]) / 3.0];
        num += area * (norm(sub(m, c)) - r).abs();
        den += area;
    }
    num / den
}

#[test]
fn refinement_is_conforming() {
    let mut r = Refiner::new([0.0; 3], [2, 2, 2], 1.0);
    r.add_points(&[[0.3, 0.4, 0.5], [1.7, 1.2, 0.1]], 9);
    r.refine();
    let m = r.mesh();
    // Conforming: every face is shared by two tets or lies on the box boundary.
    let faces = m.interior_faces();
    let total = m.tets.len() * 4;
    let boundary = total - 2 * faces.len();
    let mut bcount = 0;
    let mut vol = 0.0;
    for t in 0..m.tets.len() {
        let c = m.corners(t);
        vol += crate::geom::vol6(c[0], c[1], c[2], c[3]) / 6.0;
        assert!(crate::geom::vol6(c[0], c[1], c[2], c[3]) > 0.0);
    }
    assert!((vol - 8.0).abs() < 1e-9, "volume {vol}");
    // Boundary faces of the box: each has all vertices on one box face.
    for t in &m.tets {
        for skip in 0..4 {
            let f: Vec<[f64; 3]> = (0..4).filter(|&k| k != skip).map(|k| m.verts[t[k] as usize]).collect();
            if (0..3).any(|ax| f.iter().all(|p| p[ax] == 0.0) || f.iter().all(|p| p[ax] == 2.0)) {
                bcount += 1;
            }
        }
    }
    assert_eq!(boundary, bcount, "faces not shared = hanging vertices");
    assert!(m.tets.len() > 48);
}

#[test]
fn noisy_sphere_within_sigma() {
    let sigma = 0.02;
    let pts = generate::sphere(3000, [0.0; 3], 1.0, sigma, 5.0, 1);
    let t = std::time::Instant::now();
    let (m, rep) = build(&pts, &[], &[], &BuildOptions::default(), &mut |_| {}).unwrap();
    let s = iso_surface(&m.mesh, &m.phi, 0.0, None);
    let mut s2 = s.clone();
    s2.translate(m.origin);
    let d = mean_sphere_distance(&s2, [0.0; 3], 1.0);
    eprintln!("sphere: {:?} time {:?} dist {d} closed {}", rep, t.elapsed(), s.is_closed());
    assert!(d < sigma, "mean distance {d} ≥ σ {sigma}");
    assert!(s.is_closed());
    let _ = (Locator::new(&m.mesh), CsgOp::Union);
}
