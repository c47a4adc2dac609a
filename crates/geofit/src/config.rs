//! The one place every subcommand gets its stdin/stdout/file handling, progress and
//! report output from (the xsv `Config` idea), so all commands behave alike.

use std::fs::File;
use std::io::{self, BufRead, BufReader, IsTerminal, Read, Write};
use std::path::{Path, PathBuf};

use crate::error::{CliError, Exit};
use input_limits::mapped::InputBytes;

/// Options shared by every subcommand.
#[derive(Debug, Clone, Default)]
pub struct Config {
    /// `--quiet`: no progress bars, no stage lines.
    pub quiet: bool,
    /// `--keep-partial`: write the outputs of a step that ends with exit 1 (a fit short of
    /// --max-error, `diff --check` over tolerance); without it they are not written.
    pub keep_partial: bool,
}

/// Where an input comes from: a path or `-` for stdin.
#[derive(Debug, Clone)]
pub enum Input {
    Stdin,
    Path(PathBuf),
}

impl Input {
    pub fn from_arg(arg: &str) -> Input {
        if arg == "-" {
            Input::Stdin
        } else {
            Input::Path(PathBuf::from(arg))
        }
    }

    /// The name used in error messages (`<stdin>` or the path as given).
    pub fn display_name(&self) -> String {
        match self {
            Input::Stdin => "<stdin>".to_string(),
            Input::Path(p) => p.display().to_string(),
        }
    }

    /// The file path, if the input is a file (needed by libraries that open paths themselves, e.g. GDAL).
    pub fn path(&self) -> Option<&Path> {
        match self {
            Input::Stdin => None,
            Input::Path(p) => Some(p),
        }
    }

    /// Opens the input for buffered streaming reads.
    pub fn open(&self) -> Result<Box<dyn BufRead>, CliError> {
        match self {
            Input::Stdin => Ok(Box::new(BufReader::with_capacity(1 << 16, io::stdin()))),
            Input::Path(p) => {
                let f = File::open(p).map_err(|e| CliError::unreadable(format!("{}: {e}", p.display())))?;
                Ok(Box::new(BufReader::with_capacity(1 << 16, f)))
            }
        }
    }

    /// Reads the whole input into memory, within the byte budget
    /// (`input_limits::budget::ByteBudget`): a regular file is refused by its size before a byte
    /// is read, a pipe or device (`/dev/zero`, an endless stdin) once it has delivered more than
    /// the budget, with exit 3 naming the limit instead of the machine running out of memory.
    pub fn read_all(&self) -> Result<Vec<u8>, CliError> {
        self.read_all_within(input_limits::budget::ByteBudget::current())
    }

    /// The whole input for a reader that streams through it once (the CityGML object stream):
    /// a regular file is memory-mapped, whatever its size, and the reader releases the pages
    /// behind it (`InputBytes::release_before`), so memory stays bounded by the largest object
    /// (docs/decisions.md#streaming-citygml); anything else is read whole within the byte budget.
    pub fn map_or_read(&self) -> Result<InputBytes, CliError> {
        let unreadable = |e: io::Error| CliError::unreadable(format!("{}: {e}", self.display_name()));
        if let Some(p) = self.path() {
            let file = File::open(p).map_err(unreadable)?;
            if file.metadata().map_err(unreadable)?.is_file() {
                return InputBytes::map(&file).map_err(unreadable);
            }
        }
        self.read_all().map(InputBytes::Read)
    }

    fn read_all_within(&self, budget: input_limits::budget::ByteBudget) -> Result<Vec<u8>, CliError> {
        let too_big = || CliError::unreadable(format!("{}: too large to read whole (more than {})", self.display_name(), budget.describe()));
        let known_len = self.path().and_then(|p| std::fs::metadata(p).ok()).filter(|m| m.is_file()).map(|m| m.len());
        if known_len.is_some_and(|len| !budget.allows(len)) {
            return Err(too_big());
        }
        let mut buf = Vec::with_capacity(known_len.unwrap_or(0) as usize);
        self.open()?
            .take(budget.max_bytes.saturating_add(1))
            .read_to_end(&mut buf)
            .map_err(|e| CliError::unreadable(format!("{}: {e}", self.display_name())))?;
        if !budget.allows(buf.len() as u64) {
            return Err(too_big());
        }
        Ok(buf)
    }
}

/// Whether file descriptor 1 was closed when the process started (`geofit info x.gml >&-`).
///
/// Rust's runtime reopens a closed stdout onto `/dev/null` before `main`, so every write would
/// "succeed" and the command exit 0 having written nothing. A constructor in `.init_array` runs
/// before that and records the closed descriptor; writes to stdout then fail like any other
/// failed output (exit 4).
static STDOUT_CLOSED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

#[cfg(target_os = "linux")]
#[used]
#[link_section = ".init_array"]
static RECORD_CLOSED_STDOUT: extern "C" fn() = record_closed_stdout;

#[cfg(target_os = "linux")]
extern "C" fn record_closed_stdout() {
    // SAFETY: F_GETFD only queries the descriptor's flags; it fails with EBADF when fd 1 is closed.
    if unsafe { libc::fcntl(1, libc::F_GETFD) } == -1 {
        STDOUT_CLOSED.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Where an output goes: stdout (`-` or no `-o`) or a file written atomically.
#[derive(Debug, Clone)]
pub enum Output {
    Stdout,
    Path(PathBuf),
}

impl Output {
    pub fn from_arg(arg: Option<&str>) -> Output {
        match arg {
            None | Some("-") => Output::Stdout,
            Some(p) => Output::Path(PathBuf::from(p)),
        }
    }

    pub fn path(&self) -> Option<&Path> {
        match self {
            Output::Stdout => None,
            Output::Path(p) => Some(p),
        }
    }

    /// Checks before the work starts that a file output can be created: its directory exists.
    pub fn check_target(&self) -> Result<(), CliError> {
        self.check_target_of("-o")
    }

    /// [`Output::check_target`] naming the option that gave the path (`--report`, `--png`).
    pub fn check_target_of(&self, flag: &str) -> Result<(), CliError> {
        let Output::Path(p) = self else { return Ok(()) };
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            return Err(CliError::usage(format!("{flag} {}: the directory {} does not exist", p.display(), dir.display())));
        }
        if p.is_dir() {
            return Err(CliError::usage(format!("{flag} {}: is a directory", p.display())));
        }
        Ok(())
    }

    /// The lower-case file extension, used to pick a format (`out.glb` → `glb`).
    pub fn extension(&self) -> Option<String> {
        self.path()
            .and_then(|p| p.extension())
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
    }

    /// Writes through `f`; for a file, into a temporary file beside the target that is renamed
    /// over it only when `f` succeeded, so a failure never leaves a half-written output.
    pub fn write_with<F>(&self, f: F) -> Result<(), CliError>
    where
        F: FnOnce(&mut dyn Write) -> Result<(), CliError>,
    {
        match self {
            Output::Stdout => {
                if STDOUT_CLOSED.load(std::sync::atomic::Ordering::Relaxed) {
                    return Err(CliError::output("write failed: stdout is closed (Bad file descriptor)"));
                }
                let stdout = io::stdout();
                let mut lock = io::BufWriter::with_capacity(1 << 16, stdout.lock());
                f(&mut lock)?;
                lock.flush().map_err(CliError::io_out)
            }
            Output::Path(p) => write_atomic(p, f),
        }
    }

    /// Writes a byte buffer (see [`Output::write_with`]).
    pub fn write_bytes(&self, bytes: &[u8]) -> Result<(), CliError> {
        self.write_with(|w| w.write_all(bytes).map_err(CliError::io_out))
    }
}

/// The file outputs every subcommand names the same way (argument id, option as typed).
const OUTPUT_OPTIONS: &[(&str, &str)] =
    &[("output", "-o"), ("report", "--report"), ("png", "--png"), ("hist", "--hist"), ("outliers_csv", "--outliers-csv"), ("vtk", "--vtk")];

/// Checks every file output of the parsed command line before any work starts, so a typo in
/// an output directory is a usage error (exit 2) at once, not a failure after a long fit.
pub fn check_output_args(matches: &clap::ArgMatches) -> Result<(), CliError> {
    let mut m = matches;
    while let Some((_, sub)) = m.subcommand() {
        m = sub;
    }
    for (id, flag) in OUTPUT_OPTIONS {
        // GDAL virtual paths (/vsi…) are the raster writer's to accept or refuse
        if let Ok(Some(path)) = m.try_get_one::<String>(id).map(|p| p.filter(|p| !raster_io::gdal_io::is_gdal_virtual_path(Path::new(p)))) {
            Output::from_arg(Some(path)).check_target_of(flag)?;
        }
    }
    Ok(())
}

/// `--report -` puts the JSON report on stdout: refused before the work when the data goes
/// there too (no `-o FILE`), since the two would be mixed in one stream.
pub fn check_report_target(report: Option<&str>, output: Option<&str>) -> Result<(), CliError> {
    if report == Some("-") && matches!(output, None | Some("-")) {
        return Err(CliError::usage("--report - needs -o FILE: the data already goes to stdout"));
    }
    Ok(())
}

/// Writes `path` atomically: temp file in the same directory, fsync, rename.
pub fn write_atomic<F>(path: &Path, f: F) -> Result<(), CliError>
where
    F: FnOnce(&mut dyn Write) -> Result<(), CliError>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    clean_stale_temps(&dir);
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".geofit-{}-", std::process::id()))
        .suffix(".tmp")
        .tempfile_in(&dir)
        .map_err(|e| CliError::output(format!("cannot create a temporary file in {}: {e}", dir.display())))?;
    // A write error names the target (`out.tif: File too large`), not the temporary file,
    // which is removed when `tmp` drops on the error path.
    let named = |e: CliError| match e.message.strip_prefix("write failed: ") {
        Some(cause) => CliError::output(format!("cannot write {}: {cause}", path.display())),
        None => e,
    };
    {
        let mut w = io::BufWriter::with_capacity(1 << 16, tmp.as_file());
        f(&mut w).map_err(named)?;
        w.flush().map_err(|e| named(CliError::io_out(e)))?;
    }
    tmp.as_file().sync_all().map_err(|e| named(CliError::io_out(e)))?;
    // tempfile creates 0600 files; an output is an ordinary file others may read.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644)).map_err(CliError::io_out)?;
    }
    tmp.persist(path)
        .map_err(|e| CliError::output(format!("cannot write {}: {}", path.display(), e.error)))?;
    Ok(())
}

/// The process id in the name of a geofit temporary file or directory:
/// `.geofit-[TAG-]PID-REST.tmp` (the atomic writer's `.geofit-PID-XXXXXX.tmp`, raster-io's
/// staging directory `.geofit-raster-PID-N.tmp`). `None` for any other name.
pub fn temp_owner(name: &str) -> Option<u32> {
    let rest = name.strip_prefix(".geofit-")?.strip_suffix(".tmp")?;
    let rest = rest.strip_prefix("raster-").unwrap_or(rest);
    let (pid, tail) = rest.split_once('-')?;
    if tail.is_empty() || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Removes the geofit temporaries in `dir` whose process is gone (no `/proc/PID`): what a
/// `kill -9`, a power cut or `ulimit -f` left behind (docs/decisions.md#stale-temporaries).
/// A temporary of a running process — any process with that id — is left alone, as is
/// everything where `/proc` is not mounted. Errors are ignored: cleaning is a courtesy, and
/// the write that follows reports a directory it cannot use.
pub fn clean_stale_temps(dir: &Path) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(temp_owner) else { continue };
        if pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists() {
            continue;
        }
        let p = e.path();
        let _ = match e.file_type() {
            Ok(t) if t.is_dir() => std::fs::remove_dir_all(&p),
            Ok(_) => std::fs::remove_file(&p),
            Err(_) => continue,
        };
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
            let bar = if total > 0 {
                indicatif::ProgressBar::new(total)
            } else {
                indicatif::ProgressBar::new_spinner()
            };
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

    /// Whether a data output goes out for a command ending with `exit`: a failed step
    /// (non-zero) writes none unless `--keep-partial`, so `make` runs it again instead of
    /// taking the partial result as done. Says so on stderr when it withholds `output`.
    pub fn keeps_output(&self, exit: Exit, output: Option<&str>) -> bool {
        if exit == Exit::Ok || self.keep_partial {
            return true;
        }
        crate::say!("geofit: {} not written: the step failed (exit {}); --keep-partial writes it anyway", output.unwrap_or("stdout"), exit as u8);
        false
    }

    /// A one-line notice on stderr (suppressed by `--quiet`).
    pub fn notice(&self, msg: &str) {
        if !self.quiet {
            crate::say!("geofit: {msg}");
        }
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
            ProgressMode::Lines => crate::say!("geofit:   {}{took}", if msg.is_empty() { String::new() } else { format!("{msg}; ") }),
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
pub fn write_batch_error(w: &mut dyn Write, json: bool, schema: &str, name: &str, e: &CliError) -> Result<(), CliError> {
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
