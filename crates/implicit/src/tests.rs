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

#[test]
fn model_file_roundtrip_and_corruption() {
    let pts = generate::sphere(600, [10.0, 20.0, 30.0], 1.0, 0.0, 0.0, 3);
    let (m, _) = build(&pts, &[], &[], &BuildOptions::default(), &mut |_| {}).unwrap();
    let b = m.to_bytes();
    let back = crate::model::Model::from_bytes(&b).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.to_bytes(), b, "byte-identical rewrite");
    for cut in [0, 10, 16, 100, b.len() - 1] {
        assert!(crate::model::Model::from_bytes(&b[..cut]).is_err());
    }
    // φ vanishes on the (noise-free) sphere and has the normal's sign off it.
    let loc = m.locator();
    let on = m.eval_world(&loc, [11.0, 20.0, 30.0]).unwrap();
    let out = m.eval_world(&loc, [11.3, 20.0, 30.0]).unwrap();
    let inn = m.eval_world(&loc, [10.7, 20.0, 30.0]).unwrap();
    assert!(on.abs() < 0.02 && out > 0.1 && inn < -0.1, "{on} {out} {inn}");
}

#[test]
fn fault_cut_duplicates_vertices_only_across_the_fault() {
    use crate::fault::{cut, Fault};
    let mut r = Refiner::new([-1.0, -1.0, -1.0], [2, 2, 2], 1.0);
    r.add_points(&[[0.1, 0.1, 0.1]], 3);
    r.refine();
    let m = r.mesh();
    // A plane x = 0.05 through the whole box; and a small patch that ends inside.
    let big = Fault { name: "big".into(), tris: vec![[[0.05, -5.0, -5.0], [0.05, 5.0, -5.0], [0.05, 0.0, 5.0]]] };
    let (c, dv) = cut(&m, &[big]).unwrap();
    assert!(c.verts.len() > m.verts.len(), "vertices on the fault must be duplicated");
    assert_eq!(dv.len(), c.verts.len());
    // The cut mesh splits into two parts: no interior face joins a tet with centroid x < 0.05
    // to one with x > 0.05.
    for f in c.interior_faces() {
        let cx = |t: u32| c.corners(t as usize).iter().map(|p| p[0]).sum::<f64>() / 4.0;
        assert_eq!(cx(f.tets[0]) < 0.05, cx(f.tets[1]) < 0.05);
    }
    let far = Fault { name: "far".into(), tris: vec![[[50.0, 50.0, 50.0], [51.0, 50.0, 50.0], [50.0, 51.0, 50.0]]] };
    assert!(matches!(cut(&m, &[far]), Err(crate::Error::FaultOutsideDomain(_))));
}

#[test]
fn ic0_pcg_solves_a_small_spd_system() {
    use crate::dsi::pcg;
    // 1-D Laplacian + identity, n = 50: compare with the exact solution of a known x.
    let n = 50;
    let a = sparse_spd::laplacian_1d(n, 1.0);
    let xt: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
    let mut b = vec![0.0; n];
    a.mul(&xt, &mut b);
    let mut x = vec![0.0; n];
    let st = pcg(&a, &b, &mut x, 1e-12, 200, None).unwrap();
    assert!(st.true_residual <= 1e-12);
    for (p, q) in x.iter().zip(&xt) {
        assert!((p - q).abs() < 1e-9);
    }
}

/// Issue 40: a `.gfim` whose stored value weight is NaN or 1e300 made `implicit update` run
/// forever. Such a model is refused when read, naming the field; the solver itself refuses a
/// non-finite system.
#[test]
fn models_with_non_finite_or_huge_parameters_are_refused() {
    let points = generate::sphere(200, [0.0; 3], 1.0, 0.0, 0.0, 1);
    let opt = BuildOptions { coarse: 4, ..Default::default() };
    let (m, _) = build(&points, &[], &[], &opt, &mut |_| {}).unwrap();
    let bytes = m.to_bytes();
    assert!(crate::model::Model::from_bytes(&bytes).is_ok());
    // ϖ_value is the first f64 after magic (16), version (4), origin (24) and cell (8)
    let at = 16 + 4 + 24 + 8;
    for (v, why) in [(f64::NAN, "value weight NaN"), (1e300, "value weight 1e300"), (-1.0, "value weight -1")] {
        let mut b = bytes.clone();
        b[at..at + 8].copy_from_slice(&v.to_le_bytes());
        let e = crate::model::Model::from_bytes(&b).unwrap_err().to_string();
        assert!(e.contains(why), "{e}");
    }
    // the CG iteration cap (after 6 f64 parameters)
    let mut b = bytes.clone();
    b[at + 48..at + 56].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(crate::model::Model::from_bytes(&b).unwrap_err().to_string().contains("iteration cap"));
    // builds refuse a weight beyond MAX_WEIGHT before any solve
    let mut opt = opt;
    opt.weights.normal = 1e308;
    let t0 = std::time::Instant::now();
    assert!(build(&points, &[], &[], &opt, &mut |_| {}).unwrap_err().to_string().contains("normal weight"));
    assert!(t0.elapsed().as_secs() < 20);
}

/// Every reproducer the fuzzer found (fuzz/regressions/gfim) is refused when read; the corpus
/// seed reads.
#[test]
fn fuzz_regressions_do_not_panic() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let files = |d: &str| -> Vec<_> { std::fs::read_dir(root.join(d)).unwrap().map(|e| e.unwrap().path()).collect() };
    let bad = files("regressions/gfim");
    assert!(!bad.is_empty(), "no reproducers");
    for f in bad {
        assert!(crate::model::Model::from_bytes(&std::fs::read(&f).unwrap()).is_err(), "{}", f.display());
    }
    for f in files("corpus/gfim") {
        assert!(crate::model::Model::from_bytes(&std::fs::read(&f).unwrap()).is_ok(), "{}", f.display());
    }
}
