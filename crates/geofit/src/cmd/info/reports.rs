//! What `geofit info` reports per kind of input (CityGML, T-mesh, raster, points): the JSON
//! object and the text block of each, with the units of the JSON fields.

use std::io::Write;

use citygml_io::summary::DocumentCounts;
use citygml_io::Envelope;
use serde::Serialize;

use crate::report::{ReportKind, Z_UNIT};

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
    /// Every count of the document, flattened into this object in `DocumentCounts`' order.
    #[serde(flatten)]
    pub counts: DocumentCounts,
    pub unresolved_xlinks: usize,
}

pub(super) fn env(e: &Envelope) -> Option<[[f64; 3]; 2]> {
    (!e.is_empty()).then_some([e.min, e.max])
}

/// What `info` found in one input; serialized as the inner report.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub(super) enum Info {
    CityGml(InfoReport),
    TMesh(TMeshInfo),
    Raster(RasterInfo),
    Points(PointsInfo),
}

/// `--json`: one input's summary, the same object as a line of a many-file run; its units
/// depend on what the input is ([`Info::units`]).
pub(super) const REPORT: ReportKind = ReportKind { schema: "geofit-info/1", units: &[] };

impl Info {
    pub(super) fn units(&self) -> &'static [(&'static str, &'static str)] {
        match self {
            Info::CityGml(_) => &[("envelope", "CRS units"), ("declared_envelope", "CRS units")],
            Info::TMesh(_) => &[("domain", "raster cells (parameter units)"), ("georef", "CRS units (x0, y0, dx, dy)")],
            Info::Raster(_) => &[
                ("width", "cells"),
                ("height", "cells"),
                ("geotransform", "CRS units"),
                ("nodata", Z_UNIT),
                ("range", Z_UNIT),
            ],
            Info::Points(_) => &[("envelope", "CRS units")],
        }
    }

    pub(super) fn write_text(&self, w: &mut dyn Write) -> std::io::Result<()> {
        match self {
            Info::CityGml(r) => write_text(w, r),
            Info::TMesh(r) => write_tmesh_text(w, r),
            Info::Raster(r) => write_raster_text(w, r),
            Info::Points(r) => write_points_text(w, r),
        }
    }
}

fn write_text(w: &mut dyn Write, r: &InfoReport) -> std::io::Result<()> {
    let fmt_env = |e: &Option<[[f64; 3]; 2]>| match e {
        Some([a, b]) => format!("{} {} {} .. {} {} {}", a[0], a[1], a[2], b[0], b[1], b[2]),
        None => "none".to_string(),
    };
    let c = &r.counts;
    writeln!(w, "file:        {}", r.file)?;
    writeln!(w, "version:     CityGML {}", r.version)?;
    writeln!(w, "crs:         {}", r.crs.as_deref().unwrap_or("none"))?;
    writeln!(w, "envelope:    {}", fmt_env(&r.envelope))?;
    if r.declared_envelope.is_some() {
        writeln!(w, "declared:    {}", fmt_env(&r.declared_envelope))?;
    }
    let all: usize = c.feature_types.values().sum();
    writeln!(w, "objects:     {} top-level, {} in all", c.top_level_objects, all)?;
    writeln!(w, "feature types:")?;
    for (k, v) in &c.feature_types {
        writeln!(w, "  {k:<28} {v:>8}")?;
    }
    writeln!(w, "levels of detail:            geometries polygons")?;
    for (k, v) in &c.lods {
        writeln!(w, "  {k:<28} {:>8} {:>8}", v.geometries, v.polygons)?;
    }
    writeln!(w, "solids:      {}", c.solids)?;
    writeln!(w, "polygons:    {}", c.polygons)?;
    writeln!(w, "rings:       {} ({} interior)", c.rings, c.interior_rings)?;
    writeln!(w, "points:      {}", c.points)?;
    if c.triangles > 0 {
        writeln!(w, "triangles:   {} (TIN)", c.triangles)?;
    }
    writeln!(w, "xlinks:      {} resolved, {} unresolved", c.xlinks_resolved, r.unresolved_xlinks)?;
    Ok(())
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

pub(super) fn tmesh_info(f: &tspline::format::TMeshFile, name: &str) -> Info {
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
    /// The unit of the heights as band 1 declares it (GDAL's unit type: "m", "km", "US survey
    /// foot", ...); null when it declares none.
    pub z_unit: Option<String>,
    /// How many bands the file has (the report is of band 1).
    pub bands: usize,
}

pub(super) fn raster_info(r: &raster_io::Raster, name: &str, bands: usize) -> Info {
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
        z_unit: r.z_unit.clone(),
        bands,
    };
    Info::Raster(info)
}

fn write_raster_text(w: &mut dyn Write, info: &RasterInfo) -> std::io::Result<()> {
    let gt = &info.geotransform;
    writeln!(w, "file:         {}", info.file)?;
    let bands = if info.bands > 1 { format!(", {} bands (this is band 1)", info.bands) } else { String::new() };
    writeln!(w, "kind:         raster, {}×{} cells{bands}", info.width, info.height)?;
    writeln!(w, "geotransform: {} {} {} {} {} {}", gt[0], gt[1], gt[2], gt[3], gt[4], gt[5])?;
    writeln!(w, "crs:          {}", info.crs.as_deref().map(short_crs).unwrap_or("none"))?;
    writeln!(
        w,
        "nodata:       {} cells (marker {})",
        info.nodata_count,
        info.nodata.map(|v| v.to_string()).unwrap_or_else(|| "none".into())
    )?;
    writeln!(w, "valid:        {} cells", info.valid_count)?;
    match info.range {
        Some([a, b]) => writeln!(w, "range:        {a} .. {b}")?,
        None => writeln!(w, "range:        none (no valid cell)")?,
    }
    let unit = match &info.z_unit {
        Some(u) => match raster_io::units::parse_length_unit(u) {
            Some(l) if l.name == u.as_str() => u.clone(),
            Some(l) => format!("{u} ({})", l.name),
            None => format!("{u} (not a unit of length geofit knows: fit and diff need --z-unit)"),
        },
        None => "none declared (taken as metres)".into(),
    };
    writeln!(w, "z unit:       {unit}")
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

pub(super) fn points_info(c: &raster_io::PointCloud, name: &str) -> Info {
    let mut e = Envelope::empty();
    for p in &c.points {
        e.add_point(p);
    }
    let info = PointsInfo {
        file: name.to_string(),
        kind: "points",
        points: c.points.len(),
        envelope: env(&e),
        crs: c.crs.clone(),
    };
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
