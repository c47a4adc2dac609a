//! `geofit implicit`: implicit surfaces by Discrete Smooth Interpolation (DSI) on adaptive
//! tetrahedral meshes (seed 003). One step (`geofit implicit POINTS -o SURFACE`) or the stages
//! `interpolate`, `update`, `iso`, `section`, `csg`.

use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use implicit::contour::{self, CsgOp, Surface};
use implicit::dsi::{Weights, DEFAULT_ROUGHNESS};
use implicit::fault::{self, Fault};
use implicit::model::{self, BuildOptions, BuildReport, Event, Model};
use implicit::points::{self, DataPoint, SidePoint};
use serde::Serialize;

use crate::config::{Config, Input, Output};
use crate::report::{write_json_report, ReportKind};
use crate::error::{CliError, CmdResult, Exit};

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
    #[command(after_long_help = "Example:\n  geofit implicit interpolate horizons.csv --fault f.obj -o model.gfim --vtk field.vtk")]
    Interpolate(InterpolateArgs),
    /// Move or add constraints and re-interpolate (base + float constraints, warm-started CG).
    #[command(after_long_help = "Example (move data point 17 to new world coordinates, in metres):\n  geofit implicit update model.gfim --move 17,550600,7821900,-9730 -o moved.gfim")]
    Update(UpdateArgs),
    /// Iso-surfaces of a saved model by marching tetrahedra.
    #[command(after_long_help = "Example:\n  geofit implicit iso model.gfim --value 60 --value 250 -o horizons.glb")]
    Iso(IsoArgs),
    /// Cross-section of a saved model by a plane, coloured by φ or the model's attribute.
    #[command(after_long_help = "Example (a horizontal section at z = -9800 m):\n  geofit implicit section model.gfim --plane z=-9800 -o section.obj")]
    Section(SectionArgs),
    /// Union, intersection or difference of two models (min/max of their fields).
    #[command(after_long_help = "Example:\n  geofit implicit csg a.gfim b.gfim --op difference -o a_minus_b.glb")]
    Csg(CsgArgs),
    /// Writes synthetic test data with known truth (noisy sphere, plane, faulted layers).
    #[command(hide = true)]
    Generate(GenerateArgs),
}

#[derive(ClapArgs, Clone)]
pub struct BuildArgs {
    /// Points: XYZ/CSV (`-` = stdin) or LAS/LAZ.
    #[arg(value_name = "POINTS", required = true)]
    pub points: Option<String>,
    /// Side points `x y z ±1` (φ > 0 / φ < 0 there) orienting φ where there are no normals.
    #[arg(long, value_name = "FILE")]
    pub side_points: Option<String>,
    /// Give every point without a normal the normal (0, 0, 1): terrain/bathymetry, φ > 0 above.
    #[arg(long)]
    pub up_normals: bool,
    /// Fault surface as OBJ; repeat for several faults.
    #[arg(long, value_name = "OBJ")]
    pub fault: Vec<String>,
    /// A second scalar attribute `x y z v` interpolated on the same mesh, shown as vertex colours.
    #[arg(long, value_name = "FILE")]
    pub attribute: Option<String>,
    /// Finest cell size near the data (default: from the point density).
    #[arg(long)]
    pub cell: Option<f64>,
    /// Coarse cubes along the longest side of the domain.
    #[arg(long, default_value_t = 8)]
    pub coarse: usize,
    /// Relative weight ϖ of the value constraints φ = v at the points (dimensionless).
    #[arg(long, default_value_t = 1.0)]
    pub w_value: f64,
    /// Relative weight ϖ of the normal / side inequality constraints.
    #[arg(long, default_value_t = 1.0)]
    pub w_normal: f64,
    /// Relative weight ϖ_r of the roughness constraints: higher = smoother (dimensionless).
    /// Default: from the points' noise σ̂ (local quadric fits) and the finest cell h,
    /// ϖ_r = √((σ̂/h)² + 0.02²)/0.04 (5 for a unit sphere with σ = 0.03).
    #[arg(long)]
    pub w_rough: Option<f64>,
    /// Step δ along and against each normal (default: the finest cell size).
    #[arg(long)]
    pub step: Option<f64>,
    /// Gradient magnitude g the normal constraints ask for (default: fitted to the values, else 1).
    #[arg(long)]
    pub grad: Option<f64>,
    /// CG relative residual tolerance.
    #[arg(long, default_value_t = 1e-6)]
    pub tol: f64,
    /// CG iteration cap per solve.
    #[arg(long, default_value_t = 20000)]
    pub max_iter: usize,
    /// Cap on active-set rounds of the inequality constraints (each round is one CG solve).
    #[arg(long, default_value_t = 8)]
    pub rounds: usize,
    /// Misfit-driven refinement rounds (interpolate, measure, refine, re-interpolate).
    #[arg(long, default_value_t = 1)]
    pub refine: usize,
    /// Misfit (distance units) above which the mesh is refined at a point (default: cell/2).
    #[arg(long)]
    pub misfit_tol: Option<f64>,
    /// Also write the field on the mesh as a VTK unstructured grid (legacy ASCII).
    #[arg(long, value_name = "PATH")]
    pub vtk: Option<String>,
    /// Write a JSON report (sizes, CG iterations, misfit) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

#[derive(ClapArgs, Clone)]
pub struct RunArgs {
    #[command(flatten)]
    pub build: BuildArgs,
    /// Output surface (.obj or .glb; stdout = OBJ).
    #[arg(short, long, value_name = "SURFACE")]
    pub output: Option<String>,
    /// Iso-value(s) to extract (default: 0, or each distinct data value up to 16 of them).
    #[arg(long = "iso", value_name = "V")]
    pub iso: Vec<f64>,
    /// Also save the model.
    #[arg(long, value_name = "PATH")]
    pub model: Option<String>,
}

#[derive(ClapArgs)]
pub struct InterpolateArgs {
    #[command(flatten)]
    pub build: BuildArgs,
    /// Output model file (`.gfim`: mesh, constraints and solution, read by update/iso/section/csg).
    #[arg(short, long, value_name = "MODEL")]
    pub output: Option<String>,
}

#[derive(ClapArgs)]
pub struct UpdateArgs {
    /// Saved model.
    pub model: String,
    /// Points to add as float constraints (same formats as POINTS).
    #[arg(long, value_name = "FILE")]
    pub add: Option<String>,
    /// Move constraint I to X,Y,Z (world coordinates); repeatable. I = 0-based index of the point
    /// among the input data rows (duplicates merged), then side points, then added points.
    #[arg(long = "move", value_name = "I,X,Y,Z")]
    pub moves: Vec<String>,
    /// Start CG from zero instead of the saved solution (for comparison).
    #[arg(long)]
    pub cold: bool,
    /// Output model (default: stdout).
    #[arg(short, long, value_name = "MODEL")]
    pub output: Option<String>,
    /// Also write the updated field on the mesh as a VTK unstructured grid (legacy ASCII).
    #[arg(long, value_name = "PATH")]
    pub vtk: Option<String>,
    /// Write a JSON report (constraints, CG iterations, misfit) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

#[derive(ClapArgs)]
pub struct IsoArgs {
    /// Saved model (`.gfim`).
    pub model: String,
    /// Iso-value(s) (default: 0, or each distinct constraint value up to 16).
    #[arg(long = "value", value_name = "V")]
    pub values: Vec<f64>,
    /// Output (.obj or .glb; stdout = OBJ).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Vertex colours: from the model's attribute (`auto`: when it has one), from φ, or none.
    #[arg(long, value_enum, default_value_t = Colour::Auto)]
    pub colour: Colour,
    /// Write a JSON report (triangles per iso-value, area) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

#[derive(Copy, Clone, PartialEq, Eq, ValueEnum)]
pub enum Colour {
    Auto,
    Attribute,
    Phi,
    None,
}

#[derive(ClapArgs)]
pub struct SectionArgs {
    /// Saved model (`.gfim`).
    pub model: String,
    /// The plane: `x=V`, `y=V`, `z=V` or `PX,PY,PZ,NX,NY,NZ` (point and normal, world coordinates).
    #[arg(long)]
    pub plane: String,
    /// Colour by the model's attribute instead of φ.
    #[arg(long)]
    pub attribute: bool,
    /// Output section (.obj or .glb; stdout = OBJ).
    #[arg(short, long)]
    pub output: Option<String>,
}

#[derive(ClapArgs)]
pub struct CsgArgs {
    /// First saved model (`.gfim`).
    pub a: String,
    /// Second saved model (`.gfim`); both fields are sampled on a common mesh one level finer than either.
    pub b: String,
    /// The operation: union (min φ), intersection (max φ) or difference (max(φa, −φb)).
    #[arg(long, value_enum)]
    pub op: Op,
    /// Output surface of the combined φ = 0 (.obj or .glb; stdout = OBJ).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Also write the combined field as a VTK unstructured grid (legacy ASCII).
    #[arg(long, value_name = "PATH")]
    pub vtk: Option<String>,
    /// Write a JSON report (triangles, area) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

#[derive(Copy, Clone, PartialEq, Eq, ValueEnum)]
pub enum Op {
    Union,
    Intersection,
    Difference,
}

#[derive(ClapArgs)]
pub struct GenerateArgs {
    #[arg(value_enum)]
    pub shape: Shape,
    #[arg(long, default_value_t = 4000)]
    pub n: usize,
    /// Gaussian position noise σ.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Normal noise (degrees, standard deviation).
    #[arg(long, default_value_t = 0.0)]
    pub normal_noise: f64,
    #[arg(long, default_value_t = 1.0)]
    pub radius: f64,
    /// Sphere centre X,Y,Z.
    #[arg(long, default_value = "0,0,0")]
    pub center: String,
    /// Fault throw (faulted).
    #[arg(long, default_value_t = 10.0)]
    pub throw: f64,
    /// Write the fault surface here (faulted).
    #[arg(long)]
    pub fault_obj: Option<String>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(short, long)]
    pub output: Option<String>,
}

#[derive(Copy, Clone, PartialEq, Eq, ValueEnum)]
pub enum Shape {
    Sphere,
    Plane,
    Faulted,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    match args.command {
        None => run_one_step(args.run, config),
        Some(Sub::Run(a)) => run_one_step(a, config),
        Some(Sub::Interpolate(a)) => interpolate(a, config),
        Some(Sub::Update(a)) => update(a, config),
        Some(Sub::Iso(a)) => iso(a, config),
        Some(Sub::Section(a)) => section(a, config),
        Some(Sub::Csg(a)) => csg(a, config),
        Some(Sub::Generate(a)) => generate(a),
    }
}

// ---------- shared helpers ----------

fn lib_err(name: &str, e: implicit::Error) -> CliError {
    match e {
        implicit::Error::Parse { .. } => CliError::unreadable(e.to_string()),
        implicit::Error::Model(m) => CliError::unreadable(format!("{name}: not a readable model file: {m}")),
        implicit::Error::NotConverged { .. } => CliError::findings(format!("{name}: {e}")),
        _ => CliError::findings(format!("{name}: {e}")),
    }
}

fn read_points(arg: &str) -> Result<Vec<DataPoint>, CliError> {
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

fn read_model(arg: &str) -> Result<Model, CliError> {
    let input = Input::from_arg(arg);
    let bytes = input.read_all()?;
    Model::from_bytes(&bytes).map_err(|e| lib_err(&input.display_name(), e))
}

fn forward(config: &Config) -> impl FnMut(Event) + '_ {
    move |ev| match ev {
        Event::Stage(s) => config.notice(s),
        Event::Cg { round, iterations, residual } => {
            config.notice(&format!("  CG round {round}: {iterations} iterations, relative residual {residual:.2e}"))
        }
    }
}

/// Lengths of the implicit models are in the units of the input points' coordinates.
const LENGTH: &str = "CRS units of the points";

/// `implicit interpolate --report`.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-report/1",
    units: &[
        ("cell", LENGTH),
        ("misfit_mean", LENGTH),
        ("misfit_max", LENGTH),
        ("noise_sigma", LENGTH),
        ("seconds", "s"),
        ("cpu_seconds", "s"),
    ],
};

#[derive(Serialize)]
struct Report {
    points: usize,
    duplicates_merged: usize,
    cell: f64,
    vertices: usize,
    tetrahedra: usize,
    refinement_rounds: usize,
    cg_iterations: Vec<usize>,
    cg_iterations_total: usize,
    misfit_mean: f64,
    misfit_max: f64,
    gradient_scale: f64,
    /// Estimated noise of the value points across their surface (distance units; null: not estimated).
    noise_sigma: Option<f64>,
    /// Roughness weight ϖ_r used (from the noise unless --w-rough was given).
    w_rough: f64,
    seconds: f64,
    /// CPU seconds of the same span, all threads (Linux; null elsewhere): less load-dependent.
    cpu_seconds: Option<f64>,
}

/// CPU seconds (user + system, all threads) this process has used so far: Linux
/// `/proc/self/stat` fields 14 and 15, in USER_HZ = 100 ticks per second; None elsewhere.
fn process_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name (which may contain spaces).
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let (u, k): (f64, f64) = (f.get(11)?.parse().ok()?, f.get(12)?.parse().ok()?);
    Some((u + k) / 100.0)
}

/// Wall-clock and CPU seconds of a build.
#[derive(Clone, Copy)]
struct Timing {
    wall: f64,
    cpu: Option<f64>,
}

fn build_model(b: &BuildArgs, config: &Config) -> Result<(Model, BuildReport, Timing), CliError> {
    let t0 = std::time::Instant::now();
    let cpu0 = process_cpu_seconds();
    let name = b.points.clone().unwrap_or_else(|| "-".into());
    let mut pts = read_points(&name)?;
    if b.up_normals {
        for p in &mut pts {
            if p.normal.is_none() {
                p.normal = Some([0.0, 0.0, 1.0]);
            }
        }
    }
    let sides: Vec<SidePoint> = match &b.side_points {
        Some(s) => {
            let input = Input::from_arg(s);
            points::parse_side_points(&input.read_all()?, &input.display_name()).map_err(|e| lib_err(s, e))?
        }
        None => Vec::new(),
    };
    let mut faults: Vec<Fault> = Vec::new();
    for f in &b.fault {
        let input = Input::from_arg(f);
        faults.push(fault::read_fault_obj(&input.read_all()?, f, [0.0; 3]).map_err(|e| lib_err(f, e))?);
    }
    // Without --w-rough the library derives ϖ_r from the data (DEFAULT_ROUGHNESS only where the
    // noise cannot be estimated).
    let rough = b.w_rough.unwrap_or(DEFAULT_ROUGHNESS);
    for (w, n) in [(b.w_value, "--w-value"), (b.w_normal, "--w-normal"), (rough, "--w-rough"), (b.tol, "--tol")] {
        if !(w >= 0.0 && w.is_finite()) {
            return Err(CliError::usage(format!("{n} must be a finite non-negative number, got {w}")));
        }
    }
    let opt = BuildOptions {
        cell: b.cell,
        coarse: b.coarse,
        weights: Weights { value: b.w_value, normal: b.w_normal, rough },
        auto_rough: b.w_rough.is_none(),
        step: b.step,
        grad: b.grad,
        tol: b.tol,
        max_iter: b.max_iter,
        refine_rounds: b.refine,
        rounds: b.rounds,
        misfit_tol: b.misfit_tol,
        ..Default::default()
    };
    let mut fwd = forward(config);
    let (mut m, rep) = model::build(&pts, &sides, &faults, &opt, &mut fwd).map_err(|e| lib_err(&name, e))?;
    if let Some(a) = &b.attribute {
        let apts = read_points(a)?;
        m.interpolate_attribute(a, &apts).map_err(|e| lib_err(a, e))?;
    }
    config.notice(&format!(
        "{} points, cell {:.4}, roughness weight {:.3}: {} vertices, {} tetrahedra; CG iterations {:?}; misfit at the values mean {:.4} max {:.4}",
        rep.points, rep.cell, rep.w_rough, rep.vertices, rep.tetrahedra, rep.cg_iterations, rep.misfit_mean, rep.misfit_max
    ));
    let cpu = match (cpu0, process_cpu_seconds()) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    Ok((m, rep, Timing { wall: t0.elapsed().as_secs_f64(), cpu }))
}

fn write_report(path: &Option<String>, rep: &BuildReport, secs: Timing) -> Result<(), CliError> {
    if let Some(p) = path {
        let r = Report {
            points: rep.points,
            duplicates_merged: rep.duplicates_merged,
            cell: rep.cell,
            vertices: rep.vertices,
            tetrahedra: rep.tetrahedra,
            refinement_rounds: rep.refinement_rounds,
            cg_iterations_total: rep.cg_iterations.iter().sum(),
            cg_iterations: rep.cg_iterations.clone(),
            misfit_mean: rep.misfit_mean,
            misfit_max: rep.misfit_max,
            gradient_scale: rep.grad,
            noise_sigma: rep.noise_sigma,
            w_rough: rep.w_rough,
            seconds: secs.wall,
            cpu_seconds: secs.cpu,
        };
        write_json_report(p, &REPORT, &r)?;
    }
    Ok(())
}

fn write_vtk(path: &Option<String>, m: &Model) -> Result<(), CliError> {
    let Some(p) = path else { return Ok(()) };
    let mut fields: Vec<(&str, &[f64])> = vec![("phi", &m.phi)];
    if let Some((_, a)) = &m.attribute {
        fields.push(("attribute", a));
    }
    Output::from_arg(Some(p)).write_with(|w| implicit::vtk::write_vtk(w, &m.mesh, m.origin, &fields).map_err(CliError::io_out))
}

/// Default iso-values: 0, or the distinct constraint values (≤ 16) for stratigraphic data.
fn default_isos(m: &Model) -> Vec<f64> {
    let mut v: Vec<f64> = m.constraints.iter().filter_map(|c| c.value).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() > 1 && v.len() <= 16 {
        v
    } else {
        vec![0.0]
    }
}

/// Blue → white → red colour ramp over [lo, hi].
fn ramp(v: f64, lo: f64, hi: f64) -> [f32; 4] {
    let t = if hi > lo { ((v - lo) / (hi - lo)).clamp(0.0, 1.0) } else { 0.5 } as f32;
    if t < 0.5 {
        let s = t * 2.0;
        [0.23 + 0.77 * s, 0.30 + 0.70 * s, 0.75 + 0.25 * s, 1.0]
    } else {
        let s = (t - 0.5) * 2.0;
        [1.0 - 0.3 * s, 1.0 - 0.985 * s, 1.0 - 0.85 * s, 1.0]
    }
}

fn write_surfaces(out: &Option<String>, parts: &[(String, Surface)], config: &Config) -> Result<(), CliError> {
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
            mesh.colors = Some(sc.iter().map(|&v| ramp(v, lo, hi)).collect());
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

fn iso_parts(m: &Model, values: &[f64], colour: Colour) -> Vec<(String, Surface)> {
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

// ---------- subcommands ----------

fn run_one_step(a: RunArgs, config: &Config) -> CmdResult {
    if a.build.points.is_none() {
        return Err(CliError::usage("missing POINTS (see `geofit implicit --help`)"));
    }
    let ext = Output::from_arg(a.output.as_deref()).extension();
    if !matches!(ext.as_deref(), None | Some("obj") | Some("glb")) {
        return Err(CliError::usage(format!("-o: unknown surface format `.{}`: use .obj or .glb", ext.unwrap_or_default())));
    }
    let (m, rep, secs) = build_model(&a.build, config)?;
    let isos = if a.iso.is_empty() { default_isos(&m) } else { a.iso.clone() };
    let parts = iso_parts(&m, &isos, Colour::Auto);
    write_surfaces(&a.output, &parts, config)?;
    if let Some(p) = &a.model {
        Output::from_arg(Some(p)).write_bytes(&m.to_bytes())?;
    }
    write_vtk(&a.build.vtk, &m)?;
    write_report(&a.build.report, &rep, secs)?;
    Ok(Exit::Ok)
}

fn interpolate(a: InterpolateArgs, config: &Config) -> CmdResult {
    let (m, rep, secs) = build_model(&a.build, config)?;
    Output::from_arg(a.output.as_deref()).write_bytes(&m.to_bytes())?;
    write_vtk(&a.build.vtk, &m)?;
    write_report(&a.build.report, &rep, secs)?;
    Ok(Exit::Ok)
}

/// `implicit update --report`.
const UPDATE_REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-update-report/1",
    units: &[("misfit_mean", LENGTH), ("misfit_max", LENGTH), ("seconds", "s")],
};

#[derive(Serialize)]
struct UpdateReport {
    warm_start: bool,
    cg_iterations: Vec<usize>,
    cg_iterations_total: usize,
    float_constraints: usize,
    misfit_mean: f64,
    misfit_max: f64,
    seconds: f64,
}

fn update(a: UpdateArgs, config: &Config) -> CmdResult {
    let t0 = std::time::Instant::now();
    let mut m = read_model(&a.model)?;
    let added = match &a.add {
        Some(p) => read_points(p)?,
        None => Vec::new(),
    };
    let mut moves = Vec::new();
    for s in &a.moves {
        let f: Vec<&str> = s.split(',').map(|x| x.trim()).collect();
        let bad = || CliError::usage(format!("--move `{s}`: expected I,X,Y,Z (constraint index and new world position)"));
        if f.len() != 4 {
            return Err(bad());
        }
        let i: usize = f[0].parse().map_err(|_| bad())?;
        let p: Vec<f64> = f[1..].iter().map(|x| x.parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
        if p.iter().any(|x| !x.is_finite()) {
            return Err(bad());
        }
        moves.push((i, [p[0], p[1], p[2]]));
    }
    if added.is_empty() && moves.is_empty() && !a.cold {
        return Err(CliError::usage("nothing to update: give --add FILE and/or --move I,X,Y,Z"));
    }
    let mut fwd = forward(config);
    let sol = m.update(&added, &moves, a.cold, &mut fwd).map_err(|e| lib_err(&a.model, e))?;
    let loc = m.locator();
    let (mean, max) = m.misfit(&loc);
    let total: usize = sol.iterations.iter().sum();
    config.notice(&format!(
        "re-interpolated ({} start): CG iterations {:?} (total {total}); misfit mean {mean:.4} max {max:.4}",
        if a.cold { "cold" } else { "warm" },
        sol.iterations
    ));
    Output::from_arg(a.output.as_deref()).write_bytes(&m.to_bytes())?;
    write_vtk(&a.vtk, &m)?;
    if let Some(p) = &a.report {
        write_json_report(
            p,
            &UPDATE_REPORT,
            &UpdateReport {
                warm_start: !a.cold,
                cg_iterations: sol.iterations.clone(),
                cg_iterations_total: total,
                float_constraints: m.constraints.iter().filter(|c| c.float).count(),
                misfit_mean: mean,
                misfit_max: max,
                seconds: t0.elapsed().as_secs_f64(),
            },
        )?;
    }
    Ok(Exit::Ok)
}

/// `implicit iso --report`.
const ISO_REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-iso-report/1",
    units: &[("value", LENGTH), ("area", "CRS units squared"), ("volume", "CRS units cubed")],
};

#[derive(Serialize)]
struct IsoReport {
    value: f64,
    triangles: usize,
    vertices: usize,
    area: f64,
    closed: bool,
    volume: Option<f64>,
}

fn iso(a: IsoArgs, config: &Config) -> CmdResult {
    let m = read_model(&a.model)?;
    if a.colour == Colour::Attribute && m.attribute.is_none() {
        return Err(CliError::usage(format!("--colour attribute: {} has no attribute (interpolate with --attribute FILE)", a.model)));
    }
    let values = if a.values.is_empty() { default_isos(&m) } else { a.values.clone() };
    let parts = iso_parts(&m, &values, a.colour);
    write_surfaces(&a.output, &parts, config)?;
    if let Some(p) = &a.report {
        let r: Vec<IsoReport> = parts
            .iter()
            .zip(&values)
            .map(|((_, s), &v)| {
                let closed = s.is_closed();
                IsoReport { value: v, triangles: s.tris.len(), vertices: s.positions.len(), area: s.area(), closed, volume: closed.then(|| s.volume().abs()) }
            })
            .collect();
        write_json_report(p, &ISO_REPORT, &r)?;
    }
    Ok(Exit::Ok)
}

fn parse_plane(s: &str) -> Result<([f64; 3], [f64; 3]), CliError> {
    let bad = || CliError::usage(format!("--plane `{s}`: use x=V, y=V, z=V or PX,PY,PZ,NX,NY,NZ"));
    if let Some((axis, v)) = s.split_once('=') {
        let v: f64 = v.trim().parse().map_err(|_| bad())?;
        let k = match axis.trim() {
            "x" | "X" => 0,
            "y" | "Y" => 1,
            "z" | "Z" => 2,
            _ => return Err(bad()),
        };
        let mut p = [0.0; 3];
        let mut n = [0.0; 3];
        p[k] = v;
        n[k] = 1.0;
        return if v.is_finite() { Ok((p, n)) } else { Err(bad()) };
    }
    let f: Vec<f64> = s.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
    if f.len() != 6 || f.iter().any(|x| !x.is_finite()) {
        return Err(bad());
    }
    let n = implicit::geom::normalize([f[3], f[4], f[5]]).ok_or_else(bad)?;
    Ok(([f[0], f[1], f[2]], n))
}

fn section(a: SectionArgs, config: &Config) -> CmdResult {
    let (p, n) = parse_plane(&a.plane)?;
    let m = read_model(&a.model)?;
    if a.attribute && m.attribute.is_none() {
        return Err(CliError::usage(format!("--attribute: {} has no attribute", a.model)));
    }
    let s = contour::section(&m, p, n, a.attribute);
    if s.tris.is_empty() {
        return Err(CliError::findings(format!("the plane {} does not cross the model's domain", a.plane)));
    }
    write_surfaces(&a.output, &[("section".to_string(), s)], config)?;
    Ok(Exit::Ok)
}

/// `implicit csg --report`.
const CSG_REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-csg-report/1",
    units: &[("area", "CRS units squared"), ("volume", "CRS units cubed")],
};

#[derive(Serialize)]
struct CsgReport {
    op: &'static str,
    triangles: usize,
    closed: bool,
    volume: f64,
    area: f64,
}

fn csg(a: CsgArgs, config: &Config) -> CmdResult {
    let ma = read_model(&a.a)?;
    let mb = read_model(&a.b)?;
    let (op, name) = match a.op {
        Op::Union => (CsgOp::Union, "union"),
        Op::Intersection => (CsgOp::Intersection, "intersection"),
        Op::Difference => (CsgOp::Difference, "difference"),
    };
    let (s, mesh, field) = contour::csg(&ma, &mb, op);
    let closed = s.is_closed();
    let volume = s.volume().abs();
    config.notice(&format!("{name}: {} triangles, closed {closed}, volume {volume:.6}", s.tris.len()));
    if let Some(p) = &a.vtk {
        Output::from_arg(Some(p)).write_with(|w| {
            implicit::vtk::write_vtk(w, &mesh, ma.origin, &[("phi", &field)]).map_err(CliError::io_out)
        })?;
    }
    if let Some(p) = &a.report {
        write_json_report(p, &CSG_REPORT, &CsgReport { op: name, triangles: s.tris.len(), closed, volume, area: s.area() })?;
    }
    write_surfaces(&a.output, &[(name.to_string(), s)], config)?;
    Ok(Exit::Ok)
}

fn generate(a: GenerateArgs) -> CmdResult {
    use implicit::generate as g;
    let c: Vec<f64> = a.center.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| CliError::usage("--center: expected X,Y,Z"))?;
    if c.len() != 3 {
        return Err(CliError::usage("--center: expected X,Y,Z"));
    }
    let text = match a.shape {
        Shape::Sphere => g::to_text(&g::sphere(a.n, [c[0], c[1], c[2]], a.radius, a.noise, a.normal_noise, a.seed), false),
        Shape::Plane => g::to_text(&g::plane(a.n, 2.0 * a.radius, a.noise, a.normal_noise, a.seed), false),
        Shape::Faulted => {
            let (pts, f) = g::faulted(a.n / 3, &[-20.0, 0.0, 20.0], a.throw, a.noise, a.seed);
            if let Some(p) = &a.fault_obj {
                Output::from_arg(Some(p)).write_bytes(g::fault_obj(&f).as_bytes())?;
            }
            g::to_text(&pts, true)
        }
    };
    Output::from_arg(a.output.as_deref()).write_bytes(text.as_bytes())?;
    Ok(Exit::Ok)
}
