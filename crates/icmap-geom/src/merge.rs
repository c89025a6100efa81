//! Merging a detection into a global instance (Algorithm 2 of IC-Mapper).

use crate::error::Result;
use crate::types::Point;

/// Merges a detected polyline into a global polyline (both world frame): decides the orientation of
/// the detection from the geometry, reorders and concatenates (cases: partial overlap, one
/// containing the other, end-to-end continuation, reversed direction), fits a smoothing spline with
/// parameter `s` ([`crate::fit::fit_curve`]) and resamples about `spacing` apart. The result keeps the
/// global instance's direction.
pub fn merge_polyline(global: &[Point], detected: &[Point], s: f64, spacing: f64) -> Result<Vec<Point>> {
    let _ = (global, detected, s, spacing);
    todo!("merge.rs: merge_polyline")
}

/// Merges a detected crossing into a global crossing by polygon union; returns the new outer ring
/// resampled about `spacing` apart along the contour. If the union falls apart (disjoint
/// polygons), the convex hull of both is stored so that no area is lost (documented behaviour).
pub fn merge_polygon(global: &[Point], detected: &[Point], spacing: f64) -> Result<Vec<Point>> {
    let _ = (global, detected, spacing);
    todo!("merge.rs: merge_polygon")
}
