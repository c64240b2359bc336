//! What `/proc` says about this process and others (no `unsafe`: plain file reads).

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

/// A process as `/proc/PID/stat` tells it: its name, its state letter and when it started
/// (clock ticks after boot), which together with the pid names one process for good (a pid
/// is reused; a pid and its start time are not).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProcessStat {
    pub name: String,
    pub state: char,
    pub start_ticks: u64,
}

impl ProcessStat {
    /// The process has ended: a zombie waiting for its parent, or dead.
    pub fn ended(&self) -> bool {
        matches!(self.state, 'Z' | 'X' | 'x')
    }
}

/// `/proc/PID/stat` of `pid`, `None` when there is no such process.
pub fn process_stat(pid: u32) -> Option<ProcessStat> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    parse_stat(&text)
}

/// This process's start time (clock ticks after boot).
pub fn own_start_ticks() -> u64 {
    process_stat(std::process::id()).map_or(0, |s| s.start_ticks)
}

/// Whether a live process (not a zombie) named `name` runs (as `ps -C name` finds it; the
/// name is the kernel's, at most 15 bytes).
pub fn process_running(name: &str) -> bool {
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return false;
    };
    dir.flatten()
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter_map(process_stat)
        .any(|s| s.name == name && !s.ended())
}

/// `PID (NAME) STATE ... starttime ...`: the name may hold spaces and parentheses, so the
/// fields after it are counted from its last `)`; the start time is field 22.
fn parse_stat(text: &str) -> Option<ProcessStat> {
    let open = text.find('(')?;
    let close = text.rfind(')')?;
    let name = text.get(open + 1..close)?.to_string();
    let mut rest = text.get(close + 1..)?.split_whitespace();
    let state = rest.next()?.chars().next()?;
    // Fields 4 to 21 lie between the state (3) and the start time (22).
    let start_ticks = rest.nth(18)?.parse().ok()?;
    Some(ProcessStat {
        name,
        state,
        start_ticks,
    })
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

    #[test]
    fn stat_lines_are_read_past_names_with_spaces_and_parentheses() {
        let line = "4242 (edmd (serve) x) S 1 4242 4242 0 -1 4194560 100 0 0 0 5 3 0 0 20 0 \
                    9 0 123456 10000 200 18446744073709551615";
        let s = parse_stat(line).unwrap();
        assert_eq!(s.name, "edmd (serve) x");
        assert_eq!(s.state, 'S');
        assert_eq!(s.start_ticks, 123456);
        assert!(!s.ended());
        assert!(parse_stat("12 (z) Z 1").is_none(), "too short");
        let own = process_stat(std::process::id()).unwrap();
        assert_eq!(own.start_ticks, own_start_ticks());
        assert!(!own.ended());
        assert!(process_stat(u32::MAX).is_none());
    }
}
