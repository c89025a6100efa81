//! Givens rotations of the banded least-squares systems (FITPACK `fpgivs` / `fprota`) in three
//! variants (FITPACK's overflow-guarded form, a bounded form for the observation rows, and a
//! switch between them for the scaled smoothing rows), and back substitution of the banded
//! triangular factor.

/// Givens rotation zeroing `piv` against `ww` (FITPACK `fpgivs`): returns `(cos, sin)` and
/// replaces `ww` by the rotated value.
fn givens(piv: f64, ww: &mut f64) -> (f64, f64) {
    let store = piv.abs();
    let dd = if store >= *ww {
        store * (1.0 + (*ww / piv).powi(2)).sqrt()
    } else {
        *ww * (1.0 + (piv / *ww).powi(2)).sqrt()
    };
    if dd == 0.0 {
        return (1.0, 0.0);
    }
    let (cos, sin) = (*ww / dd, piv / dd);
    *ww = dd;
    (cos, sin)
}

/// [`givens`] for bounded entries (the least-squares system of B-spline values in `[0, 1]`, whose
/// triangular factor stays below `sqrt(m)`): `hypot` without FITPACK's overflow guard, and one
/// division instead of three.
#[inline]
pub(super) fn givens_bounded(piv: f64, ww: &mut f64) -> (f64, f64) {
    let dd = (piv * piv + *ww * *ww).sqrt();
    if dd == 0.0 {
        return (1.0, 0.0);
    }
    let inv = 1.0 / dd;
    let (cos, sin) = (*ww * inv, piv * inv);
    *ww = dd;
    (cos, sin)
}

/// [`givens_bounded`] while both entries are far from overflow when squared, [`givens`] (FITPACK's
/// scaled form) otherwise: the smoothing rows are scaled by `1 / p`, which can be large.
#[inline]
pub(super) fn givens_scaled(piv: f64, ww: &mut f64) -> (f64, f64) {
    const SAFE: f64 = 1e150;
    if piv.abs() < SAFE && ww.abs() < SAFE {
        givens_bounded(piv, ww)
    } else {
        givens(piv, ww)
    }
}

/// Applies a Givens rotation to the pair `(a, b)` (FITPACK `fprota`).
pub(super) fn rotate(cos: f64, sin: f64, a: &mut f64, b: &mut f64) {
    let (s1, s2) = (*a, *b);
    *b = cos * s2 + sin * s1;
    *a = cos * s1 - sin * s2;
}

/// Back substitution for the banded upper-triangular `r` (`r[i][j]` = R(i, i + j), bandwidth `bw`).
pub(super) fn back_substitute(r: &[[f64; 5]], z: &[f64], bw: usize) -> Vec<f64> {
    let mut c = vec![0.0; z.len()];
    back_substitute_into(r, z, bw, &mut c);
    c
}

/// [`back_substitute`] into `c` (`z.len()` long).
pub(super) fn back_substitute_into(r: &[[f64; 5]], z: &[f64], bw: usize, c: &mut [f64]) {
    let n = z.len();
    for i in (0..n).rev() {
        let mut acc = z[i];
        for l in 1..bw.min(n - i) {
            acc -= c[i + l] * r[i][l];
        }
        c[i] = acc / r[i][0];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rotating the pair `(piv, ww)` by the rotation computed for it gives `(0, hypot)`.
    fn check(piv: f64, ww: f64, f: fn(f64, &mut f64) -> (f64, f64)) -> f64 {
        let mut w = ww;
        let (cos, sin) = f(piv, &mut w);
        let dd = piv.hypot(ww);
        assert!((w - dd).abs() <= 1e-15 * dd, "{piv} {ww}: {w} vs {dd}");
        assert!((cos * cos + sin * sin - 1.0).abs() < 1e-15);
        let (mut a, mut b) = (piv, ww);
        rotate(cos, sin, &mut a, &mut b);
        assert!(a.abs() <= 1e-15 * dd && (b - dd).abs() <= 1e-15 * dd);
        w
    }

    #[test]
    fn every_variant_zeroes_the_pivot() {
        let pairs = [
            (3.0, 4.0),
            (-2.5, 0.5),
            (1e-3, 7.0),
            (0.0, 2.0),
            (5.0, 0.0),
            (-1e-8, 1e-8),
        ];
        for (piv, ww) in pairs {
            let w = [givens, givens_bounded, givens_scaled].map(|f| check(piv, ww, f));
            assert!(w.iter().all(|&v| (v - w[0]).abs() <= 1e-15 * w[0]));
        }
        // Nothing to rotate: the identity. (FITPACK's form gives NaN for a zero pair; its callers
        // skip zero pivots and the scaled form takes it only for large entries.)
        for f in [givens_bounded, givens_scaled] {
            let mut w = 0.0;
            assert_eq!(f(0.0, &mut w), (1.0, 0.0));
            assert_eq!(w, 0.0);
        }
    }

    #[test]
    fn scaled_variant_survives_large_entries() {
        // The bounded form squares its entries (overflow); the scaled one switches to FITPACK's.
        let (piv, ww) = (3e200, 4e200);
        let mut w = ww;
        givens_bounded(piv, &mut w);
        assert!(w.is_infinite());
        let w = check(piv, ww, givens_scaled);
        assert!((w - 5e200).abs() <= 1e-15 * 5e200);
        check(piv, ww, givens);
    }

    #[test]
    fn back_substitution_inverts_the_banded_factor() {
        // R: 6 x 6 upper triangular with bandwidth 4; z = R c.
        let n = 6;
        let bw = 4;
        let r: Vec<[f64; 5]> = (0..n)
            .map(|i| {
                let mut row = [0.0; 5];
                for (j, v) in row.iter_mut().enumerate().take(bw) {
                    *v = if j == 0 {
                        2.0 + i as f64
                    } else {
                        0.3 * j as f64 - 0.1 * i as f64
                    };
                }
                row
            })
            .collect();
        let c: Vec<f64> = (0..n).map(|i| (i as f64 * 1.7).sin()).collect();
        let z: Vec<f64> = (0..n)
            .map(|i| (0..bw.min(n - i)).map(|j| r[i][j] * c[i + j]).sum())
            .collect();
        let got = back_substitute(&r, &z, bw);
        assert!(got.iter().zip(&c).all(|(a, b)| (a - b).abs() < 1e-14));
        let mut into = vec![f64::NAN; n];
        back_substitute_into(&r, &z, bw, &mut into);
        assert_eq!(into, got);
    }
}
