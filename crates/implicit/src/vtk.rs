//! The field on the mesh as a legacy ASCII VTK unstructured grid (ParaView, VisIt, meshio).

use std::io::Write;

use crate::geom::V3;
use crate::mesh::TetMesh;

/// Writes `mesh` (shifted by `origin`) with point scalars `fields` (name, values per vertex).
/// Numbers use Rust's shortest round-trip formatting: identical input gives identical bytes.
pub fn write_vtk(w: &mut dyn Write, mesh: &TetMesh, origin: V3, fields: &[(&str, &[f64])]) -> std::io::Result<()> {
    writeln!(w, "# vtk DataFile Version 3.0")?;
    writeln!(w, "geofit implicit field")?;
    writeln!(w, "ASCII")?;
    writeln!(w, "DATASET UNSTRUCTURED_GRID")?;
    writeln!(w, "POINTS {} double", mesh.verts.len())?;
    for p in &mesh.verts {
        writeln!(w, "{} {} {}", p[0] + origin[0], p[1] + origin[1], p[2] + origin[2])?;
    }
    writeln!(w, "CELLS {} {}", mesh.tets.len(), mesh.tets.len() * 5)?;
    for t in &mesh.tets {
        writeln!(w, "4 {} {} {} {}", t[0], t[1], t[2], t[3])?;
    }
    writeln!(w, "CELL_TYPES {}", mesh.tets.len())?;
    for _ in &mesh.tets {
        writeln!(w, "10")?;
    }
    if !fields.is_empty() {
        writeln!(w, "POINT_DATA {}", mesh.verts.len())?;
        for (name, vals) in fields {
            let name: String =
                name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
            writeln!(w, "SCALARS {name} double 1")?;
            writeln!(w, "LOOKUP_TABLE default")?;
            for v in vals.iter() {
                writeln!(w, "{v}")?;
            }
        }
    }
    Ok(())
}
