//! One CityJSON geometry → its CityGML 2.0 property. Semantic faces are defined once, inside
//! the boundary surface (`bldg:WallSurface`, ...) that their semantic object becomes, and the
//! geometry points to them by `xlink:href`; faces without semantics are written inline
//! (docs/decisions.md#cityjson-semantics-as-boundary-surfaces).

use std::collections::HashSet;
use std::fmt::Write;

use citygml_io::SurfaceType;
use serde_json::Value;

use crate::report::Report;
use crate::xml::{escape, polygon};
use crate::CityJsonError;

/// The shape of a geometry's boundaries, faces as rings of vertex indices.
enum Shape {
    Surfaces(Vec<Face>),
    Solid(Vec<Vec<Face>>),
    Solids(Vec<Vec<Vec<Face>>>),
}

type Face = Vec<Vec<usize>>;

/// What one geometry becomes: the geometry property and the boundary surfaces it defines.
pub struct GeomOut {
    /// Integer LoD of the property.
    pub lod: u8,
    /// `Solid`, `MultiSurface` or `Geometry` (the property name is `lod{lod}{kind}`).
    pub kind: &'static str,
    /// The GML geometry element (`<gml:Solid ...>...</gml:Solid>`).
    pub xml: String,
    /// `<bldg:boundedBy>` elements, one per semantic surface.
    pub boundary: Vec<String>,
}

/// Everything a geometry needs from its object and document.
pub struct GeomContext<'a> {
    pub object: &'a str,
    pub index: usize,
    pub vertices: &'a [[f64; 3]],
    pub decimals: usize,
    /// srsName for the geometry element (when the document has no envelope to carry it).
    pub srs_name: Option<&'a str>,
    /// The CityGML LoD to write whatever the CityJSON one (rooms: 4).
    pub lod_override: Option<u8>,
    pub ids: &'a mut HashSet<String>,
    pub report: &'a mut Report,
}

fn idx(v: &Value, ctx_obj: &str, n: usize) -> Result<usize, CityJsonError> {
    let i = v.as_u64().ok_or_else(|| {
        CityJsonError::structure(Some(ctx_obj), "a boundary holds something other than a vertex index")
    })? as usize;
    if i >= n {
        return Err(CityJsonError::structure(Some(ctx_obj), format!("vertex index {i} past the {n} vertices")));
    }
    Ok(i)
}

fn arr<'v>(v: &'v Value, obj: &str) -> Result<&'v Vec<Value>, CityJsonError> {
    v.as_array().ok_or_else(|| {
        CityJsonError::structure(Some(obj), "boundaries are not nested arrays as the geometry type needs")
    })
}

fn face(v: &Value, obj: &str, n: usize) -> Result<Face, CityJsonError> {
    arr(v, obj)?.iter().map(|ring| arr(ring, obj)?.iter().map(|i| idx(i, obj, n)).collect()).collect()
}

fn faces(v: &Value, obj: &str, n: usize) -> Result<Vec<Face>, CityJsonError> {
    arr(v, obj)?.iter().map(|f| face(f, obj, n)).collect()
}

fn shape(ty: &str, b: &Value, obj: &str, n: usize) -> Result<Shape, CityJsonError> {
    Ok(match ty {
        "MultiSurface" | "CompositeSurface" => Shape::Surfaces(faces(b, obj, n)?),
        "Solid" => Shape::Solid(arr(b, obj)?.iter().map(|s| faces(s, obj, n)).collect::<Result<_, _>>()?),
        _ => Shape::Solids(
            arr(b, obj)?
                .iter()
                .map(|solid| arr(solid, obj)?.iter().map(|s| faces(s, obj, n)).collect())
                .collect::<Result<_, _>>()?,
        ),
    })
}

/// The semantic value of each face, in the order faces are visited (flattened).
fn semantic_values(ty: &str, values: Option<&Value>) -> Vec<Option<usize>> {
    let Some(v) = values else { return Vec::new() };
    let depth = match ty {
        "MultiSurface" | "CompositeSurface" => 1,
        "Solid" => 2,
        _ => 3,
    };
    let mut out = Vec::new();
    flatten(v, depth, &mut out);
    out
}

fn flatten(v: &Value, depth: usize, out: &mut Vec<Option<usize>>) {
    match (depth, v) {
        (1, Value::Array(a)) => out.extend(a.iter().map(|x| x.as_u64().map(|i| i as usize))),
        (_, Value::Array(a)) => a.iter().for_each(|x| flatten(x, depth - 1, out)),
        // null for a whole shell/solid: its faces have no semantics
        _ => {}
    }
}

/// The LoD as written (`"2.2"`, `2`, `"1"`), as a string and its integer part.
pub fn lod_of(g: &Value) -> Option<(String, u8)> {
    let s = match g.get("lod")? {
        Value::String(s) => s.clone(),
        Value::Number(n) => n.to_string(),
        _ => return None,
    };
    let int = s.chars().next()?.to_digit(10)? as u8;
    Some((s, int))
}

/// A semantic surface's CityGML type, if CityGML 2.0's building module has one.
fn surface_type(sem: &Value) -> Option<SurfaceType> {
    sem.get("type").and_then(Value::as_str).and_then(SurfaceType::from_local_name)
}

/// Emits one geometry (already resolved: a template instance is expanded by the caller).
pub fn emit(ctx: &mut GeomContext<'_>, g: &Value) -> Result<Option<GeomOut>, CityJsonError> {
    let obj = ctx.object;
    let ty = g.get("type").and_then(Value::as_str).unwrap_or("");
    if !matches!(ty, "MultiSurface" | "CompositeSurface" | "Solid" | "MultiSolid" | "CompositeSolid") {
        ctx.report.add(format!("{ty} geometry (no surface or solid: left out)"), Some(obj));
        return Ok(None);
    }
    let Some((lod, lod_int)) = lod_of(g) else {
        return Err(CityJsonError::structure(Some(obj), format!("geometry {} has no \"lod\"", ctx.index)));
    };
    let lod_int = ctx.lod_override.unwrap_or(lod_int);
    if lod_int > 4 {
        return Err(CityJsonError::structure(Some(obj), format!("geometry {} has lod {lod}", ctx.index)));
    }
    for key in ["material", "texture"] {
        if g.get(key).is_some() {
            ctx.report.add(format!("geometry {key} (appearance: not carried to CityGML)"), Some(obj));
        }
    }
    let boundaries =
        g.get("boundaries").ok_or_else(|| CityJsonError::structure(Some(obj), "geometry without \"boundaries\""))?;
    let shape = shape(ty, boundaries, obj, ctx.vertices.len())?;
    let semantics = g.get("semantics");
    let surfaces: Vec<Value> =
        semantics.and_then(|s| s.get("surfaces")).and_then(Value::as_array).cloned().unwrap_or_default();
    let values = semantic_values(ty, semantics.and_then(|s| s.get("values")));
    let gid = format!("geofit-{obj}-g{}-lod{lod}", ctx.index);
    let srs = ctx.srs_name.map(|s| format!(" srsName=\"{}\"", escape(s))).unwrap_or_default();
    let sem = Semantics::new(ctx, &surfaces, &gid);

    let mut polys: Vec<Vec<String>> = vec![Vec::new(); surfaces.len()];
    let mut face_no = 0usize;
    let mut member = |f: &Face, out: &mut String, ctx: &mut GeomContext<'_>| {
        let pid = format!("{gid}-p{face_no}");
        let s = values.get(face_no).copied().flatten().filter(|s| sem.representable(*s));
        face_no += 1;
        let rings: Vec<Vec<[f64; 3]>> = f.iter().map(|r| r.iter().map(|i| ctx.vertices[*i]).collect()).collect();
        let mut p = String::new();
        polygon(&mut p, &pid, &rings, ctx.decimals);
        match s {
            Some(s) => {
                let _ = write!(out, "<gml:surfaceMember xlink:href=\"#{}\"/>", escape(&pid));
                polys[s].push(p);
            }
            None => {
                let _ = write!(out, "<gml:surfaceMember>{p}</gml:surfaceMember>");
            }
        }
    };
    let mut xml = String::new();
    let shell = |faces: &[Face],
                 xml: &mut String,
                 ctx: &mut GeomContext<'_>,
                 member: &mut dyn FnMut(&Face, &mut String, &mut GeomContext<'_>)| {
        xml.push_str("<gml:CompositeSurface>");
        faces.iter().for_each(|f| member(f, xml, ctx));
        xml.push_str("</gml:CompositeSurface>");
    };
    let solid = |shells: &[Vec<Face>],
                 xml: &mut String,
                 ctx: &mut GeomContext<'_>,
                 member: &mut dyn FnMut(&Face, &mut String, &mut GeomContext<'_>),
                 id: &str,
                 srs: &str| {
        let _ = write!(xml, "<gml:Solid gml:id=\"{}\"{srs}>", escape(id));
        for (i, s) in shells.iter().enumerate() {
            let tag = if i == 0 { "exterior" } else { "interior" };
            let _ = write!(xml, "<gml:{tag}>");
            shell(s, xml, ctx, member);
            let _ = write!(xml, "</gml:{tag}>");
        }
        xml.push_str("</gml:Solid>");
    };
    let kind = match &shape {
        Shape::Surfaces(fs) => {
            let el = if ty == "CompositeSurface" { "CompositeSurface" } else { "MultiSurface" };
            let _ = write!(xml, "<gml:{el} gml:id=\"{}\"{srs}>", escape(&gid));
            fs.iter().for_each(|f| member(f, &mut xml, ctx));
            let _ = write!(xml, "</gml:{el}>");
            "MultiSurface"
        }
        Shape::Solid(shells) => {
            solid(shells, &mut xml, ctx, &mut member, &gid, &srs);
            "Solid"
        }
        Shape::Solids(solids) => {
            let el = if ty == "CompositeSolid" { "CompositeSolid" } else { "MultiSolid" };
            let _ = write!(xml, "<gml:{el} gml:id=\"{}\"{srs}>", escape(&gid));
            for (i, shells) in solids.iter().enumerate() {
                xml.push_str("<gml:solidMember>");
                solid(shells, &mut xml, ctx, &mut member, &format!("{gid}-solid{i}"), "");
                xml.push_str("</gml:solidMember>");
            }
            let _ = write!(xml, "</gml:{el}>");
            "Solid"
        }
    };
    let boundary = sem.boundary_surfaces(ctx, &surfaces, &polys, lod_int, &lod);
    Ok(Some(GeomOut { lod: lod_int, kind, xml, boundary }))
}

/// The semantic surfaces of one geometry: their gml:ids and which of them CityGML can hold.
struct Semantics {
    ids: Vec<String>,
    ok: Vec<bool>,
}

impl Semantics {
    fn new(ctx: &mut GeomContext<'_>, surfaces: &[Value], gid: &str) -> Semantics {
        let mut ids = Vec::new();
        let mut ok = Vec::new();
        for (i, s) in surfaces.iter().enumerate() {
            let own = s.get("id").and_then(Value::as_str).filter(|id| !ctx.ids.contains(*id));
            if s.get("id").is_some() && own.is_none() {
                ctx.report.add("semantic surface id used twice (the second gets a new gml:id)", Some(ctx.object));
            }
            let id = own.map(str::to_string).unwrap_or_else(|| format!("{gid}-s{i}"));
            ctx.ids.insert(id.clone());
            ids.push(id);
            let t = surface_type(s);
            let parent_ok = match (t, s.get("parent").and_then(Value::as_u64)) {
                (Some(t), None) => !t.is_opening(),
                (Some(t), Some(p)) => {
                    t.is_opening() && surfaces.get(p as usize).and_then(surface_type).is_some_and(|pt| !pt.is_opening())
                }
                (None, _) => false,
            };
            if !parent_ok {
                let ty = s.get("type").and_then(Value::as_str).unwrap_or("?");
                ctx.report
                    .add(format!("semantic surface {ty} (no CityGML 2.0 building boundary surface or opening there: faces kept without it)"), Some(ctx.object));
            }
            ok.push(parent_ok);
        }
        Semantics { ids, ok }
    }

    fn representable(&self, s: usize) -> bool {
        self.ok.get(s).copied().unwrap_or(false)
    }

    /// `<bldg:boundedBy>` for each top semantic surface holding faces (its own or its openings').
    fn boundary_surfaces(
        &self,
        ctx: &mut GeomContext<'_>,
        surfaces: &[Value],
        polys: &[Vec<String>],
        lod: u8,
        lod_str: &str,
    ) -> Vec<String> {
        let parent = |s: &Value| s.get("parent").and_then(Value::as_u64).map(|p| p as usize);
        let mut out = Vec::new();
        for (i, s) in surfaces.iter().enumerate() {
            if !self.ok[i] || parent(s).is_some() {
                continue;
            }
            let openings: Vec<usize> = (0..surfaces.len())
                .filter(|j| self.ok[*j] && parent(&surfaces[*j]) == Some(i) && !polys[*j].is_empty())
                .collect();
            if polys[i].is_empty() && openings.is_empty() {
                continue;
            }
            let t = surface_type(s).expect("ok surfaces have a type").local_name();
            let mut x = format!("<bldg:boundedBy><bldg:{t} gml:id=\"{}\">", escape(&self.ids[i]));
            x.push_str(&self.surface_body(ctx, s, &polys[i], lod, lod_str, &self.ids[i]));
            for j in openings {
                let ot = surface_type(&surfaces[j]).expect("ok").local_name();
                let _ = write!(x, "<bldg:opening><bldg:{ot} gml:id=\"{}\">", escape(&self.ids[j]));
                x.push_str(&self.surface_body(ctx, &surfaces[j], &polys[j], lod, lod_str, &self.ids[j]));
                let _ = write!(x, "</bldg:{ot}></bldg:opening>");
            }
            let _ = write!(x, "</bldg:{t}></bldg:boundedBy>");
            out.push(x);
        }
        out
    }

    /// A surface's attributes and its `lodNMultiSurface` of faces.
    fn surface_body(
        &self,
        ctx: &mut GeomContext<'_>,
        s: &Value,
        polys: &[String],
        lod: u8,
        lod_str: &str,
        id: &str,
    ) -> String {
        let mut x = String::new();
        if let Some(m) = s.as_object() {
            for (k, v) in m.iter().filter(|(k, _)| !matches!(k.as_str(), "type" | "parent" | "children" | "id")) {
                super::attributes::generic(&mut x, k, v, ctx.object, ctx.report);
            }
        }
        if !polys.is_empty() {
            let _ = write!(
                x,
                "<bldg:lod{lod}MultiSurface><gml:MultiSurface gml:id=\"{}\">",
                escape(&format!("geofit-{id}-lod{lod_str}"))
            );
            for p in polys {
                let _ = write!(x, "<gml:surfaceMember>{p}</gml:surfaceMember>");
            }
            let _ = write!(x, "</gml:MultiSurface></bldg:lod{lod}MultiSurface>");
        }
        x
    }
}
