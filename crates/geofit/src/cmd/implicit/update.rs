//! `geofit implicit update`: move or add constraints of a saved model and re-interpolate
//! (warm-started from the saved solution).

use clap::Args as ClapArgs;
use serde::Serialize;

use super::{forward, lib_err, read_model, read_points, write_vtk, LENGTH};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};

#[derive(ClapArgs)]
pub struct UpdateArgs {
    /// Saved model.
    pub model: String,
    /// Points to add as float constraints (same formats as POINTS).
    #[arg(long, value_name = "FILE")]
    pub add: Option<String>,
    /// Move constraint I to X,Y,Z (world coordinates); repeatable. I = 0-based index of the point
    /// among the input data rows (duplicates merged), then side points, then added points.
    #[arg(long = "move", value_name = "I,X,Y,Z")]
    pub moves: Vec<String>,
    /// Start CG from zero instead of the saved solution (for comparison).
    #[arg(long)]
    pub cold: bool,
    /// Output model (default: stdout).
    #[arg(short, long, value_name = "MODEL")]
    pub output: Option<String>,
    /// Also write the updated field on the mesh as a VTK unstructured grid (legacy ASCII).
    #[arg(long, value_name = "PATH")]
    pub vtk: Option<String>,
    /// Write a JSON report (constraints, CG iterations, misfit) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

/// `implicit update --report`.
const UPDATE_REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-update-report/1",
    units: &[("misfit_mean", LENGTH), ("misfit_max", LENGTH), ("seconds", "s")],
};

#[derive(Serialize)]
struct UpdateReport {
    warm_start: bool,
    cg_iterations: Vec<usize>,
    cg_iterations_total: usize,
    float_constraints: usize,
    misfit_mean: f64,
    misfit_max: f64,
    seconds: f64,
}

pub(super) fn run(a: UpdateArgs, config: &Config) -> CmdResult {
    let t0 = std::time::Instant::now();
    let mut m = read_model(&a.model)?;
    let added = match &a.add {
        Some(p) => read_points(p)?,
        None => Vec::new(),
    };
    let mut moves = Vec::new();
    for s in &a.moves {
        let f: Vec<&str> = s.split(',').map(|x| x.trim()).collect();
        let bad =
            || CliError::usage(format!("--move `{s}`: expected I,X,Y,Z (constraint index and new world position)"));
        if f.len() != 4 {
            return Err(bad());
        }
        let i: usize = f[0].parse().map_err(|_| bad())?;
        let p: Vec<f64> = f[1..].iter().map(|x| x.parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
        if p.iter().any(|x| !x.is_finite()) {
            return Err(bad());
        }
        moves.push((i, [p[0], p[1], p[2]]));
    }
    if added.is_empty() && moves.is_empty() && !a.cold {
        return Err(CliError::usage("nothing to update: give --add FILE and/or --move I,X,Y,Z"));
    }
    let mut fwd = forward(config);
    let sol = m.update(&added, &moves, a.cold, &mut fwd).map_err(|e| lib_err(&a.model, e))?;
    let loc = m.locator();
    let (mean, max) = m.misfit(&loc);
    let total: usize = sol.iterations.iter().sum();
    config.notice(&format!(
        "re-interpolated ({} start): CG iterations {:?} (total {total}); misfit mean {mean:.4} max {max:.4}",
        if a.cold { "cold" } else { "warm" },
        sol.iterations
    ));
    Output::from_arg(a.output.as_deref()).write_bytes(&m.to_bytes())?;
    write_vtk(&a.vtk, &m)?;
    if let Some(p) = &a.report {
        write_json_report(
            p,
            &UPDATE_REPORT,
            &UpdateReport {
                warm_start: !a.cold,
                cg_iterations: sol.iterations.clone(),
                cg_iterations_total: total,
                float_constraints: m.constraints.iter().filter(|c| c.float).count(),
                misfit_mean: mean,
                misfit_max: max,
                seconds: t0.elapsed().as_secs_f64(),
            },
        )?;
    }
    Ok(Exit::Ok)
}
