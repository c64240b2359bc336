//! The kernel calls of the real-time loop, each behind a tiny safe wrapper (rppal's
//! `ioctl.rs` pattern): the monotonic clock, absolute-deadline sleep, `SCHED_FIFO`,
//! `mlockall`, CPU affinity, timer slack and the CPU wake-up latency request (plus the peak
//! RSS for the job summary, from `/proc`). This is the only module of the runtime with
//! `unsafe`.
//!
//! All of them act on the calling thread (Linux: `pid` 0 means "this thread" for the
//! scheduler calls), so the consumer thread calls them on itself.

use std::io;

/// `CLOCK_MONOTONIC` now, in ns.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until `CLOCK_MONOTONIC` reaches `deadline_ns` (`clock_nanosleep` with
/// `TIMER_ABSTIME`: no drift, however long the work between sleeps took). Restarted when a
/// signal interrupts it.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remainder pointer may be null with
        // TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Puts the calling thread under `SCHED_FIFO` at `priority` (1..=99).
pub fn set_fifo_priority(priority: u8) -> io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority as libc::c_int,
    };
    // SAFETY: `param` is a valid sched_param; pid 0 is the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Locks every current and future page of the process in RAM.
pub fn lock_all_memory() -> io::Result<()> {
    // SAFETY: mlockall takes only flags.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> io::Result<()> {
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(io::Error::from_raw_os_error(libc::EINVAL));
    }
    // SAFETY: an all-zero cpu_set_t is the empty set; CPU_SET stays in bounds (checked above);
    // pid 0 is the calling thread and the size is the set's own.
    let rc = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Sets the calling thread's timer slack to 1 ns. A normal thread's default slack of 50 µs
/// lets the kernel wake it up to 50 µs late, a whole tick at the default period; real-time
/// threads ignore slack, so this matters when `SCHED_FIFO` was refused.
pub fn minimise_timer_slack() -> io::Result<()> {
    // SAFETY: PR_SET_TIMERSLACK takes one integer argument; the rest are ignored.
    let rc = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Asks the kernel (PM QoS, `/dev/cpu_dma_latency`) to keep CPUs out of idle states whose
/// wake-up takes longer than 0 µs, as `cyclictest` does. The request holds while the returned
/// file stays open.
pub fn hold_zero_cpu_wakeup_latency() -> io::Result<std::fs::File> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")?;
    file.write_all(&0i32.to_ne_bytes())?;
    Ok(file)
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absolute_sleep_reaches_its_deadline() {
        let start = monotonic_ns();
        let deadline = start + 2_000_000;
        sleep_until_ns(deadline);
        assert!(monotonic_ns() >= deadline);
        // A deadline in the past returns at once.
        sleep_until_ns(start);
    }

    #[test]
    fn refusals_are_errors_not_panics() {
        // Whether these are permitted depends on the machine; either way they must return.
        let _ = set_fifo_priority(1);
        let _ = lock_all_memory();
        assert!(pin_to_cpu(usize::MAX).is_err());
    }

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
