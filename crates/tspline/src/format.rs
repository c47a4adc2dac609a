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

use input_limits::quote;
use quick_xml::events::Event;
use quick_xml::Reader;

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
            return rest.starts_with(b"<tmesh")
                && rest.get(6).is_some_and(|b| b.is_ascii_whitespace() || *b == b'>' || *b == b'/');
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
    writeln!(
        w,
        r#"  <georef x0="{:?}" y0="{:?}" dx="{:?}" dy="{:?}"><crs>{}</crs></georef>"#,
        g.x0,
        g.y0,
        g.dx,
        g.dy,
        esc(&g.crs)
    )?;
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
    let text_of = XmlText(data);
    // XML allows no NUL character anywhere; one that reached the CRS went on to GDAL as a C
    // string and failed there ("FfiNulError", exit 4) instead of naming the input.
    if let Some(pos) = data.iter().position(|&b| b == 0) {
        return Err(text_of.err(pos, "a NUL byte, which XML text cannot hold".into()));
    }
    let mut r = Reader::from_reader(data);
    r.config_mut().trim_text(false);
    let mut parts = XmlParts::default();
    let mut open: Vec<String> = Vec::new();
    let mut text = String::new();
    let mut text_pos = 0usize;
    loop {
        let pos = r.buffer_position() as usize;
        let ev =
            r.read_event().map_err(|e| text_of.err(pos, format!("not well-formed XML: {}", quote(&e.to_string()))))?;
        match ev {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let tag = StartTag::read(e, pos, &text_of)?;
                parts.open(open.len(), &tag)?;
                if matches!(ev, Event::Start(_)) {
                    open.push(tag.name);
                    text.clear();
                    text_pos = r.buffer_position() as usize;
                }
            }
            Event::Text(t) => {
                let s = t.decode().map_err(|e| text_of.err(pos, format!("bad text: {e}")))?;
                let s = quick_xml::escape::unescape(&s).map_err(|e| text_of.err(pos, format!("bad text: {e}")))?;
                text.push_str(&s);
            }
            Event::GeneralRef(e) => {
                let name = String::from_utf8_lossy(&e).to_string();
                let c = predefined_entity(&name)
                    .ok_or_else(|| text_of.err(pos, format!("unknown entity &{};", quote(&name))))?;
                text.push_str(c);
            }
            Event::End(_) => {
                let name = open.pop().unwrap_or_default();
                parts.close(&name, &text).map_err(|msg| text_of.err(text_pos, msg))?;
                text.clear();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    parts.finish(&text_of)
}

/// The XML text being read, for turning a byte position into the line:column of a message.
struct XmlText<'a>(&'a [u8]);

impl XmlText<'_> {
    fn err(&self, pos: usize, msg: String) -> TsplineError {
        TsplineError::Format { pos: line_col(self.0, pos), msg }
    }
}

/// One element's start tag: its name and attributes, and where it sits for messages.
struct StartTag<'a> {
    name: String,
    attrs: Vec<(String, String)>,
    pos: usize,
    text_of: &'a XmlText<'a>,
}

impl<'a> StartTag<'a> {
    fn read(
        e: &quick_xml::events::BytesStart,
        pos: usize,
        text_of: &'a XmlText<'a>,
    ) -> Result<StartTag<'a>, TsplineError> {
        let name = quote(&String::from_utf8_lossy(e.local_name().as_ref())).into_owned();
        let mut attrs = Vec::new();
        for a in e.attributes() {
            let a = a.map_err(|x| text_of.err(pos, format!("<{name}>: bad attribute: {}", quote(&x.to_string()))))?;
            let v = a
                .unescape_value()
                .map_err(|x| text_of.err(pos, format!("<{name}>: bad attribute value: {}", quote(&x.to_string()))))?
                .to_string();
            attrs.push((String::from_utf8_lossy(a.key.local_name().as_ref()).to_string(), v));
        }
        Ok(StartTag { name, attrs, pos, text_of })
    }

    fn err(&self, msg: String) -> TsplineError {
        self.text_of.err(self.pos, msg)
    }

    fn get(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(n, _)| n == key).map(|(_, v)| v.as_str())
    }

    fn required(&self, key: &str) -> Result<&str, TsplineError> {
        self.get(key).ok_or_else(|| self.err(format!("<{}> lacks attribute {key}", self.name)))
    }

    fn num(&self, key: &str) -> Result<f64, TsplineError> {
        let v = self.required(key)?;
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| self.err(format!("<{}> {key}=\"{}\" is not a number", self.name, quote(v))))?;
        if !x.is_finite() {
            return Err(self.err(format!("<{}> {key} is not finite", self.name)));
        }
        Ok(x)
    }

    fn uint(&self, key: &str) -> Result<usize, TsplineError> {
        let v = self.required(key)?;
        v.trim()
            .parse()
            .map_err(|_| self.err(format!("<{}> {key}=\"{}\" is not a non-negative integer", self.name, quote(v))))
    }
}

/// The five entities XML predefines; a `.tmesh` file declares no others.
fn predefined_entity(name: &str) -> Option<&'static str> {
    Some(match name {
        "amp" => "&",
        "lt" => "<",
        "gt" => ">",
        "quot" => "\"",
        "apos" => "'",
        _ => return None,
    })
}

/// What the XML reader has collected so far: each element's start tag and text fill one part.
#[derive(Default)]
struct XmlParts {
    root_seen: bool,
    degree: Option<Degree>,
    georef: Option<Georef>,
    points: Option<(usize, Vec<ControlPoint>)>,
    cells: Option<(usize, Vec<[PointId; 4]>)>,
    mask: Option<DataMask>,
    warp: Option<String>,
}

impl XmlParts {
    /// A start tag at `depth` (0 = the root): checks where it may stand and reads its attributes.
    fn open(&mut self, depth: usize, tag: &StartTag) -> Result<(), TsplineError> {
        match (depth, tag.name.as_str()) {
            (0, "tmesh") => {
                self.root_seen = true;
                let ns = tag.get("xmlns").unwrap_or("");
                if ns != NAMESPACE {
                    return Err(tag.err(format!("<tmesh> namespace is \"{}\", expected \"{NAMESPACE}\"", quote(ns))));
                }
                let k = tag.uint("degree")?;
                self.degree = Some(
                    Degree::from_u32(k as u32)
                        .ok_or_else(|| tag.err(format!("degree {k} is not supported (1 or 3)")))?,
                );
            }
            (0, other) => return Err(tag.err(format!("root element is <{other}>, expected <tmesh>"))),
            (1, "georef") => {
                let g = Georef {
                    x0: tag.num("x0")?,
                    y0: tag.num("y0")?,
                    dx: tag.num("dx")?,
                    dy: tag.num("dy")?,
                    crs: String::new(),
                };
                if g.dx == 0.0 || g.dy == 0.0 {
                    return Err(tag.err("<georef> dx and dy must be non-zero".into()));
                }
                self.georef = Some(g);
            }
            (2, "crs") => {}
            (1, "points") => self.points = Some((tag.uint("count")?, Vec::new())),
            (1, "cells") => self.cells = Some((tag.uint("count")?, Vec::new())),
            (1, "mask") => {
                if tag.get("encoding") != Some("rle") {
                    return Err(tag.err("<mask> encoding must be \"rle\"".into()));
                }
                self.mask = Some(DataMask { width: tag.uint("width")?, height: tag.uint("height")?, bits: Vec::new() });
            }
            (1, "warp") => {
                if tag.get("encoding") != Some("json") {
                    return Err(tag.err("<warp> encoding must be \"json\"".into()));
                }
                self.warp = Some(String::new());
            }
            (d, other) => return Err(tag.err(format!("unexpected element <{other}> at depth {d}"))),
        }
        Ok(())
    }

    /// An end tag: the element's text becomes its part; the message is placed at the text.
    fn close(&mut self, name: &str, text: &str) -> Result<(), String> {
        match name {
            "crs" => {
                if let Some(g) = self.georef.as_mut() {
                    g.crs = text.trim().to_string();
                }
            }
            "points" => {
                if let Some((count, v)) = self.points.as_mut() {
                    *v = parse_points(*count, text)?;
                }
            }
            "cells" => {
                if let Some((count, v)) = self.cells.as_mut() {
                    *v = parse_cells(*count, text)?;
                }
            }
            "mask" => {
                if let Some(m) = self.mask.as_mut() {
                    m.bits = parse_mask_runs(m.width, m.height, text)?;
                }
            }
            "warp" => self.warp = Some(text.to_string()),
            _ => {}
        }
        Ok(())
    }

    /// The file, once every required part was seen; a missing part is reported at the end of
    /// the text, a missing root at its start.
    fn finish(self, text_of: &XmlText) -> Result<TMeshFile, TsplineError> {
        if !self.root_seen {
            return Err(text_of.err(0, "no <tmesh> element".into()));
        }
        let missing = |what: &str| text_of.err(text_of.0.len(), what.to_string());
        let degree = self.degree.ok_or_else(|| missing("<tmesh> lacks degree"))?;
        let georef = self.georef.ok_or_else(|| missing("missing <georef>"))?;
        let (_, points) = self.points.ok_or_else(|| missing("missing <points>"))?;
        let (_, cells) = self.cells.ok_or_else(|| missing("missing <cells>"))?;
        let mesh = TMesh::from_cells(degree, points, cells)?;
        Ok(TMeshFile { mesh, georef, mask: self.mask, warp: self.warp })
    }
}

fn parse_points(count: usize, text: &str) -> Result<Vec<ControlPoint>, String> {
    let nums = parse_f64s(text).map_err(|m| format!("<points>: {m}"))?;
    if nums.len() != count * 6 {
        return Err(format!("<points count=\"{count}\"> holds {} numbers, expected {}", nums.len(), count * 6));
    }
    Ok(nums.chunks_exact(6).map(|c| ControlPoint { s: c[0], t: c[1], x: c[2], y: c[3], z: c[4], w: c[5] }).collect())
}

fn parse_cells(count: usize, text: &str) -> Result<Vec<[PointId; 4]>, String> {
    let mut ids = Vec::with_capacity(count * 4);
    for tok in text.split_ascii_whitespace() {
        ids.push(tok.parse::<u32>().map_err(|_| format!("<cells>: \"{}\" is not a point index", quote(tok)))?);
    }
    if ids.len() != count * 4 {
        return Err(format!("<cells count=\"{count}\"> holds {} indices, expected {}", ids.len(), count * 4));
    }
    Ok(ids.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect())
}

/// Run lengths of alternating no-data / data (the format's mask, [`DataMask::runs`]) back to bits.
fn parse_mask_runs(width: usize, height: usize, text: &str) -> Result<Vec<bool>, String> {
    let total = width * height;
    let mut bits = Vec::with_capacity(total);
    let mut bit = false;
    for tok in text.split_ascii_whitespace() {
        let n: usize = tok.parse().map_err(|_| format!("<mask>: \"{}\" is not a run length", quote(tok)))?;
        if bits.len() + n > total {
            return Err(format!("<mask>: runs exceed {width}×{height} cells"));
        }
        bits.extend(std::iter::repeat_n(bit, n));
        bit = !bit;
    }
    if bits.len() != total {
        return Err(format!("<mask>: runs cover {} of {} cells", bits.len(), total));
    }
    Ok(bits)
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
        assert!(is_tmesh_document(
            b"\xEF\xBB\xBF<?xml version=\"1.0\"?>\n<!-- a > b --><tmesh xmlns=\"urn:geofit:tmesh:1\">"
        ));
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
            georef: Georef {
                x0: 500015.0,
                y0: 2150015.5,
                dx: 30.0,
                dy: 30.0,
                crs: "PROJCS[\"WGS 84 / UTM <5N>\"] & co".into(),
            },
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
    fn nul_bytes_are_refused_with_their_position() {
        let mut buf = Vec::new();
        write(
            &TMeshFile {
                mesh: TMesh::grid(Degree::Cubic, 0.0, 0.0, 1.0, 2, 2),
                georef: Georef::identity(),
                mask: None,
                warp: None,
            },
            &mut buf,
        )
        .unwrap();
        let text = String::from_utf8(buf).unwrap().replace("<crs>", "<crs>EPSG:\u{0}25832");
        let e = read(text.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("line 3:") && e.contains("a NUL byte") && !e.contains('\0'), "{e}");
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
