//! Durable writes with a bound on the wait: [`write_atomic_bounded`] hands the write to one
//! writer thread and waits at most [`WRITE_TIMEOUT`] for it. A disk or a network mount that
//! hangs (an NFS server gone, a dying disk) then costs the caller that long and an error,
//! never a thread stuck for ever: the daemon's control loop writes the machine state and the
//! checkpoints, and it must go on answering status, hold and the jog's dead-man.
//!
//! One thread, one queue: writes land in the order they were asked for, so a write that the
//! caller gave up on and that finishes later is followed by every later one, and the file
//! ends as the last write left it. The queue is short: while the writer is stuck, further
//! writes fail at once.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::Duration;

/// How long a caller waits for its write.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);

/// Writes waiting behind the one in hand before further ones fail at once.
const QUEUE: usize = 16;

type Job = Box<dyn FnOnce() -> io::Result<()> + Send>;

struct Writer {
    jobs: SyncSender<(Job, SyncSender<io::Result<()>>)>,
}

impl Writer {
    fn start(name: &str) -> io::Result<Writer> {
        let (jobs, queue) = sync_channel::<(Job, SyncSender<io::Result<()>>)>(QUEUE);
        std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || serve(queue))?;
        Ok(Writer { jobs })
    }

    /// Runs `job` on the writer and waits for it at most `timeout`.
    fn run(&self, job: Job, timeout: Duration) -> io::Result<()> {
        let (done, result) = sync_channel(1);
        self.jobs.try_send((job, done)).map_err(|_| {
            io::Error::new(
                io::ErrorKind::TimedOut,
                "the writer is still busy with earlier writes (a hung disk or mount?)",
            )
        })?;
        result.recv_timeout(timeout).unwrap_or_else(|_| {
            Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!(
                    "the write did not finish in {} ms (a hung disk or mount?)",
                    timeout.as_millis()
                ),
            ))
        })
    }
}

fn serve(queue: Receiver<(Job, SyncSender<io::Result<()>>)>) {
    for (job, done) in queue {
        // The caller may have stopped waiting: nobody to tell.
        let _ = done.send(job());
    }
}

/// [`super::write_atomic`] on the writer thread, waited for at most [`WRITE_TIMEOUT`]. If the
/// thread cannot be started, the write is made here.
pub fn write_atomic_bounded(path: &Path, bytes: &[u8]) -> io::Result<()> {
    static WRITER: OnceLock<Option<Writer>> = OnceLock::new();
    let (path, bytes): (PathBuf, Vec<u8>) = (path.to_path_buf(), bytes.to_vec());
    match WRITER.get_or_init(|| Writer::start("edmd-writer").ok()) {
        Some(writer) => writer.run(
            Box::new(move || super::write_atomic(&path, &bytes)),
            WRITE_TIMEOUT,
        ),
        None => super::write_atomic(&path, &bytes),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    /// A write that hangs costs its caller the timeout and an error; the ones queued behind
    /// it fail within theirs; once it finishes, writes go through again, in order.
    #[test]
    fn a_hung_write_costs_its_timeout_not_the_caller() {
        let writer = Writer::start("edmd-writer-test").unwrap();
        let timeout = Duration::from_millis(100);
        let order = std::sync::Arc::new(parking_lot::Mutex::new(Vec::new()));
        let hung = order.clone();
        let started = Instant::now();
        let e = writer
            .run(
                Box::new(move || {
                    std::thread::sleep(Duration::from_millis(600));
                    hung.lock().push(1);
                    Ok(())
                }),
                timeout,
            )
            .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
        assert!(e.to_string().contains("did not finish in 100 ms"), "{e}");
        assert!(started.elapsed() < Duration::from_millis(400));
        let behind = order.clone();
        let e = writer
            .run(
                Box::new(move || {
                    behind.lock().push(2);
                    Ok(())
                }),
                timeout,
            )
            .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
        std::thread::sleep(Duration::from_millis(700));
        let after = order.clone();
        writer
            .run(
                Box::new(move || {
                    after.lock().push(3);
                    Ok(())
                }),
                timeout,
            )
            .unwrap();
        assert_eq!(*order.lock(), [1, 2, 3], "in the order asked for");
        let e = writer
            .run(Box::new(|| Err(io::Error::other("disk full"))), timeout)
            .unwrap_err();
        assert_eq!(e.to_string(), "disk full", "the write's own error");
    }
}
