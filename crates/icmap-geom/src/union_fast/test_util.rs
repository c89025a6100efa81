//! Test helpers shared by the fast union's tests: a deterministic generator and random simple
//! polygons, and brute-force oracles.

use crate::types::Point;

pub(super) use crate::splitmix::Rng;

/// A random star-shaped polygon (so simple), counter-clockwise: `k` vertices at increasing angles
/// around `(cx, cy)`, at radii in `[0.4 r, r]`.
pub(super) fn star(rng: &mut Rng, cx: f64, cy: f64, k: usize, r: f64) -> Vec<Point> {
    (0..k)
        .map(|i| {
            let t = (i as f64 + rng.uniform(0.0, 0.8)) / k as f64 * std::f64::consts::TAU;
            let rr = rng.uniform(0.4 * r, r);
            Point::new(cx + rr * t.cos(), cy + rr * t.sin())
        })
        .collect()
}

/// Whether segments `p1-p2` and `q1-q2` cross properly (each one's ends strictly on both sides of
/// the other's line).
pub(super) fn cross_properly(p1: Point, p2: Point, q1: Point, q2: Point) -> bool {
    let side = |a: Point, b: Point, c: Point| (b - a).perp(&(c - a));
    let (d1, d2) = (side(q1, q2, p1), side(q1, q2, p2));
    let (d3, d4) = (side(p1, p2, q1), side(p1, p2, q2));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Distance from `p` to segment `a-b`.
pub(super) fn seg_dist(p: Point, a: Point, b: Point) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.dot(&ab)).clamp(0.0, 1.0);
    (p - (a + ab * t)).norm()
}
