//! The kernel calls edmd makes, each behind a tiny safe wrapper (rppal's `ioctl.rs`
//! pattern): the monotonic clock and absolute-deadline sleep ([`clock`]), the real-time
//! settings of a thread ([`rt`]), looking up a group ([`group`]), what `/proc` says of
//! this process ([`proc`]), the descriptor limit ([`limits`]), and opening files that may
//! have been swapped for a FIFO without blocking ([`files`]).
//!
//! With `parport/ioctl.rs` (the ppdev ioctls, kept beside the device they drive), these are
//! the only modules allowed `unsafe`: `src/lib.rs` denies it everywhere else, and each
//! `unsafe` block here carries a `// SAFETY:` comment (clippy's
//! `undocumented_unsafe_blocks` is an error in CI).
//!
//! Must never: import another edmd module, log, or hold state. A refusal is an
//! `io::Error` for the caller to word; nothing here panics on what the kernel answers.

#[allow(unsafe_code)]
mod clock;
mod files;
#[allow(unsafe_code)]
mod group;
#[allow(unsafe_code)]
mod limits;
mod proc;
#[allow(unsafe_code)]
mod rt;
mod writer;

pub use clock::{local_stamp, local_stamp_of, monotonic_ns, sleep_until_ns};
pub use files::{
    PrivateText, create_private, open_regular, random_hex, read_private, read_regular,
    temporary_path, write_atomic,
};
pub use group::group_id;
pub use limits::raise_descriptor_limit;
pub use proc::{
    ProcessStat, host_name, own_start_ticks, peak_rss_kib, process_running, process_stat,
};
pub use rt::{
    hold_zero_cpu_wakeup_latency, lock_all_memory, minimise_timer_slack, pin_to_cpu,
    set_fifo_priority,
};
pub use writer::{WRITE_TIMEOUT, write_atomic_bounded};
