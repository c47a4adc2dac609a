//! `geofit heal`: make the faces of CityGML buildings planar without making any building worse
//! (spec §8.2 as one command; the algorithm and its guard live in the `heal` crate).

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cmd::args::{require_non_negative, require_positive, InputOutput};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use heal::{HealError, HealOptions, HealReport};
use normalize::conditions::ConditionOptions;
use normalize::to_citygml::BackOptions;
use normalize::Tolerances;

const AFTER_HELP: &str = "\
Example:
  geofit heal LoD2_tile.gml -o LoD2_tile.healed.gml --report heal.json
  geofit validate LoD2_tile.healed.gml

Each building (or building part) is turned into planes (every face becomes exactly planar) about
its own reference point, adjusted with weak identity observations so every plane stays near its
measured place, and its vertices are written back as plane intersections. Everything that is not
geometry is copied byte for byte; unchanged numbers keep their text, new ones the most decimals
the input file uses (or --precision).

Do no harm: the healed file is read back and every building validated and measured again. A
building keeps its original geometry when healing would give it a validation finding it did not
have (e.g. an open shell), change its surface area by more than --max-area-change percent, or
move its surface further than --max-move metres (Hausdorff: no input vertex farther from the
healed surface, no healed vertex farther from the input surface). Coplanar polygons merge only
within one thematic surface type, and never so that a polygon or surface with a gml:id or
attributes disappears. A building counts as healed when its geometry was rewritten and its
validation findings fell. Such buildings are named on stderr and in the
report; the output is complete and the exit code 0. With --strict any kept building is an error
(exit 1, no output written). A file in a geographic CRS (degrees) is refused: the tolerances are
metres.

Exit codes: 0 written (see the report for kept buildings); 1 --strict and a building was kept, or
no building with geometry; 2 bad options or a geographic CRS; 3 unreadable input; 4 internal.";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP, mut_arg("input", |a| a.help("CityGML file, `-` for stdin")), mut_arg("output", |a| a.help("Output CityGML (stdout when missing or `-`)")))]
pub struct Args {
    #[command(flatten)]
    pub io: InputOutput,
    /// Highest LoD to read.
    #[arg(long, default_value_t = 4)]
    pub lod: u8,
    /// Snap tolerance for nodes (m).
    #[arg(long, default_value_t = 0.001)]
    pub snap: f64,
    /// Reject faces further than this from planar (m).
    #[arg(long, default_value_t = 0.1)]
    pub planarity: f64,
    /// ε: parallel planes of the same semantic type closer than this become coplanar (m).
    /// Default 0: healing makes faces planar with the least change; normalization already merges
    /// planes within 1 mm.
    #[arg(long, default_value_t = 0.0)]
    pub epsilon: f64,
    /// Parallelism / orthogonality conditions within this angle (degrees). Default 0 (none):
    /// healing should make faces planar with the least change, not square the building.
    #[arg(long, default_value_t = 0.0)]
    pub angle: f64,
    /// A building whose vertices would move further than this keeps its geometry (m).
    #[arg(long, default_value_t = 0.05)]
    pub max_move: f64,
    /// A building whose surface area would change by more than this keeps its geometry (percent).
    #[arg(long, default_value_t = 0.5)]
    pub max_area_change: f64,
    /// Decimals of rewritten coordinates (default: the most the input file uses).
    #[arg(long)]
    pub precision: Option<usize>,
    /// Do not merge coplanar polygons.
    #[arg(long)]
    pub no_merge: bool,
    /// Any building that keeps its original geometry is an error: exit 1 and no output.
    #[arg(long)]
    pub strict: bool,
    /// Write a JSON report to this path (`-` = stdout, only when the data goes to -o).
    #[arg(long)]
    pub report: Option<String>,
}

/// `--report`: what healing changed and what it kept (`tile report` sums these).
const REPORT: ReportKind = ReportKind {
    schema: "geofit-heal-report/1",
    units: &[
        ("area_before_m2", "m2"),
        ("area_after_m2", "m2"),
        ("back.max_move", "m"),
        ("back.mean_move", "m"),
        ("back.max_move_by_building.*", "m"),
        ("moved_by_building_m.*", "m"),
        ("max_moved_m", "m"),
    ],
};

#[derive(Serialize)]
struct Report<'a> {
    input: String,
    #[serde(flatten)]
    heal: &'a HealReport,
}

fn options(a: &Args) -> Result<HealOptions, CliError> {
    require_positive(&[("snap", a.snap), ("planarity", a.planarity), ("max-move", a.max_move)])?;
    require_non_negative(&[("epsilon", a.epsilon), ("angle", a.angle), ("max-area-change", a.max_area_change)])?;
    let d = HealOptions::default();
    Ok(HealOptions {
        lod: a.lod,
        tolerances: Tolerances { snap: a.snap, planarity: a.planarity, ..Tolerances::default() },
        conditions: ConditionOptions {
            parallel_deg: a.angle,
            orthogonal_deg: a.angle,
            epsilon: a.epsilon,
            ..d.conditions
        },
        back: BackOptions { merge: !a.no_merge, precision: a.precision, ..BackOptions::default() },
        max_move: a.max_move,
        max_area_change: a.max_area_change / 100.0,
        validation: d.validation,
    })
}

fn heal_error(name: &str, e: HealError) -> CliError {
    match e {
        HealError::Unreadable(m) => CliError::unreadable(format!("{name}: {m}")),
        HealError::NoBuildings => CliError::findings(format!("{name}: {e}")),
        HealError::Geographic { .. } => CliError::usage(format!("{name}: {e}")),
        HealError::Internal(_) => CliError::internal(format!("{name}: {e}")),
    }
}

fn print_summary(r: &HealReport) {
    let pct = if r.area_before_m2 > 0.0 { 100.0 * (r.area_after_m2 / r.area_before_m2 - 1.0) } else { 0.0 };
    crate::say!(
        "heal: {} of {} buildings healed (geometry rewritten and validation findings fell), {} only rewritten (made planar), {} unchanged, {} kept as they were; {} → {} without any finding; surface area {:.1} → {:.1} m² ({pct:+.3} %); largest move {:.4} m (Hausdorff, input vertices to healed surface and back)",
        r.healed,
        r.buildings,
        r.changed - r.healed,
        r.buildings - r.changed - r.kept.len(),
        r.kept.len(),
        r.valid_before,
        r.valid_after,
        r.area_before_m2,
        r.area_after_m2,
        r.max_moved_m
    );
    for k in &r.kept {
        crate::say!("heal: kept {}: {}", k.building, k.reason);
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let opts = options(&args)?;
    let output = Output::from_arg(args.io.output.as_deref());
    output.check_target()?;
    crate::config::check_report_target(args.report.as_deref(), args.io.output.as_deref())?;
    let input = Input::from_arg(&args.io.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let progress = config.progress("heal", 0);
    // no message per building: on a terminal the bar counts, elsewhere one summary line
    let healed = heal::heal(&bytes, &opts, &|n| progress.set(n as u64, "")).map_err(|e| heal_error(&name, e))?;
    progress.finish("buildings adjusted and verified");
    let r = &healed.report;
    // A file whose every building is kept for what the reader refuses heals nothing: it is
    // refused as every other command refuses it (a non-finite coordinate: exit 3; an XLink to
    // nothing: exit 1), not "0 of 1 healed" with exit 0. Defects in some buildings of a file whose
    // others heal keep only their buildings (docs/decisions.md#messages-and-refusals-of-issue-40).
    if r.healed == 0 {
        if let Some(d) = healed.defects.bad_numbers.first() {
            return Err(CliError::unreadable(format!("{name}:{d}; nothing healed")));
        }
        if let Some(d) = healed.defects.unresolved_xlinks.first() {
            return Err(CliError::findings(format!("{name}:{d}; nothing healed")));
        }
    }
    if !config.quiet {
        print_summary(r);
    }
    if args.strict && !r.kept.is_empty() {
        return Err(CliError::findings(format!(
            "{name}: --strict: {} building(s) would keep their original geometry (first: {}: {}); nothing written",
            r.kept.len(),
            r.kept[0].building,
            r.kept[0].reason
        )));
    }
    crate::config::encoding::write_document(&output, &healed.document)?;
    if let Some(p) = &args.report {
        write_json_report(p, &REPORT, &Report { input: name, heal: r })?;
    }
    Ok(Exit::Ok)
}
