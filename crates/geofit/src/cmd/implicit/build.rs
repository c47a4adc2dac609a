//! Interpolation from points, shared by `implicit run` and `implicit interpolate`: the options of
//! a DSI build, reading its inputs, and its JSON report.

use clap::Args as ClapArgs;
use implicit::dsi::{Weights, DEFAULT_ROUGHNESS};
use implicit::fault::{self, Fault};
use implicit::model::{self, BuildOptions, BuildReport, Model};
use implicit::points::{self, SidePoint};
use serde::Serialize;

use super::{forward, lib_err, read_points, LENGTH};
use crate::config::{Config, Input};
use crate::error::CliError;
use crate::report::{write_json_report, ReportKind};

#[derive(ClapArgs, Clone)]
pub struct BuildArgs {
    /// Points: XYZ/CSV (`-` = stdin) or LAS/LAZ.
    #[arg(value_name = "POINTS", required = true)]
    pub points: Option<String>,
    /// Side points `x y z ±1` (φ > 0 / φ < 0 there) orienting φ where there are no normals.
    #[arg(long, value_name = "FILE")]
    pub side_points: Option<String>,
    /// Give every point without a normal the normal (0, 0, 1): terrain/bathymetry, φ > 0 above.
    #[arg(long)]
    pub up_normals: bool,
    /// Fault surface as OBJ; repeat for several faults.
    #[arg(long, value_name = "OBJ")]
    pub fault: Vec<String>,
    /// A second scalar attribute `x y z v` interpolated on the same mesh, shown as vertex colours.
    #[arg(long, value_name = "FILE")]
    pub attribute: Option<String>,
    /// Finest cell size near the data (default: from the point density).
    #[arg(long)]
    pub cell: Option<f64>,
    /// Coarse cubes along the longest side of the domain.
    #[arg(long, default_value_t = 8)]
    pub coarse: usize,
    /// Relative weight ϖ of the value constraints φ = v at the points (dimensionless).
    #[arg(long, default_value_t = 1.0)]
    pub w_value: f64,
    /// Relative weight ϖ of the normal / side inequality constraints.
    #[arg(long, default_value_t = 1.0)]
    pub w_normal: f64,
    /// Relative weight ϖ_r of the roughness constraints: higher = smoother (dimensionless).
    /// Default: from the points' noise σ̂ (local quadric fits) and the finest cell h,
    /// ϖ_r = √((σ̂/h)² + 0.02²)/0.04 (5 for a unit sphere with σ = 0.03).
    #[arg(long)]
    pub w_rough: Option<f64>,
    /// Step δ along and against each normal (default: the finest cell size).
    #[arg(long)]
    pub step: Option<f64>,
    /// Gradient magnitude g the normal constraints ask for (default: fitted to the values, else 1).
    #[arg(long)]
    pub grad: Option<f64>,
    /// CG relative residual tolerance.
    #[arg(long, default_value_t = 1e-6)]
    pub tol: f64,
    /// CG iteration cap per solve.
    #[arg(long, default_value_t = 20000)]
    pub max_iter: usize,
    /// Cap on active-set rounds of the inequality constraints (each round is one CG solve).
    #[arg(long, default_value_t = 8)]
    pub rounds: usize,
    /// Misfit-driven refinement rounds (interpolate, measure, refine, re-interpolate).
    #[arg(long, default_value_t = 1)]
    pub refine: usize,
    /// Misfit (distance units) above which the mesh is refined at a point (default: cell/2).
    #[arg(long)]
    pub misfit_tol: Option<f64>,
    /// Also write the field on the mesh as a VTK unstructured grid (legacy ASCII).
    #[arg(long, value_name = "PATH")]
    pub vtk: Option<String>,
    /// Write a JSON report (sizes, CG iterations, misfit) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

/// `implicit interpolate --report`.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-report/1",
    units: &[
        ("cell", LENGTH),
        ("misfit_mean", LENGTH),
        ("misfit_max", LENGTH),
        ("noise_sigma", LENGTH),
        ("seconds", "s"),
        ("cpu_seconds", "s"),
    ],
};

#[derive(Serialize)]
struct Report {
    points: usize,
    duplicates_merged: usize,
    cell: f64,
    vertices: usize,
    tetrahedra: usize,
    refinement_rounds: usize,
    cg_iterations: Vec<usize>,
    cg_iterations_total: usize,
    misfit_mean: f64,
    misfit_max: f64,
    gradient_scale: f64,
    /// Estimated noise of the value points across their surface (distance units; null: not estimated).
    noise_sigma: Option<f64>,
    /// Roughness weight ϖ_r used (from the noise unless --w-rough was given).
    w_rough: f64,
    seconds: f64,
    /// CPU seconds of the same span, all threads (Linux; null elsewhere): less load-dependent.
    cpu_seconds: Option<f64>,
}

/// Wall-clock and CPU seconds of a build.
#[derive(Clone, Copy)]
pub(super) struct Timing {
    wall: f64,
    cpu: Option<f64>,
}

pub(super) fn build_model(b: &BuildArgs, config: &Config) -> Result<(Model, BuildReport, Timing), CliError> {
    let t0 = std::time::Instant::now();
    let cpu0 = crate::process_stats::cpu_seconds();
    let name = b.points.clone().unwrap_or_else(|| "-".into());
    let mut pts = read_points(&name)?;
    if b.up_normals {
        for p in &mut pts {
            if p.normal.is_none() {
                p.normal = Some([0.0, 0.0, 1.0]);
            }
        }
    }
    let sides: Vec<SidePoint> = match &b.side_points {
        Some(s) => {
            let input = Input::from_arg(s);
            points::parse_side_points(&input.read_all()?, &input.display_name()).map_err(|e| lib_err(s, e))?
        }
        None => Vec::new(),
    };
    let mut faults: Vec<Fault> = Vec::new();
    for f in &b.fault {
        let input = Input::from_arg(f);
        faults.push(fault::read_fault_obj(&input.read_all()?, f, [0.0; 3]).map_err(|e| lib_err(f, e))?);
    }
    // Without --w-rough the library derives ϖ_r from the data (DEFAULT_ROUGHNESS only where the
    // noise cannot be estimated).
    let rough = b.w_rough.unwrap_or(DEFAULT_ROUGHNESS);
    for (w, n) in [(b.w_value, "--w-value"), (b.w_normal, "--w-normal"), (rough, "--w-rough"), (b.tol, "--tol")] {
        if !(w >= 0.0 && w.is_finite()) {
            return Err(CliError::usage(format!("{n} must be a finite non-negative number, got {w}")));
        }
    }
    // Weights are squared in the normal system: 1e300 overflowed it and the solve never
    // returned (docs/decisions.md#crashes-and-hangs-of-issue-40).
    for (w, n) in [(b.w_value, "--w-value"), (b.w_normal, "--w-normal"), (rough, "--w-rough")] {
        if w > implicit::dsi::MAX_WEIGHT {
            return Err(CliError::usage(format!(
                "{n} {w:e} is above the largest weight, {:e}",
                implicit::dsi::MAX_WEIGHT
            )));
        }
    }
    if b.max_iter > implicit::dsi::MAX_ITER || b.rounds > implicit::dsi::MAX_ROUNDS {
        return Err(CliError::usage(format!(
            "--max-iter is at most {} and --rounds at most {}",
            implicit::dsi::MAX_ITER,
            implicit::dsi::MAX_ROUNDS
        )));
    }
    let opt = BuildOptions {
        cell: b.cell,
        coarse: b.coarse,
        weights: Weights { value: b.w_value, normal: b.w_normal, rough },
        auto_rough: b.w_rough.is_none(),
        step: b.step,
        grad: b.grad,
        tol: b.tol,
        max_iter: b.max_iter,
        refine_rounds: b.refine,
        rounds: b.rounds,
        misfit_tol: b.misfit_tol,
        ..Default::default()
    };
    let mut fwd = forward(config);
    let (mut m, rep) = model::build(&pts, &sides, &faults, &opt, &mut fwd).map_err(|e| lib_err(&name, e))?;
    if let Some(a) = &b.attribute {
        let apts = read_points(a)?;
        m.interpolate_attribute(a, &apts).map_err(|e| lib_err(a, e))?;
    }
    config.notice(&format!(
        "{} points, cell {:.4}, roughness weight {:.3}: {} vertices, {} tetrahedra; CG iterations {:?}; misfit at the values mean {:.4} max {:.4}",
        rep.points, rep.cell, rep.w_rough, rep.vertices, rep.tetrahedra, rep.cg_iterations, rep.misfit_mean, rep.misfit_max
    ));
    let cpu = match (cpu0, crate::process_stats::cpu_seconds()) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    Ok((m, rep, Timing { wall: t0.elapsed().as_secs_f64(), cpu }))
}

pub(super) fn write_report(path: &Option<String>, rep: &BuildReport, secs: Timing) -> Result<(), CliError> {
    if let Some(p) = path {
        let r = Report {
            points: rep.points,
            duplicates_merged: rep.duplicates_merged,
            cell: rep.cell,
            vertices: rep.vertices,
            tetrahedra: rep.tetrahedra,
            refinement_rounds: rep.refinement_rounds,
            cg_iterations_total: rep.cg_iterations.iter().sum(),
            cg_iterations: rep.cg_iterations.clone(),
            misfit_mean: rep.misfit_mean,
            misfit_max: rep.misfit_max,
            gradient_scale: rep.grad,
            noise_sigma: rep.noise_sigma,
            w_rough: rep.w_rough,
            seconds: secs.wall,
            cpu_seconds: secs.cpu,
        };
        write_json_report(p, &REPORT, &r)?;
    }
    Ok(())
}
