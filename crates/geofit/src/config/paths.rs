//! The checks of a command line's paths before any work (issue 41, "exit 0 means right"):
//! an output naming an input, an `-o` extension the command does not write, and an input of
//! a kind the command does not read. Each is refused in one line naming the fix, so a typo
//! never replaces the user's data and a wrong file never gets as far as a reader's puzzling
//! message (docs/decisions.md#paths-checked-before-the-work-issue-41).

use std::path::Path;

use file_kind::FileKind;

use crate::error::CliError;

/// The subcommand's name as typed (`fit`, `tile stitch`) and its own matches.
pub fn leaf(matches: &clap::ArgMatches) -> (String, &clap::ArgMatches) {
    let mut names = Vec::new();
    let mut m = matches;
    while let Some((name, sub)) = m.subcommand() {
        names.push(name);
        m = sub;
    }
    (names.join(" "), m)
}

/// The string values of an argument, whatever its arity (none for flags and numbers that
/// clap does not store as strings).
fn string_values<'a>(m: &'a clap::ArgMatches, id: &str) -> Vec<&'a str> {
    match m.try_get_many::<String>(id) {
        Ok(Some(values)) => values.map(String::as_str).collect(),
        _ => Vec::new(),
    }
}

/// Refuses an output that is one of the inputs (the same file by device and inode: the same
/// path, a hard link or a symlink to it). The atomic writer would otherwise replace the input
/// with the output, as `fit g2.tif -o g2.tif` did.
pub fn check_outputs_are_not_inputs(matches: &clap::ArgMatches, outputs: &[(&str, &str)]) -> Result<(), CliError> {
    let (command, m) = leaf(matches);
    let output_ids: Vec<&str> = outputs.iter().map(|(id, _)| *id).collect();
    let inputs: Vec<(&str, &str)> = m
        .ids()
        .map(|id| id.as_str())
        .filter(|id| !output_ids.contains(id))
        .flat_map(|id| string_values(m, id).into_iter().map(move |v| (id, v)))
        .filter(|(_, v)| *v != "-")
        .collect();
    check_outputs_are_distinct(&command, m, outputs)?;
    for (id, flag) in outputs {
        for out in string_values(m, id).into_iter().filter(|v| *v != "-") {
            if let Some((arg, input)) = inputs.iter().find(|(_, input)| same_file(Path::new(input), Path::new(out))) {
                let how = if *input == out { String::new() } else { format!(", the same file as {out}") };
                return Err(CliError::usage(format!(
                    "{command}: {flag} {out} names the input {input} ({arg}{how}): the output would replace it; write to another file"
                )));
            }
        }
    }
    Ok(())
}

/// Refuses two outputs of one command naming one file (`-o out.json --report out.json`): the
/// second write would replace the first. Paths are compared by their directory's canonical
/// form and the file name, so they need not exist yet; devices (`/dev/null`) may repeat.
fn check_outputs_are_distinct(command: &str, m: &clap::ArgMatches, outputs: &[(&str, &str)]) -> Result<(), CliError> {
    let mut seen: Vec<(std::path::PathBuf, &str, &str)> = Vec::new();
    for (id, flag) in outputs {
        for out in string_values(m, id).into_iter().filter(|v| *v != "-" && !is_device(Path::new(v))) {
            let path = Path::new(out);
            let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
            let Some(key) = dir.canonicalize().ok().zip(path.file_name()).map(|(d, n)| d.join(n)) else { continue };
            if let Some((_, other_flag, other)) = seen.iter().find(|(k, _, _)| *k == key) {
                return Err(CliError::usage(format!(
                    "{command}: {other_flag} {other} and {flag} {out} name one file: give each output its own"
                )));
            }
            seen.push((key, flag, out));
        }
    }
    Ok(())
}

/// An existing target that is neither a regular file nor a directory (`/dev/null`, a FIFO).
fn is_device(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// Whether two paths are one file (device and inode, symlinks followed). Paths that do not
/// both exist are not the same file; `/dev/null`, `/dev/stdout` and other character devices
/// as an output are never an input's replacement.
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{FileTypeExt, MetadataExt};
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(ma), Ok(mb)) => !mb.file_type().is_char_device() && ma.dev() == mb.dev() && ma.ino() == mb.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
    }
}

/// The one format each document-writing command writes to `-o`, by the extensions that name it.
/// Raster outputs are GDAL's (driver from the extension, `-of`), meshes are checked by their
/// commands (`export`, `surface`, `implicit`), so they are not listed.
const OUTPUT_EXTENSIONS: &[(&str, &str, &[&str])] = &[
    ("fit", "a T-mesh", &["tmesh", "tmb", "xml"]),
    ("tile stitch", "a T-mesh", &["tmesh", "tmb", "xml"]),
    ("heal", "CityGML or CityJSON", &["gml", "xml", "citygml", "json", "jsonl"]),
    ("convert", "CityGML or CityJSON", &["gml", "xml", "citygml", "json", "jsonl"]),
    ("popa3d2citygml", "CityGML", &["gml", "xml", "citygml"]),
    ("citygml2popa3d", "a popa3d model", &["popa3d", "xml"]),
    ("obj2popa3d", "a popa3d model", &["popa3d", "xml"]),
    ("adjust", "a popa3d model", &["popa3d", "xml"]),
    ("observe", "a popa3d model", &["popa3d", "xml"]),
    ("tile report", "a JSON report", &["json"]),
    ("tile seams", "a JSON report", &["json"]),
    ("tile tileset", "a 3D Tiles tileset (JSON)", &["json"]),
];

/// Refuses an `-o` whose extension names another format than the command writes (`fit -o
/// x.tif` wrote T-mesh XML into a `.tif`). A name without an extension (`/dev/null`, `out`)
/// is taken as it is.
pub fn check_output_extension(matches: &clap::ArgMatches) -> Result<(), CliError> {
    let (command, m) = leaf(matches);
    let Some((_, what, extensions)) = OUTPUT_EXTENSIONS.iter().find(|(c, _, _)| *c == command) else { return Ok(()) };
    for out in string_values(m, "output").into_iter().filter(|v| *v != "-") {
        let Some(ext) = Path::new(out).extension().map(|e| e.to_string_lossy().to_ascii_lowercase()) else { continue };
        if !extensions.contains(&ext.as_str()) {
            let names: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
            return Err(CliError::usage(format!(
                "{command}: -o {out}: {command} writes {what} ({}), not a .{ext} file",
                names.join(", ")
            )));
        }
    }
    Ok(())
}

/// What a command's input argument takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Takes {
    /// CityGML (an XML document the CityGML reader judges), directories for many-file runs.
    CityGml,
    /// CityGML or a T-mesh (`export`).
    CityGmlOrTMesh,
    Popa3d,
    TMesh,
    /// Whatever GDAL opens.
    Raster,
    /// XYZ/CSV text or LAS/LAZ.
    Points,
    Obj,
    /// `info`: any kind geofit summarises.
    Summarisable,
}

/// The input arguments each command reads, by argument id. Inputs not listed (implicit
/// models, plans, reports) are left to their readers.
const INPUTS: &[(&str, &str, Takes)] = &[
    ("info", "inputs", Takes::Summarisable),
    ("validate", "inputs", Takes::CityGml),
    ("heal", "input", Takes::CityGml),
    ("convert", "input", Takes::CityGml),
    ("citygml2popa3d", "input", Takes::CityGml),
    ("export", "input", Takes::CityGmlOrTMesh),
    ("popa3d2citygml", "input", Takes::Popa3d),
    ("popa3d2citygml", "template", Takes::CityGml),
    ("adjust", "input", Takes::Popa3d),
    ("observe", "input", Takes::Popa3d),
    ("obj2popa3d", "input", Takes::Obj),
    ("fit", "input", Takes::Raster),
    ("warp", "input", Takes::Raster),
    ("unwarp", "input", Takes::Raster),
    ("diff", "a", Takes::Raster),
    ("diff", "b", Takes::Raster),
    ("tile stitch", "source", Takes::Raster),
    ("eval", "mesh", Takes::TMesh),
    ("eval", "like", Takes::Raster),
    ("surface", "mesh", Takes::TMesh),
    ("rasterize", "input", Takes::Points),
];

/// Refuses (exit 3) an input file whose first bytes show a kind its command does not read,
/// naming what it is and the commands that take it. Unknown kinds, stdin, GDAL virtual paths
/// and missing files are left to the command's reader and its own message.
pub fn check_input_kinds(matches: &clap::ArgMatches) -> Result<(), CliError> {
    let (command, m) = leaf(matches);
    for (_, id, takes) in INPUTS.iter().filter(|(c, _, _)| *c == command) {
        for value in string_values(m, id) {
            let path = Path::new(value);
            if value == "-" || raster_io::gdal_io::is_gdal_virtual_path(path) {
                continue;
            }
            let Ok(kind) = file_kind::sniff_path(path) else { continue };
            if !accepts(*takes, &kind, path) {
                return Err(CliError::unreadable(format!(
                    "{command}: {value} is {}; {command} reads {}{}",
                    kind.describe(),
                    takes_what(*takes),
                    hint(&kind, value)
                )));
            }
        }
    }
    Ok(())
}

fn accepts(takes: Takes, kind: &FileKind, path: &Path) -> bool {
    use FileKind as K;
    match kind {
        K::Unknown => true,
        K::Device(_) | K::Gltf | K::Zip | K::Gzip => false,
        // Converted to CityGML at input (docs/decisions.md#cityjson-at-the-edges).
        K::CityJson => matches!(takes, Takes::CityGml | Takes::CityGmlOrTMesh | Takes::Summarisable),
        // The XML and text readers locate these themselves (`empty.gml:1:1: empty file`);
        // GDAL and the point reader do not.
        K::Empty => !matches!(takes, Takes::Raster | Takes::Points),
        K::Directory => match takes {
            Takes::CityGml | Takes::Summarisable => true,
            // An Arc/Info binary grid is a directory GDAL opens.
            Takes::Raster => path.join("hdr.adf").exists(),
            _ => false,
        },
        K::CityGml => matches!(takes, Takes::CityGml | Takes::CityGmlOrTMesh | Takes::Summarisable),
        // The CityGML reader names a wrong root or namespace with its line; GDAL opens XML
        // rasters (VRT); the other readers say what they expected.
        K::Xml(_) => !matches!(takes, Takes::Points | Takes::Obj),
        K::Popa3d => takes == Takes::Popa3d,
        K::TMesh => matches!(takes, Takes::TMesh | Takes::CityGmlOrTMesh | Takes::Summarisable),
        K::Raster(_) => matches!(takes, Takes::Raster | Takes::Summarisable),
        K::Las => matches!(takes, Takes::Points | Takes::Summarisable),
        // GDAL reads XYZ grids; an OBJ-looking text of numbers only is point text too.
        K::PointText => matches!(takes, Takes::Points | Takes::Raster | Takes::Summarisable | Takes::Obj),
        K::Obj => takes == Takes::Obj,
        // Unknown binary formats may still be GDAL rasters (ERDAS .img, ENVI); the XML readers
        // say "1:1: not an XML document".
        K::Binary => takes != Takes::Points,
        K::Json => takes == Takes::Raster,
    }
}

fn takes_what(takes: Takes) -> &'static str {
    match takes {
        Takes::CityGml => "CityGML (1.0, 2.0, 3.0) or CityJSON (2.0, 1.1, CityJSONSeq)",
        Takes::CityGmlOrTMesh => "CityGML, CityJSON or a T-mesh",
        Takes::Popa3d => "a popa3d model (made by citygml2popa3d or obj2popa3d)",
        Takes::TMesh => "a T-mesh (.tmesh or .tmb, made by fit)",
        Takes::Raster => "a raster GDAL opens (GeoTIFF, netCDF, BAG, ASCII grid, ...)",
        Takes::Points => "point text (XYZ/CSV) or LAS/LAZ",
        Takes::Obj => "an OBJ sketch",
        Takes::Summarisable => "CityGML, CityJSON, T-meshes, rasters and point files",
    }
}

/// What to do with a file of this kind: the commands that read it, or how to make it readable.
fn hint(kind: &FileKind, value: &str) -> String {
    use FileKind as K;
    let commands = match kind {
        K::CityGml | K::CityJson => "validate, heal, export, citygml2popa3d, convert, info",
        K::Popa3d => "adjust, observe, popa3d2citygml",
        K::TMesh => "eval, surface, export, info",
        K::Raster(_) => "fit, warp, unwarp, diff, info",
        K::Las | K::PointText => "rasterize, info, implicit",
        K::Obj => "obj2popa3d",
        K::Gltf => return " (glTF is what export and surface write; geofit does not read it)".into(),
        K::Gzip => {
            return format!(
            " (decompress it first: gunzip -c {value} | geofit ... -, or for a raster give GDAL's /vsigzip/{value})"
        )
        }
        K::Zip => return format!(" (unzip it first, or for a raster give GDAL's /vsizip/{value}/NAME)"),
        K::Empty => return " (the file holds nothing: did an earlier step fail?)".into(),
        K::Directory => return " (give a file in it)".into(),
        _ => return String::new(),
    };
    format!(" (read it with geofit {commands})")
}

#[cfg(test)]
#[path = "paths_tests.rs"]
mod tests;
