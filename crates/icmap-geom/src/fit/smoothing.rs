//! The smoothing weight with fixed knots (FITPACK `fppara` part 2): the discontinuity jumps of the
//! k-th derivative (`fpdisc`), the rational-interpolation step (`fprati`) and the iteration that
//! finds `p` with `fp(p) = s`.

use super::givens::{back_substitute_into, givens_scaled, rotate};
use super::lsq_qr::LsqFit;
use super::spline::{make_curve, SplineCurve};
use super::{MAXIT, TOL};

/// Relative size (to the least diagonal entry of R) below which a smoothing row counts as
/// eliminated in [`smooth_on_knots`] (as the fits call it): 2^-100, far below where the
/// differences to FITPACK's full rotations (about 1e-12 of the curve's extent on a 3 km curve of
/// 400 knots, the size of the rounding noise of that system) would come from the cut rather than
/// from the order of the arithmetic.
pub(super) const NEGLIGIBLE_ROW: f64 = 7.888609052210118e-31; // 2^-100

/// Discontinuity jumps of the k-th derivative of the B-splines at the interior knots (FITPACK
/// `fpdisc`): one row of `k + 2` entries per interior knot, row `r` acting on coefficients
/// `r..r + k + 2`.
fn discontinuity_jumps(t: &[f64], k: usize) -> Vec<[f64; 6]> {
    let n = t.len();
    let (k1, k2) = (k + 1, k + 2);
    let nk1 = n - k1;
    let tt = |i: usize| t[i - 1]; // 1-based access, as in FITPACK
    let fac = (nk1 - k) as f64 / (tt(nk1 + 1) - tt(k1));
    let mut rows = Vec::with_capacity(n.saturating_sub(2 * k1));
    for l in k2..=nk1 {
        let mut h = [0.0; 12];
        for j in 1..=k1 {
            h[j] = tt(l) - tt(l + j - k2);
            h[j + k1] = tt(l) - tt(l + j);
        }
        let mut row = [0.0; 6];
        for (j, cell) in row.iter_mut().enumerate().take(k2) {
            let lp = l - k1 + j;
            let mut prod = h[j + 1];
            for i in 1..=k {
                prod *= h[j + 1 + i] * fac;
            }
            *cell = (tt(lp + k1) - tt(lp)) / prod;
        }
        rows.push(row);
    }
    rows
}

/// Rational interpolation step for the smoothing weight (FITPACK `fprati`); updates the bracket.
fn rational_step(p1: &mut f64, f1: &mut f64, p2: f64, f2: f64, p3: &mut f64, f3: &mut f64) -> f64 {
    let p = if *p3 > 0.0 {
        let h1 = *f1 * (f2 - *f3);
        let h2 = f2 * (*f3 - *f1);
        let h3 = *f3 * (*f1 - f2);
        -(*p1 * p2 * h3 + p2 * *p3 * h1 + *p3 * *p1 * h2) / (*p1 * h1 + p2 * h2 + *p3 * h3)
    } else {
        (*p1 * (*f1 - *f3) * f2 - p2 * (f2 - *f3) * *f1) / ((*f1 - f2) * *f3)
    };
    if f2 < 0.0 {
        *p3 = p2;
        *f3 = f2;
    } else {
        *p1 = p2;
        *f1 = f2;
    }
    p
}

/// FITPACK `fppara` part 2: with the knots `t` fixed (least-squares fit `fit` with `fp - s =
/// fpms < 0`; `fp0` the least-squares polynomial's `fp`), the smoothing weight `p` with
/// `fp(p) = s`. `negligible_row`: the relative size below which a smoothing row counts as
/// eliminated ([`NEGLIGIBLE_ROW`]; 0: FITPACK's full rotations).
#[allow(clippy::too_many_arguments)]
pub(super) fn smooth_on_knots(
    t: Vec<f64>,
    fit: &LsqFit,
    u: &[f64],
    k: usize,
    s: f64,
    fp0: f64,
    fpms: f64,
    negligible_row: f64,
) -> SplineCurve {
    let (k1, k2) = (k + 1, k + 2);
    let nmin = 2 * k1;
    let acc = TOL * s;
    let n = t.len();
    let nk1 = n - k1;
    let n8 = n - nmin;
    let b = discontinuity_jumps(&t, k);
    let (mut p1, mut f1, mut p3, mut f3) = (0.0, fp0 - s, -1.0, fpms);
    let diag: f64 = fit.r.iter().map(|r| r[0]).sum();
    let mut p = nk1 as f64 / diag;
    let (mut ich1, mut ich3) = (false, false);
    // The latest iteration's coefficients and fp (each iteration's replace the previous ones).
    let mut coef = fit.c.clone();
    let mut fp_best = fit.fp;
    // Work copies of the triangularised system, reset from `fit` on every iteration.
    let mut g = fit.r.clone();
    let mut c = fit.z.clone();
    // A row whose entries have all fallen below `negligible` is eliminated for all purposes: a
    // rotation by it has `cos == 1` exactly and `sin <= 2^-100` (the diagonal of R only grows
    // under rotations, so the least diagonal entry of the least-squares R bounds it from below).
    // FITPACK rotates every row on to the last coefficient: O(n^2) per iteration, seconds for a
    // curve of thousands of knots (a 10 km polyline at 1 m), where the rows die out after some
    // dozens of steps (3.6 s -> 0.4 s for a fit of 20,000 points).
    let dmin = fit.r.iter().map(|row| row[0]).fold(f64::INFINITY, f64::min);
    let negligible = if dmin.is_finite() && dmin > 0.0 {
        dmin * negligible_row
    } else {
        0.0
    };
    for iter in 1..=MAXIT {
        let pinv = 1.0 / p;
        g.copy_from_slice(&fit.r);
        c[0].copy_from_slice(&fit.z[0]);
        c[1].copy_from_slice(&fit.z[1]);
        for (it, brow) in b.iter().enumerate() {
            let mut h = [0.0; 6];
            for j in 0..k2 {
                h[j] = brow[j] * pinv;
            }
            let mut xi = [0.0; 2];
            for j in it..nk1 {
                // Once the row is eliminated (or negligible, see above), FITPACK's remaining
                // rotations are identities.
                if h[..k2].iter().all(|&v| v.abs() <= negligible) {
                    break;
                }
                let (cos, sin) = givens_scaled(h[0], &mut g[j][0]);
                for d in 0..2 {
                    rotate(cos, sin, &mut xi[d], &mut c[d][j]);
                }
                if j == nk1 - 1 {
                    break;
                }
                let i2 = if j >= n8 { nk1 - 1 - j } else { k1 };
                for i in 1..=i2 {
                    rotate(cos, sin, &mut h[i], &mut g[j][i]);
                    h[i - 1] = h[i];
                }
                h[i2] = 0.0;
            }
        }
        back_substitute_into(&g, &c[0], k2, &mut coef[0]);
        back_substitute_into(&g, &c[1], k2, &mut coef[1]);
        // fp = |B c - x|^2 = |R c - z|^2 + fp of the least-squares fit (B = Q R, z = Q^T x): a
        // sum over the coefficients instead of over the data points.
        let bw = k1.min(nk1);
        let mut fp = fit.fp;
        for (cd, zd) in coef.iter().zip(&fit.z) {
            for (j, row) in fit.r.iter().enumerate() {
                let w = bw.min(nk1 - j);
                let rc: f64 = (0..w).map(|l| row[l] * cd[j + l]).sum();
                let e = rc - zd[j];
                fp += e * e;
            }
        }
        fp_best = fp;
        let fpms = fp - s;
        if fpms.abs() < acc || iter == MAXIT {
            break;
        }
        let (p2, f2) = (p, fpms);
        if !ich3 {
            if f2 - f3 <= acc {
                // The initial p was too large.
                p3 = p2;
                f3 = f2;
                p *= 0.04;
                if p <= p1 {
                    p = p1 * 0.9 + p2 * 0.1;
                }
                continue;
            }
            if f2 < 0.0 {
                ich3 = true;
            }
        }
        if !ich1 {
            if f1 - f2 <= acc {
                // The initial p was too small.
                p1 = p2;
                f1 = f2;
                p /= 0.04;
                if p3 >= 0.0 && p >= p3 {
                    p = p2 * 0.1 + p3 * 0.9;
                }
                continue;
            }
            if f2 > 0.0 {
                ich1 = true;
            }
        }
        if f2 >= f1 || f2 <= f3 {
            break;
        }
        p = rational_step(&mut p1, &mut f1, p2, f2, &mut p3, &mut f3);
    }
    make_curve(t, coef, k, u, fp_best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::basis::design;
    use crate::fit::knots::full_knots;
    use crate::fit::lsq_qr::lsq_fit;
    use crate::fit::test_util::lsq_data;

    #[test]
    fn jumps_are_proportional_to_the_third_derivative_jumps() {
        // A cubic spline with four interior knots and arbitrary coefficients: each row of
        // `discontinuity_jumps` applied to the coefficients is the jump of the third derivative
        // at its knot (by exact forward differences on each side), times one common factor.
        let t = full_knots(&[0.2, 0.45, 0.5, 0.8], 3);
        let c: Vec<f64> = (0..8).map(|i| ((i * 37 % 11) as f64 - 5.0) * 0.7).collect();
        let curve = make_curve(t.clone(), [c.clone(), vec![0.0; 8]], 3, &[0.0, 1.0], 0.0);
        let d3 = |lo: f64, hi: f64| {
            // The third derivative of the cubic piece on [lo, hi].
            let h = (hi - lo) / 4.0;
            let f = |i: f64| curve.eval(lo + h * (0.5 + i)).x;
            (f(3.0) - 3.0 * f(2.0) + 3.0 * f(1.0) - f(0.0)) / (h * h * h)
        };
        let rows = discontinuity_jumps(&t, 3);
        assert_eq!(rows.len(), 4);
        let mut ratio = None;
        for (r, row) in rows.iter().enumerate() {
            let (left, knot, right) = (t[3 + r], t[4 + r], t[5 + r]);
            let jump = d3(knot, right) - d3(left, knot);
            let b: f64 = (0..5).map(|j| row[j] * c[r + j]).sum();
            let q = b / jump;
            let want = *ratio.get_or_insert(q);
            assert!(
                (q - want).abs() < 1e-6 * want.abs(),
                "row {r}: {q} vs {want}"
            );
        }
        // The constant 1 (all coefficients 1) has no jumps.
        for row in &rows {
            let ones: f64 = row[..5].iter().sum();
            assert!(ones.abs() < 1e-9 * row[0].abs());
        }
    }

    #[test]
    fn rational_step_finds_the_zero_of_a_rational_function() {
        // f(p) = (2 - p) / (p + 1): zero at p = 2.
        let f = |p: f64| (2.0 - p) / (p + 1.0);
        let (mut p1, mut f1, mut p3, mut f3) = (0.5, f(0.5), 4.0, f(4.0));
        let p = rational_step(&mut p1, &mut f1, 1.0, f(1.0), &mut p3, &mut f3);
        assert!((p - 2.0).abs() < 1e-12, "{p}");
        // f(1) > 0: the bracket's lower end moves to p = 1.
        assert_eq!((p1, p3), (1.0, 4.0));
        // With p3 = infinity (p3 <= 0 by FITPACK's convention), f3 is the limit -1.
        let (mut p1, mut f1, mut p3, mut f3) = (0.5, f(0.5), -1.0, -1.0);
        let p = rational_step(&mut p1, &mut f1, 1.0, f(1.0), &mut p3, &mut f3);
        assert!((p - 2.0).abs() < 1e-12, "{p}");
    }

    /// The cut-off of negligible rows gives FITPACK's full rotations' curve (to rounding) on a
    /// long noisy curve with many knots, where it saves most of the work.
    #[test]
    fn negligible_rows_change_nothing() {
        let m = 3000;
        let u: Vec<f64> = (0..m).map(|i| i as f64 / (m - 1) as f64).collect();
        let x: Vec<[f64; 2]> = u
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let e = ((i * 7919 % 101) as f64 / 101.0 - 0.5) * 0.2;
                [3000.0 * v, (40.0 * v).sin() + e]
            })
            .collect();
        let interior: Vec<f64> = (1..400).map(|i| i as f64 / 400.0).collect();
        let t = full_knots(&interior, 3);
        let fit = lsq_fit(&t, 3, &x, &design(&t, 3, &u));
        let t0 = full_knots(&[], 3);
        let fp0 = lsq_fit(&t0, 3, &x, &design(&t0, 3, &u)).fp;
        let s = fit.fp + 0.3 * (fp0 - fit.fp);
        let cut = smooth_on_knots(t.clone(), &fit, &u, 3, s, fp0, fit.fp - s, NEGLIGIBLE_ROW);
        let full = smooth_on_knots(t, &fit, &u, 3, s, fp0, fit.fp - s, 0.0);
        assert!(
            (cut.residual - full.residual).abs() <= 1e-12 * full.residual,
            "fp {} vs {}",
            cut.residual,
            full.residual
        );
        // Coefficients to 1e-11 of the curve's extent (3 km here): rounding noise of a system
        // of 400 knots.
        let scale = full
            .coeffs
            .iter()
            .flatten()
            .fold(0.0f64, |a, v| a.max(v.abs()));
        for d in 0..2 {
            for (a, b) in cut.coeffs[d].iter().zip(&full.coeffs[d]) {
                assert!((a - b).abs() <= 1e-11 * scale, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn smoothing_weight_meets_s_on_fixed_knots() {
        let (u, x) = lsq_data(80);
        let t = full_knots(&[0.2, 0.4, 0.6, 0.8], 3);
        let fit = lsq_fit(&t, 3, &x, &design(&t, 3, &u));
        let t0 = full_knots(&[], 3);
        let fp0 = lsq_fit(&t0, 3, &x, &design(&t0, 3, &u)).fp;
        assert!(fit.fp < fp0);
        for frac in [0.01, 0.2, 0.5, 0.9] {
            let s = fit.fp + frac * (fp0 - fit.fp);
            let curve = smooth_on_knots(t.clone(), &fit, &u, 3, s, fp0, fit.fp - s, NEGLIGIBLE_ROW);
            assert!(
                (curve.residual - s).abs() <= TOL * s,
                "fp {} s {s}",
                curve.residual
            );
            // The reported fp is the residual of the returned curve at the data.
            let direct: f64 = u
                .iter()
                .zip(&x)
                .map(|(&ui, xy)| {
                    let q = curve.eval(ui);
                    (q.x - xy[0]).powi(2) + (q.y - xy[1]).powi(2)
                })
                .sum();
            assert!((direct - curve.residual).abs() <= 1e-9 * direct);
        }
    }
}
