//! `output.fault_at_tick`: an output that dies mid-job, to exercise the stop path end to end.

use super::{OutputError, PulseOutput};
use crate::gap::GapState;
use crate::vocab::MAX_AXES;

/// Passes writes to `inner` until tick `fail_at`, then fails every write (without passing it
/// on, so the failed tick's steps are not taken). `finish` still reaches `inner`, so a pulse
/// log keeps every tick before the fault.
#[derive(Debug)]
pub struct FaultInjector<O> {
    inner: O,
    fail_at: u64,
}

impl<O> FaultInjector<O> {
    pub fn new(inner: O, fail_at: u64) -> FaultInjector<O> {
        FaultInjector { inner, fail_at }
    }

    pub fn into_inner(self) -> O {
        self.inner
    }
}

impl<O: PulseOutput> PulseOutput for FaultInjector<O> {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        if tick >= self.fail_at {
            return Err(OutputError::Injected { tick });
        }
        self.inner.write(tick, steps, gap)
    }

    fn finish(&mut self, why: crate::output::StopReason) -> Result<(), OutputError> {
        self.inner.finish(why)
    }

    fn idle(&mut self, elapsed_ns: u64) -> Result<(), OutputError> {
        self.inner.idle(elapsed_ns)
    }

    fn prepare(&mut self) {
        self.inner.prepare()
    }

    fn sync(&mut self) -> Result<(), OutputError> {
        self.inner.sync()
    }

    fn moving_in(&mut self, now: super::Activity) {
        self.inner.moving_in(now)
    }

    fn set_points(&mut self, condition: u16, set: &crate::vocab::GeneratorSetPoints) {
        self.inner.set_points(condition, set)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Count(u64, bool);
    impl PulseOutput for Count {
        fn write(&mut self, _: u64, _: &[i8; MAX_AXES], _: GapState) -> Result<(), OutputError> {
            self.0 += 1;
            Ok(())
        }
        fn finish(&mut self, _why: crate::output::StopReason) -> Result<(), OutputError> {
            self.1 = true;
            Ok(())
        }
    }

    #[test]
    fn fails_from_its_tick_on_without_passing_the_write() {
        let mut out = FaultInjector::new(Count::default(), 3);
        let steps = [1, 0, 0, 0, 0, 0];
        for t in 0..3 {
            out.write(t, &steps, GapState::Normal).unwrap();
        }
        let err = out.write(3, &steps, GapState::Normal).unwrap_err();
        assert!(!err.step_taken());
        assert!(err.to_string().contains("tick 3"), "{err}");
        assert!(out.write(4, &steps, GapState::Normal).is_err());
        out.finish(crate::output::StopReason::Ended).unwrap();
        let inner = out.into_inner();
        assert_eq!((inner.0, inner.1), (3, true));
    }
}
