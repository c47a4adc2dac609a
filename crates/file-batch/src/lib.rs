//! Many input files in one process (`geofit validate DIR`, `geofit info a.gml b.gml`).
//!
//! * [`expand`] turns command-line arguments — files, directories (walked recursively for the
//!   given extensions), glob patterns the shell did not expand (quoted), and `-` for stdin — into
//!   one ordered list of [`Source`]s. The order is the arguments' order, a directory's or a
//!   pattern's files sorted by path, so a run's output does not depend on the file system's
//!   listing order.
//! * [`run_ordered`] runs one job per source on a rayon pool and hands each result to the
//!   caller in input order as soon as all earlier ones are done: the output streams, and it is
//!   the same whatever the number of threads. A job that panics becomes an error for its item
//!   alone; the others still run.
//!
//! Whether arguments ask for this many-file form at all ([`is_batch`]) depends on their shape,
//! never on how many files a directory or pattern happens to hold, so a script always gets the
//! same kind of output from the same kind of call.
//!
//! # Examples
//!
//! A directory expands to its matching files sorted by path; the results come back in that
//! order whatever the threads did:
//!
//! ```
//! use file_batch::{expand, run_ordered, Source};
//! let dir = std::env::temp_dir().join(format!("file-batch-doc-{}", std::process::id()));
//! std::fs::create_dir_all(dir.join("sub")).unwrap();
//! for name in ["b.gml", "a.gml", "sub/c.gml", "notes.txt"] {
//!     std::fs::write(dir.join(name), name).unwrap();
//! }
//! let sources = expand(&[dir.display().to_string()], &["gml"]).unwrap();
//! let names: Vec<String> = sources.iter().map(|s| s.display_name().rsplit('/').next().unwrap().to_string()).collect();
//! assert_eq!(names, ["a.gml", "b.gml", "c.gml"]);
//!
//! let mut lengths = Vec::new();
//! run_ordered(sources, |s: Source| std::fs::read(s.as_arg()).unwrap().len(), |i, r| lengths.push((i, r.unwrap())));
//! assert_eq!(lengths, [(0, 5), (1, 5), (2, 9)]);
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::mpsc;

/// One input: a file, or standard input (`-`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Source {
    Stdin,
    Path(PathBuf),
}

impl Source {
    /// The name reports use: `<stdin>` or the path as found.
    pub fn display_name(&self) -> String {
        match self {
            Source::Stdin => "<stdin>".to_string(),
            Source::Path(p) => p.display().to_string(),
        }
    }

    /// The argument that names this source on its own (`-` or the path).
    pub fn as_arg(&self) -> String {
        match self {
            Source::Stdin => "-".to_string(),
            Source::Path(p) => p.display().to_string(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ExpandError {
    #[error("{0}: no file matches this pattern")]
    NoMatch(String),
    #[error("{pattern}: not a valid glob pattern: {message}")]
    BadPattern { pattern: String, message: String },
    #[error("{dir}: the directory holds no {exts} file")]
    EmptyDir { dir: String, exts: String },
    #[error("`-` (standard input) given more than once")]
    StdinTwice,
    #[error("no input given")]
    Nothing,
}

/// Characters that make an argument a glob pattern (when no file has that very name).
const GLOB_META: &[char] = &['*', '?', '['];

fn is_pattern(arg: &str) -> bool {
    arg.contains(GLOB_META) && !Path::new(arg).exists()
}

/// Whether `args` ask for the many-file form: more than one argument, a directory, or a glob
/// pattern. One file (or `-`) keeps the one-file form even when it does not exist, so its
/// error is reported as before.
pub fn is_batch(args: &[String]) -> bool {
    match args {
        [one] => one != "-" && (Path::new(one).is_dir() || is_pattern(one)),
        _ => true,
    }
}

/// Expands `args` into sources, in order: `-` is stdin (once at most); a directory gives its
/// files with one of `dir_exts` (lower-case, no dot; matched case-insensitively), found
/// recursively and sorted by path; a pattern gives its matches sorted (directories among them
/// walked like directories); anything else is taken as a file, existing or not — a file that
/// cannot be read is the job's error, reported in its place, not a reason to stop the run.
pub fn expand(args: &[String], dir_exts: &[&str]) -> Result<Vec<Source>, ExpandError> {
    if args.is_empty() {
        return Err(ExpandError::Nothing);
    }
    let mut out = Vec::new();
    let mut stdin_seen = false;
    for arg in args {
        if arg == "-" {
            if stdin_seen {
                return Err(ExpandError::StdinTwice);
            }
            stdin_seen = true;
            out.push(Source::Stdin);
        } else if is_pattern(arg) {
            let matches = glob_matches(arg)?;
            if matches.is_empty() {
                return Err(ExpandError::NoMatch(arg.clone()));
            }
            for m in matches {
                push_path(&mut out, m, dir_exts)?;
            }
        } else {
            push_path(&mut out, PathBuf::from(arg), dir_exts)?;
        }
    }
    Ok(out)
}

fn glob_matches(pattern: &str) -> Result<Vec<PathBuf>, ExpandError> {
    let paths = glob::glob(pattern)
        .map_err(|e| ExpandError::BadPattern { pattern: pattern.to_string(), message: e.to_string() })?;
    // An entry the pattern reached but could not read is kept: its job reports why.
    let mut v: Vec<PathBuf> = paths.map(|r| r.unwrap_or_else(|e| e.path().to_path_buf())).collect();
    v.sort();
    Ok(v)
}

fn push_path(out: &mut Vec<Source>, p: PathBuf, dir_exts: &[&str]) -> Result<(), ExpandError> {
    if !p.is_dir() {
        out.push(Source::Path(p));
        return Ok(());
    }
    let found = walk_dir(&p, dir_exts);
    if found.is_empty() {
        let exts: Vec<String> = dir_exts.iter().map(|e| format!("*.{e}")).collect();
        return Err(ExpandError::EmptyDir { dir: p.display().to_string(), exts: exts.join("/") });
    }
    out.extend(found.into_iter().map(Source::Path));
    Ok(())
}

/// Files under `dir` with one of the extensions, sorted by path. Symbolic links are followed
/// (walkdir stops at loops); an entry that cannot be read is kept so its job reports it.
fn walk_dir(dir: &Path, exts: &[&str]) -> Vec<PathBuf> {
    let wanted = |p: &Path| {
        p.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).is_some_and(|e| exts.contains(&e.as_str()))
    };
    let mut v = Vec::new();
    for entry in walkdir::WalkDir::new(dir).follow_links(true).sort_by_file_name() {
        match entry {
            Ok(e) if e.file_type().is_file() && wanted(e.path()) => v.push(e.into_path()),
            Ok(_) => {}
            Err(e) => {
                if let Some(p) = e.path() {
                    v.push(p.to_path_buf());
                }
            }
        }
    }
    v.sort();
    v
}

/// A job that panicked: its message, for the item's own error line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Panicked(pub String);

/// Runs `work` on every item on a rayon pool (`RAYON_NUM_THREADS` threads, or one per core)
/// and calls `emit(index, result)` on the calling thread in input order, each as soon as the
/// items before it are done. Items are started in input order (FIFO), so the output streams.
/// Worker threads get 8 MiB stacks, like a main thread, for deeply nested documents.
pub fn run_ordered<T, R, W, E>(items: Vec<T>, work: W, mut emit: E)
where
    T: Send,
    R: Send,
    W: Fn(T) -> R + Sync,
    E: FnMut(usize, Result<R, Panicked>),
{
    let pool =
        rayon::ThreadPoolBuilder::new().stack_size(8 << 20).thread_name(|i| format!("file-batch-{i}")).build().ok();
    let (tx, rx) = mpsc::channel::<(usize, Result<R, Panicked>)>();
    let work = &work;
    std::thread::scope(|s| {
        s.spawn(move || {
            match &pool {
                Some(p) => p.scope_fifo(|sc| spawn_all(sc, items, work, &tx)),
                None => rayon::scope_fifo(|sc| spawn_all(sc, items, work, &tx)),
            }
            // the receiver's loop ends when this last sender is gone
            drop(tx);
        });
        let mut pending = BTreeMap::new();
        let mut next = 0usize;
        for (i, r) in rx {
            pending.insert(i, r);
            while let Some(r) = pending.remove(&next) {
                emit(next, r);
                next += 1;
            }
        }
    });
}

/// Spawns one FIFO job per item; each sends its index and result (or panic) to `tx`.
fn spawn_all<'s, T, R, W>(
    sc: &rayon::ScopeFifo<'s>,
    items: Vec<T>,
    work: &'s W,
    tx: &mpsc::Sender<(usize, Result<R, Panicked>)>,
) where
    T: Send + 's,
    R: Send + 's,
    W: Fn(T) -> R + Sync,
{
    for (i, item) in items.into_iter().enumerate() {
        let tx = tx.clone();
        sc.spawn_fifo(move |_| {
            let r = catch_unwind(AssertUnwindSafe(|| work(item))).map_err(|p| Panicked(panic_message(p.as_ref())));
            // the receiver lives until every sender is gone
            let _ = tx.send((i, r));
        });
    }
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "a job panicked".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn args(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    fn tree() -> tempfile::TempDir {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        fs::create_dir_all(d.join("b/sub")).unwrap();
        fs::create_dir_all(d.join("a")).unwrap();
        for f in ["b/sub/z.GML", "b/y.xml", "b/notes.txt", "a/x.citygml", "a/w.gml", "top.gml"] {
            fs::write(d.join(f), "<x/>").unwrap();
        }
        t
    }

    fn names(v: &[Source], root: &Path) -> Vec<String> {
        v.iter()
            .map(|s| match s {
                Source::Stdin => "-".into(),
                Source::Path(p) => p.strip_prefix(root).unwrap_or(p).display().to_string(),
            })
            .collect()
    }

    #[test]
    fn directories_are_walked_sorted_with_the_extensions_only() {
        let t = tree();
        let d = t.path();
        let got = expand(&args(&[d.to_str().unwrap()]), &["gml", "xml", "citygml"]).unwrap();
        assert_eq!(names(&got, d), ["a/w.gml", "a/x.citygml", "b/sub/z.GML", "b/y.xml", "top.gml"]);
    }

    #[test]
    fn arguments_keep_their_order_and_patterns_expand_sorted() {
        let t = tree();
        let d = t.path();
        let pat = format!("{}/*/*.*ml", d.display());
        let top = d.join("top.gml");
        let got = expand(&args(&[top.to_str().unwrap(), "-", &pat]), &["gml"]).unwrap();
        assert_eq!(names(&got, d), ["top.gml", "-", "a/w.gml", "a/x.citygml", "b/y.xml"]);
        // a pattern that matches a directory walks it
        let got = expand(&args(&[&format!("{}/[b]", d.display())]), &["gml"]).unwrap();
        assert_eq!(names(&got, d), ["b/sub/z.GML"]);
    }

    #[test]
    fn what_cannot_be_expanded_is_an_error_and_missing_files_are_kept() {
        let t = tree();
        let d = t.path();
        assert!(matches!(expand(&args(&[&format!("{}/*.none", d.display())]), &["gml"]), Err(ExpandError::NoMatch(_))));
        assert!(matches!(expand(&args(&["-", "-"]), &["gml"]), Err(ExpandError::StdinTwice)));
        assert!(matches!(
            expand(&args(&[d.join("b/sub").to_str().unwrap()]), &["txt"]),
            Err(ExpandError::EmptyDir { .. })
        ));
        assert!(matches!(expand(&[], &["gml"]), Err(ExpandError::Nothing)));
        let missing = d.join("missing.gml");
        let got = expand(&args(&[missing.to_str().unwrap()]), &["gml"]).unwrap();
        assert_eq!(got, [Source::Path(missing)]);
    }

    #[test]
    fn batch_form_by_shape_of_the_arguments() {
        let t = tree();
        let d = t.path();
        let top = d.join("top.gml");
        assert!(!is_batch(&args(&[top.to_str().unwrap()])));
        assert!(!is_batch(&args(&["-"])));
        assert!(!is_batch(&args(&["/no/such/file.gml"])));
        assert!(is_batch(&args(&[d.to_str().unwrap()])));
        assert!(is_batch(&args(&[&format!("{}/*.gml", d.display())])));
        assert!(is_batch(&args(&[top.to_str().unwrap(), top.to_str().unwrap()])));
        // a file whose name holds a glob character is that file
        let odd = d.join("odd[1].gml");
        fs::write(&odd, "<x/>").unwrap();
        assert!(!is_batch(&args(&[odd.to_str().unwrap()])));
    }

    #[test]
    fn results_come_back_in_input_order_and_a_panic_stays_with_its_item() {
        // later items finish first (shorter sleeps): the order must still be the input order
        let items: Vec<u64> = (0..24).collect();
        let mut seen = Vec::new();
        run_ordered(
            items,
            |i| {
                std::thread::sleep(std::time::Duration::from_millis(24 - i));
                if i == 7 {
                    panic!("item seven");
                }
                i * 10
            },
            |k, r| seen.push((k, r)),
        );
        assert_eq!(seen.len(), 24);
        for (k, (idx, r)) in seen.iter().enumerate() {
            assert_eq!(*idx, k);
            if k == 7 {
                assert_eq!(r, &Err(Panicked("item seven".into())));
            } else {
                assert_eq!(r, &Ok(k as u64 * 10));
            }
        }
    }
}
