//! The least-squares cubic polynomial (a cubic spline without interior knots, FITPACK's first fit)
//! on the Bernstein basis: 4 x 4 normal equations, unrolled.

use super::basis::bernstein3;
use super::lsq_normal::{add_gram, NORMAL_PIVOT_MIN};

/// The least-squares cubic polynomial through `x` at parameters `u` (FITPACK's first fit: no
/// interior knots), as [`lsq_fit_cubic_normal`] computes it on the Bernstein basis, without the
/// design matrix, heap storage or the banded solver: the 4 x 4 normal equations summed in
/// registers (data centred on the first point), their Cholesky factor and the two triangular
/// solves unrolled. Returns the B-spline coefficients of x and y and `fp`; `None` under the same
/// pivot rule as [`lsq_fit_cubic_normal`] (the caller then takes the general path).
pub(super) fn fit_cubic_polynomial(u: &[f64], x: &[[f64; 2]]) -> Option<([[f64; 4]; 2], f64)> {
    let origin = x[0];
    // Upper triangle of B^T B, row-major: (0,0..3), (1,1..3), (2,2..3), (3,3).
    let mut a = [0.0f64; 10];
    let mut rhs = [[0.0f64; 4]; 2];
    for (&ui, xy) in u.iter().zip(x) {
        let h = bernstein3(ui);
        let v = [xy[0] - origin[0], xy[1] - origin[1]];
        add_gram(&mut a, &h);
        for i in 0..4 {
            rhs[0][i] += h[i] * v[0];
            rhs[1][i] += h[i] * v[1];
        }
    }
    // Cholesky A = R^T R (R upper triangular), with the pivot test of the banded solver.
    let pivot = |d: f64, diag: f64| -> Option<f64> {
        (!(d.is_nan() || d <= NORMAL_PIVOT_MIN * diag)).then(|| d.sqrt())
    };
    let r00 = pivot(a[0], a[0])?;
    let (r01, r02, r03) = (a[1] / r00, a[2] / r00, a[3] / r00);
    let r11 = pivot(a[4] - r01 * r01, a[4])?;
    let r12 = (a[5] - r01 * r02) / r11;
    let r13 = (a[6] - r01 * r03) / r11;
    let r22 = pivot(a[7] - (r02 * r02 + r12 * r12), a[7])?;
    let r23 = (a[8] - (r02 * r03 + r12 * r13)) / r22;
    let r33 = pivot(a[9] - (r03 * r03 + r13 * r13 + r23 * r23), a[9])?;
    let mut c = [[0.0f64; 4]; 2];
    for (cd, b) in c.iter_mut().zip(&rhs) {
        // R^T z = b, then R c = z.
        let z0 = b[0] / r00;
        let z1 = (b[1] - r01 * z0) / r11;
        let z2 = (b[2] - (r02 * z0 + r12 * z1)) / r22;
        let z3 = (b[3] - (r03 * z0 + r13 * z1 + r23 * z2)) / r33;
        let c3 = z3 / r33;
        let c2 = (z2 - r23 * c3) / r22;
        let c1 = (z1 - r12 * c2 - r13 * c3) / r11;
        let c0 = (z0 - r01 * c1 - r02 * c2 - r03 * c3) / r00;
        *cd = [c0, c1, c2, c3];
    }
    let mut fp = 0.0;
    for (&ui, xy) in u.iter().zip(x) {
        let h = bernstein3(ui);
        for d in 0..2 {
            let cd = &c[d];
            let fit = cd[0] * h[0] + cd[1] * h[1] + cd[2] * h[2] + cd[3] * h[3];
            let e = fit - (xy[d] - origin[d]);
            fp += e * e;
        }
    }
    if !fp.is_finite() {
        return None;
    }
    for (cd, o) in c.iter_mut().zip(origin) {
        for v in cd.iter_mut() {
            *v += o;
        }
    }
    Some((c, fp))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::basis::design;
    use crate::fit::knots::full_knots;
    use crate::fit::lsq_qr::lsq_fit;
    use crate::fit::test_util::{check_lsq, lsq_data};

    #[test]
    fn polynomial_agrees_with_the_banded_solvers() {
        for m in [4, 5, 20, 200] {
            let (u, x) = lsq_data(m);
            let (c, fp) = fit_cubic_polynomial(&u, &x).expect("well conditioned");
            let c = c.map(|cd| cd.to_vec());
            let t = full_knots(&[], 3);
            check_lsq(&t, 3, &u, &x, &c, fp);
            let qr = lsq_fit(&t, 3, &x, &design(&t, 3, &u));
            for (cd, qd) in c.iter().zip(&qr.c) {
                assert!(cd.iter().zip(qd).all(|(a, b)| (a - b).abs() < 1e-9));
            }
            assert!((fp - qr.fp).abs() <= 1e-9 * qr.fp.max(1e-12));
        }
    }

    #[test]
    fn three_points_are_declined() {
        // Four coefficients from three points: singular.
        let (u, x) = lsq_data(3);
        assert!(fit_cubic_polynomial(&u, &x).is_none());
    }
}
