//! The indirect reduction's bridge between the original raster and the warped frame the fit
//! works in (spec §1, §2.3): the original cells become scattered points at their forward-mapped
//! positions, so least squares and the tolerance check see the original values where `geofit
//! eval` evaluates them, and neither the splat's resampling nor the dilation-filled cells enter
//! the fit; after the fit, each control point's geometry goes back through the inverse map
//! (spec §2.3.7).
//!
//! # Examples
//!
//! ```
//! use raster_io::Raster;
//! use raster_proc::warp::{warp_raster, WarpParams};
//! use tspline_raster::{indirect, layout};
//! let mut r = Raster::new_empty(40, 30, [0.0, 1.0, 0.0, 30.0, 0.0, -1.0], None);
//! for row in 0..30 {
//!     for col in 0..40 {
//!         r.set(col, row, (col + row) as f64);
//!     }
//! }
//! let (warped, field, _) = warp_raster(&r, &WarpParams::default()).unwrap();
//! let mut l = layout::samples_from_raster(warped).unwrap();
//! let pts = indirect::scatter_forward(&r, &field, &l.georef, &mut l.samples);
//! assert_eq!(pts.z.len(), 40 * 30); // one point per valid original cell
//! ```

use raster_io::Raster;
use raster_proc::warp::{self, WarpField, WarpParams};
use raster_proc::ProcError;
use tspline::fit::{Samples, Scattered};
use tspline::format::Georef;
use tspline::TMesh;

/// Which warp an unwarped raster gets for an indirect fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WarpChoice {
    /// The principal-axis rotation only (smooth: no kinks along the warp's triangles).
    Rotate,
    /// Rotation plus the local x/y warp of `geofit warp`, landmarks every `spacing` cells
    /// (default: `geofit warp`'s).
    Full { spacing_cells: Option<f64> },
}

/// The raster an indirect fit works on: the warped raster, its field, and the original raster
/// whose cells the fit follows (`None` when the input was warped already by `geofit warp`: its
/// resampled, filled cells are fitted as they are, in the warped frame).
pub struct WarpedInput {
    pub warped: Raster,
    pub field: WarpField,
    pub original: Option<Raster>,
}

/// The input of an indirect fit: a raster written by `geofit warp` as it is (it carries its
/// field), any other raster warped here as `choice` says.
pub fn warp_for_fit(raster: Raster, choice: WarpChoice) -> Result<WarpedInput, ProcError> {
    if let Ok(field) = warp::field_of(&raster) {
        return Ok(WarpedInput { warped: raster, field, original: None });
    }
    let mut params = WarpParams::default();
    match choice {
        WarpChoice::Rotate => {
            params.x_warp = false;
            params.y_warp = false;
        }
        WarpChoice::Full { spacing_cells: Some(sp) } => {
            let (dx, dy) = raster.cell_size();
            params.landmark_spacing = Some(sp * (dx * dy).abs().sqrt());
        }
        WarpChoice::Full { spacing_cells: None } => {}
    }
    let (warped, field, _) = warp::warp_raster(&raster, &params)?;
    Ok(WarpedInput { warped, field, original: Some(raster) })
}

/// The valid cells of `original` at their positions in the warped frame's parameters. The
/// warped `samples` stay as the probes' reference only where an original cell lands within one
/// parameter cell; everywhere else they become NaN, so no filled cell is checked.
pub fn scatter_forward(original: &Raster, field: &WarpField, georef: &Georef, samples: &mut Samples) -> Scattered {
    let mapper = field.mapper();
    let mut pts = Scattered::default();
    for row in 0..original.height {
        for col in 0..original.width {
            if let Some(z) = original.get(col, row) {
                let (x, y) = original.cell_centre(col, row);
                let q = mapper.forward([x, y]);
                let (s, t) = georef.param(q[0], q[1]);
                pts.st.push([s, t]);
                pts.z.push(z);
            }
        }
    }
    keep_samples_near(samples, &pts.st);
    pts
}

/// NaN every sample that is not a corner of a parameter cell holding one of `st`.
fn keep_samples_near(samples: &mut Samples, st: &[[f64; 2]]) {
    let (w, h) = (samples.width, samples.height);
    let mut near = vec![false; w * h];
    for p in st {
        let (i0, j0) = (p[0].floor(), p[1].floor());
        for (di, dj) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let (i, j) = (i0 + di, j0 + dj);
            if i >= 0.0 && j >= 0.0 && (i as usize) < w && (j as usize) < h {
                near[j as usize * w + i as usize] = true;
            }
        }
    }
    for (q, n) in near.iter().enumerate() {
        if !n {
            samples.z.set_nan(q);
        }
    }
}

/// Moves every control point's geometry (x, y) back through the inverted field into the
/// original frame; its parameters (s, t) and height stay.
pub fn map_back(mesh: &mut TMesh, field: &WarpField, georef: &Georef) {
    let mapper = field.mapper();
    for p in &mut mesh.points {
        let (xw, yw) = georef.world(p.s, p.t);
        let q = mapper.inverse([xw, yw]);
        let (ps, pt) = georef.param(q[0], q[1]);
        p.x = ps;
        p.y = pt;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_samples_at_the_corners_of_a_points_cell_stay() {
        let mut s = Samples { width: 4, height: 3, z: vec![1.0; 12].into() };
        keep_samples_near(&mut s, &[[1.5, 0.25]]);
        let kept: Vec<usize> = (0..12).filter(|&q| !s.z.get(q).is_nan()).collect();
        assert_eq!(kept, vec![1, 2, 5, 6]);
    }
}
