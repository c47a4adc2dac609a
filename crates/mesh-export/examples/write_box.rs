//! Writes a small two-material box with a line set, at UTM-like coordinates, in every format:
//! `cargo run -p mesh-export --example write_box -- OUT_DIR` → box.glb, box.gltf, box_ext.gltf +
//! box_ext.bin, box.obj + box.mtl. Shows the whole API in one page.

use mesh_export::{GltfBuffer, LineSet, Material, MeshNode, Scene, TriangleMesh};
use std::fs::File;
use std::io::BufWriter;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    let (x0, y0, z0) = (458_100.0, 5_438_200.0, 112.0);
    let c = |x: f64, y: f64, z: f64| [x0 + 4.0 * x, y0 + 3.0 * y, z0 + 5.0 * z];
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
    walls.indices = vec![0, 2, 1, 0, 3, 2, 0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7];
    let mut roof = TriangleMesh::new(Some(1));
    roof.positions = vec![v[4], v[5], v[6], v[7]];
    roof.indices = vec![0, 1, 2, 0, 2, 3];
    roof.normals = Some(vec![[0.0, 0.0, 1.0]; 4]);
    roof.colors = Some(vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]]);
    let mut building = MeshNode::new("box");
    building.extras = Some(serde_json::json!({"gml_id": "BOX_1"}));
    building.meshes = vec![walls, roof];
    let mut edges = MeshNode::new("edges");
    edges.lines.push(LineSet {
        positions: vec![v[0], v[6], v[1], v[7]],
        indices: vec![0, 1, 2, 3],
        colors: None,
        material: Some(2),
    });
    building.children.push(edges);
    let mut scene = Scene {
        nodes: vec![building],
        materials: vec![
            Material::new("WallSurface", [0.85, 0.85, 0.8, 1.0]),
            Material::new("RoofSurface", [0.7, 0.15, 0.1, 1.0]),
            Material::new("edges", [0.0, 0.0, 0.0, 1.0]),
        ],
        crs: Some("EPSG:25832".into()),
        generator: Some("mesh-export example".into()),
        ..Default::default()
    };
    scene.origin = scene.auto_origin();
    mesh_export::write_glb(&scene, &mut BufWriter::new(File::create(dir.join("box.glb"))?))?;
    mesh_export::write_gltf(&scene, &mut BufWriter::new(File::create(dir.join("box.gltf"))?), GltfBuffer::Embedded)?;
    let mut bin = BufWriter::new(File::create(dir.join("box_ext.bin"))?);
    mesh_export::write_gltf(
        &scene,
        &mut BufWriter::new(File::create(dir.join("box_ext.gltf"))?),
        GltfBuffer::External { uri: "box_ext.bin", bin: &mut bin },
    )?;
    let mut mtl = BufWriter::new(File::create(dir.join("box.mtl"))?);
    mesh_export::write_obj(
        &scene,
        &mut BufWriter::new(File::create(dir.join("box.obj"))?),
        Some(("box.mtl", &mut mtl)),
    )?;
    println!("triangles {} area {}", scene.triangle_count(), scene.area());
    Ok(())
}
