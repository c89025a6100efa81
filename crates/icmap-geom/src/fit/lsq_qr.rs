//! Least-squares spline with fixed knots by Givens QR of the banded observation matrix (FITPACK
//! `fppara`'s least-squares step; any degree 1..=3).

use super::basis::Design;
use super::givens::{back_substitute, givens_bounded, rotate};

/// Least-squares fit with fixed knots: the triangularised system and the fit.
pub(super) struct LsqFit {
    /// Banded R of the observation matrix (bandwidth k + 1).
    pub(super) r: Vec<[f64; 5]>,
    /// Rotated right-hand sides (x and y).
    pub(super) z: [Vec<f64>; 2],
    /// Coefficients (x and y).
    pub(super) c: [Vec<f64>; 2],
    /// Sum of squared residuals.
    pub(super) fp: f64,
}

pub(super) fn lsq_fit(t: &[f64], k: usize, x: &[[f64; 2]], des: &Design) -> LsqFit {
    match k {
        3 => lsq_fit_of_degree::<3>(t, x, des),
        2 => lsq_fit_of_degree::<2>(t, x, des),
        _ => lsq_fit_of_degree::<1>(t, x, des),
    }
}

/// [`lsq_fit`] with the degree known at compile time (the inner loops unrolled).
fn lsq_fit_of_degree<const K: usize>(t: &[f64], x: &[[f64; 2]], des: &Design) -> LsqFit {
    let k1 = K + 1;
    let nk1 = t.len() - k1;
    let mut r = vec![[0.0; 5]; nk1];
    let mut z = [vec![0.0; nk1], vec![0.0; nk1]];
    let mut fp = 0.0;
    for ((basis, xy), &l) in des.basis.iter().zip(x).zip(&des.interval) {
        let mut h = *basis;
        let mut xi = *xy;
        let j0 = l - K;
        for i in 0..=K {
            let piv = h[i];
            if piv == 0.0 {
                continue;
            }
            let j = j0 + i;
            let row = &mut r[j];
            let (cos, sin) = givens_bounded(piv, &mut row[0]);
            for d in 0..2 {
                rotate(cos, sin, &mut xi[d], &mut z[d][j]);
            }
            for i1 in i + 1..=K {
                rotate(cos, sin, &mut h[i1], &mut row[i1 - i]);
            }
        }
        fp += xi[0] * xi[0] + xi[1] * xi[1];
    }
    let c = [
        back_substitute(&r, &z[0], k1),
        back_substitute(&r, &z[1], k1),
    ];
    LsqFit { r, z, c, fp }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::basis::design;
    use crate::fit::knots::full_knots;
    use crate::fit::test_util::{check_lsq, lsq_data};

    #[test]
    fn givens_qr_solves_the_least_squares_problem() {
        let (u, x) = lsq_data(40);
        for k in 1..=3 {
            for interior in [&[][..], &[0.3, 0.6][..], &[0.1, 0.2, 0.5, 0.55, 0.9][..]] {
                let t = full_knots(interior, k);
                let fit = lsq_fit(&t, k, &x, &design(&t, k, &u));
                check_lsq(&t, k, &u, &x, &fit.c, fit.fp);
                // R is upper triangular with a positive diagonal.
                assert!(fit.r.iter().all(|row| row[0] > 0.0));
            }
        }
    }
}
