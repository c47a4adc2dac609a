//! What this process has used so far, for the `seconds`/`cpu_seconds`/`peak_rss_mib` fields of
//! JSON reports: read from Linux's `/proc/self`; `None` on other systems, never an error.

/// CPU seconds (user + system, all threads): `/proc/self/stat` fields 14 and 15 in
/// USER_HZ = 100 ticks per second. Less load-dependent than wall time on a shared machine.
pub fn cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name (which may contain spaces).
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let (u, k): (f64, f64) = (f.get(11)?.parse().ok()?, f.get(12)?.parse().ok()?);
    Some((u + k) / 100.0)
}

/// Peak resident set size in MiB (`/proc/self/status` VmHWM).
pub fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(target_os = "linux")]
    fn a_running_process_has_used_memory_and_some_cpu() {
        let rss = super::peak_rss_mib().expect("VmHWM on Linux");
        assert!(rss > 0.5 && rss < 1e6, "{rss}");
        let spin: u64 = (0..3_000_000u64).fold(0, |a, b| a.wrapping_add(b * b));
        assert!(spin > 0);
        assert!(super::cpu_seconds().expect("stat on Linux") >= 0.0);
    }
}
