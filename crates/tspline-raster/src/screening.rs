//! What a raster goes through before a fit: values declared as no data, the tolerance of each
//! cell, and the blunder screen (docs/decisions.md#blunders-before-a-fit): isolated cells far from
//! their neighbourhood's prediction are found and, on request, excluded; values beyond what f64
//! arithmetic can follow at the tolerance (an undeclared no-data marker such as 1e30) are refused
//! unless excluded. All on the raster as read (rows from the top), so positions are the file's.
//!
//! # Examples
//!
//! ```
//! use raster_io::Raster;
//! use tspline_raster::screening::{screen_blunders, RasterTolerance};
//! let mut r = Raster::new_empty(9, 9, [0.0, 1.0, 0.0, 9.0, 0.0, -1.0], None);
//! for q in 0..81 {
//!     r.data[q] = (q % 9) as f64 * 0.1;
//! }
//! r.data[40] = 50.0; // a spike in the middle
//! let tol = RasterTolerance::uniform(0.5);
//! let screen = screen_blunders(&mut r, 10.0, true, &tol).unwrap();
//! assert_eq!(screen.found.len(), 1);
//! assert_eq!(screen.position(screen.found[0].index).row, 4);
//! assert!(!r.is_valid(40)); // excluded
//! ```

use raster_io::Raster;
use tspline::blunders::{self, Blunder};

/// `--nodata V`: cells equal to `v` (or to `v` at float32 precision, as float32 rasters store
/// it) become no data.
pub fn declare_nodata(r: &mut Raster, v: f64) {
    let v32 = v as f32;
    for d in r.data.iter_mut() {
        if *d == v || (v32.is_finite() && *d as f32 == v32) {
            *d = f64::NAN;
        }
    }
}

/// The tolerance of each cell of the raster as read: `floor` everywhere, or
/// max(floor, k · u) with an uncertainty layer `u` (NaN = none: the floor).
pub struct RasterTolerance<'a> {
    pub floor: Option<f64>,
    pub k: Option<f64>,
    pub uncertainty: Option<&'a [f64]>,
}

impl RasterTolerance<'_> {
    pub fn uniform(e: f64) -> RasterTolerance<'static> {
        RasterTolerance { floor: Some(e), k: None, uncertainty: None }
    }

    pub fn at(&self, q: usize) -> f64 {
        let floor = self.floor.unwrap_or(0.0);
        match (self.k, self.uncertainty) {
            (Some(k), Some(u)) if !u[q].is_nan() => (k * u[q]).max(floor),
            _ => floor,
        }
    }

    /// The smallest tolerance over the valid cells (∞ when none is valid).
    pub fn min_over(&self, r: &Raster) -> f64 {
        (0..r.data.len()).filter(|&q| r.is_valid(q)).map(|q| self.at(q)).fold(f64::INFINITY, f64::min)
    }

    /// How a user would write it: `0.5`, `max(0.1, 2 × uncertainty)`, `2 × uncertainty`.
    pub fn describe(&self) -> String {
        match (self.floor, self.k) {
            (Some(e), Some(k)) => format!("max({e}, {k} × uncertainty)"),
            (None, Some(k)) => format!("{k} × uncertainty"),
            (Some(e), None) => format!("{e}"),
            (None, None) => "0".into(),
        }
    }

    /// The valid cells without a positive finite tolerance (no uncertainty and no floor).
    pub fn uncovered(&self, r: &Raster) -> Vec<usize> {
        (0..r.data.len()).filter(|&q| r.is_valid(q) && !(self.at(q) > 0.0 && self.at(q).is_finite())).collect()
    }
}

/// A cell's place in the raster: row and column from the top left, and its centre in world
/// coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellPosition {
    pub row: usize,
    pub col: usize,
    pub x: f64,
    pub y: f64,
}

/// What the blunder screen found (cells by raster index) and did.
#[derive(Debug)]
pub struct Screening {
    pub found: Vec<Blunder>,
    /// For each of `found`, the local linear prediction nearest its value: the one the test
    /// compares with the threshold (a blunder is off even the nearest), so the deviation shown
    /// is the one that made it a blunder (`Blunder::predicted` is the median of them).
    pub nearest: Vec<f64>,
    pub rejected: bool,
    width: usize,
    geotransform: [f64; 6],
}

impl Screening {
    pub fn position(&self, q: usize) -> CellPosition {
        position(q, self.width, self.geotransform)
    }
}

fn position(q: usize, width: usize, gt: [f64; 6]) -> CellPosition {
    let (col, row) = (q % width, q / width);
    let (x, y) = (gt[0] + (col as f64 + 0.5) * gt[1], gt[3] + (row as f64 + 0.5) * gt[5]);
    CellPosition { row, col, x, y }
}

/// Values no fit within the tolerance can follow in f64 (after any exclusion).
#[derive(Debug)]
pub struct BeyondPrecision {
    pub count: usize,
    pub first: CellPosition,
    pub value: f64,
    /// The first such cell is also an isolated blunder (`--reject-outliers` would exclude it).
    pub isolated: bool,
    /// What the screen found before refusing (reported either way).
    pub screening: Screening,
}

/// Finds isolated cells more than `k` × their tolerance off their neighbourhood's prediction and,
/// when `reject`, makes them no data (NaN, as every cell without data already is). Values beyond ±1e100 get the library's own refusal (the range its sums stay finite in).
pub fn screen_blunders(r: &mut Raster, k: f64, reject: bool, tol: &RasterTolerance) -> Result<Screening, ScreenError> {
    tspline::fit::check_value_range(&r.data)?;
    let found = blunders::detect(&r.data, r.width, r.height, &|q| k * tol.at(q));
    let nearest = found.iter().map(|b| nearest_prediction(r, b.index).unwrap_or(b.predicted)).collect();
    if reject {
        for b in &found {
            r.data[b.index] = f64::NAN;
        }
    }
    let screening = Screening { found, nearest, rejected: reject, width: r.width, geotransform: r.geotransform };
    let beyond = blunders::beyond_precision(&r.data, &|q| tol.at(q));
    match beyond.first() {
        None => Ok(screening),
        Some(&q) => Err(ScreenError::BeyondPrecision(Box::new(BeyondPrecision {
            count: beyond.len(),
            first: position(q, r.width, r.geotransform),
            value: r.data[q],
            isolated: screening.found.iter().any(|b| b.index == q),
            screening,
        }))),
    }
}

/// The local linear prediction of cell `q` nearest its value, as `tspline::blunders` forms them:
/// the mean of each pair of opposite neighbours (left/right, down/up, both diagonals), or where
/// one side is missing the linear extrapolation 2·z₁ − z₂ from the other.
pub fn nearest_prediction(r: &Raster, q: usize) -> Option<f64> {
    let (w, h) = (r.width as isize, r.height as isize);
    let (i, j) = ((q % r.width) as isize, (q / r.width) as isize);
    let at = |di: isize, dj: isize| {
        let (a, b) = (i + di, j + dj);
        if a < 0 || b < 0 || a >= w || b >= h {
            f64::NAN
        } else {
            r.data[(b * w + a) as usize]
        }
    };
    let v = r.data[q];
    let mut best: Option<f64> = None;
    let mut offer = |p: f64| {
        if best.is_none_or(|b| (v - p).abs() < (v - b).abs()) {
            best = Some(p);
        }
    };
    for (di, dj) in [(1, 0), (0, 1), (1, 1), (1, -1)] {
        let (a, b) = (at(di, dj), at(-di, -dj));
        if !a.is_nan() && !b.is_nan() {
            offer(0.5 * (a + b));
            continue;
        }
        for s in [1, -1] {
            let (z1, z2) = (at(s * di, s * dj), at(2 * s * di, 2 * s * dj));
            if !z1.is_nan() && !z2.is_nan() {
                offer(2.0 * z1 - z2);
            }
        }
    }
    best
}

/// Why a raster cannot be fitted as it is.
#[derive(Debug, thiserror::Error)]
pub enum ScreenError {
    #[error(transparent)]
    Range(#[from] tspline::TsplineError),
    #[error("{} cell(s) hold values no fit within the tolerance can follow in f64 arithmetic, first row {}, col {} (x {}, y {}): {:e}", .0.count, .0.first.row, .0.first.col, .0.first.x, .0.first.y, .0.value)]
    BeyondPrecision(Box<BeyondPrecision>),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_float32_nodata_marker_is_matched_at_float32_precision() {
        let mut r = Raster::new_empty(3, 1, [0.0, 1.0, 0.0, 1.0, 0.0, -1.0], None);
        r.data = vec![-3.4028234663852886e38, 1.0, (-3.4028235e38f32) as f64];
        declare_nodata(&mut r, -3.4028235e38);
        assert_eq!(r.valid_mask(), vec![false, true, false]);
        assert!(r.data[0].is_nan());
    }

    #[test]
    fn the_tolerance_is_the_larger_of_floor_and_k_times_uncertainty() {
        let u = [0.1, f64::NAN, 2.0];
        let t = RasterTolerance { floor: Some(0.5), k: Some(2.0), uncertainty: Some(&u) };
        assert_eq!([t.at(0), t.at(1), t.at(2)], [0.5, 0.5, 4.0]);
        assert_eq!(t.describe(), "max(0.5, 2 × uncertainty)");
        let no_floor = RasterTolerance { floor: None, k: Some(2.0), uncertainty: Some(&u) };
        let mut r = Raster::new_empty(3, 1, [0.0, 1.0, 0.0, 1.0, 0.0, -1.0], None);
        r.data = vec![1.0; 3];
        assert_eq!(no_floor.uncovered(&r), vec![1]);
    }

    /// Issue 41: the deviation printed is the one the test used (from the nearest prediction),
    /// so it is over the threshold for every cell found, where the median's need not be.
    #[test]
    fn the_reported_deviation_is_over_the_threshold() {
        let mut r = Raster::new_empty(7, 7, [0.0, 1.0, 0.0, 7.0, 0.0, -1.0], None);
        for q in 0..49 {
            // a ridge along row 3: the row's own neighbours predict it, the columns do not
            r.data[q] = if q / 7 == 3 { 4.0 } else { 0.0 };
        }
        r.data[3 * 7 + 3] = 30.0;
        let s = screen_blunders(&mut r, 2.0, false, &RasterTolerance::uniform(1.0)).unwrap();
        let i = s.found.iter().position(|b| b.index == 24).expect("the spike is found");
        assert_eq!(s.nearest[i], 4.0);
        assert!((s.found[i].value - s.nearest[i]).abs() > 2.0);
    }

    #[test]
    fn an_undeclared_1e30_is_refused_with_its_position() {
        let mut r = Raster::new_empty(5, 5, [100.0, 2.0, 0.0, 50.0, 0.0, -2.0], None);
        r.data = vec![1.0; 25];
        r.data[7] = 1e30;
        let err = screen_blunders(&mut r, 10.0, false, &RasterTolerance::uniform(0.1)).unwrap_err();
        let ScreenError::BeyondPrecision(b) = err else { panic!("{err}") };
        assert_eq!((b.first.row, b.first.col, b.first.x, b.first.y), (1, 2, 105.0, 47.0));
        assert_eq!(b.value, 1e30);
    }
}
