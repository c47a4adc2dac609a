//! `geofit heal`: CityGML → popa3d → adjustment → CityGML in one process, for LoD2 data that fails
//! planarity checks (spec §8.2 as one command).

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cmd::args::{require_non_negative, require_positive};
use crate::config::{write_json_report, Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use adjust::popa3d::{adjust_model, DatumChoice, ModelOptions};
use normalize::conditions::{self, ConditionOptions, Ranges};
use normalize::to_citygml::{to_citygml_with, BackReport, Template};
use normalize::Tolerances;
use popa3d_model::{Popa3d, SourceDocument};

const AFTER_HELP: &str = "\
Example:
  geofit heal LoD2_tile.gml -o LoD2_tile.healed.gml --report heal.json
  geofit validate LoD2_tile.healed.gml

Each building is converted to popa3d (planes instead of points: every face becomes exactly
planar), conditions are generated from geometry and semantics (parallelism, orthogonality,
coplanarity below --epsilon, weak identity observations as soft datum), the model is adjusted, and
the node coordinates are written back into the file as plane intersections. Everything that is not
geometry is copied unchanged. Buildings that cannot be converted or adjusted are left as they are
and listed (exit 1). The report gives the vertex moves (largest, mean); --max-move makes a larger
move an error for that building (it is then left unchanged).";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// CityGML file, `-` for stdin.
    pub input: String,
    /// Output CityGML (stdout when missing or `-`).
    #[arg(short, long)]
    pub output: Option<String>,
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
    /// healing should make faces planar with the least change, not square the building; on the
    /// NRW tiles even 0.05° moves some roof vertices by more than 5 cm.
    #[arg(long, default_value_t = 0.0)]
    pub angle: f64,
    /// Buildings whose vertices would move further than this are left unchanged (m).
    #[arg(long, default_value_t = 0.05)]
    pub max_move: f64,
    /// Do not merge coplanar polygons.
    #[arg(long)]
    pub no_merge: bool,
    /// Write a JSON report to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
}

#[derive(Serialize, Clone)]
struct Skipped {
    building: String,
    reason: String,
}

#[derive(Serialize)]
struct Report {
    input: String,
    buildings: usize,
    healed: usize,
    skipped: Vec<Skipped>,
    back: BackReport,
}

/// One building into `model` (normalized, no conditions yet): its element ranges.
fn convert(b: &citygml_io::CityObject, model: &mut Popa3d, a: &Args) -> Result<Ranges, String> {
    let tol = Tolerances { snap: a.snap, planarity: a.planarity, ..Tolerances::default() };
    let soup = normalize::citygml::building_soup(b, a.lod).map_err(|r| r.to_string())?;
    let before = (model.faces.len(), model.planes.len(), model.normals.len(), model.parameters.len());
    normalize::normalize_into(model, &soup, &tol).map_err(|r| r.to_string())?;
    Ok(Ranges {
        faces: before.0..model.faces.len(),
        planes: before.1..model.planes.len(),
        normals: before.2..model.normals.len(),
        parameters: before.3..model.parameters.len(),
    })
}

fn condition_options(a: &Args) -> ConditionOptions {
    ConditionOptions { parallel_deg: a.angle, orthogonal_deg: a.angle, epsilon: a.epsilon, ..ConditionOptions::default() }
}

fn model_opts() -> ModelOptions {
    let mut mo = ModelOptions { datum: DatumChoice::Soft, ..ModelOptions::default() };
    mo.engine.statistics = false;
    mo.engine.unknown_sigmas = false;
    mo
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    require_positive(&[("snap", args.snap), ("planarity", args.planarity), ("max-move", args.max_move)])?;
    require_non_negative(&[("epsilon", args.epsilon), ("angle", args.angle)])?;
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let city = citygml_io::parse(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    let origin = normalize::citygml::local_origin(&city);
    let units: Vec<&citygml_io::CityObject> =
        normalize::citygml::buildings(&city).into_iter().filter(|b| normalize::citygml::has_own_geometry(b)).collect();
    if units.is_empty() {
        return Err(CliError::findings(format!("{name}: no Building or BuildingPart with geometry")));
    }
    let back_opts = super::popa3d2citygml::back_options(1e-3, 1e-6, 1e-6, args.no_merge)?;
    // the document's polygons indexed once, for every building's dry run and the final write
    let template = Template::new(&bytes, &city);
    let progress = config.progress("heal", units.len() as u64);
    // Pass 1: each building alone (convert, adjust, back-transform dry run): keep the good ones.
    let mut good: Vec<usize> = Vec::new();
    let mut skipped: Vec<Skipped> = Vec::new();
    for (i, b) in units.iter().enumerate() {
        let bid = b.id.clone().unwrap_or_else(|| format!("Building@{}:{}", b.span.line, b.span.column));
        progress.set(i as u64 + 1, &bid);
        let mut m = Popa3d::new(origin);
        let res = convert(b, &mut m, &args)
            .map(|r| {
                conditions::semantic(&mut m, &r, &condition_options(&args));
            })
            .and_then(|_| adjust_model(&mut m, &model_opts()).map(|_| ()).map_err(|e| e.to_string()))
            .and_then(|_| to_citygml_with(&m, &template, &back_opts, false).map_err(|e| e.to_string()))
            .and_then(|(_, r)| if r.max_move > args.max_move { Err(format!("a vertex would move {:.3} m (> --max-move {})", r.max_move, args.max_move)) } else { Ok(()) });
        match res {
            Ok(()) => good.push(i),
            Err(reason) => skipped.push(Skipped { building: bid, reason }),
        }
    }
    progress.finish(&format!("{} healed, {} left unchanged", good.len(), skipped.len()));
    // Pass 2: all good buildings in one model (independent components), one write-back.
    let mut model = Popa3d::new(origin);
    model.srs_name = city.srs_name.clone();
    model.source = Some(SourceDocument { format: "citygml".into(), file: name.clone() });
    let mut ranges = Vec::with_capacity(good.len());
    for &i in &good {
        ranges.push(convert(units[i], &mut model, &args).map_err(|e| CliError::internal(format!("{name}: second conversion failed: {e}")))?);
    }
    // conditions once all are in (the incidence and node positions are built once)
    conditions::semantic_many(&mut model, &ranges, &condition_options(&args));
    let (out, back) = if good.is_empty() {
        (bytes.clone(), BackReport::default())
    } else {
        adjust_model(&mut model, &model_opts()).map_err(|e| CliError::internal(format!("{name}: {e}")))?;
        to_citygml_with(&model, &template, &back_opts, true).map_err(|e| super::popa3d2citygml::back_error(&name, e))?
    };
    if !config.quiet {
        super::popa3d2citygml::print_back(&back);
        for s in &skipped {
            eprintln!("geofit: left unchanged: {}: {}", s.building, s.reason);
        }
    }
    Output::from_arg(args.output.as_deref()).write_bytes(&out)?;
    if let Some(p) = &args.report {
        write_json_report(p, &Report { input: name, buildings: units.len(), healed: good.len(), skipped: skipped.clone(), back })?;
    }
    Ok(if skipped.is_empty() { Exit::Ok } else { Exit::Findings })
}
