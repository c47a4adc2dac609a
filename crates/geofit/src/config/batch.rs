//! Many inputs in one call: directories and globs expanded, files processed in parallel and
//! reported in input order, the worst exit code kept.

use std::io::Write;

use super::Output;
use super::{Config, Input};
use crate::error::CliError;

/// What a directory argument is searched for by the commands that take many CityGML files.
pub const CITYGML_EXTENSIONS: &[&str] = &["gml", "xml", "citygml"];

/// The inputs of a many-file call (files, directories searched for `dir_exts`, glob patterns,
/// `-`), in order; a pattern or directory that names no file is a usage error.
pub fn batch_inputs(args: &[String], dir_exts: &[&str]) -> Result<Vec<Input>, CliError> {
    let sources = file_batch::expand(args, dir_exts).map_err(|e| CliError::usage(e.to_string()))?;
    Ok(sources
        .into_iter()
        .map(|s| match s {
            file_batch::Source::Stdin => Input::Stdin,
            file_batch::Source::Path(p) => Input::Path(p),
        })
        .collect())
}

/// The exit status of a run over many files: the worse of two, by code (4 internal failure,
/// 3 unreadable input, 2 usage, 1 findings, 0 success).
pub fn worse_exit(a: crate::error::Exit, b: crate::error::Exit) -> crate::error::Exit {
    if (b as u8) > (a as u8) {
        b
    } else {
        a
    }
}

/// Runs a many-file command: `work` on every input in parallel ([`file_batch::run_ordered`]),
/// `emit` with each result on stdout's writer in input order (a panic in `work` arrives as an
/// internal error for that input alone; every error is also said on stderr), then `finish`
/// (the summary). Once stdout fails (`| head`) no further input is started and the write
/// error is returned.
pub fn run_batch<R: Send>(
    inputs: Vec<Input>,
    stage: &str,
    config: &Config,
    work: impl Fn(&Input) -> Result<R, CliError> + Sync,
    mut emit: impl FnMut(&mut dyn Write, &str, Result<R, CliError>) -> Result<(), CliError>,
    finish: impl FnOnce(&mut dyn Write) -> Result<(), CliError>,
) -> Result<(), CliError> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let names: Vec<String> = inputs.iter().map(Input::display_name).collect();
    let progress = config.progress(stage, names.len() as u64);
    let stop = AtomicBool::new(false);
    Output::Stdout.write_with(|w| {
        let mut failed: Option<CliError> = None;
        file_batch::run_ordered(
            inputs,
            |input| (!stop.load(Ordering::Relaxed)).then(|| work(&input)),
            |i, result| {
                let result = match result {
                    Ok(Some(r)) => r,
                    Ok(None) => return,
                    Err(p) => Err(CliError::internal(format!("{}: internal error: {}", names[i], p.0))),
                };
                if let Err(e) = &result {
                    crate::say!("geofit: error: {}", e.message);
                }
                progress.set(i as u64 + 1, "");
                if failed.is_some() {
                    return;
                }
                if let Err(e) = emit(w, &names[i], result).and_then(|()| w.flush().map_err(CliError::io_out)) {
                    stop.store(true, Ordering::Relaxed);
                    failed = Some(e);
                }
            },
        );
        match failed {
            Some(e) => Err(e),
            None => finish(w),
        }
    })?;
    progress.finish(&format!("{} files", names.len()));
    Ok(())
}

/// The line a many-file run writes for an input it could not check: JSON
/// `{"schema", "file", "error", "exit"}`, or text `FILE: UNREADABLE: message` (`ERROR` for
/// other failures).
pub fn write_batch_error(
    w: &mut dyn Write,
    json: bool,
    schema: &str,
    name: &str,
    e: &CliError,
) -> Result<(), CliError> {
    if json {
        let line = serde_json::json!({ "schema": schema, "file": name, "error": e.message, "exit": e.exit as u8 });
        return write_json_line(w, &line);
    }
    let what = if e.exit == crate::error::Exit::Unreadable { "UNREADABLE" } else { "ERROR" };
    writeln!(w, "{name}: {what}: {}", e.message).map_err(CliError::io_out)
}

/// One compact JSON value and a newline (JSON lines).
pub fn write_json_line<T: serde::Serialize>(w: &mut dyn Write, value: &T) -> Result<(), CliError> {
    serde_json::to_writer(&mut *w, value).map_err(|e| CliError::internal(e.to_string()))?;
    w.write_all(b"\n").map_err(CliError::io_out)
}
