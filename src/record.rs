//! The recorder (`edmd run --report DIR`): what actually ran, not what was planned.
//!
//! ```text
//!  consumer thread loop                               supervisor thread
//!  RecordedOutput(out) ── position, gap ──► Handoff<Sample> (bounded) ──► Recording
//!                                                                          + servo events
//! ```
//!
//! The wrapper sits in the real-time loop: it keeps the position from the steps it passes on
//! and pushes a small [`Sample`] into a preallocated lock-free queue at every gap change and
//! every `every` ticks of motion. It never allocates, logs or waits (in real time a full queue
//! drops the sample and counts it; in virtual time the loop yields until there is room, as
//! the tracer does). The supervisor drains the queue into a [`Recording`]: a decimated path
//! and feed, the gap state over time, and the servo events it logs anyway.

use crate::buffer::BlockFlags;
use std::sync::Arc;

use crate::gap::GapState;
use crate::output::{OutputError, PulseOutput};
use crate::plot::Decimated;
use crate::trace::Handoff;
use crate::vocab::TickPeriod;
use crate::vocab::{MAX_AXES, Steps};

/// Where the machine was at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub tick: u64,
    pub position: Steps,
    pub gap: GapState,
    /// Part of a rapid (G0).
    pub rapid: bool,
}

/// The queue from the wrapper to the supervisor.
pub type Recorder = Handoff<Sample>;

/// Records an output's motion and gap states into a [`Recorder`].
#[derive(Debug)]
pub struct RecordedOutput<O> {
    inner: O,
    recorder: Arc<Recorder>,
    every: u64,
    position: Steps,
    last_gap: Option<GapState>,
    next: u64,
    rapid: bool,
    /// The move changed kind since the last sample: sample at the next tick.
    kind_changed: bool,
}

impl<O> RecordedOutput<O> {
    /// A sample at every gap change and at most every `every` ticks of motion; `start` is the
    /// position in steps the job starts from.
    pub fn new(inner: O, recorder: Arc<Recorder>, every: u64, start: Steps) -> Self {
        RecordedOutput {
            inner,
            recorder,
            every: every.max(1),
            position: start,
            last_gap: None,
            next: 0,
            rapid: false,
            kind_changed: false,
        }
    }
}

impl<O: PulseOutput> PulseOutput for RecordedOutput<O> {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        self.inner.write(tick, steps, gap)?;
        let mut moved = false;
        for (p, &s) in self.position.iter_mut().zip(steps) {
            *p += i64::from(s);
            moved |= s != 0;
        }
        if self.last_gap != Some(gap) || self.kind_changed || (moved && tick >= self.next) {
            self.last_gap = Some(gap);
            self.kind_changed = false;
            self.next = tick + self.every;
            self.recorder.push(Sample {
                tick,
                position: self.position,
                gap,
                rapid: self.rapid,
            });
        }
        Ok(())
    }

    fn moving_in(&mut self, now: crate::output::Activity) {
        let rapid = now.flags.contains(BlockFlags::RAPID);
        self.kind_changed |= rapid != self.rapid;
        self.rapid = rapid;
        self.inner.moving_in(now);
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

    fn set_points(&mut self, condition: u16, set: &crate::vocab::GeneratorSetPoints) {
        self.inner.set_points(condition, set)
    }
}

/// What a report's event says happened: the servo's events, and the daemon operator's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EventKind {
    Short,
    /// The gap cleared after turning back.
    TurnBack,
    Resumed,
    Starved,
    Alarm,
    Done,
    Pause,
    Collision,
    Condition,
    /// A pass of the technology table starts (the value: its number).
    Pass,
    FlushOn,
    FlushOff,
    /// The operator's feed or rapid override changed (the value: percent).
    FeedOverride,
    RapidOverride,
    Jump,
    WireBreak,
    Probe,
    ProbeMissed,
    /// A drilling move broke through (1) or ended without (0).
    Breakthrough,
    /// The operator's hold, its release, a rethread asked for, an abort.
    Hold,
    Released,
    Rethread,
    Abort,
}

impl EventKind {
    /// The name `events.csv` writes.
    pub fn name(self) -> &'static str {
        match self {
            EventKind::Short => "short",
            EventKind::TurnBack => "turn_back",
            EventKind::Resumed => "resumed",
            EventKind::Starved => "starved",
            EventKind::Alarm => "alarm",
            EventKind::Done => "done",
            EventKind::Pause => "pause",
            EventKind::Collision => "collision",
            EventKind::Condition => "condition",
            EventKind::Pass => "pass",
            EventKind::FlushOn => "flush_on",
            EventKind::FlushOff => "flush_off",
            EventKind::FeedOverride => "feed_override",
            EventKind::RapidOverride => "rapid_override",
            EventKind::Jump => "jump",
            EventKind::WireBreak => "wire_break",
            EventKind::Probe => "probe",
            EventKind::ProbeMissed => "probe_missed",
            EventKind::Breakthrough => "breakthrough",
            EventKind::Hold => "hold",
            EventKind::Released => "released",
            EventKind::Rethread => "rethread",
            EventKind::Abort => "abort",
        }
    }
}

/// A servo event as the report lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedEvent {
    pub tick: u64,
    pub line: u64,
    pub kind: EventKind,
    /// Blocks turned back over (`turn_back`, `alarm`).
    pub depth: Option<u64>,
    /// Where the electrode was (mm, machine axis order): the last sample before the event.
    pub position_mm: Vec<f64>,
}

/// The window over which the report measures the feed (s of machine time).
pub const FEED_WINDOW_S: f64 = 0.02;

/// Points kept per plotted series.
const PLOT_POINTS: usize = 20_000;
/// Events kept in a report (a job with more lists the first ones and says how many it left).
pub const MAX_EVENTS: usize = 100_000;

/// Points kept of the process trace; past it every other point goes and the spacing doubles.
const PROCESS_POINTS: usize = 4_000;
/// The process trace's first spacing (s of machine time): a share of pulses over a quarter
/// second is the process, over one tick it is noise.
pub const PROCESS_EVERY_S: f64 = 0.25;

/// Ticks between the process points the consumer's loop queues at `tick`: the trace's
/// first spacing.
pub fn process_every_ticks(tick: TickPeriod) -> u64 {
    ((PROCESS_EVERY_S * 1e9) as u64 / tick.ns()).max(1)
}

/// The queue from the consumer's loop to the supervisor: a process point every
/// `every_ticks` of machine time. Lossless in virtual time, so the trace does not depend on
/// how often the supervisor is scheduled.
#[derive(Debug, Clone)]
pub struct ProcessTap {
    pub queue: Arc<Handoff<ProcessPoint>>,
    pub every_ticks: u64,
}

/// One reading of the process, as the consumer's loop queues it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessPoint {
    pub tick: u64,
    /// Path length from the program's start (mm); goes back during a turn-back.
    pub path_mm: f64,
    /// The gap's pulses so far by class (normal, arc, short, open): running totals.
    pub pulses: [u64; 4],
    /// The generator's off time in force (µs; 0 with no condition).
    pub off_time_us: f64,
    /// The adaptive law's estimate of the part height (mm; NaN while it does not run).
    pub height_mm: f64,
}

/// What a stretch of the job cut, from its process trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutStretch {
    /// Advanced along the path (mm): where the stretch ended less where it began, so a
    /// turn-back and its re-advance count nothing.
    pub cut_mm: f64,
    /// The mean of the height estimates within it (mm), where the adaptive law ran.
    pub height_estimate_mm: Option<f64>,
}

/// What the supervisor gathered of a job: bounded whatever the job's length.
#[derive(Debug)]
pub struct Recording {
    pub step_mm: Vec<f64>,
    pub tick: TickPeriod,
    /// X–Y of the executed path (mm), decimated; turn-back stretches separately.
    pub path: Decimated,
    /// Points reached while turning back or re-advancing (mm), between [`crate::plot::BREAK`]s.
    pub turn_back: Vec<(f64, f64)>,
    /// Rapid moves (mm), one stroke each between [`crate::plot::BREAK`]s.
    pub rapids: Vec<(f64, f64)>,
    /// The programmed cutting path (mm, machine coordinates), strokes between
    /// [`crate::plot::BREAK`]s, when whoever asked for the report drew it.
    pub programmed: Vec<(f64, f64)>,
    /// Feed along the path (mm/min) against machine time (s).
    pub feed: Decimated,
    /// Gap state against machine time: 0 open, 1 normal, 2 short (decimated, peaks kept: a
    /// short is never decimated away).
    pub gap: Decimated,
    pub events: Vec<RecordedEvent>,
    pub events_left_out: u64,
    pub start: Option<(f64, f64)>,
    pub direction: Option<(f64, f64)>,
    /// A four-axis wire machine's upper guide (X + U, Y + V; mm), decimated, and the indices
    /// of U and V.
    pub upper: Option<([usize; 2], Decimated)>,
    /// The process as the pulses told it, in tick order: running totals, so thinning the
    /// trace makes its windows longer, never wrong.
    pub process: Vec<ProcessPoint>,
    /// Ticks between process points kept (doubles as the trace thins).
    process_every: u64,
    last: Option<Sample>,
    /// Where the feed's current window started: steps are whole, so a feed measured over a
    /// few ticks is mostly quantisation; over [`FEED_WINDOW_S`] it is the feed.
    feed_from: Option<Sample>,
    /// Inside a turn-back or its re-advance (from a short to the resume).
    turning_back: bool,
    turn_back_points: usize,
    /// Where the job started (steps): the position of events before the first sample.
    origin: Vec<i64>,
}

impl Recording {
    pub fn new(step_mm: &[f64], tick: TickPeriod) -> Recording {
        Recording {
            step_mm: step_mm.to_vec(),
            tick,
            path: Decimated::new(PLOT_POINTS),
            turn_back: Vec::new(),
            rapids: Vec::new(),
            programmed: Vec::new(),
            feed: Decimated::new(PLOT_POINTS),
            gap: Decimated::new(PLOT_POINTS),
            events: Vec::new(),
            events_left_out: 0,
            start: None,
            direction: None,
            upper: None,
            process: Vec::new(),
            process_every: process_every_ticks(tick),
            last: None,
            feed_from: None,
            turning_back: false,
            turn_back_points: 0,
            origin: Vec::new(),
        }
    }

    /// The job starts at `steps` (machine axis order): where events before the first sample
    /// happened.
    pub fn starting_at(mut self, steps: &[i64]) -> Recording {
        self.origin = steps.to_vec();
        self
    }

    /// Also records the upper guide of a four-axis wire machine, whose U and V (the upper
    /// guide relative to the lower one) are these axes.
    pub fn with_upper_guide(mut self, uv: Option<[usize; 2]>) -> Recording {
        self.upper = uv.map(|uv| (uv, Decimated::new(PLOT_POINTS)));
        self
    }

    /// Machine time of `ticks` (s), exact for whole milliseconds and microseconds.
    pub fn secs(&self, ticks: u64) -> f64 {
        (u128::from(ticks) * u128::from(self.tick.ns())) as f64 * 1e-9
    }

    fn mm(&self, position: &Steps, axis: usize) -> f64 {
        self.step_mm
            .get(axis)
            .map_or(0.0, |s| position[axis] as f64 * s)
    }

    /// Takes one sample (in tick order).
    pub fn sample(&mut self, s: &Sample) {
        let (x, y) = (self.mm(&s.position, 0), self.mm(&s.position, 1));
        let t = self.secs(s.tick);
        if self.start.is_none() {
            self.start = Some((x, y));
        }
        if let Some(last) = self.last {
            let (lx, ly) = (self.mm(&last.position, 0), self.mm(&last.position, 1));
            if self.direction.is_none() && (x != lx || y != ly) {
                self.direction = Some((x - lx, y - ly));
            }
            let from = *self.feed_from.get_or_insert(last);
            let dt = self.secs(s.tick - from.tick);
            if dt >= FEED_WINDOW_S {
                let d: f64 = (0..self.step_mm.len())
                    .map(|a| self.mm(&s.position, a) - self.mm(&from.position, a))
                    .map(|d| d * d)
                    .sum::<f64>()
                    .sqrt();
                self.feed.push(t, d / dt * 60.0);
                self.feed_from = Some(*s);
            }
            if last.gap != s.gap {
                // A step: the old state up to this tick, the new one from it.
                self.gap.push(t, gap_level(last.gap));
            }
            if self.turning_back && self.turn_back_points < PLOT_POINTS {
                self.turn_back.push((x, y));
                self.turn_back_points += 1;
            }
            if s.rapid && self.rapids.len() < PLOT_POINTS {
                if !last.rapid {
                    let from = (self.mm(&last.position, 0), self.mm(&last.position, 1));
                    self.rapids.extend([crate::plot::BREAK, from]);
                }
                self.rapids.push((x, y));
            }
        }
        self.gap.push(t, gap_level(s.gap));
        self.path.push(x, y);
        if let Some(([u, v], _)) = self.upper {
            let (du, dv) = (self.mm(&s.position, u), self.mm(&s.position, v));
            if let Some((_, upper)) = &mut self.upper {
                upper.push(x + du, y + dv);
            }
        }
        self.last = Some(*s);
    }

    /// Takes one servo event (in tick order, after the samples up to its tick).
    pub fn event(&mut self, tick: u64, line: u64, kind: EventKind, depth: Option<u64>) {
        match kind {
            EventKind::Short if !self.turning_back => {
                self.turning_back = true;
                if let Some(last) = self.last {
                    let p = (self.mm(&last.position, 0), self.mm(&last.position, 1));
                    self.turn_back.extend([crate::plot::BREAK, p]);
                }
            }
            EventKind::Resumed | EventKind::Alarm | EventKind::Done => self.turning_back = false,
            _ => {}
        }
        if self.events.len() < MAX_EVENTS {
            let position_mm = self.last_position_mm();
            self.events.push(RecordedEvent {
                tick,
                line,
                kind,
                depth,
                position_mm,
            });
        } else {
            self.events_left_out += 1;
        }
    }

    /// Takes one reading of the process (in tick order): kept if it is the first, the
    /// job's last (`closing`), or the spacing after the last one kept.
    pub fn process_point(&mut self, point: ProcessPoint, closing: bool) {
        let due = self.process.last().is_none_or(|last| {
            point.tick >= last.tick + self.process_every || (closing && point.tick > last.tick)
        });
        if !due {
            return;
        }
        if self.process.len() >= PROCESS_POINTS {
            let mut i = 0;
            self.process.retain(|_| {
                i += 1;
                i % 2 == 1
            });
            self.process_every *= 2;
        }
        self.process.push(point);
    }

    /// Where along the path the electrode stood at `tick` (mm), between the process points
    /// around it; `None` with no trace.
    fn path_at(&self, tick: u64) -> Option<f64> {
        let after = self.process.partition_point(|p| p.tick < tick);
        match (
            after.checked_sub(1).map(|i| self.process[i]),
            self.process.get(after).copied(),
        ) {
            (Some(a), Some(b)) if b.tick > a.tick => {
                let f = (tick - a.tick) as f64 / (b.tick - a.tick) as f64;
                Some(a.path_mm + f * (b.path_mm - a.path_mm))
            }
            (_, Some(p)) | (Some(p), None) => Some(p.path_mm),
            (None, None) => None,
        }
    }

    /// What the job cut from tick `from` to tick `until`; `None` with no process trace.
    pub fn cut_between(&self, from: u64, until: u64) -> Option<CutStretch> {
        let cut_mm = self.path_at(until)? - self.path_at(from)?;
        let heights: Vec<f64> = self
            .process
            .iter()
            .filter(|p| p.tick >= from && p.tick <= until && p.height_mm.is_finite())
            .map(|p| p.height_mm)
            .collect();
        Some(CutStretch {
            cut_mm,
            height_estimate_mm: (!heights.is_empty())
                .then(|| heights.iter().sum::<f64>() / heights.len() as f64),
        })
    }

    /// The position (mm, machine axis order) of the last sample so far.
    fn last_position_mm(&self) -> Vec<f64> {
        self.last.map_or_else(
            || {
                (0..self.step_mm.len())
                    .map(|a| {
                        self.origin
                            .get(a)
                            .map_or(0.0, |&s| s as f64 * self.step_mm[a])
                    })
                    .collect()
            },
            |s| {
                (0..self.step_mm.len())
                    .map(|a| self.mm(&s.position, a))
                    .collect()
            },
        )
    }

    /// The gap state at the end of the samples so far, for the chart's last step.
    pub fn close(&mut self, end_tick: u64) {
        if let Some(last) = self.last {
            let t = self.secs(end_tick.max(last.tick));
            self.gap.push(t, gap_level(last.gap));
        }
    }
}

fn gap_level(gap: GapState) -> f64 {
    match gap {
        GapState::Open => 0.0,
        GapState::Normal => 1.0,
        GapState::Short => 2.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::NullOutput;

    #[test]
    fn samples_at_gap_changes_and_every_n_ticks_of_motion() {
        let recorder = Recorder::new(64, true, None);
        let mut out = RecordedOutput::new(NullOutput, recorder.clone(), 10, [0; MAX_AXES]);
        let step = [1, 0, 0, 0, 0, 0];
        let still = [0; MAX_AXES];
        for tick in 0..25 {
            out.write(tick, &step, GapState::Normal).unwrap();
        }
        out.write(25, &still, GapState::Short).unwrap();
        out.write(26, &still, GapState::Short).unwrap();
        let mut got = Vec::new();
        recorder.drain(|s| got.push((s.tick, s.position[0], s.gap)));
        use GapState::*;
        assert_eq!(
            got,
            [
                (0, 1, Normal),
                (10, 11, Normal),
                (20, 21, Normal),
                (25, 25, Short)
            ]
        );
    }

    #[test]
    fn a_recording_marks_turn_backs_and_keeps_events() {
        let mut r = Recording::new(&[0.001, 0.001], TickPeriod::from_us(1000).unwrap());
        let s = |tick, x, gap| Sample {
            tick,
            position: [x, 0, 0, 0, 0, 0],
            gap,
            rapid: false,
        };
        r.sample(&s(0, 0, GapState::Normal));
        r.sample(&s(1000, 1000, GapState::Normal));
        r.event(1000, 3, EventKind::Short, None);
        r.sample(&s(1000, 1000, GapState::Short));
        r.sample(&s(1500, 900, GapState::Normal));
        r.event(1500, 3, EventKind::TurnBack, Some(1));
        r.sample(&s(1600, 1000, GapState::Normal));
        r.event(1600, 3, EventKind::Resumed, None);
        r.sample(&s(2000, 1400, GapState::Normal));
        assert_eq!(r.start, Some((0.0, 0.0)));
        assert_eq!(r.direction, Some((1.0, 0.0)));
        // The turn-back stroke: from the short, back, and forward again to the resume.
        let stroke: Vec<_> = r
            .turn_back
            .iter()
            .filter(|p| !p.0.is_nan())
            .copied()
            .collect();
        assert_eq!(stroke, [(1.0, 0.0), (1.0, 0.0), (0.9, 0.0), (1.0, 0.0)]);
        assert_eq!(r.events.len(), 3);
        // Feed: 1 mm in 1 s = 60 mm/min.
        assert_eq!(r.feed.points()[0], (1.0, 60.0));
        let gap = r.gap.points();
        assert_eq!(gap[0], (0.0, 1.0));
        assert!(gap.contains(&(1.0, 2.0)), "{gap:?}");
    }

    #[test]
    fn a_four_axis_recording_keeps_the_upper_guide() {
        let tick = TickPeriod::from_us(1000).unwrap();
        let mut r = Recording::new(&[0.001; 4], tick).with_upper_guide(Some([2, 3]));
        for (k, (x, u)) in [(0, 0), (1000, 500), (2000, 1000)].into_iter().enumerate() {
            r.sample(&Sample {
                tick: k as u64,
                position: [x, 0, u, -u, 0, 0],
                gap: GapState::Normal,
                rapid: false,
            });
        }
        let (_, upper) = r.upper.as_ref().unwrap();
        assert_eq!(upper.points(), [(0.0, 0.0), (1.5, -0.5), (3.0, -1.0)]);
        assert!(Recording::new(&[0.001; 2], tick).upper.is_none());
    }

    fn point(tick: u64, path_mm: f64, height_mm: f64) -> ProcessPoint {
        ProcessPoint {
            tick,
            path_mm,
            pulses: [tick, 0, 0, 0],
            off_time_us: 16.0,
            height_mm,
        }
    }

    #[test]
    fn the_process_trace_keeps_its_spacing_and_thins_without_losing_the_ends() {
        // 1 ms ticks: a point every 250 ticks at first.
        let mut r = Recording::new(&[0.001; 2], TickPeriod::from_us(1000).unwrap());
        for tick in 0..1000 {
            r.process_point(point(tick, 0.0, f64::NAN), false);
        }
        let ticks: Vec<u64> = r.process.iter().map(|p| p.tick).collect();
        assert_eq!(ticks, [0, 250, 500, 750]);
        // The job's last reading is kept whatever the spacing.
        r.process_point(point(999, 0.0, f64::NAN), true);
        assert_eq!(r.process.last().unwrap().tick, 999);
        // Past its capacity the trace halves and its spacing doubles: bounded, still in
        // order, still starting at the job's start.
        let mut r = Recording::new(&[0.001; 2], TickPeriod::from_us(1000).unwrap());
        for tick in (0..10_000_000).step_by(50) {
            r.process_point(point(tick, 0.0, f64::NAN), false);
        }
        assert!(r.process.len() <= PROCESS_POINTS, "{}", r.process.len());
        assert!(r.process.len() > PROCESS_POINTS / 4, "{}", r.process.len());
        assert_eq!(r.process[0].tick, 0);
        assert!(r.process.windows(2).all(|w| w[0].tick < w[1].tick));
    }

    #[test]
    fn a_stretch_cut_is_where_it_ended_less_where_it_began_turn_backs_netted_out() {
        let mut r = Recording::new(&[0.001; 2], TickPeriod::from_us(1000).unwrap());
        assert_eq!(r.cut_between(0, 100), None, "no trace, no figure");
        // Forward 2 mm, back 1 mm (a turn-back), forward 3 mm; the law's height from tick
        // 500 on.
        for (tick, mm, h) in [
            (0, 0.0, f64::NAN),
            (250, 2.0, f64::NAN),
            (500, 1.0, 20.0),
            (750, 4.0, 30.0),
        ] {
            r.process_point(point(tick, mm, h), false);
        }
        let all = r.cut_between(0, 750).unwrap();
        assert_eq!(all.cut_mm, 4.0);
        assert_eq!(all.height_estimate_mm, Some(25.0));
        // Between the points, along the line from one to the next.
        let part = r.cut_between(125, 625).unwrap();
        assert!((part.cut_mm - (2.5 - 1.0)).abs() < 1e-12, "{part:?}");
        let early = r.cut_between(0, 250).unwrap();
        assert_eq!(early.height_estimate_mm, None);
    }
}
