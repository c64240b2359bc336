//! A recording port and a virtual clock, for tests: every register write is kept with the
//! virtual time it happened at, so a test can rebuild each pin's waveform and check it
//! against the drive's timing rules.

use std::io;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};

use parking_lot::Mutex;

use super::pins::{OUTPUT_PINS, Pin, PinLevels, PinMap, StepTiming, status_register};
use super::{Clock, Port};

/// Which register a write went to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Register {
    Data,
    Control,
}

/// One recorded write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortWrite {
    pub at_ns: u64,
    pub register: Register,
    pub value: u8,
}

/// The state a [`RecordingPort`] and a [`VirtualClock`] share.
#[derive(Debug, Clone, Default)]
pub struct Bench {
    now: Arc<AtomicU64>,
    writes: Arc<Mutex<Vec<PortWrite>>>,
    status: Arc<AtomicU8>,
    /// Writes left before every further write fails (`u64::MAX`: never).
    writes_left: Arc<AtomicU64>,
}

impl Bench {
    pub fn new() -> Bench {
        let bench = Bench::default();
        bench.writes_left.store(u64::MAX, Ordering::Relaxed);
        bench
    }

    pub fn port(&self) -> RecordingPort {
        RecordingPort {
            bench: self.clone(),
        }
    }

    pub fn clock(&self) -> VirtualClock {
        VirtualClock {
            bench: self.clone(),
        }
    }

    pub fn now_ns(&self) -> u64 {
        self.now.load(Ordering::Relaxed)
    }

    /// Moves virtual time to `at_ns` (never backwards).
    pub fn set_now(&self, at_ns: u64) {
        self.now.fetch_max(at_ns, Ordering::Relaxed);
    }

    pub fn writes(&self) -> Vec<PortWrite> {
        self.writes.lock().clone()
    }

    /// The status pins at these levels (bit `p` = pin `p` high).
    pub fn set_inputs(&self, levels: PinLevels) {
        self.status
            .store(status_register(levels), Ordering::Relaxed);
    }

    /// After `n` more successful writes, every write fails with EIO (a port that died).
    pub fn fail_after_writes(&self, n: u64) {
        self.writes_left.store(n, Ordering::Relaxed);
    }

    /// The output pin levels after every write, with its time, starting from `initial`.
    pub fn waveform(&self, initial: PinLevels) -> Vec<(u64, PinLevels)> {
        let (mut data, mut control) = (initial.data_register(), initial.control_register());
        self.writes()
            .iter()
            .map(|w| {
                match w.register {
                    Register::Data => data = w.value,
                    Register::Control => control = w.value,
                }
                (w.at_ns, PinLevels::from_registers(data, control))
            })
            .collect()
    }
}

impl Bench {
    /// What the drives on each axis counted: at every step edge, +1 or -1 from the level of
    /// the direction pin. Checks on the way, failing with a description:
    /// - only registers whose value changes are written;
    /// - direction setup before each edge, step length, step space and direction hold after
    ///   each release, per axis, and no direction change inside a pulse;
    /// - pins outside `map` are never driven, and the last write leaves every output idle.
    pub fn drive_steps(&self, map: &PinMap, timing: StepTiming) -> Result<Vec<Vec<i8>>, String> {
        let idle = map.idle();
        let (mut data, mut control) = (idle.data_register(), idle.control_register());
        for w in self.writes() {
            let shadow = match w.register {
                Register::Data => &mut data,
                Register::Control => &mut control,
            };
            if *shadow == w.value {
                return Err(format!("{w:?} changes nothing"));
            }
            *shadow = w.value;
        }
        let wave = self.waveform(idle);
        let mut axes = Vec::with_capacity(map.axes);
        for axis in 0..map.axes {
            axes.push(axis_steps(map, timing, &wave, axis)?);
        }
        let used: Vec<Pin> = (0..map.axes)
            .flat_map(|a| [map.step[a], map.dir[a]])
            .chain(map.enable)
            .collect();
        for &(at, levels) in &wave {
            if let Some(pin) = OUTPUT_PINS
                .iter()
                .find(|p| !used.contains(p) && levels.is_high(**p))
            {
                return Err(format!("unused pin {pin} driven at {at} ns"));
            }
        }
        match wave.last() {
            Some(&(at, last)) if last != idle => Err(format!(
                "the last write ({at} ns) leaves outputs active: {last:?}"
            )),
            _ => Ok(axes),
        }
    }
}

/// One axis of [`Bench::drive_steps`].
fn axis_steps(
    map: &PinMap,
    timing: StepTiming,
    wave: &[(u64, PinLevels)],
    axis: usize,
) -> Result<Vec<i8>, String> {
    let (sp, dp) = (map.step[axis], map.dir[axis]);
    let active = |l: PinLevels| l.is_high(sp) == map.level(sp, true);
    let positive = |l: PinLevels| l.is_high(dp) == map.level(dp, true);
    let mut steps = Vec::new();
    let mut prev = map.idle();
    let mut last_dir_change: Option<u64> = None;
    let mut last_release: Option<u64> = None;
    let mut edge: Option<u64> = None;
    let fail = |rule: &str, at: u64| Err(format!("axis {axis}: {rule} violated at {at} ns"));
    for &(at, levels) in wave {
        if positive(levels) != positive(prev) {
            if edge.is_some() {
                return fail("no direction change inside a pulse", at);
            }
            if last_release.is_some_and(|r| at < r + timing.dir_hold_ns) {
                return fail("dir hold", at);
            }
            last_dir_change = Some(at);
        }
        if active(levels) && !active(prev) {
            if last_dir_change.is_some_and(|d| at < d + timing.dir_setup_ns) {
                return fail("dir setup", at);
            }
            if last_release.is_some_and(|r| at < r + timing.step_space_ns) {
                return fail("step space", at);
            }
            edge = Some(at);
            steps.push(if positive(levels) { 1 } else { -1 });
        }
        if !active(levels) && active(prev) {
            match edge.take() {
                Some(start) if at < start + timing.step_length_ns => {
                    return fail("step length", at);
                }
                _ => last_release = Some(at),
            }
        }
        prev = levels;
    }
    match edge {
        Some(at) => fail("every pulse released", at),
        None => Ok(steps),
    }
}

/// A [`Port`] that records its writes.
#[derive(Debug, Clone)]
pub struct RecordingPort {
    bench: Bench,
}

impl RecordingPort {
    fn record(&self, register: Register, value: u8) -> io::Result<()> {
        let left = &self.bench.writes_left;
        if left.load(Ordering::Relaxed) == 0 {
            return Err(io::Error::from_raw_os_error(libc::EIO));
        }
        let _ = left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1));
        self.bench.writes.lock().push(PortWrite {
            at_ns: self.bench.now_ns(),
            register,
            value,
        });
        Ok(())
    }
}

impl Port for RecordingPort {
    fn write_data(&mut self, value: u8) -> io::Result<()> {
        self.record(Register::Data, value)
    }

    fn write_control(&mut self, value: u8) -> io::Result<()> {
        self.record(Register::Control, value)
    }

    fn read_status(&mut self) -> io::Result<u8> {
        Ok(self.bench.status.load(Ordering::Relaxed))
    }
}

/// A [`Clock`] whose waits move virtual time instead of spinning.
#[derive(Debug, Clone)]
pub struct VirtualClock {
    bench: Bench,
}

impl Clock for VirtualClock {
    fn now_ns(&mut self) -> u64 {
        self.bench.now_ns()
    }

    fn wait_until_ns(&mut self, deadline_ns: u64) {
        self.bench.set_now(deadline_ns);
    }
}
