//! `geofit popa3d2citygml`: write an (adjusted) popa3d model back into the user's original CityGML
//! file (spec §8.2 step 3). The algorithm lives in `normalize::to_citygml`.

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cmd::args::{require_non_negative, require_positive};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use heal::{HealError, HealOptions, WriteBackError};
use normalize::to_citygml::{BackError, BackOptions, BackReport};

const AFTER_HELP: &str = "\
Example:
  geofit citygml2popa3d b.gml | geofit adjust - | geofit popa3d2citygml - --template b.gml -o out.gml

The template is the original CityGML file: everything that is not geometry is copied byte for
byte. The provenance in the popa3d document (polygon gml:id, ring, vertex index of every node)
says which coordinates each node maps to; new coordinates are plane intersections. Planes on one
normal closer than --coplanar-tolerance become one plane; polygons that lost their area are removed
with every reference to them; touching coplanar polygons of the same semantic type are merged and
the openings of a surface left empty move to the surface keeping the merged polygon (--no-merge
keeps every polygon); a polygon or surface with a gml:id or attributes is never merged away. A
template that does not match the provenance is an error naming the node and polygon.

Every write-back verifies itself, like heal: the written document is read back and every
building validated and measured again. A building that would get a validation finding it did not
have (e.g. an open shell), change its surface area by more than --max-area-change percent, or
move further than --max-move metres (Hausdorff: an input vertex from the written surface, or a
written vertex from the input surface) keeps its original geometry. Without --keep that is an
error naming the buildings (exit 1, nothing written); with --keep the output is written with
those buildings as they were, they are named on stderr, and the exit code is 0. Unchanged numbers
keep their text; new ones get the most decimals the input file uses (or --precision).

Exit codes: 0 written; 1 a building failed the verification (without --keep), or the model does
not fit the template; 2 bad options; 3 unreadable input; 4 internal.";

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
    /// Largest move accepted (m, Hausdorff distance per building); a building moving further fails the verification.
    #[arg(long, default_value_t = 0.05)]
    pub max_move: f64,
    /// Largest change of a building's surface area accepted (percent).
    #[arg(long, default_value_t = 0.5)]
    pub max_area_change: f64,
    /// Write the output even when buildings fail the verification: those keep their original geometry and are named on stderr (exit 0).
    #[arg(long)]
    pub keep: bool,
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
        ("moved_by_building_m.*", "m"),
    ],
};

#[derive(Serialize)]
struct Report<'a> {
    template: String,
    options: &'a BackOptions,
    #[serde(flatten)]
    result: &'a BackReport,
    /// The verification: buildings kept as they were, with the reason.
    kept: &'a [heal::Kept],
    moved_by_building_m: &'a std::collections::BTreeMap<String, f64>,
}

fn back_options(a: &Args) -> Result<BackOptions, CliError> {
    require_positive(&[
        ("coplanar-tolerance", a.coplanar_tolerance),
        ("collapse-tolerance", a.collapse_tolerance),
        ("area-tolerance", a.area_tolerance),
        ("max-move", a.max_move),
    ])?;
    Ok(BackOptions {
        coplanar_tolerance: a.coplanar_tolerance,
        collapse_tolerance: a.collapse_tolerance,
        area_tolerance: a.area_tolerance,
        merge: !a.no_merge,
        precision: a.precision,
    })
}

/// The error of the conversion back, its message bounded: the provenance checks repeat ids of
/// the popa3d input (a polygon id of 100 MB came back whole), so the message is cut like any
/// quote of the input (`input_limits`, at 800 bytes: the message around the ids stays whole).
fn write_back_error(template: &str, e: WriteBackError) -> CliError {
    match e {
        WriteBackError::Back(b) => back_error(template, b),
        WriteBackError::Heal(HealError::Unreadable(m)) => CliError::unreadable(format!("{template}: {m}")),
        WriteBackError::Heal(h @ HealError::Internal(_)) => CliError::internal(format!("{template}: {h}")),
        WriteBackError::Heal(h) => CliError::findings(format!("{template}: {h}")),
    }
}

/// The options of the verification: heal's validation tolerances, this command's limits.
fn verify_options(a: &Args) -> Result<HealOptions, CliError> {
    require_non_negative(&[("max-area-change", a.max_area_change)])?;
    Ok(HealOptions { max_move: a.max_move, max_area_change: a.max_area_change / 100.0, ..HealOptions::default() })
}

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
    let vopts = verify_options(&args)?;
    let output = Output::from_arg(args.output.as_deref());
    output.check_target()?;
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let model = popa3d_model::read(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    let tin = Input::from_arg(&args.template);
    let tname = tin.display_name();
    let tbytes = tin.read_all()?;
    let (healed, report) = heal::write_back(&model, &tbytes, &opts, &vopts).map_err(|e| write_back_error(&tname, e))?;
    if !config.quiet {
        print_back(&report);
    }
    let kept = &healed.report.kept;
    if !kept.is_empty() {
        let ids: Vec<&str> = kept.iter().take(10).map(|k| k.building.as_str()).collect();
        let more = if kept.len() > 10 { ", ..." } else { "" };
        if !args.keep {
            return Err(CliError::findings(format!(
                "{tname}: {} building(s) fail the verification of the write-back: {}{more} (first: {}: {}); nothing written (--keep writes them as they were)",
                kept.len(),
                ids.join(", "),
                kept[0].building,
                kept[0].reason
            )));
        }
        // --keep: named on stderr even with -q, the output is only right with them in mind
        for k in kept {
            crate::say!("popa3d2citygml: kept {} as it was: {}", k.building, k.reason);
        }
    }
    output.write_bytes(&healed.document)?;
    if let Some(p) = &args.report {
        write_json_report(
            p,
            &REPORT,
            &Report {
                template: tname,
                options: &opts,
                result: &report,
                kept,
                moved_by_building_m: &healed.report.moved_by_building_m,
            },
        )?;
    }
    Ok(Exit::Ok)
}
