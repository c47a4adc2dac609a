//! Temporaries of the atomic writer left behind by a killed run, and when they may be removed.

use std::path::Path;

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

/// How long a temporary of a process this host cannot see must have gone unwritten before it
/// is taken for stale: a run in another PID namespace (another container on the same volume,
/// another node of a shared file system) writes its temporary now.
const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(3600);

/// Removes the geofit temporaries in `dir` whose process is gone (no `/proc/PID`) and that
/// nothing wrote for [`STALE_AFTER`]: what a `kill -9`, a power cut or `ulimit -f` left behind
/// (docs/decisions.md#stale-temporaries). A temporary of a running process — any process with
/// that id — is left alone, and so is a fresh one of a process this host cannot see (its PID
/// is another namespace's), as is everything where `/proc` is not mounted. Errors are
/// ignored: cleaning is a courtesy, and the write that follows reports a directory it cannot use.
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
        if written_within(&p, STALE_AFTER) {
            continue;
        }
        let _ = match e.file_type() {
            Ok(t) if t.is_dir() => std::fs::remove_dir_all(&p),
            Ok(_) => std::fs::remove_file(&p),
            Err(_) => continue,
        };
    }
}

/// Whether `path` (or, for a directory, anything directly in it) was modified within `age`.
/// An unreadable time counts as recent: nothing is removed on a guess.
fn written_within(path: &Path, age: std::time::Duration) -> bool {
    let recent = |p: &Path| {
        std::fs::metadata(p).and_then(|m| m.modified()).map_or(true, |t| t.elapsed().map_or(true, |e| e < age))
    };
    if recent(path) {
        return true;
    }
    match std::fs::read_dir(path) {
        Ok(entries) => entries.flatten().any(|e| recent(&e.path())),
        Err(_) => false,
    }
}
