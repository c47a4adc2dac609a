//! `geofit implicit generate` (hidden): synthetic points with known truth for tests and demos.

use clap::{Args as ClapArgs, ValueEnum};

use crate::config::Output;
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs)]
pub struct GenerateArgs {
    #[arg(value_enum)]
    pub shape: Shape,
    #[arg(long, default_value_t = 4000)]
    pub n: usize,
    /// Gaussian position noise σ.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Normal noise (degrees, standard deviation).
    #[arg(long, default_value_t = 0.0)]
    pub normal_noise: f64,
    #[arg(long, default_value_t = 1.0)]
    pub radius: f64,
    /// Sphere centre X,Y,Z.
    #[arg(long, default_value = "0,0,0")]
    pub center: String,
    /// Fault throw (faulted).
    #[arg(long, default_value_t = 10.0)]
    pub throw: f64,
    /// Write the fault surface here (faulted).
    #[arg(long)]
    pub fault_obj: Option<String>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(short, long)]
    pub output: Option<String>,
}

#[derive(Copy, Clone, PartialEq, Eq, ValueEnum)]
pub enum Shape {
    Sphere,
    Plane,
    Faulted,
}

pub(super) fn run(a: GenerateArgs) -> CmdResult {
    use implicit::generate as g;
    let c: Vec<f64> = a
        .center
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| CliError::usage("--center: expected X,Y,Z"))?;
    if c.len() != 3 {
        return Err(CliError::usage("--center: expected X,Y,Z"));
    }
    let text = match a.shape {
        Shape::Sphere => {
            g::to_text(&g::sphere(a.n, [c[0], c[1], c[2]], a.radius, a.noise, a.normal_noise, a.seed), false)
        }
        Shape::Plane => g::to_text(&g::plane(a.n, 2.0 * a.radius, a.noise, a.normal_noise, a.seed), false),
        Shape::Faulted => {
            let (pts, f) = g::faulted(a.n / 3, &[-20.0, 0.0, 20.0], a.throw, a.noise, a.seed);
            if let Some(p) = &a.fault_obj {
                Output::from_arg(Some(p)).write_bytes(g::fault_obj(&f).as_bytes())?;
            }
            g::to_text(&pts, true)
        }
    };
    Output::from_arg(a.output.as_deref()).write_bytes(text.as_bytes())?;
    Ok(Exit::Ok)
}
