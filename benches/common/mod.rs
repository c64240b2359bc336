//! Helpers shared by the benches.

use edmd::gcode::{Block, open_program};
use edmd::vocab::Axis;

/// The first NURBS block of a sample program in `programs/` (the papers' curves live there,
/// once).
pub fn program_curve(name: &str) -> Block {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("programs")
        .join(name);
    open_program(&path, &[Axis::X, Axis::Y])
        .expect("the sample program opens")
        .map(|b| b.expect("the sample program parses"))
        .find(|b| b.curve.degree() > 1)
        .expect("the sample program has a NURBS block")
}
