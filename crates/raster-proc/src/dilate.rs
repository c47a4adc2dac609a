//! Dilation fill (spec §2.3.5, Alg. 2): unknown cells next to known ones get a value
//! extrapolated from those neighbours, pass after pass, until the rectangle is full.
//!
//! Spec A6 decided as the digest reads the worked examples (Figs. 3.31/3.32): every known
//! neighbour n (direction d) contributes the linear extrapolation z_n − (z_{n+d} − z_n), or z_n
//! when the cell beyond it is unknown; contributions are averaged with equal weights. Each pass
//! computes all newly fillable cells from the previous state and commits them together
//! (wave front), so the result does not depend on scan order. 8-neighbourhood is the default
//! (the smoother of the two examples).
//!
//! Our addition: extrapolated values are clamped to the range of the cells known before the
//! fill widened by that range's span on each side ([min − span, max + span]). Repeated linear
//! extrapolation otherwise continues a slope without bound into large empty corners; the
//! filled cells carry no confidence anyway (spec §2.3.5). The thesis' examples stay inside.

use raster_io::Raster;

use crate::ProcError;

/// 4- or 8-neighbourhood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Neighbourhood {
    Four,
    #[default]
    Eight,
}

/// Fills every unknown cell of `r`; returns the number of passes. Errors on a raster without
/// any known cell (nothing to extrapolate from).
///
/// The tspline fit has a second, simpler fill (`tspline::fit::mean_dilation_fill`: the mean of
/// valued neighbours, no extrapolation) for its dragging reference; the two differ on purpose.
pub fn extrapolating_dilation_fill(r: &mut Raster, nb: Neighbourhood) -> Result<usize, ProcError> {
    let (lo, hi) = r.min_max().ok_or_else(|| ProcError::Input("cannot fill a raster without any valid cell".into()))?;
    let (lo, hi) = (lo - (hi - lo), hi + (hi - lo));
    let (w, h) = (r.width as isize, r.height as isize);
    let dirs: &[(isize, isize)] = match nb {
        Neighbourhood::Four => &[(1, 0), (-1, 0), (0, 1), (0, -1)],
        Neighbourhood::Eight => &[(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)],
    };
    // The current front: unknown cells with a known neighbour.
    let idx = |c: isize, r_: isize| (r_ * w + c) as usize;
    let mut front: Vec<usize> = Vec::new();
    let mut queued = vec![false; r.data.len()];
    let push_unknown_neighbours = |r: &Raster, i: usize, front: &mut Vec<usize>, queued: &mut Vec<bool>| {
        let (c, rr) = ((i as isize) % w, (i as isize) / w);
        for &(dx, dy) in dirs {
            let (nc, nr) = (c + dx, rr + dy);
            if nc >= 0 && nr >= 0 && nc < w && nr < h {
                let j = idx(nc, nr);
                if !r.is_valid(j) && !queued[j] {
                    queued[j] = true;
                    front.push(j);
                }
            }
        }
    };
    for i in 0..r.data.len() {
        if r.is_valid(i) {
            push_unknown_neighbours(r, i, &mut front, &mut queued);
        }
    }
    let mut passes = 0;
    while !front.is_empty() {
        passes += 1;
        front.sort_unstable();
        let values: Vec<f64> = front
            .iter()
            .map(|&i| {
                let (c, rr) = ((i as isize) % w, (i as isize) / w);
                let mut sum = 0.0;
                let mut n = 0usize;
                for &(dx, dy) in dirs {
                    let (nc, nr) = (c + dx, rr + dy);
                    if nc < 0 || nr < 0 || nc >= w || nr >= h || !r.is_valid(idx(nc, nr)) {
                        continue;
                    }
                    let zn = r.data[idx(nc, nr)];
                    let (fc, fr) = (nc + dx, nr + dy);
                    let slope = if fc >= 0 && fr >= 0 && fc < w && fr < h && r.is_valid(idx(fc, fr)) {
                        r.data[idx(fc, fr)] - zn
                    } else {
                        0.0
                    };
                    sum += zn - slope;
                    n += 1;
                }
                (sum / n as f64).clamp(lo, hi)
            })
            .collect();
        let committed = std::mem::take(&mut front);
        for (&i, v) in committed.iter().zip(values) {
            r.data[i] = v; // finite: clamped between finite bounds
        }
        for &i in &committed {
            push_unknown_neighbours(r, i, &mut front, &mut queued);
        }
    }
    Ok(passes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raster(w: usize, h: usize, vals: &[f64]) -> Raster {
        Raster::from_values(w, h, Raster::geotransform_from_centres(0.0, 0.0, 1.0, -1.0), None, vals.to_vec()).unwrap()
    }

    #[test]
    fn thesis_worked_examples() {
        let n = f64::NAN;
        // Fig. 3.31 (4-neighbourhood): left neighbour 1.45 with 1.51 beyond, top neighbour
        // 1.42 with 1.47 beyond ⇒ ½(1.45−0.06) + ½(1.42−0.05) = 1.38.
        #[rustfmt::skip]
        let mut r = raster(3, 3, &[
            n,   n,    1.47,
            n,   n,    1.42,
            1.51, 1.45, n,
        ]);
        // unknown target is (2,2): left neighbour (1,2)=1.45 beyond (0,2)=1.51; up (2,1)=1.42 beyond (2,0)=1.47
        let v = {
            let mut t = r.clone();
            extrapolating_dilation_fill(&mut t, Neighbourhood::Four).unwrap();
            t.get(2, 2).unwrap()
        };
        assert!((v - 1.38).abs() < 1e-12, "{v}");
        // 8-neighbourhood adds the diagonal (1,1)... here unknown, so build the Fig. 3.32 case:
        #[rustfmt::skip]
        let mut r8 = raster(3, 3, &[
            1.47, n,    1.47,
            n,    1.47, 1.42,
            1.51, 1.45, n,
        ]);
        extrapolating_dilation_fill(&mut r8, Neighbourhood::Eight).unwrap();
        // ⅓(1.45−0.06) + ⅓(1.42−0.05) + ⅓(1.47−0.0) = 1.41
        assert!((r8.get(2, 2).unwrap() - 1.41).abs() < 1e-12, "{}", r8.get(2, 2).unwrap());
        assert_eq!(extrapolating_dilation_fill(&mut r, Neighbourhood::Four).unwrap(), 2);
        assert_eq!(r.valid_count(), 9);
    }

    #[test]
    fn all_nodata_is_an_error() {
        let mut r = raster(2, 1, &[f64::NAN, f64::NAN]);
        assert!(extrapolating_dilation_fill(&mut r, Neighbourhood::Eight).is_err());
    }

    #[test]
    fn clamped_to_known_range() {
        let n = f64::NAN;
        let mut r = raster(6, 1, &[0.0, 1.0, n, n, n, n]);
        extrapolating_dilation_fill(&mut r, Neighbourhood::Four).unwrap();
        assert_eq!(r.get(2, 0), Some(2.0));
        assert_eq!(r.get(5, 0), Some(2.0));
    }
}
