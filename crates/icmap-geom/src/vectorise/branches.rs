//! The skeleton of a line mask as ordered branches: cut at its junctions, each branch's cells
//! walked in path order, and (with `through` > 0) lines joined through the junctions and spurs
//! dropped.
//!
//! A junction is a skeleton cell with at least three skeleton neighbours, grown by one cell on
//! the skeleton ([`raster::junctions`]). At each junction (a connected group of junction cells)
//! the two branch ends that continue each other most straightly (their courses within
//! `through` degrees of a straight line) are joined, greedily, best pair first (lane lines and
//! kerbs do not branch). A branch left with an unjoined end at a junction that is shorter than
//! `spur` metres is a spur and is dropped.

use std::collections::{BTreeMap, HashMap, HashSet};

use super::{pairwise_sum_f64, polyline, raster, skeleton, Cell, Frame, Grid};
use crate::types::Point;

/// The 8 neighbour offsets in the order a path walk prefers them: edge neighbours before
/// diagonal ones, then by coordinate (the walk takes the first unvisited one).
const WALK: [(isize, isize); 8] = [
    (-1, 0),
    (0, -1),
    (0, 1),
    (1, 0),
    (-1, -1),
    (-1, 1),
    (1, -1),
    (1, 1),
];

/// The cells of one skeleton branch (no junctions; any order) in path order, from an end: the
/// lowest `(i, j)` cell with at most one neighbour (the lowest cell when there is none, a loop),
/// then always the first unvisited neighbour in `WALK` order (edge neighbours first: up, left,
/// right, down; then the diagonals).
pub fn order_branch(cells: &[Cell]) -> Vec<Cell> {
    if cells.len() <= 1 {
        return cells.to_vec();
    }
    // the cells' indices on a grid around them (one cell of margin)
    let i0 = cells.iter().map(|c| c.0).min().unwrap_or(0);
    let j0 = cells.iter().map(|c| c.1).min().unwrap_or(0);
    let w = cells.iter().map(|c| c.1).max().unwrap_or(0) - j0 + 3;
    let h = cells.iter().map(|c| c.0).max().unwrap_or(0) - i0 + 3;
    let mut index = vec![usize::MAX; w * h];
    let local = |c: Cell| (c.0 - i0 + 1) * w + (c.1 - j0 + 1);
    for (k, &c) in cells.iter().enumerate() {
        index[local(c)] = k;
    }
    let nb: Vec<[Option<usize>; 8]> = cells
        .iter()
        .map(|&c| {
            let at = local(c) as isize;
            let mut row = [None; 8];
            for (slot, &(di, dj)) in row.iter_mut().zip(WALK.iter()) {
                let q = index[(at + di * w as isize + dj) as usize];
                *slot = (q != usize::MAX).then_some(q);
            }
            row
        })
        .collect();
    let degree = |k: usize| nb[k].iter().filter(|q| q.is_some()).count();
    let ends: Vec<usize> = (0..cells.len()).filter(|&k| degree(k) <= 1).collect();
    let pool: Vec<usize> = if ends.is_empty() {
        (0..cells.len()).collect()
    } else {
        ends
    };
    let mut cur = pool.into_iter().min_by_key(|&k| cells[k]).unwrap_or(0);
    let mut seen = vec![false; cells.len()];
    seen[cur] = true;
    let mut path = vec![cells[cur]];
    while let Some(next) = nb[cur].iter().flatten().copied().find(|&q| !seen[q]) {
        cur = next;
        seen[cur] = true;
        path.push(cells[cur]);
    }
    path
}

/// The skeleton of `mask` cut at its junctions: each branch's cells in path order and its
/// polyline in metres, for branches of at least two cells and `min_length` metres. With
/// `through` > 0 (degrees) lines go on through junctions and spurs shorter than `spur` are
/// dropped (see the module docs).
pub fn skeleton_branches(
    mask: &Grid<bool>,
    frame: &Frame,
    min_length: f64,
    through: f64,
    spur: f64,
) -> Vec<(Vec<Cell>, Vec<Point>)> {
    skeleton_branches_at(mask, (0, 0), frame, min_length, through, spur)
}

/// [`skeleton_branches`] of a `mask` cut out of `frame`'s grid, its cell `(0, 0)` at the grid's
/// cell `origin` (cells and metres are the grid's).
pub fn skeleton_branches_at(
    mask: &Grid<bool>,
    origin: Cell,
    frame: &Frame,
    min_length: f64,
    through: f64,
    spur: f64,
) -> Vec<(Vec<Cell>, Vec<Point>)> {
    let (skel, cells) = skeleton::skeletonize_padded(mask);
    let junction = raster::junction_flags(&skel, &cells);
    let (plain, joints): (Vec<usize>, Vec<usize>) = cells.iter().partition(|&&k| junction[k] == 0);
    let (_, comps) = raster::label_cells(skel.py, skel.pad.len(), &plain);
    let (oi, oj) = origin;
    let mut paths: Vec<Vec<Cell>> = comps
        .iter()
        .map(|c| {
            let local: Vec<Cell> = c.iter().map(|&k| skel.cell(k)).collect();
            let mut path = order_branch(&local);
            path.iter_mut().for_each(|q| *q = (q.0 + oi, q.1 + oj));
            path
        })
        .collect();
    if through > 0.0 && !paths.is_empty() {
        let (jlab, _) = raster::label_cells(skel.py, skel.pad.len(), &joints);
        let junction_at = |c: Cell| {
            // the smallest junction label in the 3x3 neighbourhood of the mask's cell `c`
            let k = skel.index((c.0 - oi, c.1 - oj)) as isize;
            std::iter::once(0)
                .chain(skel.offsets())
                .map(|d| jlab[(k + d) as usize])
                .filter(|&l| l > 0)
                .min()
        };
        paths = through_junctions(paths, junction_at, frame, through, spur);
    }
    paths
        .into_iter()
        .filter(|path| path.len() >= 2)
        .filter_map(|path| {
            let line = frame.metres_of(&path);
            (polyline::length(&line) >= min_length).then_some((path, line))
        })
        .collect()
}

/// A branch end at a junction: (branch, end 0 = first cell / 1 = last cell, unit direction of
/// the branch's course towards the junction).
type End = (usize, usize, [f64; 2]);

/// Joins branches `paths` (cells of `frame`'s grid in order) through the junctions and drops
/// spurs (see the module docs) -> the joined paths. `junction_at(cell)`: the junction (the least
/// label of a connected group of junction cells) next to a branch's end cell, if any.
pub fn through_junctions(
    paths: Vec<Vec<Cell>>,
    junction_at: impl Fn(Cell) -> Option<u32>,
    frame: &Frame,
    through: f64,
    spur: f64,
) -> Vec<Vec<Cell>> {
    let mut ends: BTreeMap<u32, Vec<End>> = BTreeMap::new();
    for (b, path) in paths.iter().enumerate() {
        let l = path.len();
        if l == 0 {
            continue;
        }
        let pairs = [
            (path[0], path[4.min(l - 1)]),
            (path[l - 1], path[l.saturating_sub(5)]),
        ];
        for (e, &(cell, inner)) in pairs.iter().enumerate() {
            if e == 1 && l == 1 {
                continue;
            }
            let Some(j) = junction_at(cell) else { continue };
            let (p, q) = (frame.metres(cell), frame.metres(inner));
            let out = [p.x - q.x, p.y - q.y];
            let norm = (out[0] * out[0] + out[1] * out[1]).sqrt();
            let dir = if norm > 0.0 {
                [out[0] / norm, out[1] / norm]
            } else {
                [0.0, 0.0]
            };
            ends.entry(j).or_default().push((b, e, dir));
        }
    }
    let cos_min = through.to_radians().cos();
    let mut link: HashMap<(usize, usize), (usize, usize)> = HashMap::new();
    let mut loose: HashSet<usize> = HashSet::new();
    for list in ends.values() {
        let mut cands: Vec<(f64, usize, usize)> = Vec::new();
        for (x, a) in list.iter().enumerate() {
            for (y, b) in list.iter().enumerate().skip(x + 1) {
                if a.0 != b.0 {
                    let dot = a.2[0] * b.2[0] + a.2[1] * b.2[1];
                    cands.push((-dot, x, y));
                }
            }
        }
        // Python's sorted() of (straightness, x, y) tuples, walked from the straightest
        cands.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)).then(p.2.cmp(&q.2)));
        let mut used: HashSet<usize> = HashSet::new();
        for &(straight, x, y) in cands.iter().rev() {
            if straight < cos_min || used.contains(&x) || used.contains(&y) {
                continue;
            }
            used.insert(x);
            used.insert(y);
            let (a, b) = (list[x], list[y]);
            link.insert((a.0, a.1), (b.0, b.1));
            link.insert((b.0, b.1), (a.0, a.1));
        }
        for (x, end) in list.iter().enumerate() {
            if !used.contains(&x) {
                loose.insert(end.0);
            }
        }
    }
    let mut out = Vec::new();
    let mut done = vec![false; paths.len()];
    for start in 0..paths.len() {
        if done[start] {
            continue;
        }
        // walk to one end of the chain (a branch end without a link), or around a loop
        let (mut b, mut e) = (start, 0usize);
        while let Some(&(nb, ne)) = link.get(&(b, e)) {
            b = nb;
            e = 1 - ne;
            if b == start {
                break;
            }
        }
        // `end`: the end of `cur` the walk leaves by
        let (mut cur, mut end) = (b, 1 - e);
        let mut chain: Vec<Cell> = Vec::new();
        let mut pieces = 0;
        while !done[cur] {
            done[cur] = true;
            pieces += 1;
            if end == 1 {
                chain.extend_from_slice(&paths[cur]);
            } else {
                chain.extend(paths[cur].iter().rev());
            }
            match link.get(&(cur, end)) {
                Some(&(nc, ne)) => {
                    cur = nc;
                    end = 1 - ne;
                }
                None => break,
            }
        }
        if pieces == 1 && loose.contains(&start) && spur > 0.0 {
            let xy = frame.metres_of(&chain);
            let segs: Vec<f64> = xy
                .windows(2)
                .map(|w| {
                    let (dx, dy) = (w[1].x - w[0].x, w[1].y - w[0].y);
                    (dx * dx + dy * dy).sqrt()
                })
                .collect();
            if pairwise_sum_f64(&segs) < spur {
                continue; // a spur off a line
            }
        }
        out.push(chain);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vectorise::skeleton::grid_from;

    #[test]
    fn order_branch_walks_from_the_lowest_end() {
        let path = vec![(3, 1), (3, 2), (4, 3), (5, 3), (6, 4), (6, 5)];
        let mut shuffled = path.clone();
        shuffled.reverse();
        shuffled.swap(0, 3);
        assert_eq!(order_branch(&shuffled), path);
        // edge neighbours before diagonal ones
        let corner = vec![(1, 2), (1, 1), (0, 1), (0, 0)];
        assert_eq!(order_branch(&corner), vec![(0, 0), (0, 1), (1, 1), (1, 2)]);
        // a loop starts at its lowest cell
        let ring = vec![(0, 1), (1, 0), (1, 2), (2, 1)];
        assert_eq!(order_branch(&ring), vec![(0, 1), (1, 0), (2, 1), (1, 2)]);
        assert_eq!(order_branch(&[(7, 7)]), vec![(7, 7)]);
        assert!(order_branch(&[]).is_empty());
    }

    fn frame_of(m: &Grid<bool>) -> Frame {
        // 1 m cells
        Frame::new(m.nx, m.ny, m.nx as f64 / 2.0, m.ny as f64 / 2.0)
    }

    /// The branches of `m` (no minimum length) at `through` and `spur`, each as (cells, first
    /// cell, last cell).
    fn summary(m: &Grid<bool>, through: f64, spur: f64) -> Vec<(usize, Cell, Cell)> {
        skeleton_branches(m, &frame_of(m), 0.0, through, spur)
            .iter()
            .map(|(p, _)| (p.len(), p[0], p[p.len() - 1]))
            .collect()
    }

    #[test]
    fn a_line_goes_on_through_a_junction_and_a_long_spur_stays() {
        // a line of 36 cells with a 7-cell stem (1 m cells); the reference's answers
        let mut m = Grid::filled(12, 40, false);
        for j in 2..38 {
            m.set(4, j, true);
        }
        for i in 5..12 {
            m.set(i, 20, true);
        }
        assert_eq!(
            summary(&m, 45.0, 4.0),
            vec![(31, (4, 2), (4, 37)), (5, (7, 20), (11, 20))]
        );
        assert_eq!(
            summary(&m, 0.0, 0.0),
            vec![
                (16, (4, 2), (4, 17)),
                (15, (4, 23), (4, 37)),
                (5, (7, 20), (11, 20))
            ]
        );
        // a stem shorter than `spur` is dropped
        assert_eq!(summary(&m, 45.0, 6.0), vec![(31, (4, 2), (4, 37))]);
    }

    #[test]
    fn an_x_stays_two_lines_and_a_loop_one() {
        let mut m = Grid::filled(21, 21, false);
        for k in 0..21 {
            m.set(10, k, true);
            m.set(k, 10, true);
        }
        assert_eq!(
            summary(&m, 45.0, 4.0),
            vec![(16, (0, 10), (20, 10)), (16, (10, 0), (10, 20))]
        );
        let ring = grid_from(&[
            ".......", ".#####.", ".#...#.", ".#...#.", ".#...#.", ".#####.", ".......",
        ]);
        let loops = skeleton_branches(&ring, &frame_of(&ring), 0.0, 45.0, 4.0);
        assert_eq!(loops.len(), 1);
        assert_eq!((loops[0].0.len(), loops[0].0[0]), (12, (1, 2)));
    }

    #[test]
    fn short_and_single_cell_branches_are_dropped() {
        let m = grid_from(&["#....", ".....", "..##."]);
        let f = frame_of(&m);
        assert_eq!(skeleton_branches(&m, &f, 0.0, 45.0, 4.0).len(), 1);
        assert!(skeleton_branches(&m, &f, 1.5, 45.0, 4.0).is_empty());
        assert!(skeleton_branches(&Grid::filled(3, 3, false), &f, 0.0, 45.0, 4.0).is_empty());
    }
}
