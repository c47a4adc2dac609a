//! Engine benchmark: a synthetic city of N box buildings (6 planes, 3 normals / 9 parameters each),
//! with sketch priors, relative angles, unit-norm restrictions, laser distances and a weak soft
//! datum — the popa3d equation types on the generic engine. Prints planes, unknowns, conditions,
//! time and σ̂0. Usage: cargo run --release -p adjust --example city_bench -- N
use adjust::equations::*;
use adjust::{adjust, Options, Problem, Slot};
use std::time::Instant;

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(16667);
    let t0 = Instant::now();
    let mut p = Problem::new();
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    for b in 0..n {
        let mut nrm = Vec::new();
        for k in 0..3 {
            let ids: Vec<_> = (0..3)
                .map(|c| p.add_unknown(format!("b{b}.n{k}.{c}"), if c == k { 1.0 } else { 0.001 * rnd() }))
                .collect();
            p.add_restriction(format!("b{b} NormNV {k}"), NormNvRestriction, ids.iter().map(|&u| u.into()).collect())
                .unwrap();
            nrm.push(ids);
        }
        let size = [10.0 + 5.0 * rnd(), 10.0 + 5.0 * rnd(), 8.0 + 4.0 * rnd()];
        let mut planes = Vec::new();
        for k in 0..3 {
            let lo = p.add_unknown(format!("b{b}.d{k}lo"), 0.05 * rnd());
            let hi = p.add_unknown(format!("b{b}.d{k}hi"), size[k] + 0.05 * rnd());
            planes.push((lo, hi));
            let o = p.add_observation(format!("b{b} sketch {k}"), size[k] + 0.1 * rnd(), 0.1).unwrap();
            p.add_condition(
                format!("b{b} RelativeDistancePlanePlane {k}"),
                RelativeDistancePlanePlane,
                vec![lo.into(), hi.into()],
                vec![o],
            )
            .unwrap();
            let sl =
                |d| -> Vec<Slot> { nrm[k].iter().map(|&u| u.into()).chain(std::iter::once(Slot::from(d))).collect() };
            let o = p.add_observation(format!("b{b} laser {k}"), size[k] + 0.001 * rnd(), 0.001).unwrap();
            p.add_condition(format!("b{b} DistanceFaceFace {k}"), DistanceFaceFace, [sl(lo), sl(hi)].concat(), vec![o])
                .unwrap();
            for d in [lo, hi] {
                p.add_identity_observation(d, 1.0).unwrap();
            }
        }
        for (a, c) in [(0, 1), (0, 2), (1, 2)] {
            let o = p.add_observation(format!("b{b} relangle {a}{c}"), 0.001 * rnd(), 0.001).unwrap();
            let x: Vec<Slot> = nrm[a].iter().chain(nrm[c].iter()).map(|&u| u.into()).collect();
            p.add_condition(format!("b{b} RelativeAngleNormalNormal {a}{c}"), RelativeAngleNormalNormal, x, vec![o])
                .unwrap();
        }
        for k in 0..3 {
            for &u in &nrm[k] {
                p.add_identity_observation(u, 0.01).unwrap();
            }
        }
    }
    let build = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let opts = Options { unknown_sigmas: false, ..Options::default() };
    let sol = adjust(&p, &opts).expect("adjustment");
    let secs = t1.elapsed().as_secs_f64();
    println!(
        "buildings {n} planes {} unknowns {} conditions {} restrictions {} components {} iterations {} build {build:.2} s adjust {secs:.2} s sigma0 {:.3} sum_r {:.1} r {}",
        6 * n,
        p.unknown_count(),
        p.condition_count(),
        p.restriction_count(),
        sol.components,
        sol.iterations,
        sol.sigma0_post.unwrap_or(f64::NAN),
        sol.redundancy_sum,
        sol.redundancy
    );
}
