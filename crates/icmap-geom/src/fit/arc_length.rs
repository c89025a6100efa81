//! Points evenly spaced by arc length along a fitted curve: per knot span the derivative as a
//! quadratic, an arc-length table by adaptive Gauss-Legendre quadrature, and the inversion of
//! each piece's arc-length model by safeguarded Newton iteration.

use super::spline::SplineCurve;
use crate::error::{GeomError, Result};
use crate::resample::MAX_RESAMPLE_POINTS;
use crate::types::Point;

/// Gauss-Legendre nodes on `[0, 1]` (5 points) and their weights (summing to 1).
const GL_NODES: [f64; 5] = [
    0.046_910_077_030_668_004,
    0.230_765_344_947_158_45,
    0.5,
    0.769_234_655_052_841_6,
    0.953_089_922_969_332,
];
const GL_WEIGHTS: [f64; 5] = [
    0.118_463_442_528_094_54,
    0.239_314_335_249_683_23,
    0.284_444_444_444_444_45,
    0.239_314_335_249_683_23,
    0.118_463_442_528_094_54,
];
/// The outer nodes of 3-point Gauss-Legendre on `[0, 1]` (the middle one is 0.5, shared with the
/// 5-point rule) and the weights of the outer and middle nodes.
const GL3_NODES: [f64; 2] = [0.112_701_665_379_258_31, 0.887_298_334_620_741_7];
const GL3_W_OUTER: f64 = 5.0 / 18.0;
const GL3_W_MID: f64 = 8.0 / 18.0;
/// Relative (to `spacing`) tolerance of a piece's quadrature: a piece is split while its 5-node
/// and 3-node Gauss-Legendre lengths differ by more than this (the difference estimates the
/// 3-node rule's error, a bound far above the 5-node rule's).
const QUAD_TOL: f64 = 1e-5;
/// Length of the arc-length table's pieces before any split, in spacings.
const PIECE_SPACINGS: f64 = 8.0;
/// Tolerance (relative to `spacing`) on the arc length of an inverted sample, far below the
/// documented `1e-3 * spacing`.
const INVERT_TOL: f64 = 1e-7;
/// Maximal bisection depth of a piece.
const QUAD_MAX_DEPTH: u32 = 12;

/// One non-empty knot span `[a, a + w]` of a curve with its derivative `C'(a + w * tau)`,
/// `tau in [0, 1]`, as a quadratic in `tau` per coordinate (exact for degree <= 3).
pub(super) struct Span {
    /// Start parameter (read by the tests' parameter view of the samples).
    #[cfg_attr(not(test), allow(dead_code))]
    a: f64,
    w: f64,
    d: [[f64; 3]; 2],
    /// `C(a)`, the curve at the start of the span.
    p0: [f64; 2],
}

impl Span {
    /// `C(a + w * tau)`: the start point plus the integral of the derivative quadratic (the same
    /// cubic as the B-spline form, evaluated in power form by Horner's rule).
    #[inline]
    pub(super) fn point(&self, tau: f64) -> Point {
        let [x, y] = [0, 1].map(|i| {
            let c = &self.d[i];
            self.p0[i] + self.w * tau * (c[0] + tau * (c[1] / 2.0 + tau * (c[2] / 3.0)))
        });
        Point::new(x, y)
    }

    /// `|dC/dtau|` at `tau` (metres per unit `tau`).
    #[inline]
    fn speed(&self, tau: f64) -> f64 {
        let [dx, dy] = self.d.map(|c| self.w * (c[0] + tau * (c[1] + tau * c[2])));
        (dx * dx + dy * dy).sqrt()
    }

    /// Arc length from `t0` to `t1` by 5-node Gauss-Legendre quadrature.
    fn length(&self, t0: f64, t1: f64) -> f64 {
        let h = t1 - t0;
        h * GL_NODES
            .iter()
            .zip(&GL_WEIGHTS)
            .map(|(&x, &wt)| wt * self.speed(t0 + h * x))
            .sum::<f64>()
    }
}

impl SplineCurve {
    /// The non-empty knot spans with their derivative polynomials.
    fn spans(&self) -> Vec<Span> {
        let k = self.degree;
        let t = &self.knots;
        let nk1 = t.len() - k - 1;
        if k == 3 && nk1 == 4 && t[4] > t[3] {
            // One cubic span (no interior knots): the coefficients are its Bernstein control
            // points, and its derivative is 3 / w times the Bernstein quadratic of their
            // differences, here in power form.
            let (a, w) = (t[3], t[4] - t[3]);
            let d = [0, 1].map(|i| {
                let c = &self.coeffs[i];
                let (d0, d1, d2) = (c[1] - c[0], c[2] - c[1], c[3] - c[2]);
                let f = 3.0 / w;
                [f * d0, f * 2.0 * (d1 - d0), f * (d0 - 2.0 * d1 + d2)]
            });
            let p0 = [self.coeffs[0][0], self.coeffs[1][0]];
            return vec![Span { a, w, d, p0 }];
        }
        (k..nk1)
            .filter(|&l| t[l + 1] > t[l])
            .map(|l| {
                let (a, w) = (t[l], t[l + 1] - t[l]);
                let f0 = self.derivative_in(l, a);
                let fh = self.derivative_in(l, a + 0.5 * w);
                let f1 = self.derivative_in(l, t[l + 1]);
                let d = [0, 1].map(|i| {
                    [
                        f0[i],
                        -3.0 * f0[i] + 4.0 * fh[i] - f1[i],
                        2.0 * f0[i] - 4.0 * fh[i] + 2.0 * f1[i],
                    ]
                });
                let p = self.eval_in(a, l);
                Span {
                    a,
                    w,
                    d,
                    p0: [p.x, p.y],
                }
            })
            .collect()
    }
}

/// A piece of the arc-length table: `tau in [t0, t1]` of span `span`, starting at arc length `s0`
/// and `len` long (its 5-node Gauss-Legendre length), with its arc-length model `arc` (the
/// power-form coefficients of [`arc_model`]).
struct Piece {
    span: usize,
    t0: f64,
    t1: f64,
    s0: f64,
    len: f64,
    arc: [f64; 6],
}

/// `INTEGRATED_LAGRANGE[i][j]`: coefficient of `x^j` in `int_0^x l_i`, where `l_i` is the Lagrange
/// polynomial of the 5 Gauss-Legendre nodes on `[0, 1]` that is 1 at node `i` (at `x = 1` the sum
/// of row `i` is the node's quadrature weight).
const INTEGRATED_LAGRANGE: [[f64; 6]; 5] = [
    [
        0.0,
        1.551_408_049_094_313,
        -6.735_142_250_597_436,
        12.881_499_685_114_732,
        -11.247_246_263_969_75,
        3.667_944_222_886_234_6,
    ],
    [
        0.0,
        -0.893_158_392_000_071_7,
        11.462_166_777_861_865,
        -29.407_603_609_387_63,
        29.465_853_781_661_753,
        -10.387_944_222_886_235,
    ],
    [
        0.0,
        0.533_333_333_333_333_3,
        -7.466_666_666_666_667,
        27.377_777_777_777_778,
        -33.6,
        13.44,
    ],
    [
        0.0,
        -0.267_941_652_223_387_5,
        3.844_963_589_192_847,
        -15.423_630_711_602_96,
        22.473_867_332_769_42,
        -10.387_944_222_886_235,
    ],
    [
        0.0,
        0.076_358_661_795_812_9,
        -1.105_321_449_790_609_5,
        4.571_956_858_098_08,
        -7.092_474_850_461_424,
        3.667_944_222_886_234_6,
    ],
];

/// The arc-length model of a piece `h` long in `tau` with speeds `v` at the 5 Gauss-Legendre
/// nodes: `s(x) = h * int_0^x v(y) dy` for the fraction `x in [0, 1]`, where `v` is the quartic
/// through the 5 speeds (so `s(1)` is exactly the piece's quadrature length). Power-form
/// coefficients of `s`.
fn arc_model(h: f64, v: &[f64; 5]) -> [f64; 6] {
    let mut c = [0.0; 6];
    for (row, &vi) in INTEGRATED_LAGRANGE.iter().zip(v) {
        for (cj, &r) in c.iter_mut().zip(row) {
            *cj += h * vi * r;
        }
    }
    c
}

/// Appends `[t0, t1]` of span `si` to `out` as one piece when its 5-node and 3-node quadratures
/// agree to `tol` and its arc-length model gives the quadrature's length of its first half to
/// `tol`, else its two halves (recursively); arc length accumulated in `*s`.
#[allow(clippy::too_many_arguments)]
fn quad_pieces(
    sp: &Span,
    si: usize,
    t0: f64,
    t1: f64,
    tol: f64,
    depth: u32,
    s: &mut f64,
    out: &mut Vec<Piece>,
) {
    let h = t1 - t0;
    let v: [f64; 5] = std::array::from_fn(|i| sp.speed(t0 + h * GL_NODES[i]));
    let len = h * (0..5).map(|i| GL_WEIGHTS[i] * v[i]).sum::<f64>();
    let gl3 = h
        * (GL3_W_OUTER * (sp.speed(t0 + h * GL3_NODES[0]) + sp.speed(t0 + h * GL3_NODES[1]))
            + GL3_W_MID * v[2]);
    let err = (len - gl3).abs();
    let tm = 0.5 * (t0 + t1);
    let split = |out: &mut Vec<Piece>, s: &mut f64| {
        quad_pieces(sp, si, t0, tm, tol, depth + 1, s, out);
        quad_pieces(sp, si, tm, t1, tol, depth + 1, s, out);
    };
    // (A NaN difference splits too, down to the depth limit.)
    if depth < QUAD_MAX_DEPTH && (err > tol || err.is_nan()) {
        split(out, s);
        return;
    }
    // The inversion reads the piece's arc-length model inside it, not only its total: where the
    // speed dips sharply (near a cusp of a wiggly fit) both rules can agree on the total while
    // the model is off inside, so the model's half-way length is checked against quadrature.
    let arc = arc_model(h, &v);
    let half_err = (arc.iter().rev().fold(0.0, |acc, &c| acc * 0.5 + c) - sp.length(t0, tm)).abs();
    if depth < QUAD_MAX_DEPTH && (half_err > tol || half_err.is_nan()) {
        split(out, s);
        return;
    }
    out.push(Piece {
        span: si,
        t0,
        t1,
        s0: *s,
        len,
        arc,
    });
    *s += len;
}

/// The parameter `tau` in `piece` at arc length `r` from its start (`0 <= r <= piece.len`): the
/// root of the piece's arc-length model ([`arc_model`]) by Newton iteration safeguarded by
/// bisection, to `tol` (metres of arc length). The model integrates the quartic interpolant of the
/// speed; a piece whose model is off at its middle by more than the quadrature tolerance was split
/// ([`quad_pieces`]), which keeps the error far below the documented `1e-3 * spacing` (tested).
fn invert(piece: &Piece, r: f64, tol: f64) -> f64 {
    let (t0, t1) = (piece.t0, piece.t1);
    if piece.len.is_nan() || piece.len <= 0.0 {
        return t0;
    }
    let c = &piece.arc;
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let mut x = (r / piece.len).clamp(0.0, 1.0);
    for _ in 0..60 {
        let f = x * (c[1] + x * (c[2] + x * (c[3] + x * (c[4] + x * c[5])))) - r;
        if f.abs() <= tol {
            break;
        }
        if f > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let df = c[1] + x * (2.0 * c[2] + x * (3.0 * c[3] + x * (4.0 * c[4] + x * 5.0 * c[5])));
        let next = if df > 0.0 { x - f / df } else { f64::NAN };
        let next = if next > lo && next < hi {
            next
        } else {
            0.5 * (lo + hi)
        };
        x = next;
        if hi - lo <= 1e-15 {
            break;
        }
    }
    t0 + (t1 - t0) * x
}

/// The parameters `u_i` of the `max(2, ceil(L / spacing) + 1)` points evenly spaced by arc length
/// along `curve` (first and last are the curve's ends). See [`fit_curve`].
#[cfg(test)]
pub(super) fn arc_length_params(curve: &SplineCurve, spacing: f64) -> Result<Vec<f64>> {
    let k = curve.degree;
    let (u_start, u_end) = (curve.knots[k], curve.knots[curve.knots.len() - k - 1]);
    let (spans, samples) = arc_length_samples(curve, spacing)?;
    let last = samples.len() - 1;
    Ok(samples
        .iter()
        .enumerate()
        .map(|(i, &(si, tau))| {
            if i == last {
                u_end
            } else {
                (spans[si].a + spans[si].w * tau).clamp(u_start, u_end)
            }
        })
        .collect())
}

/// A point of the curve as `(span index, tau)`: `C(a + w * tau)` of that span.
pub(super) type Sample = (usize, f64);

/// The curve's non-empty knot spans and the `max(2, ceil(L / spacing) + 1)` samples evenly spaced
/// by arc length along it, each as `(span index, tau)` (the first is the curve's start, the last
/// its end). See [`fit_curve`].
pub(super) fn arc_length_samples(
    curve: &SplineCurve,
    spacing: f64,
) -> Result<(Vec<Span>, Vec<Sample>)> {
    let too_many = |len: f64| GeomError::InvalidParameter {
        name: "spacing",
        reason: format!("length {len} / spacing {spacing} gives too many points"),
    };
    let spans = curve.spans();
    let span_len: Vec<f64> = spans.iter().map(|sp| sp.length(0.0, 1.0)).collect();
    let rough: f64 = span_len.iter().sum();
    if !rough.is_finite() || rough / spacing >= MAX_RESAMPLE_POINTS as f64 {
        return Err(too_many(rough));
    }
    // Arc-length table: each span cut into pieces of at most about `spacing`, refined adaptively.
    let tol = QUAD_TOL * spacing;
    let mut pieces = Vec::with_capacity((2.0 * rough / spacing) as usize + 2 * spans.len());
    let mut len = 0.0;
    for (si, (sp, &sl)) in spans.iter().zip(&span_len).enumerate() {
        let parts = (sl / (PIECE_SPACINGS * spacing)).ceil().max(1.0) as usize;
        for j in 0..parts {
            let (t0, t1) = (j as f64 / parts as f64, (j + 1) as f64 / parts as f64);
            quad_pieces(sp, si, t0, t1, tol, 0, &mut len, &mut pieces);
        }
    }
    if !(len.is_finite() && len > 0.0) || pieces.is_empty() {
        return Err(GeomError::Degenerate {
            what: "fitted curve".into(),
            reason: "zero length".into(),
        });
    }
    // Tolerance on the ratio: a length of exactly k spacings (up to rounding) gives k + 1 points.
    let ratio = (len / spacing * (1.0 - 1e-9)).ceil();
    if !ratio.is_finite() || ratio >= MAX_RESAMPLE_POINTS as f64 {
        return Err(too_many(len));
    }
    let count = (ratio as usize + 1).max(2);
    let mut out = Vec::with_capacity(count);
    out.push((0, 0.0));
    let mut pi = 0usize;
    for i in 1..count - 1 {
        let target = len * i as f64 / (count - 1) as f64;
        while pi + 1 < pieces.len() && pieces[pi].s0 + pieces[pi].len < target {
            pi += 1;
        }
        let piece = &pieces[pi];
        let tau = invert(piece, target - piece.s0, INVERT_TOL * spacing);
        out.push((piece.span, tau.clamp(0.0, 1.0)));
    }
    out.push((spans.len() - 1, 1.0));
    Ok((spans, out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::fit_curve;
    use crate::fit::fit_spline;
    use crate::fit::test_util::{check_even, noisy_arc, p};

    #[test]
    fn arc_length_evenly_spaced() {
        // A smooth noisy arc, and an interpolating zig-zag (loops, near-cusps, fast parameter).
        let arc = noisy_arc(30, 0.3);
        let zigzag: Vec<Point> = (0..25)
            .map(|i| {
                let e = (i * 7919 % 101) as f64 / 101.0 - 0.5;
                p(
                    0.4 * i as f64 + 3.0 * e,
                    if i % 2 == 0 { 1.0 } else { -1.0 } + e,
                )
            })
            .collect();
        for (pts, s) in [(&arc, 0.5), (&arc, 0.0), (&zigzag, 0.0), (&zigzag, 0.3)] {
            let c = fit_spline(pts, s).unwrap();
            for spacing in [0.05, 0.3, 1.0, 7.0] {
                check_even(&c, spacing);
            }
        }
        // fit_curve returns the spline at those parameters.
        let c = fit_spline(&arc, 0.5).unwrap();
        let us = arc_length_params(&c, 1.0).unwrap();
        let out = fit_curve(&arc, 0.5, 1.0).unwrap();
        assert_eq!(out.len(), us.len());
        assert!(out
            .iter()
            .zip(&us)
            .all(|(q, &u)| (c.eval(u) - q).norm() < 1e-12));
    }

    /// A span whose speed varies: `C'(tau) = (1 + 2 tau, 3 tau^2)`.
    fn span() -> Span {
        Span {
            a: 0.0,
            w: 1.0,
            d: [[1.0, 2.0, 0.0], [0.0, 0.0, 3.0]],
            p0: [1.0, -2.0],
        }
    }

    /// Arc length of `sp` on `[t0, t1]` by 20,000 chords.
    fn chord_length(sp: &Span, t0: f64, t1: f64) -> f64 {
        let n = 20_000;
        (0..n)
            .map(|i| {
                let (a, b) = (
                    t0 + (t1 - t0) * i as f64 / n as f64,
                    t0 + (t1 - t0) * (i + 1) as f64 / n as f64,
                );
                (sp.point(b) - sp.point(a)).norm()
            })
            .sum()
    }

    #[test]
    fn span_point_integrates_its_derivative() {
        let sp = span();
        // C(tau) = p0 + (tau + tau^2, tau^3).
        for tau in [0.0, 0.3, 1.0] {
            let q = sp.point(tau);
            assert!((q.x - (1.0 + tau + tau * tau)).abs() < 1e-15);
            assert!((q.y - (-2.0 + tau * tau * tau)).abs() < 1e-15);
        }
        assert!((sp.length(0.0, 1.0) - chord_length(&sp, 0.0, 1.0)).abs() < 1e-6);
    }

    #[test]
    fn inversion_hits_the_requested_arc_length() {
        let sp = span();
        let mut s = 0.0;
        let mut pieces = Vec::new();
        quad_pieces(&sp, 0, 0.0, 1.0, 1e-9, 0, &mut s, &mut pieces);
        assert!(pieces.len() > 1, "split by the quadrature test");
        assert!((s - chord_length(&sp, 0.0, 1.0)).abs() < 1e-7);
        for piece in &pieces {
            for f in [0.0, 0.1, 0.5, 0.77, 1.0] {
                let r = f * piece.len;
                let tau = invert(piece, r, 1e-12);
                assert!((piece.t0..=piece.t1).contains(&tau));
                let got = chord_length(&sp, piece.t0, tau);
                assert!((got - r).abs() < 1e-7, "r {r}: {got}");
            }
        }
    }
}
