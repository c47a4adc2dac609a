//! The document-wide id index XLinks outside their own object are resolved through.

use super::*;

/// A first pass over the whole document: every id'd surface element with its span and owner
/// semantics, and every other id'd element (so a reference to a city object can say what it
/// points to; where an id repeats, a geometry wins). Built only when an XLink points outside
/// its own top-level object.
pub(crate) fn build_index<'a>(
    src: &'a [u8],
    lines: &Arc<LineIndex<'a>>,
    range: Range<usize>,
) -> Result<FxMap<String, IdEntry>, ReadError> {
    let mut p = Parser::new(src, lines.clone(), range, Vec::new());
    let mut map = FxMap::default();
    // (start, id, whether a surface element, thematic semantic if thematic surface)
    let mut stack: Vec<(usize, Option<String>, bool, Option<Owner>)> = Vec::new();
    let other = |map: &mut FxMap<String, IdEntry>, id: String, bytes: Range<usize>| {
        map.entry(id).or_insert(IdEntry { bytes, semantic: None });
    };
    loop {
        match p.next()? {
            Ev::Start(t) => {
                let l = t.local();
                let geometry = t.ns == Ns::Gml && is_surface_like(l);
                let id = t.attr_string(b"id");
                let sem = match t.ns {
                    Ns::CityGml(..) => surface_type(l).map(|s| (s, id.clone())),
                    _ => None,
                };
                stack.push((t.start, id, geometry, sem));
            }
            Ev::Empty(t) => {
                // an empty geometry (`<gml:Polygon gml:id="q"/>`) brings nothing in: left out,
                // so a reference to it stays unresolved as before
                let geometry = t.ns == Ns::Gml && is_surface_like(t.local());
                if let (false, Some(id)) = (geometry, t.attr_string(b"id")) {
                    other(&mut map, id, t.start..p.pos());
                }
            }
            Ev::End { end } => match stack.pop() {
                Some((start, Some(id), true, _)) => {
                    let semantic = stack.iter().rev().find_map(|s| s.3.clone());
                    map.insert(id, IdEntry { bytes: start..end, semantic });
                }
                Some((start, Some(id), false, _)) => other(&mut map, id, start..end),
                _ => {}
            },
            Ev::Eof => break,
            _ => {}
        }
    }
    Ok(map)
}
