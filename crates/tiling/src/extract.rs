//! A tile's buildings as one CityGML document: the root start tag of its (first) source, a
//! `gml:boundedBy` envelope of the tile's buildings with the source's srsName, and each owned
//! building's member element copied byte for byte, so that heal, validate and export see exactly
//! the text they would see in the source file.

use std::ops::Range;

use citygml_io::{Envelope, ObjectStream};

use crate::buildings::{cell, cell_id, footprint_centroid, owns_building};
use crate::plan::{Tile, TileKind};
use crate::TilingError;

/// The extracted document and how many buildings it holds.
pub struct Extract {
    pub document: Vec<u8>,
    pub buildings: usize,
}

/// The buildings of `tile` from its sources (`read` gives the bytes of a source path).
pub fn extract(tile: &Tile, read: &dyn Fn(&str) -> Result<Vec<u8>, TilingError>) -> Result<Extract, TilingError> {
    if tile.kind != TileKind::Buildings {
        return Err(TilingError::Usage(format!("tile {}: a raster tile has no buildings to extract", tile.id)));
    }
    let mut head: Option<(String, Vec<u8>, String)> = None; // (source, root start tag incl. prolog, root name)
    let (mut members, mut envelope, mut srs, mut count) = (Vec::new(), Envelope::empty(), None, 0);
    for src in &tile.sources {
        let bytes = read(src)?;
        let (prolog, root) = root_start(&bytes).ok_or_else(|| TilingError::unreadable(src, "no root element"))?;
        if let Some((first, tag, _)) = &head {
            if tag.as_slice() != &bytes[..prolog.end] {
                return Err(TilingError::unreadable(
                    src,
                    format!("its XML prolog and root start tag differ from {first}'s: tile {} cannot mix them in one document", tile.id),
                ));
            }
        } else {
            head = Some((src.clone(), bytes[..prolog.end].to_vec(), root.clone()));
        }
        let mut stream = ObjectStream::new(&bytes).map_err(|e| TilingError::unreadable(src, e))?;
        for o in stream.by_ref() {
            let o = o.map_err(|e| TilingError::unreadable(src, e))?;
            if !owns_building(&o) {
                continue;
            }
            let Some(c) = footprint_centroid(&o) else { continue };
            if cell_id(cell(c, tile.size)) != tile.id {
                continue;
            }
            let m = member_span(&bytes, o.span.bytes.clone()).ok_or_else(|| {
                TilingError::unreadable(src, format!("line {}: building not inside a member element", o.span.line))
            })?;
            members.push(bytes[m].to_vec());
            envelope.merge(&o.envelope);
            count += 1;
        }
        // known once the stream has passed the document's envelope (or first geometry)
        srs = srs.or_else(|| stream.srs_name());
    }
    let Some((_, start, root)) = head else {
        return Err(TilingError::Usage(format!("tile {}: the plan names no source", tile.id)));
    };
    let mut doc = start;
    doc.extend_from_slice(b"\n");
    if !envelope.is_empty() {
        let gml = gml_prefix(&doc).unwrap_or_else(|| "gml".into());
        doc.extend_from_slice(bounded_by(&gml, &envelope, srs.as_deref()).as_bytes());
    }
    for m in members {
        doc.extend_from_slice(b"  ");
        doc.extend_from_slice(&m);
        doc.extend_from_slice(b"\n");
    }
    doc.extend_from_slice(format!("</{root}>\n").as_bytes());
    Ok(Extract { document: doc, buildings: count })
}

fn bounded_by(gml: &str, e: &Envelope, srs: Option<&str>) -> String {
    let srs = srs.map(|s| format!(" srsName=\"{s}\"")).unwrap_or_default();
    let c = |p: [f64; 3]| p.map(|v| v.to_string()).join(" ");
    format!(
        "  <{gml}:boundedBy>\n    <{gml}:Envelope{srs} srsDimension=\"3\">\n      <{gml}:lowerCorner>{}</{gml}:lowerCorner>\n      <{gml}:upperCorner>{}</{gml}:upperCorner>\n    </{gml}:Envelope>\n  </{gml}:boundedBy>\n",
        c(e.min),
        c(e.max)
    )
}

/// The prefix bound to the GML 3.1/3.2 namespace in the root start tag.
fn gml_prefix(start: &[u8]) -> Option<String> {
    let s = String::from_utf8_lossy(start);
    for ns in ["\"http://www.opengis.net/gml\"", "\"http://www.opengis.net/gml/3.2\""] {
        if let Some(i) = s.find(&format!("={ns}")) {
            let before = &s[..i];
            let at = before.rfind("xmlns:")?;
            return Some(before[at + 6..].to_string());
        }
    }
    None
}

/// The byte range from the document start to the end of the root start tag, and the root's
/// qualified name. Skips the XML declaration, comments, processing instructions and a DOCTYPE.
fn root_start(b: &[u8]) -> Option<(Range<usize>, String)> {
    let mut i = 0;
    loop {
        i += b[i..].iter().position(|&c| c == b'<')?;
        match b.get(i + 1)? {
            b'?' => i += find(&b[i..], b"?>")? + 2,
            b'!' if b[i..].starts_with(b"<!--") => i += find(&b[i..], b"-->")? + 3,
            b'!' => i += b[i..].iter().position(|&c| c == b'>')? + 1,
            _ => {
                let end = tag_end(b, i)?;
                let name: String = b[i + 1..end]
                    .iter()
                    .take_while(|c| !c.is_ascii_whitespace() && **c != b'>' && **c != b'/')
                    .map(|&c| c as char)
                    .collect();
                return Some((0..end + 1, name));
            }
        }
    }
}

/// Index of the `>` closing the tag that starts at `i` (quotes respected).
fn tag_end(b: &[u8], i: usize) -> Option<usize> {
    let mut quote = None;
    for (k, &c) in b.iter().enumerate().skip(i) {
        match (quote, c) {
            (None, b'"' | b'\'') => quote = Some(c),
            (Some(q), _) if c == q => quote = None,
            (None, b'>') => return Some(k),
            _ => {}
        }
    }
    None
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// The member element (`<core:cityObjectMember>` …) around the object at `obj`: its start tag is
/// the last tag before the object, its end tag the first after it.
fn member_span(b: &[u8], obj: Range<usize>) -> Option<Range<usize>> {
    let start = b[..obj.start].iter().rposition(|&c| c == b'<')?;
    if matches!(b.get(start + 1), Some(b'/' | b'!' | b'?')) {
        return None;
    }
    let name: Vec<u8> =
        b[start + 1..].iter().take_while(|c| !c.is_ascii_whitespace() && **c != b'>').copied().collect();
    let close = [b"</".as_slice(), &name, b">"].concat();
    let rel = find(&b[obj.end..], &close)?;
    // only whitespace between the object and the member's end tag
    b[obj.end..obj.end + rel].iter().all(|c| c.is_ascii_whitespace()).then(|| start..obj.end + rel + close.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_and_member_spans() {
        let doc = b"<?xml version=\"1.0\"?>\n<!-- c -->\n<core:CityModel xmlns:gml=\"http://www.opengis.net/gml\" a='>'>\n  <core:cityObjectMember>\n    <bldg:Building gml:id=\"b\"/>\n  </core:cityObjectMember>\n</core:CityModel>";
        let (r, name) = root_start(doc).unwrap();
        assert_eq!(name, "core:CityModel");
        assert!(doc[..r.end].ends_with(b"a='>'>"));
        assert_eq!(gml_prefix(&doc[..r.end]).as_deref(), Some("gml"));
        let s = find(doc, b"<bldg:Building").unwrap();
        let e = find(doc, b"/>\n  </core").unwrap() + 2;
        let m = member_span(doc, s..e).unwrap();
        assert_eq!(
            &doc[m],
            b"<core:cityObjectMember>\n    <bldg:Building gml:id=\"b\"/>\n  </core:cityObjectMember>".as_slice()
        );
    }
}
