//! Progress on stderr: a bar with elapsed time and ETA on a terminal, plain lines otherwise,
//! nothing with `--quiet`.

use std::io::{self, IsTerminal};

use super::Config;

/// Progress on stderr: an indicatif bar with elapsed time and ETA when stderr is a terminal,
/// otherwise one plain line per stage and a last line with the stage's elapsed time; nothing
/// with `--quiet`. Library crates report through callbacks and the CLI forwards them here.
pub struct Progress {
    mode: ProgressMode,
    started: std::time::Instant,
}

enum ProgressMode {
    Silent,
    Lines,
    Bar(indicatif::ProgressBar),
}

impl Config {
    /// A progress reporter for one stage of work with `total` steps (0 if unknown).
    pub fn progress(&self, stage: &str, total: u64) -> Progress {
        let mode = if self.quiet {
            ProgressMode::Silent
        } else if io::stderr().is_terminal() {
            let bar =
                if total > 0 { indicatif::ProgressBar::new(total) } else { indicatif::ProgressBar::new_spinner() };
            // a known total gets a bar and an ETA; an unknown one a spinner and the count so far
            let template = if total > 0 {
                "{prefix:>12} {elapsed_precise} [{bar:30}] {pos}/{len} ETA {eta} {msg}"
            } else {
                "{prefix:>12} {elapsed_precise} {spinner} {pos} {msg}"
            };
            bar.set_style(
                indicatif::ProgressStyle::with_template(template)
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            bar.enable_steady_tick(std::time::Duration::from_millis(250));
            bar.set_prefix(stage.to_string());
            ProgressMode::Bar(bar)
        } else {
            crate::say!("geofit: {stage}");
            ProgressMode::Lines
        };
        Progress { mode, started: std::time::Instant::now() }
    }
}

impl Progress {
    /// Advances to `pos`; in line mode prints `msg` when it is non-empty (one line per iteration).
    pub fn set(&self, pos: u64, msg: &str) {
        match &self.mode {
            ProgressMode::Silent => {}
            ProgressMode::Lines => {
                if !msg.is_empty() {
                    crate::say!("geofit:   {msg}");
                }
            }
            ProgressMode::Bar(b) => {
                b.set_position(pos);
                b.set_message(msg.to_string());
            }
        }
    }

    /// Ends the stage with `msg` and the time it took.
    pub fn finish(self, msg: &str) {
        let took = format_elapsed(self.started.elapsed());
        match self.mode {
            ProgressMode::Silent => {}
            ProgressMode::Lines => {
                crate::say!("geofit:   {}{took}", if msg.is_empty() { String::new() } else { format!("{msg}; ") })
            }
            ProgressMode::Bar(b) => b.finish_with_message(msg.to_string()),
        }
    }
}

/// "done in 3.2 s", "done in 2 min 05 s": a stage's elapsed time for a person.
fn format_elapsed(d: std::time::Duration) -> String {
    let s = d.as_secs_f64();
    if s < 60.0 {
        format!("done in {s:.1} s")
    } else {
        format!("done in {} min {:02} s", (s / 60.0).floor(), (s % 60.0).floor())
    }
}
