//! Tracing the union's boundary from crossing to crossing (step 3 of the module doc, second half).

use super::crossings::Cross;
use super::primitives::V;
use super::Source;
use crate::types::Point;

/// Traces the loops of the union's boundary: from each crossing along the ring that leaves the
/// other one there, up to that ring's next crossing (`order` / `rank` as
/// [`order_along_rings`](super::order::order_along_rings) fills them). The one loop of positive
/// area (the outer ring, in the caller's coordinates) is left in `outer_pts`; returns twice its
/// area and twice the (negative) area of the holes. `None` (decline) on a traversal that does
/// not close, not exactly one outer loop, or a hole when `holes_ok` is false.
#[allow(clippy::too_many_arguments)]
pub(super) fn trace_loops(
    rings: &[&[V]; 2],
    crosses: &[Cross],
    order: &[Vec<u32>; 2],
    rank: &[Vec<u32>; 2],
    src: &Source<'_>,
    holes_ok: bool,
    visited: &mut Vec<bool>,
    ring_pts: &mut Vec<Point>,
    outer_pts: &mut Vec<Point>,
) -> Option<(f64, f64)> {
    let nc = crosses.len();
    visited.clear();
    visited.resize(nc, false);
    // Twice the area of the outer loop, whose points are kept in `outer_pts`.
    let mut outer: Option<f64> = None;
    let mut holes_area2 = 0.0;
    let max_steps = rings[0].len() + rings[1].len() + 2 * nc + 1;
    for first_c in 0..nc {
        if visited[first_c] {
            continue;
        }
        ring_pts.clear();
        // Twice the signed area by the shoelace formula, in the local frame.
        let first = crosses[first_c].p;
        let mut prev = first;
        let mut a2 = 0.0;
        let mut c = first_c;
        let mut steps = 0usize;
        loop {
            visited[c] = true;
            let cr = crosses[c];
            a2 += prev.cross(cr.p);
            prev = cr.p;
            ring_pts.push(cr.pw);
            // Continue along the ring that leaves the other one here, up to its next crossing.
            let ring: usize = if cr.a_exits { 0 } else { 1 };
            let r = rings[ring];
            let k = rank[ring][c] as usize;
            let next = order[ring][if k + 1 == nc { 0 } else { k + 1 }] as usize;
            let cn = &crosses[next];
            let (e0, t0, e1, t1) = if ring == 0 {
                (cr.ea, cr.ta, cn.ea, cn.ta)
            } else {
                (cr.eb, cr.tb, cn.eb, cn.tb)
            };
            // The vertices after edge e0's start up to edge e1's start, around the ring when
            // the next crossing lies behind this one.
            let (e0, e1) = (e0 as usize, e1 as usize);
            let count = if e1 > e0 || (e1 == e0 && t1 > t0) {
                e1 - e0
            } else {
                e1 + r.len() - e0
            };
            steps += count + 1;
            if steps > max_steps {
                return None;
            }
            let mut i = e0;
            for _ in 0..count {
                i = if i + 1 == r.len() { 0 } else { i + 1 };
                let v = r[i];
                a2 += prev.cross(v);
                prev = v;
                ring_pts.push(src.orig(ring as u8, i));
            }
            // Arriving along `ring`, which must enter the other ring at `next`.
            if (cn.a_exits == (ring == 0)) || (next != first_c && visited[next]) {
                return None;
            }
            if next == first_c {
                break;
            }
            c = next;
        }
        a2 += prev.cross(first);
        if a2 > 0.0 {
            if outer.is_some() {
                return None;
            }
            outer = Some(a2);
            std::mem::swap(ring_pts, outer_pts);
        } else if holes_ok {
            holes_area2 += a2;
        } else {
            return None;
        }
    }
    Some((outer?, holes_area2))
}
