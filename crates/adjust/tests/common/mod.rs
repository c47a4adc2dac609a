//! Helpers shared by the adjust crate's integration tests.

use adjust::equations::GON;

/// What a total station reads when it points at world point `p`: (Hz, V in gon, slope distance),
/// from a station at `t` with instrument height `ih` whose axes are the columns of `r`. The
/// simulated truth of the polar tests, written out independently of the engine's equations.
pub fn polar_reading(r: &[[f64; 3]; 3], t: [f64; 3], ih: f64, p: [f64; 3]) -> (f64, f64, f64) {
    let dw = [p[0] - t[0], p[1] - t[1], p[2] - t[2] - ih];
    let xl = [0, 1, 2].map(|c| r[0][c] * dw[0] + r[1][c] * dw[1] + r[2][c] * dw[2]);
    let s = (xl[0] * xl[0] + xl[1] * xl[1] + xl[2] * xl[2]).sqrt();
    let mut hz = xl[0].atan2(xl[1]) / GON;
    if hz < 0.0 {
        hz += 400.0;
    }
    let v = (xl[2] / s).acos() / GON;
    (hz, v, s)
}
