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
use super::segments::{
    line_intersection, orientation, point_segment_distance, segment_intersection,
};
use crate::types::Point;

/// GEOS's default mitre limit (`BufferParameters::DEFAULT_MITRE_LIMIT`).
const MITRE_LIMIT: f64 = 5.0;

#[inline]
fn dist(a: Point, b: Point) -> f64 {
    ((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y)).sqrt()
}

/// `OffsetSegmentGenerator::computeOffsetSegment`: segment `a -> b` moved `d` to its left
/// (`left`) or right.
fn offset_segment(a: Point, b: Point, left: bool, d: f64) -> (Point, Point) {
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
fn input_simplify(pts: &[Point], signed_tol: f64) -> Vec<Point> {
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
fn project(p: Point, d: f64, dir: f64) -> Point {
    let (mut s, mut c) = dir.sin_cos();
    if s.abs() < 5e-16 {
        s = 0.0;
    }
    if c.abs() < 5e-16 {
        c = 0.0;
    }
    Point::new(p.x + d * c, p.y + d * s)
}

fn normalize_angle(mut a: f64) -> f64 {
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
fn line_segment_intersection(l1: Point, l2: Point, s1: Point, s2: Point) -> Option<Point> {
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
struct Curve {
    d: f64,
    left: bool,
    pts: Vec<Point>,
    s0: Point,
    s1: Point,
    s2: Point,
}

impl Curve {
    fn new(d: f64, left: bool) -> Self {
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

    fn add(&mut self, p: Point) {
        if let Some(&last) = self.pts.last() {
            if dist(p, last) < self.d * 1e-4 {
                return;
            }
        }
        self.pts.push(p);
    }

    fn init(&mut self, a: Point, b: Point) {
        self.s1 = a;
        self.s2 = b;
    }

    fn next(&mut self, p: Point, add_start: bool) {
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

    fn outside_turn(&mut self, o0: (Point, Point), o1: (Point, Point)) {
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

    fn inside_turn(&mut self, o0: (Point, Point), o1: (Point, Point)) {
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

    fn close(&mut self) {
        if let (Some(&first), Some(&last)) = (self.pts.first(), self.pts.last()) {
            if first != last {
                self.pts.push(first);
            }
        }
    }
}

/// GEOS `computeRingBufferCurve` of the closed ring `closed` at distance `d > 0` on its `left`
/// or right: the raw curve, closed.
fn ring_curve(closed: &[Point], left: bool, d: f64) -> Vec<Point> {
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

/// A node of the raw curve's graph and its outgoing edges (direction point, edge index, forward).
struct Node {
    at: Point,
    out: Vec<(Point, usize, bool)>,
}

/// GEOS `Quadrant::quadrant` of a direction.
fn quadrant(dx: f64, dy: f64) -> u8 {
    match (dx >= 0.0, dy >= 0.0) {
        (true, true) => 0,
        (false, true) => 1,
        (false, false) => 2,
        (true, false) => 3,
    }
}

/// Where GEOS's polygon builder starts the buffer's ring: the first node, in depth-first order
/// from the node of least (x, y) of the noded raw `curve` (closed), that lies on the eroded
/// polygon `poly` (counter-clockwise) with the polygon on the right of one of its edges.
fn ring_start(curve: &[Point], poly: &[Point]) -> Option<Point> {
    let m = curve.len().checked_sub(1)?;
    if m < 2 {
        return None;
    }
    // nodes on each segment: (segment, fraction along it, point)
    let mut cuts: Vec<(usize, f64, Point)> = vec![(0, 0.0, curve[0])];
    for i in 0..m {
        for j in i + 1..m {
            let pts = segment_intersection((curve[i], curve[i + 1]), (curve[j], curve[j + 1]));
            let adjacent = j == i + 1 || (i == 0 && j == m - 1);
            if pts.is_empty() || (adjacent && pts.len() == 1) {
                continue;
            }
            for x in pts {
                for s in [i, j] {
                    let (a, b) = (curve[s], curve[s + 1]);
                    let len = dist(a, b);
                    let f = if len > 0.0 { dist(a, x) / len } else { 0.0 };
                    // GEOS moves a node at a segment's end to the start of the next segment
                    if x == b && s + 1 < m {
                        cuts.push((s + 1, 0.0, x));
                    } else {
                        cuts.push((s, f, x));
                    }
                }
            }
        }
    }
    cuts.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    cuts.dedup_by(|a, b| a.2 == b.2 && a.0 == b.0);
    // edges between consecutive cuts along the closed curve: a cut, the vertices after it up
    // to the next cut's segment, the next cut (the last edge ends at the curve's end)
    let mut edges: Vec<Vec<Point>> = Vec::new();
    for c in 0..cuts.len() {
        let (s0, _, p0) = cuts[c];
        let (s1, p1) = match cuts.get(c + 1) {
            Some(&(s, _, q)) => (s, q),
            None => (m - 1, curve[m]),
        };
        let mut e = vec![p0];
        e.extend_from_slice(&curve[s0 + 1..=s1.max(s0)]);
        e.push(p1);
        e.dedup();
        if e.len() >= 2 {
            edges.push(e);
        }
    }
    let mut nodes: Vec<Node> = Vec::new();
    let node_of = |nodes: &mut Vec<Node>, p: Point| -> usize {
        match nodes.iter().position(|n| n.at == p) {
            Some(k) => k,
            None => {
                nodes.push(Node {
                    at: p,
                    out: Vec::new(),
                });
                nodes.len() - 1
            }
        }
    };
    let mut ends: Vec<(usize, usize)> = Vec::new();
    for (k, e) in edges.iter().enumerate() {
        let a = node_of(&mut nodes, e[0]);
        let b = node_of(&mut nodes, e[e.len() - 1]);
        nodes[a].out.push((e[1], k, true));
        nodes[b].out.push((e[e.len() - 2], k, false));
        ends.push((a, b));
    }
    for n in &mut nodes {
        let at = n.at;
        n.out.sort_by(|x, y| {
            let (qx, qy) = (
                quadrant(x.0.x - at.x, x.0.y - at.y),
                quadrant(y.0.x - at.x, y.0.y - at.y),
            );
            qx.cmp(&qy).then_with(|| 0.cmp(&orientation(at, y.0, x.0)))
        });
    }
    // a directed edge bounds the result if it runs along the polygon with it on the right
    let on_result = |from: Point, to: Point| -> bool {
        let mid = Point::new((from.x + to.x) / 2.0, (from.y + to.y) / 2.0);
        let scale = 1.0 + mid.x.abs().max(mid.y.abs());
        let n = poly.len();
        let on =
            (0..n).any(|k| point_segment_distance(mid, poly[k], poly[(k + 1) % n]) < 1e-9 * scale);
        if !on {
            return false;
        }
        let len = dist(from, to);
        if len.is_nan() || len <= 0.0 {
            return false;
        }
        let eps = 1e-7 * scale;
        let probe = Point::new(
            mid.x + eps * (to.y - from.y) / len,
            mid.y - eps * (to.x - from.x) / len,
        );
        (0..n).all(|k| {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            (b.x - a.x) * (probe.y - a.y) - (b.y - a.y) * (probe.x - a.x) >= 0.0
        })
    };
    let first = (0..nodes.len()).min_by(|&a, &b| {
        nodes[a]
            .at
            .x
            .total_cmp(&nodes[b].at.x)
            .then(nodes[a].at.y.total_cmp(&nodes[b].at.y))
    })?;
    let mut visited = vec![false; nodes.len()];
    let mut stack = vec![first];
    while let Some(k) = stack.pop() {
        visited[k] = true;
        for &(to, e, fwd) in &nodes[k].out {
            if on_result(nodes[k].at, to) {
                return Some(nodes[k].at);
            }
            let (a, b) = ends[e];
            let other = if fwd { b } else { a };
            if !visited[other] {
                stack.push(other);
            }
        }
    }
    None
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

    fn p(x: f64, y: f64) -> Point {
        Point::new(x, y)
    }

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
