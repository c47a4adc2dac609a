//! `geofit info`: what a CityGML file holds — version, CRS, envelope, counts per feature type
//! and LoD, polygons, rings, points. Reads object by object (bounded memory on big tiles).

use std::collections::BTreeMap;
use std::io::Write;

use citygml_io::{CityObject, Envelope, ObjectStream, ReadError};
use clap::Args as ClapArgs;
use serde::Serialize;

use crate::config::{Config, Input, Output};
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

Counts are of definitions: a polygon referenced by xlink:href (the faces of an NRW lod2Solid)
is counted once, where it is defined; `xlinks_resolved` says how many references were followed.
Exit 1 when the file is readable but has rings with fewer than 4 positions or XLinks whose
target is missing (each listed on stderr as FILE:LINE:COL); exit 3 when it cannot be read.";

#[derive(ClapArgs, Debug)]
#[command(about = "Summarise a CityGML file: version, CRS, envelope, feature/LoD/polygon counts", after_help = EXAMPLE)]
pub struct Args {
    /// CityGML file (1.0, 2.0 or 3.0), or `-` for stdin.
    pub input: String,
    /// Print the report as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Default, Serialize)]
pub struct LodCounts {
    /// Geometry properties with this LoD (`lod2Solid`, `lod2MultiSurface`, ...).
    pub geometries: usize,
    /// Polygons defined in them.
    pub polygons: usize,
}

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
    /// Every city object, nested ones included (Building, BuildingPart, WallSurface, ...).
    pub feature_types: BTreeMap<String, usize>,
    /// Keyed `lod0`..`lod4`, or `none` for geometry without a LoD in its property name.
    pub lods: BTreeMap<String, LodCounts>,
    pub solids: usize,
    pub polygons: usize,
    pub rings: usize,
    /// Triangles of TIN reliefs (gml:TriangulatedSurface / gml:Tin), not counted as polygons.
    pub triangles: usize,
    pub interior_rings: usize,
    pub points: usize,
    pub xlinks_resolved: usize,
    pub unresolved_xlinks: usize,
}

fn env(e: &Envelope) -> Option<[[f64; 3]; 2]> {
    (!e.is_empty()).then_some([e.min, e.max])
}

pub fn run(args: Args, _config: &Config) -> CmdResult {
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let src = input.read_all()?;
    let located = |e: ReadError| CliError::unreadable(format!("{name}:{e}"));

    let mut stream = ObjectStream::new(&src).map_err(located)?;
    let mut feature_types = BTreeMap::new();
    let mut lods: BTreeMap<String, LodCounts> = BTreeMap::new();
    let mut envelope = Envelope::empty();
    let (mut top, mut solids, mut polygons, mut rings, mut interior_rings, mut points, mut xlinks) =
        (0, 0, 0, 0, 0, 0, 0usize);
    let mut findings: Vec<String> = Vec::new();
    let mut triangles = 0usize;
    for obj in &mut stream {
        let obj: CityObject = obj.map_err(located)?;
        // One href may stand for several polygons (a CompositeSurface): count hrefs, not copies.
        let mut hrefs = std::collections::HashSet::new();
        top += 1;
        envelope.merge(&obj.envelope);
        for o in obj.walk() {
            *feature_types.entry(o.kind.clone()).or_insert(0) += 1;
            for g in &o.geometries {
                let key = g.lod.map(|l| format!("lod{l}")).unwrap_or_else(|| "none".into());
                let lc = lods.entry(key).or_default();
                lc.geometries += 1;
                solids += match &g.kind {
                    citygml_io::GeometryKind::Solid { .. } => 1,
                    citygml_io::GeometryKind::Solids(v) => v.len(),
                    citygml_io::GeometryKind::Surfaces(_) => 0,
                };
                let tin = matches!(g.gml_type.as_str(), "TriangulatedSurface" | "Tin");
                for p in g.polygons() {
                    if tin {
                        triangles += 1;
                        continue;
                    }
                    if let Some(v) = &p.via_xlink {
                        hrefs.insert(v.bytes.start);
                        continue;
                    }
                    lc.polygons += 1;
                    polygons += 1;
                    for r in std::iter::once(&p.exterior).chain(&p.interiors) {
                        rings += 1;
                        points += r.points.len();
                        if r.points.len() < 4 {
                            findings.push(format!(
                                "{name}:{}:{}: gml:LinearRing has {} positions, at least 4 are needed (closed ring of 3 points)",
                                r.span.line,
                                r.span.column,
                                r.points.len()
                            ));
                        }
                    }
                    interior_rings += p.interiors.len();
                }
            }
        }
        xlinks += hrefs.len();
    }
    for u in stream.unresolved_xlinks() {
        findings.push(format!(
            "{name}:{}:{}: xlink:href=\"{}\" points to nothing in the document",
            u.span.line, u.span.column, u.href
        ));
    }
    let report = InfoReport {
        file: name.clone(),
        version: stream.version().as_str().to_string(),
        crs: stream.srs_name(),
        envelope: env(&envelope),
        declared_envelope: stream.declared_envelope().as_ref().and_then(env),
        top_level_objects: top,
        feature_types,
        lods,
        solids,
        polygons,
        rings,
        triangles,
        interior_rings,
        points,
        xlinks_resolved: xlinks,
        unresolved_xlinks: stream.unresolved_xlinks().len(),
    };
    Output::Stdout.write_with(|w| {
        if args.json {
            serde_json::to_writer_pretty(&mut *w, &report).map_err(|e| CliError::internal(e.to_string()))?;
            writeln!(w).map_err(CliError::io_out)
        } else {
            write_text(w, &report).map_err(CliError::io_out)
        }
    })?;
    for f in &findings {
        eprintln!("{f}");
    }
    Ok(if findings.is_empty() { Exit::Ok } else { Exit::Findings })
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
