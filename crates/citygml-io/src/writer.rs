//! Lossless writing: the output is the source bytes with [`Edit`]s spliced in. Without edits the
//! output IS the input (byte-identical, hence canonically equal); with coordinate edits only the
//! touched coordinate texts change. Nothing is ever re-serialised.

use std::io::Write;
use std::ops::Range;

use crate::error::WriteError;
use crate::model::{CoordEncoding, Point3, Ring};

/// Replace `bytes` of the source by `replacement` (an empty range inserts, an empty
/// replacement deletes, e.g. a `Polygon::member_span` to drop a polygon with its wrapper).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Edit {
    pub bytes: Range<usize>,
    pub replacement: Vec<u8>,
}

/// Writes `src` with `edits` applied. Edits may come in any order; they must not overlap
/// (two insertions at the same offset are applied in the order given).
pub fn write_with_edits(src: &[u8], edits: &[Edit], out: &mut dyn Write) -> Result<(), WriteError> {
    let mut order: Vec<&Edit> = edits.iter().collect();
    order.sort_by_key(|e| (e.bytes.start, e.bytes.end));
    for e in &order {
        if e.bytes.start > e.bytes.end || e.bytes.end > src.len() {
            return Err(WriteError::OutOfBounds { start: e.bytes.start, end: e.bytes.end, len: src.len() });
        }
    }
    for w in order.windows(2) {
        let (a, b) = (&w[0].bytes, &w[1].bytes);
        if a.end > b.start {
            return Err(WriteError::Overlap { a_start: a.start, a_end: a.end, b_start: b.start, b_end: b.end });
        }
    }
    let mut at = 0;
    for e in order {
        out.write_all(&src[at..e.bytes.start])?;
        out.write_all(&e.replacement)?;
        at = e.bytes.end;
    }
    out.write_all(&src[at..])?;
    Ok(())
}

/// One position as text: values separated by `sep`, in the ring's dimension, shortest
/// round-trip formatting (Rust `{}` of f64: `3.5`, `1`, `0.1`, `385421.123`).
fn push_point(s: &mut String, p: &Point3, dim: u8, sep: char) {
    use std::fmt::Write as _;
    for (i, v) in p.iter().take(dim as usize).enumerate() {
        if i > 0 {
            s.push(sep);
        }
        // `+ 0.0` turns -0 into 0, so a coordinate never reads "-0".
        let _ = write!(s, "{}", v + 0.0);
    }
}

/// The coordinate text for `points` in `ring`'s own encoding and dimension: `gml:posList` →
/// `x y z x y z ...`; `gml:coordinates` → `x,y,z x,y,z ...`; `gml:pos` → the same text as a
/// posList (a `gml:pos` ring has one text per position: use [`ring_edits`] to edit it).
pub fn format_coordinates(ring: &Ring, points: &[Point3]) -> String {
    let mut s = String::with_capacity(points.len() * 3 * 12);
    let (tuple_sep, value_sep) = match ring.encoding {
        CoordEncoding::Coordinates => (' ', ','),
        CoordEncoding::PosList | CoordEncoding::Pos => (' ', ' '),
    };
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            s.push(tuple_sep);
        }
        push_point(&mut s, p, ring.srs_dimension, value_sep);
    }
    s
}

/// The edits that replace `ring`'s coordinates by `points`, keeping its encoding, dimension
/// and the whitespace around the texts. A `gml:pos` ring gets one edit per position and must
/// keep its number of positions; a posList/coordinates ring may change it (a `count`
/// attribute on the posList, rare in CityGML, is not updated).
pub fn ring_edits(ring: &Ring, points: &[Point3]) -> Result<Vec<Edit>, WriteError> {
    ring_edits_with(ring, points, |_, _, v| format!("{}", v + 0.0))
}

/// [`ring_edits`] with the text of each value chosen by `value(point index, coordinate index,
/// value)`: a writer that keeps the input's number of decimals, or its unchanged tokens.
pub fn ring_edits_with(
    ring: &Ring,
    points: &[Point3],
    value: impl Fn(usize, usize, f64) -> String,
) -> Result<Vec<Edit>, WriteError> {
    if points.iter().flatten().any(|v| !v.is_finite()) {
        return Err(WriteError::Coordinates("a new coordinate is not finite".into()));
    }
    let dim = ring.srs_dimension as usize;
    let point_text = |i: usize, p: &Point3, sep: char| -> String {
        let mut s = String::new();
        for (c, v) in p.iter().take(dim).enumerate() {
            if c > 0 {
                s.push(sep);
            }
            s.push_str(&value(i, c, *v));
        }
        s
    };
    match ring.encoding {
        CoordEncoding::Pos => {
            if points.len() != ring.pos_spans.len() {
                return Err(WriteError::Coordinates(format!(
                    "a gml:pos ring has {} positions, {} given",
                    ring.pos_spans.len(),
                    points.len()
                )));
            }
            Ok(ring
                .pos_spans
                .iter()
                .zip(points)
                .enumerate()
                .map(|(i, (sp, p))| Edit { bytes: sp.bytes.clone(), replacement: point_text(i, p, ' ').into_bytes() })
                .collect())
        }
        CoordEncoding::PosList | CoordEncoding::Coordinates => {
            let value_sep = if ring.encoding == CoordEncoding::Coordinates { ',' } else { ' ' };
            let text: Vec<String> = points.iter().enumerate().map(|(i, p)| point_text(i, p, value_sep)).collect();
            Ok(vec![Edit { bytes: ring.text_span.bytes.clone(), replacement: text.join(" ").into_bytes() }])
        }
    }
}

/// Escapes `&`, `<`, `>` and `"` for an attribute value.
fn attr_escape(v: &str) -> String {
    v.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A `gml:LinearRing` element with one `gml:posList` holding `coordinates` (the text of the
/// positions, see [`format_coordinates`]), in the GML namespace prefix `prefix` (`"gml:"`, or
/// `""` for a default namespace), with an optional gml:id: what a writer puts where a ring is
/// replaced by one of another length.
///
/// # Examples
/// ```
/// use citygml_io::writer::linear_ring_element;
/// assert_eq!(
///     linear_ring_element("gml:", Some("r1"), "0 0 0 1 0 0 1 1 0 0 0 0", 3),
///     r#"<gml:LinearRing gml:id="r1"><gml:posList srsDimension="3">0 0 0 1 0 0 1 1 0 0 0 0</gml:posList></gml:LinearRing>"#
/// );
/// ```
pub fn linear_ring_element(prefix: &str, id: Option<&str>, coordinates: &str, srs_dimension: u8) -> String {
    let id = id.map(|i| format!(" {prefix}id=\"{}\"", attr_escape(i))).unwrap_or_default();
    format!("<{prefix}LinearRing{id}><{prefix}posList srsDimension=\"{srs_dimension}\">{coordinates}</{prefix}posList></{prefix}LinearRing>")
}

/// A `gml:Polygon` element: `rings[0]` is the exterior, the others interiors; each ring is
/// (its gml:id, its posList text). Used to write a polygon whose outline changed (merged
/// coplanar polygons) in place of the old element.
pub fn polygon_element(prefix: &str, id: Option<&str>, rings: &[(Option<&str>, String)], srs_dimension: u8) -> String {
    let mut t =
        format!("<{prefix}Polygon{}>", id.map(|i| format!(" {prefix}id=\"{}\"", attr_escape(i))).unwrap_or_default());
    for (k, (rid, coords)) in rings.iter().enumerate() {
        let wrapper = if k == 0 { "exterior" } else { "interior" };
        t.push_str(&format!(
            "<{prefix}{wrapper}>{}</{prefix}{wrapper}>",
            linear_ring_element(prefix, *rid, coords, srs_dimension)
        ));
    }
    t.push_str(&format!("</{prefix}Polygon>"));
    t
}
