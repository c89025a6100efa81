//! Topology-preserving Douglas-Peucker simplification of one line or ring, as shapely's
//! `simplify(tolerance)` (GEOS `TopologyPreservingSimplifier`, `TaggedLineStringSimplifier`).
//!
//! Douglas-Peucker (a section is flattened to its end points when its furthest vertex lies within
//! the tolerance), where a flattening is refused if the new segment would cross (meet in the
//! interior of either) a remaining input segment outside the section or a segment flattened
//! before, or would leave the output with fewer points than a line (2) or ring (4) needs. A ring
//! may also lose its start point. With one geometry there is no other component to jump over.

use super::segments::{invalid_intersection, orientation, point_segment_distance};
use crate::types::Point;

type Seg = (Point, Point);

struct Tagged<'a> {
    pts: &'a [Point],
    tol: f64,
    min_size: usize,
    /// Input segments still in GEOS's input index.
    alive: Vec<bool>,
    /// Flattened segments (GEOS's output index).
    flat: Vec<Seg>,
    /// The result segments in order.
    result: Vec<Seg>,
}

impl Tagged<'_> {
    fn seg(&self, k: usize) -> Seg {
        (self.pts[k], self.pts[k + 1])
    }

    fn result_size(&self) -> usize {
        if self.result.is_empty() {
            0
        } else {
            self.result.len() + 1
        }
    }

    fn has_output_intersection(&self, s: Seg) -> bool {
        self.flat.iter().any(|&f| invalid_intersection(f, s))
    }

    /// An intersection with an input segment outside `[start, end)` (`None`: none excluded).
    fn has_input_intersection(&self, exclude: Option<(usize, usize)>, s: Seg) -> bool {
        (0..self.alive.len()).any(|k| {
            self.alive[k]
                && exclude.is_none_or(|(a, b)| k < a || k >= b)
                && invalid_intersection(self.seg(k), s)
        })
    }

    /// GEOS `simplifySection(i, j, depth)`, depth first with an explicit stack (a long line
    /// would overflow the call stack): a section is flattened or split at its furthest vertex,
    /// the left half first.
    fn simplify_sections(&mut self, i: usize, j: usize) {
        let mut todo = vec![(i, j, 0usize)];
        while let Some((i, j, depth)) = todo.pop() {
            if let Some(far) = self.section(i, j, depth + 1) {
                todo.push((far, j, depth + 1));
                todo.push((i, far, depth + 1));
            }
        }
    }

    /// One section at `depth`: flattened or kept (`None`), or the vertex to split it at.
    fn section(&mut self, i: usize, j: usize, depth: usize) -> Option<usize> {
        if i + 1 == j {
            let s = self.seg(i);
            self.result.push(s);
            return None;
        }
        let mut valid = !(self.result_size() < self.min_size && depth + 1 < self.min_size);
        let (a, b) = (self.pts[i], self.pts[j]);
        let mut far = i;
        let mut max = -1.0;
        for k in i + 1..j {
            let d = point_segment_distance(self.pts[k], a, b);
            if d > max {
                max = d;
                far = k;
            }
        }
        if max.is_nan() || max < 0.0 || far == i {
            // no distance (non-finite coordinates): keep the section as it is
            for k in i..j {
                let s = self.seg(k);
                self.result.push(s);
            }
            return None;
        }
        if max > self.tol {
            valid = false;
        }
        let flat = (a, b);
        if valid {
            valid = !self.has_output_intersection(flat)
                && !self.has_input_intersection(Some((i, j)), flat);
        }
        if valid {
            self.flat.push(flat);
            for k in i..j {
                self.alive[k] = false;
            }
            self.result.push(flat);
            return None;
        }
        Some(far)
    }

    fn ring_endpoint(&mut self) {
        if self.result_size() <= self.min_size {
            return;
        }
        let first = self.result[0];
        let last = self.result[self.result.len() - 1];
        let simp = (last.0, first.1);
        let end = first.0;
        if point_segment_distance(end, simp.0, simp.1) > self.tol {
            return;
        }
        let valid = orientation(simp.0, simp.1, end) == 0
            || (!self.has_output_intersection(simp) && !self.has_input_intersection(None, simp));
        if valid {
            // the flattened segments may be in either index: GEOS removes them from both
            self.flat.retain(|&f| f != first && f != last);
            self.result[0].0 = last.0;
            self.result.pop();
            self.flat.push(self.result[0]);
        }
    }

    fn coordinates(&self) -> Vec<Point> {
        let mut out: Vec<Point> = self.result.iter().map(|s| s.0).collect();
        if let Some(s) = self.result.last() {
            out.push(s.1);
        }
        out
    }
}

fn run(pts: &[Point], tol: f64, ring: bool) -> Vec<Point> {
    if pts.len() < 2 {
        return pts.to_vec();
    }
    let closed = pts[0] == pts[pts.len() - 1];
    let mut t = Tagged {
        pts,
        tol,
        min_size: if closed { 4 } else { 2 },
        alive: vec![true; pts.len() - 1],
        flat: Vec::new(),
        result: Vec::new(),
    };
    t.simplify_sections(0, pts.len() - 1);
    if ring && closed {
        t.ring_endpoint();
    }
    t.coordinates()
}

/// A `LineString` simplified with `tolerance`: shapely `LineString(pts).simplify(tolerance)`.
pub fn simplify_line(pts: &[Point], tolerance: f64) -> Vec<Point> {
    run(pts, tolerance, false)
}

/// A ring (closed: first point repeated at the end) simplified with `tolerance`: shapely
/// `LinearRing(pts).simplify(tolerance)` (or a polygon's exterior), closed.
pub fn simplify_ring(closed_pts: &[Point], tolerance: f64) -> Vec<Point> {
    run(closed_pts, tolerance, true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    #[test]
    fn douglas_peucker_on_a_line() {
        let line = [
            p(0.0, 0.0),
            p(1.0, 0.1),
            p(2.0, 0.0),
            p(3.0, 1.0),
            p(4.0, 0.0),
        ];
        assert_eq!(
            simplify_line(&line, 0.2),
            vec![p(0.0, 0.0), p(2.0, 0.0), p(3.0, 1.0), p(4.0, 0.0)]
        );
        assert_eq!(simplify_line(&line, 2.0), vec![p(0.0, 0.0), p(4.0, 0.0)]);
        assert_eq!(simplify_line(&line[..1], 1.0), vec![p(0.0, 0.0)]);
    }

    #[test]
    fn a_flattening_that_would_cross_the_line_is_refused() {
        // a hairpin: flattening 0..2 would cut through the way back (shapely keeps every point;
        // plain Douglas-Peucker would drop (5, 0.3) and (5, -0.2))
        let line = [
            p(0.0, 0.0),
            p(5.0, 0.3),
            p(10.0, 0.0),
            p(10.0, 1.0),
            p(5.0, -0.2),
            p(0.0, 1.0),
        ];
        assert_eq!(simplify_line(&line, 0.5), line.to_vec());
    }

    #[test]
    fn rings_keep_four_points_and_may_lose_their_start() {
        let sq = [
            p(0.0, 0.0),
            p(0.0, 4.0),
            p(4.0, 4.0),
            p(4.0, 0.0),
            p(0.0, 0.0),
        ];
        assert_eq!(simplify_ring(&sq, 10.0).len(), 4);
        // a start point in the middle of a side goes
        let mid = [
            p(2.0, 0.0),
            p(0.0, 0.0),
            p(0.0, 4.0),
            p(4.0, 4.0),
            p(4.0, 0.0),
            p(2.0, 0.0),
        ];
        let out = simplify_ring(&mid, 0.1);
        assert_eq!(
            out,
            vec![
                p(4.0, 0.0),
                p(0.0, 0.0),
                p(0.0, 4.0),
                p(4.0, 4.0),
                p(4.0, 0.0)
            ]
        );
    }
}
