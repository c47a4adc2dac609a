//! Writer tests: read the output back with independent readers (`gltf` crate, `tobj`) and compare
//! with the scene that was written.

use crate::*;

const O: [f64; 3] = [458_123.0, 5_438_456.0, 100.0];

/// A 2 × 3 × 4 box at a UTM-like position: 12 triangles, area 2·(6 + 8 + 12) = 52, walls and a
/// roof in different materials, plus a child node with a line set.
fn box_scene() -> Scene {
    let (sx, sy, sz) = (2.0, 3.0, 4.0);
    let c = |x: f64, y: f64, z: f64| [O[0] + 10.0 + x * sx, O[1] - 5.0 + y * sy, O[2] + z * sz];
    let v = [
        c(0., 0., 0.),
        c(1., 0., 0.),
        c(1., 1., 0.),
        c(0., 1., 0.),
        c(0., 0., 1.),
        c(1., 0., 1.),
        c(1., 1., 1.),
        c(0., 1., 1.),
    ];
    let mut walls = TriangleMesh::new(Some(0));
    walls.positions = v.to_vec();
    walls.indices = vec![
        0, 2, 1, 0, 3, 2, // bottom (outward = −z)
        0, 1, 5, 0, 5, 4, // y = 0
        1, 2, 6, 1, 6, 5, // x = 1
        2, 3, 7, 2, 7, 6, // y = 1
        3, 0, 4, 3, 4, 7, // x = 0
    ];
    let mut roof = TriangleMesh::new(Some(2));
    roof.positions = vec![v[4], v[5], v[6], v[7]];
    roof.indices = vec![0, 1, 2, 0, 2, 3];
    roof.normals = Some(vec![[0.0, 0.0, 2.0]; 4]);
    let mut node = MeshNode::new("box one");
    node.extras = Some(serde_json::json!({"gml_id": "B1"}));
    node.meshes = vec![walls, roof];
    let mut child = MeshNode::new("edges");
    child.lines.push(LineSet {
        positions: vec![v[0], v[6]],
        indices: vec![0, 1],
        colors: Some(vec![[1.0, 0.0, 0.0, 1.0]; 2]),
        material: None,
    });
    node.children.push(child);
    Scene {
        nodes: vec![node],
        materials: vec![
            Material::new("wall", [0.9, 0.9, 0.85, 1.0]),
            Material::new("unused", [0.0, 0.0, 1.0, 1.0]),
            Material::new("roof", [0.7, 0.1, 0.1, 1.0]),
        ],
        origin: O,
        crs: Some("EPSG:25832".into()),
        generator: Some("mesh-export test".into()),
    }
}

#[test]
fn area_and_counts() {
    let s = box_scene();
    assert_eq!(s.triangle_count(), 12);
    assert!((s.area() - 52.0).abs() < 1e-9);
    let (min, max) = s.bounds().unwrap();
    assert_eq!(max[2] - min[2], 4.0);
    // centre x,y rounded, bottom z
    assert_eq!(s.auto_origin(), [O[0] + 11.0, (O[1] - 5.0 + 1.5f64).round(), O[2]]);
}

#[test]
fn glb_reads_back_with_gltf_crate() {
    let s = box_scene();
    let mut glb = Vec::new();
    write_glb(&s, &mut glb).unwrap();
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize, glb.len());
    assert_eq!(glb.len() % 4, 0);
    let g = ::gltf::Gltf::from_slice(&glb).expect("valid glb");
    let blob = g.blob.as_ref().expect("BIN chunk");
    // Only used materials are written, in scene order.
    let names: Vec<_> = g.materials().map(|m| m.name().unwrap().to_string()).collect();
    assert_eq!(names, ["wall", "roof"]);
    // The root node records the origin exactly and turns Z-up into Y-up.
    let root = g.default_scene().unwrap().nodes().next().unwrap();
    let extras: serde_json::Value = serde_json::from_str(root.extras().as_ref().unwrap().get()).unwrap();
    assert_eq!(extras["origin"], serde_json::json!(O));
    assert_eq!(extras["crs"], "EPSG:25832");
    let node = root.children().next().unwrap();
    assert_eq!(node.name(), Some("box one"));
    let mesh = node.mesh().unwrap();
    let mut area = 0.0f64;
    let mut tris = 0;
    for prim in mesh.primitives() {
        let r = prim.reader(|_| Some(&blob[..]));
        let pos: Vec<[f32; 3]> = r.read_positions().unwrap().collect();
        // min/max of the accessor are the exact extremes of the written values.
        let acc = prim.get(&::gltf::Semantic::Positions).unwrap();
        let min: Vec<f32> = serde_json::from_value(acc.min().unwrap()).unwrap();
        for k in 0..3 {
            assert_eq!(min[k], pos.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min));
        }
        if let Some(n) = r.read_normals() {
            for n in n {
                assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-6);
            }
        }
        let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
        for t in idx.chunks(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| pos[i as usize].map(f64::from));
            area += crate::vec3::triangle_area(a, b, c);
            tris += 1;
        }
        // Local coordinates: world − origin.
        assert!(pos.iter().all(|p| p[0] >= 10.0 && p[0] <= 12.0 && p[1] >= -5.0 && p[1] <= -2.0));
    }
    assert_eq!(tris, 12);
    assert!((area - 52.0).abs() < 1e-5, "{area}");
    let child = node.children().next().unwrap();
    let lp = child.mesh().unwrap().primitives().next().unwrap();
    assert_eq!(lp.mode(), ::gltf::mesh::Mode::Lines);
}

#[test]
fn output_is_deterministic() {
    let s = box_scene();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    write_glb(&s, &mut a).unwrap();
    write_glb(&s.clone(), &mut b).unwrap();
    assert_eq!(a, b);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    write_obj(&s, &mut a, None).unwrap();
    write_obj(&s.clone(), &mut b, None).unwrap();
    assert_eq!(a, b);
}

#[test]
fn gltf_embedded_and_external_buffers() {
    let s = box_scene();
    let mut glb = Vec::new();
    write_glb(&s, &mut glb).unwrap();
    let from_glb = ::gltf::Gltf::from_slice(&glb).unwrap();
    let bin_glb = from_glb.blob.clone().unwrap();

    let mut text = Vec::new();
    write_gltf(&s, &mut text, GltfBuffer::Embedded).unwrap();
    let g = ::gltf::Gltf::from_slice(&text).unwrap();
    let buf = g.buffers().next().unwrap();
    let ::gltf::buffer::Source::Uri(uri) = buf.source() else { panic!("embedded buffer expected") };
    let b64 = uri.strip_prefix("data:application/octet-stream;base64,").unwrap();
    use base64::Engine as _;
    let data = base64::engine::general_purpose::STANDARD.decode(b64).unwrap();
    assert_eq!(data, bin_glb);

    let (mut text, mut bin) = (Vec::new(), Vec::new());
    write_gltf(&s, &mut text, GltfBuffer::External { uri: "model.bin", bin: &mut bin }).unwrap();
    let g = ::gltf::Gltf::from_slice(&text).unwrap();
    let ::gltf::buffer::Source::Uri(uri) = g.buffers().next().unwrap().source() else { panic!() };
    assert_eq!(uri, "model.bin");
    assert_eq!(bin, bin_glb);
}

#[test]
fn obj_reads_back_with_tobj() {
    let s = box_scene();
    let dir = tempfile_dir();
    let (mut obj, mut mtl) = (Vec::new(), Vec::new());
    write_obj(&s, &mut obj, Some(("box.mtl", &mut mtl))).unwrap();
    let text = String::from_utf8(obj.clone()).unwrap();
    assert!(text.contains(&format!("# origin: {} {} {}", O[0], O[1], O[2])));
    std::fs::write(dir.join("box.obj"), &obj).unwrap();
    std::fs::write(dir.join("box.mtl"), &mtl).unwrap();
    let (models, mats) = tobj::load_obj(
        dir.join("box.obj"),
        &tobj::LoadOptions { single_index: true, triangulate: false, ignore_lines: false, ..Default::default() },
    )
    .unwrap();
    let mats = mats.unwrap();
    assert_eq!(mats.len(), 3);
    assert_eq!(mats[2].name, "roof");
    assert_eq!(mats[2].diffuse, Some([0.7, 0.1, 0.1]));
    let mut tris = 0;
    let mut area = 0.0f64;
    for m in &models {
        let p = &m.mesh.positions;
        if m.mesh.face_arities.contains(&2) {
            continue; // the line set
        }
        assert!(m.mesh.face_arities.is_empty() || m.mesh.face_arities.iter().all(|&a| a == 3));
        for t in m.mesh.indices.chunks(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| {
                let i = i as usize * 3;
                [p[i] as f64, p[i + 1] as f64, p[i + 2] as f64]
            });
            area += crate::vec3::triangle_area(a, b, c);
            tris += 1;
        }
    }
    assert_eq!(tris, 12);
    assert!((area - 52.0).abs() < 1e-4, "{area}");
    assert!(models.iter().any(|m| m.name == "box_one"));
    assert!(text.contains("o box_one/edges\n"));
    assert!(text.contains("\nl "));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn invalid_scenes_are_refused() {
    let mut s = box_scene();
    s.nodes[0].meshes[0].indices.push(99);
    s.nodes[0].meshes[0].indices.extend([0, 1]);
    let e = write_glb(&s, &mut Vec::new()).unwrap_err();
    assert!(e.to_string().contains("index 99 out of range"), "{e}");

    let mut s = box_scene();
    s.nodes[0].meshes[0].positions[3][1] = f64::NAN;
    assert!(matches!(write_obj(&s, &mut Vec::new(), None), Err(ExportError::NonFinite { .. })));

    let mut s = box_scene();
    s.nodes[0].meshes[1].normals = Some(vec![[0.0; 3]; 4]);
    assert!(write_glb(&s, &mut Vec::new()).is_err());

    let mut s = box_scene();
    s.nodes[0].meshes[0].material = Some(7);
    assert!(write_glb(&s, &mut Vec::new()).is_err());
}

#[test]
fn empty_scene_is_a_valid_gltf() {
    let s = Scene::default();
    let mut glb = Vec::new();
    write_glb(&s, &mut glb).unwrap();
    let g = ::gltf::Gltf::from_slice(&glb).unwrap();
    assert_eq!(g.buffers().count(), 0);
    assert_eq!(g.nodes().count(), 1);
}

fn tempfile_dir() -> std::path::PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "mesh-export-test-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::SeqCst)
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A closed box written as walls + roof meshes: one `v` per corner in the object, and every edge
/// of its faces used exactly twice, so MeshLab/FreeCAD read a closed 2-manifold without merging.
#[test]
fn obj_shares_vertices_within_an_object() {
    let s = box_scene();
    let mut obj = Vec::new();
    write_obj(&s, &mut obj, None).unwrap();
    let text = String::from_utf8(obj).unwrap();
    let object = text.split("o box_one/edges").next().unwrap();
    assert_eq!(object.lines().filter(|l| l.starts_with("v ")).count(), 8, "{object}");
    let mut uses = std::collections::HashMap::<(u64, u64), u32>::new();
    for l in object.lines().filter(|l| l.starts_with("f ")) {
        let v: Vec<u64> = l[2..].split(' ').map(|c| c.split('/').next().unwrap().parse().unwrap()).collect();
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert_eq!(uses.len(), 18);
    assert!(uses.values().all(|&n| n == 2), "{uses:?}");
}
