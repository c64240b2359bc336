//! Real-time settings of the calling thread: `SCHED_FIFO`, `mlockall`, CPU affinity, timer
//! slack and the CPU wake-up latency request. All act on the calling thread (Linux: `pid` 0
//! means "this thread" for the scheduler calls), so the fine thread calls them on itself.

use std::io;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_errors_not_panics() {
        // Whether these are permitted depends on the machine; either way they must return.
        let _ = set_fifo_priority(1);
        let _ = lock_all_memory();
        assert!(pin_to_cpu(usize::MAX).is_err());
    }
}
