//! Ready-made fits with errors in all coordinates, built on the generic engine: each point's
//! coordinates are observations, the shape parameters unknowns, one condition per point
//! (total least squares, which a correctly linearised Gauss–Helmert model equals; spec §6.1).

use crate::ad::{Equation, Scalar};
use crate::problem::{Problem, Slot};
use crate::solve::{adjust, Options, Solution};
use crate::AdjustError;

/// `y − (a + b·x) = 0` with x, y observed.
pub struct LineYofX;
impl Equation for LineYofX {
    fn kind(&self) -> &str {
        "LineYofX"
    }
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D {
        l[1] - (x[0] + x[1] * l[0])
    }
}

/// `⟨n, p⟩ − d = 0` with p = (px, py, pz) observed, unknowns (nx, ny, nz, d).
pub struct PointOnPlane;
impl Equation for PointOnPlane {
    fn kind(&self) -> &str {
        "PointOnPlane"
    }
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D {
        x[0] * l[0] + x[1] * l[1] + x[2] * l[2] - x[3]
    }
}

/// `‖n‖ − 1 = 0` (spec T 3.6, restriction form of NormNV).
pub struct UnitNorm3;
impl Equation for UnitNorm3 {
    fn kind(&self) -> &str {
        "NormNV"
    }
    fn eval<D: Scalar>(&self, x: &[D], _l: &[D]) -> D {
        (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt() - 1.0
    }
}

/// `‖p − c‖ − r = 0` with p = (px, py) observed, unknowns (cx, cy, r).
pub struct PointOnCircle;
impl Equation for PointOnCircle {
    fn kind(&self) -> &str {
        "PointOnCircle"
    }
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D {
        let dx = l[0] - x[0];
        let dy = l[1] - x[1];
        (dx * dx + dy * dy).sqrt() - x[2]
    }
}

/// Result of [`fit_line_2d`].
#[derive(Debug, Clone)]
pub struct LineFit {
    pub intercept: f64,
    pub slope: f64,
    pub solution: Solution,
}

/// Straight line y = a + b·x through points with independent errors σx, σy (York's problem).
///
/// ```
/// use adjust::fits::fit_line_2d;
/// let pts = [(0.0, 0.9), (1.0, 3.1), (2.0, 4.9), (3.0, 7.1)];
/// let f = fit_line_2d(&pts, &[0.1; 4], &[0.1; 4]).unwrap();
/// assert!((f.slope - 2.04).abs() < 0.05);
/// ```
pub fn fit_line_2d(points: &[(f64, f64)], sigma_x: &[f64], sigma_y: &[f64]) -> Result<LineFit, AdjustError> {
    fit_line_2d_with(points, sigma_x, sigma_y, &Options::default())
}

/// [`fit_line_2d`] with explicit options.
pub fn fit_line_2d_with(
    points: &[(f64, f64)],
    sigma_x: &[f64],
    sigma_y: &[f64],
    opts: &Options,
) -> Result<LineFit, AdjustError> {
    // Starting values: ordinary least squares of y on x.
    let n = points.len() as f64;
    let (mx, my) = points.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let b0 = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let mut pr = Problem::new();
    let a = pr.add_unknown("intercept", my - b0 * mx);
    let b = pr.add_unknown("slope", b0);
    for (i, p) in points.iter().enumerate() {
        let ox = pr.add_observation(format!("x{i}"), p.0, sigma_x[i])?;
        let oy = pr.add_observation(format!("y{i}"), p.1, sigma_y[i])?;
        pr.add_condition(format!("point {i}"), LineYofX, vec![a.into(), b.into()], vec![ox, oy])?;
    }
    let solution = adjust(&pr, opts)?;
    Ok(LineFit { intercept: solution.x[0], slope: solution.x[1], solution })
}

/// Result of [`fit_plane`].
#[derive(Debug, Clone)]
pub struct PlaneFit {
    /// Unit normal.
    pub normal: [f64; 3],
    /// Distance: ⟨normal, p⟩ = d for points p on the plane.
    pub d: f64,
    pub solution: Solution,
}

/// Plane through 3D points with errors in all three coordinates (σ per point, isotropic).
///
/// ```
/// use adjust::fits::fit_plane;
/// let pts = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.01], [0.0, 1.0, 0.99], [1.0, 1.0, 1.0], [0.5, 0.5, 1.0]];
/// let f = fit_plane(&pts, &[0.01; 5]).unwrap();
/// assert!(f.normal[2].abs() > 0.999 && (f.d.abs() - 1.0).abs() < 0.01);
/// ```
pub fn fit_plane(points: &[[f64; 3]], sigma: &[f64]) -> Result<PlaneFit, AdjustError> {
    fit_plane_with(points, sigma, &Options::default())
}

/// [`fit_plane`] with explicit options.
pub fn fit_plane_with(points: &[[f64; 3]], sigma: &[f64], opts: &Options) -> Result<PlaneFit, AdjustError> {
    let n = points.len();
    // Starting normal: Newell's method over the points in the given order (robust for
    // polygon-like sequences), falling back to the widest triangle.
    let c = centroid(points);
    let mut nrm = popa3d_model::vec3::newell_about(points, [0.0; 3]);
    let mut len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
    if len < 1e-12 && n >= 3 {
        let (a, b, cc) = (points[0], points[n / 2], points[n - 1]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [cc[0] - a[0], cc[1] - a[1], cc[2] - a[2]];
        nrm = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
    }
    if len < 1e-12 {
        nrm = [0.0, 0.0, 1.0];
        len = 1.0;
    }
    let nrm = [nrm[0] / len, nrm[1] / len, nrm[2] / len];
    let mut pr = Problem::new();
    let ux = pr.add_unknown("nx", nrm[0]);
    let uy = pr.add_unknown("ny", nrm[1]);
    let uz = pr.add_unknown("nz", nrm[2]);
    let ud = pr.add_unknown("d", nrm[0] * c[0] + nrm[1] * c[1] + nrm[2] * c[2]);
    let slots: Vec<Slot> = vec![ux.into(), uy.into(), uz.into(), ud.into()];
    for (i, p) in points.iter().enumerate() {
        let o: Vec<_> = (0..3)
            .map(|k| pr.add_observation(format!("p{i}.{}", ["x", "y", "z"][k]), p[k], sigma[i]))
            .collect::<Result<_, _>>()?;
        pr.add_condition(format!("point {i}"), PointOnPlane, slots.clone(), o)?;
    }
    pr.add_restriction("unit normal", UnitNorm3, vec![ux.into(), uy.into(), uz.into()])?;
    let solution = adjust(&pr, opts)?;
    let x = &solution.x;
    Ok(PlaneFit { normal: [x[0], x[1], x[2]], d: x[3], solution })
}

/// Result of [`fit_circle_2d`].
#[derive(Debug, Clone)]
pub struct CircleFit {
    pub center: [f64; 2],
    pub radius: f64,
    pub solution: Solution,
}

/// Circle through 2D points with isotropic errors σ per point.
///
/// ```
/// use adjust::fits::fit_circle_2d;
/// let pts: Vec<(f64, f64)> = (0..12).map(|k| {
///     let t = k as f64 * 0.5;
///     (3.0 + 2.0 * t.cos() + 0.001 * (k % 3) as f64, -1.0 + 2.0 * t.sin())
/// }).collect();
/// let f = fit_circle_2d(&pts, &[0.001; 12]).unwrap();
/// assert!((f.radius - 2.0).abs() < 0.002 && (f.center[0] - 3.0).abs() < 0.002);
/// ```
pub fn fit_circle_2d(points: &[(f64, f64)], sigma: &[f64]) -> Result<CircleFit, AdjustError> {
    // Starting values: Kåsa's algebraic fit x² + y² + D x + E y + F = 0 (linear least squares).
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for p in points {
        let row = nalgebra::Vector3::new(p.0, p.1, 1.0);
        ata += row * row.transpose();
        atb += row * -(p.0 * p.0 + p.1 * p.1);
    }
    let sol = ata.lu().solve(&atb).unwrap_or(nalgebra::Vector3::new(0.0, 0.0, -1.0));
    let (cx, cy) = (-sol[0] / 2.0, -sol[1] / 2.0);
    let r = (cx * cx + cy * cy - sol[2]).max(1e-12).sqrt();
    let mut pr = Problem::new();
    let ux = pr.add_unknown("cx", cx);
    let uy = pr.add_unknown("cy", cy);
    let ur = pr.add_unknown("r", r);
    for (i, p) in points.iter().enumerate() {
        let ox = pr.add_observation(format!("p{i}.x"), p.0, sigma[i])?;
        let oy = pr.add_observation(format!("p{i}.y"), p.1, sigma[i])?;
        pr.add_condition(format!("point {i}"), PointOnCircle, vec![ux.into(), uy.into(), ur.into()], vec![ox, oy])?;
    }
    let solution = adjust(&pr, &Options::default())?;
    let x = &solution.x;
    Ok(CircleFit { center: [x[0], x[1]], radius: x[2], solution })
}

fn centroid(points: &[[f64; 3]]) -> [f64; 3] {
    let n = points.len().max(1) as f64;
    let mut c = [0.0; 3];
    for p in points {
        for k in 0..3 {
            c[k] += p[k] / n;
        }
    }
    c
}
