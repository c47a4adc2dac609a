//! `geofit validate`: XSD validation against the offline CityGML schemas (libxml2 in-process) and
//! geometric validation with the val3dity / OGC QIE error codes (ring → polygon → shell → solid).
//! This file: options, schemas and one file; `many.rs` the many-file run; `text.rs` the text
//! report.

mod frame;
mod many;
mod text;

use std::path::{Path, PathBuf};
use std::time::Instant;

use citygml_validate::document::{validate_document_in, Checks, DocumentError, Progress, SchemaSet};
use citygml_validate::Options;
use clap::Args as ClapArgs;

use crate::config::{batch_inputs, Config, Input, CITYGML_EXTENSIONS};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{print_report, ReportKind};

const EXAMPLE: &str = "\
Example:
  $ geofit validate building.gml
  building.gml: CityGML 2.0
  building.gml: XSD (citygml-2.0.xsd): valid
  building.gml:52:17: 203 NON_PLANAR_POLYGON_DISTANCE_PLANE feature=BLDG_1 primitive=POLY_7:
      distance to fitted plane 0.023400 m at (...) (tolerance 0.01 m)
  building.gml: geometry: 1 error (snap 0.001 m, planarity 0.01 m, normals 20°)
  building.gml: INVALID
  $ geofit validate --json --no-xsd --planarity-tol 0.05 - < tile.gml | jq '.geometry.findings[].code'
  $ geofit validate tiles/ 'more/*.gml' extra.gml
  ... one block per file, in argument order (a directory's files sorted by path) ...
  summary: 66 files: 62 valid, 4 invalid, 0 unreadable; errors: 203 ×10, 302 ×3, xsd ×2; 1.912 s
  $ geofit validate --json tiles/ | jq -c 'select(.file) | [.file, .valid]'

Many files (several arguments, a directory — searched recursively for *.gml, *.xml, *.citygml —
or a glob pattern): the schemas are parsed once and the files checked in parallel
(RAYON_NUM_THREADS threads, default one per core); the output is in input order whatever the
threads. Text: each file's block as for one file, then a summary line. --json: JSON lines, one
object per file (the one-file report plus \"schema\": \"geofit-validate/1\"; a file that cannot be
read is {\"schema\", \"file\", \"error\", \"exit\"}), then {\"schema\", \"summary\": {files, valid,
invalid, unreadable, errors (per code: val3dity codes, xsd, not_well_formed), wall_seconds}}. A
file that cannot be read is reported in its place (and on stderr) and the others are still
checked; the exit status is the worst over the files.

Geometric checks run level by level like val3dity — ring (101–104), polygon (201–208), shell
(301–307), solid (401–405), CompositeSolid (501–503) — and a primitive whose lower level fails
is not checked further.
Ring and polygon checks work in the polygon's least-squares plane. Codes and names are val3dity's
current ones (legacy QIE 105 → 104, 304 → 303, 308 → 405). Solids (gml:Solid, each solid of a
CompositeSolid/MultiSolid) get all levels; the solids of a CompositeSolid must not be identical
(502) or overlap (501) and must be connected by shared faces (503); MultiSolid members are
independent. Shells may touch along lines unless the contact closes a loop (404). MultiSurface /
CompositeSurface get ring and polygon checks. Vertices closer than --snap-tol are merged per shell.

Units: tolerances are metres. A file in a geographic CRS (EPSG:4979, 4326, 4258, CRS84...:
degrees) is checked in the UTM zone of its first point, through PROJ, with the axis order its
CRS declares (latitude first for EPSG codes, longitude first for CRS84); a latitude beyond ±90°
is refused (exit 3, the file is in the other order). The report says so (text `frame:` line,
JSON geometry.frame) and finding positions are then UTM metres:
  $ geofit validate wgs84.gml
  wgs84.gml: frame: EPSG:4979 (EPSG:4979, degrees, latitude, longitude)
      checked in UTM zone 32N (EPSG:32632 axes, GRS80), metres; heights as written
A CRS with a height system (compound CRS, AdV URN) is named: text `heights:` line, JSON
`heights` (name, epsg, kind), e.g. NRW: DHHN2016 height (EPSG:7837, normal heights).

Schemas: --schemas DIR, else $GEOFIT_SCHEMAS, else ../shared/xsd beside the checkout (searched
from the working directory upwards and from the source tree geofit was built from). DIR holds
citygml-1.0.xsd, citygml-2.0.xsd, citygml-3.0.xsd wrappers (see ../shared/xsd/README.md); the
wrapper is chosen from the document's namespaces. Without schemas the geometric checks run alone.

Exit status: 0 valid, 1 XSD or geometric errors (all listed), 2 bad options (or a pattern or
directory that names no file), 3 unreadable input, 4 internal failure.";

#[derive(ClapArgs, Debug)]
#[command(about = "Validate CityGML: XSD schema (libxml2) and geometry (val3dity/QIE codes)", after_help = EXAMPLE)]
pub struct Args {
    /// CityGML files (1.0, 2.0 or 3.0), directories (searched recursively for *.gml, *.xml,
    /// *.citygml), glob patterns (quoted: expanded by geofit), or `-` for stdin.
    #[arg(required = true, value_name = "INPUT")]
    pub inputs: Vec<String>,
    /// Print the report as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Directory with the wrapper schemas `citygml-<version>.xsd`.
    #[arg(long, value_name = "DIR")]
    pub schemas: Option<PathBuf>,
    /// Skip the XSD validation (geometric checks only).
    #[arg(long)]
    pub no_xsd: bool,
    /// Skip the geometric checks (XSD only).
    #[arg(long)]
    pub no_geometry: bool,
    /// Vertices closer than this are merged (m).
    #[arg(long, default_value_t = 0.001, value_name = "M")]
    pub snap_tol: f64,
    /// Maximum distance of a polygon's vertex to its least-squares plane (m).
    #[arg(long, default_value_t = 0.01, value_name = "M")]
    pub planarity_tol: f64,
    /// Maximum angle between the normals of a polygon's triangles (degrees).
    #[arg(long, default_value_t = 20.0, value_name = "DEG")]
    pub normals_tol: f64,
}

const HOW_TO_GET: &str =
    "CityGML schemas not found (no --schemas DIR, GEOFIT_SCHEMAS unset or empty, no ../shared/xsd \
beside the checkout): XSD validation skipped, geometric checks only. To enable it, point --schemas or GEOFIT_SCHEMAS \
at an offline bundle holding citygml-1.0.xsd, citygml-2.0.xsd and citygml-3.0.xsd wrappers that import the OGC \
CityGML/GML schemas by relative paths (e.g. the schemas shipped in citygml4j, \
citygml4j-xml/src/main/resources/org/citygml4j/schemas, plus the wrappers described in shared/xsd/README.md)";

/// Where the schemas are: --schemas, $GEOFIT_SCHEMAS, ../shared/xsd beside the checkout.
fn find_schema_dir(explicit: Option<&Path>) -> Result<PathBuf, String> {
    if let Some(d) = explicit {
        return if d.is_dir() {
            Ok(d.to_path_buf())
        } else {
            Err(format!("--schemas {}: not a directory", d.display()))
        };
    }
    match std::env::var_os("GEOFIT_SCHEMAS") {
        // set but empty: no schemas on purpose, no search
        Some(d) if d.is_empty() => return Err(HOW_TO_GET.to_string()),
        Some(d) => {
            let d = PathBuf::from(d);
            return if d.is_dir() { Ok(d) } else { Err(format!("GEOFIT_SCHEMAS={}: not a directory", d.display())) };
        }
        None => {}
    }
    let mut cands: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        for a in cwd.ancestors() {
            cands.push(a.join("../shared/xsd"));
        }
    }
    // the checkout geofit was built from (crates/geofit → repository root)
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    cands.push(repo.join("../shared/xsd"));
    for c in cands {
        if c.join("citygml-2.0.xsd").is_file() {
            return Ok(c.canonicalize().unwrap_or(c));
        }
    }
    Err(HOW_TO_GET.to_string())
}

fn check_opts(args: &Args) -> Result<Options, CliError> {
    for (name, v) in
        [("--snap-tol", args.snap_tol), ("--planarity-tol", args.planarity_tol), ("--normals-tol", args.normals_tol)]
    {
        if !v.is_finite() || v < 0.0 {
            return Err(CliError::usage(format!("{name} must be a finite number ≥ 0, got {v}")));
        }
    }
    if args.normals_tol > 180.0 {
        return Err(CliError::usage(format!(
            "--normals-tol is an angle in degrees (0..180), got {}",
            args.normals_tol
        )));
    }
    Ok(Options { snap_tol: args.snap_tol, planarity_tol: args.planarity_tol, normals_tol_deg: args.normals_tol })
}

/// Checks that do not depend on the documents: tolerances, schemas (found once per process).
fn checks(args: &Args, options: Options, config: &Config) -> Result<Checks, CliError> {
    let xsd = if args.no_xsd {
        Err("--no-xsd".to_string())
    } else {
        match find_schema_dir(args.schemas.as_deref()) {
            Ok(dir) => Ok(SchemaSet::new(dir)),
            Err(why) => {
                if args.schemas.is_some() || std::env::var_os("GEOFIT_SCHEMAS").is_some_and(|v| !v.is_empty()) {
                    return Err(CliError::usage(why));
                }
                config.notice(&why);
                Err(why)
            }
        }
    };
    Ok(Checks { xsd, geometry: !args.no_geometry, options })
}

fn document_error(e: DocumentError) -> CliError {
    match e {
        DocumentError::Unreadable(m) => CliError::unreadable(m),
        DocumentError::Schema(m) => CliError::usage(m),
        DocumentError::Internal(m) => CliError::internal(m),
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let started = Instant::now();
    citygml_io::crs::quiet_proj();
    let options = check_opts(&args)?;
    if !file_batch::is_batch(&args.inputs) {
        return run_one(&args, options, config);
    }
    let sources = batch_inputs(&args.inputs, CITYGML_EXTENSIONS)?;
    let checks = checks(&args, options, config)?;
    many::run(sources, &checks, args.json, config, started)
}

/// One file or `-`: the report as it always was (pretty JSON or text), exit 3 when unreadable.
fn run_one(args: &Args, options: Options, config: &Config) -> CmdResult {
    let input = Input::from_arg(&args.inputs[0]);
    let name = input.display_name();
    // Mapped: the geometry check releases the pages behind it (with the XSD check on, libxml2
    // still reads the whole document).
    let bytes = input.map_or_read()?;
    let checks = checks(args, options, config)?;
    let report = if checks.geometry {
        let progress = config.progress("validate", bytes.len() as u64);
        let on_batch = |p: Progress| {
            bytes.release_before(p.bytes_read);
            progress.set(p.bytes_read as u64, &format!("{} features checked", p.features));
        };
        let mut frame = frame::GeographicFrame::default();
        let report =
            validate_document_in(&bytes, &name, &checks, Some(&mut frame), &on_batch).map_err(document_error)?;
        progress.finish(&format!("{} features checked", report.geometry.features));
        report
    } else {
        validate_document_in(&bytes, &name, &checks, None, &|_| {}).map_err(document_error)?
    };
    print_report(args.json, &REPORT, &report, |w| text::write(w, &report))?;
    Ok(if report.valid { Exit::Ok } else { Exit::Findings })
}

/// `--json`: one file's report, the same object as a line of a many-file run.
const REPORT: ReportKind = ReportKind {
    schema: "geofit-validate/1",
    units: &[
        ("geometry.options.snap_tol", "CRS units (m)"),
        ("geometry.options.planarity_tol", "CRS units (m)"),
        ("geometry.options.normals_tol_deg", "deg"),
    ],
};
