//! A T-spline surface as a triangle mesh for viewers: a regular parameter grid of samples,
//! masked by the data footprint, two triangles per fully valued grid quad, vertex colours by
//! height or by error against a reference, and the leaf-cell edges draped on the surface as a
//! separate line node (`surface` and `tmesh` nodes of a [`mesh_export::Scene`]).
//!
//! Evaluation is not done here: the caller evaluates the [`SampleGrid`]'s points (CPU
//! [`PbSpline::eval_z`] or the OpenCL twin, same values) and hands the heights in, so the
//! device choice stays with the caller.

use mesh_export::{LineSet, Material, MeshNode, Scene, TriangleMesh};

use crate::format::{DataMask, TMeshFile};
use crate::{PbSpline, Rect};

/// Most samples a grid may have (50 million: ~1.2 GB of positions and colours before writing).
pub const MAX_SAMPLES: usize = 50_000_000;

/// Samples along the longer side when no spacing is given.
const DEFAULT_SAMPLES_ALONG: f64 = 512.0;

/// Points per leaf-cell side when draping the edges on the surface (8 segments).
const EDGE_SEGMENTS: usize = 8;

/// Why a surface could not be tessellated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TessellateError {
    #[error("the sample spacing must be positive, got {0}")]
    Step(f64),
    #[error("{ns}×{nt} samples are too many")]
    TooManySamples { ns: usize, nt: usize },
    #[error("the surface has no point inside the mask")]
    NoPointInMask,
}

/// The regular parameter grid the surface is sampled on, row-major from (s_min, t_min).
#[derive(Debug, Clone)]
pub struct SampleGrid {
    /// Samples along s.
    pub ns: usize,
    /// Samples along t.
    pub nt: usize,
    /// The (s, t) parameter points, `ns * nt` of them.
    pub points: Vec<[f64; 2]>,
}

impl SampleGrid {
    /// Samples `bounds` every `step` parameter units; without a step, about 512 samples along
    /// the longer side (at least one raster cell apart).
    pub fn new(bounds: Rect, step: Option<f64>) -> Result<SampleGrid, TessellateError> {
        let step = match step {
            Some(s) if s > 0.0 && s.is_finite() => s,
            Some(s) => return Err(TessellateError::Step(s)),
            None => (bounds.width().max(bounds.height()) / DEFAULT_SAMPLES_ALONG).max(1.0),
        };
        let ns = (bounds.width() / step).floor() as usize + 1;
        let nt = (bounds.height() / step).floor() as usize + 1;
        if ns.saturating_mul(nt) > MAX_SAMPLES {
            return Err(TessellateError::TooManySamples { ns, nt });
        }
        let points = (0..nt)
            .flat_map(|j| (0..ns).map(move |i| [bounds.s_min + i as f64 * step, bounds.t_min + j as f64 * step]))
            .collect();
        Ok(SampleGrid { ns, nt, points })
    }
}

/// How the surface vertices are coloured.
pub enum Colouring<'a> {
    /// A blue → cyan → green → brown ramp from `range.0` to `range.1` (heights outside it take
    /// the end colours), or without a range from the lowest to the highest sample. Tiles of one
    /// area are given one range so that a height has one colour on both sides of a seam.
    Height { range: Option<(f64, f64)> },
    /// Classes of |reference(x, y) − z| (green < 0.1, yellow < 0.5, orange < 1, red);
    /// grey where the reference has no value (`None`).
    ErrorAgainst(&'a dyn Fn(f64, f64) -> Option<f64>),
}

/// Builds the scene of `file`'s surface: `z` holds the heights at `grid.points` (NaN where the
/// surface has none); with `use_mask`, samples outside the file's data mask are dropped.
///
/// Node `surface` holds the triangles (material 0, vertex colours), node `tmesh` the leaf-cell
/// edges (material 1) when `cell_edges` (they outweigh the surface of a finely refined mesh: a
/// 3D Tiles tile wants the surface alone). The scene's origin is its automatic one; the generator is left unset.
///
/// # Examples
///
/// ```
/// use tspline::format::{Georef, TMeshFile};
/// use tspline::tessellate::{tessellate, Colouring, SampleGrid};
/// use tspline::{Degree, PbSpline, TMesh};
///
/// let mesh = TMesh::grid(Degree::Cubic, 0.0, 0.0, 4.0, 2, 2); // 8 × 8 parameter units
/// let file = TMeshFile { mesh, georef: Georef::identity(), mask: None, warp: None };
/// let pb = PbSpline::build(&file.mesh);
/// let grid = SampleGrid::new(file.mesh.bounds(), Some(2.0)).unwrap(); // 5 × 5 samples
/// let z = pb.eval_z(&grid.points, false);
/// let scene = tessellate(&file, &pb, &grid, z, Colouring::Height { range: None }, true, true).unwrap();
/// assert_eq!(scene.nodes[0].name, "surface");
/// assert_eq!(scene.triangle_count(), 2 * 4 * 4);
/// ```
pub fn tessellate(
    file: &TMeshFile,
    pb: &PbSpline,
    grid: &SampleGrid,
    mut z: Vec<f64>,
    colouring: Colouring,
    use_mask: bool,
    cell_edges: bool,
) -> Result<Scene, TessellateError> {
    let mask = file.mask.as_ref().filter(|_| use_mask);
    if let Some(m) = mask {
        for (q, p) in grid.points.iter().enumerate() {
            if !inside_mask(m, p[0], p[1]) {
                z[q] = f64::NAN;
            }
        }
    }
    let surface = surface_mesh(file, grid, &z, &colouring)?;
    let lines = if cell_edges { draped_cell_edges(file, pb, mask) } else { LineSet::default() };
    let g = &file.georef;
    let mut surface_node = MeshNode::new("surface");
    surface_node.meshes.push(surface);
    let mut tmesh_node = MeshNode::new("tmesh");
    if !lines.indices.is_empty() {
        tmesh_node.lines.push(lines);
    }
    let mut scene = Scene {
        materials: vec![
            Material::new("surface", [1.0, 1.0, 1.0, 1.0]),
            Material::new("tmesh-edges", [0.05, 0.05, 0.05, 1.0]),
        ],
        crs: if g.crs.is_empty() { None } else { Some(g.crs.clone()) },
        ..Default::default()
    };
    scene.nodes.push(surface_node);
    if cell_edges {
        scene.nodes.push(tmesh_node);
    }
    scene.origin = scene.auto_origin();
    Ok(scene)
}

/// Whether parameter point (s, t) falls on a data cell (nearest cell centre). The mask's outer
/// edge (s = −½ or s = width − ½, likewise t) belongs to the cells along it: rounding alone sends
/// −½ and width − ½ outside, which dropped the outermost ring of samples and left a gap of one
/// step between the glb of adjacent tiles (docs/decisions.md#terrain-tilesets).
fn inside_mask(m: &DataMask, s: f64, t: f64) -> bool {
    let cell = |u: f64, n: usize| {
        (n > 0 && u >= -0.5 && u <= n as f64 - 0.5).then(|| (u.round().max(0.0) as usize).min(n - 1))
    };
    match (cell(s, m.width), cell(t, m.height)) {
        (Some(i), Some(j)) => m.get(i, j),
        _ => false,
    }
}

/// The valued samples as coloured vertices, two triangles per quad whose four corners have values.
fn surface_mesh(
    file: &TMeshFile,
    grid: &SampleGrid,
    z: &[f64],
    colouring: &Colouring,
) -> Result<TriangleMesh, TessellateError> {
    let (lowest, highest) =
        z.iter().filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    if !lowest.is_finite() {
        return Err(TessellateError::NoPointInMask);
    }
    let (zmin, zmax) = match colouring {
        Colouring::Height { range: Some(r) } => *r,
        _ => (lowest, highest),
    };
    let mut mesh = TriangleMesh::new(Some(0));
    let mut colours = Vec::new();
    let mut vid = vec![u32::MAX; z.len()];
    for (q, p) in grid.points.iter().enumerate() {
        if !z[q].is_finite() {
            continue;
        }
        let (x, y) = file.georef.world(p[0], p[1]);
        vid[q] = mesh.push_vertex([x, y, z[q]]);
        colours.push(match colouring {
            Colouring::ErrorAgainst(reference) => {
                error_colour(reference(x, y).map(|v| (v - z[q]).abs()).unwrap_or(f64::NAN))
            }
            Colouring::Height { .. } => mesh_export::colour::elevation((z[q] - zmin) / (zmax - zmin).max(1e-300)),
        });
    }
    let ns = grid.ns;
    for j in 0..grid.nt.saturating_sub(1) {
        for i in 0..ns.saturating_sub(1) {
            let (a, b, c, d) = (j * ns + i, j * ns + i + 1, (j + 1) * ns + i, (j + 1) * ns + i + 1);
            if [a, b, c, d].iter().all(|&q| vid[q] != u32::MAX) {
                mesh.indices.extend_from_slice(&[vid[a], vid[b], vid[d], vid[a], vid[d], vid[c]]);
            }
        }
    }
    mesh.colors = Some(colours);
    Ok(mesh)
}

/// Every side of every leaf cell, draped on the surface; a side is broken where the surface has
/// no value or leaves the mask. Edges shared by two leaves are drawn twice.
fn draped_cell_edges(file: &TMeshFile, pb: &PbSpline, mask: Option<&DataMask>) -> LineSet {
    let mut lines = LineSet { material: Some(1), ..Default::default() };
    for c in file.mesh.cells.iter().filter(|c| c.is_leaf()) {
        let r = c.rect;
        for (s0, t0, s1, t1) in [
            (r.s_min, r.t_min, r.s_max, r.t_min),
            (r.s_min, r.t_min, r.s_min, r.t_max),
            (r.s_min, r.t_max, r.s_max, r.t_max),
            (r.s_max, r.t_min, r.s_max, r.t_max),
        ] {
            let mut prev: Option<u32> = None;
            for k in 0..=EDGE_SEGMENTS {
                let f = k as f64 / EDGE_SEGMENTS as f64;
                let (s, t) = (s0 + (s1 - s0) * f, t0 + (t1 - t0) * f);
                let z = pb.point(s, t)[2];
                if !z.is_finite() || mask.is_some_and(|m| !inside_mask(m, s, t)) {
                    prev = None;
                    continue;
                }
                let (x, y) = file.georef.world(s, t);
                lines.positions.push([x, y, z]);
                let id = (lines.positions.len() - 1) as u32;
                if let Some(p) = prev {
                    lines.indices.extend_from_slice(&[p, id]);
                }
                prev = Some(id);
            }
        }
    }
    lines
}

fn error_colour(e: f64) -> [f32; 4] {
    if !e.is_finite() {
        [0.5, 0.5, 0.5, 1.0]
    } else if e < 0.1 {
        [0.1, 0.7, 0.2, 1.0]
    } else if e < 0.5 {
        [0.9, 0.85, 0.1, 1.0]
    } else if e < 1.0 {
        [0.95, 0.5, 0.1, 1.0]
    } else {
        [0.85, 0.1, 0.1, 1.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::Georef;
    use crate::{Degree, TMesh};

    /// A 4 × 4-cell raster's mesh (domain −½ … 3½, cell centres on the integers) with every cell
    /// valid, sampled every cell edge: 5 × 5 samples.
    fn four_by_four(mask_bits: Vec<bool>, colouring: Colouring) -> Scene {
        let mesh = TMesh::grid(Degree::Cubic, -0.5, -0.5, 4.0, 1, 1);
        let mask = DataMask { width: 4, height: 4, bits: mask_bits };
        let file = TMeshFile { mesh, georef: Georef::identity(), mask: Some(mask), warp: None };
        let pb = PbSpline::build(&file.mesh);
        let grid = SampleGrid::new(file.mesh.bounds(), Some(1.0)).unwrap();
        assert_eq!((grid.ns, grid.nt), (5, 5));
        let z = pb.eval_z(&grid.points, false);
        tessellate(&file, &pb, &grid, z, colouring, true, false).unwrap()
    }

    #[test]
    fn a_full_mask_keeps_the_samples_on_the_domain_edge() {
        let scene = four_by_four(vec![true; 16], Colouring::Height { range: None });
        let surface = &scene.nodes[0].meshes[0];
        assert_eq!(surface.positions.len(), 25, "every sample, the outer ring included");
        assert_eq!(scene.triangle_count(), 2 * 4 * 4, "every cell covered");
        assert_eq!(scene.nodes.len(), 1, "no cell-edge node when not asked for");
    }

    #[test]
    fn an_empty_border_column_still_drops_its_samples() {
        // column i = 0 without data: the samples at s = −½ (nearest centre i = 0) go, those at
        // s = ½ belong to i = 1 (rounding half away from zero) and stay
        let bits = (0..16).map(|q| q % 4 != 0).collect();
        let scene = four_by_four(bits, Colouring::Height { range: None });
        assert_eq!(scene.nodes[0].meshes[0].positions.len(), 20);
    }

    #[test]
    fn a_given_height_range_fixes_the_colours() {
        let flat = |range| {
            let s = four_by_four(vec![true; 16], Colouring::Height { range });
            s.nodes[0].meshes[0].colors.clone().unwrap()
        };
        // the grid mesh's heights are all 0: without a range the ramp starts there (blue end),
        // within [-1, 1] a height of 0 sits mid-ramp; far below a range it clamps to the low end
        let own = flat(None);
        assert_eq!(own[0], mesh_export::colour::elevation(0.0));
        assert_eq!(flat(Some((-1.0, 1.0)))[0], mesh_export::colour::elevation(0.5));
        assert_eq!(flat(Some((5.0, 6.0)))[0], mesh_export::colour::elevation(0.0));
        assert_ne!(flat(Some((-1.0, 1.0)))[0], own[0]);
    }
}
