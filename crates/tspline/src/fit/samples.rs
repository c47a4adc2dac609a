//! The fit's input raster in the parameter layout: [`Samples`] and its heights, stored as f64
//! or f32 ([`Heights`]; docs/decisions.md#float32-samples).

/// A raster in parameter layout: value (i, j) at (s = i, t = j), row-major from the bottom row,
/// NaN = no data (docs/decisions.md#nan-is-no-data).
#[derive(Debug, Clone)]
pub struct Samples {
    pub width: usize,
    pub height: usize,
    pub z: Heights,
}

/// The heights of [`Samples`] at the precision the raster holds them: 4 bytes a cell when every
/// height is exactly an f32 (a float32 raster), else 8 (docs/decisions.md#float32-samples).
/// Every f32 is an f64 exactly, so the fit reads the same numbers either way.
#[derive(Debug, Clone, PartialEq)]
pub enum Heights {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

/// A block of [`Heights`], for the loops that run over many cells: they are written once,
/// generic over the element type ([`Height`]), and dispatched per block.
pub enum HeightsSlice<'a> {
    F64(&'a [f64]),
    F32(&'a [f32]),
}

/// A stored height: f32 or f64, read as f64.
pub trait Height: Copy + Send + Sync {
    fn f64(self) -> f64;
}

impl Height for f64 {
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

impl Height for f32 {
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

impl From<Vec<f64>> for Heights {
    fn from(z: Vec<f64>) -> Heights {
        Heights::F64(z)
    }
}

impl Heights {
    /// f32 storage when every value (NaN included) survives the round trip f64 → f32 → f64,
    /// else the f64 values as they are.
    pub fn compact(z: Vec<f64>) -> Heights {
        if z.iter().all(|&v| v.is_nan() || (v as f32) as f64 == v) {
            Heights::F32(z.iter().map(|&v| v as f32).collect())
        } else {
            Heights::F64(z)
        }
    }

    #[inline]
    pub fn get(&self, q: usize) -> f64 {
        match self {
            Heights::F64(v) => v[q],
            Heights::F32(v) => v[q] as f64,
        }
    }

    /// Makes cell `q` no data.
    pub fn set_nan(&mut self, q: usize) {
        match self {
            Heights::F64(v) => v[q] = f64::NAN,
            Heights::F32(v) => v[q] = f32::NAN,
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Heights::F64(v) => v.len(),
            Heights::F32(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes per cell as stored (8 or 4).
    pub fn bytes_per_cell(&self) -> usize {
        match self {
            Heights::F64(_) => 8,
            Heights::F32(_) => 4,
        }
    }

    /// Every value as f64, in order.
    pub fn iter(&self) -> impl Iterator<Item = f64> + '_ {
        (0..self.len()).map(|q| self.get(q))
    }

    /// The cells `start..end`.
    pub fn slice(&self, start: usize, end: usize) -> HeightsSlice<'_> {
        match self {
            Heights::F64(v) => HeightsSlice::F64(&v[start..end]),
            Heights::F32(v) => HeightsSlice::F32(&v[start..end]),
        }
    }

    /// An f64 copy of every value.
    pub fn to_f64(&self) -> Vec<f64> {
        match self {
            Heights::F64(v) => v.clone(),
            Heights::F32(v) => v.iter().map(|&x| x as f64).collect(),
        }
    }
}

impl Samples {
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.z.get(j * self.width + i)
    }

    /// Standard bilinear interpolation (spec eq. 4.1 in the corrected form of §2.1 / A2); NaN
    /// when outside or when any of the four corners has no data.
    pub fn bilinear(&self, s: f64, t: f64) -> f64 {
        if !(s >= 0.0 && t >= 0.0 && s <= (self.width - 1) as f64 && t <= (self.height - 1) as f64) {
            return f64::NAN;
        }
        let i = (s.floor() as usize).min(self.width.saturating_sub(2));
        let j = (t.floor() as usize).min(self.height.saturating_sub(2));
        let fs = s - i as f64;
        let ft = t - j as f64;
        let i1 = (i + 1).min(self.width - 1);
        let j1 = (j + 1).min(self.height - 1);
        let (a, b, c, d) = (self.get(i, j), self.get(i1, j), self.get(i, j1), self.get(i1, j1));
        // corners with zero weight do not matter (exact integer positions next to no data)
        let w = [(1.0 - fs) * (1.0 - ft), fs * (1.0 - ft), (1.0 - fs) * ft, fs * ft];
        let mut v = 0.0;
        for (wk, zk) in w.iter().zip([a, b, c, d]) {
            if *wk != 0.0 {
                if zk.is_nan() {
                    return f64::NAN;
                }
                v += wk * zk;
            }
        }
        v
    }

    pub fn valid_count(&self) -> usize {
        self.z.iter().filter(|v| !v.is_nan()).count()
    }
}
