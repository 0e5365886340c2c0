//! The memory limits the process runs under, and the check that what a step needs fits them.
//!
//! Two limits can end a process that allocates past them: the address-space limit
//! (`RLIMIT_AS`, `ulimit -v`: every mapping counts, reserved or touched) and the memory limit of
//! the cgroup it runs in (v2 `memory.max`, v1 `memory.limit_in_bytes`: memory actually used, by
//! every process of the group). Past either, an allocation fails: Rust aborts the process, and
//! C code that does not check what `malloc` returns (the AprilTag detector) crashes it. So a step
//! that knows roughly what it will allocate ([`check`], [`how_many_fit`]) compares that with the
//! room each limit leaves before it starts, and refuses with the figures instead.
//!
//! The limits are read through `rustix` (`getrlimit`) and the cgroup's own files; what is in
//! use through `/proc/self/statm` (address space) and the cgroup's usage file. Off Linux, or
//! where a file cannot be read, that limit is taken as absent: the check never refuses on a
//! guess.

use std::path::{Path, PathBuf};

/// One mebibyte, the unit every message uses ("MB").
pub const MB: u64 = 1 << 20;

/// Which limit a figure is of.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LimitKind {
    /// The address-space limit, `ulimit -v` (`RLIMIT_AS`).
    AddressSpace,
    /// The memory limit of the cgroup the process runs in (the limit file).
    Cgroup(PathBuf),
    /// No limit is set, and the system could not give the memory.
    System,
}

impl std::fmt::Display for LimitKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LimitKind::AddressSpace => write!(f, "the address-space limit, `ulimit -v`"),
            LimitKind::Cgroup(file) => write!(f, "the cgroup memory limit, {}", file.display()),
            LimitKind::System => write!(f, "no limit is set: the system has no more to give"),
        }
    }
}

/// A limit the process runs under and how much of it is in use now, bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limit {
    /// Which limit.
    pub kind: LimitKind,
    /// The limit.
    pub bytes: u64,
    /// In use now: this process's address space, or the whole cgroup's memory.
    pub in_use: u64,
}

impl Limit {
    /// What is left under the limit, bytes.
    pub fn room(&self) -> u64 {
        self.bytes.saturating_sub(self.in_use)
    }
}

/// The limits set on this process (none when it runs unlimited), as they stand now.
pub fn limits() -> Vec<Limit> {
    let mut limits = Vec::new();
    if let Some(bytes) = address_space_limit() {
        limits.push(Limit {
            kind: LimitKind::AddressSpace,
            bytes,
            in_use: address_space_in_use().unwrap_or(0),
        });
    }
    limits.extend(cgroup_limit());
    limits
}

/// Whether an address-space limit (`ulimit -v`) is set.
pub fn address_space_limited() -> bool {
    address_space_limit().is_some()
}

/// `RLIMIT_AS`'s soft limit, when one is set.
fn address_space_limit() -> Option<u64> {
    #[cfg(unix)]
    {
        rustix::process::getrlimit(rustix::process::Resource::As).current
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// This process's address space now (`/proc/self/statm`'s first field, in pages).
fn address_space_in_use() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().next()?.parse().ok()?;
    Some(pages * page_size())
}

fn page_size() -> u64 {
    #[cfg(unix)]
    {
        rustix::param::page_size() as u64
    }
    #[cfg(not(unix))]
    {
        4096
    }
}

/// The memory limit of the cgroup this process runs in (v2, else v1), the tightest of its
/// ancestors' (each may set one), with the usage of that group.
fn cgroup_limit() -> Option<Limit> {
    let membership = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let root = Path::new("/sys/fs/cgroup");
    let mut best: Option<Limit> = None;
    for line in membership.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let relative = path.trim_start_matches('/');
        let (base, files) = if controllers.is_empty() {
            (root.to_path_buf(), CGROUP_V2)
        } else if controllers.split(',').any(|c| c == "memory") {
            (root.join("memory"), CGROUP_V1)
        } else {
            continue;
        };
        // The group and each ancestor up to the mount's root.
        let mut dir = base.join(relative);
        loop {
            if let Some(limit) = cgroup_files(&dir, files) {
                if best.as_ref().is_none_or(|b| limit.room() < b.room()) {
                    best = Some(limit);
                }
            }
            if dir == base || !dir.pop() {
                break;
            }
        }
    }
    best
}

/// The files of one cgroup version: its limit, its usage and, in its `memory.stat`, the key of
/// the page cache the kernel drops first under pressure.
#[derive(Debug, Clone, Copy)]
struct CgroupFiles {
    limit: &'static str,
    usage: &'static str,
    inactive_file: &'static str,
}

const CGROUP_V2: CgroupFiles = CgroupFiles {
    limit: "memory.max",
    usage: "memory.current",
    inactive_file: "inactive_file",
};

const CGROUP_V1: CgroupFiles = CgroupFiles {
    limit: "memory.limit_in_bytes",
    usage: "memory.usage_in_bytes",
    inactive_file: "total_inactive_file",
};

/// One cgroup folder's limit and what of it is in use; `None` when it sets no limit ("max", or
/// v1's huge number for none) or cannot be read. In use is the usage less the inactive page
/// cache (the working set, as container runtimes count it): the kernel reclaims that cache
/// before it refuses memory, so counting it would refuse room that is there.
fn cgroup_files(dir: &Path, files: CgroupFiles) -> Option<Limit> {
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).ok();
    let bytes: u64 = read(files.limit)?.trim().parse().ok()?;
    // cgroup v1 says "no limit" with the largest page-aligned i64.
    if bytes >= 1 << 60 {
        return None;
    }
    let usage: u64 = read(files.usage)?.trim().parse().unwrap_or(0);
    let inactive_file = read("memory.stat")
        .and_then(|stat| {
            stat.lines().find_map(|line| {
                let (key, value) = line.split_once(' ')?;
                (key == files.inactive_file).then(|| value.trim().parse::<u64>().ok())?
            })
        })
        .unwrap_or(0);
    Some(Limit {
        kind: LimitKind::Cgroup(dir.join(files.limit)),
        bytes,
        in_use: usage.saturating_sub(inactive_file),
    })
}

/// A step does not fit the memory the process may use: what, how much, the limit.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct NotEnoughMemory {
    /// The step, for people ("detection with 4 detector threads at 1280x720").
    pub what: String,
    /// What it needs besides what is in use, bytes.
    pub needs: u64,
    /// The limit it does not fit.
    pub limit: Limit,
    /// What else to do, starting with " or" (`" or use `-j 1`"`), or empty.
    pub advice: String,
}

impl std::fmt::Display for NotEnoughMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let limit = &self.limit;
        write!(f, "not enough memory: {} needs about ", self.what)?;
        if limit.kind == LimitKind::System {
            write!(f, "{} MB ({})", self.needs.div_ceil(MB), limit.kind)?;
        } else {
            write!(
                f,
                "{} MB ({} MB in use + {} MB more), the limit is {} MB ({})",
                (limit.in_use + self.needs).div_ceil(MB),
                limit.in_use.div_ceil(MB),
                self.needs.div_ceil(MB),
                limit.bytes / MB,
                limit.kind
            )?;
        }
        write!(f, ": raise it{}", self.advice)
    }
}

/// Allocates `bytes` and gives them back at once: whether the memory a step is about to use
/// (in this thread, through the same allocator) is there now. Before C code that does not check
/// its allocations, this turns a crash into this error.
pub fn probe(what: &str, bytes: u64, advice: &str) -> Result<(), NotEnoughMemory> {
    let mut probe: Vec<u8> = Vec::new();
    if probe
        .try_reserve_exact(usize::try_from(bytes).unwrap_or(usize::MAX))
        .is_ok()
    {
        return Ok(());
    }
    Err(not_enough(what, bytes, advice))
}

/// `n` copies of `value`, or, when their memory cannot be had, the error naming `what` and the
/// tightest limit: an allocation that would otherwise abort the process (a frame's buffers under
/// `ulimit -v`) made an error the caller reports.
pub fn try_filled<T: Clone>(what: &str, n: usize, value: T) -> Result<Vec<T>, NotEnoughMemory> {
    let mut filled = try_with_capacity(what, n)?;
    filled.resize(n, value);
    Ok(filled)
}

/// An empty vector with room for `n` values, or the error of [`try_filled`].
pub fn try_with_capacity<T>(what: &str, n: usize) -> Result<Vec<T>, NotEnoughMemory> {
    let mut empty = Vec::new();
    match empty.try_reserve_exact(n) {
        Ok(()) => Ok(empty),
        Err(_) => {
            let bytes = n.saturating_mul(size_of::<T>());
            Err(not_enough(what, bytes as u64, ""))
        }
    }
}

/// The error of `what` needing `bytes` more that could not be had, against the tightest limit
/// the process runs under (the system's when none is set).
fn not_enough(what: &str, bytes: u64, advice: &str) -> NotEnoughMemory {
    let limit = limits()
        .into_iter()
        .min_by_key(Limit::room)
        .unwrap_or(Limit {
            kind: LimitKind::System,
            bytes: 0,
            in_use: 0,
        });
    NotEnoughMemory {
        what: what.to_string(),
        needs: bytes,
        limit,
        advice: advice.to_string(),
    }
}

/// Checks that `needs` bytes more fit under every limit the process runs under now.
pub fn check(what: &str, needs: u64, advice: &str) -> Result<(), NotEnoughMemory> {
    match limits().into_iter().find(|limit| needs > limit.room()) {
        Some(limit) => Err(NotEnoughMemory {
            what: what.to_string(),
            needs,
            limit,
            advice: advice.to_string(),
        }),
        None => Ok(()),
    }
}

/// How many of `wanted` workers fit when each needs `each` bytes on top of `fixed`: `wanted`
/// when every limit has room for them all, else as many as the tightest leaves room for (at
/// least one), or the error for one when not even one fits. `what(n)` names the step with `n`
/// workers.
pub fn how_many_fit(
    what: impl Fn(usize) -> String,
    fixed: u64,
    each: u64,
    wanted: usize,
) -> Result<usize, NotEnoughMemory> {
    let wanted = wanted.max(1);
    let room = limits().into_iter().min_by_key(Limit::room);
    let Some(limit) = room else {
        return Ok(wanted);
    };
    let fit = limit.room().saturating_sub(fixed) / each.max(1);
    if fit >= 1 {
        return Ok(wanted.min(fit as usize));
    }
    Err(NotEnoughMemory {
        what: what(1),
        needs: fixed + each,
        limit,
        advice: String::new(),
    })
}

/// The message for a thread that could not start: a memory limit named as the cause when one
/// is set and the error is the one an exhausted address space gives (`EAGAIN`, "Resource
/// temporarily unavailable": the stack could not be mapped; `ENOMEM`).
pub fn thread_start_error(what: &str, error: &std::io::Error) -> String {
    let memory = matches!(
        error.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::OutOfMemory
    );
    match limits().into_iter().min_by_key(Limit::room) {
        Some(limit) if memory => format!(
            "not enough memory to start {what} ({error}): the limit is {} MB ({}), {} MB of it in use: raise it or use `-j 1`",
            limit.bytes / MB,
            limit.kind,
            limit.in_use.div_ceil(MB)
        ),
        _ => format!("cannot start {what}: {error}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_message_names_memory_the_figures_and_the_limit() {
        let error = NotEnoughMemory {
            what: "detection with 2 detector threads at 1280x720".into(),
            needs: 70 * MB,
            limit: Limit {
                kind: LimitKind::AddressSpace,
                bytes: 96 * MB,
                in_use: 40 * MB,
            },
            advice: " or use `-j 1`".into(),
        };
        assert_eq!(
            error.to_string(),
            "not enough memory: detection with 2 detector threads at 1280x720 needs about 110 MB (40 MB in use + 70 MB more), the limit is 96 MB (the address-space limit, `ulimit -v`): raise it or use `-j 1`"
        );
    }

    #[test]
    fn a_cgroup_folder_without_a_limit_is_no_limit_and_its_page_cache_is_room() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, text: &str| std::fs::write(dir.path().join(name), text).unwrap();
        write("memory.max", "max\n");
        write("memory.current", "1000\n");
        assert_eq!(cgroup_files(dir.path(), CGROUP_V2), None);
        write("memory.max", "268435456\n");
        let limit = cgroup_files(dir.path(), CGROUP_V2).unwrap();
        assert_eq!((limit.bytes, limit.in_use), (256 * MB, 1000));
        // 200 MB used, 150 MB of it inactive page cache: 50 MB in use, 206 MB of room.
        write("memory.current", &(200 * MB).to_string());
        write(
            "memory.stat",
            &format!("anon 1\ninactive_file {}\nactive_file 2\n", 150 * MB),
        );
        let limit = cgroup_files(dir.path(), CGROUP_V2).unwrap();
        assert_eq!((limit.in_use, limit.room()), (50 * MB, 206 * MB));
        // cgroup v1's "no limit".
        write("memory.limit_in_bytes", "9223372036854771712\n");
        write("memory.usage_in_bytes", "1000\n");
        assert_eq!(cgroup_files(dir.path(), CGROUP_V1), None);
    }
}
