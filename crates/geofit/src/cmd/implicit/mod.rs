//! `geofit implicit`: implicit surfaces by Discrete Smooth Interpolation (DSI) on adaptive
//! tetrahedral meshes (seed 003). One step (`geofit implicit POINTS -o SURFACE`) or the stages
//! `interpolate`, `update`, `iso`, `section`, `csg`, one file each; this module holds what they
//! share: reading points and models, the library's errors as exit codes, writing surfaces.

mod build;
mod csg;
mod generate;
mod interpolate;
mod iso;
mod run;
mod section;
mod update;

use clap::{Args as ClapArgs, Subcommand};
use implicit::contour::{self, Surface};
use implicit::model::{Event, Model};
use implicit::points::{self, DataPoint};

use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult};

pub use csg::CsgArgs;
pub use generate::GenerateArgs;
pub use interpolate::InterpolateArgs;
pub use iso::{Colour, IsoArgs};
pub use run::RunArgs;
pub use section::SectionArgs;
pub use update::UpdateArgs;

const HELP: &str = "\
Implicit surfaces from scattered points by Discrete Smooth Interpolation (DSI) on an adaptive
tetrahedral mesh: value constraints φ = v at the points, inequality constraints φ > 0 / φ < 0 a
small step along and against each normal (or at side points), and a roughness constraint on the
gradient across the mesh graph, solved by preconditioned conjugate gradients. Faults (OBJ) cut
the mesh graph so φ jumps across them.

Points: XYZ/CSV `x y z [val] [nx ny nz]` (header or 3/4/6/7 columns; empty CSV fields = absent)
or LAS/LAZ (.las/.laz). Normals point to φ > 0. Without a value column every point is on φ = 0;
with one (stratigraphy, e.g. LoopStructural CSVs) each horizon is the iso-surface of its value.

Examples:
  geofit implicit generate sphere --noise 0.02 -o sphere.xyz
  geofit implicit sphere.xyz -o sphere.glb                     # one step: interpolate + φ = 0
  geofit implicit interpolate horizons.csv --fault f.obj -o model.gfim --vtk field.vtk
  geofit implicit iso model.gfim --value 60 --value 250 -o horizons.glb
  geofit implicit update model.gfim --move 17,550600,7821900,-9730 -o moved.gfim
  geofit implicit section model.gfim --plane z=-9800 -o section.obj
  geofit implicit csg a.gfim b.gfim --op difference -o a_minus_b.glb

The one-step form is also available as `geofit implicit run POINTS -o SURFACE`.";

#[derive(ClapArgs)]
#[command(
    about = "Implicit surfaces by DSI on adaptive tetrahedral meshes (reconstruct, update, iso, section, CSG)",
    after_long_help = HELP,
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true
)]
pub struct Args {
    #[command(subcommand)]
    pub command: Option<Sub>,
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Subcommand)]
pub enum Sub {
    /// Interpolate and write iso-surfaces in one step (same as the bare form).
    #[command(after_long_help = "Example:\n  geofit implicit run sphere.xyz -o sphere.glb --report report.json")]
    Run(RunArgs),
    /// Interpolate φ on an adaptive mesh and save the model (mesh, constraints, solution).
    #[command(
        after_long_help = "Example:\n  geofit implicit interpolate horizons.csv --fault f.obj -o model.gfim --vtk field.vtk"
    )]
    Interpolate(InterpolateArgs),
    /// Move or add constraints and re-interpolate (base + float constraints, warm-started CG).
    #[command(
        after_long_help = "Example (move data point 17 to new world coordinates, in metres):\n  geofit implicit update model.gfim --move 17,550600,7821900,-9730 -o moved.gfim"
    )]
    Update(UpdateArgs),
    /// Iso-surfaces of a saved model by marching tetrahedra.
    #[command(after_long_help = "Example:\n  geofit implicit iso model.gfim --value 60 --value 250 -o horizons.glb")]
    Iso(IsoArgs),
    /// Cross-section of a saved model by a plane, coloured by φ or the model's attribute.
    #[command(
        after_long_help = "Example (a horizontal section at z = -9800 m):\n  geofit implicit section model.gfim --plane z=-9800 -o section.obj"
    )]
    Section(SectionArgs),
    /// Union, intersection or difference of two models (min/max of their fields).
    #[command(after_long_help = "Example:\n  geofit implicit csg a.gfim b.gfim --op difference -o a_minus_b.glb")]
    Csg(CsgArgs),
    /// Writes synthetic test data with known truth (noisy sphere, plane, faulted layers).
    #[command(hide = true)]
    Generate(GenerateArgs),
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    match args.command {
        None => run::run(args.run, config),
        Some(Sub::Run(a)) => run::run(a, config),
        Some(Sub::Interpolate(a)) => interpolate::run(a, config),
        Some(Sub::Update(a)) => update::run(a, config),
        Some(Sub::Iso(a)) => iso::run(a, config),
        Some(Sub::Section(a)) => section::run(a, config),
        Some(Sub::Csg(a)) => csg::run(a, config),
        Some(Sub::Generate(a)) => generate::run(a),
    }
}

pub(super) fn lib_err(name: &str, e: implicit::Error) -> CliError {
    match e {
        implicit::Error::Parse { .. } => CliError::unreadable(e.to_string()),
        implicit::Error::Model(m) => CliError::unreadable(format!("{name}: not a readable model file: {m}")),
        implicit::Error::NotConverged { .. } => CliError::findings(format!("{name}: {e}")),
        _ => CliError::findings(format!("{name}: {e}")),
    }
}

pub(super) fn read_points(arg: &str) -> Result<Vec<DataPoint>, CliError> {
    let input = Input::from_arg(arg);
    let bytes = input.read_all()?;
    let name = input.display_name();
    let lower = arg.to_ascii_lowercase();
    if points::is_las(&bytes) || lower.ends_with(".las") || lower.ends_with(".laz") {
        points::read_las(bytes, &name).map_err(|e| lib_err(&name, e))
    } else {
        points::parse_xyz(&bytes, &name).map_err(|e| lib_err(&name, e))
    }
}

pub(super) fn read_model(arg: &str) -> Result<Model, CliError> {
    let input = Input::from_arg(arg);
    let bytes = input.read_all()?;
    Model::from_bytes(&bytes).map_err(|e| lib_err(&input.display_name(), e))
}

pub(super) fn forward(config: &Config) -> impl FnMut(Event) + '_ {
    move |ev| match ev {
        Event::Stage(s) => config.notice(s),
        Event::Cg { round, iterations, residual } => {
            config.notice(&format!("  CG round {round}: {iterations} iterations, relative residual {residual:.2e}"))
        }
    }
}

/// Lengths of the implicit models are in the units of the input points' coordinates.
pub(super) const LENGTH: &str = "CRS units of the points";

pub(super) fn write_vtk(path: &Option<String>, m: &Model) -> Result<(), CliError> {
    let Some(p) = path else { return Ok(()) };
    let mut fields: Vec<(&str, &[f64])> = vec![("phi", &m.phi)];
    if let Some((_, a)) = &m.attribute {
        fields.push(("attribute", a));
    }
    Output::from_arg(Some(p))
        .write_with(|w| implicit::vtk::write_vtk(w, &m.mesh, m.origin, &fields).map_err(CliError::io_out))
}

pub(super) fn write_surfaces(
    out: &Option<String>,
    parts: &[(String, Surface)],
    config: &Config,
) -> Result<(), CliError> {
    let output = Output::from_arg(out.as_deref());
    let (lo, hi) = parts
        .iter()
        .filter_map(|(_, s)| s.scalars.as_ref())
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let mut scene = mesh_export::Scene {
        materials: vec![mesh_export::Material::new("implicit", [0.8, 0.75, 0.6, 1.0])],
        generator: Some(format!("geofit {} implicit", env!("CARGO_PKG_VERSION"))),
        ..Default::default()
    };
    let mut total = 0;
    for (name, s) in parts {
        let mut node = mesh_export::MeshNode::new(name.clone());
        let mut mesh = mesh_export::TriangleMesh::new(Some(0));
        mesh.positions = s.positions.clone();
        mesh.indices = s.tris.iter().flatten().cloned().collect();
        if let Some(sc) = &s.scalars {
            mesh.colors = Some(sc.iter().map(|&v| mesh_export::colour::diverging(v, lo, hi)).collect());
        }
        total += s.tris.len();
        node.meshes.push(mesh);
        scene.nodes.push(node);
    }
    if total == 0 {
        config.notice("warning: the requested iso-surface / section is empty");
    }
    scene.origin = scene.auto_origin();
    let ext = output.extension();
    output.write_with(|w| {
        let r = match ext.as_deref() {
            Some("glb") => mesh_export::write_glb(&scene, w),
            Some("obj") | None => mesh_export::write_obj(&scene, w, None),
            Some(e) => return Err(CliError::usage(format!("unknown surface format `.{e}`: use .obj or .glb"))),
        };
        r.map_err(|e| CliError::internal(format!("writing the surface: {e}")))
    })
}

pub(super) fn iso_parts(m: &Model, values: &[f64], colour: Colour) -> Vec<(String, Surface)> {
    let attr: Option<&[f64]> = match (colour, &m.attribute) {
        (Colour::Auto | Colour::Attribute, Some((_, a))) => Some(a),
        (Colour::Phi, _) => Some(&m.phi),
        _ => None,
    };
    values
        .iter()
        .map(|&v| {
            let mut s = contour::iso_surface(&m.mesh, &m.phi, v, attr);
            s.translate(m.origin);
            (format!("iso_{v}"), s)
        })
        .collect()
}
