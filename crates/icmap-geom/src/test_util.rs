//! Test helpers shared by the crate's unit tests (compiled for tests only): short constructors
//! of points, shapes and maps.

use crate::error::{GeomError, Result};
use crate::store::{GlobalMap, MapConfig};
use crate::types::{MapClass, Point};
use proptest::prelude::*;

/// `Point::new(x, y)`, short for the tests' literals.
pub(crate) fn p(x: f64, y: f64) -> Point {
    Point::new(x, y)
}

/// An empty map of the default configuration.
pub(crate) fn map() -> GlobalMap {
    GlobalMap::new(MapConfig::default()).unwrap()
}

/// Inserts `points` of `class` seen at `frame` into `m` (which must accept them); the new id.
pub(crate) fn add(m: &mut GlobalMap, class: MapClass, points: &[Point], frame: i64) -> u64 {
    m.insert(class, points, frame).unwrap()
}

/// The axis-aligned rectangle of centre (cx, cy) and half sizes hx, hy, counter-clockwise.
pub(crate) fn rect(cx: f64, cy: f64, hx: f64, hy: f64) -> Vec<Point> {
    vec![
        p(cx - hx, cy - hy),
        p(cx + hx, cy - hy),
        p(cx + hx, cy + hy),
        p(cx - hx, cy + hy),
    ]
}

/// The reason of a [`GeomError::Format`] (panics on any other error).
pub(crate) fn reason(e: GeomError) -> String {
    match e {
        GeomError::Format { reason, .. } => reason,
        other => panic!("expected a Format error, got {other:?}"),
    }
}

/// Checks that `parse` (a map file reader) says "truncated" (or "empty file") for every proper
/// prefix of the file `bytes`, and "trailing" for it with one byte more.
pub(crate) fn check_truncations(bytes: &[u8], parse: impl Fn(&[u8]) -> Result<GlobalMap>) {
    for cut in 0..bytes.len() {
        let msg = reason(parse(&bytes[..cut]).unwrap_err());
        assert!(
            msg.contains("truncated") || msg.contains("empty file"),
            "cut {cut}: {msg}"
        );
    }
    let mut longer = bytes.to_vec();
    longer.push(0);
    assert!(reason(parse(&longer).unwrap_err()).contains("trailing"));
}

/// Checks that `parse` (a map file reader) refuses the file `bytes` with any one bit flipped
/// (bits 0, 3 and 7 of every byte) with a [`GeomError::Format`].
pub(crate) fn check_flipped_bytes(bytes: &[u8], parse: impl Fn(&[u8]) -> Result<GlobalMap>) {
    for i in 0..bytes.len() {
        for bit in [0u8, 3, 7] {
            let mut b = bytes.to_vec();
            b[i] ^= 1 << bit;
            assert!(
                matches!(parse(&b), Err(GeomError::Format { .. })),
                "byte {i} bit {bit}"
            );
        }
    }
}

/// `n` random query boxes `(x, y, w, h)`: corner within `reach` of the origin on both axes, sides
/// up to `size`.
pub(crate) fn query_boxes(
    reach: f64,
    size: f64,
    n: usize,
) -> impl Strategy<Value = Vec<(f64, f64, f64, f64)>> {
    prop::collection::vec((-reach..reach, -reach..reach, 0.0..size, 0.0..size), n)
}
