//! What `/proc` says about this process (no `unsafe`: plain file reads).

/// The process's peak resident set size so far, in KiB: `VmHWM` of `/proc/self/status`, the
/// high-water mark of this program's own memory; 0 if it cannot be read.
///
/// Not `getrusage`'s `ru_maxrss`: Linux carries that across `execve`, so a process started
/// from a large parent (a test harness holding a generated program) reports the parent's peak.
pub fn peak_rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            status
                .lines()
                .find_map(|line| line.strip_prefix("VmHWM:"))
                .and_then(|value| value.trim().trim_end_matches("kB").trim().parse().ok())
        })
        .unwrap_or(0)
}

/// The machine's host name (`/proc/sys/kernel/hostname`), or `localhost` where it cannot be
/// read.
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|s| s.trim().to_string())
        .ok()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "localhost".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_rss_is_read_and_follows_what_the_process_touches() {
        let before = peak_rss_kib();
        assert!(before > 0, "VmHWM not read");
        let touched = vec![1u8; 64 << 20];
        std::hint::black_box(&touched);
        assert!(
            peak_rss_kib() >= before.max(64 << 10),
            "{} KiB",
            peak_rss_kib()
        );
    }
}
