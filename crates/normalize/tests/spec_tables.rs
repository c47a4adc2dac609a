//! The spec's regression numbers that concern normalization (spec §3.3 cuboid, Table 7.1 shape,
//! §10.1 item 21), checked against hand counts.

use normalize::conditions::{self, Ranges};
use normalize::{normalize_into, Soup, SoupPolygon, SoupSolid, Tolerances};
use popa3d_model::*;

fn quad(p: [[f64; 3]; 4], solid: usize, id: &str) -> SoupPolygon {
    SoupPolygon {
        rings: vec![p.to_vec()],
        vertex_sources: vec![(0..4).map(|i| VertexSource::CityGml { polygon: id.into(), ring: 0, index: i }).collect()],
        solid,
        source: FaceSource { polygon: id.into(), semantic: Some("WallSurface".into()), owner: None, merged: vec![] },
        locator: id.into(),
        parent: None,
    }
}

/// Box faces (outward, counter-clockwise seen from outside) from 8 corners indexed by bits (x, y, z).
fn box_faces(c: &dyn Fn(usize) -> [f64; 3], solid: usize, tag: &str) -> Vec<SoupPolygon> {
    let f =
        |a: usize, b: usize, cc: usize, d: usize, n: &str| quad([c(a), c(b), c(cc), c(d)], solid, &format!("{tag}{n}"));
    vec![
        f(0, 2, 3, 1, "bottom"), // z = 0, normal −z
        f(4, 5, 7, 6, "top"),
        f(0, 1, 5, 4, "front"), // y = 0, normal −y
        f(2, 6, 7, 3, "back"),
        f(0, 4, 6, 2, "left"), // x = 0, normal −x
        f(1, 3, 7, 5, "right"),
    ]
}

fn cuboid(theta: f64, dims: [f64; 3], t: [f64; 3]) -> Soup {
    let (s, co) = theta.sin_cos();
    let corner = move |i: usize| {
        let (x, y, z) = ((i & 1) as f64 * dims[0], ((i >> 1) & 1) as f64 * dims[1], ((i >> 2) & 1) as f64 * dims[2]);
        [co * x - s * y + t[0], s * x + co * y + t[1], z + t[2]]
    };
    Soup {
        name: "cuboid".into(),
        solids: vec![SoupSolid { kind: SolidKind::Room, name: Some("cuboid".into()) }],
        polygons: box_faces(&corner, 0, "c-"),
        source_rings: 6,
        multisurface_only: false,
    }
}

#[test]
fn cuboid_stored_values_24_to_12_and_checks_15_to_3() {
    // spec §3.3: a cuboid needs 9 pieces; 8 points store 24 (redundancy 15); normalized with
    // parameter sharing 6 parameters + 6 d = 12 (redundancy 3: two unit norms and α6 = 0).
    let soup = cuboid(0.4, [5.0, 3.0, 2.5], [10.0, 20.0, 1.0]);
    let tol = Tolerances { share_orthogonal: true, ..Default::default() };
    let mut m = Popa3d::new([0.0; 3]);
    let r = normalize_into(&mut m, &soup, &tol).expect("cuboid normalizes");
    let st = &r.counts.stages;
    assert_eq!(st[0].nodes * 3, 24, "8 points store 24 coordinates");
    assert_eq!(st[0].nodes * 3 - 9, 15, "redundancy of the point model");
    // Unnormalized planes: 6 × (n, d) = 24 stored values, redundancy 15.
    assert_eq!(st[1].planes + st[1].parameters, 24);
    let last = r.counts.last();
    assert_eq!((last.planes, last.normals, last.parameters), (6, 3, 6));
    assert_eq!(m.object_unknowns(), 12);
    // The consistency checks the model needs: unit norms of distinct parameter sets + zero fixes.
    let rg = Ranges { faces: 0..6, planes: 0..6, normals: 0..3, parameters: 0..6 };
    let c = conditions::semantic(&mut m, &rg, &conditions::ConditionOptions::default());
    let fixes = m.observations.iter().filter(|o| matches!(o.kind, ObsKind::ParameterFix { .. })).count();
    assert_eq!(c.norm, 2, "‖(α1,α2,α3)‖ = 1 and ‖(α4,α5,α6)‖ = 1");
    assert_eq!(fixes, 1, "α6 = 0");
    assert_eq!(c.norm + fixes, 12 - 9, "checks = stored − 9");
    // The recomputed corners are the input corners.
    assert!(r.counts.max_node_shift < 1e-9, "shift {}", r.counts.max_node_shift);
    // Sharing encodes the walls' orthogonality; only roof/floor ⟂ walls remain as conditions.
    assert_eq!(c.orthogonality, 2);
    assert_eq!(c.parallelism + c.coplanarity, 0);
}

#[test]
fn cuboid_without_sharing_has_nine_parameters() {
    let soup = cuboid(0.4, [5.0, 3.0, 2.5], [10.0, 20.0, 1.0]);
    let mut m = Popa3d::new([0.0; 3]);
    let r = normalize_into(&mut m, &soup, &Tolerances::default()).unwrap();
    let last = r.counts.last();
    assert_eq!((last.planes, last.normals, last.parameters), (6, 3, 9));
}

/// k box rooms in a row sharing walls (the shape of the TU Berlin floor, Table 7.1).
fn row_of_rooms(k: usize) -> Soup {
    let mut soup = Soup { name: "row".into(), ..Default::default() };
    for r in 0..k {
        let x0 = r as f64 * 4.0;
        let corner =
            move |i: usize| [x0 + (i & 1) as f64 * 4.0, ((i >> 1) & 1) as f64 * 5.0, ((i >> 2) & 1) as f64 * 3.0];
        soup.solids.push(SoupSolid { kind: SolidKind::Room, name: Some(format!("room{r}")) });
        soup.polygons.extend(box_faces(&corner, r, &format!("r{r}-")));
        soup.source_rings += 6;
    }
    soup
}

#[test]
fn table_7_1_shape_rooms_in_a_row() {
    let k = 7;
    let soup = row_of_rooms(k);
    let mut m = Popa3d::new([0.0; 3]);
    let r = normalize_into(&mut m, &soup, &Tolerances::default()).unwrap();
    let st = &r.counts.stages;
    // Hand count: nodes 4(k+1); shared walls are one face each: 6k − (k−1) faces; edges: 4 along x
    // per room (4k) + 4 per cross-wall section ((k+1)·4).
    let nodes = 4 * (k + 1);
    let faces = 6 * k - (k - 1);
    let edges = 4 * k + 4 * (k + 1);
    for s in &st[1..] {
        assert_eq!((s.nodes, s.edges, s.faces), (nodes, edges, faces), "stage {}", s.stage);
    }
    assert_eq!(st[0].faces, 6 * k, "the soup has every room's walls");
    // planar: one plane and normal per face; parallel: 3 normals, 9 parameters; coplanar: floor,
    // ceiling, front, back and k+1 cross walls.
    assert_eq!((st[1].planes, st[1].normals, st[1].parameters), (faces, faces, 3 * faces));
    assert_eq!((st[2].normals, st[2].parameters), (3, 9));
    assert_eq!(st[3].planes, k + 5);
    // Unknowns relative to 3 × nodes decrease stage by stage (88 % → 22 % → 7 % in Table 7.1).
    assert!(st[1].unknowns_percent > st[2].unknowns_percent && st[2].unknowns_percent > st[3].unknowns_percent);
    assert!((st[3].unknowns_percent - 100.0 * (k + 5 + 9) as f64 / (3 * nodes) as f64).abs() < 1e-12);
    // Every shared wall separates two rooms.
    let shared = m.faces.iter().filter(|f| m.solids[f.front.idx()].kind == SolidKind::Room).count();
    assert_eq!(shared, k - 1);
}

#[test]
fn write_read_write_is_byte_identical() {
    let soup = cuboid(0.123456789, [5.1, 3.3, 2.7], [345678.123, 5712345.987, 101.5]);
    let mut m = Popa3d::new([345678.0, 5712345.0, 101.0]);
    let tol = Tolerances { share_orthogonal: true, ..Default::default() };
    normalize_into(&mut m, &soup, &tol).unwrap();
    let rg = Ranges { faces: 0..6, planes: 0..6, normals: 0..3, parameters: 0..6 };
    conditions::semantic(&mut m, &rg, &conditions::ConditionOptions::default());
    conditions::sketch_priors(&mut m, &rg, &conditions::SketchOptions::default());
    let a = popa3d_model::write_to_vec(&m).unwrap();
    let m2 = popa3d_model::read(&a).unwrap();
    assert_eq!(m, m2, "read gives back the same model, every double bit-identical");
    let b = popa3d_model::write_to_vec(&m2).unwrap();
    assert_eq!(a, b);
}

#[test]
fn open_box_is_rejected_with_ta03() {
    let mut soup = cuboid(0.0, [1.0, 1.0, 1.0], [0.0; 3]);
    soup.polygons.pop();
    let mut m = Popa3d::new([0.0; 3]);
    let e = normalize_into(&mut m, &soup, &Tolerances::default()).unwrap_err();
    assert_eq!(e.rule, "TA03");
    assert!(m.faces.is_empty(), "a rejected object leaves the model unchanged");
}

#[test]
fn degenerate_and_non_planar_faces_are_rejected() {
    let mut soup = cuboid(0.0, [1.0, 1.0, 1.0], [0.0; 3]);
    soup.polygons[0].rings[0] = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0004]];
    let e = normalize_into(&mut Popa3d::default(), &soup, &Tolerances::default()).unwrap_err();
    assert_eq!((e.rule.as_str(), e.element.as_str()), ("TA05", "c-bottom"));
    let mut soup = cuboid(0.0, [1.0, 1.0, 1.0], [0.0; 3]);
    // Lift one top corner by 0.5 m: the top and two walls are far from planar.
    for p in soup.polygons.iter_mut() {
        for q in p.rings[0].iter_mut() {
            if *q == [1.0, 1.0, 1.0] {
                q[2] = 1.5;
            }
        }
    }
    let e = normalize_into(&mut Popa3d::default(), &soup, &Tolerances::default()).unwrap_err();
    assert_eq!(e.rule, "GA-PLANAR");
}

#[test]
fn validation_layers_pass_on_normalized_models_and_catch_breakage() {
    use popa3d_model::validate::validate;
    // A normalized row of rooms with sketch priors validates (Euler–Poincaré with 1 shell, no rings).
    let soup = row_of_rooms(3);
    let mut m = Popa3d::new([0.0; 3]);
    normalize_into(&mut m, &soup, &Tolerances::default()).unwrap();
    let r = Ranges::whole(&m);
    conditions::sketch_priors(&mut m, &r, &conditions::SketchOptions::default());
    // Priors alone do not fix the datum: AA02 counts 6 + 2 + 3 + 3 = 14 equations for 8 + 9 unknowns.
    let v = validate(&m);
    assert_eq!(v.iter().map(|x| x.rule.as_str()).collect::<Vec<_>>(), vec!["AA02"], "{v:?}");
    // With a soft datum it is complete.
    conditions::semantic(&mut m, &r, &conditions::ConditionOptions::default());
    assert!(validate(&m).is_empty(), "{:?}", validate(&m));
    // Break the topology: drop a half-edge → TA03/TA05/TA06/TA07 and the layer stops there.
    let mut b = m.clone();
    b.half_edges.pop();
    let v = validate(&b);
    assert!(v.iter().any(|x| x.rule == "TA03") && v.iter().all(|x| x.rule.starts_with("TA")), "{v:?}");
    // A σ of 0 is a model-layer violation.
    let mut c = m.clone();
    c.observations.push(Observation::new(
        ObsKind::DistanceFaceFace { a: FaceId(0), b: FaceId(1), l: Measured::new(1.0, 0.0) },
        ObsOrigin::Measured,
    ));
    assert_eq!(validate(&c)[0].rule, "MA12");
}

#[test]
fn euler_poincare_with_inner_rings_table_6_3() {
    use popa3d_model::validate::topology_axioms;
    // A cube whose top face carries a smaller box (its footprint is an inner ring of the top face,
    // the box's bottom is not a face): Table 6.3 a) shape, v − e + f = 2(s − h) + r.
    let mut soup = cuboid(0.0, [4.0, 4.0, 2.0], [0.0; 3]);
    let top = soup.polygons.iter_mut().find(|p| p.locator == "c-top").unwrap();
    top.rings.push(vec![[1.0, 1.0, 2.0], [1.0, 3.0, 2.0], [3.0, 3.0, 2.0], [3.0, 1.0, 2.0]]);
    top.vertex_sources
        .push((0..4).map(|i| VertexSource::CityGml { polygon: "c-top".into(), ring: 1, index: i }).collect());
    let b = |i: usize| [1.0 + (i & 1) as f64 * 2.0, 1.0 + ((i >> 1) & 1) as f64 * 2.0, 2.0 + ((i >> 2) & 1) as f64];
    let mut bump = box_faces(&b, 0, "b-");
    bump.remove(0); // no bottom
    soup.polygons.extend(bump);
    let mut m = Popa3d::new([0.0; 3]);
    normalize_into(&mut m, &soup, &Tolerances::default()).unwrap();
    assert_eq!((m.nodes.len(), m.edges.len(), m.faces.len()), (16, 24, 11));
    // 16 − 24 + 11 = 3 = 2(1 − 0) + 1 inner ring.
    let inc = Incidence::new(&m);
    assert!(topology_axioms(&m, &inc).is_empty(), "{:?}", topology_axioms(&m, &inc));
}
