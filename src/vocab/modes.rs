//! The modes a configuration chooses among: the segmenter's predictor and segmentation, a
//! die-sinker's orbit shape.

use serde::Deserialize;

/// How the segmenter predicts the next curve parameter (`interpolation.predictor`): the
/// corrected second-order Taylor update, or Hamming's predictor (seed 001), each followed by
/// the Lagrange correction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Predictor {
    Taylor,
    Hamming,
}

/// How a curve is cut into segments (`interpolation.segmentation`): the longest chords within
/// the chord tolerance, or one segment per interpolation period along the planned profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Segmentation {
    Chord,
    Period,
}

/// A die-sinker's orbit (planetary motion) around the tool axis while it sinks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OrbitShape {
    /// No orbit: a straight plunge.
    #[default]
    None,
    Circle,
    Square,
    /// Back and forth along X.
    VectorX,
    /// Back and forth along Y.
    VectorY,
    /// A circle with the tool axis raised on a sphere: a rounded floor.
    Sphere,
}

impl OrbitShape {
    pub const ALL: [OrbitShape; 6] = [
        OrbitShape::None,
        OrbitShape::Circle,
        OrbitShape::Square,
        OrbitShape::VectorX,
        OrbitShape::VectorY,
        OrbitShape::Sphere,
    ];

    /// As the configuration spells it: `none`, `circle`, `square`, `vector-x`, `vector-y`,
    /// `sphere`.
    pub fn name(self) -> &'static str {
        match self {
            OrbitShape::None => "none",
            OrbitShape::Circle => "circle",
            OrbitShape::Square => "square",
            OrbitShape::VectorX => "vector-x",
            OrbitShape::VectorY => "vector-y",
            OrbitShape::Sphere => "sphere",
        }
    }

    pub fn parse(text: &str) -> Option<OrbitShape> {
        OrbitShape::ALL
            .into_iter()
            .find(|s| s.name() == text.trim())
    }
}
