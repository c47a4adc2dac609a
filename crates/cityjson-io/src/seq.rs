//! CityJSONSeq (`.city.jsonl`): a CityJSON header line, then one CityJSONFeature per line.
//! Read line by line and written feature by feature, so memory holds one feature at a time
//! (docs/decisions.md#cityjson-seq-streaming).

use std::io::{BufRead, Write};

use serde_json::{json, Map, Value};

use crate::from_gml::{ObjectMapper, VertexPool};
use crate::report::Report;
use crate::to_gml::{real_vertices, top_level_ids, DocHeader, GmlOptions, GmlWriter};
use crate::transform::Transform;
use crate::{cityjson_header, CityJsonError, WriteOptions};

/// What a streamed conversion went through.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeqStats {
    pub features: usize,
    pub lines: usize,
}

/// Streams a CityJSONSeq from `r` into CityGML 2.0 on `w`. Each feature's objects are written on
/// the CityGML line with the number of the feature's CityJSONSeq line.
pub fn seq_to_citygml<R: BufRead, W: Write>(
    mut r: R,
    w: W,
    opts: GmlOptions,
) -> Result<(W, Report, SeqStats), CityJsonError> {
    let mut line = String::new();
    let mut n = 0usize;
    let mut writer: Option<GmlWriter<W>> = None;
    let mut w = Some(w);
    let mut stats = SeqStats::default();
    loop {
        line.clear();
        if r.read_line(&mut line)? == 0 {
            break;
        }
        n += 1;
        if line.trim().is_empty() {
            continue;
        }
        let v: Value = serde_json::from_str(&line).map_err(|e| CityJsonError::json(&e, 0).on_line(n))?;
        match writer.as_mut() {
            None => {
                let mut report = Report::default();
                let header = DocHeader::from_json(&v, &mut report).map_err(|e| e.on_line(n))?;
                if v.get("CityObjects").and_then(Value::as_object).is_some_and(|m| !m.is_empty()) {
                    report.add("objects in the CityJSONSeq header line (read as a feature)", None);
                }
                let mut gw = GmlWriter::begin(w.take().expect("once"), header, opts, report)?;
                feature(&mut gw, &v, n, true).map_err(|e| e.on_line(n))?;
                writer = Some(gw);
            }
            Some(gw) => {
                feature(gw, &v, n, false).map_err(|e| e.on_line(n))?;
                stats.features += 1;
            }
        }
    }
    stats.lines = n;
    let gw = writer.ok_or_else(|| CityJsonError::structure(None, "empty CityJSONSeq (no header line)"))?;
    let (w, report) = gw.finish()?;
    Ok((w, report, stats))
}

/// One CityJSONFeature (or the header's own objects) into the writer.
fn feature<W: Write>(gw: &mut GmlWriter<W>, v: &Value, line: usize, header: bool) -> Result<(), CityJsonError> {
    if !header && v.get("type").and_then(Value::as_str) != Some("CityJSONFeature") {
        return Err(CityJsonError::structure(None, "a line after the header is not a CityJSONFeature"));
    }
    let empty = Map::new();
    let objects = v.get("CityObjects").and_then(Value::as_object).unwrap_or(&empty);
    if objects.is_empty() {
        return Ok(());
    }
    let verts = v.get("vertices").and_then(Value::as_array).map(Vec::as_slice).unwrap_or_default();
    let verts = real_vertices(verts, &gw.header().transform.clone())?;
    if v.get("appearance").is_some() {
        gw.report.add("feature appearance (not carried to CityGML)", v.get("id").and_then(Value::as_str));
    }
    for id in top_level_ids(objects) {
        gw.write_object(id, objects, &verts, Some(line))?;
    }
    Ok(())
}

/// CityGML → CityJSONSeq on `w`, one top-level feature per line, reading the CityGML object by
/// object (bounded by the largest feature).
pub fn citygml_to_seq<W: Write>(
    gml: &[u8],
    opts: &WriteOptions,
    mut w: W,
) -> Result<(W, Report, SeqStats), CityJsonError> {
    let mut stream = citygml_io::ObjectStream::new(gml)?;
    let mut report = Report::default();
    let mut stats = SeqStats::default();
    let mut transform: Option<Transform> = opts.transform;
    while let Some(obj) = stream.next() {
        let obj = obj?;
        let t = *transform.get_or_insert_with(|| {
            let origin = stream.declared_envelope().filter(|e| !e.is_empty()).unwrap_or(obj.envelope).min;
            Transform::with_origin(opts.scale, origin)
        });
        if stats.lines == 0 {
            // The envelope and its srsName come before the first object: known now.
            let header = cityjson_header(&t, stream.srs_name().as_deref(), stream.declared_envelope(), &mut report);
            serde_json::to_writer(&mut w, &header).map_err(std::io::Error::from)?;
            w.write_all(b"\n")?;
            stats.lines = 1;
        }
        let mut m = ObjectMapper::new(gml, VertexPool::new(t));
        let mut objects = Map::new();
        let Some(id) = m.object(&obj, None, &mut objects) else {
            report.merge(m.report);
            continue;
        };
        report.merge(m.report);
        let f = json!({"type": "CityJSONFeature", "id": id, "CityObjects": objects, "vertices": m.pool.into_json()});
        serde_json::to_writer(&mut w, &f).map_err(std::io::Error::from)?;
        w.write_all(b"\n")?;
        stats.features += 1;
        stats.lines += 1;
    }
    if stats.lines == 0 {
        let t = transform.unwrap_or_else(|| Transform::with_origin(opts.scale, [0.0; 3]));
        let header = cityjson_header(&t, stream.srs_name().as_deref(), stream.declared_envelope(), &mut report);
        serde_json::to_writer(&mut w, &header).map_err(std::io::Error::from)?;
        w.write_all(b"\n")?;
        stats.lines = 1;
    }
    for u in stream.unresolved_xlinks() {
        report.add("XLink to nothing in the document (left out)", u.feature.as_deref());
    }
    w.flush()?;
    Ok((w, report, stats))
}
