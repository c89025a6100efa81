//! Polygon union of pedestrian crossings (geo's `BooleanOps`, i_overlay underneath).
//!
//! Input is validated first (finite coordinates, at least 3 points per ring) because the overlay
//! engine must never see NaN. Self-intersecting rings are accepted: the overlay resolves them.

use crate::clip::signed_area2;
use crate::error::Result;
use crate::types::{validate_points, Point};
use geo::{BooleanOps, Coord, LineString, MultiPolygon, Polygon};

/// Union of many polygons by pairwise unions in a balanced tree. geo's `unary_union` over all
/// inputs at once was seen to take minutes on two dozen small, overlapping crossing pieces with
/// shared edges (the clipped views of one crossing across frames); pairwise unions of the partial
/// results take well under a millisecond on the same input.
fn balanced_union(mut parts: Vec<MultiPolygon<f64>>) -> MultiPolygon<f64> {
    if parts.is_empty() {
        return MultiPolygon(vec![]);
    }
    while parts.len() > 1 {
        let mut next = Vec::with_capacity(parts.len().div_ceil(2));
        let mut it = parts.into_iter();
        while let Some(a) = it.next() {
            match it.next() {
                Some(b) => next.push(a.union(&b)),
                None => next.push(a),
            }
        }
        parts = next;
    }
    parts.pop().unwrap_or_else(|| MultiPolygon(vec![]))
}

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
///
/// Two rings (a crossing merge) first try [`union_fast`](crate::union_fast)'s direct union of two
/// simple polygons in general position, about ten times cheaper than the overlay; any input it
/// does not accept (self-intersections, touching or shared edges, near-degenerate crossings, zero
/// area, see its fallback rule) goes through geo's overlay exactly as before. Both give the same
/// rings up to floating-point rounding (i_overlay snaps to a grid of about `extent / 2^30`),
/// including each ring's first vertex (its smallest `(x, y)`).
pub fn polygon_union(rings: &[Vec<Point>]) -> Result<Vec<Vec<Point>>> {
    for (i, ring) in rings.iter().enumerate() {
        validate_points(open_ring(ring), 3, &format!("ring {i}"))?;
    }
    if let [a, b] = rings {
        if let Some(out) = crate::union_fast::union_two_simple(open_ring(a), open_ring(b)) {
            return Ok(out);
        }
    }
    Ok(overlay_union(rings))
}

/// The general path of [`polygon_union`] (validated input): geo's overlay.
fn overlay_union(rings: &[Vec<Point>]) -> Vec<Vec<Point>> {
    // Resolve every ring on its own first (a self-intersecting ring with lobes of opposite
    // orientation would otherwise cancel the other rings' winding numbers in the joint overlay).
    let polys: Vec<Polygon<f64>> = rings
        .iter()
        .flat_map(|r| geo::unary_union(std::iter::once(&to_polygon(open_ring(r)))).0)
        .collect();
    let union = balanced_union(polys.into_iter().map(|p| MultiPolygon(vec![p])).collect());
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
    out.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::GeomError;
    use proptest::prelude::*;

    fn p(x: f64, y: f64) -> Point {
        Point::new(x, y)
    }

    /// 24 clipped views of one Argoverse 2 crossing across frames (shared and collinear edges):
    /// a joint `unary_union` took minutes here; the balanced pairwise union is instant.
    #[test]
    fn many_clipped_views_of_one_crossing() {
        let rings: Vec<Vec<Point>> = vec![
            vec![
                p(6.625471, 9.997863),
                p(8.512670, 9.417476),
                p(8.115120, 10.530118),
            ],
            vec![
                p(6.918810, 9.907649),
                p(12.345511, 8.238728),
                p(11.236165, 11.415359),
            ],
            vec![
                p(7.354924, 9.773528),
                p(16.061265, 7.095989),
                p(14.618173, 11.388877),
                p(13.338296, 11.784891),
            ],
            vec![
                p(7.958973, 9.587759),
                p(19.692682, 5.979187),
                p(18.347774, 10.234882),
                p(14.133140, 11.538954),
            ],
            vec![
                p(8.843760, 9.315652),
                p(23.556107, 4.791034),
                p(22.361939, 8.992838),
                p(15.346108, 11.163643),
            ],
            vec![
                p(10.014680, 8.955549),
                p(27.836658, 3.474598),
                p(26.857552, 7.601827),
                p(17.071752, 10.629703),
            ],
            vec![
                p(11.354500, 8.543502),
                p(29.640000, 2.920000),
                p(30.160000, 6.580000),
                p(19.296337, 9.941382),
            ],
            vec![
                p(12.715823, 8.124843),
                p(29.640000, 2.920000),
                p(30.160000, 6.580000),
                p(22.183670, 9.047998),
            ],
            vec![
                p(13.533393, 7.873408),
                p(29.640000, 2.920000),
                p(30.160000, 6.580000),
                p(25.821547, 7.922383),
            ],
            vec![
                p(12.300282, 8.252638),
                p(29.640000, 2.920000),
                p(30.133388, 6.392696),
            ],
            vec![
                p(4.599749, 10.698543),
                p(4.570000, 10.630000),
                p(29.640000, 2.920000),
                p(30.009671, 5.521918),
            ],
            vec![
                p(5.231147, 12.153319),
                p(4.570000, 10.630000),
                p(29.640000, 2.920000),
                p(29.965571, 5.211516),
            ],
            vec![
                p(5.816146, 13.501187),
                p(4.570000, 10.630000),
                p(29.640000, 2.920000),
                p(29.961914, 5.185779),
            ],
            vec![
                p(4.570000, 10.630000),
                p(29.640000, 2.920000),
                p(29.974260, 5.272677),
                p(11.932773, 12.219781),
                p(6.050000, 14.040000),
            ],
            vec![
                p(5.498974, 10.344304),
                p(29.640000, 2.920000),
                p(29.991637, 5.394986),
                p(18.124971, 10.303821),
                p(6.916810, 13.771796),
            ],
            vec![
                p(7.312312, 9.786633),
                p(29.640000, 2.920000),
                p(30.016661, 5.571114),
                p(22.139298, 9.061727),
                p(8.817602, 13.183662),
            ],
            vec![
                p(8.956268, 9.281052),
                p(29.640000, 2.920000),
                p(30.045282, 5.772562),
                p(24.806923, 8.236323),
                p(10.540985, 12.650421),
            ],
            vec![
                p(10.452630, 8.820862),
                p(29.640000, 2.920000),
                p(30.074984, 5.981620),
                p(26.690560, 7.653497),
                p(12.105298, 12.166399),
            ],
            vec![
                p(11.817456, 8.401126),
                p(29.640000, 2.920000),
                p(30.101278, 6.166685),
                p(27.977279, 7.255367),
                p(13.522615, 11.727860),
            ],
            vec![
                p(13.119920, 8.000567),
                p(29.640000, 2.920000),
                p(30.128520, 6.358426),
                p(29.079512, 6.914319),
                p(14.873585, 11.309849),
            ],
            vec![
                p(14.319777, 7.631564),
                p(29.640000, 2.920000),
                p(30.158001, 6.565928),
                p(30.095993, 6.599805),
                p(16.118845, 10.924546),
            ],
            vec![
                p(15.494478, 7.270298),
                p(29.640000, 2.920000),
                p(30.160000, 6.580000),
                p(17.332342, 10.549072),
            ],
            vec![
                p(16.826368, 6.860690),
                p(29.640000, 2.920000),
                p(30.160000, 6.580000),
                p(18.703659, 10.124766),
            ],
            vec![
                p(18.232811, 6.428154),
                p(29.640000, 2.920000),
                p(30.160000, 6.580000),
                p(20.150291, 9.677156),
            ],
        ];
        let out = polygon_union(&rings).unwrap();
        assert_eq!(out.len(), 1);
        let area = signed_area2(&out[0]).abs() / 2.0;
        let max_in = rings
            .iter()
            .map(|r| signed_area2(r).abs() / 2.0)
            .fold(0.0, f64::max);
        assert!(
            area >= max_in - 1e-6,
            "union area {area} < largest input {max_in}"
        );
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
