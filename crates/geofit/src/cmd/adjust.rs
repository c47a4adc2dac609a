//! `geofit adjust`: least-squares adjustment of a popa3d model (spec §4–§6): Gauss–Helmert with
//! restrictions, datum choice, statistics and blunder detection.

use clap::{Args as ClapArgs, ValueEnum};

use crate::cmd::args::require_positive;
use crate::config::{write_json_report, Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use adjust::popa3d::{adjust_model, DatumChoice, ModelError, ModelOptions, ObsReport, Report};

const AFTER_HELP: &str = "\
Example:
  geofit citygml2popa3d b.gml | geofit adjust - | geofit popa3d2citygml - --template b.gml -o out.gml
  geofit adjust rooms.popa3d -o rooms.adj.popa3d --datum free --report rooms.json

Every observation and condition of the document enters a Gauss–Helmert adjustment with restrictions
(unit norms, levelled set-ups, fixes); the adjusted plane distances, normal parameters and set-up
unknowns are written back, the observations stay as measured. Running it again after `geofit
observe` added measurements starts from the last solution.

Datum: `free` = inner constraints over the object geometry (hunting blunders strains nothing),
`soft` = weak identity observations of every plane distance / normal parameter that has none,
`hard` = a minimal set of plane distances and normal parameters is fixed.

stderr shows a table sorted by normalised residual (Baarda's w); observations with w above the
critical value (α = --alpha) are flagged, observations with a redundancy number below --min-ev are
\"not controllable\", and sketch priors that still control the geometry are listed as not yet
measured. With --strict the exit code is 1 when the global test fails or an observation is
rejected (for use as a quality gate); otherwise such findings are reported and the exit code is 0.";

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum DatumArg {
    Free,
    Soft,
    Hard,
}

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// popa3d document, `-` for stdin.
    pub input: String,
    /// Adjusted popa3d document (stdout when missing or `-`).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Datum definition.
    #[arg(long, value_enum, default_value = "free")]
    pub datum: DatumArg,
    /// σ of added soft-datum identity observations of plane distances (m).
    #[arg(long, default_value_t = 1.0)]
    pub soft_sigma_d: f64,
    /// σ of added soft-datum identity observations of normal parameters.
    #[arg(long, default_value_t = 0.01)]
    pub soft_sigma_param: f64,
    /// Convergence tolerance on relative updates.
    #[arg(long, default_value_t = 1e-10)]
    pub tolerance: f64,
    /// Iteration cap.
    #[arg(long, default_value_t = 50)]
    pub max_iterations: usize,
    /// Significance level of data snooping (two-sided); 0.001 gives k = 3.29.
    #[arg(long, default_value_t = 0.001)]
    pub alpha: f64,
    /// Redundancy number below which an observation counts as not controllable.
    #[arg(long, default_value_t = 0.1)]
    pub min_ev: f64,
    /// Rows of the stderr table (0 = none).
    #[arg(long, default_value_t = 20)]
    pub rows: usize,
    /// Write the JSON report to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
    /// Exit 1 when the global test fails or an observation is rejected.
    #[arg(long)]
    pub strict: bool,
    /// Recompute the starting values of every total-station set-up by the grid search over
    /// 0..399 gon (done automatically for set-ups without a unit quaternion).
    #[arg(long)]
    pub polar_start: bool,
}

pub(crate) fn model_options(a: &Args) -> Result<ModelOptions, CliError> {
    require_positive(&[("soft-sigma-d", a.soft_sigma_d), ("soft-sigma-param", a.soft_sigma_param), ("tolerance", a.tolerance)])?;
    if !(a.alpha > 0.0 && a.alpha < 1.0) {
        return Err(CliError::usage(format!("--alpha must lie in (0, 1), got {}", a.alpha)));
    }
    let mut mo = ModelOptions::default();
    mo.datum = match a.datum {
        DatumArg::Free => DatumChoice::Free,
        DatumArg::Soft => DatumChoice::Soft,
        DatumArg::Hard => DatumChoice::Hard,
    };
    mo.soft_sigma_d = a.soft_sigma_d;
    mo.soft_sigma_param = a.soft_sigma_param;
    mo.polar_start = a.polar_start;
    mo.engine.tolerance = a.tolerance;
    mo.engine.max_iterations = a.max_iterations;
    mo.engine.alpha = a.alpha;
    mo.engine.min_redundancy = a.min_ev;
    mo.engine.unknown_sigmas = false;
    Ok(mo)
}

pub(crate) fn map_error(name: &str, e: ModelError) -> CliError {
    match e {
        ModelError::Reference { .. } => CliError::findings(format!("{name}: {e}")),
        ModelError::Adjust(a) => CliError::findings(format!("{name}: adjustment failed: {a}")),
    }
}

fn row(o: &ObsReport) -> String {
    format!(
        "{:>6} {:<28} {:<9} {:>3} {:>14.6} {:>11.3e} {:>12.3e} {:>6.1} {:>7.2}{}",
        if o.observation == u32::MAX { "-".to_string() } else { o.observation.to_string() },
        o.class,
        o.origin,
        o.component,
        o.value,
        o.sigma,
        o.v,
        100.0 * o.redundancy,
        o.normalised,
        if o.rejected {
            "  REJECTED"
        } else if !o.controllable {
            "  not controllable"
        } else {
            ""
        }
    )
}

pub(crate) fn print_report(r: &Report, rows: usize) {
    eprintln!(
        "adjust: datum {}, {} unknowns, {} conditions, {} restrictions (+{} datum), redundancy {} (Σ r_i = {:.3}), {} iteration(s), {} component(s)",
        r.datum, r.unknowns, r.conditions, r.restrictions, r.datum_restrictions, r.redundancy, r.redundancy_sum, r.iterations, r.components
    );
    match (&r.sigma0, &r.global_test) {
        (Some(s), Some(g)) => eprintln!(
            "σ̂0 = {s:.4}; global test vᵀPv = {:.3} in [{:.3}, {:.3}] for {} dof: {}",
            g.statistic,
            g.lower,
            g.upper,
            g.dof,
            if g.passed { "passed" } else { "FAILED" }
        ),
        _ => eprintln!("no redundancy: σ̂0 and the global test are undefined"),
    }
    eprintln!("{:<28} {:>6} {:>14} {:>14} {:>8}", "type", "count", "max misclosure", "max |v|", "mean EV");
    for (k, t) in &r.per_type {
        eprintln!("{:<28} {:>6} {:>14.3e} {:>14.3e} {:>7.1}%", k, t.count, t.max_misclosure_before, t.max_abs_residual, 100.0 * t.mean_redundancy);
    }
    if rows > 0 {
        eprintln!("{:>6} {:<28} {:<9} {:>3} {:>14} {:>11} {:>12} {:>6} {:>7}", "obs", "class", "origin", "", "value", "σ", "v", "EV %", "w");
        for o in r.observations.iter().take(rows) {
            eprintln!("{}", row(o));
        }
    }
    if let Some(s) = &r.largest_suspect {
        eprintln!("largest suspect: observation {} ({}{}) w = {:.2} (critical {:.2})", s.observation, s.class, if s.component.is_empty() { String::new() } else { format!(" {}", s.component) }, s.normalised, r.critical_w);
    }
    if !r.not_yet_measured.is_empty() {
        eprintln!("not yet measured ({} sketch priors still control the geometry):", r.not_yet_measured.len());
        for o in r.not_yet_measured.iter().take(rows.max(1)) {
            eprintln!("  observation {} {} {}", o.observation, o.class, o.label.clone().unwrap_or_default());
        }
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let opts = model_options(&args)?;
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let mut model = popa3d_model::read(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    let progress = config.progress("adjust", 1);
    let report = adjust_model(&mut model, &opts).map_err(|e| map_error(&name, e))?;
    progress.finish(&format!("{} iteration(s)", report.iterations));
    if !config.quiet {
        print_report(&report, args.rows);
    }
    let out = Output::from_arg(args.output.as_deref());
    out.write_with(|w| popa3d_model::write(&model, w).map_err(|e| CliError::internal(e.to_string())))?;
    if let Some(p) = &args.report {
        write_json_report(p, &report)?;
    }
    let rejected = report.observations.iter().any(|o| o.rejected);
    let failed = report.global_test.as_ref().is_some_and(|g| !g.passed);
    Ok(if args.strict && (rejected || failed) { Exit::Findings } else { Exit::Ok })
}
