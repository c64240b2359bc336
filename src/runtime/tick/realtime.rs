//! The real-time features the consumer's thread asks for before its loop starts
//! (`SCHED_FIFO`, `mlockall`, CPU pinning, timer slack, `/dev/cpu_dma_latency`), each refusal
//! a warning and a reason, never an error.

use super::consumer::LoopSettings;
use crate::sys;

/// Real-time features in force for the loop; dropping it releases them.
#[derive(Debug, Default)]
pub struct RealtimeGuard {
    /// Holds the zero wake-up latency request while open.
    _cpu_latency: Option<std::fs::File>,
    /// What the system refused, as operator-facing reasons.
    pub refused: Vec<String>,
}

/// Applies the configured real-time features to the calling thread; refusals come back as
/// human-readable reasons (and are logged as warnings), never as errors. In real time the
/// timer slack is always minimised and, with `lock_memory`, CPUs are kept out of deep idle
/// states (`/dev/cpu_dma_latency`, as cyclictest does).
pub fn apply_realtime(settings: &LoopSettings) -> RealtimeGuard {
    let mut guard = RealtimeGuard::default();
    if settings.virtual_time {
        return guard;
    }
    let refused = &mut guard.refused;
    if let Err(e) = sys::minimise_timer_slack() {
        refused.push(format!(
            "timer slack: cannot minimise it ({e}); wake-ups may come up to 50 µs late"
        ));
    }
    if settings.lock_memory {
        if let Err(e) = sys::lock_all_memory() {
            refused.push(format!(
                "fine.lock_memory: mlockall refused ({e}); running with pageable memory \
                 (raise RLIMIT_MEMLOCK, e.g. systemd LimitMEMLOCK=infinity)"
            ));
        }
        match sys::hold_zero_cpu_wakeup_latency() {
            Ok(file) => guard._cpu_latency = Some(file),
            Err(e) => refused.push(format!(
                "fine.lock_memory: cannot hold /dev/cpu_dma_latency at 0 ({e}); CPUs may sleep \
                 in deep idle states between ticks"
            )),
        }
    }
    if let Some(cpu) = settings.cpu
        && let Err(e) = sys::pin_to_cpu(cpu)
    {
        refused.push(format!(
            "fine.cpu: cannot pin to CPU {cpu} ({e}); running on any CPU"
        ));
    }
    if settings.rt_priority > 0
        && let Err(e) = sys::set_fifo_priority(settings.rt_priority)
    {
        refused.push(format!(
            "fine.rt_priority: SCHED_FIFO {} refused ({e}); running at normal priority \
             (needs CAP_SYS_NICE or RLIMIT_RTPRIO, e.g. systemd LimitRTPRIO={})",
            settings.rt_priority, settings.rt_priority
        ));
    }
    for reason in &guard.refused {
        tracing::warn!("{reason}");
    }
    guard
}
