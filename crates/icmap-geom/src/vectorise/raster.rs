//! Raster operations on boolean grids with scipy.ndimage's semantics: connected components
//! (`label`, 8-connectivity, labels in the raster order of each component's first cell), hole
//! filling (`binary_fill_holes`: background not 4-connected to the grid's border), the exact
//! Euclidean distance transform (`distance_transform_edt`) and the skeleton's junction cells
//! (neighbour counts by `convolve` with a 3x3 kernel, `binary_dilation` with a 3x3 square).
//! Cells outside the grid are unset.

use super::{Cell, Grid};

/// The 4 edge-neighbour offsets.
const N4: [(isize, isize); 4] = [(-1, 0), (0, -1), (0, 1), (1, 0)];

#[inline]
fn step(g_nx: usize, g_ny: usize, c: Cell, d: (isize, isize)) -> Option<Cell> {
    let i = c.0.checked_add_signed(d.0)?;
    let j = c.1.checked_add_signed(d.1)?;
    (i < g_nx && j < g_ny).then_some((i, j))
}

/// A boolean grid copied into a byte array with a one-cell unset border, so that the 8
/// neighbours of any cell are at fixed offsets (no bounds checks): cell `(i, j)` is at index
/// `(i + 1) * py + j + 1`.
#[derive(Debug, Clone)]
pub struct Padded {
    /// Cells along the first axis of the grid (without the border).
    pub nx: usize,
    /// Cells along the second axis of the grid (without the border).
    pub ny: usize,
    /// Row length with the border (`ny + 2`).
    pub py: usize,
    /// `(nx + 2) * py` bytes, 1 on set cells.
    pub pad: Vec<u8>,
}

impl Padded {
    /// `mask` padded, and the padded indices of its set cells in raster order.
    pub fn new(mask: &Grid<bool>) -> (Self, Vec<usize>) {
        let (nx, ny) = (mask.nx, mask.ny);
        let py = ny + 2;
        let mut pad = vec![0u8; (nx + 2) * py];
        let mut cells = Vec::new();
        for i in 0..nx {
            let row = &mask.data[i * ny..(i + 1) * ny];
            for (j, &v) in row.iter().enumerate() {
                if v {
                    let k = (i + 1) * py + j + 1;
                    pad[k] = 1;
                    cells.push(k);
                }
            }
        }
        (Self { nx, ny, py, pad }, cells)
    }

    /// The 8 neighbour offsets in the padded array.
    pub fn offsets(&self) -> [isize; 8] {
        let py = self.py as isize;
        [-py - 1, -py, -py + 1, -1, 1, py - 1, py, py + 1]
    }

    /// The grid cell of padded index `k`.
    #[inline]
    pub fn cell(&self, k: usize) -> Cell {
        (k / self.py - 1, k % self.py - 1)
    }

    /// The padded index of grid cell `c`.
    #[inline]
    pub fn index(&self, c: Cell) -> usize {
        (c.0 + 1) * self.py + c.1 + 1
    }
}

/// The 8-connected components of the cells `cells` (padded indices in raster order, of a padded
/// array of `len` bytes and rows of `py`): a label per padded index (0 elsewhere; components
/// 1..=n in the raster order of their first cell) and each component's cells in raster order.
/// One scan with union-find over provisional labels (a cell's already scanned neighbours are
/// the row above and the cell before it).
pub fn label_cells(py: usize, len: usize, cells: &[usize]) -> (Vec<u32>, Vec<Vec<usize>>) {
    let mut labels = vec![0u32; len];
    let mut parent: Vec<u32> = vec![0];
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let up = parent[parent[x as usize] as usize];
            parent[x as usize] = up;
            x = up;
        }
        x
    }
    let before = [py + 1, py, py - 1, 1];
    for &k in cells {
        let mut best = 0u32;
        for &d in &before {
            let l = labels[k - d];
            if l != 0 {
                let r = find(&mut parent, l);
                best = if best == 0 { r } else { best.min(r) };
            }
        }
        if best == 0 {
            best = parent.len() as u32;
            parent.push(best);
        } else {
            for &d in &before {
                let l = labels[k - d];
                if l != 0 {
                    let r = find(&mut parent, l);
                    parent[r as usize] = best;
                }
            }
        }
        labels[k] = best;
    }
    let mut final_id = vec![0u32; parent.len()];
    let mut comps: Vec<Vec<usize>> = Vec::new();
    for &k in cells {
        let r = find(&mut parent, labels[k]) as usize;
        if final_id[r] == 0 {
            comps.push(Vec::new());
            final_id[r] = comps.len() as u32;
        }
        labels[k] = final_id[r];
        comps[final_id[r] as usize - 1].push(k);
    }
    (labels, comps)
}

/// The 8-connected components of `mask`: the label grid (0 = unset, components 1..=n in the
/// raster order of their first cell, as `scipy.ndimage.label(mask, ones((3, 3)))`) and the cells
/// of each component in raster order (`cells[c - 1]`, as `argwhere(labels == c)`).
pub fn label8(mask: &Grid<bool>) -> (Grid<u32>, Vec<Vec<Cell>>) {
    let (p, cells) = Padded::new(mask);
    let (lab, comps) = label_cells(p.py, p.pad.len(), &cells);
    let mut labels = Grid::filled(mask.nx, mask.ny, 0u32);
    for &k in &cells {
        let (i, j) = p.cell(k);
        labels.set(i, j, lab[k]);
    }
    let comps = comps
        .into_iter()
        .map(|c| c.into_iter().map(|k| p.cell(k)).collect())
        .collect();
    (labels, comps)
}

/// The holes of `mask`: unset cells not 4-connected to the grid's border through unset cells
/// (`binary_fill_holes(mask) & ~mask`).
pub fn holes(mask: &Grid<bool>) -> Grid<bool> {
    let (nx, ny) = (mask.nx, mask.ny);
    let mut outside = Grid::filled(nx, ny, false);
    let mut stack = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            let border = i == 0 || j == 0 || i + 1 == nx || j + 1 == ny;
            if border && !mask.at(i, j) && !outside.at(i, j) {
                outside.set(i, j, true);
                stack.push((i, j));
            }
        }
    }
    while let Some(c) = stack.pop() {
        for d in N4 {
            if let Some(n) = step(nx, ny, c, d) {
                if !mask.at(n.0, n.1) && !outside.at(n.0, n.1) {
                    outside.set(n.0, n.1, true);
                    stack.push(n);
                }
            }
        }
    }
    Grid {
        nx,
        ny,
        data: mask
            .data
            .iter()
            .zip(&outside.data)
            .map(|(&m, &o)| !m && !o)
            .collect(),
    }
}

/// 1-D squared distance transform of `f` (Felzenszwalb-Huttenlocher lower envelope of parabolas
/// rooted at the finite entries) into `d`; all infinite if `f` has no finite entry.
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut Vec<usize>, z: &mut Vec<f64>) {
    let Some(first) = f.iter().position(|x| x.is_finite()) else {
        d.iter_mut().for_each(|x| *x = f64::INFINITY);
        return;
    };
    let root = |q: usize| f[q] + (q * q) as f64;
    v.clear();
    z.clear();
    v.push(first);
    z.push(f64::NEG_INFINITY);
    z.push(f64::INFINITY);
    for (q, fq) in f.iter().enumerate().skip(first + 1) {
        if !fq.is_finite() {
            continue;
        }
        let mut k = v.len() - 1;
        let mut s = (root(q) - root(v[k])) / (2.0 * (q - v[k]) as f64);
        // z[0] is -inf and s is finite: the loop stops at k = 0 at the latest
        while s <= z[k] {
            k -= 1;
            s = (root(q) - root(v[k])) / (2.0 * (q - v[k]) as f64);
        }
        v.truncate(k + 1);
        z.truncate(k + 1);
        v.push(q);
        z.push(s);
        z.push(f64::INFINITY);
    }
    let mut k = 0;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let dq = q as f64 - v[k] as f64;
        *out = dq * dq + f[v[k]];
    }
}

/// The Euclidean distance (cells) of every set cell of `fg` to the nearest unset cell of the grid
/// (`distance_transform_edt(fg)`; 0 on unset cells, infinity where the grid has no unset cell).
pub fn distance_transform(fg: &Grid<bool>) -> Grid<f64> {
    let (nx, ny) = (fg.nx, fg.ny);
    let mut sq = Grid {
        nx,
        ny,
        data: fg
            .data
            .iter()
            .map(|&v| if v { f64::INFINITY } else { 0.0 })
            .collect(),
    };
    let (mut v, mut z) = (Vec::new(), Vec::new());
    let mut line = vec![0.0; nx.max(ny)];
    let mut out = vec![0.0; nx.max(ny)];
    for j in 0..ny {
        for (i, x) in line[..nx].iter_mut().enumerate() {
            *x = sq.at(i, j);
        }
        edt_1d(&line[..nx], &mut out[..nx], &mut v, &mut z);
        for (i, &x) in out[..nx].iter().enumerate() {
            sq.set(i, j, x);
        }
    }
    for i in 0..nx {
        line[..ny].copy_from_slice(&sq.data[i * ny..(i + 1) * ny]);
        edt_1d(&line[..ny], &mut out[..ny], &mut v, &mut z);
        sq.data[i * ny..(i + 1) * ny].copy_from_slice(&out[..ny]);
    }
    sq.data.iter_mut().for_each(|x| *x = x.sqrt());
    sq
}

/// The junction flags of a skeleton (padded, `cells` its set cells): cells with at least 3 set
/// 8-neighbours, grown by one cell (3x3) and kept on the skeleton
/// (`binary_dilation(skel & (degree >= 3), ones((3, 3))) & skel`), 1 in a padded byte array.
pub fn junction_flags(skel: &Padded, cells: &[usize]) -> Vec<u8> {
    let offsets = skel.offsets();
    let pad = &skel.pad;
    let mut grown = vec![0u8; pad.len()];
    for &k in cells {
        let degree: u8 = offsets
            .iter()
            .map(|&d| pad[(k as isize + d) as usize])
            .sum();
        if degree >= 3 {
            grown[k] = 1;
            for d in offsets {
                let q = (k as isize + d) as usize;
                if pad[q] != 0 {
                    grown[q] = 1;
                }
            }
        }
    }
    grown
}

/// [`junction_flags`] of a skeleton grid, as a grid.
pub fn junctions(skel: &Grid<bool>) -> Grid<bool> {
    let (p, cells) = Padded::new(skel);
    let flags = junction_flags(&p, &cells);
    let mut out = Grid::filled(skel.nx, skel.ny, false);
    for &k in &cells {
        let (i, j) = p.cell(k);
        out.set(i, j, flags[k] != 0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vectorise::skeleton::grid_from;

    #[test]
    fn labels_follow_the_raster_order_of_first_cells() {
        let m = grid_from(&["..#..#", ".#...#", "#....#", "...#.."]);
        let (lab, comps) = label8(&m);
        assert_eq!(comps.len(), 3);
        assert_eq!(comps[0], vec![(0, 2), (1, 1), (2, 0)]); // diagonal: one component
        assert_eq!(comps[1], vec![(0, 5), (1, 5), (2, 5)]);
        assert_eq!(comps[2], vec![(3, 3)]);
        assert_eq!(lab.at(2, 0), 1);
        assert_eq!(lab.at(3, 3), 3);
        let (_, none) = label8(&Grid::filled(3, 3, false));
        assert!(none.is_empty());
    }

    #[test]
    fn holes_are_enclosed_background_by_four_connectivity() {
        let m = grid_from(&["#####.", "#..#..", "#####.", "......"]);
        let h = holes(&m);
        assert_eq!(h.cells(), vec![(1, 1), (1, 2)]);
        // a diagonal gap lets no background through under 4-connectivity
        let d = grid_from(&[".#.", "#.#", ".#."]);
        assert_eq!(holes(&d).cells(), vec![(1, 1)]);
        assert!(!holes(&Grid::filled(4, 4, true)).any());
    }

    #[test]
    fn distance_transform_is_exact() {
        let mut fg = Grid::filled(7, 9, true);
        fg.set(0, 0, false);
        fg.set(6, 8, false);
        let d = distance_transform(&fg);
        for i in 0..7 {
            for j in 0..9 {
                let a = ((i * i + j * j) as f64).sqrt();
                let b = (((6 - i) * (6 - i) + (8 - j) * (8 - j)) as f64).sqrt();
                assert_eq!(d.at(i, j), a.min(b));
            }
        }
        let all = distance_transform(&Grid::filled(2, 2, true));
        assert!(all.data.iter().all(|v| v.is_infinite()));
    }

    #[test]
    fn junctions_of_a_t() {
        let t = grid_from(&[".....", "#####", "..#..", "..#.."]);
        // every cell with three neighbours (diagonals count), grown by one cell (scipy's answer)
        let j = junctions(&t);
        assert_eq!(
            j.cells(),
            vec![(1, 0), (1, 1), (1, 2), (1, 3), (1, 4), (2, 2), (3, 2)]
        );
        let line = grid_from(&["#####"]);
        assert!(!junctions(&line).any());
    }
}
