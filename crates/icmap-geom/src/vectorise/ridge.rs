//! The ridge mask of a line class: cells above `ridge_threshold` where the probabilities curve
//! downwards across the line (the smaller eigenvalue of their Hessian, at the Gaussian scale
//! `ridge_sigma`, below `-ridge_curvature`).
//!
//! As scikit-image `hessian_matrix(prob, sigma, order="rc", use_gaussian_derivatives=False)` and
//! `hessian_matrix_eigvals` on float32 probabilities: a Gaussian filter (scipy `gaussian_filter`,
//! mode `constant`, truncate 4, each axis pass summed in float64 and stored in float32), then
//! `np.gradient` twice (central differences inside, one-sided at the edges) and the closed-form
//! eigenvalue, all in float32 as numpy computes them.
//!
//! Only the cells above the threshold can be on a ridge, and their Hessian reads the smoothed
//! probabilities within two cells, which read the input within the kernel's radius: the filter is
//! evaluated on those spans of each row only (the same sums, term for term, as over the whole
//! grid; a 100x50 BEV upsampled 4x has a 33-cell kernel, and the dividers cover a fraction of it).

use super::{pairwise_sum_f64, Frame, Grid, VectoriseParams};

/// Largest kernel radius (cells): bounds the work for absurd scales (tiny cells).
pub const MAX_RADIUS: usize = 4096;

/// The normalised 1-D Gaussian kernel of `sigma` cells (scipy `_gaussian_kernel1d`, radius
/// `int(4 sigma + 0.5)`), centre at index `radius`.
pub fn gaussian_kernel(sigma: f64) -> Vec<f64> {
    let radius = (4.0 * sigma + 0.5) as usize;
    let radius = radius.min(MAX_RADIUS);
    let sigma2 = sigma * sigma;
    let phi: Vec<f64> = (0..=2 * radius)
        .map(|k| {
            let x = k as f64 - radius as f64;
            (-0.5 / sigma2 * (x * x)).exp()
        })
        .collect();
    let sum = pairwise_sum_f64(&phi);
    phi.iter().map(|v| v / sum).collect()
}

/// Half-open column spans of each row.
type Spans = Vec<Vec<(usize, usize)>>;

/// The spans of the set cells of each row of `marks` (`nx` rows of `ny`), each grown by `grow`
/// columns on both sides (clipped to the row) and merged.
fn row_spans(marks: &[bool], nx: usize, ny: usize, grow: usize) -> Spans {
    (0..nx)
        .map(|i| {
            let row = &marks[i * ny..(i + 1) * ny];
            let mut spans: Vec<(usize, usize)> = Vec::new();
            let mut j = 0;
            while j < ny {
                if !row[j] {
                    j += 1;
                    continue;
                }
                let a = j;
                while j < ny && row[j] {
                    j += 1;
                }
                let (lo, hi) = (a.saturating_sub(grow), (j + grow).min(ny));
                match spans.last_mut() {
                    Some(last) if last.1 >= lo => last.1 = hi,
                    _ => spans.push((lo, hi)),
                }
            }
            spans
        })
        .collect()
}

/// scipy's `gaussian_filter(img, mode="constant")` with the kernel `w`, evaluated on `need`'s
/// spans of each row (elsewhere 0): axis 0, then axis 1, each pass summed in float64 in scipy's
/// order (the centre, then the offset pairs from the farthest; a cell past the grid's edge reads
/// zero, and x + 0 is x exactly) and stored as float32.
fn gaussian_on(img: &Grid<f32>, w: &[f64], need: &Spans) -> Grid<f32> {
    let (nx, ny) = (img.nx, img.ny);
    let r = w.len() / 2;
    let inp = |k: usize, a: usize, b: usize| img.data[k * ny + a..k * ny + b].iter();
    // axis 0 on the spans the second pass reads (its spans grown by the radius)
    let mut rows_needed = vec![false; nx * ny];
    for (i, spans) in need.iter().enumerate() {
        for &(a, b) in spans {
            rows_needed[i * ny + a..i * ny + b]
                .iter_mut()
                .for_each(|v| *v = true);
        }
    }
    let first_spans = row_spans(&rows_needed, nx, ny, r);
    let mut tmp = Grid::filled(nx, ny, 0.0f32);
    let mut acc: Vec<f64> = Vec::with_capacity(ny);
    for (i, spans) in first_spans.iter().enumerate() {
        for &(a, b) in spans {
            acc.clear();
            acc.extend(inp(i, a, b).map(|&x| x as f64 * w[r]));
            for d in (1..=r.min(nx)).rev() {
                let wd = w[r - d];
                match (i.checked_sub(d), (i + d < nx).then_some(i + d)) {
                    (Some(lo), Some(hi)) => {
                        for ((s, &x), &y) in acc.iter_mut().zip(inp(lo, a, b)).zip(inp(hi, a, b)) {
                            *s += (x as f64 + y as f64) * wd;
                        }
                    }
                    (Some(k), None) | (None, Some(k)) => {
                        for (s, &x) in acc.iter_mut().zip(inp(k, a, b)) {
                            *s += x as f64 * wd;
                        }
                    }
                    (None, None) => {}
                }
            }
            for (o, &v) in tmp.data[i * ny + a..i * ny + b].iter_mut().zip(&acc) {
                *o = v as f32;
            }
        }
    }
    // axis 1 on the needed spans, from a row of the first pass padded with zeros
    let mut out = Grid::filled(nx, ny, 0.0f32);
    let mut buf = vec![0.0f64; ny + 2 * r];
    for (i, spans) in need.iter().enumerate() {
        if spans.is_empty() {
            continue;
        }
        for (bv, &t) in buf[r..r + ny]
            .iter_mut()
            .zip(&tmp.data[i * ny..(i + 1) * ny])
        {
            *bv = t as f64;
        }
        for &(a, b) in spans {
            acc.clear();
            acc.extend(buf[r + a..r + b].iter().map(|&x| x * w[r]));
            for d in (1..=r).rev() {
                let wd = w[r - d];
                let (lo, hi) = (&buf[r + a - d..r + b - d], &buf[r + a + d..r + b + d]);
                for ((s, &x), &y) in acc.iter_mut().zip(lo).zip(hi) {
                    *s += (x + y) * wd;
                }
            }
            for (o, &v) in out.data[i * ny + a..i * ny + b].iter_mut().zip(&acc) {
                *o = v as f32;
            }
        }
    }
    out
}

/// scipy `gaussian_filter(img, sigma, mode="constant", cval=0)` of a float32 grid.
pub fn gaussian_filter(img: &Grid<f32>, sigma: f64) -> Grid<f32> {
    let all = vec![
        if img.ny > 0 {
            vec![(0, img.ny)]
        } else {
            vec![]
        };
        img.nx
    ];
    gaussian_on(img, &gaussian_kernel(sigma), &all)
}

/// `np.gradient(f, axis)` of a float32 grid: `(f[k+1] - f[k-1]) / 2` inside, one-sided
/// differences at the two ends, float32. An axis of one cell has no gradient (zeros; numpy
/// raises there).
pub fn gradient(f: &Grid<f32>, axis: usize) -> Grid<f32> {
    let mut out = Grid::filled(f.nx, f.ny, 0.0f32);
    for i in 0..f.nx {
        for j in 0..f.ny {
            out.set(i, j, gradient_at(|a, b| f.at(a, b), f.nx, f.ny, axis, i, j));
        }
    }
    out
}

/// `np.gradient` of the values `f(i, j)` of an `nx x ny` grid along `axis` at `(i, j)`.
#[inline]
fn gradient_at(
    f: impl Fn(usize, usize) -> f32,
    nx: usize,
    ny: usize,
    axis: usize,
    i: usize,
    j: usize,
) -> f32 {
    let (n, k) = if axis == 0 { (nx, i) } else { (ny, j) };
    let at = |m: usize| if axis == 0 { f(m, j) } else { f(i, m) };
    if n < 2 {
        0.0
    } else if k == 0 {
        (at(1) - at(0)) / 1.0
    } else if k == n - 1 {
        (at(n - 1) - at(n - 2)) / 1.0
    } else {
        (at(k + 1) - at(k - 1)) / 2.0
    }
}

/// The smaller eigenvalue (per cell^2) of the Hessian of the smoothed probabilities `g` at
/// `(i, j)`, `hessian_matrix_eigvals(hessian_matrix(...))[1]` there.
fn low_eigenvalue_at(g: &Grid<f32>, i: usize, j: usize) -> f32 {
    let (nx, ny) = (g.nx, g.ny);
    let gr = |a: usize, b: usize| gradient_at(|x, y| g.at(x, y), nx, ny, 0, a, b);
    let gc = |a: usize, b: usize| gradient_at(|x, y| g.at(x, y), nx, ny, 1, a, b);
    let m00 = gradient_at(gr, nx, ny, 0, i, j);
    let m01 = gradient_at(gr, nx, ny, 1, i, j);
    let m11 = gradient_at(gc, nx, ny, 1, i, j);
    let half = (m00 - m11) / 2.0;
    let hsqrtdet = (m01 * m01 + half * half).sqrt();
    (m00 + m11) / 2.0 - hsqrtdet
}

/// The smaller eigenvalue of the Hessian of `prob` smoothed at `sigma` cells at every cell
/// (float32, per cell^2).
pub fn hessian_low_eigenvalue(prob: &Grid<f32>, sigma: f64) -> Grid<f32> {
    let g = gaussian_filter(prob, sigma);
    let mut out = Grid::filled(prob.nx, prob.ny, 0.0f32);
    for i in 0..prob.nx {
        for j in 0..prob.ny {
            out.set(i, j, low_eigenvalue_at(&g, i, j));
        }
    }
    out
}

/// The ridge mask of `prob` on `frame`'s grid (see the module docs).
pub fn ridge_mask(prob: &Grid<f32>, frame: &Frame, p: &VectoriseParams) -> Grid<bool> {
    let (nx, ny) = (prob.nx, prob.ny);
    let thr = p.ridge_threshold as f32;
    let mut out = Grid::filled(nx, ny, false);
    let cand: Vec<usize> = (0..nx * ny).filter(|&k| prob.data[k] > thr).collect();
    if cand.is_empty() {
        return out;
    }
    let px = (frame.sx * frame.sy).sqrt(); // metres per cell
    let w = gaussian_kernel(p.ridge_sigma / px);
    // the smoothed values the candidates' Hessians read: within two cells of them
    let mut near = vec![false; nx * ny];
    for &k in &cand {
        let (i, j) = (k / ny, k % ny);
        for a in i.saturating_sub(2)..(i + 3).min(nx) {
            near[a * ny + j.saturating_sub(2)..a * ny + (j + 3).min(ny)]
                .iter_mut()
                .for_each(|v| *v = true);
        }
    }
    let g = gaussian_on(prob, &w, &row_spans(&near, nx, ny, 0));
    let curv = (-p.ridge_curvature * px * px) as f32;
    for k in cand {
        let (i, j) = (k / ny, k % ny);
        out.data[k] = low_eigenvalue_at(&g, i, j) < curv;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_is_normalised_and_symmetric() {
        let w = gaussian_kernel(2.0);
        assert_eq!(w.len(), 17);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        for k in 0..8 {
            assert_eq!(w[k], w[16 - k]);
        }
        assert_eq!(gaussian_kernel(0.01), vec![1.0]);
    }

    #[test]
    fn gradient_of_a_parabola() {
        let f = Grid {
            nx: 5,
            ny: 1,
            data: vec![4.0f32, 1.0, 0.0, 1.0, 4.0],
        };
        assert_eq!(gradient(&f, 0).data, vec![-3.0, -2.0, 0.0, 2.0, 3.0]);
        assert_eq!(gradient(&f, 1).data, vec![0.0; 5]); // one cell: no gradient
        let h = gradient(&gradient(&f, 0), 0);
        assert_eq!(h.data, vec![1.0, 1.5, 2.0, 1.5, 1.0]);
    }

    #[test]
    fn a_line_is_a_ridge_and_a_plateau_is_not() {
        // a bright line along x at j = 10 on a 0.3 m grid; a wide plateau beside it
        let (nx, ny) = (40, 40);
        let mut g = Grid::filled(nx, ny, 0.05f32);
        for i in 0..nx {
            for j in 8..13 {
                let d = (j as f32 - 10.0).abs();
                g.set(i, j, 0.95 - 0.2 * d);
            }
            for j in 22..40 {
                g.set(i, j, 0.95);
            }
        }
        let frame = Frame::new(nx, ny, 6.0, 6.0);
        let m = ridge_mask(&g, &frame, &VectoriseParams::default());
        assert!(m.at(20, 10));
        assert!(!m.at(20, 30)); // flat inside the plateau
        assert!(!m.at(20, 2));
    }

    #[test]
    fn tiny_grids_do_not_panic() {
        let frame = Frame::new(1, 1, 1.0, 1.0);
        let g = Grid::filled(1, 1, 0.9f32);
        let m = ridge_mask(&g, &frame, &VectoriseParams::default());
        assert_eq!(m.data.len(), 1);
    }

    #[test]
    fn the_ridge_on_spans_is_the_ridge_of_the_whole_grid() {
        // smooth random blobs: the mask from the candidates' spans equals the one from the
        // Hessian of the whole grid, cell for cell
        let (nx, ny) = (60, 37);
        let mut state = 12345u64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % 10_000) as f32 / 10_000.0
        };
        let centres: Vec<(f32, f32, f32)> = (0..9)
            .map(|_| (rnd() * 60.0, rnd() * 37.0, rnd()))
            .collect();
        let mut g = Grid::filled(nx, ny, 0.0f32);
        for i in 0..nx {
            for j in 0..ny {
                let v: f32 = centres
                    .iter()
                    .map(|&(a, b, h)| {
                        h * (-((i as f32 - a).powi(2) + (j as f32 - b).powi(2)) / 18.0).exp()
                    })
                    .sum();
                g.set(i, j, v.min(1.0));
            }
        }
        let frame = Frame::new(nx, ny, 9.0, 5.55);
        let p = VectoriseParams::default();
        let got = ridge_mask(&g, &frame, &p);
        let px = (frame.sx * frame.sy).sqrt();
        let low = hessian_low_eigenvalue(&g, p.ridge_sigma / px);
        let curv = (-p.ridge_curvature * px * px) as f32;
        let want: Vec<bool> = (0..nx * ny)
            .map(|k| g.data[k] > p.ridge_threshold as f32 && low.data[k] < curv)
            .collect();
        assert_eq!(got.data, want);
        assert!(want.iter().any(|&v| v) && want.iter().any(|&v| !v));
    }
}
