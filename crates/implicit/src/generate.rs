//! Synthetic point sets with known truth (for the demo, tests and benchmarks): a noisy sphere, a
//! noisy tilted plane, and a two-block layered model with a planted fault throw. Deterministic
//! for a given seed (SplitMix64 + Box–Muller; no external RNG so outputs never drift).

use crate::fault::Fault;
use crate::geom::{add, cross, normalize, scale, V3};
use crate::points::DataPoint;

/// SplitMix64 random numbers.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal.
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    fn gauss3(&mut self, s: f64) -> V3 {
        [self.gauss() * s, self.gauss() * s, self.gauss() * s]
    }
}

/// Tilts unit vector `n` by a random angle with standard deviation `deg` degrees.
fn noisy_normal(rng: &mut Rng, n: V3, deg: f64) -> V3 {
    if deg <= 0.0 {
        return n;
    }
    let s = deg.to_radians();
    normalize(add(n, rng.gauss3(s))).unwrap_or(n)
}

/// `n` points on a sphere, isotropic Gaussian position noise σ, normals tilted by `normal_deg`.
pub fn sphere(n: usize, center: V3, radius: f64, sigma: f64, normal_deg: f64, seed: u64) -> Vec<DataPoint> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| {
            let z = 2.0 * rng.uniform() - 1.0;
            let a = 2.0 * std::f64::consts::PI * rng.uniform();
            let r = (1.0 - z * z).sqrt();
            let u = [r * a.cos(), r * a.sin(), z];
            let p = add(add(center, scale(u, radius)), rng.gauss3(sigma));
            DataPoint { pos: p, value: None, normal: Some(noisy_normal(&mut rng, u, normal_deg)), line: i + 1 }
        })
        .collect()
}

/// The tilted plane z = 0.3·x − 0.2·y over [−size/2, size/2]², noise as for [`sphere`].
pub fn plane(n: usize, size: f64, sigma: f64, normal_deg: f64, seed: u64) -> Vec<DataPoint> {
    let mut rng = Rng::new(seed);
    let nrm = normalize([-0.3, 0.2, 1.0]).unwrap_or([0.0, 0.0, 1.0]);
    (0..n)
        .map(|i| {
            let x = (rng.uniform() - 0.5) * size;
            let y = (rng.uniform() - 0.5) * size;
            let p = add([x, y, 0.3 * x - 0.2 * y], rng.gauss3(sigma));
            DataPoint { pos: p, value: None, normal: Some(noisy_normal(&mut rng, nrm, normal_deg)), line: i + 1 }
        })
        .collect()
}

/// Distance of `p` from the plane of [`plane`].
pub fn plane_distance(p: V3) -> f64 {
    let n = normalize([-0.3, 0.2, 1.0]).unwrap_or([0.0, 0.0, 1.0]);
    crate::geom::dot(p, n)
}

/// Two-block layered model over [−100, 100]² m: horizons with values v ∈ `values` at
/// z = v + 0.05·x + 0.1·y, the block x > 0 dropped by `throw` along the vertical fault x = 0.
/// Every 10th point carries the layer normal. Returns the points and the fault surface.
pub fn faulted(per_horizon: usize, values: &[f64], throw: f64, sigma: f64, seed: u64) -> (Vec<DataPoint>, Fault) {
    let mut rng = Rng::new(seed);
    let nrm = normalize([-0.05, -0.1, 1.0]).unwrap_or([0.0, 0.0, 1.0]);
    let mut pts = Vec::new();
    for &v in values {
        for _ in 0..per_horizon {
            let x = (rng.uniform() - 0.5) * 200.0;
            let y = (rng.uniform() - 0.5) * 200.0;
            let z = v + 0.05 * x + 0.1 * y - if x > 0.0 { throw } else { 0.0 };
            let p = add([x, y, z], rng.gauss3(sigma));
            let normal = (pts.len() % 10 == 0).then_some(nrm);
            pts.push(DataPoint { pos: p, value: Some(v), normal, line: pts.len() + 1 });
        }
    }
    let (a, b, c, d) = ([0.0, -200.0, -200.0], [0.0, 200.0, -200.0], [0.0, 200.0, 200.0], [0.0, -200.0, 200.0]);
    let _ = cross;
    (pts, Fault { name: "fault".into(), tris: vec![[a, b, c], [a, c, d]] })
}

/// Writes points as text: `x y z [v] nx ny nz` (values only when `with_values`).
pub fn to_text(pts: &[DataPoint], with_values: bool) -> String {
    let mut s = String::new();
    s.push_str(if with_values { "x y z val nx ny nz\n" } else { "x y z nx ny nz\n" });
    for p in pts {
        let n = p.normal;
        let f = |x: Option<f64>| x.map(|v| format!("{v:.6}")).unwrap_or_default();
        let cols: Vec<String> = [p.pos[0], p.pos[1], p.pos[2]].iter().map(|v| format!("{v:.6}")).collect();
        let mut line = cols.join(" ");
        if with_values {
            line.push(' ');
            line.push_str(&f(p.value));
        }
        // Text rows must keep the column count: use CSV-like commas when a field can be empty.
        let nn: Vec<String> = match n {
            Some(n) => n.iter().map(|v| format!("{v:.6}")).collect(),
            None => vec![String::new(); 3],
        };
        let row = if with_values {
            format!("{},{},{},{},{},{},{}", cols[0], cols[1], cols[2], f(p.value), nn[0], nn[1], nn[2])
        } else {
            format!("{},{},{},{},{},{}", cols[0], cols[1], cols[2], nn[0], nn[1], nn[2])
        };
        let _ = line;
        s.push_str(&row);
        s.push('\n');
    }
    if with_values {
        s.replace_range(0..s.find('\n').unwrap_or(0), "x,y,z,val,nx,ny,nz");
    } else {
        s.replace_range(0..s.find('\n').unwrap_or(0), "x,y,z,nx,ny,nz");
    }
    s
}

/// The fault as OBJ text.
pub fn fault_obj(f: &Fault) -> String {
    let mut s = String::from("# geofit implicit generate: fault surface\n");
    let mut idx = 1;
    for t in &f.tris {
        for p in t {
            s.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
        }
        s.push_str(&format!("f {} {} {}\n", idx, idx + 1, idx + 2));
        idx += 3;
    }
    s
}
