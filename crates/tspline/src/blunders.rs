//! Blunder (spike) detection before a fit (issue 19; docs/decisions.md#blunders-before-a-fit).
//!
//! A blunder is a cell that no smooth surface can meet within the tolerance E without
//! refining down to that single cell: it lies far from what its neighbourhood predicts AND it
//! stands (nearly) alone. Two tests, both at the threshold `K·E`:
//!
//! 1. **Far from every local linear prediction.** Every pair of opposite neighbours
//!    (left/right, down/up and the two diagonals) predicts the centre by its mean; where one side
//!    is missing (raster border, hole) two cells on the other side extrapolate linearly
//!    (2·z₁ − z₂). The predictions are exact on planes (any slope, also at borders) and follow
//!    smooth terrain to its curvature. The cell is suspect when even the nearest prediction is
//!    more than K·E away: one rough or noisy direction (the extrapolations at a border amplify
//!    noise) cannot make a cell a blunder, all of them must disagree with it. The median of the
//!    predictions is reported as what the neighbourhood predicts.
//!    Also more than 5 σ from the nearest prediction, σ the robust spread of |z − P| over the raster: where the terrain
//!    is rough at the cell scale everywhere, single-cell peaks are its texture.
//! 2. **Isolated.** At most two of its valid 8-neighbours lie within K·E of its value. A cell on
//!    the edge of a cliff, a building corner or any feature of four or more connected cells has
//!    three or more neighbours at its own level and is terrain, not a blunder; isolated cells and
//!    clusters of two or three (an L-shaped triple included) are blunders.
//!
//! The scan is orientation-agnostic (row-major in either direction), one pass, parallel by rows,
//! and holds no per-cell array: only the blunders found.

use rayon::prelude::*;

/// One cell flagged as a blunder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blunder {
    /// Row-major index of the cell (`row * width + col` in the layout given to [`detect`]).
    pub index: usize,
    /// Its value.
    pub value: f64,
    /// What the neighbourhood predicts there (median of the local linear predictions).
    pub predicted: f64,
}

impl Blunder {
    /// |value − predicted|.
    pub fn deviation(&self) -> f64 {
        (self.value - self.predicted).abs()
    }
}

/// At most this many valid neighbours within the threshold: the cell stands (nearly) alone.
const MAX_CLOSE_NEIGHBOURS: usize = 2;
/// A verdict needs at least this many linear predictions (else the cell is not judged).
const MIN_PREDICTIONS: usize = 2;
/// A blunder also lies this many robust standard deviations of the raster's |z − P| away
/// (σ = 1.4826 · median |z − P| over a strided sample of the valid cells): on terrain that is
/// rough at the cell scale everywhere (a coarse global bathymetry) single-cell peaks are the
/// terrain's texture, not blunders.
const SIGMA_FACTOR: f64 = 5.0;

/// The blunders of a raster (`z` row-major, `width` × `height`, NaN = no data) at the
/// threshold `threshold(q)` of each cell (= K·E, or K·T_q with a per-cell tolerance), in index
/// order.
pub fn detect(z: &[f64], width: usize, height: usize, threshold: &(dyn Fn(usize) -> f64 + Sync)) -> Vec<Blunder> {
    assert_eq!(z.len(), width * height, "detect: {} values for {width}×{height}", z.len());
    if width == 0 {
        return Vec::new();
    }
    let floor = SIGMA_FACTOR * robust_scale(z, width, height);
    (0..height)
        .into_par_iter()
        .with_min_len(16)
        .flat_map_iter(|j| {
            (0..width).filter_map(move |i| {
                let q = j * width + i;
                let v = z[q];
                if v.is_nan() {
                    return None;
                }
                let threshold = threshold(q).max(floor);
                let at = |di: isize, dj: isize| neighbour(z, width, height, i, j, di, dj);
                // test 2 first: it is cheap and clears almost every cell
                let mut close = 0;
                for dj in -1..=1 {
                    for di in -1..=1 {
                        if (di, dj) != (0, 0) {
                            let n = at(di, dj);
                            if !n.is_nan() && (n - v).abs() <= threshold {
                                close += 1;
                            }
                        }
                    }
                }
                if close > MAX_CLOSE_NEIGHBOURS {
                    return None;
                }
                let (predicted, nearest) = predict(&at, v)?;
                (nearest > threshold).then_some(Blunder { index: q, value: v, predicted })
            })
        })
        .collect()
}

/// 1.4826 · the median of |z − P| over up to 65 536 valid cells at a regular stride (0 when
/// there is no prediction anywhere).
fn robust_scale(z: &[f64], width: usize, height: usize) -> f64 {
    let valid = z.iter().filter(|v| !v.is_nan()).count();
    let stride = valid.div_ceil(1 << 16).max(1);
    let mut r: Vec<f64> = (0..z.len())
        .filter(|&q| !z[q].is_nan())
        .step_by(stride)
        .filter_map(|q| {
            let (i, j) = (q % width, q / width);
            predict(&|di, dj| neighbour(z, width, height, i, j, di, dj), z[q]).map(|(p, _)| (z[q] - p).abs())
        })
        .collect();
    if r.is_empty() {
        return 0.0;
    }
    let mid = r.len() / 2;
    1.4826 * *r.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
}

/// z at (i + di, j + dj), NaN outside.
#[inline]
fn neighbour(z: &[f64], width: usize, height: usize, i: usize, j: usize, di: isize, dj: isize) -> f64 {
    let (a, b) = (i as isize + di, j as isize + dj);
    if a < 0 || b < 0 || a >= width as isize || b >= height as isize {
        f64::NAN
    } else {
        z[b as usize * width + a as usize]
    }
}

/// The median of the local linear predictions of the centre of `at` (offsets from the cell)
/// and the distance from `v` to the nearest of them; None with fewer than [`MIN_PREDICTIONS`].
fn predict(at: &dyn Fn(isize, isize) -> f64, v: f64) -> Option<(f64, f64)> {
    let mut preds = [0.0f64; 8];
    let mut n = 0;
    for (di, dj) in [(1, 0), (0, 1), (1, 1), (1, -1)] {
        let (a, b) = (at(di, dj), at(-di, -dj));
        if !a.is_nan() && !b.is_nan() {
            preds[n] = 0.5 * (a + b);
            n += 1;
            continue;
        }
        for s in [1, -1] {
            let (z1, z2) = (at(s * di, s * dj), at(2 * s * di, 2 * s * dj));
            if !z1.is_nan() && !z2.is_nan() {
                preds[n] = 2.0 * z1 - z2;
                n += 1;
            }
        }
    }
    if n < MIN_PREDICTIONS {
        return None;
    }
    let p = &mut preds[..n];
    p.sort_unstable_by(|a, b| a.total_cmp(b));
    let nearest = p.iter().map(|x| (v - x).abs()).fold(f64::INFINITY, f64::min);
    Some((if n % 2 == 1 { p[n / 2] } else { 0.5 * (p[n / 2 - 1] + p[n / 2]) }, nearest))
}

/// Sets the blunders' cells to NaN (no data).
pub fn exclude(z: &mut [f64], blunders: &[Blunder]) {
    for b in blunders {
        z[b.index] = f64::NAN;
    }
}

/// Relative rounding the fit's arithmetic may carry (2⁻⁴⁰ ≈ 9e-13): the evaluation paths agree
/// to ~1e-12 of the magnitudes summed (crate::tolerance).
pub const ROUNDING: f64 = 1.0 / (1u64 << 40) as f64;

/// Cells (indices, in order) whose distance from the bulk of the data is so large that the
/// rounding it brings into every sum it enters exceeds the tolerance `tol(q)` — typically an
/// undeclared no-data marker (1e30, -3.4e38 in a Float64 band): |z − centre| · [`ROUNDING`] >
/// tol, the centre being the median of up to 65 536 valid values taken at a regular stride.
/// No fit can hold such a cell, nor its neighbourhood, within the tolerance.
pub fn beyond_precision(z: &[f64], tol: &(dyn Fn(usize) -> f64 + Sync)) -> Vec<usize> {
    let valid = z.iter().filter(|v| !v.is_nan()).count();
    if valid == 0 {
        return Vec::new();
    }
    let stride = valid.div_ceil(1 << 16);
    let mut sample: Vec<f64> = z.iter().filter(|v| !v.is_nan()).step_by(stride).copied().collect();
    let mid = sample.len() / 2;
    let centre = *sample.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
    (0..z.len()).into_par_iter().filter(|&q| !z[q].is_nan() && (z[q] - centre).abs() * ROUNDING > tol(q)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(w: usize, h: usize, f: impl Fn(f64, f64) -> f64) -> Vec<f64> {
        (0..w * h).map(|q| f((q % w) as f64, (q / w) as f64)).collect()
    }

    /// Steep planes (any direction, slope up to 50 per cell), smooth curvature and straight
    /// cliffs are terrain: nothing flagged, also at the borders and around holes.
    #[test]
    fn smooth_terrain_and_cliffs_are_not_blunders() {
        let (w, h) = (40, 30);
        for (gx, gy) in [(50.0, 0.0), (0.0, -50.0), (35.0, 35.0), (12.0, -47.0)] {
            let mut z = grid(w, h, |x, y| gx * x + gy * y);
            for q in [5 * w + 7, 5 * w + 8, 20 * w + 30] {
                z[q] = f64::NAN;
            }
            assert!(detect(&z, w, h, &|_| 0.5).is_empty(), "plane {gx} {gy}");
        }
        let z = grid(w, h, |x, y| 0.01 * (x - 20.0).powi(2) + 0.02 * (y - 15.0).powi(2));
        assert!(detect(&z, w, h, &|_| 0.5).is_empty(), "paraboloid");
        // a 100-unit cliff along a column, and a block with convex corners
        let z = grid(w, h, |x, _| if x < 17.0 { 0.0 } else { 100.0 });
        assert!(detect(&z, w, h, &|_| 0.5).is_empty(), "cliff");
        let z = grid(w, h, |x, y| if (10.0..20.0).contains(&x) && (8.0..14.0).contains(&y) { 30.0 } else { 0.0 });
        assert!(detect(&z, w, h, &|_| 0.5).is_empty(), "block");
    }

    /// An undeclared no-data region (1e30, not isolated: not a blunder) is beyond the f64
    /// precision at a tolerance of 1; ordinary data and a moderate spike are not.
    #[test]
    fn undeclared_nodata_is_beyond_precision() {
        let (w, h) = (20, 10);
        let mut z = grid(w, h, |x, y| 100.0 + x - y);
        z[3 * w + 4] += 1e4;
        for q in [5 * w + 5, 5 * w + 6, 6 * w + 5, 6 * w + 6] {
            z[q] = 1e30;
        }
        assert_eq!(beyond_precision(&z, &|_| 1.0), vec![5 * w + 5, 5 * w + 6, 6 * w + 5, 6 * w + 6]);
        assert!(detect(&z, w, h, &|_| 10.0).iter().all(|b| b.index == 3 * w + 4), "the block is not isolated");
        // huge but homogeneous data is fine
        let z = grid(w, h, |x, _| 1e13 + x);
        assert!(beyond_precision(&z, &|_| 1.0).is_empty());
    }

    /// Single spikes (also at a border, a corner and beside a hole), a pair and an L-triple on a
    /// sloped plane are all found at their positions, with the plane's value as the prediction;
    /// a 1e30 cell too, without flagging its neighbours.
    #[test]
    fn spikes_and_small_clusters_are_found() {
        let (w, h) = (40, 30);
        let plane = |x: f64, y: f64| 3.0 * x - 2.0 * y + 100.0;
        let mut z = grid(w, h, plane);
        z[12 * w + 21] = f64::NAN; // a hole beside the spike at (20, 12)
        let spikes = [
            (20, 12, 9.0),
            (0, 15, -8.0),
            (39, 29, 7.0),
            (5, 5, 12.0),
            (6, 5, 12.0),
            (30, 20, -12.0),
            (31, 20, -12.0),
            (31, 21, -12.0),
        ];
        for &(i, j, d) in &spikes {
            z[j * w + i] += d;
        }
        z[25 * w + 10] = 1e30;
        let found = detect(&z, w, h, &|_| 5.0);
        let mut want: Vec<usize> = spikes.iter().map(|&(i, j, _)| j * w + i).collect();
        want.push(25 * w + 10);
        want.sort_unstable();
        assert_eq!(found.iter().map(|b| b.index).collect::<Vec<_>>(), want);
        for b in &found {
            if b.value < 1e29 {
                let p = plane((b.index % w) as f64, (b.index / w) as f64);
                // the clusters' members see each other in some predictions: within a spike height
                assert!((b.predicted - p).abs() < 6.1, "{b:?} vs {p}");
            }
        }
        // below the threshold nothing is flagged
        let mut z = grid(w, h, plane);
        z[12 * w + 20] += 4.9;
        assert!(detect(&z, w, h, &|_| 5.0).is_empty());
    }
}
