//! Forward-mode automatic differentiation of equation objects (spec §5).
//!
//! An equation is written ONCE, generically over the scalar type `D` (`f64` for plain values,
//! `num_dual::DualSVec64<N>` for value + gradient). The engine resolves the equation's slots to
//! the *distinct* unknowns and observations it touches (spec §6.2 "parameter net"), seeds one
//! gradient direction per distinct variable and reads the whole gradient row from one evaluation.
//! The gradient length is therefore the number of distinct variables of that equation, never the
//! size of the problem.

use num_dual::{DualNum, DualSVec64};

/// Scalar type an equation is evaluated with: `f64` or a vector dual number over `f64`.
pub trait Scalar: DualNum<Primitive = f64> + Copy {}
impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {}

/// A scalar equation `f(x, l) = 0` (a condition when `l` is non-empty, a restriction otherwise).
///
/// `x` holds the values of the unknown slots (already multiplied by their slot sign), `l` the
/// values of the observation slots (observation + current residual, spec §6.1: B is linearised at
/// l + v). The same code yields values and exact derivatives.
pub trait Equation: Send + Sync + 'static {
    /// Equation type name used in reports and per-type statistics (e.g. `"DistanceFaceFace"`).
    fn kind(&self) -> &str;
    /// Evaluate the misclosure function.
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D;
}

/// Object-safe face of [`Equation`], implemented for every `Equation` (the engine stores these).
pub trait DynEquation: Send + Sync {
    fn kind(&self) -> &str;
    /// Plain value.
    fn value(&self, x: &[f64], l: &[f64]) -> f64;
    /// Value and gradient w.r.t. distinct variables.
    ///
    /// `vars` are the values of the distinct variables; `xmap[s] = (var index, sign)` maps unknown
    /// slot `s` to a variable, `lmap[s]` maps observation slot `s` to a variable. `grad` (length
    /// `vars.len()`) receives ∂f/∂var. Returns `None` when the equation touches more distinct
    /// variables than the largest supported gradient length ([`MAX_VARS`]).
    fn value_grad(&self, vars: &[f64], xmap: &[(usize, f64)], lmap: &[usize], grad: &mut [f64]) -> Option<f64>;
}

/// Largest number of distinct variables one equation may touch (popa3d needs ≤ 24 + 3).
pub const MAX_VARS: usize = 64;

fn eval_n<E: Equation + ?Sized, const N: usize>(
    eq: &E,
    vars: &[f64],
    xmap: &[(usize, f64)],
    lmap: &[usize],
    grad: &mut [f64],
) -> f64 {
    debug_assert!(vars.len() <= N);
    let seeded: Vec<DualSVec64<N>> =
        vars.iter().enumerate().map(|(i, &v)| DualSVec64::<N>::from_re(v).derivative(i)).collect();
    let x: Vec<DualSVec64<N>> = xmap.iter().map(|&(i, s)| seeded[i] * s).collect();
    let l: Vec<DualSVec64<N>> = lmap.iter().map(|&i| seeded[i]).collect();
    let f = eq.eval(&x, &l);
    match f.eps.0 {
        Some(m) => {
            for (i, g) in grad.iter_mut().enumerate() {
                *g = m[i];
            }
        }
        None => grad.iter_mut().for_each(|g| *g = 0.0),
    }
    f.re
}

impl<E: Equation> DynEquation for E {
    fn kind(&self) -> &str {
        Equation::kind(self)
    }
    fn value(&self, x: &[f64], l: &[f64]) -> f64 {
        self.eval::<f64>(x, l)
    }
    fn value_grad(&self, vars: &[f64], xmap: &[(usize, f64)], lmap: &[usize], grad: &mut [f64]) -> Option<f64> {
        // Dispatch to the smallest fixed gradient length that fits: stack-allocated duals.
        let n = vars.len();
        Some(match n {
            0..=1 => eval_n::<E, 1>(self, vars, xmap, lmap, grad),
            2 => eval_n::<E, 2>(self, vars, xmap, lmap, grad),
            3 => eval_n::<E, 3>(self, vars, xmap, lmap, grad),
            4 => eval_n::<E, 4>(self, vars, xmap, lmap, grad),
            5..=6 => eval_n::<E, 6>(self, vars, xmap, lmap, grad),
            7..=8 => eval_n::<E, 8>(self, vars, xmap, lmap, grad),
            9..=12 => eval_n::<E, 12>(self, vars, xmap, lmap, grad),
            13..=16 => eval_n::<E, 16>(self, vars, xmap, lmap, grad),
            17..=24 => eval_n::<E, 24>(self, vars, xmap, lmap, grad),
            25..=32 => eval_n::<E, 32>(self, vars, xmap, lmap, grad),
            33..=48 => eval_n::<E, 48>(self, vars, xmap, lmap, grad),
            49..=64 => eval_n::<E, 64>(self, vars, xmap, lmap, grad),
            _ => return None,
        })
    }
}

/// Central finite-difference gradient of an equation (test helper; step `h` relative).
pub fn finite_difference_gradient<E: Equation>(eq: &E, x: &[f64], l: &[f64], h: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(x.len() + l.len());
    let mut xs = x.to_vec();
    let mut ls = l.to_vec();
    for i in 0..x.len() {
        out.push(central_difference(&mut xs, i, h, |xs| eq.eval::<f64>(xs, &ls)));
    }
    for i in 0..l.len() {
        out.push(central_difference(&mut ls, i, h, |ls| eq.eval::<f64>(&xs, ls)));
    }
    out
}

/// `(f(v + step·e_i) − f(v − step·e_i)) / (2·step)` with `step = h·(1 + |v_i|)`; `v` is restored.
fn central_difference(v: &mut [f64], i: usize, h: f64, f: impl Fn(&[f64]) -> f64) -> f64 {
    let vi = v[i];
    let step = h * (1.0 + vi.abs());
    v[i] = vi + step;
    let fp = f(v);
    v[i] = vi - step;
    let fm = f(v);
    v[i] = vi;
    (fp - fm) / (2.0 * step)
}

/// AD gradient w.r.t. every slot (each slot its own variable, sign +1; test helper).
pub fn ad_gradient<E: Equation>(eq: &E, x: &[f64], l: &[f64]) -> Vec<f64> {
    let vars: Vec<f64> = x.iter().chain(l.iter()).copied().collect();
    let xmap: Vec<(usize, f64)> = (0..x.len()).map(|i| (i, 1.0)).collect();
    let lmap: Vec<usize> = (x.len()..x.len() + l.len()).collect();
    let mut g = vec![0.0; vars.len()];
    DynEquation::value_grad(eq, &vars, &xmap, &lmap, &mut g).expect("too many variables");
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The thesis' AD test vector (spec §5): y = atan((y2−y1)/(x2−x1)).
    struct Azimuth;
    impl Equation for Azimuth {
        fn kind(&self) -> &str {
            "Azimuth"
        }
        fn eval<D: Scalar>(&self, x: &[D], _l: &[D]) -> D {
            ((x[3] - x[2]) / (x[1] - x[0])).atan()
        }
    }

    #[test]
    fn thesis_atan_test_vector() {
        // x1=2, x2=13, y1=5, y2=19 → y=0.9048, ∂y/∂x2=−0.0442, ∂y/∂x1=+0.0442, ∂y/∂y2=+0.0347, ∂y/∂y1=−0.0347
        let x = [2.0, 13.0, 5.0, 19.0];
        let g = ad_gradient(&Azimuth, &x, &[]);
        let y = Azimuth.eval::<f64>(&x, &[]);
        assert!((y - 0.9048).abs() < 5e-5, "{y}");
        let expect = [0.0442, -0.0442, -0.0347, 0.0347];
        for (a, b) in g.iter().zip(expect) {
            assert!((a - b).abs() < 5e-5, "{g:?}");
        }
        let fd = finite_difference_gradient(&Azimuth, &x, &[], 1e-6);
        for (a, b) in g.iter().zip(fd) {
            assert!((a - b).abs() < 1e-8);
        }
    }

    #[test]
    fn shared_slot_gradients_sum() {
        // f = x0 * x1 with both slots mapped to the same variable, second with sign −1: f = −v²
        struct Prod;
        impl Equation for Prod {
            fn kind(&self) -> &str {
                "Prod"
            }
            fn eval<D: Scalar>(&self, x: &[D], _l: &[D]) -> D {
                x[0] * x[1]
            }
        }
        let mut g = [0.0];
        let f = DynEquation::value_grad(&Prod, &[3.0], &[(0, 1.0), (0, -1.0)], &[], &mut g).unwrap();
        assert_eq!(f, -9.0);
        assert_eq!(g[0], -6.0);
    }
}
