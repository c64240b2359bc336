//! The consumer thread's loop: the clock around the tick core.
//!
//! ```text
//! real time:    deadline += period ─► clock_nanosleep(ABSTIME) ─► latency = now − deadline
//!               ─► inputs.sample(tick) (E-stop, limits, switches, probe, wire break)
//!               ─► gap = sensor.sample(tick) ─► fine.tick(gap) ─► limits hold? ─► output(steps)
//!               ─► late for the next deadline? count an overrun, skip the missed deadlines
//! virtual time: the same without the clock; waiting for the producer stops time
//! ```
//!
//! The loop is the only part of the consumer that reads the clock or touches the hardware.
//! Nothing in it allocates or logs once the loop has started: servo events go into a
//! lock-free bounded queue that a normal-priority thread drains and logs, counters are
//! published through atomics. Real-time scheduling (`SCHED_FIFO`, `mlockall`, CPU pinning)
//! is requested before the loop starts; each refusal is logged as a warning and the loop
//! runs without it.
//!
//! **Overruns.** When a tick's work ends after the next deadline, the missed deadlines are
//! skipped rather than caught up: catching up would fire several ticks back to back, a burst
//! of steps faster than the planned speed. Motion simply pauses for the missed periods.

use crate::buffer::BlockFlags;
use std::sync::atomic::Ordering;

pub use super::controls::RethreadRequest;
use super::controls::{self, ControlWord, Controls};
use super::histogram::LatencyHistogram;
use super::probe::ProbeResult;
use super::published::ProcessTapper;
pub use super::published::{EventRecord, LATENCY_BUCKETS_US, PUBLISH_EVERY_TICKS, Published};
pub use super::snapshot::Snapshot;
use crate::buffer::BlockSource;
use crate::fine::{Interpolator, Tick};
use crate::gap::{GapError, GapSensor, GapState};
use crate::inputs::{InputError, InputReading, MachineInputs};
use crate::output::{Activity, OutputError, PulseOutput};
use crate::servo::{Excursion, GapReading, LawInput, PathPoint, ServoEvent, ServoState};
use crate::sys;
use crate::vocab::{Axis, LimitSet, MAX_AXES, SafetyInputs, Trip};

/// How the loop runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSettings {
    pub tick_ns: u64,
    pub virtual_time: bool,
    /// Ticks run back to back per wake-up in real time (`fine.ticks_per_wake`).
    pub ticks_per_wake: u32,
    /// SCHED_FIFO priority, 0 for none.
    pub rt_priority: u8,
    pub lock_memory: bool,
    pub cpu: Option<usize>,
    /// There is an operator (the daemon): a programmed stop (`M0`/`M1`) sets
    /// `Published::hold` (and `paused_line`), a collision or an alarm holds the job, all until
    /// released. Without one (`edmd run`) stops pass and collisions and alarms end the loop.
    pub program_pauses: bool,
    /// The machine's axes in step order: which limit switch a step runs into.
    pub axes: [Option<Axis>; MAX_AXES],
}

impl LoopSettings {
    pub fn from_config(config: &crate::config::Config) -> LoopSettings {
        let f = &config.fine;
        LoopSettings {
            tick_ns: f.tick.ns(),
            virtual_time: f.virtual_time,
            ticks_per_wake: f.ticks_per_wake,
            rt_priority: f.rt_priority,
            lock_memory: f.lock_memory,
            cpu: f.cpu,
            program_pauses: false,
            axes: std::array::from_fn(|i| config.machine.axes.get(i).copied()),
        }
    }
}

/// The reading the servo law takes: the input's state, and the voltage or the ratios if the
/// law reads them (they are not asked for otherwise).
#[inline]
fn read_for<G: GapSensor + ?Sized>(input: LawInput, gap: GapState, sensor: &G) -> GapReading {
    let pulses = sensor.pulses();
    let flushing = sensor.flushing();
    match input {
        LawInput::State => GapReading {
            pulses,
            flushing,
            ..GapReading::state(gap)
        },
        LawInput::Volts => GapReading {
            state: gap,
            volts: sensor.volts(),
            ratios: None,
            pulses,
            flushing,
        },
        LawInput::Ratios => GapReading {
            state: gap,
            volts: None,
            ratios: sensor.ratios(),
            pulses,
            flushing,
        },
    }
}

/// What the loop measured.
#[derive(Debug)]
pub struct LoopReport {
    /// Ticks executed.
    pub ticks: u64,
    /// Real time only: wake-up latency of every tick.
    pub latency: Option<LatencyHistogram>,
    /// Ticks whose work ended after the next deadline.
    pub overruns: u64,
    /// Deadlines skipped to resynchronise after overruns.
    pub missed_deadlines: u64,
    pub wall_ns: u64,
    /// The output failed; the loop stopped at once.
    pub output_error: Option<OutputError>,
    /// The failed write's tick did not reach the drives: its steps and event direction, to
    /// take back out of the interpolator's ledger.
    pub untaken: Option<([i8; MAX_AXES], i8)>,
    /// With `untaken`: where along the program the electrode was before that tick (segment
    /// and step, and the segment's step count), the checkpoint's point to go with the ledger.
    pub untaken_from: Option<(PathPoint, i64)>,
    /// The gap input failed; the loop stopped before that tick moved anything.
    pub gap_error: Option<GapError>,
    /// The machine inputs failed; the loop stopped before that tick moved anything.
    pub input_error: Option<InputError>,
    /// The supervisor asked the loop to stop.
    pub stopped: bool,
    /// A collision during a rapid ended a job without an operator: where, and the line.
    pub collision: Option<(PathPoint, u64)>,
    /// The wire broke in a job without an operator: where, the line, and whether an open
    /// gap (not the sensor) told.
    pub wire_break: Option<(PathPoint, u64, bool)>,
    /// A `G38.2`/`G38.4` reached its end point without contact: where, and the line.
    pub probe_missed: Option<(PathPoint, u64)>,
    /// An E-stop or a limit switch stopped the job: which, where, and the line.
    pub tripped: Option<(Trip, PathPoint, u64)>,
    /// The limit switches that read closed at the last reading (a trip is kept until its
    /// switch opens).
    pub limits_at_end: LimitSet,
    /// Where the last probing move ended.
    pub last_probe: Option<ProbeResult>,
    /// Real-time features the system refused, with the reason.
    pub rt_refused: Vec<String>,
}

impl LoopReport {
    /// The report of a loop that never ran.
    pub fn empty() -> LoopReport {
        LoopReport {
            ticks: 0,
            latency: None,
            overruns: 0,
            missed_deadlines: 0,
            wall_ns: 0,
            output_error: None,
            untaken: None,
            untaken_from: None,
            gap_error: None,
            input_error: None,
            stopped: false,
            collision: None,
            wire_break: None,
            probe_missed: None,
            tripped: None,
            limits_at_end: LimitSet::EMPTY,
            last_probe: None,
            rt_refused: Vec::new(),
        }
    }
}

/// Holds the job (the consumer's own holds: a programmed stop, a collision, an alarm, a
/// wire break), counting it.
fn hold(published: &Published) {
    if !published.hold.swap(true, Ordering::Relaxed) {
        published.holds.fetch_add(1, Ordering::Relaxed);
    }
}

/// Runs the tick core until the program is done, an alarm, an output error or a stop
/// request. Call from the consumer thread after [`apply_realtime`].
#[inline(never)]
pub fn run_loop<S, O, G, I>(
    fine: &mut Interpolator,
    source: &mut S,
    output: &mut O,
    sensor: &mut G,
    inputs: &mut I,
    settings: &LoopSettings,
    published: &Published,
) -> LoopReport
where
    S: BlockSource + ?Sized,
    O: PulseOutput + ?Sized,
    G: GapSensor + ?Sized,
    I: MachineInputs + ?Sized,
{
    let mut latency = (!settings.virtual_time).then(LatencyHistogram::default);
    let mut report = LoopReport::empty();
    let started = sys::monotonic_ns();
    let mut deadline = started + settings.tick_ns;
    let mut tick_no: u64 = 0;
    // What the machine is doing, as the output was last told.
    let mut activity = Activity::default();
    fine.set_contact_reading(activity.flags.contains(BlockFlags::PROBE));
    let law_input = fine.law_input();
    // The controls the tick core has (a job starts with the defaults, then takes the word).
    let mut controls_word = ControlWord::default().word();
    apply_controls(Controls::default(), fine);
    // The limit switches closed at the job's first reading: the job may stand on them and
    // move away (a jog off a tripped switch); one that closes later stops it.
    let mut limits_at_start: Option<LimitSet> = None;
    let inputs_wired = inputs.wired();
    let mut process = ProcessTapper::new(published);
    loop {
        wait_for_tick(&mut latency, deadline, tick_no, settings, fine, published);
        take_controls(&mut controls_word, fine, tick_no, published);
        take_requests(fine, inputs, published);
        let probing = activity.flags.contains(BlockFlags::PROBE);
        let sensed = sense(inputs, inputs_wired, sensor, probing, tick_no, published);
        let (machine, gap) = match sensed {
            Ok(sensed) => sensed,
            Err(failed) => {
                failed.into_report(&mut report);
                break;
            }
        };
        // An E-stop, or a limit switch that closed during the job, stops motion in the tick
        // it is seen: no step of this tick is taken; the output's finish then drops the
        // drives' enable and the spark.
        let safety = machine.safety;
        report.limits_at_end = safety.limits;
        let allowed = *limits_at_start.get_or_insert(safety.limits);
        if let Some(trip) = newly_tripped(safety, allowed) {
            report.tripped = Some((trip, fine.here(), fine.line()));
            break;
        }
        // Where the electrode stands before this tick (two words): if the output refuses the
        // tick's step, this is the point that goes with the ledger the drives received.
        let before = fine.here();
        fine.set_wire_input(machine.wire_broken);
        let reading = read_for(law_input, gap, sensor);
        let tick = fine.tick_measured(reading, source);
        tell_activity(&mut activity, fine, tick_no, output, sensor, published);
        // A step further into a closed limit switch is not taken: motion away from it, and
        // along other axes, is.
        if !safety.limits.is_empty()
            && let Some(switch) = safety.limits.blocking(&settings.axes, &tick.steps)
        {
            untake(&mut report, fine, &tick, before);
            report.tripped = Some((Trip::Limit(switch), before, fine.line()));
            tick_no += 1;
            break;
        }
        if let Err(e) = output.write(tick_no, &tick.steps, gap) {
            if !e.step_taken() {
                untake(&mut report, fine, &tick, before);
            }
            report.output_error = Some(e);
            tick_no += 1;
            break;
        }
        sensor.observe(&tick.steps, tick.dir);
        route_event(&tick, tick_no, fine, settings, published, &mut report);
        tick_no += 1;
        // Every servo event and every held tick (a controlled stop waits for `still`);
        // otherwise every PUBLISH_EVERY_TICKS (3.2 ms at 50 µs), so the ticks that publish
        // nothing stay cheap.
        if tick.event.is_some() || fine.held() || tick_no.is_multiple_of(PUBLISH_EVERY_TICKS) {
            published.publish(tick_no, fine);
            published.ticks.store(tick_no, Ordering::Relaxed);
        }
        process.offer(tick_no, fine);
        if let Err(e) = settle_standstill(fine, output, published, &mut deadline) {
            report.output_error = Some(e);
            break;
        }
        let state = fine.state();
        let alarm_held = state == ServoState::Alarm && settings.program_pauses;
        let ended = report.collision.is_some()
            || report.wire_break.is_some()
            || report.probe_missed.is_some();
        if (state.is_final() && !alarm_held) || ended {
            break;
        }
        if published.stop.load(Ordering::Relaxed) {
            report.stopped = true;
            break;
        }
        if latency.is_some() {
            keep_deadline(&mut deadline, settings.tick_ns, &mut report, published);
        }
    }
    report.ticks = tick_no;
    report.wall_ns = sys::monotonic_ns() - started;
    report.latency = latency;
    published.ticks.store(tick_no, Ordering::Relaxed);
    published.publish(tick_no, fine);
    published.probe.close();
    published.finished.store(true, Ordering::Release);
    report
}

/// Phase 2: the machine inputs (when something is wired), then the gap (a probing move reads
/// its contact from the machine's pin where one is wired).
#[inline(always)]
fn sense<G, I>(
    inputs: &mut I,
    wired: bool,
    sensor: &mut G,
    probing: bool,
    tick_no: u64,
    published: &Published,
) -> Result<(InputReading, GapState), SenseError>
where
    G: GapSensor + ?Sized,
    I: MachineInputs + ?Sized,
{
    let machine = if wired {
        inputs.sample(tick_no).map_err(SenseError::Inputs)?
    } else {
        InputReading::default()
    };
    let mut gap = sensor.sample(tick_no).map_err(SenseError::Gap)?;
    if probing && let Some(contact) = machine.contact {
        gap = if contact {
            GapState::Short
        } else {
            GapState::Open
        };
    }
    published.gap_ticks[gap.index()].fetch_add(1, Ordering::Relaxed);
    published
        .gap
        .store(gap.index() as u8 + 1, Ordering::Relaxed);
    published.gap_volts.store(
        sensor.volts().unwrap_or(f64::NAN).to_bits(),
        Ordering::Relaxed,
    );
    Ok((machine, gap))
}

/// Which input failed.
enum SenseError {
    Inputs(InputError),
    Gap(GapError),
}

impl SenseError {
    #[cold]
    fn into_report(self, report: &mut LoopReport) {
        match self {
            SenseError::Inputs(e) => report.input_error = Some(e),
            SenseError::Gap(e) => report.gap_error = Some(e),
        }
    }
}

/// The tick's steps never reached the drives (the output refused them, or they ran into a
/// closed limit switch): they go into the report, to be taken back out of the interpolator's
/// ledger, with the point the electrode stood at before them.
fn untake(report: &mut LoopReport, fine: &Interpolator, tick: &Tick, before: PathPoint) {
    if !tick.moved() {
        return;
    }
    report.untaken = Some((tick.steps, tick.dir));
    // A tick takes at most one step event: if it finished the segment, that segment had one
    // event more than the point before it.
    let events = match fine.block() {
        Some(b) if b.seq == before.seq => b.events() as i64,
        _ => before.event + 1,
    };
    report.untaken_from = Some((before, events));
}

/// Phase 2b: what stops the job at once: the E-stop, or a limit switch that was not closed
/// when the job started.
#[inline(always)]
fn newly_tripped(safety: SafetyInputs, allowed: LimitSet) -> Option<Trip> {
    if safety.estop {
        return Some(Trip::EStop);
    }
    // Bit operations on every tick; the switches are named only when one closed.
    let closed = safety.limits.without(allowed);
    if closed.is_empty() {
        return None;
    }
    closed.iter().next().map(Trip::Limit)
}

/// Phase 1c: what the other threads asked for: a rethread, a hold (the dead-man's too).
#[inline(always)]
fn take_requests<I: MachineInputs + ?Sized>(
    fine: &mut Interpolator,
    inputs: &mut I,
    published: &Published,
) {
    if let Some(at) = published.rethread.take()
        && fine.rethread(at)
    {
        inputs.rethreaded();
    }
    keep_dead_man(published);
    fine.set_hold(published.hold.load(Ordering::Acquire));
}

/// A continuous jog whose renewal deadline passed is held here, on the job's own
/// thread, whatever the control loop is doing (the control loop then ends it). Reads the
/// clock only while a dead-man is armed.
#[inline(always)]
fn keep_dead_man(published: &Published) {
    let deadline = published.dead_man_ns.load(Ordering::Acquire);
    if deadline == 0 {
        return;
    }
    if sys::monotonic_ns() >= deadline && !published.dead_man_tripped.load(Ordering::Relaxed) {
        published.dead_man_tripped.store(true, Ordering::Release);
        hold(published);
    }
}

/// Phase 1 of a tick: wait for its deadline (real time: sleep to it and record how late the
/// wake-up was; a tick between two wake-ups, `fine.ticks_per_wake`, runs at once in the
/// burst of the last one), or in virtual time let the CPU go while held at a standstill.
#[inline(always)]
fn wait_for_tick(
    latency: &mut Option<LatencyHistogram>,
    deadline: u64,
    tick_no: u64,
    settings: &LoopSettings,
    fine: &Interpolator,
    published: &Published,
) {
    if let Some(histogram) = latency.as_mut() {
        // Only in real time: virtual time never pays the division.
        if settings.ticks_per_wake > 1
            && !tick_no.is_multiple_of(u64::from(settings.ticks_per_wake))
        {
            return;
        }
        sys::sleep_until_ns(deadline);
        let woke = sys::monotonic_ns();
        let late = woke.saturating_sub(deadline);
        histogram.record(late);
        published.latency_sum_ns.fetch_add(late, Ordering::Relaxed);
        published.latency_samples.fetch_add(1, Ordering::Relaxed);
        published.latency_max_ns.fetch_max(late, Ordering::Relaxed);
        let bucket = LATENCY_BUCKETS_US
            .iter()
            .position(|&le| late <= le * 1000)
            .unwrap_or(LATENCY_BUCKETS_US.len());
        published.latency_buckets[bucket].fetch_add(1, Ordering::Relaxed);
    } else if fine.held() && fine.still() {
        // Held in virtual time: nothing can change but the operator's mind, so let the
        // CPU go rather than spin through ticks.
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Phase 1b: the operator's controls, handed to the tick core when their word changes (an
/// event for the log and the report says when an override took effect).
#[inline(always)]
fn take_controls(had: &mut u64, fine: &mut Interpolator, tick_no: u64, published: &Published) {
    let word = published.controls.word();
    if word == *had {
        return;
    }
    let (was, now) = (controls::controls_of(*had), controls::controls_of(word));
    *had = word;
    apply_controls(now, fine);
    for (rapid, was, is) in [
        (false, was.feed_pct, now.feed_pct),
        (true, was.rapid_pct, now.rapid_pct),
    ] {
        if was != is {
            let record = EventRecord {
                tick: tick_no,
                line: fine.line(),
                event: ServoEvent::Override {
                    rapid,
                    percent: is as u16,
                },
            };
            if published.events.push(record).is_err() {
                published.events_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

fn apply_controls(controls: Controls, fine: &mut Interpolator) {
    fine.set_overrides(controls.overrides());
    fine.set_single_block(controls.single_block);
}

/// Phase 4: tell the output and the gap input what the machine is doing when it changes
/// (flushing, machining condition, the kind of motion), and report the changes as events;
/// the tick core learns whether the input's next readings are of a probe's contact.
#[inline(always)]
fn tell_activity<O, G>(
    activity: &mut Activity,
    fine: &mut Interpolator,
    tick_no: u64,
    output: &mut O,
    sensor: &mut G,
    published: &Published,
) where
    O: PulseOutput + ?Sized,
    G: GapSensor + ?Sized,
{
    let block = fine.block();
    let excursion = fine.state().spark_off();
    let mut flags = block.map_or(BlockFlags::NONE, |b| b.flags);
    if fine.dry_run() && !flags.contains(BlockFlags::PROBE) {
        // A dry run positions along the program: to the output and the gap input every move
        // is a rapid (spark off; the simulator's electrode moves through the open).
        flags |= BlockFlags::RAPID;
    }
    let now = Activity {
        flags,
        excursion,
        spark: block.is_some()
            && !flags.intersects(BlockFlags::RAPID | BlockFlags::PROBE)
            && !excursion
            && !fine.held()
            && !fine.state().is_final(),
        condition: fine.process().condition(),
        set_points: fine.process().changes(),
    };
    if now != *activity {
        let tell = |event| {
            let record = EventRecord {
                tick: tick_no,
                line: fine.line(),
                event,
            };
            if published.events.push(record).is_err() {
                published.events_dropped.fetch_add(1, Ordering::Relaxed);
            }
        };
        if flags.contains(BlockFlags::FLUSH) != activity.flags.contains(BlockFlags::FLUSH) {
            tell(ServoEvent::Flushing {
                on: flags.contains(BlockFlags::FLUSH),
            });
        }
        if flags.contains(BlockFlags::PASS_START)
            && !activity.flags.contains(BlockFlags::PASS_START)
        {
            tell(ServoEvent::PassStart {
                number: block.map_or(0, |b| b.pass),
            });
        }
        if now.condition != activity.condition {
            tell(ServoEvent::Condition {
                number: now.condition,
            });
        }
        if (flags, excursion) != (activity.flags, activity.excursion) {
            sensor.moving_in(now);
            // The input reads the contact from the next tick on (or stops reading it).
            fine.set_contact_reading(flags.contains(BlockFlags::PROBE));
        }
        if now.set_points != activity.set_points {
            output.set_points(now.condition, fine.process().generator());
            sensor.generator(fine.process().generator());
        }
        *activity = now;
        output.moving_in(now);
    }
}

/// Phase 6: what the tick's servo event means to the loop (a hold, an end, a probe result),
/// and the event on its way to the supervisor.
#[inline(always)]
fn route_event(
    tick: &Tick,
    tick_no: u64,
    fine: &Interpolator,
    settings: &LoopSettings,
    published: &Published,
    report: &mut LoopReport,
) {
    match tick.event {
        Some(ServoEvent::Paused { kind, .. }) if settings.program_pauses => {
            published.paused_kind.store(kind.code(), Ordering::Relaxed);
            published.paused_line.store(fine.line(), Ordering::Relaxed);
            hold(published);
        }
        // A collision or an alarm holds a job that has an operator; otherwise it ends it.
        Some(ServoEvent::Collision { .. } | ServoEvent::Alarm { .. })
            if settings.program_pauses =>
        {
            hold(published);
        }
        Some(ServoEvent::Collision { at }) => report.collision = Some((at, fine.line())),
        // A wire break, or a rethread's arrival at the start hole, waits for the operator.
        Some(
            ServoEvent::WireBreak { .. }
            | ServoEvent::Retreated {
                why: Excursion::Rethread,
                ..
            },
        ) if settings.program_pauses => hold(published),
        Some(ServoEvent::WireBreak { at, open }) => {
            report.wire_break = Some((at, fine.line(), open))
        }
        Some(ServoEvent::Probed { steps, contact, .. }) => {
            let result = ProbeResult { steps, contact };
            report.last_probe = Some(result);
            published.probe.publish(&result);
        }
        Some(ServoEvent::ProbeMissed { at }) => report.probe_missed = Some((at, fine.line())),
        // The producer waits for where a drilling move ended, as for a probe.
        Some(ServoEvent::Breakthrough { steps, found, .. }) => {
            published.probe.publish(&ProbeResult {
                steps,
                contact: found,
            });
        }
        _ => {}
    }
    if let Some(event) = tick.event
        && published
            .events
            .push(EventRecord {
                tick: tick_no,
                line: fine.line(),
                event,
            })
            .is_err()
    {
        published.events_dropped.fetch_add(1, Ordering::Relaxed);
    }
}

/// Phase 8: at a held standstill the output's record is made durable once, before the
/// supervisor writes its checkpoint (it waits for `output_synced`). Nothing moves here, so the
/// time a disk takes costs no step; the next deadline starts afresh.
#[inline(always)]
fn settle_standstill<O: PulseOutput + ?Sized>(
    fine: &Interpolator,
    output: &mut O,
    published: &Published,
    deadline: &mut u64,
) -> Result<(), OutputError> {
    let standstill = fine.held() && fine.still();
    if standstill && !published.output_synced.load(Ordering::Relaxed) {
        output.sync()?;
        published.output_synced.store(true, Ordering::Release);
        *deadline = sys::monotonic_ns();
    } else if !standstill && published.output_synced.load(Ordering::Relaxed) {
        published.output_synced.store(false, Ordering::Relaxed);
    }
    Ok(())
}

/// Phase 10 (real time): the next deadline, one period on; after an overrun the missed
/// periods are skipped rather than caught up.
#[inline(always)]
fn keep_deadline(deadline: &mut u64, period: u64, report: &mut LoopReport, published: &Published) {
    *deadline += period;
    let now = sys::monotonic_ns();
    if now > *deadline {
        report.overruns += 1;
        published.overruns.fetch_add(1, Ordering::Relaxed);
        let missed = (now - *deadline) / period + 1;
        report.missed_deadlines += missed;
        *deadline += missed * period;
    }
}
