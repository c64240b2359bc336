//! Corner control: a lower feed ceiling around sharp corners of a cut.
//!
//! In a rough wire cut the wire bows behind the guides under the spark pressure, so at a sharp
//! corner it cuts inside the programmed corner and rounds it. Wire controls slow down around
//! such corners (and may pause in them) so the wire straightens before it turns. Which corners,
//! how slow and how far depend on the condition, so the rules are per condition
//! (`[[generator.condition]]`'s `corner_angle_deg`, `corner_feed_factor`, `corner_distance_mm`,
//! `corner_dwell_ms`).
//!
//! ```text
//!  Segmenter ──► CornerControl (holds the last `distance` of path) ──► Planner
//!                  corner found at a piece start: the held segments within `distance`
//!                  before it and the next ones within `distance` after it get their feed
//!                  ceiling × factor; a dwell makes the path stop at the corner
//! ```
//!
//! A corner is a junction between pieces (blocks, or a curve's corner knots) whose included
//! angle is below `corner_angle_deg` (a straight continuation is 180°, a square corner 90°),
//! measured between the chords that meet there. Only cuts count: rapids, probing moves and a
//! run-from-line's approach have no corner control. Memory is the path held: `distance` of it,
//! so bounded by the longest rule's distance over the shortest segment.

use std::collections::VecDeque;

use super::GeoSegment;
use crate::gcode::BlockKind;
use crate::geometry::Point;

/// One condition's corner rule, as the preprocessor uses it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerRule {
    /// The condition (`E<number>`) it applies to.
    pub condition: u32,
    /// A corner turns the path by more than this (radians): π − the included angle.
    pub min_turn: f64,
    /// The feed ceiling around the corner, as a fraction of the segment's own (0, 1].
    pub feed_factor: f64,
    /// How far before and after the corner (mm of path).
    pub distance: f64,
    /// A stop at the corner for this long (s); 0: none.
    pub dwell_s: f64,
}

/// A held segment and the lowest corner factor that reaches it.
#[derive(Debug)]
struct Held {
    geo: GeoSegment,
    factor: f64,
}

/// The corner-control stage between the segmenter and the planner.
#[derive(Debug)]
pub struct CornerControl {
    rules: Vec<CornerRule>,
    /// The longest distance of any rule: how much path is held.
    reach: f64,
    held: VecDeque<Held>,
    held_mm: f64,
    /// The direction of the last cut segment pushed, and the condition it ran in.
    last: Option<(Point, u32)>,
    /// Path left in the zone after the last corner (mm) and its factor.
    after: (f64, f64),
    /// Corners found (for the preprocessor's statistics and tests).
    pub corners: u64,
}

impl CornerControl {
    pub fn new(rules: Vec<CornerRule>) -> CornerControl {
        let reach = rules.iter().map(|r| r.distance).fold(0.0, f64::max);
        CornerControl {
            rules,
            reach,
            held: VecDeque::new(),
            held_mm: 0.0,
            last: None,
            after: (0.0, 1.0),
            corners: 0,
        }
    }

    /// No rules: the stage passes segments straight through.
    pub fn is_off(&self) -> bool {
        self.rules.is_empty()
    }

    /// Takes the next segment; hands on those no corner ahead can reach any more.
    pub fn push<F: FnMut(GeoSegment)>(&mut self, mut geo: GeoSegment, mut emit: F) {
        let cut = geo.block.spark_off.is_none()
            && matches!(
                geo.block.kind,
                BlockKind::Line | BlockKind::Arc { .. } | BlockKind::Nurbs { .. }
            );
        let direction = (geo.end - geo.start).normalize();
        let mut factor = 1.0;
        if !cut || !direction.iter().all(|c| c.is_finite()) {
            self.last = None;
            self.after = (0.0, 1.0);
        } else {
            if geo.first_of_piece
                && let Some((incoming, condition)) = self.last
                && let Some(rule) = self.rule(geo.block.condition).or(self.rule(condition))
                && incoming.dot(&direction).clamp(-1.0, 1.0).acos() > rule.min_turn
            {
                self.corners += 1;
                self.slow_before(rule.distance, rule.feed_factor);
                self.after = (rule.distance, rule.feed_factor);
                if rule.dwell_s > 0.0 {
                    geo.corner_dwell_s = rule.dwell_s;
                    geo.entry_limit = 0.0;
                }
            }
            if self.after.0 > 0.0 {
                factor = self.after.1;
                self.after.0 -= geo.arc;
            }
            self.last = Some((direction, geo.block.condition));
        }
        self.held_mm += geo.arc;
        self.held.push_back(Held { geo, factor });
        while self
            .held
            .front()
            .is_some_and(|h| self.held_mm - h.geo.arc >= self.reach)
        {
            self.release(&mut emit);
        }
    }

    /// End of the program: everything held goes on.
    pub fn finish<F: FnMut(GeoSegment)>(&mut self, mut emit: F) {
        while !self.held.is_empty() {
            self.release(&mut emit);
        }
        self.last = None;
        self.after = (0.0, 1.0);
    }

    fn rule(&self, condition: u32) -> Option<CornerRule> {
        self.rules
            .iter()
            .copied()
            .find(|r| r.condition == condition)
    }

    /// The held segments within `distance` before the corner (the back of the queue) get
    /// `factor`; the segment that reaches into the zone counts whole.
    fn slow_before(&mut self, distance: f64, factor: f64) {
        let mut covered = 0.0;
        for held in self.held.iter_mut().rev() {
            if covered >= distance {
                break;
            }
            held.factor = held.factor.min(factor);
            covered += held.geo.arc;
        }
    }

    fn release<F: FnMut(GeoSegment)>(&mut self, emit: &mut F) {
        if let Some(Held { mut geo, factor }) = self.held.pop_front() {
            self.held_mm -= geo.arc;
            if factor < 1.0 {
                geo.feed_limit *= factor;
                geo.speed_limit *= factor;
            }
            emit(geo);
        }
    }
}
