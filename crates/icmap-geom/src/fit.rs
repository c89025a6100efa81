//! Smoothing cubic-spline fit of a polyline (the semantics of scipy's `splprep`).

use crate::error::Result;
use crate::types::Point;

/// Fits a smoothing parametric cubic spline to `points` and returns it evaluated about `spacing`
/// metres apart (ends included).
///
/// Semantics of scipy `splprep(..., s=s, k=3)`: chord-length parameter on [0, 1], unit weights, the
/// smoothest spline whose sum of squared residuals is at most `s`. Duplicate consecutive points are
/// removed first. With 2 or 3 distinct points the degree drops (k = min(3, m - 1)).
pub fn fit_curve(points: &[Point], s: f64, spacing: f64) -> Result<Vec<Point>> {
    let _ = (points, s, spacing);
    todo!("fit.rs: fit_curve")
}
