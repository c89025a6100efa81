//! Bilinear upsampling of one class's probabilities by an integer factor, as torch's
//! `F.interpolate(scale_factor=f, mode="bilinear", align_corners=False)`.
//!
//! The source positions and weights are torch's (float32: `src = max(0, (d + 0.5) / f - 0.5)`, the
//! upper neighbour clamped at the last cell); the weighted sum is taken in float64 and rounded
//! once to float32. torch's own float32 sums differ by the CPU kernel it picks (its result changes
//! with the thread count and the vector unit by up to one float32 ulp); this one does not.

/// Source index pairs and weights along one axis of `n_in` cells upsampled `factor` times:
/// `(i0, i1, w0, w1)` per output cell.
fn axis_weights(n_in: usize, factor: usize) -> Vec<(usize, usize, f64, f64)> {
    let scale = (1.0 / factor as f64) as f32;
    (0..n_in * factor)
        .map(|d| {
            let src = (scale * (d as f32 + 0.5) - 0.5).max(0.0);
            let i0 = (src.floor() as usize).min(n_in - 1);
            let i1 = if i0 < n_in - 1 { i0 + 1 } else { i0 };
            let l1 = (src - i0 as f32).clamp(0.0, 1.0);
            let l0 = 1.0 - l1;
            (i0, i1, l0 as f64, l1 as f64)
        })
        .collect()
}

/// `src` `(nx, ny)` row-major upsampled `factor` times -> `(nx * factor, ny * factor)`. A factor
/// of 1 returns a copy. Total for any input (an empty axis gives an empty output).
pub fn bilinear(src: &[f32], nx: usize, ny: usize, factor: usize) -> Vec<f32> {
    if factor <= 1 || nx == 0 || ny == 0 || src.len() != nx * ny {
        return src.to_vec();
    }
    let wx = axis_weights(nx, factor);
    let wy = axis_weights(ny, factor);
    let oy = ny * factor;
    // each source row interpolated along y once (float64), then pairs of rows along x: the same
    // sums as the direct two-dimensional formula, computed once
    let mut rows: Vec<f64> = Vec::with_capacity(nx * oy);
    for i in 0..nx {
        let r = &src[i * ny..(i + 1) * ny];
        for &(w0, w1, b0, b1) in &wy {
            rows.push(b0 * r[w0] as f64 + b1 * r[w1] as f64);
        }
    }
    let mut out = Vec::with_capacity(nx * factor * oy);
    for &(h0, h1, a0, a1) in &wx {
        let top = &rows[h0 * oy..(h0 + 1) * oy];
        let bottom = &rows[h1 * oy..(h1 + 1) * oy];
        out.extend(
            top.iter()
                .zip(bottom)
                .map(|(&t, &b)| (a0 * t + a1 * b) as f32),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factor_four_weights_are_torch_s() {
        // output cells 0, 1 copy the first input; then 7/8 : 1/8, 5/8 : 3/8, ...
        let w = axis_weights(3, 4);
        assert_eq!(w.len(), 12);
        assert_eq!(w[0], (0, 1, 1.0, 0.0));
        assert_eq!(w[1], (0, 1, 1.0, 0.0));
        assert_eq!(w[2], (0, 1, 0.875, 0.125));
        assert_eq!(w[5], (0, 1, 0.125, 0.875));
        assert_eq!(w[6], (1, 2, 0.875, 0.125));
        assert_eq!(w[10], (2, 2, 0.875, 0.125)); // past the last centre: the last cell twice
        assert_eq!(w[11], (2, 2, 0.625, 0.375));
    }

    #[test]
    fn constant_and_linear_fields() {
        let out = bilinear(&[0.25; 6], 2, 3, 4);
        assert_eq!(out.len(), 8 * 12);
        assert!(out.iter().all(|&v| v == 0.25));
        // a ramp along y stays a ramp between the cell centres
        let src = [0.0f32, 1.0, 2.0, 0.0, 1.0, 2.0];
        let out = bilinear(&src, 2, 3, 2);
        assert_eq!(&out[..6], &[0.0, 0.25, 0.75, 1.25, 1.75, 2.0]);
        assert_eq!(bilinear(&src, 2, 3, 1), src.to_vec());
    }

    #[test]
    fn single_cell_and_empty() {
        assert_eq!(bilinear(&[0.7], 1, 1, 3), vec![0.7; 9]);
        assert!(bilinear(&[], 0, 4, 4).is_empty());
    }
}
