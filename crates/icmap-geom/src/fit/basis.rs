//! B-spline basis values: the de Boor-Cox recurrence (FITPACK `fpbspl`), its unrolled cubic form
//! with per-interval knot reciprocals, the Bernstein polynomials (cubic, no interior knots), and
//! the design of a fit (every data point's knot interval and basis values).

/// The `k + 1` non-zero B-splines of degree `k` at `x` with `t[l] <= x < t[l + 1]` (de Boor-Cox,
/// FITPACK's `fpbspl`); entry `i` belongs to coefficient `l - k + i`.
#[inline]
pub(super) fn bspline_basis(t: &[f64], k: usize, x: f64, l: usize) -> [f64; 6] {
    // The common cubic and quadratic cases with the degree a constant (the recurrence unrolled
    // by the compiler); the arithmetic, and so the result, is the same.
    match k {
        3 => basis_recurrence(t, 3, x, l),
        2 => basis_recurrence(t, 2, x, l),
        _ => basis_recurrence(t, k, x, l),
    }
}

#[inline(always)]
fn basis_recurrence(t: &[f64], k: usize, x: f64, l: usize) -> [f64; 6] {
    let mut h = [0.0; 6];
    let mut hh = [0.0; 6];
    h[0] = 1.0;
    for j in 1..=k {
        hh[..j].copy_from_slice(&h[..j]);
        h[0] = 0.0;
        for i in 1..=j {
            let li = l + i;
            let lj = li - j;
            let (tli, tlj) = (t[li], t[lj]);
            if tli == tlj {
                h[i] = 0.0;
                continue;
            }
            let f = hh[i - 1] / (tli - tlj);
            h[i - 1] += f * (tli - x);
            h[i] = f * (x - tlj);
        }
    }
    h
}

/// Per data point: its knot interval `l` and its `k + 1` basis values.
pub(super) struct Design {
    pub(super) interval: Vec<usize>,
    pub(super) basis: Vec<[f64; 6]>,
}

pub(super) fn design(t: &[f64], k: usize, u: &[f64]) -> Design {
    let nk1 = t.len() - k - 1;
    let mut l = k;
    let mut interval = Vec::with_capacity(u.len());
    let mut basis = Vec::with_capacity(u.len());
    if k == 3 && t.len() == 8 && t[..4] == [0.0; 4] && t[4..] == [1.0; 4] {
        // No interior knots (FITPACK's first fit, and most merges): the cubic B-splines on
        // [0, 1] are the Bernstein polynomials.
        for &x in u {
            let [b0, b1, b2, b3] = bernstein3(x);
            interval.push(3);
            basis.push([b0, b1, b2, b3, 0.0, 0.0]);
        }
        return Design { interval, basis };
    }
    if k == 3 {
        // The cubic recurrence with the knot-difference reciprocals of the current interval
        // computed once per interval (data points share intervals).
        let mut inv = cubic_reciprocals(t, l);
        for &ui in u {
            let l0 = l;
            while ui >= t[l + 1] && l + 1 < nk1 {
                l += 1;
            }
            if l != l0 {
                inv = cubic_reciprocals(t, l);
            }
            interval.push(l);
            basis.push(cubic_basis(t, &inv, ui, l));
        }
        return Design { interval, basis };
    }
    for &ui in u {
        while ui >= t[l + 1] && l + 1 < nk1 {
            l += 1;
        }
        interval.push(l);
        basis.push(bspline_basis(t, k, ui, l));
    }
    Design { interval, basis }
}

/// `1 / (t[l + i] - t[l + i - j])` for the de Boor-Cox recurrence of degree 3 in interval `l`
/// (`j = 1..=3`, `i = 1..=j`, row-major), 0 where the knots coincide (that term vanishes).
fn cubic_reciprocals(t: &[f64], l: usize) -> [f64; 6] {
    let mut inv = [0.0; 6];
    let mut q = 0;
    for j in 1..=3 {
        for i in 1..=j {
            let d = t[l + i] - t[l + i - j];
            inv[q] = if d == 0.0 { 0.0 } else { 1.0 / d };
            q += 1;
        }
    }
    inv
}

/// The 4 non-zero cubic B-splines at `x` in interval `l` (as [`bspline_basis`]), with the knot
/// reciprocals `inv` of [`cubic_reciprocals`] instead of divisions (the recurrence unrolled).
#[inline]
fn cubic_basis(t: &[f64], inv: &[f64; 6], x: f64, l: usize) -> [f64; 6] {
    let (tm2, tm1, t0) = (t[l - 2], t[l - 1], t[l]);
    let (t1, t2, t3) = (t[l + 1], t[l + 2], t[l + 3]);
    // Degree 1.
    let f = inv[0];
    let (a0, a1) = (f * (t1 - x), f * (x - t0));
    // Degree 2.
    let f = a0 * inv[1];
    let mut b0 = f * (t1 - x);
    let mut b1 = f * (x - tm1);
    let f = a1 * inv[2];
    b1 += f * (t2 - x);
    let b2 = f * (x - t0);
    // Degree 3.
    let f = b0 * inv[3];
    b0 = f * (t1 - x);
    let mut c1 = f * (x - tm2);
    let f = b1 * inv[4];
    c1 += f * (t2 - x);
    let mut c2 = f * (x - tm1);
    let f = b2 * inv[5];
    c2 += f * (t3 - x);
    let c3 = f * (x - t0);
    [b0, c1, c2, c3, 0.0, 0.0]
}

/// The cubic B-splines on `[0, 1]` without interior knots (the Bernstein polynomials) at `x`.
#[inline(always)]
pub(super) fn bernstein3(x: f64) -> [f64; 4] {
    let y = 1.0 - x;
    [y * y * y, 3.0 * x * y * y, 3.0 * x * x * y, x * x * x]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clamped cubic knot vector with uneven interior knots, one of them double.
    const KNOTS: [f64; 12] = [0.0, 0.0, 0.0, 0.0, 0.1, 0.35, 0.35, 0.8, 1.0, 1.0, 1.0, 1.0];

    /// The B-spline `N_{i,k}(x)` by its recursive definition (half-open intervals, 0 / 0 = 0): an
    /// oracle independent of the recurrence's in-place form.
    fn naive(t: &[f64], i: usize, k: usize, x: f64) -> f64 {
        if k == 0 {
            return if t[i] <= x && x < t[i + 1] { 1.0 } else { 0.0 };
        }
        let a = if t[i + k] > t[i] {
            (x - t[i]) / (t[i + k] - t[i]) * naive(t, i, k - 1, x)
        } else {
            0.0
        };
        let b = if t[i + k + 1] > t[i + 1] {
            (t[i + k + 1] - x) / (t[i + k + 1] - t[i + 1]) * naive(t, i + 1, k - 1, x)
        } else {
            0.0
        };
        a + b
    }

    /// The knot interval `l` of `x` (`t[l] <= x < t[l + 1]`, the last one for the right end).
    fn interval(t: &[f64], k: usize, x: f64) -> usize {
        let nk1 = t.len() - k - 1;
        k + t[k + 1..nk1].partition_point(|&v| v <= x)
    }

    #[test]
    fn basis_matches_the_recursive_definition() {
        for k in 1..=3 {
            // The same interior knots with k + 1 end knots.
            let t = &KNOTS[3 - k..KNOTS.len() - (3 - k)];
            for i in 0..200 {
                let x = i as f64 / 200.0;
                let l = interval(t, k, x);
                let h = bspline_basis(t, k, x, l);
                for (j, &v) in h[..=k].iter().enumerate() {
                    let want = naive(t, l - k + j, k, x);
                    assert!((v - want).abs() < 1e-14, "k {k} x {x} j {j}: {v} vs {want}");
                }
                assert!((h[..=k].iter().sum::<f64>() - 1.0).abs() < 1e-14);
                assert!(h[k + 1..].iter().all(|&v| v == 0.0));
            }
        }
    }

    #[test]
    fn cubic_forms_match_the_recurrence() {
        let t = &KNOTS;
        for i in 0..=200 {
            let x = i as f64 / 200.0;
            let l = interval(t, 3, x);
            let want = bspline_basis(t, 3, x, l);
            let got = cubic_basis(t, &cubic_reciprocals(t, l), x, l);
            for j in 0..4 {
                assert!((got[j] - want[j]).abs() < 1e-15, "x {x} j {j}");
            }
        }
        // Without interior knots the cubic B-splines are the Bernstein polynomials.
        let t0 = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        for i in 0..=200 {
            let x = i as f64 / 200.0;
            let want = bspline_basis(&t0, 3, x, 3);
            let got = bernstein3(x);
            for j in 0..4 {
                assert!((got[j] - want[j]).abs() < 1e-15, "x {x} j {j}");
            }
        }
    }

    #[test]
    fn design_puts_every_point_in_its_interval() {
        let u: Vec<f64> = (0..=50).map(|i| i as f64 / 50.0).collect();
        for (t, k) in [
            (&KNOTS[..], 3),
            (&KNOTS[1..11], 2),
            (&[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0][..], 3),
        ] {
            let des = design(t, k, &u);
            let nk1 = t.len() - k - 1;
            assert_eq!((des.interval.len(), des.basis.len()), (u.len(), u.len()));
            for ((&x, &l), h) in u.iter().zip(&des.interval).zip(&des.basis) {
                assert!(t[l] <= x && (x < t[l + 1] || l == nk1 - 1), "x {x} l {l}");
                let want = bspline_basis(t, k, x, l);
                for j in 0..=k {
                    assert!((h[j] - want[j]).abs() < 1e-15, "x {x} j {j}");
                }
            }
        }
    }
}
