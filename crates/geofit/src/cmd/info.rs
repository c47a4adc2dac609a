//! `geofit info`: what a file holds. CityGML: version, CRS, envelope, counts per feature type
//! and LoD, polygons, rings, points, read object by object (bounded memory on big tiles).
//! Also T-meshes (degree, cells, control points, georeference, mask), rasters (anything GDAL
//! opens: size, geotransform, CRS, nodata marker and count, value range) and point files
//! (XYZ/CSV text, LAS/LAZ: count, bounds, CRS). The kind comes from the extension where it is
//! unambiguous, otherwise from the content (root element, then GDAL, then XYZ text).

use crate::report::{print_report_with_units, tagged, ReportKind, Z_UNIT};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::io::Write;
use std::time::Instant;

use citygml_io::summary::{DocumentCounts, LodCounts};
use citygml_io::{Envelope, ObjectStream, ReadError};
use clap::Args as ClapArgs;
use serde::Serialize;

use crate::config::{
    batch_inputs, run_batch, worse_exit, write_batch_error, write_json_line, Config, Input, CITYGML_EXTENSIONS,
};
use crate::error::{CliError, CmdResult, Exit};

const EXAMPLE: &str = "\
Example:
  $ geofit info LoD2_32_324_5729_1_NW.gml
  file:        LoD2_32_324_5729_1_NW.gml
  version:     CityGML 1.0
  crs:         urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016
  envelope:    324259.661 5729140.133 17.854 .. 324277.942 5729161.128 22.505
  declared:    324000 5729000 17.854 .. 325000 5730000 22.505
  objects:     1 top-level, 10 in all
  feature types:
    Building                            1
    GroundSurface                       1
    RoofSurface                         2
    WallSurface                         6
  levels of detail:            geometries polygons
    lod2                               10        9
  solids:      1
  polygons:    9
  rings:       9 (0 interior)
  points:      43
  xlinks:      9 resolved, 0 unresolved
  $ geofit info --json - < city.gml | jq .polygons
  $ geofit info --json bathy.tmesh | jq '.degree, .cells, .control_points'
  $ geofit info --json gmt_Kilauea.utm.nc | jq '.width, .height, .geotransform, .nodata_count'
  $ geofit info soundings.xyz

Counts are of definitions: a polygon referenced by xlink:href (the faces of an NRW lod2Solid)
is counted once, where it is defined; `xlinks_resolved` says how many references were followed.

Many inputs (several arguments, a directory — searched recursively for *.gml, *.xml, *.citygml —
or a glob pattern): read in parallel, reported in input order, each block as for one file and a
blank line, then a summary line; with --json, JSON lines: one object per file (the one-file
report plus \"schema\": \"geofit-info/1\"; an unreadable one is {\"schema\", \"file\", \"error\",
\"exit\"}), then {\"schema\", \"summary\": {files, clean, with_findings, unreadable, wall_seconds}}.
An unreadable input is reported in its place and the rest still read; the exit status is the
worst over the inputs.
Exit 1 when the file is readable but has rings with fewer than 4 positions or XLinks whose
target is missing (each listed on stderr as FILE:LINE:COL); exit 3 when it cannot be read.";

#[derive(ClapArgs, Debug)]
#[command(about = "Summarise a CityGML file (or a T-mesh, raster or point file): counts, extent, CRS", after_help = EXAMPLE)]
pub struct Args {
    /// CityGML files (1.0, 2.0 or 3.0), T-meshes, rasters (GDAL) or point files (XYZ/CSV, LAS/LAZ);
    /// directories (searched recursively for *.gml, *.xml, *.citygml), glob patterns (quoted:
    /// expanded by geofit), or `-` for stdin.
    #[arg(required = true, value_name = "INPUT")]
    pub inputs: Vec<String>,
    /// Print the report as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `info` of a CityGML file: the counts of `citygml_io::summary::DocumentCounts` (which says how
/// each is counted) between what the document declares, in the report's field order.
#[derive(Debug, Serialize)]
pub struct InfoReport {
    pub file: String,
    pub version: String,
    pub crs: Option<String>,
    /// Envelope of all coordinates, `[min, max]`; null when there are none.
    pub envelope: Option<[[f64; 3]; 2]>,
    /// Envelope declared in the document's gml:boundedBy.
    pub declared_envelope: Option<[[f64; 3]; 2]>,
    pub top_level_objects: usize,
    pub feature_types: BTreeMap<String, usize>,
    pub lods: BTreeMap<String, LodCounts>,
    pub solids: usize,
    pub polygons: usize,
    pub rings: usize,
    pub triangles: usize,
    pub interior_rings: usize,
    pub points: usize,
    pub xlinks_resolved: usize,
    pub unresolved_xlinks: usize,
}

fn env(e: &Envelope) -> Option<[[f64; 3]; 2]> {
    (!e.is_empty()).then_some([e.min, e.max])
}

/// What `info` summarises, by extension where it is unambiguous.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    CityGml,
    TMesh,
    Raster,
    Points,
}

/// Point extensions come first: GDAL has raster drivers for some of them (`.xyz` grids).
fn kind_by_extension(p: &std::path::Path) -> Option<Kind> {
    // `/vsigzip/x.tif.gz`, `/vsizip/a.zip/x.tif`: only GDAL opens these
    if raster_io::gdal_io::is_gdal_virtual_path(p) {
        return Some(Kind::Raster);
    }
    let ext = p.extension()?.to_string_lossy().to_ascii_lowercase();
    match ext.as_str() {
        "gml" | "citygml" | "xml" => Some(Kind::CityGml),
        "tmesh" | "tmb" => Some(Kind::TMesh),
        "las" | "laz" | "xyz" | "csv" | "txt" | "pts" => Some(Kind::Points),
        _ => raster_io::RasterFormat::from_path(p).map(|_| Kind::Raster),
    }
}

/// The first non-blank byte (after a UTF-8 BOM) is `<`.
fn looks_like_xml(src: &[u8]) -> bool {
    let src = src.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(src);
    src.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'<')
}

/// What `info` found in one input; serialized as the inner report.
#[derive(Debug, Serialize)]
#[serde(untagged)]
enum Info {
    CityGml(InfoReport),
    TMesh(TMeshInfo),
    Raster(RasterInfo),
    Points(PointsInfo),
}

/// `--json`: one input's summary, the same object as a line of a many-file run; its units
/// depend on what the input is ([`Info::units`]).
const REPORT: ReportKind = ReportKind { schema: "geofit-info/1", units: &[] };

impl Info {
    fn units(&self) -> &'static [(&'static str, &'static str)] {
        match self {
            Info::CityGml(_) => &[("envelope", "CRS units"), ("declared_envelope", "CRS units")],
            Info::TMesh(_) => &[("domain", "raster cells (parameter units)"), ("georef", "CRS units (x0, y0, dx, dy)")],
            Info::Raster(_) => &[("width", "cells"), ("height", "cells"), ("geotransform", "CRS units"), ("nodata", Z_UNIT), ("range", Z_UNIT)],
            Info::Points(_) => &[("envelope", "CRS units")],
        }
    }

    fn write_text(&self, w: &mut dyn Write) -> std::io::Result<()> {
        match self {
            Info::CityGml(r) => write_text(w, r),
            Info::TMesh(r) => write_tmesh_text(w, r),
            Info::Raster(r) => write_raster_text(w, r),
            Info::Points(r) => write_points_text(w, r),
        }
    }
}

/// One input's summary and its located problems (`FILE:LINE:COL: …`, exit 1 when there are any).
struct Summary {
    info: Info,
    findings: Vec<String>,
}

impl From<Info> for Summary {
    fn from(info: Info) -> Summary {
        Summary { info, findings: Vec::new() }
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let started = Instant::now();
    crate::terrain_io::gdal_notices(config);
    if file_batch::is_batch(&args.inputs) {
        let inputs = batch_inputs(&args.inputs, CITYGML_EXTENSIONS)?;
        return run_many(inputs, args.json, config, started);
    }
    let s = summarize(&Input::from_arg(&args.inputs[0]))?;
    print_report_with_units(args.json, &REPORT, s.info.units(), &s.info, |w| s.info.write_text(w))?;
    for f in &s.findings {
        crate::say!("{f}");
    }
    Ok(if s.findings.is_empty() { Exit::Ok } else { Exit::Findings })
}

/// Reads one input and summarises it, whatever kind it is.
fn summarize(input: &Input) -> Result<Summary, CliError> {
    let name = input.display_name();
    // Binary rasters and LAS/LAZ are opened by path (GDAL, las): decide before reading.
    let by_ext = input.path().and_then(kind_by_extension);
    match (by_ext, input.path()) {
        (Some(Kind::Raster), Some(p)) => return Ok(raster_info(&read_raster_path(p)?, &name).into()),
        (Some(Kind::Points), Some(p)) => {
            let cloud = raster_io::read_points(p, None).map_err(|e| CliError::unreadable(e.to_string()))?;
            return Ok(points_info(&cloud, &name).into());
        }
        _ => {}
    }
    // Mapped: the CityGML stream below holds only the pages ahead of it.
    let src = input.map_or_read()?;
    // Nothing to summarise: say so, rather than what the first format tried found missing.
    let text = src.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(&src);
    // (a `.gml` file gets the CityGML reader's located message instead)
    if by_ext.is_none() && text.iter().all(u8::is_ascii_whitespace) {
        let what = if src.is_empty() { "0 bytes".to_string() } else { format!("{} bytes, only whitespace", src.len()) };
        return Err(CliError::unreadable(format!("{name}: the input is empty ({what})")));
    }
    if by_ext == Some(Kind::TMesh) || (by_ext.is_none() && tspline::format::is_tmesh_document(&src)) {
        let file = tspline::format::read(&src).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
        return Ok(tmesh_info(&file, &name).into());
    }
    if by_ext.is_none() && !src.is_empty() && !looks_like_xml(&src) {
        // No telling extension and not XML: a raster GDAL opens, else XYZ text.
        if let Some(r) = raster_from_bytes(&src, input.path())? {
            return Ok(raster_info(&r, &name).into());
        }
        return match raster_io::points::read_xyz(&src[..], &name) {
            Ok(cloud) => Ok(points_info(&cloud, &name).into()),
            // The XYZ error names file and line; say what else was tried.
            Err(e) => Err(CliError::unreadable(format!("{e} (read as XYZ text: not XML, and no raster GDAL opens)"))),
        };
    }
    let located = |e: ReadError| CliError::unreadable(format!("{name}:{e}"));

    let mut stream = ObjectStream::new(&src).map_err(located)?;
    let mut counts = DocumentCounts::default();
    while let Some(obj) = stream.next() {
        counts.add(&obj.map_err(located)?);
        src.release_before(stream.consumed());
    }
    let mut findings: Vec<String> = counts
        .short_rings
        .iter()
        .map(|(span, n)| {
            format!("{name}:{}:{}: gml:LinearRing has {n} positions, at least 4 are needed (closed ring of 3 points)", span.line, span.column)
        })
        .collect();
    for u in stream.unresolved_xlinks() {
        findings.push(format!("{name}:{}:{}: {}", u.span.line, u.span.column, u.reason()));
    }
    let report = InfoReport {
        file: name.clone(),
        version: stream.version().as_str().to_string(),
        crs: stream.srs_name(),
        envelope: env(&counts.envelope),
        declared_envelope: stream.declared_envelope().as_ref().and_then(env),
        top_level_objects: counts.top_level_objects,
        feature_types: counts.feature_types,
        lods: counts.lods,
        solids: counts.solids,
        polygons: counts.polygons,
        rings: counts.rings,
        triangles: counts.triangles,
        interior_rings: counts.interior_rings,
        points: counts.points,
        xlinks_resolved: counts.xlinks_resolved,
        unresolved_xlinks: stream.unresolved_xlinks().len(),
    };
    Ok(Summary { info: Info::CityGml(report), findings })
}

fn write_text(w: &mut dyn Write, r: &InfoReport) -> std::io::Result<()> {
    let fmt_env = |e: &Option<[[f64; 3]; 2]>| match e {
        Some([a, b]) => format!("{} {} {} .. {} {} {}", a[0], a[1], a[2], b[0], b[1], b[2]),
        None => "none".to_string(),
    };
    writeln!(w, "file:        {}", r.file)?;
    writeln!(w, "version:     CityGML {}", r.version)?;
    writeln!(w, "crs:         {}", r.crs.as_deref().unwrap_or("none"))?;
    writeln!(w, "envelope:    {}", fmt_env(&r.envelope))?;
    if r.declared_envelope.is_some() {
        writeln!(w, "declared:    {}", fmt_env(&r.declared_envelope))?;
    }
    let all: usize = r.feature_types.values().sum();
    writeln!(w, "objects:     {} top-level, {} in all", r.top_level_objects, all)?;
    writeln!(w, "feature types:")?;
    for (k, v) in &r.feature_types {
        writeln!(w, "  {k:<28} {v:>8}")?;
    }
    writeln!(w, "levels of detail:            geometries polygons")?;
    for (k, v) in &r.lods {
        writeln!(w, "  {k:<28} {:>8} {:>8}", v.geometries, v.polygons)?;
    }
    writeln!(w, "solids:      {}", r.solids)?;
    writeln!(w, "polygons:    {}", r.polygons)?;
    writeln!(w, "rings:       {} ({} interior)", r.rings, r.interior_rings)?;
    writeln!(w, "points:      {}", r.points)?;
    if r.triangles > 0 {
        writeln!(w, "triangles:   {} (TIN)", r.triangles)?;
    }
    writeln!(w, "xlinks:      {} resolved, {} unresolved", r.xlinks_resolved, r.unresolved_xlinks)?;
    Ok(())
}

/// Reads a raster by path; errors name the file.
fn read_raster_path(p: &std::path::Path) -> Result<raster_io::Raster, CliError> {
    raster_io::read_raster(p).map_err(|e| CliError::unreadable(e.to_string()))
}

/// A raster GDAL opens from this input (the path, or stdin's bytes spooled), or None.
/// A raster too large to read is an error, not a reason to try XYZ text.
fn raster_from_bytes(src: &[u8], path: Option<&std::path::Path>) -> Result<Option<raster_io::Raster>, CliError> {
    match path {
        Some(p) => match raster_io::read_raster(p) {
            Ok(r) => Ok(Some(r)),
            Err(e @ raster_io::RasterError::TooLarge { .. }) => Err(CliError::unreadable(e.to_string())),
            Err(_) => Ok(None),
        },
        None => Ok(crate::terrain_io::raster_from_stdin_bytes(src).ok()),
    }
}

/// `info` of a T-mesh file.
#[derive(Debug, Serialize)]
pub struct TMeshInfo {
    pub file: String,
    pub kind: &'static str,
    pub degree: usize,
    /// Leaf cells (faces of the T-mesh).
    pub cells: usize,
    /// Control points that carry a blending function (all points of a written file).
    pub control_points: usize,
    /// Parameter domain [s_min, t_min, s_max, t_max] (raster cell units).
    pub domain: [f64; 4],
    /// World = (x0 + s·dx, y0 + t·dy).
    pub georef: [f64; 4],
    pub crs: Option<String>,
    /// Data mask size and the number of cells with data; null without a mask.
    pub mask: Option<[usize; 3]>,
    /// Indirect reduction: the warp field travels in the file.
    pub indirect: bool,
}

fn tmesh_info(f: &tspline::format::TMeshFile, name: &str) -> Info {
    let m = &f.mesh;
    let b = m.bounds();
    let g = &f.georef;
    let r = TMeshInfo {
        file: name.to_string(),
        kind: "tmesh",
        degree: m.degree.k(),
        cells: m.cells.iter().filter(|c| c.is_leaf()).count(),
        control_points: m.active_points().iter().filter(|a| **a).count(),
        domain: [b.s_min, b.t_min, b.s_max, b.t_max],
        georef: [g.x0, g.y0, g.dx, g.dy],
        crs: (!g.crs.is_empty()).then(|| g.crs.clone()),
        mask: f.mask.as_ref().map(|k| [k.width, k.height, k.bits.iter().filter(|v| **v).count()]),
        indirect: f.warp.is_some(),
    };
    Info::TMesh(r)
}

fn write_tmesh_text(w: &mut dyn Write, r: &TMeshInfo) -> std::io::Result<()> {
    writeln!(w, "file:           {}", r.file)?;
    writeln!(w, "kind:           T-mesh, degree {}", r.degree)?;
    writeln!(w, "cells:          {}", r.cells)?;
    writeln!(w, "control points: {}", r.control_points)?;
    writeln!(w, "domain (s, t):  {} {} .. {} {}", r.domain[0], r.domain[1], r.domain[2], r.domain[3])?;
    writeln!(w, "georef:         x = {} + s·{}, y = {} + t·{}", r.georef[0], r.georef[2], r.georef[1], r.georef[3])?;
    writeln!(w, "crs:            {}", r.crs.as_deref().map(short_crs).unwrap_or("none"))?;
    match r.mask {
        Some([mw, mh, n]) => writeln!(w, "mask:           {mw}×{mh}, {n} cells with data")?,
        None => writeln!(w, "mask:           none")?,
    }
    writeln!(w, "indirect:       {}", if r.indirect { "yes (warp field stored)" } else { "no" })
}

/// `info` of a raster.
#[derive(Debug, Serialize)]
pub struct RasterInfo {
    pub file: String,
    pub kind: &'static str,
    pub width: usize,
    pub height: usize,
    /// GDAL order: [x0, dx, rx, y0, ry, dy] of the upper-left corner.
    pub geotransform: [f64; 6],
    pub crs: Option<String>,
    /// The band's nodata marker, if it declares one.
    pub nodata: Option<f64>,
    /// Cells without a value (the marker, NaN, or outside the valid range).
    pub nodata_count: usize,
    pub valid_count: usize,
    /// [min, max] of the valid cells; null when there are none.
    pub range: Option<[f64; 2]>,
}

fn raster_info(r: &raster_io::Raster, name: &str) -> Info {
    let info = RasterInfo {
        file: name.to_string(),
        kind: "raster",
        width: r.width,
        height: r.height,
        geotransform: r.geotransform,
        crs: r.crs.clone(),
        nodata: r.nodata,
        nodata_count: r.nodata_count(),
        valid_count: r.valid_count(),
        range: r.min_max().map(|(a, b)| [a, b]),
    };
    Info::Raster(info)
}

fn write_raster_text(w: &mut dyn Write, info: &RasterInfo) -> std::io::Result<()> {
    let gt = &info.geotransform;
    writeln!(w, "file:         {}", info.file)?;
    writeln!(w, "kind:         raster, {}×{} cells", info.width, info.height)?;
    writeln!(w, "geotransform: {} {} {} {} {} {}", gt[0], gt[1], gt[2], gt[3], gt[4], gt[5])?;
    writeln!(w, "crs:          {}", info.crs.as_deref().map(short_crs).unwrap_or("none"))?;
    writeln!(w, "nodata:       {} cells (marker {})", info.nodata_count, info.nodata.map(|v| v.to_string()).unwrap_or_else(|| "none".into()))?;
    writeln!(w, "valid:        {} cells", info.valid_count)?;
    match info.range {
        Some([a, b]) => writeln!(w, "range:        {a} .. {b}"),
        None => writeln!(w, "range:        none (no valid cell)"),
    }
}

/// `info` of a point file.
#[derive(Debug, Serialize)]
pub struct PointsInfo {
    pub file: String,
    pub kind: &'static str,
    pub points: usize,
    /// [[min x, min y, min z], [max x, max y, max z]]; null for an empty file.
    pub envelope: Option<[[f64; 3]; 2]>,
    pub crs: Option<String>,
}

fn points_info(c: &raster_io::PointCloud, name: &str) -> Info {
    let mut e = Envelope::empty();
    for p in &c.points {
        e.add_point(p);
    }
    let info = PointsInfo { file: name.to_string(), kind: "points", points: c.points.len(), envelope: env(&e), crs: c.crs.clone() };
    Info::Points(info)
}

fn write_points_text(w: &mut dyn Write, info: &PointsInfo) -> std::io::Result<()> {
    writeln!(w, "file:     {}", info.file)?;
    writeln!(w, "kind:     points")?;
    writeln!(w, "points:   {}", info.points)?;
    match info.envelope {
        Some([a, b]) => writeln!(w, "envelope: {} {} {} .. {} {} {}", a[0], a[1], a[2], b[0], b[1], b[2])?,
        None => writeln!(w, "envelope: none")?,
    }
    writeln!(w, "crs:      {}", info.crs.as_deref().map(short_crs).unwrap_or("none"))
}

/// The first line of a CRS for the text report (WKT is long; the JSON keeps all of it).
fn short_crs(s: &str) -> &str {
    let s = s.trim();
    match s.find('[') {
        Some(i) if s.len() > 80 => {
            // PROJCS["name", ... → PROJCS["name"
            let rest = &s[i + 1..];
            let end = rest.find(',').map(|j| i + 1 + j).unwrap_or(s.len());
            &s[..end]
        }
        _ => s,
    }
}

/// Version of the JSON lines a many-file run writes (one object per file, then the summary).
const JSON_LINES_SCHEMA: &str = REPORT.schema;

#[derive(Debug, Default, Serialize)]
struct BatchSummary {
    files: usize,
    /// Read, and nothing to report (exit 0 on their own).
    clean: usize,
    /// Read, with located problems (exit 1 on their own).
    with_findings: usize,
    unreadable: usize,
    wall_seconds: f64,
}

#[derive(Serialize)]
struct SummaryLine<'a> {
    schema: &'static str,
    summary: &'a BatchSummary,
}

/// Several inputs: summarised in parallel, reported in input order (text blocks separated by a
/// blank line, or JSON lines), then a summary; an unreadable input is reported in its place.
fn run_many(inputs: Vec<Input>, json: bool, config: &Config, started: Instant) -> CmdResult {
    // shared by the per-file and the summary writer
    let tally = RefCell::new((BatchSummary::default(), Exit::Ok));
    run_batch(
        inputs,
        "info",
        config,
        summarize,
        |w, name, result| {
            let (summary, worst) = &mut *tally.borrow_mut();
            summary.files += 1;
            let s = match result {
                Ok(s) => s,
                Err(e) => {
                    summary.unreadable += 1;
                    *worst = worse_exit(*worst, e.exit);
                    return write_batch_error(w, json, JSON_LINES_SCHEMA, name, &e);
                }
            };
            for f in &s.findings {
                crate::say!("{f}");
            }
            if s.findings.is_empty() {
                summary.clean += 1;
            } else {
                summary.with_findings += 1;
                *worst = worse_exit(*worst, Exit::Findings);
            }
            if json {
                write_json_line(w, &tagged(&REPORT, s.info.units(), &s.info))
            } else {
                s.info.write_text(w).and_then(|()| writeln!(w)).map_err(CliError::io_out)
            }
        },
        |w| {
            let (summary, _) = &mut *tally.borrow_mut();
            summary.wall_seconds = started.elapsed().as_secs_f64();
            if json {
                return write_json_line(w, &SummaryLine { schema: JSON_LINES_SCHEMA, summary });
            }
            writeln!(
                w,
                "summary: {} files: {} without findings, {} with findings, {} unreadable; {:.3} s",
                summary.files, summary.clean, summary.with_findings, summary.unreadable, summary.wall_seconds
            )
            .map_err(CliError::io_out)
        },
    )?;
    let worst = tally.borrow().1;
    Ok(worst)
}
