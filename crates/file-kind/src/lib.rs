//! What kind of file an input is, from its first bytes.
//!
//! A command given the wrong kind of file used to fail deep in a reader with a message about
//! the reader ("cannot decode input using UTF-8", `x = "<core:CityModel" is not a number`,
//! "GDAL call GDALOpenEx failed"). Looking at the first bytes before the work lets the command
//! say what the file is and which command takes it. The sniff is deliberately conservative:
//! it names a kind only on a signature (magic bytes, an XML root element, a JSON `"type"`) or
//! on lines that leave no doubt (numbers only, OBJ keywords); anything else is
//! [`FileKind::Unknown`] and left to the command's own reader.
//!
//! # Examples
//!
//! ```
//! use file_kind::{sniff, FileKind};
//! let gml = b"<?xml version=\"1.0\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\">";
//! assert_eq!(sniff(gml), FileKind::CityGml);
//! assert_eq!(sniff(b"II*\0\x08\0\0\0"), FileKind::Raster("TIFF/GeoTIFF"));
//! assert_eq!(sniff(b"{\"type\": \"CityJSON\", \"version\": \"2.0\"}"), FileKind::CityJson);
//! assert_eq!(sniff(b"x;y;z\n341000,5;5724000,25;12,5\n"), FileKind::PointText);
//! assert_eq!(sniff(b"# rooms\nv 0 0 0\nv 1 0 0\nf 1 2 3\n"), FileKind::Obj);
//! assert_eq!(sniff(b""), FileKind::Empty);
//! ```

use std::io::Read;
use std::path::Path;

/// How many bytes of a file the sniff reads.
pub const HEAD_BYTES: usize = 64 * 1024;

/// The kinds of file geofit meets, as far as their first bytes tell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileKind {
    /// XML whose root element is `CityModel` (CityGML 1.0–3.0).
    CityGml,
    /// JSON of `"type": "CityJSON"` or `"CityJSONFeature"` (a CityJSON file or CityJSONSeq).
    CityJson,
    /// geofit's plane-parameterised building model (`<popa3d>`).
    Popa3d,
    /// A T-mesh: XML `<tmesh>` or the binary `.tmb`.
    TMesh,
    /// Other XML, with its root element's local name.
    Xml(String),
    /// A raster format GDAL reads, named.
    Raster(&'static str),
    /// An ASPRS LAS/LAZ point cloud.
    Las,
    /// A Wavefront OBJ mesh.
    Obj,
    /// A glTF model (`.glb` or `.gltf` JSON).
    Gltf,
    /// Lines of numbers (XYZ/CSV soundings, after an optional header).
    PointText,
    /// Other JSON.
    Json,
    /// gzip-compressed data.
    Gzip,
    /// A zip archive.
    Zip,
    /// No bytes at all.
    Empty,
    /// A directory.
    Directory,
    /// A device such as `/dev/zero` (named): endless or empty bytes, never a data file.
    Device(String),
    /// Binary data of no kind above (NUL bytes).
    Binary,
    /// Text of no kind above: the command's reader decides.
    Unknown,
}

impl FileKind {
    /// The kind in words, for messages: "a CityGML document", "a TIFF/GeoTIFF raster".
    pub fn describe(&self) -> String {
        match self {
            FileKind::CityGml => "a CityGML document".into(),
            FileKind::CityJson => "a CityJSON file".into(),
            FileKind::Popa3d => "a popa3d model".into(),
            FileKind::TMesh => "a T-mesh".into(),
            FileKind::Xml(root) => format!("an XML document with root element <{root}>"),
            FileKind::Raster(format) => format!("a {format} raster"),
            FileKind::Las => "a LAS/LAZ point cloud".into(),
            FileKind::Obj => "an OBJ mesh".into(),
            FileKind::Gltf => "a glTF model".into(),
            FileKind::PointText => "point text (lines of numbers)".into(),
            FileKind::Json => "a JSON document".into(),
            FileKind::Gzip => "gzip-compressed".into(),
            FileKind::Zip => "a zip archive".into(),
            FileKind::Empty => "empty (0 bytes)".into(),
            FileKind::Directory => "a directory".into(),
            FileKind::Device(name) => format!("the device {name}, not a data file"),
            FileKind::Binary => "binary data of no kind geofit reads".into(),
            FileKind::Unknown => "of no kind geofit recognises".into(),
        }
    }
}

/// The kind of the file at `path`. Only regular files are read (at most [`HEAD_BYTES`]): a
/// pipe, a terminal or `/dev/stdin` is [`FileKind::Unknown`], since reading would take bytes
/// from the command. Memory devices (`/dev/zero`, `/dev/null`, `/dev/urandom`) are named.
pub fn sniff_path(path: &Path) -> std::io::Result<FileKind> {
    let meta = std::fs::metadata(path)?;
    if meta.is_dir() {
        return Ok(FileKind::Directory);
    }
    if is_memory_device(&meta) {
        return Ok(FileKind::Device(path.display().to_string()));
    }
    if !meta.is_file() {
        return Ok(FileKind::Unknown);
    }
    let mut head = Vec::with_capacity(HEAD_BYTES.min(meta.len() as usize));
    std::fs::File::open(path)?.take(HEAD_BYTES as u64).read_to_end(&mut head)?;
    Ok(sniff_head(&head, head.len() < HEAD_BYTES))
}

/// Linux's memory character devices (major 1: null, zero, full, random, urandom, ...).
#[cfg(unix)]
fn is_memory_device(meta: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::{FileTypeExt, MetadataExt};
    meta.file_type().is_char_device() && (meta.rdev() >> 8) & 0xfff == 1
}

#[cfg(not(unix))]
fn is_memory_device(_meta: &std::fs::Metadata) -> bool {
    false
}

/// The kind of a whole file given as bytes (see [`sniff_path`] for a file on disk).
pub fn sniff(bytes: &[u8]) -> FileKind {
    sniff_head(&bytes[..bytes.len().min(HEAD_BYTES)], bytes.len() <= HEAD_BYTES)
}

/// The kind from the first bytes; `complete` says whether they are the whole file (else the
/// last, possibly cut, line is not looked at).
fn sniff_head(head: &[u8], complete: bool) -> FileKind {
    if head.is_empty() {
        return FileKind::Empty;
    }
    if let Some(kind) = by_magic(head) {
        return kind;
    }
    let text = head.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(head);
    let start = text.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(text.len());
    let text = &text[start..];
    // XML and JSON are named by their start; what follows is their reader's to judge.
    match text.first() {
        Some(b'<') => xml_kind(text),
        Some(b'{') => json_kind(text),
        _ if text[..text.len().min(4096)].contains(&0) => FileKind::Binary,
        _ => text_kind(text, complete),
    }
}

/// Signatures at the start of the file.
fn by_magic(head: &[u8]) -> Option<FileKind> {
    const MAGIC: &[(&[u8], FileKind)] = &[
        (b"\x89TMB", FileKind::TMesh),
        (b"II*\0", FileKind::Raster("TIFF/GeoTIFF")),
        (b"MM\0*", FileKind::Raster("TIFF/GeoTIFF")),
        (b"II+\0", FileKind::Raster("BigTIFF")),
        (b"MM\0+", FileKind::Raster("BigTIFF")),
        (b"\x89PNG", FileKind::Raster("PNG")),
        (b"CDF\x01", FileKind::Raster("netCDF")),
        (b"CDF\x02", FileKind::Raster("netCDF")),
        (b"CDF\x05", FileKind::Raster("netCDF")),
        (b"\x89HDF\r\n\x1a\n", FileKind::Raster("HDF5 (netCDF-4, BAG)")),
        (b"\xff\xd8\xff", FileKind::Raster("JPEG")),
        (b"DSBB", FileKind::Raster("Surfer grid")),
        (b"DSRB", FileKind::Raster("Surfer grid")),
        (b"DSAA", FileKind::Raster("Surfer grid")),
        (b"LASF", FileKind::Las),
        (b"glTF", FileKind::Gltf),
        (b"\x1f\x8b", FileKind::Gzip),
        (b"PK\x03\x04", FileKind::Zip),
    ];
    MAGIC.iter().find(|(magic, _)| head.starts_with(magic)).map(|(_, kind)| kind.clone())
}

/// The root element of an XML document (after declarations, comments and a DOCTYPE).
fn xml_kind(text: &[u8]) -> FileKind {
    let Some(root) = root_element(text) else { return FileKind::Unknown };
    let local = root.rsplit(':').next().unwrap_or(&root);
    match local {
        "CityModel" => FileKind::CityGml,
        "popa3d" => FileKind::Popa3d,
        "tmesh" => FileKind::TMesh,
        _ => FileKind::Xml(root.clone()),
    }
}

/// The qualified name of the first element, `None` when the head holds none.
fn root_element(mut text: &[u8]) -> Option<String> {
    loop {
        let at = text.iter().position(|&b| b == b'<')?;
        text = &text[at..];
        let skip_to = |end: &[u8]| text.windows(end.len()).position(|w| w == end).map(|p| p + end.len());
        let after = if text.starts_with(b"<?") {
            skip_to(b"?>")?
        } else if text.starts_with(b"<!--") {
            skip_to(b"-->")?
        } else if text.starts_with(b"<!") {
            skip_to(b">")?
        } else {
            let name: Vec<u8> = text[1..]
                .iter()
                .copied()
                .take_while(|b| !b.is_ascii_whitespace() && !matches!(b, b'>' | b'/'))
                .collect();
            return (!name.is_empty()).then(|| String::from_utf8_lossy(&name).into_owned());
        };
        text = &text[after..];
    }
}

/// CityJSON (a file or the first line of a CityJSONSeq), glTF JSON, or other JSON.
fn json_kind(text: &[u8]) -> FileKind {
    let s = String::from_utf8_lossy(&text[..text.len().min(HEAD_BYTES)]);
    let compact: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    if compact.contains("\"type\":\"CityJSON\"") || compact.contains("\"type\":\"CityJSONFeature\"") {
        FileKind::CityJson
    } else if compact.contains("\"asset\":{")
        && ["\"meshes\"", "\"buffers\"", "\"scenes\""].iter().any(|k| compact.contains(k))
    {
        FileKind::Gltf
    } else {
        FileKind::Json
    }
}

/// Text that is not XML or JSON: an ESRI ASCII grid, OBJ, point text, or unknown.
fn text_kind(text: &[u8], complete: bool) -> FileKind {
    let s = String::from_utf8_lossy(text);
    let mut lines: Vec<&str> = s.lines().map(str::trim).collect();
    if !complete && lines.len() > 1 {
        lines.pop();
    }
    let content: Vec<&str> = lines
        .into_iter()
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with('%') && !l.starts_with('>'))
        .take(50)
        .collect();
    let Some(first) = content.first() else { return FileKind::Unknown };
    let keyword = first.split_whitespace().next().unwrap_or("").to_ascii_lowercase();
    if keyword == "ncols" || keyword == "nrows" {
        return FileKind::Raster("ESRI ASCII grid");
    }
    const OBJ_KEYWORDS: &[&str] = &["v", "vn", "vt", "f", "l", "o", "g", "s", "mtllib", "usemtl"];
    if content.iter().all(|l| OBJ_KEYWORDS.contains(&l.split_whitespace().next().unwrap_or(""))) {
        return FileKind::Obj;
    }
    // The first content line may be a header naming the columns.
    let data = if numeric_line(first) { &content[..] } else { &content[1..] };
    if !data.is_empty() && data.iter().all(|l| numeric_line(l)) {
        FileKind::PointText
    } else {
        FileKind::Unknown
    }
}

/// Two or more fields, each a number (decimal point or comma), split by `,` `;` tabs or spaces.
fn numeric_line(line: &str) -> bool {
    let by_strong = line.contains(';') || line.contains('\t');
    let fields: Vec<&str> = if by_strong {
        line.split([';', '\t']).map(str::trim).collect()
    } else {
        line.split(|c: char| c == ',' || c.is_whitespace()).filter(|f| !f.is_empty()).collect()
    };
    fields.len() >= 2 && fields.iter().all(|f| number(f))
}

fn number(field: &str) -> bool {
    let f = field.trim_matches('"');
    !f.is_empty() && f.replacen(',', ".", 1).parse::<f64>().is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xml_roots_after_prolog_and_comments() {
        let popa = b"<?xml version='1.0'?>\n<!-- made by hand -->\n<popa3d xmlns=\"urn:x\" version=\"1\">";
        assert_eq!(sniff(popa), FileKind::Popa3d);
        assert_eq!(sniff(b"<tmesh xmlns=\"urn:geofit:tmesh:1\">"), FileKind::TMesh);
        assert_eq!(sniff(b"<!DOCTYPE x>\n<CityModel>"), FileKind::CityGml);
        assert_eq!(sniff(b"<gml:FeatureCollection>"), FileKind::Xml("gml:FeatureCollection".into()));
        assert_eq!(sniff(b"\xEF\xBB\xBF  <core:CityModel>"), FileKind::CityGml);
    }

    #[test]
    fn magic_bytes() {
        assert_eq!(sniff(b"\x89TMB\r\n\x1a\n\x01"), FileKind::TMesh);
        assert_eq!(sniff(b"\x89PNG\r\n\x1a\n"), FileKind::Raster("PNG"));
        assert_eq!(sniff(b"\x89HDF\r\n\x1a\n"), FileKind::Raster("HDF5 (netCDF-4, BAG)"));
        assert_eq!(sniff(b"LASF\x00\x00"), FileKind::Las);
        assert_eq!(sniff(b"\x1f\x8b\x08\x00"), FileKind::Gzip);
        assert_eq!(sniff(&[0u8; 100]), FileKind::Binary);
        assert_eq!(sniff(b"<CityModel/>\0\0\0"), FileKind::CityGml, "junk after the root is the reader's to find");
    }

    #[test]
    fn text_kinds() {
        assert_eq!(sniff(b"ncols 4\nnrows 3\n"), FileKind::Raster("ESRI ASCII grid"));
        assert_eq!(sniff(b"x,y,z\r\n1.5,2,3\r\n4,5,6\r\n"), FileKind::PointText);
        assert_eq!(sniff(b"1 2 3\n4 5 6\n"), FileKind::PointText);
        assert_eq!(sniff(b"x y z\n"), FileKind::Unknown, "a header alone says nothing");
        assert_eq!(sniff(b"hello world\nthis is prose\n"), FileKind::Unknown);
        assert_eq!(sniff(b"{\"type\":\"FeatureCollection\"}"), FileKind::Json);
        assert_eq!(sniff(b"{\"asset\": {\"version\": \"2.0\"}, \"meshes\": []}"), FileKind::Gltf);
        assert_eq!(sniff(b"{\"type\":\"CityJSONFeature\",\"id\":\"a\"}\n"), FileKind::CityJson);
    }

    #[test]
    fn a_cut_last_line_is_not_judged() {
        let mut head = b"1 2 3\n".repeat(HEAD_BYTES / 6);
        head.extend_from_slice(b"4 5 6\n");
        head.truncate(HEAD_BYTES);
        head.pop();
        head.extend_from_slice(b"x");
        assert_eq!(sniff_head(&head, false), FileKind::PointText);
    }

    #[test]
    fn paths() {
        let dir = std::env::temp_dir();
        assert_eq!(sniff_path(&dir).unwrap(), FileKind::Directory);
        if Path::new("/dev/zero").exists() {
            assert_eq!(sniff_path(Path::new("/dev/zero")).unwrap(), FileKind::Device("/dev/zero".into()));
        }
    }
}
