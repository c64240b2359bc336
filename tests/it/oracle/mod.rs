//! Independent measures shared by the accuracy tests (`tests/it/preprocess.rs`,
//! `tests/it/chord_bound.rs`): written here, not taken from the code under test.

use edmd::geometry::Point;

/// Distance from `p` to the segment `a`–`b`.
pub fn dist_to_segment(p: &Point, a: &Point, b: &Point) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}
