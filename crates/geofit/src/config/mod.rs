//! The one place every subcommand gets its stdin/stdout/file handling, progress and
//! report output from (the xsv `Config` idea), so all commands behave alike: inputs
//! (`input.rs`), atomic outputs (`output.rs`), progress (`progress.rs`), many-file runs
//! (`batch.rs`), the checks of a command line's paths before the work (`paths.rs`), and stderr lines that never panic (here).

mod batch;
pub mod encoding;
mod input;
mod output;
mod paths;
mod progress;
mod stale;

use std::io::{self, Write};

use crate::error::Exit;

pub use batch::{batch_inputs, run_batch, worse_exit, write_batch_error, write_json_line, CITYGML_EXTENSIONS};
pub use input::Input;
pub(crate) use output::write_atomic;
pub use output::{check_output_args, check_report_target, commit_outputs, discard_outputs, Output};
pub use stale::clean_stale_temps;

/// Options shared by every subcommand.
#[derive(Debug, Clone, Default)]
pub struct Config {
    /// `--quiet`: no progress bars, no stage lines.
    pub quiet: bool,
    /// `--keep-partial`: write the outputs of a step that ends with exit 1 (a fit short of
    /// --max-error, `diff --check` over tolerance); without it they are not written.
    pub keep_partial: bool,
}

impl Config {
    /// Whether a data output goes out for a command ending with `exit`: a failed step
    /// (non-zero) writes none unless `--keep-partial`, so `make` runs it again instead of
    /// taking the partial result as done. Says so on stderr when it withholds `output`.
    pub fn keeps_output(&self, exit: Exit, output: Option<&str>) -> bool {
        if exit == Exit::Ok || self.keep_partial {
            return true;
        }
        crate::say!(
            "geofit: {} not written: the step failed (exit {}); --keep-partial writes it anyway",
            output.unwrap_or("stdout"),
            exit as u8
        );
        false
    }

    /// A one-line notice on stderr (suppressed by `--quiet`).
    pub fn notice(&self, msg: &str) {
        if !self.quiet {
            crate::say!("geofit: {msg}");
        }
    }
}

/// Writes `args` and a newline to stderr, ignoring write errors.
///
/// Progress, notices and summaries are for a person watching; when stderr is a closed pipe
/// (`geofit fit … 2>&1 | head -n 1`) or a full device (`2>/dev/full`) the command must still do
/// its work and write its output, so, unlike `eprintln!`, this never panics. Every stderr write
/// of the CLI goes through here (or [`stderr_str`]) — use the [`say!`](crate::say) macro.
pub fn stderr_line(args: std::fmt::Arguments<'_>) {
    let mut e = io::stderr().lock();
    let _ = e.write_fmt(args).and_then(|()| e.write_all(b"\n"));
}

/// Writes `s` to stderr as it is (no newline added), ignoring write errors (see [`stderr_line`]).
pub fn stderr_str(s: &str) {
    let _ = io::stderr().lock().write_all(s.as_bytes());
}

/// `eprintln!` that never panics: one line to stderr, write errors ignored ([`stderr_line`]).
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::config::stderr_line(format_args!($($arg)*))
    };
}
