//! Raster-vs-raster comparison (spec §4.2, §9.1 item 24): statistics of |Δz|, cells over a
//! tolerance, a histogram over error classes and an error-class map, as in the thesis'
//! figures (classes 1 cm … 2 m).
//!
//! Spec A17 decided:
//! - Statistics run over the cells valid in BOTH rasters (after masking: a T-mesh evaluated
//!   with the data mask has no value outside the footprint). Cells valid in only one are
//!   counted separately, never as errors.
//! - Δz = b − a; mean, σ, median, max and RMS are of |Δz|; the signed mean (bias) is reported
//!   beside them. σ is the population standard deviation (divide by n), the median of an even
//!   count is the mean of the two middle values (numpy's conventions).
//! - Classes from bounds b₀ < b₁ < … < b_{k−1}: class 0 is |Δz| < b₀, class i is
//!   b_{i−1} ≤ |Δz| < b_i, class k is |Δz| ≥ b_{k−1}. "Over tolerance" is |Δz| > tolerance.
//! - Different grids: B is sampled bilinearly (strict missing corners) at A's cell centres and
//!   the report says so; the same grid (size and geotransform within 1e-9 of a cell) compares
//!   cell by cell.

use serde::Serialize;

use raster_io::{MissingCorners, Raster};

use crate::ProcError;

/// The thesis' error classes (1 cm … 2 m), as upper class bounds in metres.
pub const DEFAULT_CLASS_BOUNDS: [f64; 8] = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0];

/// Options of [`compare`].
#[derive(Debug, Clone, PartialEq)]
pub struct DiffOptions {
    /// Cells with |Δz| above this count as "over tolerance".
    pub tolerance: f64,
    /// Strictly increasing, positive class bounds.
    pub class_bounds: Vec<f64>,
}

impl Default for DiffOptions {
    fn default() -> Self {
        DiffOptions { tolerance: 1.0, class_bounds: DEFAULT_CLASS_BOUNDS.to_vec() }
    }
}

impl DiffOptions {
    pub fn validate(&self) -> Result<(), ProcError> {
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(ProcError::Input(format!("tolerance {} must be a non-negative number", self.tolerance)));
        }
        if self.class_bounds.is_empty() {
            return Err(ProcError::Input("at least one error-class bound is needed".into()));
        }
        let ok = self.class_bounds.iter().all(|b| b.is_finite() && *b > 0.0)
            && self.class_bounds.windows(2).all(|w| w[0] < w[1]);
        if !ok {
            return Err(ProcError::Input(format!(
                "class bounds {:?} must be positive and strictly increasing",
                self.class_bounds
            )));
        }
        Ok(())
    }

    /// Class index of an absolute error (see the module docs).
    #[inline]
    pub fn class_of(&self, e: f64) -> usize {
        self.class_bounds.partition_point(|b| *b <= e)
    }
}

/// One histogram class.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ErrorClass {
    /// Lower bound (inclusive).
    pub from: f64,
    /// Upper bound (exclusive); `None` = open.
    pub to: Option<f64>,
    pub count: usize,
    pub share: f64,
}

/// The comparison result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiffReport {
    pub width: usize,
    pub height: usize,
    /// True when B was resampled onto A's grid.
    pub resampled: bool,
    /// Cells valid in both (the statistics' population).
    pub cells_compared: usize,
    pub only_in_a: usize,
    pub only_in_b: usize,
    pub mean_abs: f64,
    pub std_abs: f64,
    pub median_abs: f64,
    pub max_abs: f64,
    pub rms: f64,
    /// Mean of b − a.
    pub mean_signed: f64,
    /// Cell (col, row) of A where |Δz| is largest.
    pub max_at: Option<[usize; 2]>,
    pub tolerance: f64,
    pub over_tolerance: usize,
    pub share_over_tolerance: f64,
    pub histogram: Vec<ErrorClass>,
}

/// Per-cell outcome, for the error-class map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellClass {
    Neither,
    OnlyA,
    OnlyB,
    Class(u8),
}

/// Compares `b` against `a` (see the module docs).
pub fn compare(a: &Raster, b: &Raster, opts: &DiffOptions) -> Result<DiffReport, ProcError> {
    compare_with_map(a, b, opts).map(|(r, _)| r)
}

fn same_grid(a: &Raster, b: &Raster) -> bool {
    if a.width != b.width || a.height != b.height {
        return false;
    }
    let (cx, cy) = a.cell_size();
    let tol = 1e-9 * cx.min(cy);
    a.geotransform.iter().zip(&b.geotransform).all(|(p, q)| (p - q).abs() <= tol)
}

/// Like [`compare`], also returning the per-cell classes on A's grid (row-major).
pub fn compare_with_map(a: &Raster, b: &Raster, opts: &DiffOptions) -> Result<(DiffReport, Vec<CellClass>), ProcError> {
    opts.validate()?;
    a.validate()?;
    b.validate()?;
    let resampled = !same_grid(a, b);
    let bval = |col: usize, row: usize| -> Option<f64> {
        if resampled {
            let (x, y) = a.cell_centre(col, row);
            b.sample(x, y, MissingCorners::Strict)
        } else {
            b.get(col, row)
        }
    };
    let mut errs: Vec<f64> = Vec::with_capacity(a.valid_count());
    let mut classes = vec![CellClass::Neither; a.width * a.height];
    let (mut only_a, mut only_b) = (0usize, 0usize);
    let (mut sum, mut sum_signed, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
    let mut max_abs = 0.0f64;
    let mut max_at = None;
    let mut counts = vec![0usize; opts.class_bounds.len() + 1];
    let mut over = 0usize;
    for row in 0..a.height {
        for col in 0..a.width {
            let i = row * a.width + col;
            match (a.get(col, row), bval(col, row)) {
                (Some(za), Some(zb)) => {
                    let d = zb - za;
                    let e = d.abs();
                    sum += e;
                    sum_signed += d;
                    sum_sq += d * d;
                    if max_at.is_none() || e > max_abs {
                        max_abs = e;
                        max_at = Some([col, row]);
                    }
                    if e > opts.tolerance {
                        over += 1;
                    }
                    let k = opts.class_of(e);
                    counts[k] += 1;
                    classes[i] = CellClass::Class(k.min(255) as u8);
                    errs.push(e);
                }
                (Some(_), None) => {
                    only_a += 1;
                    classes[i] = CellClass::OnlyA;
                }
                (None, Some(_)) => {
                    only_b += 1;
                    classes[i] = CellClass::OnlyB;
                }
                (None, None) => {}
            }
        }
    }
    let n = errs.len();
    if n == 0 {
        return Err(ProcError::Input(format!(
            "the rasters share no valid cell (A has {} valid, B {} {})",
            a.valid_count(),
            if resampled { "resampled onto A's grid:" } else { "has" },
            only_b
        )));
    }
    let nf = n as f64;
    let mean = sum / nf;
    let var = errs.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / nf;
    let median = median_of(&mut errs);
    let histogram = error_histogram(&counts, opts, nf);
    Ok((
        DiffReport {
            width: a.width,
            height: a.height,
            resampled,
            cells_compared: n,
            only_in_a: only_a,
            only_in_b: only_b,
            mean_abs: mean,
            std_abs: var.sqrt(),
            median_abs: median,
            max_abs,
            rms: (sum_sq / nf).sqrt(),
            mean_signed: sum_signed / nf,
            max_at,
            tolerance: opts.tolerance,
            over_tolerance: over,
            share_over_tolerance: over as f64 / nf,
            histogram,
        },
        classes,
    ))
}

/// The error classes with their counts and shares of the `nf` compared cells, bounded by
/// `opts.class_bounds` (the last class is open above).
fn error_histogram(counts: &[usize], opts: &DiffOptions, nf: f64) -> Vec<ErrorClass> {
    counts
        .iter()
        .enumerate()
        .map(|(k, &c)| ErrorClass {
            from: if k == 0 { 0.0 } else { opts.class_bounds[k - 1] },
            to: opts.class_bounds.get(k).copied(),
            count: c,
            share: c as f64 / nf,
        })
        .collect()
}

/// The median of the absolute errors (mean of the two middle values for an even count), by
/// selection instead of a full sort; `errs` is reordered.
fn median_of(errs: &mut [f64]) -> f64 {
    let n = errs.len();
    let mid = n / 2;
    let (lower, m, _) = errs.select_nth_unstable_by(mid, |x, y| x.total_cmp(y));
    if n % 2 == 1 {
        *m
    } else {
        // the lower half holds everything ≤ m: its largest is the other middle value
        let lower_max = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower_max + *m)
    }
}

/// Colour of error class `k` of `n` classes: green (small) → yellow → red (large).
pub fn class_colour(k: usize, n: usize) -> [u8; 4] {
    let t = if n <= 1 { 0.0 } else { k as f64 / (n - 1) as f64 };
    let (r, g) = if t < 0.5 { (2.0 * t, 1.0) } else { (1.0, 2.0 * (1.0 - t)) };
    [(r * 255.0).round() as u8, (g * 200.0).round() as u8, 40, 255]
}

/// Map colour of a cell where only one of the two rasters has a value.
pub const ONE_RASTER_ONLY: [u8; 4] = [150, 150, 150, 255];

/// The error-class map as RGBA8 pixels (A's grid, row 0 on top): class colours, grey where
/// only one raster has a value, transparent where neither has.
pub fn class_map_rgba(classes: &[CellClass], n_classes: usize) -> Vec<u8> {
    let mut px = Vec::with_capacity(classes.len() * 4);
    for c in classes {
        px.extend_from_slice(&match c {
            CellClass::Neither => [0, 0, 0, 0],
            CellClass::OnlyA | CellClass::OnlyB => ONE_RASTER_ONLY,
            CellClass::Class(k) => class_colour(*k as usize, n_classes),
        });
    }
    px
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(vals: &[f64]) -> Raster {
        Raster::from_values(vals.len(), 1, Raster::geotransform_from_centres(0.0, 0.0, 1.0, -1.0), None, vals.to_vec())
            .unwrap()
    }

    #[test]
    fn statistics_by_hand() {
        let n = f64::NAN;
        let a = r(&[0.0, 0.0, 0.0, 0.0, 1.0, n]);
        let b = r(&[0.005, -0.03, 0.3, 3.0, n, 2.0]);
        let rep = compare(&a, &b, &DiffOptions { tolerance: 0.1, ..Default::default() }).unwrap();
        assert_eq!(rep.cells_compared, 4);
        assert_eq!((rep.only_in_a, rep.only_in_b), (1, 1));
        let e = [0.005, 0.03, 0.3, 3.0];
        let mean = e.iter().sum::<f64>() / 4.0;
        assert!((rep.mean_abs - mean).abs() < 1e-15);
        let var = e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 4.0;
        assert!((rep.std_abs - var.sqrt()).abs() < 1e-15);
        assert!((rep.median_abs - 0.165).abs() < 1e-15);
        assert_eq!(rep.max_abs, 3.0);
        assert_eq!(rep.max_at, Some([3, 0]));
        assert!((rep.rms - (e.iter().map(|x| x * x).sum::<f64>() / 4.0).sqrt()).abs() < 1e-15);
        assert!((rep.mean_signed - (0.005 - 0.03 + 0.3 + 3.0) / 4.0).abs() < 1e-15);
        assert_eq!(rep.over_tolerance, 2);
        let counts: Vec<usize> = rep.histogram.iter().map(|c| c.count).collect();
        // <1cm, 1-2, 2-5, 5-10, 10-20, 20-50, 50-100, 100-200, ≥200 cm
        assert_eq!(counts, vec![1, 0, 1, 0, 0, 1, 0, 0, 1]);
    }

    #[test]
    fn class_bounds_are_lower_inclusive() {
        let o = DiffOptions::default();
        assert_eq!(o.class_of(0.0), 0);
        assert_eq!(o.class_of(0.01), 1);
        assert_eq!(o.class_of(2.0), 8);
        assert!(DiffOptions { class_bounds: vec![0.1, 0.1], ..Default::default() }.validate().is_err());
    }

    #[test]
    fn nothing_shared_is_an_error() {
        let n = f64::NAN;
        assert!(compare(&r(&[1.0, n]), &r(&[n, 1.0]), &DiffOptions::default()).is_err());
    }
}
