//! Fast union of two simple polygons (the common case of a crossing merge), with a strict
//! fallback rule: any input that is not clearly generic returns `None` and the caller uses the
//! general overlay (geo / i_overlay) instead.
//!
//! # Algorithm
//!
//! 1. Both rings are moved to a local frame (origin at the first vertex of the first ring) and
//!    oriented counter-clockwise. `tol = 1e-7 * extent` (`extent` = the larger side of the joint
//!    bounding box) is the distance under which two features count as touching: about a hundred
//!    steps of i_overlay's integer grid (`extent / 2^30`), so that its snapping cannot change a
//!    topology that is decided here.
//! 2. One pass over consecutive edges of each ring rejects spikes (a neighbour folding back),
//!    then a bucketed sweep along the long axis of the joint bounding box (edges counting-sorted
//!    by their smallest coordinate there, the most selective test, across the axis, first) visits
//!    every other pair of edges whose bounding boxes (grown by `tol`) overlap:
//!    - two edges of the same ring that are not neighbours must stay `tol` apart (the ring is
//!      simple), two neighbours must not fold back onto each other (no spike);
//!    - an edge of each ring: every endpoint must stay `tol` away from the other edge (no touching,
//!      no shared or collinear-overlapping edges, no crossing near a vertex); a proper crossing
//!      is recorded with its parameters along both edges.
//!
//!    The smallest distance between two segments that do not cross is attained at an endpoint,
//!    so the endpoint tests plus the crossing test decide "closer than `tol`" exactly.
//! 3. Without crossings the rings are disjoint or one contains the other (a vertex tested by ray
//!    casting is at least `tol` from the other boundary). With crossings, the boundary is traced
//!    Greiner-Hormann style: the crossings are ordered along both rings (by edge, then along it);
//!    at every crossing exactly one ring leaves the other one, and the union's boundary goes on
//!    along that ring. Every crossing lies on exactly one traced loop; the loop with positive area
//!    is the outer ring, loops with negative area are holes (dropped, as the general path does).
//! 4. Output rings follow the general path's conventions so that callers see the same result up
//!    to floating-point rounding: counter-clockwise, largest area first, inner vertices of
//!    axis-parallel runs removed (i_overlay drops collinear vertices; other nearly collinear ones
//!    may differ, which moves no boundary), starting where i_overlay starts a contour: at the
//!    predecessor of the lowest-left vertex (smallest `(x, y)`). A resampled ring depends on
//!    that start, so it must match.
//!
//! # Fallback rule
//!
//! `None` (use the general overlay) on: more than [`MAX_VERTICES`] vertices in all, a ring with
//! (nearly) zero area or an edge shorter than `tol`, a ring that is not simple or has a spike,
//! any two features of different rings closer than `tol` without a proper crossing between them
//! (touching, shared or collinear edges, a crossing near a vertex), two crossings closer than
//! `tol` on one edge, an odd number of crossings, crossings that do not alternate in and out
//! along a ring, a traversal that does not close, not exactly one outer loop, a union area outside
//! `[max(area), area_a + area_b]`, or an output start that i_overlay could choose differently
//! (two lowest-left candidates whose x differ by less than `tol`, or a start or lowest-left vertex
//! within `tol` of the line through its neighbours).

use crate::types::Point;

/// Above this many vertices in all the general overlay is used (the sweep is quadratic in the
/// worst case, i_overlay is not).
pub(crate) const MAX_VERTICES: usize = 2048;

/// Relative distance (to the joint extent) under which two features count as touching.
const REL_TOL: f64 = 1e-7;

/// Slack on the cheap lower bounds that decide whether the exact distance test [`near`] is
/// needed: a bound within rounding of `tol` still runs the exact test.
const NEAR_MARGIN: f64 = 1.0 + 1e-9;

#[derive(Clone, Copy, Debug)]
struct V {
    x: f64,
    y: f64,
}

impl V {
    #[inline]
    fn sub(self, o: V) -> V {
        V {
            x: self.x - o.x,
            y: self.y - o.y,
        }
    }
    #[inline]
    fn dot(self, o: V) -> f64 {
        self.x * o.x + self.y * o.y
    }
    #[inline]
    fn cross(self, o: V) -> f64 {
        self.x * o.y - self.y * o.x
    }
}

/// The larger side of the points' bounding box and whether it is the x side; `None` when it is
/// not finite and positive.
fn extent_of<'a>(points: impl Iterator<Item = &'a V>) -> Option<(f64, bool)> {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in points {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    let extent = (x1 - x0).max(y1 - y0);
    (extent.is_finite() && extent > 0.0).then_some((extent, x1 - x0 >= y1 - y0))
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy)]
struct BBox {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl BBox {
    fn join(&self, o: &BBox) -> BBox {
        BBox {
            x0: self.x0.min(o.x0),
            x1: self.x1.max(o.x1),
            y0: self.y0.min(o.y0),
            y1: self.y1.max(o.y1),
        }
    }

    /// The larger side and whether it is the x side; `None` when it is not finite and positive.
    fn extent(&self) -> Option<(f64, bool)> {
        let (w, h) = (self.x1 - self.x0, self.y1 - self.y0);
        let extent = w.max(h);
        (extent.is_finite() && extent > 0.0).then_some((extent, w >= h))
    }
}

/// Writes `ring` in the frame centred at `origin` into `out`; returns its bounding box there and
/// twice its signed area (as [`area2`] computes it). Comparisons ignore NaN in the box; a NaN
/// coordinate still makes the area NaN.
fn load_ring(ring: &[Point], origin: Point, out: &mut Vec<V>) -> (BBox, f64) {
    let to_local = |p: &Point| V {
        x: p.x - origin.x,
        y: p.y - origin.y,
    };
    out.clear();
    let mut bb = BBox {
        x0: f64::INFINITY,
        x1: f64::NEG_INFINITY,
        y0: f64::INFINITY,
        y1: f64::NEG_INFINITY,
    };
    let Some(last) = ring.last() else {
        return (bb, 0.0);
    };
    let mut prev = to_local(last);
    let mut s = 0.0;
    for p in ring {
        let v = to_local(p);
        s += prev.cross(v);
        prev = v;
        bb.x0 = if v.x < bb.x0 { v.x } else { bb.x0 };
        bb.x1 = if v.x > bb.x1 { v.x } else { bb.x1 };
        bb.y0 = if v.y < bb.y0 { v.y } else { bb.y0 };
        bb.y1 = if v.y > bb.y1 { v.y } else { bb.y1 };
        out.push(v);
    }
    (bb, s)
}

/// Twice the signed area of a ring.
fn area2(r: &[V]) -> f64 {
    let Some(&last) = r.last() else {
        return 0.0;
    };
    let mut s = 0.0;
    let mut prev = last;
    for &p in r {
        s += prev.cross(p);
        prev = p;
    }
    s
}

/// Whether `p` is closer than `sqrt(tol2)` to the segment `a`-`b` (`a != b`).
#[inline]
fn near(p: V, a: V, b: V, tol2: f64) -> bool {
    let ab = b.sub(a);
    let ap = p.sub(a);
    let t = (ap.dot(ab) / ab.dot(ab)).clamp(0.0, 1.0);
    let d = V {
        x: ap.x - ab.x * t,
        y: ap.y - ab.y * t,
    };
    d.dot(d) < tol2
}

/// Ray casting (half-open rule); `p` must be well away from the ring's boundary.
fn inside(p: V, r: &[V]) -> bool {
    let n = r.len();
    let mut c = false;
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (r[i], r[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            c = !c;
        }
        j = i;
    }
    c
}

/// One edge of a ring: ring (0 or 1), index of its first vertex.
#[derive(Clone, Copy)]
struct Edge {
    ring: u8,
    i: u32,
    p: V,
    q: V,
    /// Length of the edge.
    len: f64,
}

/// The bounding box of an edge grown by tol (`x` along the sweep axis, `y` across it).
#[derive(Clone, Copy)]
struct SweepBox {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    /// Index into the edge list.
    edge: u32,
    /// Index of the next edge of the same ring in the edge list.
    next: u32,
}

/// A proper crossing of edge `ea` of ring 0 with edge `eb` of ring 1.
#[derive(Clone, Copy)]
struct Cross {
    ea: u32,
    ta: f64,
    eb: u32,
    tb: f64,
    p: V,
    /// The crossing in the caller's coordinates.
    pw: Point,
    /// Ring 0 leaves ring 1 here (so ring 1 enters ring 0).
    a_exits: bool,
}

/// Union of two closed rings (no repeated closing point, finite, at least 3 points each) when
/// both are simple and in general position (see the module doc for the exact rule); `None` asks
/// the caller to use the general overlay. Outer rings counter-clockwise, largest area first,
/// holes dropped, each starting at the predecessor of its smallest `(x, y)` (module doc, step 4).
pub(crate) fn union_two_simple(a: &[Point], b: &[Point]) -> Option<Vec<Vec<Point>>> {
    with_scratch(|sc| union_in(a, b, sc, true))
}

/// [`union_two_simple`] when the union is one polygon without holes (its outer ring); `None`
/// also when the union falls apart or has a hole (a later piece could sit in that hole).
pub(crate) fn union_two_simple_solid(a: &[Point], b: &[Point]) -> Option<Vec<Point>> {
    let mut out = with_scratch(|sc| union_in(a, b, sc, false))?;
    if out.len() == 1 {
        out.pop()
    } else {
        None
    }
}

fn with_scratch<T>(f: impl FnOnce(&mut Scratch) -> T) -> T {
    SCRATCH.with(|sc| match sc.try_borrow_mut() {
        Ok(mut sc) => f(&mut sc),
        Err(_) => f(&mut Scratch::default()),
    })
}

/// Working buffers of [`union_two_simple`], kept per thread so that a merge allocates little
/// more than its output.
#[derive(Default)]
struct Scratch {
    ra: Vec<V>,
    rb: Vec<V>,
    edges: Vec<Edge>,
    boxes: Vec<SweepBox>,
    sorted: Vec<SweepBox>,
    start: Vec<u32>,
    fill: Vec<u32>,
    /// Each box's bucket (in `boxes` order).
    bucket_of: Vec<u32>,
    /// Candidate partners of one box (indices into `sorted`).
    cand: Vec<u32>,
    crosses: Vec<Cross>,
    /// Per ring: crossing ids in order along the ring, and each crossing's place in that order.
    order: [Vec<u32>; 2],
    rank: [Vec<u32>; 2],
    visited: Vec<bool>,
    ring_pts: Vec<Point>,
    outer_pts: Vec<Point>,
    /// The kept vertices in [`finish_ring`].
    kept: Vec<Point>,
    keys: Vec<u128>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// [`union_two_simple`] with the given working buffers.
/// `holes_ok`: whether a union with holes is accepted (they are dropped).
fn union_in(a: &[Point], b: &[Point], sc: &mut Scratch, holes_ok: bool) -> Option<Vec<Vec<Point>>> {
    let Scratch {
        ra,
        rb,
        edges,
        boxes,
        sorted,
        start,
        fill,
        bucket_of,
        cand,
        crosses,
        order,
        rank,
        visited,
        ring_pts,
        outer_pts,
        kept,
        keys,
    } = sc;
    let (n, m) = (a.len(), b.len());
    if n < 3 || m < 3 || n + m > MAX_VERTICES {
        return None;
    }
    // Local frame, joint bounding box and signed areas, in one pass over each ring.
    let origin = a[0];
    let (box_a, mut area_a) = load_ring(a, origin, ra);
    let (box_b, mut area_b) = load_ring(b, origin, rb);
    let (extent, along_x) = box_a.join(&box_b).extent()?;
    let tol = REL_TOL * extent;
    let tol2 = tol * tol;

    // Orientation (counter-clockwise) and non-degenerate area. `orig` maps a vertex of the
    // (possibly reversed) local ring back to the caller's exact coordinates.
    let min_area2 = tol * extent;
    if !(area_a.abs() > min_area2 && area_b.abs() > min_area2) {
        return None;
    }
    let rev_a = area_a < 0.0;
    let rev_b = area_b < 0.0;
    if rev_a {
        ra.reverse();
        area_a = -area_a;
    }
    if rev_b {
        rb.reverse();
        area_b = -area_b;
    }
    let orig = |ring: u8, i: usize| -> Point {
        match (ring, rev_a, rev_b) {
            (0, false, _) => a[i],
            (0, true, _) => a[n - 1 - i],
            (_, _, false) => b[i],
            (_, _, true) => b[m - 1 - i],
        }
    };
    let rings: [&[V]; 2] = [ra, rb];

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
                x0,
                x1: x1 + tol,
                y0: y0 - tol,
                y1: y1 + tol,
                edge: (base + i) as u32,
                next: (base + next) as u32,
            });
        }
        if spike(&edges[base + k - 1], &edges[base]) {
            return None;
        }
    }
    // Candidate pairs: edges whose bounding boxes (grown by tol) overlap. The boxes are bucketed
    // by their start along the sweep axis (a counting sort: `bucket` is monotone in x, so a box
    // overlapping box `e` starts in a bucket between `e`'s and that of `e`'s end). Every pair is
    // met once, from the box that comes first in bucket order.
    let ne = edges.len();
    let nb = ne;
    let scale = nb as f64 / (hi - lo);
    let scale = if scale.is_finite() { scale } else { 0.0 };
    let last_bucket = (nb - 1) as u32;
    // (`as u32` saturates; the argument is never negative: `x >= lo`.)
    let bucket = |x: f64| (((x - lo) * scale) as u32).min(last_bucket) as usize;
    // `start[b]..start[b + 1]`: the boxes of bucket `b` in `sorted`.
    start.clear();
    start.resize(nb + 1, 0);
    bucket_of.clear();
    for bx in boxes.iter() {
        let b = bucket(bx.x0);
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

    // The overlap test is branch-free (whether two boxes overlap is data-dependent, and a
    // mispredicted branch per pair costs more than the test): candidates are written to a buffer
    // and kept by advancing its length.
    crosses.clear();
    cand.clear();
    cand.resize(ne, 0);
    for (k, be) in sorted.iter().enumerate() {
        let end = start[bucket(be.x1) + 1] as usize;
        let mut nc = 0usize;
        // `end > k`: a box's own bucket is at most its end's bucket.
        for (bf, j) in sorted.get(k + 1..end).unwrap_or(&[]).iter().zip(k + 1..) {
            let keep = (bf.y0 <= be.y1)
                & (be.y0 <= bf.y1)
                & (bf.x0 <= be.x1)
                & (be.x0 <= bf.x1)
                & (bf.edge != be.next)
                & (be.edge != bf.next);
            cand[nc] = j as u32;
            nc += usize::from(keep);
        }
        for &j in &cand[..nc] {
            let bf = &sorted[j as usize];
            // Not neighbours (tested above).
            let (e, f) = (&edges[be.edge as usize], &edges[bf.edge as usize]);
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
                continue;
            }
            if e.ring == f.ring {
                return None; // self-crossing ring
            }
            // All four are well away from zero here (each endpoint is >= tol from the other
            // segment and the crossing is proper), so both denominators are non-zero.
            let (ea, ta, eb, tb, da, db, pa) = if e.ring == 0 {
                (
                    e.i,
                    d1 / (d1 - d2),
                    f.i,
                    d3 / (d3 - d4),
                    p2.sub(p1),
                    q2.sub(q1),
                    p1,
                )
            } else {
                (
                    f.i,
                    d3 / (d3 - d4),
                    e.i,
                    d1 / (d1 - d2),
                    q2.sub(q1),
                    p2.sub(p1),
                    q1,
                )
            };
            if !(ta > 0.0 && ta < 1.0 && tb > 0.0 && tb < 1.0) {
                return None;
            }
            let p = V {
                x: pa.x + da.x * ta,
                y: pa.y + da.y * ta,
            };
            // On an axis-parallel edge the crossing keeps that edge's exact coordinate (i_overlay
            // keeps it too: the edge lies on a grid line), so that runs along axis-parallel edges
            // and lowest-left ties are seen as i_overlay sees them.
            let (wa, wb) = (orig(0, ea as usize), orig(1, eb as usize));
            let pw = Point::new(
                if da.x == 0.0 {
                    wa.x
                } else if db.x == 0.0 {
                    wb.x
                } else {
                    p.x + origin.x
                },
                if da.y == 0.0 {
                    wa.y
                } else if db.y == 0.0 {
                    wb.y
                } else {
                    p.y + origin.y
                },
            );
            crosses.push(Cross {
                ea,
                ta,
                eb,
                tb,
                p,
                pw,
                a_exits: da.cross(db) > 0.0,
            });
        }
    }

    if crosses.is_empty() {
        let rings_out: &[u8] = if inside(ra[0], rb) {
            &[1]
        } else if inside(rb[0], ra) {
            &[0]
        } else if area_a >= area_b {
            &[0, 1]
        } else {
            &[1, 0]
        };
        let mut out = Vec::with_capacity(rings_out.len());
        for &ring in rings_out {
            ring_pts.clear();
            ring_pts.extend((0..rings[ring as usize].len()).map(|i| orig(ring, i)));
            out.push(finish_ring(ring_pts, kept)?);
        }
        return Some(out);
    }
    if crosses.len() % 2 != 0 {
        return None;
    }

    // The crossings in order along each ring (by edge, then by parameter along the edge); two
    // crossings on one edge must be at least tol apart, and exits and entries must alternate.
    let nc = crosses.len();
    for ring in 0..2 {
        let (ord, rk) = (&mut order[ring], &mut rank[ring]);
        let key = |c: &Cross| {
            if ring == 0 {
                (c.ea, c.ta)
            } else {
                (c.eb, c.tb)
            }
        };
        // Sort keys `(edge, t, id)` packed in one integer: `t` lies in (0, 1), where the bits of
        // a positive f64 sort as the number does.
        keys.clear();
        keys.extend(crosses.iter().enumerate().map(|(id, c)| {
            let (e, t) = key(c);
            (u128::from(e) << 96) | (u128::from(t.to_bits()) << 32) | id as u128
        }));
        keys.sort_unstable();
        ord.clear();
        ord.extend(keys.iter().map(|&k| k as u32));
        rk.clear();
        rk.resize(nc, 0);
        let r = rings[ring];
        for (k, w) in ord.windows(2).enumerate() {
            let (c0, c1) = (&crosses[w[0] as usize], &crosses[w[1] as usize]);
            let ((e0, t0), (e1, t1)) = (key(c0), key(c1));
            if e0 == e1 {
                let iu = e0 as usize;
                let q = if iu + 1 == r.len() { r[0] } else { r[iu + 1] };
                let d = q.sub(r[iu]);
                if (t1 - t0) * (t1 - t0) * d.dot(d) < tol2 {
                    return None;
                }
            }
            if c0.a_exits == c1.a_exits {
                return None;
            }
            rk[w[1] as usize] = k as u32 + 1;
        }
    }

    // Trace the loops.
    visited.clear();
    visited.resize(nc, false);
    // Twice the area of the outer loop, whose points are kept in `outer_pts`.
    let mut outer: Option<f64> = None;
    let mut holes_area2 = 0.0;
    let max_steps = n + m + 2 * nc + 1;
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
                ring_pts.push(orig(ring as u8, i));
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
    let outer_area2 = outer?;
    let union2 = outer_area2 + holes_area2;
    let slack = 2.0 * tol * extent;
    if !(union2 >= area_a.max(area_b) - slack && union2 <= area_a + area_b + slack) {
        return None;
    }
    Some(vec![finish_ring(outer_pts, ring_pts)?])
}

/// Drops the inner vertices of axis-parallel runs and rotates the ring to start where i_overlay
/// starts its contours (the predecessor of the lowest-left vertex). `None` when that choice is
/// not certain on i_overlay's grid: another vertex's x within a hair of the smallest x, or the
/// start or lowest-left vertex within a hair of the line through its neighbours (i_overlay could
/// drop it as collinear); also when fewer than 3 vertices remain.
///
/// One pass writes the kept vertices to `kept` (a working buffer) and finds their bounding box,
/// the lowest-left one and the smallest x above the smallest; the output (one allocation) is
/// `kept` rotated to the start.
fn finish_ring(ring: &[Point], kept: &mut Vec<Point>) -> Option<Vec<Point>> {
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

/// Whether a closed ring (no repeated closing point, finite) is clearly simple: at least 3
/// vertices, area well away from zero, no edge shorter than `tol`, no spike, and any two
/// non-neighbouring edges at least `tol` apart, with `tol = 1e-7 * extent` of the ring's own
/// bounding box (the same rule [`union_two_simple`] applies to each of its rings). Such a ring is
/// its own resolution: the overlay's `unary_union` of it gives back the same polygon up to its
/// grid snapping. `false` asks for the overlay.
pub(crate) fn ring_is_simple(ring: &[Point]) -> bool {
    let k = ring.len();
    if !(3..=MAX_VERTICES).contains(&k) {
        return false;
    }
    let o = ring[0];
    let r: Vec<V> = ring
        .iter()
        .map(|p| V {
            x: p.x - o.x,
            y: p.y - o.y,
        })
        .collect();
    let Some((extent, _)) = extent_of(r.iter()) else {
        return false;
    };
    let tol = REL_TOL * extent;
    let tol2 = tol * tol;
    let a2 = area2(&r).abs();
    if a2.is_nan() || a2 <= tol * extent {
        return false;
    }
    let nx = |i: usize| if i + 1 == k { 0 } else { i + 1 };
    let mut lens = Vec::with_capacity(k);
    for i in 0..k {
        let d = r[nx(i)].sub(r[i]);
        let l2 = d.dot(d);
        if l2 < tol2 {
            return false;
        }
        lens.push(l2.sqrt());
    }
    // Spikes: the far end of a neighbouring edge near the other edge.
    for i in 0..k {
        let (p, v, q) = (r[i], r[nx(i)], r[nx(nx(i))]);
        let c = v.sub(p).cross(q.sub(v)).abs();
        if c <= tol * lens[i].max(lens[nx(i)]) * NEAR_MARGIN
            && (near(q, p, v, tol2) || near(p, v, q, tol2))
        {
            return false;
        }
    }
    // Other pairs: a sweep along x over the edges sorted by their smallest x (grown by tol).
    let mut idx: Vec<(f64, f64, u32)> = (0..k)
        .map(|i| {
            let (p, q) = (r[i], r[nx(i)]);
            (p.x.min(q.x) - tol, p.x.max(q.x) + tol, i as u32)
        })
        .collect();
    idx.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    for (s, &(_, ex1, ie)) in idx.iter().enumerate() {
        let ie = ie as usize;
        let (p1, p2) = (r[ie], r[nx(ie)]);
        let (ey0, ey1) = (p1.y.min(p2.y) - tol, p1.y.max(p2.y) + tol);
        for &(fx0, _, jf) in &idx[s + 1..] {
            if fx0 > ex1 {
                break;
            }
            let jf = jf as usize;
            if jf == nx(ie) || ie == nx(jf) {
                continue;
            }
            let (q1, q2) = (r[jf], r[nx(jf)]);
            if q1.y.max(q2.y) + tol < ey0 || q1.y.min(q2.y) - tol > ey1 {
                continue;
            }
            let (dp, dq) = (p2.sub(p1), q2.sub(q1));
            let d1 = dq.cross(p1.sub(q1));
            let d2 = dq.cross(p2.sub(q1));
            let d3 = dp.cross(q1.sub(p1));
            let d4 = dp.cross(q2.sub(p1));
            let (lq, lp) = (tol * lens[jf] * NEAR_MARGIN, tol * lens[ie] * NEAR_MARGIN);
            if (d1.abs() <= lq && near(p1, q1, q2, tol2))
                || (d2.abs() <= lq && near(p2, q1, q2, tol2))
                || (d3.abs() <= lp && near(q1, p1, p2, tol2))
                || (d4.abs() <= lp && near(q2, p1, p2, tol2))
            {
                return false;
            }
            if (d1 > 0.0) != (d2 > 0.0) && (d3 > 0.0) != (d4 > 0.0) {
                return false;
            }
        }
    }
    true
}
