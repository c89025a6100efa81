//! Arc-length resampling of polylines and closed contours.

use crate::error::Result;
use crate::types::Point;

/// Total length of the polyline (for `closed`, including the closing edge).
pub fn polyline_length(points: &[Point], closed: bool) -> f64 {
    let _ = (points, closed);
    todo!("resample.rs: polyline_length")
}

/// Removes consecutive points closer than `eps` to the previous kept point (and, for closed
/// contours, a last point that repeats the first). Keeps the first and the last point of a polyline.
pub fn dedup(points: &[Point], eps: f64, closed: bool) -> Vec<Point> {
    let _ = (points, eps, closed);
    todo!("resample.rs: dedup")
}

/// Exactly `n` points evenly spaced by arc length.
/// Open polyline: first and last point kept, `n >= 2`. Closed contour (`closed`): `n` points along
/// the contour including the closing edge, starting at the first point, the first not repeated at
/// the end, `n >= 3`. Errors on fewer than 2 points, non-finite values, zero length, bad `n`.
pub fn resample(points: &[Point], n: usize, closed: bool) -> Result<Vec<Point>> {
    let _ = (points, n, closed);
    todo!("resample.rs: resample")
}

/// Points about `spacing` apart by arc length: `max(2, ceil(length / spacing) + 1)` points for an
/// open polyline (ends kept), `max(3, ceil(length / spacing))` for a closed contour.
pub fn resample_spacing(points: &[Point], spacing: f64, closed: bool) -> Result<Vec<Point>> {
    let _ = (points, spacing, closed);
    todo!("resample.rs: resample_spacing")
}
