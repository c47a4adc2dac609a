//! XSD validation with the system libxml2, linked in-process through a small hand-written FFI
//! (the handful of calls `xmllint --schema` makes). Network access is off (`XML_PARSE_NONET` and
//! libxml2's no-network entity loader), so the offline schema bundle must be complete.
//!
//! libxml2 reports the line of each validity error but not its column (its nodes carry no
//! column), so the column is recovered from the source: the start tag of the reported element on
//! that line.

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::Path;
use std::sync::Once;

#[repr(C)]
struct XmlError {
    domain: c_int,
    code: c_int,
    message: *const c_char,
    level: c_int,
    file: *const c_char,
    line: c_int,
    str1: *const c_char,
    str2: *const c_char,
    str3: *const c_char,
    int1: c_int,
    int2: c_int,
    ctxt: *mut c_void,
    node: *mut c_void,
}

/// The first fields of libxml2's `xmlNode` (stable since 2.0).
#[repr(C)]
struct XmlNodeHead {
    private: *mut c_void,
    kind: c_int,
    name: *const c_char,
}

type StructuredErrorFunc = unsafe extern "C" fn(*mut c_void, *const XmlError);
type EntityLoader = unsafe extern "C" fn(*const c_char, *const c_char, *mut c_void) -> *mut c_void;

#[link(name = "xml2")]
extern "C" {
    fn xmlInitParser();
    fn xmlSchemaInitTypes();
    fn xmlSetExternalEntityLoader(f: EntityLoader);
    fn xmlNoNetExternalEntityLoader(url: *const c_char, id: *const c_char, ctxt: *mut c_void) -> *mut c_void;
    fn xmlSetStructuredErrorFunc(ctx: *mut c_void, handler: Option<StructuredErrorFunc>);
    fn xmlSchemaNewParserCtxt(url: *const c_char) -> *mut c_void;
    fn xmlSchemaSetParserStructuredErrors(ctxt: *mut c_void, serror: Option<StructuredErrorFunc>, ctx: *mut c_void);
    fn xmlSchemaParse(ctxt: *mut c_void) -> *mut c_void;
    fn xmlSchemaFreeParserCtxt(ctxt: *mut c_void);
    fn xmlSchemaFree(schema: *mut c_void);
    fn xmlSchemaNewValidCtxt(schema: *mut c_void) -> *mut c_void;
    fn xmlSchemaSetValidStructuredErrors(ctxt: *mut c_void, serror: Option<StructuredErrorFunc>, ctx: *mut c_void);
    fn xmlSchemaValidateDoc(ctxt: *mut c_void, doc: *mut c_void) -> c_int;
    fn xmlSchemaFreeValidCtxt(ctxt: *mut c_void);
    fn xmlReadMemory(
        buffer: *const c_char,
        size: c_int,
        url: *const c_char,
        encoding: *const c_char,
        options: c_int,
    ) -> *mut c_void;
    fn xmlFreeDoc(doc: *mut c_void);
    fn xmlReaderForMemory(
        buffer: *const c_char,
        size: c_int,
        url: *const c_char,
        encoding: *const c_char,
        options: c_int,
    ) -> *mut c_void;
    fn xmlTextReaderSetStructuredErrorHandler(reader: *mut c_void, f: Option<StructuredErrorFunc>, arg: *mut c_void);
    fn xmlTextReaderSetSchema(reader: *mut c_void, schema: *mut c_void) -> c_int;
    fn xmlTextReaderRead(reader: *mut c_void) -> c_int;
    fn xmlTextReaderIsValid(reader: *mut c_void) -> c_int;
    fn xmlFreeTextReader(reader: *mut c_void);
}

const XML_PARSE_NONET: c_int = 1 << 11;
const XML_PARSE_COMPACT: c_int = 1 << 16;
const XML_PARSE_BIG_LINES: c_int = 1 << 22;
/// Lifts libxml2's default limits, among them the 10 MB dictionary that also interns every
/// xs:ID value: past it each further id is "not a valid value of the atomic type 'xs:ID'"
/// (a valid NRW tile ×250, 311 MB: false findings after 25 min; with it, valid in 22 s).
/// docs/decisions.md#xsd-validation-of-big-files
const XML_PARSE_HUGE: c_int = 1 << 19;
/// libxml2's error domain of its allocator, and its out-of-memory code: failures of the
/// machine, never findings about the document.
const XML_FROM_MEMORY: c_int = 6;
const XML_ERR_NO_MEMORY: c_int = 2;
/// Documents from this size on are validated streaming (libxml2's reader with the schema
/// attached) instead of as a tree, which takes about six times the document in memory.
/// `GEOFIT_XSD_STREAM_BYTES` overrides it (the tests compare both ways on small files).
pub const STREAM_FROM_BYTES: usize = 64 << 20;

fn stream_from_bytes() -> usize {
    std::env::var("GEOFIT_XSD_STREAM_BYTES").ok().and_then(|v| v.parse().ok()).unwrap_or(STREAM_FROM_BYTES)
}

static INIT: Once = Once::new();

/// libxml2's process-wide set-up, once, before any thread parses: `xmlInitParser`, and
/// `xmlSchemaInitTypes`, which `xmlSchemaParse` otherwise runs lazily without a lock (two
/// threads parsing their first schemas at once could both build the built-in types; libxml2
/// issue 930). After this, schemas may be parsed and documents validated on any thread.
fn init() {
    INIT.call_once(|| unsafe {
        xmlInitParser();
        xmlSchemaInitTypes();
        xmlSetExternalEntityLoader(xmlNoNetExternalEntityLoader);
    });
}

#[derive(Debug, thiserror::Error)]
pub enum XsdError {
    #[error("cannot load schema {path}: {message}")]
    SchemaLoad { path: String, message: String },
    #[error("document is too large for libxml2 ({0} bytes, limit 2 GiB); check it with --no-xsd")]
    TooLarge(usize),
    #[error("libxml2 ran out of memory during the schema check ({0}); it says nothing about the file: check it with --no-xsd")]
    OutOfMemory(String),
}

/// What kind of problem libxml2 reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum XsdErrorKind {
    /// The document is not well-formed XML (no schema check possible).
    NotWellFormed,
    /// The document breaks the schema.
    Invalid,
}

/// One XSD finding.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct XsdFinding {
    pub kind: XsdErrorKind,
    pub line: usize,
    /// 1-based column; for validity errors, the column of the element's start tag.
    pub column: usize,
    /// Local name of the element libxml2 blames, when it names one.
    pub element: Option<String>,
    pub message: String,
}

struct Collector {
    findings: Vec<(XsdErrorKind, XmlErrorCopy)>,
    kind: XsdErrorKind,
    /// libxml2's own message when its allocator failed (docs/decisions.md#xsd-validation-of-big-files).
    out_of_memory: Option<String>,
}

struct XmlErrorCopy {
    line: usize,
    column: usize,
    element: Option<String>,
    message: String,
}

unsafe extern "C" fn collect(ctx: *mut c_void, err: *const XmlError) {
    if ctx.is_null() || err.is_null() {
        return;
    }
    let c = &mut *(ctx as *mut Collector);
    let e = &*err;
    // warnings (level 1) are not errors
    if e.level < 2 {
        return;
    }
    let message = if e.message.is_null() {
        String::from("unknown error")
    } else {
        CStr::from_ptr(e.message).to_string_lossy().trim_end().to_string()
    };
    if e.domain == XML_FROM_MEMORY || e.code == XML_ERR_NO_MEMORY {
        c.out_of_memory.get_or_insert(message);
        return;
    }
    let element = if !e.node.is_null() {
        let n = &*(e.node as *const XmlNodeHead);
        // XML_ELEMENT_NODE = 1
        (n.kind == 1 && !n.name.is_null()).then(|| CStr::from_ptr(n.name).to_string_lossy().into_owned())
    } else {
        None
    };
    c.findings.push((
        c.kind,
        XmlErrorCopy { line: e.line.max(0) as usize, column: e.int2.max(0) as usize, element, message },
    ));
}

/// A parsed XML schema; parse it once per run and validate any number of documents with it.
pub struct Schema {
    ptr: *mut c_void,
}

// The parsed schema is immutable after xmlSchemaParse; libxml2 allows sharing it between
// validation contexts on different threads.
unsafe impl Send for Schema {}
unsafe impl Sync for Schema {}

impl Drop for Schema {
    fn drop(&mut self) {
        unsafe { xmlSchemaFree(self.ptr) }
    }
}

impl Schema {
    /// Parses the schema at `path` (imports are resolved relative to it, never over the network).
    pub fn load(path: &Path) -> Result<Schema, XsdError> {
        init();
        let shown = path.display().to_string();
        let c = CString::new(path.to_string_lossy().as_bytes())
            .map_err(|_| XsdError::SchemaLoad { path: shown.clone(), message: "path contains a NUL byte".into() })?;
        let mut col = Collector { findings: Vec::new(), kind: XsdErrorKind::Invalid, out_of_memory: None };
        unsafe {
            let pctxt = xmlSchemaNewParserCtxt(c.as_ptr());
            if pctxt.is_null() {
                return Err(XsdError::SchemaLoad {
                    path: shown,
                    message: "libxml2 could not create a schema parser".into(),
                });
            }
            let colp = &mut col as *mut Collector as *mut c_void;
            xmlSchemaSetParserStructuredErrors(pctxt, Some(collect), colp);
            xmlSetStructuredErrorFunc(colp, Some(collect));
            let schema = xmlSchemaParse(pctxt);
            xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
            xmlSchemaFreeParserCtxt(pctxt);
            if schema.is_null() {
                let msg = col
                    .findings
                    .first()
                    .map(|(_, e)| format!("{} (line {})", e.message, e.line))
                    .unwrap_or_else(|| "the schema could not be parsed".into());
                return Err(XsdError::SchemaLoad { path: shown, message: msg });
            }
            Ok(Schema { ptr: schema })
        }
    }

    /// Validates a document held in memory. `name` is used as the document URL in libxml2.
    /// Returns the findings in document order (empty when the document is valid).
    pub fn validate(&self, xml: &[u8], name: &str) -> Result<Vec<XsdFinding>, XsdError> {
        init();
        if xml.len() > i32::MAX as usize {
            return Err(XsdError::TooLarge(xml.len()));
        }
        if let Some(f) = too_many_attributes(xml, MAX_ATTRIBUTES) {
            return Ok(vec![f]);
        }
        if xml.len() >= stream_from_bytes() {
            return self.validate_streaming(xml, name);
        }
        let url = CString::new(name.replace('\0', "")).unwrap_or_default();
        let mut col = Collector { findings: Vec::new(), kind: XsdErrorKind::NotWellFormed, out_of_memory: None };
        unsafe {
            let colp = &mut col as *mut Collector as *mut c_void;
            xmlSetStructuredErrorFunc(colp, Some(collect));
            let doc = xmlReadMemory(
                xml.as_ptr() as *const c_char,
                xml.len() as c_int,
                url.as_ptr(),
                std::ptr::null(),
                XML_PARSE_NONET | XML_PARSE_COMPACT | XML_PARSE_BIG_LINES | XML_PARSE_HUGE,
            );
            if doc.is_null() || !col.findings.is_empty() {
                xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
                if !doc.is_null() {
                    xmlFreeDoc(doc);
                }
                if col.findings.is_empty() {
                    col.findings.push((
                        XsdErrorKind::NotWellFormed,
                        XmlErrorCopy {
                            line: 1,
                            column: 1,
                            element: None,
                            message: "document could not be parsed".into(),
                        },
                    ));
                }
                return finish_checked(col, xml);
            }
            col.kind = XsdErrorKind::Invalid;
            let vctxt = xmlSchemaNewValidCtxt(self.ptr);
            if vctxt.is_null() {
                xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
                xmlFreeDoc(doc);
                return Err(XsdError::SchemaLoad {
                    path: name.into(),
                    message: "cannot create a validation context".into(),
                });
            }
            xmlSchemaSetValidStructuredErrors(vctxt, Some(collect), colp);
            let rc = xmlSchemaValidateDoc(vctxt, doc);
            xmlSchemaFreeValidCtxt(vctxt);
            xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
            xmlFreeDoc(doc);
            if rc != 0 && col.findings.is_empty() {
                col.findings.push((
                    XsdErrorKind::Invalid,
                    XmlErrorCopy {
                        line: 0,
                        column: 0,
                        element: None,
                        message: format!("validation failed (libxml2 code {rc})"),
                    },
                ));
            }
        }
        finish_checked(col, xml)
    }

    /// [`Schema::validate`] through libxml2's streaming reader with the schema attached: the
    /// memory is that of the open elements and the id table, not of the whole tree.
    fn validate_streaming(&self, xml: &[u8], name: &str) -> Result<Vec<XsdFinding>, XsdError> {
        let url = CString::new(name.replace('\0', "")).unwrap_or_default();
        let mut col = Collector { findings: Vec::new(), kind: XsdErrorKind::Invalid, out_of_memory: None };
        unsafe {
            let colp = &mut col as *mut Collector as *mut c_void;
            xmlSetStructuredErrorFunc(colp, Some(collect));
            let options = XML_PARSE_NONET | XML_PARSE_COMPACT | XML_PARSE_BIG_LINES | XML_PARSE_HUGE;
            let reader = xmlReaderForMemory(
                xml.as_ptr() as *const c_char,
                xml.len() as c_int,
                url.as_ptr(),
                std::ptr::null(),
                options,
            );
            if reader.is_null() {
                xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
                return Err(XsdError::OutOfMemory("cannot create a streaming reader".into()));
            }
            xmlTextReaderSetStructuredErrorHandler(reader, Some(collect), colp);
            if xmlTextReaderSetSchema(reader, self.ptr) != 0 {
                xmlFreeTextReader(reader);
                xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
                return Err(XsdError::SchemaLoad {
                    path: name.into(),
                    message: "cannot attach the schema to a streaming reader".into(),
                });
            }
            let mut rc = 1;
            while rc == 1 {
                rc = xmlTextReaderRead(reader);
            }
            let valid = xmlTextReaderIsValid(reader);
            xmlFreeTextReader(reader);
            xmlSetStructuredErrorFunc(std::ptr::null_mut(), None);
            if (rc < 0 || valid != 1) && col.findings.is_empty() && col.out_of_memory.is_none() {
                col.findings.push((
                    XsdErrorKind::Invalid,
                    XmlErrorCopy {
                        line: 0,
                        column: 0,
                        element: None,
                        message: "validation failed (libxml2 streaming reader)".into(),
                    },
                ));
            }
        }
        finish_checked(col, xml)
    }
}

/// The findings, or the allocator's failure when libxml2 reported one: a machine that ran out
/// of memory says nothing about the file.
fn finish_checked(col: Collector, xml: &[u8]) -> Result<Vec<XsdFinding>, XsdError> {
    match col.out_of_memory {
        Some(why) => Err(XsdError::OutOfMemory(input_limits::quote(&why).into_owned())),
        None => Ok(finish(col, xml)),
    }
}

/// The most attributes (namespace declarations included) one element may have for the schema
/// check to run. libxml2's schema validation takes time quadratic in the attributes of one
/// element (100 000 attributes: 100 s, 10⁶: more than 5 minutes); no CityGML element declares
/// more than a handful, and real root elements carry a few dozen namespace declarations.
pub const MAX_ATTRIBUTES: usize = 1000;

/// A finding for the first element with more than `max` attributes (a linear pre-scan with
/// quick-xml before libxml2 sees the document; docs/decisions.md#xsd-attribute-limit).
/// Not well-formed XML passes: libxml2 reports it with its own message.
fn too_many_attributes(xml: &[u8], max: usize) -> Option<XsdFinding> {
    let mut reader = quick_xml::Reader::from_reader(xml);
    reader.config_mut().check_end_names = false;
    loop {
        let pos = reader.buffer_position() as usize;
        match reader.read_event() {
            Ok(quick_xml::events::Event::Start(e)) | Ok(quick_xml::events::Event::Empty(e)) => {
                let n = count_attributes(e.attributes_raw());
                if n > max {
                    let pos = pos.min(xml.len());
                    let local = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
                    return Some(XsdFinding {
                        kind: XsdErrorKind::Invalid,
                        line: 1 + xml[..pos].iter().filter(|&&c| c == b'\n').count(),
                        column: pos - xml[..pos].iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1) + 1,
                        message: format!(
                            "Element '{}': {n} attributes, more than the {max} checked against the schema (the schema check was not run: libxml2 takes quadratic time on such an element)",
                            input_limits::quote(&local)
                        ),
                        element: Some(local),
                    });
                }
            }
            Ok(quick_xml::events::Event::Eof) | Err(_) => return None,
            Ok(_) => {}
        }
    }
}

/// Attributes in the raw bytes after an element name: `=` signs outside quoted values.
fn count_attributes(raw: &[u8]) -> usize {
    let mut n = 0;
    let mut quote: Option<u8> = None;
    for &b in raw {
        match quote {
            Some(q) if b == q => quote = None,
            Some(_) => {}
            None if b == b'"' || b == b'\'' => quote = Some(b),
            None if b == b'=' => n += 1,
            None => {}
        }
    }
    n
}

/// libxml2 quotes the document's values and names between single quotes ("'…' is not a valid
/// value of …"): each quoted part is cut to ~200 bytes (`input_limits::quote`), the rest of the
/// message (the schema's words, lists of expected elements) is kept.
fn shorten_quoted(message: &str) -> String {
    let parts: Vec<&str> = message.split('\'').collect();
    if parts.len() < 3 || parts.iter().all(|p| p.len() <= input_limits::QUOTE_MAX_BYTES) {
        return message.to_string();
    }
    // odd indices lie between a pair of quotes
    parts
        .iter()
        .enumerate()
        .map(
            |(i, p)| {
                if i % 2 == 1 && i + 1 < parts.len() {
                    input_limits::quote(p)
                } else {
                    std::borrow::Cow::Borrowed(*p)
                }
            },
        )
        .collect::<Vec<_>>()
        .join("'")
}

fn finish(col: Collector, xml: &[u8]) -> Vec<XsdFinding> {
    let starts = line_starts(xml);
    col.findings
        .into_iter()
        .map(|(kind, e)| {
            let column = if e.column > 0 {
                e.column
            } else {
                e.element.as_deref().and_then(|n| element_column(xml, &starts, e.line, n)).unwrap_or(0)
            };
            XsdFinding { kind, line: e.line, column, element: e.element, message: shorten_quoted(&e.message) }
        })
        .collect()
}

fn line_starts(xml: &[u8]) -> Vec<usize> {
    let mut v = vec![0];
    v.extend(xml.iter().enumerate().filter(|(_, &b)| b == b'\n').map(|(i, _)| i + 1));
    v
}

/// Column (1-based, in characters) of the start tag `<name` or `<prefix:name` on `line`.
fn element_column(xml: &[u8], starts: &[usize], line: usize, local: &str) -> Option<usize> {
    if line == 0 || line > starts.len() {
        return None;
    }
    let s = starts[line - 1];
    let e = starts.get(line).copied().unwrap_or(xml.len());
    let text = String::from_utf8_lossy(&xml[s..e]);
    let mut from = 0;
    while let Some(k) = text[from..].find('<') {
        let at = from + k;
        let rest = &text[at + 1..];
        let qname: String = rest.chars().take_while(|c| !c.is_whitespace() && *c != '>' && *c != '/').collect();
        let ln = qname.rsplit(':').next().unwrap_or("");
        if ln == local {
            return Some(text[..at].chars().count() + 1);
        }
        from = at + 1;
    }
    None
}

/// The CityGML version of a document from the namespaces bound on its root element
/// ("1.0", "2.0" or "3.0"), without a full parse. Used to pick the wrapper schema.
pub fn sniff_version(xml: &[u8]) -> Option<&'static str> {
    let mut i = 0;
    let n = xml.len();
    // skip BOM, declaration, comments, doctype, PIs
    while i < n {
        if xml[i] == b'<' {
            let next = xml.get(i + 1).copied();
            if next == Some(b'?') || next == Some(b'!') {
                if xml[i..].starts_with(b"<!--") {
                    i = find(xml, i, b"-->").map(|k| k + 3)?;
                } else {
                    i = find(xml, i, b">").map(|k| k + 1)?;
                }
                continue;
            }
            let end = find(xml, i, b">")?;
            let tag = &xml[i..end];
            for (ns, v) in [
                (&b"http://www.opengis.net/citygml/3.0"[..], "3.0"),
                (&b"http://www.opengis.net/citygml/2.0"[..], "2.0"),
                (&b"http://www.opengis.net/citygml/1.0"[..], "1.0"),
            ] {
                if find(tag, 0, ns).is_some() {
                    return Some(v);
                }
            }
            // module namespaces (…/building/2.0) when the core namespace is not bound
            for v in ["3.0", "2.0", "1.0"] {
                let pat = format!("/{v}\"");
                let s = String::from_utf8_lossy(tag);
                if s.contains("opengis.net/citygml") && s.contains(&pat) {
                    return Some(v);
                }
            }
            return None;
        }
        i += 1;
    }
    None
}

fn find(hay: &[u8], from: usize, needle: &[u8]) -> Option<usize> {
    if from >= hay.len() {
        return None;
    }
    hay[from..].windows(needle.len()).position(|w| w == needle).map(|k| k + from)
}

/// File name of the project's wrapper schema for a CityGML version (see `../shared/xsd/README.md`).
pub fn wrapper_for(version: &str) -> String {
    format!("citygml-{version}.xsd")
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0"
    xmlns:bldg="http://www.opengis.net/citygml/building/2.0" xmlns:gml="http://www.opengis.net/gml">
  <core:cityObjectMember>
    <bldg:Building gml:id="B1"/>
  </core:cityObjectMember>
</core:CityModel>
"#;

    #[test]
    fn long_quoted_values_are_shortened_and_attributes_counted() {
        let v = "9".repeat(1000);
        let m = shorten_quoted(&format!("Element 'pos': '{v}' is not a valid value of the atomic type 'xs:double'."));
        assert!(
            m.starts_with("Element 'pos': '999")
                && m.contains("… (1000 bytes)' is not a valid value of the atomic type 'xs:double'."),
            "{m}"
        );
        assert_eq!(shorten_quoted("it's short"), "it's short");
        assert_eq!(count_attributes(br#" a="1" b='x=y' c = "=""#), 3);
        let many: String = (0..20).map(|i| format!(" a{i}=\"{i}\"")).collect();
        let doc = format!("<r>\n <e{many}/></r>");
        let f = too_many_attributes(doc.as_bytes(), 10).unwrap();
        assert_eq!((f.line, f.column, f.element.as_deref()), (2, 2, Some("e")), "{f:?}");
        assert!(too_many_attributes(doc.as_bytes(), 20).is_none());
    }

    #[test]
    fn version_from_root_namespaces() {
        assert_eq!(sniff_version(DOC.as_bytes()), Some("2.0"));
        let v3 = "\u{feff}<?xml version=\"1.0\"?><!-- c --><CityModel xmlns=\"http://www.opengis.net/citygml/3.0\"/>";
        assert_eq!(sniff_version(v3.as_bytes()), Some("3.0"));
        assert_eq!(sniff_version(b"<x xmlns=\"urn:other\"/>"), None);
        assert_eq!(sniff_version(b""), None);
    }

    #[test]
    fn column_of_the_blamed_start_tag() {
        let starts = line_starts(DOC.as_bytes());
        assert_eq!(element_column(DOC.as_bytes(), &starts, 5, "Building"), Some(5));
        assert_eq!(element_column(DOC.as_bytes(), &starts, 5, "Nothing"), None);
    }

    /// Against the offline bundle beside the checkout, when it is there (the e2e tests compare
    /// with xmllint on every fixture).
    #[test]
    fn validates_in_process() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/xsd");
        if !dir.join("citygml-2.0.xsd").is_file() {
            eprintln!("SKIP: {} not found", dir.display());
            return;
        }
        let schema = Schema::load(&dir.join("citygml-2.0.xsd")).unwrap();
        assert!(schema.validate(DOC.as_bytes(), "ok.gml").unwrap().is_empty());
        // an xs:ID must not start with a digit
        let bad = DOC.replace("gml:id=\"B1\"", "gml:id=\"1B\"");
        let f = schema.validate(bad.as_bytes(), "bad.gml").unwrap();
        assert!(!f.is_empty());
        assert_eq!((f[0].kind, f[0].line, f[0].column), (XsdErrorKind::Invalid, 5, 5), "{f:?}");
        // not well-formed: a libxml2 parser error with its own column
        let f = schema.validate(&DOC.as_bytes()[..DOC.len() - 20], "cut.gml").unwrap();
        assert_eq!(f[0].kind, XsdErrorKind::NotWellFormed);
        assert!(f[0].line >= 6 && f[0].column >= 1, "{f:?}");
        assert!(Schema::load(&dir.join("no-such.xsd")).is_err());
    }

    /// The rules the many-file run relies on: schemas parsed on several threads at once (after
    /// the one-time set-up) and one parsed schema validating on several threads at once give
    /// the same findings as one thread alone.
    #[test]
    fn schemas_parse_and_validate_on_many_threads() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/xsd");
        if !dir.join("citygml-2.0.xsd").is_file() {
            eprintln!("SKIP: {} not found", dir.display());
            return;
        }
        let bad = DOC.replace("gml:id=\"B1\"", "gml:id=\"1B\"");
        let alone = Schema::load(&dir.join("citygml-2.0.xsd")).unwrap().validate(bad.as_bytes(), "bad.gml").unwrap();
        assert!(!alone.is_empty());
        let shared = Schema::load(&dir.join("citygml-2.0.xsd")).unwrap();
        std::thread::scope(|s| {
            for k in 0..4 {
                let (dir, bad, alone, shared) = (&dir, &bad, &alone, &shared);
                s.spawn(move || {
                    // each thread parses a different wrapper first
                    let v = ["1.0", "2.0", "3.0", "2.0"][k];
                    Schema::load(&dir.join(wrapper_for(v))).unwrap();
                    for _ in 0..20 {
                        assert_eq!(&shared.validate(bad.as_bytes(), "bad.gml").unwrap(), alone);
                        assert!(shared.validate(DOC.as_bytes(), "ok.gml").unwrap().is_empty());
                    }
                });
            }
        });
    }
}
