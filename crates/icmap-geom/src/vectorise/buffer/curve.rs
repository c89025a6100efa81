//! GEOS's raw offset curve of a ring (`OffsetSegmentGenerator`): offset segments, mitre points
//! at outside turns (bevelled beyond the mitre limit), the offset segments' crossing or closing
//! segments at inside turns, and the input simplification GEOS applies first.

use crate::types::Point;
use crate::vectorise::segments::{
    line_intersection, orientation, point_segment_distance, segment_intersection,
};

/// GEOS's default mitre limit (`BufferParameters::DEFAULT_MITRE_LIMIT`).
pub(super) const MITRE_LIMIT: f64 = 5.0;

#[inline]
pub(super) fn dist(a: Point, b: Point) -> f64 {
    ((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y)).sqrt()
}

/// `OffsetSegmentGenerator::computeOffsetSegment`: segment `a -> b` moved `d` to its left
/// (`left`) or right.
pub(super) fn offset_segment(a: Point, b: Point, left: bool, d: f64) -> (Point, Point) {
    let side = if left { 1.0 } else { -1.0 };
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let len = (dx * dx + dy * dy).sqrt();
    let ux = side * d * dx / len;
    let uy = side * d * dy / len;
    (
        Point::new(a.x - uy, a.y + ux),
        Point::new(b.x - uy, b.y + ux),
    )
}

/// `BufferInputLineSimplifier::simplify` of a closed ring with a signed tolerance (negative:
/// clockwise corners are candidates). As in GEOS, a vertex is only deleted when it also lies
/// within the tolerance of the previous kept vertex (its `isShallowSampled` test).
pub(super) fn input_simplify(pts: &[Point], signed_tol: f64) -> Vec<Point> {
    let tol = signed_tol.abs();
    let angle = if signed_tol < 0.0 { -1 } else { 1 };
    let n = pts.len();
    let mut deleted = vec![false; n];
    let next = |deleted: &[bool], i: usize| {
        let mut j = i + 1;
        while j < n && deleted[j] {
            j += 1;
        }
        j
    };
    loop {
        let mut changed = false;
        let mut index = 1;
        let mut mid = next(&deleted, index);
        let mut last = next(&deleted, mid);
        while last < n {
            let (p0, p1, p2) = (pts[index], pts[mid], pts[last]);
            let deletable =
                orientation(p0, p1, p2) == angle && point_segment_distance(p1, p0, p2) < tol && {
                    let inc = ((last - index) / 10).max(1);
                    (index..last)
                        .step_by(inc)
                        .all(|i| point_segment_distance(p1, p0, pts[i]) < tol)
                };
            if deletable {
                deleted[mid] = true;
                changed = true;
                index = last;
            } else {
                index = mid;
            }
            mid = next(&deleted, index);
            last = next(&deleted, mid);
        }
        if !changed {
            break;
        }
    }
    pts.iter()
        .zip(&deleted)
        .filter(|(_, &d)| !d)
        .map(|(&p, _)| p)
        .collect()
}

/// GEOS `Angle::sinCosSnap` + `OffsetSegmentGenerator::project`.
pub(super) fn project(p: Point, d: f64, dir: f64) -> Point {
    let (mut s, mut c) = dir.sin_cos();
    if s.abs() < 5e-16 {
        s = 0.0;
    }
    if c.abs() < 5e-16 {
        c = 0.0;
    }
    Point::new(p.x + d * c, p.y + d * s)
}

pub(super) fn normalize_angle(mut a: f64) -> f64 {
    use std::f64::consts::PI;
    while a > PI {
        a -= 2.0 * PI;
    }
    while a <= -PI {
        a += 2.0 * PI;
    }
    a
}

/// GEOS `Intersection::intersectionLineSegment`: the line through `l1 l2` with segment `s1 s2`.
pub(super) fn line_segment_intersection(
    l1: Point,
    l2: Point,
    s1: Point,
    s2: Point,
) -> Option<Point> {
    let o1 = orientation(l1, l2, s1);
    if o1 == 0 {
        return Some(s1);
    }
    let o2 = orientation(l1, l2, s2);
    if o2 == 0 {
        return Some(s2);
    }
    if (o1 > 0 && o2 > 0) || (o1 < 0 && o2 < 0) {
        return None;
    }
    line_intersection(l1, l2, s1, s2).or(Some(s1))
}

/// The raw offset curve of GEOS's `OffsetSegmentGenerator` (mitre joins), point by point.
pub(super) struct Curve {
    pub(super) d: f64,
    pub(super) left: bool,
    pub(super) pts: Vec<Point>,
    pub(super) s0: Point,
    pub(super) s1: Point,
    pub(super) s2: Point,
}

impl Curve {
    pub(super) fn new(d: f64, left: bool) -> Self {
        let o = Point::origin();
        Self {
            d,
            left,
            pts: Vec::new(),
            s0: o,
            s1: o,
            s2: o,
        }
    }

    pub(super) fn add(&mut self, p: Point) {
        if let Some(&last) = self.pts.last() {
            if dist(p, last) < self.d * 1e-4 {
                return;
            }
        }
        self.pts.push(p);
    }

    pub(super) fn init(&mut self, a: Point, b: Point) {
        self.s1 = a;
        self.s2 = b;
    }

    pub(super) fn next(&mut self, p: Point, add_start: bool) {
        if self.s2 == p {
            return;
        }
        self.s0 = self.s1;
        self.s1 = self.s2;
        self.s2 = p;
        let (d, left) = (self.d, self.left);
        let o0 = offset_segment(self.s0, self.s1, left, d);
        let o1 = offset_segment(self.s1, self.s2, left, d);
        let turn = orientation(self.s0, self.s1, self.s2);
        if turn == 0 {
            // collinear: only a reversal adds points
            if segment_intersection((self.s0, self.s1), (self.s1, self.s2)).len() >= 2 {
                if add_start {
                    self.add(o0.1);
                }
                self.add(o1.0);
            }
        } else if (turn < 0 && left) || (turn > 0 && !left) {
            self.outside_turn(o0, o1);
        } else {
            self.inside_turn(o0, o1);
        }
    }

    pub(super) fn outside_turn(&mut self, o0: (Point, Point), o1: (Point, Point)) {
        let d = self.d;
        if dist(o0.1, o1.0) < d * 1e-3 {
            self.add(o0.1);
            return;
        }
        let limit = MITRE_LIMIT * d;
        let corner = self.s1;
        if let Some(x) = line_intersection(o0.0, o0.1, o1.0, o1.1) {
            if dist(x, corner) <= limit {
                self.add(x);
                return;
            }
        }
        if point_segment_distance(corner, o0.1, o1.0) >= limit {
            self.add(o0.1);
            self.add(o1.0);
            return;
        }
        // a mitre limited to `limit` from the corner (GEOS `addLimitedMitreJoin`)
        let a1 = (self.s0.y - corner.y).atan2(self.s0.x - corner.x);
        let a2 = (self.s2.y - corner.y).atan2(self.s2.x - corner.x);
        let mut interior = a2 - a1;
        use std::f64::consts::PI;
        if interior <= -PI {
            interior += 2.0 * PI;
        } else if interior > PI {
            interior -= 2.0 * PI;
        }
        let bisector = normalize_angle(a1 + interior / 2.0);
        let out = normalize_angle(bisector + PI);
        let mid = project(corner, limit, out);
        let dir = normalize_angle(out + PI / 2.0);
        let (b0, b1) = (project(mid, d, dir), project(mid, d, dir + PI));
        match (
            line_segment_intersection(o0.0, o0.1, b0, b1),
            line_segment_intersection(o1.0, o1.1, b0, b1),
        ) {
            (Some(x0), Some(x1)) => {
                self.add(x0);
                self.add(x1);
            }
            _ => {
                self.add(o0.1);
                self.add(o1.0);
            }
        }
    }

    pub(super) fn inside_turn(&mut self, o0: (Point, Point), o1: (Point, Point)) {
        if let Some(&x) = segment_intersection(o0, o1).first() {
            self.add(x);
            return;
        }
        if dist(o0.1, o1.0) < self.d * 1e-3 {
            self.add(o0.1);
            return;
        }
        let s1 = self.s1;
        self.add(o0.1);
        self.add(Point::new((o0.1.x + s1.x) / 2.0, (o0.1.y + s1.y) / 2.0));
        self.add(Point::new((o1.0.x + s1.x) / 2.0, (o1.0.y + s1.y) / 2.0));
        self.add(o1.0);
    }

    pub(super) fn close(&mut self) {
        if let (Some(&first), Some(&last)) = (self.pts.first(), self.pts.last()) {
            if first != last {
                self.pts.push(first);
            }
        }
    }
}

/// GEOS `computeRingBufferCurve` of the closed ring `closed` at distance `d > 0` on its `left`
/// or right: the raw curve, closed.
pub(super) fn ring_curve(closed: &[Point], left: bool, d: f64) -> Vec<Point> {
    let tol = if left { d * 0.01 } else { -d * 0.01 };
    let simp = input_simplify(closed, tol);
    let n = simp.len() - 1;
    let mut c = Curve::new(d, left);
    c.init(simp[n - 1], simp[0]);
    for (i, &p) in simp.iter().enumerate().skip(1) {
        c.next(p, i != 1);
    }
    c.close();
    c.pts
}
