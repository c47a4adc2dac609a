//! Polar pointings through the popa3d mapping: a total-station set-up on the project's OBJ sketch
//! (fixtures/popa3d/rooms.obj), starting values from the spec's grid search (P11), a levelled
//! instrument (P3/P8: q1 = q2 = 0), pointings simulated from the sketch geometry.
mod common;

use adjust::equations::{rotation, GON};
use adjust::popa3d::{adjust_model, ModelOptions};
use normalize::conditions::{sketch_priors, Ranges, SketchOptions};
use popa3d_model::*;

fn model() -> Popa3d {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/popa3d/rooms.obj");
    let bytes = std::fs::read(&root).expect("rooms.obj fixture");
    let soup = normalize::obj::read_sketch(&bytes, "rooms.obj").unwrap();
    let mut m = Popa3d::new([0.0; 3]);
    normalize::normalize_into(&mut m, &soup, &normalize::Tolerances::default()).unwrap();
    let r = Ranges::whole(&m);
    sketch_priors(&mut m, &r, &SketchOptions::default());
    m
}

#[test]
fn levelled_setup_found_by_grid_search_and_adjusted() {
    let mut m = model();
    let inc = Incidence::new(&m);
    let pos = m.node_positions(&inc).unwrap();
    // Instrument inside the bounding box, rotated by 123 gon about z, levelled.
    let (lo, hi) = pos.iter().fold(([f64::MAX; 3], [f64::MIN; 3]), |(a, b), p| {
        ([a[0].min(p[0]), a[1].min(p[1]), a[2].min(p[2])], [b[0].max(p[0]), b[1].max(p[1]), b[2].max(p[2])])
    });
    let t = [lo[0] + 0.3 * (hi[0] - lo[0]), lo[1] + 0.4 * (hi[1] - lo[1]), lo[2]];
    let ih = 1.2;
    let kappa = 123.0 * GON;
    let q = [(kappa / 2.0).cos(), 0.0, 0.0, (kappa / 2.0).sin()];
    let r = rotation(&q);
    let fp = m.add_fixed_point(FixedPoint { t: [0.0; 3] });
    let su = m.add_setup(Setup { fixed_point: fp, instrument_height: ih, q: [0.0; 4], levelled: true });
    m.add_observation(Observation::new(ObsKind::NormQ { setup: su }, ObsOrigin::Consistency));
    // Point at the centroid of each face's outer loop (visible or not: a simulation).
    let mut n = 0;
    for f in 0..m.faces.len() {
        let loops = m.face_loops(&inc, FaceId::from(f), &pos).unwrap();
        let c = loops[0]
            .iter()
            .fold([0.0; 3], |a, nd| [a[0] + pos[nd.idx()][0], a[1] + pos[nd.idx()][1], a[2] + pos[nd.idx()][2]]);
        let k = loops[0].len() as f64;
        let p = [c[0] / k, c[1] / k, c[2] / k];
        let (hz, v, s) = common::polar_reading(&r, t, ih, p);
        m.add_observation(Observation::new(
            ObsKind::PointOnFace {
                setup: su,
                target: FaceId::from(f),
                hz: Measured::new(hz, 0.0005),
                v: Measured::new(v, 0.0005),
                s: Measured::new(s, 0.002),
            },
            ObsOrigin::Measured,
        ));
        n += 1;
    }
    assert!(n >= 6);
    let report = adjust_model(&mut m, &ModelOptions::default()).unwrap();
    let s = m.setups[0];
    let ang = 2.0 * s.q[3].atan2(s.q[0]) / GON;
    assert!((ang.rem_euclid(400.0) - 123.0).abs() < 1e-6, "rotation {ang} gon, q {:?}", s.q);
    assert!(s.q[1].abs() < 1e-12 && s.q[2].abs() < 1e-12, "levelled: {:?}", s.q);
    let tt = m.fixed_points[0].t;
    for k in 0..3 {
        assert!((tt[k] - t[k]).abs() < 1e-6, "translation {tt:?} vs {t:?}");
    }
    assert!(report.per_type.contains_key("PointOnFace"));
    assert!((report.redundancy_sum - report.redundancy as f64).abs() < 1e-6);
}
