//! The G-code word table: what each `G` number means to edmd, its modal group (two words of
//! one group in a block conflict), and the refusals, each with the reason and what to post
//! instead. Codes are compared as whole tenths (`G06.2` is 62), never as floats.

use super::{Fail, Step};

use crate::gcode::error::GcodeErrorKind;
use crate::gcode::lexer::Word;
use crate::gcode::work::WorkSystem;
use crate::gcode::{NurbsForm, Plane};

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Motion {
    Rapid,
    Linear,
    Cw,
    Ccw,
    /// `G38.2`…`G38.5`, `G31`: a straight move that stops at contact.
    Probe(Probing),
    /// `G5.1`: a quadratic B-spline through the block's end, its control point at `I J`.
    QuadSpline,
    /// `G81`, `G82`, `G83`, `G73`: a canned cycle in the XY plane.
    Cycle(Cycle),
}

/// The canned cycles edmd has: a plunge along Z under the servo at each hole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cycle {
    /// `G81`: down at the feed, out at the rapid.
    Drill,
    /// `G82`: `G81` with a dwell `P` at the bottom.
    DwellAtBottom,
    /// `G83`: pecks of `Q`, out to the R plane after each.
    Peck,
    /// `G73`: pecks of `Q`, backing off a little after each.
    ChipBreak,
}

impl Cycle {
    /// The cycle of `G81`, `G82`, `G83` or `G73` (times ten).
    fn of_tenths(tenths: u32) -> Cycle {
        match tenths {
            810 => Cycle::Drill,
            820 => Cycle::DwellAtBottom,
            830 => Cycle::Peck,
            _ => Cycle::ChipBreak,
        }
    }

    pub(super) fn g_code(self) -> &'static str {
        match self {
            Cycle::Drill => "G81",
            Cycle::DwellAtBottom => "G82",
            Cycle::Peck => "G83",
            Cycle::ChipBreak => "G73",
        }
    }
}

/// What a probing move looks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Probing {
    pub(super) probe: crate::gcode::Probe,
    /// `G31` (Fanuc's skip) holds for its block only; `G38.x` is modal, as in LinuxCNC.
    pub(super) one_shot: bool,
}

/// What a G word does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum GCode {
    Motion(Motion),
    /// G80: cancels the modal motion (it is in the motion group).
    MotionCancel,
    Curve(NurbsForm),
    CurveEnd,
    Inch(bool),
    Incremental(bool),
    ArcCentreAbsolute(bool),
    Plane(Plane),
    /// A mode edmd is always in (G49, G61, G64, G94): accepted, nothing to do.
    Accepted(u8),
    /// A code edmd can safely ignore, with the words it takes: `G64 P… Q…` (path blending:
    /// edmd keeps to its chord tolerance), `G43 H…` (tool length offsets: none on an EDM's
    /// X/Y path). Ignored with one warning.
    Ignored {
        group: u8,
        takes: &'static [char],
        /// Warn only when the block has one of `takes` (a bare `G64` is the default mode).
        only_with_words: bool,
        why: &'static str,
    },
    /// G96/G97, spindle speed modes (group 14): meaningless on an EDM, accepted with a
    /// warning as `S` and `M3` are (LinuxCNC's NURBS examples start with `G96 M3 S200`).
    SpindleMode,
    /// G4 P<seconds> (group 0).
    Dwell,
    /// G40 (group 7): wire offset off.
    CompOff,
    /// G41 (left) / G42 (right) with D (group 7).
    Comp {
        left: bool,
    },
    /// G50 (group 16): the wire vertical again (taper off).
    TaperOff,
    /// G51 (left of the direction of travel) / G52 (right) with A, the angle in degrees
    /// (group 16): a tapered cut.
    Taper {
        left: bool,
    },
    /// G92 family and G10 (group 0).
    Offset(OffsetCode),
    /// G54…G59.3 (group 12): a work coordinate system.
    WorkSystem(WorkSystem),
    /// G53 (group 0): this block's move is in machine coordinates.
    MachineCoords,
    /// G28/G30 (group 0): to a stored machine position; G28.1/G30.1 store it.
    Reference {
        g30: bool,
        store: bool,
    },
    /// G98 (back to the initial level) / G99 (to the R plane) after a cycle (group 10).
    Retract {
        initial_level: bool,
    },
}

/// The G92 family and G10.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum OffsetCode {
    /// G10 L2 / L20: an entry of the work offset table.
    Table,
    /// G92: the current point gets the given coordinates.
    Set,
    /// G92.1: offsets cleared.
    Clear,
    /// G92.2: offsets suspended (kept for G92.3).
    Suspend,
    /// G92.3: suspended offsets restored.
    Restore,
}

impl GCode {
    /// Modal group: two words of one group in a block conflict.
    pub(super) fn group(self) -> u8 {
        match self {
            GCode::Motion(_) | GCode::MotionCancel | GCode::Curve(_) | GCode::CurveEnd => 1,
            GCode::Inch(_) => 2,
            GCode::Incremental(_) => 3,
            GCode::ArcCentreAbsolute(_) => 4,
            GCode::Plane(_) => 5,
            GCode::Accepted(g) => g,
            GCode::Ignored { group, .. } => group,
            GCode::SpindleMode => 14,
            GCode::Dwell | GCode::Offset(_) | GCode::MachineCoords | GCode::Reference { .. } => 0,
            GCode::Retract { .. } => 10,
            GCode::WorkSystem(_) => 12,
            GCode::CompOff | GCode::Comp { .. } => 7,
            GCode::TaperOff | GCode::Taper { .. } => 16,
        }
    }
}

/// `G` number times ten (`G06.2` is 62), so codes compare exactly.
pub(super) fn g_code_tenths(w: &Word) -> Step<u32> {
    let tenths = w.value * 10.0;
    if w.value < 0.0 || (tenths - tenths.round()).abs() > 1e-6 || tenths > 9999.0 {
        return Err((
            w.col,
            GcodeErrorKind::UnknownG {
                code: w.text.to_string(),
            },
        )
            .into());
    }
    Ok(tenths.round() as u32)
}

pub(super) fn g_name(tenths: u32) -> String {
    if tenths.is_multiple_of(10) {
        format!("{}", tenths / 10)
    } else {
        format!("{}.{}", tenths / 10, tenths % 10)
    }
}

pub(super) fn classify_g(tenths: u32, col: usize) -> Step<GCode> {
    let unsupported = |why: &'static str| -> Step<GCode> {
        Err((
            col,
            GcodeErrorKind::UnsupportedG {
                code: g_name(tenths),
                why,
            },
        )
            .into())
    };
    Ok(match tenths {
        0 => GCode::Motion(Motion::Rapid),
        10 => GCode::Motion(Motion::Linear),
        20 => GCode::Motion(Motion::Cw),
        30 => GCode::Motion(Motion::Ccw),
        380 => GCode::Curve(NurbsForm::G38),
        62 => GCode::Curve(NurbsForm::Fanuc),
        52 => GCode::Curve(NurbsForm::LinuxCnc),
        53 => GCode::CurveEnd,
        800 => GCode::MotionCancel,
        200 => GCode::Inch(true),
        210 => GCode::Inch(false),
        900 => GCode::Incremental(false),
        910 => GCode::Incremental(true),
        901 => GCode::ArcCentreAbsolute(true),
        911 => GCode::ArcCentreAbsolute(false),
        170 => GCode::Plane(Plane::XY),
        180 => GCode::Plane(Plane::ZX),
        190 => GCode::Plane(Plane::YZ),
        400 => GCode::CompOff,
        410 => GCode::Comp { left: true },
        420 => GCode::Comp { left: false },
        490 => GCode::Accepted(8),
        540 | 550 | 560 | 570 | 580 | 590 | 591..=593 => GCode::WorkSystem(
            WorkSystem::from_g_tenths(tenths).expect("the nine work system codes"),
        ),
        530 => GCode::MachineCoords,
        100 => GCode::Offset(OffsetCode::Table),
        610 | 611 => GCode::Accepted(13),
        640 => GCode::Ignored {
            group: 13,
            takes: &['P', 'Q'],
            only_with_words: true,
            why: "G64 P/Q (path blending tolerance) is ignored: the path keeps within \
                  interpolation.chord_tolerance_mm",
        },
        940 => GCode::Accepted(6),
        411 | 421 => {
            return unsupported(
                "dynamic compensation with a diameter word; use G41/G42 with a D register \
                 (compensation.d_mm)",
            );
        }
        430..=432 => GCode::Ignored {
            group: 8,
            takes: &['H'],
            only_with_words: false,
            why: "G43 (tool length offset) is ignored: an EDM's wire or electrode length is \
                  not offset in the path",
        },
        433..=439 => return unsupported("tool length offsets"),
        930 => return unsupported("inverse time feed; use G94 (units per minute)"),
        950 => return unsupported("feed per revolution; use G94 (units per minute)"),
        40 => GCode::Dwell,
        920 => GCode::Offset(OffsetCode::Set),
        921 => GCode::Offset(OffsetCode::Clear),
        922 => GCode::Offset(OffsetCode::Suspend),
        923 => GCode::Offset(OffsetCode::Restore),
        51 => GCode::Motion(Motion::QuadSpline),
        50 => return unsupported("cubic splines (G5); use G5.1 or the G5.2/G5.3 NURBS form"),
        60 | 61 => return unsupported("this is a G06.x code edmd does not have; use G06.2"),
        70 | 80 => return unsupported("lathe modes"),
        500 => GCode::TaperOff,
        510 => GCode::Taper { left: true },
        520 => GCode::Taper { left: false },
        280 | 281 | 300 | 301 => GCode::Reference {
            g30: tenths >= 300,
            store: tenths % 10 == 1,
        },
        980 => GCode::Retract {
            initial_level: true,
        },
        990 => GCode::Retract {
            initial_level: false,
        },
        330 | 331 | 760 => return unsupported("threading"),
        382..=385 => GCode::Motion(Motion::Probe(Probing {
            probe: crate::gcode::Probe {
                away: tenths >= 384,
                must_touch: tenths.is_multiple_of(2),
            },
            one_shot: false,
        })),
        310 => GCode::Motion(Motion::Probe(Probing {
            probe: crate::gcode::Probe {
                away: false,
                must_touch: false,
            },
            one_shot: true,
        })),
        810 | 820 | 830 | 730 => GCode::Motion(Motion::Cycle(Cycle::of_tenths(tenths))),
        740 | 840 => return unsupported("tapping cycles (they reverse a spindle an EDM has not)"),
        850..=890 => return unsupported("boring cycles; edmd has G81, G82, G83 and G73"),
        960 | 970 => GCode::SpindleMode,
        _ => {
            return Err((
                col,
                GcodeErrorKind::UnknownG {
                    code: g_name(tenths),
                },
            )
                .into());
        }
    })
}

/// The G words of a block that act after the modes are set: its motion, its offset code
/// (`G10`/`G92`…) and `G53`.
#[derive(Default)]
pub(super) struct LaterCodes<'w> {
    pub(super) motion: Option<(GCode, &'w Word)>,
    pub(super) offset: Option<(OffsetCode, &'w Word)>,
    pub(super) machine: Option<&'w Word>,
    /// `G28`/`G30` (`g30`), or their `.1` (`store`).
    pub(super) reference: Option<(bool, bool, &'w Word)>,
}

/// A block's G codes: kept in the reader's stack frame up to eight (a line costs no
/// allocation for them; a safe-start line has five or six).
pub(super) type BlockCodes<'w> = smallvec::SmallVec<[(GCode, &'w Word); 8]>;

/// The G codes of a block, one per modal group. `G80` beside another motion code is passed
/// over, in either order, as LinuxCNC does: `G0 G80`, `G80 G81` are the safe-start and
/// restart lines of Fanuc and Haas posts, and the other code is what moves.
pub(super) fn g_codes(words: &[Word]) -> Result<BlockCodes<'_>, Fail> {
    let mut codes = BlockCodes::new();
    for w in words.iter().filter(|w| w.letter == 'G') {
        let code = classify_g(g_code_tenths(w)?, w.col)?;
        let motion = code.group() == 1;
        if motion && code == GCode::MotionCancel && codes.iter().any(|(c, _)| c.group() == 1) {
            continue;
        }
        if motion {
            codes.retain(|(c, _)| *c != GCode::MotionCancel);
        }
        if let Some((_, other)) = codes.iter().find(|(c, _)| c.group() == code.group()) {
            return Err((
                w.col,
                GcodeErrorKind::ConflictingG {
                    a: other.text.to_string(),
                    b: w.text.to_string(),
                },
            )
                .into());
        }
        codes.push((code, w));
    }
    Ok(codes)
}
