//! Helpers shared by the integration tests (`mod common;` in each).

use icmap_geom::Point;

/// `Point::new(x, y)`, short for the tests' literals.
pub fn p(x: f64, y: f64) -> Point {
    Point::new(x, y)
}

/// Whether every coordinate of `pts` is finite.
pub fn finite(pts: &[Point]) -> bool {
    pts.iter().all(|q| q.x.is_finite() && q.y.is_finite())
}
