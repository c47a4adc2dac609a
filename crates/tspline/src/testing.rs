//! Helpers shared by the crate's unit tests (one pseudo-random source, one test mesh), so the
//! tests of the CPU paths and of their OpenCL twins run on the same data.

use crate::mesh::{Degree, Rect, TMesh};

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
