//! NURBS curves in the three dialects, collected over several lines until they close:
//!
//! - `G38 O<degree> C<count> X Y [W] [K]` (seed 000): the header names the degree and the
//!   number of control points; knots are clamped uniform on [0, 1] unless every line
//!   carries `K`;
//! - `G06.2 P<order> K<knot> X Y [R<weight>]` (Fanuc): a knot on every point line, closed by
//!   as many knot-only `K` lines as the order (LinuxCNC's `Q` ignored);
//! - `G5.2 [X Y] [P<weight>] [L<order>]` … `G5.3` (LinuxCNC): the current position is the
//!   first control point, order 3 unless `L` says otherwise, knots clamped uniform in whole
//!   numbers.
//!
//! A curve in progress is a [`PendingCurve`]; anything else on its lines (another motion,
//! an unknown word, a decreasing knot) is an error naming the line where the curve began.

use super::axes::MachineAxes;
use super::codes::{GCode, classify_g, g_code_tenths};
use super::state::{BlockEnv, InterpState};
use super::{CURVE_START_TOLERANCE_MM, Fail, Letters, MAX_CURVE_POINTS, Step, first_col, whole};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind, NurbsForm};
use crate::geometry::{MAX_DEGREE, NurbsCurve, NurbsError, Point};

/// A NURBS curve being collected over several lines.
pub(super) struct PendingCurve {
    pub(super) form: NurbsForm,
    pub(super) start_line: u64,
    pub(super) start_col: usize,
    pub(super) start_text: String,
    pub(super) degree: usize,
    /// G38's `C`: how many control points the header announced.
    pub(super) announced_points: Option<usize>,
    pub(super) points: Vec<Point>,
    pub(super) weights: Vec<f64>,
    /// The smallest and largest weight so far.
    pub(super) weight_range: (f64, f64),
    /// Knots as given (G06.2 always; G38 when its lines carry K).
    pub(super) knots: Vec<f64>,
    pub(super) knots_given: bool,
    /// Knot-only blocks seen so far (the closing knots).
    pub(super) closing_knots: usize,
    pub(super) feed: Option<f64>,
}

/// Largest ratio between a curve's largest and smallest weight. Beyond it double precision
/// no longer resolves the curve: at 10^6 its measured length is off by 0.2 %, at 10^8 by
/// 38 % (a quadratic whose middle weight grows, against dense sampling); CAM weights stay
/// within a few tens of each other (seed 001's curve: 1 and 10).
pub const MAX_WEIGHT_RATIO: f64 = 1.0e4;

impl PendingCurve {
    pub(super) fn order(&self) -> usize {
        self.degree + 1
    }

    /// Adds a control point's weight (written as `word`, if written), refusing one that
    /// takes the curve's weights further apart than [`MAX_WEIGHT_RATIO`].
    pub(super) fn push_weight(&mut self, w: f64, word: Option<&Word>) -> Step<()> {
        let (lo, hi) = (self.weight_range.0.min(w), self.weight_range.1.max(w));
        if hi > lo * MAX_WEIGHT_RATIO {
            let col = word.map_or(self.start_col, |w| w.col);
            return Err((
                col,
                GcodeErrorKind::WeightRatio {
                    weight: w,
                    low: lo,
                    high: hi,
                    max: MAX_WEIGHT_RATIO,
                },
            )
                .into());
        }
        self.weights.push(w);
        self.weight_range = (lo, hi);
        Ok(())
    }

    pub(super) fn interrupted(&self, by: String, hint: &'static str) -> GcodeErrorKind {
        if self.closing_knots > 0 || (self.knots_given && self.form == NurbsForm::G38) {
            let need = self.points.len() + self.order();
            return GcodeErrorKind::KnotCount(format!(
                "the {} curve started at line {} has {} control points of order {} and needs {need} knots; {} were given before {by}",
                self.form.name(),
                self.start_line,
                self.points.len(),
                self.order(),
                self.knots.len()
            ));
        }
        GcodeErrorKind::NurbsInterrupted {
            form: self.form,
            start_line: self.start_line,
            by: by.into(),
            hint,
        }
    }

    pub(super) fn close_hint(&self) -> &'static str {
        match self.form {
            NurbsForm::LinuxCnc => " (close it with G5.3)",
            NurbsForm::Fanuc => " (it ends after as many knot-only K blocks as its order P)",
            NurbsForm::G38 => " (it ends after the number of points given by C)",
        }
    }
}

impl PendingCurve {
    /// The curve a `G38`, `G06.2` or `G5.2` block opens at `state`'s position, with the
    /// block's control point (if it gives one) in it.
    pub(super) fn open(
        state: &InterpState,
        env: &mut BlockEnv,
        form: NurbsForm,
        text: &str,
        g_word: &Word,
        letters: &Letters,
    ) -> Step<PendingCurve> {
        let feed = env.feed_limit(state, g_word.col);
        let (degree, low_order) = opening_degree(form, g_word, letters)?;
        if let Some((col, message)) = low_order {
            env.warn_once("G5.2 order", col, message);
        }
        let mut curve = PendingCurve {
            form,
            start_line: env.line.line_no,
            start_col: g_word.col,
            start_text: text.to_string(),
            degree,
            announced_points: None,
            points: Vec::new(),
            weights: Vec::new(),
            weight_range: (f64::INFINITY, 0.0),
            knots: Vec::new(),
            knots_given: false,
            closing_knots: 0,
            feed,
        };
        if form == NurbsForm::G38 {
            let c = letters.get('C').ok_or((
                g_word.col,
                GcodeErrorKind::MissingCoordinate {
                    what: "the first G38 block needs C<number of control points>".into(),
                },
            ))?;
            let count = whole(c, 2.0, MAX_CURVE_POINTS as f64)? as usize;
            if count < degree + 1 {
                return Err((
                    c.col,
                    NurbsError::TooFewPoints {
                        points: count,
                        degree,
                    }
                    .into(),
                )
                    .into());
            }
            curve.announced_points = Some(count);
            curve.knots_given = letters.get('K').is_some();
        }
        if form == NurbsForm::LinuxCnc {
            // The current position is the first control point; a G5.2 without axis words only
            // sets that point's weight.
            let (_, any) = env.target(state, &state.position, letters, &off_plane(env.axes))?;
            let p0_weight = if any { 1.0 } else { weight(letters.get('P'))? };
            curve.points.push(state.position);
            curve.push_weight(p0_weight, letters.get('P'))?;
            if any {
                curve.add_point(state, env, letters, g_word.col)?;
            }
        } else {
            let first = curve.add_point(state, env, letters, g_word.col)?;
            let gap = (first - state.position).norm();
            if gap > CURVE_START_TOLERANCE_MM {
                return Err((
                    g_word.col,
                    GcodeErrorKind::NurbsStartMismatch {
                        first: format_point(env.axes, state.scale(), &first),
                        current: format_point(env.axes, state.scale(), &state.position),
                    },
                )
                    .into());
            }
            // Within tolerance: start exactly where the tool is, so no step is lost or invented.
            curve.points[0] = state.position;
        }
        Ok(curve)
    }

    /// Adds the block's control point (and its weight and knot); returns the point.
    ///
    /// `G5.2` points follow LinuxCNC (interp_convert.cc, `convert_nurbs`): under `G91` each is
    /// relative to the curve's start point, not to the previous point, and only X and Y are
    /// part of the curve (other axis words are ignored; the curve stays at its start's other
    /// coordinates). Each is warned about once where a program relies on it.
    fn add_point(
        &mut self,
        state: &InterpState,
        env: &mut BlockEnv,
        letters: &Letters,
        col: usize,
    ) -> Step<Point> {
        if self.points.len() >= MAX_CURVE_POINTS {
            return Err((
                col,
                GcodeErrorKind::TooManyPoints {
                    limit: MAX_CURVE_POINTS,
                },
            )
                .into());
        }
        let linuxcnc = self.form == NurbsForm::LinuxCnc;
        let base = match self.points.first() {
            Some(&start) if linuxcnc => start,
            _ => self.points.last().copied().unwrap_or(state.position),
        };
        // G38's first line uses C for the point count, even on a machine with a C axis; a G5.2
        // curve takes X and Y only.
        let reserved: String = if self.form == NurbsForm::G38 && self.points.is_empty() {
            "C".into()
        } else if linuxcnc {
            off_plane(env.axes)
        } else {
            String::new()
        };
        if linuxcnc {
            // LinuxCNC 2.9 takes a point only with both X and Y (whatever the plane: a
            // curve in G18 written with X Z is refused, not flattened), and every line after
            // the G5.2 with its weight.
            if letters.get('X').is_none() || letters.get('Y').is_none() {
                return Err((
                    col,
                    GcodeErrorKind::MissingCoordinate {
                        what: "a G5.2 control point needs both X and Y, as in LinuxCNC (the \
                               curve lies in the XY plane whatever G17/G18/G19 says)"
                            .into(),
                    },
                )
                    .into());
            }
            if env.line.line_no != self.start_line && letters.get('P').is_none() {
                return Err((
                    col,
                    GcodeErrorKind::MissingCoordinate {
                        what: "a G5.2 control point after the first line needs its weight P, \
                               as in LinuxCNC"
                            .into(),
                    },
                )
                    .into());
            }
        }
        if linuxcnc {
            if let Some(w) = reserved.chars().find_map(|l| letters.get(l)) {
                env.warn_once(
                    "G5.2 plane",
                    w.col,
                    format!(
                        "{}{}: a G5.2 curve moves X and Y only, as in LinuxCNC; the word is ignored",
                        w.letter, w.text
                    ),
                );
            }
            if state.modal.incremental && self.points.len() >= 2 {
                env.warn_once(
                    "G5.2 incremental",
                    col,
                    "G5.2 under G91: every control point is relative to the curve's start point, \
                     not to the previous point, as in LinuxCNC"
                        .to_string(),
                );
            }
        }
        let (p, any) = env.target(state, &base, letters, &reserved)?;
        if !any {
            return Err((
                col,
                GcodeErrorKind::MissingCoordinate {
                    what: format!("{} control point without axis words", self.form.name()),
                },
            )
                .into());
        }
        let w = weight(letters.get(self.form.weight_letter()))?;
        if self.form == NurbsForm::Fanuc || self.knots_given {
            push_knot(self, letters, col)?;
        } else if let Some(k) = letters.get('K') {
            return Err((
                k.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: 'K',
                    context: "here: the first G38 block gave no knots, so none may follow".into(),
                },
            )
                .into());
        }
        self.points.push(p);
        self.push_weight(w, letters.get(self.form.weight_letter()))?;
        Ok(p)
    }

    /// Takes one line of an open curve; `true` when the curve is complete.
    pub(super) fn take_line(
        &mut self,
        state: &InterpState,
        env: &mut BlockEnv,
        letters: &Letters,
        words: &[Word],
    ) -> Step<bool> {
        // Anything but the curve's own G word interrupts it.
        let mut own_g = false;
        for w in words.iter().filter(|w| matches!(w.letter, 'G' | 'M')) {
            let by = format!("{}{}", w.letter, w.text);
            if w.letter == 'G' {
                let code = classify_g(g_code_tenths(w)?, w.col)?;
                match (self.form, code) {
                    (NurbsForm::G38, GCode::Curve(NurbsForm::G38))
                    | (NurbsForm::Fanuc, GCode::Curve(NurbsForm::Fanuc)) => {
                        own_g = true;
                        continue;
                    }
                    (NurbsForm::LinuxCnc, GCode::CurveEnd) => {
                        if let Some(other) = letters.present().find(|o| !"GN".contains(o.letter)) {
                            return Err((
                                other.col,
                                GcodeErrorKind::UnexpectedWord {
                                    letter: other.letter,
                                    context: "with G5.3 (it only closes the curve)".into(),
                                },
                            )
                                .into());
                        }
                        return Ok(true);
                    }
                    _ => {}
                }
            }
            return Err((w.col, self.interrupted(by, self.close_hint())).into());
        }
        if self.form == NurbsForm::G38 && !own_g {
            return Err((
                first_col(words),
                GcodeErrorKind::NurbsInterrupted {
                    form: NurbsForm::G38,
                    start_line: self.start_line,
                    by: "a block without G38".into(),
                    hint: " (every control point line starts with G38)",
                },
            )
                .into());
        }
        env.axes.check_letters(
            letters,
            true,
            curve_letters(self.form, false),
            self.form.inside_name(),
        )?;
        let col = first_col(words);
        let has_axis = env.axes.first_word(letters)?.is_some();
        match self.form {
            NurbsForm::LinuxCnc => {
                self.add_point(state, env, letters, col)?;
                Ok(false)
            }
            NurbsForm::G38 => {
                let announced = self.announced_points.unwrap_or(0);
                if self.points.len() < announced {
                    self.add_point(state, env, letters, col)?;
                    return Ok(self.points.len() == announced && !self.knots_given);
                }
                self.closing_knot(letters, has_axis, col)
            }
            NurbsForm::Fanuc => {
                if has_axis || letters.get('R').is_some() {
                    if self.closing_knots > 0 {
                        return Err((
                            col,
                            GcodeErrorKind::PointAfterClosingKnots {
                                form: self.form.name(),
                            },
                        )
                            .into());
                    }
                    self.add_point(state, env, letters, col)?;
                    return Ok(false);
                }
                self.closing_knot(letters, has_axis, col)
            }
        }
    }

    /// A knot-only block; `true` once all `order` closing knots are in.
    fn closing_knot(&mut self, letters: &Letters, has_axis: bool, col: usize) -> Step<bool> {
        if has_axis {
            return Err((
                col,
                GcodeErrorKind::PointAfterClosingKnots {
                    form: self.form.name(),
                },
            )
                .into());
        }
        push_knot(self, letters, col)?;
        self.closing_knots += 1;
        Ok(self.closing_knots == self.order())
    }

    /// The curve's block, once its last line is in; `state` moves to its end.
    pub(super) fn close(self, state: &mut InterpState, axes: &MachineAxes) -> Step<Block> {
        let curve = self;
        let knots = if curve.form == NurbsForm::Fanuc || curve.knots_given {
            curve.knots
        } else {
            clamped_uniform_knots(curve.points.len(), curve.degree, curve.form)
        };
        let at = |kind: GcodeErrorKind| Fail {
            col: curve.start_col,
            kind,
            at: Some((curve.start_line, curve.start_text.clone())),
        };
        let nurbs = NurbsCurve::new(
            curve.degree,
            axes.len(),
            &curve.points,
            &curve.weights,
            knots,
        )
        .map_err(|e| at(e.into()))?;
        state.position = nurbs.end_point();
        state.modal.motion = None;
        Ok(state.block(
            curve.start_line,
            BlockKind::Nurbs { form: curve.form },
            nurbs,
            curve.feed,
        ))
    }
}

/// `p` in program units, as `X1.0000 Y2.0000`, for a message.
fn format_point(axes: &MachineAxes, scale: f64, p: &Point) -> String {
    let parts: Vec<String> = axes
        .iter()
        .enumerate()
        .map(|(i, a)| format!("{a}{:.4}", p[i] / scale))
        .collect();
    parts.join(" ")
}

/// The machine's axis letters a `G5.2` curve does not move: all but X and Y.
fn off_plane(axes: &MachineAxes) -> String {
    axes.iter()
        .map(|a| a.letter())
        .filter(|&l| l != 'X' && l != 'Y')
        .collect()
}

/// The degree the first block of a curve in `form` gives (`G38`'s `O`, `G06.2`'s order `P`,
/// `G5.2`'s order `L`), and the warning (column, text) for an order below LinuxCNC's 3.
fn opening_degree(
    form: NurbsForm,
    g_word: &Word,
    letters: &Letters,
) -> Step<(usize, Option<(usize, String)>)> {
    let mut low_order = None;
    let degree = match form {
        NurbsForm::G38 => {
            let o = letters.get('O').ok_or((
                g_word.col,
                GcodeErrorKind::MissingCoordinate {
                    what: "the first G38 block needs O<degree>".into(),
                },
            ))?;
            whole(o, 1.0, MAX_DEGREE as f64)? as usize
        }
        NurbsForm::Fanuc => {
            let p = letters.get('P').ok_or((
                g_word.col,
                GcodeErrorKind::MissingCoordinate {
                    what: "the first G06.2 block needs P<order>".into(),
                },
            ))?;
            whole(p, 2.0, (MAX_DEGREE + 1) as f64)? as usize - 1
        }
        // LinuxCNC's order is 3 unless L is above 3 (interp_convert.cc, convert_nurbs).
        NurbsForm::LinuxCnc => match letters.get('L') {
            Some(l) => {
                let order = whole(l, 0.0, (MAX_DEGREE + 1) as f64)? as usize;
                if order < 3 {
                    low_order = Some((
                        l.col,
                        format!(
                            "L{}: an order below 3 is read as order 3, as LinuxCNC does",
                            l.text
                        ),
                    ));
                }
                order.max(3) - 1
            }
            None => 2,
        },
    };
    Ok((degree, low_order))
}

/// Knots for a curve whose program gives none: clamped and uniform, on `[0, 1]` for G38 (seed 000,
/// Table I) and on `[0, n - order + 2]` in whole numbers for G5.2 (LinuxCNC's convention).
pub(super) fn clamped_uniform_knots(points: usize, degree: usize, form: NurbsForm) -> Vec<f64> {
    let mut knots = crate::geometry::clamped_uniform_knots(points, degree);
    if form == NurbsForm::LinuxCnc {
        let spans = (points.saturating_sub(degree + 1) + 1) as f64;
        // Whole numbers: scale, then round away the division's last-bit noise.
        knots.iter_mut().for_each(|k| *k = (*k * spans).round());
    }
    knots
}

/// Appends the block's `K` (which must be there) to the curve's knots, refusing a decrease.
pub(super) fn push_knot(curve: &mut PendingCurve, letters: &Letters, col: usize) -> Step<()> {
    let k = letters.get('K').ok_or((
        col,
        GcodeErrorKind::MissingKnot {
            form: curve.form.name(),
        },
    ))?;
    if let Some(&previous) = curve.knots.last()
        && k.value < previous
    {
        return Err((
            k.col,
            GcodeErrorKind::KnotsDecreasing {
                value: k.value,
                previous,
            },
        )
            .into());
    }
    curve.knots.push(k.value);
    Ok(())
}

pub(super) fn weight(w: Option<&Word>) -> Step<f64> {
    match w {
        None => Ok(1.0),
        Some(w) if w.value > 0.0 => Ok(w.value),
        Some(w) => Err((
            w.col,
            GcodeErrorKind::BadWeight {
                letter: w.letter,
                value: w.value,
            },
        )
            .into()),
    }
}

/// Words (besides G M N F S T and axes) allowed in a curve's first block or its later blocks.
pub(super) fn curve_letters(form: NurbsForm, first: bool) -> &'static str {
    match (form, first) {
        (NurbsForm::G38, true) => "OCWK",
        (NurbsForm::G38, false) => "WK",
        (NurbsForm::Fanuc, true) => "PKRQ",
        (NurbsForm::Fanuc, false) => "KRQ",
        (NurbsForm::LinuxCnc, true) => "PL",
        (NurbsForm::LinuxCnc, false) => "P",
    }
}

/// `G5.1 X Y I J`: LinuxCNC's quadratic B-spline from here to the end point, its middle
/// control point at `I J` from the start (both needed), in the XY plane and never under
/// the wire offset (LinuxCNC refuses both). Exact as a degree-2 curve.
pub(super) fn quad_spline(
    state: &mut InterpState,
    env: &mut BlockEnv,
    line_no: u64,
    letters: &Letters,
    col: usize,
) -> Step<Block> {
    let fail = |col, what: &str| Fail::from((col, GcodeErrorKind::Control(what.to_string())));
    env.axes.check_letters(letters, true, "IJ", "with G5.1")?;
    if state.modal.plane != crate::gcode::Plane::XY {
        return Err(fail(col, "G5.1 works in the XY plane (G17) only"));
    }
    if state.modal.wire_offset.engaged() {
        return Err(fail(
            col,
            "G5.1 cannot be used with the wire offset on (G40 first)",
        ));
    }
    let (Some(i), Some(j)) = (letters.get('I'), letters.get('J')) else {
        return Err(fail(
            col,
            "G5.1 needs both I and J (its control point from the start)",
        ));
    };
    let index = |axis| env.axes.iter().position(|&a| a == axis);
    let (Some(ix), Some(iy)) = (index(crate::vocab::Axis::X), index(crate::vocab::Axis::Y)) else {
        return Err(fail(col, "G5.1 needs the axes X and Y"));
    };
    let feed = env.feed_limit(state, col);
    let start = state.position;
    let (end, _) = env.target(state, &start, letters, "")?;
    let mut control = start;
    control[ix] += i.value * state.scale();
    control[iy] += j.value * state.scale();
    let curve = NurbsCurve::new(
        2,
        env.axes.len(),
        &[start, control, end],
        &[1.0; 3],
        vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
    )
    .map_err(|e| Fail::from((col, e.into())))?;
    state.position = end;
    // Of LinuxCNC's G5.x family: reported with its NURBS form.
    let kind = BlockKind::Nurbs {
        form: NurbsForm::LinuxCnc,
    };
    Ok(state.block(line_no, kind, curve, feed))
}
