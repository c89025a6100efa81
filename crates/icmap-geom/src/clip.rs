//! Clipping of polylines and polygons to an oriented patch, and even sampling of the clipped pieces
//! (Algorithm 1 of IC-Mapper).

use crate::error::Result;
use crate::types::{Patch, Point};

/// The parts of an open polyline inside `patch`, in world coordinates, in the polyline's order.
/// Each piece has at least 2 points (entry/exit points are exact segment-rectangle intersections).
pub fn clip_polyline(points: &[Point], patch: &Patch) -> Vec<Vec<Point>> {
    let _ = (points, patch);
    todo!("clip.rs: clip_polyline")
}

/// A closed ring clipped to `patch` (the patch is convex: Sutherland-Hodgman), world coordinates,
/// without repeating the first point. Empty when the ring lies outside the patch.
pub fn clip_polygon(ring: &[Point], patch: &Patch) -> Vec<Point> {
    let _ = (ring, patch);
    todo!("clip.rs: clip_polygon")
}

/// Samples clipped geometry evenly to exactly `n` points.
///
/// Several pieces are sampled jointly: the `n` points are spread over the total length of all
/// pieces, in the pieces' order, so the spacing is the same on every piece (every piece of positive
/// length gets at least one point while `n` allows). Returns the points and a connectivity mask of
/// the same length: `mask[j]` is true iff point `j` and point `j + 1` lie on the same piece (for a
/// single closed ring the last entry is true: it connects back to the first point). Returns `None`
/// when the pieces have zero total length.
pub fn sample_pieces(pieces: &[Vec<Point>], closed: bool, n: usize) -> Result<Option<(Vec<Point>, Vec<bool>)>> {
    let _ = (pieces, closed, n);
    todo!("clip.rs: sample_pieces")
}
