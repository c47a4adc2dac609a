//! CityJSON → CityGML 2.0 text, one top-level city object (with its parts) at a time. Each
//! top-level object is written on one line, on the line number the caller asks for, so a
//! finding located in the CityGML text names the CityJSONSeq line of its feature
//! (docs/decisions.md#cityjson-at-the-edges).

mod attributes;
pub(crate) mod geometry;

use std::collections::HashSet;
use std::fmt::Write as _;
use std::io::Write;

use serde_json::{Map, Value};

use crate::report::Report;
use crate::transform::{format_number, Transform};
use crate::xml::{escape, CITYGML2_NAMESPACES};
use crate::{crs, CityJsonError};
use geometry::{GeomContext, GeomOut};

/// How strictly the CityGML written must follow the CityGML 2.0 schema.
#[derive(Debug, Clone, Copy, Default)]
pub struct GmlOptions {
    /// `true` (what `convert` writes): one geometry per `lodN…` property, as the schema has
    /// it; further geometries of one LoD are left out and reported. `false` (the buildings
    /// commands' view of a CityJSON input): every geometry is kept, so a write-back loses none.
    pub strict: bool,
}

/// What the document's first member(s) say about all its objects.
#[derive(Debug, Clone)]
pub struct DocHeader {
    pub transform: Transform,
    pub srs_name: Option<String>,
    pub extent: Option<[f64; 6]>,
    /// `geometry-templates`: the templates and their (real, not quantised) vertices.
    pub templates: Option<(Vec<Value>, Vec<[f64; 3]>)>,
    pub version: String,
}

impl DocHeader {
    /// From a CityJSON document or the first line of a CityJSONSeq (`"type": "CityJSON"`).
    pub fn from_json(v: &Value, report: &mut Report) -> Result<DocHeader, CityJsonError> {
        let err = |m: String| CityJsonError::structure(None, m);
        if v.get("type").and_then(Value::as_str) != Some("CityJSON") {
            return Err(err("not a CityJSON document (its \"type\" is not \"CityJSON\")".into()));
        }
        let version = v.get("version").and_then(Value::as_str).unwrap_or("").to_string();
        if !matches!(version.as_str(), "2.0" | "1.1" | "2.0.1" | "2.0.0") {
            return Err(err(format!(
                "CityJSON version \"{version}\": geofit reads 2.0 and 1.1 (upgrade with cjio FILE upgrade save OUT)"
            )));
        }
        let transform = Transform::from_json(v.get("transform")).map_err(err)?;
        let meta = v.get("metadata");
        let srs_name = meta.and_then(|m| m.get("referenceSystem")).and_then(Value::as_str).map(crs::to_srs_name);
        let extent = meta.and_then(|m| m.get("geographicalExtent")).and_then(Value::as_array).and_then(|a| {
            let n: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
            <[f64; 6]>::try_from(n).ok()
        });
        if let Some(m) = meta.and_then(Value::as_object) {
            for k in m.keys().filter(|k| !matches!(k.as_str(), "referenceSystem" | "geographicalExtent")) {
                report.add(format!("metadata \"{k}\" (no CityGML counterpart)"), None);
            }
        }
        for k in ["appearance", "extensions"] {
            if v.get(k).is_some() {
                report.add(format!("document \"{k}\" (not carried to CityGML)"), None);
            }
        }
        let templates = match v.get("geometry-templates") {
            None => None,
            Some(t) => {
                let list = t.get("templates").and_then(Value::as_array).cloned().unwrap_or_default();
                let verts = t
                    .get("vertices-templates")
                    .and_then(Value::as_array)
                    .map(|a| real_vertices(a, &Transform::default()))
                    .transpose()?
                    .unwrap_or_default();
                Some((list, verts))
            }
        };
        Ok(DocHeader { transform, srs_name, extent, templates, version })
    }
}

/// Vertices as real coordinates.
pub fn real_vertices(a: &[Value], t: &Transform) -> Result<Vec<[f64; 3]>, CityJsonError> {
    a.iter()
        .enumerate()
        .map(|(i, v)| {
            let n: Vec<f64> = v.as_array().map(|x| x.iter().filter_map(Value::as_f64).collect()).unwrap_or_default();
            match n[..] {
                [x, y, z] => Ok(t.apply([x, y, z])),
                _ => Err(CityJsonError::structure(None, format!("vertex {i} is not three numbers"))),
            }
        })
        .collect()
}

/// Writes CityGML 2.0: [`GmlWriter::begin`], then [`GmlWriter::write_object`] for each top-level
/// object, then [`GmlWriter::finish`].
pub struct GmlWriter<W: Write> {
    out: W,
    header: DocHeader,
    opts: GmlOptions,
    line: usize,
    pub report: Report,
}

impl<W: Write> GmlWriter<W> {
    /// Writes the XML declaration, the root and the envelope, all on line 1.
    pub fn begin(
        mut out: W,
        header: DocHeader,
        opts: GmlOptions,
        report: Report,
    ) -> Result<GmlWriter<W>, CityJsonError> {
        let mut s = format!("<?xml version=\"1.0\" encoding=\"UTF-8\"?><core:CityModel {CITYGML2_NAMESPACES}>");
        if let Some(e) = header.extent {
            let d = header.transform.decimals();
            let srs = header.srs_name.as_ref().map(|s| format!(" srsName=\"{}\"", escape(s))).unwrap_or_default();
            let f = |a: &[f64]| a.iter().map(|v| format_number(*v, d)).collect::<Vec<_>>().join(" ");
            let _ = write!(s, "<gml:boundedBy><gml:Envelope{srs} srsDimension=\"3\"><gml:lowerCorner>{}</gml:lowerCorner><gml:upperCorner>{}</gml:upperCorner></gml:Envelope></gml:boundedBy>", f(&e[..3]), f(&e[3..]));
        }
        out.write_all(s.as_bytes())?;
        Ok(GmlWriter { out, header, opts, line: 1, report })
    }

    pub fn header(&self) -> &DocHeader {
        &self.header
    }

    /// Writes top-level object `id` of `objects` (its children with it) as one
    /// `core:cityObjectMember`, starting on line `line` if that is below the current one.
    pub fn write_object(
        &mut self,
        id: &str,
        objects: &Map<String, Value>,
        vertices: &[[f64; 3]],
        line: Option<usize>,
    ) -> Result<(), CityJsonError> {
        let mut e = Emitter {
            objects,
            vertices,
            header: &self.header,
            opts: self.opts,
            report: &mut self.report,
            ids: HashSet::new(),
            depth: 0,
        };
        let Some(xml) = e.object(id)? else { return Ok(()) };
        let target = line.unwrap_or(self.line + 1).max(self.line);
        let pad = "\n".repeat(target - self.line);
        self.line = target;
        write!(self.out, "{pad}<core:cityObjectMember>{xml}</core:cityObjectMember>")?;
        Ok(())
    }

    /// Closes the root; returns the sink and the report.
    pub fn finish(mut self) -> Result<(W, Report), CityJsonError> {
        self.out.write_all(b"\n</core:CityModel>\n")?;
        self.out.flush()?;
        Ok((self.out, self.report))
    }
}

/// The ids of `objects` that are not children of another (`parents` empty or absent).
pub fn top_level_ids(objects: &Map<String, Value>) -> Vec<&str> {
    objects
        .iter()
        .filter(|(_, o)| o.get("parents").and_then(Value::as_array).is_none_or(|p| p.is_empty()))
        .map(|(id, _)| id.as_str())
        .collect()
}

/// A CityJSON object type's CityGML 2.0 element and the properties its module defines.
fn element_of(ty: &str) -> Option<(&'static str, &'static str, &'static [&'static str])> {
    Some(match ty {
        "Building" => ("bldg", "Building", attributes::BUILDING_PROPERTIES),
        "BuildingPart" => ("bldg", "BuildingPart", attributes::BUILDING_PROPERTIES),
        "BuildingInstallation" => ("bldg", "BuildingInstallation", attributes::OTHER_PROPERTIES),
        "BuildingRoom" => ("bldg", "Room", attributes::OTHER_PROPERTIES),
        "BuildingFurniture" => ("bldg", "BuildingFurniture", attributes::OTHER_PROPERTIES),
        "GenericCityObject" => ("gen", "GenericCityObject", attributes::OTHER_PROPERTIES),
        _ => return None,
    })
}

/// The property linking a child object to its parent (a building or part, or a room).
fn child_property(parent: &str, child: &str) -> Option<&'static str> {
    Some(match (parent, child) {
        ("Building" | "BuildingPart", "BuildingPart") => "consistsOfBuildingPart",
        ("Building" | "BuildingPart", "BuildingInstallation") => "outerBuildingInstallation",
        ("Building" | "BuildingPart", "BuildingRoom") => "interiorRoom",
        ("BuildingRoom", "BuildingFurniture") => "interiorFurniture",
        ("BuildingRoom", "BuildingInstallation") => "roomInstallation",
        _ => return None,
    })
}

struct Emitter<'a> {
    objects: &'a Map<String, Value>,
    vertices: &'a [[f64; 3]],
    header: &'a DocHeader,
    opts: GmlOptions,
    report: &'a mut Report,
    ids: HashSet<String>,
    depth: usize,
}

impl Emitter<'_> {
    /// One object and its children, or `None` (reported) when CityGML 2.0 has no place for it.
    fn object(&mut self, id: &str) -> Result<Option<String>, CityJsonError> {
        let o = self
            .objects
            .get(id)
            .ok_or_else(|| CityJsonError::structure(Some(id), "listed as a child but not among the CityObjects"))?;
        let ty = o
            .get("type")
            .and_then(Value::as_str)
            .ok_or_else(|| CityJsonError::structure(Some(id), "city object without \"type\""))?;
        let Some((prefix, element, props)) = element_of(ty) else {
            self.report.add(format!("{ty} object (no CityGML 2.0 building-module counterpart: left out)"), Some(id));
            return Ok(None);
        };
        if self.depth > 16 {
            return Err(CityJsonError::structure(Some(id), "children nested more than 16 deep (a cycle?)"));
        }
        self.ids.insert(id.to_string());
        for k in o.as_object().map(|m| m.keys()).into_iter().flatten() {
            if !matches!(k.as_str(), "type" | "attributes" | "geometry" | "children" | "parents" | "geographicalExtent")
            {
                self.report.add(format!("object member \"{k}\" (not carried to CityGML)"), Some(id));
            }
        }
        let empty = Map::new();
        let attrs = o.get("attributes").and_then(Value::as_object).unwrap_or(&empty);
        let a = attributes::attributes(attrs, prefix, props, id, self.report);
        let geoms = self.geometries(id, o, ty)?;
        let mut children: Vec<(usize, String)> = Vec::new();
        for c in o.get("children").and_then(Value::as_array).into_iter().flatten().filter_map(Value::as_str) {
            let cty = self.objects.get(c).and_then(|x| x.get("type")).and_then(Value::as_str).unwrap_or("");
            let Some(prop) = child_property(ty, cty) else {
                self.report.add(format!("{cty} child of a {ty} (no CityGML 2.0 property for it: left out)"), Some(c));
                continue;
            };
            self.depth += 1;
            let xml = self.object(c)?;
            self.depth -= 1;
            if let Some(xml) = xml {
                children.push((rank(ty, prop, 9), format!("<bldg:{prop}>{xml}</bldg:{prop}>")));
            }
        }
        let mut parts: Vec<(usize, String)> = geoms;
        parts.extend(children);
        parts.sort_by_key(|(r, _)| *r);
        let mut x = format!("<{prefix}:{element} gml:id=\"{}\">{}{}{}", escape(id), a.gml_core, a.generic, a.module);
        parts.into_iter().for_each(|(_, p)| x.push_str(&p));
        let _ = write!(x, "</{prefix}:{element}>");
        Ok(Some(x))
    }

    /// Every geometry of an object as ranked property elements (geometry and boundedBy).
    fn geometries(&mut self, id: &str, o: &Value, ty: &str) -> Result<Vec<(usize, String)>, CityJsonError> {
        let (prefix, _, _) = element_of(ty).expect("checked");
        let decimals = self.header.transform.decimals();
        let mut out = Vec::new();
        let mut used: HashSet<String> = HashSet::new();
        for (k, g) in o.get("geometry").and_then(Value::as_array).into_iter().flatten().enumerate() {
            let (g, verts) = self.resolve(id, g)?;
            // Without an envelope to carry it, each geometry names the CRS.
            let srs_name = if self.header.extent.is_none() { self.header.srs_name.as_deref() } else { None };
            // CityGML 2.0 rooms and their furniture exist in LoD 4 only (CityJSON has no LoD 4).
            let lod_override = matches!(ty, "BuildingRoom" | "BuildingFurniture").then_some(4);
            let mut ctx = GeomContext {
                object: id,
                index: k,
                vertices: verts.as_deref().unwrap_or(self.vertices),
                decimals,
                srs_name,
                lod_override,
                ids: &mut self.ids,
                report: self.report,
            };
            let Some(GeomOut { lod, kind, xml, boundary }) = geometry::emit(&mut ctx, &g)? else { continue };
            let prop = property_name(ty, lod, kind, &used);
            if self.opts.strict && used.contains(&prop) {
                self.report.add(format!("second {prop} of one object (CityGML 2.0 holds one: left out)"), Some(id));
                continue;
            }
            used.insert(prop.clone());
            out.push((rank(ty, &prop, lod), format!("<{prefix}:{prop}>{xml}</{prefix}:{prop}>")));
            let b = rank(ty, "boundedBy", lod);
            out.extend(boundary.into_iter().map(|x| (b, x)));
        }
        Ok(out)
    }

    /// A geometry instance expanded from its template (vertices transformed), else as it is.
    fn resolve(&mut self, id: &str, g: &Value) -> Result<(Value, Option<Vec<[f64; 3]>>), CityJsonError> {
        if g.get("type").and_then(Value::as_str) != Some("GeometryInstance") {
            return Ok((g.clone(), None));
        }
        let (templates, tverts) = self
            .header
            .templates
            .as_ref()
            .ok_or_else(|| CityJsonError::structure(Some(id), "GeometryInstance but no \"geometry-templates\""))?;
        let t = g
            .get("template")
            .and_then(Value::as_u64)
            .and_then(|i| templates.get(i as usize))
            .ok_or_else(|| CityJsonError::structure(Some(id), "GeometryInstance names no existing template"))?;
        let m: Vec<f64> = g
            .get("transformationMatrix")
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default();
        let refv = g
            .get("boundaries")
            .and_then(|b| b.get(0))
            .and_then(Value::as_u64)
            .and_then(|i| self.vertices.get(i as usize))
            .copied();
        let (Some(r), 16) = (refv, m.len()) else {
            return Err(CityJsonError::structure(
                Some(id),
                "GeometryInstance without a reference vertex or a 4×4 transformationMatrix",
            ));
        };
        let verts = tverts
            .iter()
            .map(|p| {
                [0, 1, 2].map(|i| m[4 * i] * p[0] + m[4 * i + 1] * p[1] + m[4 * i + 2] * p[2] + m[4 * i + 3] + r[i])
            })
            .collect();
        self.report.add("geometry instance (template expanded into its own geometry)", Some(id));
        let mut expanded = t.clone();
        if let (Some(lod), Some(obj)) = (t.get("lod").cloned(), expanded.as_object_mut()) {
            obj.insert("lod".into(), lod);
        }
        Ok((expanded, Some(verts)))
    }
}

/// `lod2Solid`, `lod2MultiSurface`, `lod0FootPrint` then `lod0RoofEdge`, `lod2Geometry`.
fn property_name(ty: &str, lod: u8, kind: &str, used: &HashSet<String>) -> String {
    match ty {
        "BuildingInstallation" | "GenericCityObject" | "BuildingFurniture" => format!("lod{lod}Geometry"),
        _ if lod == 0 => {
            if used.contains("lod0FootPrint") {
                "lod0RoofEdge".into()
            } else {
                "lod0FootPrint".into()
            }
        }
        _ => format!("lod{lod}{kind}"),
    }
}

/// Schema order of the properties after the attributes (CityGML 2.0 building.xsd).
fn rank(ty: &str, prop: &str, lod: u8) -> usize {
    let building = matches!(ty, "Building" | "BuildingPart");
    match prop {
        "lod0FootPrint" => 0,
        "lod0RoofEdge" => 1,
        "outerBuildingInstallation" => 60,
        "boundedBy" if building => 70,
        "boundedBy" => 100,
        "interiorFurniture" => 104,
        "roomInstallation" => 105,
        "interiorRoom" => 110,
        "consistsOfBuildingPart" => 120,
        p => {
            let base = if building && lod >= 3 { 80 + 10 * (lod as usize - 3) } else { 10 * lod as usize };
            base + usize::from(p.ends_with("MultiSurface")) + 2 * usize::from(p.ends_with("Geometry"))
        }
    }
}
