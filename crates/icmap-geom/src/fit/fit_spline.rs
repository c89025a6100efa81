//! [`fit_spline`]: the smoothing spline of scipy's `splprep(s=...)` (FITPACK `parcur` / `fppara`
//! part 1: knots added until the least-squares fit meets `s`), with the overshoot rule.

use super::basis::design;
use super::knots::{add_knot, full_knots, interpolation_knots, interval_residuals};
use super::lsq_normal::lsq_fit_cubic_normal;
use super::lsq_poly::fit_cubic_polynomial;
use super::lsq_qr::lsq_fit;
use super::smoothing::{smooth_on_knots, NEGLIGIBLE_ROW};
use super::spline::{make_curve, SplineCurve};
use super::TOL;
use crate::error::{GeomError, Result};
use crate::resample::{cumulative_lengths, dedup_cow};
use crate::types::{check_non_negative, validate_points, Point};

/// A fit whose B-spline coefficients leave the data's bounding box by more than this times its
/// diagonal is ill-posed (see [`fit_spline`]) and is redone on the interpolation knots.
const OVERSHOOT: f64 = 2.0;
/// Consecutive input points closer than this (metres) are merged before fitting.
const DEDUP_EPS: f64 = 1e-9;

/// Fits the smoothing spline of `splprep(points.T, s=s, k=min(3, m - 1))` (unit weights,
/// chord-length parameter) to the points after removing consecutive duplicates.
///
/// One departure from scipy: FITPACK's knot placement (`fpknot`) can put a knot at every data
/// point of a stretch, leaving more B-spline coefficients there than data (the Schoenberg-Whitney
/// conditions fail); the smoothing system is then nearly singular and scipy returns a curve that
/// shoots off by up to ~1e9 m while still meeting `fp = s` at the data. When a coefficient lies
/// farther than twice the data's bounding-box diagonal outside that box, the fit is redone with
/// the same `s` on the interpolation knots (well-posed), so the result always stays near the data.
///
/// Errors on fewer than 2 distinct points, non-finite input, a negative / non-finite `s`, or a
/// fit that stays singular.
pub fn fit_spline(points: &[Point], s: f64) -> Result<SplineCurve> {
    validate_points(points, 2, "curve")?;
    check_non_negative("s", s)?;
    let pts = dedup_cow(points, DEDUP_EPS, false);
    // (The last cumulative length is the polyline's length: the same sums in the same order.)
    let cum = cumulative_lengths(&pts);
    let total = cum[cum.len() - 1];
    if !total.is_finite() {
        return Err(GeomError::NonFinite {
            what: "curve length (coordinates too large)".into(),
        });
    }
    if pts.len() < 2 || (pts[pts.len() - 1] - pts[pts.len() - 2]).norm() <= DEDUP_EPS {
        return Err(GeomError::Degenerate {
            what: "curve".into(),
            reason: "fewer than 2 distinct points".into(),
        });
    }
    let m = pts.len();
    let k = 3.min(m - 1);
    let mut u: Vec<f64> = cum.iter().map(|c| c / total).collect();
    u[m - 1] = 1.0;
    let x: Vec<[f64; 2]> = pts.iter().map(|p| [p.x, p.y]).collect();
    let mut curve = fit_parametric(&u, &x, k, s);
    if overshoots(&curve, &pts) {
        curve = fit_on_interpolation_knots(&u, &x, k, s);
    }
    if !curve.coeffs.iter().flatten().all(|c| c.is_finite()) || overshoots(&curve, &pts) {
        return Err(GeomError::Degenerate {
            what: "curve".into(),
            reason: "the spline system is singular (the fit leaves the data)".into(),
        });
    }
    Ok(curve)
}

/// Whether a B-spline coefficient of `curve` lies farther than [`OVERSHOOT`] times the diagonal of
/// the data's bounding box outside that box (the curve lies in the convex hull of its
/// coefficients, so a fit passing this check stays within that margin of the data).
fn overshoots(curve: &SplineCurve, pts: &[Point]) -> bool {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for q in pts {
        for d in 0..2 {
            lo[d] = lo[d].min(q[d]);
            hi[d] = hi[d].max(q[d]);
        }
    }
    let margin = OVERSHOOT * (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    (0..2).any(|d| {
        curve.coeffs[d]
            .iter()
            .any(|&c| !(c >= lo[d] - margin && c <= hi[d] + margin))
    })
}

/// The smoothing spline with `fp = s` on the interpolation knots (FITPACK's knots when `s` is
/// small enough that all are needed). They satisfy the Schoenberg-Whitney conditions, so the
/// system stays well-posed for every smoothing weight.
fn fit_on_interpolation_knots(u: &[f64], x: &[[f64; 2]], k: usize, s: f64) -> SplineCurve {
    let t = full_knots(&interpolation_knots(u, k), k);
    let des = design(&t, k, u);
    let fit = lsq_fit(&t, k, x, &des);
    let fpms = fit.fp - s;
    if s == 0.0 || fpms >= 0.0 {
        return make_curve(t, fit.c, k, u, fit.fp);
    }
    let t0 = full_knots(&[], k);
    let fit0 = lsq_fit(&t0, k, x, &design(&t0, k, u));
    if fit0.fp - s <= 0.0 {
        return make_curve(t0, fit0.c, k, u, fit0.fp);
    }
    smooth_on_knots(t, &fit, u, k, s, fit0.fp, fpms, NEGLIGIBLE_ROW)
}

/// FITPACK `fppara` with `iopt = 0`, unit weights, `idim = 2`.
fn fit_parametric(u: &[f64], x: &[[f64; 2]], k: usize, s: f64) -> SplineCurve {
    let m = u.len();
    let k1 = k + 1;
    let nmin = 2 * k1;
    let nmax = m + k1;
    let acc = TOL * s;

    if s == 0.0 {
        let t = full_knots(&interpolation_knots(u, k), k);
        let des = design(&t, k, u);
        let fit = lsq_fit(&t, k, x, &des);
        return make_curve(t, fit.c, k, u, fit.fp);
    }

    // Part 1: knots.
    let mut interior: Vec<f64> = Vec::new();
    let mut fpint: Vec<f64> = vec![0.0];
    let mut nrdata: Vec<usize> = vec![m - 2];
    let mut fpold = 0.0;
    let mut fp0 = 0.0;
    let mut nplus = 0usize;
    let mut interpolating = false;
    let (t, fit, fpms) = loop {
        let t = full_knots(&interior, k);
        let n = t.len();
        let first = n == nmin;
        if first && k == 3 && !interpolating {
            // The least-squares polynomial, without the general machinery (most fits end here).
            if let Some((c, fp)) = fit_cubic_polynomial(u, x) {
                fp0 = fp;
                let fpms = fp - s;
                if fpms.abs() < acc || fpms < 0.0 || n >= nmax {
                    return make_curve(t, c.map(|cd| cd.to_vec()), k, u, fp);
                }
                // Too rough: one knot in the one interval (its residual sum is all of `fp`).
                nplus = 1;
                fpold = fp;
                fpint = vec![fp];
                if !add_knot(u, &mut interior, &mut fpint, &mut nrdata)
                    || interior.len() + nmin >= nmax
                {
                    interior = interpolation_knots(u, k);
                    interpolating = true;
                }
                continue;
            }
        }
        let des = design(&t, k, u);
        let fit = if k == 3 {
            lsq_fit_cubic_normal(&t, x, &des).unwrap_or_else(|| lsq_fit(&t, k, x, &des))
        } else {
            lsq_fit(&t, k, x, &des)
        };
        let fp = fit.fp;
        if first {
            fp0 = fp;
        }
        let fpms = fp - s;
        if fpms.abs() < acc || (fpms < 0.0 && first) || n >= nmax || interpolating {
            // Accepted least-squares fit: within tolerance, the polynomial already smooth enough,
            // or the interpolating spline (n = nmax).
            if fpms < 0.0 && !first && fpms.abs() >= acc {
                break (t, fit, fpms);
            }
            return make_curve(t, fit.c, k, u, fp);
        }
        if fpms < 0.0 {
            break (t, fit, fpms);
        }
        // Number of knots to add.
        if first {
            nplus = 1;
        } else {
            let mut npl1 = nplus * 2;
            if fpold - fp > acc {
                npl1 = (nplus as f64 * fpms / (fpold - fp)) as usize;
            }
            nplus = (nplus * 2).min(npl1.max(nplus / 2).max(1));
        }
        fpold = fp;
        fpint = interval_residuals(&t, k, u, x, &fit.c, &des);
        for _ in 0..nplus {
            if !add_knot(u, &mut interior, &mut fpint, &mut nrdata) || interior.len() + nmin >= nmax
            {
                interior = interpolation_knots(u, k);
                interpolating = true;
                break;
            }
        }
    };

    smooth_on_knots(t, &fit, u, k, s, fp0, fpms, NEGLIGIBLE_ROW)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::fit_curve;
    use crate::fit::test_util::{check_even, noisy_arc, p};
    use crate::fit::TOL;
    use crate::resample::polyline_length;
    use proptest::prelude::*;

    #[test]
    fn interpolation_passes_through_points() {
        let pts = noisy_arc(12, 0.3);
        let c = fit_spline(&pts, 0.0).unwrap();
        for (q, &u) in pts.iter().zip(&c.params) {
            assert!((c.eval(u) - q).norm() < 1e-9);
        }
    }

    #[test]
    fn smoothing_meets_s() {
        let pts = noisy_arc(60, 0.3);
        for s in [0.5, 2.0, 5.0] {
            let c = fit_spline(&pts, s).unwrap();
            assert!(
                (c.residual - s).abs() <= TOL * s * 1.0001 || c.knots.len() == 8,
                "fp {} s {}",
                c.residual,
                s
            );
        }
        // A huge s gives the least-squares cubic polynomial (no interior knots).
        let c = fit_spline(&pts, 1e6).unwrap();
        assert_eq!(c.knots.len(), 8);
    }

    #[test]
    fn few_points_lower_degree() {
        let two = [p(0.0, 0.0), p(3.0, 4.0)];
        assert_eq!(fit_spline(&two, 0.5).unwrap().degree, 1);
        let out = fit_curve(&two, 0.5, 1.0).unwrap();
        assert_eq!(out.len(), 6);
        let three = [p(0.0, 0.0), p(1.0, 1.0), p(1.0, 1.0), p(2.0, 0.0)];
        let c = fit_spline(&three, 0.0).unwrap();
        assert_eq!(c.degree, 2);
        assert!((c.eval(0.5) - p(1.0, 1.0)).norm() < 1e-12);
        let four = [p(0.0, 0.0), p(1.0, 1.0), p(2.0, 0.0), p(3.0, 1.0)];
        assert_eq!(fit_spline(&four, 0.1).unwrap().degree, 3);
    }

    #[test]
    fn ill_posed_fitpack_knots_stay_near_data() {
        // proptest regression: FITPACK (and scipy's splprep, measured) put a knot at every data
        // point of the last ~12 points here, and its smoothing spline reaches ~4e8 m (coefficients
        // ~9e8) while meeting fp = s; the fit is redone on the interpolation knots.
        let v = [
            (0.0, 0.29242814533132244),
            (0.0, -0.42965562337574154),
            (0.2492683057117663, -0.17972025284286788),
            (0.0, 0.0),
            (0.4991213469064916, 0.31532794488227667),
            (0.32424685107341433, 0.0990721555480008),
            (0.4299536652597266, 0.0),
            (0.33956597268145233, 0.013999256908586643),
            (0.0, -0.46141611606062444),
            (0.0, -0.4090234481107488),
            (0.0, 0.0),
            (0.09332303329010946, -0.2911522582138828),
            (0.0, 0.44483077532879567),
            (0.26292656762676536, 0.1745979270765869),
            (-0.3049340699588067, 0.0),
            (-0.22720425183382648, 0.10460343822036483),
            (-0.4960888906068653, 0.18899327511285305),
            (0.17089464401408122, 0.38500745788248486),
            (0.13240962849973925, -0.36659082862164627),
            (-0.39269864319455133, -0.49539164695444116),
            (0.0, 0.2530280790627245),
            (0.2897288434108224, 0.0),
            (-0.3900820753828992, -0.1730493356364795),
            (0.1503296673199984, -0.36264091647023583),
            (-0.2039120377273493, -0.0738015938750514),
            (0.42726391311639783, -0.306013746475458),
            (-0.04509041392329944, 0.0),
            (-0.3130397557526532, -0.18633163667521915),
            (0.0, 0.45437078194073177),
            (0.20428801022872906, -0.24043210068777052),
            (-0.20188225839993912, -0.22972994923630644),
            (0.0, -0.4978952379261555),
            (0.15071720600542798, -0.041834881984373955),
            (0.0, 0.051729416533572305),
            (0.24549351288346638, -0.25950906681629277),
            (0.17182566222736853, 0.3576315743483506),
            (-0.27204166192396756, -0.477495567170751),
            (0.34780317485650036, 0.0),
            (0.24479165186595223, 0.08742559328493969),
            (0.32399335395545054, -0.18890919192289152),
            (0.0, -0.23251685748768847),
            (0.259232834230756, 0.0),
            (0.0, 0.45446308518126216),
            (-0.2317528548644894, 0.4249579816030424),
            (0.0, 0.0),
            (-0.38829548013334325, 0.0),
            (-0.4992058182137383, 0.0),
            (0.20426583437244736, -0.4765701635185831),
            (0.0, 0.0),
            (0.0, 0.0),
            (0.0, 0.0),
            (0.4211868677033316, -0.3189039914581989),
            (-0.0992551003694192, 0.0),
            (0.437213814371033, 0.0),
            (0.0, 0.0),
            (0.0, 0.0),
            (0.0, 0.0),
        ];
        let pts: Vec<Point> = v
            .iter()
            .enumerate()
            .map(|(i, (a, b))| p(i as f64 + a, 0.02 * (i * i) as f64 + b))
            .collect();
        let s = 0.057632713274599755;
        let c = fit_spline(&pts, s).unwrap();
        assert!(!overshoots(&c, &pts));
        assert!(
            (c.residual - s).abs() <= TOL * s * 1.0001,
            "fp {}",
            c.residual
        );
        let out = fit_curve(&pts, s, 1.28).unwrap();
        let chord = polyline_length(&pts, false);
        let len = polyline_length(&out, false);
        assert!(
            len > 0.9 * chord && len < 1.2 * chord,
            "length {len} chord {chord}"
        );
        // Every output point is near the data polyline.
        for q in &out {
            let d = pts
                .iter()
                .map(|r| (r - q).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(d < 1.5, "point {q} is {d} m from the data");
        }
        check_even(&c, 0.3);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn prop_fit_finite_and_close(v in prop::collection::vec((-0.5f64..0.5, -0.5f64..0.5), 2..60), s in 0.0f64..5.0, spacing in 0.3f64..3.0) {
            // Noisy samples along a gentle curve.
            let pts: Vec<Point> = v.iter().enumerate().map(|(i, (a, b))| p(i as f64 + a, 0.02 * (i * i) as f64 + b)).collect();
            let c = fit_spline(&pts, s).unwrap();
            prop_assert!(c.residual <= s * (1.0 + TOL) + 1e-9 || c.knots.len() >= pts.len() + c.degree + 1 - 1);
            let out = fit_curve(&pts, s, spacing).unwrap();
            prop_assert!(out.len() >= 2);
            prop_assert!(out.iter().all(|q| q.x.is_finite() && q.y.is_finite()));
            // Chords between consecutive points are at most the arc step (<= spacing).
            let gaps: Vec<f64> = out.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
            let max = gaps.iter().cloned().fold(0.0, f64::max);
            prop_assert!(max <= spacing * 1.001 + 1e-9, "max gap {} spacing {} n {} knots {}", max, spacing, out.len(), c.knots.len());
            // The curve stays near the data (its coefficients' hull within the overshoot margin),
            // and the points are evenly spaced by arc length.
            prop_assert!(!overshoots(&c, &pts));
            check_even(&c, spacing);
        }
    }
}
