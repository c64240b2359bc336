//! Wire-touch setup cycles (`edmd ctl find`): finding the part before a cut.
//!
//! A wire machine finds its work by touching it with the wire: the generator at its least
//! energy (`wire.touch_condition`) senses contact through the gap. A cycle is a sequence of
//! small jobs, each a probing program this module writes (`G38.3`, relative, in the touch
//! condition); the daemon runs each through the same pipeline as any program and hands back
//! where it ended and where it touched. This module is the arithmetic and the order of the
//! moves, and nothing else: no I/O, no clock, so every cycle is tested here move by move.
//!
//! One **touch** on a side (`X+`: moving towards +X):
//! 1. approach at `touch_feed_mm_per_min` until contact (at most `touch_search_mm`, and never
//!    past the soft limit);
//! 2. back off `touch_backoff_mm` and touch again at a tenth of the feed: the measurement;
//! 3. a retouch that finds nothing within twice the back-off means the first contact was
//!    false (a bounce): approach again, at most `touch_retries` times.
//!
//! The wire's centre is where it touched; the part's edge is a wire radius further on.
//!
//! - `edge X+`: one touch; the edge is the contact plus the radius; the wire backs off.
//! - `corner X+Y+`: the part lies towards +X and +Y. From the start (off the corner), move
//!   `touch_corner_clearance_mm` along +Y (past the corner), touch X+, back to the start; move
//!   the clearance along +X, touch Y+, back to the start. The corner is the two edges.
//! - `center` (the wire in a hole): touch X+ and X−, move to their middle; touch Y+ and Y−,
//!   move to their middle: one round. Rounds repeat until two agree within a step (the first
//!   round's X touches are a chord off the centre); the last round's touches, each through the
//!   centre, give the diameter on X and on Y.
//!
//! Every positioning move is itself a probing move: a wire that touches something on its way
//! stops, and the cycle fails there instead of dragging the wire across the part.

use crate::config::{Config, TouchConfig};

/// One way of touching: an axis of the program plane (0: X, 1: Y) and the direction of travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Side {
    pub axis: usize,
    pub positive: bool,
}

impl Side {
    pub const X_PLUS: Side = Side {
        axis: 0,
        positive: true,
    };
    pub const X_MINUS: Side = Side {
        axis: 0,
        positive: false,
    };
    pub const Y_PLUS: Side = Side {
        axis: 1,
        positive: true,
    };
    pub const Y_MINUS: Side = Side {
        axis: 1,
        positive: false,
    };

    fn sign(self) -> f64 {
        if self.positive { 1.0 } else { -1.0 }
    }

    fn letter(self) -> char {
        ['X', 'Y'][self.axis]
    }

    /// `X+`, `Y-`.
    pub fn name(self) -> String {
        format!("{}{}", self.letter(), if self.positive { '+' } else { '-' })
    }

    /// `X+`, `x-`, `Y+` … (the whole text).
    fn parse(text: &str) -> Option<Side> {
        let mut chars = text.chars();
        let axis = match chars.next()?.to_ascii_uppercase() {
            'X' => 0,
            'Y' => 1,
            _ => return None,
        };
        let positive = match chars.next()? {
            '+' => true,
            '-' => false,
            _ => return None,
        };
        chars.next().is_none().then_some(Side { axis, positive })
    }
}

/// What a cycle finds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// The part's face met moving this way.
    Edge(Side),
    /// The corner of the faces met moving these ways (an X side, then a Y side).
    Corner(Side, Side),
    /// The centre of the hole the wire stands in.
    Center,
}

/// A target that is not one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0:?} is not something to find: edge X+|X-|Y+|Y-, corner X+Y+|X+Y-|X-Y+|X-Y-, center")]
pub struct TargetError(pub String);

impl Target {
    /// `edge X+`, `corner X-Y+`, `center` (case and spacing free).
    pub fn parse(text: &str) -> Result<Target, TargetError> {
        let bad = || TargetError(text.to_string());
        let words: Vec<&str> = text.split_whitespace().collect();
        match words[..] {
            [w] if w.eq_ignore_ascii_case("center") || w.eq_ignore_ascii_case("centre") => {
                Ok(Target::Center)
            }
            [w, side] if w.eq_ignore_ascii_case("edge") => {
                Side::parse(side).map(Target::Edge).ok_or_else(bad)
            }
            [w, sides] if w.eq_ignore_ascii_case("corner") && sides.len() == 4 => {
                let (a, b) = sides.split_at(2);
                match (Side::parse(a), Side::parse(b)) {
                    (Some(x), Some(y)) if x.axis == 0 && y.axis == 1 => Ok(Target::Corner(x, y)),
                    (Some(y), Some(x)) if x.axis == 0 && y.axis == 1 => Ok(Target::Corner(x, y)),
                    _ => Err(bad()),
                }
            }
            _ => Err(bad()),
        }
    }

    /// `edge X+`, `corner X+Y-`, `center`.
    pub fn name(self) -> String {
        match self {
            Target::Edge(s) => format!("edge {}", s.name()),
            Target::Corner(x, y) => format!("corner {}{}", x.name(), y.name()),
            Target::Center => "center".to_string(),
        }
    }

    /// The plane axes whose coordinate the cycle finds (and a `--system` offset sets).
    pub fn axes(self) -> &'static [usize] {
        match self {
            Target::Edge(Side { axis: 0, .. }) => &[0],
            Target::Edge(_) => &[1],
            _ => &[0, 1],
        }
    }
}

/// Everything a cycle computes with: the touch settings, the wire, the steps and the soft
/// limits of X and Y.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FindSettings {
    pub touch: TouchConfig,
    pub wire_radius_mm: f64,
    /// Step sizes of X and Y, mm.
    pub step_mm: [f64; 2],
    /// Soft limits of X and Y (`None`: none).
    pub travel: [Option<[f64; 2]>; 2],
}

impl FindSettings {
    /// The settings of `config` for a machine whose X and Y are at `plane` in its axes.
    pub fn from_config(config: &Config, plane: [usize; 2]) -> FindSettings {
        let m = &config.machine;
        FindSettings {
            touch: config.wire.touch,
            wire_radius_mm: config.wire.diameter_mm / 2.0,
            step_mm: plane.map(|i| m.step_mm[i]),
            travel: plane.map(|i| m.travel[i].map(|t| [t.min_mm, t.max_mm])),
        }
    }
}

/// What a move is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MoveKind {
    /// The fast approach of a touch.
    Approach(Side),
    /// The back-off and slow retouch.
    Retouch(Side),
    /// Positioning (spark off, stopping at any contact), or only backing off a contact.
    Position,
}

/// One move of a cycle: a job of its own.
#[derive(Debug, Clone, PartialEq)]
pub struct Move {
    pub kind: MoveKind,
    /// The program (relative moves, mm, in the touch condition).
    pub program: String,
    /// The cycle's first approach (the one a simulated bounce disturbs).
    pub first: bool,
}

/// How a move's job ended: where the wire stands and where it touched (X, Y, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveEnd {
    pub at_mm: [f64; 2],
    /// Where the last probing move read contact; `None` when it read none.
    pub contact_mm: Option<[f64; 2]>,
}

/// What a cycle found.
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    pub target: Target,
    /// The part's edge (or corner, or the hole's centre) on X and Y, mm in machine
    /// coordinates; `None` on the axis an edge does not measure.
    pub point_mm: [Option<f64>; 2],
    /// The wire's centre where it touched (an edge, a corner) or the centre (a hole).
    pub wire_mm: [Option<f64>; 2],
    /// A hole's diameter measured on X and on Y (the last round's), mm.
    pub diameter_mm: Option<[f64; 2]>,
    pub touches: u32,
    /// Approaches made again after a false first contact.
    pub retries: u32,
    /// A hole's rounds.
    pub rounds: u32,
}

/// Why a cycle stops without a result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FindError {
    #[error("{side}: no contact within {mm:.3} mm")]
    NoContact { side: String, mm: f64 },
    #[error("{side}: no room to search (at the soft limit)")]
    NoRoom { side: String },
    #[error(
        "{side}: the retouch found nothing {tries} times (a false contact each time?): check \
         the wire, the flushing and the touch condition"
    )]
    Unsteady { side: String, tries: u32 },
    #[error("the wire touched something while positioning, at X{:.4} Y{:.4}", at[0], at[1])]
    Collided { at: [f64; 2] },
    #[error("the hole's centre did not settle within a step in {rounds} rounds")]
    Unsettled { rounds: u32 },
}

/// What the daemon does next.
#[derive(Debug, Clone, PartialEq)]
pub enum Next {
    Run(Move),
    Done(Found),
}

/// One task of a cycle's plan.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Task {
    Touch(Side),
    /// Move to the start, offset along an axis by this much (mm).
    GoFromStart([f64; 2]),
    /// Move to the middle of the last two touches on this axis.
    GoBetween(usize),
    /// Back off the contact the wire stands in.
    BackOff,
    /// A hole round ends: settle or go round again.
    EndRound,
}

/// Where a touch stands.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Touching {
    /// `distance`: how far it searches (mm).
    Approaching {
        side: Side,
        tries: u32,
        distance: f64,
    },
    Retouching {
        side: Side,
        tries: u32,
    },
}

/// A cycle in progress.
#[derive(Debug, Clone)]
pub struct FindCycle {
    target: Target,
    s: FindSettings,
    start: [f64; 2],
    at: [f64; 2],
    /// The wire stands in contact on this side: the next move backs off first.
    in_contact: Option<Side>,
    tasks: std::collections::VecDeque<Task>,
    touching: Option<Touching>,
    /// Where a move in hand goes (a positioning move's target).
    expect_position: bool,
    /// Touches so far: the side and the wire centre's coordinate on its axis.
    touched: Vec<(Side, f64)>,
    centres: Vec<[f64; 2]>,
    retries: u32,
    first_sent: bool,
}

impl FindCycle {
    /// A cycle for `target`, the wire standing at `at_mm` (X, Y machine coordinates).
    pub fn new(target: Target, s: FindSettings, at_mm: [f64; 2]) -> FindCycle {
        let c = s.touch.corner_clearance_mm;
        let tasks = match target {
            Target::Edge(side) => vec![Task::Touch(side), Task::BackOff],
            Target::Corner(x, y) => vec![
                Task::GoFromStart([0.0, y.sign() * c]),
                Task::Touch(x),
                Task::GoFromStart([0.0, 0.0]),
                Task::GoFromStart([x.sign() * c, 0.0]),
                Task::Touch(y),
                Task::GoFromStart([0.0, 0.0]),
            ],
            Target::Center => round(),
        };
        FindCycle {
            target,
            s,
            start: at_mm,
            at: at_mm,
            in_contact: None,
            tasks: tasks.into(),
            touching: None,
            expect_position: false,
            touched: Vec::new(),
            centres: Vec::new(),
            retries: 0,
            first_sent: false,
        }
    }

    pub fn target(&self) -> Target {
        self.target
    }

    /// The first move.
    pub fn begin(&mut self) -> Result<Next, FindError> {
        self.advance()
    }

    /// The move in hand ended as `end`: the next move, or the result.
    pub fn moved(&mut self, end: MoveEnd) -> Result<Next, FindError> {
        self.at = end.at_mm;
        if let Some(t) = self.touching.take() {
            return self.touch_ended(t, end);
        }
        if std::mem::take(&mut self.expect_position) {
            if end.contact_mm.is_some() {
                return Err(FindError::Collided { at: end.at_mm });
            }
            self.in_contact = None;
        }
        self.advance()
    }

    fn touch_ended(&mut self, t: Touching, end: MoveEnd) -> Result<Next, FindError> {
        match (t, end.contact_mm) {
            (Touching::Approaching { side, tries, .. }, Some(_)) => {
                self.in_contact = Some(side);
                self.touching = Some(Touching::Retouching { side, tries });
                Ok(Next::Run(self.retouch(side)))
            }
            (Touching::Approaching { side, distance, .. }, None) => Err(FindError::NoContact {
                side: side.name(),
                mm: distance,
            }),
            (Touching::Retouching { side, .. }, Some(p)) => {
                self.in_contact = Some(side);
                self.touched.push((side, p[side.axis]));
                self.advance()
            }
            (Touching::Retouching { side, tries }, None) => {
                // The first contact was false: nothing where it was.
                self.in_contact = None;
                if tries >= self.s.touch.retries {
                    return Err(FindError::Unsteady {
                        side: side.name(),
                        tries: tries + 1,
                    });
                }
                self.retries += 1;
                self.approach(side, tries + 1)
            }
        }
    }

    /// The next task's move (tasks that need none are done on the way).
    fn advance(&mut self) -> Result<Next, FindError> {
        while let Some(task) = self.tasks.pop_front() {
            let target = match task {
                Task::Touch(side) => return self.approach(side, 0),
                Task::BackOff => {
                    if self.in_contact.is_none() {
                        continue;
                    }
                    self.back_off().1
                }
                Task::GoFromStart(d) => [self.start[0] + d[0], self.start[1] + d[1]],
                Task::GoBetween(axis) => {
                    let mut to = self.at;
                    to[axis] = self.middle(axis);
                    to
                }
                Task::EndRound => {
                    if let Some(done) = self.end_round()? {
                        return Ok(Next::Done(done));
                    }
                    continue;
                }
            };
            let Some(the_move) = self.position(target) else {
                continue;
            };
            self.expect_position = true;
            return Ok(Next::Run(the_move));
        }
        Ok(Next::Done(self.found()))
    }

    /// The middle of the last touches on each side of `axis`.
    fn middle(&self, axis: usize) -> f64 {
        let last = |positive: bool| {
            self.touched
                .iter()
                .rev()
                .find(|(s, _)| s.axis == axis && s.positive == positive)
                .map_or(self.at[axis], |&(_, v)| v)
        };
        (last(true) + last(false)) / 2.0
    }

    /// A hole round ended: the centre, and whether it settled.
    fn end_round(&mut self) -> Result<Option<Found>, FindError> {
        let centre = [self.middle(0), self.middle(1)];
        self.centres.push(centre);
        let rounds = self.centres.len();
        if rounds >= 2 {
            let before = self.centres[rounds - 2];
            if (0..2).all(|i| (centre[i] - before[i]).abs() <= self.s.step_mm[i] * 1.000_001) {
                return Ok(Some(self.found()));
            }
        }
        if rounds as u32 >= self.s.touch.center_rounds {
            return Err(FindError::Unsettled {
                rounds: rounds as u32,
            });
        }
        self.tasks.extend(round());
        Ok(None)
    }

    /// The result, from the touches.
    fn found(&self) -> Found {
        let r = self.s.wire_radius_mm;
        let last = |side: Side| {
            self.touched
                .iter()
                .rev()
                .find(|(s, _)| *s == side)
                .map(|&(_, v)| v)
        };
        let mut point_mm = [None; 2];
        let mut wire_mm = [None; 2];
        let mut diameter_mm = None;
        let sides = match self.target {
            Target::Edge(side) => [Some(side), None],
            Target::Corner(x, y) => [Some(x), Some(y)],
            Target::Center => [None, None],
        };
        for side in sides.into_iter().flatten() {
            wire_mm[side.axis] = last(side);
            point_mm[side.axis] = last(side).map(|v| v + side.sign() * r);
        }
        match self.target {
            Target::Edge(_) | Target::Corner(..) => {}
            Target::Center => {
                let centre = self.centres.last().copied().unwrap_or(self.at);
                point_mm = centre.map(Some);
                wire_mm = point_mm;
                let across = |axis: usize| {
                    let plus = last(Side {
                        axis,
                        positive: true,
                    });
                    let minus = last(Side {
                        axis,
                        positive: false,
                    });
                    plus.zip(minus).map_or(0.0, |(p, m)| p - m + 2.0 * r)
                };
                diameter_mm = Some([across(0), across(1)]);
            }
        }
        Found {
            target: self.target,
            point_mm,
            wire_mm,
            diameter_mm,
            touches: self.touched.len() as u32,
            retries: self.retries,
            rounds: self.centres.len() as u32,
        }
    }

    // ---- the programs ------------------------------------------------------------------

    /// `G0` off the contact the wire stands in (empty when it stands in none), and where
    /// that leaves it.
    fn back_off(&self) -> (String, [f64; 2]) {
        match self.in_contact {
            None => (String::new(), self.at),
            Some(side) => {
                let d = -side.sign() * self.s.touch.backoff_mm;
                let mut to = self.at;
                to[side.axis] += d;
                (format!("G0 {}{} (back off)\n", side.letter(), num(d)), to)
            }
        }
    }

    fn head(&self) -> String {
        format!(
            "G21 G91 E{} (find {}: wire touch, spark off)\n",
            self.s.touch.condition,
            self.target.name()
        )
    }

    fn approach(&mut self, side: Side, tries: u32) -> Result<Next, FindError> {
        let (back, from) = self.back_off();
        let room =
            crate::machine::travel::room(self.s.travel[side.axis], from[side.axis], side.positive);
        let distance = self.s.touch.search_mm.min(room);
        if distance < self.s.step_mm[side.axis] {
            return Err(FindError::NoRoom { side: side.name() });
        }
        let program = format!(
            "{}{back}G38.3 {}{} F{} (approach {})\nM2\n",
            self.head(),
            side.letter(),
            num(side.sign() * distance),
            num(self.s.touch.feed_mm_per_min),
            side.name()
        );
        self.touching = Some(Touching::Approaching {
            side,
            tries,
            distance,
        });
        let first = !self.first_sent;
        self.first_sent = true;
        Ok(Next::Run(Move {
            kind: MoveKind::Approach(side),
            program,
            first,
        }))
    }

    fn retouch(&self, side: Side) -> Move {
        let (back, _) = self.back_off();
        let b = self.s.touch.backoff_mm;
        Move {
            kind: MoveKind::Retouch(side),
            program: format!(
                "{}{back}G38.3 {}{} F{} (retouch {} at a tenth of the feed)\nM2\n",
                self.head(),
                side.letter(),
                num(side.sign() * 2.0 * b),
                num(self.s.touch.feed_mm_per_min / 10.0),
                side.name()
            ),
            first: false,
        }
    }

    /// Back off (if in contact), then a probing move to `to` (if it is elsewhere); `None`
    /// when there is nothing to do.
    fn position(&self, to: [f64; 2]) -> Option<Move> {
        let (back, from) = self.back_off();
        let d = [to[0] - from[0], to[1] - from[1]];
        let still = (0..2).all(|i| d[i].abs() < self.s.step_mm[i] / 2.0);
        let go = if still {
            if back.is_empty() {
                return None;
            }
            String::new()
        } else {
            format!(
                "G38.3 X{} Y{} F{} (position)\n",
                num(d[0]),
                num(d[1]),
                num(self.s.touch.feed_mm_per_min)
            )
        };
        Some(Move {
            kind: MoveKind::Position,
            program: format!("{}{back}{go}M2\n", self.head()),
            first: false,
        })
    }
}

/// One round of a hole-centre cycle.
fn round() -> Vec<Task> {
    vec![
        Task::Touch(Side::X_PLUS),
        Task::Touch(Side::X_MINUS),
        Task::GoBetween(0),
        Task::Touch(Side::Y_PLUS),
        Task::Touch(Side::Y_MINUS),
        Task::GoBetween(1),
        Task::EndRound,
    ]
}

/// A program number: mm to a nanometre, no trailing zeros.
fn num(v: f64) -> String {
    let text = format!("{v:.6}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".to_string()
    } else {
        text.to_string()
    }
}

#[cfg(test)]
mod tests;
