//! The sweep over the edges' boxes (step 2 of the module doc, second half): every pair of edges
//! whose boxes overlap is tested; features closer than `tol` without a proper crossing decline,
//! proper crossings between the rings are recorded.

use super::edges::{Edge, SweepBox};
use super::primitives::{near, V};
use super::{Source, NEAR_MARGIN};
use crate::types::Point;

/// A proper crossing of edge `ea` of ring 0 with edge `eb` of ring 1.
#[derive(Clone, Copy)]
pub(super) struct Cross {
    pub(super) ea: u32,
    pub(super) ta: f64,
    pub(super) eb: u32,
    pub(super) tb: f64,
    pub(super) p: V,
    /// The crossing in the caller's coordinates.
    pub(super) pw: Point,
    /// Ring 0 leaves ring 1 here (so ring 1 enters ring 0).
    pub(super) a_exits: bool,
}

/// Working buffers of the sweep.
#[derive(Default)]
pub(super) struct SweepBuffers {
    sorted: Vec<SweepBox>,
    start: Vec<u32>,
    fill: Vec<u32>,
    /// Each box's bucket (in `boxes` order).
    bucket_of: Vec<u32>,
    /// Candidate partners of one box (indices into `sorted`).
    cand: Vec<u32>,
}

/// The sweep's buckets: `n` equal slices of `(lo, hi)` along the sweep axis. `of` is monotone in
/// x, so a box overlapping box `e` starts in a bucket between `e`'s and that of `e`'s end.
#[derive(Clone, Copy)]
struct Buckets {
    lo: f64,
    scale: f64,
    last: u32,
}

impl Buckets {
    fn new((lo, hi): (f64, f64), n: usize) -> Self {
        let scale = n as f64 / (hi - lo);
        let scale = if scale.is_finite() { scale } else { 0.0 };
        Self {
            lo,
            scale,
            last: (n - 1) as u32,
        }
    }

    /// The bucket of `x >= lo`.
    #[inline(always)]
    fn of(&self, x: f64) -> usize {
        // (`as u32` saturates; the argument is never negative: `x >= lo`.)
        (((x - self.lo) * self.scale) as u32).min(self.last) as usize
    }
}

impl SweepBuffers {
    /// Counting sort of `boxes` by the bucket of their start into `sorted`, stable;
    /// `start[b]..start[b + 1]`: the boxes of bucket `b` in `sorted`.
    fn sort_into_buckets(&mut self, boxes: &[SweepBox], buckets: Buckets, nb: usize) {
        let SweepBuffers {
            sorted,
            start,
            fill,
            bucket_of,
            ..
        } = self;
        start.clear();
        start.resize(nb + 1, 0);
        bucket_of.clear();
        for bx in boxes.iter() {
            let b = buckets.of(bx.bb.x0);
            bucket_of.push(b as u32);
            start[b + 1] += 1;
        }
        for b in 0..nb {
            start[b + 1] += start[b];
        }
        fill.clear();
        fill.extend_from_slice(&start[..nb]);
        sorted.clear();
        sorted.extend_from_slice(boxes);
        for (bx, &b) in boxes.iter().zip(bucket_of.iter()) {
            let b = b as usize;
            sorted[fill[b] as usize] = *bx;
            fill[b] += 1;
        }
    }
}

/// Fills `crosses` with the proper crossings of an edge of ring 0 with an edge of ring 1 (their
/// parameters along both edges, the point in the local and in the caller's frame, and the
/// direction). `boxes` and `(lo, hi)` as [`build_edges`](super::edges::build_edges) returns them.
/// `None` (decline) when two features come closer than `tol` other than by a proper crossing,
/// or when a ring crosses itself.
pub(super) fn find_crossings(
    edges: &[Edge],
    boxes: &[SweepBox],
    range: (f64, f64),
    tol: f64,
    src: &Source<'_>,
    buf: &mut SweepBuffers,
    crosses: &mut Vec<Cross>,
) -> Option<()> {
    let tol2 = tol * tol;
    // Candidate pairs: edges whose bounding boxes (grown by tol) overlap. The boxes are bucketed
    // by their start along the sweep axis (a counting sort). Every pair is met once, from the box
    // that comes first in bucket order.
    let ne = edges.len();
    let buckets = Buckets::new(range, ne);
    buf.sort_into_buckets(boxes, buckets, ne);
    let SweepBuffers {
        sorted,
        start,
        cand,
        ..
    } = buf;

    // The overlap test is branch-free (whether two boxes overlap is data-dependent, and a
    // mispredicted branch per pair costs more than the test): candidates are written to a buffer
    // and kept by advancing its length.
    crosses.clear();
    cand.clear();
    cand.resize(ne, 0);
    for (k, be) in sorted.iter().enumerate() {
        let end = start[buckets.of(be.bb.x1) + 1] as usize;
        let mut nc = 0usize;
        // `end > k`: a box's own bucket is at most its end's bucket.
        for (bf, j) in sorted.get(k + 1..end).unwrap_or(&[]).iter().zip(k + 1..) {
            let keep = (bf.bb.y0 <= be.bb.y1)
                & (be.bb.y0 <= bf.bb.y1)
                & (bf.bb.x0 <= be.bb.x1)
                & (be.bb.x0 <= bf.bb.x1)
                & (bf.edge != be.next)
                & (be.edge != bf.next);
            cand[nc] = j as u32;
            nc += usize::from(keep);
        }
        for &j in &cand[..nc] {
            let bf = &sorted[j as usize];
            // Not neighbours (tested above).
            let (e, f) = (&edges[be.edge as usize], &edges[bf.edge as usize]);
            if let Some(c) = test_pair(e, f, tol, tol2, src)? {
                crosses.push(c);
            }
        }
    }
    Some(())
}

/// The test of two edges that are not neighbours: `None` (decline) when an endpoint comes closer
/// than `tol` to the other edge, or when the edges of one ring cross; `Some(Some(_))` for a
/// proper crossing of the two rings, `Some(None)` when they do not cross.
#[inline(always)]
fn test_pair(e: &Edge, f: &Edge, tol: f64, tol2: f64, src: &Source<'_>) -> Option<Option<Cross>> {
    let (p1, p2, q1, q2) = (e.p, e.q, f.p, f.q);
    let (dp, dq) = (p2.sub(p1), q2.sub(q1));
    let d1 = dq.cross(p1.sub(q1));
    let d2 = dq.cross(p2.sub(q1));
    let d3 = dp.cross(q1.sub(p1));
    let d4 = dp.cross(q2.sub(p1));
    // |d1| / |q| is p1's distance to q's line, which bounds its distance to q from below:
    // only endpoints near the other edge's line need the exact segment distance.
    let (lq, lp) = (tol * f.len * NEAR_MARGIN, tol * e.len * NEAR_MARGIN);
    if (d1.abs() <= lq && near(p1, q1, q2, tol2))
        || (d2.abs() <= lq && near(p2, q1, q2, tol2))
        || (d3.abs() <= lp && near(q1, p1, p2, tol2))
        || (d4.abs() <= lp && near(q2, p1, p2, tol2))
    {
        return None;
    }
    if !((d1 > 0.0) != (d2 > 0.0) && (d3 > 0.0) != (d4 > 0.0)) {
        return Some(None);
    }
    if e.ring == f.ring {
        return None; // self-crossing ring
    }
    // All four are well away from zero here (each endpoint is >= tol from the other
    // segment and the crossing is proper), so both denominators are non-zero.
    // Each edge's index, crossing parameter, direction and start; ring 0's edge first.
    let at_e = (e.i, d1 / (d1 - d2), p2.sub(p1), p1);
    let at_f = (f.i, d3 / (d3 - d4), q2.sub(q1), q1);
    let ((ea, ta, da, pa), (eb, tb, db, _)) = if e.ring == 0 {
        (at_e, at_f)
    } else {
        (at_f, at_e)
    };
    if !(ta > 0.0 && ta < 1.0 && tb > 0.0 && tb < 1.0) {
        return None;
    }
    let p = V {
        x: pa.x + da.x * ta,
        y: pa.y + da.y * ta,
    };
    Some(Some(Cross {
        ea,
        ta,
        eb,
        tb,
        p,
        pw: caller_point(p, (ea, da), (eb, db), src),
        a_exits: da.cross(db) > 0.0,
    }))
}

/// The crossing `p` of edge `ea` (direction `da`) of ring 0 with edge `eb` (direction `db`) of
/// ring 1, in the caller's coordinates. On an axis-parallel edge the crossing keeps that edge's
/// exact coordinate (i_overlay keeps it too: the edge lies on a grid line), so that runs along
/// axis-parallel edges and lowest-left ties are seen as i_overlay sees them.
#[inline(always)]
fn caller_point(p: V, (ea, da): (u32, V), (eb, db): (u32, V), src: &Source<'_>) -> Point {
    let (wa, wb) = (src.orig(0, ea as usize), src.orig(1, eb as usize));
    // One coordinate: edge a's if a is parallel to the other axis, else edge b's, else p's.
    let pick = |da: f64, db: f64, wa: f64, wb: f64, p: f64| {
        if da == 0.0 {
            wa
        } else if db == 0.0 {
            wb
        } else {
            p
        }
    };
    Point::new(
        pick(da.x, db.x, wa.x, wb.x, p.x + src.origin.x),
        pick(da.y, db.y, wa.y, wb.y, p.y + src.origin.y),
    )
}

#[cfg(test)]
mod tests {
    use super::super::edges::build_edges;
    use super::super::primitives::load_ring;
    use super::super::test_util::{cross_properly, star, Rng};
    use super::*;

    /// Builds the edges of rings `a` and `b` (local frame at `a[0]`) and runs the sweep: its
    /// answer and the crossings found.
    fn sweep(a: &[Point], b: &[Point]) -> (Option<()>, Vec<Cross>) {
        let origin = a[0];
        let (mut ra, mut rb) = (Vec::new(), Vec::new());
        let (ba, _) = load_ring(a, origin, &mut ra);
        let (bb, _) = load_ring(b, origin, &mut rb);
        let (extent, along_x) = ba.join(&bb).extent().unwrap();
        let tol = 1e-7 * extent;
        let rings: [&[V]; 2] = [&ra, &rb];
        let (mut edges, mut boxes) = (Vec::new(), Vec::new());
        let range = build_edges(&rings, tol, along_x, &mut edges, &mut boxes).unwrap();
        let src = Source {
            a,
            b,
            origin,
            rev_a: false,
            rev_b: false,
        };
        let mut crosses = Vec::new();
        let found = find_crossings(
            &edges,
            &boxes,
            range,
            tol,
            &src,
            &mut SweepBuffers::default(),
            &mut crosses,
        );
        (found, crosses)
    }

    /// The sweep finds exactly the proper crossings that testing every pair of edges finds, at
    /// the right points, on random star polygons (when it does not decline).
    #[test]
    fn sweep_finds_every_crossing_found_by_brute_force() {
        let mut checked = 0;
        for seed in 0..300 {
            let mut rng = Rng(seed);
            let a = star(&mut rng, 0.0, 0.0, 3 + (seed % 37) as usize, 6.0);
            let (dx, dy) = (rng.uniform(-6.0, 6.0), rng.uniform(-6.0, 6.0));
            let b = star(&mut rng, dx, dy, 3 + (seed % 23) as usize, 5.0);
            let (found, crosses) = sweep(&a, &b);
            if found.is_none() {
                continue;
            }
            checked += 1;
            let mut want = Vec::new();
            for i in 0..a.len() {
                for j in 0..b.len() {
                    let (p1, p2) = (a[i], a[(i + 1) % a.len()]);
                    let (q1, q2) = (b[j], b[(j + 1) % b.len()]);
                    if cross_properly(p1, p2, q1, q2) {
                        want.push((i as u32, j as u32));
                    }
                }
            }
            let mut got: Vec<(u32, u32)> = crosses.iter().map(|c| (c.ea, c.eb)).collect();
            got.sort_unstable();
            want.sort_unstable();
            assert_eq!(got, want, "seed {seed}");
            for c in &crosses {
                let (ea, eb) = (c.ea as usize, c.eb as usize);
                let pa = a[ea] + (a[(ea + 1) % a.len()] - a[ea]) * c.ta;
                let pb = b[eb] + (b[(eb + 1) % b.len()] - b[eb]) * c.tb;
                assert!(
                    (pa - c.pw).norm() < 1e-9 && (pb - c.pw).norm() < 1e-9,
                    "seed {seed}"
                );
                // a_exits: ring 0's direction crosses ring 1's from left to right.
                let (da, db) = (a[(ea + 1) % a.len()] - a[ea], b[(eb + 1) % b.len()] - b[eb]);
                assert_eq!(c.a_exits, da.perp(&db) > 0.0);
            }
        }
        assert!(checked > 250, "{checked}");
    }

    #[test]
    fn touching_and_self_crossing_rings_are_declined() {
        let sq = |x0: f64, y0: f64| {
            vec![
                Point::new(x0, y0),
                Point::new(x0 + 1.0, y0),
                Point::new(x0 + 1.0, y0 + 1.0),
                Point::new(x0, y0 + 1.0),
            ]
        };
        let bowtie = vec![
            Point::new(5.0, 0.0),
            Point::new(6.0, 1.0),
            Point::new(6.0, 0.0),
            Point::new(5.0, 1.0),
        ];
        for (a, b) in [(sq(0.0, 0.0), sq(1.0, 0.5)), (sq(0.0, 0.0), bowtie)] {
            let (found, _) = sweep(&a, &b);
            assert!(found.is_none());
        }
    }
}
