//! Arc-length resampling of polylines and closed contours.
//!
//! Pure geometry on world- or ego-frame points; every function that takes user input either
//! returns a [`GeomError`] or is total (never panics).

use crate::error::{GeomError, Result};
use crate::types::{check_positive, validate_points, Point};

/// Largest number of points that [`resample`] and [`resample_spacing`] produce (guards against a
/// huge `n` or `length / spacing` overflowing memory, e.g. `n = 10**12` or a 1e7 m polyline at
/// 1 nm spacing).
pub const MAX_RESAMPLE_POINTS: usize = 10_000_000;

/// Total length of the polyline (for `closed`, including the closing edge).
pub fn polyline_length(points: &[Point], closed: bool) -> f64 {
    let mut len: f64 = points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    if closed && points.len() > 1 {
        len += (points[0] - points[points.len() - 1]).norm();
    }
    len
}

/// Removes consecutive points not farther than `eps` from the previous kept point (so `eps = 0`
/// removes exact repeats), and, for closed contours, trailing points that repeat the first one.
/// Keeps the first and the last point of an open polyline (the last replaces a kept point closer
/// than `eps` to it). Non-finite points are dropped (comparisons with NaN fail).
pub fn dedup(points: &[Point], eps: f64, closed: bool) -> Vec<Point> {
    let n = points.len();
    if n <= 1 {
        return points.to_vec();
    }
    // (Squared distances: no square root per point.)
    let eps2 = eps * eps;
    let far = |a: &Point, b: &Point| {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        dx * dx + dy * dy > eps2
    };
    let mut kept: Vec<Point> = Vec::with_capacity(n);
    kept.push(points[0]);
    let body_end = if closed { n } else { n - 1 };
    for p in &points[1..body_end] {
        if far(kept.last().unwrap_or(&points[0]), p) {
            kept.push(*p);
        }
    }
    if closed {
        while kept.len() > 1 && !far(&kept[0], &kept[kept.len() - 1]) {
            kept.pop();
        }
    } else {
        let last = points[n - 1];
        let len = kept.len();
        if len == 1 || far(&kept[len - 1], &last) {
            kept.push(last);
        } else {
            kept[len - 1] = last;
        }
    }
    kept
}

/// [`dedup`] without a copy when nothing would be removed (the common case: geometry the map
/// produced itself): the input borrowed if every consecutive pair (and, closed, the last and
/// the first point) lies farther apart than `eps`, else [`dedup`]'s result.
pub(crate) fn dedup_cow(points: &[Point], eps: f64, closed: bool) -> std::borrow::Cow<'_, [Point]> {
    let eps2 = eps * eps;
    let far = |a: &Point, b: &Point| {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        dx * dx + dy * dy > eps2
    };
    let n = points.len();
    let clean = n <= 1
        || (points.windows(2).all(|w| far(&w[0], &w[1]))
            && (!closed || far(&points[n - 1], &points[0])));
    if clean {
        std::borrow::Cow::Borrowed(points)
    } else {
        std::borrow::Cow::Owned(dedup(points, eps, closed))
    }
}

/// Cumulative arc length at every vertex of `pts` (first entry 0).
pub(crate) fn cumulative_lengths(pts: &[Point]) -> Vec<f64> {
    let mut cum = Vec::with_capacity(pts.len());
    let mut acc = 0.0;
    cum.push(0.0);
    for w in pts.windows(2) {
        acc += (w[1] - w[0]).norm();
        cum.push(acc);
    }
    cum
}

/// Points of the polyline `pts` (cumulative lengths `cum`) at the non-decreasing arc lengths
/// `targets`. Targets outside `[0, cum.last()]` are clamped to the ends.
pub(crate) fn points_at_lengths(pts: &[Point], cum: &[f64], targets: &[f64]) -> Vec<Point> {
    let nseg = pts.len().saturating_sub(1);
    let mut out = Vec::with_capacity(targets.len());
    if nseg == 0 {
        out.extend(targets.iter().map(|_| pts[0]));
        return out;
    }
    let mut i = 0usize;
    for &t in targets {
        while i + 1 < nseg && cum[i + 1] < t {
            i += 1;
        }
        let seg = cum[i + 1] - cum[i];
        let f = if seg > 0.0 {
            ((t - cum[i]) / seg).clamp(0.0, 1.0)
        } else {
            0.0
        };
        out.push(pts[i] + (pts[i + 1] - pts[i]) * f);
    }
    out
}

/// The vertices of `points` with the first point appended for a closed contour.
fn with_closing(points: &[Point], closed: bool) -> Vec<Point> {
    let mut pts = points.to_vec();
    if closed {
        pts.push(points[0]);
    }
    pts
}

/// Exactly `n` points evenly spaced by arc length.
/// Open polyline: first and last point kept, `n >= 2`. Closed contour (`closed`): `n` points along
/// the contour including the closing edge, starting at the first point, the first not repeated at
/// the end, `n >= 3`. Errors on fewer than 2 points, non-finite values, zero length, bad `n`
/// (below the minimum, or above [`MAX_RESAMPLE_POINTS`]: the output is allocated up front).
pub fn resample(points: &[Point], n: usize, closed: bool) -> Result<Vec<Point>> {
    validate_points(points, 2, "polyline")?;
    if n > MAX_RESAMPLE_POINTS {
        return Err(GeomError::InvalidParameter {
            name: "n",
            reason: format!("must be at most {MAX_RESAMPLE_POINTS}, got {n}"),
        });
    }
    let min_n = if closed { 3 } else { 2 };
    if n < min_n {
        return Err(GeomError::InvalidParameter {
            name: "n",
            reason: format!(
                "must be >= {min_n} for a {} geometry, got {n}",
                if closed { "closed" } else { "open" }
            ),
        });
    }
    let pts = with_closing(points, closed);
    let cum = cumulative_lengths(&pts);
    let total = cum[cum.len() - 1];
    check_length(total)?;
    let denom = if closed { n as f64 } else { (n - 1) as f64 };
    let targets: Vec<f64> = (0..n).map(|j| total * (j as f64) / denom).collect();
    let mut out = points_at_lengths(&pts, &cum, &targets);
    out[0] = points[0];
    if !closed {
        out[n - 1] = points[points.len() - 1];
    }
    Ok(out)
}

/// Errors unless `total` is a finite positive length.
fn check_length(total: f64) -> Result<()> {
    if !total.is_finite() {
        return Err(GeomError::NonFinite {
            what: "polyline length (coordinates too large)".into(),
        });
    }
    if total <= 0.0 {
        return Err(GeomError::Degenerate {
            what: "polyline".into(),
            reason: "zero length".into(),
        });
    }
    Ok(())
}

/// Points about `spacing` apart by arc length: `max(2, ceil(length / spacing) + 1)` points for an
/// open polyline (ends kept), `max(3, ceil(length / spacing))` for a closed contour.
/// Errors as [`resample`], on a non-positive or non-finite `spacing`, and when more than
/// [`MAX_RESAMPLE_POINTS`] points would be produced.
pub fn resample_spacing(points: &[Point], spacing: f64, closed: bool) -> Result<Vec<Point>> {
    validate_points(points, 2, "polyline")?;
    check_positive("spacing", spacing)?;
    let total = polyline_length(points, closed);
    check_length(total)?;
    let segments = (total / spacing).ceil();
    if !segments.is_finite() || segments >= MAX_RESAMPLE_POINTS as f64 {
        return Err(GeomError::InvalidParameter {
            name: "spacing",
            reason: format!(
                "length {total} / spacing {spacing} gives more than {MAX_RESAMPLE_POINTS} points"
            ),
        });
    }
    let segments = segments as usize;
    let n = if closed {
        segments.max(3)
    } else {
        (segments + 1).max(2)
    };
    Ok(resample_checked(points, n, closed, total))
}

/// [`resample`] of validated `points` (at least 2, finite) with `n` valid for `closed` and
/// `total` = [`polyline_length`]`(points, closed)`, finite and positive: the same points as
/// [`resample`] (the same arithmetic in the same order), without its intermediate buffers.
fn resample_checked(points: &[Point], n: usize, closed: bool, total: f64) -> Vec<Point> {
    let np = points.len();
    let nseg = if closed { np } else { np - 1 };
    let denom = if closed { n as f64 } else { (n - 1) as f64 };
    let mut out = Vec::with_capacity(n);
    // Segment `i` runs from `points[i]` to `points[(i + 1) % np]`, between the cumulative
    // lengths `c0` and `c1` (accumulated as `cumulative_lengths` does).
    let vertex = |i: usize| if i == np { points[0] } else { points[i] };
    let mut i = 0usize;
    let mut c0 = 0.0;
    let mut c1 = (vertex(1) - points[0]).norm();
    for j in 0..n {
        let t = total * (j as f64) / denom;
        while i + 1 < nseg && c1 < t {
            i += 1;
            c0 = c1;
            c1 += (vertex(i + 1) - points[i]).norm();
        }
        let seg = c1 - c0;
        let f = if seg > 0.0 {
            ((t - c0) / seg).clamp(0.0, 1.0)
        } else {
            0.0
        };
        out.push(points[i] + (vertex(i + 1) - points[i]) * f);
    }
    out[0] = points[0];
    if !closed {
        out[n - 1] = points[np - 1];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;
    use proptest::prelude::*;

    #[test]
    fn length_open_and_closed() {
        let sq = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        assert!((polyline_length(&sq, false) - 3.0).abs() < 1e-12);
        assert!((polyline_length(&sq, true) - 4.0).abs() < 1e-12);
        assert_eq!(polyline_length(&[], true), 0.0);
        assert_eq!(polyline_length(&sq[..1], true), 0.0);
    }

    #[test]
    fn dedup_removes_repeats_keeps_ends() {
        let pts = [
            p(0.0, 0.0),
            p(0.0, 0.0),
            p(1.0, 0.0),
            p(1.0, 0.0 + 1e-12),
            p(2.0, 0.0),
            p(2.0, 1e-13),
        ];
        let d = dedup(&pts, 1e-9, false);
        assert_eq!(d, vec![p(0.0, 0.0), p(1.0, 0.0), p(2.0, 1e-13)]);
        let ring = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 0.0)];
        assert_eq!(dedup(&ring, 0.0, true).len(), 3);
        let same = [p(3.0, 3.0), p(3.0, 3.0), p(3.0, 3.0)];
        assert_eq!(dedup(&same, 0.0, false).len(), 2);
        assert_eq!(dedup(&same, 0.0, true).len(), 1);
    }

    #[test]
    fn resample_open_even() {
        let pts = [p(0.0, 0.0), p(10.0, 0.0)];
        let r = resample(&pts, 11, false).unwrap();
        for (j, q) in r.iter().enumerate() {
            assert!((q.x - j as f64).abs() < 1e-12 && q.y == 0.0);
        }
    }

    #[test]
    fn resample_closed_goes_around() {
        let sq = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        let r = resample(&sq, 8, true).unwrap();
        let want = [
            (0.0, 0.0),
            (0.5, 0.0),
            (1.0, 0.0),
            (1.0, 0.5),
            (1.0, 1.0),
            (0.5, 1.0),
            (0.0, 1.0),
            (0.0, 0.5),
        ];
        assert_eq!(r.len(), 8);
        for (q, w) in r.iter().zip(want) {
            assert!(
                (q.x - w.0).abs() < 1e-12 && (q.y - w.1).abs() < 1e-12,
                "{q:?} vs {w:?}"
            );
        }
    }

    /// Issue 14, point 2: `resample(pts, 10**12)` tried to allocate 8 TB and aborted the process,
    /// `usize::MAX` panicked (capacity overflow); `n` is capped like `resample_spacing`'s count.
    #[test]
    fn resample_caps_n() {
        let line = [p(0.0, 0.0), p(1.0, 0.0)];
        for n in [MAX_RESAMPLE_POINTS + 1, 1_000_000_000_000, usize::MAX] {
            for closed in [false, true] {
                assert!(matches!(
                    resample(&line, n, closed),
                    Err(GeomError::InvalidParameter { name: "n", .. })
                ));
            }
        }
        assert_eq!(resample(&line, 1000, false).unwrap().len(), 1000);
    }

    #[test]
    fn resample_errors() {
        let line = [p(0.0, 0.0), p(1.0, 0.0)];
        assert!(matches!(
            resample(&[], 5, false),
            Err(GeomError::TooFewPoints { .. })
        ));
        assert!(matches!(
            resample(&line[..1], 5, false),
            Err(GeomError::TooFewPoints { .. })
        ));
        assert!(matches!(
            resample(&[p(f64::NAN, 0.0), p(1.0, 0.0)], 5, false),
            Err(GeomError::NonFinite { .. })
        ));
        assert!(matches!(
            resample(&[p(f64::INFINITY, 0.0), p(1.0, 0.0)], 5, false),
            Err(GeomError::NonFinite { .. })
        ));
        assert!(matches!(
            resample(&[p(1.0, 1.0), p(1.0, 1.0)], 5, false),
            Err(GeomError::Degenerate { .. })
        ));
        assert!(matches!(
            resample(&line, 1, false),
            Err(GeomError::InvalidParameter { .. })
        ));
        assert!(matches!(
            resample(&line, 2, true),
            Err(GeomError::InvalidParameter { .. })
        ));
        // Outside the coordinate domain (issue 14.3: the length overflowed to inf).
        assert!(matches!(
            resample(&[p(-1e308, 0.0), p(1e308, 0.0)], 5, false),
            Err(GeomError::OutOfDomain { .. })
        ));
        assert!(matches!(
            resample_spacing(&line, 0.0, false),
            Err(GeomError::InvalidParameter { .. })
        ));
        assert!(matches!(
            resample_spacing(&line, f64::NAN, false),
            Err(GeomError::InvalidParameter { .. })
        ));
        assert!(matches!(
            resample_spacing(&[p(0.0, 0.0), p(1e7, 0.0)], 1e-3, false),
            Err(GeomError::InvalidParameter { .. })
        ));
        assert!(matches!(
            resample_spacing(&[p(0.0, 0.0), p(1e150, 0.0)], 1.0, false),
            Err(GeomError::OutOfDomain { .. })
        ));
    }

    #[test]
    fn resample_spacing_counts() {
        let line = [p(0.0, 0.0), p(10.0, 0.0)];
        assert_eq!(resample_spacing(&line, 1.0, false).unwrap().len(), 11);
        assert_eq!(resample_spacing(&line, 3.0, false).unwrap().len(), 5);
        assert_eq!(resample_spacing(&line, 100.0, false).unwrap().len(), 2);
        assert_eq!(resample_spacing(&line, 1.0, true).unwrap().len(), 20);
        assert_eq!(resample_spacing(&line, 100.0, true).unwrap().len(), 3);
    }

    fn polyline_strategy() -> impl Strategy<Value = Vec<Point>> {
        prop::collection::vec((-100.0f64..100.0, -100.0f64..100.0), 2..30)
            .prop_map(|v| v.into_iter().map(|(x, y)| p(x, y)).collect())
    }

    proptest! {
        #[test]
        fn prop_resample_keeps_ends_and_length(pts in polyline_strategy(), n in 2usize..50) {
            let len = polyline_length(&pts, false);
            prop_assume!(len > 1e-6);
            let r = resample(&pts, n, false).unwrap();
            prop_assert_eq!(r.len(), n);
            prop_assert_eq!(r[0], pts[0]);
            prop_assert_eq!(r[n - 1], pts[pts.len() - 1]);
            prop_assert!(r.iter().all(|q| q.x.is_finite() && q.y.is_finite()));
            // Resampling never lengthens the polyline (chords of the original).
            prop_assert!(polyline_length(&r, false) <= len * (1.0 + 1e-9) + 1e-9);
        }

        #[test]
        fn prop_fine_resample_keeps_length(pts in polyline_strategy(), closed in any::<bool>()) {
            let len = polyline_length(&pts, closed);
            prop_assume!(len > 1e-3);
            // About 200 samples per vertex: the corners cut off are tiny.
            let r = resample(&pts, 200 * pts.len() + 3, closed).unwrap();
            let rl = polyline_length(&r, closed);
            prop_assert!((rl - len).abs() <= 0.02 * len, "{} vs {}", rl, len);
        }

        #[test]
        fn prop_resample_spacing_even(pts in polyline_strategy(), spacing in 0.1f64..20.0) {
            let len = polyline_length(&pts, false);
            prop_assume!(len > 1e-6);
            let r = resample_spacing(&pts, spacing, false).unwrap();
            prop_assert_eq!(r.len(), ((len / spacing).ceil() as usize + 1).max(2));
            // Consecutive samples are at most one arc step apart (chord <= arc).
            let step = len / (r.len() - 1) as f64;
            prop_assert!(r.windows(2).all(|w| (w[1] - w[0]).norm() <= step * (1.0 + 1e-9) + 1e-9));
        }

        #[test]
        fn prop_no_panic_arbitrary(v in prop::collection::vec((any::<f64>(), any::<f64>()), 0..6), n in 0usize..10, closed in any::<bool>(), sp in any::<f64>()) {
            let pts: Vec<Point> = v.into_iter().map(|(x, y)| p(x, y)).collect();
            let _ = polyline_length(&pts, closed);
            let _ = dedup(&pts, 0.0, closed);
            if let Ok(r) = resample(&pts, n, closed) {
                prop_assert!(r.iter().all(|q| q.x.is_finite() && q.y.is_finite()));
            }
            let _ = resample_spacing(&pts, sp, closed);
        }
    }
}
