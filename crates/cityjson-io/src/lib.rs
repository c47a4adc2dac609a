//! CityJSON 2.0 (1.1 read) and CityJSONSeq, mapped to and from CityGML.
//!
//! geofit's buildings commands work on CityGML (citygml-io's model and its lossless writer); a
//! CityJSON input is turned into CityGML 2.0 text at the edge and the result turned back, so
//! every command reads CityJSON without a second model (docs/decisions.md#cityjson-at-the-edges).
//!
//! - [`to_citygml`]: a CityJSON document or CityJSONSeq (in memory) → CityGML 2.0 text.
//! - [`seq::seq_to_citygml`]: a CityJSONSeq streamed line by line → CityGML 2.0, bounded memory.
//! - [`from_citygml`]: CityGML 1.0/2.0/3.0 → one CityJSON 2.0 document.
//! - [`seq::citygml_to_seq`]: CityGML → CityJSONSeq, object by object.
//! - [`overlay_original`]: puts back what the CityGML view could not hold (typed attributes,
//!   metadata) after a command rewrote a CityJSON input.
//!
//! Every conversion returns a [`Report`] of what the target cannot hold: nothing is dropped
//! silently.
//!
//! # Examples
//!
//! ```
//! let cj = br#"{"type":"CityJSON","version":"2.0","transform":{"scale":[0.001,0.001,0.001],"translate":[100,200,0]},
//!   "metadata":{"referenceSystem":"https://www.opengis.net/def/crs/EPSG/0/7415"},
//!   "CityObjects":{"B1":{"type":"Building","attributes":{"measuredHeight":3.5,"owner":"x"},
//!     "geometry":[{"type":"MultiSurface","lod":"2.2","boundaries":[[[0,1,2,3]]],
//!       "semantics":{"surfaces":[{"type":"RoofSurface"}],"values":[0]}}]}},
//!   "vertices":[[0,0,3000],[1000,0,3000],[1000,1000,3000],[0,1000,3000]]}"#;
//! let (gml, _report) = cityjson_io::to_citygml(cj, cityjson_io::GmlOptions::default()).unwrap();
//! let model = citygml_io::parse(&gml).unwrap();
//! assert_eq!(model.objects[0].id.as_deref(), Some("B1"));
//! assert_eq!(model.all_polygons()[0].semantic, Some(citygml_io::SurfaceType::Roof));
//!
//! let (back, report) = cityjson_io::from_citygml(&gml, &cityjson_io::WriteOptions::default()).unwrap();
//! assert!(report.is_empty(), "{:?}", report);
//! let b1 = &back["CityObjects"]["B1"];
//! assert_eq!(b1["attributes"]["measuredHeight"], 3.5);
//! assert_eq!(b1["geometry"][0]["lod"], "2.2");
//! assert_eq!(b1["geometry"][0]["semantics"]["surfaces"][0]["type"], "RoofSurface");
//! assert_eq!(back["metadata"]["referenceSystem"], "https://www.opengis.net/def/crs/EPSG/0/7415");
//! ```

pub mod crs;
mod error;
mod from_gml;
mod lines;
pub mod report;
pub mod seq;
mod to_gml;
pub mod transform;
mod xml;

use serde_json::{json, Map, Value};

pub use error::CityJsonError;
pub use report::Report;
pub use to_gml::{DocHeader, GmlOptions, GmlWriter};
pub use transform::Transform;

/// How CityJSON is written.
#[derive(Debug, Clone, Copy)]
pub struct WriteOptions {
    /// Precision of the quantised vertices (the `transform` scale), in CRS units.
    pub scale: f64,
    /// A transform to use as it is (a write-back keeps its input's); `None`: `scale` and the
    /// document's lower corner.
    pub transform: Option<Transform>,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions { scale: 0.001, transform: None }
    }
}

/// Whether `bytes` are a CityJSONSeq: a CityJSON header line followed by more JSON lines.
pub fn is_seq(bytes: &[u8]) -> bool {
    let text = bytes.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(bytes);
    let start = text.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(text.len());
    let text = &text[start..];
    let Some(nl) = text.iter().position(|b| *b == b'\n') else { return false };
    let first = &text[..nl];
    let rest_starts_json = text[nl..].iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{');
    rest_starts_json
        && serde_json::from_slice::<Value>(first)
            .is_ok_and(|v| v.get("type").and_then(Value::as_str) == Some("CityJSON"))
}

/// A CityJSON document or CityJSONSeq in memory → CityGML 2.0 text and the report. Objects
/// are written on the line where their id stands in the CityJSON (a CityJSONSeq: their
/// feature's line), so CityGML line numbers point into the CityJSON.
pub fn to_citygml(bytes: &[u8], opts: GmlOptions) -> Result<(Vec<u8>, Report), CityJsonError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(bytes);
    if is_seq(bytes) {
        let (out, report, _) = seq::seq_to_citygml(bytes, Vec::new(), opts)?;
        return Ok((out, report));
    }
    let v: Value = serde_json::from_slice(bytes).map_err(|e| CityJsonError::json(&e, 0))?;
    if v.get("type").and_then(Value::as_str) == Some("CityJSONFeature") {
        return Err(CityJsonError::structure(
            None,
            "a lone CityJSONFeature: a CityJSONSeq starts with its CityJSON header line",
        ));
    }
    let mut report = Report::default();
    let mut header = DocHeader::from_json(&v, &mut report)?;
    let empty = Map::new();
    let objects = v.get("CityObjects").and_then(Value::as_object).unwrap_or(&empty);
    let verts = v.get("vertices").and_then(Value::as_array).map(Vec::as_slice).unwrap_or_default();
    let verts = to_gml::real_vertices(verts, &header.transform)?;
    if header.extent.is_none() && !verts.is_empty() {
        let mut e =
            [f64::INFINITY, f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for p in &verts {
            for i in 0..3 {
                e[i] = e[i].min(p[i]);
                e[i + 3] = e[i + 3].max(p[i]);
            }
        }
        header.extent = Some(e);
    }
    let mut ids = to_gml::top_level_ids(objects);
    let at = lines::key_lines(bytes, &ids);
    ids.sort_by_key(|id| at.get(*id).copied().unwrap_or(usize::MAX));
    let mut w = GmlWriter::begin(Vec::new(), header, opts, report)?;
    for id in ids {
        w.write_object(id, objects, &verts, at.get(id).copied())?;
    }
    let (out, report) = w.finish()?;
    Ok((out, report))
}

/// The CityJSON members before the objects: type, version, transform, metadata.
pub(crate) fn cityjson_header(
    t: &Transform,
    srs: Option<&str>,
    envelope: Option<citygml_io::Envelope>,
    report: &mut Report,
) -> Value {
    let mut metadata = Map::new();
    if let Some(s) = srs {
        match crs::to_reference_system(s) {
            Some((r, dropped)) => {
                metadata.insert("referenceSystem".into(), json!(r));
                if let Some(v) = dropped {
                    report.add(format!("vertical CRS EPSG:{v} of {s} (metadata.referenceSystem names one CRS)"), None);
                }
            }
            None => report.add(format!("srsName {s} (no EPSG code to name in metadata.referenceSystem)"), None),
        }
    }
    if let Some(e) = envelope.filter(|e| !e.is_empty()) {
        metadata
            .insert("geographicalExtent".into(), json!([e.min[0], e.min[1], e.min[2], e.max[0], e.max[1], e.max[2]]));
    }
    let mut h =
        json!({"type": "CityJSON", "version": "2.0", "transform": t.to_json(), "CityObjects": {}, "vertices": []});
    if !metadata.is_empty() {
        h["metadata"] = Value::Object(metadata);
    }
    h
}

/// CityGML (1.0/2.0/3.0) → one CityJSON 2.0 document, and the report of what it cannot hold.
pub fn from_citygml(gml: &[u8], opts: &WriteOptions) -> Result<(Value, Report), CityJsonError> {
    let (seq, report, _) = seq::citygml_to_seq(gml, opts, Vec::new())?;
    let mut lines = seq.split(|b| *b == b'\n').filter(|l| !l.is_empty());
    let mut doc: Value =
        serde_json::from_slice(lines.next().unwrap_or(b"{}")).map_err(|e| CityJsonError::json(&e, 0))?;
    let t = Transform::from_json(doc.get("transform")).map_err(|m| CityJsonError::structure(None, m))?;
    let mut pool: Vec<Value> = Vec::new();
    let mut objects = Map::new();
    let mut extent: Option<[i64; 6]> = None;
    for line in lines {
        let mut f: Value = serde_json::from_slice(line).map_err(|e| CityJsonError::json(&e, 0))?;
        let offset = pool.len();
        let verts = f["vertices"].as_array().cloned().unwrap_or_default();
        for v in &verts {
            let q: Vec<i64> = v.as_array().map(|a| a.iter().filter_map(Value::as_i64).collect()).unwrap_or_default();
            let e = extent.get_or_insert([q[0], q[1], q[2], q[0], q[1], q[2]]);
            for i in 0..3 {
                e[i] = e[i].min(q[i]);
                e[i + 3] = e[i + 3].max(q[i]);
            }
        }
        pool.extend(verts);
        if let Some(objs) = f["CityObjects"].as_object_mut() {
            for (id, mut o) in std::mem::take(objs) {
                shift_indices(&mut o, offset);
                objects.insert(id, o);
            }
        }
    }
    if let Some(e) = extent {
        let p = |i: usize| t.apply([e[i] as f64, e[i + 1] as f64, e[i + 2] as f64]);
        let (lo, hi) = (p(0), p(3));
        doc["metadata"]["geographicalExtent"] = json!([lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]]);
    }
    doc["CityObjects"] = Value::Object(objects);
    doc["vertices"] = Value::Array(pool);
    Ok((doc, report))
}

/// A CityJSON document as compact JSON with `type` and `version` first (serde_json sorts the
/// keys; a reader sniffing the first bytes must meet `"type":"CityJSON"` early).
pub fn to_vec(doc: &Value) -> Vec<u8> {
    const FIRST: &[&str] = &["type", "version", "transform", "metadata", "extensions"];
    let Some(m) = doc.as_object() else { return serde_json::to_vec(doc).unwrap_or_default() };
    let keys = FIRST
        .iter()
        .copied()
        .filter(|k| m.contains_key(*k))
        .chain(m.keys().map(String::as_str).filter(|k| !FIRST.contains(k)));
    let mut out = b"{".to_vec();
    for (i, k) in keys.enumerate() {
        if i > 0 {
            out.push(b',');
        }
        out.extend(serde_json::to_vec(k).unwrap_or_default());
        out.push(b':');
        out.extend(serde_json::to_vec(&m[k]).unwrap_or_default());
    }
    out.extend(b"}\n");
    out
}

/// Adds `offset` to every vertex index in an object's geometry boundaries.
fn shift_indices(o: &mut Value, offset: usize) {
    fn shift(v: &mut Value, offset: usize) {
        match v {
            Value::Array(a) => a.iter_mut().for_each(|x| shift(x, offset)),
            Value::Number(n) => {
                if let Some(i) = n.as_u64() {
                    *v = json!(i as usize + offset);
                }
            }
            _ => {}
        }
    }
    if offset == 0 {
        return;
    }
    for g in o.get_mut("geometry").and_then(Value::as_array_mut).into_iter().flatten() {
        if let Some(b) = g.get_mut("boundaries") {
            shift(b, offset);
        }
    }
}

/// After a command rewrote a CityJSON input through CityGML: puts back the input's own
/// attributes (JSON types intact) of every object still there, and its metadata, extensions
/// and other top-level members the CityGML view does not hold. Geometry stays the new one.
pub fn overlay_original(new: &mut Value, original: &Value) {
    if let (Some(objs), Some(orig)) = (
        new.get_mut("CityObjects").and_then(Value::as_object_mut),
        original.get("CityObjects").and_then(Value::as_object),
    ) {
        for (id, o) in objs.iter_mut() {
            let Some(src) = orig.get(id) else { continue };
            match src.get("attributes") {
                Some(a) => o["attributes"] = a.clone(),
                None => {
                    o.as_object_mut().map(|m| m.remove("attributes"));
                }
            }
            if let Some(ty) = src.get("type") {
                o["type"] = ty.clone();
            }
        }
    }
    if let (Some(n), Some(orig)) = (new.as_object_mut(), original.as_object()) {
        for (k, v) in orig {
            if !matches!(
                k.as_str(),
                "CityObjects" | "vertices" | "transform" | "appearance" | "geometry-templates" | "version" | "type"
            ) {
                if k == "metadata" {
                    let extent = n.get("metadata").and_then(|m| m.get("geographicalExtent")).cloned();
                    let mut m = v.clone();
                    if let (Some(e), Some(mm)) = (extent, m.as_object_mut()) {
                        mm.insert("geographicalExtent".into(), e);
                    }
                    n.insert(k.clone(), m);
                } else {
                    n.insert(k.clone(), v.clone());
                }
            }
        }
    }
}
