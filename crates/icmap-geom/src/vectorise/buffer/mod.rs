//! Mitre-joined buffers of convex polygons, as shapely's `polygon.buffer(d, join_style="mitre")`
//! (GEOS `BufferOp`, mitre limit 5) returns them for the crossing outlines: vertices and the
//! vertex the exterior ring starts at.
//!
//! GEOS offsets the ring into a raw curve (`OffsetSegmentGenerator`: mitre points at outside
//! turns, the crossing of the offset segments, or closing segments, at inside turns), nodes it
//! and keeps the graph edges bounding the buffer, clockwise. For a convex polygon the buffer is
//! the polygon grown by `d` (mitre corners, bevelled beyond the limit) or, for `d < 0`, the
//! intersection of the half-planes its edges bound moved `|d|` inwards, which this module
//! computes directly. The ring starts where GEOS's polygon builder starts it: at the first node
//! of the raw curve's graph (in GEOS's depth-first order from the node of least x, then y) that
//! lies on the buffer, which the module finds by building that graph. Degenerate hulls (all
//! cells on a line) are buffered with round caps as GEOS does (16 segments a quadrant).

use super::hull::signed_area2;
use super::segments::{line_intersection, point_segment_distance};
use crate::types::Point;

mod curve;
mod ring_start;

use curve::{dist, input_simplify, offset_segment, ring_curve};
use ring_start::ring_start;

/// Consecutive repeated points removed; a closed ring stays closed.
fn dedup_closed(ring: &[Point]) -> Vec<Point> {
    let mut out: Vec<Point> = Vec::with_capacity(ring.len() + 1);
    for &p in ring {
        if out.last() != Some(&p) {
            out.push(p);
        }
    }
    if out.len() > 1 && out[0] == out[out.len() - 1] {
        out.pop();
    }
    let first = out.first().copied();
    out.extend(first);
    out
}

/// The vertex order of a ring rotated to start at `start` (a vertex, or a point on an edge,
/// which is then inserted), clockwise.
fn start_at(cw: &[Point], start: Point) -> Vec<Point> {
    let n = cw.len();
    let tol = 1e-9 * (1.0 + start.x.abs().max(start.y.abs()));
    if let Some(k) = (0..n).find(|&k| dist(cw[k], start) <= tol) {
        let mut out = cw.to_vec();
        out.rotate_left(k);
        return out;
    }
    let on_edge = (0..n)
        .min_by(|&a, &b| {
            let da = point_segment_distance(start, cw[a], cw[(a + 1) % n]);
            let db = point_segment_distance(start, cw[b], cw[(b + 1) % n]);
            da.total_cmp(&db)
        })
        .unwrap_or(0);
    let mut out = Vec::with_capacity(n + 1);
    out.push(start);
    for k in 0..n {
        out.push(cw[(on_edge + 1 + k) % n]);
    }
    out
}

/// A convex polygon `ring` (not closed, any orientation, strictly convex or nearly) grown by
/// `d > 0` with mitre joins: its buffer's exterior, clockwise, not closed.
pub fn expand_convex(ring: &[Point], d: f64) -> Vec<Point> {
    let closed = dedup_closed(ring);
    if closed.len() < 4 {
        return match closed.len() {
            0 => Vec::new(),
            1 | 2 => capsule(closed[0], closed[0], d),
            _ => capsule(closed[0], closed[1], d),
        };
    }
    let ccw = signed_area2(&closed[..closed.len() - 1]) > 0.0;
    // GEOS offsets a clockwise shell to its left; a counter-clockwise one to its right
    let curve = ring_curve(&closed, !ccw, d);
    let mut out: Vec<Point> = curve[..curve.len().saturating_sub(1)].to_vec();
    if ccw && !out.is_empty() {
        out[1..].reverse();
    }
    out
}

/// GEOS's round-capped buffer (16 segments a quadrant) of the segment `a b`, clockwise from
/// the left offset of `b`; of the point `a` when `a == b` (a 64-gon from `a + (d, 0)`).
pub fn capsule(a: Point, b: Point, d: f64) -> Vec<Point> {
    use std::f64::consts::PI;
    let step = PI / 2.0 / 16.0;
    let at = |c: Point, angle: f64| Point::new(c.x + d * angle.cos(), c.y + d * angle.sin());
    if a == b {
        return (0..64).map(|k| at(a, -(k as f64) * step)).collect();
    }
    let angle = (b.y - a.y).atan2(b.x - a.x);
    let mut out = Vec::with_capacity(66);
    for (centre, from) in [(b, angle + PI / 2.0), (a, angle - PI / 2.0)] {
        for k in 0..=32 {
            out.push(at(centre, from - step * k as f64));
        }
    }
    out
}

/// The half-planes of the edges of a counter-clockwise convex ring moved `d` inwards, clipped
/// from the ring (Sutherland-Hodgman): the eroded polygon, counter-clockwise; empty when nothing
/// is left.
fn erode(ccw: &[Point], d: f64) -> Vec<Point> {
    let n = ccw.len();
    let mut poly: Vec<Point> = ccw.to_vec();
    for k in 0..n {
        let (o0, o1) = offset_segment(ccw[k], ccw[(k + 1) % n], true, d);
        let (dx, dy) = (o1.x - o0.x, o1.y - o0.y);
        let side = |p: Point| dx * (p.y - o0.y) - dy * (p.x - o0.x);
        let mut out = Vec::with_capacity(poly.len() + 1);
        for m in 0..poly.len() {
            let (cur, next) = (poly[m], poly[(m + 1) % poly.len()]);
            let (inside, next_inside) = (side(cur) >= 0.0, side(next) >= 0.0);
            if inside {
                out.push(cur);
            }
            if inside != next_inside {
                let fallback = if inside { cur } else { next };
                out.push(line_intersection(cur, next, o0, o1).unwrap_or(fallback));
            }
        }
        poly = out;
        if poly.len() < 3 {
            return Vec::new();
        }
    }
    // merge (near-)coincident neighbours: the zero-length edge between them goes
    let size = ccw
        .iter()
        .map(|p| p.x.abs().max(p.y.abs()))
        .fold(0.0, f64::max);
    let scale = 1e-12 * (1.0 + size);
    let mut k = 0;
    while poly.len() >= 3 && k < poly.len() {
        if dist(poly[k], poly[(k + 1) % poly.len()]) <= scale {
            poly.remove(k);
        } else {
            k += 1;
        }
    }
    if poly.len() < 3 {
        return Vec::new();
    }
    poly
}

/// A convex polygon `ring` (not closed, any orientation) shrunk by `d > 0` (shapely
/// `buffer(-d, join_style="mitre")`): the exterior, clockwise, from GEOS's start vertex, or
/// `None` when nothing is left.
pub fn shrink_convex(ring: &[Point], d: f64) -> Option<Vec<Point>> {
    let mut closed: Vec<Point> = ring.to_vec();
    closed.extend(ring.first().copied());
    // GEOS `isRingFullyEroded`
    if closed.len() < 4 {
        return None;
    }
    if closed.len() == 4 {
        let (p0, p1, p2) = (closed[0], closed[1], closed[2]);
        let (l0, l1, l2) = (dist(p1, p2), dist(p0, p2), dist(p0, p1));
        let c = l0 + l1 + l2;
        let centre = Point::new(
            (l0 * p0.x + l1 * p1.x + l2 * p2.x) / c,
            (l0 * p0.y + l1 * p1.y + l2 * p2.y) / c,
        );
        let inradius = point_segment_distance(centre, p0, p1);
        if inradius.is_nan() || inradius < d {
            return None;
        }
    } else {
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in &closed {
            x0 = x0.min(p.x);
            x1 = x1.max(p.x);
            y0 = y0.min(p.y);
            y1 = y1.max(p.y);
        }
        if 2.0 * d > (x1 - x0).min(y1 - y0) {
            return None;
        }
    }
    let closed = dedup_closed(&closed);
    if closed.len() < 4 {
        return None;
    }
    let ccw = signed_area2(&closed[..closed.len() - 1]) > 0.0;
    // the inside of a clockwise shell is its right; a counter-clockwise one is flipped
    let left = ccw;
    let tol = if left { d * 0.01 } else { -d * 0.01 };
    let simp = input_simplify(&closed, tol);
    let mut ccw_ring: Vec<Point> = simp[..simp.len() - 1].to_vec();
    if !ccw {
        ccw_ring.reverse();
    }
    let eroded = erode(&ccw_ring, d);
    let area = signed_area2(&eroded);
    if eroded.len() < 3 || area.is_nan() || area <= 0.0 {
        return None;
    }
    let curve = ring_curve(&closed, left, d);
    let mut cw = eroded.clone();
    cw.reverse();
    let start = ring_start(&curve, &eroded).unwrap_or_else(|| {
        *cw.iter()
            .min_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)))
            .unwrap_or(&cw[0])
    });
    Some(start_at(&cw, start))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    fn close(a: &[Point], b: &[Point]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| dist(*x, *y) < 1e-9)
    }

    #[test]
    fn a_square_grows_with_mitre_corners_from_its_first_vertex() {
        let sq = [p(0.0, 0.0), p(0.0, 2.0), p(2.0, 2.0), p(2.0, 0.0)]; // clockwise
        let out = expand_convex(&sq, 0.5);
        assert!(
            close(
                &out,
                &[p(-0.5, -0.5), p(-0.5, 2.5), p(2.5, 2.5), p(2.5, -0.5)]
            ),
            "{out:?}"
        );
        // counter-clockwise input: the same buffer, clockwise, from the same corner
        let ccw: Vec<Point> = [sq[0], sq[3], sq[2], sq[1]].to_vec();
        assert!(close(&expand_convex(&ccw, 0.5), &out));
    }

    #[test]
    fn a_sharp_corner_is_bevelled_at_the_mitre_limit() {
        let tri = [p(0.0, 0.0), p(10.0, 1.0), p(10.0, 0.0)]; // clockwise, a 5.7 degree corner
        let out = expand_convex(&tri, 0.1);
        // shapely: Polygon(tri).buffer(0.1, join_style="mitre")
        let want = [
            p(-0.495634, -0.1),
            p(-0.503125, 0.050186),
            p(10.1, 1.110499),
            p(10.1, -0.1),
        ];
        assert_eq!(out.len(), 4);
        for (a, b) in out.iter().zip(&want) {
            assert!(dist(*a, *b) < 1e-6, "{out:?}");
        }
    }

    #[test]
    fn shrinking_a_rectangle_and_losing_it() {
        let r = [p(0.0, 0.0), p(0.0, 2.0), p(6.0, 2.0), p(6.0, 0.0)];
        let out = shrink_convex(&r, 0.5).unwrap();
        assert!(
            close(&out, &[p(0.5, 0.5), p(0.5, 1.5), p(5.5, 1.5), p(5.5, 0.5)]),
            "{out:?}"
        );
        assert!(shrink_convex(&r, 1.1).is_none());
        assert!(shrink_convex(&r[..2], 0.1).is_none());
        let tri = [p(0.0, 0.0), p(0.0, 1.0), p(1.0, 0.0)];
        assert!(shrink_convex(&tri, 0.4).is_none());
        assert!(shrink_convex(&tri, 0.1).is_some());
    }

    #[test]
    fn a_short_edge_vanishes_when_shrinking() {
        // a rectangle with one corner cut by a short edge: the cut disappears at d = 1
        let r = [
            p(0.0, 0.0),
            p(0.0, 3.8),
            p(0.2, 4.0),
            p(8.0, 4.0),
            p(8.0, 0.0),
        ];
        let out = shrink_convex(&r, 1.0).unwrap();
        // shapely: [[1, 3], [7, 3], [7, 1], [1, 1]]
        assert!(
            close(&out, &[p(1.0, 3.0), p(7.0, 3.0), p(7.0, 1.0), p(1.0, 1.0)]),
            "{out:?}"
        );
    }

    #[test]
    fn capsules() {
        // shapely: LineString([(0, 0), (4, 0)]).buffer(1, join_style="mitre"): 66 points from
        // (4, 1), then (4.098017, 0.995185)
        let c = capsule(p(0.0, 0.0), p(4.0, 0.0), 1.0);
        assert_eq!(c.len(), 66);
        assert!(dist(c[1], p(4.098017, 0.995185)) < 1e-6);
        assert!(signed_area2(&c) < 0.0);
        assert!((c[0].y - 1.0).abs() < 1e-12 && (c[0].x - 4.0).abs() < 1e-12);
        // Point(1, 1).buffer(1): 64 points from (2, 1), then (1.995185, 0.901983)
        let o = expand_convex(&[p(1.0, 1.0)], 1.0);
        assert_eq!(o.len(), 64);
        assert!(dist(o[0], p(2.0, 1.0)) < 1e-12 && dist(o[1], p(1.995185, 0.901983)) < 1e-6);
    }
}
