//! Crossing instances from a crossing mask: each connected component (8-connectivity) large
//! enough becomes one outline per crossing in it.
//!
//! A component's holes of inscribed radius up to `max_hole` are filled (the unpainted inside of
//! one wide crossing's outline mask). Crossings that touch (the arms of an intersection, often a
//! ring around it) form one mask whose outline would cover them all: a mask around a wider hole
//! is cut along the sides of the hole's convex hull; a mask that fills less than
//! `rectangularity` of its minimum rotated rectangle along the straight runs of its skeleton;
//! both found by Douglas-Peucker with `corner_tolerance`. Every cell goes to its nearest side or
//! run, then the two parts whose union is most rectangular are joined while it stays above
//! `rectangularity` ([`crossing_parts`]).
//!
//! A part's outline: for a cut mask a rectangle fitted robustly to its cells
//! ([`band_rectangle`]); otherwise the convex hull of its cells grown by half a cell (mitre),
//! simplified by `hull_simplify` (0: their minimum rotated rectangle); then shrunk by `shrink`
//! (the target's line radius), kept unshrunk where nothing would be left.

use super::buffer::{capsule, expand_convex, shrink_convex};
use super::hull::{capsule_area, convex_hull, min_area_rectangle, signed_area2, Hull};
use super::principal::principal_axes;
use super::simplify::{simplify_line, simplify_ring};
use super::{branches, raster, Cell, Frame, Grid, VectoriseParams};
use crate::types::Point;

/// A component's cells copied into a grid around them (one unset cell of margin): the grid and
/// the global cell of its `(0, 0)`.
fn crop(cells: &[Cell]) -> (Grid<bool>, Cell) {
    // The cells' range along one axis with the margin: (first, one past the last).
    let range = |axis: fn(&Cell) -> usize| {
        let lo = cells.iter().map(axis).min().unwrap_or(0).saturating_sub(1);
        (lo, cells.iter().map(axis).max().unwrap_or(0) + 2)
    };
    let ((i0, i1), (j0, j1)) = (range(|c| c.0), range(|c| c.1));
    let mut g = Grid::filled(i1 - i0, j1 - j0, false);
    for &(i, j) in cells {
        g.set(i - i0, j - j0, true);
    }
    (g, (i0, j0))
}

/// The convex hull of cells (their centres in metres): only each row's two end cells can be
/// vertices (the cells between lie on the segment joining them), so only those are hulled.
fn cell_hull(frame: &Frame, cells: &[Cell]) -> Hull {
    let mut ends: std::collections::BTreeMap<usize, (usize, usize)> = Default::default();
    for &(i, j) in cells {
        let e = ends.entry(i).or_insert((j, j));
        e.0 = e.0.min(j);
        e.1 = e.1.max(j);
    }
    let pts: Vec<Point> = ends
        .iter()
        .flat_map(|(&i, &(a, b))| [frame.metres((i, a)), frame.metres((i, b))])
        .collect();
    convex_hull(&pts)
}

/// The area of the minimum rotated rectangle of a hull grown by `half` (mitre).
fn area_of_rect_around(hull: &Hull, half: f64) -> f64 {
    match hull {
        Hull::Empty => 0.0,
        Hull::Point(_) => capsule_area(0.0, half),
        Hull::Segment(a, b) => capsule_area((b - a).norm(), half),
        Hull::Polygon(h) => match min_area_rectangle(h) {
            Some((_, w, l)) => (w + 2.0 * half) * (l + 2.0 * half),
            None => 0.0,
        },
    }
}

/// The fraction of the minimum rotated rectangle of `m` cells with hull `hull`, grown by half a
/// cell, that the cells cover (1 for no area), as the Python `_fill`.
fn fill(m: usize, hull: &Hull, half: f64) -> f64 {
    let area = area_of_rect_around(hull, half);
    if area > 0.0 {
        (m as f64 * (2.0 * half) * (2.0 * half)) / area
    } else {
        1.0
    }
}

/// The vertices of the hull (the points that matter for the hull of a union).
fn hull_points(h: &Hull) -> Vec<Point> {
    match h {
        Hull::Empty => Vec::new(),
        Hull::Point(p) => vec![*p],
        Hull::Segment(a, b) => vec![*a, *b],
        Hull::Polygon(v) => v.clone(),
    }
}

/// numpy's `percentile(values, q)` (linear), `values` sorted.
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let virt = (n - 1) as f64 * (q / 100.0);
    let prev = (virt.floor().max(0.0) as usize).min(n - 1);
    let next = (prev + 1).min(n - 1);
    let t = virt - prev as f64;
    let (a, b) = (sorted[prev], sorted[next]);
    let diff = b - a;
    if t >= 0.5 {
        b - diff * (1.0 - t)
    } else {
        a + diff * t
    }
}

/// A rectangle fitted robustly to the cells `xy` of one part of a split crossing mask: along its
/// principal axis from the 1st to the 99th percentile, across it the width the 10th-90th
/// percentiles span in a uniform band (corners in the order of the Python `_band_rectangle`).
pub fn band_rectangle(xy: &[Point], half: f64) -> Vec<Point> {
    let m = xy.len().max(1) as f64;
    let (mut sx, mut sy) = (0.0, 0.0);
    for p in xy {
        sx += p.x;
        sy += p.y;
    }
    let centre = Point::new(sx / m, sy / m);
    let a: Vec<Point> = xy
        .iter()
        .map(|p| Point::new(p.x - centre.x, p.y - centre.y))
        .collect();
    let vt = principal_axes(&a);
    let proj = |k: usize| -> Vec<f64> {
        let mut v: Vec<f64> = a.iter().map(|p| p.x * vt[k][0] + p.y * vt[k][1]).collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let (along, across) = (proj(0), proj(1));
    let (a0, a1) = (
        percentile(&along, 1.0) - half,
        percentile(&along, 99.0) + half,
    );
    let (c10, c90) = (percentile(&across, 10.0), percentile(&across, 90.0));
    let mid = 0.5 * (c10 + c90);
    let w = 0.5 * (c90 - c10) / 0.8 + half;
    [(a0, mid - w), (a1, mid - w), (a1, mid + w), (a0, mid + w)]
        .iter()
        .map(|&(u, v)| {
            Point::new(
                centre.x + u * vt[0][0] + v * vt[1][0],
                centre.y + u * vt[0][1] + v * vt[1][1],
            )
        })
        .collect()
}

/// The cells of each crossing in one connected crossing mask `cells` (see the module docs).
pub fn crossing_parts(cells: &[Cell], frame: &Frame, p: &VectoriseParams) -> Vec<Vec<Cell>> {
    let cell_area = frame.sx * frame.sy;
    let half = 0.5 * cell_area.sqrt();
    let (mut comp, (oi, oj)) = crop(cells);
    let glob = |c: Cell| (c.0 + oi, c.1 + oj);
    let holes = raster::holes(&comp);
    let radius = raster::distance_transform(&holes);
    let (_, hole_cells) = raster::label8(&holes);
    let mut wide: Vec<&Vec<Cell>> = Vec::new();
    for h in &hole_cells {
        let r = h
            .iter()
            .map(|&(i, j)| radius.at(i, j) * 2.0 * half)
            .fold(f64::NEG_INFINITY, f64::max);
        if r > p.max_hole {
            wide.push(h);
        } else {
            for &(i, j) in h {
                comp.set(i, j, true);
            }
        }
    }
    let all: Vec<Cell> = comp.cells().into_iter().map(glob).collect();
    let ring = !wide.is_empty();
    let whole = |all: Vec<Cell>| vec![all];
    if p.rectangularity <= 0.0 {
        return whole(all);
    }
    if !ring && fill(all.len(), &cell_hull(frame, &all), half) >= p.rectangularity {
        return whole(all);
    }
    let mut segs: Vec<(Point, Point)> = Vec::new();
    let mut add = |v: &[Point]| segs.extend(v.windows(2).map(|w| (w[0], w[1])));
    if ring {
        // around an intersection: the crossings lie along the sides of its hole
        for h in &wide {
            let pts: Vec<Point> = h.iter().map(|&c| frame.metres(glob(c))).collect();
            if let Hull::Polygon(mut v) = convex_hull(&pts) {
                v.push(v[0]);
                add(&simplify_ring(&v, p.corner_tolerance));
            }
        }
    } else {
        // along the straight runs of its skeleton
        for (_, line) in
            branches::skeleton_branches_at(&comp, (oi, oj), frame, p.min_length, 0.0, 0.0)
        {
            add(&simplify_line(&line, p.corner_tolerance));
        }
    }
    if segs.len() < 2 {
        return whole(all);
    }
    // every cell to its nearest segment (numpy's operation order; the first on ties)
    let mut by_seg: Vec<Vec<Cell>> = vec![Vec::new(); segs.len()];
    for &c in &all {
        let x = frame.metres(c);
        let mut best = (f64::INFINITY, 0);
        for (s, &(a, b)) in segs.iter().enumerate() {
            let (abx, aby) = (b.x - a.x, b.y - a.y);
            let num = (x.x - a.x) * abx + (x.y - a.y) * aby;
            let den = (abx * abx + aby * aby).max(1e-12);
            let t = (num / den).clamp(0.0, 1.0);
            let (dx, dy) = (x.x - (a.x + t * abx), x.y - (a.y + t * aby));
            let d = (dx * dx + dy * dy).sqrt();
            if d < best.0 {
                best = (d, s);
            }
        }
        by_seg[best.1].push(c);
    }
    let mut parts: Vec<Vec<Cell>> = by_seg.into_iter().filter(|q| !q.is_empty()).collect();
    let mut hulls: Vec<Hull> = parts.iter().map(|q| cell_hull(frame, q)).collect();
    while parts.len() > 1 {
        let mut best = p.rectangularity;
        let mut pair = None;
        for i in 0..parts.len() {
            for j in i + 1..parts.len() {
                let mut pts = hull_points(&hulls[i]);
                pts.extend(hull_points(&hulls[j]));
                let f = fill(parts[i].len() + parts[j].len(), &convex_hull(&pts), half);
                if f >= best {
                    best = f;
                    pair = Some((i, j));
                }
            }
        }
        let Some((i, j)) = pair else { break };
        let moved = parts.remove(j);
        parts[i].extend(moved);
        let mut pts = hull_points(&hulls[i]);
        pts.extend(hull_points(&hulls.remove(j)));
        hulls[i] = convex_hull(&pts);
    }
    parts
        .into_iter()
        .filter(|q| q.len() as f64 * cell_area >= p.min_area)
        .collect()
}

/// The outline of one part (not shrunk): `None` where it has no area.
fn part_outline(
    cells: &[Cell],
    frame: &Frame,
    split: bool,
    p: &VectoriseParams,
) -> Option<Vec<Point>> {
    let half = 0.5 * frame.sx;
    if split {
        return Some(band_rectangle(&frame.metres_of(cells), half));
    }
    let hull = cell_hull(frame, cells);
    if p.hull_simplify > 0.0 {
        let grown = match &hull {
            Hull::Empty => return None,
            Hull::Point(a) => capsule(*a, *a, half),
            Hull::Segment(a, b) => capsule(*a, *b, half),
            Hull::Polygon(v) => expand_convex(v, half),
        };
        let mut closed = grown;
        closed.push(*closed.first()?);
        let mut simple = simplify_ring(&closed, p.hull_simplify);
        simple.pop();
        return Some(simple);
    }
    match hull {
        Hull::Polygon(v) => min_area_rectangle(&v).map(|(c, _, _)| c.to_vec()),
        _ => None, // a line or a point: no polygon
    }
}

/// The crossing instances of a crossing `mask` on `frame`'s grid: each instance's cells (for
/// its score) and outline (ego metres, a ring not closed), in the order of the components'
/// first cells and their parts.
pub fn crossing_outlines(
    mask: &Grid<bool>,
    frame: &Frame,
    p: &VectoriseParams,
) -> Vec<(Vec<Cell>, Vec<Point>)> {
    let (_, comps) = raster::label8(mask);
    let mut out = Vec::new();
    for comp in comps {
        if comp.len() as f64 * frame.sx * frame.sy < p.min_area {
            continue;
        }
        let parts = crossing_parts(&comp, frame, p);
        let split = parts.len() > 1;
        for cells in parts {
            let Some(mut ring) = part_outline(&cells, frame, split, p) else {
                continue;
            };
            let area = signed_area2(&ring).abs();
            if ring.len() < 3 || area.is_nan() || area == 0.0 {
                continue;
            }
            if p.shrink > 0.0 {
                if let Some(small) = shrink_convex(&ring, p.shrink) {
                    ring = small;
                }
            }
            out.push((cells, ring));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Frame {
        Frame::new(200, 100, 30.0, 15.0) // 0.3 m cells
    }

    fn rect_mask(f: &Frame, boxes: &[(usize, usize, usize, usize)]) -> Grid<bool> {
        let mut g = Grid::filled(f.nx, f.ny, false);
        for &(i0, i1, j0, j1) in boxes {
            for i in i0..i1 {
                for j in j0..j1 {
                    g.set(i, j, true);
                }
            }
        }
        g
    }

    #[test]
    fn percentiles_as_numpy() {
        let v = [1.0, 2.0, 3.0, 4.0, 10.0];
        assert_eq!(percentile(&v, 50.0), 3.0);
        assert!((percentile(&v, 99.0) - 9.76).abs() < 1e-12);
        assert!((percentile(&v, 10.0) - 1.4).abs() < 1e-12);
    }

    /// The areas of the crossing instances (their 20 resampled points) of a 0.3 m grid with sure
    /// crossing cells in `boxes` (row and column ranges), at the native resolution.
    fn crossing_areas(boxes: &[(usize, usize, usize, usize)], p: VectoriseParams) -> Vec<f64> {
        let (nx, ny) = (200, 100);
        let mut prob = vec![0.05f32; 3 * nx * ny];
        for &(i0, i1, j0, j1) in boxes {
            for i in i0..i1 {
                for j in j0..j1 {
                    prob[i * ny + j] = 0.95;
                }
            }
        }
        let p = VectoriseParams { upsample: 1, ..p };
        let out = super::super::vectorise(&prob, [3, nx, ny], 30.0, 15.0, &p, false).unwrap();
        (0..out.len())
            .filter(|&k| out.classes[k] == 0)
            .map(|k| {
                let ring: Vec<Point> = out.points[k * 20..(k + 1) * 20]
                    .iter()
                    .map(|q| Point::new(q[0] as f64, q[1] as f64))
                    .collect();
                signed_area2(&ring).abs() / 2.0
            })
            .collect()
    }

    fn assert_areas(got: &[f64], want: &[f64]) {
        assert_eq!(got.len(), want.len(), "{got:?}");
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-4, "{got:?} vs {want:?}");
        }
    }

    // The expected areas are the reference's (`icmapper.testing.vectorise_reference`) on the
    // same float32 probabilities.

    #[test]
    fn a_rectangular_crossing_is_one_instance() {
        let got = crossing_areas(&[(20, 30, 20, 70)], VectoriseParams::default());
        assert_areas(&got, &[15.552010219574186]);
    }

    #[test]
    fn touching_crossings_are_split() {
        let l = [(20, 33, 20, 80), (33, 90, 20, 33)]; // an L: two bands meeting at a corner
        let p = VectoriseParams::default();
        assert_areas(
            &crossing_areas(&l, p.clone()),
            &[35.90099299912805, 38.46053987483083],
        );
        let joined = VectoriseParams {
            rectangularity: 0.0,
            ..p
        };
        assert_areas(&crossing_areas(&l, joined), &[195.41370869770554]);
    }

    #[test]
    fn a_ring_around_an_intersection_is_cut_along_its_hole() {
        let ring = [
            (60, 73, 30, 70),
            (127, 140, 30, 70),
            (73, 127, 30, 43),
            (73, 127, 57, 70),
        ];
        let got = crossing_areas(&ring, VectoriseParams::default());
        let want = [
            26.70164957842826,
            41.79900209992329,
            15.324566232814709,
            30.43080371303563,
        ];
        assert_areas(&got, &want);
    }

    #[test]
    fn a_narrow_hole_is_filled() {
        let f = frame();
        let mut m = rect_mask(&f, &[(20, 34, 20, 70)]);
        for j in 30..60 {
            m.set(27, j, false); // an unpainted line inside one crossing
        }
        let out = crossing_outlines(&m, &f, &VectoriseParams::default());
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].0.len(), 14 * 50);
    }

    #[test]
    fn small_and_degenerate_components() {
        let boxes = [(5, 6, 5, 6), (50, 51, 10, 40)]; // a cell, a one-cell-wide line
        let p = VectoriseParams::default();
        // the line (30 cells, 2.7 m^2) survives as its simplified round-capped buffer
        assert_areas(&crossing_areas(&boxes, p.clone()), &[0.6223115933451027]);
        // its minimum rotated rectangle is a line: no polygon
        let mrr = VectoriseParams {
            hull_simplify: 0.0,
            ..p
        };
        assert!(crossing_areas(&boxes, mrr).is_empty());
    }
}
