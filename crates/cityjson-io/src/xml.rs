//! The bits of XML text the CityGML writer needs: escaping and the GML polygon.

use std::fmt::Write;

use crate::transform::format_number;

/// Text or attribute value with `& < > "` escaped.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            // A newline inside one feature would break the one-line-per-feature layout.
            '\n' => out.push_str("&#10;"),
            '\r' => out.push_str("&#13;"),
            _ => out.push(c),
        }
    }
    out
}

/// A `gml:Polygon` whose rings are given as points (not closed: the closing point is added).
pub fn polygon(out: &mut String, id: &str, rings: &[Vec<[f64; 3]>], decimals: usize) {
    let _ = write!(out, "<gml:Polygon gml:id=\"{}\">", escape(id));
    for (i, ring) in rings.iter().enumerate() {
        let tag = if i == 0 { "exterior" } else { "interior" };
        let _ = write!(out, "<gml:{tag}><gml:LinearRing><gml:posList srsDimension=\"3\">");
        let closed = ring.iter().chain(ring.first());
        for (k, p) in closed.enumerate() {
            if k > 0 {
                out.push(' ');
            }
            let _ = write!(
                out,
                "{} {} {}",
                format_number(p[0], decimals),
                format_number(p[1], decimals),
                format_number(p[2], decimals)
            );
        }
        let _ = write!(out, "</gml:posList></gml:LinearRing></gml:{tag}>");
    }
    out.push_str("</gml:Polygon>");
}

/// The namespace declarations of the CityGML 2.0 documents the writer makes.
pub const CITYGML2_NAMESPACES: &str = concat!(
    "xmlns:core=\"http://www.opengis.net/citygml/2.0\" ",
    "xmlns:bldg=\"http://www.opengis.net/citygml/building/2.0\" ",
    "xmlns:gen=\"http://www.opengis.net/citygml/generics/2.0\" ",
    "xmlns:gml=\"http://www.opengis.net/gml\" ",
    "xmlns:xlink=\"http://www.w3.org/1999/xlink\" ",
    "xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" ",
    "xsi:schemaLocation=\"http://www.opengis.net/citygml/building/2.0 http://schemas.opengis.net/citygml/building/2.0/building.xsd ",
    "http://www.opengis.net/citygml/generics/2.0 http://schemas.opengis.net/citygml/generics/2.0/generics.xsd\""
);
