//! Helpers shared by the end-to-end tests: the real `geofit` binary, the shared fixtures, and
//! temporary directories. Each test file does `mod common;` and uses what it needs.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

/// The `geofit` binary cargo built for this test run.
pub fn geofit() -> Command {
    Command::new(env!("CARGO_BIN_EXE_geofit"))
}

/// Repository root (the workspace).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").canonicalize().expect("repo root")
}

/// `../shared` beside the checkout, or `$GEOFIT_SHARED`.
pub fn shared_dir() -> PathBuf {
    match std::env::var_os("GEOFIT_SHARED") {
        Some(p) => PathBuf::from(p),
        None => repo_root().join("../shared"),
    }
}

/// True when running in CI (`CI=true`): a missing fixture is then a failure, not a skip.
pub fn in_ci() -> bool {
    std::env::var("CI").map(|v| v == "true" || v == "1").unwrap_or(false)
}

/// A file under `../shared/fixtures/`. Missing: panics in CI, otherwise prints a clear skip and
/// returns `None` (callers `let Some(p) = fixture(..) else { return };`).
pub fn fixture(rel: &str) -> Option<PathBuf> {
    let p = shared_dir().join("fixtures").join(rel);
    if p.exists() {
        return Some(p);
    }
    if in_ci() {
        panic!("fixture missing in CI: {}", p.display());
    }
    eprintln!("SKIP: fixture {} not found (set GEOFIT_SHARED or put ../shared beside the checkout)", p.display());
    None
}

/// The directory `../shared/xsd` (CityGML/GML schemas), same missing-rule as [`fixture`].
pub fn shared_xsd() -> Option<PathBuf> {
    let p = shared_dir().join("xsd");
    if p.exists() {
        return Some(p);
    }
    if in_ci() {
        panic!("schemas missing in CI: {}", p.display());
    }
    eprintln!("SKIP: {} not found", p.display());
    None
}

/// Is an external tool on PATH? In CI a missing tool is a failure (make setup installs it).
pub fn tool(name: &str) -> bool {
    let found = Command::new("sh")
        .arg("-c")
        .arg(format!("command -v {name}"))
        .stdout(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if !found {
        if in_ci() {
            panic!("external tool `{name}` missing in CI (make setup installs it)");
        }
        eprintln!("SKIP: external tool `{name}` not found; run `make setup`");
    }
    found
}

/// Runs geofit with `args`, feeding `stdin` when given; returns the output.
pub fn run(args: &[&str], stdin: Option<&[u8]>) -> Output {
    let mut cmd = geofit();
    cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
    cmd.stdin(if stdin.is_some() { Stdio::piped() } else { Stdio::null() });
    let mut child = cmd.spawn().expect("spawn geofit");
    if let Some(data) = stdin {
        let mut si = child.stdin.take().unwrap();
        let data = data.to_vec();
        std::thread::spawn(move || {
            let _ = si.write_all(&data);
        });
    }
    child.wait_with_output().expect("wait geofit")
}

/// Exit code of an output (panics on signal, which is itself a test failure: e.g. a crash).
pub fn code(o: &Output) -> i32 {
    o.status
        .code()
        .unwrap_or_else(|| panic!("geofit killed by a signal; stderr: {}", String::from_utf8_lossy(&o.stderr)))
}

/// A fresh temporary directory for one test.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("tempdir")
}

/// Python 3 interpreter used by the independent-truth check scripts in `tests/scripts/`: the
/// project's virtual environment (`GEOFIT_PYTHON`, set by `make`), else `python3` on PATH.
pub fn python() -> Command {
    Command::new(std::env::var_os("GEOFIT_PYTHON").unwrap_or_else(|| "python3".into()))
}

/// `bash` in `dir` with this run's `geofit` first on PATH (then the test Python's directory,
/// when `GEOFIT_PYTHON` names one) and `GEOFIT_SHARED` set: how scripts and the README's
/// lines meet the binary under test.
pub fn bash_with_geofit(dir: &Path) -> Command {
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_geofit")).parent().unwrap().to_path_buf();
    let mut path = format!("{}:{}", bin_dir.display(), std::env::var("PATH").unwrap_or_default());
    if let Some(py_dir) = std::env::var_os("GEOFIT_PYTHON").as_deref().and_then(|p| Path::new(p).parent()) {
        path = format!("{}:{path}", py_dir.display());
    }
    let mut cmd = Command::new("bash");
    cmd.current_dir(dir).env("PATH", path).env("GEOFIT_SHARED", shared_dir());
    cmd
}

/// Every `.rs` file below `dir`, recursively.
pub fn rust_sources(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(rust_sources(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out
}

/// Every `.gml` file below `dir`, recursively, sorted (the fixture sweeps of citygml, export and
/// validate go through the same list).
pub fn gml_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "gml") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The subcommands `geofit --help` lists (without `help`), in its order.
pub fn subcommands() -> Vec<String> {
    let o = run(&["--help"], None);
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter(|l| !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect()
}

/// (rule, tile) of every job a Snakemake dry run lists.
pub fn snakemake_dry_run_jobs(o: &Output) -> std::collections::BTreeSet<(String, String)> {
    assert!(o.status.success(), "snakemake -n failed: {}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    let mut jobs = std::collections::BTreeSet::new();
    let mut rule: Option<String> = None;
    for line in text.lines() {
        let l = line.trim();
        if let Some(r) =
            l.strip_prefix("rule ").or_else(|| l.strip_prefix("localrule ")).or_else(|| l.strip_prefix("checkpoint "))
        {
            if let Some(r) = r.strip_suffix(':') {
                if let Some(prev) = rule.replace(r.to_string()) {
                    jobs.insert((prev, String::new()));
                }
            }
        } else if let (Some(w), Some(r)) = (l.strip_prefix("wildcards: tile="), rule.as_ref()) {
            jobs.insert((r.clone(), w.to_string()));
            rule = None;
        }
    }
    if let Some(r) = rule {
        jobs.insert((r, String::new()));
    }
    jobs
}

/// The tileset read back by py3dtiles (tests/scripts/tileset_py3dtiles.py): its JSON report, or
/// `None` (a printed skip) where py3dtiles is not installed outside CI. Panics on a report with
/// errors, or in CI without py3dtiles.
pub fn tileset_read_by_py3dtiles(tileset: &Path) -> Option<serde_json::Value> {
    let have = python().args(["-c", "import py3dtiles.tileset"]).output().is_ok_and(|o| o.status.success());
    if !have {
        assert!(!in_ci(), "py3dtiles missing in CI (make setup installs it)");
        eprintln!("SKIP: py3dtiles not installed");
        return None;
    }
    let o = python()
        .arg(repo_root().join("tests/scripts/tileset_py3dtiles.py"))
        .arg(tileset)
        .output()
        .expect("python runs");
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "py3dtiles on {}: {text}{}", tileset.display(), String::from_utf8_lossy(&o.stderr));
    Some(serde_json::from_str(text.lines().last().unwrap_or("")).expect("one JSON line"))
}

/// The refusal every trap test checks (issue 41): exit `exit`, exactly one stderr line holding
/// every one of `words`, nothing written at `out` (unless `out` is one of the inputs), and every
/// path in `untouched` with the bytes it had (or still missing). Returns stderr.
#[track_caller]
pub fn refused(
    args: &[&str],
    stdin: Option<&[u8]>,
    exit: i32,
    words: &[&str],
    out: Option<&Path>,
    untouched: &[&Path],
) -> String {
    let before: Vec<Option<Vec<u8>>> = untouched.iter().map(|p| std::fs::read(p).ok()).collect();
    let o = run(args, stdin);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(code(&o), exit, "{args:?}: stderr {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: one line, got {err}");
    for w in words {
        assert!(err.contains(w), "{args:?}: '{w}' missing from: {err}");
    }
    if let Some(out) = out {
        assert!(!out.exists() || untouched.contains(&out), "{args:?}: {} was written", out.display());
    }
    for (p, b) in untouched.iter().zip(before) {
        assert_eq!(std::fs::read(p).ok(), b, "{args:?}: {} changed", p.display());
    }
    err
}

/// `geofit validate --no-xsd` geometry findings per (feature gml:id, code), counted.
pub fn findings_by_feature(f: &Path) -> std::collections::BTreeMap<(String, i64), usize> {
    let v = run(&["validate", "-q", "--no-xsd", "--json", f.to_str().unwrap()], None);
    let j: serde_json::Value = serde_json::from_slice(&v.stdout)
        .unwrap_or_else(|_| panic!("validate {}: {}", f.display(), String::from_utf8_lossy(&v.stderr)));
    let mut out = std::collections::BTreeMap::new();
    for x in j["geometry"]["findings"].as_array().cloned().unwrap_or_default() {
        let feature = x["feature"].as_str().unwrap_or("(no id)").to_string();
        *out.entry((feature, x["code"].as_i64().unwrap())).or_insert(0) += 1;
    }
    out
}
