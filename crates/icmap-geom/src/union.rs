//! Polygon union of pedestrian crossings (geo's `BooleanOps`, i_overlay underneath).
//!
//! Input is validated first (finite coordinates, at least 3 points per ring) because the overlay
//! engine must never see NaN. Self-intersecting rings are accepted: the overlay resolves them.

use crate::clip::signed_area2;
use crate::error::Result;
use crate::types::{validate_points, Point};
use geo::{Coord, LineString, Polygon};

/// A ring without a repeated closing point.
fn open_ring(ring: &[Point]) -> &[Point] {
    if ring.len() >= 2 && ring[0] == ring[ring.len() - 1] {
        &ring[..ring.len() - 1]
    } else {
        ring
    }
}

/// The ring as a geo polygon, oriented counter-clockwise (by its signed area).
fn to_polygon(ring: &[Point]) -> Polygon<f64> {
    let mut coords: Vec<Coord<f64>> = ring.iter().map(|p| Coord { x: p.x, y: p.y }).collect();
    if signed_area2(ring) < 0.0 {
        coords.reverse();
    }
    Polygon::new(LineString::new(coords), vec![])
}

/// Union of closed rings (each without a repeated closing point). Returns the outer rings of the
/// resulting polygons (holes dropped), counter-clockwise, largest area first, never losing area:
/// when the union falls apart into several polygons, all of them are returned. Rings with zero
/// area contribute nothing (an all-degenerate input gives an empty list). A repeated closing point
/// in the input is ignored. Errors on a ring with fewer than 3 points or a non-finite coordinate.
pub fn polygon_union(rings: &[Vec<Point>]) -> Result<Vec<Vec<Point>>> {
    for (i, ring) in rings.iter().enumerate() {
        validate_points(open_ring(ring), 3, &format!("ring {i}"))?;
    }
    // Resolve every ring on its own first (a self-intersecting ring with lobes of opposite
    // orientation would otherwise cancel the other rings' winding numbers in the joint overlay).
    let polys: Vec<Polygon<f64>> = rings
        .iter()
        .flat_map(|r| geo::unary_union(std::iter::once(&to_polygon(open_ring(r)))).0)
        .collect();
    let union = geo::unary_union(polys.iter());
    let mut out: Vec<(f64, Vec<Point>)> = Vec::new();
    for poly in union.0 {
        let mut ring: Vec<Point> = poly
            .exterior()
            .0
            .iter()
            .map(|c| Point::new(c.x, c.y))
            .collect();
        if ring.len() >= 2 && ring[0] == ring[ring.len() - 1] {
            ring.pop();
        }
        ring.dedup();
        if ring.len() < 3 {
            continue;
        }
        let a2 = signed_area2(&ring);
        if !(a2.is_finite() && a2 != 0.0) {
            continue;
        }
        if a2 < 0.0 {
            ring.reverse();
        }
        out.push((a2.abs(), ring));
    }
    out.sort_by(|a, b| b.0.total_cmp(&a.0));
    Ok(out.into_iter().map(|(_, r)| r).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::GeomError;
    use proptest::prelude::*;

    fn p(x: f64, y: f64) -> Point {
        Point::new(x, y)
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point> {
        vec![p(x0, y0), p(x1, y0), p(x1, y1), p(x0, y1)]
    }

    fn area(r: &[Point]) -> f64 {
        signed_area2(r) / 2.0
    }

    #[test]
    fn overlapping_rects_merge() {
        let u = polygon_union(&[rect(0.0, 0.0, 2.0, 1.0), rect(1.0, 0.0, 3.0, 1.0)]).unwrap();
        assert_eq!(u.len(), 1);
        assert!((area(&u[0]) - 3.0).abs() < 1e-9, "ccw and area 3");
        assert_ne!(u[0][0], u[0][u[0].len() - 1]);
    }

    #[test]
    fn disjoint_rects_all_kept_largest_first() {
        let mut cw = rect(10.0, 0.0, 13.0, 2.0);
        cw.reverse();
        let u = polygon_union(&[rect(0.0, 0.0, 1.0, 1.0), cw]).unwrap();
        assert_eq!(u.len(), 2);
        assert!((area(&u[0]) - 6.0).abs() < 1e-9 && (area(&u[1]) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn self_intersecting_and_degenerate_do_not_panic() {
        let bowtie = vec![p(0.0, 0.0), p(1.0, 1.0), p(1.0, 0.0), p(0.0, 1.0)];
        let u = polygon_union(&[bowtie]).unwrap();
        assert!(u.iter().all(|r| area(r) > 0.0));
        let flat = vec![p(0.0, 0.0), p(1.0, 0.0), p(2.0, 0.0)];
        assert!(polygon_union(&[flat]).unwrap().is_empty());
        assert!(polygon_union(&[]).unwrap().is_empty());
        let closed = vec![p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 0.0)];
        assert_eq!(polygon_union(&[closed]).unwrap()[0].len(), 3);
    }

    #[test]
    fn errors() {
        assert!(matches!(
            polygon_union(&[vec![p(0.0, 0.0), p(1.0, 0.0)]]),
            Err(GeomError::TooFewPoints { .. })
        ));
        let nan = vec![p(0.0, 0.0), p(1.0, f64::NAN), p(1.0, 1.0)];
        assert!(matches!(
            polygon_union(&[rect(0.0, 0.0, 1.0, 1.0), nan]),
            Err(GeomError::NonFinite { .. })
        ));
    }

    proptest! {
        #[test]
        fn prop_union_area_bounds(a in prop::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 3..8),
                                  r in (-10.0f64..10.0, -10.0f64..10.0, 0.1f64..8.0, 0.1f64..8.0)) {
            let a: Vec<Point> = a.into_iter().map(|(x, y)| p(x, y)).collect();
            let b = rect(r.0, r.1, r.0 + r.2, r.1 + r.3);
            let u = polygon_union(&[a, b]).unwrap();
            prop_assert!(!u.is_empty());
            let total: f64 = u.iter().map(|r| area(r)).sum();
            // The union holds at least the (simple) rectangle.
            prop_assert!(total >= r.2 * r.3 * (1.0 - 1e-6));
            prop_assert!(u.iter().all(|r| area(r) > 0.0 && r.len() >= 3));
            prop_assert!(u.windows(2).all(|w| area(&w[0]) >= area(&w[1])));
        }

        #[test]
        fn prop_no_panic_arbitrary(v in prop::collection::vec((any::<f64>(), any::<f64>()), 0..8)) {
            let ring: Vec<Point> = v.into_iter().map(|(x, y)| p(x, y)).collect();
            let _ = polygon_union(&[ring.clone(), rect(0.0, 0.0, 1.0, 1.0)]);
        }
    }
}
