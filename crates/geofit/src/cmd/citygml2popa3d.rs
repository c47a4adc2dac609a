//! `geofit citygml2popa3d`: CityGML buildings → a normalized popa3d model with generated conditions
//! (spec §3, §8.2 step 1 and step 5).

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cmd::args::{require_positive, InputOutput, NormalizeArgs};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use normalize::conditions::{ConditionCounts, ConditionOptions};
use normalize::convert::{convert_buildings, model_for, select_buildings, BuildingOptions, BuildingReport, Conversion};
use normalize::{Counts, Rejection, Tolerances};

const AFTER_HELP: &str = "\
Example:
  geofit citygml2popa3d FZK-Haus-LoD2.gml -o haus.popa3d --report haus.json
  geofit citygml2popa3d tile.gml --id DENW39AL10003Yy0 | geofit adjust - -o adjusted.popa3d

Each Building / BuildingPart with geometry becomes one closed solid: points within --snap become
nodes, edges are shared through half-edges, every face gets a least-squares plane; parallel normals
(within --normal-angle) and coplanar planes (within --plane-distance) are merged, so nodes are plane
intersections. Conditions are generated as for measured CityGML buildings: parallelism and
orthogonality between normals within --parallel-angle / --orthogonal-angle, coplanarity (distance 0)
between parallel planes of the same semantic type closer than --epsilon, wall-window distances kept
at their source value even below --epsilon, unit-norm conditions, and weak identity observations of
every plane distance and normal parameter (the soft datum).

Coordinates are reduced to a local origin (the envelope centre, rounded to metres) written into the
document. Every node keeps the polygon gml:id, ring and vertex index it came from.

Buildings that cannot be converted (open shell, MultiSurface-only geometry that does not close,
rings with < 3 distinct points, faces far from planar, nodes without 3 independent planes) are
listed on stderr with rule and gml:id; the others are still converted and the exit code is 1.

Units: coordinates and every tolerance are metres of a projected CRS. A file in a geographic CRS
(EPSG:4979, 4326, 4258, CRS84 ...: degrees) is refused in one line (exit 2) naming the CRS and
the UTM zone to reproject to, e.g.
  $ geofit citygml2popa3d wgs84.gml
  geofit: wgs84.gml: CRS EPSG:4979 is geographic (EPSG:4979, degrees, latitude,
  longitude): ... reproject the file to a projected CRS first, e.g. EPSG:32632 ...";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP, mut_arg("input", |a| a.help("CityGML file (1.0, 2.0 or 3.0), `-` for stdin")), mut_arg("output", |a| a.help("Output popa3d document (stdout when missing or `-`)")))]
pub struct Args {
    #[command(flatten)]
    pub io: InputOutput,
    /// Convert only the building(s) with this gml:id (repeatable).
    #[arg(long = "id")]
    pub ids: Vec<String>,
    /// Highest LoD to read (the best solid ≤ this LoD is used).
    #[arg(long, default_value_t = 4)]
    pub lod: u8,
    #[command(flatten)]
    pub normalize: NormalizeArgs,
    /// Generate parallelism conditions for normals within this angle of parallel (degrees).
    #[arg(long, default_value_t = 2.0)]
    pub parallel_angle: f64,
    /// Generate orthogonality conditions for normals within this angle of orthogonal (degrees).
    #[arg(long, default_value_t = 2.0)]
    pub orthogonal_angle: f64,
    /// ε: parallel planes of the same semantic type closer than this become coplanar (m).
    #[arg(long, default_value_t = 0.2)]
    pub epsilon: f64,
    /// σ of generated angle conditions (cosine units).
    #[arg(long, default_value_t = 1e-4)]
    pub sigma_angle: f64,
    /// σ of coplanarity and wall-window distances (m).
    #[arg(long, default_value_t = 0.001)]
    pub sigma_distance: f64,
    /// σ of the identity observations of plane distances (soft datum, m).
    #[arg(long, default_value_t = 0.1)]
    pub sigma_identity_d: f64,
    /// σ of the identity observations of normal parameters (soft datum).
    #[arg(long, default_value_t = 0.05)]
    pub sigma_identity_param: f64,
    /// σ of unit-norm pseudo-observations; without it they are restrictions.
    #[arg(long)]
    pub sigma_norm: Option<f64>,
    /// Write no conditions (topology and geometry only).
    #[arg(long)]
    pub no_conditions: bool,
    /// Write a JSON report (counts per building, conditions, rejections) to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
}

/// `--report`: what was converted, per building.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-citygml2popa3d-report/1",
    units: &[
        ("origin", "CRS units (subtracted from every coordinate)"),
        ("tolerances.snap", "m"),
        ("tolerances.planarity", "m"),
        ("tolerances.normal_angle_deg", "deg"),
        ("total.max_node_shift", "m"),
        ("buildings[].counts.max_node_shift", "m"),
    ],
};

#[derive(Serialize)]
struct Report {
    input: String,
    origin: [f64; 3],
    tolerances: Tolerances,
    conditions: ConditionOptions,
    converted: usize,
    rejected: Vec<Rejection>,
    total: Counts,
    buildings: Vec<BuildingReport>,
}

fn condition_options(args: &Args) -> Result<ConditionOptions, CliError> {
    require_positive(&[
        ("parallel-angle", args.parallel_angle),
        ("orthogonal-angle", args.orthogonal_angle),
        ("epsilon", args.epsilon),
        ("sigma-angle", args.sigma_angle),
        ("sigma-distance", args.sigma_distance),
        ("sigma-identity-d", args.sigma_identity_d),
        ("sigma-identity-param", args.sigma_identity_param),
    ])?;
    if let Some(s) = args.sigma_norm {
        require_positive(&[("sigma-norm", s)])?;
    }
    Ok(ConditionOptions {
        parallel_deg: args.parallel_angle,
        orthogonal_deg: args.orthogonal_angle,
        epsilon: args.epsilon,
        sigma_angle: args.sigma_angle,
        sigma_distance: args.sigma_distance,
        sigma_identity_d: args.sigma_identity_d,
        sigma_identity_param: args.sigma_identity_param,
        sigma_norm: args.sigma_norm,
    })
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let tol = args.normalize.tolerances()?;
    let copt = condition_options(&args)?;
    let input = Input::from_arg(&args.io.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let city = citygml_io::parse(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    // docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41
    if let Some(g) = citygml_io::frame::geographic_document(&city, None) {
        return Err(CliError::usage(format!(
            "{name}: {}: --snap, --plane-distance and the adjustment are metres; reproject the file to a projected CRS first, e.g. {} (citygml-tools reproject)",
            g.what(),
            g.suggestion()
        )));
    }
    let units = select_buildings(&city, &args.ids).map_err(|e| CliError::usage(format!("{name}: {e}")))?;
    if units.is_empty() {
        return Err(CliError::findings(format!("{name}: no Building or BuildingPart with geometry")));
    }
    let mut model = model_for(&city, &name);
    let origin = model.origin;
    let progress = config.progress("citygml2popa3d", units.len() as u64);
    let options = BuildingOptions { lod: args.lod, tolerances: tol, conditions: (!args.no_conditions).then_some(copt) };
    let done = convert_buildings(&mut model, &units, &options, &|i, id| progress.set(i as u64 + 1, id));
    progress.finish(&format!("{} converted, {} rejected", done.buildings.len(), done.rejected.len()));
    let total = Counts::sum(&name, done.buildings.iter().map(|r| &r.counts));
    if !config.quiet {
        print_summary(&total, &done);
    }
    for r in &done.rejected {
        crate::say!("geofit: rejected: {r}");
    }
    if !done.buildings.is_empty() {
        let out = Output::from_arg(args.io.output.as_deref());
        out.write_with(|w| popa3d_model::write(&model, w).map_err(|e| CliError::internal(e.to_string())))?;
    }
    let (converted, rejected) = (done.buildings.len(), done.rejected);
    if let Some(p) = &args.report {
        let report = Report {
            input: name.clone(),
            origin,
            tolerances: tol,
            conditions: copt,
            converted,
            rejected: rejected.clone(),
            total,
            buildings: done.buildings,
        };
        write_json_report(p, &REPORT, &report)?;
    }
    if rejected.is_empty() {
        Ok(Exit::Ok)
    } else {
        if units.len() == rejected.len() {
            crate::say!("geofit: error: {name}: no building could be converted");
        }
        Ok(Exit::Findings)
    }
}

/// The counts table, the generated conditions and every notice on stderr.
fn print_summary(total: &Counts, done: &Conversion) {
    crate::config::stderr_str(&total.table());
    let cc = ConditionCounts::sum(done.buildings.iter().map(|r| &r.conditions));
    crate::say!(
        "conditions: parallelism {}, coplanarity {}, orthogonality {}, wall-window {}, identity {}, normal-norm {}",
        cc.parallelism,
        cc.coplanarity,
        cc.orthogonality,
        cc.wall_window,
        cc.identity,
        cc.norm
    );
    for r in &done.buildings {
        for n in &r.notices {
            crate::say!("geofit: notice: {}: {}: {}: {}", r.id, n.rule, n.element, n.message);
        }
    }
}
