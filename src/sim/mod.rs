//! The simulated EDM machine (`gap.kind = "sim"`, with `output.kind = "sim"`): no hardware,
//! a believable gap, closed around the pulses the consumer emits.
//!
//! With `output.kind = "sim"` the simulated drives take every step: their position is the
//! pulse ledger, so that output is [`crate::output::NullOutput`], and the electrode learns
//! its motion through [`GapSensor::observe`]: each emitted event's length (from the steps
//! and the step sizes), signed by its direction along the program.
//!
//! Two models of what happens in the gap (`sim.model`):
//! - **discharge** (the default, [`discharge`]): the generator's pulses one by one (ignition
//!   delay against the gap width, normal, arc, short and open pulses, removal by energy,
//!   debris and flushing, the wire's heat and its breaking), driven by the condition in
//!   force, the part height and the flushing along the cut (`@MM` lines of `sim.events`);
//! - **kinematic**: the front erodes at `sim.erosion_mm_per_min` while the gap sparks,
//!   whatever the condition; deterministic shorts from placed debris and wire breaks per
//!   metre (the tests that need that determinism use it).
//!
//! Both share the geometry below and everything else here (rapids, probing, holds,
//! breakthrough). A one-dimensional model along the programmed path, the view the servo has
//! of it:
//!
//! ```text
//!   electrode progress σ ──► gap g = φ − σ ◄── workpiece front φ
//!   (+ one event's length forward,              (+ erosion · dt while sparking)
//!    − one event's length on turn-back)
//!
//!   g < short_gap ─► short      short_gap ≤ g ≤ open_gap ─► normal (sparking)      g > open_gap ─► open
//! ```
//!
//! Four ways to a short circuit, all deterministic for a seed:
//! - **Proximity**: the electrode closes the gap faster than sparking erodes the front (a
//!   servo feed above the erosion rate, or harder material from a scripted `erosion` event).
//!   Turning back opens the gap again after a few µm.
//! - **Placed debris** (`sim.debris_shorts_per_mm`): bridges at seeded random points, so many
//!   per mm of the program's cutting moves (rapids are positioning in the open), one in each
//!   of that many equal stretches. A bridge holds the gap shorted until the electrode has
//!   turned back `debris_clear_um` from where it formed (flushing clears it); none forms in
//!   the first `debris_clear_um` of cutting, where no turn-back could go that far, so a short
//!   move (an MDI line) cuts clean.
//! - **Random debris** (`sim.debris_shorts_per_s`): the same bridges as a Poisson process in
//!   time while sparking (past the first `debris_clear_um` too), from a seeded splitmix64: a
//!   stationary process for long runs.
//! - **Scripted** (`sim.events`, [`events`]): debris at a tick, erosion-rate changes, and
//!   holds (the gap reads short or open for so many ticks whatever the electrode does: a
//!   welded short that only an alarm ends, a dielectric failure).
//!
//! With the default erosion rate above the normal feed and below the open feed, the servo
//! alternates between sparking and closing in, and only debris shorts the gap.
//!
//! **Breakthrough** (`sim.breakthrough_at_mm`): past that far into the work (the cutting
//! travel less the turn-backs over it) the work has ended: the gap reads open, as a drill's
//! does when it comes out of the far side.
//!
//! **Rapids** (told through [`GapSensor::moving_in`]): the spark is off, so the gap reads open
//! (a debris bridge still shorts it, and a scripted hold still applies: that is how a
//! collision is simulated), and moving forward through one carries the front along, so the
//! next cut starts at `initial_gap` from the work, as after positioning to a new start hole.

pub mod discharge;
pub mod events;
mod inputs;
mod probe;

use crate::buffer::BlockFlags;
use std::path::PathBuf;

use crate::gap::{GapError, GapSensor, GapState, ScriptError};
use crate::inputs::SimulatedWire;
use crate::rng::SplitMix64;
use crate::vocab::TickPeriod;
use crate::vocab::{GapVolts, GeneratorSetPoints, MAX_AXES, PulseCounts};

pub use discharge::{DischargeParams, Discharges};
pub use events::{CutChange, SimEvent, SimScript};
pub use inputs::SimInputs;
pub use probe::{SimHole, SimPart};

/// The simulated gap's own settings (`[sim]`, validated by the configuration), lengths in mm
/// and speeds in mm/s.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    pub seed: u64,
    pub initial_gap_mm: f64,
    pub short_gap_mm: f64,
    pub open_gap_mm: f64,
    pub erosion_mm_per_s: f64,
    /// Debris shorts placed along the program's cutting, per mm of it.
    pub debris_per_mm: f64,
    pub debris_shorts_per_s: f64,
    pub debris_clear_mm: f64,
    /// Wire breaks per metre of cutting travel (a seeded Poisson process; 0: none).
    pub wire_breaks_per_m: f64,
    /// Scripted events file.
    pub events: Option<PathBuf>,
    /// Where each machine axis's home switch is, in the machine coordinates an unhomed axis
    /// believes (mm; `None`: at the axis's `home_position_mm`). A homed axis finds its
    /// switch at its home position.
    pub home_switch_mm: Vec<Option<f64>>,
    /// The part a wire-touch cycle finds (`sim.part_edge_mm`, `sim.hole_*`).
    pub part: SimPart,
    /// The work's thickness along the cut: past this far into the work (mm of cutting travel,
    /// less the turn-backs over it) there is no material and the gap reads open (a drill
    /// breaks through); infinite: never.
    pub breakthrough_at_mm: f64,
    /// What happens in the gap.
    pub model: SimModel,
}

/// `sim.model`: what the gap does when it sparks.
#[derive(Debug, Clone, PartialEq)]
pub enum SimModel {
    /// The front erodes at `erosion_mm_per_s`, whatever the condition.
    Kinematic,
    /// The generator's pulses, one by one.
    Discharge(Box<DischargeParams>),
}

/// Everything the model needs: its own settings, the machine's step sizes (unused axes 0)
/// and the tick period.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSettings {
    pub params: SimConfig,
    pub step_mm: [f64; MAX_AXES],
    pub tick: TickPeriod,
    /// The gap voltage's thresholds: the sparking band of the model maps onto them.
    pub volts: GapVolts,
    /// Indices of X and Y in the machine's axes (where the part lies), if it has both.
    pub plane: Option<[usize; 2]>,
    /// The wire's radius (`wire.diameter_mm` / 2), mm.
    pub wire_radius_mm: f64,
}

/// The simulated generator's open-circuit voltage (V): what an open gap reads.
pub const OPEN_CIRCUIT_V: f64 = 80.0;
/// Ticks per sampling window of the simulated pulse counters (1 ms at 50 µs).
pub const RATIO_WINDOW_TICKS: u32 = 20;

/// What the simulated gap did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimCounters {
    /// Shorts from debris (placed, random or scripted).
    pub debris_shorts: u64,
    /// Shorts from the electrode reaching the front.
    pub proximity_shorts: u64,
    /// Ticks the gap spent sparking.
    pub sparking_ticks: u64,
    /// Wire breaks.
    pub wire_breaks: u64,
}

/// `gap.kind = "sim"`: the simulated machine, as a device with two sides like the port's
/// and HAL's: the gap and the machine inputs.
#[derive(Debug, Clone)]
pub struct SimMachine {
    pub gap: SimGap,
    pub inputs: SimInputs,
}

impl SimMachine {
    /// The machine for a program whose cutting moves lie at `cutting_spans` along its path
    /// (`(from, to)`, mm of path length from the start), with scripted `events`.
    pub fn new(
        settings: &SimSettings,
        cutting_spans: &[(f64, f64)],
        script: SimScript,
    ) -> SimMachine {
        let (pressed, gap_events): (Vec<_>, Vec<_>) = script
            .by_tick
            .into_iter()
            .partition(|(_, e)| e.presses_an_input());
        let wire = SimulatedWire::default();
        let mut gap = SimGap::new(settings, cutting_spans, gap_events, wire.clone());
        gap.along = script.by_cut_mm;
        SimMachine {
            gap,
            inputs: SimInputs::new(pressed, wire),
        }
    }

    /// The machine of `settings` for a program with these cutting spans (see
    /// [`new`](Self::new)), with the scripted events of `sim.events` (read and checked here,
    /// before the job).
    pub fn load(
        settings: &SimSettings,
        cutting_spans: &[(f64, f64)],
    ) -> Result<SimMachine, ScriptError> {
        let events = match &settings.params.events {
            Some(path) => events::load(path)?,
            None => SimScript::default(),
        };
        Ok(SimMachine::new(settings, cutting_spans, events))
    }
}

/// The simulated machine's gap side: the closed-loop gap model.
#[derive(Debug, Clone)]
pub struct SimGap {
    params: SimConfig,
    step_mm: [f64; MAX_AXES],
    dt: f64,
    rng: SplitMix64,
    /// Electrode progress along the path (mm).
    progress: f64,
    /// Workpiece front along the path (mm).
    front: f64,
    /// Current erosion rate (mm/s).
    erosion: f64,
    /// A debris bridge holds the gap shorted until progress falls to this (mm).
    debris_until: Option<f64>,
    /// A scripted bridge waiting for the gap to spark: its clearing distance (mm).
    debris_pending: Option<f64>,
    /// Placed debris, by progress along the path (mm), ascending; the next one to form.
    debris_at: Vec<f64>,
    next_debris: usize,
    /// Probability of a random debris short in one sparking tick.
    debris_per_tick: f64,
    events: Vec<(u64, SimEvent)>,
    next_event: usize,
    /// A scripted hold: this state until (excluding) this tick.
    hold: Option<(GapState, u64)>,
    state: GapState,
    /// The move in hand is a rapid: the spark is off, the electrode moves through the open.
    rapid: bool,
    /// The generator is off while the electrode moves (a probing move, a jump, a rethread):
    /// the gap is only the distance, nothing erodes and no debris forms.
    spark_off: bool,
    /// Probing away from the work: forward motion opens the gap.
    away: bool,
    /// A probing move is in hand.
    probing: bool,
    /// What probing moves read: the gap model, a homing job's switch or a find cycle's part.
    probe: probe::Target,
    wire: probe::SimWire,
    /// Cutting travel so far, and where along it the wire breaks next (mm; infinite: never).
    cut_mm: f64,
    next_break_mm: f64,
    /// How far the cutting has gone into the work (mm): forward cutting travel less the
    /// turn-backs over it, so a re-advance does not count twice.
    into_work_mm: f64,
    /// The wire breaks' own generator, so that turning them on leaves the debris as it was.
    break_rng: SplitMix64,
    /// The wire is broken: the gap reads open. The wire is the one the inputs side reports
    /// and a rethread mends (`wire_sensor`); `broken` is what this side last knew of it.
    broken: bool,
    wire_sensor: SimulatedWire,
    /// Voltage thresholds (V), see [`GapSensor::volts`].
    volts: GapVolts,
    /// The ratio counters of the window in progress (open, short, ticks) and the last
    /// window's ratios, see [`GapSensor::ratios`].
    window: (f64, f64, u32),
    ratios: (f64, f64),
    counters: SimCounters,
    /// The discharge model (`sim.model = "discharge"`), its own random numbers, the
    /// generator's set points in force, the last tick's pulses and mean voltage.
    discharges: Option<Discharges>,
    process_rng: SplitMix64,
    generator: GeneratorSetPoints,
    pulses: PulseCounts,
    window_pulses: PulseCounts,
    process_volts: f64,
    /// The changes along the cut, by position into the work (mm); the next one to apply.
    along: Vec<(f64, CutChange)>,
    next_along: usize,
}

impl SimGap {
    /// The gap side of [`SimMachine::new`], with the events that change the gap and the
    /// wire it shares with the inputs side.
    fn new(
        settings: &SimSettings,
        cutting_spans: &[(f64, f64)],
        events: Vec<(u64, SimEvent)>,
        wire_sensor: SimulatedWire,
    ) -> SimGap {
        let step_mm = settings.step_mm;
        let dt = settings.tick.secs();
        let params = settings.params.clone();
        let mut rng = SplitMix64::new(params.seed);
        // One bridge in each of n equal stretches of the cutting past its first
        // `debris_clear` (a bridge there could not be backed away from), away from the
        // stretch ends.
        let cutting: f64 = cutting_spans.iter().map(|(a, b)| b - a).sum();
        let clear = params.debris_clear_mm;
        let room = (cutting - clear).max(0.0);
        // The discharge model makes its own shorts (contamination) and breaks (heat).
        let kinematic = params.model == SimModel::Kinematic;
        let n = if kinematic {
            (params.debris_per_mm * room).round() as usize
        } else {
            0
        };
        // The bridges' cutting distances increase with k, so one walk over the spans places
        // them all.
        let mut spans = cutting_spans.iter().peekable();
        let mut before = 0.0; // cutting length of the spans walked past
        let debris_at = (0..n)
            .map(|k| {
                let into = clear + room * (k as f64 + rng.uniform(0.1, 0.9)) / n as f64;
                while let Some(&&(from, to)) = spans.peek() {
                    if into - before <= to - from {
                        return from + (into - before);
                    }
                    before += to - from;
                    spans.next();
                }
                cutting_spans.last().map_or(0.0, |&(_, to)| to)
            })
            .collect();
        let mut break_rng = SplitMix64::new(params.seed ^ 0x5749_5245_4252_4b21);
        let breaks_per_m = if kinematic {
            params.wire_breaks_per_m
        } else {
            0.0
        };
        let next_break_mm = next_break(&mut break_rng, breaks_per_m, 0.0);
        SimGap {
            spark_off: false,
            away: false,
            probing: false,
            probe: probe::Target::Gap,
            wire: probe::SimWire {
                part: settings.params.part,
                plane: settings.plane,
                radius_mm: settings.wire_radius_mm,
            },
            cut_mm: 0.0,
            into_work_mm: 0.0,
            next_break_mm,
            break_rng,
            broken: false,
            wire_sensor,
            debris_per_tick: if kinematic {
                -(-params.debris_shorts_per_s * dt).exp_m1()
            } else {
                0.0
            },
            rng,
            front: params.initial_gap_mm,
            erosion: params.erosion_mm_per_s,
            params,
            step_mm,
            dt,
            progress: 0.0,
            debris_until: None,
            debris_pending: None,
            debris_at,
            next_debris: 0,
            events,
            next_event: 0,
            hold: None,
            state: GapState::Open,
            rapid: false,
            volts: settings.volts,
            window: (0.0, 0.0, 0),
            ratios: (1.0, 0.0),
            counters: SimCounters::default(),
            discharges: match &settings.params.model {
                SimModel::Kinematic => None,
                SimModel::Discharge(p) => Some(Discharges::new(**p)),
            },
            process_rng: SplitMix64::new(settings.params.seed ^ 0x4449_5343_4841_5247),
            generator: GeneratorSetPoints::default(),
            pulses: PulseCounts::default(),
            window_pulses: PulseCounts::default(),
            process_volts: f64::NAN,
            along: Vec::new(),
            next_along: 0,
        }
    }

    /// The gap distance (mm).
    fn gap_mm(&self) -> f64 {
        self.front - self.progress
    }

    pub fn counters(&self) -> SimCounters {
        self.counters
    }

    /// Where the placed debris bridges form, by progress along the path (mm).
    pub fn debris_positions(&self) -> &[f64] {
        &self.debris_at
    }

    fn apply_events(&mut self, tick: u64) {
        while let Some(&(at, event)) = self.events.get(self.next_event) {
            if at > tick {
                break;
            }
            self.next_event += 1;
            match event {
                SimEvent::Debris { clear_mm } => {
                    self.debris_pending = Some(clear_mm.unwrap_or(self.params.debris_clear_mm));
                }
                SimEvent::Erosion { mm_per_s } => self.erosion = mm_per_s,
                SimEvent::Hold { state, ticks } => {
                    self.hold = Some((state, at.saturating_add(ticks)));
                }
                // The inputs side's (split off in `SimMachine::new`).
                SimEvent::Estop | SimEvent::Limit(_) => {}
            }
        }
    }

    /// The inputs side mended the wire (a rethread): the next break is drawn from here.
    fn rethreaded(&mut self) {
        self.broken = false;
        if let Some(d) = &mut self.discharges {
            d.rethreaded();
        }
        self.next_break_mm = next_break(
            &mut self.break_rng,
            self.params.wire_breaks_per_m,
            self.cut_mm,
        );
    }

    /// While sparking: is a debris bridge forming now? Returns its clearing distance.
    fn debris_forming(&mut self) -> Option<f64> {
        if let Some(clear) = self.debris_pending.take() {
            return Some(clear);
        }
        if self
            .debris_at
            .get(self.next_debris)
            .is_some_and(|&at| self.progress >= at)
        {
            self.next_debris += 1;
            return Some(self.params.debris_clear_mm);
        }
        if self.debris_per_tick > 0.0
            && self.cut_mm >= self.params.debris_clear_mm
            && self.rng.next_f64() < self.debris_per_tick
        {
            return Some(self.params.debris_clear_mm);
        }
        None
    }
}

/// Where along the cutting travel the wire breaks next: exponentially distributed at `per_m`
/// breaks per metre after `from_mm` (never when the rate is 0).
fn next_break(rng: &mut SplitMix64, per_m: f64, from_mm: f64) -> f64 {
    if per_m <= 0.0 {
        return f64::INFINITY;
    }
    let u = 1.0 - rng.next_f64();
    from_mm - u.ln() / per_m * 1000.0
}

impl SimGap {
    /// The gap state of tick `tick` from the model (scripted holds, debris, rapids, distance).
    fn sample_state(&mut self, tick: u64) -> GapState {
        self.apply_events(tick);
        if let Some(state) = self.probe.state(self.probing, &self.wire, &self.step_mm) {
            self.state = state;
            return state;
        }
        if let Some((state, until)) = self.hold {
            if tick < until {
                self.state = state;
                return state;
            }
            self.hold = None;
        }
        if let Some(until) = self.debris_until {
            if self.progress > until {
                self.state = GapState::Short;
                return self.state;
            }
            self.debris_until = None;
        }
        if self.rapid || self.broken || self.into_work_mm >= self.params.breakthrough_at_mm {
            // The spark is off while positioning (and no wire, no discharge): open.
            self.state = GapState::Open;
            return self.state;
        }
        if self.discharges.is_some() {
            self.state = self.discharge_state();
            return self.state;
        }
        let gap = self.gap_mm();
        let previous = self.state;
        self.state = if gap < self.params.short_gap_mm {
            GapState::Short
        } else if gap > self.params.open_gap_mm {
            GapState::Open
        } else {
            GapState::Normal
        };
        if self.state == GapState::Short && previous != GapState::Short {
            self.counters.proximity_shorts += 1;
        }
        if self.state == GapState::Normal && !self.spark_off {
            self.counters.sparking_ticks += 1;
            self.front += self.erosion * self.dt;
            if let Some(clear) = self.debris_forming() {
                self.debris_until = Some(self.progress - clear);
                self.counters.debris_shorts += 1;
                self.state = GapState::Short;
            }
        }
        self.state
    }

    /// The discharge model's tick: the generator's cycles at the gap's width (a contact below
    /// `short_gap`), the front moved by what they removed, the wire heated; with the spark
    /// off, only the distance (and the wire cools).
    fn discharge_state(&mut self) -> GapState {
        let Some(d) = self.discharges.as_mut() else {
            return self.state;
        };
        let gap = self.front - self.progress;
        let contact = gap < self.params.short_gap_mm;
        let dt_us = self.dt * 1e6;
        if self.spark_off {
            d.idle(dt_us);
            self.pulses = PulseCounts::default();
            self.process_volts = f64::NAN;
            return if contact {
                GapState::Short
            } else {
                GapState::Open
            };
        }
        while let Some(&(at, change)) = self.along.get(self.next_along) {
            if at > self.into_work_mm {
                break;
            }
            self.next_along += 1;
            match change {
                CutChange::Height(mm) => d.set_height(mm),
                CutChange::Flushing(f) => d.set_flushing(f),
            }
        }
        let gap_um = if contact { 0.0 } else { gap * 1000.0 };
        let t = d.tick(dt_us, gap_um, &self.generator, &mut self.process_rng);
        self.front += t.removed_mm;
        self.pulses = t.pulses;
        if t.volts.is_finite() {
            self.process_volts = t.volts;
        }
        if t.wire_broke {
            self.broken = true;
            self.wire_sensor.set_broken(true);
            self.counters.wire_breaks += 1;
            return GapState::Open;
        }
        let state = t.pulses.state().unwrap_or(self.state);
        if contact && self.state != GapState::Short {
            self.counters.proximity_shorts += 1;
        }
        if state == GapState::Normal {
            self.counters.sparking_ticks += 1;
        }
        state
    }

    /// Counts the tick into the pulse-ratio window: an open gap is all open pulses, a shorted
    /// one all short, a sparking one open in proportion to how far across the sparking band the
    /// gap is (a wider gap fails to ignite more often).
    fn count_pulses(&mut self, state: GapState) {
        if self.discharges.is_some() {
            self.window_pulses.add(&self.pulses);
            self.window.2 += 1;
            if self.window.2 >= RATIO_WINDOW_TICKS {
                let w = self.window_pulses;
                let n = w.total().max(1) as f64;
                self.ratios = (w.open as f64 / n, w.short as f64 / n);
                self.window_pulses = PulseCounts::default();
                self.window.2 = 0;
            }
            return;
        }
        let open = match state {
            GapState::Open => 1.0,
            GapState::Short => 0.0,
            GapState::Normal => {
                let p = &self.params;
                ((self.gap_mm() - p.short_gap_mm) / (p.open_gap_mm - p.short_gap_mm))
                    .clamp(0.0, 1.0)
            }
        };
        let short = if state == GapState::Short { 1.0 } else { 0.0 };
        self.window.0 += open;
        self.window.1 += short;
        self.window.2 += 1;
        if self.window.2 >= RATIO_WINDOW_TICKS {
            let n = self.window.2 as f64;
            self.ratios = (self.window.0 / n, self.window.1 / n);
            self.window = (0.0, 0.0, 0);
        }
    }
}

impl GapSensor for SimGap {
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError> {
        if self.broken && !self.wire_sensor.is_broken() {
            self.rethreaded();
        }
        let state = self.sample_state(tick);
        self.count_pulses(state);
        Ok(state)
    }

    fn observe(&mut self, steps: &[i8; MAX_AXES], dir: i8) {
        self.probe.observe(steps);
        if dir == 0 {
            return;
        }
        let mut len2 = 0.0;
        for (s, mm) in steps.iter().zip(&self.step_mm) {
            let d = *s as f64 * mm;
            len2 += d * d;
        }
        let len = len2.sqrt();
        self.progress += dir as f64 * len;
        if self.away {
            // Probing away: the electrode leaves the work as it advances.
            self.front += 2.0 * dir as f64 * len;
        }
        if !self.rapid {
            self.into_work_mm += dir as f64 * len;
        }
        if dir > 0 && !self.rapid && !self.spark_off && !self.broken {
            self.cut_mm += len;
            if self.cut_mm >= self.next_break_mm {
                self.broken = true;
                self.wire_sensor.set_broken(true);
                self.counters.wire_breaks += 1;
            }
        }
        if self.rapid && dir > 0 {
            // Positioning through the open: the next cut starts at the initial gap. (A
            // turn-back through a rapid retraces it and leaves the front where it is.)
            self.front = self.progress + self.params.initial_gap_mm;
        }
    }

    fn moving_in(&mut self, now: crate::buffer::Activity) {
        let flags = now.flags;
        self.rapid = flags.contains(BlockFlags::RAPID);
        self.spark_off = flags.contains(BlockFlags::PROBE) || now.excursion;
        self.away = flags.contains(BlockFlags::PROBE_AWAY) && !now.excursion;
        self.probing = flags.contains(BlockFlags::PROBE) && !now.excursion;
    }

    fn probe_reads(&mut self, what: crate::vocab::ProbeReads) {
        self.probe = probe::Target::new(what);
    }

    /// The generator's average gap voltage as the model sees it: 0 V shorted, the
    /// open-circuit voltage open, and across the sparking band (`short_gap` to `open_gap`) a
    /// linear rise from the short threshold to the open one: a wider gap burns at a higher
    /// voltage, as a real gap does.
    fn volts(&self) -> Option<f64> {
        if self.discharges.is_some() {
            // The mean over the tick's cycles where it sparked; a shorted or open gap's as
            // the kinematic model says.
            return Some(match self.state {
                GapState::Short => 0.0,
                _ if self.process_volts.is_finite() && !self.spark_off && !self.rapid => {
                    self.process_volts
                }
                _ => OPEN_CIRCUIT_V,
            });
        }
        Some(match self.state {
            GapState::Short => 0.0,
            GapState::Open => OPEN_CIRCUIT_V,
            GapState::Normal => {
                let p = &self.params;
                let f = ((self.gap_mm() - p.short_gap_mm) / (p.open_gap_mm - p.short_gap_mm))
                    .clamp(0.0, 1.0);
                self.volts.short_below + (self.volts.open_above - self.volts.short_below) * f
            }
        })
    }

    fn ratios(&self) -> Option<(f64, f64)> {
        Some(self.ratios)
    }

    fn pulses(&self) -> Option<PulseCounts> {
        self.discharges.as_ref().map(|_| self.pulses)
    }

    fn generator(&mut self, set: &GeneratorSetPoints) {
        self.generator = *set;
    }

    fn flushing(&self) -> Option<f64> {
        self.discharges.as_ref().map(|d| d.flushing())
    }
}

#[cfg(test)]
pub(crate) mod tests;
