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
                assert!(first.starts_with(&head), "`geofit {name} --help` starts with '{first}', the list says '{summary}'");
            }
        }
    }
    assert!(names.len() >= 17, "{names:?}");
    let mut sorted = names.clone();
    sorted.sort();
    assert_eq!(names, sorted, "subcommands are listed alphabetically");
}
