//! LinuxCNC's HAL as the machine's hardware layer (`output.kind = "hal"`): edmd becomes a HAL
//! userspace component, and whatever HAL drives (Mesa cards through `hm2_eth`/`hm2_pci`, the
//! parallel port through `hal_parport` with `stepgen` in a base thread, EtherCAT drives
//! through `lcec`) drives the EDM machine.
//!
//! ```text
//!  edmd's consumer thread, each tick            HAL (its servo thread, each period)
//!  ledger + steps ─► edmd.axis.L.pos-cmd ──net──► stepgen.N.position-cmd ─► step/dir
//!  edmd.axis.L.pos-fb ◄──────────────────────net── stepgen.N.position-fb   (following error)
//!  edmd.estop-ok-in, …-lim-sw, home-sw, probe-in, wire-break-in ◄── input pins
//!  edmd.gap.short / .open / .voltage ◄── the generator's gap detection
//!  edmd.gap.pulses-normal / -arc / -short / -open, .ignition-delay-us, .flushing
//!                                      ◄── its pulse discriminator's counters, the nozzle's
//!                                          pressure sensor
//!  edmd.enable-out, spark-on, flush-on, condition, state ──► the drives and the generator
//!  edmd.watchdog ──► a `watchdog` in a HAL thread (edmd's heartbeat)
//!  edmd.rt-beat-in ◄── `charge_pump` in the servo thread (HAL's heartbeat)
//!  edmd.gen.on-time-us, off-time-us, peak-current-a, open-voltage-v, servo-ref-v,
//!      wire-tension-n, wire-speed-m-min, flushing-bar ──► the generator's set points
//! ```
//!
//! **Set points.** The `edmd.gen.*` float pins carry what the condition in force sets the
//! generator to (`[generator] condition`, or the job's technology table), written when the
//! condition changes; 0 where the condition gives no value (and under no condition).
//!
//! **Units and frames.** Pins are in machine units (mm). `pos-cmd` is the pulse ledger: every
//! step edmd has given the axis, in mm, as LinuxCNC's `motor-pos-cmd` is the joint position
//! plus the offset homing set. It never jumps: homing and offsets move edmd's idea of where
//! the machine is, never the drives. It starts where the drives' feedback stands (`pos-fb`,
//! rounded to a step): at 0 in a HAL just started, as `stepgen`'s counts are, and where a
//! previous edmd left the drives when edmd is loaded again into a HAL that kept running; the
//! daemon then distrusts the machine position until it is homed or confirmed, since the
//! drives may have moved while no edmd watched ([`Opened::drives_moved`]). `pos-fb`, when
//! `hal.max_following_error_mm` is set, is the same motor position read back; a difference
//! beyond it, or a feedback that is not a number, stops the job with an alarm naming the axis
//! (LinuxCNC's joint following error).
//!
//! **Timing.** edmd's tick runs free on its own thread (50 µs by default) and writes `pos-cmd`
//! every tick; HAL's servo thread reads it at its own period. A HAL thread cannot pace a
//! userspace component (its functions run in `rtapi_app`, not in edmd), and the tick core's
//! determinism does not depend on HAL: the lattice position is exact at every tick, and a
//! position-mode `stepgen` reaches it within a servo period and its own acceleration limits.
//! `BENCHMARKS.md` gives the measured lag.
//!
//! **Safety.** `estop-ok-in` is LinuxCNC's sense: false stops (so an unconnected pin stops the
//! machine: net it, or `setp` it true on a bench), in a job within the tick and between jobs
//! within the fine thread's idle poll (1 ms), which also latches a pulse the control loop
//! has not yet seen; `enable-out` is false from then until a reset and the next motion.
//! Dropping the component first sets `enable-out`, `spark-on` and `flush-on` false, then
//! leaves HAL, which removes its pins.
//!
//! A killed edmd cannot drop anything, so HAL must notice by itself: `edmd.watchdog` toggles
//! every `hal.heartbeat_ms` while the fine thread runs (each tick's share of it in a job, each
//! idle poll between jobs; not every tick, which a slower HAL thread could sample in step with
//! and see standing still), and the HAL file gates the drives' enables and the spark with a
//! `watchdog` of it (`config/hal/sim.hal`). The other way round, `edmd.rt-beat-in` is a bit a
//! HAL thread toggles (`charge_pump`); with `hal.rt_beat_timeout_ms` set, a bit that stands
//! still that long is HAL's real-time side gone, an alarm in a job and between jobs.
//!
//! **Who holds the name.** The component's id and the daemon's pid are recorded
//! ([`owner`]): `edmd hal-reap`, the HAL file's line before `loadusr -W edmd serve`, removes
//! the component a killed edmd left, so the name is free again for the edmd loaded next
//! (`loadusr -W` itself would take the dead component, still marked ready, for the new one
//! and return at once); and `edmd hal-wait`, the service's last HAL command, fails when edmd
//! did not stop cleanly, so `halrun` unloads HAL and systemd sees the failure.
//!
//! The library is loaded at run time (`hal/ffi.rs`); without LinuxCNC's HAL the component is
//! refused at startup with the package to install.

mod devices;
// The HAL library's calls: the module's only `unsafe`.
#[allow(unsafe_code)]
mod ffi;
pub mod owner;

use std::path::PathBuf;
use std::sync::Arc;

pub use devices::{HalGap, HalInputs, HalOutput};
use ffi::{BitPin, Component, Dir, Hal, Pin};

use crate::vocab::{Axis, GapVolts, GeneratorSetPoints};

/// How the generator tells the gap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GapPins {
    /// `edmd.gap.short` and `edmd.gap.open` (bits from the generator's detection).
    Bits,
    /// `edmd.gap.voltage` (the average gap voltage, V), by the gap's two thresholds.
    Voltage,
}

/// What the component is made with (`[hal]`).
#[derive(Debug, Clone, PartialEq)]
pub struct HalSettings {
    /// The component's name: every pin's prefix.
    pub component: String,
    pub axes: Vec<Axis>,
    pub step_mm: Vec<f64>,
    /// `|pos-cmd − pos-fb|` beyond this stops the job (mm); `None`: `pos-fb` is not read.
    pub max_following_error_mm: Option<f64>,
    pub gap: GapPins,
    /// `edmd.probe-in` is wired to a probe: probing moves read it (otherwise, as on a wire
    /// machine, the gap's short is the contact).
    pub probe_input: bool,
    /// The voltage thresholds of `gap.kind = "hal"` with [`GapPins::Voltage`].
    pub volts: GapVolts,
    /// The HAL library: a name the dynamic loader finds, or a path.
    pub library: String,
    /// The fine thread's tick: a job's time, tick by tick, for the heartbeats.
    pub tick_ns: u64,
    /// `edmd.watchdog` changes level this often.
    pub heartbeat_ns: u64,
    /// `edmd.rt-beat-in` standing still this long is HAL's real-time side gone; `None`: not
    /// read.
    pub rt_beat_timeout_ns: Option<u64>,
    /// The record of who holds the component ([`owner`]).
    pub owner_file: PathBuf,
}

/// Why the component could not be made.
#[derive(Debug, thiserror::Error)]
pub enum HalError {
    #[error(
        "output.kind = \"hal\" needs LinuxCNC's HAL library ({reason}); install Debian's \
         linuxcnc-uspace (apt install linuxcnc-uspace), or point hal.library at the library"
    )]
    Library { reason: String },
    #[error(
        "cannot join HAL as component {component:?} (hal_init returned {code}): is the name \
         free (`halcmd show comp`)? Start edmd from the HAL file with `loadusr -W edmd serve …`"
    )]
    Init { component: String, code: i32 },
    #[error(
        "HAL is not running (no rtapi_app process): start edmd from the machine's HAL file \
         (`halrun -f machine.hal` with `loadusr -W edmd serve …`, or LinuxCNC's), not on its own"
    )]
    NotRunning,
    #[error(
        "HAL component {component:?} is held by a running edmd (pid {pid}): stop it first, or \
         give this one another hal.component"
    )]
    Taken { component: String, pid: u32 },
    #[error(
        "HAL component {component:?} was left by edmd pid {pid}, which did not stop (killed?): \
         remove it first with `edmd hal-reap` (the HAL file's line before `loadusr -W edmd \
         serve`: `loadusr -W` would otherwise take the dead component for this one, and the \
         file's nets would go to its pins)"
    )]
    LeftByDead { component: String, pid: u32 },
    #[error("HAL: {call} failed ({code})")]
    Call { call: String, code: i32 },
    #[error("HAL: {0:?} is not a name HAL takes")]
    Name(String),
}

/// One axis's pins.
#[derive(Debug)]
pub(crate) struct AxisPins {
    pub pos_cmd: Pin<f64>,
    pub pos_fb: Pin<f64>,
    pub home_sw: BitPin,
    pub pos_lim_sw: BitPin,
    pub neg_lim_sw: BitPin,
}

/// Every pin of the component. The component itself leaves HAL when the last pin goes.
#[derive(Debug)]
pub(crate) struct Pins {
    pub axes: Vec<AxisPins>,
    pub enable_out: BitPin,
    pub spark_on: BitPin,
    pub flush_on: BitPin,
    pub condition: Pin<i32>,
    /// The condition's set points, in [`GeneratorSetPoints::named`]'s order.
    pub generator: Vec<Pin<f64>>,
    pub state: Pin<i32>,
    pub estop_ok_in: BitPin,
    pub probe_in: BitPin,
    pub wire_break_in: BitPin,
    pub gap_voltage: Pin<f64>,
    pub gap_short: BitPin,
    pub gap_open: BitPin,
    /// The discriminator's running counts of normal, arc, short and open pulses (edmd reads
    /// what each gained in a tick; they may wrap), the mean ignition delay of its last
    /// pulses (µs) and the flushing a nozzle pressure sensor reads (1 at the part, 0: not
    /// connected).
    pub gap_pulses: [Pin<i32>; 4],
    pub gap_ignition_delay_us: Pin<f64>,
    pub gap_flushing: Pin<f64>,
    /// edmd's heartbeat, for a HAL `watchdog`.
    pub watchdog: BitPin,
    /// HAL's heartbeat (a bit a HAL thread toggles).
    pub rt_beat_in: BitPin,
}

impl Pins {
    /// The outputs inactive: drives disabled, no spark, no flushing.
    fn make_safe(&self) {
        self.enable_out.set(false);
        self.spark_on.set(false);
        self.flush_on.set(false);
        self.state.set(State::Idle as i32);
    }
}

impl Drop for Pins {
    fn drop(&mut self) {
        self.make_safe();
    }
}

/// What `edmd.state` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(i32)]
pub enum State {
    /// No job.
    Idle = 0,
    /// A job is running (moving, held or sparking).
    Running = 1,
    /// The last job stopped on an alarm (a following error, a device).
    Alarm = 2,
}

/// The component's three sides, sharing its pins, and what opening it found.
pub struct Opened {
    pub output: HalOutput,
    pub gap: HalGap,
    pub inputs: HalInputs,
    /// Why the machine position is not to be trusted: edmd joins a HAL that outlived an
    /// earlier edmd (one killed, whose component it removed, or drives whose feedback is not
    /// 0), and the drives may have moved meanwhile. The daemon distrusts the position until it
    /// is homed or confirmed.
    pub distrust: Option<String>,
    /// Says the component is ready (what `loadusr -W` waits for): call once the daemon
    /// serves (its control socket listens).
    pub ready: ReadySignal,
}

/// Tells HAL the component is ready, once.
pub struct ReadySignal(Arc<Component>);

impl ReadySignal {
    pub fn send(self) -> Result<(), HalError> {
        self.0.ready()?;
        tracing::info!("HAL: component {} ready", self.0.name());
        Ok(())
    }
}

/// Joins the running HAL as `settings.component` (taking the name back from a dead edmd that
/// left it), makes every pin and records who holds it. The component is not ready yet:
/// [`Opened::ready`].
pub fn open(settings: &HalSettings) -> Result<Opened, HalError> {
    let (c, dead) = join(settings)?;
    let name = |pin: &str| format!("{}.{pin}", settings.component);
    let mut axes = Vec::new();
    for a in &settings.axes {
        let l = a.letter().to_ascii_lowercase();
        axes.push(AxisPins {
            pos_cmd: c.float(&name(&format!("axis.{l}.pos-cmd")), Dir::Out)?,
            pos_fb: c.float(&name(&format!("axis.{l}.pos-fb")), Dir::In)?,
            home_sw: c.bit(&name(&format!("axis.{l}.home-sw")), Dir::In)?,
            pos_lim_sw: c.bit(&name(&format!("axis.{l}.pos-lim-sw")), Dir::In)?,
            neg_lim_sw: c.bit(&name(&format!("axis.{l}.neg-lim-sw")), Dir::In)?,
        });
    }
    let pins = Pins {
        axes,
        enable_out: c.bit(&name("enable-out"), Dir::Out)?,
        spark_on: c.bit(&name("spark-on"), Dir::Out)?,
        flush_on: c.bit(&name("flush-on"), Dir::Out)?,
        condition: c.s32(&name("condition"), Dir::Out)?,
        generator: GeneratorSetPoints::default()
            .named()
            .iter()
            .map(|(pin, _)| c.float(&name(&format!("gen.{pin}")), Dir::Out))
            .collect::<Result<_, _>>()?,
        state: c.s32(&name("state"), Dir::Out)?,
        estop_ok_in: c.bit(&name("estop-ok-in"), Dir::In)?,
        probe_in: c.bit(&name("probe-in"), Dir::In)?,
        wire_break_in: c.bit(&name("wire-break-in"), Dir::In)?,
        gap_voltage: c.float(&name("gap.voltage"), Dir::In)?,
        gap_short: c.bit(&name("gap.short"), Dir::In)?,
        gap_open: c.bit(&name("gap.open"), Dir::In)?,
        gap_pulses: [
            c.s32(&name("gap.pulses-normal"), Dir::In)?,
            c.s32(&name("gap.pulses-arc"), Dir::In)?,
            c.s32(&name("gap.pulses-short"), Dir::In)?,
            c.s32(&name("gap.pulses-open"), Dir::In)?,
        ],
        gap_ignition_delay_us: c.float(&name("gap.ignition-delay-us"), Dir::In)?,
        gap_flushing: c.float(&name("gap.flushing"), Dir::In)?,
        watchdog: c.bit(&name("watchdog"), Dir::Out)?,
        rt_beat_in: c.bit(&name("rt-beat-in"), Dir::In)?,
    };
    pins.make_safe();
    if let Err(e) = owner::Owner::this_process(c.name(), c.id()).write(&settings.owner_file) {
        tracing::warn!(
            "{}: cannot record who holds HAL component {} ({e}): a restart after a kill will \
             find the name taken",
            settings.owner_file.display(),
            c.name()
        );
    }
    tracing::info!(
        "HAL: component {} made ({} pins)",
        c.name(),
        5 * pins.axes.len() + 19 + pins.generator.len()
    );
    let pins = Arc::new(pins);
    let output = HalOutput::new(pins.clone(), settings);
    let distrust = match dead {
        Some(pid) => Some(format!(
            "edmd pid {pid} ended without a clean stop while HAL ran on, and the drives with it"
        )),
        None => output
            .drives_moved()
            .then(|| "HAL's drives do not stand at zero: HAL outlived an earlier edmd".into()),
    };
    Ok(Opened {
        output,
        gap: HalGap::new(pins.clone(), settings),
        inputs: HalInputs::new(pins, settings),
        distrust,
        ready: ReadySignal(c),
    })
}

/// Removes the component a dead edmd left (its record `owner`); `Ok(false)`: it was gone.
pub fn remove_left_component(
    settings: &HalSettings,
    owner: &owner::Owner,
) -> Result<bool, HalError> {
    if !crate::sys::process_running("rtapi_app") {
        return Ok(false);
    }
    let hal = Hal::load(&settings.library)?;
    // Joining under the dead one's name is refused, and maps HAL's memory here without a
    // component of this process's own, as `remove_dead` requires. If it is accepted, the
    // dead component is gone already.
    match hal.join(&owner.component) {
        Ok(_ours) => Ok(false),
        Err(_) => {
            let present = hal.name_of(owner.comp_id).as_deref() == Some(owner.component.as_str());
            hal.remove_dead(owner.comp_id, &owner.component)?;
            Ok(present)
        }
    }
}

/// Joins HAL as `settings.component`; a name held by a dead edmd is refused with the way out
/// (`edmd hal-reap`). With the joined component, the pid of a dead edmd that `edmd hal-reap`
/// removed before this one (its record is kept for this).
fn join(settings: &HalSettings) -> Result<(Arc<Component>, Option<u32>), HalError> {
    let hal = Hal::load(&settings.library)?;
    // A userspace component alone would make HAL's memory itself and call itself ready in a
    // HAL that nothing runs: no thread would ever read its pins.
    if !crate::sys::process_running("rtapi_app") {
        return Err(HalError::NotRunning);
    }
    let name = &settings.component;
    let record = owner::Owner::read(&settings.owner_file).filter(|o| &o.component == name);
    match hal.join(name) {
        // A record outlived its edmd: the one before this one ended without a clean stop.
        Ok(c) => Ok((c, record.filter(|o| !o.alive()).map(|o| o.pid))),
        Err(refused) => Err(match record {
            Some(held) if held.alive() => HalError::Taken {
                component: name.clone(),
                pid: held.pid,
            },
            Some(held) => HalError::LeftByDead {
                component: name.clone(),
                pid: held.pid,
            },
            None => refused,
        }),
    }
}
