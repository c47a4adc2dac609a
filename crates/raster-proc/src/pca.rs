//! Principal-axis rotation (spec §2.3.1): the raster as a thin plate with mass per valid cell,
//! its centroid and inertia matrix, and the rotation that aligns the primary axis with the
//! nearer grid axis.
//!
//! Spec A3 decided: the mass is selectable. [`Mass::Unit`] (default) weighs every valid cell 1,
//! a pure footprint PCA that works for land and sea alike; [`Mass::Depth`] is the thesis'
//! water-column mass max(−z, 0) (z negative below datum), which is zero on land. NOVALUE cells
//! never count.

use raster_io::Raster;

use crate::ProcError;

/// The mass a valid cell contributes to the moments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mass {
    #[default]
    Unit,
    Depth,
}

/// Result of the moment analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrincipalAxes {
    /// Centroid (x_s, y_s) in world coordinates.
    pub centroid: [f64; 2],
    /// Direction of the primary axis (larger eigenvalue), radians from +x (east), in (−π/2, π/2].
    pub primary_angle: f64,
    /// Eigenvalues of D, larger first.
    pub eigenvalues: [f64; 2],
    /// The counter-clockwise rotation (radians, |α| ≤ π/4) that turns the primary axis onto
    /// the nearer of the E–W and N–S axes (spec footnote 8).
    pub rotation: f64,
}

/// Moments M_00, M_10, M_01 and the central second moments of spec §2.3.1 over valid cells.
pub fn principal_axes(r: &Raster, mass: Mass) -> Result<PrincipalAxes, ProcError> {
    let m = |z: f64| match mass {
        Mass::Unit => 1.0,
        Mass::Depth => (-z).max(0.0),
    };
    let (mut m00, mut m10, mut m01) = (0.0, 0.0, 0.0);
    for row in 0..r.height {
        for col in 0..r.width {
            if let Some(z) = r.get(col, row) {
                let w = m(z);
                let (x, y) = r.cell_centre(col, row);
                m00 += w;
                m10 += w * x;
                m01 += w * y;
            }
        }
    }
    if m00.is_nan() || m00 <= 0.0 {
        return Err(ProcError::Input(match mass {
            Mass::Unit => "no valid cell: nothing to orient".into(),
            Mass::Depth => "no cell below datum (z < 0): depth mass is zero; use unit mass".into(),
        }));
    }
    let (xs, ys) = (m10 / m00, m01 / m00);
    let (mut s20, mut s02, mut s11) = (0.0, 0.0, 0.0);
    for row in 0..r.height {
        for col in 0..r.width {
            if let Some(z) = r.get(col, row) {
                let w = m(z);
                let (x, y) = r.cell_centre(col, row);
                s20 += w * (x - xs) * (x - xs);
                s02 += w * (y - ys) * (y - ys);
                s11 += w * (x - xs) * (y - ys);
            }
        }
    }
    let (a, b, c) = (s20 / m00, s11 / m00, s02 / m00);
    // Eigen-decomposition of the symmetric 2×2 [[a, b], [b, c]] in closed form.
    let mean = 0.5 * (a + c);
    let rad = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let eigenvalues = [mean + rad, mean - rad];
    let mut primary_angle = 0.5 * (2.0 * b).atan2(a - c);
    if primary_angle <= -std::f64::consts::FRAC_PI_2 {
        primary_angle += std::f64::consts::PI;
    }
    // Rotate by −θ onto E–W, or onto N–S when that is the smaller turn.
    let q = std::f64::consts::FRAC_PI_2;
    let rotation = if primary_angle > q / 2.0 {
        q - primary_angle
    } else if primary_angle < -q / 2.0 {
        -q - primary_angle
    } else {
        -primary_angle
    };
    Ok(PrincipalAxes { centroid: [xs, ys], primary_angle, eigenvalues, rotation })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_angle_of_a_rotated_strip() {
        // A thin strip along direction 30° in a 200×200 raster of 1 m cells.
        let gt = Raster::geotransform_from_centres(0.0, 199.0, 1.0, -1.0);
        let mut r = Raster::new_empty(200, 200, gt, None);
        let t = 30f64.to_radians();
        for row in 0..200 {
            for col in 0..200 {
                let (x, y) = r.cell_centre(col, row);
                let (dx, dy) = (x - 100.0, y - 100.0);
                let along = dx * t.cos() + dy * t.sin();
                let across = -dx * t.sin() + dy * t.cos();
                if along.abs() < 80.0 && across.abs() < 10.0 {
                    r.set(col, row, -5.0);
                }
            }
        }
        let pa = principal_axes(&r, Mass::Unit).unwrap();
        assert!((pa.primary_angle.to_degrees() - 30.0).abs() < 0.5, "{}", pa.primary_angle.to_degrees());
        assert!((pa.rotation.to_degrees() + 30.0).abs() < 0.5);
        assert!((pa.centroid[0] - 100.0).abs() < 0.5 && (pa.centroid[1] - 100.0).abs() < 0.5);
        let pd = principal_axes(&r, Mass::Depth).unwrap();
        assert!((pd.primary_angle - pa.primary_angle).abs() < 1e-12);
    }

    #[test]
    fn steep_axis_turns_to_north_south() {
        let gt = Raster::geotransform_from_centres(0.0, 99.0, 1.0, -1.0);
        let mut r = Raster::new_empty(100, 100, gt, None);
        for row in 0..100 {
            for col in 0..100 {
                let (x, y) = r.cell_centre(col, row);
                // strip along 80°
                let t = 80f64.to_radians();
                let across = -(x - 50.0) * t.sin() + (y - 50.0) * t.cos();
                if across.abs() < 4.0 {
                    r.set(col, row, 1.0);
                }
            }
        }
        let pa = principal_axes(&r, Mass::Unit).unwrap();
        assert!((pa.rotation.to_degrees() - 10.0).abs() < 1.0, "{}", pa.rotation.to_degrees());
        assert!(principal_axes(&r, Mass::Depth).is_err());
    }
}
