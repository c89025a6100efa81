//! Polylines of cell centres: length (GEOS `LineString.length`) and arc-length resampling to a
//! fixed number of points (the Python `resample_polyline`: numpy `linspace` targets and `interp`
//! along the cumulative length), float32 output.

use crate::types::Point;

/// Length of the polyline `pts` (sum of its segments, in order).
pub fn length(pts: &[Point]) -> f64 {
    pts.windows(2).map(|w| seg_len(w[0], w[1])).sum()
}

#[inline]
fn seg_len(a: Point, b: Point) -> f64 {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    (dx * dx + dy * dy).sqrt()
}

/// numpy `interp(x, xp, fp)` for increasing `xp` (ties allowed) and `x` inside `[xp[0], xp[-1]]`.
fn interp(x: f64, xp: &[f64], fp: &[f64]) -> f64 {
    let n = xp.len();
    if x >= xp[n - 1] {
        return fp[n - 1];
    }
    if x <= xp[0] {
        // x < xp[0] gives fp[0] (left); x == xp[0] the exact match below
        if x < xp[0] {
            return fp[0];
        }
    }
    // j: the last index with xp[j] <= x
    let j = xp.partition_point(|&v| v <= x).saturating_sub(1);
    if j >= n - 1 {
        return fp[n - 1];
    }
    if xp[j] == x {
        return fp[j];
    }
    let slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
    slope * (x - xp[j]) + fp[j]
}

/// `n` points evenly spaced along the polyline `line` (open), or along the closed ring `line`
/// (its first point not repeated; `closed`), as float32. A line without length (or without
/// points) gives `n` copies of its first point (the origin for no points).
pub fn resample_polyline(line: &[Point], n: usize, closed: bool) -> Vec<[f32; 2]> {
    if line.is_empty() || n == 0 {
        return vec![[0.0, 0.0]; n];
    }
    let mut pts = line.to_vec();
    if closed {
        pts.push(line[0]);
    }
    let mut cum = Vec::with_capacity(pts.len());
    cum.push(0.0);
    let mut acc = 0.0;
    for w in pts.windows(2) {
        acc += seg_len(w[0], w[1]);
        cum.push(acc);
    }
    let total = acc;
    if total.is_nan() || total <= 0.0 {
        return vec![[pts[0].x as f32, pts[0].y as f32]; n];
    }
    // linspace(0, total, n) (closed: linspace(0, total, n + 1)[:-1]); the last target is `total`
    let div = if closed { n } else { n - 1 };
    let step = total / div.max(1) as f64;
    let xs: Vec<f64> = pts.iter().map(|p| p.x).collect();
    let ys: Vec<f64> = pts.iter().map(|p| p.y).collect();
    (0..n)
        .map(|k| {
            let d = if !closed && k == n - 1 && n > 1 {
                total
            } else {
                k as f64 * step
            };
            [interp(d, &cum, &xs) as f32, interp(d, &cum, &ys) as f32]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::p;

    #[test]
    fn open_and_closed_resampling() {
        let out = resample_polyline(&[p(0.0, 0.0), p(10.0, 0.0)], 11, false);
        for (k, q) in out.iter().enumerate() {
            assert!((q[0] - k as f32).abs() < 1e-5 && q[1] == 0.0);
        }
        let sq = [p(0.0, 0.0), p(4.0, 0.0), p(4.0, 4.0), p(0.0, 4.0)];
        let ring = resample_polyline(&sq, 8, true);
        assert_eq!(ring[0], [0.0, 0.0]);
        assert_eq!(ring[1], [2.0, 0.0]);
        assert_eq!(ring[7], [0.0, 2.0]);
        assert_eq!(length(&sq), 12.0);
    }

    #[test]
    fn degenerate_lines() {
        assert_eq!(
            resample_polyline(&[p(1.0, 2.0); 3], 5, false),
            vec![[1.0, 2.0]; 5]
        );
        assert_eq!(resample_polyline(&[], 3, true), vec![[0.0, 0.0]; 3]);
        assert!(resample_polyline(&[p(0.0, 0.0)], 0, false).is_empty());
        // a repeated vertex (zero-length segment) on the way
        let out = resample_polyline(
            &[p(0.0, 0.0), p(1.0, 0.0), p(1.0, 0.0), p(2.0, 0.0)],
            3,
            false,
        );
        assert_eq!(out, vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]);
    }
}
