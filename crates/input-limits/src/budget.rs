//! The one rule for how much of something untrusted input may make geofit hold in memory:
//! the number an environment variable sets, else what the memory left to the process now holds
//! at the stated cost per unit, else a fixed fallback. The memory left is the smallest of the
//! machine's available memory, the memory cgroup's limit less its usage, and `ulimit -v` /
//! `ulimit -d` less what the process uses ([`memory_headroom`]), and a refusal names the one
//! that applied. Cells (raster-io), points (raster-io, implicit)
//! and whole-input bytes ([`ByteBudget`]) share it, so every refusal reads alike and names the
//! variable that raises the limit.
//!
//! # Examples
//!
//! ```
//! use input_limits::budget::{ByteBudget, BudgetSource};
//!
//! let b = ByteBudget { max_bytes: 1 << 20, source: BudgetSource::Env };
//! assert!(b.allows(1 << 20) && !b.allows((1 << 20) + 1));
//! assert_eq!(b.describe(), "1048576 bytes set by GEOFIT_MAX_INPUT_BYTES");
//! ```

/// The budget when available memory cannot be read: 2³³ units.
pub const FALLBACK_MAX_UNITS: u64 = 1 << 33;

/// Memory available to a new allocation, in bytes (`MemAvailable`), if the system says.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// A limit on this process's memory narrower than the machine's available memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MemoryLimit {
    /// The memory cgroup (v1 or v2, its own or an ancestor's): `docker -m`, systemd `MemoryMax`.
    Cgroup,
    /// `RLIMIT_AS` (`ulimit -v`), less the address space the process already maps.
    AddressSpace,
    /// `RLIMIT_DATA` (`ulimit -d`), less the data segment the process already has.
    DataSize,
}

impl MemoryLimit {
    /// The limit as a message names it.
    pub fn name(self) -> &'static str {
        match self {
            MemoryLimit::Cgroup => "the memory cgroup's limit",
            MemoryLimit::AddressSpace => "ulimit -v (RLIMIT_AS)",
            MemoryLimit::DataSize => "ulimit -d (RLIMIT_DATA)",
        }
    }
}

/// What this process may still allocate, in bytes, and which limit says so: the smallest of the
/// machine's available memory, the memory cgroup's limit less its usage, and `RLIMIT_AS` /
/// `RLIMIT_DATA` less what the process uses (docs/decisions.md#budgets-under-cgroups-and-ulimit).
/// `None` where none of them can be read. A cgroup or rlimit headroom keeps back one eighth for
/// what a budget's cost per unit does not count (libraries loaded later, thread stacks).
pub fn memory_headroom() -> Option<(u64, Option<MemoryLimit>)> {
    let mut best = available_memory().map(|b| (b, None));
    let limits = [
        (cgroup_headroom(), MemoryLimit::Cgroup),
        (rlimit_headroom(RLIMIT_AS_NAME, "VmSize:"), MemoryLimit::AddressSpace),
        (rlimit_headroom(RLIMIT_DATA_NAME, "VmData:"), MemoryLimit::DataSize),
    ];
    for (bytes, limit) in limits {
        let Some(bytes) = bytes else { continue };
        let bytes = bytes - bytes / 8;
        if best.is_none_or(|(b, _)| bytes < b) {
            best = Some((bytes, Some(limit)));
        }
    }
    best
}

const RLIMIT_AS_NAME: &str = "Max address space";
const RLIMIT_DATA_NAME: &str = "Max data size";

/// The soft limit named `name` ("Max address space") in `/proc/self/limits` text, in bytes;
/// `None` when unlimited or absent.
pub fn parse_limits(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    line[name.len()..].split_whitespace().next()?.parse().ok()
}

/// A `kB` field ("VmSize:") of `/proc/self/status` text, in bytes.
pub fn parse_status_kb(text: &str, field: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(field))?;
    let kb: u64 = line[field.len()..].split_whitespace().next()?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// The rlimit `name` less the `used` field of `/proc/self/status`, if the rlimit is set.
fn rlimit_headroom(name: &str, used: &str) -> Option<u64> {
    let limit = parse_limits(&std::fs::read_to_string("/proc/self/limits").ok()?, name)?;
    let used = std::fs::read_to_string("/proc/self/status").ok().and_then(|s| parse_status_kb(&s, used)).unwrap_or(0);
    Some(limit.saturating_sub(used))
}

/// The process's cgroups from `/proc/self/cgroup` text: the v2 path (`0::/path`) and the v1
/// path of the memory controller (`4:memory:/path`), where present.
pub fn parse_proc_cgroup(text: &str) -> (Option<String>, Option<String>) {
    let (mut v2, mut v1) = (None, None);
    for line in text.lines() {
        let mut f = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (f.next(), f.next(), f.next()) else { continue };
        if id == "0" && controllers.is_empty() {
            v2 = Some(path.to_string());
        } else if controllers.split(',').any(|c| c == "memory") {
            v1 = Some(path.to_string());
        }
    }
    (v2, v1)
}

/// The cgroup mounts in `/proc/self/mountinfo` text: (root within the hierarchy, mount point)
/// of the cgroup2 file system and of the v1 hierarchy holding the memory controller.
pub fn parse_cgroup_mounts(text: &str) -> (Option<(String, String)>, Option<(String, String)>) {
    let (mut v2, mut v1) = (None, None);
    for line in text.lines() {
        let Some((left, right)) = line.split_once(" - ") else { continue };
        let left: Vec<&str> = left.split(' ').collect();
        let right: Vec<&str> = right.split(' ').collect();
        let (Some(root), Some(point)) = (left.get(3), left.get(4)) else { continue };
        let mount = Some((root.to_string(), point.replace("\\040", " ")));
        match (right.first(), right.get(2)) {
            (Some(&"cgroup2"), _) if v2.is_none() => v2 = mount,
            (Some(&"cgroup"), Some(opts)) if v1.is_none() && opts.split(',').any(|o| o == "memory") => v1 = mount,
            _ => {}
        }
    }
    (v2, v1)
}

/// A cgroup memory file's value in bytes; `None` for "max" (v2) or a v1 "unlimited" (above 2⁶²).
pub fn parse_cgroup_bytes(text: &str) -> Option<u64> {
    text.trim().parse().ok().filter(|&b: &u64| b < 1 << 62)
}

/// The reclaimable page cache (`inactive_file`) in a cgroup's `memory.stat` text, in bytes:
/// usage counts it, but the kernel drops it before it fails an allocation.
pub fn parse_inactive_file(text: &str, key: &str) -> u64 {
    text.lines().find_map(|l| l.strip_prefix(key)?.strip_prefix(' ')?.trim().parse().ok()).unwrap_or(0)
}

/// The directories of the cgroup `path` under a hierarchy mounted at `point` from `root`, the
/// process's own first and then each ancestor up to the mount's root.
pub fn cgroup_dirs(point: &str, root: &str, path: &str) -> Vec<std::path::PathBuf> {
    let root = root.trim_end_matches('/');
    let rel = path.strip_prefix(root).filter(|r| r.is_empty() || r.starts_with('/')).unwrap_or(path);
    let mut dir = std::path::PathBuf::from(point);
    let mut dirs = vec![dir.clone()];
    for part in rel.split('/').filter(|p| !p.is_empty()) {
        dir.push(part);
        dirs.push(dir.clone());
    }
    dirs.reverse();
    dirs
}

/// The smallest limit less usage over the process's memory cgroup and its ancestors (v2
/// `memory.max` − `memory.current`, v1 `memory.limit_in_bytes` − `memory.usage_in_bytes`, the
/// usage less its reclaimable page cache); `None` where no limit is set or none can be read.
fn cgroup_headroom() -> Option<u64> {
    let read = |p: std::path::PathBuf| std::fs::read_to_string(p).ok();
    let (v2, v1) = parse_proc_cgroup(&read("/proc/self/cgroup".into())?);
    let (m2, m1) = read("/proc/self/mountinfo".into()).map(|t| parse_cgroup_mounts(&t)).unwrap_or_default();
    let m2 = m2.unwrap_or_else(|| ("/".into(), "/sys/fs/cgroup".into()));
    let m1 = m1.unwrap_or_else(|| ("/".into(), "/sys/fs/cgroup/memory".into()));
    let files = [
        (v2, m2, "memory.max", "memory.current", "inactive_file"),
        (v1, m1, "memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file"),
    ];
    let mut best: Option<u64> = None;
    for (path, (root, point), max, current, inactive) in files {
        let Some(path) = path else { continue };
        for dir in cgroup_dirs(&point, &root, &path) {
            let Some(limit) = read(dir.join(max)).and_then(|t| parse_cgroup_bytes(&t)) else { continue };
            let usage = read(dir.join(current)).and_then(|t| parse_cgroup_bytes(&t)).unwrap_or(0);
            let cache = read(dir.join("memory.stat")).map(|t| parse_inactive_file(&t, inactive)).unwrap_or(0);
            let left = limit.saturating_sub(usage.saturating_sub(cache));
            best = Some(best.map_or(left, |b| b.min(left)));
        }
    }
    best
}

/// Where a budget comes from, for the message that refuses a size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BudgetSource {
    /// The environment variable.
    Env,
    /// Available memory (bytes) divided by the cost of a unit.
    Memory(u64),
    /// What a narrower limit leaves the process (bytes) divided by the cost of a unit.
    Limit(u64, MemoryLimit),
    /// Neither: [`FALLBACK_MAX_UNITS`].
    Fallback,
}

/// The most units of `bytes_per_unit` each that may be held, and why: the number `env` sets,
/// else what the memory left to the process holds ([`memory_headroom`]), else the fixed fallback.
pub fn budget(env: &str, bytes_per_unit: u64) -> (u64, BudgetSource) {
    if let Some(n) = std::env::var(env).ok().and_then(|v| v.trim().parse::<u64>().ok()) {
        return (n, BudgetSource::Env);
    }
    match memory_headroom() {
        Some((b, None)) => (b / bytes_per_unit.max(1), BudgetSource::Memory(b)),
        Some((b, Some(limit))) => (b / bytes_per_unit.max(1), BudgetSource::Limit(b, limit)),
        None => (FALLBACK_MAX_UNITS, BudgetSource::Fallback),
    }
}

/// Why a budget is what it is, for an error message ("… more than {this}").
pub fn describe(limit: u64, what: &str, source: BudgetSource, env: &str) -> String {
    match source {
        BudgetSource::Env => format!("{limit} {what} set by {env}"),
        BudgetSource::Memory(b) => {
            format!("{limit} {what}, what the {} of available memory hold; {env} sets another limit", gib(b))
        }
        BudgetSource::Limit(b, l) => {
            format!("{limit} {what}, what the {} left under {} hold; {env} sets another limit", size(b), l.name())
        }
        BudgetSource::Fallback => format!("{limit} {what}; {env} sets another limit"),
    }
}

/// `bytes` as "12.3 GiB".
pub fn gib(bytes: u64) -> String {
    format!("{:.1} GiB", bytes as f64 / (1u64 << 30) as f64)
}

/// `bytes` as "12.3 GiB", or "456 MiB" below one GiB.
fn size(bytes: u64) -> String {
    if bytes >= 1 << 30 {
        gib(bytes)
    } else {
        format!("{} MiB", bytes >> 20)
    }
}

/// The environment variable that sets the whole-input byte budget explicitly.
pub const MAX_INPUT_BYTES_ENV: &str = "GEOFIT_MAX_INPUT_BYTES";

/// What one byte of an input read whole costs before it is parsed: the byte itself, and as much
/// again for the parsed form built beside it (a CityGML tree, a popa3d model, a point list).
pub const READ_BYTES_PER_INPUT_BYTE: u64 = 2;

/// The most bytes a command may read whole from one input (a file, or stdin that never ends:
/// `geofit info /dev/zero`), and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ByteBudget {
    pub max_bytes: u64,
    pub source: BudgetSource,
}

impl ByteBudget {
    /// The budget of the running process ([`MAX_INPUT_BYTES_ENV`] or available memory).
    pub fn current() -> ByteBudget {
        let (max_bytes, source) = budget(MAX_INPUT_BYTES_ENV, READ_BYTES_PER_INPUT_BYTE);
        ByteBudget { max_bytes, source }
    }

    /// Whether `len` bytes fit.
    pub fn allows(&self, len: u64) -> bool {
        len <= self.max_bytes
    }

    /// Why the limit is what it is, for an error message ("… more than {this}").
    pub fn describe(&self) -> String {
        describe(self.max_bytes, "bytes", self.source, MAX_INPUT_BYTES_ENV)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_budget_divides_by_the_cost_and_names_the_variable() {
        match budget("GEOFIT_TEST_UNSET_BUDGET_VARIABLE", 8) {
            (n, BudgetSource::Memory(b)) | (n, BudgetSource::Limit(b, _)) => assert_eq!(n, b / 8),
            (_, source) => panic!("{source:?}"),
        }
        assert!(describe(7, "cells", BudgetSource::Memory(1 << 30), "X").ends_with("; X sets another limit"));
        assert_eq!(describe(5, "points", BudgetSource::Fallback, "Y"), "5 points; Y sets another limit");
        let d = describe(9, "bytes", BudgetSource::Limit(300 << 20, MemoryLimit::AddressSpace), "Z");
        assert_eq!(d, "9 bytes, what the 300 MiB left under ulimit -v (RLIMIT_AS) hold; Z sets another limit");
        let d = describe(9, "bytes", BudgetSource::Limit(3 << 30, MemoryLimit::Cgroup), "Z");
        assert_eq!(d, "9 bytes, what the 3.0 GiB left under the memory cgroup's limit hold; Z sets another limit");
    }

    #[test]
    fn proc_self_limits_give_the_soft_limit_or_none_when_unlimited() {
        let text = "Limit                     Soft Limit           Hard Limit           Units     \n\
                    Max data size             unlimited            unlimited            bytes     \n\
                    Max stack size            8388608              unlimited            bytes     \n\
                    Max address space         1073741824           unlimited            bytes     \n";
        assert_eq!(parse_limits(text, RLIMIT_AS_NAME), Some(1 << 30));
        assert_eq!(parse_limits(text, RLIMIT_DATA_NAME), None);
        assert_eq!(parse_limits("", RLIMIT_AS_NAME), None);
        let status = "Name:\tgeofit\nVmPeak:\t  182876 kB\nVmSize:\t  182636 kB\nVmData:\t    6024 kB\n";
        assert_eq!(parse_status_kb(status, "VmSize:"), Some(182636 * 1024));
        assert_eq!(parse_status_kb(status, "VmData:"), Some(6024 * 1024));
        assert_eq!(parse_status_kb(status, "VmSwap:"), None);
        assert!(
            parse_limits(&std::fs::read_to_string("/proc/self/limits").unwrap_or_default(), "Max stack size").is_some()
                || !std::path::Path::new("/proc/self/limits").exists()
        );
    }

    #[test]
    fn proc_self_cgroup_gives_the_v2_path_and_the_v1_memory_path() {
        assert_eq!(
            parse_proc_cgroup("0::/user.slice/session-1.scope\n"),
            (Some("/user.slice/session-1.scope".into()), None)
        );
        let hybrid = "9:name=systemd:/\n4:memory:/docker/abc\n3:cpu,cpuacct:/\n0::/\n";
        assert_eq!(parse_proc_cgroup(hybrid), (Some("/".into()), Some("/docker/abc".into())));
        assert_eq!(parse_proc_cgroup("5:memory,hugetlb:/a:b\n"), (None, Some("/a:b".into())));
        assert_eq!(parse_proc_cgroup(""), (None, None));
    }

    #[test]
    fn cgroup_files_and_mounts_parse() {
        assert_eq!(parse_cgroup_bytes("max\n"), None);
        assert_eq!(parse_cgroup_bytes("1073741824\n"), Some(1 << 30));
        assert_eq!(parse_cgroup_bytes("9223372036854771712\n"), None); // v1 "unlimited"
        assert_eq!(parse_cgroup_bytes(""), None);
        let stat = "anon 100\nfile 300\ninactive_file 200\nactive_file 100\n";
        assert_eq!(parse_inactive_file(stat, "inactive_file"), 200);
        assert_eq!(parse_inactive_file("cache 5\ntotal_inactive_file 7\n", "total_inactive_file"), 7);
        assert_eq!(parse_inactive_file("cache 5\n", "inactive_file"), 0);
        let mountinfo = "31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755\n\
                         35 31 0:32 /docker/abc /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory\n\
                         36 31 0:33 / /sys/fs/cgroup/cpu rw,relatime shared:9 - cgroup cgroup rw,cpu\n\
                         41 31 0:38 / /sys/fs/cgroup/unified rw,relatime shared:10 - cgroup2 cgroup2 rw\n";
        let (v2, v1) = parse_cgroup_mounts(mountinfo);
        assert_eq!(v2, Some(("/".into(), "/sys/fs/cgroup/unified".into())));
        assert_eq!(v1, Some(("/docker/abc".into(), "/sys/fs/cgroup/memory".into())));
        let p = |s: &str| std::path::PathBuf::from(s);
        // a container sees its own cgroup at the mount point
        assert_eq!(cgroup_dirs("/sys/fs/cgroup/memory", "/docker/abc", "/docker/abc"), [p("/sys/fs/cgroup/memory")]);
        assert_eq!(
            cgroup_dirs("/sys/fs/cgroup", "/", "/a/b"),
            [p("/sys/fs/cgroup/a/b"), p("/sys/fs/cgroup/a"), p("/sys/fs/cgroup")]
        );
        assert_eq!(cgroup_dirs("/sys/fs/cgroup", "/", "/"), [p("/sys/fs/cgroup")]);
    }

    #[test]
    fn the_smallest_headroom_applies() {
        if let Some((bytes, _)) = memory_headroom() {
            assert!(available_memory().is_none_or(|a| bytes <= a));
        }
    }
}
