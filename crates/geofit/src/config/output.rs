//! `Output`: a path written atomically (temporary file + rename) or stdout (`-`), with a
//! closed stdout detected as a write failure.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use super::stale::clean_stale_temps;
use crate::error::CliError;

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
            // the same stream under its device names: renaming a temporary over /dev/stdout
            // would replace the link itself (issue 40)
            None | Some("-" | "/dev/stdout" | "/dev/fd/1" | "/proc/self/fd/1") => Output::Stdout,
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
            return Err(CliError::usage(format!(
                "{flag} {}: the directory {} does not exist",
                p.display(),
                dir.display()
            )));
        }
        if p.is_dir() {
            return Err(CliError::usage(format!("{flag} {}: is a directory", p.display())));
        }
        Ok(())
    }

    /// The lower-case file extension, used to pick a format (`out.glb` → `glb`).
    pub fn extension(&self) -> Option<String> {
        self.path().and_then(|p| p.extension()).map(|e| e.to_string_lossy().to_ascii_lowercase())
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
const OUTPUT_OPTIONS: &[(&str, &str)] = &[
    ("output", "-o"),
    ("report", "--report"),
    ("png", "--png"),
    ("hist", "--hist"),
    ("outliers_csv", "--outliers-csv"),
    ("vtk", "--vtk"),
];

/// Checks every path of the parsed command line before any work starts, so a typo in an output
/// directory is a usage error (exit 2) at once, not a failure after a long fit, an output that
/// names an input or has another format's extension is refused (exit 2), and an input of a kind
/// the command does not read is named (exit 3; see `paths`).
pub fn check_output_args(matches: &clap::ArgMatches) -> Result<(), CliError> {
    let mut m = matches;
    while let Some((_, sub)) = m.subcommand() {
        m = sub;
    }
    for (id, flag) in OUTPUT_OPTIONS {
        // GDAL virtual paths (/vsi…) are the raster writer's to accept or refuse
        if let Ok(Some(path)) =
            m.try_get_one::<String>(id).map(|p| p.filter(|p| !raster_io::gdal_io::is_gdal_virtual_path(Path::new(p))))
        {
            Output::from_arg(Some(path)).check_target_of(flag)?;
        }
    }
    super::paths::check_outputs_are_not_inputs(matches, OUTPUT_OPTIONS)?;
    super::paths::check_output_extension(matches)?;
    super::paths::check_input_kinds(matches)
}

/// `--report -` puts the JSON report on stdout: refused before the work when the data goes
/// there too (no `-o FILE`), since the two would be mixed in one stream.
pub fn check_report_target(report: Option<&str>, output: Option<&str>) -> Result<(), CliError> {
    if report == Some("-") && matches!(output, None | Some("-")) {
        return Err(CliError::usage("--report - needs -o FILE: the data already goes to stdout"));
    }
    Ok(())
}

/// Writes `path` atomically: temp file in the same directory, fsync, and a rename when the
/// command has succeeded ([`commit_outputs`], together with its other outputs). A target that
/// exists and is not a regular file (`/dev/null`, `/dev/stdout`, a FIFO) is written straight
/// into: renaming over it would replace the device node itself, for every process on the host
/// when run as root (docs/decisions.md#devices-as-outputs-are-written-not-replaced).
pub fn write_atomic<F>(path: &Path, f: F) -> Result<(), CliError>
where
    F: FnOnce(&mut dyn Write) -> Result<(), CliError>,
{
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) || is_system_path(path) {
        return write_into_device(path, f);
    }
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
    // tempfile creates 0600 files: the output gets the mode of the file it replaces, or that of
    // a new file under the process's umask (0644 under the usual 022, 0600 under 077).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode =
            std::fs::metadata(path).map(|m| m.permissions().mode() & 0o7777).unwrap_or_else(|_| 0o666 & !umask());
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(mode)).map_err(CliError::io_out)?;
    }
    PENDING.lock().unwrap_or_else(|e| e.into_inner()).push((tmp.into_temp_path(), path.to_path_buf()));
    Ok(())
}

/// Outputs written whole to their temporaries, waiting to be renamed into place together.
static PENDING: std::sync::Mutex<Vec<(tempfile::TempPath, PathBuf)>> = std::sync::Mutex::new(Vec::new());

/// Renames every output the command wrote into place, in the order they were written: called
/// once the command has succeeded (or ended with findings it reports), so a command with
/// several outputs (`fit -o m.tmesh --report r.json --outliers-csv o.csv`) replaces all of them
/// or none; a disk that fills while the third is written leaves the first two as they were
/// (docs/decisions.md#outputs-are-committed-together).
pub fn commit_outputs() -> Result<(), CliError> {
    let pending = std::mem::take(&mut *PENDING.lock().unwrap_or_else(|e| e.into_inner()));
    for (tmp, path) in pending {
        tmp.persist(&path).map_err(|e| CliError::output(format!("cannot write {}: {}", path.display(), e.error)))?;
    }
    Ok(())
}

/// Removes the temporaries of a command that failed: none of its outputs replaces anything.
pub fn discard_outputs() {
    PENDING.lock().unwrap_or_else(|e| e.into_inner()).clear();
}

/// The process's file-creation mask, read without changing it (`/proc/self/status`, Linux
/// 4.7+); 022 where it cannot be read.
#[cfg(unix)]
fn umask() -> u32 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find_map(|l| l.strip_prefix("Umask:").and_then(|v| u32::from_str_radix(v.trim(), 8).ok()))
        })
        .unwrap_or(0o022)
}

/// A link under `/dev` or `/proc` (`/dev/stderr`, `/proc/self/fd/3`): a stream the process
/// was handed, which may lead to a regular file; the link itself must not be replaced. Files
/// in directories there (`/dev/shm/x.tmesh`) are ordinary outputs.
fn is_system_path(path: &Path) -> bool {
    (path.starts_with("/dev") || path.starts_with("/proc"))
        && std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

/// Writes into an existing device, FIFO or stream as it is (opened for writing, never created,
/// truncated or renamed; a regular file behind `/dev/stderr` is appended to).
fn write_into_device<F>(path: &Path, f: F) -> Result<(), CliError>
where
    F: FnOnce(&mut dyn Write) -> Result<(), CliError>,
{
    let named = |e: io::Error| CliError::output(format!("cannot write {}: {e}", path.display()));
    let append = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    let file = std::fs::OpenOptions::new().write(true).append(append).open(path).map_err(named)?;
    let mut w = io::BufWriter::with_capacity(1 << 16, file);
    f(&mut w)?;
    w.flush().map_err(named)
}
