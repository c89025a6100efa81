//! Two kerbs merged into one band of probability, drawn as its outline.
//!
//! A median island narrower than about 3 m puts its two kerbs within a BEV cell or two of each
//! other: on 1.2 m cells the boundary probabilities of both sides are one band, and its skeleton
//! runs down the middle of the island, a metre or more from either kerb (docs/mapping.md, "Kerbs
//! round median islands"). A band is a connected component of the mask whose skeleton lies
//! farther than `band` times the targets' line radius (`shrink`) from the mask's edge over at
//! least half of its cells (one kerb's mask is about one radius wide on either side of its
//! skeleton). Its lines are the outline of the band shrunk by the radius, as a crossing's outline
//! is: the cells of the component farther than `shrink` from its edge, and of those the ones with
//! a 4-neighbour inside the grid outside them (the grid's border is no edge: the band goes on
//! past the range there), cut into ordered branches as a skeleton is. A frame that sees the
//! island's nose gives one line round it, up one side and down the other, as the ground truth
//! holds the island's kerb.

use super::branches::skeleton_branches;
use super::raster::{distance_transform, label8};
use super::{Cell, Frame, Grid, VectoriseParams};
use crate::types::Point;

/// The skeleton branches `(cells, metres)` of a line class's `mask`, with those of every band
/// replaced by the branches of its shrunk outline (kept branches first, in their order; then each
/// band's outline branches, bands in label order). `params.band <= 0`: the branches as they are.
pub fn outline_bands(
    mask: &Grid<bool>,
    frame: &Frame,
    branches: Vec<(Vec<Cell>, Vec<Point>)>,
    params: &VectoriseParams,
) -> Vec<(Vec<Cell>, Vec<Point>)> {
    if params.band <= 0.0 || branches.is_empty() {
        return branches;
    }
    let wide = params.band * params.shrink;
    if wide.is_nan() {
        return branches; // an infinite band of no width: no cell is farther than NaN
    }
    // thick skeleton cells per branch, by a scan of the disc of radius `wide` around each (the
    // distance transform's `dt * sx > wide`, exactly; most frames have none and stop here)
    let disc = disc_offsets(wide, frame.sx, mask.nx.max(mask.ny));
    let thick_in: Vec<usize> = branches
        .iter()
        .map(|(path, _)| {
            path.iter()
                .filter(|&&c| is_thick(mask, c, &disc, wide))
                .count()
        })
        .collect();
    if thick_in.iter().all(|&n| n == 0) {
        return branches;
    }
    let dt = distance_transform(mask); // cells
    let (labels, comps) = label8(mask);
    let (mut thick, mut total) = (vec![0usize; comps.len() + 1], vec![0usize; comps.len() + 1]);
    for ((path, _), n) in branches.iter().zip(&thick_in) {
        let c = labels.at(path[0].0, path[0].1) as usize;
        total[c] += path.len();
        thick[c] += n;
    }
    let is_band = |c: usize| total[c] > 0 && 2 * thick[c] >= total[c];
    let mut out: Vec<(Vec<Cell>, Vec<Point>)> = branches
        .into_iter()
        .filter(|(path, _)| !is_band(labels.at(path[0].0, path[0].1) as usize))
        .collect();
    for (c, cells) in comps.iter().enumerate().map(|(k, cells)| (k + 1, cells)) {
        if !is_band(c) {
            continue;
        }
        let mut inner = Grid::filled(mask.nx, mask.ny, false);
        for &(i, j) in cells {
            if dt.at(i, j) * frame.sx > params.shrink {
                inner.set(i, j, true);
            }
        }
        let mut edge = Grid::filled(mask.nx, mask.ny, false);
        for &(i, j) in cells {
            if !inner.at(i, j) {
                continue;
            }
            let outside = (i > 0 && !inner.at(i - 1, j))
                || (i + 1 < mask.nx && !inner.at(i + 1, j))
                || (j > 0 && !inner.at(i, j - 1))
                || (j + 1 < mask.ny && !inner.at(i, j + 1));
            if outside {
                edge.set(i, j, true);
            }
        }
        if edge.any() {
            out.extend(skeleton_branches(
                &edge,
                frame,
                params.min_length,
                params.through,
                params.spur,
            ));
        }
    }
    out
}

/// The cell offsets `(di, dj, distance in metres)` within `wide` metres of a cell and the first
/// one beyond it, nearest first (cells `sx` metres square), at most `extent` cells out: no offset
/// farther reaches another cell of a grid `extent` cells across, so a huge or infinite `wide`
/// costs no more than the grid.
fn disc_offsets(wide: f64, sx: f64, extent: usize) -> Vec<(isize, isize, f64)> {
    let r = (wide / sx).ceil().min(extent as f64) as isize + 1;
    let mut out: Vec<(isize, isize, f64)> = (-r..=r)
        .flat_map(|di| (-r..=r).map(move |dj| (di, dj)))
        .map(|(di, dj)| (di, dj, ((di * di + dj * dj) as f64).sqrt() * sx))
        .collect();
    out.sort_by(|a, b| a.2.total_cmp(&b.2));
    out
}

/// Whether set cell `c` of `mask` lies farther than `wide` metres from every unset cell of the
/// grid (the distance transform's `dt * sx > wide`; cells past the grid's border do not count, as
/// there), scanning `disc` (`disc_offsets(wide, sx, extent)`) nearest first.
fn is_thick(mask: &Grid<bool>, c: Cell, disc: &[(isize, isize, f64)], wide: f64) -> bool {
    for &(di, dj, d) in disc {
        if d > wide {
            break;
        }
        let (i, j) = (c.0 as isize + di, c.1 as isize + dj);
        if i < 0 || j < 0 || i >= mask.nx as isize || j >= mask.ny as isize {
            continue;
        }
        if !mask.at(i as usize, j as usize) {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> VectoriseParams {
        VectoriseParams::default()
    }

    /// A mask (200 x 100 cells of 0.3 m over 60 x 30 m) with rows `rows` set from column `x0` on.
    fn band_mask(rows: std::ops::Range<usize>, x0: usize) -> Grid<bool> {
        let mut g = Grid::filled(200, 100, false);
        for i in x0..200 {
            for j in rows.clone() {
                g.set(i, j, true);
            }
        }
        g
    }

    #[test]
    fn the_disc_scan_is_the_distance_transforms_test() {
        // random blobs on small grids, several radii: `is_thick` == `dt * sx > wide` everywhere
        let mut rng = crate::splitmix::Rng(7);
        for trial in 0..40 {
            let (nx, ny) = (20 + trial % 7, 15 + trial % 5);
            let mut g = Grid::filled(nx, ny, false);
            for i in 0..nx {
                for j in 0..ny {
                    let (x, y) = (i as f64 - nx as f64 / 2.0, j as f64 - ny as f64 / 2.0);
                    g.set(i, j, x * x + 0.5 * y * y < 40.0 || rng.next() < 0.6);
                }
            }
            let dt = distance_transform(&g);
            for wide in [0.3, 0.9, 1.62, 2.5] {
                let sx = 0.3;
                let disc = disc_offsets(wide, sx, nx.max(ny));
                for (i, j) in g.cells() {
                    assert_eq!(
                        is_thick(&g, (i, j), &disc, wide),
                        dt.at(i, j) * sx > wide,
                        "trial {trial} wide {wide} cell ({i}, {j})"
                    );
                }
            }
        }
        // a grid with no unset cell: infinitely far from one, as the transform has it
        let full = Grid::filled(6, 4, true);
        assert!(distance_transform(&full).at(2, 2).is_infinite());
        assert!(is_thick(&full, (2, 2), &disc_offsets(1.62, 0.3, 6), 1.62));
        // a huge or infinite radius scans no farther than the grid
        let mut g = Grid::filled(8, 5, true);
        g.set(0, 0, false);
        for wide in [1e9, f64::INFINITY] {
            let disc = disc_offsets(wide, 0.3, 8);
            assert!(disc.len() <= 19 * 19);
            assert!(!is_thick(&g, (7, 4), &disc, wide));
            assert!(is_thick(&full, (3, 2), &disc_offsets(wide, 0.3, 6), wide));
        }
    }

    #[test]
    fn a_thin_kerb_keeps_its_skeleton_and_a_band_becomes_its_outline() {
        let frame = Frame::new(200, 100, 30.0, 15.0);
        let p = params();
        // one kerb: 6 cells (1.8 m) wide
        let thin = band_mask(40..46, 0);
        let b = skeleton_branches(&thin, &frame, p.min_length, p.through, p.spur);
        assert_eq!(outline_bands(&thin, &frame, b.clone(), &p), b);
        // an island's two kerbs merged: 14 cells (4.2 m) wide, its nose at x = 0 m
        let wide = band_mask(40..54, 100);
        let b = skeleton_branches(&wide, &frame, p.min_length, p.through, p.spur);
        let out = outline_bands(&wide, &frame, b.clone(), &p);
        assert_ne!(out, b);
        // one line round the nose, its two ends at the far (x = 30 m) edge, 2.4 m apart
        assert_eq!(out.len(), 1);
        let line = &out[0].1;
        let (a, z) = (line[0], line[line.len() - 1]);
        assert!(a.x > 28.0 && z.x > 28.0, "{a:?} {z:?}");
        assert!(((a.y - z.y).abs() - 2.4).abs() < 0.4, "{a:?} {z:?}");
        assert!(line.iter().any(|q| q.x < 1.5));
        // off
        let off = VectoriseParams { band: 0.0, ..p };
        assert_eq!(outline_bands(&wide, &frame, b.clone(), &off), b);
    }
}
