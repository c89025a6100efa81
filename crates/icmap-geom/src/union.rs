//! Polygon union of pedestrian crossings (geo's `BooleanOps`, i_overlay underneath).
//!
//! Input is validated first (finite coordinates, at least 3 points per ring) because the overlay
//! engine must never see NaN. Self-intersecting rings are accepted: the overlay resolves them.

use crate::clip::{open_ring, signed_area2};
use crate::error::Result;
use crate::types::{points_in_domain, validate_points, Point};
use geo::{BooleanOps, Coord, LineString, MapCoordsInPlace, MultiPolygon, Polygon};

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
    if let [a, b] = rings {
        return polygon_union_two(a, b);
    }
    for (i, ring) in rings.iter().enumerate() {
        validate_ring(ring, i)?;
    }
    Ok(overlay_union(rings))
}

/// [`polygon_union`] of exactly two rings, taken by reference (no copies into a `Vec` of rings):
/// the same result and the same errors as `polygon_union(&[a.to_vec(), b.to_vec()])`.
pub fn polygon_union_two(a: &[Point], b: &[Point]) -> Result<Vec<Vec<Point>>> {
    validate_ring(a, 0)?;
    validate_ring(b, 1)?;
    let (a, b) = (open_ring(a), open_ring(b));
    if let Some(out) = crate::union_fast::union_two_simple(a, b) {
        return Ok(out);
    }
    Ok(union_two_resolved(a, b))
}

/// Errors unless ring number `i` has at least 3 points (without a repeated closing point), all
/// in the coordinate domain.
fn validate_ring(ring: &[Point], i: usize) -> Result<()> {
    let r = open_ring(ring);
    // The name is formatted only for an error (a merge is a few microseconds).
    if r.len() < 3 || !points_in_domain(r) {
        validate_points(r, 3, &format!("ring {i}"))?;
    }
    Ok(())
}

/// The exterior of a polygon without its repeated closing point.
fn exterior_points(poly: &Polygon<f64>) -> Vec<Point> {
    let mut ring: Vec<Point> = poly
        .exterior()
        .0
        .iter()
        .map(|c| Point::new(c.x, c.y))
        .collect();
    if ring.len() >= 2 && ring[0] == ring[ring.len() - 1] {
        ring.pop();
    }
    ring
}

/// Two rings that the fast path declined. A ring that is not clearly simple
/// ([`ring_is_simple`](crate::union_fast::ring_is_simple)) is resolved alone by the overlay, as
/// the general path does first. When every resolved piece is a polygon without holes, the fast
/// path gets a second try: the pieces (and the simple ring) are added one at a time, largest
/// first, each step required to give one polygon without holes (so that no piece could fall into
/// a dropped hole); the fast path decides by itself whether each pair is in general position.
/// Otherwise the general path goes on from the resolved rings (computed once), giving exactly
/// what [`overlay_union`] gives.
fn union_two_resolved(a: &[Point], b: &[Point]) -> Vec<Vec<Point>> {
    let resolved: [Option<Vec<Polygon<f64>>>; 2] =
        [a, b].map(|r| (!crate::union_fast::ring_is_simple(r)).then(|| resolve_ring(r)));
    if resolved.iter().any(Option::is_some) {
        if let Some(out) = union_pieces(a, b, &resolved) {
            return vec![out];
        }
    }
    let [res_a, res_b] = resolved;
    let polys = [(a, res_a), (b, res_b)]
        .into_iter()
        .flat_map(|(r, res)| res.unwrap_or_else(|| resolve_ring(r)))
        .collect();
    union_of_resolved(polys)
}

/// The second try of [`union_two_resolved`]: the union as one ring, or `None` when any step is
/// not certain.
fn union_pieces(
    a: &[Point],
    b: &[Point],
    resolved: &[Option<Vec<Polygon<f64>>>; 2],
) -> Option<Vec<Point>> {
    let mut pieces: Vec<(f64, Vec<Point>)> = Vec::new();
    for (r, res) in [(a, &resolved[0]), (b, &resolved[1])] {
        match res {
            None => pieces.push((signed_area2(r).abs(), r.to_vec())),
            Some(polys) => {
                for p in polys {
                    if !p.interiors().is_empty() {
                        return None;
                    }
                    let ring = exterior_points(p);
                    pieces.push((signed_area2(&ring).abs(), ring));
                }
            }
        }
    }
    pieces.sort_by(|x, y| y.0.total_cmp(&x.0));
    let mut it = pieces.into_iter().map(|(_, r)| r);
    let first = it.next()?;
    // At least one step (its output follows the overlay's conventions: start vertex, runs).
    let mut acc = crate::union_fast::union_two_simple_solid(&first, &it.next()?)?;
    for piece in it {
        acc = crate::union_fast::union_two_simple_solid(&acc, &piece)?;
    }
    Some(acc)
}

/// A ring resolved into simple polygons alone: geo's `unary_union` of the ring. (Taking a clearly
/// simple ring as it is would skip an overlay, but the result is snapped twice to different grids
/// and then differs from this one by a grid step, sometimes starting at another vertex.)
fn resolve_ring(ring: &[Point]) -> Vec<Polygon<f64>> {
    let scale = overlay_scale(half_extent(ring.iter().map(|p| (p.x, p.y))));
    if scale == 1.0 {
        return geo::unary_union(std::iter::once(&to_polygon(ring))).0;
    }
    let scaled: Vec<Point> = ring.iter().map(|p| p * scale).collect();
    let mut polys = geo::unary_union(std::iter::once(&to_polygon(&scaled))).0;
    for p in &mut polys {
        p.map_coords_in_place(|c| c / scale);
    }
    polys
}

/// i_overlay (under geo's `BooleanOps`) maps coordinates onto its integer grid with the scale
/// `2^(29 - floor(log2(h)))`, `h` the half extent of the bounding box: below `h` of about 2^-994
/// (1e-299 m) that power of two overflows to infinity and the overlay never returns (a crossing
/// ring of 1e-299 m spun for 15 CPU-minutes). Geometry with a half extent below this bound
/// (2^-900) goes through the overlay scaled by [`OVERLAY_SCALE_UP`] and is scaled back after.
const OVERLAY_MIN_HALF_EXTENT: f64 = f64::from_bits((1023 - 900) << 52);
/// 2^1000: a half extent in `[2^-1074, 2^-900)` becomes one in `[2^-74, 2^100)`, well inside the
/// overlay's range. Coordinates are at most 2^53 half extents from the origin here (a larger one
/// would have a coarser spacing than the extent), so none overflows. A power of two changes no
/// digit of a normal number, and the overlay's own scale is a power of two: the result is the
/// overlay's at a normal size, scaled.
const OVERLAY_SCALE_UP: f64 = f64::from_bits((1023 + 1000) << 52);

/// The factor by which geometry of bounding-box half extent `h` is scaled for the overlay (see
/// [`OVERLAY_MIN_HALF_EXTENT`]): 1 unless `0 < h < 2^-900`.
fn overlay_scale(h: f64) -> f64 {
    if h > 0.0 && h < OVERLAY_MIN_HALF_EXTENT {
        OVERLAY_SCALE_UP
    } else {
        1.0
    }
}

/// Half the larger side of the bounding box of the coordinates (0 for none).
fn half_extent(coords: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in coords {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let h = 0.5 * (x1 - x0).max(y1 - y0);
    if h.is_finite() {
        h
    } else {
        0.0
    }
}

/// The general path of [`polygon_union`] (validated input): geo's overlay.
fn overlay_union(rings: &[Vec<Point>]) -> Vec<Vec<Point>> {
    // Resolve every ring on its own first (a self-intersecting ring with lobes of opposite
    // orientation would otherwise cancel the other rings' winding numbers in the joint overlay).
    let polys: Vec<Polygon<f64>> = rings
        .iter()
        .flat_map(|r| resolve_ring(open_ring(r)))
        .collect();
    union_of_resolved(polys)
}

/// The pairwise union of resolved polygons, as [`polygon_union`] returns it.
fn union_of_resolved(mut polys: Vec<Polygon<f64>>) -> Vec<Vec<Point>> {
    // Tiny geometry only (see OVERLAY_MIN_HALF_EXTENT): the overlay works on it scaled up.
    let scale = overlay_scale(half_extent(
        polys
            .iter()
            .flat_map(|p| {
                p.exterior()
                    .0
                    .iter()
                    .chain(p.interiors().iter().flat_map(|r| r.0.iter()))
            })
            .map(|c| (c.x, c.y)),
    ));
    if scale != 1.0 {
        for p in &mut polys {
            p.map_coords_in_place(|c| c * scale);
        }
    }
    let mut union = balanced_union(polys.into_iter().map(|p| MultiPolygon(vec![p])).collect());
    if scale != 1.0 {
        union.map_coords_in_place(|c| c / scale);
    }
    let mut out: Vec<(f64, Vec<Point>)> = Vec::new();
    for poly in union.0 {
        let mut ring = exterior_points(&poly);
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
    use crate::splitmix::Rng;
    use crate::test_util::p;
    use proptest::prelude::*;

    /// The rings of [`many_clipped_views_of_one_crossing`].
    const CLIPPED_VIEWS: [&[(f64, f64)]; 24] = [
        &[
            (6.625471, 9.997863),
            (8.512670, 9.417476),
            (8.115120, 10.530118),
        ],
        &[
            (6.918810, 9.907649),
            (12.345511, 8.238728),
            (11.236165, 11.415359),
        ],
        &[
            (7.354924, 9.773528),
            (16.061265, 7.095989),
            (14.618173, 11.388877),
            (13.338296, 11.784891),
        ],
        &[
            (7.958973, 9.587759),
            (19.692682, 5.979187),
            (18.347774, 10.234882),
            (14.133140, 11.538954),
        ],
        &[
            (8.843760, 9.315652),
            (23.556107, 4.791034),
            (22.361939, 8.992838),
            (15.346108, 11.163643),
        ],
        &[
            (10.014680, 8.955549),
            (27.836658, 3.474598),
            (26.857552, 7.601827),
            (17.071752, 10.629703),
        ],
        &[
            (11.354500, 8.543502),
            (29.640000, 2.920000),
            (30.160000, 6.580000),
            (19.296337, 9.941382),
        ],
        &[
            (12.715823, 8.124843),
            (29.640000, 2.920000),
            (30.160000, 6.580000),
            (22.183670, 9.047998),
        ],
        &[
            (13.533393, 7.873408),
            (29.640000, 2.920000),
            (30.160000, 6.580000),
            (25.821547, 7.922383),
        ],
        &[
            (12.300282, 8.252638),
            (29.640000, 2.920000),
            (30.133388, 6.392696),
        ],
        &[
            (4.599749, 10.698543),
            (4.570000, 10.630000),
            (29.640000, 2.920000),
            (30.009671, 5.521918),
        ],
        &[
            (5.231147, 12.153319),
            (4.570000, 10.630000),
            (29.640000, 2.920000),
            (29.965571, 5.211516),
        ],
        &[
            (5.816146, 13.501187),
            (4.570000, 10.630000),
            (29.640000, 2.920000),
            (29.961914, 5.185779),
        ],
        &[
            (4.570000, 10.630000),
            (29.640000, 2.920000),
            (29.974260, 5.272677),
            (11.932773, 12.219781),
            (6.050000, 14.040000),
        ],
        &[
            (5.498974, 10.344304),
            (29.640000, 2.920000),
            (29.991637, 5.394986),
            (18.124971, 10.303821),
            (6.916810, 13.771796),
        ],
        &[
            (7.312312, 9.786633),
            (29.640000, 2.920000),
            (30.016661, 5.571114),
            (22.139298, 9.061727),
            (8.817602, 13.183662),
        ],
        &[
            (8.956268, 9.281052),
            (29.640000, 2.920000),
            (30.045282, 5.772562),
            (24.806923, 8.236323),
            (10.540985, 12.650421),
        ],
        &[
            (10.452630, 8.820862),
            (29.640000, 2.920000),
            (30.074984, 5.981620),
            (26.690560, 7.653497),
            (12.105298, 12.166399),
        ],
        &[
            (11.817456, 8.401126),
            (29.640000, 2.920000),
            (30.101278, 6.166685),
            (27.977279, 7.255367),
            (13.522615, 11.727860),
        ],
        &[
            (13.119920, 8.000567),
            (29.640000, 2.920000),
            (30.128520, 6.358426),
            (29.079512, 6.914319),
            (14.873585, 11.309849),
        ],
        &[
            (14.319777, 7.631564),
            (29.640000, 2.920000),
            (30.158001, 6.565928),
            (30.095993, 6.599805),
            (16.118845, 10.924546),
        ],
        &[
            (15.494478, 7.270298),
            (29.640000, 2.920000),
            (30.160000, 6.580000),
            (17.332342, 10.549072),
        ],
        &[
            (16.826368, 6.860690),
            (29.640000, 2.920000),
            (30.160000, 6.580000),
            (18.703659, 10.124766),
        ],
        &[
            (18.232811, 6.428154),
            (29.640000, 2.920000),
            (30.160000, 6.580000),
            (20.150291, 9.677156),
        ],
    ];

    /// 24 clipped views of one Argoverse 2 crossing across frames (shared and collinear edges):
    /// a joint `unary_union` took minutes here; the balanced pairwise union is instant.
    #[test]
    fn many_clipped_views_of_one_crossing() {
        let rings: Vec<Vec<Point>> = CLIPPED_VIEWS
            .iter()
            .map(|r| r.iter().map(|&(x, y)| p(x, y)).collect())
            .collect();
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

    /// A C-shaped ring (open to the left) and a bar closing its mouth: their union is a square
    /// ring around a hole.
    fn c_and_bar() -> (Vec<Point>, Vec<Point>) {
        let c = vec![
            p(0.0, 0.0),
            p(6.0, 0.0),
            p(6.0, 6.0),
            p(0.0, 6.0),
            p(0.0, 4.0),
            p(4.0, 4.0),
            p(4.0, 2.0),
            p(0.0, 2.0),
        ];
        (c, rect(-1.0, 1.0, 2.0, 5.0))
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

    /// Global ring of one of three kinds: an axis-parallel rectangle with integer corners sampled
    /// every 1 m (as stored crossings start out), a rotated rectangle, or a star-shaped
    /// (non-convex) polygon; all simple and counter-clockwise.
    fn global_ring(kind: u8, rng: &mut Rng) -> Vec<Point> {
        let (cx, cy) = (rng.uniform(-500.0, 500.0), rng.uniform(-500.0, 500.0));
        match kind % 3 {
            0 => {
                let (x0, y0) = (cx.round(), cy.round());
                let (w, h) = (
                    rng.uniform(2.0, 15.0).round(),
                    rng.uniform(2.0, 15.0).round(),
                );
                let r = rect(x0, y0, x0 + w, y0 + h);
                crate::resample::resample_spacing(&r, 1.0, true).unwrap()
            }
            1 => {
                let (w, h, a) = (
                    rng.uniform(2.0, 15.0),
                    rng.uniform(2.0, 6.0),
                    rng.uniform(0.0, 3.2),
                );
                let (c, s) = (a.cos(), a.sin());
                let r: Vec<Point> = rect(-w / 2.0, -h / 2.0, w / 2.0, h / 2.0)
                    .iter()
                    .map(|q| p(cx + c * q.x - s * q.y, cy + s * q.x + c * q.y))
                    .collect();
                crate::resample::resample_spacing(&r, 1.0, true).unwrap()
            }
            _ => {
                let k = 5 + (rng.next() * 30.0) as usize;
                let big = rng.uniform(3.0, 10.0);
                (0..k)
                    .map(|i| {
                        let t =
                            (i as f64 + rng.uniform(0.0, 0.8)) / k as f64 * std::f64::consts::TAU;
                        let r = rng.uniform(0.4 * big, big);
                        p(cx + r * t.cos(), cy + r * t.sin())
                    })
                    .collect()
            }
        }
    }

    /// A detection of `g`: `g` scaled by `scale` towards a random point near it, shifted by
    /// `shift`, resampled to 20 points, with N(0, `noise`) noise.
    fn detection(g: &[Point], rng: &mut Rng, scale: f64, shift: f64, noise: f64) -> Vec<Point> {
        let n = g.len() as f64;
        let c = g
            .iter()
            .fold(p(0.0, 0.0), |a, q| p(a.x + q.x / n, a.y + q.y / n));
        let (fx, fy) = (c.x + rng.normal(2.0), c.y + rng.normal(2.0));
        let moved: Vec<Point> = g
            .iter()
            .map(|q| {
                p(
                    fx + (q.x - fx) * scale + shift,
                    fy + (q.y - fy) * scale + shift,
                )
            })
            .collect();
        crate::resample::resample(&moved, 20, true)
            .unwrap()
            .into_iter()
            .map(|q| p(q.x + rng.normal(noise), q.y + rng.normal(noise)))
            .collect()
    }

    /// Checks the fast path against the overlay when it is taken: same number of rings, each
    /// ring's area equal to 1e-9 relative or to the overlay's grid rounding (perimeter times
    /// i_overlay's grid step), and the same ring once resampled at 1 m (start included), up to the
    /// grid rounding amplified at shallow crossings. Returns whether the fast path was taken.
    fn check_fast_vs_overlay(a: &[Point], b: &[Point]) -> bool {
        let slow = overlay_union(&[a.to_vec(), b.to_vec()]);
        let Some(fast) = crate::union_fast::union_two_simple(a, b) else {
            return false;
        };
        assert_eq!(fast.len(), slow.len(), "ring count");
        let ext = a.iter().chain(b).fold(
            [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ],
            |e, q| [e[0].min(q.x), e[1].max(q.x), e[2].min(q.y), e[3].max(q.y)],
        );
        let grid = (ext[1] - ext[0]).max(ext[3] - ext[2]) * 2f64.powi(-29);
        for (f, s) in fast.iter().zip(&slow) {
            let (af, as_) = (area(f), area(s));
            let perim = crate::resample::polyline_length(s, true);
            assert!(af > 0.0, "ccw");
            assert!(
                (af - as_).abs() <= (1e-9 * as_).max(perim * grid),
                "area fast {af} overlay {as_}"
            );
            let rf = crate::resample::resample_spacing(f, 1.0, true).unwrap();
            let rs = crate::resample::resample_spacing(s, 1.0, true).unwrap();
            let pf = crate::resample::polyline_length(f, true);
            // the overlay snaps its vertices to the grid, and an intersection of two nearly
            // parallel edges moves by a grid step over the sine of their angle (1.4e-6 m seen)
            assert!(
                (pf - perim).abs() < 1e-5,
                "perimeter fast {pf} overlay {perim}"
            );
            if rf.len() != rs.len() {
                // ceil(perimeter / spacing) on a whole number of metres (a contained integer
                // rectangle): rounding decides the count either way.
                assert!((perim - perim.round()).abs() < 1e-6, "resampled count");
                continue;
            }
            for (x, y) in rf.iter().zip(&rs) {
                assert!((x - y).norm() < 1e-4, "resampled {x:?} vs {y:?}");
            }
        }
        true
    }

    #[test]
    fn fast_path_matches_overlay_on_rectangles() {
        let (a, b) = (rect(0.0, 0.0, 2.0, 1.0), rect(1.0, -0.5, 3.0, 0.5));
        assert!(check_fast_vs_overlay(&a, &b));
        let u = polygon_union(&[a, b]).unwrap();
        assert_eq!(u.len(), 1);
        assert!((area(&u[0]) - 3.5).abs() < 1e-12);
        // Lowest-left vertex (0, 0) second: the overlay's contours start at its predecessor.
        assert_eq!(u[0][1], p(0.0, 0.0));
        assert_eq!(u[0][0], p(0.0, 1.0));
        // Rectangles (x0, y0, x1, y1) of each pair.
        for (a, b) in [
            // Containment both ways, and disjoint rings.
            ([0.0, 0.0, 4.0, 4.0], [1.0, 1.0, 2.0, 2.0]),
            ([1.0, 1.0, 2.0, 2.0], [0.0, 0.0, 4.0, 4.0]),
            ([0.0, 0.0, 1.0, 1.0], [5.0, 0.0, 8.0, 2.0]),
            // A cross: the union has a concave outline.
            ([0.0, 1.0, 3.0, 2.0], [1.0, 0.0, 2.0, 3.0]),
        ] {
            let r = |[x0, y0, x1, y1]: [f64; 4]| rect(x0, y0, x1, y1);
            assert!(check_fast_vs_overlay(&r(a), &r(b)), "{a:?} {b:?}");
        }
        // A ring around a hole: an annulus-like union whose hole is dropped.
        let (c, bar) = c_and_bar();
        assert!(check_fast_vs_overlay(&c, &bar));
        let u = polygon_union(&[c, bar]).unwrap();
        assert_eq!(u.len(), 1);
        // Outline [-1, 6] x [0, 6] less the corners left of x = 0 (4 + 36); the 2 x 2 hole dropped.
        assert!((area(&u[0]) - 40.0).abs() < 1e-9);
    }

    /// Crossing-like merges (noisy partial copies overlapping the global ring): the fast path is
    /// the common case and agrees with the overlay (so the checks above are not vacuous).
    #[test]
    fn fast_path_is_common_on_crossing_merges() {
        let mut taken = 0;
        let total = 300;
        for seed in 0..total {
            let mut rng = Rng(seed);
            let g = global_ring((seed % 3) as u8, &mut rng);
            let scale = rng.uniform(0.5, 1.1);
            let shift = rng.uniform(-1.0, 1.0);
            let d = detection(&g, &mut rng, scale, shift, 0.1);
            taken += check_fast_vs_overlay(&g, &d) as usize;
        }
        assert!(
            taken * 10 >= total as usize * 7,
            "fast path taken {taken} / {total}"
        );
    }

    /// Degenerate and touching inputs are not the fast path's business: it declines them, and
    /// the overlay still gives the right union.
    #[test]
    fn degenerate_inputs_take_the_fallback() {
        let a = rect(0.0, 0.0, 2.0, 1.0);
        let cases: Vec<(Vec<Point>, f64)> = vec![
            (a.clone(), 2.0),                                   // identical
            (rect(2.0, 0.0, 3.0, 1.0), 3.0),                    // shared edge
            (rect(1.0, 0.0, 3.0, 1.0), 3.0),                    // collinear overlapping edges
            (rect(2.0, 1.0, 3.0, 2.0), 3.0),                    // touching corners
            (vec![p(1.0, 1.0), p(1.5, 2.0), p(0.5, 2.0)], 2.5), // vertex on an edge
            (
                vec![p(0.0, 0.0), p(1.0, 1.0), p(1.0, 0.0), p(0.0, 1.0)],
                2.0,
            ), // bowtie inside
            (vec![p(5.0, 5.0), p(6.0, 5.0), p(7.0, 5.0)], 2.0), // zero area
            (
                vec![
                    p(3.0, 0.0),
                    p(4.0, 0.0),
                    p(4.0, 1.0),
                    p(3.0, 1.0),
                    p(3.5, 0.5),
                    p(3.5, 0.5 + 1e-12),
                ],
                2.75,
            ), // a tiny edge
        ];
        for (b, want) in cases {
            assert!(
                crate::union_fast::union_two_simple(&a, &b).is_none(),
                "fast path must decline {b:?}"
            );
            let u = polygon_union(&[a.clone(), b.clone()]).unwrap();
            let total: f64 = u.iter().map(|r| area(r)).sum();
            assert!(
                (total - want).abs() < 1e-6,
                "{b:?}: area {total} want {want}"
            );
            assert!(u.iter().all(|r| area(r) > 0.0));
        }
    }

    /// The fast path on a self-crossing ring declines too (the overlay resolves it).
    #[test]
    fn self_crossing_detection_falls_back() {
        let g = rect(0.0, 0.0, 4.0, 2.0);
        let d = vec![p(1.0, -1.0), p(3.0, 3.0), p(3.0, -1.0), p(1.0, 3.0)];
        assert!(crate::union_fast::union_two_simple(&g, &d).is_none());
        let u = polygon_union(&[g, d]).unwrap();
        assert_eq!(u.len(), 1);
        assert!(area(&u[0]) > 8.0);
    }

    /// A self-crossing detection over a simple global ring: the detection is resolved alone and
    /// its pieces go through the fast path (second try), agreeing with the overlay.
    #[test]
    fn self_crossing_detection_second_try_matches_overlay() {
        let g = rect(0.0, 0.0, 4.0, 2.0);
        // A bowtie crossing itself at (2.1, 1.05), inside g; its lobes stick out of g.
        let d = vec![p(1.0, -1.0), p(3.2, 3.1), p(3.3, -0.9), p(1.1, 3.2)];
        assert!(crate::union_fast::ring_is_simple(&g));
        assert!(!crate::union_fast::ring_is_simple(&d));
        assert!(crate::union_fast::union_two_simple(&g, &d).is_none());
        let resolved = [None, Some(resolve_ring(&d))];
        assert!(resolved[1].as_ref().is_some_and(|r| !r.is_empty()));
        let second = union_pieces(&g, &d, &resolved).expect("second try taken");
        let slow = overlay_union(&[g.clone(), d.clone()]);
        assert_eq!(slow.len(), 1);
        assert!((area(&second) - area(&slow[0])).abs() < 1e-9);
        assert!(area(&second) > 8.0);
        assert_eq!(polygon_union(&[g, d]).unwrap(), vec![second.clone()]);
        let rf = crate::resample::resample_spacing(&second, 1.0, true).unwrap();
        let rs = crate::resample::resample_spacing(&slow[0], 1.0, true).unwrap();
        assert_eq!(rf.len(), rs.len());
        assert!(rf.iter().zip(&rs).all(|(x, y)| (x - y).norm() < 1e-6));
    }

    /// The second try declines when a step's union has a hole (a later piece could be an island
    /// in it, which the overlay keeps as a separate polygon), and with a single piece.
    #[test]
    fn second_try_declines_holes_and_single_pieces() {
        let (c, bar) = c_and_bar();
        assert!(crate::union_fast::union_two_simple(&c, &bar).is_some());
        assert!(crate::union_fast::union_two_simple_solid(&c, &bar).is_none());
        // An island in that hole: two polygons from the overlay, never one ring.
        let island = vec![p(2.5, 2.9), p(3.0, 3.1), p(2.8, 3.3)];
        let u = overlay_union(&[c.clone(), bar.clone(), island]);
        assert_eq!(u.len(), 2);
        // A resolved ring with zero area leaves one piece: no step, no second try.
        let flat = vec![p(1.0, 1.0), p(2.0, 2.0), p(3.0, 3.0), p(2.0, 2.0)];
        let resolved = [None, Some(resolve_ring(&flat))];
        assert!(union_pieces(&c, &flat, &resolved).is_none());
    }

    /// A ring that `ring_is_simple` accepts resolves to itself: the overlay's `unary_union` gives
    /// one polygon without holes, with the same area and the same vertices up to its grid; the
    /// bowtie, a spike and a ring touching itself are refused.
    #[test]
    fn simple_rings_resolve_to_themselves() {
        for seed in 0..60u64 {
            let mut rng = Rng(seed);
            let g = global_ring((seed % 3) as u8, &mut rng);
            let d = detection(&g, &mut rng, 0.9, 0.3, 0.05);
            for r in [g, d] {
                if !crate::union_fast::ring_is_simple(&r) {
                    continue;
                }
                let res = resolve_ring(&r);
                assert_eq!(res.len(), 1);
                assert!(res[0].interiors().is_empty());
                let e = exterior_points(&res[0]);
                assert!(
                    (area(&e)
                        - area(
                            &to_polygon(&r)
                                .exterior()
                                .0
                                .iter()
                                .map(|c| p(c.x, c.y))
                                .collect::<Vec<_>>()
                        ))
                    .abs()
                        < 1e-6
                );
                assert!(e.iter().all(|q| r.iter().any(|v| (v - q).norm() < 1e-6)));
            }
        }
        // Rings that are not simple: a bowtie, a spike, a vertex touching an edge.
        let bowtie: &[(f64, f64)] = &[(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0)];
        let spike = &[
            (0.0, 0.0),
            (2.0, 0.0),
            (2.0, 1.0),
            (1.0, 1.0),
            (1.0, 3.0),
            (1.0, 1.001),
        ];
        let touching = &[(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (2.0, 0.0), (0.0, 2.0)];
        for ring in [bowtie, spike, touching] {
            let ring: Vec<Point> = ring.iter().map(|&(x, y)| p(x, y)).collect();
            assert!(!crate::union_fast::ring_is_simple(&ring), "{ring:?}");
        }
        assert!(crate::union_fast::ring_is_simple(&rect(0.0, 0.0, 2.0, 1.0)));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]

        /// Random crossings-like inputs: the fast path, when taken, agrees with the overlay;
        /// containment (scale < 1, no shift), disjoint (large shift) and partial overlaps occur.
        #[test]
        fn prop_fast_path_agrees_with_overlay(seed in any::<u64>(), kind in 0u8..3,
                                              scale in 0.2f64..1.3, shift in prop_oneof![Just(0.0), -3.0f64..3.0, 20.0f64..30.0],
                                              noise in prop_oneof![Just(0.0), 0.01f64..0.2]) {
            let mut rng = Rng(seed);
            let g = global_ring(kind, &mut rng);
            let d = detection(&g, &mut rng, scale, shift, noise);
            check_fast_vs_overlay(&g, &d);
            check_fast_vs_overlay(&d, &g);
            // Also with the detection reversed (clockwise) and the global ring itself.
            let mut rev = d.clone();
            rev.reverse();
            check_fast_vs_overlay(&g, &rev);
            prop_assert!(crate::union_fast::union_two_simple(&g, &g).is_none());
        }
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

    /// Runs `f` on its own thread and fails unless it returns within `secs` seconds (a hang
    /// fails the test instead of freezing the suite; the thread is left behind).
    fn within<T: Send + 'static>(secs: u64, f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        rx.recv_timeout(std::time::Duration::from_secs(secs))
            .expect("did not return in time")
    }

    /// Issue 14, point 1: a ring of ~1e-299 m made the overlay spin forever (its grid scale
    /// overflowed). Now every union returns; a ring whose area underflows to zero contributes
    /// nothing.
    #[test]
    #[allow(clippy::excessive_precision)] // the ring as the fuzzer found it
    fn tiny_rings_return() {
        let tiny = vec![
            p(-4.1006077439108852e-299, 1.1037331569773797e-299),
            p(-4.3541446871708736e-299, 7.2194332142851638e-300),
            p(-4.2127516405641947e-299, 6.3347407334057527e-300),
        ];
        let sq = rect(0.0, 0.0, 1.0, 1.0);
        let t1 = tiny.clone();
        assert!(within(10, move || polygon_union(&[t1])).unwrap().is_empty());
        let (t2, s2) = (tiny.clone(), sq.clone());
        let u = within(10, move || polygon_union(&[t2, s2])).unwrap();
        assert_eq!(u.len(), 1);
        assert!((area(&u[0]) - 1.0).abs() < 1e-12);
        let (t3, s3) = (tiny.clone(), sq.clone());
        let shifted: Vec<Point> = sq.iter().map(|q| p(q.x + 0.5, q.y + 0.5)).collect();
        let u = within(10, move || polygon_union(&[t3, s3, shifted])).unwrap();
        assert_eq!(u.len(), 1);
        assert!((area(&u[0]) - 1.75).abs() < 1e-12);
        // Two overlapping squares and a bowtie at every scale down to the subnormals: the union
        // returns, and while areas are representable it is the union at 1 m scaled (the
        // overlay's result is scale-invariant up to its grid).
        let shapes = |s: f64| {
            (
                [
                    rect(0.0, 0.0, s, s),
                    rect(0.5 * s, 0.5 * s, 1.5 * s, 1.5 * s),
                ],
                vec![p(0.0, 0.0), p(s, s), p(s, 0.0), p(0.0, s)],
            )
        };
        let total = |u: &[Vec<Point>]| u.iter().map(|r| area(r)).sum::<f64>();
        let (squares, bowtie) = shapes(1.0);
        let (want_u, want_v) = (
            total(&polygon_union(&squares).unwrap()),
            total(&polygon_union(&[bowtie]).unwrap()),
        );
        assert!((want_u - 1.75).abs() < 1e-9 && want_v > 0.0);
        for e in [
            -30, -100, -150, -160, -200, -271, -272, -290, -299, -300, -305, -308, -312, -320,
        ] {
            let s = 10f64.powi(e);
            let (squares, bowtie) = shapes(s);
            let u = within(10, move || polygon_union(&squares)).unwrap();
            let v = within(10, move || polygon_union(&[bowtie])).unwrap();
            if e >= -150 {
                assert_eq!(u.len(), 1, "scale 1e{e}");
                assert!((total(&u) / (s * s) - want_u).abs() < 1e-6, "scale 1e{e}");
                assert!((total(&v) / (s * s) - want_v).abs() < 1e-6, "scale 1e{e}");
            }
            assert!(u
                .iter()
                .chain(&v)
                .all(|r| r.len() >= 3 && signed_area2(r) > 0.0));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Rings at any scale from the subnormals to 1e7 m, one, two or three of them (the fast
        /// path, the overlay, and the fast path's second try): every union returns in bounded
        /// time, with rings of at least 3 points and positive area.
        #[test]
        fn prop_any_scale_returns(e in -325i32..7, shapes in prop::collection::vec(prop::collection::vec((-1.0f64..1.0, -1.0f64..1.0), 3..9), 1..4)) {
            let s = 10f64.powi(e);
            let rings: Vec<Vec<Point>> = shapes.iter().map(|r| r.iter().map(|&(x, y)| p(x * s, y * s)).collect()).collect();
            // (A ring that repeats its first point may have too few points: an error, in time.)
            if let Ok(u) = within(10, move || polygon_union(&rings)) {
                // (The doubled area: at 1e-161 m the area itself can round to zero.)
                prop_assert!(u.iter().all(|r| r.len() >= 3 && signed_area2(r) > 0.0));
            }
        }
    }
}
