//! Chamfer distances between point sets.

use crate::error::Result;
use crate::types::Point;

/// Chamfer distance: (mean over `a` of the distance to the nearest point of `b` + mean over `b` of
/// the distance to the nearest point of `a`) / 2. For equal sizes N this equals
/// (sum of nearest distances in both directions) / (2 N). Errors on empty or non-finite input.
pub fn chamfer_distance(a: &[Point], b: &[Point]) -> Result<f64> {
    let _ = (a, b);
    todo!("chamfer.rs: chamfer_distance")
}

/// All pairwise Chamfer distances, row-major `(a.len(), b.len())` (parallel over rows).
pub fn chamfer_matrix(a: &[Vec<Point>], b: &[Vec<Point>]) -> Result<Vec<f64>> {
    let _ = (a, b);
    todo!("chamfer.rs: chamfer_matrix")
}
