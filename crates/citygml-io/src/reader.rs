//! The CityGML event parser: one pass of quick-xml's slice reader over the bytes, recursive
//! descent per city object, geometry decoded where it stands.
//!
//! Namespaces are resolved here (not by quick-xml's `NsReader`) so that any element can be
//! re-parsed later from its own byte span with the document's root bindings: that is how
//! XLinks are resolved without keeping the whole document model in memory.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::Arc;

use quick_xml::events::{BytesStart, Event};
use quick_xml::name::PrefixDeclaration;
use quick_xml::Reader;

use input_limits::quote;
use crate::error::ReadError;
use crate::lines::LineIndex;
use crate::model::*;

/// What namespace an element is in, as far as the reader cares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ns {
    Gml,
    /// A CityGML namespace: version and module short name (`core`, `bldg`, `con`, ...).
    CityGml(CityGmlVersion, &'static str),
    Xal,
    Other,
}

pub(crate) fn classify_ns(uri: &[u8]) -> Ns {
    match uri {
        b"http://www.opengis.net/gml" | b"http://www.opengis.net/gml/3.2" => return Ns::Gml,
        b"urn:oasis:names:tc:ciq:xsdschema:xAL:2.0" => return Ns::Xal,
        _ => {}
    }
    let Some(rest) = uri.strip_prefix(b"http://www.opengis.net/citygml/") else {
        return Ns::Other;
    };
    let (module, ver) = match memchr::memrchr(b'/', rest) {
        Some(i) => (&rest[..i], &rest[i + 1..]),
        None => (&b""[..], rest),
    };
    let version = match ver {
        b"1.0" => CityGmlVersion::V1_0,
        b"2.0" => CityGmlVersion::V2_0,
        b"3.0" => CityGmlVersion::V3_0,
        _ => return Ns::Other,
    };
    let m = match module {
        b"" => "core",
        b"building" => "bldg",
        b"relief" => "dem",
        b"generics" => "gen",
        b"cityobjectgroup" => "grp",
        b"landuse" => "luse",
        b"transportation" => "tran",
        b"vegetation" => "veg",
        b"waterbody" => "wtr",
        b"cityfurniture" => "frn",
        b"bridge" => "brid",
        b"tunnel" => "tun",
        b"appearance" => "app",
        b"texturedsurface" => "tex",
        b"construction" => "con",
        b"versioning" => "vers",
        b"dynamizer" => "dyn",
        b"pointcloud" => "pcl",
        _ => "other",
    };
    Ns::CityGml(version, m)
}

/// A namespace prefix binding in scope (`depth` = element depth that declared it).
#[derive(Debug, Clone)]
pub(crate) struct Binding {
    prefix: Vec<u8>,
    uri: Vec<u8>,
    ns: Ns,
    depth: usize,
}

/// A start tag with its resolved namespace and byte offset of its `<`.
pub(crate) struct Tag<'a> {
    pub raw: BytesStart<'a>,
    pub start: usize,
    pub ns: Ns,
}

impl Tag<'_> {
    pub fn local(&self) -> &[u8] {
        self.raw.local_name().into_inner()
    }
    pub fn local_str(&self) -> String {
        String::from_utf8_lossy(self.local()).into_owned()
    }
    pub fn attr(&self, local: &[u8]) -> Option<Cow<'_, [u8]>> {
        attr_raw(&self.raw, local)
    }
    pub fn attr_string(&self, local: &[u8]) -> Option<String> {
        if self.raw.attributes_raw().is_empty() {
            return None;
        }
        self.attr(local).map(|v| match String::from_utf8(v.into_owned()) {
            Ok(s) => s,
            Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
        })
    }
    fn is_gml(&self, local: &[u8]) -> bool {
        self.ns == Ns::Gml && self.local() == local
    }
}

fn attr_raw<'t>(e: &'t BytesStart<'_>, local: &[u8]) -> Option<Cow<'t, [u8]>> {
    match find_attr(e.attributes_raw(), local) {
        AttrScan::Found(v) => Some(Cow::Borrowed(v)),
        AttrScan::Absent => None,
        // A malformed attribute before the one asked for: quick-xml's iterator (what the reader
        // used before the fast scan) skips it and goes on, so an xlink:href after `foo` or
        // `a=b` is still found.
        AttrScan::Malformed => e.attributes().with_checks(false).flatten().find(|a| a.key.local_name().as_ref() == local).map(|a| a.value),
    }
}

/// Result of [`find_attr`].
#[derive(Debug, PartialEq, Eq)]
enum AttrScan<'t> {
    Found(&'t [u8]),
    Absent,
    /// The scan met an attribute without `=` or without a quoted value before finding `local`.
    Malformed,
}

/// The raw value of the attribute whose local name is `local` (any prefix), scanning the raw
/// attribute bytes of a start tag directly (no attribute iterator, no allocation). Well-formed
/// tags (all real CityGML) are answered here; on malformed attribute syntax it says so and the
/// caller falls back to quick-xml's lenient iterator.
fn find_attr<'t>(raw: &'t [u8], local: &[u8]) -> AttrScan<'t> {
    let n = raw.len();
    let mut i = 0usize;
    loop {
        while i < n && raw[i].is_ascii_whitespace() {
            i += 1;
        }
        if i >= n {
            return AttrScan::Absent;
        }
        let ks = i;
        while i < n && raw[i] != b'=' && !raw[i].is_ascii_whitespace() {
            i += 1;
        }
        let key = &raw[ks..i];
        while i < n && raw[i].is_ascii_whitespace() {
            i += 1;
        }
        if i >= n || raw[i] != b'=' {
            return AttrScan::Malformed;
        }
        i += 1;
        while i < n && raw[i].is_ascii_whitespace() {
            i += 1;
        }
        let q = match raw.get(i) {
            Some(&q) if q == b'"' || q == b'\'' => q,
            _ => return AttrScan::Malformed,
        };
        let vs = i + 1;
        let Some(len) = memchr::memchr(q, &raw[vs..]) else { return AttrScan::Malformed };
        let ve = vs + len;
        i = ve + 1;
        let lname = match memchr::memchr(b':', key) {
            Some(c) => &key[c + 1..],
            None => key,
        };
        if lname == local {
            return AttrScan::Found(&raw[vs..ve]);
        }
    }
}

/// Maps keyed by short gml:ids from the document itself, where SipHash's DoS resistance buys
/// nothing and costs a visible share of the parse: rustc's FxHash (`rustc-hash`).
pub(crate) type FxMap<K, V> = rustc_hash::FxHashMap<K, V>;

pub(crate) enum Ev<'a> {
    Start(Tag<'a>),
    Empty(Tag<'a>),
    End { end: usize },
    /// Character data at `at`, `len` bytes; `nonblank` is `Some(true)` for CDATA and entity
    /// references, `None` for plain text (see [`Parser::is_blank`]).
    Text { nonblank: Option<bool>, at: usize, len: usize },
    Eof,
}

/// The thematic surface (type, gml:id) that owns a polygon.
pub(crate) type Owner = (SurfaceType, Option<String>);

/// Where an id'd surface element is defined, with the semantics of the thematic surface that
/// owns it (so a polygon reached by XLink gets the type of its owner, not of the referrer).
#[derive(Debug, Clone)]
pub(crate) struct IdEntry {
    pub bytes: Range<usize>,
    pub semantic: Option<(SurfaceType, Option<String>)>,
}

/// Element names that open a (surface or solid) geometry.
fn is_geometry(local: &[u8]) -> bool {
    matches!(
        local,
        b"Polygon"
            | b"MultiSurface"
            | b"CompositeSurface"
            | b"OrientableSurface"
            | b"Surface"
            | b"TriangulatedSurface"
            | b"Tin"
            | b"Shell"
            | b"Solid"
            | b"CompositeSolid"
            | b"MultiSolid"
            | b"MultiGeometry"
            | b"GeometricComplex"
    )
}

fn is_polygon_like(local: &[u8]) -> bool {
    matches!(local, b"Polygon" | b"PolygonPatch" | b"Triangle" | b"Rectangle")
}

/// Elements that hold surfaces: the geometries plus the polygon-like patches inside them.
fn is_surface_like(local: &[u8]) -> bool {
    is_geometry(local) || is_polygon_like(local)
}

/// City objects that nest inside other city objects (parts, rooms, installations, boundary
/// surfaces, openings, relief components, ...). Any other CityGML element inside an object is
/// looked through for geometry (properties, ADE wrappers).
fn is_nested_object(local: &[u8]) -> bool {
    if surface_type(local).is_some() {
        return true;
    }
    matches!(
        local,
        b"Building"
            | b"BuildingPart"
            | b"Room"
            | b"BuildingRoom"
            | b"BuildingInstallation"
            | b"IntBuildingInstallation"
            | b"BuildingFurniture"
            | b"BuildingConstructiveElement"
            | b"BuildingUnit"
            | b"Storey"
            | b"BridgePart"
            | b"BridgeRoom"
            | b"BridgeInstallation"
            | b"IntBridgeInstallation"
            | b"BridgeConstructionElement"
            | b"BridgeConstructiveElement"
            | b"BridgeFurniture"
            | b"TunnelPart"
            | b"HollowSpace"
            | b"TunnelInstallation"
            | b"IntTunnelInstallation"
            | b"TunnelConstructiveElement"
            | b"TunnelFurniture"
            | b"TINRelief"
            | b"MassPointRelief"
            | b"BreaklineRelief"
            | b"RasterRelief"
            | b"TrafficArea"
            | b"AuxiliaryTrafficArea"
            | b"TrafficSpace"
            | b"AuxiliaryTrafficSpace"
            | b"Section"
            | b"Intersection"
            | b"Marking"
            | b"HoleSurface"
            | b"WaterSurface"
            | b"WaterGroundSurface"
            | b"WaterClosureSurface"
    )
}

/// `SurfaceType::from_local_name` on bytes (no UTF-8 check: the names are ASCII).
fn surface_type(local: &[u8]) -> Option<SurfaceType> {
    if !local.ends_with(b"Surface") && local != b"Window" && local != b"Door" {
        return None;
    }
    std::str::from_utf8(local).ok().and_then(SurfaceType::from_local_name)
}

/// CityGML elements whose content is never the object's own geometry.
fn is_skipped(local: &[u8]) -> bool {
    matches!(
        local,
        b"Address" | b"ImplicitGeometry" | b"ExternalReference" | b"address" | b"externalReference"
    )
}

/// `lod2Solid` → 2.
fn lod_of(local: &[u8]) -> Option<u8> {
    if local.len() > 3 && local.starts_with(b"lod") && local[3].is_ascii_digit() {
        Some(local[3] - b'0')
    } else {
        None
    }
}

/// The LoD of a geometry property name (`lod2Solid`, `lod1MultiSurface`, `lod0FootPrint`, ...),
/// None for other `lodN…` properties (`lod2TerrainIntersection` curves, ...).
fn by_reference_lod(l: &[u8]) -> Option<u8> {
    // called for every element: the cheap lodN test first, the name search only on a hit
    lod_of(l).filter(|_| [&b"Solid"[..], b"Surface", b"Geometry", b"FootPrint", b"RoofEdge"].iter().any(|k| memchr::memmem::find(l, k).is_some()))
}

/// Qualified name (as written, prefix included) of the element whose `<` is at `start`.
fn qname_at(src: &[u8], start: usize) -> &[u8] {
    let s = &src[start + 1..];
    let end = s.iter().position(|b| b.is_ascii_whitespace() || *b == b'>' || *b == b'/').unwrap_or(s.len());
    &s[..end]
}

/// Local name of the element whose `<` is at `start`.
fn name_at(src: &[u8], start: usize) -> &[u8] {
    let q = qname_at(src, start);
    match memchr::memchr(b':', q) {
        Some(i) => &q[i + 1..],
        None => q,
    }
}

/// Deeper nesting is refused: the parser is recursive (a 2 MiB thread stack holds well over
/// 256 levels) and real CityGML stays below ~40 (object → part → surface → opening → geometry).
const MAX_DEPTH: usize = 256;

/// The parser: a quick-xml slice reader over `src[range]` plus our own namespace scope.
pub(crate) struct Parser<'a> {
    r: Reader<&'a [u8]>,
    pub src: &'a [u8],
    base: usize,
    pub lines: Arc<LineIndex<'a>>,
    bindings: Vec<Binding>,
    depth: usize,
    /// The thematic surface (type, gml:id) the parser is inside, given to its polygons.
    cur_sem: Option<(SurfaceType, Option<String>)>,
    /// srsDimension declared on the enclosing geometry element, if any.
    dim_hint: Option<u8>,
    /// First srsName seen (the document CRS when the root has no boundedBy).
    pub first_srs: Option<String>,
    /// Id'd aggregate surfaces (CompositeSurface, OrientableSurface, ...) of the current object.
    pub local_ids: FxMap<String, IdEntry>,
    /// Number of XLink placeholders created in the current object.
    pub placeholders: usize,
    /// End of the parsed range, and the offset of the next `xmlns` in it at or after the
    /// current tag (usize::MAX: none left): namespace declarations are looked for only in tags
    /// that contain one, not in every tag's attributes.
    limit: usize,
    next_xmlns: usize,
    /// Reused buffer for a posList's points: the ring gets an exact-size copy (a capacity
    /// guessed from the text length would leave ~30 % slack in every ring of a big model).
    scratch: Vec<Point3>,
    /// The namespaces of the last few prefixes looked up ([`prefix_key`] → Ns), emptied when a
    /// binding is declared or goes out of scope. A document root declares a dozen or more
    /// prefixes, most of the same length (`gml`, `app`, `dem`, ...): searching the bindings
    /// byte by byte for every tag was the largest part of [`Parser::next`].
    ns_cache: [(u64, Ns); 4],
    ns_cache_next: usize,
    /// Reused buffer the polygons of a geometry or shell are collected in; the geometry gets
    /// an exact-size copy. A Polygon is ~340 bytes: growing each geometry's own Vec by doubling
    /// and shrinking it to fit moved every polygon two or three times and made large
    /// allocations that keep glibc consolidating its free lists.
    polys: Vec<Polygon>,
}

const NS_CACHE_EMPTY: [(u64, Ns); 4] = [(u64::MAX, Ns::Other); 4];

/// A prefix of up to 7 bytes as one integer (length in the top byte), None if longer.
#[inline]
fn prefix_key(p: &[u8]) -> Option<u64> {
    if p.len() > 7 {
        return None;
    }
    let mut k = (p.len() as u64) << 56;
    for (i, &b) in p.iter().enumerate() {
        k |= (b as u64) << (8 * i);
    }
    Some(k)
}

/// How far ahead of the reader the next namespace declaration is looked for (see
/// `Parser::xmlns_bound`): one search per MiB of declaration-free document.
const XMLNS_LOOKAHEAD: usize = 1 << 20;

static XMLNS: std::sync::LazyLock<memchr::memmem::Finder<'static>> =
    std::sync::LazyLock::new(|| memchr::memmem::Finder::new(b"xmlns"));

/// What [`Parser::parse_linear_ring`] has read of a ring's coordinates so far.
struct RingCoords {
    points: Vec<Point3>,
    /// The encoding seen first; `None` until a coordinate element is read.
    encoding: Option<CoordEncoding>,
    dim: u8,
    text_span: SourceSpan,
    pos_spans: Vec<SourceSpan>,
}

impl<'a> Parser<'a> {
    pub fn new(src: &'a [u8], lines: Arc<LineIndex<'a>>, range: Range<usize>, bindings: Vec<Binding>) -> Parser<'a> {
        let mut r = Reader::from_reader(&src[range.clone()]);
        let c = r.config_mut();
        c.trim_text(false);
        c.check_end_names = true;
        c.expand_empty_elements = false;
        c.check_comments = false;
        Parser {
            r,
            src,
            base: range.start,
            lines,
            bindings,
            depth: 0,
            cur_sem: None,
            dim_hint: None,
            first_srs: None,
            local_ids: FxMap::default(),
            placeholders: 0,
            limit: range.end,
            next_xmlns: 0,
            scratch: Vec::new(),
            ns_cache: NS_CACHE_EMPTY,
            ns_cache_next: 0,
            polys: Vec::new(),
        }
    }

    /// The bindings in scope, as the outermost scope of a parser over a sub-range.
    pub fn bindings(&self) -> Vec<Binding> {
        self.bindings.iter().map(|b| Binding { depth: 0, ..b.clone() }).collect()
    }

    pub fn pos(&self) -> usize {
        self.base + self.r.buffer_position() as usize
    }

    #[cold]
    pub fn err(&self, at: usize, message: impl Into<String>) -> ReadError {
        let (line, column) = self.lines.line_col(at);
        ReadError { line, column, byte: at, message: message.into() }
    }

    fn span(&self, start: usize, end: usize) -> SourceSpan {
        self.lines.span(start, end)
    }

    #[cold]
    fn xml_err(&self, e: quick_xml::Error) -> ReadError {
        use quick_xml::errors::{IllFormedError, SyntaxError};
        let at = self.base + self.r.error_position() as usize;
        let msg = match &e {
            quick_xml::Error::IllFormed(IllFormedError::MissingEndTag(n)) => {
                format!("unexpected end of file: <{}> is not closed (truncated document?)", quote(n))
            }
            quick_xml::Error::IllFormed(IllFormedError::MismatchedEndTag { expected, found }) => {
                format!("malformed XML: end tag </{}> does not match the open <{}>", quote(found), quote(expected))
            }
            quick_xml::Error::Syntax(SyntaxError::UnclosedTag) => {
                "unexpected end of file inside a tag: `>` missing (truncated document?)".to_string()
            }
            quick_xml::Error::Syntax(
                SyntaxError::UnclosedComment
                | SyntaxError::UnclosedCData
                | SyntaxError::UnclosedDoctype
                | SyntaxError::UnclosedPIOrXmlDecl,
            ) => format!("unexpected end of file: {} (truncated document?)", quote(&e.to_string())),
            _ => format!("malformed XML: {}", quote(&e.to_string())),
        };
        self.err(at, msg)
    }

    #[cold]
    fn unclosed(&self, what: &[u8], start: usize) -> ReadError {
        let (l, c) = self.lines.line_col(start);
        self.err(
            self.pos(),
            format!(
                "unexpected end of file: <{}> opened at {l}:{c} is not closed (truncated document?)",
                String::from_utf8_lossy(what)
            ),
        )
    }

    fn declare(&mut self, e: &BytesStart<'_>, depth: usize, start: usize) {
        let end = self.pos();
        if self.next_xmlns < start {
            self.next_xmlns = self.xmlns_bound(start);
        }
        if self.next_xmlns >= end {
            return;
        }
        self.next_xmlns = self.xmlns_bound(end);
        let raw = e.attributes_raw();
        if !memchr::memchr_iter(b'x', raw).any(|i| raw[i..].starts_with(b"xmlns")) {
            return;
        }
        for a in e.attributes().with_checks(false).flatten() {
            if let Some(decl) = a.key.as_namespace_binding() {
                let prefix = match decl {
                    PrefixDeclaration::Default => Vec::new(),
                    PrefixDeclaration::Named(p) => p.to_vec(),
                };
                self.bindings.push(Binding { prefix, ns: classify_ns(&a.value), uri: a.value.to_vec(), depth });
                self.ns_cache = NS_CACHE_EMPTY;
            }
        }
    }

    /// A lower bound of the next `xmlns` at or after `from`: its offset when there is one within
    /// [`XMLNS_LOOKAHEAD`] bytes, else the offset up to which there is none. Bounded, so that a
    /// document without further declarations is not scanned to its end ahead of the reader
    /// (that would touch every page of a memory-mapped tile: docs/decisions.md#streaming-citygml).
    fn xmlns_bound(&self, from: usize) -> usize {
        let window_end = from.saturating_add(XMLNS_LOOKAHEAD).min(self.limit);
        match XMLNS.find(&self.src[from..window_end]) {
            Some(i) => from + i,
            None if window_end == self.limit => usize::MAX,
            // an `xmlns` may straddle the window's end
            None => window_end - (b"xmlns".len() - 1),
        }
    }

    fn binding_of(&self, qname: &[u8]) -> Option<&Binding> {
        let prefix = match qname.iter().position(|&c| c == b':') {
            Some(i) => &qname[..i],
            None => &b""[..],
        };
        // Prefixes are a few bytes: compare length and bytes inline, no memcmp call.
        self.bindings
            .iter()
            .rev()
            .find(|b| b.prefix.len() == prefix.len() && b.prefix.iter().zip(prefix).all(|(x, y)| x == y))
    }

    /// Namespace URI of a tag (for messages).
    pub fn uri_of(&self, t: &Tag<'_>) -> String {
        self.binding_of(t.raw.name().as_ref())
            .map(|b| String::from_utf8_lossy(&b.uri).into_owned())
            .unwrap_or_default()
    }

    fn resolve(&mut self, qname: &[u8]) -> Ns {
        let prefix = match memchr::memchr(b':', qname) {
            Some(i) => &qname[..i],
            None => &b""[..],
        };
        let Some(k) = prefix_key(prefix) else {
            return self.binding_of(qname).map(|b| b.ns).unwrap_or(Ns::Other);
        };
        for &(ck, ns) in &self.ns_cache {
            if ck == k {
                return ns;
            }
        }
        let ns = self.binding_of(qname).map(|b| b.ns).unwrap_or(Ns::Other);
        self.ns_cache[self.ns_cache_next] = (k, ns);
        self.ns_cache_next = (self.ns_cache_next + 1) % self.ns_cache.len();
        ns
    }

    fn pop_bindings(&mut self) {
        while self.bindings.last().is_some_and(|b| b.depth > self.depth) {
            self.bindings.pop();
            self.ns_cache = NS_CACHE_EMPTY;
        }
    }

    /// Inlined into its dozen callers: the event comes back in registers, not through a
    /// ~120-byte Result in memory read right after the call (that store/load round trip was
    /// the hottest spot of parse_object in perf); the error paths stay out of line (#[cold]).
    #[inline(always)]
    pub fn next(&mut self) -> Result<Ev<'a>, ReadError> {
        loop {
            let start = self.pos();
            let ev = self.r.read_event().map_err(|e| self.xml_err(e))?;
            match ev {
                Event::Start(e) => {
                    self.depth += 1;
                    if self.depth > MAX_DEPTH {
                        return Err(self.err(start, format!("elements nested deeper than {MAX_DEPTH} levels")));
                    }
                    self.declare(&e, self.depth, start);
                    let ns = self.resolve(e.name().as_ref());
                    return Ok(Ev::Start(Tag { raw: e, start, ns }));
                }
                Event::Empty(e) => {
                    self.declare(&e, self.depth + 1, start);
                    let ns = self.resolve(e.name().as_ref());
                    self.pop_bindings();
                    return Ok(Ev::Empty(Tag { raw: e, start, ns }));
                }
                Event::End(_) => {
                    self.depth = self.depth.saturating_sub(1);
                    self.pop_bindings();
                    return Ok(Ev::End { end: self.pos() });
                }
                Event::Text(t) => {
                    // Whether the text is blank is asked only outside objects (stream.rs): it is
                    // not computed for every indentation run inside them.
                    return Ok(Ev::Text { nonblank: None, at: start, len: t.len() });
                }
                Event::CData(_) | Event::GeneralRef(_) => {
                    return Ok(Ev::Text { nonblank: Some(true), at: start, len: 0 })
                }
                Event::Eof => return Ok(Ev::Eof),
                Event::Decl(_) | Event::PI(_) | Event::Comment(_) | Event::DocType(_) => continue,
            }
        }
    }

    /// Whether a text event (see [`Ev::Text`]) has anything but whitespace.
    pub fn nonblank(&self, nonblank: Option<bool>, at: usize, len: usize) -> bool {
        nonblank.unwrap_or_else(|| self.src[at..at + len].iter().any(|b| !b.is_ascii_whitespace()))
    }

    /// Skips the content of a started element; returns the offset after its end tag.
    pub fn skip(&mut self, t: &Tag<'_>) -> Result<usize, ReadError> {
        self.content(t).map(|_| self.pos())
    }

    /// The content range without leading/trailing whitespace (coordinate texts: an edit then
    /// keeps the document's indentation).
    fn trimmed(&self, r: Range<usize>) -> Range<usize> {
        let s = &self.src[r.clone()];
        let a = s.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(s.len());
        let b = s.iter().rposition(|b| !b.is_ascii_whitespace()).map(|i| i + 1).unwrap_or(a);
        r.start + a..r.start + b.max(a)
    }

    /// Reads to the end of a started element; returns the byte range of its content.
    fn content(&mut self, t: &Tag<'_>) -> Result<Range<usize>, ReadError> {
        let span = self.r.read_to_end(t.raw.name()).map_err(|e| match e {
            quick_xml::Error::IllFormed(quick_xml::errors::IllFormedError::MissingEndTag(_)) => {
                self.unclosed(t.raw.name().as_ref(), t.start)
            }
            e => self.xml_err(e),
        })?;
        self.depth = self.depth.saturating_sub(1);
        self.pop_bindings();
        Ok(self.base + span.start as usize..self.base + span.end as usize)
    }

    // ---------------------------------------------------------------------------------------
    // City objects

    /// Parses a city object whose start tag was just read, up to its end tag. XLinks are left
    /// as placeholders; [`resolve_object`] replaces them.
    pub fn parse_object(&mut self, tag: Tag<'a>) -> Result<CityObject, ReadError> {
        let kind = tag.local_str();
        let module = match tag.ns {
            Ns::CityGml(_, m) => Some(m.to_string()),
            _ => None,
        };
        let id = tag.attr_string(b"id");
        let saved_sem = self.cur_sem.take();
        if let Some(t) = SurfaceType::from_local_name(&kind) {
            self.cur_sem = Some((t, id.clone()));
        }
        let mut obj = CityObject {
            id,
            kind,
            module,
            geometries: Vec::new(),
            children: Vec::new(),
            envelope: Envelope::empty(),
            span: SourceSpan::default(),
        };
        // Elements open inside the object (properties, wrappers): start offset and LoD of name.
        let mut stack: Vec<(usize, Option<u8>)> = Vec::new();
        loop {
            match self.next()? {
                Ev::Start(t) => {
                    let l = t.local();
                    match t.ns {
                        Ns::Gml => {
                            if stack.is_empty() && l == b"boundedBy" {
                                if let Some(env) = self.parse_bounded_by(&t)? {
                                    obj.envelope = env;
                                }
                            } else if is_geometry(l) && !stack.is_empty() {
                                let (prop, _) = *stack.last().unwrap();
                                let lod = stack.iter().rev().find_map(|s| s.1);
                                let g = self.parse_geometry(t, prop, lod)?;
                                obj.geometries.push(g);
                            } else {
                                self.skip(&t)?;
                            }
                        }
                        Ns::CityGml(_, m) => {
                            if m == "app" || is_skipped(l) {
                                self.skip(&t)?;
                            } else if !stack.is_empty() && is_nested_object(l) {
                                let child = self.parse_object(t)?;
                                obj.children.push(child);
                            } else if by_reference_lod(l).is_some() && t.attr(b"href").is_some() {
                                // the same reference written with an end tag
                                // (`<bldg:lod2Solid xlink:href="#s"></bldg:lod2Solid>`)
                                let end = self.skip(&t)?;
                                if let Some(g) = self.geometry_by_reference(&t, end) {
                                    obj.geometries.push(g);
                                }
                            } else {
                                stack.push((t.start, lod_of(l)));
                            }
                        }
                        Ns::Xal => {
                            self.skip(&t)?;
                        }
                        Ns::Other => {
                            // ADE wrappers and properties: look through them for geometry.
                            stack.push((t.start, lod_of(l)));
                        }
                    }
                }
                Ev::Empty(t) => {
                    // `<bldg:lod2Solid xlink:href="#solid"/>`: a whole geometry by reference.
                    let end = self.pos();
                    if let Some(g) = self.geometry_by_reference(&t, end) {
                        obj.geometries.push(g);
                    }
                }
                Ev::End { end } => {
                    if stack.pop().is_none() {
                        obj.span = self.span(tag.start, end);
                        break;
                    }
                }
                Ev::Text { .. } => {}
                Ev::Eof => return Err(self.unclosed(tag.raw.name().as_ref(), tag.start)),
            }
        }
        self.cur_sem = saved_sem;
        Ok(obj)
    }

    /// A `lodN…` geometry property that is only an `xlink:href` (ending at `end`): a
    /// placeholder geometry resolved with the other XLinks (a solid property (`lodNSolid`)
    /// becomes the solid it points to, resolved with the solidMember references; anything
    /// else the geometry it points to), or None for other properties.
    fn geometry_by_reference(&mut self, t: &Tag<'_>, end: usize) -> Option<Geometry> {
        let l = t.local();
        let lod = by_reference_lod(l)?;
        let href = t.attr_string(b"href")?;
        let kind = if memchr::memmem::find(l, b"Solid").is_some() {
            GeometryKind::Solids(vec![self.solid_placeholder(href, t.start, end)])
        } else {
            GeometryKind::Surfaces(vec![self.placeholder(href, t.start, end, false)])
        };
        Some(Geometry {
            id: None,
            lod: Some(lod),
            property: t.local_str(),
            gml_type: "xlink".to_string(),
            srs_name: None,
            kind,
            span: self.span(t.start, end),
            skipped_members: Vec::new(),
        })
    }

    /// `gml:boundedBy/gml:Envelope` → envelope (None when absent or not finite, e.g. the NaN
    /// heights of empty NRW tiles).
    pub fn parse_bounded_by(&mut self, t: &Tag<'_>) -> Result<Option<Envelope>, ReadError> {
        let mut corners: Vec<Vec<f64>> = Vec::new();
        let mut ok = true;
        let mut depth = 0usize;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let l = c.local();
                    if c.ns == Ns::Gml && l == b"Envelope" {
                        depth += 1;
                        if let Some(s) = c.attr_string(b"srsName") {
                            if self.first_srs.is_none() {
                                self.first_srs = Some(s);
                            }
                        }
                    } else if c.ns == Ns::Gml && matches!(l, b"lowerCorner" | b"upperCorner" | b"pos") {
                        let r = self.content(&c)?;
                        let mut v = Vec::new();
                        for (at, tok) in tokens(&self.src[r.clone()], r.start) {
                            match parse_f64(tok) {
                                Some(x) if x.is_finite() => v.push(x),
                                Some(_) => ok = false,
                                None => {
                                    return Err(self.err(
                                        at,
                                        format!("gml:{}: '{}' is not a number", String::from_utf8_lossy(l), lossy(tok)),
                                    ))
                                }
                            }
                        }
                        corners.push(v);
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { .. } => {
                    if depth == 0 {
                        break;
                    }
                    depth -= 1;
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                _ => {}
            }
        }
        if !ok || corners.len() != 2 || corners.iter().any(|c| c.len() < 2 || c.len() > 3) {
            return Ok(None);
        }
        let p = |c: &Vec<f64>| [c[0], c[1], if c.len() == 3 { c[2] } else { 0.0 }];
        let mut env = Envelope::empty();
        env.add_point(&p(&corners[0]));
        env.add_point(&p(&corners[1]));
        Ok(Some(env))
    }

    // ---------------------------------------------------------------------------------------
    // Geometry

    fn parse_geometry(&mut self, t: Tag<'a>, prop_start: usize, lod: Option<u8>) -> Result<Geometry, ReadError> {
        let id = t.attr_string(b"id");
        let srs_name = t.attr_string(b"srsName");
        if self.first_srs.is_none() {
            self.first_srs = srs_name.clone();
        }
        let saved_dim = self.dim_hint;
        if let Some(d) = t.attr(b"srsDimension").and_then(|v| parse_dim(&v)) {
            self.dim_hint = Some(d);
        }
        let gml_type = t.local_str();
        let property = String::from_utf8_lossy(name_at(self.src, prop_start)).into_owned();
        let start = t.start;
        let mut skipped_members = Vec::new();
        let kind = match t.local() {
            b"Solid" => {
                let (e, i) = self.parse_solid(&t)?;
                GeometryKind::Solid { exterior: e, interior: i }
            }
            b"CompositeSolid" | b"MultiSolid" => {
                let mut solids = Vec::new();
                self.parse_solid_members(&t, &mut solids, &mut skipped_members)?;
                GeometryKind::Solids(solids)
            }
            _ => {
                let mut buf = std::mem::take(&mut self.polys);
                let mark = buf.len();
                self.collect_element(t, false, Some(prop_start), &mut buf)?;
                let v = buf.drain(mark..).collect(); // exact size
                self.polys = buf;
                GeometryKind::Surfaces(v)
            }
        };
        self.dim_hint = saved_dim;
        let end = self.pos();
        Ok(Geometry { id, lod, property, gml_type, srs_name, kind, span: self.span(start, end), skipped_members })
    }

    /// The members of a `gml:CompositeSolid` / `gml:MultiSolid` whose start tag was just read:
    /// each `gml:Solid` as parsed, each `solidMember xlink:href` as a placeholder solid (see
    /// [`Parser::solid_placeholder`]; [`resolve_object`] replaces it by a copy of its target),
    /// the solids of a nested CompositeSolid / MultiSolid as members of their own; anything
    /// else goes to `skipped` (never dropped silently).
    fn parse_solid_members(
        &mut self,
        t: &Tag<'a>,
        solids: &mut Vec<(Shell, Vec<Shell>)>,
        skipped: &mut Vec<SkippedMember>,
    ) -> Result<(), ReadError> {
        let id = t.attr_string(b"id");
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if !(c.ns == Ns::Gml && matches!(c.local(), b"solidMember" | b"solidMembers")) {
                        self.skip(&c)?;
                        continue;
                    }
                    if let Some(href) = c.attr_string(b"href") {
                        self.skip(&c)?;
                        let ph = self.solid_placeholder(href, c.start, self.pos());
                        solids.push(ph);
                        continue;
                    }
                    let before = solids.len() + skipped.len();
                    loop {
                        match self.next()? {
                            Ev::Start(s) if s.is_gml(b"Solid") => {
                                let solid = self.parse_solid(&s)?;
                                solids.push(solid);
                            }
                            Ev::Start(s) if s.ns == Ns::Gml && matches!(s.local(), b"CompositeSolid" | b"MultiSolid") => {
                                self.parse_solid_members(&s, solids, skipped)?;
                            }
                            Ev::Start(s) => {
                                let end = self.skip(&s)?;
                                skipped.push(self.not_a_solid(&s, end));
                            }
                            Ev::Empty(s) if s.is_gml(b"Solid") => {
                                let shell = Shell { id: None, polygons: Vec::new(), via_xlink: None };
                                solids.push((shell, Vec::new()));
                            }
                            Ev::Empty(s) => {
                                let end = self.pos();
                                skipped.push(self.not_a_solid(&s, end));
                            }
                            Ev::End { end } => {
                                if solids.len() + skipped.len() == before {
                                    skipped.push(SkippedMember {
                                        href: None,
                                        reason: format!("gml:{} holds no solid", c.local_str()),
                                        span: self.span(c.start, end),
                                    });
                                }
                                break;
                            }
                            Ev::Eof => return Err(self.unclosed(c.raw.name().as_ref(), c.start)),
                            Ev::Text { .. } => {}
                        }
                    }
                }
                Ev::Empty(c) => {
                    if c.ns == Ns::Gml && matches!(c.local(), b"solidMember" | b"solidMembers") {
                        let end = self.pos();
                        if let Some(href) = c.attr_string(b"href") {
                            let ph = self.solid_placeholder(href, c.start, end);
                            solids.push(ph);
                        } else {
                            skipped.push(SkippedMember {
                                href: None,
                                reason: format!("empty gml:{} (no solid, no xlink:href)", c.local_str()),
                                span: self.span(c.start, end),
                            });
                        }
                    }
                }
                Ev::End { end } => {
                    if let Some(id) = id {
                        self.local_ids.insert(id, IdEntry { bytes: t.start..end, semantic: self.cur_sem.clone() });
                    }
                    return Ok(());
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                Ev::Text { .. } => {}
            }
        }
    }

    fn not_a_solid(&self, s: &Tag<'_>, end: usize) -> SkippedMember {
        SkippedMember {
            href: None,
            reason: format!("<{}> is not a solid (not read)", String::from_utf8_lossy(s.raw.name().as_ref())),
            span: self.span(s.start, end),
        }
    }

    /// A solid that stands for a `solidMember xlink:href`: an exterior shell holding one
    /// placeholder polygon marked by `srs_dimension == 0` (see [`is_solid_placeholder`]).
    fn solid_placeholder(&mut self, href: String, start: usize, end: usize) -> (Shell, Vec<Shell>) {
        let mut ph = self.placeholder(href, start, end, false);
        ph.exterior.srs_dimension = 0;
        (Shell { id: None, polygons: vec![ph], via_xlink: None }, Vec::new())
    }

    /// A `gml:Solid` whose start tag was just read → (exterior shell, interior shells).
    fn parse_solid(&mut self, t: &Tag<'a>) -> Result<(Shell, Vec<Shell>), ReadError> {
        let id = t.attr_string(b"id");
        let mut exterior = Shell { id: None, polygons: Vec::new(), via_xlink: None };
        let mut interior = Vec::new();
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let is_ext = c.is_gml(b"exterior");
                    if is_ext || c.is_gml(b"interior") {
                        let mut buf = std::mem::take(&mut self.polys);
                        let mark = buf.len();
                        let id = self.collect_prop(c, false, &mut buf)?;
                        let shell = Shell { id, polygons: buf.drain(mark..).collect(), via_xlink: None };
                        self.polys = buf;
                        if is_ext {
                            exterior = shell;
                        } else {
                            interior.push(shell);
                        }
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::Empty(c) => {
                    if let Some(href) = c.attr_string(b"href") {
                        let ph = self.placeholder(href, c.start, self.pos(), false);
                        let shell = Shell { id: None, polygons: vec![ph], via_xlink: None };
                        if c.is_gml(b"exterior") {
                            exterior = shell;
                        } else {
                            interior.push(shell);
                        }
                    }
                }
                Ev::End { end } => {
                    // A solid can be a CompositeSolid member by reference (`solidMember xlink:href`).
                    if let Some(id) = id {
                        self.local_ids.insert(id, IdEntry { bytes: t.start..end, semantic: self.cur_sem.clone() });
                    }
                    break;
                }
                Ev::Text { .. } => {}
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
            }
        }
        Ok((exterior, interior))
    }

    /// Reads a geometry property element (`surfaceMember`, `baseSurface`, `exterior`, ...)
    /// whose start tag was just read; its surfaces go to `out`. Returns the gml:id of the
    /// first geometry inside (a Shell's id).
    fn collect_prop(&mut self, p: Tag<'a>, reversed: bool, out: &mut Vec<Polygon>) -> Result<Option<String>, ReadError> {
        if let Some(href) = p.attr_string(b"href") {
            self.skip(&p)?;
            let ph = self.placeholder(href, p.start, self.pos(), reversed);
            out.push(ph);
            return Ok(None);
        }
        let mut first_id = None;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if c.ns == Ns::Gml && is_surface_like(c.local()) {
                        if first_id.is_none() {
                            first_id = c.attr_string(b"id");
                        }
                        self.collect_element(c, reversed, Some(p.start), out)?;
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { .. } => return Ok(first_id),
                Ev::Eof => return Err(self.unclosed(p.raw.name().as_ref(), p.start)),
                _ => {}
            }
        }
    }

    /// A surface element whose start tag was just read: a polygon, or an aggregate whose
    /// members are collected (an `OrientableSurface` with `orientation="-"` flips them).
    fn collect_element(
        &mut self,
        t: Tag<'a>,
        reversed: bool,
        member_start: Option<usize>,
        out: &mut Vec<Polygon>,
    ) -> Result<(), ReadError> {
        if is_polygon_like(t.local()) {
            let p = self.parse_polygon(t, reversed, member_start)?;
            out.push(p);
            return Ok(());
        }
        let rev = if t.local() == b"OrientableSurface" && t.attr(b"orientation").as_deref() == Some(b"-") {
            !reversed
        } else {
            reversed
        };
        let id = t.attr_string(b"id");
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if c.ns == Ns::Gml {
                        self.collect_prop(c, rev, out)?;
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::Empty(c) => {
                    if let Some(href) = c.attr_string(b"href") {
                        let ph = self.placeholder(href, c.start, self.pos(), rev);
                        out.push(ph);
                    }
                }
                Ev::End { end } => {
                    if let Some(id) = id {
                        self.local_ids.insert(id, IdEntry { bytes: t.start..end, semantic: self.cur_sem.clone() });
                    }
                    return Ok(());
                }
                Ev::Text { .. } => {}
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
            }
        }
    }

    fn placeholder(&mut self, href: String, start: usize, end: usize, reversed: bool) -> Polygon {
        self.placeholders += 1;
        Polygon {
            id: Some(href),
            exterior: empty_ring(),
            interiors: Vec::new(),
            semantic: None,
            semantic_owner: None,
            reversed,
            span: SourceSpan::default(),
            member_span: None,
            via_xlink: Some(self.span(start, end)),
        }
    }

    /// Span of the property element that encloses a polygon: from the property's start tag
    /// to the end tag that directly follows the polygon (None when something else follows).
    fn member_span(&self, member_start: usize, poly_end: usize) -> Option<SourceSpan> {
        let mut i = poly_end;
        while i < self.src.len() && self.src[i].is_ascii_whitespace() {
            i += 1;
        }
        if self.src.get(i..i + 2) != Some(b"</") {
            return None;
        }
        let close = memchr::memchr(b'>', &self.src[i..])?;
        Some(self.span(member_start, i + close + 1))
    }

    fn parse_polygon(&mut self, t: Tag<'a>, reversed: bool, member_start: Option<usize>) -> Result<Polygon, ReadError> {
        let id = t.attr_string(b"id");
        let mut exterior = None;
        let mut interiors = Vec::new();
        let end;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let l = c.local();
                    if c.ns == Ns::Gml && matches!(l, b"exterior" | b"outerBoundaryIs") {
                        exterior = self.parse_ring_prop(c)?;
                    } else if c.ns == Ns::Gml && matches!(l, b"interior" | b"innerBoundaryIs") {
                        if let Some(r) = self.parse_ring_prop(c)? {
                            interiors.push(r);
                        }
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { end: e } => {
                    end = e;
                    break;
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                _ => {}
            }
        }
        let Some(exterior) = exterior else {
            return Err(self.err(
                t.start,
                format!(
                    "gml:{} {}has no exterior gml:LinearRing (missing coordinates)",
                    t.local_str(),
                    id.as_ref().map(|i| format!("'{}' ", quote(i))).unwrap_or_default()
                ),
            ));
        };
        let (semantic, semantic_owner) = match &self.cur_sem {
            Some((s, o)) => (Some(*s), o.clone()),
            None => (None, None),
        };
        Ok(Polygon {
            id,
            exterior,
            interiors,
            semantic,
            semantic_owner,
            reversed,
            span: self.span(t.start, end),
            member_span: member_start.and_then(|m| self.member_span(m, end)),
            via_xlink: None,
        })
    }

    /// `gml:exterior`/`gml:interior` of a polygon → its LinearRing.
    fn parse_ring_prop(&mut self, p: Tag<'a>) -> Result<Option<Ring>, ReadError> {
        let mut ring = None;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if c.is_gml(b"LinearRing") {
                        ring = Some(self.parse_linear_ring(c)?);
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { .. } => return Ok(ring),
                Ev::Eof => return Err(self.unclosed(p.raw.name().as_ref(), p.start)),
                _ => {}
            }
        }
    }

    /// A `gml:LinearRing` in any of GML's three coordinate encodings (never mixed); the text
    /// spans are kept so the coordinates can be rewritten in place.
    fn parse_linear_ring(&mut self, t: Tag<'a>) -> Result<Ring, ReadError> {
        let id = t.attr_string(b"id");
        let mut acc = RingCoords { points: Vec::new(), encoding: None, dim: 3, text_span: SourceSpan::default(), pos_spans: Vec::new() };
        let end;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let l = c.local();
                    if c.ns != Ns::Gml {
                        self.skip(&c)?;
                        continue;
                    }
                    match l {
                        b"posList" => self.ring_pos_list(&c, &mut acc)?,
                        b"pos" => self.ring_pos(&c, &mut acc)?,
                        b"coordinates" => self.ring_coordinates(&c, &mut acc)?,
                        _ => {
                            self.skip(&c)?;
                        }
                    }
                }
                Ev::Empty(c) => {
                    if c.ns == Ns::Gml && matches!(c.local(), b"posList" | b"pos" | b"coordinates") {
                        return Err(self.err(
                            c.start,
                            format!("empty gml:{} (missing coordinates)", c.local_str()),
                        ));
                    }
                }
                Ev::End { end: e } => {
                    end = e;
                    break;
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                Ev::Text { .. } => {}
            }
        }
        let RingCoords { points, encoding, dim, text_span, pos_spans } = acc;
        let Some(encoding) = encoding else {
            return Err(self.err(
                t.start,
                "gml:LinearRing has no coordinates (no gml:posList, gml:pos or gml:coordinates)",
            ));
        };
        Ok(Ring { id, points, srs_dimension: dim, encoding, text_span, pos_spans, span: self.span(t.start, end) })
    }

    /// A ring's `gml:posList`: all its points at once, in the declared (or inherited) dimension.
    fn ring_pos_list(&mut self, c: &Tag<'a>, acc: &mut RingCoords) -> Result<(), ReadError> {
        if acc.encoding.is_some() {
            return Err(self.err(c.start, "gml:LinearRing mixes coordinate encodings"));
        }
        let d = c.attr(b"srsDimension").and_then(|v| parse_dim(&v)).or(self.dim_hint).unwrap_or(3);
        let r = self.content(c)?;
        let (pts, nvals) = self.pos_list(r.clone(), d)?;
        if nvals == 0 {
            return Err(self.err(c.start, "empty gml:posList (missing coordinates)"));
        }
        if nvals % d as usize != 0 {
            return Err(self.err(
                c.start,
                format!("gml:posList has {nvals} values, not a multiple of srsDimension {d}"),
            ));
        }
        acc.points = pts;
        acc.dim = d;
        let tr = self.trimmed(r);
        acc.text_span = self.span(tr.start, tr.end);
        acc.encoding = Some(CoordEncoding::PosList);
        Ok(())
    }

    /// One `gml:pos` of a ring: one point, in the dimension of the ring's first; the text span
    /// grows to cover first..last `gml:pos`.
    fn ring_pos(&mut self, c: &Tag<'a>, acc: &mut RingCoords) -> Result<(), ReadError> {
        if acc.encoding.is_some_and(|e| e != CoordEncoding::Pos) {
            return Err(self.err(c.start, "gml:LinearRing mixes coordinate encodings"));
        }
        let d_attr = c.attr(b"srsDimension").and_then(|v| parse_dim(&v));
        let r = self.content(c)?;
        let vals = self.numbers(r.clone(), "gml:pos")?;
        let d = d_attr.unwrap_or(vals.len() as u8);
        if !(vals.len() == 2 || vals.len() == 3) || vals.len() != d as usize {
            return Err(self.err(
                c.start,
                format!("gml:pos has {} values, expected 2 or 3 (one position)", vals.len()),
            ));
        }
        let tr = self.trimmed(r);
        if acc.encoding.is_none() {
            acc.dim = d;
            acc.text_span = self.span(tr.start, tr.end);
        } else if d != acc.dim {
            return Err(self.err(c.start, format!("gml:pos has {d} values, the ring's first has {}", acc.dim)));
        }
        acc.text_span.bytes.end = tr.end;
        acc.points.push(to_point(&vals));
        acc.pos_spans.push(self.span(tr.start, tr.end));
        acc.encoding = Some(CoordEncoding::Pos);
        Ok(())
    }

    /// A ring's `gml:coordinates` (GML 2 style, with its own separators): all its points at once.
    fn ring_coordinates(&mut self, c: &Tag<'a>, acc: &mut RingCoords) -> Result<(), ReadError> {
        if acc.encoding.is_some() {
            return Err(self.err(c.start, "gml:LinearRing mixes coordinate encodings"));
        }
        let cs = c.attr(b"cs").map(|v| v.into_owned()).unwrap_or_else(|| b",".to_vec());
        let dec = c.attr(b"decimal").map(|v| v.into_owned()).unwrap_or_else(|| b".".to_vec());
        let r = self.content(c)?;
        let (pts, d) = self.coordinates(r.clone(), &cs, &dec)?;
        if pts.is_empty() {
            return Err(self.err(c.start, "empty gml:coordinates (missing coordinates)"));
        }
        acc.points = pts;
        acc.dim = d;
        let tr = self.trimmed(r);
        acc.text_span = self.span(tr.start, tr.end);
        acc.encoding = Some(CoordEncoding::Coordinates);
        Ok(())
    }

    /// A posList straight into points (no intermediate Vec<f64>, no token slices: each number
    /// is parsed in place from the buffer): returns the complete positions and the number of
    /// values read (a count that is not a multiple of `d` is the caller's error to report).
    fn pos_list(&mut self, r: Range<usize>, d: u8) -> Result<(Vec<Point3>, usize), ReadError> {
        let mut pts = std::mem::take(&mut self.scratch);
        pts.clear();
        let mut cur = [0.0f64; 3];
        let (mut k, mut n) = (0usize, 0usize);
        let d = d as usize;
        let read = self.each_number(r, "gml:posList", |x| {
            cur[k] = x;
            k += 1;
            n += 1;
            if k == d {
                if d == 2 {
                    cur[2] = 0.0;
                }
                pts.push(cur);
                k = 0;
            }
        });
        let out = read.map(|()| (pts.as_slice().to_vec(), n));
        self.scratch = pts;
        out
    }

    fn number_err(&self, at: usize, bad: NumErr<'_>, what: &str) -> ReadError {
        match bad {
            NumErr::NonFinite(tok) => self.err(at, format!("{what}: non-finite coordinate '{}'", lossy(tok))),
            NumErr::NotANumber(tok) if tok.contains(&b'<') => {
                self.err(at, format!("{what}: unexpected markup inside the coordinate text"))
            }
            NumErr::NotANumber(tok) => self.err(at, format!("{what}: '{}' is not a number", lossy(tok))),
        }
    }

    /// Whitespace-separated numbers of `src[r]`; a bad token is an error at its own position.
    fn numbers(&self, r: Range<usize>, what: &str) -> Result<Vec<f64>, ReadError> {
        let mut v = Vec::with_capacity(3);
        self.each_number(r, what, |x| v.push(x))?;
        Ok(v)
    }

    /// Calls `f` with each whitespace-separated number of `src[r]` in order, parsed in place
    /// from the buffer; a bad token is an error at its own position (`what` names the element).
    #[inline]
    fn each_number(&self, r: Range<usize>, what: &str, mut f: impl FnMut(f64)) -> Result<(), ReadError> {
        let s = &self.src[r.clone()];
        let mut i = 0usize;
        loop {
            while i < s.len() && is_ws(s[i]) {
                i += 1;
            }
            if i >= s.len() {
                return Ok(());
            }
            match number_at(s, i) {
                Ok((x, len)) => {
                    f(x);
                    i += len;
                }
                Err(bad) => return Err(self.number_err(r.start + i, bad, what)),
            }
        }
    }

    /// `gml:coordinates`: tuples separated by whitespace, values by `cs`.
    fn coordinates(&self, r: Range<usize>, cs: &[u8], dec: &[u8]) -> Result<(Vec<Point3>, u8), ReadError> {
        let mut pts = Vec::new();
        let mut dim = 0u8;
        for (at, tuple) in tokens(&self.src[r.clone()], r.start) {
            let mut vals = Vec::with_capacity(3);
            let sep = cs.first().copied().unwrap_or(b',');
            for part in tuple.split(|b| *b == sep) {
                let owned;
                let part = if dec != b"." && dec.len() == 1 {
                    owned = part.iter().map(|b| if *b == dec[0] { b'.' } else { *b }).collect::<Vec<u8>>();
                    &owned[..]
                } else {
                    part
                };
                match parse_f64(part) {
                    Some(x) if x.is_finite() => vals.push(x),
                    _ => {
                        return Err(self.err(at, format!("gml:coordinates: '{}' is not a coordinate tuple", lossy(tuple))))
                    }
                }
            }
            if !(vals.len() == 2 || vals.len() == 3) {
                return Err(self.err(at, format!("gml:coordinates: tuple '{}' has {} values", lossy(tuple), vals.len())));
            }
            if dim == 0 {
                dim = vals.len() as u8;
            } else if dim as usize != vals.len() {
                return Err(self.err(at, "gml:coordinates: tuples of different dimension"));
            }
            pts.push(to_point(&vals));
        }
        Ok((pts, dim))
    }
}

fn empty_ring() -> Ring {
    Ring {
        id: None,
        points: Vec::new(),
        srs_dimension: 3,
        encoding: CoordEncoding::PosList,
        text_span: SourceSpan::default(),
        pos_spans: Vec::new(),
        span: SourceSpan::default(),
    }
}

fn to_point(v: &[f64]) -> Point3 {
    [v[0], v[1], if v.len() > 2 { v[2] } else { 0.0 }]
}

fn parse_dim(v: &[u8]) -> Option<u8> {
    match v {
        b"2" => Some(2),
        b"3" => Some(3),
        _ => None,
    }
}

fn lossy(b: &[u8]) -> String {
    let s = String::from_utf8_lossy(b);
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.into_owned()
    }
}

/// XML whitespace (what separates the values of a coordinate list).
#[inline]
fn is_ws(b: u8) -> bool {
    matches!(b, b' ' | b'\n' | b'\t' | b'\r' | b'\x0c')
}

pub(crate) enum NumErr<'s> {
    NotANumber(&'s [u8]),
    NonFinite(&'s [u8]),
}

/// The finite number that starts at `s[i]` (not whitespace) and runs to the next whitespace or
/// the end, and its length in bytes. Parsed in place by Eisel–Lemire (`fast-float2`: correctly
/// rounded, the same value as `str::parse::<f64>`); no token slice is scanned twice.
#[inline]
fn number_at(s: &[u8], i: usize) -> Result<(f64, usize), NumErr<'_>> {
    let rest = &s[i..];
    if let Ok((x, len)) = fast_float2::parse_partial::<f64, _>(rest) {
        if len > 0 && (len == rest.len() || is_ws(rest[len])) {
            if x.is_finite() {
                return Ok((x, len));
            }
            return Err(NumErr::NonFinite(&rest[..len]));
        }
    }
    let end = rest.iter().position(|b| is_ws(*b)).unwrap_or(rest.len());
    Err(NumErr::NotANumber(&rest[..end]))
}

/// Decimal text → f64 (correctly rounded, like `str::parse::<f64>`, without the UTF-8 check).
pub(crate) fn parse_f64(tok: &[u8]) -> Option<f64> {
    match fast_float2::parse_partial::<f64, _>(tok) {
        Ok((x, len)) if len == tok.len() && len > 0 => Some(x),
        _ => None,
    }
}

/// Whitespace-separated tokens with their absolute byte offsets.
fn tokens(s: &[u8], base: usize) -> impl Iterator<Item = (usize, &[u8])> {
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < s.len() && s[i].is_ascii_whitespace() {
            i += 1;
        }
        if i >= s.len() {
            return None;
        }
        let st = i;
        while i < s.len() && !s[i].is_ascii_whitespace() {
            i += 1;
        }
        Some((base + st, &s[st..i]))
    })
}

/// Placeholders are polygons reached by `xlink:href` that are not yet filled in.
fn is_placeholder(p: &Polygon) -> bool {
    p.via_xlink.is_some() && p.span.bytes.end == 0
}

/// A solid standing for a `solidMember xlink:href` (see [`Parser::solid_placeholder`]).
fn is_solid_placeholder(s: &(Shell, Vec<Shell>)) -> bool {
    s.1.is_empty() && s.0.polygons.len() == 1 && is_placeholder(&s.0.polygons[0]) && s.0.polygons[0].exterior.srs_dimension == 0
}

type Solid = (Shell, Vec<Shell>);

/// What one solid XLink stands for: its solids and the members left out.
type ResolvedSolids = (Vec<Solid>, Vec<SkippedMember>);

fn visit_geoms<'o>(obj: &'o CityObject, f: &mut dyn FnMut(&'o Geometry)) {
    for g in &obj.geometries {
        f(g);
    }
    for c in &obj.children {
        visit_geoms(c, f);
    }
}

fn visit_geoms_mut(obj: &mut CityObject, f: &mut dyn FnMut(&mut Geometry)) {
    for g in &mut obj.geometries {
        f(g);
    }
    for c in &mut obj.children {
        visit_geoms_mut(c, f);
    }
}

/// The one placeholder of a whole surface-type geometry given by reference
/// (`<bldg:lod2MultiSurface xlink:href="#ms"/>`), before it is resolved.
fn whole_surface_ref(g: &Geometry) -> Option<&Polygon> {
    match &g.kind {
        GeometryKind::Surfaces(v) if g.gml_type == "xlink" && v.len() == 1 && is_placeholder(&v[0]) => Some(&v[0]),
        _ => None,
    }
}

fn solid_placeholders_in(g: &Geometry) -> bool {
    matches!(&g.kind, GeometryKind::Solids(v) if v.iter().any(is_solid_placeholder))
}

fn href_id(href: &str) -> Option<&str> {
    match href.strip_prefix('#') {
        Some(id) => Some(id),
        None if !href.contains('#') && !href.contains('/') => Some(href),
        None => None,
    }
}

fn visit_polys<'o>(obj: &'o CityObject, f: &mut dyn FnMut(&'o Polygon)) {
    for g in &obj.geometries {
        for p in g.polygons() {
            f(p);
        }
    }
    for c in &obj.children {
        visit_polys(c, f);
    }
}

fn visit_vecs_mut(obj: &mut CityObject, f: &mut dyn FnMut(&mut Vec<Polygon>)) {
    for g in &mut obj.geometries {
        match &mut g.kind {
            GeometryKind::Surfaces(v) => f(v),
            GeometryKind::Solid { exterior, interior } => {
                f(&mut exterior.polygons);
                for s in interior {
                    f(&mut s.polygons);
                }
            }
            GeometryKind::Solids(v) => {
                for (e, i) in v {
                    f(&mut e.polygons);
                    for s in i {
                        f(&mut s.polygons);
                    }
                }
            }
        }
    }
    for c in &mut obj.children {
        visit_vecs_mut(c, f);
    }
}

/// Where XLink targets outside the current object are looked up (the stream's lazy index).
pub(crate) trait GlobalIds {
    fn lookup(&mut self, id: &str) -> Result<Option<IdEntry>, ReadError>;
}

/// The element `id` names: the current object's own id'd aggregates first, then the document's
/// index (built on first use).
fn find_id(local_ids: &FxMap<String, IdEntry>, global: &mut dyn GlobalIds, id: &str) -> Result<Option<IdEntry>, ReadError> {
    match local_ids.get(id) {
        Some(e) => Ok(Some(e.clone())),
        None => global.lookup(id),
    }
}

/// Context to re-parse an id'd element from its own bytes.
pub(crate) struct Reparse<'s, 'a> {
    pub src: &'a [u8],
    pub lines: &'s Arc<LineIndex<'a>>,
    pub bindings: &'s [Binding],
}

impl Reparse<'_, '_> {
    /// The solids of the element at `e` (a Solid, or the members of a CompositeSolid /
    /// MultiSolid) with the members it skips; `Err(name)` when the element is not a solid.
    #[allow(clippy::type_complexity)]
    fn solids(&self, e: &IdEntry) -> Result<Result<(Vec<Solid>, Vec<SkippedMember>), String>, ReadError> {
        let mut p = Parser::new(self.src, self.lines.clone(), e.bytes.clone(), self.bindings.to_vec());
        p.cur_sem = e.semantic.clone();
        loop {
            match p.next()? {
                Ev::Start(t) => {
                    if let Some(d) = t.attr(b"srsDimension").and_then(|v| parse_dim(&v)) {
                        p.dim_hint = Some(d);
                    }
                    let (mut solids, mut skipped) = (Vec::new(), Vec::new());
                    if t.is_gml(b"Solid") {
                        solids.push(p.parse_solid(&t)?);
                    } else if t.ns == Ns::Gml && matches!(t.local(), b"CompositeSolid" | b"MultiSolid") {
                        p.parse_solid_members(&t, &mut solids, &mut skipped)?;
                    } else {
                        return Ok(Err(String::from_utf8_lossy(t.raw.name().as_ref()).into_owned()));
                    }
                    return Ok(Ok((solids, skipped)));
                }
                Ev::Empty(t) => {
                    if t.is_gml(b"Solid") {
                        return Ok(Ok((vec![(Shell { id: None, polygons: Vec::new(), via_xlink: None }, Vec::new())], Vec::new())));
                    }
                    return Ok(Err(String::from_utf8_lossy(t.raw.name().as_ref()).into_owned()));
                }
                Ev::Eof => return Ok(Err("nothing".to_string())),
                _ => {}
            }
        }
    }

    fn surfaces(&self, e: &IdEntry) -> Result<Vec<Polygon>, ReadError> {
        let mut p = Parser::new(self.src, self.lines.clone(), e.bytes.clone(), self.bindings.to_vec());
        p.cur_sem = e.semantic.clone();
        let mut out = Vec::new();
        loop {
            match p.next()? {
                Ev::Start(t) => {
                    if t.ns == Ns::Gml && is_surface_like(t.local()) {
                        p.collect_element(t, false, None, &mut out)?;
                    } else {
                        p.skip(&t)?;
                    }
                    break;
                }
                Ev::Eof => break,
                _ => {}
            }
        }
        Ok(out)
    }
}

/// Replaces the XLink placeholders of one top-level object by copies of their targets:
/// polygons defined in the object itself, id'd aggregates of the object (re-parsed from their
/// bytes), then anything else in the document through `global`. Unresolvable ones are removed
/// and returned.
pub(crate) fn resolve_object(
    obj: &mut CityObject,
    local_ids: &FxMap<String, IdEntry>,
    reparse: &Reparse<'_, '_>,
    global: &mut dyn GlobalIds,
) -> Result<Vec<XLinkRef>, ReadError> {
    let mut unresolved = Vec::new();
    let mut lk = Lookups { local_ids, reparse, global };
    resolve_whole_surface_refs(obj, &mut lk)?;
    resolve_solid_refs(obj, &mut lk, &mut unresolved)?;
    resolve_polygon_refs(obj, &mut lk, &mut unresolved)?;
    // Each reference says where it sits (the innermost object holding it) and, when its id
    // names an element that is not a geometry (a city object, an appearance...), what that is.
    for u in &mut unresolved {
        if let Some(o) = innermost_at(obj, u.span.bytes.start) {
            u.feature = o.id.clone();
            u.feature_type = o.kind.clone();
        }
        if let Some(id) = href_id(&u.href) {
            u.target = find_id(lk.local_ids, lk.global, id)?.map(|e| String::from_utf8_lossy(qname_at(lk.reparse.src, e.bytes.start)).into_owned());
        }
    }
    Ok(unresolved)
}

/// The lookups an object's XLinks are resolved through: the object's own ids, the document
/// bytes targets are re-parsed from, and the ids of the rest of the document.
struct Lookups<'l, 's, 'a> {
    local_ids: &'l FxMap<String, IdEntry>,
    reparse: &'l Reparse<'s, 'a>,
    global: &'l mut dyn GlobalIds,
}

/// Phase -1: a whole surface-type geometry property by reference (`<bldg:lod2MultiSurface
/// xlink:href="#ms"/>`, read as one polygon placeholder) becomes what its target is: a solid
/// placeholder for a Solid/CompositeSolid/MultiSolid (resolved by [`resolve_solid_refs`] with the
/// solidMember references), the surfaces of a surface geometry (named after it), and for anything
/// else a skipped member instead of the polygons it happens to contain. A target that does not
/// exist stays a placeholder: the polygon phase reports it as an unresolved XLink.
fn resolve_whole_surface_refs(
    obj: &mut CityObject,
    lk: &mut Lookups<'_, '_, '_>,
) -> Result<(), ReadError> {
    let whole = whole_surface_targets(obj, lk)?;
    if whole.is_empty() {
        return Ok(());
    }
    let mut it = whole.into_iter();
    visit_geoms_mut(obj, &mut |g| {
        if whole_surface_ref(g).is_none() {
            return;
        }
        let Some(Some((name, qname))) = it.next() else { return };
        let GeometryKind::Surfaces(v) = &mut g.kind else { return };
        if matches!(name.as_str(), "Solid" | "CompositeSolid" | "MultiSolid") {
            let Some(mut ph) = v.pop() else { return };
            ph.exterior.srs_dimension = 0;
            g.kind = GeometryKind::Solids(vec![(Shell { id: None, polygons: vec![ph], via_xlink: None }, Vec::new())]);
        } else if is_surface_like(name.as_bytes()) {
            g.gml_type = name;
        } else {
            let Some(ph) = v.pop() else { return };
            let href = ph.id.unwrap_or_default();
            g.skipped_members.push(SkippedMember {
                reason: format!("xlink:href=\"{}\" points to <{}>, not a geometry", quote(&href), quote(&qname)),
                href: Some(href),
                span: ph.via_xlink.unwrap_or_default(),
            });
        }
    });
    Ok(())
}

/// Per whole surface-type property by reference, in visiting order: (local name, qualified name
/// for messages) of its target, `None` when there is none.
fn whole_surface_targets(
    obj: &CityObject,
    lk: &mut Lookups<'_, '_, '_>,
) -> Result<Vec<Option<(String, String)>>, ReadError> {
    let (local_ids, reparse, global) = (lk.local_ids, lk.reparse, &mut *lk.global);
    let mut by_id: rustc_hash::FxHashSet<&str> = Default::default();
    visit_polys(obj, &mut |p| {
        if let (false, Some(id)) = (is_placeholder(p), &p.id) {
            by_id.insert(id.as_str());
        }
    });
    let mut hrefs: Vec<&str> = Vec::new();
    visit_geoms(obj, &mut |g| {
        if let Some(ph) = whole_surface_ref(g) {
            hrefs.push(ph.id.as_deref().unwrap_or(""));
        }
    });
    let mut whole = Vec::new();
    for href in hrefs {
        let name = match href_id(href) {
            Some(id) if by_id.contains(id) => Some(("Polygon".to_string(), "gml:Polygon".to_string())),
            Some(id) => find_id(local_ids, global, id)?.map(|e| {
                let at = e.bytes.start;
                (String::from_utf8_lossy(name_at(reparse.src, at)).into_owned(), String::from_utf8_lossy(qname_at(reparse.src, at)).into_owned())
            }),
            None => None,
        };
        whole.push(name);
    }
    Ok(whole)
}

/// Phase 0: `solidMember xlink:href`s become copies of the solids they point to (their own
/// polygon XLinks resolved), or skipped members that say why not.
fn resolve_solid_refs(
    obj: &mut CityObject,
    lk: &mut Lookups<'_, '_, '_>,
    unresolved: &mut Vec<XLinkRef>,
) -> Result<(), ReadError> {
    let mut has_solid_refs = false;
    visit_geoms(obj, &mut |g| has_solid_refs |= solid_placeholders_in(g));
    if !has_solid_refs {
        return Ok(());
    }
    let resolved = solid_ref_targets(obj, lk, unresolved)?;
    let mut it = resolved.into_iter();
    visit_geoms_mut(obj, &mut |g| {
        if !solid_placeholders_in(g) {
            return;
        }
        let GeometryKind::Solids(v) = &mut g.kind else { return };
        let old = std::mem::take(v);
        let mut target = None;
        for s in old {
            if is_solid_placeholder(&s) {
                if let Some(((solids, skipped), name)) = it.next() {
                    v.extend(solids);
                    g.skipped_members.extend(skipped);
                    target = target.or(name);
                }
            } else {
                v.push(s);
            }
        }
        g.skipped_members.sort_by_key(|m| m.span.bytes.start);
        if g.gml_type == "xlink" {
            // `<bldg:lod2Solid xlink:href="#s"/>`: the geometry is what it points to
            if let Some(name) = target.filter(|_| !v.is_empty()) {
                g.gml_type = name;
            }
            if g.gml_type == "Solid" && v.len() == 1 && g.skipped_members.is_empty() {
                if let Some((exterior, interior)) = v.pop() {
                    g.kind = GeometryKind::Solid { exterior, interior };
                }
            }
        }
    });
    Ok(())
}

/// Per solid placeholder, in visiting order: its solids and skipped members, and the element
/// name of its target (a whole `lodNSolid xlink:href` geometry takes the target's type).
fn solid_ref_targets(
    obj: &CityObject,
    lk: &mut Lookups<'_, '_, '_>,
    unresolved: &mut Vec<XLinkRef>,
) -> Result<Vec<(ResolvedSolids, Option<String>)>, ReadError> {
    let (local_ids, reparse, global) = (lk.local_ids, lk.reparse, &mut *lk.global);
    let mut by_id: FxMap<&str, &Polygon> = FxMap::default();
    visit_polys(obj, &mut |p| {
        if let (false, Some(id)) = (is_placeholder(p), &p.id) {
            by_id.insert(id.as_str(), p);
        }
    });
    let mut phs: Vec<&Polygon> = Vec::new();
    visit_geoms(obj, &mut |g| {
        if let GeometryKind::Solids(v) = &g.kind {
            phs.extend(v.iter().filter(|s| is_solid_placeholder(s)).map(|s| &s.0.polygons[0]));
        }
    });
    let ctx = SolidCtx { by_id: &by_id, local_ids, reparse };
    let mut resolved = Vec::new();
    for ph in phs {
        let via = ph.via_xlink.clone().unwrap_or_default();
        let mut out = (Vec::new(), Vec::new());
        let href = ph.id.as_deref().unwrap_or("");
        ctx.resolve_solid(href, &via, global, 0, &mut out, unresolved)?;
        let target = match href_id(href) {
            Some(id) => find_id(local_ids, global, id)?,
            None => None,
        };
        let name = target.map(|e| String::from_utf8_lossy(name_at(reparse.src, e.bytes.start)).into_owned());
        resolved.push((out, name));
    }
    Ok(resolved)
}

/// Phases 1 and 2: what each polygon placeholder becomes (under a shared borrow, in visiting
/// order), then spliced in in the same order.
fn resolve_polygon_refs(
    obj: &mut CityObject,
    lk: &mut Lookups<'_, '_, '_>,
    unresolved: &mut Vec<XLinkRef>,
) -> Result<(), ReadError> {
    let (local_ids, reparse, global) = (lk.local_ids, lk.reparse, &mut *lk.global);
    let mut replacements: Vec<Option<Vec<Polygon>>> = Vec::new();
    {
        let mut by_id: FxMap<&str, &Polygon> = FxMap::default();
        let mut phs: Vec<&Polygon> = Vec::new();
        visit_polys(obj, &mut |p| {
            if is_placeholder(p) {
                phs.push(p);
            } else if let Some(id) = &p.id {
                by_id.insert(id.as_str(), p);
            }
        });
        for ph in phs {
            let r = resolve_one(ph, &by_id, local_ids, reparse, global, 0)?;
            if r.is_none() {
                unresolved.push(XLinkRef::at(ph.id.clone().unwrap_or_default(), ph.via_xlink.clone().unwrap_or_default()));
            }
            replacements.push(r);
        }
    }
    let mut it = replacements.into_iter();
    visit_vecs_mut(obj, &mut |v| {
        if !v.iter().any(is_placeholder) {
            return;
        }
        let cap = v.len();
        let old = std::mem::replace(v, Vec::with_capacity(cap));
        for p in old {
            if is_placeholder(&p) {
                if let Some(Some(r)) = it.next() {
                    v.extend(r);
                }
            } else {
                v.push(p);
            }
        }
    });
    Ok(())
}

/// The deepest object of `obj` (itself included) whose element holds byte `at`.
fn innermost_at(obj: &CityObject, at: usize) -> Option<&CityObject> {
    if !obj.span.bytes.contains(&at) {
        return None;
    }
    obj.children.iter().find_map(|c| innermost_at(c, at)).or(Some(obj))
}

/// What resolving a solid XLink needs besides the global index.
struct SolidCtx<'m, 'o, 'r, 'a> {
    by_id: &'m FxMap<&'o str, &'o Polygon>,
    local_ids: &'m FxMap<String, IdEntry>,
    reparse: &'m Reparse<'r, 'a>,
}

impl SolidCtx<'_, '_, '_, '_> {
    /// The solids `href` (a `solidMember xlink:href` at `via`) stands for, appended to `out.0`
    /// as copies (every polygon's `via_xlink` = `via`, polygon XLinks inside them resolved);
    /// when there are none, a skipped member saying why goes to `out.1`.
    #[allow(clippy::too_many_arguments)]
    fn resolve_solid(
        &self,
        href: &str,
        via: &SourceSpan,
        global: &mut dyn GlobalIds,
        depth: usize,
        out: &mut (Vec<Solid>, Vec<SkippedMember>),
        unresolved: &mut Vec<XLinkRef>,
    ) -> Result<(), ReadError> {
        let skip = |reason: String| SkippedMember { href: Some(href.to_string()), reason, span: via.clone() };
        let nowhere = |unresolved: &mut Vec<XLinkRef>| {
            unresolved.push(XLinkRef::at(href.to_string(), via.clone()));
            skip(format!("xlink:href=\"{}\" points to nothing in the document", quote(href)))
        };
        let Some(id) = href_id(href) else {
            out.1.push(nowhere(unresolved));
            return Ok(());
        };
        if depth > 8 {
            out.1.push(skip(format!("xlink:href=\"{}\": reference cycle", quote(href))));
            return Ok(());
        }
        let entry = find_id(self.local_ids, global, id)?;
        let Some(entry) = entry else {
            out.1.push(nowhere(unresolved));
            return Ok(());
        };
        let (solids, skipped) = match self.reparse.solids(&entry)? {
            Ok(r) => r,
            Err(name) => {
                out.1.push(skip(format!("xlink:href=\"{}\" points to <{}>, not a solid", quote(href), quote(&name))));
                return Ok(());
            }
        };
        out.1.extend(skipped);
        for mut s in solids {
            if is_solid_placeholder(&s) {
                let ph = &s.0.polygons[0];
                let inner = ph.id.clone().unwrap_or_default();
                self.resolve_solid(&inner, via, global, depth + 1, out, unresolved)?;
                continue;
            }
            for shell in std::iter::once(&mut s.0).chain(s.1.iter_mut()) {
                if shell.polygons.iter().any(is_placeholder) {
                    let old = std::mem::take(&mut shell.polygons);
                    for p in old {
                        if !is_placeholder(&p) {
                            shell.polygons.push(p);
                            continue;
                        }
                        match resolve_one(&p, self.by_id, self.local_ids, self.reparse, global, 0)? {
                            Some(r) => shell.polygons.extend(r),
                            None => unresolved.push(XLinkRef::at(p.id.clone().unwrap_or_default(), p.via_xlink.clone().unwrap_or_default())),
                        }
                    }
                }
                for p in &mut shell.polygons {
                    p.via_xlink = Some(via.clone());
                }
                shell.via_xlink = Some(via.clone());
            }
            out.0.push(s);
        }
        Ok(())
    }
}

fn resolve_one(
    ph: &Polygon,
    by_id: &FxMap<&str, &Polygon>,
    local_ids: &FxMap<String, IdEntry>,
    reparse: &Reparse<'_, '_>,
    global: &mut dyn GlobalIds,
    depth: usize,
) -> Result<Option<Vec<Polygon>>, ReadError> {
    let href = ph.id.as_deref().unwrap_or("");
    let Some(id) = href_id(href) else { return Ok(None) };
    let via = ph.via_xlink.clone();
    let copy = |p: &Polygon| {
        let mut c = p.clone();
        c.reversed ^= ph.reversed;
        c.via_xlink = via.clone();
        c
    };
    if let Some(p) = by_id.get(id) {
        return Ok(Some(vec![copy(p)]));
    }
    if depth > 8 {
        return Ok(None); // reference cycle
    }
    let Some(entry) = find_id(local_ids, global, id)? else { return Ok(None) };
    if !is_surface_like(name_at(reparse.src, entry.bytes.start)) {
        return Ok(None); // an id'd element that is not a geometry (the global index holds all ids)
    }
    let mut out = Vec::new();
    for p in reparse.surfaces(&entry)? {
        if is_placeholder(&p) {
            if let Some(r) = resolve_one(&p, by_id, local_ids, reparse, global, depth + 1)? {
                out.extend(r.iter().map(&copy));
            }
        } else {
            out.push(copy(&p));
        }
    }
    Ok(Some(out))
}

/// Computes envelopes from coordinates (children included); keeps the declared one where an
/// object has no geometry of its own.
pub(crate) fn finish_envelopes(obj: &mut CityObject) {
    let mut env = Envelope::empty();
    for c in &mut obj.children {
        finish_envelopes(c);
        env.merge(&c.envelope);
    }
    // Plain comparisons instead of Envelope::add_point's f64::min/max, in locals: the same
    // result (a NaN never wins a comparison, as f64::min ignores it; the reader rejects
    // non-finite coordinates anyway) in straight min/max instructions.
    let (mut lo, mut hi) = (env.min, env.max);
    let mut add_shell = |polys: &[Polygon]| {
        for p in polys {
            for r in std::iter::once(&p.exterior).chain(p.interiors.iter()) {
                for q in &r.points {
                    for i in 0..3 {
                        lo[i] = if q[i] < lo[i] { q[i] } else { lo[i] };
                        hi[i] = if q[i] > hi[i] { q[i] } else { hi[i] };
                    }
                }
            }
        }
    };
    for g in &obj.geometries {
        match &g.kind {
            GeometryKind::Surfaces(v) => add_shell(v),
            GeometryKind::Solid { exterior, interior } => {
                add_shell(&exterior.polygons);
                for s in interior {
                    add_shell(&s.polygons);
                }
            }
            GeometryKind::Solids(v) => {
                for (e, i) in v {
                    add_shell(&e.polygons);
                    for s in i {
                        add_shell(&s.polygons);
                    }
                }
            }
        }
    }
    env.min = lo;
    env.max = hi;
    if !env.is_empty() {
        obj.envelope = env;
    }
}

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

#[cfg(test)]
mod tests {
    use super::{attr_raw, find_attr, number_at, parse_f64, AttrScan};
    use quick_xml::events::BytesStart;

    #[test]
    fn attribute_scan_and_its_fallback() {
        assert_eq!(find_attr(br##" xlink:href="#P1" gml:id='a'"##, b"id"), AttrScan::Found(b"a"));
        assert_eq!(find_attr(br##" a = "x" "##, b"a"), AttrScan::Found(b"x"));
        assert_eq!(find_attr(br##" a="x""##, b"b"), AttrScan::Absent);
        assert_eq!(find_attr(br##" foo xlink:href="#P1""##, b"href"), AttrScan::Malformed);
        assert_eq!(find_attr(br##" a=b c="x""##, b"c"), AttrScan::Malformed);
        // The fallback finds what follows a malformed attribute, as quick-xml's iterator did.
        for tag in [r##"gml:surfaceMember foo xlink:href="#P1""##, r##"gml:surfaceMember a=b xlink:href="#P1""##] {
            let e = BytesStart::from_content(tag, "gml:surfaceMember".len());
            assert_eq!(attr_raw(&e, b"href").as_deref(), Some(&b"#P1"[..]), "{tag}");
        }
    }

    #[test]
    fn fast_float_path_agrees_with_std() {
        let cases = [
            "0", "1", "-0.0", "385421.123", "5729890.812", "0.1", "0.3", "123456789012345", "1234567890123456",
            "0.000000000000000000001", "1e3", "-2.5E-3", "3333399999990.0", "17.854", "+4.25", ".5", "5.",
        ];
        for c in cases {
            assert_eq!(parse_f64(c.as_bytes()), c.parse::<f64>().ok(), "{c}");
        }
        // Pseudo-random decimals with up to 15 significant digits.
        let mut x: u64 = 0x9E3779B97F4A7C15;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let int = x % 10_000_000;
            let frac = (x >> 24) % 100_000_000;
            let digits = (x >> 56) as usize % 9;
            let s = format!("{int}.{:0width$}", frac % 10u64.pow(digits as u32), width = digits);
            assert_eq!(parse_f64(s.as_bytes()), s.parse::<f64>().ok(), "{s}");
        }
        // The plain-decimal fast path at its limits: significands around 2^53, up to 19 digits,
        // up to 23 decimals, signs, leading zeros (each either exact or handed to fast-float2).
        let edge = [
            "9007199254740992", "9007199254740993", "900719925474099.3", "-9007199254740.992", "0.9007199254740993",
            "1234567890123456789", "12345678901234567890", "0.0000000000000000000001", "0.00000000000000000000001",
            "-0", "+0.", "-.5", "007.250", "4503599627370497.5", "1.7976931348623157", "-", "+", "-.", "1.-2",
        ];
        for c in edge {
            assert_eq!(parse_f64(c.as_bytes()).map(f64::to_bits), c.parse::<f64>().ok().map(f64::to_bits), "{c}");
        }
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let digits = 1 + (x >> 59) as usize % 19;
            let m = x % 10u64.pow(digits as u32);
            let frac = (x >> 32) as usize % (digits + 5);
            let sign = if x & 1 == 1 { "-" } else { "" };
            let t = format!("{m:0digits$}");
            let s = if frac >= t.len() {
                format!("{sign}0.{:0>frac$}", t)
            } else {
                format!("{sign}{}.{}", &t[..t.len() - frac], &t[t.len() - frac..])
            };
            assert_eq!(parse_f64(s.as_bytes()).map(f64::to_bits), s.parse::<f64>().ok().map(f64::to_bits), "{s}");
            // in a coordinate list, followed by whitespace
            let list = format!("{s} 1");
            let (v, len) = number_at(list.as_bytes(), 0).ok().unwrap();
            assert_eq!((v.to_bits(), len), (s.parse::<f64>().unwrap().to_bits(), s.len()), "{s}");
        }
        for bad in ["", "-", ".", "abc", "1.2.3", "1,5", "nan"] {
            assert_eq!(parse_f64(bad.as_bytes()).map(|v| v.is_finite()), bad.parse::<f64>().ok().map(|v| v.is_finite()), "{bad}");
        }
    }
}
