//! Names that say which process wrote a temporary file or holds a lease: `{host}-pid{pid}`,
//! followed by `-{random}`. A process on the same host can then tell whether the writer is still
//! running (`/proc/{pid}`), so leftovers of a killed process are reclaimed at once and a live
//! process's files are never touched.

use std::path::Path;

/// `{host}-pid{pid}` of this process.
pub fn process_tag() -> String {
    format!("{}-pid{}", host_name(), std::process::id())
}

/// `{host}-pid{pid}-{random}` -> (host, pid); the random part has no `-`.
pub fn parse_tagged(tagged: &str) -> Option<(&str, u32)> {
    let (rest, _random) = tagged.rsplit_once('-')?;
    let (host, pid) = rest.rsplit_once("-pid")?;
    Some((host, pid.parse().ok()?))
}

/// Whether `tagged` (`{host}-pid{pid}-{random}`) names a process on this host, other than this
/// one, that has exited. `false` when the name does not parse, names another host, or this
/// process (several services may run in one process, as tests do).
pub fn tagged_by_a_stopped_local_process(tagged: &str) -> bool {
    let Some((host, pid)) = parse_tagged(tagged) else {
        return false;
    };
    host == host_name() && pid != std::process::id() && !process_alive(pid)
}

/// Whether a process with this pid exists. Without `/proc` (not Linux) every process counts as
/// alive, so nothing is taken early.
pub fn process_alive(pid: u32) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    Path::new(&format!("/proc/{pid}")).exists()
}

/// `HOSTNAME`, else the kernel's host name, else `segsplat` (a `/`, which would break file
/// names, becomes `_`).
pub fn host_name() -> String {
    std::env::var("HOSTNAME")
        .ok()
        .or_else(|| std::fs::read_to_string("/proc/sys/kernel/hostname").ok())
        .map(|name| name.trim().replace('/', "_"))
        .filter(|name| !name.is_empty())
        .unwrap_or_else(|| "segsplat".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tags_parse_and_tell_stopped_processes() {
        let tag = process_tag();
        assert!(!tagged_by_a_stopped_local_process(&format!("{tag}-abc")));
        let host = host_name();
        // Above the kernel's pid limit: cannot be running.
        assert!(tagged_by_a_stopped_local_process(&format!(
            "{host}-pid4294967-x1"
        )));
        assert!(!tagged_by_a_stopped_local_process(&format!(
            "{host}-pid1-x1"
        )));
        assert!(!tagged_by_a_stopped_local_process(
            "elsewhere-pid4294967-x1"
        ));
        assert!(!tagged_by_a_stopped_local_process("no-tag"));
        assert_eq!(parse_tagged("a-b-pid12-r4nd"), Some(("a-b", 12)));
    }
}
