//! `geofit export`: CityGML buildings as triangle meshes (glb, glTF, OBJ) for viewers and CAD;
//! a T-mesh (`.tmesh`, recognised by its root element) is tessellated as `geofit surface` does it
//! (`crate::mesh_output`, shared by both commands).
//!
//! The CityGML → scene mapping lives here (which polygons, which node, which material); the
//! triangulation and the file formats are `mesh_export`'s.

use city_scene::{build_scene, Reproject, SceneOptions};
use citygml_io::crs::proj_crs;
use clap::Args as ClapArgs;
use mesh_export::Scene;
use serde::Serialize;

use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::mesh_output::{tessellate, write_scene, Format, SurfaceOptions};
use crate::report::{write_json_report, ReportKind};

mod options;
use options::checked_options;

const EXAMPLE: &str = "\
Example:
  $ geofit export LoD2_32_332_5729_1_NW.gml -o tile.glb
  $ geofit export FZK-Haus-LoD2.gml --lod 2 -o haus.obj        # also writes haus.mtl
  $ geofit export tile.gml --t-srs EPSG:4647 --origin 32332000,5729000,0 -o tile.gltf
  $ cat city.gml | geofit export - --format glb > city.glb
  $ geofit export bathy.tmesh -o bathy.glb --reference bathy.tif  # T-mesh: as `geofit surface`

What is exported: every top-level city object with polygons of the chosen LoD becomes one node
(glTF node / OBJ object) named by its gml:id; BuildingParts become child nodes (OBJ objects
`building/part`); boundary surfaces, openings, installations and rooms are merged into their
building's node, one mesh (glTF primitive / OBJ `usemtl` run) per semantic surface type, whose
material is named after it (WallSurface, RoofSurface, GroundSurface, ClosureSurface, Window, ...;
`Unclassified` without semantics). A polygon referenced by xlink:href (the faces of an NRW
lod2Solid) is exported once. Without --lod each object is exported at its highest LoD.

Polygons (holes included) are triangulated in their own plane (Newell normal, constrained
Delaunay); the triangles keep the original vertices, so neighbouring polygons still share
their edges (closed shells stay closed), and the polygon's orientation (`orientation=\"-\"`
flips it). Real data are not exactly planar (NRW tiles: up to 4 cm), so the mesh area is then
slightly larger than the polygons' projected (Newell) area; --planar moves each polygon's
vertices onto its plane instead (exact area, small gaps between neighbours). A polygon that cannot be triangulated (collinear, too few points)
is skipped and listed: exit 1, and the mesh is written only with --keep-partial (the report is).

Coordinates: --origin auto (default) subtracts the bounding-box centre (x, y) and bottom (z),
rounded to whole units; `none` keeps world coordinates; `x,y,z` gives it. The origin is recorded:
glTF root node `extras.origin` (f64; world = local + origin), OBJ header `# origin: x y z`.
glTF is Y-up: vertex data stay Z-up and the root node's matrix turns them. --t-srs reprojects x
and y with PROJ from the file's CRS (or --s-srs); heights are kept (metres), and a height system
the source CRS names goes along into the recorded CRS (`EPSG:4647+7837` for NRW's DHHN2016), so
`geofit tile tileset` knows it.
Units: mesh coordinates are metres. A file in a geographic CRS (EPSG:4979, 4326, CRS84...:
degrees, axis order as the CRS declares: latitude first for EPSG codes) needs a projected
--t-srs, else it is refused naming its UTM zone; a geographic --t-srs is refused too:
  $ geofit export wgs84.gml -o b.glb                 # exit 2: ... e.g. --t-srs EPSG:32632
  $ geofit export wgs84.gml --t-srs EPSG:32632 -o b.glb

T-mesh input (a geofit .tmesh, root element <tmesh>) is tessellated exactly as `geofit surface`
does it (same bytes): the surface with vertex colours by height or by |dz| against --reference,
the T-mesh cell edges as a second node; --step, --reference, --no-mask and --device apply, the
CityGML options do not.";

#[derive(ClapArgs, Debug)]
#[command(about = "Export CityGML buildings (or a T-mesh surface) as triangle meshes: glb, glTF or OBJ (+MTL)", after_help = EXAMPLE)]
pub struct Args {
    /// CityGML file (1.0, 2.0 or 3.0) or T-mesh, or `-` for stdin.
    pub input: String,
    /// Output file (.glb, .gltf, .obj); `-` or none = stdout (then --format is required).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Output format; default from the output file's extension.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// Level of detail to export (0-4); default: each object's highest.
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=4))]
    pub lod: Option<u8>,
    /// Target CRS for x and y (anything PROJ accepts, e.g. EPSG:4647).
    #[arg(long, value_name = "CRS")]
    pub t_srs: Option<String>,
    /// Source CRS, overriding the file's srsName (needed with --t-srs when the file has none).
    #[arg(long, value_name = "CRS")]
    pub s_srs: Option<String>,
    /// Local origin: `auto`, `none` or `x,y,z` (subtracted from every coordinate, recorded in the file).
    #[arg(long, default_value = "auto")]
    pub origin: String,
    /// Move each polygon's vertices onto its plane: the mesh area then equals the polygons'
    /// (Newell) area exactly, but shared edges of non-planar polygons no longer meet.
    #[arg(long)]
    pub planar: bool,
    /// glTF: write the binary buffer to OUT.bin beside OUT.gltf instead of embedding it.
    #[arg(long)]
    pub gltf_bin: bool,
    /// Write a JSON report (objects, polygons, triangles, area, skipped polygons) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
    #[command(flatten, next_help_heading = "T-mesh input")]
    pub surface: SurfaceOptions,
}

/// T-mesh input: reject the CityGML-only options, then tessellate like `geofit surface`.
fn export_tmesh(args: &Args, src: &[u8], name: &str, output: &Output, format: Format, config: &Config) -> CmdResult {
    let citygml_only = [
        ("--lod", args.lod.is_some()),
        ("--t-srs", args.t_srs.is_some()),
        ("--s-srs", args.s_srs.is_some()),
        ("--origin", args.origin != "auto"),
        ("--planar", args.planar),
        ("--gltf-bin", args.gltf_bin),
        ("--report", args.report.is_some()),
    ];
    if let Some((opt, _)) = citygml_only.iter().find(|(_, given)| *given) {
        return Err(CliError::usage(format!("{name} is a T-mesh: {opt} applies to CityGML input only")));
    }
    let file = tspline::format::read(src).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    tessellate(file, name, output, format, &args.surface, config)
}

/// What `--report` writes.
/// `--report`: what went into the mesh file.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-export-report/1",
    units: &[
        ("origin", "CRS units (subtracted from every vertex)"),
        ("area", "CRS units squared (m2 in a metric CRS)"),
    ],
};

#[derive(Debug, Serialize)]
pub struct ExportReport {
    pub file: String,
    pub format: Format,
    /// `--lod` as given (null: each object's highest).
    pub lod: Option<u8>,
    pub crs: Option<String>,
    pub origin: [f64; 3],
    /// Top-level nodes written.
    pub objects: usize,
    pub polygons: usize,
    pub triangles: usize,
    /// Sum of the triangle areas (world units², before the origin shift).
    pub area: f64,
    /// Polygons left out, each `FILE:LINE:COL: what`.
    pub skipped: Vec<String>,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    citygml_io::crs::quiet_proj();
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let output = Output::from_arg(args.output.as_deref());
    let (format, fixed_origin) = checked_options(&args, &output)?;

    let src = input.read_all()?;
    if tspline::format::is_tmesh_document(&src) {
        return export_tmesh(&args, &src, &name, &output, format, config);
    }
    if let Some(opt) = args.surface.given().first() {
        return Err(CliError::usage(format!("{name}: {opt} applies to T-mesh input only")));
    }
    let progress = config.progress("export: read", 0);
    let model = citygml_io::parse(&src).map_err(|e| CliError::unreadable(format!("{name}:{e}")))?;
    drop(src);
    progress.finish(&format!("{} top-level objects", model.objects.len()));

    let source_crs = args.s_srs.clone().or_else(|| model.srs_name.clone());
    // docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41
    let plan = city_scene::crs::export_crs(&model, &name, args.s_srs.as_deref(), args.t_srs.as_deref()).map_err(
        |e| match e {
            city_scene::crs::ExportCrsError::Usage(m) => CliError::usage(m),
            city_scene::crs::ExportCrsError::Unreadable(m) => CliError::unreadable(m),
        },
    )?;
    let swap = plan.swap_axes;
    let transform = match &args.t_srs {
        None => None,
        Some(t) => {
            let Some(s) = &source_crs else {
                return Err(CliError::usage(format!(
                    "{name} names no CRS (srsName); give the source CRS with --s-srs"
                )));
            };
            let from = proj_crs(s);
            let p = proj::Proj::new_known_crs(&from, t, None)
                .map_err(|e| CliError::usage(format!("cannot transform from '{s}' (as '{from}') to '{t}': {e}")))?;
            Some(p)
        }
    };

    let reproject = |x: f64, y: f64| match &transform {
        Some(t) if swap => t.convert((y, x)).map_err(|e| e.to_string()),
        Some(t) => t.convert((x, y)).map_err(|e| e.to_string()),
        None => Ok((x, y)),
    };
    let progress = config.progress("export: triangulate", model.objects.len() as u64);
    let options = SceneOptions { lod: args.lod, planar: args.planar };
    let built = build_scene(&model, &name, &options, transform.is_some().then_some(&reproject as Reproject), &|n| {
        progress.set(n as u64, "")
    });
    let mut scene =
        Scene { crs: plan.recorded, generator: Some(format!("geofit {}", env!("CARGO_PKG_VERSION"))), ..built.scene };
    progress.finish(&format!("{} polygons, {} triangles", built.polygons, scene.triangle_count()));
    scene.origin = fixed_origin.unwrap_or_else(|| scene.auto_origin());

    let mut findings = built.skipped;
    for u in &model.unresolved_xlinks {
        findings.push(format!("{name}:{}:{}: {}", u.span.line, u.span.column, u.reason()));
    }
    if scene.nodes.is_empty() {
        findings.push(match args.lod {
            Some(l) => format!("{name}: no polygons of LoD {l} to export"),
            None => format!("{name}: no polygons in any lod0..lod4 geometry to export"),
        });
    }

    let exit = if findings.is_empty() { Exit::Ok } else { Exit::Findings };
    if config.keeps_output(exit, args.output.as_deref()) {
        write_scene(&scene, &output, format, args.gltf_bin, "export")?;
    }

    if let Some(path) = &args.report {
        let report = ExportReport {
            file: name.clone(),
            format,
            lod: args.lod,
            crs: scene.crs.clone(),
            origin: scene.origin,
            objects: scene.nodes.len(),
            polygons: built.polygons,
            triangles: scene.triangle_count(),
            area: scene.area(),
            skipped: findings.clone(),
        };
        write_json_report(path, &REPORT, &report)?;
    }
    for f in &findings {
        crate::say!("{f}");
    }
    Ok(exit)
}
