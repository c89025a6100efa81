//! Knot placement (FITPACK `fpknot` and the interpolation knots), and the residual of a data point
//! that decides where knots go.

use super::basis::Design;

/// Squared residual of data point `it` for coefficients `c`.
#[inline(always)]
fn residual2(c: &[Vec<f64>; 2], k: usize, des: &Design, x: &[[f64; 2]], it: usize) -> f64 {
    let l0 = des.interval[it] - k;
    let h = &des.basis[it];
    if k == 3 {
        // The same sums, unrolled (one bounds check per coordinate).
        let [cx, cy] = [&c[0][l0..l0 + 4], &c[1][l0..l0 + 4]];
        let vx = cx[0] * h[0] + cx[1] * h[1] + cx[2] * h[2] + cx[3] * h[3];
        let vy = cy[0] * h[0] + cy[1] * h[1] + cy[2] * h[2] + cy[3] * h[3];
        let (ex, ey) = (vx - x[it][0], vy - x[it][1]);
        return ex * ex + ey * ey;
    }
    (0..2)
        .map(|d| {
            let v: f64 = (0..=k).map(|i| c[d][l0 + i] * h[i]).sum();
            (v - x[it][d]).powi(2)
        })
        .sum()
}

/// Interior knots for interpolation (FITPACK: data points for odd k, midpoints for even k).
pub(super) fn interpolation_knots(u: &[f64], k: usize) -> Vec<f64> {
    let m = u.len();
    let mk1 = m - (k + 1);
    let k3 = k / 2;
    (0..mk1)
        .map(|i| {
            let j = k3 + 1 + i; // 0-based index of FITPACK's u(k3 + 2 + i)
            if k.is_multiple_of(2) {
                0.5 * (u[j] + u[j - 1])
            } else {
                u[j]
            }
        })
        .collect()
}

pub(super) fn full_knots(interior: &[f64], k: usize) -> Vec<f64> {
    let mut t = vec![0.0; k + 1];
    t.extend_from_slice(interior);
    t.extend(std::iter::repeat_n(1.0, k + 1));
    t
}

/// Adds one knot at a data point in the interval with the largest residual sum among those with
/// interior data points (FITPACK `fpknot`). Returns false when no interval can take a knot.
pub(super) fn add_knot(
    u: &[f64],
    interior: &mut Vec<f64>,
    fpint: &mut Vec<f64>,
    nrdata: &mut Vec<usize>,
) -> bool {
    let mut best: Option<(usize, usize, usize, f64)> = None; // (interval, count, begin, fp)
    let mut fpmax = 0.0;
    let mut jbegin = 0usize; // 0-based index of the interval's left data point
    for j in 0..nrdata.len() {
        let jpoint = nrdata[j];
        if !(fpmax >= fpint[j] || jpoint == 0) {
            fpmax = fpint[j];
            best = Some((j, jpoint, jbegin, fpint[j]));
        }
        jbegin += jpoint + 1;
    }
    let Some((number, maxpt, maxbeg, fpmax)) = best else {
        return false;
    };
    let ihalf = maxpt / 2 + 1;
    let nrx = maxbeg + ihalf;
    let left = ihalf - 1;
    let right = maxpt - ihalf;
    nrdata[number] = left;
    nrdata.insert(number + 1, right);
    fpint[number] = fpmax * left as f64 / maxpt as f64;
    fpint.insert(number + 1, fpmax * right as f64 / maxpt as f64);
    interior.insert(number, u[nrx]);
    true
}

/// The sums of squared residuals of the fit `c` per knot interval of `t` (FITPACK's `fpint`): a
/// data point at or past an interior knot counts half to each side of it.
pub(super) fn interval_residuals(
    t: &[f64],
    k: usize,
    u: &[f64],
    x: &[[f64; 2]],
    c: &[Vec<f64>; 2],
    des: &Design,
) -> Vec<f64> {
    let n = t.len();
    let (k1, k2) = (k + 1, k + 2);
    let nk1 = n - k1;
    let nrint = n - 2 * k1 + 1;
    let mut fpint = vec![0.0; nrint];
    let mut fpart = 0.0;
    let mut i = 0usize;
    let mut l = k2; // 1-based, as FITPACK
    for (it, &ui) in u.iter().enumerate() {
        let mut new = false;
        if l <= nk1 && ui >= t[l - 1] {
            new = true;
            l += 1;
        }
        let term = residual2(c, k, des, x, it);
        fpart += term;
        if new {
            let store = 0.5 * term;
            fpint[i] = fpart - store;
            i += 1;
            fpart = store;
        }
    }
    fpint[nrint - 1] = fpart;
    fpint
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::basis::design;
    use crate::fit::lsq_qr::lsq_fit;
    use crate::fit::test_util::lsq_data;

    #[test]
    fn interpolation_knots_are_data_points_or_midpoints() {
        let u = [0.0, 0.1, 0.3, 0.4, 0.7, 0.9, 1.0];
        // Odd degree: the data points u[2..m - 2]; even: midpoints; m - k - 1 knots.
        assert_eq!(interpolation_knots(&u, 3), vec![0.3, 0.4, 0.7]);
        assert_eq!(interpolation_knots(&u, 1), vec![0.1, 0.3, 0.4, 0.7, 0.9]);
        let even = interpolation_knots(&u, 2);
        assert_eq!(even.len(), 4);
        for (v, w) in even.iter().zip([0.2, 0.35, 0.55, 0.8]) {
            assert!((v - w).abs() < 1e-15);
        }
        assert_eq!(
            full_knots(&[0.5], 2),
            vec![0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0]
        );
    }

    #[test]
    fn add_knot_splits_the_worst_interval_with_data() {
        let u: Vec<f64> = (0..16).map(|i| i as f64 / 15.0).collect();
        // Three intervals with 4, 6 and 3 interior data points (and a knot point between each).
        let mut interior = vec![u[5], u[12]];
        let mut fpint = vec![1.0, 5.0, 2.0];
        let mut nrdata = vec![4, 6, 3];
        assert!(add_knot(&u, &mut interior, &mut fpint, &mut nrdata));
        // The middle interval (largest residual) starts at data point 5; its 6 interior points
        // are split at the 4th one (u[9]): 3 left of the new knot, 2 right.
        assert_eq!(interior, vec![u[5], u[9], u[12]]);
        assert_eq!(nrdata, vec![4, 3, 2, 3]);
        assert_eq!(fpint, vec![1.0, 2.5, 5.0 / 3.0, 2.0]);
        // No interval with interior data points: nothing to add.
        let (mut i2, mut f2, mut n2) = (vec![0.5], vec![3.0, 4.0], vec![0, 0]);
        assert!(!add_knot(&u, &mut i2, &mut f2, &mut n2));
        assert_eq!(i2, vec![0.5]);
    }

    #[test]
    fn interval_residuals_sum_to_fp() {
        let (u, x) = lsq_data(50);
        for (k, interior) in [(3, vec![0.25, 0.5, 0.75]), (2, vec![0.33]), (1, vec![])] {
            let t = full_knots(&interior, k);
            let des = design(&t, k, &u);
            let fit = lsq_fit(&t, k, &x, &des);
            let fpint = interval_residuals(&t, k, &u, &x, &fit.c, &des);
            assert_eq!(fpint.len(), interior.len() + 1);
            assert!(fpint.iter().all(|&v| v >= 0.0));
            let total: f64 = fpint.iter().sum();
            assert!(
                (total - fit.fp).abs() <= 1e-9 * fit.fp,
                "{total} vs {}",
                fit.fp
            );
        }
    }
}
