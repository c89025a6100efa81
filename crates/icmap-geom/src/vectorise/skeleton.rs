//! One-cell-wide skeletons of boolean masks: scikit-image `skeletonize` (2-D, Zhang-Suen), cell
//! for cell.
//!
//! Each iteration has two sub-passes; in each, every set cell whose 8-neighbourhood code maps to
//! a removable class in scikit-image's lookup table (1: first pass, 2: second pass, 3: both) is
//! removed, all decisions of a sub-pass taken on the mask as it was when the sub-pass began.
//! Cells outside the grid are unset.

use super::raster::Padded;
use super::Grid;

/// scikit-image's `_fast_skeletonize` lookup table, indexed by the neighbourhood code
/// `NW + 2 N + 4 NE + 8 E + 16 SE + 32 S + 64 SW + 128 W` (N = row above).
const LUT: [u8; 256] = [
    0, 0, 0, 1, 0, 0, 1, 3, 0, 0, 3, 1, 1, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 2, 0, 3, 0, 3, 3,
    0, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 3, 0, 2, 2,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    2, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 3, 0, 2, 0,
    0, 0, 3, 1, 0, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1,
    3, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    2, 3, 1, 3, 0, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    2, 3, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 3, 3, 0, 1, 0, 0, 0, 0, 2, 2, 0, 0, 2, 0, 0, 0,
];

/// The Zhang-Suen skeleton of `mask` (same shape).
pub fn skeletonize(mask: &Grid<bool>) -> Grid<bool> {
    let (p, cells) = skeletonize_padded(mask);
    let mut out = Grid::filled(mask.nx, mask.ny, false);
    for k in cells {
        let (i, j) = p.cell(k);
        out.set(i, j, true);
    }
    out
}

/// The Zhang-Suen skeleton of `mask`, padded (see [`Padded`]), and its cells' padded indices
/// in raster order.
pub fn skeletonize_padded(mask: &Grid<bool>) -> (Padded, Vec<usize>) {
    let (mut p, live) = Padded::new(mask);
    let o = p.offsets(); // NW, N, NE, W, E, SW, S, SE
                         // each cell's neighbourhood code (the lookup table's index), kept up to date as cells go:
                         // a removed cell clears its bit in each neighbour's code (the bit of the opposite direction)
    let bits: [(isize, u8); 8] = [
        (o[0], 1),
        (o[1], 2),
        (o[2], 4),
        (o[4], 8),
        (o[7], 16),
        (o[6], 32),
        (o[5], 64),
        (o[3], 128),
    ];
    let skel = &mut p.pad;
    let mut code = vec![0u8; skel.len()];
    for &k in &live {
        code[k] = bits
            .iter()
            .map(|&(d, b)| {
                if skel[(k as isize + d) as usize] != 0 {
                    b
                } else {
                    0
                }
            })
            .fold(0, |a, b| a | b);
    }
    // every set cell is evaluated in every sub-pass from its code (one lookup); a removal clears
    // its bit in its neighbours' codes (the bit of the opposite direction: 4 places along the
    // ring, NW<->SE, N<->S, NE<->SW, E<->W)
    let mut set: Vec<usize> = live.clone();
    let mut remove = Vec::new();
    loop {
        let mut removed_any = false;
        for removable in [[false, true, false, true], [false, false, true, true]] {
            remove.clear();
            remove.extend(
                set.iter()
                    .copied()
                    .filter(|&k| removable[LUT[code[k] as usize] as usize]),
            );
            if remove.is_empty() {
                continue;
            }
            removed_any = true;
            for &k in &remove {
                skel[k] = 0;
                for &(d, b) in &bits {
                    let q = (k as isize + d) as usize;
                    code[q] &= !b.rotate_left(4);
                }
            }
            set.retain(|&k| skel[k] != 0);
        }
        if !removed_any {
            break;
        }
    }
    (p, set)
}

#[cfg(test)]
pub(crate) fn grid_from(rows: &[&str]) -> Grid<bool> {
    let nx = rows.len();
    let ny = rows.first().map_or(0, |r| r.len());
    let mut g = Grid::filled(nx, ny, false);
    for (i, r) in rows.iter().enumerate() {
        for (j, ch) in r.chars().enumerate() {
            g.set(i, j, ch == '#');
        }
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(g: &Grid<bool>) -> Vec<String> {
        (0..g.nx)
            .map(|i| {
                (0..g.ny)
                    .map(|j| if g.at(i, j) { '#' } else { '.' })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn ellipse_of_the_scikit_image_docs() {
        // skimage.morphology.skeletonize's docstring example
        let m = grid_from(&[
            "...###...",
            "..#####..",
            "..#####..",
            "..#####..",
            "..#####..",
            "..#####..",
            "..#####..",
            "..#####..",
            "...###...",
        ]);
        let s = skeletonize(&m);
        assert_eq!(
            rows(&s),
            [
                ".........",
                ".........",
                ".........",
                "....#....",
                "....#....",
                "....#....",
                "....#....",
                ".........",
                ".........",
            ]
        );
    }

    #[test]
    fn thin_shapes_stay_and_empty_or_full_masks_do_not_break() {
        let line = grid_from(&["......", ".####.", "......"]);
        assert_eq!(skeletonize(&line), line);
        let dot = grid_from(&["...", ".#.", "..."]);
        assert_eq!(skeletonize(&dot), dot);
        let empty = Grid::filled(4, 5, false);
        assert_eq!(skeletonize(&empty), empty);
        let full = Grid::filled(7, 7, true);
        let s = skeletonize(&full);
        assert!(s.any() && s.data.iter().filter(|&&v| v).count() < 7);
        assert_eq!(skeletonize(&Grid::filled(0, 3, true)).data.len(), 0);
    }

    #[test]
    fn a_ring_keeps_its_loop() {
        let ring = grid_from(&[
            ".......", ".#####.", ".##.##.", ".#...#.", ".##.##.", ".#####.", ".......",
        ]);
        let s = skeletonize(&ring);
        // the loop around the hole survives: the hole stays enclosed
        assert!(!s.at(3, 3));
        for (i, j) in [(1, 3), (5, 3), (3, 1), (3, 5)] {
            let near = (i - 1..=i + 1).any(|a| (j - 1..=j + 1).any(|b| s.at(a, b)));
            assert!(near, "{:?}", rows(&s));
        }
    }
}
