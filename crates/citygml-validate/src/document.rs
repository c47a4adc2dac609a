//! One document's validation report — XSD and geometry — as `geofit validate` prints it, and a
//! [`SchemaSet`] that parses each CityGML version's schema once per process however many
//! documents are checked, from however many threads.
//!
//! libxml2's rules (2.9 and later): a parsed `xmlSchemaPtr` is read-only during validation and
//! may be shared between threads, each validation with its own `xmlSchemaValidCtxt` (see
//! [`Schema::validate`]); `xmlInitParser` and `xmlSchemaInitTypes` run once before any of it
//! ([`crate::xsd`]). The per-version cells below make every version's parse happen once.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use citygml_io::crs::VerticalDatum;
use citygml_io::{CityObject, ObjectStream, ReadError};
use serde::Serialize;

use crate::xsd::{sniff_version, wrapper_for, Schema, XsdErrorKind, XsdFinding};
use crate::{add_unresolved_xlinks, sort_findings, validate_objects, Finding, Options};

#[derive(Debug, Clone, Serialize)]
pub struct XsdReport {
    pub checked: bool,
    /// Why it was not checked.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub schema: Option<String>,
    pub valid: Option<bool>,
    pub errors: Vec<XsdFinding>,
}

impl XsdReport {
    fn skipped(reason: impl Into<String>, schema: Option<String>) -> XsdReport {
        XsdReport { checked: false, reason: Some(reason.into()), schema, valid: None, errors: vec![] }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct GeometryReport {
    pub checked: bool,
    pub options: Options,
    pub features: usize,
    pub valid: Option<bool>,
    pub findings: Vec<Finding>,
    /// The metric frame the tolerances applied in, when it is not the file's CRS (a geographic
    /// CRS's coordinates are checked in a UTM zone; finding positions are in that frame).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame: Option<String>,
}

/// What `geofit validate` reports on one document.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub file: String,
    pub version: Option<String>,
    /// The height system of the document's CRS, when it names one (a compound CRS, an AdV URN).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heights: Option<VerticalDatum>,
    pub valid: bool,
    pub xsd: XsdReport,
    pub geometry: GeometryReport,
}

/// The CityGML wrapper schemas of one directory, each parsed on first use and then shared.
pub struct SchemaSet {
    dir: PathBuf,
    /// 1.0, 2.0, 3.0: the parsed schema, or why it could not be loaded.
    parsed: [OnceLock<Result<Schema, String>>; 3],
}

impl SchemaSet {
    pub fn new(dir: PathBuf) -> SchemaSet {
        SchemaSet { dir, parsed: Default::default() }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn path_for(&self, version: &str) -> PathBuf {
        self.dir.join(wrapper_for(version))
    }

    /// The parsed wrapper for `version` ("1.0", "2.0", "3.0"); parsed once, the first time it
    /// is asked for (other threads asking meanwhile wait for that parse).
    pub fn get(&self, version: &str) -> Result<&Schema, String> {
        let k = match version {
            "1.0" => 0,
            "2.0" => 1,
            "3.0" => 2,
            v => return Err(format!("no CityGML schema for version {v}")),
        };
        self.parsed[k]
            .get_or_init(|| Schema::load(&self.path_for(version)).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(Clone::clone)
    }
}

/// Which checks run.
pub struct Checks {
    /// The schemas, or why there is no XSD check (`--no-xsd`, no schemas found).
    pub xsd: Result<SchemaSet, String>,
    pub geometry: bool,
    pub options: Options,
}

#[derive(Debug, thiserror::Error)]
pub enum DocumentError {
    /// Not readable as CityGML; the message names the file and place.
    #[error("{0}")]
    Unreadable(String),
    /// The schema directory is there but the document's wrapper could not be loaded.
    #[error("{0}")]
    Schema(String),
    /// A failure of geofit itself.
    #[error("{0}")]
    Internal(String),
}

/// How far the geometry check has come, given to the progress callback of [`validate_document`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// Top-level features read and checked so far.
    pub features: usize,
    /// Bytes of the document read so far: the geometry check does not look before this offset
    /// again (a memory-mapped document can release those pages), and against the file size it
    /// gives an ETA.
    pub bytes_read: usize,
}

/// Moves each object read, before it is checked, into the frame the tolerances are metres in;
/// gets the document's srsName as far as it is known. Its error (one line) makes the document
/// unreadable, located at the object. `describe` says what it did, for the report.
pub trait ObjectFrame {
    fn apply(&mut self, document_srs: Option<&str>, obj: &mut CityObject) -> Result<(), String>;
    fn describe(&self) -> Option<String>;
}

/// Validates one document held in memory (or memory-mapped). The XSD check runs on its own
/// thread while the geometry is read and checked; `progress` is called after each batch of
/// checked features. `name` is used in the report and in error messages.
pub fn validate_document(
    bytes: &[u8],
    name: &str,
    checks: &Checks,
    progress: &dyn Fn(Progress),
) -> Result<Report, DocumentError> {
    validate_document_in(bytes, name, checks, None, progress)
}

/// [`validate_document`] with each object moved by `frame` first (geofit: a geographic CRS's
/// degrees into metres, docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).
pub fn validate_document_in(
    bytes: &[u8],
    name: &str,
    checks: &Checks,
    frame: Option<&mut dyn ObjectFrame>,
    progress: &dyn Fn(Progress),
) -> Result<Report, DocumentError> {
    let version = sniff_version(bytes);
    let (xsd, geometry) = std::thread::scope(|s| {
        let xsd_job = s.spawn(|| xsd_report(bytes, name, &checks.xsd, version));
        let geometry = if checks.geometry {
            check_geometry(bytes, &checks.options, frame, progress)
        } else {
            let srs = ObjectStream::new(bytes).ok().and_then(|s| s.srs_name());
            let report = GeometryReport {
                checked: false,
                options: checks.options,
                features: 0,
                valid: None,
                findings: vec![],
                frame: None,
            };
            Ok((report, srs))
        };
        (xsd_job.join(), geometry)
    });
    let xsd = xsd.map_err(|_| DocumentError::Internal("XSD validation thread panicked".into()))?;
    if let (false, Some(why), Ok(_), Some(_)) = (xsd.checked, &xsd.reason, &checks.xsd, version) {
        // the schema directory was found but the wrapper could not be loaded
        return Err(DocumentError::Schema(why.clone()));
    }
    let (geometry, srs) = geometry.map_err(|e| {
        // Unreadable as CityGML: what libxml2 said about well-formedness, when it said something.
        match xsd.errors.iter().find(|f| f.kind == XsdErrorKind::NotWellFormed) {
            Some(f) => {
                DocumentError::Unreadable(format!("{name}:{}:{}: not well-formed XML: {}", f.line, f.column, f.message))
            }
            None => DocumentError::Unreadable(format!("{name}:{e}")),
        }
    })?;
    let valid = xsd.valid != Some(false) && geometry.valid != Some(false);
    let heights = srs.as_deref().and_then(citygml_io::crs::vertical_part);
    Ok(Report { file: name.to_string(), version: version.map(str::to_string), heights, valid, xsd, geometry })
}

fn xsd_report(bytes: &[u8], name: &str, schemas: &Result<SchemaSet, String>, version: Option<&str>) -> XsdReport {
    let set = match (schemas, version) {
        (Err(why), _) => return XsdReport::skipped(why.clone(), None),
        (Ok(_), None) => {
            return XsdReport::skipped(
                "no CityGML 1.0/2.0/3.0 namespace on the root element, no schema to choose",
                None,
            )
        }
        (Ok(set), Some(_)) => set,
    };
    let version = version.unwrap_or_default();
    let shown = Some(set.path_for(version).display().to_string());
    let schema = match set.get(version) {
        Ok(s) => s,
        Err(why) => return XsdReport::skipped(why, shown),
    };
    match schema.validate(bytes, name) {
        Ok(errors) => XsdReport { checked: true, reason: None, schema: shown, valid: Some(errors.is_empty()), errors },
        Err(e) => XsdReport::skipped(e.to_string(), shown),
    }
}

/// Objects are read one by one and checked in parallel batches: memory stays bounded. Also
/// returns the document's srsName.
fn check_geometry(
    bytes: &[u8],
    opts: &Options,
    mut frame: Option<&mut dyn ObjectFrame>,
    progress: &dyn Fn(Progress),
) -> Result<(GeometryReport, Option<String>), ReadError> {
    let mut stream = ObjectStream::new(bytes)?;
    let mut findings = Vec::new();
    let mut batch = Vec::new();
    let mut features = 0usize;
    while let Some(obj) = stream.next() {
        let mut obj = obj?;
        if let Some(f) = frame.as_deref_mut() {
            let srs = stream.srs_name();
            f.apply(srs.as_deref(), &mut obj).map_err(|message| ReadError {
                line: obj.span.line,
                column: obj.span.column,
                byte: obj.span.bytes.start,
                message,
            })?;
        }
        batch.push(obj);
        if batch.len() == 256 {
            features += batch.len();
            findings.extend(validate_objects(&batch, opts));
            batch.clear();
            progress(Progress { features, bytes_read: stream.consumed() });
        }
    }
    features += batch.len();
    findings.extend(validate_objects(&batch, opts));
    add_unresolved_xlinks(&mut findings, stream.unresolved_xlinks());
    sort_findings(&mut findings);
    let described = frame.as_deref().and_then(|f| f.describe());
    let report = GeometryReport {
        checked: true,
        options: *opts,
        features,
        valid: Some(findings.is_empty()),
        findings,
        frame: described,
    };
    Ok((report, stream.srs_name()))
}

/// Counts over many reports, for the summary of a many-file run.
#[derive(Debug, Default, Clone, Serialize)]
pub struct Summary {
    pub files: usize,
    pub valid: usize,
    pub invalid: usize,
    /// Files that could not be read (or whose schema could not be loaded): no report.
    pub unreadable: usize,
    /// Findings per code over all files: val3dity codes for the geometry, `xsd` for schema
    /// errors, `not_well_formed` for XML syntax errors.
    pub errors: std::collections::BTreeMap<String, usize>,
    pub wall_seconds: f64,
}

impl Summary {
    pub fn add_report(&mut self, r: &Report) {
        self.files += 1;
        if r.valid {
            self.valid += 1;
        } else {
            self.invalid += 1;
        }
        for e in &r.xsd.errors {
            let key = match e.kind {
                XsdErrorKind::Invalid => "xsd",
                XsdErrorKind::NotWellFormed => "not_well_formed",
            };
            *self.errors.entry(key.to_string()).or_default() += 1;
        }
        for f in &r.geometry.findings {
            *self.errors.entry(f.code.to_string()).or_default() += 1;
        }
    }

    pub fn add_unreadable(&mut self) {
        self.files += 1;
        self.unreadable += 1;
    }
}
