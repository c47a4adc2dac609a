//! `geofit diff`: compares two rasters (spec §4.2, §9.1 item 24): mean, σ, median, max and RMS
//! of |Δz|, cells over a tolerance, a histogram over error classes (1 cm … 2 m by default) and
//! an error-class map as PNG, as in the thesis' figures. The statistics come from
//! `raster_proc::diff::compare`; definitions (which cells, σ, median, class bounds) are
//! documented there.

use std::io::Write;

use clap::Args as ClapArgs;

use raster_io::Raster;
use raster_picture::{aux_xml, bar_chart, sidecar_paths, world_file, Canvas};
use raster_proc::diff::{class_map_rgba, compare_with_map, DiffOptions, DiffReport, DEFAULT_CLASS_BOUNDS};
use raster_proc::diff_figures::{error_map, histogram_chart};

use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{print_report_with_units, with_z_unit, write_json_report_with_units, ReportKind, Z_UNIT};
use crate::terrain_io::{gdal_notices, proc_err, read_raster_arg, z_unit_of};

const EXAMPLE: &str = "\
Example:
  $ geofit diff bathy.tif surface.tif --tolerance 0.5 --png errors.png --hist hist.png
  cells compared  401233 (only in A 0, only in B 1822)
  |dz| mean       0.0812   sigma 0.0950   median 0.0511   max 1.2040   RMS 0.1250
  signed mean     -0.0031
  over 0.5        1022 (0.25 %)
  class [0, 0.01)         61243  15.26 %
  ...
  $ geofit diff a.tif b.tif --json | jq .rms

Δz = B − A over the cells valid in both; B is resampled bilinearly onto A's grid when the grids
differ. Classes are given by their upper bounds (--classes 0.01,0.02,0.05,...), the last class
is open. The map PNG has one pixel per cell of A, coloured green (small) to red (large) by
class, grey where only one raster has a value, transparent where neither has; a title above and
a legend to the right name the classes in --z-unit. Beside it go a world file (errors.pgw) and
errors.png.aux.xml with A's CRS, so GDAL and QGIS place the map (the title and legend lie
outside the map's footprint); --plain writes the bare map. The histogram PNG is a bar chart with
axes, in % of the compared cells. Exit 1 with --check when any cell is over --tolerance; exit 3
for unreadable input.";

#[derive(ClapArgs, Debug)]
#[command(about = "Compare two rasters: |dz| statistics, error classes, error-class map PNG", after_help = EXAMPLE)]
pub struct Args {
    /// Reference raster A (`-` = stdin).
    pub a: String,
    /// Raster B compared against A.
    pub b: String,
    /// Cells with |dz| above this count as over tolerance.
    #[arg(long, default_value_t = 1.0)]
    pub tolerance: f64,
    /// Error-class upper bounds, comma separated, strictly increasing.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_CLASS_BOUNDS.to_vec())]
    pub classes: Vec<f64>,
    /// Write the JSON report to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
    /// Write the error-class map (A's grid, with title and legend) as PNG, plus its world
    /// file (.pgw) and .aux.xml with the CRS.
    #[arg(long)]
    pub png: Option<String>,
    /// The map PNG without title and legend: one pixel per cell, for overlays in a GIS.
    #[arg(long, requires = "png")]
    pub plain: bool,
    /// Write the class histogram as a PNG bar chart with axes.
    #[arg(long)]
    pub hist: Option<String>,
    /// Unit of the heights (m, km, cm, ft, us-ft, ...), for legends and the report's units;
    /// default: the unit the rasters declare (B is converted into A's when they differ), else m.
    /// --tolerance and --classes are in this unit.
    #[arg(long, value_name = "UNIT")]
    pub z_unit: Option<String>,
    /// Print the report as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Exit 1 when any cell is over the tolerance.
    #[arg(long)]
    pub check: bool,
}

/// `--report` / `--json`: the comparison's statistics.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-diff-report/1",
    units: &[
        ("width", "cells"),
        ("height", "cells"),
        ("mean_abs", Z_UNIT),
        ("std_abs", Z_UNIT),
        ("median_abs", Z_UNIT),
        ("max_abs", Z_UNIT),
        ("rms", Z_UNIT),
        ("mean_signed", Z_UNIT),
        ("max_at", "[column, row] of A"),
        ("tolerance", Z_UNIT),
        ("share_over_tolerance", "fraction of compared cells"),
        ("histogram[].from", Z_UNIT),
        ("histogram[].to", Z_UNIT),
        ("histogram[].share", "fraction of compared cells"),
    ],
};

fn png_bytes(c: &Canvas) -> Result<Vec<u8>, CliError> {
    c.to_png().map_err(|e| CliError::internal(e.to_string()))
}

/// The map picture and, when it is a file and A is georeferenced, its world file and CRS.
fn write_map(path: &str, a: &Raster, map: &Canvas, map_at: (usize, usize)) -> Result<(), CliError> {
    Output::from_arg(Some(path)).write_bytes(&png_bytes(map)?)?;
    let (pgw, aux) = sidecar_paths(std::path::Path::new(path));
    Output::from_arg(pgw.to_str()).write_bytes(world_file(a.geotransform, map_at.0, map_at.1).as_bytes())?;
    if let Some(wkt) = &a.crs {
        Output::from_arg(aux.to_str()).write_bytes(aux_xml(wkt).as_bytes())?;
    }
    Ok(())
}

fn base_name(arg: &str) -> &str {
    std::path::Path::new(arg).file_name().and_then(|n| n.to_str()).unwrap_or(arg)
}

/// Loads A. (A T-mesh evaluated on B's grid can be plugged in here.)
fn load_a(arg: &str) -> Result<(Raster, String), CliError> {
    read_raster_arg(arg)
}

/// The unit both rasters' heights are compared in: --z-unit, else what they declare (one that
/// declares none is taken to share the other's: an `eval` output of a mesh fitted on it), else m.
/// B's heights are converted into A's unit when the two declare different units.
fn common_unit(
    a: &Raster,
    name_a: &str,
    b: &mut Raster,
    name_b: &str,
    given: Option<&str>,
    config: &Config,
) -> Result<String, CliError> {
    let ua = z_unit_of(a, name_a, given)?;
    let ub = z_unit_of(b, name_b, given)?;
    if let (Some(ua), Some(ub)) = (ua, ub) {
        if ua.unit != ub.unit {
            let f = ub.unit.metres / ua.unit.metres;
            b.data.iter_mut().for_each(|v| *v *= f);
            config.notice(&format!("{name_b}: heights in {}, converted to {name_a}'s {}", ub.unit.name, ua.unit.name));
        }
    }
    Ok(match (given, ua.or(ub)) {
        (Some(g), _) => g.to_string(),
        (None, Some(u)) => u.unit.name.to_string(),
        (None, None) => "m".to_string(),
    })
}

fn print_text(w: &mut dyn Write, r: &DiffReport) -> std::io::Result<()> {
    writeln!(
        w,
        "cells compared  {} (only in A {}, only in B {}){}",
        r.cells_compared,
        r.only_in_a,
        r.only_in_b,
        if r.resampled { ", B resampled onto A's grid" } else { "" }
    )?;
    writeln!(
        w,
        "|dz| mean       {:.4}   sigma {:.4}   median {:.4}   max {:.4}   RMS {:.4}",
        r.mean_abs, r.std_abs, r.median_abs, r.max_abs, r.rms
    )?;
    // `+ 0.0` turns a rounding −0.0 into 0.0 for display
    writeln!(w, "signed mean     {:.4}", r.mean_signed + 0.0)?;
    if let Some([c, row]) = r.max_at {
        writeln!(w, "max at cell     col {c} row {row}")?;
    }
    writeln!(w, "over {:<10} {} ({:.2} %)", r.tolerance, r.over_tolerance, 100.0 * r.share_over_tolerance)?;
    for c in &r.histogram {
        let label = match c.to {
            Some(t) => format!("[{}, {})", c.from, t),
            None => format!(">= {}", c.from),
        };
        writeln!(w, "class {label:<16} {:>10}  {:6.2} %", c.count, 100.0 * c.share)?;
    }
    Ok(())
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    gdal_notices(config);
    let opts = DiffOptions { tolerance: args.tolerance, class_bounds: args.classes.clone() };
    opts.validate().map_err(|e| CliError::usage(e.to_string()))?;
    // stdout always carries the statistics (text, --json or --report -): a picture there would mix with them
    for (flag, p) in [("--png", &args.png), ("--hist", &args.hist)] {
        if p.as_deref() == Some("-") {
            return Err(CliError::usage(format!("{flag} -: stdout carries the statistics; give a file name")));
        }
    }
    if args.a == "-" && args.b == "-" {
        return Err(CliError::usage("only one of A and B can be stdin"));
    }
    let (a, name_a) = load_a(&args.a)?;
    let (mut b, name_b) = read_raster_arg(&args.b)?;
    let z_unit = common_unit(&a, &name_a, &mut b, &name_b, args.z_unit.as_deref(), config)?;
    let (report, classes) =
        compare_with_map(&a, &b, &opts).map_err(|e| proc_err(&format!("{name_a} vs {name_b}"), e))?;
    let units = with_z_unit(REPORT.units, &z_unit);
    let exit = if args.check && report.over_tolerance > 0 { Exit::Findings } else { Exit::Ok };
    // --check failing is a failed step: its pictures are not written (make) unless
    // --keep-partial; the statistics still are.
    let keep = |p: &str| config.keeps_output(exit, Some(p));
    if let Some(p) = args.png.as_deref().filter(|p| keep(p)) {
        if args.plain {
            let map = Canvas::from_rgba(a.width, a.height, class_map_rgba(&classes, opts.class_bounds.len() + 1));
            write_map(p, &a, &map, (0, 0))?;
        } else {
            let title = format!("{} vs {}", base_name(&args.a), base_name(&args.b));
            let framed = error_map(&report, &classes, &opts, &z_unit, &title);
            write_map(p, &a, &framed.canvas, (framed.map_x, framed.map_y))?;
        }
    }
    if let Some(p) = args.hist.as_deref().filter(|p| keep(p)) {
        Output::from_arg(Some(p)).write_bytes(&png_bytes(&bar_chart(&histogram_chart(&report, &z_unit)))?)?;
    }
    if let Some(p) = &args.report {
        write_json_report_with_units(p, &REPORT, &units, &report)?;
    }
    if args.json || args.report.as_deref() != Some("-") {
        print_report_with_units(args.json, &REPORT, &units, &report, |w| print_text(w, &report))?;
    }
    if exit == Exit::Findings {
        crate::say!(
            "geofit: {} of {} cells differ by more than {} (max {:.4} at col {} row {})",
            report.over_tolerance,
            report.cells_compared,
            report.tolerance,
            report.max_abs,
            report.max_at.map(|m| m[0]).unwrap_or(0),
            report.max_at.map(|m| m[1]).unwrap_or(0)
        );
        return Ok(Exit::Findings);
    }
    Ok(Exit::Ok)
}
