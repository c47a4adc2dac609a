//! TIN-linear rasterization: Delaunay triangulation of the points (spade), value at every cell
//! centre by barycentric interpolation in its triangle — the same model as
//! `gdal_grid -a linear:radius=0`. Cells outside the convex hull get no value; with `max_edge`
//! also cells inside triangles with an edge longer than that (gaps between survey lines), so
//! nothing is invented where no point is near.
//!
//! Points with identical (x, y) are merged into one vertex with the mean z (a Delaunay
//! triangulation cannot hold both); this is reported in [`TinStats::merged_duplicates`].

use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

use raster_io::limits::{gib, PointBudget};
use raster_io::{PointCloud, Raster};

use crate::grid::GridSpec;
use crate::ProcError;

#[derive(Debug, Clone, Copy)]
struct Vertex {
    x: f64,
    y: f64,
    z: f64,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        Point2::new(self.x, self.y)
    }
}

/// Options of [`tin_points`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TinOptions {
    /// Leave cells without a value when their triangle has an edge longer than this
    /// (world units); `None` = only outside the convex hull.
    pub max_edge: Option<f64>,
}

/// What the triangulation saw.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TinStats {
    pub vertices: usize,
    pub merged_duplicates: usize,
    pub triangles: usize,
}

/// What one point costs the TIN path at its peak: the cloud and its sorted copy (48 bytes),
/// the vertex list and spade's triangulation (vertices, half-edges, faces: ~150 bytes) —
/// ~218 bytes a point measured on 10⁷ points (issue 13), rounded up.
pub const TIN_BYTES_PER_POINT: u64 = 220;

/// Rasterizes `cloud` onto `grid` by linear interpolation in its Delaunay triangulation; refuses
/// clouds whose triangulation would not fit the point budget (`GEOFIT_MAX_POINTS`, else the
/// available memory over [`TIN_BYTES_PER_POINT`]).
pub fn tin_points(
    cloud: &PointCloud,
    grid: &GridSpec,
    opts: &TinOptions,
    crs: Option<String>,
) -> Result<(Raster, TinStats), ProcError> {
    tin_points_within(cloud, grid, opts, crs, PointBudget::for_cost(TIN_BYTES_PER_POINT))
}

fn tin_points_within(
    cloud: &PointCloud,
    grid: &GridSpec,
    opts: &TinOptions,
    crs: Option<String>,
    budget: PointBudget,
) -> Result<(Raster, TinStats), ProcError> {
    if let Some(m) = opts.max_edge {
        if !(m.is_finite() && m > 0.0) {
            return Err(ProcError::Input(format!("max edge {m} must be a positive length")));
        }
    }
    if cloud.points.len() as u64 > budget.max_points {
        return Err(ProcError::TinTooLarge {
            points: cloud.points.len(),
            size: gib(cloud.points.len() as u64 * TIN_BYTES_PER_POINT),
            bytes_per_point: TIN_BYTES_PER_POINT,
            limit: budget.describe(),
        });
    }
    // Merge exact duplicates (sorted, so the result does not depend on input order).
    let mut pts: Vec<[f64; 3]> = cloud.points.clone();
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])).then(a[2].total_cmp(&b[2])));
    let mut verts: Vec<Vertex> = Vec::with_capacity(pts.len());
    let mut merged = 0;
    let mut i = 0;
    while i < pts.len() {
        let mut j = i + 1;
        let mut sum = pts[i][2];
        while j < pts.len() && pts[j][0] == pts[i][0] && pts[j][1] == pts[i][1] {
            sum += pts[j][2];
            j += 1;
        }
        merged += j - i - 1;
        verts.push(Vertex { x: pts[i][0], y: pts[i][1], z: sum / (j - i) as f64 });
        i = j;
    }
    if verts.len() < 3 {
        return Err(ProcError::Input(format!("a TIN needs at least 3 distinct points, got {}", verts.len())));
    }
    let tri: DelaunayTriangulation<Vertex> = DelaunayTriangulation::bulk_load(verts)
        .map_err(|e| ProcError::Input(format!("cannot triangulate the points: {e:?}")))?;
    if tri.num_inner_faces() == 0 {
        return Err(ProcError::Input("all points are collinear: no triangle to interpolate in".into()));
    }
    let stats = TinStats { vertices: tri.num_vertices(), merged_duplicates: merged, triangles: tri.num_inner_faces() };
    let max2 = opts.max_edge.map(|m| m * m);
    let long = |a: Point2<f64>, b: Point2<f64>| max2.is_some_and(|m| (a.x - b.x).powi(2) + (a.y - b.y).powi(2) > m);

    // Scan-convert every triangle over the cell centres in its bounding box (O(cells + triangles);
    // locating each cell would walk the triangulation, slow for sparse survey lines). A centre on
    // a shared edge is taken by the first triangle in spade's fixed face order; both give the
    // same value up to rounding.
    let mut data = vec![f64::NAN; grid.width * grid.height];
    for f in tri.inner_faces() {
        let [a, b, c] = f.vertices();
        let (pa, pb, pc) = (a.position(), b.position(), c.position());
        if long(pa, pb) || long(pb, pc) || long(pc, pa) {
            continue;
        }
        let (za, zb, zc) = (a.data().z, b.data().z, c.data().z);
        let det = (pb.y - pc.y) * (pa.x - pc.x) + (pc.x - pb.x) * (pa.y - pc.y);
        if det == 0.0 {
            continue;
        }
        // Pixel-space bounding box of the triangle (centre-based pixel coordinates).
        let (ax, ay) = grid.world_to_pixel(pa.x, pa.y);
        let (bx, by) = grid.world_to_pixel(pb.x, pb.y);
        let (cx, cy) = grid.world_to_pixel(pc.x, pc.y);
        let c0 = ax.min(bx).min(cx).ceil().max(0.0);
        let c1 = ax.max(bx).max(cx).floor().min(grid.width as f64 - 1.0);
        let r0 = ay.min(by).min(cy).ceil().max(0.0);
        let r1 = ay.max(by).max(cy).floor().min(grid.height as f64 - 1.0);
        if c0 > c1 || r0 > r1 {
            continue;
        }
        // Relative slack so centres exactly on an edge are not lost to rounding.
        let eps = -1e-12;
        for row in r0 as usize..=r1 as usize {
            for col in c0 as usize..=c1 as usize {
                let i = row * grid.width + col;
                if !data[i].is_nan() {
                    continue;
                }
                let (x, y) = grid.cell_centre(col, row);
                let l1 = ((pb.y - pc.y) * (x - pc.x) + (pc.x - pb.x) * (y - pc.y)) / det;
                let l2 = ((pc.y - pa.y) * (x - pc.x) + (pa.x - pc.x) * (y - pc.y)) / det;
                let l3 = 1.0 - l1 - l2;
                if l1 >= eps && l2 >= eps && l3 >= eps {
                    data[i] = l1 * za + l2 * zb + l3 * zc;
                }
            }
        }
    }
    Ok((Raster::from_values(grid.width, grid.height, grid.geotransform, crs, data)?, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cloud over the TIN's point budget is refused before triangulating, saying what it would
    /// take; at the budget it is triangulated.
    #[test]
    fn clouds_beyond_the_tin_budget_are_refused() {
        let points: Vec<[f64; 3]> = (0..100).map(|i| [(i % 10) as f64, (i / 10) as f64, i as f64]).collect();
        let cloud = PointCloud { points, crs: None };
        let grid = GridSpec::from_edges(0.0, 0.0, 10.0, 10.0, 1.0).unwrap();
        let budget = |max_points| PointBudget { max_points, source: raster_io::limits::BudgetSource::Env };
        let e = tin_points_within(&cloud, &grid, &TinOptions::default(), None, budget(99)).unwrap_err();
        assert!(matches!(e, ProcError::TinTooLarge { points: 100, bytes_per_point: TIN_BYTES_PER_POINT, .. }), "{e}");
        assert!(e.to_string().contains("--method gauss"), "{e}");
        assert!(tin_points_within(&cloud, &grid, &TinOptions::default(), None, budget(100)).is_ok());
    }

    #[test]
    fn reproduces_a_plane_inside_the_hull() {
        // z = 2x − 3y + 1 sampled at scattered points; linear interpolation is exact for planes.
        let mut pts = Vec::new();
        let mut s = 12345u64;
        for _ in 0..200 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let x = (s >> 11) as f64 / (1u64 << 53) as f64 * 10.0;
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let y = (s >> 11) as f64 / (1u64 << 53) as f64 * 10.0;
            pts.push([x, y, 2.0 * x - 3.0 * y + 1.0]);
        }
        pts.push([0.0, 0.0, 1.0]);
        pts.push([0.0, 0.0, 1.0]); // duplicate
        let cloud = PointCloud { points: pts, crs: None };
        let grid = GridSpec::from_edges(0.0, 0.0, 10.0, 10.0, 0.5).unwrap();
        let (r, st) = tin_points(&cloud, &grid, &TinOptions::default(), None).unwrap();
        assert_eq!(st.merged_duplicates, 1);
        let mut n = 0;
        for row in 0..r.height {
            for col in 0..r.width {
                if let Some(v) = r.get(col, row) {
                    let (x, y) = r.cell_centre(col, row);
                    assert!((v - (2.0 * x - 3.0 * y + 1.0)).abs() < 1e-9);
                    n += 1;
                }
            }
        }
        assert!(n > 300, "{n}");
        // corners of the grid lie outside the hull of random points only by chance; the cell
        // at (0.25, 9.75) is outside unless a point is very close — with max_edge tiny, nothing survives
        let (r2, _) = tin_points(&cloud, &grid, &TinOptions { max_edge: Some(1e-3) }, None).unwrap();
        assert_eq!(r2.valid_count(), 0);
    }

    #[test]
    fn collinear_points_are_an_error() {
        let cloud = PointCloud { points: vec![[0.0, 0.0, 1.0], [1.0, 1.0, 2.0], [2.0, 2.0, 3.0]], crs: None };
        let grid = GridSpec::from_edges(0.0, 0.0, 2.0, 2.0, 1.0).unwrap();
        assert!(tin_points(&cloud, &grid, &TinOptions::default(), None).is_err());
    }
}
