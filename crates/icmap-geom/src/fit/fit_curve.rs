//! [`fit_curve`]: the smoothing spline of the points evaluated about `spacing` apart by arc length.

use super::arc_length::arc_length_samples;
use super::fit_spline::fit_spline;
use crate::error::Result;
use crate::types::{check_positive, Point};

/// Fits a smoothing parametric cubic spline to `points` and returns it evaluated about `spacing`
/// metres apart (ends included).
///
/// Semantics of scipy `splprep(..., s=s, k=3)`: chord-length parameter on [0, 1], unit weights, the
/// smoothest spline whose sum of squared residuals is at most `s` (see [`fit_spline`] for the one
/// departure, on fits FITPACK leaves ill-posed). Duplicate consecutive points are removed first.
/// With 2 or 3 distinct points the degree drops (k = min(3, m - 1)).
///
/// The output has `count = max(2, ceil(L / spacing) + 1)` points, where `L` is the arc length of the
/// spline (5-node Gauss-Legendre quadrature of `|C'(u)|` on pieces of each knot span, split
/// adaptively until the 5- and 3-node rules agree to `1e-5 * spacing`). Every output point is the spline
/// evaluated at a parameter `u_i` (so it lies exactly on the spline); the first and last are the
/// spline's ends `S(0)`, `S(1)`; the arc length from `S(0)` to point `i` is `i * L / (count - 1)`
/// to within `1e-3 * spacing` (tested), so consecutive points are evenly spaced by arc length
/// and every chord between them is at most `spacing * (1 + 1e-3)`.
///
/// Errors as [`fit_spline`], on a non-positive or non-finite `spacing`, and when
/// `L / spacing` would give [`MAX_RESAMPLE_POINTS`](crate::resample::MAX_RESAMPLE_POINTS) points or more.
pub fn fit_curve(points: &[Point], s: f64, spacing: f64) -> Result<Vec<Point>> {
    check_positive("spacing", spacing)?;
    let curve = fit_spline(points, s)?;
    let (spans, samples) = arc_length_samples(&curve, spacing)?;
    let mut out: Vec<Point> = samples
        .iter()
        .map(|&(si, tau)| spans[si].point(tau))
        .collect();
    // The last point is the curve's end, evaluated in B-spline form (exactly `S(1)`).
    let k = curve.degree;
    if let Some(last) = out.last_mut() {
        *last = curve.eval(curve.knots[curve.knots.len() - k - 1]);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::GeomError;
    use crate::fit::test_util::{noisy_arc, p};
    use proptest::prelude::*;

    #[test]
    fn straight_line_stays_straight() {
        let pts: Vec<Point> = (0..20).map(|i| p(i as f64, 2.0 * i as f64)).collect();
        let out = fit_curve(&pts, 0.5, 1.0).unwrap();
        let len = 19.0 * 5f64.sqrt();
        assert_eq!(out.len(), (len.ceil() as usize) + 1);
        assert!((out[0] - pts[0]).norm() < 1e-9 && (out[out.len() - 1] - pts[19]).norm() < 1e-9);
        assert!(out.iter().all(|q| (q.y - 2.0 * q.x).abs() < 1e-9));
        let gaps: Vec<f64> = out.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
        assert!(gaps
            .iter()
            .all(|g| (g - len / (out.len() - 1) as f64).abs() < 1e-6));
    }

    #[test]
    fn errors() {
        let pts = noisy_arc(10, 0.1);
        assert!(matches!(
            fit_curve(&pts, -1.0, 1.0),
            Err(GeomError::InvalidParameter { name: "s", .. })
        ));
        assert!(matches!(
            fit_curve(&pts, f64::NAN, 1.0),
            Err(GeomError::InvalidParameter { name: "s", .. })
        ));
        assert!(matches!(
            fit_curve(&pts, 0.5, 0.0),
            Err(GeomError::InvalidParameter {
                name: "spacing",
                ..
            })
        ));
        assert!(matches!(
            fit_curve(&[], 0.5, 1.0),
            Err(GeomError::TooFewPoints { .. })
        ));
        assert!(matches!(
            fit_curve(&[p(1.0, 1.0)], 0.5, 1.0),
            Err(GeomError::TooFewPoints { .. })
        ));
        assert!(matches!(
            fit_curve(&[p(1.0, 1.0), p(1.0, 1.0)], 0.5, 1.0),
            Err(GeomError::Degenerate { .. })
        ));
        assert!(matches!(
            fit_curve(&[p(1.0, f64::NAN), p(1.0, 1.0)], 0.5, 1.0),
            Err(GeomError::NonFinite { .. })
        ));
    }

    proptest! {

        #[test]
        fn prop_no_panic_arbitrary(v in prop::collection::vec((any::<f64>(), any::<f64>()), 0..8), s in any::<f64>(), sp in any::<f64>()) {
            let pts: Vec<Point> = v.into_iter().map(|(x, y)| p(x, y)).collect();
            if let Ok(out) = fit_curve(&pts, s, sp) {
                prop_assert!(out.iter().all(|q| q.x.is_finite() && q.y.is_finite()));
            }
        }
    }
}
