//! The T-mesh file format (`.tmesh`, XML, schema `xsd/tmesh.xsd`, namespace
//! `urn:geofit:tmesh:1`). Spec §5.2 "Export" and item 26: leaf cells, control points
//! (s, t, x, y, z, w), degree, plus what later steps need: the georeference (affine map from
//! parameters to world coordinates, CRS), the data mask and, for indirect fits, the warp field.
//!
//! ```xml
//! <tmesh xmlns="urn:geofit:tmesh:1" version="1" degree="3">
//!   <georef x0="500015" y0="2150015" dx="30" dy="30"><crs>EPSG:32605</crs></georef>
//!   <points count="9">s t x y z w   (one control point per line)</points>
//!   <cells count="4">i0 i1 i2 i3     (corner indices: (s_min,t_max) (s_max,t_max) (s_min,t_min) (s_max,t_min))</cells>
//!   <mask width="857" height="793" encoding="rle">runs</mask>          (optional)
//!   <warp encoding="json">{...}</warp>                                 (optional)
//! </tmesh>
//! ```
//!
//! - Control points' x, y are in parameter units like s, t (direct fits: x = s, y = t).
//! - World coordinates of parameter (s, t): x = x0 + s·dx, y = y0 + t·dy (A21: s, t in raster
//!   cells, t counted from the bottom row; x0, y0 is the centre of the bottom-left raster cell).
//! - Numbers are written in Rust's shortest round-trip form, so write → read is exact.
//! - Mask: cell (i, j) is parameter (s = i, t = j), stored row by row from t = 0, as run lengths
//!   of alternating 0 (no data) and 1 (data), starting with a (possibly empty) run of 0.
//! - Warp (indirect reduction): the piecewise-linear displacement field of `geofit warp` as its
//!   JSON record (XML-escaped). The mesh's parameters and georeference live in the warped frame;
//!   control points' x, y are mapped back to the original frame (spec §2.3.7); evaluation on an
//!   original grid maps each cell forward through the field first.

use std::io::Write;

use quick_xml::events::Event;
use quick_xml::Reader;
use input_limits::quote;

use crate::mesh::{ControlPoint, Degree, PointId, TMesh};
use crate::TsplineError;

pub const NAMESPACE: &str = "urn:geofit:tmesh:1";

/// Affine parameter → world map and CRS.
#[derive(Debug, Clone, PartialEq)]
pub struct Georef {
    pub x0: f64,
    pub y0: f64,
    pub dx: f64,
    pub dy: f64,
    /// CRS as given by the source raster (WKT, EPSG code or empty).
    pub crs: String,
}

impl Georef {
    pub fn identity() -> Georef {
        Georef { x0: 0.0, y0: 0.0, dx: 1.0, dy: 1.0, crs: String::new() }
    }
    pub fn world(&self, s: f64, t: f64) -> (f64, f64) {
        (self.x0 + s * self.dx, self.y0 + t * self.dy)
    }
    pub fn param(&self, x: f64, y: f64) -> (f64, f64) {
        ((x - self.x0) / self.dx, (y - self.y0) / self.dy)
    }
}

/// Bit mask of the data footprint at raster resolution (spec §2.2 masking), as the `.tmesh` and
/// `.tmb` files store it; made from NaN heights by [`DataMask::of_samples`].
#[derive(Debug, Clone, PartialEq)]
pub struct DataMask {
    pub width: usize,
    pub height: usize,
    /// Row-major from t = 0 (bottom row).
    pub bits: Vec<bool>,
}

impl DataMask {
    /// The mask of a raster in the fit's layout: a cell has data where its height is not NaN.
    /// The only place a mask is made from data (docs/decisions.md#nan-is-no-data): in memory,
    /// NaN says "no data"; the mask is how the file stores that.
    pub fn of_samples(samples: &crate::fit::Samples) -> DataMask {
        DataMask { width: samples.width, height: samples.height, bits: samples.z.iter().map(|v| !v.is_nan()).collect() }
    }

    pub fn get(&self, i: usize, j: usize) -> bool {
        self.bits[j * self.width + i]
    }
    /// Run lengths of alternating no-data / data, starting with no data (the first run may be
    /// 0): how both file formats store the mask.
    pub(crate) fn runs(&self) -> Vec<usize> {
        let mut runs = Vec::new();
        let mut cur = false;
        let mut n = 0usize;
        for &b in &self.bits {
            if b == cur {
                n += 1;
            } else {
                runs.push(n);
                cur = b;
                n = 1;
            }
        }
        runs.push(n);
        runs
    }
}

/// Everything a `.tmesh` file holds.
#[derive(Debug, Clone)]
pub struct TMeshFile {
    pub mesh: TMesh,
    pub georef: Georef,
    pub mask: Option<DataMask>,
    /// Indirect reduction: the displacement field as the JSON record of `raster-proc`'s
    /// `WarpField` (landmarks in the source and target frames, triangles, source grid), kept
    /// verbatim so this crate does not depend on the warp code.
    pub warp: Option<String>,
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A T-mesh document: a binary `.tmb` (its magic bytes, [`crate::tmb`]), or XML whose first element (after a BOM, the XML declaration, comments and a
/// DOCTYPE) is `<tmesh`. CityGML never starts so, so the sniff cannot take a city model for a
/// T-mesh; commands that take either (`geofit export`, `geofit info`) use it to choose the reader.
pub fn is_tmesh_document(src: &[u8]) -> bool {
    if src.starts_with(crate::tmb::MAGIC) {
        return true;
    }
    let mut rest = src.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(src);
    loop {
        let start = rest.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(rest.len());
        rest = &rest[start..];
        let skip = if rest.starts_with(b"<?") {
            rest.windows(2).position(|w| w == b"?>").map(|i| i + 2)
        } else if rest.starts_with(b"<!--") {
            rest.windows(3).position(|w| w == b"-->").map(|i| i + 3)
        } else if rest.starts_with(b"<!") {
            // <!DOCTYPE ...> (no internal subset in a T-mesh file)
            rest.iter().position(|&b| b == b'>').map(|i| i + 1)
        } else {
            return rest.starts_with(b"<tmesh") && rest.get(6).is_some_and(|b| b.is_ascii_whitespace() || *b == b'>' || *b == b'/');
        };
        match skip {
            Some(n) => rest = &rest[n..],
            None => return false,
        }
    }
}

/// The file formats a T-mesh is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// The XML `.tmesh` (the documented exchange format).
    Xml,
    /// The compact binary `.tmb` ([`crate::tmb`]).
    Binary,
}

impl Encoding {
    /// `.tmb` paths are binary, everything else (and stdout) XML.
    pub fn for_path(path: Option<&str>) -> Encoding {
        match path {
            Some(p) if p.to_ascii_lowercase().ends_with(".tmb") => Encoding::Binary,
            _ => Encoding::Xml,
        }
    }
}

/// Writes `f` in the given encoding.
pub fn write_as(f: &TMeshFile, encoding: Encoding, w: &mut dyn Write) -> std::io::Result<()> {
    match encoding {
        Encoding::Xml => write(f, w),
        Encoding::Binary => crate::tmb::write(f, w),
    }
}

/// Writes a T-mesh file (leaf cells only, compact point numbering).
pub fn write(f: &TMeshFile, w: &mut dyn Write) -> std::io::Result<()> {
    let m = f.mesh.compacted();
    let g = &f.georef;
    writeln!(w, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(w, r#"<tmesh xmlns="{NAMESPACE}" version="1" degree="{}">"#, m.degree.k())?;
    writeln!(w, r#"  <georef x0="{:?}" y0="{:?}" dx="{:?}" dy="{:?}"><crs>{}</crs></georef>"#, g.x0, g.y0, g.dx, g.dy, esc(&g.crs))?;
    writeln!(w, r#"  <points count="{}">"#, m.points.len())?;
    for p in &m.points {
        writeln!(w, "{:?} {:?} {:?} {:?} {:?} {:?}", p.s, p.t, p.x, p.y, p.z, p.w)?;
    }
    writeln!(w, "  </points>")?;
    writeln!(w, r#"  <cells count="{}">"#, m.leaf_count())?;
    for c in m.cells.iter().filter(|c| c.is_leaf()) {
        writeln!(w, "{} {} {} {}", c.corners[0], c.corners[1], c.corners[2], c.corners[3])?;
    }
    writeln!(w, "  </cells>")?;
    if let Some(mask) = &f.mask {
        write!(w, r#"  <mask width="{}" height="{}" encoding="rle">"#, mask.width, mask.height)?;
        for (i, r) in mask.runs().iter().enumerate() {
            if i > 0 {
                write!(w, " ")?;
            }
            write!(w, "{r}")?;
        }
        writeln!(w, "</mask>")?;
    }
    if let Some(json) = &f.warp {
        writeln!(w, r#"  <warp encoding="json">{}</warp>"#, esc(json))?;
    }
    writeln!(w, "</tmesh>")?;
    Ok(())
}

fn line_col(data: &[u8], pos: usize) -> String {
    let pos = pos.min(data.len());
    let line = data[..pos].iter().filter(|&&b| b == b'\n').count() + 1;
    let col = pos - data[..pos].iter().rposition(|&b| b == b'\n').map(|p| p + 1).unwrap_or(0) + 1;
    format!("line {line}:{col}")
}

/// Reads a T-mesh file, XML or binary (told apart by the binary's magic bytes, not by a file
/// name); every problem is reported with its line:column and element (XML) or byte (binary).
pub fn read(data: &[u8]) -> Result<TMeshFile, TsplineError> {
    if data.starts_with(crate::tmb::MAGIC) {
        return crate::tmb::read(data);
    }
    let ferr = |pos: usize, msg: String| TsplineError::Format { pos: line_col(data, pos), msg };
    let mut r = Reader::from_reader(data);
    r.config_mut().trim_text(false);
    let mut stack: Vec<String> = Vec::new();
    let mut degree = None;
    let mut georef: Option<Georef> = None;
    let mut points: Option<(usize, Vec<ControlPoint>)> = None;
    let mut cells: Option<(usize, Vec<[PointId; 4]>)> = None;
    let mut mask: Option<DataMask> = None;
    let mut warp: Option<String> = None;
    let mut pending_attrs: Vec<(String, String)> = Vec::new();
    let mut text = String::new();
    let mut text_pos = 0usize;
    let mut root_seen = false;
    loop {
        let pos = r.buffer_position() as usize;
        let ev = r.read_event().map_err(|e| ferr(pos, format!("not well-formed XML: {}", quote(&e.to_string()))))?;
        match ev {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let name = quote(&String::from_utf8_lossy(e.local_name().as_ref())).into_owned();
                let mut attrs = Vec::new();
                for a in e.attributes() {
                    let a = a.map_err(|x| ferr(pos, format!("<{name}>: bad attribute: {}", quote(&x.to_string()))))?;
                    let v = a.unescape_value().map_err(|x| ferr(pos, format!("<{name}>: bad attribute value: {}", quote(&x.to_string()))))?.to_string();
                    attrs.push((String::from_utf8_lossy(a.key.local_name().as_ref()).to_string(), v));
                }
                let get = |k: &str| attrs.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
                let num = |k: &str| -> Result<f64, TsplineError> {
                    let v = get(k).ok_or_else(|| ferr(pos, format!("<{name}> lacks attribute {k}")))?;
                    let x: f64 = v.trim().parse().map_err(|_| ferr(pos, format!("<{name}> {k}=\"{}\" is not a number", quote(&v))))?;
                    if !x.is_finite() {
                        return Err(ferr(pos, format!("<{name}> {k} is not finite")));
                    }
                    Ok(x)
                };
                let uint = |k: &str| -> Result<usize, TsplineError> {
                    let v = get(k).ok_or_else(|| ferr(pos, format!("<{name}> lacks attribute {k}")))?;
                    v.trim().parse().map_err(|_| ferr(pos, format!("<{name}> {k}=\"{}\" is not a non-negative integer", quote(&v))))
                };
                match (stack.len(), name.as_str()) {
                    (0, "tmesh") => {
                        root_seen = true;
                        let ns = attrs.iter().find(|(n, _)| n == "xmlns").map(|(_, v)| v.as_str()).unwrap_or("");
                        if ns != NAMESPACE {
                            return Err(ferr(pos, format!("<tmesh> namespace is \"{}\", expected \"{NAMESPACE}\"", quote(ns))));
                        }
                        let k = uint("degree")?;
                        degree = Some(Degree::from_u32(k as u32).ok_or_else(|| ferr(pos, format!("degree {k} is not supported (1 or 3)")))?);
                    }
                    (0, other) => return Err(ferr(pos, format!("root element is <{other}>, expected <tmesh>"))),
                    (1, "georef") => {
                        georef = Some(Georef { x0: num("x0")?, y0: num("y0")?, dx: num("dx")?, dy: num("dy")?, crs: String::new() });
                        let g = georef.as_ref().unwrap();
                        if g.dx == 0.0 || g.dy == 0.0 {
                            return Err(ferr(pos, "<georef> dx and dy must be non-zero".into()));
                        }
                    }
                    (2, "crs") => {}
                    (1, "points") => points = Some((uint("count")?, Vec::new())),
                    (1, "cells") => cells = Some((uint("count")?, Vec::new())),
                    (1, "mask") => {
                        if get("encoding").as_deref() != Some("rle") {
                            return Err(ferr(pos, "<mask> encoding must be \"rle\"".into()));
                        }
                        mask = Some(DataMask { width: uint("width")?, height: uint("height")?, bits: Vec::new() });
                    }
                    (1, "warp") => {
                        if get("encoding").as_deref() != Some("json") {
                            return Err(ferr(pos, "<warp> encoding must be \"json\"".into()));
                        }
                        warp = Some(String::new());
                    }
                    (d, other) => return Err(ferr(pos, format!("unexpected element <{other}> at depth {d}"))),
                }
                pending_attrs = attrs;
                if matches!(ev, Event::Start(_)) {
                    stack.push(name);
                    text.clear();
                    text_pos = r.buffer_position() as usize;
                }
            }
            Event::Text(t) => {
                let s = t.decode().map_err(|e| ferr(pos, format!("bad text: {e}")))?;
                let s = quick_xml::escape::unescape(&s).map_err(|e| ferr(pos, format!("bad text: {e}")))?;
                text.push_str(&s);
            }
            Event::GeneralRef(e) => {
                let n = String::from_utf8_lossy(&e).to_string();
                text.push_str(match n.as_str() {
                    "amp" => "&",
                    "lt" => "<",
                    "gt" => ">",
                    "quot" => "\"",
                    "apos" => "'",
                    _ => return Err(ferr(pos, format!("unknown entity &{};", quote(&n)))),
                });
            }
            Event::End(_) => {
                let name = stack.pop().unwrap_or_default();
                let tp = text_pos;
                match name.as_str() {
                    "crs" => {
                        if let Some(g) = georef.as_mut() {
                            g.crs = text.trim().to_string();
                        }
                    }
                    "points" => {
                        let (count, v) = points.as_mut().unwrap();
                        let nums = parse_f64s(&text).map_err(|m| ferr(tp, format!("<points>: {m}")))?;
                        if nums.len() != *count * 6 {
                            return Err(ferr(tp, format!("<points count=\"{count}\"> holds {} numbers, expected {}", nums.len(), *count * 6)));
                        }
                        *v = nums.chunks_exact(6).map(|c| ControlPoint { s: c[0], t: c[1], x: c[2], y: c[3], z: c[4], w: c[5] }).collect();
                    }
                    "cells" => {
                        let (count, v) = cells.as_mut().unwrap();
                        let mut ids = Vec::with_capacity(*count * 4);
                        for tok in text.split_ascii_whitespace() {
                            ids.push(tok.parse::<u32>().map_err(|_| ferr(tp, format!("<cells>: \"{}\" is not a point index", quote(tok))))?);
                        }
                        if ids.len() != *count * 4 {
                            return Err(ferr(tp, format!("<cells count=\"{count}\"> holds {} indices, expected {}", ids.len(), *count * 4)));
                        }
                        *v = ids.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
                    }
                    "mask" => {
                        let m = mask.as_mut().unwrap();
                        let mut bit = false;
                        let total = m.width * m.height;
                        for tok in text.split_ascii_whitespace() {
                            let n: usize = tok.parse().map_err(|_| ferr(tp, format!("<mask>: \"{}\" is not a run length", quote(tok))))?;
                            if m.bits.len() + n > total {
                                return Err(ferr(tp, format!("<mask>: runs exceed {}×{} cells", m.width, m.height)));
                            }
                            m.bits.extend(std::iter::repeat_n(bit, n));
                            bit = !bit;
                        }
                        if m.bits.len() != total {
                            return Err(ferr(tp, format!("<mask>: runs cover {} of {} cells", m.bits.len(), total)));
                        }
                    }
                    "warp" => {
                        *warp.as_mut().unwrap() = text.clone();
                    }
                    _ => {}
                }
                text.clear();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    let _ = pending_attrs;
    if !root_seen {
        return Err(ferr(0, "no <tmesh> element".into()));
    }
    let end = data.len();
    let degree = degree.ok_or_else(|| ferr(end, "<tmesh> lacks degree".into()))?;
    let georef = georef.ok_or_else(|| ferr(end, "missing <georef>".into()))?;
    let (_, points) = points.ok_or_else(|| ferr(end, "missing <points>".into()))?;
    let (_, cells) = cells.ok_or_else(|| ferr(end, "missing <cells>".into()))?;
    let mesh = TMesh::from_cells(degree, points, cells)?;
    Ok(TMeshFile { mesh, georef, mask, warp })
}

fn parse_f64s(text: &str) -> Result<Vec<f64>, String> {
    let mut v = Vec::new();
    for tok in text.split_ascii_whitespace() {
        let x: f64 = tok.parse().map_err(|_| format!("\"{}\" is not a number", quote(tok)))?;
        if !x.is_finite() {
            return Err(format!("\"{}\" is not finite", quote(tok)));
        }
        v.push(x);
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tmesh_documents_are_recognised_by_their_root() {
        assert!(is_tmesh_document(b"\xEF\xBB\xBF<?xml version=\"1.0\"?>\n<!-- a > b --><tmesh xmlns=\"urn:geofit:tmesh:1\">"));
        assert!(is_tmesh_document(b"  <tmesh>"));
        assert!(is_tmesh_document(b"<?xml version=\"1.0\"?><!DOCTYPE tmesh><tmesh degree=\"1\">"));
        assert!(!is_tmesh_document(b"<?xml version=\"1.0\"?><core:CityModel>"));
        assert!(!is_tmesh_document(b"<tmeshes>"));
        assert!(!is_tmesh_document(b"<?xml unterminated"));
        assert!(!is_tmesh_document(b""));
        assert!(!is_tmesh_document(b"1 2 3\n"));
    }

    #[test]
    fn write_read_exact() {
        let mut m = TMesh::grid(Degree::Cubic, -3.0, 2.0, 4.0, 3, 2);
        let mut g = |s: f64, t: f64| (s * 0.1 + 1e-300, t / 3.0, (s * t).sin());
        m.split(1, &mut g);
        for (i, p) in m.points.iter_mut().enumerate() {
            p.z = (i as f64).sqrt() * 1e-7 - 12345.678;
            p.w = 1.0 + i as f64 / 7.0;
        }
        let file = TMeshFile {
            mesh: m.clone(),
            georef: Georef { x0: 500015.0, y0: 2150015.5, dx: 30.0, dy: 30.0, crs: "PROJCS[\"WGS 84 / UTM <5N>\"] & co".into() },
            mask: Some(DataMask { width: 5, height: 3, bits: (0..15).map(|i| i % 4 != 0).collect() }),
            warp: Some(r#"{"version":1,"rotation":0.5,"src":[[1.0,2.0]],"note":"<a & b>"}"#.into()),
        };
        let mut buf = Vec::new();
        write(&file, &mut buf).unwrap();
        let back = read(&buf).unwrap();
        assert_eq!(back.georef, file.georef);
        assert_eq!(back.mask, file.mask);
        assert_eq!(back.warp, file.warp);
        let c = m.compacted();
        assert_eq!(back.mesh.points, c.points);
        let cells_a: Vec<_> = c.cells.iter().map(|c| c.corners).collect();
        let cells_b: Vec<_> = back.mesh.cells.iter().map(|c| c.corners).collect();
        assert_eq!(cells_a, cells_b);
        // writing again gives the same bytes
        let mut buf2 = Vec::new();
        write(&back, &mut buf2).unwrap();
        assert_eq!(buf, buf2);
    }

    #[test]
    fn errors_name_the_position() {
        let bad = b"<tmesh xmlns=\"urn:geofit:tmesh:1\" version=\"1\" degree=\"3\">\n<georef x0=\"0\" y0=\"0\" dx=\"1\" dy=\"1\"/>\n<points count=\"2\">0 0 0 0 0 1\n1 x 0 0 0 1</points></tmesh>";
        let e = read(bad).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("\"x\""), "{e}");
        let bad = b"<tmesh xmlns=\"urn:geofit:tmesh:1\" degree=\"2\"/>";
        assert!(read(bad).unwrap_err().to_string().contains("degree 2"));
        // a mesh breaking the T-mesh rules (cell corners not a rectangle)
        let bad = b"<tmesh xmlns=\"urn:geofit:tmesh:1\" degree=\"1\"><georef x0=\"0\" y0=\"0\" dx=\"1\" dy=\"1\"/><points count=\"4\">0 1 0 1 0 1 1 1 1 1 0 1 0 0 0 0 0 1 2 0 2 0 0 1</points><cells count=\"1\">0 1 2 3</cells></tmesh>";
        assert!(read(bad).unwrap_err().to_string().contains("rectangle"));
    }
}
