//! `geofit validate`: XSD validation against the offline CityGML schemas (libxml2 in-process) and
//! geometric validation with the val3dity / OGC QIE error codes (ring → polygon → shell → solid).

use std::io::Write;
use std::path::{Path, PathBuf};

use citygml_io::ObjectStream;
use citygml_validate::xsd::{sniff_version, wrapper_for, Schema, XsdErrorKind, XsdFinding};
use citygml_validate::{add_unresolved_xlinks, sort_findings, validate_objects, Finding, Options};
use clap::Args as ClapArgs;
use serde::Serialize;

use crate::config::{print_report, Config, Input};
use crate::error::{CliError, CmdResult, Exit};

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

Geometric checks run level by level like val3dity — ring (101–104), polygon (201–208), shell
(301–307), solid (401–405), CompositeSolid (501–503) — and a primitive whose lower level fails
is not checked further.
Ring and polygon checks work in the polygon's least-squares plane. Codes and names are val3dity's
current ones (legacy QIE 105 → 104, 304 → 303, 308 → 405). Solids (gml:Solid, each solid of a
CompositeSolid/MultiSolid) get all levels; the solids of a CompositeSolid must not be identical
(502) or overlap (501) and must be connected by shared faces (503); MultiSolid members are
independent. Shells may touch along lines unless the contact closes a loop (404). MultiSurface /
CompositeSurface get ring and polygon checks. Vertices closer than --snap-tol are merged per shell.

Schemas: --schemas DIR, else $GEOFIT_SCHEMAS, else ../shared/xsd beside the checkout (searched
from the working directory upwards and from the source tree geofit was built from). DIR holds
citygml-1.0.xsd, citygml-2.0.xsd, citygml-3.0.xsd wrappers (see ../shared/xsd/README.md); the
wrapper is chosen from the document's namespaces. Without schemas the geometric checks run alone.

Exit status: 0 valid, 1 XSD or geometric errors (all listed), 2 bad options, 3 unreadable input.";

#[derive(ClapArgs, Debug)]
#[command(about = "Validate CityGML: XSD schema (libxml2) and geometry (val3dity/QIE codes)", after_help = EXAMPLE)]
pub struct Args {
    /// CityGML file (1.0, 2.0 or 3.0), or `-` for stdin.
    pub input: String,
    /// Print the report as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Directory with the wrapper schemas citygml-<version>.xsd.
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

#[derive(Serialize)]
struct XsdReport {
    checked: bool,
    /// Why it was not checked.
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    schema: Option<String>,
    valid: Option<bool>,
    errors: Vec<XsdFinding>,
}

#[derive(Serialize)]
struct GeometryReport {
    checked: bool,
    options: Options,
    features: usize,
    valid: Option<bool>,
    findings: Vec<Finding>,
}

#[derive(Serialize)]
struct Report {
    file: String,
    version: Option<String>,
    valid: bool,
    xsd: XsdReport,
    geometry: GeometryReport,
}

const HOW_TO_GET: &str = "CityGML schemas not found (no --schemas DIR, GEOFIT_SCHEMAS unset or empty, no ../shared/xsd \
beside the checkout): XSD validation skipped, geometric checks only. To enable it, point --schemas or GEOFIT_SCHEMAS \
at an offline bundle holding citygml-1.0.xsd, citygml-2.0.xsd and citygml-3.0.xsd wrappers that import the OGC \
CityGML/GML schemas by relative paths (e.g. the schemas shipped in citygml4j, \
citygml4j-xml/src/main/resources/org/citygml4j/schemas, plus the wrappers described in shared/xsd/README.md)";

/// Where the schemas are: --schemas, $GEOFIT_SCHEMAS, ../shared/xsd beside the checkout.
fn find_schema_dir(explicit: Option<&Path>) -> Result<PathBuf, String> {
    if let Some(d) = explicit {
        return if d.is_dir() { Ok(d.to_path_buf()) } else { Err(format!("--schemas {}: not a directory", d.display())) };
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
    for (name, v) in [("--snap-tol", args.snap_tol), ("--planarity-tol", args.planarity_tol), ("--normals-tol", args.normals_tol)] {
        if !v.is_finite() || v < 0.0 {
            return Err(CliError::usage(format!("{name} must be a finite number ≥ 0, got {v}")));
        }
    }
    if args.normals_tol > 180.0 {
        return Err(CliError::usage(format!("--normals-tol is an angle in degrees (0..180), got {}", args.normals_tol)));
    }
    Ok(Options { snap_tol: args.snap_tol, planarity_tol: args.planarity_tol, normals_tol_deg: args.normals_tol })
}

fn run_xsd(bytes: &[u8], name: &str, dir: &Path, version: &str) -> XsdReport {
    let path = dir.join(wrapper_for(version));
    let schema = match Schema::load(&path) {
        Ok(s) => s,
        Err(e) => {
            return XsdReport { checked: false, reason: Some(e.to_string()), schema: Some(path.display().to_string()), valid: None, errors: vec![] }
        }
    };
    match schema.validate(bytes, name) {
        Ok(errors) => XsdReport {
            checked: true,
            reason: None,
            schema: Some(path.display().to_string()),
            valid: Some(errors.is_empty()),
            errors,
        },
        Err(e) => XsdReport { checked: false, reason: Some(e.to_string()), schema: Some(path.display().to_string()), valid: None, errors: vec![] },
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let opts = check_opts(&args)?;
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let version = sniff_version(&bytes);

    let schema_dir = if args.no_xsd { None } else { Some(find_schema_dir(args.schemas.as_deref())) };
    if let Some(Err(why)) = &schema_dir {
        if args.schemas.is_some() || std::env::var_os("GEOFIT_SCHEMAS").is_some_and(|v| !v.is_empty()) {
            return Err(CliError::usage(why.clone()));
        }
        config.notice(why);
    }

    // XSD on its own thread while the geometry is read and checked.
    let (xsd, geometry) = std::thread::scope(|s| {
        let xsd_job = s.spawn(|| match (&schema_dir, version) {
            (None, _) => XsdReport { checked: false, reason: Some("--no-xsd".into()), schema: None, valid: None, errors: vec![] },
            (Some(Err(why)), _) => XsdReport { checked: false, reason: Some(why.clone()), schema: None, valid: None, errors: vec![] },
            (Some(Ok(_)), None) => XsdReport {
                checked: false,
                reason: Some("no CityGML 1.0/2.0/3.0 namespace on the root element, no schema to choose".into()),
                schema: None,
                valid: None,
                errors: vec![],
            },
            (Some(Ok(dir)), Some(v)) => run_xsd(&bytes, &name, dir, v),
        });
        let geometry = if args.no_geometry {
            Ok(GeometryReport { checked: false, options: opts, features: 0, valid: None, findings: vec![] })
        } else {
            check_geometry(&bytes, &name, &opts, config)
        };
        (xsd_job.join(), geometry)
    });
    let xsd = xsd.map_err(|_| CliError::internal("XSD validation thread panicked"))?;
    if let (false, Some(why), Some(Ok(_))) = (xsd.checked, &xsd.reason, &schema_dir) {
        if version.is_some() {
            // the schema directory was found but the wrapper could not be loaded
            return Err(CliError::usage(why.clone()));
        }
    }
    let geometry = match geometry {
        Ok(g) => g,
        Err(e) => {
            // Unreadable as CityGML: show what libxml2 said about well-formedness, then exit 3.
            if let Some(f) = xsd.errors.iter().find(|f| f.kind == XsdErrorKind::NotWellFormed) {
                return Err(CliError::unreadable(format!("{name}:{}:{}: not well-formed XML: {}", f.line, f.column, f.message)));
            }
            return Err(e);
        }
    };
    let xsd_bad = xsd.valid == Some(false);
    let geom_bad = geometry.valid == Some(false);
    let report = Report {
        file: name.clone(),
        version: version.map(str::to_string),
        valid: !xsd_bad && !geom_bad,
        xsd,
        geometry,
    };
    print_report(args.json, &report, |w| write_text(w, &report))?;
    Ok(if report.valid { Exit::Ok } else { Exit::Findings })
}

fn check_geometry(bytes: &[u8], name: &str, opts: &Options, config: &Config) -> Result<GeometryReport, CliError> {
    let unreadable = |e: citygml_io::ReadError| CliError::unreadable(format!("{name}:{e}"));
    let mut stream = ObjectStream::new(bytes).map_err(unreadable)?;
    let progress = config.progress("validate", 0);
    let mut findings = Vec::new();
    let mut batch = Vec::new();
    let mut features = 0usize;
    // Objects are read one by one and checked in parallel batches: memory stays bounded.
    for obj in stream.by_ref() {
        batch.push(obj.map_err(unreadable)?);
        if batch.len() == 256 {
            features += batch.len();
            findings.extend(validate_objects(&batch, opts));
            batch.clear();
            progress.set(features as u64, &format!("{features} features checked"));
        }
    }
    features += batch.len();
    findings.extend(validate_objects(&batch, opts));
    add_unresolved_xlinks(&mut findings, stream.unresolved_xlinks());
    sort_findings(&mut findings);
    progress.finish(&format!("{features} features checked"));
    Ok(GeometryReport { checked: true, options: *opts, features, valid: Some(findings.is_empty()), findings })
}

fn write_text(w: &mut dyn Write, r: &Report) -> std::io::Result<()> {
    let f = &r.file;
    writeln!(w, "{f}: CityGML {}", r.version.as_deref().unwrap_or("(version unknown)"))?;
    let schema_name = r.xsd.schema.as_deref().map(|s| Path::new(s).file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default());
    if r.xsd.checked {
        let sn = schema_name.unwrap_or_default();
        if r.xsd.errors.is_empty() {
            writeln!(w, "{f}: XSD ({sn}): valid")?;
        } else {
            for e in &r.xsd.errors {
                let what = if e.kind == XsdErrorKind::NotWellFormed { "not well-formed" } else { "XSD" };
                writeln!(w, "{f}:{}:{}: {what}: {}", e.line, e.column, e.message)?;
            }
            writeln!(w, "{f}: XSD ({sn}): {} error{}", r.xsd.errors.len(), if r.xsd.errors.len() == 1 { "" } else { "s" })?;
        }
    } else {
        writeln!(w, "{f}: XSD: not checked ({})", r.xsd.reason.as_deref().unwrap_or(""))?;
    }
    let g = &r.geometry;
    if g.checked {
        for x in &g.findings {
            let mut ids = String::new();
            if let Some(id) = &x.feature {
                ids.push_str(&format!(" feature={id}"));
            } else {
                ids.push_str(&format!(" feature=({})", x.feature_type));
            }
            if let Some(p) = &x.primitive {
                ids.push_str(&format!(" primitive={p}"));
            }
            writeln!(w, "{f}:{}:{}: {} {}{} [{}]: {}", x.line, x.column, x.code, x.name, ids, x.geometry, x.detail)?;
        }
        let o = &g.options;
        let n = g.findings.len();
        writeln!(
            w,
            "{f}: geometry: {} in {} feature{} (snap {} m, planarity {} m, normals {}°)",
            if n == 0 { "valid".to_string() } else { format!("{n} error{}", if n == 1 { "" } else { "s" }) },
            g.features,
            if g.features == 1 { "" } else { "s" },
            o.snap_tol,
            o.planarity_tol,
            o.normals_tol_deg
        )?;
    } else {
        writeln!(w, "{f}: geometry: not checked (--no-geometry)")?;
    }
    writeln!(w, "{f}: {}", if r.valid { "VALID" } else { "INVALID" })
}
