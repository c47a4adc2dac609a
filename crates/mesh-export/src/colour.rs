//! Colour ramps for vertex colours: one diverging ramp for signed fields (φ of an implicit model,
//! a section), one sequential ramp for heights. Both return linear RGBA in 0..1, as glTF's
//! `COLOR_0` and OBJ's vertex colours take them.
//!
//! # Examples
//!
//! ```
//! use mesh_export::colour::{diverging, elevation};
//! assert_eq!(diverging(0.0, -1.0, 1.0), [1.0, 1.0, 1.0, 1.0]); // the middle is white
//! assert_eq!(diverging(-5.0, -1.0, 1.0), diverging(-1.0, -1.0, 1.0)); // clamped
//! assert_eq!(elevation(0.0), [0.05, 0.15, 0.55, 1.0]); // deep blue at the bottom
//! ```

/// Blue → white → red over `[lo, hi]`, white at the middle: signs of a field read at a glance.
/// An empty range (`hi ≤ lo`) gives the middle colour.
pub fn diverging(v: f64, lo: f64, hi: f64) -> [f32; 4] {
    let t = if hi > lo { ((v - lo) / (hi - lo)).clamp(0.0, 1.0) } else { 0.5 } as f32;
    if t < 0.5 {
        let s = t * 2.0;
        [0.23 + 0.77 * s, 0.30 + 0.70 * s, 0.75 + 0.25 * s, 1.0]
    } else {
        let s = (t - 0.5) * 2.0;
        [1.0 - 0.3 * s, 1.0 - 0.985 * s, 1.0 - 0.85 * s, 1.0]
    }
}

/// Deep blue → cyan → green → brown for a height normalised to `0..1` (clamped): the
/// bathymetric/topographic convention, deep water blue and high ground brown.
pub fn elevation(f: f64) -> [f32; 4] {
    let f = f.clamp(0.0, 1.0) as f32;
    let stops = [[0.05, 0.15, 0.55], [0.1, 0.6, 0.8], [0.2, 0.65, 0.25], [0.55, 0.4, 0.2]];
    let x = f * 3.0;
    let i = (x.floor() as usize).min(2);
    let t = x - i as f32;
    let (a, b) = (stops[i], stops[i + 1]);
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t, 1.0]
}
