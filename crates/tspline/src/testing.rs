//! Helpers shared by the crate's unit tests (one pseudo-random source, one test mesh), so the
//! tests of the CPU paths and of their OpenCL twins run on the same data.

use crate::mesh::{Degree, Rect, SplitDir, SplitRule, TMesh};

/// Deterministic pseudo-random numbers in [0, 1) (64-bit LCG, top 53 bits).
pub(crate) fn lcg(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (*seed >> 11) as f64 / (1u64 << 53) as f64
}

/// A refined, repaired mesh with T-junctions, wavy heights and non-unit weights (the rational
/// form matters).
pub(crate) fn refined_mesh(degree: Degree) -> TMesh {
    let mut m = TMesh::grid(degree, 0.0, 0.0, 16.0, 6, 5);
    let mut g = |s: f64, t: f64| (s, t, 0.0);
    for (s, t) in [(40.0, 40.0), (41.0, 41.0), (70.0, 20.0), (10.0, 70.0), (44.0, 38.0)] {
        let c = m.leaves_in(Rect::new(s, t, s, t))[0];
        m.split(c, &mut g);
    }
    m.repair(1.0, &mut g);
    for p in &mut m.points {
        p.z = (p.s * 0.1).sin() * 10.0 + p.t * 0.3 + (p.t * 0.05).cos();
        p.w = 1.0 + 0.1 * (p.s * 0.37).sin().abs();
    }
    m
}

/// The benchmark's mesh shape (`benches/tspline_mesh.py`: `n`² cubic cells of size 10, one band
/// split, smooth wavy heights) and the raster-centre parameters of its whole domain, for the
/// ignored throughput probes of the CPU and OpenCL evaluators (the same data for both).
pub(crate) fn benchmark_surface(n: usize) -> (crate::eval::PbSpline, Vec<[f64; 2]>) {
    let mut m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 10.0, n, n);
    let mut g = |s: f64, t: f64| (s, t, 0.0);
    let band = (n / 2) as f64 * 10.0;
    for c in m.leaves_in(Rect::new(0.5, band + 0.5, n as f64 * 10.0 - 0.5, band + 9.5)) {
        m.split(c, &mut g);
    }
    for p in &mut m.points {
        p.z = 20.0 * (p.s * 0.013).sin() * (p.t * 0.011).cos() + 0.01 * p.s;
    }
    let pb = crate::eval::PbSpline::build(&m);
    let side = n * 10 + 1;
    let st: Vec<[f64; 2]> = (0..side * side).map(|q| [(q % side) as f64, (side - 1 - q / side) as f64]).collect();
    (pb, st)
}

/// Random anisotropic refinement of a grid of 16-square cells: `rounds` rounds of 2- and
/// 4-splits (each leaf with probability 0.25, the direction at random), each followed by the
/// anisotropic repair (docs/decisions.md#anisotropic-splits-issue-19).
pub(crate) fn aniso_mesh(degree: Degree, seed: u64, rounds: usize) -> TMesh {
    let mut m = TMesh::grid(degree, -16.0, 0.0, 16.0, 5, 4);
    let mut g = |s: f64, t: f64| (s, t, s * 0.5 - t);
    let mut seed = seed;
    for _ in 0..rounds {
        for c in m.leaves().collect::<Vec<_>>() {
            if lcg(&mut seed) >= 0.25 {
                continue;
            }
            let r = m.cells[c as usize].rect;
            let d = match (lcg(&mut seed) * 3.0) as usize {
                0 => SplitDir::S,
                1 => SplitDir::T,
                _ => SplitDir::Quad,
            };
            let d = crate::mesh::aspect_capped(&r, d, 1.0);
            let ok = match d {
                SplitDir::S => r.width() >= 2.0,
                SplitDir::T => r.height() >= 2.0,
                SplitDir::Quad => r.width().min(r.height()) >= 2.0,
            };
            if ok {
                m.split_dir(c, d, &mut g);
            }
        }
        m.repair_with(1.0, SplitRule::Anisotropic, &mut g);
    }
    m
}
