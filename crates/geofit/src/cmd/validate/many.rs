//! `geofit validate` over many files: checked in parallel with the schemas parsed once.

use std::cell::RefCell;
use std::io::Write;
use std::time::Instant;

use citygml_validate::document::{validate_document_in, Checks, Progress, Report, Summary};
use serde::Serialize;

use super::{document_error, REPORT};
use crate::config::{run_batch, worse_exit, write_batch_error, write_json_line, Config, Input};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::tagged;

/// Version of the JSON lines a many-file run writes (one object per file, then the summary).
const JSON_LINES_SCHEMA: &str = REPORT.schema;

#[derive(Serialize)]
struct SummaryLine<'a> {
    schema: &'static str,
    summary: &'a Summary,
}

/// Reads and checks one file of a many-file run.
fn check_source(input: &Input, checks: &Checks) -> Result<Report, CliError> {
    let bytes = input.map_or_read()?;
    let mut frame = super::frame::GeographicFrame::default();
    validate_document_in(&bytes, &input.display_name(), checks, Some(&mut frame), &|p: Progress| {
        bytes.release_before(p.bytes_read)
    })
    .map_err(document_error)
}

/// Several files: checked in parallel (the schemas parsed once), reported in input order, one
/// block (text) or one line (JSON) per file, then the summary. A file that cannot be read is
/// reported in its place and the others are still checked; the exit status is the worst one.
pub(super) fn run(inputs: Vec<Input>, checks: &Checks, json: bool, config: &Config, started: Instant) -> CmdResult {
    // shared by the per-file and the summary writer
    let summary = RefCell::new(Summary::default());
    let mut worst = Exit::Ok;
    run_batch(
        inputs,
        "validate",
        config,
        |input| check_source(input, checks),
        |w, name, result| {
            let exit = match &result {
                Ok(r) if r.valid => Exit::Ok,
                Ok(_) => Exit::Findings,
                Err(e) => e.exit,
            };
            worst = worse_exit(worst, exit);
            match &result {
                Ok(report) => {
                    summary.borrow_mut().add_report(report);
                    if json {
                        write_json_line(w, &tagged(&REPORT, REPORT.units, report))
                    } else {
                        super::text::write(w, report).map_err(CliError::io_out)
                    }
                }
                Err(e) => {
                    summary.borrow_mut().add_unreadable();
                    write_batch_error(w, json, JSON_LINES_SCHEMA, name, e)
                }
            }
        },
        |w| {
            let mut summary = summary.borrow_mut();
            summary.wall_seconds = started.elapsed().as_secs_f64();
            write_summary(w, json, &summary)
        },
    )?;
    Ok(worst)
}

fn write_summary(w: &mut dyn Write, json: bool, s: &Summary) -> Result<(), CliError> {
    if json {
        return write_json_line(w, &SummaryLine { schema: JSON_LINES_SCHEMA, summary: s });
    }
    let errors: Vec<String> = s.errors.iter().map(|(code, n)| format!("{code} ×{n}")).collect();
    writeln!(
        w,
        "summary: {} file{}: {} valid, {} invalid, {} unreadable; errors: {}; {:.3} s",
        s.files,
        if s.files == 1 { "" } else { "s" },
        s.valid,
        s.invalid,
        s.unreadable,
        if errors.is_empty() { "none".to_string() } else { errors.join(", ") },
        s.wall_seconds
    )
    .map_err(CliError::io_out)
}
