//! Seams between the tiles of a raster plan (docs/decisions.md#raster-tiles-and-seams).
//!
//! Every tile is fitted on its own (`fit` with a [`crate::fit::Domain`]: square cells of one
//! size, the domain ending exactly on the tile's pixel edges), so two neighbours meet along a
//! shared border line but their surfaces differ there. [`stitch`] makes one tile's surface
//! equal, along each of its seams, to a *seam curve* that both sides compute bit for bit from
//! the same inputs (the two first-pass meshes and the corner values), and refits and refines the
//! tile's interior until every valid cell is within the tolerance again.
//!
//! Why a seam curve fixes the border exactly: with the border knots of the T-spline (the border
//! value repeated, multiplicity K), every blending function vanishes on the border and the
//! surface there is the limit from inside. For K = 3 only the border vertices' functions vanish
//! to first order (as 3·d/a_i, a_i the knot distance from vertex i to the first inward edge), so
//! the border curve is Σ (w_i/a_i) z_i B_i(u) / Σ (w_i/a_i) B_i(u), B_i the univariate cubic on the
//! border vertices' own knots. Giving every seam vertex the weight w_i = a_i/λ (λ one number per
//! tile) turns it into Σ z_i B_i / Σ B_i: a function of the seam vertices' positions and heights
//! only. For K = 1 the border curve is the polyline of the border vertices (weights 1). Square
//! cells keep a_i equal in both directions at a tile corner, so one weight serves both seams
//! through it. A seam vertex a tile adds later (refinement next to the seam) gets its height by
//! knot insertion (Boehm) into the seam curve, which leaves the curve unchanged. Cells along a
//! seam are refined to ¼ px (the seam strip, `STRIP`) so that the border vertices' influence
//! ends before the first data cell: with the border padding the rational blend cannot follow
//! the data next to a border whose vertices are held (docs/decisions.md#raster-tiles-and-seams).

use rayon::prelude::*;

use crate::eval::{basis, PbSpline};
use crate::fit::{Backend, ErrorStats, FitOptions, IterationStats, Samples, StopReason};
use crate::mesh::{Degree, Rect, TMesh};
use crate::TsplineError;

/// A tile's mesh and where it sits in the plan's frame: plan (s, t) = tile (s, t) + `offset`
/// (whole pixels: the shift is exact).
#[derive(Debug, Clone)]
pub struct Placed {
    pub mesh: TMesh,
    pub offset: [f64; 2],
}

impl Placed {
    /// The mesh shifted into the plan's frame.
    fn in_plan(&self) -> TMesh {
        shifted(&self.mesh, self.offset)
    }
    fn rect(&self) -> Rect {
        let b = self.mesh.bounds();
        Rect::new(
            b.s_min + self.offset[0],
            b.t_min + self.offset[1],
            b.s_max + self.offset[0],
            b.t_max + self.offset[1],
        )
    }
}

fn shifted(m: &TMesh, off: [f64; 2]) -> TMesh {
    let c = m.compacted();
    let points = c
        .points
        .iter()
        .map(|p| crate::mesh::ControlPoint { s: p.s + off[0], t: p.t + off[1], x: p.x + off[0], y: p.y + off[1], ..*p })
        .collect();
    let corners = c.cells.iter().map(|cell| cell.corners).collect();
    TMesh::from_cells(c.degree, points, corners).expect("a shifted valid mesh is valid")
}

/// A border line segment: `vertical` (s = c, u = t) or horizontal (t = c, u = s), u ∈ [u0, u1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    pub vertical: bool,
    pub c: f64,
    pub u0: f64,
    pub u1: f64,
}

impl Line {
    fn at(&self, u: f64) -> (f64, f64) {
        if self.vertical {
            (self.c, u)
        } else {
            (u, self.c)
        }
    }
    fn shift(&self, off: [f64; 2]) -> Line {
        let (dc, du) = if self.vertical { (off[0], off[1]) } else { (off[1], off[0]) };
        Line { vertical: self.vertical, c: self.c + dc, u0: self.u0 + du, u1: self.u1 + du }
    }
}

/// The shared border of two domain rectangles, if they meet along a segment of positive length.
fn shared_line(a: Rect, b: Rect) -> Option<Line> {
    let (t0, t1) = (a.t_min.max(b.t_min), a.t_max.min(b.t_max));
    let (s0, s1) = (a.s_min.max(b.s_min), a.s_max.min(b.s_max));
    if t1 > t0 && (a.s_max == b.s_min || a.s_min == b.s_max) {
        let c = if a.s_max == b.s_min { a.s_max } else { a.s_min };
        return Some(Line { vertical: true, c, u0: t0, u1: t1 });
    }
    if s1 > s0 && (a.t_max == b.t_min || a.t_min == b.t_max) {
        let c = if a.t_max == b.t_min { a.t_max } else { a.t_min };
        return Some(Line { vertical: false, c, u0: s0, u1: s1 });
    }
    None
}

/// A seam curve: Σ z_i B_i(u) / Σ B_i(u), B_i the degree-K B-spline on the local knots of vertex
/// i of `knots` (the T-spline's border knots: neighbours, ends repeated).
#[derive(Debug, Clone, PartialEq)]
pub struct SeamCurve {
    pub degree: Degree,
    /// Vertex positions along the seam, ascending; the first and last are the seam's ends.
    pub knots: Vec<f64>,
    pub z: Vec<f64>,
    /// Weights ω_i of the rational form Σ ω_i z_i B_i / Σ ω_i B_i: 1 from the fit; a knot
    /// inserted into an end interval of a cubic curve changes the end vertex's (the functions
    /// there are not a complete spline basis). [`stitch`] refines the end intervals below the
    /// minimum cell size first, so that corners keep ω = 1 (one weight serves both seams).
    pub w: Vec<f64>,
}

impl SeamCurve {
    /// The full knot sequence: ends repeated to multiplicity K (function i: entries i..i+K+2).
    fn sequence(&self) -> Vec<f64> {
        let h = self.degree.half();
        let (a, b) = (self.knots[0], *self.knots.last().expect("a seam has two ends"));
        let mut v = vec![a; h];
        v.extend_from_slice(&self.knots);
        v.extend(std::iter::repeat_n(b, h));
        v
    }

    /// (index, B_i(u)) of the non-zero basis functions at u.
    fn bases(&self, seq: &[f64], u: f64) -> Vec<(usize, f64)> {
        let k = self.degree.k();
        (0..self.knots.len())
            .filter_map(|i| {
                let b = basis(&seq[i..i + k + 2], k, u, false);
                (b != 0.0).then_some((i, b))
            })
            .collect()
    }

    /// The curve at u strictly inside the seam (NaN at the ends for K = 3: 0/0).
    pub fn eval(&self, u: f64) -> f64 {
        let seq = self.sequence();
        let (mut num, mut den) = (0.0, 0.0);
        for (i, b) in self.bases(&seq, u) {
            num += b * self.w[i] * self.z[i];
            den += b * self.w[i];
        }
        num / den
    }

    /// Inserts the vertex `tau` (strictly between two knots) without changing the curve
    /// (Boehm's knot insertion; the denominator's unit coefficients stay units).
    pub fn insert(&mut self, tau: f64) {
        let p = self.degree.k();
        let seq = self.sequence();
        let j = self.knots.partition_point(|&v| v < tau);
        if j == 0 || j >= self.knots.len() || self.knots[j] == tau {
            return;
        }
        // tau ∈ [seq[k], seq[k+1]) with k = (j − 1) + K/2-padding
        let k = (j - 1) + self.degree.half();
        let n = self.z.len();
        // numerator (ω z) and denominator (ω) coefficients; the functions an end interval lacks
        // (index −1 and n) have coefficient 0
        let num = |i: isize| if i < 0 || i as usize >= n { 0.0 } else { self.w[i as usize] * self.z[i as usize] };
        let den = |i: isize| if i < 0 || i as usize >= n { 0.0 } else { self.w[i as usize] };
        let (mut z, mut w) = (Vec::with_capacity(n + 1), Vec::with_capacity(n + 1));
        for i in 0..=n {
            let a = if i + p <= k {
                1.0
            } else if i > k {
                0.0
            } else {
                (tau - seq[i]) / (seq[i + p] - seq[i])
            };
            let ii = i as isize;
            let qn = a * num(ii) + (1.0 - a) * num(ii - 1);
            let qd = a * den(ii) + (1.0 - a) * den(ii - 1);
            z.push(qn / qd);
            w.push(qd);
        }
        self.knots.insert(j, tau);
        self.z = z;
        self.w = w;
    }

    /// Halves the end intervals until they are shorter than 2 (cells that small are never
    /// split), so no later insertion changes the end vertices' weights.
    fn freeze_ends(&mut self) {
        loop {
            let n = self.knots.len();
            let (a, b) = (self.knots[1] - self.knots[0], self.knots[n - 1] - self.knots[n - 2]);
            if a >= 2.0 {
                self.knots.insert(1, self.knots[0] + 0.5 * a);
            } else if b >= 2.0 {
                let n = self.knots.len();
                self.knots.insert(n - 1, self.knots[n - 1] - 0.5 * b);
            } else {
                return;
            }
        }
    }
}

/// Side of the cells along a seam (pixels): the border vertices' influence on the surface ends
/// two knots inwards (cubic), so with cells of ¼ px the layer they shape ends before the first
/// data cell centre (½ px from the seam) and the shared seam curve costs the fit nothing there.
const STRIP: f64 = 0.25;

/// No strip along a seam on a pixel-centre line (a plan on the whole fit's lattice,
/// docs/decisions.md#tiles-on-the-whole-fits-lattice): the seam's own row of cells lies on the
/// border, where the surface is the curve, and the curve is refined until it holds them; the
/// rows inside are the refit's. Measured on a 200² lidar window in 2×2 tiles, E = 0.25: ½-px
/// strip 9,006 stitched control points, 1-px strip 4,922, none 2,594 (first passes 1,533), all
/// within E.
const STRIP_ON_CENTRES: f64 = f64::INFINITY;

/// Whether a seam runs along pixel centres (integer plan coordinate) rather than pixel edges.
fn on_centres(line: Line) -> bool {
    line.c.fract() == 0.0
}

/// The side of the seam strip's cells along `line`.
fn strip_of(line: Line) -> f64 {
    if on_centres(line) {
        STRIP_ON_CENTRES
    } else {
        STRIP
    }
}

/// Samples per knot interval of the seam-curve fit.
const SEAM_SAMPLES: usize = 8;
/// Weight of a data cell lying on a pixel-centre seam in the seam-curve fit (against 1 for the
/// interpolated samples between them): the curve IS the surface at those cells.
const ON_SEAM_CELL_WEIGHT: f64 = 16.0;

/// The seam curve of two first-pass meshes `p` and `q` (plan frame) along `line`: knots the
/// union of both sides' border vertices, ends fixed to the corner values, the inner
/// coefficients the least-squares fit to the mean of the two surfaces along the line. Symmetric
/// in (p, q) bit for bit (the mean is a commutative sum), so both tiles' stitch jobs get the same.
#[allow(clippy::too_many_arguments)]
fn seam_curve(
    p: &PbSpline,
    pm: &TMesh,
    q: &PbSpline,
    qm: &TMesh,
    line: Line,
    z_ends: [f64; 2],
    source: &Source,
    max_error: f64,
) -> Result<SeamCurve, TsplineError> {
    let mut knots = border_vertices(pm, line);
    knots.extend(border_vertices(qm, line));
    knots.sort_by(f64::total_cmp);
    knots.dedup();
    if knots.first() != Some(&line.u0) || knots.last() != Some(&line.u1) {
        return Err(TsplineError::Fit(format!(
            "seam {line:?}: its ends are not vertices of both tiles (the tiles' domains do not meet at whole cells)"
        )));
    }
    // the seam strip: intervals halved down to STRIP (module doc); degree 1 has no boundary
    // layer (the border curve is the border vertices' polyline, which a held border keeps)
    let strip = if pm.degree == Degree::Cubic { strip_of(line) } else { f64::INFINITY };
    let mut fine = vec![knots[0]];
    for w in knots.windows(2) {
        let mut parts = 1usize;
        while (w[1] - w[0]) / parts as f64 > strip {
            parts *= 2;
        }
        for k in 1..=parts {
            fine.push(if k == parts { w[1] } else { w[0] + (w[1] - w[0]) * k as f64 / parts as f64 });
        }
    }
    let mut curve = SeamCurve { degree: pm.degree, knots: fine, z: Vec::new(), w: Vec::new() };
    if curve.degree == Degree::Cubic {
        curve.freeze_ends();
    }
    // on a pixel-centre seam the curve is the surface at the seam's own cells: refine it (halving
    // the knot intervals around a cell it misses) until it holds them within the tolerance, so
    // both tiles can reach it (docs/decisions.md#tiles-on-the-whole-fits-lattice)
    for _ in 0..CURVE_ROUNDS {
        fit_curve(&mut curve, p, q, line, z_ends, source)?;
        if !on_centres(line) {
            break;
        }
        let misses: Vec<usize> = curve
            .knots
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[1] - w[0] > 1.0)
            .filter(|(_, w)| {
                let (lo, hi) = (w[0].floor() as i64 + 1, w[1].ceil() as i64 - 1);
                (lo..=hi).filter(|&r| r as f64 > line.u0 && (r as f64) < line.u1).any(|r| {
                    seam_value(source, line, r as f64)
                        .is_some_and(|v| (curve.eval(r as f64) - v).abs() > CURVE_SHARE * max_error)
                })
            })
            .map(|(i, _)| i)
            .collect();
        if misses.is_empty() {
            break;
        }
        for &i in misses.iter().rev() {
            let mid = 0.5 * (curve.knots[i] + curve.knots[i + 1]);
            curve.knots.insert(i + 1, mid);
        }
    }
    Ok(curve)
}

/// Rounds of seam-curve refinement (each halves the intervals around the cells it misses).
const CURVE_ROUNDS: usize = 12;
/// The share of the tolerance the seam curve may use at a cell on the seam.
const CURVE_SHARE: f64 = 0.8;

/// The seam curve's coefficients: ends fixed to the corner values, the inner ones the
/// least-squares fit to the data on the seam where there is some, else the mean of the two
/// surfaces (`p`, `q`) along the line.
fn fit_curve(
    curve: &mut SeamCurve,
    p: &PbSpline,
    q: &PbSpline,
    line: Line,
    z_ends: [f64; 2],
    source: &Source,
) -> Result<(), TsplineError> {
    let n = curve.knots.len();
    curve.z = vec![0.0; n];
    curve.w = vec![1.0; n];
    curve.z[0] = z_ends[0];
    curve.z[n - 1] = z_ends[1];
    if n == 2 {
        return Ok(());
    }
    let seq = curve.sequence();
    // banded normal equations of the inner coefficients 1..n−2 (half bandwidth K)
    let bw = curve.degree.k();
    let m = n - 2;
    let mut band = vec![vec![0.0; bw + 1]; m]; // band[i][d] = A[i][i−d]
    let mut rhs = vec![0.0; m];
    let mut at: Vec<(f64, f64)> = Vec::with_capacity(n * (SEAM_SAMPLES + 1));
    for w in curve.knots.windows(2) {
        // a cell centre on a pixel-centre seam (not an end: those are fixed)
        if on_centres(line) && w[0].fract() == 0.0 && w[0] != curve.knots[0] && seam_value(source, line, w[0]).is_some()
        {
            at.push((w[0], ON_SEAM_CELL_WEIGHT));
        }
        at.extend((0..SEAM_SAMPLES).map(|k| (w[0] + (w[1] - w[0]) * (k as f64 + 0.5) / SEAM_SAMPLES as f64, 1.0)));
    }
    {
        for (u, weight) in at {
            let (x, y) = line.at(u);
            let g = match seam_value(source, line, u) {
                Some(v) => v,
                None => 0.5 * (p.point(x, y)[2] + q.point(x, y)[2]),
            };
            let bs = curve.bases(&seq, u);
            let den: f64 = bs.iter().map(|b| b.1).sum();
            let mut d = g;
            let row: Vec<(usize, f64)> = bs
                .into_iter()
                .filter_map(|(i, b)| {
                    let v = b / den;
                    if i == 0 || i == n - 1 {
                        d -= v * curve.z[i];
                        None
                    } else {
                        Some((i - 1, v))
                    }
                })
                .collect();
            for &(i, vi) in &row {
                rhs[i] += weight * vi * d;
                for &(j, vj) in &row {
                    if j <= i && i - j <= bw {
                        band[i][i - j] += weight * vi * vj;
                    }
                }
            }
        }
    }
    let x = band_cholesky_solve(band, rhs)
        .ok_or_else(|| TsplineError::Fit(format!("seam {line:?}: the seam-curve fit is singular")))?;
    curve.z[1..n - 1].copy_from_slice(&x);
    Ok(())
}

/// The source raster in the plan's frame: the value of the cell centred at plan (s, t) (whole
/// numbers), NaN where there is none (no data, or outside what the job read).
pub type Source<'a> = dyn Fn(i64, i64) -> f64 + Sync + 'a;

/// The data's value on the seam at u: across the seam, the 4-point cubic interpolation of the
/// cells at −1.5, −0.5, +0.5, +1.5 px (the mean of the two nearest when the outer ones are
/// missing), linear along the seam between the two nearest rows; None where the two cells next to
/// the seam are not both valid. Only source cells, in a fixed order: the same bits in both jobs.
/// On a pixel-centre seam: the cell on the seam.
fn seam_value(source: &Source, line: Line, u: f64) -> Option<f64> {
    if on_centres(line) {
        return along_centres(source, line, u, |at| Some(at(0)).filter(|v| v.is_finite()));
    }
    along_seam(source, line, u, |[a, b, c, d]| {
        if a.is_finite() && d.is_finite() {
            (-a + 9.0 * b + 9.0 * c - d) / 16.0
        } else {
            0.5 * (b + c)
        }
    })
}

/// `across` of the cells at −2 … +2 px from a pixel-centre seam (`at(k)`, NaN where missing),
/// linear along the seam between the two nearest rows of cell centres on it.
fn along_centres(
    source: &Source,
    line: Line,
    u: f64,
    across: impl Fn(&dyn Fn(i64) -> f64) -> Option<f64>,
) -> Option<f64> {
    let c = line.c as i64;
    let row = |r: i64| -> Option<f64> {
        let at = |k: i64| if line.vertical { source(c + k, r) } else { source(r, c + k) };
        across(&at)
    };
    let (lo, hi) = (line.u0.ceil() as i64, line.u1.floor() as i64);
    let uc = u.clamp(lo as f64, hi as f64);
    let r0 = (uc.floor() as i64).min(hi);
    let f = uc - r0 as f64;
    let v0 = row(r0)?;
    if f == 0.0 || r0 == hi {
        return Some(v0);
    }
    let v1 = row(r0 + 1)?;
    Some((1.0 - f) * v0 + f * v1)
}

/// `across` of the four cells at −1.5, −0.5, +0.5, +1.5 px from the seam (the inner two valid,
/// the outer ones NaN where missing), interpolated linearly along the seam between the two
/// nearest rows of cell centres inside it; None where an inner cell is missing.
fn along_seam(source: &Source, line: Line, u: f64, across: impl Fn([f64; 4]) -> f64) -> Option<f64> {
    let c0 = (line.c - 0.5).round() as i64; // the cell centre just below the seam
    let row = |r: i64| -> Option<f64> {
        let at = |k: i64| if line.vertical { source(c0 + k, r) } else { source(r, c0 + k) };
        let cells = [at(-1), at(0), at(1), at(2)];
        (cells[1].is_finite() && cells[2].is_finite()).then(|| across(cells))
    };
    let (lo, hi) = ((line.u0 + 0.5).round() as i64, (line.u1 - 0.5).round() as i64);
    let uc = u.clamp(lo as f64, hi as f64);
    let r0 = (uc.floor() as i64).min(hi);
    let f = uc - r0 as f64;
    let v0 = row(r0)?;
    if f == 0.0 || r0 == hi {
        return Some(v0);
    }
    let v1 = row(r0 + 1)?;
    Some((1.0 - f) * v0 + f * v1)
}

/// Solves a symmetric positive definite banded system (band[i][d] = A[i][i−d]) by Cholesky.
fn band_cholesky_solve(mut l: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = l.len();
    let bw = l.first().map_or(0, |r| r.len() - 1);
    let scale = l.iter().map(|r| r[0]).fold(0.0f64, f64::max).max(f64::MIN_POSITIVE);
    for r in &mut l {
        r[0] += 1e-12 * scale;
    }
    for i in 0..n {
        for d in (0..=bw.min(i)).rev() {
            let j = i - d;
            let mut v = l[i][d];
            for k in j.saturating_sub(bw).max(i.saturating_sub(bw))..j {
                v -= l[i][i - k] * l[j][j - k];
            }
            if d == 0 {
                if v <= 0.0 {
                    return None;
                }
                l[i][0] = v.sqrt();
            } else {
                l[i][d] = v / l[j][0];
            }
        }
    }
    for i in 0..n {
        let mut v = b[i];
        for k in i.saturating_sub(bw)..i {
            v -= l[i][i - k] * b[k];
        }
        b[i] = v / l[i][0];
    }
    for i in (0..n).rev() {
        let mut v = b[i];
        for k in i + 1..(i + bw + 1).min(n) {
            v -= l[k][k - i] * b[k];
        }
        b[i] = v / l[i][0];
    }
    Some(b)
}

/// Positions along `line` of the mesh's vertices on it (corners of leaves touching the line).
fn border_vertices(m: &TMesh, line: Line) -> Vec<f64> {
    let r = if line.vertical {
        Rect::new(line.c, line.u0, line.c, line.u1)
    } else {
        Rect::new(line.u0, line.c, line.u1, line.c)
    };
    let mut v = Vec::new();
    for c in m.leaves_in(r) {
        for &p in &m.cells[c as usize].corners {
            let pt = m.points[p as usize];
            let (on, u) = if line.vertical { (pt.s == line.c, pt.t) } else { (pt.t == line.c, pt.s) };
            if on && u >= line.u0 && u <= line.u1 {
                v.push(u);
            }
        }
    }
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// The value of the plan's surfaces at a tile corner: the mean over the tiles whose domain
/// holds it, summed in ascending order (the same bits in every job that computes it).
fn corner_value(pbs: &[(PbSpline, Rect)], s: f64, t: f64) -> f64 {
    let mut v: Vec<f64> =
        pbs.iter().filter(|(_, r)| r.contains_closed(s, t)).map(|(pb, _)| pb.point(s, t)[2]).collect();
    v.sort_by(f64::total_cmp);
    v.iter().sum::<f64>() / v.len() as f64
}

/// One seam of the stitched tile, as reported.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SeamInfo {
    /// Which side of the tile (west, east, south, north).
    pub side: &'static str,
    /// The neighbour's index in the `neighbours` given to [`stitch`].
    pub neighbour: usize,
    /// Seam vertices of the shared curve (both tiles' border vertices).
    pub curve_vertices: usize,
    /// max |surface − seam curve| along the seam after stitching (raster units; rounding only).
    pub max_curve_deviation: f64,
}

/// What [`stitch`] returns.
pub struct Stitched {
    /// The tile's stitched mesh, in the tile's own frame.
    pub mesh: TMesh,
    /// Whether the first inward column was held to the data's slope (approximate C1); false
    /// where that missed the tolerance and the tile was refitted with the seams alone held.
    pub c1_held: bool,
    pub stop: StopReason,
    pub iterations: Vec<IterationStats>,
    pub seams: Vec<SeamInfo>,
}

/// A seam of the tile being stitched, in its own frame.
#[derive(Clone)]
struct OwnSeam {
    line: Line,
    curve: SeamCurve,
    side: &'static str,
    neighbour: usize,
    /// The data's slope across the seam at each curve knot (d z / d plan s or t), None where the
    /// cells are missing: what the first inward column is held to (approximate C1).
    slope: Vec<Option<f64>>,
}

/// The data's slope across the seam at u (per pixel, towards increasing s or t): the 4-point
/// difference of the cells at −1.5 … +1.5 px (the 2-point one without the outer cells), linear
/// along the seam as [`seam_value`].
fn seam_slope(source: &Source, line: Line, u: f64) -> Option<f64> {
    if on_centres(line) {
        // centred differences across the seam's cell (one-sided where a side has no data)
        return along_centres(source, line, u, |at| {
            let (a, b, c, d, e) = (at(-2), at(-1), at(0), at(1), at(2));
            match (b.is_finite(), c.is_finite(), d.is_finite()) {
                (true, _, true) if a.is_finite() && e.is_finite() => Some((8.0 * (d - b) - (e - a)) / 12.0),
                (true, _, true) => Some(0.5 * (d - b)),
                (false, true, true) => Some(d - c),
                (true, true, false) => Some(c - b),
                _ => None,
            }
        });
    }
    along_seam(
        source,
        line,
        u,
        |[a, b, c, d]| if a.is_finite() && d.is_finite() { (27.0 * (c - b) - (d - a)) / 24.0 } else { c - b },
    )
}

/// Stitches one tile: `own` and its plan neighbours (first-pass meshes, any of the 8 around it),
/// `samples` the tile's raster window in its own frame (what `fit` fitted), `source` the raster
/// around it in the plan frame (at least 2 px beyond every seam). The surface along
/// every seam becomes the seam curve both sides share (exact C0 in exact arithmetic), the other
/// control points are refitted with the seam vertices held, and cells over the tolerance are
/// refined (seam vertices added by refinement are inserted into the curve) until every valid
/// cell of the tile is within the tolerance of `opts` again, as checked on the mesh as written.
pub fn stitch(
    own: &Placed,
    neighbours: &[Placed],
    samples: &Samples,
    source: &Source,
    opts: &FitOptions,
    backend: &Backend,
    progress: &mut dyn FnMut(&IterationStats),
) -> Result<Stitched, TsplineError> {
    let degree = own.mesh.degree;
    if neighbours.iter().any(|n| n.mesh.degree != degree) {
        return Err(TsplineError::InvalidMesh("the tiles of a plan must share the degree".into()));
    }
    // first-pass surfaces in the plan frame
    let own_plan = own.in_plan();
    let ra = own.rect();
    let mut all: Vec<(TMesh, Rect)> = vec![(own_plan, ra)];
    for n in neighbours {
        all.push((n.in_plan(), n.rect()));
    }
    let pbs: Vec<(PbSpline, Rect)> = all.par_iter().map(|(m, r)| (PbSpline::build(m), *r)).collect();
    let mut seams = Vec::new();
    for (k, n) in neighbours.iter().enumerate() {
        let Some(line) = shared_line(ra, n.rect()) else { continue };
        let ends = [line.at(line.u0), line.at(line.u1)].map(|(s, t)| corner_value(&pbs, s, t));
        // the pair in a fixed order (the one lower in the plan first)
        let (a, b) = if (ra.s_min, ra.t_min) < (n.rect().s_min, n.rect().t_min) { (0, k + 1) } else { (k + 1, 0) };
        let curve = seam_curve(&pbs[a].0, &all[a].0, &pbs[b].0, &all[b].0, line, ends, source, opts.max_error)?;
        let side = match (line.vertical, line.c == ra.s_min, line.c == ra.t_min) {
            (true, true, _) => "west",
            (true, false, _) => "east",
            (false, _, true) => "south",
            (false, _, false) => "north",
        };
        // into the tile's own frame (exact shifts)
        let back = [-own.offset[0], -own.offset[1]];
        let local = line.shift(back);
        let du = if line.vertical { back[1] } else { back[0] };
        let slope = if degree == Degree::Cubic {
            curve.knots.iter().map(|&u| seam_slope(source, line, u)).collect()
        } else {
            Vec::new()
        };
        let mut c = curve;
        c.knots.iter_mut().for_each(|u| *u += du);
        seams.push(OwnSeam { line: local, curve: c, side, neighbour: k, slope });
    }
    drop(pbs);
    drop(all);

    let mut mesh = own.mesh.compacted();
    // λ = 1 pixel: seam weights a_i ≥ 1, so the border row dominates the blend next to the seam
    let lambda = 1.0;
    // the seam vertices of the shared curves, in this tile
    let mut pb = PbSpline::build(&mesh);
    loop {
        let mut split = false;
        for seam in &seams {
            for &u in &seam.curve.knots {
                let (s, t) = seam.line.at(u);
                if mesh.point_id_at(s, t).is_some() {
                    continue;
                }
                let probe = Rect::new(s, t, s, t);
                let cell = mesh.leaves_in(probe).into_iter().find(|&c| {
                    let r = mesh.cells[c as usize].rect;
                    if seam.line.vertical {
                        r.t_min < t && t < r.t_max
                    } else {
                        r.s_min < s && s < r.s_max
                    }
                });
                if let Some(c) = cell {
                    let mut geom = |s: f64, t: f64| (s, t, finite_or_zero(pb.point(s, t)[2]));
                    mesh.split(c, &mut geom);
                    split = true;
                }
            }
        }
        if !split {
            break;
        }
        let mut geom = |s: f64, t: f64| (s, t, finite_or_zero(pb.point(s, t)[2]));
        // balance down to the strip's cells (the loop's own repair stops at one pixel)
        let finest = seams.iter().map(|s| strip_of(s.line)).fold(2.0, f64::min);
        mesh.repair(finest / 2.0, &mut geom);
        pb = PbSpline::build(&mesh);
    }

    // C0 (the seams alone held); then, for cubic tiles, with the inward columns held to the
    // data's slope too (approximately C1), kept when it reaches the tolerance at no more than
    // C1_BUDGET times the control points (docs/decisions.md#tiles-on-the-whole-fits-lattice)
    let c0 = refit_loop(mesh.clone(), seams.clone(), false, lambda, samples, opts, backend, progress)?;
    if degree == Degree::Cubic && c0.stop == StopReason::ToleranceReached {
        let c1 = refit_loop(mesh, seams, true, lambda, samples, opts, backend, progress)?;
        let points = |r: &Stitched| r.iterations.last().map_or(usize::MAX, |i| i.control_points) as f64;
        if c1.stop == StopReason::ToleranceReached && points(&c1) <= C1_BUDGET * points(&c0) {
            return Ok(c1);
        }
    }
    Ok(c0)
}

/// How many times the C0 stitch's control points the approximately-C1 stitch may cost. Measured
/// on a 200² lidar window in 4×4 tiles at E = 0.5: C1 held 8,204 stitched control points, C0
/// alone 2,847 (first passes 749).
const C1_BUDGET: f64 = 1.25;

/// The refit / check / refine loop of [`stitch`] with the seam vertices (and with `hold_c1` the
/// first inward column) held.
#[allow(clippy::too_many_arguments)]
fn refit_loop(
    mut mesh: TMesh,
    mut seams: Vec<OwnSeam>,
    hold_c1: bool,
    lambda: f64,
    samples: &Samples,
    opts: &FitOptions,
    backend: &Backend,
    progress: &mut dyn FnMut(&IterationStats),
) -> Result<Stitched, TsplineError> {
    if opts.split != crate::mesh::SplitRule::Quad {
        // docs/decisions.md#anisotropic-splits-issue-19: the seams need square cells
        return Err(TsplineError::Fit(
            "anisotropic splits are not available for tiles of a plan (their seams need square cells)".into(),
        ));
    }
    let (tol, tol_final) = crate::fit::tolerances(samples, None, opts)?;
    let mut iterations = Vec::new();
    let mut errs = vec![f64::NAN; samples.z.len()];
    let mut refined = 0;
    for it in 0.. {
        let t0 = std::time::Instant::now();
        let mut on_seam = sync_seams(&mut mesh, &mut seams, lambda);
        if hold_c1 {
            hold_inward_columns(&mut mesh, &seams, &mut on_seam);
        }
        let mut pb = PbSpline::build(&mesh);
        let free: Vec<bool> = pb.point_ids.iter().map(|&id| !on_seam[id as usize]).collect();
        let t_build = t0.elapsed().as_secs_f64();
        let z = crate::fit::fit_lsq_local(
            crate::fit::LsqProblem { free: Some(&free), ..crate::fit::LsqProblem::global(&mesh, samples) },
            &pb,
        )?;
        if z.iter().any(|v| !v.is_finite()) {
            return Err(TsplineError::Fit(format!(
                "stitch iteration {it}: the least-squares solution has non-finite control points"
            )));
        }
        crate::fit::set_z(&mut mesh, &mut pb, &z);
        let t_opt = t0.elapsed().as_secs_f64();
        let (mut err, mut over) = crate::fit::check(&mesh, &pb, samples, None, None, backend, &mut errs, &tol)?;
        let mut done = false;
        if err.over_tolerance == 0 {
            let (fin, o) = crate::fit::check_written(&mesh, &pb, samples, None, &mut errs, &tol_final)?;
            done = fin.over_tolerance == 0;
            (err, over) = (fin, o);
        }
        let st = stats(it, &pb, &mesh, refined, &err, t0, t_build, t_opt);
        progress(&st);
        iterations.push(st);
        let stop = if done {
            Some(StopReason::ToleranceReached)
        } else if it >= opts.max_iterations {
            Some(StopReason::MaxIterations)
        } else {
            match crate::fit::refine(&mesh, &pb, samples, opts, over, &err)? {
                crate::fit::Refined::Stop(s) => Some(s),
                crate::fit::Refined::Next(next, n) => {
                    refined = n;
                    mesh = next.compacted();
                    None
                }
            }
        };
        if let Some(stop) = stop {
            let infos = seams
                .iter()
                .map(|s| SeamInfo {
                    side: s.side,
                    neighbour: s.neighbour,
                    curve_vertices: s.curve.knots.len(),
                    max_curve_deviation: curve_deviation(&pb, s),
                })
                .collect();
            return Ok(Stitched { mesh, stop, iterations, seams: infos, c1_held: hold_c1 });
        }
    }
    unreachable!("the loop returns")
}

/// Holds the first inward column of every cubic seam at z₁ = z_b + 3·g/c₁ (inward sign), g the
/// data's slope across the seam and c₁ the u² coefficient of the column's blending function at
/// the border: the cross-seam derivative of the border limit, (1/3)·Σ c₁ B (z₁ − z_b), is then
/// g on both sides, to first order. Vertices on another seam stay as that seam holds them.
fn hold_inward_columns(mesh: &mut TMesh, seams: &[OwnSeam], held: &mut [bool]) {
    let pb = PbSpline::build(mesh);
    let mut index = vec![u32::MAX; mesh.points.len()];
    for (i, &id) in pb.point_ids.iter().enumerate() {
        index[id as usize] = i as u32;
    }
    let on_seam: Vec<bool> = held.to_vec();
    let b = mesh.bounds();
    for seam in seams {
        let l = seam.line;
        // inward: towards the tile's interior
        let dir = if l.vertical {
            if l.c == b.s_min {
                1.0
            } else {
                -1.0
            }
        } else if l.c == b.t_min {
            1.0
        } else {
            -1.0
        };
        for (k, &u) in seam.curve.knots.iter().enumerate() {
            let Some(g) = seam.slope.get(k).copied().flatten() else { continue };
            let (s, t) = l.at(u);
            let Some(bid) = mesh.point_id_at(s, t) else { continue };
            let kb = &pb.knots[index[bid as usize] as usize];
            let kn = if l.vertical { &kb[0..5] } else { &kb[5..10] };
            let a = if kn[0] == l.c { kn[3] - l.c } else { l.c - kn[1] };
            let (s1, t1) = if l.vertical { (s + dir * a, t) } else { (s, t + dir * a) };
            let Some(id) = mesh.point_id_at(s1, t1) else { continue };
            if on_seam[id as usize] || index[id as usize] == u32::MAX {
                continue;
            }
            let k1 = &pb.knots[index[id as usize] as usize];
            let k1 = if l.vertical { &k1[0..5] } else { &k1[5..10] };
            // c₁ = lim B(c − dir·ε)/ε² (ε small against a: 10⁻³ relative)
            let eps = 1e-3 * a;
            let c1 = basis(k1, 3, l.c + dir * eps, dir < 0.0) / (eps * eps);
            if !(c1 > 0.0 && c1.is_finite()) {
                continue;
            }
            // the slope inwards: g is per +s / +t
            mesh.points[id as usize].z = seam.curve.z[k] + 3.0 * dir * g / c1;
            held[id as usize] = true;
        }
    }
}

fn finite_or_zero(z: f64) -> f64 {
    if z.is_finite() {
        z
    } else {
        0.0
    }
}

#[allow(clippy::too_many_arguments)]
fn stats(
    it: usize,
    pb: &PbSpline,
    mesh: &TMesh,
    refined: usize,
    err: &ErrorStats,
    t0: std::time::Instant,
    t_build: f64,
    t_opt: f64,
) -> IterationStats {
    let t = t0.elapsed().as_secs_f64();
    IterationStats {
        iteration: it,
        control_points: pb.point_ids.len(),
        cells: mesh.leaf_count(),
        refined_cells: refined,
        merged_cells: 0,
        error: err.clone(),
        seconds: t,
        seconds_build: t_build,
        seconds_optimise: t_opt - t_build,
        seconds_check: t - t_opt,
    }
}

/// Brings every seam curve to the tile's current seam vertices (knot insertion), writes the
/// curve's coefficients into them and, for K = 3, their weights a_i/λ (module doc). Returns
/// which mesh points are seam vertices (held by the refit).
fn sync_seams(mesh: &mut TMesh, seams: &mut [OwnSeam], lambda: f64) -> Vec<bool> {
    let mut on = vec![false; mesh.points.len()];
    for seam in seams.iter_mut() {
        let verts = border_vertices(mesh, seam.line);
        for &u in &verts {
            if seam.curve.knots.binary_search_by(|k| k.total_cmp(&u)).is_err() {
                seam.curve.insert(u);
            }
        }
        for (k, u) in seam.curve.knots.iter().enumerate() {
            let (s, t) = seam.line.at(*u);
            let id = mesh.point_id_at(s, t).expect("every curve knot is a seam vertex") as usize;
            mesh.points[id].z = seam.curve.z[k];
            on[id] = true;
        }
    }
    let omega = |seams: &[OwnSeam], line: Line, u: f64| -> f64 {
        seams
            .iter()
            .find(|s| s.line == line)
            .and_then(|s| s.curve.knots.binary_search_by(|k| k.total_cmp(&u)).ok().map(|k| s.curve.w[k]))
            .unwrap_or(1.0)
    };
    if mesh.degree == Degree::Cubic {
        let pb = PbSpline::build(mesh);
        for (i, &id) in pb.point_ids.iter().enumerate() {
            if !on[id as usize] {
                continue;
            }
            let kn = &pb.knots[i];
            let p = mesh.points[id as usize];
            // the distance to the first inward knot across the seam the vertex is on
            let mut w = f64::NAN;
            for seam in seams.iter() {
                let l = seam.line;
                let (c, u) = if l.vertical { (p.s, p.t) } else { (p.t, p.s) };
                if c != l.c || u < l.u0 || u > l.u1 {
                    continue;
                }
                let k = if l.vertical { &kn[0..5] } else { &kn[5..10] };
                let a = if k[0] == c { k[3] - c } else { c - k[1] };
                w = omega(seams, l, u) * a / lambda;
            }
            mesh.points[id as usize].w = w;
        }
    }
    on
}

/// max |surface − curve| along a seam (at the curve's sample positions), the tile's own frame.
fn curve_deviation(pb: &PbSpline, seam: &OwnSeam) -> f64 {
    let mut m = 0.0f64;
    for w in seam.curve.knots.windows(2) {
        for k in 0..SEAM_SAMPLES {
            let u = w[0] + (w[1] - w[0]) * (k as f64 + 0.5) / SEAM_SAMPLES as f64;
            let (s, t) = seam.line.at(u);
            m = m.max((pb.point(s, t)[2] - seam.curve.eval(u)).abs());
        }
    }
    m
}

/// Continuity of two tiles' surfaces along their shared border.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Continuity {
    /// Positions checked along the seam.
    pub samples: usize,
    /// max |z_a − z_b| on the seam (raster units).
    pub max_gap: f64,
    /// max_gap / max |z| on the seam.
    pub max_gap_relative: f64,
    /// max angle between the two surfaces' normals on the seam, degrees (C1 defect).
    pub max_normal_angle_deg: f64,
    /// Its median over the positions checked (the max is often one corner or one noisy cell).
    pub median_normal_angle_deg: f64,
}

/// [`Continuity`] of `a` and `b` along their shared border (None: they do not share one);
/// `cell` the world size of a parameter unit in s and t (normals in world units).
pub fn continuity(a: &Placed, b: &Placed, cell: [f64; 2]) -> Option<Continuity> {
    continuity_in(a, b, cell, &|_, _| true)
}

/// [`continuity`] at the seam positions (plan frame) where `region` holds: what a user sees is
/// the surface over the data, so a seam crossing no-data is measured where both sides have data
/// (docs/decisions.md#seams-gate-on-the-data). None also when no position is in the region.
pub fn continuity_in(a: &Placed, b: &Placed, cell: [f64; 2], region: &dyn Fn(f64, f64) -> bool) -> Option<Continuity> {
    let line = shared_line(a.rect(), b.rect())?;
    let (ma, mb) = (a.in_plan(), b.in_plan());
    let (pa, pb) = (PbSpline::build(&ma), PbSpline::build(&mb));
    let mut us = border_vertices(&ma, line);
    us.extend(border_vertices(&mb, line));
    us.sort_by(f64::total_cmp);
    us.dedup();
    let mut pos = Vec::new();
    for w in us.windows(2) {
        for k in 0..8 {
            pos.push(w[0] + (w[1] - w[0]) * k as f64 / 8.0);
        }
    }
    pos.push(line.u1);
    let ra = a.rect();
    // into a: the direction from the seam into tile a, across the seam
    let into_a = if line.vertical {
        if line.c == ra.s_max {
            -1.0
        } else {
            1.0
        }
    } else if line.c == ra.t_max {
        -1.0
    } else {
        1.0
    };
    let h = 1e-3;
    let (mut gap, mut zmax, mut ang) = (0.0f64, 0.0f64, 0.0f64);
    let mut angles = Vec::with_capacity(pos.len());
    let normal = |pb: &PbSpline, u: f64, dir: f64| -> [f64; 3] {
        let (s, t) = line.at(u);
        let z0 = pb.point(s, t)[2];
        let (s1, t1) = if line.vertical { (s + dir * h, t) } else { (s, t + dir * h) };
        let across = (pb.point(s1, t1)[2] - z0) / (dir * h);
        let (u0, u1) = ((u - h).max(line.u0), (u + h).min(line.u1));
        let (sa, ta) = line.at(u0);
        let (sb, tb) = line.at(u1);
        let along = (pb.point(sb, tb)[2] - pb.point(sa, ta)[2]) / (u1 - u0);
        let (zs, zt) = if line.vertical { (across, along) } else { (along, across) };
        let (zx, zy) = (zs / cell[0], zt / cell[1]);
        let n = (zx * zx + zy * zy + 1.0).sqrt();
        [-zx / n, -zy / n, 1.0 / n]
    };
    pos.retain(|&u| {
        let (s, t) = line.at(u);
        region(s, t)
    });
    if pos.is_empty() {
        return None;
    }
    for &u in &pos {
        let (s, t) = line.at(u);
        let (za, zb) = (pa.point(s, t)[2], pb.point(s, t)[2]);
        gap = gap.max((za - zb).abs());
        zmax = zmax.max(za.abs()).max(zb.abs());
        let (na, nb) = (normal(&pa, u, into_a), normal(&pb, u, -into_a));
        let dot = (na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]).clamp(-1.0, 1.0);
        let a = dot.acos().to_degrees();
        ang = ang.max(a);
        angles.push(a);
    }
    angles.sort_by(f64::total_cmp);
    let median = angles[angles.len() / 2];
    Some(Continuity {
        samples: pos.len(),
        max_gap: gap,
        max_gap_relative: gap / zmax.max(f64::MIN_POSITIVE),
        max_normal_angle_deg: ang,
        median_normal_angle_deg: median,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{Domain, FitOptions};

    #[test]
    fn knot_insertion_keeps_the_curve() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut c = SeamCurve {
                degree,
                knots: vec![0.0, 1.0, 3.0, 4.0, 8.0],
                z: vec![1.0, -2.0, 5.0, 0.5, 3.0],
                w: vec![1.0; 5],
            };
            let before: Vec<f64> = (1..80).map(|k| c.eval(k as f64 * 0.1)).collect();
            for tau in [0.5, 2.0, 6.0, 3.5, 7.75, 0.25] {
                c.insert(tau);
            }
            let after: Vec<f64> = (1..80).map(|k| c.eval(k as f64 * 0.1)).collect();
            for (a, b) in before.iter().zip(&after) {
                assert!((a - b).abs() < 1e-12, "{degree:?}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn band_solver_matches_dense() {
        // tridiagonal-ish SPD with bandwidth 2
        let n = 6;
        let a = |i: usize, j: usize| -> f64 {
            let d = i.abs_diff(j);
            match d {
                0 => 4.0 + i as f64,
                1 => -1.0,
                2 => 0.5,
                _ => 0.0,
            }
        };
        let x: Vec<f64> = (0..n).map(|i| i as f64 - 2.0).collect();
        let b: Vec<f64> = (0..n).map(|i| (0..n).map(|j| a(i, j) * x[j]).sum()).collect();
        let band: Vec<Vec<f64>> =
            (0..n).map(|i| (0..=2).map(|d| if d <= i { a(i, i - d) } else { 0.0 }).collect()).collect();
        let y = band_cholesky_solve(band, b).unwrap();
        for (p, q) in x.iter().zip(&y) {
            assert!((p - q).abs() < 1e-9, "{p} vs {q}");
        }
    }

    /// Two tiles of one synthetic surface, fitted separately, then each stitched with the
    /// other: along the seam the two surfaces agree to rounding and every cell keeps the tolerance.
    #[test]
    fn two_tiles_meet_exactly_after_stitching() {
        let f = |x: f64, y: f64| 20.0 + (x * 0.17).sin() * 6.0 + (y * 0.11).cos() * 4.0 + 0.01 * x * y;
        let (w, h) = (32usize, 32usize);
        let e = 0.05;
        for degree in [Degree::Cubic, Degree::Linear] {
            let mut placed = Vec::new();
            let mut samples = Vec::new();
            for tile in 0..2usize {
                let z: Vec<f64> = (0..w * h).map(|q| f((q % w + tile * w) as f64, (q / w) as f64)).collect();
                let s = Samples { width: w, height: h, z: z.into() };
                let mut o = FitOptions::new(degree, e);
                o.domain = Some(Domain::anchored(w, h, 8.0, false));
                let r = crate::fit::fit(&s, &o, &Backend::Cpu, &mut |_| {}).unwrap();
                assert_eq!(r.stop, StopReason::ToleranceReached);
                placed.push(Placed { mesh: r.mesh.compacted(), offset: [(tile * w) as f64, 0.0] });
                samples.push(s);
            }
            let source = |s: i64, t: i64| {
                if s >= 0 && t >= 0 && (s as usize) < 2 * w && (t as usize) < h {
                    f(s as f64, t as f64)
                } else {
                    f64::NAN
                }
            };
            let mut out = Vec::new();
            for tile in 0..2 {
                let mut o = FitOptions::new(degree, e);
                o.domain = None;
                let other = placed[1 - tile].clone();
                let r =
                    stitch(&placed[tile], &[other], &samples[tile], &source, &o, &Backend::Cpu, &mut |_| {}).unwrap();
                assert!(r.seams[0].max_curve_deviation < 1e-6, "{degree:?}: {:?}", r.seams);
                assert_eq!(r.stop, StopReason::ToleranceReached, "{degree:?} tile {tile}");
                assert_eq!(r.seams.len(), 1);
                out.push(Placed { mesh: r.mesh, offset: placed[tile].offset });
            }
            let c = continuity(&out[0], &out[1], [1.0, 1.0]).unwrap();
            assert!(c.max_gap_relative <= 1e-9, "{degree:?}: {c:?}");
            if degree == Degree::Cubic {
                // the inward columns held to the data's slope on both sides: close to C1
                assert!(c.max_normal_angle_deg < 1.0, "{c:?}");
            }
            // and it was not C0 before
            let c0 = continuity(&placed[0], &placed[1], [1.0, 1.0]).unwrap();
            assert!(c0.max_gap > 1e-6, "{degree:?}: first pass already continuous? {c0:?}");
        }
    }
}
