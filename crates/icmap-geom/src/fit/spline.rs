//! The fitted curve in B-spline form ([`SplineCurve`]): evaluation and the derivative on one knot
//! interval.

use super::basis::bspline_basis;
use crate::types::Point;

/// A fitted parametric spline curve `u in [0, 1] -> (x(u), y(u))` in B-spline form.
#[derive(Debug, Clone, PartialEq)]
pub struct SplineCurve {
    /// Knot vector (`n` knots, `degree + 1` repeated at each end), as scipy's `tck[0]`.
    pub knots: Vec<f64>,
    /// B-spline coefficients of x and y (`n - degree - 1` each), as scipy's `tck[1]`.
    pub coeffs: [Vec<f64>; 2],
    /// Spline degree (3, or lower for 2 or 3 distinct points), as scipy's `tck[2]`.
    pub degree: usize,
    /// The chord-length parameter of the (deduplicated) data points, as scipy's `u`.
    pub params: Vec<f64>,
    /// Weighted sum of squared residuals of the fit (scipy's `fp`).
    pub residual: f64,
}

impl SplineCurve {
    /// The curve at parameter `u` (clamped to `[0, 1]`).
    pub fn eval(&self, u: f64) -> Point {
        let k = self.degree;
        let t = &self.knots;
        let nk1 = t.len() - k - 1;
        let u = u.clamp(t[k], t[nk1]);
        // Knot interval t[l] <= u < t[l + 1] with k <= l <= nk1 - 1 (binary search).
        let l = k + t[k + 1..nk1].partition_point(|&x| x <= u);
        self.eval_in(u, l)
    }

    /// The curve at `u` in knot interval `l`.
    pub(super) fn eval_in(&self, u: f64, l: usize) -> Point {
        let k = self.degree;
        let t = &self.knots;
        let h = bspline_basis(t, k, u, l);
        let mut out = [0.0; 2];
        for (d, o) in out.iter_mut().enumerate() {
            *o = (0..=k).map(|i| self.coeffs[d][l - k + i] * h[i]).sum();
        }
        Point::new(out[0], out[1])
    }
}

pub(super) fn make_curve(
    t: Vec<f64>,
    c: [Vec<f64>; 2],
    k: usize,
    u: &[f64],
    fp: f64,
) -> SplineCurve {
    SplineCurve {
        knots: t,
        coeffs: c,
        degree: k,
        params: u.to_vec(),
        residual: fp,
    }
}

impl SplineCurve {
    /// `C'(u)` on the knot interval `l` (`t[l] <= u <= t[l + 1]`, the polynomial piece of `l`).
    pub(super) fn derivative_in(&self, l: usize, u: f64) -> [f64; 2] {
        let k = self.degree;
        let t = &self.knots;
        // The derivative is a spline of degree k - 1 on t[1..n - 1] with coefficients
        // k (c[j + 1] - c[j]) / (t[j + k + 1] - t[j + 1]); interval l there is l - 1.
        let h = bspline_basis(&t[1..], k - 1, u, l - 1);
        let mut out = [0.0; 2];
        for (d, o) in out.iter_mut().enumerate() {
            let c = &self.coeffs[d];
            *o = (0..k)
                .map(|i| {
                    let j = l - k + i;
                    let den = t[j + k + 1] - t[j + 1];
                    if den > 0.0 {
                        k as f64 * (c[j + 1] - c[j]) / den * h[i]
                    } else {
                        0.0
                    }
                })
                .sum();
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cubic with one interior knot (5 coefficients per coordinate).
    fn curve() -> SplineCurve {
        make_curve(
            vec![0.0, 0.0, 0.0, 0.0, 0.4, 1.0, 1.0, 1.0, 1.0],
            [
                vec![0.0, 1.0, 3.0, 4.0, 6.0],
                vec![0.0, 2.0, -1.0, 1.0, 0.5],
            ],
            3,
            &[0.0, 1.0],
            0.0,
        )
    }

    #[test]
    fn ends_are_the_end_coefficients_and_u_is_clamped() {
        let c = curve();
        assert_eq!(c.eval(0.0), Point::new(0.0, 0.0));
        assert!((c.eval(1.0) - Point::new(6.0, 0.5)).norm() < 1e-15);
        assert_eq!(c.eval(-3.0), c.eval(0.0));
        assert_eq!(c.eval(7.0), c.eval(1.0));
    }

    #[test]
    fn derivative_matches_finite_differences() {
        let c = curve();
        for (l, lo, hi) in [(3usize, 0.0, 0.4), (4, 0.4, 1.0)] {
            for i in 1..10 {
                let u = lo + (hi - lo) * i as f64 / 10.0;
                let h = 1e-6;
                let fd = (c.eval_in(u + h, l) - c.eval_in(u - h, l)) / (2.0 * h);
                let d = c.derivative_in(l, u);
                assert!(
                    (d[0] - fd.x).abs() < 1e-6 && (d[1] - fd.y).abs() < 1e-6,
                    "u {u}"
                );
            }
        }
    }
}
