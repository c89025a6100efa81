//! Polygon union of pedestrian crossings (geo's `BooleanOps`).

use crate::error::Result;
use crate::types::Point;

/// Union of closed rings (each without a repeated closing point). Returns the outer rings of the
/// resulting polygons (holes dropped), counter-clockwise, largest area first, never losing area:
/// when the union falls apart into several polygons, all of them are returned.
pub fn polygon_union(rings: &[Vec<Point>]) -> Result<Vec<Vec<Point>>> {
    let _ = rings;
    todo!("union.rs: polygon_union")
}
