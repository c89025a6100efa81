//! Test helpers shared by the fit modules' tests.

use super::arc_length::arc_length_params;
use super::spline::SplineCurve;
use crate::resample::polyline_length;
use crate::types::Point;

pub(super) fn p(x: f64, y: f64) -> Point {
    Point::new(x, y)
}

/// A noisy arc with deterministic pseudo-noise.
pub(super) fn noisy_arc(m: usize, noise: f64) -> Vec<Point> {
    (0..m)
        .map(|i| {
            let a = i as f64 / (m - 1) as f64 * 1.5;
            let e = ((i * 7919 % 101) as f64 / 101.0 - 0.5) * 2.0 * noise;
            let r = 20.0 + e;
            p(r * a.cos(), r * a.sin())
        })
        .collect()
}

/// Arc length of `curve` between consecutive parameters of `us`, measured independently of
/// the quadrature by 512 chords per interval.
pub(super) fn arc_gaps(curve: &SplineCurve, us: &[f64]) -> Vec<f64> {
    us.windows(2)
        .map(|w| {
            let pts: Vec<Point> = (0..=512)
                .map(|j| curve.eval(w[0] + (w[1] - w[0]) * j as f64 / 512.0))
                .collect();
            polyline_length(&pts, false)
        })
        .collect()
}

/// Checks the documented contract of the arc-length evaluation on `curve`.
pub(super) fn check_even(curve: &SplineCurve, spacing: f64) {
    let us = arc_length_params(curve, spacing).unwrap();
    let gaps = arc_gaps(curve, &us);
    let len: f64 = gaps.iter().sum();
    let count = ((len / spacing * (1.0 - 1e-6)).ceil() as usize + 1).max(2);
    assert!(
        us.len().abs_diff(count) <= 1,
        "{} points for length {len}",
        us.len()
    );
    assert_eq!((us[0], us[us.len() - 1]), (0.0, 1.0));
    assert!(us.windows(2).all(|w| w[0] <= w[1]));
    let step = len / (us.len() - 1) as f64;
    let mut acc = 0.0;
    for (i, g) in gaps.iter().enumerate() {
        acc += g;
        let err = (acc - step * (i + 1) as f64).abs();
        assert!(
            err <= 1e-3 * spacing,
            "point {i}: arc error {err} (spacing {spacing})"
        );
    }
}

/// Chord-like parameters on `[0, 1]` and noisy points of a wavy curve (deterministic), for the
/// least-squares tests.
pub(super) fn lsq_data(m: usize) -> (Vec<f64>, Vec<[f64; 2]>) {
    let u: Vec<f64> = (0..m).map(|i| i as f64 / (m - 1) as f64).collect();
    let x = u
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            let e = ((i * 7919 % 101) as f64 / 101.0 - 0.5) * 0.2;
            [100.0 + 10.0 * t + e, 3.0 * (6.0 * t).sin() - e]
        })
        .collect();
    (u, x)
}

/// Checks that `c` is the least-squares spline of degree `k` on knots `t` through the points `x`
/// at parameters `u`, densely and independently of the solvers: the residual is orthogonal to
/// every B-spline (the normal equations hold) and `fp` is its squared norm.
pub(super) fn check_lsq(
    t: &[f64],
    k: usize,
    u: &[f64],
    x: &[[f64; 2]],
    c: &[Vec<f64>; 2],
    fp: f64,
) {
    let nk1 = t.len() - k - 1;
    let mut grad = vec![[0.0f64; 2]; nk1];
    let mut sum = 0.0;
    for (&ui, xy) in u.iter().zip(x) {
        let l = k + t[k + 1..nk1].partition_point(|&v| v <= ui);
        let h = super::basis::bspline_basis(t, k, ui, l);
        for d in 0..2 {
            let fit: f64 = (0..=k).map(|j| c[d][l - k + j] * h[j]).sum();
            let r = fit - xy[d];
            sum += r * r;
            for j in 0..=k {
                grad[l - k + j][d] += h[j] * r;
            }
        }
    }
    let scale = x.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs())) * (u.len() as f64).sqrt();
    for g in &grad {
        assert!(
            g[0].abs() < 1e-10 * scale && g[1].abs() < 1e-10 * scale,
            "gradient {g:?}"
        );
    }
    assert!(
        (fp - sum).abs() <= 1e-9 * sum.max(1e-12),
        "fp {fp} vs {sum}"
    );
}
