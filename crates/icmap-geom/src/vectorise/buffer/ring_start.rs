//! Where GEOS's polygon builder starts the buffer's ring: the raw curve's graph walked
//! depth-first from its node of least x, then y; the first node on the buffer.

use super::curve::dist;
use crate::types::Point;
use crate::vectorise::segments::{orientation, point_segment_distance, segment_intersection};

/// A node of the raw curve's graph and its outgoing edges (direction point, edge index, forward).
pub(super) struct Node {
    pub(super) at: Point,
    pub(super) out: Vec<(Point, usize, bool)>,
}

/// GEOS `Quadrant::quadrant` of a direction.
pub(super) fn quadrant(dx: f64, dy: f64) -> u8 {
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
pub(super) fn ring_start(curve: &[Point], poly: &[Point]) -> Option<Point> {
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
