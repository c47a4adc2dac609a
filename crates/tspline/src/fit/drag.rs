//! Dragging (spec §4.6, Alg. 4) and the mean dilation fill it starts from.

use super::*;

/// Dragging (spec §4.6, Alg. 4): z-only, Jacobi-style simultaneous update, step limit A12.
/// Returns the new z per PB point.
pub fn fit_drag(
    pb: &PbSpline,
    samples: &Samples,
    steps: usize,
    threshold: f64,
    backend: &Backend,
) -> Result<Vec<f64>, TsplineError> {
    let params: Vec<[f64; 2]> = pb.point_ids.iter().enumerate().map(|(i, _)| pb_param(pb, i)).collect();
    // Dragging needs a continuous reference (spec §4.6): holes are filled by dilation and
    // points outside the raster take the nearest edge value (A10: clamp to edge).
    let filled = mean_dilation_fill(samples);
    let (wm, hm) = ((samples.width - 1) as f64, (samples.height - 1) as f64);
    let refz: Vec<f64> = params.iter().map(|p| filled.bilinear(p[0].clamp(0.0, wm), p[1].clamp(0.0, hm))).collect();
    let mut pb = pb.clone();
    // the PB-spline buffers only: every step replaces the geometry, which would drop an
    // element extraction before its first use
    let mut dev = match backend {
        Backend::OpenCl(o) => Some((o, o.upload_pb(&pb)?)),
        Backend::Cpu => None,
    };
    let mut prev_max = f64::INFINITY;
    for _ in 0..steps {
        let delta: Vec<f64> = match &mut dev {
            Some((o, sp)) => {
                o.update_geometry(sp, &pb)?;
                o.drag_vectors(sp, &params, &refz)?
            }
            None => params.par_iter().zip(&refz).map(|(p, r)| r - pb.point(p[0], p[1])[2]).collect(),
        };
        let max = delta.iter().filter(|d| d.is_finite()).fold(0.0f64, |m, d| m.max(d.abs()));
        let limit = 0.5 * prev_max;
        for (g, d) in pb.geom.iter_mut().zip(&delta) {
            if d.is_finite() {
                g[2] += d.clamp(-limit, limit);
            }
        }
        prev_max = max.min(prev_max * 2.0);
        if max < threshold {
            break;
        }
    }
    Ok(pb.geom.iter().map(|g| g[2]).collect())
}

/// Fills every no-data cell by wave-front dilation (spec §2.3.5, Alg. 2): each pass gives the
/// cells next to valued ones the mean of their valued 8-neighbours from the previous pass, so the
/// result does not depend on scan order.
///
/// Not `raster_proc::dilate::extrapolating_dilation_fill` on purpose: that one (the warp's, A6)
/// continues slopes by linear extrapolation and must clamp the result; dragging only needs a
/// continuous reference surface, and a mean of known values never leaves their range. It also
/// works on [`Samples`] in the parameter layout rather than on a `Raster`. The result is f64
/// (the means are not f32 values).
pub fn mean_dilation_fill(samples: &Samples) -> Samples {
    let (w, h) = (samples.width, samples.height);
    let mut z = samples.z.to_f64();
    if z.iter().all(|v| v.is_nan()) {
        return Samples { width: w, height: h, z: z.into() };
    }
    let nbrs = |q: usize| {
        let (i, j) = ((q % w) as isize, (q / w) as isize);
        let mut v = Vec::with_capacity(8);
        for dj in -1..=1 {
            for di in -1..=1 {
                let (a, b) = (i + di, j + dj);
                if (di, dj) != (0, 0) && a >= 0 && b >= 0 && (a as usize) < w && (b as usize) < h {
                    v.push(b as usize * w + a as usize);
                }
            }
        }
        v
    };
    let mut front: Vec<usize> =
        (0..z.len()).filter(|&q| z[q].is_nan() && nbrs(q).iter().any(|&n| !z[n].is_nan())).collect();
    while !front.is_empty() {
        let vals: Vec<f64> = front
            .iter()
            .map(|&q| {
                let v: Vec<f64> = nbrs(q).into_iter().map(|n| z[n]).filter(|x| !x.is_nan()).collect();
                v.iter().sum::<f64>() / v.len() as f64
            })
            .collect();
        for (&q, v) in front.iter().zip(vals) {
            z[q] = v;
        }
        let mut next: Vec<usize> = front.iter().flat_map(|&q| nbrs(q)).filter(|&n| z[n].is_nan()).collect();
        next.sort_unstable();
        next.dedup();
        front = next;
    }
    Samples { width: w, height: h, z: z.into() }
}
