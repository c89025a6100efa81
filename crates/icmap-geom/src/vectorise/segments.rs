//! Segment predicates and constructions with GEOS's semantics: exact orientation, the
//! intersection of two segments as `RobustLineIntersector` reports it, the intersection of two
//! lines, and the distance from a point to a segment (`Distance::pointToSegment`).

use crate::types::Point;
use robust::{orient2d, Coord};

/// Orientation of `q` relative to the directed line `p1 -> p2`: 1 left (counter-clockwise),
/// -1 right, 0 collinear (exact).
#[inline]
pub fn orientation(p1: Point, p2: Point, q: Point) -> i32 {
    let c = |p: Point| Coord { x: p.x, y: p.y };
    let d = orient2d(c(p1), c(p2), c(q));
    if d > 0.0 {
        1
    } else if d < 0.0 {
        -1
    } else {
        0
    }
}

#[inline]
fn in_envelope(a: Point, b: Point, q: Point) -> bool {
    q.x >= a.x.min(b.x) && q.x <= a.x.max(b.x) && q.y >= a.y.min(b.y) && q.y <= a.y.max(b.y)
}

#[inline]
fn envelopes_meet(p1: Point, p2: Point, q1: Point, q2: Point) -> bool {
    p1.x.min(p2.x) <= q1.x.max(q2.x)
        && q1.x.min(q2.x) <= p1.x.max(p2.x)
        && p1.y.min(p2.y) <= q1.y.max(q2.y)
        && q1.y.min(q2.y) <= p1.y.max(p2.y)
}

/// Whether segments `p` and `q` meet in a point that is not an end point of both, or are the
/// same segment (GEOS `hasInvalidIntersection`: `equalsTopo` or `isInteriorIntersection` of
/// `RobustLineIntersector`).
pub fn invalid_intersection(p: (Point, Point), q: (Point, Point)) -> bool {
    let ((p1, p2), (q1, q2)) = (p, q);
    if (p1 == q1 && p2 == q2) || (p1 == q2 && p2 == q1) {
        return true;
    }
    segment_intersection(p, q)
        .iter()
        .any(|&x| !(x == p1 || x == p2) || !(x == q1 || x == q2))
}

/// GEOS `Distance::pointToSegment(p, a, b)`.
pub fn point_segment_distance(p: Point, a: Point, b: Point) -> f64 {
    let dist = |u: Point, v: Point| ((u.x - v.x) * (u.x - v.x) + (u.y - v.y) * (u.y - v.y)).sqrt();
    if a == b {
        return dist(p, a);
    }
    let len2 = (b.x - a.x) * (b.x - a.x) + (b.y - a.y) * (b.y - a.y);
    let r = ((p.x - a.x) * (b.x - a.x) + (p.y - a.y) * (b.y - a.y)) / len2;
    if r <= 0.0 {
        return dist(p, a);
    }
    if r >= 1.0 {
        return dist(p, b);
    }
    let s = ((a.y - p.y) * (b.x - a.x) - (a.x - p.x) * (b.y - a.y)) / len2;
    s.abs() * len2.sqrt()
}

/// The intersection of segments `p` and `q` as GEOS's `RobustLineIntersector` computes it: no
/// point, one point (a shared end point, an end point on the other segment, or a proper crossing)
/// or, for collinear overlapping segments, the two ends of the overlap.
pub fn segment_intersection(p: (Point, Point), q: (Point, Point)) -> Vec<Point> {
    let ((p1, p2), (q1, q2)) = (p, q);
    if !envelopes_meet(p1, p2, q1, q2) {
        return Vec::new();
    }
    let pq1 = orientation(p1, p2, q1);
    let pq2 = orientation(p1, p2, q2);
    if (pq1 > 0 && pq2 > 0) || (pq1 < 0 && pq2 < 0) {
        return Vec::new();
    }
    let qp1 = orientation(q1, q2, p1);
    let qp2 = orientation(q1, q2, p2);
    if (qp1 > 0 && qp2 > 0) || (qp1 < 0 && qp2 < 0) {
        return Vec::new();
    }
    if pq1 == 0 && pq2 == 0 && qp1 == 0 && qp2 == 0 {
        let (q1p, q2p) = (in_envelope(p1, p2, q1), in_envelope(p1, p2, q2));
        let (p1q, p2q) = (in_envelope(q1, q2, p1), in_envelope(q1, q2, p2));
        let pts = if q1p && q2p {
            [q1, q2]
        } else if p1q && p2q {
            [p1, p2]
        } else if q1p && p1q {
            [q1, p1]
        } else if q1p && p2q {
            [q1, p2]
        } else if q2p && p1q {
            [q2, p1]
        } else if q2p && p2q {
            [q2, p2]
        } else {
            return Vec::new();
        };
        return if pts[0] == pts[1] {
            vec![pts[0]]
        } else {
            pts.to_vec()
        };
    }
    if pq1 == 0 || pq2 == 0 || qp1 == 0 || qp2 == 0 {
        let x = if p1 == q1 || p1 == q2 {
            p1
        } else if p2 == q1 || p2 == q2 {
            p2
        } else if pq1 == 0 {
            q1
        } else if pq2 == 0 {
            q2
        } else if qp1 == 0 {
            p1
        } else {
            p2
        };
        return vec![x];
    }
    let x = line_intersection(p1, p2, q1, q2).unwrap_or_else(|| nearest_endpoint(p1, p2, q1, q2));
    // a computed point outside the segments' envelopes goes to the nearest end point, as in GEOS
    if in_envelope(p1, p2, x) && in_envelope(q1, q2, x) {
        vec![x]
    } else {
        vec![nearest_endpoint(p1, p2, q1, q2)]
    }
}

/// Double-double arithmetic as GEOS's `math::DD` (Dekker / Knuth, without fused multiply-adds).
#[derive(Clone, Copy)]
struct Dd {
    hi: f64,
    lo: f64,
}

impl Dd {
    const SPLIT: f64 = 134_217_729.0; // 2^27 + 1

    fn new(v: f64) -> Self {
        Self { hi: v, lo: 0.0 }
    }

    fn add(self, y: Dd) -> Dd {
        let (hi, lo) = (self.hi, self.lo);
        let s_ = hi + y.hi;
        let t_ = lo + y.lo;
        let mut e = s_ - hi;
        let f = t_ - lo;
        let mut s = s_ - e;
        let mut t = t_ - f;
        s = (y.hi - e) + (hi - s);
        t = (y.lo - f) + (lo - t);
        e = s + t_;
        let h_ = s_ + e;
        let h = e + (s_ - h_);
        e = t + h;
        let zhi = h_ + e;
        Dd {
            hi: zhi,
            lo: e + (h_ - zhi),
        }
    }

    fn sub(self, y: Dd) -> Dd {
        self.add(Dd {
            hi: -y.hi,
            lo: -y.lo,
        })
    }

    fn mul(self, y: Dd) -> Dd {
        let (hi, lo) = (self.hi, self.lo);
        let mut c_ = Self::SPLIT * hi;
        let mut hx = c_ - hi;
        let mut c = Self::SPLIT * y.hi;
        hx = c_ - hx;
        let tx = hi - hx;
        let mut hy = c - y.hi;
        c_ = hi * y.hi;
        hy = c - hy;
        let ty = y.hi - hy;
        c = ((((hx * hy - c_) + hx * ty) + tx * hy) + tx * ty) + (hi * y.lo + lo * y.hi);
        let zhi = c_ + c;
        hx = c_ - zhi;
        Dd {
            hi: zhi,
            lo: c + hx,
        }
    }

    fn div(self, y: Dd) -> Dd {
        let (hi, lo) = (self.hi, self.lo);
        let c_ = hi / y.hi;
        let c0 = Self::SPLIT * c_;
        let mut hc = c0 - c_;
        let mut u = Self::SPLIT * y.hi;
        hc = c0 - hc;
        let tc = c_ - hc;
        let mut hy = u - y.hi;
        let u_ = c_ * y.hi;
        hy = u - hy;
        let ty = y.hi - hy;
        u = (((hc * hy - u_) + hc * ty) + tc * hy) + tc * ty;
        let c = ((((hi - u_) - u) + lo) - c_ * y.lo) / y.hi;
        let v = c_ + c;
        Dd {
            hi: v,
            lo: (c_ - v) + c,
        }
    }

    fn value(self) -> f64 {
        self.hi + self.lo
    }
}

/// The intersection of the lines through `p1 p2` and `q1 q2` in homogeneous double-double
/// coordinates, as GEOS's `CGAlgorithmsDD::intersection` (`None`: parallel or not finite).
pub fn line_intersection(p1: Point, p2: Point, q1: Point, q2: Point) -> Option<Point> {
    let (p1x, p1y, p2x, p2y) = (Dd::new(p1.x), Dd::new(p1.y), Dd::new(p2.x), Dd::new(p2.y));
    let (q1x, q1y, q2x, q2y) = (Dd::new(q1.x), Dd::new(q1.y), Dd::new(q2.x), Dd::new(q2.y));
    let px = p1y.sub(p2y);
    let py = p2x.sub(p1x);
    let pw = p1x.mul(p2y).sub(p2x.mul(p1y));
    let qx = q1y.sub(q2y);
    let qy = q2x.sub(q1x);
    let qw = q1x.mul(q2y).sub(q2x.mul(q1y));
    let x = py.mul(qw).sub(qy.mul(pw));
    let y = qx.mul(pw).sub(px.mul(qw));
    let w = px.mul(qy).sub(qx.mul(py));
    let (xi, yi) = (x.div(w).value(), y.div(w).value());
    (xi.is_finite() && yi.is_finite()).then(|| Point::new(xi, yi))
}

/// GEOS `LineIntersector::nearestEndpoint`: the end point nearest to the other segment.
fn nearest_endpoint(p1: Point, p2: Point, q1: Point, q2: Point) -> Point {
    let mut best = (point_segment_distance(p1, q1, q2), p1);
    for (d, x) in [
        (point_segment_distance(p2, q1, q2), p2),
        (point_segment_distance(q1, p1, p2), q1),
        (point_segment_distance(q2, p1, p2), q2),
    ] {
        if d < best.0 {
            best = (d, x);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    #[test]
    fn intersections() {
        let s = (p(0.0, 0.0), p(2.0, 0.0));
        assert!(invalid_intersection(s, (p(1.0, -1.0), p(1.0, 1.0)))); // proper
        assert!(invalid_intersection(s, (p(1.0, 0.0), p(1.0, 1.0)))); // end on interior
        assert!(!invalid_intersection(s, (p(2.0, 0.0), p(3.0, 1.0)))); // shared end
        assert!(invalid_intersection(s, (p(2.0, 0.0), p(0.0, 0.0)))); // same segment
        assert!(invalid_intersection(s, (p(1.0, 0.0), p(3.0, 0.0)))); // collinear overlap
        assert!(!invalid_intersection(s, (p(2.0, 0.0), p(3.0, 0.0)))); // collinear touch
        assert!(!invalid_intersection(s, (p(0.0, 1.0), p(2.0, 1.0))));
        assert_eq!(
            point_segment_distance(p(1.0, 1.0), p(0.0, 0.0), p(2.0, 0.0)),
            1.0
        );
        assert_eq!(
            point_segment_distance(p(3.0, 0.0), p(0.0, 0.0), p(0.0, 0.0)),
            3.0
        );
    }

    #[test]
    fn intersection_points() {
        let s = (p(0.0, 0.0), p(2.0, 0.0));
        assert_eq!(
            segment_intersection(s, (p(1.0, -1.0), p(1.0, 1.0))),
            vec![p(1.0, 0.0)]
        );
        assert_eq!(
            segment_intersection(s, (p(2.0, 0.0), p(3.0, 1.0))),
            vec![p(2.0, 0.0)]
        );
        assert_eq!(segment_intersection(s, (p(1.0, 0.0), p(3.0, 0.0))).len(), 2);
        assert!(segment_intersection(s, (p(0.0, 1.0), p(2.0, 1.0))).is_empty());
        assert_eq!(
            line_intersection(p(0.0, 0.0), p(1.0, 1.0), p(0.0, 2.0), p(1.0, 1.0)),
            Some(p(1.0, 1.0))
        );
        assert_eq!(
            line_intersection(p(0.0, 0.0), p(1.0, 0.0), p(0.0, 1.0), p(1.0, 1.0)),
            None
        );
    }
}
