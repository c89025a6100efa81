//! The principal axes of a centred point set with the signs numpy's SVD gives them
//! (`np.linalg.svd(xy - centre, full_matrices=False)[2]`, LAPACK `dgesdd`).
//!
//! For an `(M, 2)` matrix with `M >= 3` LAPACK takes its QR factorisation (Householder
//! reflections, `dgeqrf`), then the SVD of the 2x2 triangular factor (`dlasv2` inside `dbdsqr`),
//! makes the singular values positive by flipping the rows of `V^T` and sorts them. The rows'
//! signs decide which corner a fitted rectangle starts at, so they are reproduced here step by
//! step.

use crate::types::Point;

/// Fortran `SIGN(a, b)`: `|a|` with the sign of `b` (`b = -0.0` counts as positive).
#[inline]
fn sign(a: f64, b: f64) -> f64 {
    if b >= 0.0 || b.is_nan() {
        a.abs()
    } else {
        -a.abs()
    }
}

/// LAPACK `dlarfg` on `(alpha, x)`: `(beta, tau, v)` with `v` the scaled tail.
fn householder(alpha: f64, x: &[f64]) -> (f64, f64, Vec<f64>) {
    let xnorm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
    if xnorm == 0.0 {
        return (alpha, 0.0, x.to_vec());
    }
    let beta = -sign(alpha.hypot(xnorm), alpha);
    let tau = (beta - alpha) / beta;
    let scale = 1.0 / (alpha - beta);
    (beta, tau, x.iter().map(|v| v * scale).collect())
}

/// LAPACK `dlasv2(f, g, h)`: `(ssmin, ssmax, snr, csr, snl, csl)` of `[[f, g], [0, h]]`.
#[allow(clippy::many_single_char_names)]
fn dlasv2(f: f64, g: f64, h: f64) -> (f64, f64, f64, f64, f64, f64) {
    let eps = f64::EPSILON / 2.0;
    let (mut ft, mut fa, mut ht, mut ha) = (f, f.abs(), h, h.abs());
    let mut pmax = 1;
    let swap = ha > fa;
    if swap {
        pmax = 3;
        std::mem::swap(&mut ft, &mut ht);
        std::mem::swap(&mut fa, &mut ha);
    }
    let (gt, ga) = (g, g.abs());
    let (ssmin, ssmax, clt, crt, slt, srt);
    if ga == 0.0 {
        (ssmin, ssmax, clt, crt, slt, srt) = (ha, fa, 1.0, 1.0, 0.0, 0.0);
    } else {
        let mut gasmal = true;
        let mut big = None;
        if ga > fa {
            pmax = 2;
            if fa / ga < eps {
                gasmal = false;
                let smin = if ha > 1.0 {
                    fa / (ga / ha)
                } else {
                    (fa / ga) * ha
                };
                big = Some((smin, ga, 1.0, ft / gt, ht / gt, 1.0));
            }
        }
        if gasmal {
            let d = fa - ha;
            let mut l = if d == fa { 1.0 } else { d / fa };
            let m = gt / ft;
            let mut t = 2.0 - l;
            let mm = m * m;
            let tt = t * t;
            let s = (tt + mm).sqrt();
            let r = if l == 0.0 {
                m.abs()
            } else {
                (l * l + mm).sqrt()
            };
            let a = 0.5 * (s + r);
            let (smin, smax) = (ha / a, fa * a);
            if mm != 0.0 {
                t = (m / (s + t) + m / (r + l)) * (1.0 + a);
            } else if l == 0.0 {
                t = sign(2.0, ft) * sign(1.0, gt);
            } else {
                t = gt / sign(d, ft) + m / t;
            }
            l = (t * t + 4.0).sqrt();
            let c = 2.0 / l;
            let sr = t / l;
            let cl = (c + sr * m) / a;
            let sl = (ht / ft) * sr / a;
            (ssmin, ssmax, clt, crt, slt, srt) = (smin, smax, cl, c, sl, sr);
        } else {
            let (smin, smax, cl, cr, sl, sr) = big.unwrap_or((ha, fa, 1.0, 1.0, 0.0, 0.0));
            (ssmin, ssmax, clt, crt, slt, srt) = (smin, smax, cl, cr, sl, sr);
        }
    }
    let (csl, snl, csr, snr) = if swap {
        (srt, crt, slt, clt)
    } else {
        (clt, slt, crt, srt)
    };
    let tsign = match pmax {
        1 => sign(1.0, csr) * sign(1.0, csl) * sign(1.0, f),
        2 => sign(1.0, snr) * sign(1.0, csl) * sign(1.0, g),
        _ => sign(1.0, snr) * sign(1.0, snl) * sign(1.0, h),
    };
    let ssmax = sign(ssmax, tsign);
    let ssmin = sign(ssmin, tsign * sign(1.0, f) * sign(1.0, h));
    (ssmin, ssmax, snr, csr, snl, csl)
}

/// The rows of `V^T` of the centred points `a` (`(M, 2)`, `M >= 3`), as numpy returns them: the
/// principal axis first.
pub fn principal_axes(a: &[Point]) -> [[f64; 2]; 2] {
    let c1: Vec<f64> = a.iter().map(|p| p.x).collect();
    let mut c2: Vec<f64> = a.iter().map(|p| p.y).collect();
    if a.is_empty() {
        return [[1.0, 0.0], [0.0, 1.0]];
    }
    // QR: the first reflector, applied to the second column
    let (r11, tau, v) = householder(c1[0], &c1[1..]);
    let w = c2[0] + v.iter().zip(&c2[1..]).map(|(x, y)| x * y).sum::<f64>();
    c2[0] -= tau * w;
    for (y, x) in c2[1..].iter_mut().zip(&v) {
        *y -= tau * x * w;
    }
    let r12 = c2[0];
    let r22 = if c2.len() > 1 {
        householder(c2[1], &c2[2..]).0
    } else {
        0.0
    };
    // dbdsqr on the bidiagonal [[r11, r12], [0, r22]]
    let mut d = [r11, r22];
    let mut vt = [[1.0, 0.0], [0.0, 1.0]];
    let eps = f64::EPSILON / 2.0;
    let tol = 10f64.max(100f64.min(eps.powf(-0.125))) * eps;
    let mut sminoa = d[0].abs();
    if sminoa != 0.0 {
        let mu = d[1].abs() * (sminoa / (sminoa + r12.abs()));
        sminoa = sminoa.min(mu);
    }
    sminoa /= 2f64.sqrt();
    let thresh = (tol * sminoa).max(6.0 * 2.0 * (2.0 * f64::MIN_POSITIVE));
    if r12.abs() > thresh {
        let (smin, smax, snr, csr, _, _) = dlasv2(d[0], r12, d[1]);
        d = [smax, smin];
        vt = [[csr, snr], [-snr, csr]];
    }
    for k in 0..2 {
        if d[k] < 0.0 {
            d[k] = -d[k];
            vt[k] = [-vt[k][0], -vt[k][1]];
        }
    }
    if d[1].is_nan() || d[0].is_nan() || d[1] > d[0] {
        vt.swap(0, 1);
    }
    vt
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_of_an_elongated_cloud() {
        // points along y = 2x with a little spread, centred
        let raw: Vec<Point> = (0..20)
            .map(|k| {
                let t = k as f64 - 9.5;
                Point::new(t + 0.1 * (k % 3) as f64, 2.0 * t)
            })
            .collect();
        let mean = raw.iter().fold(Point::origin(), |s, p| s + p.coords) / raw.len() as f64;
        let a: Vec<Point> = raw.iter().map(|p| Point::from(p - mean)).collect();
        let vt = principal_axes(&a);
        let (u, w) = (vt[0], vt[1]);
        assert!((u[0] * u[0] + u[1] * u[1] - 1.0).abs() < 1e-12);
        assert!((u[1] / u[0] - 2.0).abs() < 0.05);
        assert!((u[0] * w[0] + u[1] * w[1]).abs() < 1e-12);
        // numpy: [[0.44741578, 0.89432607], [-0.89432607, 0.44741578]]
        assert!((u[0] - 0.44741578).abs() < 1e-8 && (u[1] - 0.89432607).abs() < 1e-8);
        assert!((w[0] + 0.89432607).abs() < 1e-8 && (w[1] - 0.44741578).abs() < 1e-8);
    }

    #[test]
    fn dlasv2_of_a_diagonal_matrix() {
        let (smin, smax, _, csr, _, csl) = dlasv2(3.0, 0.0, -1.0);
        assert_eq!((smin, smax, csr, csl), (-1.0, 3.0, 1.0, 1.0));
    }
}
