//! `geofit obj2popa3d`: an OBJ sketch of rooms → a popa3d model with sketch priors, plus measured
//! distances from a CSV (spec §8.1, the first use case).

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cmd::args::{require_positive, InputOutput, NormalizeArgs};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};
use normalize::conditions::{self, Ranges, SketchOptions};
use normalize::{Counts, Notice};
use popa3d_model::{Popa3d, SourceDocument};

const AFTER_HELP: &str = "\
Example:
  geofit obj2popa3d floor.obj --distances tape.csv -o floor.popa3d
  geofit obj2popa3d floor.obj | geofit adjust - -o floor-adjusted.popa3d

The sketch is drawn by eye in any modeller (SketchUp, Blender, FreeCAD) and exported as OBJ; each
object/group is a room (a closed solid); a wall drawn in both rooms becomes one shared face, named
after the room that comes first in the file (OBJECT/fK of that room). It is
normalized like CityGML input and gets the priors a sketch deserves (weak plane differences per
normal, relative normal angles, unit norms).

Distances CSV: `type,a,b,value,sigma` per line, `#` comments, optional header. type = `distance`
(or DistanceFaceFace, DistanceFaceEdge, ...). a, b = `face:ID`, `edge:ID`, `node:ID` (popa3d ids),
`v:N` (OBJ vertex N, 1-based), or `OBJECT/fK` (the K-th face of an OBJ object). Face-face,
face-edge and edge-edge distances add their induced parallelism constraint.

  # room width and height
  distance,room1/f3,room1/f4,4.012,0.001
  distance,room1/f1,room1/f2,2.745,0.001";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP, mut_arg("input", |a| a.help("OBJ sketch, `-` for stdin")), mut_arg("output", |a| a.help("Output popa3d document (stdout when missing or `-`)")))]
pub struct Args {
    #[command(flatten)]
    pub io: InputOutput,
    /// CSV of measured distances to attach.
    #[arg(long, visible_alias = "add")]
    pub distances: Option<String>,
    #[command(flatten)]
    pub normalize: NormalizeArgs,
    /// σ of the sketch plane differences (m).
    #[arg(long, default_value_t = 0.1)]
    pub sigma_plane_difference: f64,
    /// σ of the sketch relative normal angles (cosine units).
    #[arg(long, default_value_t = 0.001)]
    pub sigma_relative_angle: f64,
    /// σ of the unit-norm pseudo-observations.
    #[arg(long, default_value_t = 0.001)]
    pub sigma_norm: f64,
    /// σ of the angle constraints induced by distances (cosine units).
    #[arg(long, default_value_t = 1e-4)]
    pub sigma_induced: f64,
    /// Write a JSON report (counts, priors, distances) to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
}

/// `--report`: what was derived from the mesh.
const REPORT: ReportKind =
    ReportKind { schema: "geofit-obj2popa3d-report/1", units: &[("counts.max_node_shift", "m")] };

#[derive(Serialize)]
struct Report {
    input: String,
    counts: Counts,
    plane_differences: usize,
    relative_angles: usize,
    norms: usize,
    distances: usize,
    induced: usize,
    notices: Vec<Notice>,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let tol = args.normalize.tolerances()?;
    require_positive(&[
        ("sigma-plane-difference", args.sigma_plane_difference),
        ("sigma-relative-angle", args.sigma_relative_angle),
        ("sigma-norm", args.sigma_norm),
        ("sigma-induced", args.sigma_induced),
    ])?;
    let input = Input::from_arg(&args.io.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let soup = normalize::obj::read_sketch(&bytes, &name).map_err(|e| CliError::unreadable(e.to_string()))?;
    let mut model = Popa3d::new(normalize::obj::sketch_origin(&soup));
    model.source = Some(SourceDocument { format: "obj".into(), file: name.clone() });
    let n = normalize::normalize_into(&mut model, &soup, &tol)
        .map_err(|r| CliError::findings(format!("{name}: rejected: {r}")))?;
    let r = Ranges::whole(&model);
    let so = SketchOptions {
        sigma_plane_difference: args.sigma_plane_difference,
        sigma_relative_angle: args.sigma_relative_angle,
        sigma_norm: args.sigma_norm,
    };
    let (nd, na, nn) = conditions::sketch_priors(&mut model, &r, &so);
    let distances = match &args.distances {
        Some(csv) => read_distances(csv, &model)?,
        None => Vec::new(),
    };
    let (ndist, nind) = conditions::add_distances(&mut model, distances, args.sigma_induced);
    if !config.quiet {
        crate::config::stderr_str(&n.counts.table());
        crate::say!("sketch priors: {nd} plane differences, {na} relative angles, {nn} unit norms; {ndist} distances, {nind} induced constraints");
        for x in &n.notices {
            crate::say!("geofit: notice: {}: {}: {}", x.rule, x.element, x.message);
        }
    }
    let out = Output::from_arg(args.io.output.as_deref());
    out.write_with(|w| popa3d_model::write(&model, w).map_err(|e| CliError::internal(e.to_string())))?;
    if let Some(p) = &args.report {
        let rep = Report {
            input: name,
            counts: n.counts,
            plane_differences: nd,
            relative_angles: na,
            norms: nn,
            distances: ndist,
            induced: nind,
            notices: n.notices,
        };
        write_json_report(p, &REPORT, &rep)?;
    }
    Ok(Exit::Ok)
}

/// The measured distances of the `--distances` CSV, resolved against the model's elements.
fn read_distances(csv: &str, model: &Popa3d) -> Result<Vec<popa3d_model::Observation>, CliError> {
    let text = String::from_utf8(Input::from_arg(csv).read_all()?)
        .map_err(|_| CliError::unreadable(format!("{csv}: not UTF-8 text")))?;
    popa3d_model::csv::parse_distances(&text, model).map_err(|e| CliError::findings(format!("{csv}: {e}")))
}
