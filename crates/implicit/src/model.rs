//! The implicit model: mesh, constraints and solution, its construction from points with the
//! "interpolate, measure, refine, re-interpolate" loop (seed §2.1), re-interpolation with base +
//! float constraints warm-started from the saved solution (seed §3), and its file format.
//!
//! # File format (`.gfim`, little-endian binary, version 1)
//! ```text
//! magic   16 bytes  "GEOFIT-IMPLICIT\0"
//! version u32       1
//! origin  3×f64     world coordinates of the local frame's origin (all positions are local)
//! cell    f64       finest cell size the mesh was refined to
//! params  6×f64     ϖ_value, ϖ_normal, ϖ_rough, step δ, gradient g, CG tolerance
//!         2×u64     CG iteration cap, active-set round cap
//! nv      u64       then nv × (3×f64 position, u32 geometric vertex id)   (fault cuts duplicate)
//! nt      u64       then nt × 4×u32 vertex indices (positively oriented tetrahedra)
//! nc      u64       then nc × (3×f64 pos, u8 flags [1 value, 2 normal, 4 float],
//!                          f64 value, 3×f64 normal, f64 side)
//! phi     nv × f64  the solution at the vertices
//! na      u64       then na × u8 active flags of the data rows (in row order)
//! attr    u8        0, or 1 then u32 name length, name bytes (UTF-8), nv × f64 values
//! ```

use crate::dsi::{self, Constraint, Params, Solution, Weights};
use crate::fault::{self, Fault};
use crate::geom::{add, cross, dot, norm, scale, sub, V3};
use crate::mesh::{Locator, Refiner, TetMesh};
use crate::points::{DataPoint, SidePoint};
use crate::Error;

/// A solved implicit model.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    pub origin: V3,
    pub cell: f64,
    pub params: Params,
    pub mesh: TetMesh,
    pub dof_vertex: Vec<u32>,
    pub constraints: Vec<Constraint>,
    pub phi: Vec<f64>,
    pub active: Vec<bool>,
    pub attribute: Option<(String, Vec<f64>)>,
}

/// Options of [`build`].
#[derive(Debug, Clone)]
pub struct BuildOptions {
    /// Finest cell size; None chooses it from the point density.
    pub cell: Option<f64>,
    /// Roughness weight from the data's noise ([`dsi::auto_roughness`]) instead of
    /// `weights.rough`.
    pub auto_rough: bool,
    /// Coarse cubes along the longest side of the domain.
    pub coarse: usize,
    pub weights: Weights,
    /// Normal step δ; None = the finest cell size.
    pub step: Option<f64>,
    /// Gradient magnitude g; None = estimated from the values (1 for a single surface).
    pub grad: Option<f64>,
    pub tol: f64,
    pub max_iter: usize,
    pub rounds: usize,
    /// Misfit-driven refinement rounds (interpolate, measure, refine, re-interpolate).
    pub refine_rounds: usize,
    /// Misfit (distance units, |φ − v|/g) above which a data point's tetrahedron is refined;
    /// None = half the finest cell size.
    pub misfit_tol: Option<f64>,
    /// Upper bound on mesh vertices for the automatic cell size.
    pub max_vertices: usize,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            cell: None,
            auto_rough: true,
            coarse: 8,
            weights: Weights::default(),
            step: None,
            grad: None,
            tol: 1e-6,
            max_iter: 20000,
            rounds: 4,
            refine_rounds: 1,
            misfit_tol: None,
            max_vertices: 400_000,
        }
    }
}

/// What [`build`] did, for reports.
#[derive(Debug, Clone, Default)]
pub struct BuildReport {
    pub points: usize,
    pub duplicates_merged: usize,
    pub cell: f64,
    pub vertices: usize,
    pub tetrahedra: usize,
    pub refinement_rounds: usize,
    pub cg_iterations: Vec<usize>,
    pub misfit_mean: f64,
    pub misfit_max: f64,
    pub grad: f64,
    /// Estimated noise of the value points across their surface (distance units).
    pub noise_sigma: Option<f64>,
    /// The roughness weight ϖ_r used.
    pub w_rough: f64,
}

/// Progress events from the library (the CLI forwards them to its progress lines).
pub enum Event<'a> {
    Stage(&'a str),
    Cg { round: usize, iterations: usize, residual: f64 },
}

fn validate(points: &[DataPoint], sides: &[SidePoint]) -> Result<(Vec<DataPoint>, usize), Error> {
    if points.len() < 4 {
        return Err(Error::BadInput(format!("need at least 4 points to span a volume, got {}", points.len())));
    }
    // Duplicates: same position. Same value → merged; different values → contradiction.
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| {
        let (p, q) = (points[a].pos, points[b].pos);
        p[0].total_cmp(&q[0]).then(p[1].total_cmp(&q[1])).then(p[2].total_cmp(&q[2])).then(a.cmp(&b))
    });
    let mut keep = vec![true; points.len()];
    let mut merged = 0;
    for w in order.windows(2) {
        let (a, b) = (&points[w[0]], &points[w[1]]);
        if a.pos == b.pos {
            if let (Some(x), Some(y)) = (a.value, b.value) {
                if x != y {
                    return Err(Error::BadInput(format!(
                        "duplicated point: lines {} and {} are both at ({}, {}, {}) with different values {x} and {y}",
                        a.line, b.line, a.pos[0], a.pos[1], a.pos[2]
                    )));
                }
            }
            if a.normal.is_none() || b.normal.is_none() || a.value.is_none() == b.value.is_none() {
                keep[w[1]] = false;
                merged += 1;
            }
        }
    }
    let pts: Vec<DataPoint> = points.iter().zip(&keep).filter(|(_, &k)| k).map(|(p, _)| p.clone()).collect();
    if pts.len() < 4 {
        return Err(Error::BadInput(format!(
            "only {} distinct positions among {} points (duplicated points); need at least 4",
            pts.len(),
            points.len()
        )));
    }
    // Dimension of the point set: farthest point, farthest from the line, farthest from the plane.
    let p0 = pts[0].pos;
    let far = |f: &dyn Fn(V3) -> f64| pts.iter().map(|p| p.pos).max_by(|a, b| f(*a).total_cmp(&f(*b))).unwrap_or(p0);
    let p1 = far(&|p| norm(sub(p, p0)));
    let ext = norm(sub(p1, p0));
    let tol = 1e-9 * ext.max(1e-300);
    let dir = scale(sub(p1, p0), 1.0 / ext.max(1e-300));
    let off_line = |p: V3| norm(cross(sub(p, p0), dir));
    let p2 = far(&off_line);
    if ext <= 0.0 || off_line(p2) <= tol {
        return Err(Error::BadInput("the points are collinear: a line does not determine a surface".into()));
    }
    let pn = crate::geom::normalize(cross(dir, sub(p2, p0))).unwrap_or([0.0, 0.0, 1.0]);
    let p3 = far(&|p| dot(sub(p, p0), pn).abs());
    if dot(sub(p3, p0), pn).abs() <= tol {
        let leaves = pts.iter().any(|p| p.normal.map(|n| dot(n, pn).abs() > 0.1).unwrap_or(false))
            || sides.iter().any(|s| dot(sub(s.pos, p0), pn).abs() > tol);
        if !leaves {
            return Err(Error::BadInput(
                "the points are coplanar and no normal or side point leaves their plane: φ is not determined across it"
                    .into(),
            ));
        }
    }
    let has_normals = pts.iter().any(|p| p.normal.is_some());
    let vals: Vec<f64> = pts.iter().map(|p| p.value.unwrap_or(0.0)).collect();
    let varying = vals.iter().any(|&v| v != vals[0]);
    if !has_normals && sides.is_empty() && !varying {
        return Err(Error::BadInput(
            "no normals and no side points: with only φ = 0 at the points, φ ≡ 0 fits every constraint exactly and \
             defines no surface. Add nx ny nz columns, give --side-points FILE (x y z ±1), or use --up-normals for terrain"
                .into(),
        ));
    }
    Ok((pts, merged))
}

/// Finest cell from the density: the smallest power-of-two fraction of the coarse cube whose
/// occupied cells still hold ≥ 3 points on average (noise averaging), within `max_cells`.
fn auto_cell(local: &[V3], cube: f64, max_cells: usize) -> f64 {
    let mut cell = cube;
    for _ in 0..7 {
        let c = cell * 0.5;
        let mut keys: Vec<(i64, i64, i64)> = local
            .iter()
            .map(|p| ((p[0] / c).floor() as i64, (p[1] / c).floor() as i64, (p[2] / c).floor() as i64))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        if (local.len() as f64) / (keys.len() as f64) < 3.0 || keys.len() * 4 > max_cells {
            break;
        }
        cell = c;
    }
    cell
}

/// Builds and solves a model from points (world coordinates), side points and faults.
pub fn build(
    points: &[DataPoint],
    sides: &[SidePoint],
    faults: &[Fault],
    opt: &BuildOptions,
    progress: &mut dyn FnMut(Event),
) -> Result<(Model, BuildReport), Error> {
    let (pts, merged) = validate(points, sides)?;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in pts.iter().map(|p| p.pos).chain(sides.iter().map(|s| s.pos)) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let origin = scale(add(lo, hi), 0.5);
    let local = |p: V3| sub(p, origin);
    let ext = sub(hi, lo);
    let longest = ext[0].max(ext[1]).max(ext[2]);
    let coarse = opt.coarse.max(1);
    let cube0 = longest * 1.2 / coarse as f64;
    // an infinite extent (points at ±1e308) would make the cube-doubling loop below endless
    if !cube0.is_finite() {
        return Err(Error::BadInput(format!("the points span {longest:e}: more than a model can hold")));
    }
    let lp: Vec<V3> = pts.iter().map(|p| local(p.pos)).collect();
    let cell = match opt.cell {
        Some(c) if c > 0.0 && c.is_finite() => c,
        Some(c) => return Err(Error::BadInput(format!("--cell must be a positive size, got {c}"))),
        None => auto_cell(&lp, cube0, opt.max_vertices),
    };
    // The coarse cube is a power-of-two multiple of the cell, so the finest level hits `cell`.
    let mut cube = cell;
    while cube * 2.0 <= cube0 * 1.0001 {
        cube *= 2.0;
    }
    let step = opt.step.unwrap_or(cell);
    let margin = (0.1 * longest).max(3.0 * cell).max(2.0 * step);
    let dims = [0, 1, 2].map(|k| (((ext[k] + 2.0 * margin) / cube).ceil() as usize).max(1));
    if dims.iter().product::<usize>() > 4_000_000 {
        return Err(Error::BadInput(format!(
            "--cell {cell} gives a coarse grid of {}×{}×{} cubes; use a larger --cell",
            dims[0], dims[1], dims[2]
        )));
    }
    let glo = [0, 1, 2].map(|k| -(dims[k] as f64) * cube * 0.5);
    // Without a value column every point lies on φ = 0 (one surface); with one, a row with a
    // normal but no value (LoopStructural style) only orients φ.
    let any_value_column = pts.iter().any(|p| p.value.is_some());
    let mut cs: Vec<Constraint> = pts
        .iter()
        .map(|p| Constraint {
            pos: local(p.pos),
            value: if any_value_column { p.value } else { Some(0.0) },
            normal: p.normal,
            side: 0.0,
            float: false,
        })
        .collect();
    cs.extend(sides.iter().map(|s| Constraint {
        pos: local(s.pos),
        value: None,
        normal: None,
        side: s.side,
        float: false,
    }));
    let grad = opt.grad.unwrap_or_else(|| dsi::gradient_scale(&cs));
    let noise_sigma = if opt.auto_rough {
        let vp: Vec<(V3, f64)> = cs.iter().filter_map(|c| c.value.map(|v| (c.pos, v))).collect();
        crate::noise::estimate(&vp)
    } else {
        None
    };
    let mut weights = opt.weights;
    if opt.auto_rough {
        weights.rough = dsi::auto_roughness(noise_sigma, cell);
    }
    let params = Params { weights, step, grad, tol: opt.tol, max_iter: opt.max_iter, rounds: opt.rounds };
    params.check().map_err(Error::BadInput)?;
    let faults: Vec<Fault> = faults
        .iter()
        .map(|f| Fault { name: f.name.clone(), tris: f.tris.iter().map(|t| t.map(local)).collect() })
        .collect();

    // Guard memory before refining: the finest cells the samples touch bound the mesh size.
    {
        let mut keys: Vec<(i64, i64, i64)> = lp
            .iter()
            .map(|p| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64, (p[2] / cell).floor() as i64))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        if keys.len() > opt.max_vertices {
            return Err(Error::BadInput(format!(
                "--cell {cell} puts the points into {} finest cells (cap {}); use a larger --cell",
                keys.len(),
                opt.max_vertices
            )));
        }
    }
    progress(Event::Stage("meshing"));
    let mut refiner = Refiner::new(glo, dims, cube);
    let target = refiner.level_of_cube_fraction(cell);
    let mut samples: Vec<V3> = Vec::new();
    for c in &cs {
        samples.push(c.pos);
        if let Some(n) = c.normal {
            samples.push(add(c.pos, scale(n, step)));
            samples.push(sub(c.pos, scale(n, step)));
        }
    }
    for f in &faults {
        samples.extend(fault::fault_samples(f, cell * 0.5));
    }
    refiner.add_points(&samples, target);
    refiner.refine();

    let misfit_tol = opt.misfit_tol.unwrap_or(0.5 * cell);
    let mut report = BuildReport {
        points: pts.len(),
        duplicates_merged: merged,
        cell,
        grad,
        noise_sigma,
        w_rough: weights.rough,
        ..Default::default()
    };
    let mut prev: Option<(Vec<f64>, Vec<u32>)> = None;
    let mut round = 0;
    loop {
        let mesh0 = refiner.mesh();
        if mesh0.verts.len() > opt.max_vertices * 2 {
            return Err(Error::BadInput(format!(
                "the mesh would have {} vertices (cap {}); use a larger --cell",
                mesh0.verts.len(),
                opt.max_vertices * 2
            )));
        }
        let (mesh, dof_vertex) = fault::cut(&mesh0, &faults)?;
        let loc = Locator::new(&mesh);
        // Warm start from the previous round: bisection keeps P1 functions, so midpoints take
        // the mean of their edge's end values.
        let start = prev.as_ref().map(|(phi, dv)| {
            let mut vsum = vec![0.0; refiner.verts.len()];
            let mut vcnt = vec![0u32; refiner.verts.len()];
            for (d, &v) in dv.iter().enumerate() {
                vsum[v as usize] += phi[d];
                vcnt[v as usize] += 1;
            }
            for v in 0..refiner.verts.len() {
                if vcnt[v] > 0 {
                    vsum[v] /= vcnt[v] as f64;
                } else if let Some([a, b]) = refiner.parents[v] {
                    vsum[v] = 0.5 * (vsum[a as usize] + vsum[b as usize]);
                }
            }
            dof_vertex.iter().map(|&v| vsum[v as usize]).collect::<Vec<f64>>()
        });
        progress(Event::Stage("solving"));
        let sol: Solution = dsi::solve(&mesh, &loc, &cs, &params, start.as_deref(), None, &mut |r, it, res| {
            progress(Event::Cg { round: r, iterations: it, residual: res })
        })?;
        report.cg_iterations.extend(&sol.iterations);
        // Misfits from the solve's value rows; if some value rows are missing (ϖ_value = 0 scales
        // them to nothing), evaluate φ at the points instead.
        let n_values = cs.iter().filter(|c| c.value.is_some()).count();
        let value_misfit: Vec<(u32, f64)> = if sol.value_misfit.len() == n_values {
            sol.value_misfit.clone()
        } else {
            dsi::value_misfits(&mesh, &loc, &cs, &sol.phi)
        };
        let mis: Vec<f64> = value_misfit.iter().map(|&(_, e)| e).collect();
        let (mean, max) = stats(&mis);
        report.misfit_mean = mean;
        report.misfit_max = max;
        report.vertices = mesh.verts.len();
        report.tetrahedra = mesh.tets.len();
        report.refinement_rounds = round;
        let bad: Vec<V3> =
            value_misfit.iter().filter(|&&(_, e)| e / grad > misfit_tol).map(|&(c, _)| cs[c as usize].pos).collect();
        if round >= opt.refine_rounds || bad.is_empty() {
            let model = Model {
                origin,
                cell,
                params,
                mesh,
                dof_vertex,
                constraints: cs,
                phi: sol.phi,
                active: sol.active,
                attribute: None,
            };
            return Ok((model, report));
        }
        progress(Event::Stage("refining where the reconstruction misses the data"));
        refiner.refine_at(&bad, target + 3);
        prev = Some((sol.phi, dof_vertex));
        round += 1;
    }
}

pub fn stats(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    (v.iter().sum::<f64>() / v.len() as f64, v.iter().cloned().fold(0.0, f64::max))
}

impl Model {
    pub fn locator(&self) -> Locator {
        Locator::new(&self.mesh)
    }

    /// The iso-values a user wants when none are named: each distinct constraint value when
    /// there are 2 to 16 of them (the horizons of stratigraphic data), otherwise the surface
    /// φ = 0 (points on one surface).
    pub fn default_iso_values(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self.constraints.iter().filter_map(|c| c.value).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        if v.len() > 1 && v.len() <= 16 {
            v
        } else {
            vec![0.0]
        }
    }

    /// φ at a world position (None outside the mesh).
    pub fn eval_world(&self, loc: &Locator, p: V3) -> Option<f64> {
        dsi::eval(&self.mesh, loc, &self.phi, sub(p, self.origin))
    }

    /// Misfit |φ − v| at the value constraints (mean, max), in φ units.
    pub fn misfit(&self, loc: &Locator) -> (f64, f64) {
        let m: Vec<f64> =
            dsi::value_misfits(&self.mesh, loc, &self.constraints, &self.phi).into_iter().map(|(_, e)| e).collect();
        stats(&m)
    }

    /// Re-interpolation (seed §3): `moves` (constraint index, new world position) and `added`
    /// constraints (world positions) become float constraints; the system A_B + A_F is solved by
    /// CG warm-started from the saved solution and active set (`cold` starts from zero instead).
    pub fn update(
        &mut self,
        added: &[DataPoint],
        moves: &[(usize, V3)],
        cold: bool,
        progress: &mut dyn FnMut(Event),
    ) -> Result<Solution, Error> {
        for &(i, p) in moves {
            let n = self.constraints.len();
            let c = self.constraints.get_mut(i).ok_or_else(|| {
                Error::BadInput(format!("--move {i}: the model has constraints 0..{} only", n.saturating_sub(1)))
            })?;
            if p.iter().any(|x| !x.is_finite()) {
                return Err(Error::BadInput(format!("--move {i}: NaN or infinite coordinate")));
            }
            c.pos = sub(p, self.origin);
            c.float = true;
        }
        let any_value = self.constraints.iter().any(|c| c.value.is_some());
        for p in added {
            self.constraints.push(Constraint {
                pos: sub(p.pos, self.origin),
                value: if p.value.is_some() || !any_value || p.normal.is_none() {
                    Some(p.value.unwrap_or(0.0))
                } else {
                    None
                },
                normal: p.normal,
                side: 0.0,
                float: true,
            });
        }
        let loc = self.locator();
        let rows = dsi::data_rows(&self.mesh, &loc, &self.constraints, &self.params)?;
        // The saved active set holds for the rows that did not change; the rows of moved and
        // added constraints are new rows, so their state comes from the saved φ at their new
        // positions (violated there → active), as any active-set round would decide it.
        let n_old = self.constraints.len() - added.len();
        let moved: std::collections::BTreeSet<u32> = moves.iter().map(|&(i, _)| i as u32).collect();
        let mut active = self.active.clone();
        active.resize(rows.len(), true);
        for r in 0..rows.len() {
            let o = rows.owner[r];
            if rows.ineq[r] && (moved.contains(&o) || o as usize >= n_old) && rows.scale[r] > 0.0 {
                active[r] = rows.dot(r, &self.phi) < rows.rhs[r];
            }
        }
        progress(Event::Stage("re-interpolating"));
        // Cold: the same rows from φ = 0 and all rows active (the comparison start).
        let (start, act) = if cold { (None, None) } else { (Some(&self.phi[..]), Some(&active[..])) };
        let sol = dsi::solve_rows(&self.mesh, &rows, &self.params, start, act, &mut |r, it, res| {
            progress(Event::Cg { round: r, iterations: it, residual: res })
        })?;
        self.phi = sol.phi.clone();
        self.active = sol.active.clone();
        Ok(sol)
    }

    /// Interpolates a second scalar attribute (value points, world coordinates) on the same mesh
    /// by DSI (value + roughness constraints), for co-visualisation on iso-surfaces and sections.
    pub fn interpolate_attribute(&mut self, name: &str, pts: &[DataPoint]) -> Result<Solution, Error> {
        let cs: Vec<Constraint> = pts
            .iter()
            .map(|p| {
                p.value
                    .map(|v| Constraint {
                        pos: sub(p.pos, self.origin),
                        value: Some(v),
                        normal: None,
                        side: 0.0,
                        float: false,
                    })
                    .ok_or_else(|| Error::BadInput(format!("attribute point at line {} has no value column", p.line)))
            })
            .collect::<Result<_, _>>()?;
        if cs.is_empty() {
            return Err(Error::BadInput("the attribute file has no points".into()));
        }
        let loc = self.locator();
        let mut params = self.params;
        params.rounds = 1;
        let sol = dsi::solve(&self.mesh, &loc, &cs, &params, None, None, &mut |_, _, _| {})?;
        self.attribute = Some((name.to_string(), sol.phi.clone()));
        Ok(sol)
    }

    // ---- file format (see module doc) ----

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(64 + self.mesh.verts.len() * 40 + self.mesh.tets.len() * 16);
        let f = |w: &mut Vec<u8>, x: f64| w.extend_from_slice(&x.to_le_bytes());
        let u = |w: &mut Vec<u8>, x: u64| w.extend_from_slice(&x.to_le_bytes());
        let u32w = |w: &mut Vec<u8>, x: u32| w.extend_from_slice(&x.to_le_bytes());
        w.extend_from_slice(MAGIC);
        u32w(&mut w, 1);
        for k in 0..3 {
            f(&mut w, self.origin[k]);
        }
        f(&mut w, self.cell);
        let p = &self.params;
        for x in [p.weights.value, p.weights.normal, p.weights.rough, p.step, p.grad, p.tol] {
            f(&mut w, x);
        }
        u(&mut w, p.max_iter as u64);
        u(&mut w, p.rounds as u64);
        u(&mut w, self.mesh.verts.len() as u64);
        for (v, &g) in self.mesh.verts.iter().zip(&self.dof_vertex) {
            for k in 0..3 {
                f(&mut w, v[k]);
            }
            u32w(&mut w, g);
        }
        u(&mut w, self.mesh.tets.len() as u64);
        for t in &self.mesh.tets {
            for &i in t {
                u32w(&mut w, i);
            }
        }
        u(&mut w, self.constraints.len() as u64);
        for c in &self.constraints {
            for k in 0..3 {
                f(&mut w, c.pos[k]);
            }
            let flags = c.value.is_some() as u8 | (c.normal.is_some() as u8) << 1 | (c.float as u8) << 2;
            w.push(flags);
            f(&mut w, c.value.unwrap_or(0.0));
            let n = c.normal.unwrap_or([0.0; 3]);
            for k in 0..3 {
                f(&mut w, n[k]);
            }
            f(&mut w, c.side);
        }
        for &x in &self.phi {
            f(&mut w, x);
        }
        u(&mut w, self.active.len() as u64);
        w.extend(self.active.iter().map(|&a| a as u8));
        match &self.attribute {
            None => w.push(0),
            Some((name, vals)) => {
                w.push(1);
                u32w(&mut w, name.len() as u32);
                w.extend_from_slice(name.as_bytes());
                for &x in vals {
                    f(&mut w, x);
                }
            }
        }
        w
    }

    pub fn from_bytes(b: &[u8]) -> Result<Model, Error> {
        let mut r = Reader { b, at: 0 };
        if r.take(16)? != MAGIC {
            return Err(Error::Model(
                "not a geofit implicit model (bad magic; expected a file written by `geofit implicit interpolate`)"
                    .into(),
            ));
        }
        let version = r.u32()?;
        if version != 1 {
            return Err(Error::Model(format!("unsupported version {version} (this geofit reads version 1)")));
        }
        let origin = [r.f64()?, r.f64()?, r.f64()?];
        let cell = r.f64()?;
        let wv = [r.f64()?, r.f64()?, r.f64()?, r.f64()?, r.f64()?, r.f64()?];
        let max_iter = r.u64()? as usize;
        let rounds = r.u64()? as usize;
        let params = Params {
            weights: Weights { value: wv[0], normal: wv[1], rough: wv[2] },
            step: wv[3],
            grad: wv[4],
            tol: wv[5],
            max_iter,
            rounds,
        };
        // Parameters and constraints feed the solver of `implicit update`: a NaN or 1e300
        // weight made it run forever (docs/decisions.md#crashes-and-hangs-of-issue-40).
        params.check().map_err(Error::Model)?;
        if !(cell.is_finite() && cell > 0.0) {
            return Err(Error::Model(format!("cell size {cell} is not a positive finite number")));
        }
        let nv = r.count(28)?;
        let mut verts = Vec::with_capacity(nv);
        let mut dof_vertex = Vec::with_capacity(nv);
        for _ in 0..nv {
            verts.push([r.f64()?, r.f64()?, r.f64()?]);
            dof_vertex.push(r.u32()?);
        }
        let nt = r.count(16)?;
        let mut tets = Vec::with_capacity(nt);
        for i in 0..nt {
            let t = [r.u32()?, r.u32()?, r.u32()?, r.u32()?];
            if t.iter().any(|&x| x as usize >= nv) {
                return Err(Error::Model(format!("tetrahedron {i} refers to a vertex beyond the {nv} stored")));
            }
            tets.push(t);
        }
        let nc = r.count(65)?;
        let mut constraints = Vec::with_capacity(nc);
        for _ in 0..nc {
            let pos = [r.f64()?, r.f64()?, r.f64()?];
            let flags = r.take(1)?[0];
            let value = r.f64()?;
            let normal = [r.f64()?, r.f64()?, r.f64()?];
            let side = r.f64()?;
            if !pos.iter().chain(&normal).chain([&value, &side]).all(|x| x.is_finite()) {
                return Err(Error::Model(format!(
                    "constraint {} has a non-finite position, value, normal or side",
                    constraints.len()
                )));
            }
            constraints.push(Constraint {
                pos,
                value: (flags & 1 != 0).then_some(value),
                normal: (flags & 2 != 0).then_some(normal),
                side,
                float: flags & 4 != 0,
            });
        }
        let mut phi = Vec::with_capacity(nv);
        for _ in 0..nv {
            phi.push(r.f64()?);
        }
        let na = r.count(1)?;
        let active = r.take(na)?.iter().map(|&x| x != 0).collect();
        let attribute = match r.take(1)?[0] {
            0 => None,
            _ => {
                let l = r.u32()? as usize;
                let name = String::from_utf8(r.take(l)?.to_vec())
                    .map_err(|_| Error::Model("attribute name is not UTF-8".into()))?;
                let mut v = Vec::with_capacity(nv);
                for _ in 0..nv {
                    v.push(r.f64()?);
                }
                Some((name, v))
            }
        };
        if r.at != b.len() {
            return Err(Error::Model(format!("{} trailing bytes after the model", b.len() - r.at)));
        }
        let finite = verts.iter().flatten().chain(&phi).chain(origin.iter()).all(|x| x.is_finite());
        if !finite {
            return Err(Error::Model("non-finite coordinate or value".into()));
        }
        Ok(Model {
            origin,
            cell,
            params,
            mesh: TetMesh { verts, tets },
            dof_vertex,
            constraints,
            phi,
            active,
            attribute,
        })
    }
}

const MAGIC: &[u8; 16] = b"GEOFIT-IMPLICIT\0";

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], Error> {
        if self.at + n > self.b.len() {
            return Err(Error::Model(format!("truncated at byte {} (needs {} more)", self.at, n)));
        }
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn f64(&mut self) -> Result<f64, Error> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap_or([0; 8])))
    }
    fn u64(&mut self) -> Result<u64, Error> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap_or([0; 8])))
    }
    fn u32(&mut self) -> Result<u32, Error> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap_or([0; 4])))
    }
    /// A count whose items take at least `each` bytes: checked against the remaining length.
    fn count(&mut self, each: usize) -> Result<usize, Error> {
        let n = self.u64()? as usize;
        if n.saturating_mul(each) > self.b.len() - self.at {
            return Err(Error::Model(format!("count {n} at byte {} exceeds the file size", self.at - 8)));
        }
        Ok(n)
    }
}
