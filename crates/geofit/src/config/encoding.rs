//! CityJSON at the edges of the buildings commands (issue 38): an input that is CityJSON or
//! CityJSONSeq (by content, not extension) is handed to the command as CityGML 2.0 text, and
//! a document the command writes goes back out in the input's encoding (or the one `-o`'s
//! extension names). The commands themselves only ever see CityGML
//! (docs/decisions.md#cityjson-at-the-edges).

use std::io::BufReader;
use std::path::Path;
use std::sync::Mutex;

use cityjson_io::{GmlOptions, Report, Transform, WriteOptions};
use input_limits::mapped::InputBytes;
use serde_json::Value;

use super::output::Output;
use crate::error::CliError;

/// The encodings of a buildings document (named as their formats are, hence the shared prefix).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(clippy::enum_variant_names)]
pub enum Encoding {
    CityGml,
    CityJson,
    CityJsonSeq,
}

impl Encoding {
    /// From the first bytes (`None`: not CityJSON, left to the CityGML reader).
    pub fn of_bytes(bytes: &[u8]) -> Encoding {
        if file_kind::sniff(&bytes[..bytes.len().min(file_kind::HEAD_BYTES)]) != file_kind::FileKind::CityJson
            && !starts_cityjson(bytes)
        {
            return Encoding::CityGml;
        }
        if cityjson_io::is_seq(bytes) {
            Encoding::CityJsonSeq
        } else {
            Encoding::CityJson
        }
    }

    /// From an output name: `.jsonl` CityJSONSeq, `.json` CityJSON, anything else CityGML.
    pub fn of_path(path: &Path) -> Option<Encoding> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        if name.ends_with(".jsonl") {
            Some(Encoding::CityJsonSeq)
        } else if name.ends_with(".json") {
            Some(Encoding::CityJson)
        } else if [".gml", ".xml", ".citygml"].iter().any(|e| name.ends_with(e)) {
            Some(Encoding::CityGml)
        } else {
            None
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Encoding::CityGml => "CityGML",
            Encoding::CityJson => "CityJSON 2.0",
            Encoding::CityJsonSeq => "CityJSONSeq",
        }
    }
}

/// A head whose first line is longer than the sniff window still names itself early.
fn starts_cityjson(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(4096)];
    let s: String = String::from_utf8_lossy(head).chars().filter(|c| !c.is_whitespace()).collect();
    s.starts_with('{') && s.contains("\"type\":\"CityJSON\"")
}

/// The CityJSON input of this run, kept for the write-back: its encoding, its transform and
/// (a whole document) the parsed original whose attributes and metadata go back out.
struct Remembered {
    encoding: Encoding,
    original: Option<Value>,
}

static INPUT: Mutex<Option<Remembered>> = Mutex::new(None);

fn remember(encoding: Encoding, original: Option<Value>) {
    if let Ok(mut g) = INPUT.lock() {
        *g = Some(Remembered { encoding, original });
    }
}

/// Says once on stderr what the CityGML view of a CityJSON input leaves out.
fn notice(name: &str, report: &Report) {
    if report.is_empty() {
        return;
    }
    let lines = report.lines();
    crate::say!("geofit: {name}: read as CityGML; not carried: {}", lines.join("; "));
}

fn read_error(name: &str, e: cityjson_io::CityJsonError) -> CliError {
    CliError::unreadable(format!("{name}:{e}"))
}

/// A buildings input as the commands read it: CityGML as it is, CityJSON converted (the
/// original remembered for [`write_document`]).
pub fn as_citygml(name: &str, bytes: Vec<u8>) -> Result<Vec<u8>, CliError> {
    let encoding = Encoding::of_bytes(&bytes);
    if encoding == Encoding::CityGml {
        return Ok(bytes);
    }
    let (gml, report) = cityjson_io::to_citygml(&bytes, GmlOptions::default()).map_err(|e| read_error(name, e))?;
    notice(name, &report);
    let original = (encoding == Encoding::CityJson).then(|| serde_json::from_slice(&bytes).ok()).flatten();
    remember(encoding, original);
    Ok(gml)
}

/// A CityJSONSeq file converted line by line into an unlinked temporary file, then mapped: the
/// command streams the CityGML while memory holds one feature
/// (docs/decisions.md#cityjson-seq-streaming).
pub fn map_seq_as_citygml(name: &str, path: &Path) -> Result<InputBytes, CliError> {
    let unreadable = |e: std::io::Error| CliError::unreadable(format!("{name}: {e}"));
    let file = std::fs::File::open(path).map_err(unreadable)?;
    let tmp = tempfile::tempfile().map_err(|e| CliError::internal(format!("temporary file: {e}")))?;
    let w = std::io::BufWriter::with_capacity(1 << 16, tmp);
    let (w, report, _) =
        cityjson_io::seq::seq_to_citygml(BufReader::with_capacity(1 << 16, file), w, GmlOptions::default())
            .map_err(|e| read_error(name, e))?;
    notice(name, &report);
    remember(Encoding::CityJsonSeq, None);
    let tmp = w.into_inner().map_err(|e| CliError::internal(format!("temporary file: {}", e.error())))?;
    InputBytes::map(&tmp).map_err(unreadable)
}

/// Writes a CityGML document a command made in the encoding of its CityJSON input, or the one
/// `-o`'s extension names (`.json`, `.jsonl`); CityGML otherwise.
pub fn write_document(output: &Output, citygml: &[u8]) -> Result<(), CliError> {
    let remembered = INPUT.lock().ok().and_then(|mut g| g.take());
    let by_path = output.path().and_then(Encoding::of_path);
    let encoding = by_path.or(remembered.as_ref().map(|r| r.encoding)).unwrap_or(Encoding::CityGml);
    if encoding == Encoding::CityGml {
        return output.write_bytes(citygml);
    }
    let original = remembered.and_then(|r| r.original);
    let transform = original
        .as_ref()
        .and_then(|o| Transform::from_json(o.get("transform")).ok())
        .filter(|t| *t != Transform::default());
    let opts = WriteOptions { transform, ..WriteOptions::default() };
    let (bytes, report) = encode(citygml, encoding, &opts, original.as_ref())?;
    if !report.is_empty() {
        crate::say!("geofit: written as {}; not carried: {}", encoding.describe(), report.lines().join("; "));
    }
    output.write_bytes(&bytes)
}

/// CityGML text → the bytes of `to` (compact CityJSON; CityJSONSeq one feature per line) and
/// the report of what `to` cannot hold.
pub fn encode(
    citygml: &[u8],
    to: Encoding,
    opts: &WriteOptions,
    original: Option<&Value>,
) -> Result<(Vec<u8>, Report), CliError> {
    let internal = |e: cityjson_io::CityJsonError| CliError::internal(format!("writing {}: {e}", to.describe()));
    match to {
        Encoding::CityGml => Ok((citygml.to_vec(), Report::default())),
        Encoding::CityJsonSeq => {
            let (out, report, _) = cityjson_io::seq::citygml_to_seq(citygml, opts, Vec::new()).map_err(internal)?;
            Ok((out, report))
        }
        Encoding::CityJson => {
            let (mut doc, report) = cityjson_io::from_citygml(citygml, opts).map_err(internal)?;
            if let Some(o) = original {
                cityjson_io::overlay_original(&mut doc, o);
            }
            Ok((cityjson_io::to_vec(&doc), report))
        }
    }
}

/// `convert`: `raw` (of encoding `from`) → the bytes of `to`, through CityGML 2.0 text when
/// both are CityJSON; the report joins what every step could not carry.
pub fn convert(
    name: &str,
    raw: &[u8],
    from: Encoding,
    to: Encoding,
    precision: f64,
) -> Result<(Vec<u8>, Report), CliError> {
    let mut report = Report::default();
    let opts = WriteOptions { scale: precision, transform: None };
    if from == Encoding::CityGml {
        // Read errors of the CityGML reader are the input's (exit 3), not internal ones.
        citygml_io::ObjectStream::new(raw).map_err(|e| CliError::unreadable(format!("{name}:{e}")))?;
        let (out, r) =
            encode(raw, to, &opts, None).map_err(|e| CliError::unreadable(format!("{name}: {}", e.message)))?;
        report.merge(r);
        return Ok((out, report));
    }
    let strict = to == Encoding::CityGml;
    let (gml, r) = cityjson_io::to_citygml(raw, GmlOptions { strict }).map_err(|e| read_error(name, e))?;
    // CityJSON to CityJSON keeps what CityGML cannot type (booleans, nulls, metadata), as a
    // write-back does.
    let original: Option<Value> =
        (from == Encoding::CityJson && to == Encoding::CityJson).then(|| serde_json::from_slice(raw).ok()).flatten();
    if original.is_none() {
        report.merge(r);
    }
    let (out, r) = encode(&gml, to, &opts, original.as_ref())?;
    report.merge(r);
    Ok((out, report))
}
