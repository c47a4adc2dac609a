//! Runs the geometric checks over a whole [`CityModel`] and locates each issue in the document
//! (feature gml:id, primitive gml:id, line:column).

use crate::polygon::PolygonInput;
use crate::{check_composite_solid, check_solid, check_surfaces, ErrorCode, Issue, Options};
use citygml_io::{CityModel, CityObject, Geometry, GeometryKind, Polygon, Shell};
use rayon::prelude::*;
use serde::Serialize;

/// One geometric finding, ready for a report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// gml:id of the city object that holds the geometry.
    pub feature: Option<String>,
    /// Its element name (`Building`, `WallSurface`, ...).
    pub feature_type: String,
    /// Geometry property (`lod2Solid`, `lod2MultiSurface`, ...).
    pub geometry: String,
    /// gml:id of the failing primitive (ring, polygon, or the solid), when it has one.
    pub primitive: Option<String>,
    pub code: u16,
    pub name: &'static str,
    pub detail: String,
    /// The measured quantity (plane distance m, normal deviation °, ring gap m), when there is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    pub line: usize,
    pub column: usize,
}

fn to_inputs<'a>(polys: &[&'a Polygon]) -> Vec<PolygonInput<'a>> {
    polys
        .iter()
        .map(|p| PolygonInput {
            exterior: &p.exterior.points,
            interiors: p.interiors.iter().map(|r| r.points.as_slice()).collect(),
            reversed: p.reversed,
        })
        .collect()
}

fn locate(obj: &CityObject, geom: &Geometry, shells: &[Vec<&Polygon>], issue: Issue) -> Finding {
    let shell = issue.shell.unwrap_or(0);
    let poly = issue.polygon.and_then(|i| shells.get(shell).and_then(|s| s.get(i)).copied());
    let (primitive, span) = match (poly, issue.ring) {
        (Some(p), Some(r)) => {
            let ring = if r == 0 { Some(&p.exterior) } else { p.interiors.get(r - 1) };
            match ring {
                Some(ring) => {
                    (ring.id.clone().or_else(|| p.id.clone()), if ring.span.line > 0 { &ring.span } else { &p.span })
                }
                None => (p.id.clone(), &p.span),
            }
        }
        (Some(p), None) => (p.id.clone(), &p.span),
        _ => (geom.id.clone(), &geom.span),
    };
    let mut detail = issue.detail;
    if let Some(i) = issue.polygon {
        if poly.is_none_or(|p| p.id.is_none()) {
            detail = format!("polygon #{}: {}", i + 1, detail);
        }
    }
    if shells.len() > 1 {
        if let Some(s) = issue.shell {
            detail = format!("shell {}: {}", s + 1, detail);
        }
    }
    Finding {
        feature: obj.id.clone(),
        feature_type: obj.kind.clone(),
        geometry: geom.property.clone(),
        primitive,
        code: issue.code.code(),
        name: issue.code.name(),
        detail,
        value: issue.value,
        line: span.line,
        column: span.column,
    }
}

fn shell_polys(s: &Shell) -> Vec<&Polygon> {
    s.polygons.iter().collect()
}

fn check_geometry(obj: &CityObject, geom: &Geometry, opts: &Options) -> Vec<Finding> {
    let mut out = Vec::new();
    match &geom.kind {
        GeometryKind::Surfaces(ps) => {
            let polys: Vec<&Polygon> = ps.iter().collect();
            let shells = vec![polys];
            for is in check_surfaces(&to_inputs(&shells[0]), opts) {
                out.push(locate(obj, geom, &shells, is));
            }
        }
        GeometryKind::Solid { exterior, interior } => {
            let shells: Vec<Vec<&Polygon>> =
                std::iter::once(exterior).chain(interior.iter()).map(shell_polys).collect();
            let inp: Vec<Vec<PolygonInput>> = shells.iter().map(|s| to_inputs(s)).collect();
            for is in check_solid(&inp, opts) {
                out.push(locate(obj, geom, &shells, is));
            }
        }
        GeometryKind::Solids(_) if !geom.skipped_members.is_empty() => {
            // Members the reader could not represent (an XLink to nothing, not to a solid, ...):
            // each is a finding; the solids that are there are checked one by one, not how they
            // fit together (501–503 on an incomplete CompositeSolid would be guesses).
            for m in &geom.skipped_members {
                let composite = if geom.gml_type == "CompositeSolid" {
                    "; the other solids of the CompositeSolid are checked one by one, not how they fit together"
                } else {
                    ""
                };
                out.push(Finding {
                    feature: obj.id.clone(),
                    feature_type: obj.kind.clone(),
                    geometry: geom.property.clone(),
                    primitive: geom.id.clone(),
                    code: ErrorCode::InvalidInputFile.code(),
                    name: ErrorCode::InvalidInputFile.name(),
                    detail: if geom.gml_type == "xlink" {
                        format!("the geometry {} refers to is left out: {}", geom.property, m.reason)
                    } else {
                        format!("gml:{} member left out: {}{composite}", geom.gml_type, m.reason)
                    },
                    value: None,
                    line: m.span.line,
                    column: m.span.column,
                });
            }
            out.extend(check_solids_one_by_one(obj, geom, opts));
        }
        GeometryKind::Solids(solids) if geom.gml_type == "CompositeSolid" => {
            // the solids of a CompositeSolid must also fit together (501–503)
            let shells: Vec<Vec<Vec<&Polygon>>> = solids
                .iter()
                .map(|(ext, ints)| std::iter::once(ext).chain(ints.iter()).map(shell_polys).collect())
                .collect();
            let inp: Vec<Vec<Vec<PolygonInput>>> =
                shells.iter().map(|s| s.iter().map(|p| to_inputs(p)).collect()).collect();
            for (k, is) in check_composite_solid(&inp, opts) {
                let between = is.shell.is_none();
                let mut f = locate(obj, geom, &shells[k], is);
                if !between && solids.len() > 1 {
                    f.detail = format!("solid {}: {}", k + 1, f.detail);
                }
                out.push(f);
            }
        }
        GeometryKind::Solids(_) => out.extend(check_solids_one_by_one(obj, geom, opts)),
    }
    out
}

/// The solids of a MultiSolid (or of an incomplete CompositeSolid), each on its own.
fn check_solids_one_by_one(obj: &CityObject, geom: &Geometry, opts: &Options) -> Vec<Finding> {
    let mut out = Vec::new();
    let GeometryKind::Solids(solids) = &geom.kind else { return out };
    for (k, (ext, ints)) in solids.iter().enumerate() {
        let shells: Vec<Vec<&Polygon>> = std::iter::once(ext).chain(ints.iter()).map(shell_polys).collect();
        let inp: Vec<Vec<PolygonInput>> = shells.iter().map(|s| to_inputs(s)).collect();
        for is in check_solid(&inp, opts) {
            let mut f = locate(obj, geom, &shells, is);
            if solids.len() > 1 {
                f.detail = format!("solid {}: {}", k + 1, f.detail);
            }
            out.push(f);
        }
    }
    out
}

/// Validates every geometry of one top-level city object and everything nested in it.
pub fn validate_object(top: &CityObject, opts: &Options) -> Vec<Finding> {
    let mut v = Vec::new();
    for obj in top.walk() {
        for g in &obj.geometries {
            v.extend(check_geometry(obj, g, opts));
        }
    }
    v
}

/// Validates the geometries of exactly these objects (no walking into their children): one
/// conversion unit of a tool that changes geometry building by building (`geofit heal`
/// compares a unit's findings before and after).
pub fn validate_objects_only(objects: &[&CityObject], opts: &Options) -> Vec<Finding> {
    let mut v: Vec<Finding> =
        objects.iter().flat_map(|o| o.geometries.iter().flat_map(|g| check_geometry(o, g, opts))).collect();
    sort_findings(&mut v);
    v
}

/// Validates top-level objects in parallel; findings come back sorted by position in the
/// document (see [`sort_findings`]).
pub fn validate_objects(objects: &[CityObject], opts: &Options) -> Vec<Finding> {
    let mut all: Vec<Finding> = objects.par_iter().flat_map_iter(|top| validate_object(top, opts)).collect();
    sort_findings(&mut all);
    all
}

/// Sorts findings by position in the document and drops repeats: a polygon reached twice
/// (defined in a boundary surface and referenced by a solid through an XLink) is reported once.
pub fn sort_findings(all: &mut Vec<Finding>) {
    all.sort_by(|a, b| {
        (a.line, a.column, a.code, &a.detail, &a.feature).cmp(&(b.line, b.column, b.code, &b.detail, &b.feature))
    });
    all.dedup_by(|a, b| a.line == b.line && a.column == b.column && a.code == b.code && a.detail == b.detail);
}

/// Validates a whole model (see [`validate_objects`]).
pub fn validate_model(model: &CityModel, opts: &Options) -> Vec<Finding> {
    let mut out = validate_objects(&model.objects, opts);
    add_unresolved_xlinks(&mut out, &model.unresolved_xlinks);
    sort_findings(&mut out);
    out
}

/// One 901 finding per `xlink:href` that brings no geometry in (its id names nothing in the
/// document, or an element that is not a geometry; a solid that lists it is open for that
/// reason), under the object that holds it, unless the same place already has a 901 (a
/// CompositeSolid member left out names its href itself).
pub fn add_unresolved_xlinks(findings: &mut Vec<Finding>, refs: &[citygml_io::XLinkRef]) {
    let code = ErrorCode::InvalidInputFile;
    let mut at: std::collections::HashSet<(usize, usize)> =
        findings.iter().filter(|f| f.code == code.code()).map(|f| (f.line, f.column)).collect();
    for r in refs {
        let (line, column) = (r.span.line, r.span.column);
        if !at.insert((line, column)) {
            continue;
        }
        findings.push(Finding {
            feature: r.feature.clone(),
            feature_type: r.feature_type.clone(),
            geometry: String::new(),
            primitive: None,
            code: code.code(),
            name: code.name(),
            detail: r.reason(),
            value: None,
            line,
            column,
        });
    }
}
