//! `CLOCK_MONOTONIC`: reading it and sleeping until an absolute deadline on it.

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

/// The wall clock now in the machine's local time zone, as `2026-11-23T20-10-03`: a name for
/// files and folders that sorts by time and that a shop reads in its own hours (no `:`, which
/// some file systems and tools refuse).
pub fn local_stamp() -> String {
    // SAFETY: a null pointer asks time() for the current time only.
    local_stamp_of(unsafe { libc::time(std::ptr::null_mut()) })
}

/// [`local_stamp`] of `now`, seconds since the Unix epoch.
pub fn local_stamp_of(now: i64) -> String {
    let now = now as libc::time_t;
    // SAFETY: `tm` is plain data, all-zero is a valid value.
    let mut tm: libc::tm = unsafe { std::mem::zeroed() };
    // SAFETY: both pointers are valid for the call; localtime_r is the reentrant form.
    let ok = !unsafe { libc::localtime_r(&now, &mut tm) }.is_null();
    if !ok {
        return format!("{now}");
    }
    format!(
        "{:04}-{:02}-{:02}T{:02}-{:02}-{:02}",
        tm.tm_year + 1900,
        tm.tm_mon + 1,
        tm.tm_mday,
        tm.tm_hour,
        tm.tm_min,
        tm.tm_sec
    )
}

#[cfg(test)]
mod tests {

    #[test]
    fn the_local_stamp_is_a_date_and_a_time() {
        let s = super::local_stamp();
        let b = s.as_bytes();
        assert_eq!(s.len(), 19, "{s}");
        assert_eq!(
            (b[4], b[7], b[10], b[13], b[16]),
            (b'-', b'-', b'T', b'-', b'-'),
            "{s}"
        );
        assert!(s[..4].parse::<u32>().unwrap() >= 2024, "{s}");
    }
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
}
