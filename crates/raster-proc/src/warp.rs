//! Indirect-reduction transform (spec §2.3.2–2.3.3): global rotation by principal axes plus a
//! local landmark warp (strip-wise x redistribution, column-wise y stretch), stored as one
//! displacement per landmark on a Delaunay triangulation and interpolated barycentrically.
//!
//! Spec A4 decided (and why):
//! - Landmarks form a regular grid in the ROTATED frame covering the whole source raster
//!   footprint plus one landmark spacing on every side. Its outermost ring is the thesis'
//!   "border landmarks that move only with the rotation": the x map keeps the grid's total
//!   width (first/last column fixed) and the y map keeps each column's end points, so the ring
//!   never moves and everything outside the grid maps by the rotation alone — continuously.
//! - x-warp: strips of width `block_width` from the grid's left edge (the last one may be
//!   narrower); new width l_i' = L·(n_i + l_i/l)/(N + Σ l_i/l), i.e. one phantom inside point per
//!   full strip, so a strip without data shrinks but never to zero width (zero width would
//!   make the warp non-invertible). The map is affine inside each strip and continuous.
//! - y-warp: Y⁻, Y*, Y⁺ over the inside landmarks, y⁻, y*, y⁺ over the inside landmarks whose
//!   (pre-warp, rotated) x lies in [x − w, x + w] with w = `window`/2 (the "window size" is the
//!   full width 2w). The column is mapped by the monotone piecewise-linear function through
//!   (B, B), (y⁻, Y⁻), (y*, Y*), (y⁺, Y⁺), (T, T) with B, T the grid's bottom and top, which
//!   is the thesis' formula between y⁻ and y⁺ and keeps the border fixed. A column without
//!   inside landmarks in its window stays put.
//! - x- and y-displacements are both computed from the rotated pre-warp positions and summed
//!   (spec "the per-point results are summed").
//! - "Inside" = the source cell under the landmark has a value.
//! - Both maps are monotone, so every grid triangle (its vertices lie on two adjacent
//!   columns) keeps its orientation: no fold-over by construction. [`WarpField::check_fold_over`]
//!   still verifies every triangle of any field (e.g. one read from a file).
//! - The target frame is the rotated frame (rotation about the centroid, so coordinates stay
//!   near the source's); the warped raster has square cells of area dx·dy and no CRS of its
//!   own (its coordinates are not the CRS's); the source CRS is kept in the field.
//! - Inverse mapping is exact for the piecewise-linear warp (spec §2.3.7 \[decision\]):
//!   barycentric coordinates in the displaced triangle applied to the source triangle.

use serde::{Deserialize, Serialize};
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

use raster_io::{MissingCorners, Raster};

use crate::dilate::{extrapolating_dilation_fill, Neighbourhood};
use crate::grid::GridSpec;
use crate::pca::{principal_axes, Mass};
use crate::splat::{SplatAccumulator, SplatKernel};
use crate::ProcError;

/// The metadata key under which a warped raster carries its [`WarpField`] (JSON).
pub const WARP_METADATA_KEY: &str = "GEOFIT_WARP_FIELD";

/// Parameters of the warp (lengths in world units; `None` = derived from the cell size).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarpParams {
    /// Rotate by principal axes (spec: optional).
    pub rotate: bool,
    pub mass: Mass,
    /// Landmark spacing (thesis example 20 m at 1 m cells); default 20 cells.
    pub landmark_spacing: Option<f64>,
    /// Strip width of the x-warp (thesis 50 m); default 2.5 × spacing.
    pub block_width: Option<f64>,
    /// Full window width 2w of the y-warp (thesis 50 m); default 2.5 × spacing.
    pub window: Option<f64>,
    pub x_warp: bool,
    pub y_warp: bool,
    /// Resampling footprint for the forward mapping.
    pub kernel: SplatKernel,
    pub neighbourhood: Neighbourhood,
}

impl Default for WarpParams {
    fn default() -> Self {
        WarpParams {
            rotate: true,
            mass: Mass::Unit,
            landmark_spacing: None,
            block_width: None,
            window: None,
            x_warp: true,
            y_warp: true,
            kernel: SplatKernel::default(),
            neighbourhood: Neighbourhood::Eight,
        }
    }
}

/// The source raster's grid, kept so `unwarp` can rebuild it without a side file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceGrid {
    pub width: usize,
    pub height: usize,
    pub geotransform: [f64; 6],
    pub crs: Option<String>,
    pub nodata: Option<f64>,
    /// Footprint mask, run-length encoded: alternating run lengths starting with a run of
    /// INVALID cells (possibly 0), row-major.
    pub mask_runs: Vec<u64>,
}

impl SourceGrid {
    pub fn from_raster(r: &Raster) -> SourceGrid {
        let mut runs = Vec::new();
        let mut cur = false;
        let mut n = 0u64;
        for v in r.data.iter().map(|d| !d.is_nan()) {
            if v == cur {
                n += 1;
            } else {
                runs.push(n);
                cur = v;
                n = 1;
            }
        }
        runs.push(n);
        SourceGrid {
            width: r.width,
            height: r.height,
            geotransform: r.geotransform,
            crs: r.crs.clone(),
            nodata: r.nodata,
            mask_runs: runs,
        }
    }

    /// The decoded footprint mask.
    pub fn mask(&self) -> Result<Vec<bool>, ProcError> {
        let n = self.width * self.height;
        let mut m = Vec::with_capacity(n);
        let mut cur = false;
        for &run in &self.mask_runs {
            if m.len() as u64 + run > n as u64 {
                return Err(ProcError::Field("footprint mask longer than the grid".into()));
            }
            m.extend(std::iter::repeat_n(cur, run as usize));
            cur = !cur;
        }
        if m.len() != n {
            return Err(ProcError::Field(format!("footprint mask has {} cells, grid {n}", m.len())));
        }
        Ok(m)
    }
}

/// The combined displacement field W = {(x_i, δ_i)} of spec §2.3.2: landmark positions in the
/// source (world) and target (rotated + warped) frames on one triangulation. Serialisable
/// (serde; JSON in raster metadata, and inside the T-mesh file for `fit --indirect`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarpField {
    /// Format version of this record.
    pub version: u32,
    /// Rotation (radians, counter-clockwise) applied about `centre`: q = R(α)(p − c) + c.
    pub rotation: f64,
    pub centre: [f64; 2],
    /// Landmark positions in the source frame (world coordinates).
    pub src: Vec<[f64; 2]>,
    /// The same landmarks in the target frame (= src + δ).
    pub dst: Vec<[f64; 2]>,
    /// Triangles (landmark indices, counter-clockwise in the source frame).
    pub triangles: Vec<[u32; 3]>,
    /// The source grid, when the field came from warping a raster.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<SourceGrid>,
}

/// How a warp went.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct WarpStats {
    pub rotation_deg: f64,
    pub landmarks: usize,
    pub landmarks_inside: usize,
    pub triangles: usize,
    pub target_width: usize,
    pub target_height: usize,
    /// Target cells reached by the splat.
    pub cells_splatted: usize,
    /// Target cells filled by dilation.
    pub cells_filled: usize,
    pub dilation_passes: usize,
}

#[derive(Clone, Copy)]
struct LmVertex {
    p: Point2<f64>,
    index: u32,
}
impl HasPosition for LmVertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

#[inline]
fn rot(a: f64, c: [f64; 2], p: [f64; 2]) -> [f64; 2] {
    let (s, co) = a.sin_cos();
    let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
    [c[0] + co * dx - s * dy, c[1] + s * dx + co * dy]
}

/// Monotone piecewise-linear map through strictly increasing knots (both coordinates).
fn piecewise(knots: &[(f64, f64)], v: f64) -> f64 {
    for w in knots.windows(2) {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if v <= x1 {
            return y0 + (v - x0) * (y1 - y0) / (x1 - x0);
        }
    }
    let (xl, yl) = knots[knots.len() - 1];
    v - xl + yl
}

impl WarpField {
    /// Builds the field for a raster (spec §9.1 items 4–8).
    pub fn build(r: &Raster, params: &WarpParams) -> Result<(WarpField, WarpStats), ProcError> {
        r.validate()?;
        if r.valid_count() == 0 {
            return Err(ProcError::Input("raster has no valid cell: nothing to warp".into()));
        }
        let (cdx, cdy) = r.cell_size();
        let cell = (cdx * cdy).sqrt();
        let spacing = params.landmark_spacing.unwrap_or(20.0 * cell);
        let block = params.block_width.unwrap_or(2.5 * spacing);
        let window = params.window.unwrap_or(2.5 * spacing);
        for (name, v) in [("landmark spacing", spacing), ("block width", block), ("window", window)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ProcError::Input(format!("{name} {v} must be a positive length")));
            }
        }
        let (rotation, centre) = if params.rotate {
            let pa = principal_axes(r, params.mass)?;
            (pa.rotation, pa.centroid)
        } else {
            let e = r.extent();
            (0.0, [0.5 * (e.0 + e.2), 0.5 * (e.1 + e.3)])
        };
        // Grid of landmarks in the rotated frame over the rotated footprint, one spacing margin.
        let corners = [
            (-0.5, -0.5),
            (r.width as f64 - 0.5, -0.5),
            (-0.5, r.height as f64 - 0.5),
            (r.width as f64 - 0.5, r.height as f64 - 0.5),
        ];
        let (mut u0, mut v0, mut u1, mut v1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for (px, py) in corners {
            let (x, y) = r.pixel_to_world(px, py);
            let q = rot(rotation, centre, [x, y]);
            u0 = u0.min(q[0]);
            v0 = v0.min(q[1]);
            u1 = u1.max(q[0]);
            v1 = v1.max(q[1]);
        }
        u0 -= spacing;
        v0 -= spacing;
        let nu = ((u1 + spacing - u0) / spacing).ceil() as usize + 1;
        let nv = ((v1 + spacing - v0) / spacing).ceil() as usize + 1;
        if nu.saturating_mul(nv) > 4_000_000 {
            return Err(ProcError::Input(format!(
                "{nu} × {nv} landmarks: spacing {spacing} is too small for this raster"
            )));
        }
        let (uend, vend) = (u0 + (nu - 1) as f64 * spacing, v0 + (nv - 1) as f64 * spacing);
        let mut rotated = Vec::with_capacity(nu * nv); // index = j * nu + i
        let mut src = Vec::with_capacity(nu * nv);
        let mut inside = Vec::with_capacity(nu * nv);
        for j in 0..nv {
            for i in 0..nu {
                let q = [u0 + i as f64 * spacing, v0 + j as f64 * spacing];
                let p = rot(-rotation, centre, q);
                let (px, py) = r.world_to_pixel(p[0], p[1]);
                let (c, rr) = (px.round(), py.round());
                let ins = c >= 0.0
                    && rr >= 0.0
                    && (c as usize) < r.width
                    && (rr as usize) < r.height
                    && r.get(c as usize, rr as usize).is_some();
                rotated.push(q);
                src.push(p);
                inside.push(ins);
            }
        }
        let n_inside = inside.iter().filter(|b| **b).count();

        // x-warp: strip redistribution.
        let total = uend - u0;
        let nblocks = (total / block).ceil().max(1.0) as usize;
        let bw: Vec<f64> = (0..nblocks).map(|b| (block).min(total - b as f64 * block)).collect();
        let mut counts = vec![0usize; nblocks];
        for (k, q) in rotated.iter().enumerate() {
            if inside[k] {
                let b = (((q[0] - u0) / block).floor() as usize).min(nblocks - 1);
                counts[b] += 1;
            }
        }
        let weights: Vec<f64> = (0..nblocks).map(|b| counts[b] as f64 + bw[b] / block).collect();
        let wsum: f64 = weights.iter().sum();
        let mut new_start = vec![u0; nblocks + 1];
        for b in 0..nblocks {
            new_start[b + 1] = new_start[b] + total * weights[b] / wsum;
        }
        new_start[nblocks] = uend; // exact: the right border stays fixed
        let xmap = |u: f64| -> f64 {
            if !params.x_warp {
                return u;
            }
            let b = (((u - u0) / block).floor().max(0.0) as usize).min(nblocks - 1);
            let start = u0 + b as f64 * block;
            new_start[b] + (u - start) * (new_start[b + 1] - new_start[b]) / bw[b]
        };

        // y-warp: per-column stretch of the inside span onto the global span.
        let ins_v: Vec<(f64, f64)> =
            rotated.iter().zip(&inside).filter(|(_, b)| **b).map(|(q, _)| (q[0], q[1])).collect();
        let (gmin, gmax, gmean) = if ins_v.is_empty() {
            (0.0, 0.0, 0.0)
        } else {
            let mn = ins_v.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
            let mx = ins_v.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
            let me = ins_v.iter().map(|p| p.1).sum::<f64>() / ins_v.len() as f64;
            (mn, mx, me)
        };
        let half = 0.5 * window;
        let column_knots: Vec<Vec<(f64, f64)>> = (0..nu)
            .map(|i| {
                let u = u0 + i as f64 * spacing;
                let local: Vec<f64> =
                    ins_v.iter().filter(|p| (p.0 - u).abs() <= half + 1e-9 * spacing).map(|p| p.1).collect();
                let mut knots = vec![(v0, v0)];
                if params.y_warp && !local.is_empty() {
                    let lmin = local.iter().cloned().fold(f64::INFINITY, f64::min);
                    let lmax = local.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                    let lmean = local.iter().sum::<f64>() / local.len() as f64;
                    for k in [(lmin, gmin), (lmean, gmean), (lmax, gmax)] {
                        let last = *knots.last().unwrap();
                        if k.0 > last.0 && k.1 > last.1 && k.0 < vend && k.1 < vend {
                            knots.push(k);
                        }
                    }
                }
                knots.push((vend, vend));
                knots
            })
            .collect();

        let mut dst_rot = Vec::with_capacity(rotated.len());
        for (k, q) in rotated.iter().enumerate() {
            let i = k % nu;
            dst_rot.push([xmap(q[0]), piecewise(&column_knots[i], q[1])]);
        }

        // Delaunay triangulation of the landmarks (in the rotated frame: a regular grid).
        let verts: Vec<LmVertex> =
            rotated.iter().enumerate().map(|(k, q)| LmVertex { p: Point2::new(q[0], q[1]), index: k as u32 }).collect();
        let tri: DelaunayTriangulation<LmVertex> = DelaunayTriangulation::bulk_load(verts)
            .map_err(|e| ProcError::Input(format!("landmark triangulation failed: {e:?}")))?;
        let mut triangles: Vec<[u32; 3]> = tri
            .inner_faces()
            .map(|f| {
                let [a, b, c] = f.vertices();
                [a.data().index, b.data().index, c.data().index]
            })
            .collect();
        // Canonical order (spade's face order is an implementation detail): rotate each
        // triangle to start at its smallest index, then sort.
        for t in triangles.iter_mut() {
            let m = (0..3).min_by_key(|&k| t[k]).unwrap();
            t.rotate_left(m);
        }
        triangles.sort_unstable();

        let field = WarpField { version: 1, rotation, centre, src, dst: dst_rot, triangles, source: None };
        field.check_fold_over()?;
        let stats = WarpStats {
            rotation_deg: rotation.to_degrees(),
            landmarks: field.src.len(),
            landmarks_inside: n_inside,
            triangles: field.triangles.len(),
            ..Default::default()
        };
        Ok((field, stats))
    }

    /// Checks the field's consistency and that no triangle flips or collapses in the target
    /// frame (spec §9.1 item 8).
    pub fn check_fold_over(&self) -> Result<(), ProcError> {
        if self.src.len() != self.dst.len() {
            return Err(ProcError::Field(format!("{} source but {} target landmarks", self.src.len(), self.dst.len())));
        }
        if self.triangles.is_empty() {
            return Err(ProcError::Field("no triangles".into()));
        }
        let n = self.src.len() as u32;
        let mut bad = 0usize;
        let mut first = None;
        for t in &self.triangles {
            if t.iter().any(|&k| k >= n) {
                return Err(ProcError::Field(format!("triangle {t:?} refers to a missing landmark (have {n})")));
            }
            let a0 = area(self.src[t[0] as usize], self.src[t[1] as usize], self.src[t[2] as usize]);
            let a1 = area(self.dst[t[0] as usize], self.dst[t[1] as usize], self.dst[t[2] as usize]);
            if !(a0 != 0.0 && a1 * a0.signum() > 1e-12 * a0.abs()) {
                bad += 1;
                first.get_or_insert(self.src[t[0] as usize]);
            }
        }
        if bad > 0 {
            let p = first.unwrap();
            return Err(ProcError::FoldOver(format!(
                "{bad} of {} triangles flip or collapse (first near {:.3}, {:.3}); use a larger block width or window",
                self.triangles.len(),
                p[0],
                p[1]
            )));
        }
        Ok(())
    }

    /// Parses a field from JSON and checks it.
    pub fn from_json(s: &str) -> Result<WarpField, ProcError> {
        let f: WarpField = serde_json::from_str(s).map_err(|e| ProcError::Field(format!("cannot decode: {e}")))?;
        if f.version != 1 {
            return Err(ProcError::Field(format!("version {} is not supported (expected 1)", f.version)));
        }
        f.check_fold_over()?;
        Ok(f)
    }

    /// The field as compact JSON (f64 printed shortest-round-trip: decoding is exact).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a WarpField always serialises")
    }

    /// A point-location structure for forward and inverse mapping.
    pub fn mapper(&self) -> WarpMapper<'_> {
        WarpMapper {
            field: self,
            src_index: TriIndex::new(&self.src, &self.triangles),
            dst_index: TriIndex::new(&self.dst, &self.triangles),
        }
    }
}

#[inline]
fn area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
}

/// Uniform bucket grid over triangles for point location.
struct TriIndex {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    buckets: Vec<Vec<u32>>,
}

impl TriIndex {
    fn new(pts: &[[f64; 2]], tris: &[[u32; 3]]) -> TriIndex {
        let (mut x0, mut y0, mut x1, mut y1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for p in pts {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        let n = (tris.len().max(1) as f64).sqrt().ceil() as usize;
        let cell = ((x1 - x0).max(y1 - y0) / n as f64).max(f64::MIN_POSITIVE);
        let nx = (((x1 - x0) / cell).floor() as usize + 1).max(1);
        let ny = (((y1 - y0) / cell).floor() as usize + 1).max(1);
        let mut buckets = vec![Vec::new(); nx * ny];
        for (k, t) in tris.iter().enumerate() {
            let ps = t.map(|i| pts[i as usize]);
            let bx0 = ((ps.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min) - x0) / cell).floor() as usize;
            let bx1 = (((ps.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max) - x0) / cell).floor() as usize)
                .min(nx - 1);
            let by0 = ((ps.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min) - y0) / cell).floor() as usize;
            let by1 = (((ps.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max) - y0) / cell).floor() as usize)
                .min(ny - 1);
            for by in by0..=by1 {
                for bx in bx0..=bx1 {
                    buckets[by * nx + bx].push(k as u32);
                }
            }
        }
        TriIndex { x0, y0, cell, nx, ny, buckets }
    }

    /// The triangle containing `p` and its barycentric coordinates.
    fn locate(&self, pts: &[[f64; 2]], tris: &[[u32; 3]], p: [f64; 2]) -> Option<(usize, [f64; 3])> {
        let bx = ((p[0] - self.x0) / self.cell).floor();
        let by = ((p[1] - self.y0) / self.cell).floor();
        if !(bx >= 0.0 && by >= 0.0 && bx < self.nx as f64 && by < self.ny as f64) {
            return None;
        }
        let mut best: Option<(usize, [f64; 3], f64)> = None;
        for &k in &self.buckets[by as usize * self.nx + bx as usize] {
            let t = tris[k as usize];
            let (a, b, c) = (pts[t[0] as usize], pts[t[1] as usize], pts[t[2] as usize]);
            let d = area(a, b, c);
            let l0 = area(p, b, c) / d;
            let l1 = area(a, p, c) / d;
            let l2 = 1.0 - l0 - l1;
            let worst = l0.min(l1).min(l2);
            if worst >= 0.0 {
                return Some((k as usize, [l0, l1, l2]));
            }
            // Points on a shared edge may fail both neighbours by rounding: keep the nearest miss.
            if worst > -1e-12 && best.as_ref().is_none_or(|b| worst > b.2) {
                best = Some((k as usize, [l0, l1, l2], worst));
            }
        }
        best.map(|(k, l, _)| (k, l))
    }
}

/// Forward and inverse mapping through a [`WarpField`].
pub struct WarpMapper<'a> {
    field: &'a WarpField,
    src_index: TriIndex,
    dst_index: TriIndex,
}

impl WarpMapper<'_> {
    /// Source (world) → target frame. Outside the landmark grid: the rotation alone.
    pub fn forward(&self, p: [f64; 2]) -> [f64; 2] {
        let f = self.field;
        match self.src_index.locate(&f.src, &f.triangles, p) {
            Some((k, l)) => {
                let t = f.triangles[k];
                let (a, b, c) = (f.dst[t[0] as usize], f.dst[t[1] as usize], f.dst[t[2] as usize]);
                [l[0] * a[0] + l[1] * b[0] + l[2] * c[0], l[0] * a[1] + l[1] * b[1] + l[2] * c[1]]
            }
            None => rot(f.rotation, f.centre, p),
        }
    }

    /// Target frame → source (world), the exact inverse of [`WarpMapper::forward`]: used to map
    /// control points back (spec §2.3.7). Outside the displaced grid: the inverse rotation.
    pub fn inverse(&self, q: [f64; 2]) -> [f64; 2] {
        let f = self.field;
        match self.dst_index.locate(&f.dst, &f.triangles, q) {
            Some((k, l)) => {
                let t = f.triangles[k];
                let (a, b, c) = (f.src[t[0] as usize], f.src[t[1] as usize], f.src[t[2] as usize]);
                [l[0] * a[0] + l[1] * b[0] + l[2] * c[0], l[0] * a[1] + l[1] * b[1] + l[2] * c[1]]
            }
            None => rot(-f.rotation, f.centre, q),
        }
    }
}

/// Warps a raster (spec §2.3.3 forward mapping + §2.3.4 splatting + §2.3.5 dilation): returns
/// the filled target raster carrying the field (with the source grid) in its metadata.
pub fn warp_raster(r: &Raster, params: &WarpParams) -> Result<(Raster, WarpField, WarpStats), ProcError> {
    let (mut field, mut stats) = WarpField::build(r, params)?;
    field.source = Some(SourceGrid::from_raster(r));
    let mapper = field.mapper();
    let mut mapped: Vec<([f64; 2], f64)> = Vec::with_capacity(r.valid_count());
    for row in 0..r.height {
        for col in 0..r.width {
            if let Some(z) = r.get(col, row) {
                let (x, y) = r.cell_centre(col, row);
                mapped.push((mapper.forward([x, y]), z));
            }
        }
    }
    let (cdx, cdy) = r.cell_size();
    let cell = (cdx * cdy).sqrt();
    let mut b = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for (q, _) in &mapped {
        b = (b.0.min(q[0]), b.1.min(q[1]), b.2.max(q[0]), b.3.max(q[1]));
    }
    // Edges half a cell outside the extreme mapped centres, then whole cells.
    let x0 = b.0 - 0.5 * cell;
    let ytop = b.3 + 0.5 * cell;
    let width = (((b.2 + 0.5 * cell) - x0) / cell).ceil().max(1.0) as usize;
    let height = ((ytop - (b.1 - 0.5 * cell)) / cell).ceil().max(1.0) as usize;
    let grid = GridSpec { width, height, geotransform: [x0, cell, 0.0, ytop, 0.0, -cell] };
    grid.check_budget()?;
    let mut acc = SplatAccumulator::new(width, height, params.kernel)?;
    for (q, z) in &mapped {
        let (px, py) = grid.world_to_pixel(q[0], q[1]);
        acc.add(px, py, *z);
    }
    let mut out = Raster::from_values(width, height, grid.geotransform, None, acc.finish())?;
    stats.cells_splatted = out.valid_count();
    stats.dilation_passes = extrapolating_dilation_fill(&mut out, params.neighbourhood)?;
    stats.cells_filled = out.valid_count() - stats.cells_splatted;
    stats.target_width = width;
    stats.target_height = height;
    out.metadata.insert(WARP_METADATA_KEY.into(), field.to_json());
    Ok((out, field, stats))
}

/// Reads the field a warped raster carries.
pub fn field_of(r: &Raster) -> Result<WarpField, ProcError> {
    let s = r.metadata.get(WARP_METADATA_KEY).ok_or_else(|| {
        ProcError::Field(format!("no {WARP_METADATA_KEY} metadata: not a raster written by `geofit warp`"))
    })?;
    WarpField::from_json(s)
}

/// Maps a warped raster back onto its source grid (spec §2.3.3 inverse mapping): every source
/// cell of the stored footprint takes the bilinear value of the warped raster at its forward
/// image. Cells outside the footprint stay without a value.
pub fn unwarp_raster(warped: &Raster, field: &WarpField) -> Result<Raster, ProcError> {
    let src = field.source.as_ref().ok_or_else(|| ProcError::Field("the field holds no source grid".into()))?;
    let mask = src.mask()?;
    let mut out = Raster::new_empty(src.width, src.height, src.geotransform, src.crs.clone());
    out.nodata = src.nodata;
    let mapper = field.mapper();
    let mut missing = 0usize;
    for row in 0..src.height {
        for col in 0..src.width {
            if !mask[row * src.width + col] {
                continue;
            }
            let (x, y) = out.cell_centre(col, row);
            let q = mapper.forward([x, y]);
            match warped.sample(q[0], q[1], MissingCorners::Renormalize) {
                Some(v) => out.set(col, row, v),
                None => missing += 1,
            }
        }
    }
    if missing > 0 && out.valid_count() == 0 {
        return Err(ProcError::Input("the warped raster covers none of the source footprint".into()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rotated channel: valid cells in a band along 30°, depth varying along it.
    fn channel(w: usize, h: usize) -> Raster {
        let gt = Raster::geotransform_from_centres(1000.0, 2000.0 + h as f64 - 1.0, 1.0, -1.0);
        let mut r = Raster::new_empty(w, h, gt, None);
        let t = 30f64.to_radians();
        let (cx, cy) = (1000.0 + w as f64 / 2.0, 2000.0 + h as f64 / 2.0);
        for row in 0..h {
            for col in 0..w {
                let (x, y) = r.cell_centre(col, row);
                let along = (x - cx) * t.cos() + (y - cy) * t.sin();
                let across = -(x - cx) * t.sin() + (y - cy) * t.cos();
                let width = 15.0 + 10.0 * (along / 20.0).sin();
                if along.abs() < 0.4 * w as f64 && across.abs() < width {
                    r.set(col, row, -10.0 - 0.05 * along - 0.2 * across.abs());
                }
            }
        }
        r
    }

    #[test]
    fn forward_then_inverse_returns_points() {
        let r = channel(160, 120);
        let (field, stats) =
            WarpField::build(&r, &WarpParams { landmark_spacing: Some(8.0), ..Default::default() }).unwrap();
        assert!((stats.rotation_deg + 30.0).abs() < 2.0, "{}", stats.rotation_deg);
        assert!(stats.landmarks_inside > 10);
        let m = field.mapper();
        // Landmarks really moved (the warp is not a pure rotation).
        let moved = field.src.iter().zip(&field.dst).filter(|(s, d)| {
            let q = rot(field.rotation, field.centre, **s);
            (q[0] - d[0]).hypot(q[1] - d[1]) > 0.5
        });
        assert!(moved.count() > 10);
        let mut s = 7u64;
        let mut worst: f64 = 0.0;
        for _ in 0..20000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            let x = 990.0 + (s >> 11) as f64 / (1u64 << 53) as f64 * 180.0;
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            let y = 1990.0 + (s >> 11) as f64 / (1u64 << 53) as f64 * 140.0;
            let q = m.forward([x, y]);
            let p = m.inverse(q);
            worst = worst.max((p[0] - x).hypot(p[1] - y));
        }
        // spec acceptance: within 1e-6 of a cell (cell = 1)
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn fold_over_is_detected() {
        let r = channel(80, 60);
        let (mut field, _) =
            WarpField::build(&r, &WarpParams { landmark_spacing: Some(8.0), ..Default::default() }).unwrap();
        let t = field.triangles[field.triangles.len() / 2];
        // Push one vertex across its opposite edge.
        let (a, b, c) = (field.dst[t[0] as usize], field.dst[t[1] as usize], field.dst[t[2] as usize]);
        let mid = [(b[0] + c[0]) / 2.0, (b[1] + c[1]) / 2.0];
        field.dst[t[0] as usize] = [a[0] + 2.5 * (mid[0] - a[0]), a[1] + 2.5 * (mid[1] - a[1])];
        assert!(matches!(field.check_fold_over(), Err(ProcError::FoldOver(_))));
    }

    #[test]
    fn warp_fills_rectangle_and_unwarps() {
        let r = channel(160, 120);
        let (w, field, stats) =
            warp_raster(&r, &WarpParams { landmark_spacing: Some(8.0), ..Default::default() }).unwrap();
        assert_eq!(w.valid_count(), w.width * w.height);
        assert!(stats.cells_filled > 0);
        let back_field = field_of(&w).unwrap();
        assert!(back_field == field, "field changed in metadata");
        let u = unwarp_raster(&w, &back_field).unwrap();
        assert_eq!(u.valid_mask(), r.valid_mask());
        assert_eq!(u.geotransform, r.geotransform);
        // values come back close (resampling twice smooths a little)
        let mut sq = 0.0;
        for (a, b) in u.data.iter().zip(&r.data).filter(|(a, _)| a.is_finite()) {
            sq += (a - b) * (a - b);
        }
        let rms = (sq / r.valid_count() as f64).sqrt();
        assert!(rms < 0.3, "{rms}");
    }

    #[test]
    fn json_round_trip_exact_and_rle_mask() {
        let r = channel(50, 40);
        let g = SourceGrid::from_raster(&r);
        assert_eq!(g.mask().unwrap(), r.valid_mask());
        let (mut f, _) = WarpField::build(&r, &WarpParams::default()).unwrap();
        f.source = Some(g);
        assert!(WarpField::from_json(&f.to_json()).unwrap() == f, "JSON round trip not exact");
        assert!(WarpField::from_json("{}").is_err());
    }
}
