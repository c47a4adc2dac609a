//! `geofit adjust`: least-squares adjustment of a popa3d model (spec §4–§6): Gauss–Helmert with
//! restrictions, datum choice, statistics and blunder detection.

use clap::{Args as ClapArgs, ValueEnum};

use crate::cmd::args::{require_positive, InputOutput};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use adjust::popa3d::{adjust_model, DatumChoice, ModelError, ModelOptions, ObsReport, Report};
use adjust::{GlobalTest, GlobalVerdict};

const AFTER_HELP: &str = "\
Example:
  geofit citygml2popa3d b.gml | geofit adjust - | geofit popa3d2citygml - --template b.gml -o out.gml
  geofit adjust rooms.popa3d -o rooms.adj.popa3d --datum free --report rooms.json

Every observation and condition of the document enters a Gauss–Helmert adjustment with restrictions
(unit norms, levelled set-ups, fixes); the adjusted plane distances, normal parameters and set-up
unknowns are written back, the observations stay as measured. Running it again after `geofit
observe` added measurements starts from the last solution.

Datum: `free` = inner constraints over the object geometry (hunting blunders strains nothing),
`soft` = weak observations of every plane / normal parameter that has none: the plane's offset at
its own reference point (the centroid of its nodes; σ --soft-sigma-d) and the normal parameters'
values, so the result does not depend on where the model origin is, `hard` = a minimal set of
plane distances and normal parameters is fixed. The identity observations of plane distances that
citygml2popa3d writes (origin \"datum\") are read as plane offsets in the same way.

stderr shows σ̂0 with the global χ² test, the largest suspect (Baarda's w above the critical value
for α = --alpha) and the plane that moved most; --verbose adds the per-type statistics, the
--rows observations with the largest w (redundancy number below --min-ev: \"not controllable\")
and the sketch priors that still control the geometry (not yet measured). The --report JSON has
all of it for every observation. vᵀPv below the lower χ² bound means the observations fit better
than their σ claim (σ too pessimistic, or conditions met exactly); only vᵀPv above the upper bound
is a failed test.

Safety: when a plane moves more than --max-shift (metres, along its normal at its own nodes, so
independent of the model origin), nothing is written and the exit code is 1; the message names the
plane, its face and polygon. With --strict the exit code is 1 also when the global test fails
(above the upper bound) or an observation is rejected (for use as a quality gate); otherwise such
findings are reported and the exit code is 0.";

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum DatumArg {
    Free,
    Soft,
    Hard,
}

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP, mut_arg("input", |a| a.help("popa3d document, `-` for stdin")), mut_arg("output", |a| a.help("Adjusted popa3d document (stdout when missing or `-`)")))]
pub struct Args {
    #[command(flatten)]
    pub io: InputOutput,
    /// Datum definition.
    #[arg(long, value_enum, default_value = "free")]
    pub datum: DatumArg,
    /// σ of added soft-datum observations of plane offsets at their reference points (m).
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
    /// Rows of the observation table shown with --verbose (0 = none).
    #[arg(long, default_value_t = 20)]
    pub rows: usize,
    /// Show the per-type statistics, the observation table and the not-yet-measured priors on stderr.
    #[arg(short, long)]
    pub verbose: bool,
    /// Largest allowed plane movement in metres (along the normal, at the plane's nodes); above it
    /// nothing is written and the exit code is 1.
    #[arg(long, value_name = "METRES", default_value_t = 1.0)]
    pub max_shift: f64,
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
    require_positive(&[
        ("soft-sigma-d", a.soft_sigma_d),
        ("soft-sigma-param", a.soft_sigma_param),
        ("tolerance", a.tolerance),
        ("max-shift", a.max_shift),
    ])?;
    if !(a.alpha > 0.0 && a.alpha < 1.0) {
        return Err(CliError::usage(format!("--alpha must lie in (0, 1), got {}", a.alpha)));
    }
    let datum = match a.datum {
        DatumArg::Free => DatumChoice::Free,
        DatumArg::Soft => DatumChoice::Soft,
        DatumArg::Hard => DatumChoice::Hard,
    };
    let mut mo = ModelOptions {
        datum,
        soft_sigma_d: a.soft_sigma_d,
        soft_sigma_param: a.soft_sigma_param,
        polar_start: a.polar_start,
        ..Default::default()
    };
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

/// Observation values, σ and residuals are in the units the popa3d model stores them.
const OBSERVATION_UNIT: &str =
    "as stored in popa3d: m for lengths and distances, gon for Hz and V, cosine for angle conditions";

/// `--report`: the adjustment's statistics (spec §6).
const REPORT: ReportKind = ReportKind {
    schema: "geofit-adjust-report/1",
    units: &[
        ("vtpv", "1 (weighted squared residuals)"),
        ("sigma0", "1 (a posteriori variance factor, square root)"),
        ("critical_w", "1 (normalised residual)"),
        ("per_type.*.max_misclosure_before", OBSERVATION_UNIT),
        ("per_type.*.max_abs_residual", OBSERVATION_UNIT),
        ("per_type.*.mean_redundancy", "fraction"),
        ("observations[].value", OBSERVATION_UNIT),
        ("observations[].sigma", OBSERVATION_UNIT),
        ("observations[].v", OBSERVATION_UNIT),
        ("observations[].redundancy", "fraction"),
        ("max_plane_shift", "m"),
    ],
};

/// The global test in words: only vᵀPv above the upper bound is a failure.
pub(crate) fn global_test_line(sigma0: f64, g: &GlobalTest) -> String {
    let head = format!(
        "σ̂0 = {sigma0:.4}; global test vᵀPv = {:.3} in [{:.3}, {:.3}] for {} dof",
        g.statistic, g.lower, g.upper, g.dof
    );
    match g.verdict {
        GlobalVerdict::Passed => format!("{head}: passed"),
        GlobalVerdict::BelowLower => format!("{head}: below the lower bound: the observations fit better than their σ claim (σ too pessimistic, or the conditions are met exactly)"),
        GlobalVerdict::AboveUpper => format!("{head}: FAILED (above the upper bound: residuals larger than the σ allow, a blunder or σ too optimistic)"),
    }
}

pub(crate) fn print_report(r: &Report, rows: usize, verbose: bool) {
    if verbose {
        crate::say!(
            "adjust: datum {}, {} unknowns, {} conditions, {} restrictions (+{} datum), redundancy {} (Σ r_i = {:.3}), {} iteration(s), {} component(s)",
            r.datum, r.unknowns, r.conditions, r.restrictions, r.datum_restrictions, r.redundancy, r.redundancy_sum, r.iterations, r.components
        );
    }
    match (&r.sigma0, &r.global_test) {
        (Some(s), Some(g)) => crate::say!("{}", global_test_line(*s, g)),
        _ => crate::say!("no redundancy: σ̂0 and the global test are undefined"),
    }
    if verbose {
        crate::say!("{:<28} {:>6} {:>14} {:>14} {:>8}", "type", "count", "max misclosure", "max |v|", "mean EV");
        for (k, t) in &r.per_type {
            crate::say!(
                "{:<28} {:>6} {:>14.3e} {:>14.3e} {:>7.1}%",
                k,
                t.count,
                t.max_misclosure_before,
                t.max_abs_residual,
                100.0 * t.mean_redundancy
            );
        }
        if rows > 0 {
            crate::say!(
                "{:>6} {:<28} {:<9} {:>3} {:>14} {:>11} {:>12} {:>6} {:>7}",
                "obs",
                "class",
                "origin",
                "",
                "value",
                "σ",
                "v",
                "EV %",
                "w"
            );
            for o in r.observations.iter().take(rows) {
                crate::say!("{}", row(o));
            }
        }
    }
    if let Some(s) = &r.largest_suspect {
        let obs = if s.observation == u32::MAX {
            "datum observation".to_string()
        } else {
            format!("observation {}", s.observation)
        };
        let comp = if s.component.is_empty() { String::new() } else { format!(" {}", s.component) };
        let rejected = r.observations.iter().filter(|o| o.rejected).count();
        crate::say!(
            "largest suspect: {obs} ({}{comp}) w = {:.2} (critical {:.2}); {rejected} rejected",
            s.class,
            s.normalised,
            r.critical_w
        );
    }
    if let Some(p) = &r.max_plane_shift_at {
        crate::say!("largest plane movement: {:.4} m, {p}", p.shift);
    }
    if !r.not_yet_measured.is_empty() {
        crate::say!(
            "not yet measured: {} sketch priors still control the geometry{}",
            r.not_yet_measured.len(),
            if verbose { ":" } else { " (--verbose lists them)" }
        );
        if verbose {
            for o in r.not_yet_measured.iter().take(rows.max(1)) {
                crate::say!("  observation {} {} {}", o.observation, o.class, o.label.clone().unwrap_or_default());
            }
        }
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    crate::config::check_report_target(args.report.as_deref(), args.io.output.as_deref())?;
    let opts = model_options(&args)?;
    let input = Input::from_arg(&args.io.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let mut model = popa3d_model::read(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    let progress = config.progress("adjust", 1);
    let report = adjust_model(&mut model, &opts).map_err(|e| map_error(&name, e))?;
    progress.finish(&format!("{} iteration(s)", report.iterations));
    if !config.quiet {
        print_report(&report, args.rows, args.verbose);
    }
    // Refuse absurd movements before the model is written (NaN counts as absurd); the report is
    // still written, it says what moved.
    if report.max_plane_shift.is_nan() || report.max_plane_shift > args.max_shift {
        if let Some(p) = &args.report {
            write_json_report(p, &REPORT, &report)?;
        }
        let at = report.max_plane_shift_at.as_ref().map_or_else(|| "a plane".to_string(), |p| p.to_string());
        return Err(CliError::findings(format!(
            "{name}: {at} moved {:.3} m, more than --max-shift {} m; nothing written (check the conditions and σ, or raise --max-shift)",
            report.max_plane_shift, args.max_shift
        )));
    }
    let out = Output::from_arg(args.io.output.as_deref());
    out.write_with(|w| popa3d_model::write(&model, w).map_err(|e| CliError::internal(e.to_string())))?;
    if let Some(p) = &args.report {
        write_json_report(p, &REPORT, &report)?;
    }
    let rejected = report.observations.iter().any(|o| o.rejected);
    let failed = report.global_test.as_ref().is_some_and(|g| g.verdict == GlobalVerdict::AboveUpper);
    Ok(if args.strict && (rejected || failed) { Exit::Findings } else { Exit::Ok })
}
