//! The probe hand-over: where a probing move ended, from the consumer to the producer.
//!
//! A probing move (`G38.x`, `G31`) ends where contact happens, which only the consumer
//! learns, and the rest of the program starts there: like LinuxCNC's interpreter, the
//! producer stops reading after a probing move until the result is in. The consumer's loop
//! publishes it with a few atomic stores (it never waits); the producer polls for it between
//! short sleeps, giving up when the job is torn down.

use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::time::Duration;

use crate::vocab::{MAX_AXES, Steps};

/// Where a probing move ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeResult {
    /// The pulse ledger there (steps).
    pub steps: Steps,
    /// Contact was made (or, probing away, lost); `false`: the move reached its end point.
    pub contact: bool,
}

/// The consumer's side writes, the producer's side reads; one result per probing move.
#[derive(Debug, Default)]
pub struct ProbeLink {
    steps: [AtomicI64; MAX_AXES],
    contact: AtomicBool,
    /// Results published so far.
    published: AtomicU64,
    /// The consumer's loop has ended: no result will come.
    closed: AtomicBool,
}

impl ProbeLink {
    /// The consumer: a probing move ended (a few stores, never a wait).
    pub fn publish(&self, result: &ProbeResult) {
        for (slot, &s) in self.steps.iter().zip(&result.steps) {
            slot.store(s, Ordering::Relaxed);
        }
        self.contact.store(result.contact, Ordering::Relaxed);
        self.published.fetch_add(1, Ordering::Release);
    }

    /// Where the last probing move ended, if one did.
    pub fn last(&self) -> Option<ProbeResult> {
        (self.published.load(Ordering::Acquire) > 0).then(|| ProbeResult {
            steps: std::array::from_fn(|i| self.steps[i].load(Ordering::Relaxed)),
            contact: self.contact.load(Ordering::Relaxed),
        })
    }

    /// The consumer's loop ended.
    pub fn close(&self) {
        self.closed.store(true, Ordering::Release);
    }

    /// The producer: waits for result number `n` (counting from 1); `None` when the job ends
    /// first (`gave_up` says so: an abort).
    pub fn wait(&self, n: u64, gave_up: impl Fn() -> bool) -> Option<ProbeResult> {
        loop {
            if self.published.load(Ordering::Acquire) >= n {
                return Some(ProbeResult {
                    steps: std::array::from_fn(|i| self.steps[i].load(Ordering::Relaxed)),
                    contact: self.contact.load(Ordering::Relaxed),
                });
            }
            if self.closed.load(Ordering::Acquire) || gave_up() {
                return None;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_producer_gets_each_result_once_published_and_gives_up_when_closed() {
        let link = std::sync::Arc::new(ProbeLink::default());
        let writer = link.clone();
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(5));
            let mut steps = [0; MAX_AXES];
            steps[2] = -123;
            writer.publish(&ProbeResult {
                steps,
                contact: true,
            });
        });
        let got = link.wait(1, || false).expect("a result");
        assert_eq!((got.steps[2], got.contact), (-123, true));
        t.join().unwrap();
        link.close();
        assert_eq!(link.wait(2, || false), None);
    }
}
