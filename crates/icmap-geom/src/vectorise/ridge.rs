//! The ridge mask of a line class: cells above `ridge_threshold` where the probabilities curve
//! downwards across the line (the smaller eigenvalue of their Hessian, at the Gaussian scale
//! `ridge_sigma`, below `-ridge_curvature`).
//!
//! As scikit-image `hessian_matrix(prob, sigma, order="rc", use_gaussian_derivatives=False)` and
//! `hessian_matrix_eigvals` on float32 probabilities: a Gaussian filter (scipy `gaussian_filter`,
//! mode `constant`, truncate 4, each axis pass summed in float64 and stored in float32), then
//! `np.gradient` twice (central differences inside, one-sided at the edges) and the closed-form
//! eigenvalue, all in float32 as numpy computes them.

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

/// One pass of scipy's `correlate1d` with a symmetric kernel `w` (centre `w[r]`) along the lines
/// `line(l)` of length `len`, zero beyond the ends: `out = x0 w0 + sum_j (x-j + x+j) w-j` in
/// float64, stored as float32.
fn correlate_line(
    input: &[f32],
    w: &[f64],
    buf: &mut Vec<f64>,
    acc: &mut Vec<f64>,
    out: &mut [f32],
) {
    let r = w.len() / 2;
    let len = input.len();
    // offsets beyond the line read zeros on both sides and add exactly nothing: skip them
    let reach = r.min(len);
    buf.clear();
    buf.resize(len + 2 * reach, 0.0);
    for (b, &v) in buf[reach..reach + len].iter_mut().zip(input) {
        *b = v as f64;
    }
    // every output's sum in scipy's order (centre, then the farthest offset first), the outputs
    // side by side (vectorised)
    acc.clear();
    acc.extend(buf[reach..reach + len].iter().map(|&v| v * w[r]));
    for d in (1..=reach).rev() {
        let wd = w[r - d];
        let lo = &buf[reach - d..reach - d + len];
        let hi = &buf[reach + d..reach + d + len];
        for ((a, &x), &y) in acc.iter_mut().zip(lo).zip(hi) {
            *a += (x + y) * wd;
        }
    }
    for (o, &a) in out.iter_mut().zip(acc.iter()) {
        *o = a as f32;
    }
}

/// scipy `gaussian_filter(img, sigma, mode="constant", cval=0)` of a float32 grid (axis 0, then
/// axis 1; float32 between and after the passes).
pub fn gaussian_filter(img: &Grid<f32>, sigma: f64) -> Grid<f32> {
    let (nx, ny) = (img.nx, img.ny);
    let w = gaussian_kernel(sigma);
    let r = w.len() / 2;
    // axis 0: every output row is a weighted sum of whole input rows, in scipy's order per cell
    // (the centre, then offset pairs from the farthest; an offset past the grid's edge reads
    // zero, and x + 0 is x exactly)
    let rows: Vec<f64> = img.data.iter().map(|&v| v as f64).collect();
    let mut tmp = Grid::filled(nx, ny, 0.0f32);
    let mut acc = vec![0.0f64; ny];
    for i in 0..nx {
        let row = |k: usize| &rows[k * ny..(k + 1) * ny];
        for (a, &x) in acc.iter_mut().zip(row(i)) {
            *a = x * w[r];
        }
        for d in (1..=r.min(nx)).rev() {
            let wd = w[r - d];
            match (i.checked_sub(d), (i + d < nx).then_some(i + d)) {
                (Some(lo), Some(hi)) => {
                    for ((a, &x), &y) in acc.iter_mut().zip(row(lo)).zip(row(hi)) {
                        *a += (x + y) * wd;
                    }
                }
                (Some(k), None) | (None, Some(k)) => {
                    for (a, &x) in acc.iter_mut().zip(row(k)) {
                        *a += x * wd;
                    }
                }
                (None, None) => {}
            }
        }
        for (o, &a) in tmp.data[i * ny..(i + 1) * ny].iter_mut().zip(&acc) {
            *o = a as f32;
        }
    }
    // axis 1: along each row
    let mut out = Grid::filled(nx, ny, 0.0f32);
    let (mut buf, mut acc) = (Vec::new(), Vec::new());
    for i in 0..nx {
        let row = &tmp.data[i * ny..(i + 1) * ny];
        correlate_line(
            row,
            &w,
            &mut buf,
            &mut acc,
            &mut out.data[i * ny..(i + 1) * ny],
        );
    }
    out
}

/// `np.gradient(f, axis)` of a float32 grid: `(f[k+1] - f[k-1]) / 2` inside, one-sided
/// differences at the two ends, float32. An axis of one cell has no gradient (zeros; numpy
/// raises there).
pub fn gradient(f: &Grid<f32>, axis: usize) -> Grid<f32> {
    let (nx, ny) = (f.nx, f.ny);
    let mut out = Grid::filled(nx, ny, 0.0f32);
    let d = &f.data;
    if axis == 0 {
        if nx < 2 {
            return out;
        }
        for i in 0..nx {
            let (a, b, div) = if i == 0 {
                (1, 0, 1.0)
            } else if i == nx - 1 {
                (nx - 1, nx - 2, 1.0)
            } else {
                (i + 1, i - 1, 2.0)
            };
            let (ra, rb) = (&d[a * ny..(a + 1) * ny], &d[b * ny..(b + 1) * ny]);
            for ((o, &x), &y) in out.data[i * ny..(i + 1) * ny].iter_mut().zip(ra).zip(rb) {
                *o = (x - y) / div;
            }
        }
    } else {
        if ny < 2 {
            return out;
        }
        for i in 0..nx {
            let r = &d[i * ny..(i + 1) * ny];
            let o = &mut out.data[i * ny..(i + 1) * ny];
            o[0] = (r[1] - r[0]) / 1.0;
            o[ny - 1] = (r[ny - 1] - r[ny - 2]) / 1.0;
            for j in 1..ny - 1 {
                o[j] = (r[j + 1] - r[j - 1]) / 2.0;
            }
        }
    }
    out
}

/// The smaller eigenvalue of the Hessian of `prob` smoothed at `sigma` cells (float32, per
/// cell^2), as `hessian_matrix_eigvals(hessian_matrix(...))[1]`.
pub fn hessian_low_eigenvalue(prob: &Grid<f32>, sigma: f64) -> Grid<f32> {
    let g = gaussian_filter(prob, sigma);
    let gr = gradient(&g, 0);
    let gc = gradient(&g, 1);
    let hrr = gradient(&gr, 0);
    let hrc = gradient(&gr, 1);
    let hcc = gradient(&gc, 1);
    let data = (0..prob.data.len())
        .map(|k| {
            let (m00, m01, m11) = (hrr.data[k], hrc.data[k], hcc.data[k]);
            let half = (m00 - m11) / 2.0;
            let hsqrtdet = (m01 * m01 + half * half).sqrt();
            (m00 + m11) / 2.0 - hsqrtdet
        })
        .collect();
    Grid {
        nx: prob.nx,
        ny: prob.ny,
        data,
    }
}

/// The ridge mask of `prob` on `frame`'s grid (see the module docs).
pub fn ridge_mask(prob: &Grid<f32>, frame: &Frame, p: &VectoriseParams) -> Grid<bool> {
    let px = (frame.sx * frame.sy).sqrt(); // metres per cell
    let low = hessian_low_eigenvalue(prob, p.ridge_sigma / px);
    let thr = p.ridge_threshold as f32;
    let curv = (-p.ridge_curvature * px * px) as f32;
    Grid {
        nx: prob.nx,
        ny: prob.ny,
        data: prob
            .data
            .iter()
            .zip(&low.data)
            .map(|(&v, &l)| v > thr && l < curv)
            .collect(),
    }
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
}
