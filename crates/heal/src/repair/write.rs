//! The repaired polygons as edits of the document: a ring that only changed its points gets
//! its coordinate text replaced (in its own encoding where it can); a polygon whose rings
//! changed in number is written anew in place (its gml:id and its rings' ids kept, so XLinks to
//! it still resolve); a polygon split into lobes becomes several members of its surface; a
//! removed polygon goes with its member element.

use super::ring::P3;
use super::work::{Face, WPoly};
use citygml_io::writer::{format_coordinates, linear_ring_element, polygon_element};
use citygml_io::{ring_edits, CoordEncoding, Edit, Ring};

/// The namespace prefix of an element from its start tag (`<gml:Polygon` → `gml:`).
fn prefix_of(doc: &[u8], start: usize, local: &str) -> Option<String> {
    let tail = doc.get(start + 1..)?;
    let end = tail.iter().position(|c| c.is_ascii_whitespace() || *c == b'>' || *c == b'/')?;
    let name = std::str::from_utf8(&tail[..end]).ok()?;
    name.strip_suffix(local).map(str::to_string)
}

fn closed(r: &[P3]) -> Vec<P3> {
    let mut v = r.to_vec();
    if let Some(&f) = r.first() {
        v.push(f);
    }
    v
}

/// The text of a ring's positions as a posList.
fn pos_text(template: &Ring, r: &[P3]) -> String {
    let mut t = template.clone();
    t.encoding = CoordEncoding::PosList;
    format_coordinates(&t, &closed(r))
}

/// A whole `gml:Polygon` element for a face (ids kept where the ring was there before).
fn polygon_text(doc: &[u8], p: &WPoly, face: &Face, id: Option<&str>) -> Result<String, String> {
    let src = p.src;
    let prefix = prefix_of(doc, src.span.bytes.start, "Polygon").ok_or("the polygon's start tag cannot be read")?;
    let orig: Vec<&Ring> = std::iter::once(&src.exterior).chain(src.interiors.iter()).collect();
    let rings: Vec<(Option<&str>, String)> = face
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let rid = if id.is_some() { orig.get(k).and_then(|o| o.id.as_deref()) } else { None };
            (rid, pos_text(&src.exterior, r))
        })
        .collect();
    Ok(polygon_element(&prefix, id, &rings, 3))
}

/// The edits that write one changed polygon.
pub fn polygon_edits(doc: &[u8], p: &WPoly) -> Result<Vec<Edit>, String> {
    let src = p.src;
    if p.removed {
        let m = src.member_span.as_ref().ok_or("a polygon without a member element cannot be removed")?;
        return Ok(vec![Edit { bytes: m.bytes.clone(), replacement: Vec::new() }]);
    }
    if !p.extra.is_empty() {
        let m = src.member_span.as_ref().ok_or("a polygon without a member element cannot be split")?;
        let open_end =
            doc[m.bytes.start..m.bytes.end].iter().position(|&c| c == b'>').ok_or("member tag")? + m.bytes.start + 1;
        let open = std::str::from_utf8(&doc[m.bytes.start..open_end]).map_err(|e| e.to_string())?;
        if open.ends_with("/>") || open.contains("href") {
            return Err("the polygon's member element cannot be repeated".into());
        }
        let name: String = open[1..].chars().take_while(|c| !c.is_whitespace() && *c != '>').collect();
        let mut text = String::new();
        for (k, f) in p.faces().enumerate() {
            let id = if k == 0 { src.id.as_deref() } else { None };
            text.push_str(&format!("{open}{}</{name}>", polygon_text(doc, p, f, id)?));
        }
        return Ok(vec![Edit { bytes: m.bytes.clone(), replacement: text.into_bytes() }]);
    }
    let orig: Vec<&Ring> = std::iter::once(&src.exterior).chain(src.interiors.iter()).collect();
    if orig.len() != p.face.len() {
        let text = polygon_text(doc, p, &p.face, src.id.as_deref())?;
        return Ok(vec![Edit { bytes: src.span.bytes.clone(), replacement: text.into_bytes() }]);
    }
    let mut edits = Vec::new();
    for (ring, r) in orig.iter().zip(&p.face) {
        let pts = closed(r);
        if pts == ring.points {
            continue;
        }
        if ring.encoding == CoordEncoding::Pos && pts.len() != ring.pos_spans.len() {
            let prefix =
                prefix_of(doc, ring.span.bytes.start, "LinearRing").ok_or("the ring's start tag cannot be read")?;
            let text = linear_ring_element(&prefix, ring.id.as_deref(), &pos_text(ring, r), 3);
            edits.push(Edit { bytes: ring.span.bytes.clone(), replacement: text.into_bytes() });
        } else {
            let same = |e: &Edit| numbers(&doc[e.bytes.clone()]) == numbers(&e.replacement);
            edits.extend(ring_edits(ring, &pts).map_err(|e| e.to_string())?.into_iter().filter(|e| !same(e)));
        }
    }
    Ok(edits)
}

/// The numbers of a coordinate text (`gml:pos` positions that did not change keep their text).
fn numbers(t: &[u8]) -> Option<Vec<f64>> {
    std::str::from_utf8(t)
        .ok()?
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|x| !x.is_empty())
        .map(|x| x.parse().ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_prefix_comes_from_the_start_tag() {
        let doc = b"<x><gml:Polygon gml:id=\"a\"><Polygon>";
        assert_eq!(prefix_of(doc, 3, "Polygon").as_deref(), Some("gml:"));
        assert_eq!(prefix_of(doc, 27, "Polygon").as_deref(), Some(""));
        assert_eq!(prefix_of(doc, 0, "Polygon"), None);
    }
}
