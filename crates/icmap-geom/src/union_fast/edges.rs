//! The rings' edges and their sweep boxes, with the edge-length and spike tests (step 2 of the
//! module doc, first half).

use super::primitives::{near, BBox, V};
use super::NEAR_MARGIN;

/// One edge of a ring: ring (0 or 1), index of its first vertex.
#[derive(Clone, Copy)]
pub(super) struct Edge {
    pub(super) ring: u8,
    pub(super) i: u32,
    pub(super) p: V,
    pub(super) q: V,
    /// Length of the edge.
    pub(super) len: f64,
}

/// The bounding box of an edge grown by tol (`x` along the sweep axis, `y` across it).
#[derive(Clone, Copy)]
pub(super) struct SweepBox {
    pub(super) bb: BBox,
    /// Index into the edge list.
    pub(super) edge: u32,
    /// Index of the next edge of the same ring in the edge list.
    pub(super) next: u32,
}

/// Fills `edges` and `boxes` (each edge's bounding box grown by `tol`, `x` along the sweep axis:
/// world x when `along_x`, else world y) for both rings; returns the range `(lo, hi)` of the
/// boxes' starts along the sweep axis. `None` (decline) on an edge shorter than `tol` or a spike.
pub(super) fn build_edges(
    rings: &[&[V]; 2],
    tol: f64,
    along_x: bool,
    edges: &mut Vec<Edge>,
    boxes: &mut Vec<SweepBox>,
) -> Option<(f64, f64)> {
    let tol2 = tol * tol;
    // Edges (no edge shorter than tol) and their boxes grown by tol, in one pass. The sweep runs
    // along the longer side of the bounding box (a crossing is long and thin: across it, every
    // edge would overlap every other one). Neighbours (consecutive edges p-v, v-q of one ring):
    // the far ends must not come back near the other edge (spike); a triangle has every pair
    // adjacent both ways, which this covers. `|c| / |pv|` is q's distance to the line through p
    // and v, a lower bound of its distance to the segment (likewise p's to v-q): only a nearly
    // collinear pair needs the exact test.
    let spike = |e: &Edge, f: &Edge| {
        let (p, v, q) = (e.p, e.q, f.q);
        let c = v.sub(p).cross(q.sub(v)).abs();
        c <= tol * e.len.max(f.len) * NEAR_MARGIN && (near(q, p, v, tol2) || near(p, v, q, tol2))
    };
    edges.clear();
    boxes.clear();
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for (ring, r) in rings.iter().enumerate() {
        let k = r.len();
        let base = edges.len();
        for i in 0..k {
            let next = if i + 1 == k { 0 } else { i + 1 };
            let (p, q) = (r[i], r[next]);
            let d = q.sub(p);
            let len2 = d.dot(d);
            if len2 < tol2 {
                return None;
            }
            let e = Edge {
                ring: ring as u8,
                i: i as u32,
                p,
                q,
                len: len2.sqrt(),
            };
            if i > 0 && spike(&edges[base + i - 1], &e) {
                return None;
            }
            edges.push(e);
            let (sp, sq, ap, aq) = if along_x {
                (p.x, q.x, p.y, q.y)
            } else {
                (p.y, q.y, p.x, q.x)
            };
            let (x0, x1) = if sp < sq { (sp, sq) } else { (sq, sp) };
            let (y0, y1) = if ap < aq { (ap, aq) } else { (aq, ap) };
            let x0 = x0 - tol;
            lo = if x0 < lo { x0 } else { lo };
            hi = if x0 > hi { x0 } else { hi };
            boxes.push(SweepBox {
                bb: BBox {
                    x0,
                    x1: x1 + tol,
                    y0: y0 - tol,
                    y1: y1 + tol,
                },
                edge: (base + i) as u32,
                next: (base + next) as u32,
            });
        }
        if spike(&edges[base + k - 1], &edges[base]) {
            return None;
        }
    }
    Some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(pts: &[(f64, f64)]) -> Vec<V> {
        pts.iter().map(|&(x, y)| V { x, y }).collect()
    }

    #[test]
    fn edges_and_boxes_of_both_rings() {
        let a = ring(&[(0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (0.0, 1.0)]);
        let b = ring(&[(1.0, -1.0), (2.0, -1.0), (2.0, 3.0)]);
        let (mut edges, mut boxes) = (Vec::new(), Vec::new());
        let tol = 1e-3;
        let (lo, hi) = build_edges(&[&a, &b], tol, true, &mut edges, &mut boxes).unwrap();
        assert_eq!((edges.len(), boxes.len()), (7, 7));
        assert_eq!(
            (edges[3].ring, edges[3].i, edges[4].ring, edges[4].i),
            (0, 3, 1, 0)
        );
        // Each box is its edge's box grown by tol; `next` is the ring's next edge.
        for (e, bx) in edges.iter().zip(&boxes) {
            assert_eq!(bx.bb.x0, e.p.x.min(e.q.x) - tol);
            assert_eq!(bx.bb.y1, e.p.y.max(e.q.y) + tol);
            assert!((e.len - e.q.sub(e.p).dot(e.q.sub(e.p)).sqrt()).abs() < 1e-15);
        }
        assert_eq!((boxes[3].next, boxes[6].next), (0, 4));
        assert_eq!((lo, hi), (-tol, 4.0 - tol));
        // Along y, the box's `x` is world y.
        build_edges(&[&a, &b], tol, false, &mut edges, &mut boxes).unwrap();
        assert_eq!(boxes[0].bb.x0, -tol);
        assert_eq!(boxes[0].bb.y1, 4.0 + tol);
    }

    #[test]
    fn short_edges_and_spikes_are_declined() {
        let b = ring(&[(10.0, 0.0), (11.0, 0.0), (11.0, 1.0)]);
        let (mut edges, mut boxes) = (Vec::new(), Vec::new());
        let short = ring(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (1.0, 1.0 + 1e-4)]);
        assert!(build_edges(&[&short, &b], 1e-3, true, &mut edges, &mut boxes).is_none());
        // A spike: the ring goes out to (3, 0.5) and comes back along the same line.
        let spike = ring(&[(0.0, 0.0), (1.0, 0.0), (3.0, 0.5), (1.0, 0.5), (0.0, 1.0)]);
        let ok = build_edges(&[&spike, &b], 1e-3, true, &mut edges, &mut boxes);
        assert!(ok.is_some(), "not a spike: the way back is 0.5 m off");
        let spike = ring(&[
            (0.0, 0.0),
            (1.0, 0.0),
            (3.0, 0.0),
            (2.0, 0.0 + 1e-5),
            (0.0, 1.0),
        ]);
        assert!(build_edges(&[&spike, &b], 1e-3, true, &mut edges, &mut boxes).is_none());
    }
}
