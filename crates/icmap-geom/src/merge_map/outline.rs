//! Steps 1-2 of the module doc: each instance's geometry prepared for point-distance queries, and
//! the overlap test of two instances (the share of one's points within the gate of the other).

use crate::clip::inside_ring;
use crate::store::Instance;
use crate::types::Point;

/// Segments per block of [`Outline`].
const BLOCK: usize = 8;

/// An instance's geometry prepared for point-distance queries: its segments (a ring's closing edge
/// included) in blocks of [`BLOCK`] with bounding boxes, so that blocks farther than the cutoff
/// are skipped.
pub(crate) struct Outline<'a> {
    pts: &'a [Point],
    closed: bool,
    /// Per block: min x, min y, max x, max y of its segments' end points.
    blocks: Vec<[f64; 4]>,
}

impl<'a> Outline<'a> {
    pub(crate) fn new(inst: &'a Instance) -> Self {
        Self::of(&inst.points, inst.closed)
    }

    pub(super) fn of(pts: &'a [Point], closed: bool) -> Self {
        let nseg = segment_count(pts.len(), closed);
        let blocks = (0..nseg)
            .step_by(BLOCK)
            .map(|b0| {
                let mut bb = [f64::INFINITY, f64::INFINITY, -f64::INFINITY, -f64::INFINITY];
                for i in b0..=(b0 + BLOCK).min(nseg) {
                    let q = pts[i % pts.len()];
                    bb = [
                        bb[0].min(q.x),
                        bb[1].min(q.y),
                        bb[2].max(q.x),
                        bb[3].max(q.y),
                    ];
                }
                bb
            })
            .collect();
        Outline {
            pts,
            closed,
            blocks,
        }
    }

    /// The distance from `p` to the geometry (0 inside a ring) if it is at most `cutoff`.
    pub(super) fn distance_within(&self, p: &Point, cutoff: f64) -> Option<f64> {
        if self.closed && inside_ring(*p, self.pts) {
            return Some(0.0);
        }
        let n = self.pts.len();
        let nseg = segment_count(n, self.closed);
        let mut best2 = cutoff * cutoff;
        let mut found = false;
        for (b, bb) in self.blocks.iter().enumerate() {
            let dx = (bb[0] - p.x).max(p.x - bb[2]).max(0.0);
            let dy = (bb[1] - p.y).max(p.y - bb[3]).max(0.0);
            if dx * dx + dy * dy > best2 {
                continue;
            }
            for i in b * BLOCK..((b + 1) * BLOCK).min(nseg) {
                let d2 = segment_distance2(p, &self.pts[i], &self.pts[(i + 1) % n]);
                if d2 <= best2 {
                    best2 = d2;
                    found = true;
                }
            }
        }
        found.then(|| best2.sqrt())
    }
}

pub(super) fn segment_count(n: usize, closed: bool) -> usize {
    if closed {
        n
    } else {
        n.saturating_sub(1)
    }
}

/// Squared distance from `p` to the segment `a b`.
pub(super) fn segment_distance2(p: &Point, a: &Point, b: &Point) -> f64 {
    let d = b - a;
    let len2 = d.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&d) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + d * t)).norm_squared()
}

/// Points of `pts` within `gate` of `outline`: their count and the sum of their distances.
fn directed(pts: &[Point], outline: &Outline<'_>, gate: f64) -> (usize, f64) {
    let mut count = 0;
    let mut sum = 0.0;
    for p in pts {
        if let Some(d) = outline.distance_within(p, gate) {
            count += 1;
            sum += d;
        }
    }
    (count, sum)
}

/// The overlap of two instances: `(max(s(a, b), s(b, a)), mean distance within the gate)` (see
/// the module docs).
pub(crate) fn overlap(a: &Outline<'_>, b: &Outline<'_>, gate: f64) -> (f64, f64) {
    let (ca, sa) = directed(a.pts, b, gate);
    let (cb, sb) = directed(b.pts, a, gate);
    let share = (ca as f64 / a.pts.len() as f64).max(cb as f64 / b.pts.len() as f64);
    let mean = if ca + cb > 0 {
        (sa + sb) / (ca + cb) as f64
    } else {
        f64::INFINITY
    };
    (share, mean)
}

/// The overlap of instance `a` of one map with `b` of the other, as public helper for tests and
/// callers that want the same test (`(share, mean distance)`, see the module docs).
pub fn instance_overlap(a: &Instance, b: &Instance, gate: f64) -> (f64, f64) {
    overlap(&Outline::new(a), &Outline::new(b), gate)
}
