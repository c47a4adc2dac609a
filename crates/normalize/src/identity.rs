//! What a merge of coplanar polygons must not delete: a thematic surface (WallSurface,
//! ClosureSurface, ...) that has a gml:id or attributes of its own. Applications read exactly
//! these elements (energy and solar studies the surface types and their areas, other data sets
//! link to the ids), so a merge that empties such a surface is not made
//! (docs/decisions.md#merges-keep-semantics-and-identity).
//!
//! # Examples
//! ```
//! use normalize::identity::has_attributes;
//! let doc = br#"<bldg:WallSurface><core:creationDate>2020-01-01</core:creationDate><bldg:lod2MultiSurface/></bldg:WallSurface>"#;
//! assert!(has_attributes(doc, 0..doc.len()));
//! let bare = br#"<bldg:WallSurface><bldg:lod2MultiSurface><gml:MultiSurface/></bldg:lod2MultiSurface></bldg:WallSurface>"#;
//! assert!(!has_attributes(bare, 0..bare.len()));
//! ```

use citygml_io::CityObject;

/// Whether the thematic surface `s` of the document `src` must stay: it has a gml:id or
/// attributes.
pub fn must_stay(src: &[u8], s: &CityObject) -> bool {
    s.id.is_some() || has_attributes(src, s.span.bytes.clone())
}

/// Child properties of a thematic surface that are geometry or openings, not attributes: the
/// `lodN…` geometry properties, openings (CityGML 1.0/2.0 `opening`, 3.0 `fillingSurface`) and the
/// envelope (`gml:boundedBy`).
fn is_geometry_property(local: &[u8]) -> bool {
    local.starts_with(b"lod") || local == b"opening" || local == b"fillingSurface" || local == b"boundedBy"
}

/// Whether the element spanning `span` of `src` has a direct child element that is not geometry,
/// an opening or its envelope (`core:creationDate`, `gml:name`, `gen:stringAttribute`, an ADE
/// attribute such as `Flaeche`, ...).
pub fn has_attributes(src: &[u8], span: std::ops::Range<usize>) -> bool {
    let el = &src[span.start.min(src.len())..span.end.min(src.len())];
    let Some(open_end) = el.iter().position(|&c| c == b'>') else { return false };
    if open_end > 0 && el[open_end - 1] == b'/' {
        return false; // an empty element
    }
    let mut depth = 0usize;
    let mut i = open_end + 1;
    while let Some(off) = el[i..].iter().position(|&c| c == b'<') {
        let at = i + off;
        let rest = &el[at + 1..];
        let Some(close) = rest.iter().position(|&c| c == b'>') else { return false };
        let tag = &rest[..close];
        i = at + 1 + close + 1;
        match tag.first() {
            Some(b'!') | Some(b'?') => {
                // a comment or CDATA may hold '>': skip to its real end
                if tag.starts_with(b"!--") {
                    if let Some(e) = find(&el[at..], b"-->") {
                        i = at + e + 3;
                    }
                } else if tag.starts_with(b"![CDATA[") {
                    if let Some(e) = find(&el[at..], b"]]>") {
                        i = at + e + 3;
                    }
                }
            }
            Some(b'/') => {
                if depth == 0 {
                    return false; // the element's own end tag
                }
                depth -= 1;
            }
            _ => {
                let self_closing = tag.last() == Some(&b'/');
                if depth == 0 && !is_geometry_property(local_name(tag)) {
                    return true;
                }
                if !self_closing {
                    depth += 1;
                }
            }
        }
    }
    false
}

/// The local name of a start tag's text (`bldg:lod2MultiSurface attr="…"` → `lod2MultiSurface`).
fn local_name(tag: &[u8]) -> &[u8] {
    let name_end = tag.iter().position(|c| c.is_ascii_whitespace() || *c == b'/').unwrap_or(tag.len());
    let name = &tag[..name_end];
    match name.iter().rposition(|&c| c == b':') {
        Some(k) => &name[k + 1..],
        None => name,
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_openings_and_comments_are_not_attributes() {
        let doc = br#"<WallSurface gml:id="w"><!-- a <comment> --><gml:boundedBy><gml:Envelope/></gml:boundedBy><bldg:lod2MultiSurface><gml:MultiSurface><gml:name>x</gml:name></gml:MultiSurface></bldg:lod2MultiSurface><bldg:opening><bldg:Window/></bldg:opening></WallSurface>"#;
        assert!(!has_attributes(doc, 0..doc.len()));
    }

    #[test]
    fn a_name_or_an_ade_value_is_an_attribute() {
        let doc = br#"<con:WallSurface><con:fillingSurface/><gml:name>Nordwand</gml:name></con:WallSurface>"#;
        assert!(has_attributes(doc, 0..doc.len()));
        let ade = br#"<WallSurface><lod3MultiSurface/><x:Flaeche uom="m2">547</x:Flaeche></WallSurface>"#;
        assert!(has_attributes(ade, 0..ade.len()));
    }
}
