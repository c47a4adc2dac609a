//! `geofit popa3d2citygml`: write an (adjusted) popa3d model back into the user's original CityGML
//! file (spec §8.2 step 3). The algorithm lives in `normalize::to_citygml`.

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cmd::args::require_positive;
use crate::config::{Config, Input, Output};
use crate::report::{write_json_report, ReportKind};
use crate::error::{CliError, CmdResult, Exit};
use normalize::to_citygml::{to_citygml, BackError, BackOptions, BackReport};

const AFTER_HELP: &str = "\
Example:
  geofit citygml2popa3d b.gml | geofit adjust - | geofit popa3d2citygml - --template b.gml -o out.gml

The template is the original CityGML file: everything that is not geometry is copied byte for
byte. The provenance in the popa3d document (polygon gml:id, ring, vertex index of every node)
says which coordinates each node maps to; new coordinates are plane intersections. Planes on one
normal closer than --coplanar-tolerance become one plane; polygons that lost their area are removed
with every reference to them; touching coplanar polygons of the same semantic type are merged and
the openings of a surface left empty move to the surface keeping the merged polygon (--no-merge
keeps every polygon). A template that does not match the provenance is an error naming the node
and polygon. A vertex that would move further than --max-move metres (or by a non-finite amount)
is an error naming the buildings (exit 1, nothing written): an adjustment that moved a building
that far is not a correction. Unchanged numbers keep their text; new ones get the most decimals
the input file uses (or --precision).";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// popa3d document, `-` for stdin.
    pub input: String,
    /// The original CityGML file the model was converted from.
    #[arg(long)]
    pub template: String,
    /// Output CityGML (stdout when missing or `-`).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Planes on one normal closer than this become one plane (m).
    #[arg(long, default_value_t = 1e-3)]
    pub coplanar_tolerance: f64,
    /// Vertices closer than this are one vertex (m).
    #[arg(long, default_value_t = 1e-6)]
    pub collapse_tolerance: f64,
    /// Rings with a smaller area are degenerate and removed (m²).
    #[arg(long, default_value_t = 1e-6)]
    pub area_tolerance: f64,
    /// Do not merge coplanar polygons.
    #[arg(long)]
    pub no_merge: bool,
    /// Largest vertex move accepted (m); a larger one is an error naming the buildings.
    #[arg(long, default_value_t = 0.05)]
    pub max_move: f64,
    /// Decimals of rewritten coordinates (default: the most the input file uses).
    #[arg(long)]
    pub precision: Option<usize>,
    /// Write a JSON report (removed, merged, vertex moves) to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
}

/// `--report`: what writing the model back changed.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-popa3d2citygml-report/1",
    units: &[
        ("options.coplanar_tolerance", "m"),
        ("options.collapse_tolerance", "m"),
        ("options.area_tolerance", "m2"),
        ("max_move", "m"),
        ("mean_move", "m"),
        ("max_move_by_building.*", "m"),
    ],
};

#[derive(Serialize)]
struct Report<'a> {
    template: String,
    options: &'a BackOptions,
    #[serde(flatten)]
    result: &'a BackReport,
}

fn back_options(a: &Args) -> Result<BackOptions, CliError> {
    require_positive(&[("coplanar-tolerance", a.coplanar_tolerance), ("collapse-tolerance", a.collapse_tolerance), ("area-tolerance", a.area_tolerance), ("max-move", a.max_move)])?;
    Ok(BackOptions { coplanar_tolerance: a.coplanar_tolerance, collapse_tolerance: a.collapse_tolerance, area_tolerance: a.area_tolerance, merge: !a.no_merge, precision: a.precision })
}

/// The error of the conversion back, its message bounded: the provenance checks repeat ids of
/// the popa3d input (a polygon id of 100 MB came back whole), so the message is cut like any
/// quote of the input (`input_limits`, at 800 bytes: the message around the ids stays whole).
fn back_error(template: &str, e: BackError) -> CliError {
    let message = format!("{template}: {}", input_limits::quote_max(&e.to_string(), 800));
    match e {
        BackError::Write(_) => CliError::internal(message),
        _ => CliError::findings(message),
    }
}

fn print_back(r: &BackReport) {
    crate::say!(
        "popa3d2citygml: {} polygons mapped, {} removed (no area), {} merge(s), {} surface(s) removed, {} opening(s) moved; vertex moves: largest {:.6} m, mean {:.6} m over {} vertices",
        r.polygons_mapped,
        r.removed_degenerate.len(),
        r.merged.len(),
        r.removed_surfaces.len(),
        r.moved_openings.len(),
        r.max_move,
        r.mean_move,
        r.vertices_written
    );
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let opts = back_options(&args)?;
    let output = Output::from_arg(args.output.as_deref());
    output.check_target()?;
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let model = popa3d_model::read(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    let tin = Input::from_arg(&args.template);
    let tname = tin.display_name();
    let tbytes = tin.read_all()?;
    let city = citygml_io::parse(&tbytes).map_err(|e| CliError::unreadable(format!("{tname}: {e}")))?;
    let (out, report) = to_citygml(&model, &tbytes, &city, &opts).map_err(|e| back_error(&tname, e))?;
    if !config.quiet {
        print_back(&report);
    }
    if let Some(why) = report.moved_further_than(args.max_move) {
        return Err(CliError::findings(format!("{tname}: {why}; nothing written")));
    }
    output.write_bytes(&out)?;
    if let Some(p) = &args.report {
        write_json_report(p, &REPORT, &Report { template: tname, options: &opts, result: &report })?;
    }
    Ok(Exit::Ok)
}
