//! `geofit info`: what a file holds. CityGML: version, CRS, envelope, counts per feature type
//! and LoD, polygons, rings, points, read object by object (bounded memory on big tiles).
//! Also T-meshes (degree, cells, control points, georeference, mask), rasters (anything GDAL
//! opens: size, geotransform, CRS, nodata marker and count, value range) and point files
//! (XYZ/CSV text, LAS/LAZ: count, bounds, CRS). The kind comes from the extension where it is
//! unambiguous, otherwise from the content (root element, then GDAL, then XYZ text).
//! This file reads one input; `reports.rs` holds what is reported per kind, `many.rs` the
//! many-file run.

mod many;
mod reports;

use std::time::Instant;

use citygml_io::summary::DocumentCounts;
use citygml_io::{ObjectStream, ReadError};
use clap::Args as ClapArgs;

use crate::config::{batch_inputs, Config, Input, CITYGML_EXTENSIONS};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::print_report_with_units;
use reports::{env, points_info, raster_info, tmesh_info, Info, InfoReport, REPORT};

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
  $ geofit info --json gmt_Kilauea.utm.nc | jq '.width, .height, .geotransform, .nodata_count, .z_unit, .bands'
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
        return many::run(inputs, args.json, config, started);
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
        (Some(Kind::Raster), Some(p)) => return Ok(raster_info(&read_raster_path(p)?, &name, band_count(p)).into()),
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
            return Ok(raster_info(&r, &name, input.path().map_or(1, band_count)).into());
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
            format!(
                "{name}:{}:{}: gml:LinearRing has {n} positions, at least 4 are needed (closed ring of 3 points)",
                span.line, span.column
            )
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
        counts,
        unresolved_xlinks: stream.unresolved_xlinks().len(),
    };
    Ok(Summary { info: Info::CityGml(report), findings })
}

/// Reads a raster by path; errors name the file.
fn read_raster_path(p: &std::path::Path) -> Result<raster_io::Raster, CliError> {
    raster_io::read_raster(p).map_err(|e| CliError::unreadable(e.to_string()))
}

/// How many bands a raster file has (1 where GDAL cannot say).
fn band_count(p: &std::path::Path) -> usize {
    raster_io::bands(p).map_or(1, |b| b.len().max(1))
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
