//! The CLI as a whole: every subcommand is listed in `geofit --help` with a one-line summary,
//! in alphabetical order, and its own `--help` shows it.

mod common;

#[test]
fn every_subcommand_has_a_summary_in_the_top_level_help() {
    let o = common::run(&["--help"], None);
    assert_eq!(common::code(&o), 0);
    let text = String::from_utf8_lossy(&o.stdout);
    let mut names = Vec::new();
    let mut in_commands = false;
    for line in text.lines() {
        if line.starts_with("Commands:") {
            in_commands = true;
            continue;
        }
        if in_commands && !line.starts_with(' ') {
            break;
        }
        // a command line: two spaces, the name, then its summary (a continuation line has none)
        if let Some(rest) = line.strip_prefix("  ").filter(|r| !r.starts_with(' ')) {
            let mut parts = rest.splitn(2, char::is_whitespace);
            let name = parts.next().unwrap();
            let summary = parts.next().unwrap_or("").trim();
            assert!(!summary.is_empty(), "`geofit {name}` has no summary in --help");
            if name != "help" {
                names.push(name.to_string());
                let sub = common::run(&[name, "--help"], None);
                assert_eq!(common::code(&sub), 0, "{name} --help");
                let first = String::from_utf8_lossy(&sub.stdout).lines().next().unwrap_or("").to_string();
                let head: String = summary.chars().take(30).collect();
                assert!(
                    first.starts_with(&head),
                    "`geofit {name} --help` starts with '{first}', the list says '{summary}'"
                );
            }
        }
    }
    assert!(names.len() >= 17, "{names:?}");
    let mut sorted = names.clone();
    sorted.sort();
    assert_eq!(names, sorted, "subcommands are listed alphabetically");
}

/// Runs geofit with stderr on `/dev/full` (every write fails with ENOSPC), or with stderr a pipe
/// whose reading end is already closed (EPIPE), stdin from `stdin`; returns the exit code.
fn run_with_broken_stderr(args: &[&str], stdin: Option<&[u8]>, full: bool) -> i32 {
    use std::io::Write;
    use std::process::Stdio;
    let mut cmd = common::geofit();
    cmd.args(args).stdout(Stdio::null());
    cmd.stdin(if stdin.is_some() { Stdio::piped() } else { Stdio::null() });
    if full {
        cmd.stderr(std::fs::OpenOptions::new().write(true).open("/dev/full").expect("/dev/full"));
    } else {
        cmd.stderr(Stdio::piped());
    }
    let mut child = cmd.spawn().expect("spawn geofit");
    drop(child.stderr.take()); // closes the reading end: the child's stderr writes get EPIPE
    if let Some(data) = stdin {
        let mut si = child.stdin.take().unwrap();
        let data = data.to_vec();
        std::thread::spawn(move || {
            let _ = si.write_all(&data);
        });
    }
    let status = child.wait().expect("wait geofit");
    status.code().unwrap_or_else(|| panic!("{args:?}: killed by a signal"))
}

/// Issue 13, item 3: progress, notices and summaries on stderr never panic when stderr is full
/// (`2>/dev/full`) or a closed pipe (`2>&1 | head -n 1`): the command does its work and writes
/// its output. Before, `eprintln!` panicked (exit 101) in fit, heal, rasterize and adjust.
#[test]
fn a_full_or_closed_stderr_does_not_stop_the_work() {
    let dir = common::tempdir();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    std::fs::write(
        d.join("r.asc"),
        "ncols 3\nnrows 3\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n1 2 3\n4 5 6\n7 8 10\n",
    )
    .unwrap();
    std::fs::write(d.join("p.xyz"), "0 0 1\n4 0 2\n0 4 3\n4 4 5\n2 2 2\n").unwrap();
    let gml = common::repo_root().join("fixtures/citygml/three_storey.gml");
    let model = common::run(&["citygml2popa3d", "-q", gml.to_str().unwrap()], None);
    assert_eq!(common::code(&model), 0, "{}", String::from_utf8_lossy(&model.stderr));
    for full in [true, false] {
        let tag = if full { "full" } else { "pipe" };
        let cases: Vec<(Vec<String>, Option<&[u8]>, String)> = vec![
            (
                vec![
                    "fit".into(),
                    p("r.asc"),
                    "--max-error".into(),
                    "0.01".into(),
                    "-o".into(),
                    p(&format!("fit-{tag}.tmesh")),
                ],
                None,
                p(&format!("fit-{tag}.tmesh")),
            ),
            (
                vec![
                    "rasterize".into(),
                    p("p.xyz"),
                    "--cell".into(),
                    "1".into(),
                    "-o".into(),
                    p(&format!("r-{tag}.tif")),
                ],
                None,
                p(&format!("r-{tag}.tif")),
            ),
            (
                vec!["heal".into(), gml.to_str().unwrap().into(), "-o".into(), p(&format!("h-{tag}.gml"))],
                None,
                p(&format!("h-{tag}.gml")),
            ),
            (
                vec!["adjust".into(), "-".into(), "-o".into(), p(&format!("a-{tag}.popa3d"))],
                Some(&model.stdout[..]),
                p(&format!("a-{tag}.popa3d")),
            ),
        ];
        for (args, stdin, out) in cases {
            let a: Vec<&str> = args.iter().map(String::as_str).collect();
            let code = run_with_broken_stderr(&a, stdin, full);
            assert_ne!(code, 101, "{tag}: {a:?} panicked");
            assert!([0, 1].contains(&code), "{tag}: {a:?} exit {code}");
            assert!(std::path::Path::new(&out).exists(), "{tag}: {a:?} wrote no output");
        }
    }
}

/// Every stderr write of the CLI goes through `config::stderr_line` (the `say!` macro), which
/// ignores write errors; a plain `eprintln!` would bring the panic above back.
#[test]
fn the_cli_has_no_eprintln() {
    let files = common::rust_sources(&common::repo_root().join("crates/geofit/src"));
    assert!(files.len() > 30, "the CLI's sources: {files:?}");
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for (i, line) in text.lines().enumerate() {
            assert!(
                !line.contains("eprintln!(") && !line.contains("eprint!("),
                "{}:{}: use crate::say! (stderr errors ignored)",
                f.display(),
                i + 1
            );
        }
    }
}

/// Issue 13, item 7: with stdout closed (`>&-`) a report command fails like any other failed
/// write (exit 4) instead of exiting 0 having written nothing; `info` on an empty stdin says
/// the input is empty (it said "no points", from the XYZ reader it tried last).
#[test]
fn closed_stdout_is_a_write_failure_and_empty_input_is_named() {
    let gml = common::repo_root().join("fixtures/citygml/three_storey.gml");
    let bin = env!("CARGO_BIN_EXE_geofit");
    for json in ["", "--json"] {
        let o = std::process::Command::new("sh")
            .arg("-c")
            .arg(format!("exec '{bin}' info {json} '{}' >&-", gml.display()))
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(4), "info {json}: {e}");
        assert!(e.contains("stdout is closed"), "{e}");
    }
    // stdout on /dev/null is not closed: still a success
    let o = std::process::Command::new(bin)
        .args(["info", gml.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    for (input, says) in
        [(&b""[..], "<stdin>: no input (the previous stage wrote nothing)"), (b"\n  \n", "<stdin>: the input is empty")]
    {
        let o = common::run(&["info", "-"], Some(input));
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(common::code(&o), 3, "{e}");
        assert!(e.contains(says) && !e.contains("no points"), "{e}");
    }
}

/// `--report -` with the data also on stdout would mix JSON into the data stream: a usage error
/// before any work (exit 2, nothing on stdout), for every command that has both.
#[test]
fn report_to_stdout_needs_an_output_file() {
    for args in [
        &["fit", "x.tif", "--max-error", "1", "--report", "-"][..],
        &["adjust", "x.popa3d", "--report", "-"][..],
        &["rasterize", "x.xyz", "--cell", "1", "--report", "-"][..],
        &["heal", "x.gml", "--report", "-"][..],
    ] {
        let o = common::run(args, None);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(common::code(&o), 2, "{args:?}: {e}");
        assert!(e.contains("--report - needs -o FILE") && o.stdout.is_empty(), "{args:?}: {e}");
    }
}

/// Internal references a user cannot resolve: spec sections, decision numbers, seed equations,
/// source paths and Rust paths (they belong in doc comments, not in `--help`).
const INTERNAL: [&str; 7] = ["§", "seed eq", "seed 00", "crates/", "::", "docs/decisions", " T29"];

/// Every subcommand (and `implicit`'s stages) shows a worked example in its `--help`, describes
/// every option, and cites nothing internal.
#[test]
fn every_subcommand_help_has_an_example_and_no_internal_references() {
    let top = common::run(&["--help"], None);
    let text = String::from_utf8_lossy(&top.stdout).to_string();
    let mut commands: Vec<Vec<String>> = text
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with(' '))
        .filter_map(|l| l.strip_prefix("  ").filter(|r| !r.starts_with(' ')))
        .map(|r| r.split_whitespace().next().unwrap().to_string())
        .filter(|n| n != "help")
        .map(|n| vec![n])
        .collect();
    for stage in ["run", "interpolate", "update", "iso", "section", "csg"] {
        commands.push(vec!["implicit".into(), stage.into()]);
    }
    let mut problems = Vec::new();
    for cmd in &commands {
        let mut args: Vec<&str> = cmd.iter().map(String::as_str).collect();
        args.push("--help");
        let o = common::run(&args, None);
        let help = String::from_utf8_lossy(&o.stdout).to_string();
        let name = cmd.join(" ");
        if !help.to_lowercase().contains("example") {
            problems.push(format!("`geofit {name} --help` has no example"));
        }
        for r in INTERNAL {
            if help.contains(r) {
                problems.push(format!("`geofit {name} --help` cites '{r}'"));
            }
        }
        for undocumented in undocumented_options(&help) {
            problems.push(format!("`geofit {name} --help`: {undocumented} has no description"));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// Option lines of a clap long help (`  -o, --output <X>` / `      --flag`) not followed by an
/// indented description line.
fn undocumented_options(help: &str) -> Vec<String> {
    let lines: Vec<&str> = help.lines().collect();
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim_start();
        let indent = l.len() - t.len();
        if (2..=6).contains(&indent) && t.starts_with('-') {
            // clap's compact form puts the description on the flag's line after 2+ spaces; its
            // long form on the next, deeper-indented line
            let same_line = t.split_once("  ").is_some_and(|(_, d)| !d.trim().is_empty());
            let next = lines.get(i + 1).copied().unwrap_or("");
            let next_line = next.len() - next.trim_start().len() > indent + 2 && !next.trim().is_empty();
            let described = same_line || next_line;
            if !described && !t.starts_with("-h, --help") && !t.starts_with("-V, --version") {
                out.push(t.to_string());
            }
        }
    }
    out
}

/// Help texts speak to users: no section, equation, table or decision numbers of the research
/// documents behind the code (those are for developers, in docs/sources.md) and no "the spec".
#[test]
fn help_texts_cite_no_spec_sections_or_decision_numbers() {
    let top = common::run(&["--help"], None);
    let top = String::from_utf8_lossy(&top.stdout).to_string();
    let commands = common::subcommands();
    let subs = [
        "interpolate",
        "update",
        "iso",
        "section",
        "csg",
        "run",
        "plan",
        "extract",
        "tileset",
        "report",
        "stitch",
        "seams",
    ];
    let mut texts = vec![("geofit".to_string(), top.clone())];
    for c in &commands {
        for sub in std::iter::once(None).chain(subs.iter().map(Some)) {
            let mut args = vec![c.as_str()];
            args.extend(sub.copied());
            args.push("--help");
            let o = common::run(&args, None);
            if o.status.success() {
                texts.push((args[..args.len() - 1].join(" "), String::from_utf8_lossy(&o.stdout).to_string()));
            }
        }
    }
    assert!(texts.len() > 25, "help texts read: {}", texts.len());
    let decision = |w: &str| {
        let w = w.trim_matches(|c: char| !c.is_ascii_alphanumeric());
        w.len() >= 2
            && w.len() <= 3
            && (w.starts_with('A') || w.starts_with('T'))
            && w[1..].chars().all(|c| c.is_ascii_digit())
    };
    for (cmd, text) in &texts {
        for line in text.lines() {
            let bad = line.contains('§')
                || line.contains("the spec")
                || line.contains("Table B")
                || line.contains(" eq. ")
                || line.split_whitespace().any(decision);
            assert!(!bad, "`geofit {cmd} --help` cites a research document: {line}");
        }
    }
}

/// Issue 16: the CLI stays thin. No file of the CLI crate is over 300 lines, and no subcommand
/// imports another (`crate::cmd::args`, the option groups they share, is not a subcommand; a
/// subcommand's own folder may share a `mod.rs`).
#[test]
fn the_cli_is_small_files_that_do_not_import_each_other() {
    let src = common::repo_root().join("crates/geofit/src");
    let files = common::rust_sources(&src);
    let cmd = src.join("cmd");
    let subcommands: Vec<String> = std::fs::read_dir(&cmd)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path().file_stem().unwrap().to_string_lossy().into_owned())
        .filter(|n| n != "mod" && n != "args")
        .collect();
    assert!(subcommands.len() > 15, "{subcommands:?}");
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let lines = text.lines().count();
        assert!(lines <= 300, "{}: {lines} lines; split it along its ideas (issue 16)", f.display());
        let Ok(rel) = f.strip_prefix(&cmd) else { continue };
        let own = rel.components().next().unwrap().as_os_str().to_string_lossy().trim_end_matches(".rs").to_string();
        for (i, line) in text.lines().enumerate() {
            for other in subcommands.iter().filter(|s| **s != own) {
                let imports = line.contains(&format!("cmd::{other}::"))
                    || line.contains(&format!("cmd::{other};"))
                    || line.contains(&format!("super::{other}::"));
                assert!(!imports, "{}:{}: subcommand `{own}` uses subcommand `{other}`; move the shared part to a library or the CLI's utility modules", f.display(), i + 1);
            }
        }
    }
}

/// Issue 16: every library crate's main page (its lib.rs) carries a runnable `# Examples`
/// doctest (a ```` ``` ```` fence without `text`, `ignore` or another language), which
/// `cargo test --doc` (part of `make test`) runs.
#[test]
fn every_library_crate_opens_with_a_runnable_example() {
    let crates = common::repo_root().join("crates");
    let mut missing = Vec::new();
    let mut seen = 0;
    for e in std::fs::read_dir(&crates).unwrap() {
        let lib = e.unwrap().path().join("src/lib.rs");
        let Ok(text) = std::fs::read_to_string(&lib) else { continue };
        seen += 1;
        let docs: Vec<&str> =
            text.lines().filter(|l| l.starts_with("//!")).map(|l| l.trim_start_matches("//!").trim()).collect();
        let runnable = docs.iter().any(|l| *l == "```" || *l == "```rust" || *l == "```no_run");
        if !(docs.contains(&"# Examples") && runnable) {
            missing.push(lib.display().to_string());
        }
    }
    assert!(seen >= 17, "library crates found: {seen}");
    assert!(missing.is_empty(), "no runnable `# Examples` on the crate page: {missing:?}");
}
