//! Noise level of the value points, estimated from the data alone (no solve): each point is
//! compared with the plane fitted (least squares, PCA) to its k nearest neighbours on the same
//! horizon (points with the same value). With the point left out of its own fit, the residual
//! has variance σ²·(1 + 1/k) plus a curvature bias that is small while the k neighbours span
//! less than the surface's radius of curvature; a robust spread (1.4826 × the median |residual|)
//! keeps outliers and the few points near sharp folds from dominating.

use rayon::prelude::*;
use rstar::{primitives::GeomWithData, RTree};

use crate::geom::{dot, sub, V3};

/// Neighbours per local plane fit.
const K: usize = 32;
/// Points used for the estimate in all (a deterministic stride sample of each horizon beyond this).
const MAX_SAMPLE: usize = 1200;

/// Estimated standard deviation of the value points' position noise normal to their horizon, in
/// distance units; None when no horizon has enough points for a local fit (k + 1) or every
/// neighbourhood is degenerate (collinear).
pub fn estimate(points: &[(V3, f64)]) -> Option<f64> {
    estimate_k(points, K)
}

/// [`estimate`] with `k` neighbours per fit.
pub fn estimate_k(points: &[(V3, f64)], k: usize) -> Option<f64> {
    // Group by value (exact: horizons are given as iso-values).
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].1.total_cmp(&points[b].1).then(a.cmp(&b)));
    let mut residuals: Vec<f64> = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let v = points[order[start]].1;
        let mut end = start;
        while end < order.len() && points[order[end]].1.total_cmp(&v).is_eq() {
            end += 1;
        }
        let group: Vec<V3> = order[start..end].iter().map(|&i| points[i].0).collect();
        start = end;
        if group.len() <= k {
            continue;
        }
        let tree =
            RTree::bulk_load(group.iter().enumerate().map(|(i, &p)| GeomWithData::new(p, i)).collect::<Vec<_>>());
        let stride = points.len().div_ceil(MAX_SAMPLE).max(1);
        let sample: Vec<usize> = (0..group.len()).step_by(stride).collect();
        let res: Vec<Option<f64>> = sample
            .par_iter()
            .map(|&i| {
                let p = group[i];
                let nb: Vec<V3> =
                    tree.nearest_neighbor_iter(&p).filter(|g| g.data != i).take(k).map(|g| *g.geom()).collect();
                if nb.len() < k {
                    return None;
                }
                quadric_residual(&nb, p).map(f64::abs)
            })
            .collect();
        residuals.extend(res.into_iter().flatten());
    }
    if residuals.len() < k {
        return None;
    }
    residuals.sort_by(f64::total_cmp);
    let med = residuals[residuals.len() / 2];
    let sigma = 1.4826 * med;
    (sigma.is_finite()).then_some(sigma)
}

/// Leave-one-out residual of `p` against the least-squares quadric height field
/// w = c₀ + c₁u + c₂v + c₃u² + c₄uv + c₅v² through `nb`, in the neighbours' PCA frame (u, v in
/// the plane, w along its normal), divided by √(1 + h) with h the leverage of `p` in that fit, so
/// its variance is σ² whatever the neighbourhood. The quadric absorbs the surface's curvature;
/// None when the neighbours are (nearly) collinear or the fit is singular.
fn quadric_residual(nb: &[V3], p: V3) -> Option<f64> {
    let n = nb.len() as f64;
    let mut c = [0.0; 3];
    for q in nb {
        for k in 0..3 {
            c[k] += q[k] / n;
        }
    }
    let mut m = [[0.0f64; 3]; 3];
    for q in nb {
        let d = sub(*q, c);
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += d[i] * d[j];
            }
        }
    }
    let (vals, vecs) = jacobi3(m);
    // vals ascending; the normal is the eigenvector of the smallest eigenvalue.
    if !(vals[1] > 1e-6 * vals[2]) || !(vals[2] > 0.0) {
        return None;
    }
    let col = |j: usize| [vecs[0][j], vecs[1][j], vecs[2][j]];
    let (e1, e2, nrm) = (col(2), col(1), col(0));
    // Scale u, v by the neighbourhood radius so the normal matrix is well conditioned.
    let r = vals[2].sqrt() / n.sqrt();
    let frame = |q: V3| {
        let d = sub(q, c);
        (dot(d, e1) / r, dot(d, e2) / r, dot(d, nrm))
    };
    let basis = |u: f64, v: f64| [1.0, u, v, u * u, u * v, v * v];
    let mut ata = [[0.0f64; 6]; 6];
    let mut atb = [0.0f64; 6];
    for q in nb {
        let (u, v, w) = frame(*q);
        let x = basis(u, v);
        for i in 0..6 {
            for j in 0..6 {
                ata[i][j] += x[i] * x[j];
            }
            atb[i] += x[i] * w;
        }
    }
    let (u, v, w) = frame(p);
    let xp = basis(u, v);
    let coef = solve6(ata, atb)?;
    let lev = dot6(&xp, &solve6(ata, xp)?);
    let fit = dot6(&xp, &coef);
    let res = (w - fit) / (1.0 + lev.max(0.0)).sqrt();
    res.is_finite().then_some(res)
}

fn dot6(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves the 6×6 system by Gaussian elimination with partial pivoting (None when singular).
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for c in 0..6 {
        let piv = (c..6).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        a.swap(c, piv);
        b.swap(c, piv);
        if !(a[c][c].abs() > 1e-10 * scale) {
            return None;
        }
        for r in c + 1..6 {
            let f = a[r][c] / a[c][c];
            for k in c..6 {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; 6];
    for c in (0..6).rev() {
        let s: f64 = (c + 1..6).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    Some(x)
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations: eigenvalues in
/// ascending order and the eigenvectors as the matching columns.
fn jacobi3(mut a: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J with the rotation J in the (p, q) plane.
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for k in 0..3 {
                let (vkp, vkq) = (v[k][p], v[k][q]);
                v[k][p] = c * vkp - s * vkq;
                v[k][q] = s * vkp + c * vkq;
            }
        }
    }
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let vals = idx.map(|i| a[i][i]);
    let mut vecs = [[0.0; 3]; 3];
    for (col, &i) in idx.iter().enumerate() {
        for k in 0..3 {
            vecs[k][col] = v[k][i];
        }
    }
    (vals, vecs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::Rng;

    #[test]
    fn recovers_the_noise_of_a_sampled_plane_and_sphere() {
        for sigma in [0.005, 0.02, 0.05] {
            let mut rng = Rng::new(11);
            let pts: Vec<(V3, f64)> = (0..5000)
                .map(|_| {
                    let (x, y) = (rng.uniform() * 4.0, rng.uniform() * 4.0);
                    ([x, y, 0.3 * x - 0.1 * y + sigma * rng.gauss()], 7.0)
                })
                .collect();
            let e = estimate(&pts).unwrap();
            // The residual is measured along the plane normal, the noise along z: factor cos.
            let want = sigma / (1.0f64 + 0.09 + 0.01).sqrt();
            assert!((e / want - 1.0).abs() < 0.15, "plane σ {sigma}: estimate {e}, want {want}");
        }
        let pts: Vec<(V3, f64)> =
            crate::generate::sphere(8000, [0.0; 3], 1.0, 0.03, 0.0, 4).iter().map(|p| (p.pos, 0.0)).collect();
        let e = estimate(&pts).unwrap();
        assert!((e / 0.03 - 1.0).abs() < 0.2, "sphere σ 0.03: estimate {e}");
        // Collinear points: no plane, no estimate.
        let line: Vec<(V3, f64)> = (0..100).map(|i| ([i as f64, 0.0, 0.0], 0.0)).collect();
        assert_eq!(estimate(&line), None);
    }
}
