//! [`ring_is_simple`]: whether one ring is clearly simple (the fast path's rule for one ring).

use super::primitives::{area2, extent_of, near, V};
use super::{MAX_VERTICES, NEAR_MARGIN, REL_TOL};
use crate::types::Point;

/// Whether a closed ring (no repeated closing point, finite) is clearly simple: at least 3
/// vertices, an extent whose `tol^2` is a normal float, area well away from zero, no edge shorter
/// than `tol`, no spike, and any two non-neighbouring edges at least `tol` apart, with
/// `tol = 1e-7 * extent` of the ring's own bounding box (the same rule
/// [`union_two_simple`](super::union_two_simple) applies to each of its rings). Such a ring is
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
    if tol2 < f64::MIN_POSITIVE {
        return false;
    }
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

#[cfg(test)]
mod tests {
    use super::super::test_util::{cross_properly, seg_dist, Rng};
    use super::*;

    /// Random polygons (vertices anywhere in a box, so often self-crossing): `ring_is_simple`
    /// accepts only rings without crossing or touching non-neighbouring edges (brute force over
    /// all pairs), and accepts every ring whose features keep well apart.
    #[test]
    fn agrees_with_brute_force_on_random_polygons() {
        let (mut simple, mut not) = (0, 0);
        for seed in 0..3000 {
            let mut rng = Rng(seed);
            let k = 3 + (seed % 6) as usize;
            let r: Vec<Point> = (0..k)
                .map(|_| Point::new(rng.uniform(0.0, 10.0), rng.uniform(0.0, 10.0)))
                .collect();
            let e = |i: usize| (r[i], r[(i + 1) % k]);
            // The smallest distance between non-neighbouring edges, and whether any two cross.
            let mut crossing = false;
            let mut gap = f64::INFINITY;
            for i in 0..k {
                for j in i + 1..k {
                    if j == i + 1 || (i == 0 && j == k - 1) {
                        continue;
                    }
                    let ((p1, p2), (q1, q2)) = (e(i), e(j));
                    crossing |= cross_properly(p1, p2, q1, q2);
                    for d in [
                        seg_dist(p1, q1, q2),
                        seg_dist(p2, q1, q2),
                        seg_dist(q1, p1, p2),
                        seg_dist(q2, p1, p2),
                    ] {
                        gap = gap.min(d);
                    }
                }
            }
            let span = |f: fn(&Point) -> f64| {
                let (lo, hi) = r
                    .iter()
                    .map(f)
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                        (lo.min(v), hi.max(v))
                    });
                hi - lo
            };
            let extent = span(|p| p.x).max(span(|p| p.y));
            let got = ring_is_simple(&r);
            if got {
                simple += 1;
                assert!(
                    !crossing && gap >= 1e-7 * extent * (1.0 - 1e-9),
                    "seed {seed}: {r:?}"
                );
            } else {
                not += 1;
            }
            // Well apart, no spike, no tiny area: must be accepted.
            let min_angle_ok = (0..k).all(|i| {
                let (a, b, c) = (r[(i + k - 1) % k], r[i], r[(i + 1) % k]);
                ((a - b).normalize().perp(&(c - b).normalize())).abs() > 1e-3
            });
            if !crossing && gap > 1e-3 && min_angle_ok {
                assert!(got, "seed {seed}: simple ring refused {r:?}");
            }
        }
        assert!(simple > 500 && not > 500, "{simple} / {not}");
    }
}
