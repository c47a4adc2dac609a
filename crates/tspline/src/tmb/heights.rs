//! Control-point heights stored to an error budget (flag [`super::QUANT`], issue 37).
//!
//! Why: a fit promises every valid cell within E, not the control points' f64 bits. Heights
//! rounded to multiples of a step `2q` move each control point by at most `q`; the T-spline's
//! blending functions are non-negative and sum to one (partition of unity), so the evaluated
//! surface moves by at most `q` everywhere (docs/decisions.md#heights-quantised-to-the-error-budget-issue-37).
//! A fit at `E − q` stored this way stays within E, and the integers cost ~5 bits a point
//! where the lossless XOR planes cost ~6 bytes.
//!
//! Coding: `step` (f64, > 0), then per point in the canonical order (by t, then s: raster order
//! of the control net) the integer `k = round(z / step)` minus the previous point's `k`
//! (the left neighbour in the same row; the first point of a row follows the last of the row
//! below), zigzag-mapped (0, −1, 1, −2, … → 0, 1, 2, 3, …) and written as a LEB128 varint. The
//! body's zstd pass is the entropy coder (measured: within ~5 % of the residuals' order-0
//! entropy; a planar or median predictor saved ≤ 3 %, docs/decisions.md#heights-quantised-to-the-error-budget-issue-37).
//! Decoded height: `k · step`.
//!
//! # Examples
//! ```
//! use tspline::tmb::heights::{decode, encode};
//! let z = [10.02, 10.31, 9.87, 10.0];
//! let (step, q) = (0.2, 0.1);
//! let mut buf = Vec::new();
//! encode(&z, step, &mut buf).unwrap();
//! let back = decode(&buf, z.len()).unwrap().0;
//! assert!(z.iter().zip(&back).all(|(a, b)| (a - b).abs() <= q + 1e-12));
//! ```

/// Largest |k| stored: beyond 2⁵², `k · step` no longer reproduces every integer multiple.
pub const MAX_K: f64 = 4_503_599_627_370_496.0;

/// Why a height array cannot be stored or read at a step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeightsError {
    #[error("the height step {0} is not a positive finite number")]
    Step(f64),
    #[error("height {index} ({z}) is more than 2^52 steps of {step} from 0: the step is too small for the heights")]
    Range { index: usize, z: f64, step: f64 },
    #[error("the heights end after {0} of the points")]
    Truncated(usize),
    #[error("height {0}: varint longer than 64 bits or out of range")]
    Varint(usize),
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// The multiple of `step` nearest `z`, as an integer (|k| ≤ [`MAX_K`]).
pub fn quantum_index(z: f64, step: f64) -> Option<i64> {
    let k = (z / step).round();
    (k.is_finite() && k.abs() <= MAX_K).then_some(k as i64)
}

/// Appends `step` and the residuals of `z` quantised to it (see the module doc).
pub fn encode(z: &[f64], step: f64, out: &mut Vec<u8>) -> Result<(), HeightsError> {
    if !(step > 0.0 && step.is_finite()) {
        return Err(HeightsError::Step(step));
    }
    out.extend_from_slice(&step.to_le_bytes());
    let mut prev = 0i64;
    for (index, &v) in z.iter().enumerate() {
        let k = quantum_index(v, step).ok_or(HeightsError::Range { index, z: v, step })?;
        let d = k - prev; // |k|, |prev| ≤ 2⁵²: no overflow
        prev = k;
        put_varint(out, ((d << 1) ^ (d >> 63)) as u64);
    }
    Ok(())
}

/// The `n` heights at the start of `data` (as [`encode`] wrote them) and the bytes they took.
pub fn decode(data: &[u8], n: usize) -> Result<(Vec<f64>, usize), HeightsError> {
    let step = f64::from_le_bytes(data.get(..8).ok_or(HeightsError::Truncated(0))?.try_into().expect("8 bytes"));
    if !(step > 0.0 && step.is_finite()) {
        return Err(HeightsError::Step(step));
    }
    let mut pos = 8;
    let mut prev = 0i64;
    let mut z = Vec::with_capacity(n.min(data.len()));
    for i in 0..n {
        let mut u = 0u64;
        let mut shift = 0;
        loop {
            let b = *data.get(pos).ok_or(HeightsError::Truncated(i))?;
            pos += 1;
            if shift >= 64 {
                return Err(HeightsError::Varint(i));
            }
            u |= ((b & 0x7f) as u64) << shift;
            shift += 7;
            if b & 0x80 == 0 {
                break;
            }
        }
        let d = ((u >> 1) as i64) ^ -((u & 1) as i64);
        let k = prev.checked_add(d).filter(|k| (*k as f64).abs() <= MAX_K).ok_or(HeightsError::Varint(i))?;
        prev = k;
        z.push(k as f64 * step);
    }
    Ok((z, pos))
}

/// The step `2q` for a storage share `q` of the tolerance: heights move by at most `q`.
pub fn step_for(q: f64) -> f64 {
    2.0 * q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every decoded height is within q of its input (|z − k·2q| ≤ q, up to one rounding of the
    /// product), on values spanning signs and magnitudes; damaged streams are errors.
    #[test]
    fn quantised_heights_are_within_half_a_step() {
        let q = 0.037;
        let z: Vec<f64> = (0..5000).map(|i| (i as f64 * 0.013).sin() * 3000.0 - 11.0 + (i % 7) as f64 * 1e-3).collect();
        let mut buf = Vec::new();
        encode(&z, step_for(q), &mut buf).unwrap();
        let (back, used) = decode(&buf, z.len()).unwrap();
        assert_eq!(used, buf.len());
        let worst = z.iter().zip(&back).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst <= q * (1.0 + 1e-12), "{worst} > {q}");
        assert!(worst > 0.9 * q, "{worst}: the test must round by nearly q somewhere");
        assert!(buf.len() < 2 * z.len(), "{} bytes for {} smooth heights", buf.len(), z.len());
        for n in 0..buf.len() {
            assert!(decode(&buf[..n], z.len()).is_err(), "truncated to {n}");
        }
        assert_eq!(
            encode(&[1e300], 1e-9, &mut Vec::new()),
            Err(HeightsError::Range { index: 0, z: 1e300, step: 1e-9 })
        );
        assert!(matches!(encode(&[1.0], 0.0, &mut Vec::new()), Err(HeightsError::Step(_))));
        let mut bad = 0.5f64.to_le_bytes().to_vec();
        bad.extend([0xff; 11]);
        assert!(decode(&bad, 1).is_err());
    }
}
