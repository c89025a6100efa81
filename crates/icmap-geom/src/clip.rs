//! Clipping of polylines and polygons to an oriented patch, and even sampling of the clipped pieces
//! (Algorithm 1 of IC-Mapper).
//!
//! The clipping is done in the patch's ego frame (where the patch is the axis-aligned box
//! `|x| <= hx, |y| <= hy`) and the results are interpolated in the world frame, so that vertices
//! inside the patch come back bit-for-bit unchanged.

use crate::error::{GeomError, Result};
use crate::resample::{cumulative_lengths, points_at_lengths, polyline_length};
use crate::types::{in_domain, validate_points, Patch, Point};

/// Whether `p` lies in the coordinate domain ([`crate::types::MAX_COORD`]; NaN and inf do not).
fn finite(p: &Point) -> bool {
    in_domain(p.x) && in_domain(p.y)
}

/// Liang-Barsky: the parameter range `[t0, t1]` of the ego-frame segment `a -> b` inside the box
/// `|x| <= hx, |y| <= hy`, or `None` when the segment misses it.
fn liang_barsky(a: &Point, b: &Point, hx: f64, hy: f64) -> Option<(f64, f64)> {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let mut t0 = 0.0f64;
    let mut t1 = 1.0f64;
    for (p, q) in [
        (-dx, a.x + hx),
        (dx, hx - a.x),
        (-dy, a.y + hy),
        (dy, hy - a.y),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    // Also rejects NaN parameters (a NaN comparison is false).
    if t0 <= t1 {
        Some((t0, t1))
    } else {
        None
    }
}

/// Moves a finished piece into `pieces` if it has positive length.
fn flush(cur: &mut Vec<Point>, pieces: &mut Vec<Vec<Point>>) {
    if cur.len() >= 2 && polyline_length(cur, false) > 0.0 {
        pieces.push(std::mem::take(cur));
    } else {
        cur.clear();
    }
}

/// The parts of an open polyline inside `patch`, in world coordinates, in the polyline's order.
/// Each piece has at least 2 points (entry/exit points are exact segment-rectangle intersections)
/// and positive length (pieces that only touch the patch are dropped). Vertices inside the patch
/// are returned unchanged. Segments with an end point outside the coordinate domain (non-finite
/// or beyond [`MAX_COORD`](crate::types::MAX_COORD)) are treated as outside; a patch that
/// [`Patch::new`] would refuse contains nothing.
pub fn clip_polyline(points: &[Point], patch: &Patch) -> Vec<Vec<Point>> {
    if !patch.is_valid() {
        return Vec::new();
    }
    let (hx, hy) = (patch.half_extents.x, patch.half_extents.y);
    let iso = patch.pose.isometry();
    // Every vertex inside (the common case for a patch with a margin): Liang-Barsky keeps every
    // segment whole (t0 = 0, t1 = 1 exactly), so the one piece is the polyline itself.
    if points.len() >= 2
        && points.iter().all(|p| {
            let e = iso.inverse_transform_point(p);
            e.x.abs() <= hx && e.y.abs() <= hy && finite(p)
        })
    {
        let mut pieces = Vec::new();
        flush(&mut points.to_vec(), &mut pieces);
        return pieces;
    }
    clip_polyline_by_segments(points, patch, true)
}

/// [`clip_polyline`] segment by segment (Liang-Barsky), without the all-inside shortcut;
/// `reject`: skip Liang-Barsky for a segment with both ends beyond the same side of the patch (it
/// misses the patch, or touches it in a zero-length fragment that is dropped anyway).
fn clip_polyline_by_segments(points: &[Point], patch: &Patch, reject: bool) -> Vec<Vec<Point>> {
    let (hx, hy) = (patch.half_extents.x, patch.half_extents.y);
    // The pose's rotation once (`Pose2::to_ego` would evaluate sin/cos for every point).
    let iso = patch.pose.isometry();
    let to_ego = |p: &Point| iso.inverse_transform_point(p);
    let mut pieces = Vec::new();
    let mut cur: Vec<Point> = Vec::new();
    let mut prev_ego: Option<Point> = None;
    for (i, w) in points.windows(2).enumerate() {
        let (a, b) = (w[0], w[1]);
        if !(finite(&a) && finite(&b)) {
            flush(&mut cur, &mut pieces);
            prev_ego = None;
            continue;
        }
        let ae = match prev_ego {
            Some(e) if i > 0 => e,
            _ => to_ego(&a),
        };
        let be = to_ego(&b);
        prev_ego = Some(be);
        if reject
            && ((ae.x > hx && be.x > hx)
                || (ae.x < -hx && be.x < -hx)
                || (ae.y > hy && be.y > hy)
                || (ae.y < -hy && be.y < -hy))
        {
            flush(&mut cur, &mut pieces);
            continue;
        }
        match liang_barsky(&ae, &be, hx, hy) {
            None => flush(&mut cur, &mut pieces),
            Some((t0, t1)) => {
                let pa = if t0 <= 0.0 { a } else { a + (b - a) * t0 };
                let pb = if t1 >= 1.0 { b } else { a + (b - a) * t1 };
                if t0 > 0.0 || cur.is_empty() {
                    flush(&mut cur, &mut pieces);
                    cur.push(pa);
                }
                cur.push(pb);
                if t1 < 1.0 {
                    flush(&mut cur, &mut pieces);
                }
            }
        }
    }
    flush(&mut cur, &mut pieces);
    pieces
}

/// A ring without a repeated closing point.
pub(crate) fn open_ring(ring: &[Point]) -> &[Point] {
    if ring.len() >= 2 && ring[0] == ring[ring.len() - 1] {
        &ring[..ring.len() - 1]
    } else {
        ring
    }
}

/// A 2-D point type the ring helpers read: its coordinates.
pub(crate) trait Xy: Copy {
    fn xy(self) -> (f64, f64);
}

impl Xy for Point {
    #[inline]
    fn xy(self) -> (f64, f64) {
        (self.x, self.y)
    }
}

/// Whether `p` lies inside `ring` (ray casting, even-odd rule; a ring without a repeated point,
/// `p` well away from its boundary for a sure answer).
pub(crate) fn inside_ring<T: Xy>(p: T, ring: &[T]) -> bool {
    let (px, py) = p.xy();
    let n = ring.len();
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let ((ax, ay), (bx, by)) = (ring[i].xy(), ring[j].xy());
        if (ay > py) != (by > py) && px < (bx - ax) * (py - ay) / (by - ay) + ax {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Twice the signed area of a ring (positive when counter-clockwise).
pub fn signed_area2(ring: &[Point]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum()
}

/// A closed ring clipped to `patch` (the patch is convex: Sutherland-Hodgman), world coordinates,
/// without repeating the first point. A repeated closing point in the input is ignored. Empty when
/// the ring lies outside the patch, when the clipped ring has no area, or when the ring has fewer
/// than 3 points or a coordinate outside the domain (non-finite or beyond
/// [`MAX_COORD`](crate::types::MAX_COORD)), or when [`Patch::new`] would refuse the patch.
pub fn clip_polygon(ring: &[Point], patch: &Patch) -> Vec<Point> {
    if !patch.is_valid() {
        return Vec::new();
    }
    clip_polygon_impl(ring, patch, true)
}

/// [`clip_polygon`]; `shortcut`: skip the clip edges when every vertex is inside (they would keep
/// the ring as it is).
fn clip_polygon_impl(ring: &[Point], patch: &Patch, shortcut: bool) -> Vec<Point> {
    let ring = open_ring(ring);
    if ring.len() < 3 || !ring.iter().all(finite) {
        return Vec::new();
    }
    let (hx, hy) = (patch.half_extents.x, patch.half_extents.y);
    // (world, ego) pairs.
    let iso = patch.pose.isometry();
    let mut poly: Vec<(Point, Point)> = ring
        .iter()
        .map(|p| (*p, iso.inverse_transform_point(p)))
        .collect();
    // Each clip edge: signed distance inside (>= 0 inside) as a function of the ego point.
    let edges: [fn(&Point, f64, f64) -> f64; 4] = [
        |e, hx, _| hx - e.x,
        |e, hx, _| e.x + hx,
        |e, _, hy| hy - e.y,
        |e, _, hy| e.y + hy,
    ];
    // Every vertex inside: each clip edge keeps the ring as it is.
    let all_inside = shortcut && poly.iter().all(|(_, e)| e.x.abs() <= hx && e.y.abs() <= hy);
    for f in edges {
        if poly.is_empty() || all_inside {
            break;
        }
        let n = poly.len();
        let mut out = Vec::with_capacity(n + 4);
        for i in 0..n {
            let cur = poly[i];
            let prev = poly[(i + n - 1) % n];
            let fc = f(&cur.1, hx, hy);
            let fp = f(&prev.1, hx, hy);
            let cross = |prev: (Point, Point), cur: (Point, Point)| {
                let t = fp / (fp - fc);
                (prev.0 + (cur.0 - prev.0) * t, prev.1 + (cur.1 - prev.1) * t)
            };
            if fc >= 0.0 {
                if fp < 0.0 {
                    out.push(cross(prev, cur));
                }
                out.push(cur);
            } else if fp >= 0.0 {
                out.push(cross(prev, cur));
            }
        }
        poly = out;
    }
    let mut world: Vec<Point> = Vec::with_capacity(poly.len());
    for (w, _) in poly {
        if world.last() != Some(&w) {
            world.push(w);
        }
    }
    while world.len() > 1 && world[0] == world[world.len() - 1] {
        world.pop();
    }
    if world.len() < 3 || signed_area2(&world) == 0.0 {
        return Vec::new();
    }
    world
}

/// Splits `total` integer units over items proportionally to `quotas` (largest remainder), each
/// item getting at least 1 (the caller guarantees `total >= quotas.len()`).
fn apportion(quotas: &[f64], total: usize) -> Vec<usize> {
    let mut counts: Vec<usize> = quotas.iter().map(|q| (q.floor() as usize).max(1)).collect();
    let mut sum: usize = counts.iter().sum();
    while sum < total {
        // Give one to the item furthest below its quota.
        let i = (0..counts.len())
            .max_by(|&i, &j| {
                (quotas[i] - counts[i] as f64).total_cmp(&(quotas[j] - counts[j] as f64))
            })
            .unwrap_or(0);
        counts[i] += 1;
        sum += 1;
    }
    while sum > total {
        // Take one from the item furthest above its quota that can spare one.
        let Some(i) = (0..counts.len())
            .filter(|&i| counts[i] > 1)
            .max_by(|&i, &j| {
                (counts[i] as f64 - quotas[i]).total_cmp(&(counts[j] as f64 - quotas[j]))
            })
        else {
            break;
        };
        counts[i] -= 1;
        sum -= 1;
    }
    counts
}

/// `count` points of one piece: open pieces keep both ends (one point: the arc-length midpoint),
/// rings start at their first point and go around (closing edge included).
fn sample_piece(piece: &[Point], count: usize, closed: bool) -> Vec<Point> {
    let mut pts = piece.to_vec();
    if closed {
        pts.push(piece[0]);
    }
    let cum = cumulative_lengths(&pts);
    let len = cum[cum.len() - 1];
    let targets: Vec<f64> = if closed {
        (0..count).map(|j| len * j as f64 / count as f64).collect()
    } else if count == 1 {
        vec![0.5 * len]
    } else {
        (0..count)
            .map(|j| len * j as f64 / (count - 1) as f64)
            .collect()
    };
    let mut out = points_at_lengths(&pts, &cum, &targets);
    if !closed && count >= 2 {
        out[0] = piece[0];
        out[count - 1] = piece[piece.len() - 1];
    }
    out
}

/// Samples clipped geometry evenly to exactly `n` points.
///
/// Several pieces are sampled jointly: the `n` points are spread over the total length of all
/// pieces, in the pieces' order, so the spacing is the same on every piece (every piece of positive
/// length gets at least one point while `n` allows). Returns the points and a connectivity mask of
/// the same length: `mask[j]` is true iff point `j` and point `j + 1` lie on the same piece (for a
/// single closed ring the last entry is true: it connects back to the first point). Returns `None`
/// when the pieces have zero total length.
///
/// Details: an open piece with `c >= 2` points keeps both its ends (spacing `L_i / (c - 1)`), with
/// `c = 1` it gets its arc-length midpoint; the counts are `1 + (n - P) L_i / L` rounded by largest
/// remainder (P pieces of positive length, total length L). With `closed`, every piece is a ring
/// (closing edge included) sampled from its first point with `c_i ~ n L_i / L` points. When there
/// are more pieces than points, the `n` longest pieces get one point each. Zero-length pieces get
/// no points. Errors on points outside the coordinate domain and on `n < 2` (`n < 3` for closed).
pub fn sample_pieces(
    pieces: &[Vec<Point>],
    closed: bool,
    n: usize,
) -> Result<Option<(Vec<Point>, Vec<bool>)>> {
    for piece in pieces {
        validate_points(piece, 0, "clipped piece")?;
    }
    let min_n = if closed { 3 } else { 2 };
    if n < min_n {
        return Err(GeomError::InvalidParameter {
            name: "n",
            reason: format!("must be >= {min_n}, got {n}"),
        });
    }
    let lens: Vec<f64> = pieces
        .iter()
        .map(|p| {
            if p.len() >= 2 {
                polyline_length(p, closed)
            } else {
                0.0
            }
        })
        .collect();
    let total: f64 = lens.iter().sum();
    if !total.is_finite() {
        return Err(GeomError::NonFinite {
            what: "clipped pieces' length (coordinates too large)".into(),
        });
    }
    if total <= 0.0 {
        return Ok(None);
    }
    let mut live: Vec<usize> = (0..pieces.len()).filter(|&i| lens[i] > 0.0).collect();
    if live.len() > n {
        // Keep the n longest pieces (ties: earlier first), in the pieces' order.
        let mut by_len = live.clone();
        by_len.sort_by(|&i, &j| lens[j].total_cmp(&lens[i]).then(i.cmp(&j)));
        by_len.truncate(n);
        by_len.sort_unstable();
        live = by_len;
    }
    let live_total: f64 = live.iter().map(|&i| lens[i]).sum();
    let quotas: Vec<f64> = if closed {
        live.iter()
            .map(|&i| n as f64 * lens[i] / live_total)
            .collect()
    } else {
        let spare = (n - live.len()) as f64;
        live.iter()
            .map(|&i| 1.0 + spare * lens[i] / live_total)
            .collect()
    };
    let counts = apportion(&quotas, n);
    let single_ring = closed && live.len() == 1;
    let mut points = Vec::with_capacity(n);
    let mut mask = Vec::with_capacity(n);
    for (&i, &c) in live.iter().zip(&counts) {
        points.extend(sample_piece(&pieces[i], c, closed));
        mask.extend((0..c).map(|j| j + 1 < c || single_ring));
    }
    Ok(Some((points, mask)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;
    use crate::types::Pose2;
    use proptest::prelude::*;

    fn unit_patch() -> Patch {
        Patch::new(Pose2::new(0.0, 0.0, 0.0).unwrap(), 1.0, 1.0, 0.0).unwrap()
    }

    fn close(a: &Point, b: &Point) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn polyline_crossing_gives_exact_entry_exit() {
        let pieces = clip_polyline(&[p(-3.0, 0.0), p(3.0, 0.0)], &unit_patch());
        assert_eq!(pieces.len(), 1);
        assert!(close(&pieces[0][0], &p(-1.0, 0.0)) && close(&pieces[0][1], &p(1.0, 0.0)));
    }

    #[test]
    fn polyline_several_pieces_and_rotation() {
        // A zig-zag leaving and re-entering the patch.
        let pts = [
            p(-2.0, 0.5),
            p(0.0, 0.5),
            p(0.0, 3.0),
            p(0.5, 3.0),
            p(0.5, -0.5),
            p(3.0, -0.5),
        ];
        let pieces = clip_polyline(&pts, &unit_patch());
        assert_eq!(pieces.len(), 2);
        assert_eq!(pieces[0].len(), 3); // entry, (0, 0.5), exit at y = 1
        assert!(
            close(&pieces[0][0], &p(-1.0, 0.5))
                && pieces[0][1] == p(0.0, 0.5)
                && close(&pieces[0][2], &p(0.0, 1.0))
        );
        assert!(
            close(&pieces[1][0], &p(0.5, 1.0))
                && pieces[1][1] == p(0.5, -0.5)
                && close(&pieces[1][2], &p(1.0, -0.5))
        );
        // Rotated patch (45 degrees, centred at (10, 5)): a line along its x axis.
        let yaw = std::f64::consts::FRAC_PI_4;
        let patch = Patch::new(Pose2::new(10.0, 5.0, yaw).unwrap(), 2.0, 1.0, 0.0).unwrap();
        let dir = Point::new(yaw.cos(), yaw.sin()).coords;
        let c = p(10.0, 5.0);
        let pieces = clip_polyline(&[c - dir * 5.0, c + dir * 5.0], &patch);
        assert_eq!(pieces.len(), 1);
        assert!(close(&pieces[0][0], &(c - dir * 2.0)) && close(&pieces[0][1], &(c + dir * 2.0)));
    }

    #[test]
    fn polyline_touching_corner_is_dropped() {
        assert!(clip_polyline(&[p(0.0, 2.0), p(2.0, 0.0)], &unit_patch()).is_empty());
        assert!(clip_polyline(&[p(5.0, 5.0), p(6.0, 6.0)], &unit_patch()).is_empty());
        assert!(clip_polyline(&[p(0.0, 0.0)], &unit_patch()).is_empty());
        assert!(clip_polyline(&[], &unit_patch()).is_empty());
        let with_nan = clip_polyline(
            &[
                p(0.0, 0.0),
                p(0.5, 0.0),
                p(f64::NAN, 0.0),
                p(0.0, 0.5),
                p(0.0, 0.9),
            ],
            &unit_patch(),
        );
        assert_eq!(
            with_nan,
            vec![
                vec![p(0.0, 0.0), p(0.5, 0.0)],
                vec![p(0.0, 0.5), p(0.0, 0.9)]
            ]
        );
    }

    #[test]
    fn polygon_clip() {
        let big = [p(-2.0, -2.0), p(2.0, -2.0), p(2.0, 2.0), p(-2.0, 2.0)];
        let r = clip_polygon(&big, &unit_patch());
        assert_eq!(r.len(), 4);
        assert!((signed_area2(&r) / 2.0 - 4.0).abs() < 1e-12);
        let half = [
            p(0.0, -2.0),
            p(2.0, -2.0),
            p(2.0, 2.0),
            p(0.0, 2.0),
            p(0.0, -2.0),
        ];
        let r = clip_polygon(&half, &unit_patch());
        assert_eq!(r.len(), 4);
        assert!((signed_area2(&r) / 2.0 - 2.0).abs() < 1e-12);
        let inside = [p(0.1, 0.1), p(0.5, 0.1), p(0.3, 0.6)];
        assert_eq!(clip_polygon(&inside, &unit_patch()), inside.to_vec());
        let outside = [p(3.0, 3.0), p(4.0, 3.0), p(4.0, 4.0)];
        assert!(clip_polygon(&outside, &unit_patch()).is_empty());
        assert!(clip_polygon(&[p(0.0, 0.0), p(1.0, 1.0)], &unit_patch()).is_empty());
        assert!(
            clip_polygon(&[p(0.0, 0.0), p(1.0, 1.0), p(f64::NAN, 0.0)], &unit_patch()).is_empty()
        );
    }

    #[test]
    fn sample_single_piece_and_ring() {
        let (pts, mask) = sample_pieces(&[vec![p(0.0, 0.0), p(4.0, 0.0)]], false, 5)
            .unwrap()
            .unwrap();
        assert_eq!(pts.len(), 5);
        assert!(pts
            .iter()
            .enumerate()
            .all(|(j, q)| (q.x - j as f64).abs() < 1e-12));
        assert_eq!(mask, vec![true, true, true, true, false]);
        let ring = vec![p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        let (pts, mask) = sample_pieces(&[ring], true, 8).unwrap().unwrap();
        assert_eq!(pts.len(), 8);
        assert!(close(&pts[1], &p(0.5, 0.0)) && close(&pts[7], &p(0.0, 0.5)));
        assert!(mask.iter().all(|&m| m));
    }

    #[test]
    fn sample_joint_pieces_same_spacing() {
        // Lengths 6 and 2 with 10 points: 8 spare points -> 1 + 6 = 7 and 1 + 2 = 3 points, spacing 1.
        let pieces = vec![
            vec![p(0.0, 0.0), p(6.0, 0.0)],
            vec![p(0.0, 5.0), p(0.0, 7.0)],
        ];
        let (pts, mask) = sample_pieces(&pieces, false, 10).unwrap().unwrap();
        assert_eq!(pts.len(), 10);
        assert_eq!(
            mask,
            vec![true, true, true, true, true, true, false, true, true, false]
        );
        assert!(
            close(&pts[7], &p(0.0, 5.0))
                && close(&pts[8], &p(0.0, 6.0))
                && close(&pts[9], &p(0.0, 7.0))
        );
        // More pieces than points: the longest get one (midpoint) each.
        let many: Vec<Vec<Point>> = (0..5)
            .map(|i| vec![p(0.0, i as f64), p(1.0 + i as f64, i as f64)])
            .collect();
        let (pts, mask) = sample_pieces(&many, false, 2).unwrap().unwrap();
        assert_eq!(pts, vec![p(2.0, 3.0), p(2.5, 4.0)]);
        assert_eq!(mask, vec![false, false]);
        // Zero length -> None; errors.
        assert!(sample_pieces(&[vec![p(1.0, 1.0), p(1.0, 1.0)]], false, 4)
            .unwrap()
            .is_none());
        assert!(sample_pieces(&[], false, 4).unwrap().is_none());
        assert!(sample_pieces(&pieces, false, 1).is_err());
        assert!(sample_pieces(&pieces, true, 2).is_err());
        assert!(sample_pieces(&[vec![p(f64::NAN, 0.0), p(1.0, 0.0)]], false, 4).is_err());
    }

    fn patch_strategy() -> impl Strategy<Value = Patch> {
        (
            -50.0f64..50.0,
            -50.0f64..50.0,
            -4.0f64..4.0,
            0.0f64..30.0,
            0.0f64..30.0,
        )
            .prop_map(|(x, y, yaw, hx, hy)| {
                Patch::new(Pose2::new(x, y, yaw).unwrap(), hx, hy, 0.0).unwrap()
            })
    }

    fn pts_strategy() -> impl Strategy<Value = Vec<Point>> {
        prop::collection::vec((-100.0f64..100.0, -100.0f64..100.0), 0..25)
            .prop_map(|v| v.into_iter().map(|(x, y)| p(x, y)).collect())
    }

    fn inside_tol(patch: &Patch, q: &Point) -> bool {
        let e = patch.pose.to_ego(q);
        let tol =
            1e-9 * (1.0 + patch.half_extents.norm() + patch.pose.x.abs() + patch.pose.y.abs());
        e.x.abs() <= patch.half_extents.x + tol && e.y.abs() <= patch.half_extents.y + tol
    }

    proptest! {
        #[test]
        fn prop_clipped_points_inside(pts in pts_strategy(), patch in patch_strategy()) {
            for piece in clip_polyline(&pts, &patch) {
                prop_assert!(piece.len() >= 2);
                prop_assert!(polyline_length(&piece, false) > 0.0);
                prop_assert!(piece.iter().all(|q| inside_tol(&patch, q)));
            }
            let ring = clip_polygon(&pts, &patch);
            prop_assert!(ring.is_empty() || ring.len() >= 3);
            prop_assert!(ring.iter().all(|q| inside_tol(&patch, q)));
        }

        #[test]
        fn prop_inside_shortcut_is_exact(
            v in prop::collection::vec((-1.0f64..1.0, -1.0f64..1.0), 0..20),
            scale in prop::sample::select(vec![0.9, 1.0, 1.3, 3.0]),
            snap in any::<bool>(),
            yaw in prop::sample::select(vec![0.0, 0.7, std::f64::consts::FRAC_PI_2]),
        ) {
            // Vertices inside, outside and (snapped) exactly on the boundary of a 2 x 2 patch.
            let s = |t: f64| if snap { (t * 4.0).round() / 4.0 } else { t };
            let pts: Vec<Point> = v.iter().map(|&(x, y)| p(s(scale * x), s(scale * y))).collect();
            let patch = Patch::new(Pose2::new(0.0, 0.0, yaw).unwrap(), 1.0, 1.0, 0.0).unwrap();
            let plain = clip_polyline_by_segments(&pts, &patch, false);
            prop_assert_eq!(clip_polyline(&pts, &patch), plain.clone());
            prop_assert_eq!(clip_polyline_by_segments(&pts, &patch, true), plain);
            prop_assert_eq!(clip_polygon(&pts, &patch), clip_polygon_impl(&pts, &patch, false));
        }

        #[test]
        fn prop_inside_polyline_unchanged(v in prop::collection::vec((-0.99f64..0.99, -0.99f64..0.99), 2..20), x in -20.0f64..20.0, yaw in -4.0f64..4.0) {
            let patch = Patch::new(Pose2::new(x, 3.0, yaw).unwrap(), 10.0, 5.0, 0.0).unwrap();
            let pts: Vec<Point> = v.iter().map(|(a, b)| patch.pose.to_world(&p(a * 10.0, b * 5.0))).collect();
            prop_assume!(pts.windows(2).all(|w| w[0] != w[1]));
            let pieces = clip_polyline(&pts, &patch);
            prop_assert_eq!(pieces, vec![pts.clone()]);
        }

        #[test]
        fn prop_sample_exact_n(pts in pts_strategy(), patch in patch_strategy(), n in 3usize..40, closed in any::<bool>()) {
            let pieces = if closed { vec![clip_polygon(&pts, &patch)] } else { clip_polyline(&pts, &patch) };
            if let Some((s, mask)) = sample_pieces(&pieces, closed, n).unwrap() {
                prop_assert_eq!(s.len(), n);
                prop_assert_eq!(mask.len(), n);
                prop_assert!(s.iter().all(|q| inside_tol(&patch, q)));
            }
        }

        #[test]
        fn prop_no_panic_arbitrary(v in prop::collection::vec((any::<f64>(), any::<f64>()), 0..8), hx in any::<f64>(), yaw in any::<f64>(), n in 0usize..8) {
            let pts: Vec<Point> = v.into_iter().map(|(x, y)| p(x, y)).collect();
            let patch = Patch { pose: Pose2 { x: 0.0, y: 0.0, yaw }, half_extents: nalgebra::Vector2::new(hx, 1.0) };
            let pieces = clip_polyline(&pts, &patch);
            let _ = sample_pieces(&pieces, false, n);
            let ring = clip_polygon(&pts, &patch);
            let _ = sample_pieces(&[ring], true, n);
        }
    }
}
