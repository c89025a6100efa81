//! The output convention of the union (step 4 of the module doc): axis-parallel runs dropped and
//! the ring started where i_overlay starts its contours.

use super::REL_TOL;
use crate::types::Point;

/// Drops the inner vertices of axis-parallel runs and rotates the ring to start where i_overlay
/// starts its contours (the predecessor of the lowest-left vertex). `None` when that choice is
/// not certain on i_overlay's grid: another vertex's x within a hair of the smallest x, or the
/// start or lowest-left vertex within a hair of the line through its neighbours (i_overlay could
/// drop it as collinear); also when fewer than 3 vertices remain.
///
/// One pass writes the kept vertices to `kept` (a working buffer) and finds their bounding box,
/// the lowest-left one and the smallest x above the smallest; the output (one allocation) is
/// `kept` rotated to the start.
pub(super) fn finish_ring(ring: &[Point], kept: &mut Vec<Point>) -> Option<Vec<Point>> {
    let n = ring.len();
    if n < 3 {
        return None;
    }
    kept.clear();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    // `best`: index in `kept` of the first vertex of smallest `(x, y)`, `b` that vertex;
    // `x_above`: the smallest x above `b.x`.
    let mut best = 0usize;
    let mut b = Point::new(f64::INFINITY, f64::INFINITY);
    let mut x_above = f64::INFINITY;
    // `p`, `c`, `q`: consecutive vertices around the ring.
    let mut p = ring[n - 1];
    let mut c = ring[0];
    for &q in ring[1..].iter().chain(std::iter::once(&ring[0])) {
        // Only axis-parallel runs are dropped: they stay collinear on i_overlay's grid. Other
        // nearly collinear vertices may or may not be dropped there, which moves no boundary.
        let on_x_line = p.x == c.x && c.x == q.x;
        let on_y_line = p.y == c.y && c.y == q.y;
        if !(on_x_line || on_y_line) {
            x0 = if c.x < x0 { c.x } else { x0 };
            x1 = if c.x > x1 { c.x } else { x1 };
            y0 = if c.y < y0 { c.y } else { y0 };
            y1 = if c.y > y1 { c.y } else { y1 };
            if c.x < b.x || (c.x == b.x && c.y < b.y) {
                if c.x != b.x {
                    // Every earlier vertex has x >= b.x.
                    x_above = b.x;
                }
                best = kept.len();
                b = c;
            } else if c.x != b.x && c.x < x_above {
                x_above = c.x;
            }
            kept.push(c);
        }
        p = c;
        c = q;
    }
    let len = kept.len();
    if len < 3 {
        return None;
    }
    let hair = REL_TOL * (x1 - x0).max(y1 - y0);
    if x_above - b.x < hair {
        return None;
    }
    // i_overlay starts a contour at the far end of the lowest-left vertex's upper link, which on
    // a counter-clockwise ring is that vertex's predecessor.
    let start = if best == 0 { len - 1 } else { best - 1 };
    // A start or lowest-left vertex that is collinear with its neighbours up to a hair could be
    // dropped by i_overlay (collinear on its grid): the contour would start elsewhere.
    for i in [start, best] {
        let (p, c, q) = (kept[(i + len - 1) % len], kept[i], kept[(i + 1) % len]);
        let pq = q - p;
        if (c - p).perp(&pq).abs() < hair * pq.norm() {
            return None;
        }
    }
    let mut out = Vec::with_capacity(len);
    out.extend_from_slice(&kept[start..]);
    out.extend_from_slice(&kept[..start]);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    #[test]
    fn runs_are_dropped_and_the_start_is_the_lowest_lefts_predecessor() {
        // A counter-clockwise rectangle sampled along its edges, starting mid-edge.
        let ring = [
            p(2.0, 0.0),
            p(3.0, 0.0),
            p(3.0, 1.0),
            p(3.0, 2.0),
            p(1.0, 2.0),
            p(0.0, 2.0),
            p(0.0, 1.0),
            p(0.0, 0.0),
            p(1.0, 0.0),
        ];
        let out = finish_ring(&ring, &mut Vec::new()).unwrap();
        assert_eq!(
            out,
            vec![p(0.0, 2.0), p(0.0, 0.0), p(3.0, 0.0), p(3.0, 2.0)]
        );
        // Fewer than 3 vertices left, or a tie for the lowest-left vertex within a hair: declined.
        assert!(finish_ring(&[p(0.0, 0.0), p(1.0, 0.0)], &mut Vec::new()).is_none());
        let tie = [p(0.0, 0.0), p(5.0, -1.0), p(1e-9, 3.0)];
        assert!(finish_ring(&tie, &mut Vec::new()).is_none());
        // The start (the lowest-left vertex's predecessor) within a hair of the line through its
        // neighbours (i_overlay could drop it): declined; a clear corner there is kept.
        let flat = [p(0.0, 0.0), p(4.0, 0.0), p(4.0, 4.0), p(2.0, 2.0 + 1e-12)];
        assert!(finish_ring(&flat, &mut Vec::new()).is_none());
        let corner = [p(0.0, 0.0), p(4.0, 0.0), p(4.0, 4.0), p(1.0, 3.0)];
        assert_eq!(
            finish_ring(&corner, &mut Vec::new()).unwrap()[0],
            p(1.0, 3.0)
        );
    }
}
