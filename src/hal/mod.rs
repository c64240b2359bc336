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
//!  edmd.enable-out, spark-on, flush-on, condition, state ──► the drives and the generator
//!  edmd.gen.on-time-us, off-time-us, peak-current-a, open-voltage-v, servo-ref-v,
//!      wire-tension-n, wire-speed-m-min, flushing-bar ──► the generator's set points
//! ```
//!
//! **Set points.** The `edmd.gen.*` float pins carry what the condition in force sets the
//! generator to (`[generator] condition`, or the job's technology table), written when the
//! condition changes; 0 where the condition gives no value (and under no condition).
//!
//! **Units and frames.** Pins are in machine units (mm). `pos-cmd` is the pulse ledger: every
//! step edmd has given the axis since the component started, in mm, as LinuxCNC's
//! `motor-pos-cmd` is the joint position plus the offset homing set. It starts at 0 with the
//! component (as `stepgen`'s counts do) and never jumps: homing and offsets move edmd's idea of
//! where the machine is, never the drives. `pos-fb`, when `hal.max_following_error_mm` is set,
//! is the same motor position read back; a difference beyond it stops the job with an alarm
//! naming the axis (LinuxCNC's joint following error).
//!
//! **Timing.** edmd's tick runs free on its own thread (50 µs by default) and writes `pos-cmd`
//! every tick; HAL's servo thread reads it at its own period. A HAL thread cannot pace a
//! userspace component (its functions run in `rtapi_app`, not in edmd), and the tick core's
//! determinism does not depend on HAL: the lattice position is exact at every tick, and a
//! position-mode `stepgen` reaches it within a servo period and its own acceleration limits.
//! `BENCHMARKS.md` gives the measured lag.
//!
//! **Safety.** `estop-ok-in` is LinuxCNC's sense: false stops (so an unconnected pin stops the
//! machine: net it, or `setp` it true on a bench). Dropping the component first sets
//! `enable-out`, `spark-on` and `flush-on` false, then leaves HAL, which removes its pins.
//!
//! The library is loaded at run time (`hal/ffi.rs`); without LinuxCNC's HAL the component is
//! refused at startup with the package to install.

mod devices;
// The HAL library's calls: the module's only `unsafe`.
#[allow(unsafe_code)]
mod ffi;

use std::sync::Arc;

pub use devices::{HalGap, HalInputs, HalOutput};
use ffi::{BitPin, Component, Dir, Pin};

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
        "cannot join HAL as component {component:?} (hal_init returned {code}): is HAL running \
         (halrun, or linuxcnc) and is the name free? Start edmd from the HAL file with \
         `loadusr -W edmd serve …`"
    )]
    Init { component: String, code: i32 },
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

/// The component's three sides, sharing its pins.
pub struct Opened {
    pub output: HalOutput,
    pub gap: HalGap,
    pub inputs: HalInputs,
}

/// Joins the running HAL as `settings.component`, makes every pin and says it is ready.
pub fn open(settings: &HalSettings) -> Result<Opened, HalError> {
    let c = Component::new(&settings.library, &settings.component)?;
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
    };
    pins.make_safe();
    for a in &pins.axes {
        a.pos_cmd.set(0.0);
    }
    c.ready()?;
    tracing::info!(
        "HAL: component {} ready ({} pins)",
        c.name(),
        5 * pins.axes.len() + 11 + pins.generator.len()
    );
    let pins = Arc::new(pins);
    Ok(Opened {
        output: HalOutput::new(pins.clone(), settings),
        gap: HalGap::new(pins.clone(), settings),
        inputs: HalInputs::new(pins, settings),
    })
}
