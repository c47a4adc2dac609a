//! Object-by-object reading with bounded memory: [`ObjectStream`] yields one top-level city
//! object at a time (with its nested parts, surfaces and openings), so a tile of any size is
//! processed building by building. XLinks inside an object are resolved from the object itself;
//! the first XLink that points into another object triggers one extra pass that indexes every
//! id'd surface of the document (id → byte span + owner semantics), after which such targets
//! are re-parsed from their bytes (see `ogc-xlink/4_Cross-Top-Level-XLink`).

use std::sync::Arc;

use crate::error::ReadError;
use crate::lines::LineIndex;
use crate::model::*;
use crate::reader::{
    build_index, finish_envelopes, resolve_object, Binding, Ev, FxMap, GlobalIds, IdEntry, Ns, Parser, Reparse,
};

const BOM: &[u8] = b"\xEF\xBB\xBF";

/// Streams the top-level city objects of a CityGML document held in memory (or memory-mapped:
/// only the current object is decoded, the bytes are never copied).
pub struct ObjectStream<'a> {
    p: Parser<'a>,
    src: &'a [u8],
    lines: Arc<LineIndex<'a>>,
    root_bindings: Vec<Binding>,
    body: std::ops::Range<usize>,
    version: CityGmlVersion,
    declared_envelope: Option<Envelope>,
    declared_srs: Option<String>,
    in_member: bool,
    done: bool,
    index: Option<FxMap<String, IdEntry>>,
    unresolved: Vec<XLinkRef>,
}

struct LazyIndex<'s, 'a> {
    index: &'s mut Option<FxMap<String, IdEntry>>,
    src: &'a [u8],
    lines: &'s Arc<LineIndex<'a>>,
    body: std::ops::Range<usize>,
}

impl GlobalIds for LazyIndex<'_, '_> {
    fn lookup(&mut self, id: &str) -> Result<Option<IdEntry>, ReadError> {
        if self.index.is_none() {
            *self.index = Some(build_index(self.src, self.lines, self.body.clone())?);
        }
        Ok(self.index.as_ref().and_then(|m| m.get(id).cloned()))
    }
}

impl<'a> ObjectStream<'a> {
    /// Checks that `src` is a CityGML document (root `core:CityModel` in a CityGML 1.0/2.0/3.0
    /// namespace) and positions the stream on its first object.
    pub fn new(src: &'a [u8]) -> Result<ObjectStream<'a>, ReadError> {
        let lines = Arc::new(LineIndex::new(src));
        if src.is_empty() {
            return Err(ReadError {
                line: 1,
                column: 1,
                byte: 0,
                message: "empty file (0 bytes), not a CityGML document".into(),
            });
        }
        let start = if src.starts_with(BOM) { BOM.len() } else { 0 };
        let body = start..src.len();
        let mut p = Parser::new(src, lines.clone(), body.clone(), Vec::new());
        let (root, empty_root) = loop {
            match p.next()? {
                Ev::Start(t) => break (t, false),
                Ev::Empty(t) => break (t, true),
                Ev::Text { nonblank, at, len } if p.nonblank(nonblank, at, len) => {
                    return Err(p.err(at, "not an XML document: text or binary data before the root element"))
                }
                Ev::Text { .. } => {}
                Ev::End { .. } => return Err(p.err(p.pos(), "malformed XML: end tag before any start tag")),
                Ev::Eof => return Err(p.err(p.pos(), "not an XML document: no root element")),
            }
        };
        let name = String::from_utf8_lossy(root.raw.name().as_ref()).into_owned();
        let version = match root.ns {
            Ns::CityGml(v, "core") if root.local() == b"CityModel" => v,
            _ if root.local() == b"CityModel" => {
                let uri = p.uri_of(&root);
                return Err(p.err(
                    root.start,
                    format!(
                        "root element <{name}> is in namespace '{uri}', not a CityGML core namespace \
                         (http://www.opengis.net/citygml/1.0, /2.0 or /3.0)"
                    ),
                ));
            }
            _ => {
                return Err(p.err(
                    root.start,
                    format!("not a CityGML document: root element is <{name}>, expected core:CityModel"),
                ))
            }
        };
        let declared_srs = root.attr_string(b"srsName");
        let root_bindings = p.bindings();
        Ok(ObjectStream {
            p,
            src,
            lines,
            root_bindings,
            body,
            version,
            declared_envelope: None,
            declared_srs,
            in_member: false,
            done: empty_root,
            index: None,
            unresolved: Vec::new(),
        })
    }

    /// CityGML version from the root element's namespace.
    pub fn version(&self) -> CityGmlVersion {
        self.version
    }

    /// The document's `gml:boundedBy` envelope, once the stream has passed it (it comes first).
    pub fn declared_envelope(&self) -> Option<Envelope> {
        self.declared_envelope
    }

    /// srsName of the document envelope, else the first srsName seen so far.
    pub fn srs_name(&self) -> Option<String> {
        self.declared_srs.clone().or_else(|| self.p.first_srs.clone())
    }

    /// Bytes of the document the stream has read so far: what lies before this offset is not
    /// needed again, except to re-parse the target of an XLink into an earlier object (and for
    /// the one-off id index such a link builds). A caller holding the document in a memory map
    /// can release the pages behind it (docs/decisions.md#streaming-citygml); it is also the
    /// natural measure of progress.
    pub fn consumed(&self) -> usize {
        self.p.pos()
    }

    /// XLinks met so far whose target is not in the document.
    pub fn unresolved_xlinks(&self) -> &[XLinkRef] {
        &self.unresolved
    }

    fn next_object(&mut self) -> Result<Option<CityObject>, ReadError> {
        loop {
            match self.p.next()? {
                Ev::Start(t) => {
                    if self.in_member {
                        self.p.local_ids.clear();
                        self.p.placeholders = 0;
                        let mut obj = self.p.parse_object(t)?;
                        if self.p.placeholders > 0 {
                            let reparse = Reparse { src: self.src, lines: &self.lines, bindings: &self.root_bindings };
                            let mut global = LazyIndex {
                                index: &mut self.index,
                                src: self.src,
                                lines: &self.lines,
                                body: self.body.clone(),
                            };
                            let un = resolve_object(&mut obj, &self.p.local_ids, &reparse, &mut global)?;
                            self.unresolved.extend(un);
                        }
                        finish_envelopes(&mut obj);
                        // The line index counts from its last lookup: moved to the object's end
                        // now, the next object's first lookup does not read back through bytes
                        // the caller may have released meanwhile (see `consumed`).
                        self.lines.line_col(self.p.pos());
                        return Ok(Some(obj));
                    }
                    let l = t.local();
                    if matches!(l, b"cityObjectMember" | b"featureMember" | b"featureMembers")
                        && matches!(t.ns, Ns::Gml | Ns::CityGml(..))
                    {
                        self.in_member = true;
                    } else if t.ns == Ns::Gml && l == b"boundedBy" {
                        let env = self.p.parse_bounded_by(&t)?;
                        if self.declared_envelope.is_none() {
                            self.declared_envelope = env;
                        }
                        if self.declared_srs.is_none() {
                            self.declared_srs = self.p.first_srs.clone();
                        }
                    } else {
                        self.p.skip(&t)?;
                    }
                }
                Ev::End { .. } => {
                    if self.in_member {
                        self.in_member = false;
                    } else {
                        // End of the root: only whitespace, comments and PIs may follow.
                        loop {
                            match self.p.next()? {
                                Ev::Eof => break,
                                Ev::Text { nonblank, at, len } => {
                                    if self.p.nonblank(nonblank, at, len) {
                                        return Err(self.p.err(at, "content after the root element"));
                                    }
                                }
                                Ev::Start(t) | Ev::Empty(t) => {
                                    return Err(self.p.err(t.start, "a second root element after </CityModel>"))
                                }
                                Ev::End { .. } => {}
                            }
                        }
                        return Ok(None);
                    }
                }
                Ev::Empty(_) | Ev::Text { .. } => {}
                Ev::Eof => {
                    return Err(self
                        .p
                        .err(self.p.pos(), "unexpected end of file: <CityModel> is not closed (truncated document?)"))
                }
            }
        }
    }
}

impl Iterator for ObjectStream<'_> {
    type Item = Result<CityObject, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.next_object() {
            Ok(Some(o)) => Some(Ok(o)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}

/// Reads a whole CityGML document (see the crate docs for what is understood).
pub fn parse(src: &[u8]) -> Result<CityModel, ReadError> {
    let mut stream = ObjectStream::new(src)?;
    let mut objects = Vec::new();
    for o in &mut stream {
        objects.push(o?);
    }
    let mut envelope = Envelope::empty();
    for o in &objects {
        envelope.merge(&o.envelope);
    }
    Ok(CityModel {
        version: stream.version(),
        srs_name: stream.srs_name(),
        declared_envelope: stream.declared_envelope(),
        envelope,
        objects,
        unresolved_xlinks: stream.unresolved,
    })
}
