//! The process's descriptor limit (`getrlimit(2)`/`setrlimit(2)`, `RLIMIT_NOFILE`).
//!
//! systemd starts services with a soft limit of 1024 descriptors and a hard one far above it
//! (524288 on current systems): a daemon that serves network clients raises its soft limit
//! to the hard one at startup, as systemd's documentation recommends, and still keeps its
//! own clients well below it.

use std::io;

/// Raises the soft descriptor limit to the hard one; returns the soft limit in force after.
pub fn raise_descriptor_limit() -> io::Result<u64> {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `limit` is a valid, writable rlimit struct for getrlimit to fill.
    if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) } != 0 {
        return Err(io::Error::last_os_error());
    }
    if limit.rlim_cur < limit.rlim_max {
        let raised = libc::rlimit {
            rlim_cur: limit.rlim_max,
            rlim_max: limit.rlim_max,
        };
        // SAFETY: `raised` is a valid rlimit struct; setrlimit only reads it.
        if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &raised) } == 0 {
            limit = raised;
        }
    }
    Ok(limit.rlim_cur)
}
