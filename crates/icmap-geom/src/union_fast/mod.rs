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
//! `None` (use the general overlay) on: more than [`MAX_VERTICES`] vertices in all, a joint
//! extent so small that `tol^2` is not a normal float (below about 1e-147 m), a ring with
//! (nearly) zero area or an edge shorter than `tol`, a ring that is not simple or has a spike,
//! any two features of different rings closer than `tol` without a proper crossing between them
//! (touching, shared or collinear edges, a crossing near a vertex), two crossings closer than
//! `tol` on one edge, an odd number of crossings, crossings that do not alternate in and out
//! along a ring, a traversal that does not close, not exactly one outer loop, a union area outside
//! `[max(area), area_a + area_b]`, or an output start that i_overlay could choose differently
//! (two lowest-left candidates whose x differ by less than `tol`, or a start or lowest-left vertex
//! within `tol` of the line through its neighbours).
//!
//! # Files
//!
//! One step per file: `primitives` (vectors, boxes, distance and point-in-ring tests), `edges`
//! (edges, spike test, sweep boxes), `crossings` (the sweep), `order` (crossings along each
//! ring), `trace` (the union's boundary), `finish` (output convention), `simple`
//! ([`ring_is_simple`]); this file holds the entry points and the working buffers.

mod crossings;
mod edges;
mod finish;
mod order;
mod primitives;
mod simple;
#[cfg(test)]
mod test_util;
mod trace;

pub(crate) use simple::ring_is_simple;

use crate::clip::inside_ring;
use crate::types::Point;
use crossings::{find_crossings, Cross, SweepBuffers};
use edges::{build_edges, Edge, SweepBox};
use finish::finish_ring;
use order::order_along_rings;
use primitives::{load_ring, V};
use trace::trace_loops;

/// Above this many vertices in all the general overlay is used (the sweep is quadratic in the
/// worst case, i_overlay is not).
pub(crate) const MAX_VERTICES: usize = 2048;

/// Relative distance (to the joint extent) under which two features count as touching.
const REL_TOL: f64 = 1e-7;

/// Slack on the cheap lower bounds that decide whether the exact distance test [`near`] is
/// needed: a bound within rounding of `tol` still runs the exact test.
const NEAR_MARGIN: f64 = 1.0 + 1e-9;

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

#[derive(Default)]
struct Scratch {
    ra: Vec<V>,
    rb: Vec<V>,
    edges: Vec<Edge>,
    boxes: Vec<SweepBox>,
    sweep: SweepBuffers,
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

/// The caller's two rings as the local frame sees them: its origin (the first vertex of `a`) and
/// whether each ring was reversed (to counter-clockwise).
struct Source<'a> {
    a: &'a [Point],
    b: &'a [Point],
    origin: Point,
    rev_a: bool,
    rev_b: bool,
}

impl Source<'_> {
    /// Vertex `i` of the (possibly reversed) local ring `ring` in the caller's exact coordinates.
    #[inline]
    fn orig(&self, ring: u8, i: usize) -> Point {
        match (ring, self.rev_a, self.rev_b) {
            (0, false, _) => self.a[i],
            (0, true, _) => self.a[self.a.len() - 1 - i],
            (_, _, false) => self.b[i],
            (_, _, true) => self.b[self.b.len() - 1 - i],
        }
    }
}

/// [`union_two_simple`] with the given working buffers: the steps of the module doc in order.
/// `holes_ok`: whether a union with holes is accepted (they are dropped).
fn union_in(a: &[Point], b: &[Point], sc: &mut Scratch, holes_ok: bool) -> Option<Vec<Vec<Point>>> {
    let Scratch {
        ra,
        rb,
        edges,
        boxes,
        sweep,
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
    // Step 1: local frame, joint bounding box and signed areas, in one pass over each ring.
    let origin = a[0];
    let (box_a, mut area_a) = load_ring(a, origin, ra);
    let (box_b, mut area_b) = load_ring(b, origin, rb);
    let (extent, along_x) = box_a.join(&box_b).extent()?;
    let tol = REL_TOL * extent;
    let tol2 = tol * tol;
    if tol2 < f64::MIN_POSITIVE {
        return None; // so small that distances squared lose their digits (subnormal)
    }

    // Orientation (counter-clockwise) and non-degenerate area. `src.orig` maps a vertex of the
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
    let src = Source {
        a,
        b,
        origin,
        rev_a,
        rev_b,
    };
    let rings: [&[V]; 2] = [ra, rb];

    // Step 2: edges, then the sweep for crossings.
    let range = build_edges(&rings, tol, along_x, edges, boxes)?;
    find_crossings(edges, boxes, range, tol, &src, sweep, crosses)?;
    if crosses.is_empty() {
        return disjoint_or_nested(&rings, [area_a, area_b], &src, ring_pts, kept);
    }
    if crosses.len() % 2 != 0 {
        return None;
    }

    // Step 3: the crossings in order along each ring, then the union's boundary.
    order_along_rings(&rings, crosses, tol2, order, rank, keys)?;
    let (outer_area2, holes_area2) = trace_loops(
        &rings, crosses, order, rank, &src, holes_ok, visited, ring_pts, outer_pts,
    )?;
    let union2 = outer_area2 + holes_area2;
    let slack = 2.0 * tol * extent;
    if !(union2 >= area_a.max(area_b) - slack && union2 <= area_a + area_b + slack) {
        return None;
    }
    // Step 4: the output convention.
    Some(vec![finish_ring(outer_pts, ring_pts)?])
}

/// The union of two rings without crossings (each vertex at least `tol` from the other ring):
/// the containing ring, or both, largest first.
fn disjoint_or_nested(
    rings: &[&[V]; 2],
    [area_a, area_b]: [f64; 2],
    src: &Source<'_>,
    ring_pts: &mut Vec<Point>,
    kept: &mut Vec<Point>,
) -> Option<Vec<Vec<Point>>> {
    let [ra, rb] = *rings;
    let rings_out: &[u8] = if inside_ring(ra[0], rb) {
        &[1]
    } else if inside_ring(rb[0], ra) {
        &[0]
    } else if area_a >= area_b {
        &[0, 1]
    } else {
        &[1, 0]
    };
    let mut out = Vec::with_capacity(rings_out.len());
    for &ring in rings_out {
        ring_pts.clear();
        ring_pts.extend((0..rings[ring as usize].len()).map(|i| src.orig(ring, i)));
        out.push(finish_ring(ring_pts, kept)?);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::test_util::{seg_dist, star, Rng};
    use super::*;
    use crate::clip::signed_area2;
    use geo::{Area, BooleanOps, Coord, LineString, Polygon};

    fn to_geo(r: &[Point]) -> Polygon<f64> {
        let coords: Vec<Coord<f64>> = r.iter().map(|p| Coord { x: p.x, y: p.y }).collect();
        Polygon::new(LineString::new(coords), vec![])
    }

    /// The fast union against geo's overlay (i_overlay) on random pairs of star-shaped (simple)
    /// polygons, overlapping, nested or apart: whenever the fast path answers, it gives as many
    /// rings as the overlay, each counter-clockwise with the overlay's exterior area (to its grid
    /// rounding), every vertex on an input boundary, starting at the predecessor of the
    /// lowest-left vertex.
    #[test]
    fn agrees_with_geo_on_random_star_polygons() {
        let (mut taken, total) = (0, 400);
        for seed in 0..total {
            let mut rng = Rng(seed);
            let ka = 3 + (rng.next() * 40.0) as usize;
            let kb = 3 + (rng.next() * 40.0) as usize;
            let (ox, oy) = (rng.uniform(-100.0, 100.0), rng.uniform(-100.0, 100.0));
            let a = star(&mut rng, ox, oy, ka, rng_r(seed));
            let (dx, dy) = (rng.uniform(-9.0, 9.0), rng.uniform(-9.0, 9.0));
            let b = star(&mut rng, ox + dx, oy + dy, kb, rng_r(seed + 7));
            let Some(fast) = union_two_simple(&a, &b) else {
                continue;
            };
            taken += 1;
            let slow = to_geo(&a).union(&to_geo(&b));
            let mut want: Vec<f64> = slow
                .0
                .iter()
                .map(|p| {
                    to_geo(
                        &p.exterior()
                            .0
                            .iter()
                            .map(|c| Point::new(c.x, c.y))
                            .collect::<Vec<_>>(),
                    )
                    .unsigned_area()
                })
                .collect();
            want.sort_by(|x, y| y.total_cmp(x));
            assert_eq!(fast.len(), want.len(), "seed {seed}: ring count");
            let extent = a
                .iter()
                .chain(&b)
                .fold(0.0f64, |e, p| e.max((p.x - ox).abs()).max((p.y - oy).abs()))
                * 2.0;
            for (r, &w) in fast.iter().zip(&want) {
                let got = 0.5 * signed_area2(r);
                assert!(got > 0.0, "seed {seed}: clockwise");
                let perim: f64 = (0..r.len())
                    .map(|i| (r[(i + 1) % r.len()] - r[i]).norm())
                    .sum();
                let grid = extent * 2f64.powi(-29);
                assert!(
                    (got - w).abs() <= (1e-9 * w).max(perim * grid),
                    "seed {seed}: area {got} vs {w}"
                );
                for q in r {
                    let on = [&a, &b].iter().any(|s| {
                        (0..s.len())
                            .any(|i| seg_dist(*q, s[i], s[(i + 1) % s.len()]) < 1e-9 * extent)
                    });
                    assert!(on, "seed {seed}: vertex {q} off the input boundaries");
                }
                let low = (0..r.len())
                    .min_by(|&i, &j| (r[i].x, r[i].y).partial_cmp(&(r[j].x, r[j].y)).unwrap())
                    .unwrap();
                assert_eq!(low, 1 % r.len(), "seed {seed}: start");
            }
        }
        assert!(
            taken * 10 >= total as usize * 8,
            "fast path taken {taken} / {total}"
        );
    }

    fn rng_r(seed: u64) -> f64 {
        Rng(seed ^ 0x5555).uniform(2.0, 10.0)
    }

    #[test]
    fn solid_variant_declines_unions_that_are_not_one_polygon() {
        let sq = |x0: f64, y0: f64, s: f64| {
            vec![
                Point::new(x0, y0),
                Point::new(x0 + s, y0),
                Point::new(x0 + s, y0 + s),
                Point::new(x0, y0 + s),
            ]
        };
        // Apart: two rings (largest first) from the plain variant, none from the solid one.
        let (a, b) = (sq(0.0, 0.0, 1.0), sq(5.0, 0.5, 2.0));
        let two = union_two_simple(&a, &b).unwrap();
        assert_eq!(two.len(), 2);
        assert!(signed_area2(&two[0]) > signed_area2(&two[1]));
        assert!(union_two_simple_solid(&a, &b).is_none());
        // Overlapping: one ring from both.
        let c = sq(0.5, 0.25, 1.0);
        let one = union_two_simple_solid(&a, &c).unwrap();
        assert_eq!(vec![one], union_two_simple(&a, &c).unwrap());
        // Too few or too many vertices: declined.
        assert!(union_two_simple(&a[..2], &c).is_none());
        let many: Vec<Point> = (0..MAX_VERTICES)
            .map(|i| {
                let t = i as f64 / MAX_VERTICES as f64 * std::f64::consts::TAU;
                Point::new(t.cos(), t.sin())
            })
            .collect();
        assert!(union_two_simple(&many, &c).is_none());
    }
}
