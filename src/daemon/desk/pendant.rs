//! The pendant: a continuous jog's button as the operator holds it. Pressed, it starts a jog;
//! pressed again within [`DEAD_MAN`] it renews it; silence stops it (a closed browser tab, a
//! lost connection). A jog that stopped while the button was still held (a hold, its
//! dead-man, a trip, its end) is latched: the same button's renewals are refused until it is
//! let go (a pause longer than [`DEAD_MAN`], or `jog-stop`), so a client that keeps pressing
//! through a trip does not start it again once the trip is cleared.
//!
//! Times are monotonic nanoseconds handed in by the control loop; the job's thread holds a
//! jog at the same deadline ([`crate::runtime::Published`]).

use super::manual::DEAD_MAN;

fn dead_man_ns() -> u64 {
    DEAD_MAN.as_nanos() as u64
}

/// A continuous jog: its axis and direction, and when it stops unless renewed.
struct Moving {
    axis: usize,
    positive: bool,
    deadline_ns: u64,
}

/// A continuous jog that stopped while its button was held, and when it was last pressed.
struct Latched {
    axis: usize,
    positive: bool,
    last_ns: u64,
}

/// The continuous jog in progress (being checked or moving) and the latched one.
#[derive(Default)]
pub(in crate::daemon) struct Pendant {
    moving: Option<Moving>,
    latched: Option<Latched>,
}

/// What a press of a jog button is.
#[derive(Debug, PartialEq, Eq)]
pub(in crate::daemon) enum Press {
    /// The latched jog's button, still held: refused.
    Latched,
    /// The moving jog's button, but its job stopped it: it is to be latched and refused.
    StoppedInJob,
    /// The moving jog's button: it moves on until this deadline.
    Renewed { deadline_ns: u64 },
    /// Another button while a jog moves: refused.
    Busy { axis: usize, positive: bool },
    /// No jog: a new one may start.
    New,
}

/// What letting go of the button (`jog-stop`) is.
#[derive(Debug, PartialEq, Eq)]
pub(in crate::daemon) enum LetGo {
    /// A jog moves: it is to brake to a standstill.
    Stop,
    /// The latched jog's button let go; nothing moves.
    AlreadyStopped,
    /// Nothing to let go.
    Nothing,
}

impl Pendant {
    /// The button of `axis` and direction pressed at `now`; `stopped_in_job`: the moving jog's
    /// job was held or its dead-man tripped.
    pub fn press(&mut self, axis: usize, positive: bool, now: u64, stopped_in_job: bool) -> Press {
        if let Some(latched) = &mut self.latched {
            if latched.axis == axis
                && latched.positive == positive
                && now.saturating_sub(latched.last_ns) <= dead_man_ns()
            {
                latched.last_ns = now;
                return Press::Latched;
            }
            self.latched = None;
        }
        match &mut self.moving {
            Some(m) if m.axis == axis && m.positive == positive => {
                if stopped_in_job {
                    return Press::StoppedInJob;
                }
                m.deadline_ns = now + dead_man_ns();
                Press::Renewed {
                    deadline_ns: m.deadline_ns,
                }
            }
            Some(m) => Press::Busy {
                axis: m.axis,
                positive: m.positive,
            },
            None => Press::New,
        }
    }

    /// A new jog was launched at `now`: it moves until [`DEAD_MAN`] from now unless renewed.
    pub fn started(&mut self, axis: usize, positive: bool, now: u64) {
        self.moving = Some(Moving {
            axis,
            positive,
            deadline_ns: now + dead_man_ns(),
        });
    }

    /// `jog-stop`: the operator let go; the next press starts a new jog.
    pub fn let_go(&mut self) -> LetGo {
        let latched = self.latched.take().is_some();
        match (self.moving.is_some(), latched) {
            (true, _) => LetGo::Stop,
            (false, true) => LetGo::AlreadyStopped,
            (false, false) => LetGo::Nothing,
        }
    }

    /// The moving jog ends at `now`; `latch`: its button's renewals that follow are refused.
    /// False when no jog was moving.
    pub fn stop(&mut self, latch: bool, now: u64) -> bool {
        let Some(m) = self.moving.take() else {
            return false;
        };
        if latch {
            self.latched = Some(Latched {
                axis: m.axis,
                positive: m.positive,
                last_ns: now,
            });
        }
        true
    }

    /// The moving jog's dead-man fell due at `now` (or its job's thread held it already).
    pub fn dead_man_due(&self, now: u64, held_by_job: bool) -> bool {
        self.moving
            .as_ref()
            .is_some_and(|m| now >= m.deadline_ns || held_by_job)
    }

    /// When the moving jog stops unless renewed.
    pub fn deadline_ns(&self) -> Option<u64> {
        self.moving.as_ref().map(|m| m.deadline_ns)
    }

    /// A jog is moving (or being checked).
    pub fn is_moving(&self) -> bool {
        self.moving.is_some()
    }
}
