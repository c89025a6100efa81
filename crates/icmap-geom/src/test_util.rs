//! Test helpers shared by the crate's unit tests (compiled for tests only): short constructors
//! of points, shapes and maps.

use crate::store::{GlobalMap, MapConfig};
use crate::types::Point;

/// `Point::new(x, y)`, short for the tests' literals.
pub(crate) fn p(x: f64, y: f64) -> Point {
    Point::new(x, y)
}

/// An empty map of the default configuration.
pub(crate) fn map() -> GlobalMap {
    GlobalMap::new(MapConfig::default()).unwrap()
}

/// The axis-aligned rectangle of centre (cx, cy) and half sizes hx, hy, counter-clockwise.
pub(crate) fn rect(cx: f64, cy: f64, hx: f64, hy: f64) -> Vec<Point> {
    vec![
        p(cx - hx, cy - hy),
        p(cx + hx, cy - hy),
        p(cx + hx, cy + hy),
        p(cx - hx, cy + hy),
    ]
}
