//! Convex hulls and minimum-area rectangles of point sets (cell centres), as GEOS computes them
//! for shapely's `MultiPoint(xy).convex_hull` and `.minimum_rotated_rectangle`.
//!
//! A hull polygon is strictly convex (exactly collinear points dropped, by exact orientation
//! tests), clockwise, and starts at its lowest point (smallest y, then smallest x), as GEOS's
//! `ConvexHull` returns it. Fewer than three non-collinear points give a point or a segment.

use super::segments::orientation;
/// Twice the signed area of a ring (positive counter-clockwise); owned by [`crate::clip`].
pub use crate::clip::signed_area2;
use crate::types::Point;

/// The convex hull of a point set.
#[derive(Debug, Clone, PartialEq)]
pub enum Hull {
    /// No points.
    Empty,
    /// All points equal.
    Point(Point),
    /// All points collinear: the two extreme points.
    Segment(Point, Point),
    /// A strictly convex polygon, clockwise, from its lowest point, not closed.
    Polygon(Vec<Point>),
}

/// The convex hull of `pts` (see the module docs).
pub fn convex_hull(pts: &[Point]) -> Hull {
    let mut v: Vec<Point> = pts.to_vec();
    v.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    v.dedup();
    match v.len() {
        0 => return Hull::Empty,
        1 => return Hull::Point(v[0]),
        _ => {}
    }
    // Andrew's monotone chain, counter-clockwise, popping non-left turns (exact)
    let mut lower: Vec<Point> = Vec::new();
    for &p in &v {
        while lower.len() >= 2
            && orientation(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0
        {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<Point> = Vec::new();
    for &p in v.iter().rev() {
        while upper.len() >= 2
            && orientation(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0
        {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    let mut ccw = lower;
    ccw.extend(upper);
    if ccw.len() < 3 {
        let (a, b) = (v[0], v[v.len() - 1]);
        return Hull::Segment(a, b);
    }
    let mut cw: Vec<Point> = ccw.into_iter().rev().collect();
    let start = (0..cw.len())
        .min_by(|&a, &b| {
            cw[a]
                .y
                .total_cmp(&cw[b].y)
                .then(cw[a].x.total_cmp(&cw[b].x))
        })
        .unwrap_or(0);
    cw.rotate_left(start);
    Hull::Polygon(cw)
}

/// GEOS `LineSegment::distancePerpendicularOriented`: signed distance of `p` from the line
/// `a b` (positive on its left).
fn oriented_distance(a: Point, b: Point, p: Point) -> f64 {
    if a == b {
        return (p - a).norm();
    }
    let len2 = (b.x - a.x) * (b.x - a.x) + (b.y - a.y) * (b.y - a.y);
    let s = ((a.y - p.y) * (b.x - a.x) - (a.x - p.x) * (b.y - a.y)) / len2;
    let d = s.abs() * len2.sqrt();
    if orientation(a, b, p) < 0 {
        -d
    } else {
        d
    }
}

/// GEOS `MinimumAreaRectangle::findFurthestVertex` on the ring `pts` (not closed).
fn furthest_vertex(pts: &[Point], a: Point, b: Point, start: usize, orient: i32) -> usize {
    let dist = |k: usize| {
        let d = oriented_distance(a, b, pts[k]);
        if orient == 0 {
            d.abs()
        } else {
            d
        }
    };
    let further = |d1: f64, d2: f64| match orient {
        0 => d1.abs() >= d2.abs(),
        1 => d1 >= d2,
        _ => d1 <= d2,
    };
    let (mut max_d, mut max_i) = (dist(start), start);
    let (mut next_d, mut next_i) = (max_d, max_i);
    while further(next_d, max_d) {
        max_d = next_d;
        max_i = next_i;
        next_i = (max_i + 1) % pts.len();
        if next_i == start {
            break;
        }
        next_d = dist(next_i);
    }
    max_i
}

/// The rectangle of least area around the hull polygon `hull` (clockwise, from GEOS's
/// `ConvexHull`), as GEOS's `MinimumAreaRectangle` builds it (rotating calipers; corners from the
/// base edge's right end, then its left end and the opposite side): `(corners, base length,
/// height)`. `None` for fewer than three points.
pub fn min_area_rectangle(hull: &[Point]) -> Option<([Point; 4], f64, f64)> {
    use super::segments::line_intersection;
    let n = hull.len();
    if n < 3 {
        return None;
    }
    let (mut best, mut best_area) = (None, f64::MAX);
    let (mut diam, mut left, mut right) = (1, 1, 1);
    for i in 0..n {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        diam = furthest_vertex(hull, a, b, diam, 0);
        let dp = hull[diam];
        // the diameter point projected on the base line (GEOS `LineSegment::project`)
        let base_pt = if dp == a || dp == b {
            dp
        } else {
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            let r = ((dp.x - a.x) * dx + (dp.y - a.y) * dy) / (dx * dx + dy * dy);
            Point::new(a.x + r * dx, a.y + r * dy)
        };
        left = furthest_vertex(hull, base_pt, dp, left, 1);
        if i == 0 {
            right = diam;
        }
        right = furthest_vertex(hull, base_pt, dp, right, -1);
        let width = oriented_distance(base_pt, dp, hull[left]).abs()
            + oriented_distance(base_pt, dp, hull[right]).abs();
        let area = (dp - base_pt).norm() * width;
        if area < best_area {
            best_area = area;
            best = Some((i, diam, left, right));
        }
    }
    let (i, diam, left, right) = best?;
    let (br, bl, opp, lp, rp) = (
        hull[i],
        hull[(i + 1) % n],
        hull[diam],
        hull[left],
        hull[right],
    );
    // GEOS `Rectangle::createFromSidePts`
    let (dx, dy) = (bl.x - br.x, bl.y - br.y);
    let c_of = |a: f64, b: f64, p: Point| a * p.y - b * p.x;
    let line = |a: f64, b: f64, c: f64| {
        if b.abs() > a.abs() {
            (Point::new(0.0, c / b), Point::new(1.0, c / b - a / b))
        } else {
            (Point::new(c / a, 0.0), Point::new(c / a - b / a, 1.0))
        }
    };
    let base = line(-dy, dx, c_of(dx, dy, br));
    let oppl = line(-dy, dx, c_of(dx, dy, opp));
    let leftl = line(-dx, -dy, c_of(-dy, dx, lp));
    let rightl = line(-dx, -dy, c_of(-dy, dx, rp));
    let meet = |u: (Point, Point), v: (Point, Point), same: bool, pt: Point| {
        if same {
            Some(pt)
        } else {
            line_intersection(u.0, u.1, v.0, v.1)
        }
    };
    let p0 = meet(base, rightl, rp == br, br)?;
    let p1 = meet(base, leftl, lp == bl, bl)?;
    let p2 = meet(oppl, leftl, lp == opp, opp)?;
    let p3 = meet(oppl, rightl, rp == opp, opp)?;
    Some(([p0, p1, p2, p3], (p1 - p0).norm(), (p2 - p1).norm()))
}

/// Area of a GEOS round-capped (16 segments a quadrant) buffer of radius `r` around a segment of
/// length `len` (`len = 0`: around a point).
pub fn capsule_area(len: f64, r: f64) -> f64 {
    2.0 * r * len + 32.0 * r * r * (std::f64::consts::PI / 32.0).sin()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    #[test]
    fn hull_is_clockwise_from_the_lowest_point_without_collinear_vertices() {
        let pts = [
            p(0.0, 0.0),
            p(1.0, 0.0),
            p(2.0, 0.0),
            p(2.0, 2.0),
            p(0.0, 2.0),
            p(1.0, 1.0),
        ];
        let Hull::Polygon(h) = convex_hull(&pts) else {
            panic!()
        };
        assert_eq!(h, vec![p(0.0, 0.0), p(0.0, 2.0), p(2.0, 2.0), p(2.0, 0.0)]);
        assert!(signed_area2(&h) < 0.0);
        // the lowest row's leftmost point starts it, wherever the input begins
        let Hull::Polygon(h) = convex_hull(&[p(5.0, 1.0), p(3.0, 1.0), p(4.0, 3.0)]) else {
            panic!()
        };
        assert_eq!(h[0], p(3.0, 1.0));
    }

    #[test]
    fn degenerate_hulls() {
        assert_eq!(convex_hull(&[]), Hull::Empty);
        assert_eq!(
            convex_hull(&[p(1.0, 1.0), p(1.0, 1.0)]),
            Hull::Point(p(1.0, 1.0))
        );
        let line = [p(0.0, 0.0), p(1.0, 1.0), p(2.0, 2.0)];
        assert_eq!(convex_hull(&line), Hull::Segment(p(0.0, 0.0), p(2.0, 2.0)));
        assert!(min_area_rectangle(&line[..2]).is_none());
    }

    #[test]
    fn rectangle_of_a_rotated_square() {
        let d = [p(0.0, -1.0), p(-1.0, 0.0), p(0.0, 1.0), p(1.0, 0.0)]; // clockwise
        let (c, w, h) = min_area_rectangle(&d).unwrap();
        assert!((w * h - 2.0).abs() < 1e-12);
        // shapely: MultiPoint(d).minimum_rotated_rectangle starts at (0, -1), then (-1, 0)
        assert_eq!(c[0], p(0.0, -1.0));
        assert!((c[1] - p(-1.0, 0.0)).norm() < 1e-12);
        assert!((capsule_area(0.0, 1.0) - std::f64::consts::PI).abs() < 0.01);
    }
}
