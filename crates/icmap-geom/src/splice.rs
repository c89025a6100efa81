//! Splicing a new observation into a stored polyline by projection: the stretch of the stored
//! polyline that the new one covers is replaced by it, the rest is kept on either side.
//!
//! The rule of IC-Mapper's fused polylines (a fused detection already combines the current view
//! with the instance's history, so it replaces what it covers instead of being averaged into it
//! again) and of the VMA- and PolyMerge-style baselines. It was numpy code in the Python package
//! (`icmapper.mapping.splice`); this is the same algorithm, step for step:
//!
//! 1. `new` is oriented like `stored` ([`orient_like`]);
//! 2. stored points within `overlap` metres of `new` are dropped (they are covered);
//! 3. the result is the stored points before the projection of `new`'s start onto `stored`, then
//!    `new`, then the stored points after the projection of its end (arc lengths along `stored`).

use crate::error::Result;
use crate::resample::polyline_length;
use crate::types::{check_non_negative, validate_points, Point};

/// The nearest point of the open polyline `poly` (at least one point) to `p`: its distance and
/// its arc length (metres from `poly[0]`). Among segments at the same (smallest) distance the
/// first is taken. A one-point polyline is that point (arc length 0).
pub fn project_onto_polyline(p: &Point, poly: &[Point]) -> (f64, f64) {
    if poly.len() == 1 {
        return ((p - poly[0]).norm(), 0.0);
    }
    let (mut best_d, mut best_s) = (f64::INFINITY, 0.0);
    let mut s0 = 0.0;
    for w in poly.windows(2) {
        let (a, ab) = (w[0], w[1] - w[0]);
        let seg_len = ab.norm();
        let denom = (seg_len * seg_len).max(1e-18);
        let t = ((p - a).dot(&ab) / denom).clamp(0.0, 1.0);
        let d = (p - (a + ab * t)).norm();
        if d < best_d {
            best_d = d;
            best_s = s0 + t * seg_len;
        }
        s0 += seg_len;
    }
    (best_d, best_s)
}

/// `new` in the direction of `stored`: reversed when its end projects before its start along
/// `stored`. When both ends project to the same place (`new` lies beyond one end of `stored`),
/// the end of `new` nearer to the end of `stored` it continues comes first (after the end) or
/// last (before the start).
pub fn orient_like(stored: &[Point], new: &[Point]) -> Vec<Point> {
    let s: Vec<f64> = new
        .iter()
        .map(|p| project_onto_polyline(p, stored).1)
        .collect();
    let total = polyline_length(stored, false);
    let tol = 1e-6 * total.max(1.0);
    let (first, last) = (s[0], s[s.len() - 1]);
    let forward = if last - first > tol {
        true
    } else if first - last > tol {
        false
    } else if s.iter().sum::<f64>() / s.len() as f64 >= total / 2.0 {
        let end = stored[stored.len() - 1];
        (new[0] - end).norm() <= (new[new.len() - 1] - end).norm()
    } else {
        let start = stored[0];
        (new[new.len() - 1] - start).norm() <= (new[0] - start).norm()
    };
    if forward {
        new.to_vec()
    } else {
        new.iter().rev().copied().collect()
    }
}

/// Splices `new` into `stored` (both open polylines of at least 2 points): see the module
/// documentation. `overlap` is in metres (finite, >= 0). Errors on too few points, non-finite or
/// out-of-domain coordinates and a bad `overlap`.
pub fn splice_polyline(stored: &[Point], new: &[Point], overlap: f64) -> Result<Vec<Point>> {
    validate_points(stored, 2, "stored polyline")?;
    validate_points(new, 2, "new polyline")?;
    check_non_negative("overlap", overlap)?;
    let q = orient_like(stored, new);
    let (_, s_start) = project_onto_polyline(&q[0], stored);
    let (_, s_end) = project_onto_polyline(&q[q.len() - 1], stored);
    let mut before = Vec::new();
    let mut after = Vec::new();
    let mut s_p = 0.0;
    for (i, p) in stored.iter().enumerate() {
        if i > 0 {
            s_p += (stored[i] - stored[i - 1]).norm();
        }
        if project_onto_polyline(p, &q).0 <= overlap {
            continue; // covered by the new observation
        }
        if s_p <= s_start {
            before.push(*p);
        }
        if s_p > s_end {
            after.push(*p);
        }
    }
    let mut out = before;
    out.reserve(q.len() + after.len());
    out.extend_from_slice(&q);
    out.extend_from_slice(&after);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(v: &[(f64, f64)]) -> Vec<Point> {
        v.iter().map(|&(x, y)| Point::new(x, y)).collect()
    }

    #[test]
    fn projection_distance_and_arc_length() {
        let poly = pts(&[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]);
        let (d, s) = project_onto_polyline(&Point::new(4.0, 3.0), &poly);
        assert!((d - 3.0).abs() < 1e-12 && (s - 4.0).abs() < 1e-12);
        let (d, s) = project_onto_polyline(&Point::new(12.0, 5.0), &poly);
        assert!((d - 2.0).abs() < 1e-12 && (s - 15.0).abs() < 1e-12);
        let (d, s) = project_onto_polyline(&Point::new(-3.0, -4.0), &poly);
        assert!((d - 5.0).abs() < 1e-12 && s == 0.0);
        // equidistant from both segments: the first one wins
        let (_, s) = project_onto_polyline(&Point::new(11.0, -1.0), &poly);
        assert!((s - 10.0).abs() < 1e-12);
        let one = pts(&[(1.0, 1.0)]);
        assert_eq!(
            project_onto_polyline(&Point::new(4.0, 5.0), &one),
            (5.0, 0.0)
        );
    }

    #[test]
    fn orientation_follows_the_stored_polyline() {
        let stored = pts(&[(0.0, 0.0), (10.0, 0.0)]);
        let along = pts(&[(2.0, 0.5), (6.0, 0.5)]);
        assert_eq!(orient_like(&stored, &along), along);
        let back: Vec<Point> = along.iter().rev().copied().collect();
        assert_eq!(orient_like(&stored, &back), along);
        // beyond the end, pointing away from it: kept; pointing back at it: reversed
        let beyond = pts(&[(12.0, 3.0), (12.0, 8.0)]);
        assert_eq!(orient_like(&stored, &beyond), beyond);
        let beyond_back: Vec<Point> = beyond.iter().rev().copied().collect();
        assert_eq!(orient_like(&stored, &beyond_back), beyond);
        // before the start: the end nearer to the start comes last
        let before = pts(&[(-2.0, 8.0), (-2.0, 3.0)]);
        assert_eq!(orient_like(&stored, &before), before);
    }

    #[test]
    fn splice_replaces_the_covered_stretch() {
        let stored: Vec<Point> = (0..=10).map(|i| Point::new(i as f64, 0.0)).collect();
        let new = pts(&[(7.5, 0.2), (5.5, 0.2), (3.5, 0.2)]); // reversed, covers x 3.5..7.5
        let out = splice_polyline(&stored, &new, 0.5).unwrap();
        let xs: Vec<f64> = out.iter().map(|p| p.x).collect();
        // x = 3 and 8 lie 0.54 m from the new polyline's ends: kept
        assert_eq!(xs, vec![0.0, 1.0, 2.0, 3.0, 3.5, 5.5, 7.5, 8.0, 9.0, 10.0]);
        assert!(out[4..7].iter().all(|p| p.y == 0.2));
        // an extension beyond the end is appended
        let ext = pts(&[(10.5, 0.0), (14.0, 0.0)]);
        let out = splice_polyline(&stored, &ext, 0.3).unwrap();
        assert_eq!(out.len(), 13);
        assert_eq!(out[out.len() - 1], Point::new(14.0, 0.0));
        // stored points within the overlap of an extension are replaced by it
        let out = splice_polyline(&stored, &ext, 0.6).unwrap();
        assert_eq!(out.len(), 12);
    }

    #[test]
    fn splice_rejects_bad_input() {
        let stored = pts(&[(0.0, 0.0), (10.0, 0.0)]);
        let new = pts(&[(1.0, 0.0), (2.0, 0.0)]);
        assert!(splice_polyline(&stored[..1], &new, 0.5).is_err());
        assert!(splice_polyline(&stored, &new[..1], 0.5).is_err());
        assert!(splice_polyline(&stored, &pts(&[(f64::NAN, 0.0), (1.0, 1.0)]), 0.5).is_err());
        assert!(splice_polyline(&stored, &pts(&[(1e9, 0.0), (1.0, 1.0)]), 0.5).is_err());
        assert!(splice_polyline(&stored, &new, -1.0).is_err());
        assert!(splice_polyline(&stored, &new, f64::NAN).is_err());
    }
}
