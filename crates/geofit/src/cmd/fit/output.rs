//! The output side of `geofit fit`: progress and stop lines, the T-mesh file (only for a fit
//! that reached its tolerance, unless --keep-partial) and the JSON report.

use tspline::fit::{FitResult, IterationStats, Method, StopReason};
use tspline::format::{DataMask, Encoding, TMeshFile};
use tspline_raster::indirect;

use super::input::{OutlierReport, Prepared};
use super::storage::{self, Stored};
use super::{lerc, Args};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{with_z_unit, write_json_report_with_units, ReportKind, Z_UNIT};

/// `--report`: what the fit did and how far it got.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-fit-report/1",
    units: &[
        ("width", "cells"),
        ("height", "cells"),
        ("max_error", Z_UNIT),
        ("max_error_from_uncertainty", "multiple of the uncertainty band"),
        ("max_abs_error", Z_UNIT),
        ("compression_ratio", "valid cells per control point"),
        ("iterations[].mean", Z_UNIT),
        ("iterations[].sigma", Z_UNIT),
        ("iterations[].median", Z_UNIT),
        ("iterations[].max", Z_UNIT),
        ("iterations[].rms", Z_UNIT),
        ("iterations[].seconds", "s"),
        ("seconds", "s"),
        ("peak_rss_mib", "MiB"),
        ("output.quantum", Z_UNIT),
        ("output.decoded_max_abs_error", Z_UNIT),
        ("output.bytes", "bytes"),
        ("output.lerc_zstd_bytes", "bytes"),
        ("output.lerc_ratio", "output bytes per LERC_ZSTD byte"),
    ],
};

#[derive(serde::Serialize)]
struct Report<'a> {
    input: &'a str,
    width: usize,
    height: usize,
    valid_cells: usize,
    degree: u32,
    method: Method,
    /// Only when not the default 4-splits (the reports of default fits stay as they were).
    #[serde(skip_serializing_if = "is_quad")]
    split: tspline::mesh::SplitRule,
    /// The unit of the heights and of every height in this report, where the input declares one
    /// (or --z-unit gives it); absent: none declared, the heights are taken as they are (metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    z_unit: Option<&'static str>,
    /// --max-error as given, in its own unit (--error-unit, metres by default), where a z unit
    /// is known; `max_error` is the same tolerance in `z_unit`.
    #[serde(skip_serializing_if = "Option::is_none")]
    max_error_given: Option<f64>,
    /// The tolerance (in the heights' unit); with a per-cell tolerance, its smallest value.
    max_error: f64,
    max_error_from_uncertainty: Option<f64>,
    outliers: OutlierReport,
    max_points: Option<usize>,
    device: String,
    stop: &'a StopReason,
    control_points: usize,
    cells: usize,
    max_abs_error: f64,
    compression_ratio: f64,
    iterations: &'a [IterationStats],
    seconds: f64,
    /// Peak resident memory of the process (Linux VmHWM), MiB; null elsewhere.
    peak_rss_mib: Option<f64>,
    /// The T-mesh file as written and the LERC GeoTIFF at the same error beside it (issue 37);
    /// absent when no file was written.
    #[serde(skip_serializing_if = "Option::is_none")]
    output: Option<OutputReport>,
}

/// The stored file beside its competitor (docs/decisions.md#lerc-beside-the-t-mesh-issue-37).
#[derive(serde::Serialize)]
struct OutputReport {
    #[serde(flatten)]
    stored: Stored,
    /// Bytes of the raster as a LERC_ZSTD GeoTIFF at MAX_Z_ERROR = max_error (null: GDAL could
    /// not encode it).
    lerc_zstd_bytes: Option<usize>,
    lerc_ratio: Option<f64>,
}

fn is_quad(s: &tspline::mesh::SplitRule) -> bool {
    *s == tspline::mesh::SplitRule::Quad
}

/// The progress line of one iteration.
pub(super) fn iteration_line(st: &IterationStats, e: &str) -> String {
    let stage =
        if st.merged_cells > 0 { format!("coarsening ({} cells merged)", st.merged_cells) } else { "iteration".into() };
    format!(
        "{stage} {}: {} control points, max {:.4}, mean {:.4}, RMS {:.4}, {} cells over {} ({:.2} s: build {:.2}, optimise {:.2}, check {:.2})",
        st.iteration,
        st.control_points,
        st.error.max,
        st.error.mean,
        st.error.rms,
        st.error.over_tolerance,
        e,
        st.seconds,
        st.seconds_build,
        st.seconds_optimise,
        st.seconds_check
    )
}

/// The exit code of the fit and the line that says why it stopped.
pub(super) fn stop_line(result: &FitResult, e: &str, max_iterations: usize) -> (Exit, String) {
    let last = result.iterations.last().expect("at least one iteration");
    match &result.stop {
        StopReason::ToleranceReached => (Exit::Ok, format!("tolerance reached: every valid cell within {e}")),
        StopReason::MaxPoints { cap } => (
            Exit::Findings,
            format!("stopped at the control-point cap {cap}: max error {:.4} > {e} at {} cells", last.error.max, last.error.over_tolerance),
        ),
        StopReason::MaxIterations => (
            Exit::Findings,
            format!("stopped after {max_iterations} iterations: max error {:.4} > {e} at {} cells", last.error.max, last.error.over_tolerance),
        ),
        StopReason::MinCellSize { cells_over } => (
            Exit::Findings,
            format!("the minimum cell size (one raster cell) stops refinement: {cells_over} cells still over {e}, max error {:.4}", last.error.max),
        ),
    }
}

/// How the fit ended, for the outputs.
pub(super) struct Done {
    pub exit: Exit,
    pub line: String,
    pub t_start: std::time::Instant,
    pub device_name: String,
    pub method: Method,
}

pub(super) fn write(args: &Args, config: &Config, p: Prepared, result: FitResult, done: Done) -> CmdResult {
    if let Some(mib) = crate::process_stats::peak_rss_mib() {
        config.notice(&format!("fit: {:.1} s, peak memory {mib:.0} MiB", done.t_start.elapsed().as_secs_f64()));
    }
    let last = result.iterations.last().cloned().expect("at least one iteration");
    let (points, valid, name) = (last.control_points, p.valid, &p.name);
    if points as f64 > 0.25 * valid as f64 {
        config.notice(&format!(
            "warning: {name} does not compress: {points} control points for {valid} valid cells ({:.0} %)",
            100.0 * points as f64 / valid as f64
        ));
    }
    if done.exit != Exit::Ok {
        crate::say!("geofit: {name}: {}", done.line);
    }
    let mut mesh = result.mesh;
    let (mask, warp) = match &p.field {
        Some(f) => {
            // The original footprint travels in the field's source grid.
            indirect::map_back(&mut mesh, f, &p.georef);
            (None, Some(f.to_json()))
        }
        // The fit does not change its samples: their NaN cells are the footprint to store.
        None => (Some(DataMask::of_samples(&p.samples)), None),
    };
    let georef = p.georef.clone();
    let file = TMeshFile { mesh, georef, mask, warp };
    // A fit that missed --max-error is a failed step: no mesh for the next one (make) unless
    // --keep-partial; the report below still says how far it got.
    let output = if config.keeps_output(done.exit, args.output.as_deref()) {
        Some(write_mesh(&file, args, config, &p, done.exit == Exit::Ok)?)
    } else {
        None
    };
    if let Some(path) = &args.report {
        let rep = Report {
            input: name,
            width: p.samples.width,
            height: p.samples.height,
            valid_cells: valid,
            degree: args.degree,
            method: done.method,
            split: match args.split {
                super::SplitArg::Quad => tspline::mesh::SplitRule::Quad,
                super::SplitArg::Aniso => tspline::mesh::SplitRule::Anisotropic,
            },
            z_unit: p.units.data_name(),
            max_error_given: args.max_error.filter(|_| p.units.data.is_some()),
            max_error: p.e_min,
            max_error_from_uncertainty: args.max_error_from_uncertainty,
            outliers: p.outliers,
            max_points: args.max_points,
            device: done.device_name,
            stop: &result.stop,
            control_points: points,
            cells: last.cells,
            max_abs_error: last.error.max,
            compression_ratio: valid as f64 / points as f64,
            iterations: &result.iterations,
            seconds: done.t_start.elapsed().as_secs_f64(),
            peak_rss_mib: crate::process_stats::peak_rss_mib(),
            output,
        };
        let mut units = with_z_unit(REPORT.units, p.units.data_name().unwrap_or(Z_UNIT));
        if rep.max_error_given.is_some() {
            units.push(("max_error_given", p.units.error.name));
        }
        write_json_report_with_units(path, &REPORT, &units, &rep)?;
    }
    Ok(done.exit)
}

/// `-o x.tmb`: the compact binary form (heights to the error budget unless --lossless,
/// `storage`); anything else the XML exchange format. States the LERC GeoTIFF's size at the
/// same error beside it, and says so when the result is not smaller than the input file.
fn write_mesh(
    file: &TMeshFile,
    args: &Args,
    config: &Config,
    p: &Prepared,
    fit_ok: bool,
) -> Result<OutputReport, CliError> {
    let (bytes, stored) = storage::encode(file, args, p, fit_ok)?;
    Output::from_arg(args.output.as_deref())
        .write_with(|w| std::io::Write::write_all(w, &bytes).map_err(CliError::io_out))?;
    let lerc = lerc::lerc_zstd_bytes(&p.samples, p.e_min);
    if let Some(l) = lerc {
        config.notice(&lerc::line(&p.name, bytes.len(), l, &format!("{}", p.e_min)));
    }
    if let Some(input_bytes) =
        Input::from_arg(&args.input).path().and_then(|p| std::fs::metadata(p).ok()).map(|m| m.len())
    {
        if bytes.len() as u64 >= input_bytes {
            config.notice(&format!(
                "notice: the T-mesh ({} bytes) is not smaller than the input raster file ({input_bytes} bytes){}",
                bytes.len(),
                if Encoding::for_path(args.output.as_deref()) == Encoding::Xml {
                    "; -o NAME.tmb writes the compact binary form"
                } else {
                    ""
                }
            ));
        }
    }
    let lerc_ratio = lerc.map(|l| bytes.len() as f64 / l as f64);
    Ok(OutputReport { stored, lerc_zstd_bytes: lerc, lerc_ratio })
}
