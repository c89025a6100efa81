//! Least-squares cubic spline with fixed knots by the banded normal equations and their Cholesky
//! factor: the same triangular system as Givens QR ([`super::lsq_qr`]) up to rounding, cheaper;
//! declines an ill-conditioned system (the caller then uses Givens).

use super::basis::Design;
use super::givens::back_substitute;
use super::lsq_qr::LsqFit;

/// Smallest accepted ratio of a Cholesky pivot to its diagonal entry of the Gram matrix in
/// [`lsq_fit_cubic_normal`]; below it the system is too ill-conditioned for the normal equations
/// (their error grows with the square of the condition number) and Givens takes over.
pub(super) const NORMAL_PIVOT_MIN: f64 = 1e-6;

/// [`lsq_fit`] for cubic splines by the normal equations: the banded Gram matrix `B^T B`
/// (bandwidth 4) and its Cholesky factor, which is the QR's `R` (positive diagonal) up to
/// rounding, at a fraction of the cost of one Givens rotation per basis value. B-spline bases are
/// well conditioned where every knot interval holds data; a pivot below [`NORMAL_PIVOT_MIN`] of its
/// diagonal entry (an ill-posed knot placement) returns `None` and the caller uses Givens. The data
/// are centred on their first point (B-splines sum to 1, so the fit shifts with the data) and `fp`
/// is summed from the explicit residuals; `z` is returned for the uncentred data, as Givens gives
/// it (`Q^T x`).
pub(super) fn lsq_fit_cubic_normal(t: &[f64], x: &[[f64; 2]], des: &Design) -> Option<LsqFit> {
    const K1: usize = 4;
    let nk1 = t.len() - K1;
    let origin = x[0];
    // Band storage: a[i][j] = A(i, i + j).
    let mut a = vec![[0.0f64; 5]; nk1];
    let mut rhs = [vec![0.0f64; nk1], vec![0.0f64; nk1]];
    // The points come in knot-interval order: each interval's 4 x 4 block (10 distinct products)
    // and right-hand sides are summed in registers and added to the band once per interval.
    let mut flush = |j0: usize, blk: &[f64; 10], bx: &[f64; 4], by: &[f64; 4]| {
        let rows = &mut a[j0..j0 + K1];
        let mut q = 0;
        for (i, row) in rows.iter_mut().enumerate() {
            for cell in &mut row[..K1 - i] {
                *cell += blk[q];
                q += 1;
            }
        }
        let [rx, ry] = &mut rhs;
        for i in 0..K1 {
            rx[j0 + i] += bx[i];
            ry[j0 + i] += by[i];
        }
    };
    let mut cur = usize::MAX;
    let (mut blk, mut bx, mut by) = ([0.0f64; 10], [0.0f64; 4], [0.0f64; 4]);
    for ((h, xy), &l) in des.basis.iter().zip(x).zip(&des.interval) {
        let j0 = l - 3;
        if j0 != cur {
            if cur != usize::MAX {
                flush(cur, &blk, &bx, &by);
            }
            (blk, bx, by) = ([0.0; 10], [0.0; 4], [0.0; 4]);
            cur = j0;
        }
        let v = [xy[0] - origin[0], xy[1] - origin[1]];
        add_gram(&mut blk, &[h[0], h[1], h[2], h[3]]);
        for i in 0..K1 {
            bx[i] += h[i] * v[0];
            by[i] += h[i] * v[1];
        }
    }
    if cur != usize::MAX {
        flush(cur, &blk, &bx, &by);
    }
    // Banded Cholesky A = R^T R; r[i][j] = R(i, i + j).
    let mut r = vec![[0.0f64; 5]; nk1];
    for i in 0..nk1 {
        let q0 = i.saturating_sub(K1 - 1);
        let d = a[i][0] - (q0..i).map(|q| r[q][i - q] * r[q][i - q]).sum::<f64>();
        // (A NaN pivot fails too.)
        if d.is_nan() || d <= NORMAL_PIVOT_MIN * a[i][0] {
            return None;
        }
        let rii = d.sqrt();
        r[i][0] = rii;
        for j in 1..K1.min(nk1 - i) {
            // Rows q < i + j - 3 have no entry in column i + j (bandwidth 4).
            let qj = q0.max((i + j).saturating_sub(K1 - 1));
            let e = a[i][j] - (qj..i).map(|q| r[q][i - q] * r[q][i + j - q]).sum::<f64>();
            r[i][j] = e / rii;
        }
    }
    // z = R^-T (B^T x) by forward substitution, then c = R^-1 z.
    let mut z = [vec![0.0f64; nk1], vec![0.0f64; nk1]];
    for d in 0..2 {
        for i in 0..nk1 {
            let q0 = i.saturating_sub(K1 - 1);
            let acc = rhs[d][i] - (q0..i).map(|q| r[q][i - q] * z[d][q]).sum::<f64>();
            z[d][i] = acc / r[i][0];
        }
    }
    let mut c = [
        back_substitute(&r, &z[0], K1),
        back_substitute(&r, &z[1], K1),
    ];
    let mut fp = 0.0;
    for ((h, xy), &l) in des.basis.iter().zip(x).zip(&des.interval) {
        let j0 = l - 3;
        for d in 0..2 {
            let fit: f64 = (0..K1).map(|i| c[d][j0 + i] * h[i]).sum();
            let e = fit - (xy[d] - origin[d]);
            fp += e * e;
        }
    }
    if !fp.is_finite() {
        return None;
    }
    // Back to the data's frame: c + origin; z + R (1 * origin).
    for d in 0..2 {
        for v in c[d].iter_mut() {
            *v += origin[d];
        }
        for i in 0..nk1 {
            let row_sum: f64 = r[i][..K1.min(nk1 - i)].iter().sum();
            z[d][i] += origin[d] * row_sum;
        }
    }
    Some(LsqFit { r, z, c, fp })
}

/// Adds `h h^T` (4 x 4, symmetric) to `blk`, its upper triangle stored row-major: (0,0..3),
/// (1,1..3), (2,2..3), (3,3).
#[inline(always)]
pub(super) fn add_gram(blk: &mut [f64; 10], h: &[f64; 4]) {
    let mut q = 0;
    for i in 0..4 {
        for j in i..4 {
            blk[q] += h[i] * h[j];
            q += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::basis::design;
    use crate::fit::knots::full_knots;
    use crate::fit::lsq_qr::lsq_fit;
    use crate::fit::test_util::{check_lsq, lsq_data};

    #[test]
    fn normal_equations_agree_with_givens() {
        let (u, x) = lsq_data(60);
        for interior in [&[][..], &[0.5][..], &[0.1, 0.2, 0.45, 0.5, 0.8, 0.95][..]] {
            let t = full_knots(interior, 3);
            let des = design(&t, 3, &u);
            let normal = lsq_fit_cubic_normal(&t, &x, &des).expect("well conditioned");
            let qr = lsq_fit(&t, 3, &x, &des);
            check_lsq(&t, 3, &u, &x, &normal.c, normal.fp);
            for d in 0..2 {
                for (a, b) in normal.c[d].iter().zip(&qr.c[d]) {
                    assert!((a - b).abs() < 1e-9, "c {a} vs {b}");
                }
                // z = Q^T x for the uncentred data, as Givens gives it.
                for (a, b) in normal.z[d].iter().zip(&qr.z[d]) {
                    assert!((a - b).abs() < 1e-8 * b.abs().max(1.0), "z {a} vs {b}");
                }
            }
            for (a, b) in normal.r.iter().zip(&qr.r) {
                assert!(a.iter().zip(b).all(|(p, q)| (p - q).abs() < 1e-10 * b[0]));
            }
            assert!((normal.fp - qr.fp).abs() <= 1e-9 * qr.fp);
        }
    }

    #[test]
    fn ill_posed_knots_are_declined() {
        // Knots in [0.6, 1] where no data lie: B-splines without data make the Gram matrix
        // singular, and the caller must use Givens.
        let (u, x) = lsq_data(30);
        let (u, x): (Vec<f64>, Vec<[f64; 2]>) = (u.iter().map(|v| v * 0.5).collect(), x);
        let t = full_knots(&[0.6, 0.7, 0.8, 0.9], 3);
        assert!(lsq_fit_cubic_normal(&t, &x, &design(&t, 3, &u)).is_none());
    }
}
