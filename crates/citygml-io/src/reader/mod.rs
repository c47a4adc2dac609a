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

use crate::error::ReadError;
use crate::lines::LineIndex;
use crate::model::*;
use input_limits::quote;

mod coords;
mod envelope;
mod geometry;
mod index;
mod names;
mod object;
mod xlink;

use self::coords::*;
pub(crate) use self::envelope::finish_envelopes;
pub(crate) use self::index::build_index;
use self::names::*;
pub(crate) use self::xlink::{resolve_object, GlobalIds, Reparse};

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
        AttrScan::Malformed => {
            e.attributes().with_checks(false).flatten().find(|a| a.key.local_name().as_ref() == local).map(|a| a.value)
        }
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
    End {
        end: usize,
    },
    /// Character data at `at`, `len` bytes; `nonblank` is `Some(true)` for CDATA and entity
    /// references, `None` for plain text (see [`Parser::is_blank`]).
    Text {
        nonblank: Option<bool>,
        at: usize,
        len: usize,
    },
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
        self.binding_of(t.raw.name().as_ref()).map(|b| String::from_utf8_lossy(&b.uri).into_owned()).unwrap_or_default()
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
            "0",
            "1",
            "-0.0",
            "385421.123",
            "5729890.812",
            "0.1",
            "0.3",
            "123456789012345",
            "1234567890123456",
            "0.000000000000000000001",
            "1e3",
            "-2.5E-3",
            "3333399999990.0",
            "17.854",
            "+4.25",
            ".5",
            "5.",
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
            "9007199254740992",
            "9007199254740993",
            "900719925474099.3",
            "-9007199254740.992",
            "0.9007199254740993",
            "1234567890123456789",
            "12345678901234567890",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "-0",
            "+0.",
            "-.5",
            "007.250",
            "4503599627370497.5",
            "1.7976931348623157",
            "-",
            "+",
            "-.",
            "1.-2",
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
            assert_eq!(
                parse_f64(bad.as_bytes()).map(|v| v.is_finite()),
                bad.parse::<f64>().ok().map(|v| v.is_finite()),
                "{bad}"
            );
        }
    }
}
