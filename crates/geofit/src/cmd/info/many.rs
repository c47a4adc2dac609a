//! `geofit info` over many inputs: summarised in parallel, reported in input order, then one
//! summary line.

use std::cell::RefCell;
use std::time::Instant;

use serde::Serialize;

use super::reports::REPORT;
use super::summarize;
use crate::config::{run_batch, worse_exit, write_batch_error, write_json_line, Config, Input};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::tagged;

/// Version of the JSON lines a many-file run writes (one object per file, then the summary).
const JSON_LINES_SCHEMA: &str = REPORT.schema;

#[derive(Debug, Default, Serialize)]
struct BatchSummary {
    files: usize,
    /// Read, and nothing to report (exit 0 on their own).
    clean: usize,
    /// Read, with located problems (exit 1 on their own).
    with_findings: usize,
    unreadable: usize,
    wall_seconds: f64,
}

#[derive(Serialize)]
struct SummaryLine<'a> {
    schema: &'static str,
    summary: &'a BatchSummary,
}

/// Several inputs: summarised in parallel, reported in input order (text blocks separated by a
/// blank line, or JSON lines), then a summary; an unreadable input is reported in its place.
pub(super) fn run(inputs: Vec<Input>, json: bool, config: &Config, started: Instant) -> CmdResult {
    // shared by the per-file and the summary writer
    let tally = RefCell::new((BatchSummary::default(), Exit::Ok));
    run_batch(
        inputs,
        "info",
        config,
        summarize,
        |w, name, result| {
            let (summary, worst) = &mut *tally.borrow_mut();
            summary.files += 1;
            let s = match result {
                Ok(s) => s,
                Err(e) => {
                    summary.unreadable += 1;
                    *worst = worse_exit(*worst, e.exit);
                    return write_batch_error(w, json, JSON_LINES_SCHEMA, name, &e);
                }
            };
            for f in &s.findings {
                crate::say!("{f}");
            }
            if s.findings.is_empty() {
                summary.clean += 1;
            } else {
                summary.with_findings += 1;
                *worst = worse_exit(*worst, Exit::Findings);
            }
            if json {
                write_json_line(w, &tagged(&REPORT, s.info.units(), &s.info))
            } else {
                s.info.write_text(w).and_then(|()| writeln!(w)).map_err(CliError::io_out)
            }
        },
        |w| {
            let (summary, _) = &mut *tally.borrow_mut();
            summary.wall_seconds = started.elapsed().as_secs_f64();
            if json {
                return write_json_line(w, &SummaryLine { schema: JSON_LINES_SCHEMA, summary });
            }
            writeln!(
                w,
                "summary: {} files: {} without findings, {} with findings, {} unreadable; {:.3} s",
                summary.files, summary.clean, summary.with_findings, summary.unreadable, summary.wall_seconds
            )
            .map_err(CliError::io_out)
        },
    )?;
    let worst = tally.borrow().1;
    Ok(worst)
}
