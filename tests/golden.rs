//! Golden outputs (issue 16): `tests/golden/outputs.sh` runs every README pipeline and every
//! subcommand on the shipped fixtures; the SHA-256 of each file it makes must equal the line in
//! `tests/golden/outputs.sha256`. Moving code between crates must not change a byte of any
//! output; an intended change is re-blessed with `GEOFIT_BLESS=1` and named in its commit.
//!
//! The hashes come from coreutils' `sha256sum`, not from code of this repository.

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

const SCRIPT: &str = "tests/golden/outputs.sh";
const HASHES: &str = "tests/golden/outputs.sha256";

/// `name → sha256` of every regular file in `dir` (the input links S, P, X are not files).
fn hash_outputs(dir: &Path) -> BTreeMap<String, String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().map(|t| t.is_file()).unwrap_or(false))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let o = Command::new("sha256sum").args(&names).current_dir(dir).output().expect("sha256sum runs");
    assert!(o.status.success(), "sha256sum: {}", String::from_utf8_lossy(&o.stderr));
    parse_hashes(&String::from_utf8_lossy(&o.stdout))
}

fn parse_hashes(text: &str) -> BTreeMap<String, String> {
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once("  ").map(|(h, n)| (n.to_string(), h.to_string())))
        .collect()
}

fn run_script(dir: &Path) {
    let o = common::bash_with_geofit(dir)
        .arg(common::repo_root().join(SCRIPT))
        .env("GEOFIT_REPO", common::repo_root())
        .output()
        .expect("bash runs");
    assert!(
        o.status.success(),
        "{SCRIPT} failed: {}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr).lines().rev().take(15).collect::<Vec<_>>().join("\n")
    );
}

#[test]
fn every_output_is_byte_identical_to_its_golden_hash() {
    if common::fixture("citygml/nrw/LoD2_32_332_5729_1_NW.gml").is_none()
        || common::fixture("terrain/giswqs-lidar_dem.tif").is_none()
        || common::shared_xsd().is_none()
    {
        return;
    }
    let dir = common::tempdir();
    run_script(dir.path());
    let got = hash_outputs(dir.path());
    let golden_path = common::repo_root().join(HASHES);
    if std::env::var("GEOFIT_BLESS").map(|v| v == "1").unwrap_or(false) {
        let text: String = got.iter().map(|(n, h)| format!("{h}  {n}\n")).collect();
        std::fs::write(&golden_path, text).unwrap();
        eprintln!("blessed {} outputs into {HASHES}", got.len());
        return;
    }
    let golden = parse_hashes(&std::fs::read_to_string(&golden_path).expect("golden hashes"));
    let changed: Vec<String> = golden
        .iter()
        .filter(|(n, h)| got.get(*n) != Some(*h))
        .map(|(n, _)| if got.contains_key(n) { format!("changed: {n}") } else { format!("missing: {n}") })
        .chain(got.keys().filter(|n| !golden.contains_key(*n)).map(|n| format!("new: {n}")))
        .collect();
    assert!(
        changed.is_empty(),
        "{} of {} golden outputs differ (GEOFIT_BLESS=1 re-blesses an intended change):\n{}",
        changed.len(),
        golden.len(),
        changed.join("\n")
    );
}

#[test]
fn the_golden_list_covers_every_subcommand() {
    let script = std::fs::read_to_string(common::repo_root().join(SCRIPT)).unwrap();
    let commands = common::subcommands();
    assert!(commands.len() > 15, "subcommands read from --help: {commands:?}");
    let missing: Vec<&String> = commands.iter().filter(|c| !script.contains(&format!("geofit {c} "))).collect();
    assert!(missing.is_empty(), "{SCRIPT} runs no `geofit {missing:?}`");
}
